"""Time our detector (GPOD) and the SGBM baseline per frame on one core, and their recall.

    asmonc bench [BAG ...] [--frames N] [--warmup K] [--repeat R] [--large-frames M]
                 [--no-large] [--json F]

Both methods run on the same stereo pairs in order (so GPOD's ground plane initialises
and tracks as it would live), with OpenCV pinned to one thread (cv2.setNumThreads(1));
the first `--warmup` pairs are processed but not timed. GPOD is timed as the node graph
runs it: the detector, then the evidence map given the motion the graph gives it (the
egomotion estimator's motions of the pairs before, as late as in the graph, through
`core.map_motion.MotionPredictor`: `asmonc campaign`'s gpod_map_lag, the same outputs).
The egomotion runs in a node of its own, so the estimator is run once over the pairs
before the timed passes and its time is in none of them. Reported per method: the median
and 90th percentile of the per-frame time of `process()` in milliseconds, the rate, the
median per stage, the median CPU time of `process()` (the thread's own time: unlike the
wall time, it does not count waiting for a core that other processes share -- the load
average is printed first), and the recall per frame of true obstacles >= 10 cm high within 5 m
(a report within 0.3 m on the ground, as `asmonc run`) with the false obstacles per
frame, over all the pairs processed. Then the ratio of the median times.

Each method makes `--repeat` passes (default 3) over the pairs, a fresh detector each,
interleaved with the other method's; each frame's time is its fastest pass. The other
load of a shared machine only ever adds time, so the fastest pass is the closest to the
code's own time, as `timeit` advises: it removes a frame's interruptions, not a slow spell
of the machine longer than the passes (on the shared 2-core development machines the
medians move by 10-20 % between such spells, the compiled stages alike -- compare the
`matching` stage between runs). `--repeat 1` gives a single pass.

Two image sizes:

* 320x240, the paper's rig: the bundled bags (default static_obstacles and
  walk_obstacles) or the BAGs given.
* 640x480 with f = 600 px (the same field of view, baseline 0.35 m): the
  static_obstacles scene (seed 0) rendered by the simulator at run time, in memory --
  `max(--warmup, 3)` obstacle-free frames first (GPOD calibrates its ground plane on
  them; untimed), then `--large-frames` frames with every obstacle in place. Rendering
  takes about a second per frame; --no-large skips this part.

The loaders (`io.frames`) and the runner (`eval.bench.run_method`) are shared with
`asmonc eval`.
"""
from __future__ import annotations

from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument('bags', nargs='*', type=Path,
                   help='320x240 bags to time on (default: the bundled static_obstacles and '
                        'walk_obstacles)')
    p.add_argument('--frames', type=int, default=0,
                   help='at most this many pairs per bag, warm-up included (0: all); also '
                        'caps the rendered 640x480 sequence')
    p.add_argument('--warmup', type=int, default=5, help='untimed pairs first (default 5)')
    p.add_argument('--large-frames', type=int, default=15,
                   help='timed 640x480 frames to render (default 15)')
    p.add_argument('--no-large', action='store_true', help='skip the 640x480 part')
    p.add_argument('--repeat', type=int, default=3,
                   help='passes over the frames per method, interleaved; each frame\'s time '
                        'is its fastest pass (default 3; 1: a single pass)')
    p.add_argument('--json', type=Path, default=None, help='also write the numbers as JSON')
    p.set_defaults(func=run)



def run(args) -> int:
    from asmonc_vision.eval.bench import bench
    return bench(args)
