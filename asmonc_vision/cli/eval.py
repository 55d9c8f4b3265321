"""Score a detector on bags with ground truth, offline, and tell how good it is.

    asmonc eval BAG [BAG ...] [--method gpod|sgbm ...] [--threshold-px T ...]
                [--outputs DIR ...] [--json OUT.json] [--plots DIR] [--frames N]
                [--match-radius 0.3] [--min-height 0.10] [--max-range 5]

By default runs our detector (GPOD, default settings, then the evidence map when it is
enabled: `core.perception.Perception`, as the detector node runs them) in this process,
without ROS, over each bag's stereo pairs in order (with no motion input: its obstacle
tracks and map are carried only while the rig stands still; `--egomotion` runs the
egomotion estimator here and feeds its motion as the node graph does when it waits for
it (``use_egomotion``), `--motion-lag N` with it gives the detector no motion and the
map its motion predicted from those of the pairs N or more before, as the graph that
does not wait (`core.map_motion`); `--map on|off` sets the evidence map; or score a
graph run with `asmonc run BAG --out DIR` and `--outputs DIR`); `--method sgbm` runs the
OpenCV StereoSGBM baseline (core.baseline) instead, and several methods or
`--threshold-px` values give one run each. With `--outputs DIR` (one per BAG) nothing is
run: the /obstacles and /ground_plane recorded by `asmonc run BAG --out DIR` are scored
against BAG's truth, and its recorded /alarms tell whether each true obstacle on the
walking path was warned of in time (`eval.evaluation.path_warnings`, the alarm node's
default criteria; as the summary of `asmonc run`). Both paths are scored by the same
code (eval.evaluation.SequenceEvaluation):

* recall per frame, per |height| x range bin of the true obstacles (0-5, 5-10, 10-20,
  20-50, >= 50 cm x 1-2, 2-3, 3-4, 4-5, 5-8 m) with counts: a true obstacle is found in a
  frame when a report lies within --match-radius of it on the ground (one report finds
  one obstacle; obstacles >= --min-height within --max-range take reports first); and the
  headline recall of those (>= 10 cm, <= 5 m, as `asmonc run`);
* false obstacles (reports that explain no true obstacle) per frame and per minute (the
  camera rate from the stamps);
* range error (median |error|, m and % of the true range) and bearing error (median
  |error|, deg) of the headline matches;
* ground-plane error against /ground_truth/ground_plane: the angle between the normals
  (deg) and the camera-height difference (mm), over the frames with a plane;
* latency of process() per frame (median, p90 ms; OpenCV on one thread; not for --outputs).
* the safety score of docs/evaluation.md (`eval.safety`: obstacles on the path warned in
  time, false alarm events per minute of walking, false reports per frame, recall), of
  the alarms the alarm node's logic (default settings) gives over the detector's outputs
  replayed in bag time (`eval.alarm_replay`), or of the recorded /alarms and /obstacles;
  needs /ground_truth/camera_pose (footprints from the simulator's metadata, else from the
  listed obstacles, `eval.truth`).

Prints a table per run (and pooled over the bags when there are several), writes all of
it as JSON with --json and PNG plots (recall heat map, range error vs range) with
--plots. Exit status: 0 done; 2 a bag is unreadable or has no ground truth, or the
arguments are wrong.
"""
from __future__ import annotations

from pathlib import Path

from asmonc_vision.eval.bench import METHODS


def add_arguments(p) -> None:
    p.add_argument('bags', nargs='+', type=Path,
                   help='rosbag2 bags with /ground_truth/* topics (e.g. bags/static_obstacles)')
    p.add_argument('--method', nargs='+', choices=METHODS, default=['gpod'],
                   help="'gpod' (ours, default) and/or 'sgbm' (the OpenCV StereoSGBM baseline)")
    p.add_argument('--threshold-px', nargs='+', type=float, default=None,
                   help='obstacle threshold(s), pixels of disparity excess (default: each '
                        "method's own, 1.7); several values give one run each")
    p.add_argument('--outputs', type=Path, action='append', default=None,
                   help='score the /obstacles and /ground_plane of this bag recorded by '
                        '`asmonc run BAG --out DIR` instead of running a detector; give one '
                        'per BAG, in the same order')
    p.add_argument('--motion', action='store_true',
                   help='also score visual egomotion against /ground_truth/camera_pose: run '
                        'the estimator offline (or, with --outputs, the recorded /egomotion)')
    p.add_argument('--map', choices=('default', 'on', 'off'), default='default',
                   help="GPOD's evidence map (core.evidence_map, `map.enabled`): its default, "
                        'on or off')
    p.add_argument('--egomotion', action='store_true',
                   help="feed GPOD each pair's motion from the egomotion estimator run here "
                        '(as the node graph does; its time is not counted), instead of none')
    p.add_argument('--motion-lag', type=int, default=0,
                   help='with --egomotion and the map: 0 gives each pair its own motion (the '
                        'graph waiting for it); N >= 1 gives the map the motion predicted from '
                        'those of the pairs N or more before and the detector none (the graph '
                        'not waiting); default 0')
    p.add_argument('--frames', type=int, default=0, help='only the first N pairs per bag (0: all)')
    p.add_argument('--match-radius', type=float, default=0.3,
                   help='a report within this distance (m) on the ground finds a true obstacle')
    p.add_argument('--min-height', type=float, default=0.10,
                   help='true obstacles at least this high (m) count in the headline recall')
    p.add_argument('--max-range', type=float, default=5.0,
                   help='true obstacles within this range (m) count in the headline recall')
    p.add_argument('--json', type=Path, default=None, help='write every number as JSON here')
    p.add_argument('--plots', type=Path, default=None,
                   help='write PNG plots here (eval_recall_*.png, eval_range_error_*.png)')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.set_defaults(func=run)


# --- progress --------------------------------------------------------------------------


def run(args) -> int:
    from asmonc_vision.eval.offline import eval_command
    return eval_command(args)
