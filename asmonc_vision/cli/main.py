"""`asmonc`: the command-line front of asmonc_vision.

    asmonc run [BAG] [--out DIR] [--rate R]   replay a bag through the node graph
    asmonc bench [BAG ...]                     time the detector and map per frame, one core
    asmonc eval BAG [BAG ...]                  score a detector against ground truth
    asmonc fig5 [--empirical]                  the paper's Fig. 5, model and measured
    asmonc motion {tables,eval,corners}        visual egomotion: Tables 2-3, bag errors
    asmonc gait {sim,fusion,real,figs}         the walk model: errors, real walking, Figs. 13-15
    asmonc smallbox [--heights ..] [--ranges ..]  small boxes standing still: GPOD vs SGBM
    asmonc campaign [--minutes M] [--workers N]   random walks scored for safety: ours vs SGBM
    asmonc images-bag FOLDER OUT [--repeat N]   a contract bag from a folder of stereo pairs
    asmonc fuzz {nmea,bag} --seconds N         fuzz the NMEA parser or the bag reader
    asmonc params [--markdown]                 every node's parameters (docs/parameters.md)
    asmonc soak BAG [--minutes M]              loop a bag through the graph; memory, fds
"""
from __future__ import annotations

import argparse
import contextlib
import faulthandler
import signal
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='asmonc', description='asmonc_vision: stereo obstacle detection for walking.')
    sub = parser.add_subparsers(dest='command', required=True)
    from asmonc_vision.cli import bench, run
    from asmonc_vision.cli import eval as eval_
    run.add_arguments(sub.add_parser(
        'run', help='replay a bag through the detector and alarm nodes',
        description=run.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    bench.add_arguments(sub.add_parser(
        'bench', help='time the detector and its map per frame on one core',
        description=bench.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    eval_.add_arguments(sub.add_parser(
        'eval', help="score a detector against a bag's ground truth, offline",
        description=eval_.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import fig5
    fig5.add_arguments(sub.add_parser('fig5', help="the paper's Fig. 5, model and measured",
        description=fig5.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import motion
    motion.add_arguments(sub.add_parser(
        'motion', help="visual egomotion: the paper's Tables 2 and 3, errors and time on bags",
        description=motion.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import gait
    gait.add_arguments(sub.add_parser(
        'gait', help='evaluate the walk model: sim, fusion, real walking, Figs. 13-15',
        description=gait.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import smallbox
    smallbox.add_arguments(sub.add_parser(
        'smallbox', help='small boxes seen standing still: GPOD against the SGBM baseline',
        description=smallbox.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import campaign
    campaign.add_arguments(sub.add_parser(
        'campaign', help='random simulated walks scored for safety: ours against the SGBM peer',
        description=campaign.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import images_bag
    images_bag.add_arguments(sub.add_parser(
        'images-bag', help='a contract bag from a folder of stereo image pairs (e.g. KITTI)',
        description=images_bag.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import fuzz
    fuzz.add_arguments(sub.add_parser(
        'fuzz', help='fuzz the NMEA parser or the bag reader for a given time',
        description=fuzz.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision import paramdoc
    paramdoc.add_arguments(sub.add_parser(
        'params', help="every node's parameters: default, range, description",
        description=paramdoc.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    from asmonc_vision.cli import soak
    soak.add_arguments(sub.add_parser(
        'soak', help='loop a bag through the graph: per-process memory and fd growth',
        description=soak.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter))
    return parser


def main(argv: list[str] | None = None) -> int:
    # `kill -USR1 PID` prints every thread's stack to stderr: where a run that seems stuck is;
    # a crash (SIGSEGV, SIGABRT ...) prints them too, where it happened (not where stderr is
    # no file, as under a test's capture)
    with contextlib.suppress(OSError, ValueError, AttributeError):
        faulthandler.enable(all_threads=True)
        if hasattr(signal, 'SIGUSR1'):
            faulthandler.register(signal.SIGUSR1, all_threads=True)
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == '__main__':
    sys.exit(main())
