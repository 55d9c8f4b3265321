"""Render-time benchmark of the scene classes: prints milliseconds per stereo frame.

    python -m asmonc_vision.sim.benchmark [--classes C ...] [--rigs backpack chest narrow]
        [--frames N] [--seed S] [--realism on|off|both]

Each (class, rig, realism) renders ``--frames`` frames spread over a 20 s walk with
ground truth (``simulate_frame``, the renderer's default two threads), after one warm-up
frame, and prints the median and the slowest time per frame and the minutes needed for
20 minutes of walks at 10 Hz. Numbers depend on the machine and its load.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from asmonc_vision.sim.render import StereoRenderer
from asmonc_vision.sim.scenarios import simulate_frame
from asmonc_vision.sim.scenes import RIGS, SCENE_CLASSES, make_scene


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    p = argparse.ArgumentParser(prog='python -m asmonc_vision.sim.benchmark',
                                description=__doc__.split('\n')[0])
    p.add_argument('--classes', nargs='+', default=list(SCENE_CLASSES),
                   choices=SCENE_CLASSES)
    p.add_argument('--rigs', nargs='+', default=list(RIGS), choices=RIGS)
    p.add_argument('--frames', type=int, default=4)
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--realism', choices=('on', 'off', 'both'), default='both')
    args = p.parse_args(argv)
    modes = {'on': (True,), 'off': (False,), 'both': (False, True)}[args.realism]
    print(f"{'class':20s} {'rig':8s} {'realism':7s} {'size':8s} {'median ms':>9s} "
          f"{'max ms':>7s} {'min/20 min':>10s}")
    for rig in args.rigs:
        for on in modes:
            per_rig = []
            for name in args.classes:
                sc = make_scene(name, args.seed, duration=20.0, rig=rig, realism=on)
                r = StereoRenderer(sc.rig)
                ks = np.linspace(10, sc.n_frames - 1, args.frames + 1).astype(int)
                simulate_frame(sc, int(ks[0]), r)
                times = []
                for k in ks[1:]:
                    t0 = time.perf_counter()
                    simulate_frame(sc, int(k), r)
                    times.append(time.perf_counter() - t0)
                med = float(np.median(times))
                per_rig.append(med)
                print(f'{name:20s} {rig:8s} {"on" if on else "off":7s} '
                      f'{sc.rig.width}x{sc.rig.height:<4d} {med * 1e3:9.0f} '
                      f'{max(times) * 1e3:7.0f} {med * 12000 / 60:10.0f}', flush=True)
            avg = float(np.mean(per_rig))
            print(f'{"mean":20s} {rig:8s} {"on" if on else "off":7s} {"":8s} '
                  f'{avg * 1e3:9.0f} {"":7s} {avg * 12000 / 60:10.0f}', flush=True)
    return 0


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
