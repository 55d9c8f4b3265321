"""Evaluate the walk model (Molton et al. 1998, Section 5) on simulated and real walking.

    asmonc gait sim    [--scenarios walk stop turn uphill bend] [--seeds N] [--json F]
    asmonc gait fusion [--seeds N] [--egomotion-sigma DEG] [--json F]
    asmonc gait real   [--data DIR] [--json F]
    asmonc gait bags   [BAG ...] [--cache DIR] [--json F]
    asmonc gait figs   [--out DIR] [--data DIR]

sim: the simulator's walker (``sim.motion.Trajectory``) and 16 Hz inclinometer
(``sim.inclinometer``, 0.3 deg noise, 0.1 deg steps, 80 ms lag), in memory, several
seeds per scenario: *walk* (stand, walk, stand), *stop* (two walks with stops), *turn*
(walking through a 90 deg and a 60 deg turn with speed changes), *uphill* (walking onto
a 6 deg slope: the trunk leans forward), *bend* (standing, bending 25 deg forward and
back: a non-walking movement that must not start the walk model). Reported: RMS error
of the 0.5 s-ahead prediction per axis against the true attitude (all samples after the
first second, and steady walking), with "hold the last measurement" on the same samples;
gait-phase RMS error in % of the cycle (pitch: the step; roll, yaw: the stride); delay
of the detected walk starts and stops after the true ones (walking = speed >= 0.6 m/s,
half the nominal speed); the time per filter step.

fusion: the same walks with visual motion (/egomotion: the left camera's rotation from
frame to frame at 10 Hz with Gaussian noise) fused into the filter; the 0.5 s-ahead
prediction of the absolute attitude and of the rig's rotation over the horizon (what
DGPR needs), for the inclinometer alone, visual motion alone and both, and with either
source dropped for 4 s.

real: the Mobilise-D lower-back IMU recordings (../shared/data/gait_lowback): attitude
at 100 Hz by a complementary filter (3 s), decimated to 16 Hz as a compass would give it,
the walk model run on it; the 0.5 s-ahead prediction against "hold the last value" on
the straight walks (Test5) within the reference walking bouts, the daily-living walk
(Test11) likewise, with two references (an oracle-aided benchmark, not a bound: a
Fourier-combiner Kalman filter given each bout's own stride frequency and start; and the
upper bound of the model family, a non-causal fit of each bout); walk starts/stops against
the reference bouts (INDIP MicroWB: precision and recall within 0.5 s and 1 s); the tracked step
frequency against the reference cadence.

figs: the paper's Figs. 13-15 redrawn from these runs (docs/gait_fig13.png, ...).
"""
from __future__ import annotations

from pathlib import Path

from asmonc_vision.eval.gait_bags import DEFAULT_CACHE
from asmonc_vision.eval.gait_walks import DEFAULT_DATA, REPO, SIM_SCENARIOS


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest='gait_command', required=True)
    s = sub.add_parser('sim', help='simulated walks: prediction, phase, start/stop')
    s.add_argument('--scenarios', nargs='+', default=list(SIM_SCENARIOS),
                   choices=SIM_SCENARIOS)
    s.add_argument('--seeds', type=int, default=5, help='seeds 0..N-1 per scenario')
    s.add_argument('--json', type=Path, default=None)
    f = sub.add_parser('fusion', help='inclinometer + visual motion, dropouts')
    f.add_argument('--seeds', type=int, default=5)
    f.add_argument('--egomotion-sigma', type=float, default=0.5,
                   help='visual-motion noise per frame and axis, degrees (default 0.5)')
    f.add_argument('--json', type=Path, default=None)
    r = sub.add_parser('real', help='Mobilise-D lower-back IMU walks')
    r.add_argument('--data', type=Path, default=DEFAULT_DATA)
    r.add_argument('--json', type=Path, default=None)
    b = sub.add_parser('bags', help='walking bags: inclinometer + the egomotion '
                       "estimator's visual motion, fused, against the ground truth")
    b.add_argument('bags', nargs='*', type=Path,
                   help='walking bags with /inclinometer/imu, stereo pairs and '
                        '/ground_truth/camera_pose (default: render clear_walk and '
                        'walk_stop_turn, 30 s, seeds 1-3)')
    b.add_argument('--cache', type=Path, default=DEFAULT_CACHE,
                   help=f'where the default bags are rendered (default {DEFAULT_CACHE})')
    b.add_argument('--json', type=Path, default=None, help='also write the numbers as JSON')
    g = sub.add_parser('figs', help="the paper's Figs. 13-15 as PNGs")
    g.add_argument('--out', type=Path, default=REPO / 'docs')
    g.add_argument('--data', type=Path, default=DEFAULT_DATA)
    p.set_defaults(func=run)


def run(args) -> int:
    if args.gait_command == 'bags':
        from asmonc_vision.eval.gait_bags import bags_command
        return bags_command(args.bags, args.cache, args.json)
    if args.gait_command == 'figs':
        from asmonc_vision.eval.gait_figures import figures_command
        return figures_command(args.out, args.data)
    if args.gait_command == 'real':
        from asmonc_vision.eval.gait_real import real_command
        return real_command(args.data, args.json)
    from asmonc_vision.eval.gait_walks import gait_command
    return gait_command(args)
