"""A contract bag from a folder of stereo image pairs (e.g. the KITTI road sequence).

    asmonc images-bag FOLDER OUT [--calibration FILE] [--right-calibration FILE]
                      [--start S] [--count K] [--repeat N] [--fps HZ]

FOLDER holds the pairs as the capture node's image folder does (``left/`` + ``right/``,
``image_2/`` + ``image_3/`` or ``image_0/`` + ``image_1/``, paired by file name) and,
unless --calibration is given, a KITTI ``calib.txt`` (any calibration the capture node
reads is accepted: OpenCV stereo YAML, a ROS camera_info YAML pair, KITTI calib.txt; raw
pairs are rectified with it). The images are read as mono8 as the capture node's image
folder reads them (``core.capture.FolderSource``: ``cv2.IMREAD_GRAYSCALE``, the luma of
a colour image).

OUT, a new rosbag2 directory (MCAP, zstd chunks), follows the topic contract (README,
"Topic contract"): per pair, at one stamp, ``/stereo/{left,right}/camera_info`` (rectified,
right ``P[0,3] = -f*B``) then ``/stereo/{left,right}/image_rect`` (mono8). The pairs
``--start`` .. ``--start + --count`` are written in order, each ``--repeat`` times in a
row (``--count 1 --repeat 30``: one pair held still for 3 s), one per 1/``--fps``
seconds. ``--fps`` defaults to the rate of the folder's ``times.txt`` (KITTI: 10 Hz), else
10 Hz. Stamps start at the simulator's epoch (``sim.bagwriter.EPOCH_NS``). No ground
truth topics: ``asmonc run`` replays and reports such a bag without scoring.

Exit status: 0 written; 2 the folder, its images or its calibration cannot be used, or
OUT exists.
"""
from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('folder', help='image folder: left/ + right/, image_2/ + image_3/ or '
                   'image_0/ + image_1/, with calib.txt unless --calibration is given')
    p.add_argument('out', help='the bag directory to write (must not exist)')
    p.add_argument('--calibration', default='', help='calibration file (default: '
                   'FOLDER/calib.txt, KITTI)')
    p.add_argument('--right-calibration', default='',
                   help="the right camera's camera_info YAML (with a left one)")
    p.add_argument('--start', type=int, default=0, help='first pair (index, sorted by name)')
    p.add_argument('--count', type=int, default=0, help='pairs used (0 = all from --start)')
    p.add_argument('--repeat', type=int, default=1,
                   help='each pair written this many times in a row (a still camera)')
    p.add_argument('--fps', type=float, default=0.0,
                   help="rate, Hz (default: FOLDER/times.txt's, else 10)")
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.io.images_bag import images_bag_command
    return images_bag_command(args)
