"""Fill numba's disk cache at install time (`make venv` runs ``python -m
asmonc_vision.eval.warm_jit``): the core's kernels are compiled for the argument types
the running system gives them, by running the detector with the evidence map, the
egomotion estimator and the walk model in-process over a bundled walking bag.

Without it, every process's first start compiles the kernels it uses (tens of seconds a
node on a 2-core machine, several nodes at once under `asmonc run`), and writes them to
the same cache. The results do not depend on it: a kernel missing from the cache is
compiled when first called. Prints the seconds it took and how many cache entries exist.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

#: the bundled bag run through the core: walking, with obstacles, ground truth and an
#: inclinometer stream
BAG = Path(__file__).resolve().parents[2] / 'bags' / 'walk_obstacles'


def warm(bag: Path = BAG) -> int:
    """Run the core over ``bag``; returns the number of numba cache index files under the
    package afterwards (0: numba is not in use)."""
    from asmonc_vision.cli.campaign import MAP_MOTION_LAG
    from asmonc_vision.eval.bench import run_method
    from asmonc_vision.eval.gait_bags import evaluate_bag, load_bag
    from asmonc_vision.io.frames import load_frames

    frames = load_frames(bag)
    run_method(frames, 'gpod', map_enabled=True, egomotion=True, motion_lag=MAP_MOTION_LAG)
    evaluate_bag(load_bag(bag))
    package = Path(__file__).resolve().parents[1]
    return sum(1 for _ in package.rglob('*.nbi'))


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    bag = Path(args[0]) if args else BAG
    t = time.monotonic()
    n = warm(bag)
    print(f'numba cache: {n} kernel index files after {time.monotonic() - t:.0f} s '
          f'over {bag.name}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
