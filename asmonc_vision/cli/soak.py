"""`asmonc soak BAG`: loop a bag through the whole node graph for a long time and print,
per node process, how its memory (RSS) and open file descriptors grew after a warm-up,
with the stereo pairs played and the results (/obstacles) received.

Exit status: 0 no process died; 1 a process died; 2 the bag or the arguments are
unusable, or the nodes did not start.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument('bag', type=Path, help='rosbag2 bag directory or .mcap file')
    p.add_argument('--minutes', type=float, default=10.0,
                   help='how long the bag is looped (default 10)')
    p.add_argument('--rate', type=float, default=1.0, help='replay speed factor (default 1)')
    p.add_argument('--warmup', type=float, default=60.0,
                   help='seconds of playing before growth is counted (default 60)')
    p.add_argument('--period', type=float, default=10.0,
                   help='seconds between samples of each process (default 10)')
    p.add_argument('--json', type=Path, default=None, help='also write the result here')
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.io import bagio
    from asmonc_vision.soak import format_table, soak

    def err(s):
        print(f'asmonc soak: {s}', file=sys.stderr)
    if not (0.01 <= args.rate <= 100) or args.minutes <= 0 or args.period <= 0 \
            or args.warmup < 0:
        err('--rate in [0.01, 100], --minutes and --period > 0, --warmup >= 0')
        return 2
    if args.warmup + 2 * args.period > args.minutes * 60:
        err('--minutes must leave at least two samples after --warmup')
        return 2
    try:
        result = soak(args.bag, args.minutes, args.rate, args.warmup, args.period,
                      echo=lambda s: print(s, flush=True))
    except (bagio.BagError, RuntimeError) as exc:
        err(str(exc))
        return 2
    for line in format_table(result['growth']):
        print(line)
    c = result['counts']
    print(f"stereo pairs in {c['pairs_in']}, results out {c['results_out']}, "
          f"alarms {c['alarms']}, walk states {c['gait_states']}")
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1) + '\n')
    if result['died']:
        print(f"died: {', '.join(result['died'])}")
        return 1
    return 0
