"""Visual egomotion: the paper's experiment, and the estimator on bags with ground truth.

    asmonc motion tables [--trials 500] [--noise 0.1 0.5 1 2] [--outliers 0.3]
                         [--points 100] [--methods ...] [--no-minimal] [--json F]
    asmonc motion eval [BAG ...] [--method M] [--params-file YAML] [--frames N] [--json F]
    asmonc motion corners [--trials 300]

`tables` reproduces Molton et al. (1998) Section 4.2: points seen by the paper's rig
(f = 300 px, B = 0.35 m, 320x240) move rigidly (rotation up to 20 degrees, translation
0.05-0.5 m), every image coordinate gets uniform noise of +-a px, 500 trials per level;
the mean error in x, y, z (mm, previous left optical frame) and roll, pitch, yaw (deg,
about the optical z, x, y axes) for every method, beside the paper's Tables 2 and 3;
then again with 30% wrong matches; then the paper's two methods on minimal point sets
(the regime their tables are in). `ms` is the CPU time per solve on one core.

`eval` runs the egomotion estimator (the node's core, default settings or a
`config/egomotion.yaml`-style --params-file) over each bag's stereo pairs in order and
compares every frame-to-frame motion with /ground_truth/camera_pose: per-frame pitch,
roll and yaw errors (deg) and translation error (mm, vector norm), median and 90th
percentile; the frames without a motion by status; the drift of the chained motions
(end-point error over the path length); and the CPU time per frame on one core
(median, p90; OpenCV and BLAS pinned to one thread). Default bags: walk_obstacles,
walk_stop_turn, slope, clear_walk.

`corners` measures the sub-pixel localisation error of the corner detectors on
synthetic corners (docs/motion.md).

Exit status: 0 done; 2 a bag is missing or unreadable, or the arguments are wrong.
"""
from __future__ import annotations

from pathlib import Path

from asmonc_vision.eval.motion_bags import DEFAULT_BAGS


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest='motion_command', required=True)
    t = sub.add_parser('tables', help="the paper's synthetic experiment (Tables 2 and 3)",
                       description=__doc__)
    t.add_argument('--trials', type=int, default=500, help='trials per noise level (500)')
    t.add_argument('--noise', type=float, nargs='+', default=[0.1, 0.5, 1.0, 2.0],
                   help='maximum pixel noise levels a (uniform in [-a, a])')
    t.add_argument('--outliers', type=float, default=0.3,
                   help='share of wrong matches of the second run (0: skip it)')
    t.add_argument('--points', type=int, default=100, help='points per trial (100)')
    t.add_argument('--methods', nargs='+', default=None,
                   help='methods (default: all of asmonc_vision.core.motion.METHODS)')
    t.add_argument('--no-minimal', action='store_true',
                   help="skip the paper's methods on minimal point sets")
    t.add_argument('--seed', type=int, default=0)
    t.add_argument('--json', type=Path, default=None, help='also write the numbers as JSON')
    e = sub.add_parser('eval', help='frame-to-frame egomotion against ground truth on bags',
                       description=__doc__)
    e.add_argument('bags', nargs='*', type=Path,
                   help='bags (default: the bundled ' + ', '.join(DEFAULT_BAGS) + ')')
    e.add_argument('--method', default=None, help='motion method (default: the config\'s)')
    e.add_argument('--params-file', type=Path, default=None,
                   help='egomotion_node ros__parameters YAML (its motion.* settings are used)')
    e.add_argument('--frames', type=int, default=0, help='at most this many pairs per bag')
    e.add_argument('--json', type=Path, default=None, help='also write the numbers as JSON')
    c = sub.add_parser('corners', help='corner localisation error on synthetic corners',
                       description=__doc__)
    c.add_argument('--trials', type=int, default=300, help='corners per kind (300)')
    c.add_argument('--seed', type=int, default=0)
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.eval.motion_bags import motion_command
    return motion_command(args)
