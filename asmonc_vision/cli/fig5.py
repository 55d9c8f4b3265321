"""The paper's Fig. 5: obstacle detection probability against obstacle height, per range.

Model (default): prints the detection probability of Molton et al. (1998), Sec. 2.3
(:mod:`asmonc_vision.eval.detection_model`) for obstacle heights 1-20 cm, one column per
range 2-8 m, and the 90% heights; ``--png`` plots Fig. 5. Without ``--pitch-deg`` the
paper's level-camera Eq. 1 is used; with it, the exact geometry of the pitched rig.

    asmonc fig5 [--focal F --baseline B --height H --pitch-deg P --threshold T --sigma S]
                [--min-pixels M] [--png out.png]

Empirical (``--empirical``): the simulator renders, standing still on the given rig
(default the paper's, pitched 20 deg), a clean pavement with one box per range
(2-8 m, alternately left and right, well separated), one scene per box height and seed
(the seed draws the pavement, and each box's size, yaw, lateral offset and shade).
GpodDetector (default GpodConfig; ``--plane-update``, ``--threshold``, ``--param
NAME=VALUE`` change it) calibrates on obstacle-free frames of the same pavement, then
runs on ``--frames`` frames with the boxes (the frames differ only in camera noise). A
box is detected in a frame when the detector reports an obstacle within 0.3 m of the
box's footprint on the ground (positions from range and bearing, as eval.evaluation);
the strict ``eval.evaluation.score_frame`` rule (within 0.3 m of the truth point, the
box's nearest visible part) is reported too. The disparity excess of matched ground
features (truth labels, away from the boxes) gives sigma. Prints the measured rates,
sigma, and the model's rates with the measured sigma and the thresholds the boxes'
edges faced (>= 1 px, >= the detector's min_obstacle_pixels, and averaged over
per-pixel thresholds); ``--out`` plots the rates (Wilson 95% binomial intervals) over
the model's curves. The default run takes ~2 minutes on 2 cores (progress on stderr).

    asmonc fig5 --empirical [--seeds N --frames K --jobs J] [--out fig.png] [--json f.json]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from asmonc_vision.eval.fig5 import EMPIRICAL_HEIGHTS_CM, RANGES_M


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group('rig and model (defaults: Molton et al. 1998)')
    g.add_argument('--focal', type=float, default=300.0, help='focal length f, px (300)')
    g.add_argument('--baseline', type=float, default=0.35, help='baseline I, m (0.35)')
    g.add_argument('--height', type=float, default=1.25, help='camera height H, m (1.25)')
    g.add_argument('--pitch-deg', type=float, default=None,
                   help='camera pitch down, degrees: exact geometry (model default: none, '
                   "the paper's level-camera Eq. 1; --empirical default: 20, the "
                   "simulator's)")
    g.add_argument('--threshold', type=float, default=None,
                   help='excess threshold, px (default 1.7; --empirical: the detector\'s '
                   'threshold_px, set by this option too)')
    g.add_argument('--sigma', type=float, default=None,
                   help='sigma of the excess, px (model default 1.0; --empirical: the '
                   'measured sigma unless given)')
    g.add_argument('--min-pixels', type=int, default=1,
                   help='obstacle pixels an edge string needs (1 = the paper)')
    p.add_argument('--png', '--out', dest='png', type=Path, default=None,
                   help='write the figure to this PNG')
    e = p.add_argument_group('empirical run')
    e.add_argument('--empirical', action='store_true',
                   help='measure detection rates with the simulator and GpodDetector')
    e.add_argument('--seeds', type=int, default=20, help='scenes per box height (20)')
    e.add_argument('--frames', type=int, default=4,
                   help='frames with the boxes per scene, after calibration (4)')
    e.add_argument('--first-seed', type=int, default=0, help='first seed (0)')
    e.add_argument('--heights-cm', type=float, nargs='+', default=list(EMPIRICAL_HEIGHTS_CM),
                   help='box heights, cm')
    e.add_argument('--ranges', type=float, nargs='+', default=list(RANGES_M),
                   help='box ranges, m (one box per range in each scene)')
    e.add_argument('--plane-update', choices=('fixed', 'refit'), default=None,
                   help="detector plane.update (default: GpodConfig's)")
    e.add_argument('--param', action='append', default=[], metavar='NAME=VALUE',
                   help='any other GpodConfig setting as GROUP.NAME=VALUE, e.g. --param '
                   'threshold.mode=fixed '
                   '(repeatable)')
    e.add_argument('--jobs', type=int, default=2, help='worker processes (2)')
    e.add_argument('--json', type=Path, default=None, help='write the results as JSON')
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.eval.fig5 import fig5_command
    return fig5_command(args)
