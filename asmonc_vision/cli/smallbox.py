"""Small obstacles seen by a wearer standing still: GPOD against the SGBM baseline.

    python -m asmonc_vision.cli.smallbox [--heights 0.04 0.08] [--ranges 2.5 5] [--grid]
        [--seeds 10] [--frames 20] [--clear-frames 5] [--rig backpack] [--method gpod sgbm]
        [--workers 1] [--cache DIR] [--json out.json]

The paper's accuracy targets (Molton et al. 1998): 90 % detection of 4 cm obstacles at
2.5 m and of 8 cm obstacles at 5 m. For every cell (heights and ranges paired in order
when they are as many, e.g. the default 4 cm at 2.5 m and 8 cm at 5 m; every
height x range with --grid or when they are not) and every seed
0 .. seeds-1 the simulator (`asmonc_vision.sim`; `--rig`: the paper's rig, f = 300 px,
B = 0.35 m, 320x240, cameras 1.25 m up pitched 20 degrees down, or a level chest rig,
f = 560 px, B = 0.12 m, 640x480, 1.3 m up, 5 degrees down) renders a wearer
standing on a random pavement (`small_box_scene`): `--clear-frames` obstacle-free
frames (GPOD calibrates its ground plane on them), then `--frames` frames with one box
of that height whose nearest footprint point is at that range (random bearing, size,
yaw and a contrasting albedo). Each method runs, fresh per scene, on the SAME rendered
frames in order.

Scored per frame in which the box is in view (truth: `sim/truth.py`, the top above the
foot of the box's nearest visible point):

* found: a report within `--match-radius` (0.3 m) on the ground of the true foot
  (range and bearing, as `asmonc run`);
* found on box: a report whose image region's centre lies on the box's (within 4 px),
  wherever it is placed on the ground;
* false: reports that are neither, plus every report in the obstacle-free frames,
  divided by all frames processed;
* the range error |r - r_true| / r_true and the bearing error |b - b_true| (degrees) of
  the nearest found report: medians (and 90th percentiles in the JSON).

GPOD is scored on what it reports (its obstacle tracks: detections, and obstacles
carried through a frame or two where their evidence dips, `core.obstacle_tracks`) and,
as the row `gpod/frame`, on each frame's detections alone.

Rendering (~0.1 s per frame) dominates; `--cache DIR` keeps the rendered frames (with
their truth) for repeated runs, `--workers 2` renders and runs two scenes at once.
"""
from __future__ import annotations

import sys
from pathlib import Path

from asmonc_vision.eval.smallbox import METHODS, RIGS


def add_arguments(p) -> None:
    p.add_argument('--heights', type=float, nargs='+', default=[0.04, 0.08],
                   help='box heights, metres (default 0.04 0.08)')
    p.add_argument('--ranges', type=float, nargs='+', default=[2.5, 5.0],
                   help='ranges of the box\'s nearest point, metres (default 2.5 5)')
    p.add_argument('--grid', action='store_true',
                   help='every height x range cell; by default heights and ranges of equal '
                        'number are paired (4 cm at 2.5 m, 8 cm at 5 m: the paper\'s two '
                        'targets), else the grid')
    p.add_argument('--seeds', type=int, default=10, help='scenes per cell, seeds 0..N-1 '
                   '(default 10)')
    p.add_argument('--first-seed', type=int, default=0, help='first seed (default 0)')
    p.add_argument('--frames', type=int, default=20, help='frames with the box per scene '
                   '(default 20)')
    p.add_argument('--clear-frames', type=int, default=5,
                   help='obstacle-free frames first, for the calibration (default 5)')
    p.add_argument('--rig', choices=RIGS, default='backpack',
                   help="the rig: the paper's ('backpack', default: 320x240, f = 300 px, "
                        "B = 0.35 m, 1.25 m up, 20 degrees down) or a level chest rig "
                        "('chest': 640x480, f = 560 px, B = 0.12 m, 1.3 m up, 5 degrees down)")
    p.add_argument('--method', nargs='+', choices=METHODS, default=list(METHODS),
                   help='methods to run on the same frames (default gpod sgbm)')
    p.add_argument('--match-radius', type=float, default=0.3,
                   help='a report within this distance (m) on the ground of the true foot '
                        'finds the box (default 0.3)')
    p.add_argument('--workers', type=int, default=1, choices=(1, 2),
                   help='scenes run in parallel (default 1)')
    p.add_argument('--cache', type=Path, default=None,
                   help='keep the rendered frames in this directory for later runs')
    p.add_argument('--map', choices=('default', 'on', 'off'), default='default',
                   help="GPOD's evidence map (core.evidence_map): its default, on or off "
                        '(standing still, no motion is needed)')
    p.add_argument('--json', type=Path, default=None, help='also write the numbers as JSON')
    p.add_argument('--quiet', action='store_true', help='no progress')
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.eval.smallbox import smallbox_command
    return smallbox_command(args)


def main(argv: list[str] | None = None) -> int:
    """``python -m asmonc_vision.cli.smallbox ...``: the same as ``asmonc smallbox ...``."""
    import argparse

    parser = argparse.ArgumentParser(prog='asmonc smallbox', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == '__main__':
    sys.exit(main())
