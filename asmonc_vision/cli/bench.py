"""Time the detector per frame on a bag's stereo pairs, on one core, and print the numbers.

The detector runs on the pairs in bag order (so the ground plane initialises and tracks
as it would live), after `--warmup` untimed pairs; OpenCV is pinned to one thread.
Reports the median and 90th percentile per stage in milliseconds, and the rate.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from asmonc_vision import bagio


def add_arguments(p) -> None:
    p.add_argument('bags', nargs='*', type=Path,
                   help='bags to time on (default: the bundled static and walking bags)')
    p.add_argument('--frames', type=int, default=0, help='at most this many pairs per bag (0: all)')
    p.add_argument('--warmup', type=int, default=5, help='untimed pairs first (default 5)')
    p.add_argument('--json', type=Path, default=None, help='also write the numbers as JSON')
    p.set_defaults(func=run)


def load_pairs(bag: Path, limit: int = 0):
    """[(left (H,W) uint8, right, StereoCamera)] from a bag, in stamp order."""
    from asmonc_vision.core.camera import StereoCamera

    topics = [bagio.TOPICS[k][0] for k in ('left_image', 'right_image', 'left_info', 'right_info')]
    by_stamp: dict[int, dict] = {}
    for topic, _, m in bagio.read_messages(bag, topics):
        slot = by_stamp.setdefault(bagio.header_stamp_ns(m), {})
        if topic.endswith('image_rect'):
            slot[topic] = bagio.image_to_gray(m.encoding, m.height, m.width, m.step, m.data)
        else:
            slot[topic] = m
    pairs = []
    for stamp in sorted(by_stamp):
        s = by_stamp[stamp]
        if len(s) < 4:
            continue
        li, ri = s[topics[2]], s[topics[3]]
        cam = StereoCamera.from_projection(li.p, ri.p, li.width, li.height)
        pairs.append((s[topics[0]], s[topics[1]], cam))
        if limit and len(pairs) >= limit:
            break
    return pairs


def time_detector(pairs, warmup: int = 5) -> dict:
    """Run GpodDetector over the pairs; per-stage median/p90 ms of the timed ones."""
    import cv2

    from asmonc_vision.core.gpod import GpodConfig, GpodDetector

    cv2.setNumThreads(1)
    det = GpodDetector(GpodConfig())
    stages: dict[str, list[float]] = {}
    wall = []
    for i, (left, right, cam) in enumerate(pairs):
        t = time.perf_counter()
        res = det.process(left, right, cam)
        dt = (time.perf_counter() - t) * 1e3
        if i < warmup:
            continue
        wall.append(dt)
        for k, v in res.timings.items():
            stages.setdefault(k, []).append(v)
    if not wall:
        return {}
    out = {'frames': len(wall), 'size': f'{pairs[0][2].width}x{pairs[0][2].height}',
           'median_ms': float(np.median(wall)), 'p90_ms': float(np.percentile(wall, 90)),
           'rate_hz': 1e3 / float(np.median(wall)),
           'stages_median_ms': {k: float(np.median(v)) for k, v in stages.items()}}
    return out


def run(args) -> int:
    root = Path(__file__).resolve().parents[2] / 'bags'
    bags = args.bags or [root / 'static_obstacles', root / 'walk_obstacles']
    results = {}
    for bag in bags:
        try:
            pairs = load_pairs(bag, args.frames)
        except bagio.BagError as exc:
            print(f'asmonc bench: {exc}', file=sys.stderr)
            return 2
        r = time_detector(pairs, args.warmup)
        if not r:
            print(f'asmonc bench: {bag}: fewer pairs than --warmup', file=sys.stderr)
            return 2
        results[str(bag)] = r
        stages = ', '.join(f'{k} {v:.1f}' for k, v in r['stages_median_ms'].items())
        print(f"{bag.name}: {r['size']}, {r['frames']} frames: detector median "
              f"{r['median_ms']:.1f} ms (p90 {r['p90_ms']:.1f} ms) = {r['rate_hz']:.0f} Hz "
              f"on one core [{stages}]")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + '\n')
    return 0
