"""A bag of the topic contract written from a folder of stereo pairs (`asmonc
images-bag`): `write_images_bag`, `folder_rate`. The command's help (`cli.images_bag`)
says which folders and calibrations are read.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmonc_vision.io import bagio
from asmonc_vision.core.capture import (CalibrationError, FolderSource, FrameSizeError,
                                        SourceError, StereoRectifier, load_calibration)
from asmonc_vision.sim.bagwriter import EPOCH_NS, dir_size, writer_qos
from asmonc_vision.sim.rig import LEFT_FRAME, RIGHT_FRAME

#: per-pair topics, in the order written (keys of bagio.TOPICS)
PAIR_TOPICS = ('left_info', 'right_info', 'left_image', 'right_image')


@dataclass(frozen=True)
class ImagesBag:
    """What ``write_images_bag`` wrote: the bag directory, stereo pairs written, distinct
    pairs read, rate (Hz), image size (w, h), focal length (px), baseline (m)."""

    path: Path
    frames: int
    pairs: int
    fps: float
    size: tuple[int, int]
    f: float
    baseline: float
    size_bytes: int


def folder_rate(folder: Path, default: float = 10.0) -> float:
    """Frame rate (Hz) from a KITTI ``times.txt`` (median interval), else ``default``."""
    path = folder / 'times.txt'
    if not path.is_file():
        return default
    try:
        t = np.array([float(x) for x in path.read_text().split()])
    except ValueError:
        return default
    dt = np.diff(t)
    dt = dt[dt > 0]
    return float(1.0 / np.median(dt)) if dt.size else default


def _rectifier(folder: Path, source: FolderSource, calibration: str,
               right_calibration: str) -> StereoRectifier:
    kitti = source.kitti_cameras()
    if calibration:
        return load_calibration(calibration, right_calibration, 0.0, kitti)
    calib = folder / 'calib.txt'
    if not calib.is_file():
        raise CalibrationError(f'no --calibration given and no {calib}: the camera_info of '
                               'the pair cannot be written')
    return load_calibration(calib, '', 0.0, kitti)


def write_images_bag(folder: str | Path, out: str | Path, calibration: str = '',
                     right_calibration: str = '', start: int = 0, count: int = 0,
                     repeat: int = 1, fps: float = 0.0) -> ImagesBag:
    """Write the image pairs of ``folder`` as a contract bag ``out`` (see the module doc).

    Args:
        folder: the image folder (capture node layout).
        out: the bag directory to create (must not exist).
        calibration, right_calibration: calibration files ('' = ``folder/calib.txt``).
        start, count: the pairs used (sorted by name; count 0 = to the end).
        repeat: each pair written this many times in a row (>= 1).
        fps: stamps 1/fps s apart (0 = ``times.txt``'s rate, else 10 Hz).
    Raises:
        SourceError, CalibrationError, FrameSizeError: unusable folder, images or
            calibration.
        ValueError: bad start/count/repeat/fps.
        rosbags.rosbag2.WriterError: ``out`` exists.
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    folder, out = Path(folder), Path(out)
    if repeat < 1 or start < 0 or count < 0 or fps < 0:
        raise ValueError('--repeat must be >= 1, --start, --count and --fps >= 0')
    source = FolderSource(str(folder))
    source.open()
    pairs = source.pairs[start:start + count if count else None]
    if not pairs:
        raise SourceError(f'{folder}: no pairs from index {start} ({len(source.pairs)} in all)')
    rect = _rectifier(folder, source, calibration, right_calibration)
    rate = fps or folder_rate(folder)
    ts = bagio.typestore()
    t = ts.types
    counts = {bagio.TOPICS[k][0]: 0 for k in PAIR_TOPICS}
    size = None
    writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)

    def header(ns: int, frame: str):
        stamp = t['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9)
        return t['std_msgs/msg/Header'](stamp=stamp, frame_id=frame)

    def info(ns: int, p: np.ndarray, frame: str, w: int, h: int):
        roi = t['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0,
                                                    width=0, do_rectify=False)
        return t['sensor_msgs/msg/CameraInfo'](
            header=header(ns, frame), height=h, width=w, distortion_model='plumb_bob',
            d=np.zeros(5), k=p[:, :3].ravel().copy(), r=np.eye(3).ravel(),
            p=p.ravel().copy(), binning_x=0, binning_y=0, roi=roi)

    def image(ns: int, img: np.ndarray, frame: str):
        return t['sensor_msgs/msg/Image'](
            header=header(ns, frame), height=img.shape[0], width=img.shape[1],
            encoding='mono8', is_bigendian=0, step=img.shape[1],
            data=np.ascontiguousarray(img, np.uint8).ravel())

    import cv2

    with writer:
        meta = {'generator': 'asmonc images-bag', 'folder': str(folder.resolve()),
                'start': start, 'pairs': len(pairs), 'repeat': repeat, 'fps': rate,
                'f': rect.f, 'baseline': rect.baseline, 'epoch_ns': EPOCH_NS}
        writer.set_custom_data('asmonc_vision.images_bag', json.dumps(meta, sort_keys=True))
        conns = {k: writer.add_connection(bagio.TOPICS[k][0], bagio.TOPICS[k][1],
                                          typestore=ts, offered_qos_profiles=writer_qos())
                 for k in PAIR_TOPICS}

        def put(key: str, ns: int, msg) -> None:
            topic, msgtype = bagio.TOPICS[key]
            writer.write(conns[key], ns, ts.serialize_cdr(msg, msgtype))
            counts[topic] += 1

        k = 0
        for lp, rp in pairs:
            left_grey = cv2.imread(str(lp), cv2.IMREAD_GRAYSCALE)
            right_grey = cv2.imread(str(rp), cv2.IMREAD_GRAYSCALE)
            if left_grey is None or right_grey is None:
                raise SourceError(f'cannot read image {lp if left_grey is None else rp}')
            left, right = rect.rectify(left_grey, right_grey)
            h, w = left.shape
            if size is None:
                size = (w, h)
            elif size != (w, h):
                raise SourceError(f'{lp.name}: {w}x{h}, the first pair was {size[0]}x{size[1]}')
            for _ in range(repeat):
                ns = EPOCH_NS + int(round(k * 1e9 / rate))
                put('left_info', ns, info(ns, rect.p_left, LEFT_FRAME, w, h))
                put('right_info', ns, info(ns, rect.p_right, RIGHT_FRAME, w, h))
                put('left_image', ns, image(ns, left, LEFT_FRAME))
                put('right_image', ns, image(ns, right, RIGHT_FRAME))
                k += 1
    return ImagesBag(path=out, frames=k, pairs=len(pairs), fps=rate, size=size, f=rect.f,
                     baseline=rect.baseline, size_bytes=dir_size(out))


def images_bag_command(args) -> int:
    """`asmonc images-bag` with its parsed arguments (see `cli.images_bag`); the exit
    status."""
    from rosbags.rosbag2 import WriterError

    try:
        bag = write_images_bag(args.folder, args.out, args.calibration,
                               args.right_calibration, args.start, args.count, args.repeat,
                               args.fps)
    except (SourceError, CalibrationError, FrameSizeError, ValueError, WriterError) as exc:
        print(f'asmonc images-bag: {exc}', file=sys.stderr)
        return 2
    w, h = bag.size
    print(f'asmonc images-bag: {bag.path} — {bag.frames} stereo pairs ({bag.pairs} distinct, '
          f'each {bag.frames // bag.pairs}x) at {bag.fps:.3g} Hz, {w}x{h} mono8, '
          f'f = {bag.f:.1f} px, B = {bag.baseline:.4f} m, {bag.size_bytes / 1e6:.1f} MB')
    return 0
