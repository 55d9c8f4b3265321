"""Timing and scoring detectors frame by frame: GPOD and the SGBM baseline (`asmonc bench`).

* `make_method` / `run_method`: a detector run over loaded frames (shared with
  `asmonc eval` and `asmonc campaign`); `score_runs`: its recall and false reports.
* `egomotion_results`: the egomotion estimator's results over frames, computed once
  (untimed) for the timed runs to take.
* `bench_frames` / `fastest_pass` / `time_detector`: per-frame times on one core.
* `render_frames`: frames of a simulator scenario rendered in memory.
* `bench`: the whole `asmonc bench` measurement.
"""
from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmonc_vision.core.config import override
from asmonc_vision.io import bagio
from asmonc_vision.io.frames import Frame, load_frames

METHODS = ('gpod', 'sgbm')
#: the 640x480 rig of the bench: f = 600 px keeps the paper's field of view
LARGE_RIG = {'width': 640, 'height': 480, 'focal': 600.0}
#: frames of the static_obstacles scenario with every obstacle in place (the bollard
#: appears at 4 s, 10 Hz)
LARGE_FIRST_FULL_FRAME = 40
#: the graph's map motion (the detector node does not wait for the egomotion): the
#: motion of a pair reaches the map this many pairs later (`run_method`'s ``motion_lag``;
#: `asmonc campaign`'s gpod_map_lag, `asmonc bench`'s GPOD). Measured in the graph: the
#: newest /egomotion/odometry pose when the map places a pair is the previous pair's
#: (the detector's /diagnostics ``map_motion_ahead_ms``, docs/map.md)
MAP_MOTION_LAG = 1


def render_frames(scenario: str = 'static_obstacles', seed: int = 0, frames=(0,),
                  **rig_changes) -> list[Frame]:
    """Render frames of a simulator scenario in memory, with their ground truth.

    Args:
        scenario, seed: as `asmonc-sim`.
        frames: frame indices to render (10 Hz; in this order).
        **rig_changes: RigSettings fields to change (e.g. width, height, focal).
    """
    from asmonc_vision.eval.evaluation import frame_from_detections
    from asmonc_vision.sim import RigSettings, StereoRenderer, make_scenario, simulate_frame
    from asmonc_vision.sim.bagwriter import stamp_ns

    rig = dataclasses.replace(RigSettings(), **rig_changes)
    sc = make_scenario(scenario, seed=seed, duration=max(frames) / rig.fps + 1.0 / rig.fps,
                       rig=rig)
    renderer = StereoRenderer(rig)
    cam = rig.camera()
    out = []
    for k in frames:
        f = simulate_frame(sc, int(k), renderer)
        ns = stamp_ns(f.time)
        out.append(Frame(ns, f.left, f.right, cam, frame_from_detections(ns, f.obstacles),
                         f.plane))
    return out


# --- running ---------------------------------------------------------------------------

@dataclass
class FrameRun:
    """One frame's output of a method: status, obstacles (FrameObstacles), ground plane
    (MetricPlane or None), the wall time of process() and its stage timings (ms), the
    CPU time of process() (ms, this thread's), and the egomotion the graph would publish
    for the pair (``/egomotion``'s translation, (3,) m, the left camera's from the
    estimator's reference pair in its optical frame; None: none published or not run),
    and how far GPOD's ground surface ahead was known: (``known_until_m``, the rule
    that ended it, `GroundSurface.ended_by`), None for the peer or without a surface."""

    stamp_ns: int
    status: str
    obstacles: object
    plane: object
    latency_ms: float
    timings: dict
    cpu_ms: float = float('nan')
    ego_t: object = None
    ground: tuple[float, str] | None = None


def make_method(method: str, threshold_px: float | None = None, map_enabled: bool | None = None):
    """A fresh detector: 'gpod' (`core.perception.Perception`: GpodDetector, default
    GpodConfig, then the evidence map when ``map_enabled`` (None: its default), as the
    detector node runs them) or 'sgbm' (SgbmBaseline, default SgbmConfig); threshold_px
    overrides the obstacle threshold of either (for GPOD it selects the fixed threshold,
    instead of the default k*sigma one)."""
    if method == 'gpod':
        from asmonc_vision.core.evidence_map import EvidenceMapConfig
        from asmonc_vision.core.gpod import GpodConfig
        from asmonc_vision.core.perception import Perception
        cfg = GpodConfig() if threshold_px is None else override(
            GpodConfig(), {'threshold.px': threshold_px, 'threshold.mode': 'fixed'})
        mcfg = (EvidenceMapConfig() if map_enabled is None
                else EvidenceMapConfig(enabled=map_enabled))
        return Perception(cfg, mcfg)
    if method == 'sgbm':
        from asmonc_vision.core.baseline import SgbmBaseline, SgbmConfig
        cfg = SgbmConfig() if threshold_px is None else SgbmConfig(threshold_px=threshold_px)
        return SgbmBaseline(cfg)
    raise ValueError(f"unknown method '{method}'; expected one of {', '.join(METHODS)}")


def egomotion_results(frames: list[Frame]) -> list:
    """The egomotion estimator (`core.motion.EgomotionEstimator`, default settings) run
    over the frames in order, on one OpenCV thread, as the egomotion node runs it: one
    `core.motion.pipeline.EgomotionResult` per frame (for `run_method`'s
    ``ego_results``: the same motions for every timed pass, the estimator's own time
    in none)."""
    import cv2

    from asmonc_vision.core.motion import EgomotionEstimator

    cv2.setNumThreads(1)
    est = EgomotionEstimator()
    return [est.process(f.left, f.right, f.cam, f.stamp_ns) for f in frames]


def run_method(frames: list[Frame], method: str = 'gpod', threshold_px: float | None = None,
               progress=None, map_enabled: bool | None = None,
               egomotion: bool = False, motion_lag: int = 0,
               map_waits: bool = False, ego_results: list | None = None) -> list[FrameRun]:
    """Run a fresh detector over the frames in order, on one OpenCV thread.

    Args:
        frames: with images.
        method: 'gpod' or 'sgbm'; threshold_px: obstacle threshold override.
        progress: optional callback(done, total) after each frame.
        map_enabled: GPOD's evidence map on or off (None: its default).
        egomotion: the egomotion estimator (`core.motion.EgomotionEstimator`, default
            settings) is run as the egomotion node runs it (its time is not counted),
            its published translation kept (`FrameRun.ego_t`, which the alarm replay
            turns into the walking speed, as the alarm node does); GPOD is given each
            pair's motion, as the node graph gives it; without it, no motion (the
            tracks and the map are carried only while still).
        motion_lag: with ``egomotion`` and the map, 0 gives each pair its own motion (as
            a graph that waits for it); N >= 1 gives the detector no motion and the map
            the prediction of a `core.map_motion.MotionPredictor` fed the motions of the
            pairs at least N before (as the graph, which does not wait, has them).
        map_waits: with ``egomotion``, the map and ``motion_lag`` 0, the detector gets
            no motion and the map the prediction of a predictor fed each pair's own
            motion before the pair (as a graph whose map, not its detector, waited for
            the pair's pose; the node's map does not wait, docs/map.md).
        ego_results: with ``egomotion``, the estimator's results for these frames
            (`egomotion_results`, one per frame), computed before (None: computed here
            first).

    GPOD is given each pair's up direction from the frame's inclinometer sample
    (`io.frames.Frame.inclinometer`, `core.rotations.up_for_pair` within the detector's
    ``plane.gravity_prior_max_age_s``), as the node takes it from `/inclinometer/imu`; none
    for frames without one.
    """
    import cv2

    from asmonc_vision.core.rotations import up_for_pair
    from asmonc_vision.eval.evaluation import frame_from_detections

    cv2.setNumThreads(1)
    det = make_method(method, threshold_px, map_enabled)
    max_age_s = det.gpod_config.plane.gravity_prior_max_age_s if method == 'gpod' else 0.0
    if egomotion and ego_results is None:
        ego_results = egomotion_results(frames)
    elif egomotion and len(ego_results) != len(frames):
        raise ValueError(f'run_method: {len(ego_results)} egomotion results for '
                         f'{len(frames)} frames')
    lagged: list = []            # (frame index, reference stamp, stamp, R, t) not yet known
    if (egomotion and method == 'gpod' and det.map is not None
            and (motion_lag > 0 or map_waits)):
        from asmonc_vision.core.map_motion import MotionPredictor
        det.motion_predictor = MotionPredictor()
    out = []
    prev_stamp = None
    for i, f in enumerate(frames):
        motion = ego_t = None
        if egomotion:
            er = ego_results[i]
            if er.ok and prev_stamp is not None and er.reference_stamp_ns == prev_stamp:
                ego_t = np.array(er.motion.t, float)   # published: from the pair before
            if method == 'gpod' and det.motion_predictor is not None:
                if er.ok and er.reference_stamp_ns is not None:
                    lagged.append((i, er.reference_stamp_ns, f.stamp_ns, er.motion.R,
                                   er.motion.t))
                while lagged and lagged[0][0] <= i - motion_lag:
                    det.motion_predictor.add_motion(*lagged.pop(0)[1:])
            elif method == 'gpod' and er.ok and er.reference_stamp_ns == prev_stamp:
                motion = (er.motion.R, er.motion.t)
            prev_stamp = f.stamp_ns
        c = time.thread_time()
        t = time.perf_counter()
        if method == 'gpod':
            up = up_for_pair(f.inclinometer, f.stamp_ns, max_age_s)
            res = det.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns, motion=motion,
                              up=up)
        else:
            res = det.process(f.left, f.right, f.cam)
        ms = (time.perf_counter() - t) * 1e3
        cpu_ms = (time.thread_time() - c) * 1e3
        plane = res.plane.metric if res.plane is not None else None
        out.append(FrameRun(f.stamp_ns, res.status, frame_from_detections(f.stamp_ns,
                                                                          res.obstacles),
                            plane, ms, dict(res.timings), cpu_ms, ego_t,
                            _ground_known(getattr(res, 'surface', None))))
        if progress is not None:
            progress(i + 1, len(frames))
    return out


def _ground_known(surface) -> tuple[float, str] | None:
    """`FrameRun.ground` of a result's surface (a GroundSurface or None)."""
    return None if surface is None else (float(surface.known_until_m), surface.ended_by())


def out_of_view_for(frames: list[Frame]) -> dict:
    """stamp_ns -> true obstacles out of view in that frame
    (`eval.evaluation.out_of_view_truth`), from the frames' truth, true poses and true
    planes; empty when they have none."""
    from asmonc_vision.eval.evaluation import out_of_view_truth

    have = [f for f in frames if f.truth is not None and f.pose is not None
            and f.truth_plane is not None]
    return out_of_view_truth({f.stamp_ns: f.truth for f in have},
                             {f.stamp_ns: f.pose for f in have},
                             {f.stamp_ns: f.truth_plane for f in have})


def score_runs(frames: list[Frame], runs: list[FrameRun], evaluation=None, warmup: int = 0,
               **criteria):
    """Score a method's output against the frames' truth (frames without truth are skipped).

    Args:
        evaluation: a eval.evaluation.SequenceEvaluation to add to (default a new one with
            `criteria`: match_radius, min_height, max_range).
        warmup: the first `warmup` latencies are left out of the latency statistics.
    Returns:
        the SequenceEvaluation.
    """
    from asmonc_vision.eval.evaluation import SequenceEvaluation

    ev = evaluation if evaluation is not None else SequenceEvaluation(**criteria)
    away = out_of_view_for(frames)
    for i, (f, r) in enumerate(zip(frames, runs)):
        if f.truth is None:
            continue
        ev.add_frame(r.obstacles, f.truth, plane=r.plane, truth_plane=f.truth_plane,
                     latency_ms=r.latency_ms if i >= warmup else None, status=r.status,
                     remembered=away.get(f.stamp_ns))
    return ev


def time_detector(pairs, warmup: int = 5) -> dict:
    """Run GpodDetector over the pairs; per-stage median/p90 ms of the timed ones."""
    frames = [Frame(i, left, right, c) for i, (left, right, c) in enumerate(pairs)]
    return _timing(run_method(frames, 'gpod'), warmup, pairs[0][2] if pairs else None)


def _timing(runs: list[FrameRun], warmup: int, cam) -> dict:
    timed = runs[warmup:]
    if not timed:
        return {}
    wall = [r.latency_ms for r in timed]
    cpu = [r.cpu_ms for r in timed]
    stages: dict[str, list[float]] = {}
    for r in timed:
        for k, v in r.timings.items():
            stages.setdefault(k, []).append(v)
    return {'frames': len(wall), 'size': f'{cam.width}x{cam.height}',
            'median_ms': float(np.median(wall)), 'p90_ms': float(np.percentile(wall, 90)),
            'rate_hz': 1e3 / float(np.median(wall)),
            'median_cpu_ms': float(np.median(cpu)), 'p90_cpu_ms': float(np.percentile(cpu, 90)),
            'stages_median_ms': {k: float(np.median(v)) for k, v in stages.items()},
            'stages_p90_ms': {k: float(np.percentile(v, 90)) for k, v in stages.items()}}


def fastest_pass(passes: list[list[FrameRun]]) -> list[FrameRun]:
    """Per frame, the fastest of several passes over the same frames (wall and CPU time
    and each stage, each its own minimum; the outputs of the first pass): the machine's
    other load only ever adds time, so the minimum is the closest to the code's own (as
    `timeit` advises). The detectors are deterministic, so the passes' outputs agree."""
    first = passes[0]
    if len(passes) == 1:
        return first
    out = []
    for k, r in enumerate(first):
        rs = [p[k] for p in passes]
        stages = {name: min(x.timings.get(name, v) for x in rs) for name, v in r.timings.items()}
        out.append(dataclasses.replace(r, latency_ms=min(x.latency_ms for x in rs),
                                       cpu_ms=min(x.cpu_ms for x in rs), timings=stages))
    return out


def bench_runs(frames: list[Frame], method: str, ego: list | None = None) -> list[FrameRun]:
    """One timed pass of a method as `asmonc bench` times it. GPOD runs as the graph runs
    it (`asmonc campaign`'s gpod_map_lag): the detector with no motion, the evidence map
    with the motion a `core.map_motion.MotionPredictor` predicts from the egomotion's
    motions of the pairs ``MAP_MOTION_LAG`` or more before; ``ego``: the egomotion's
    results for the frames (`egomotion_results`; None: the estimator runs here, its time
    not counted). SGBM as it is."""
    if method != 'gpod':
        return run_method(frames, method)
    return run_method(frames, 'gpod', map_enabled=True, egomotion=True,
                      motion_lag=MAP_MOTION_LAG, ego_results=ego)


def bench_frames(frames: list[Frame], warmup: int, repeat: int = 1) -> dict:
    """Time and score both methods on the frames (`bench_runs`): {method: {timing...,
    'recall'...}, 'ratio_gpod_over_sgbm': median time ratio}. The egomotion that GPOD's
    map takes is estimated once, before the timed passes (the egomotion node's work, not
    the detector's). With ``repeat`` > 1 the methods make that many passes, interleaved
    (gpod, sgbm, gpod, ...), and each frame counts its fastest (`fastest_pass`)."""
    ego = egomotion_results(frames)
    passes: dict[str, list[list[FrameRun]]] = {m: [] for m in METHODS}
    for _ in range(max(int(repeat), 1)):
        for method in METHODS:
            passes[method].append(bench_runs(frames, method, ego))
    out = {}
    for method in METHODS:
        runs = fastest_pass(passes[method])
        r = _timing(runs, warmup, frames[0].cam)
        r['passes'] = len(passes[method])
        ev = score_runs(frames, runs)
        s = ev.summary()
        r['recall'] = s['recall']['recall']
        r['eligible'] = s['recall']['eligible']
        r['detected'] = s['recall']['detected']
        r['false_per_frame'] = s['false_obstacles']['per_frame']
        out[method] = r
    if out['gpod'] and out['sgbm']:
        out['ratio_gpod_over_sgbm'] = out['gpod']['median_ms'] / out['sgbm']['median_ms']
    return out


def _print(name: str, res: dict) -> None:
    g = res['gpod']
    passes = (f", each its fastest of {g['passes']} passes" if g.get('passes', 1) > 1
              else '')
    print(f"{name}: {g['size']}, {g['frames']} timed frames{passes}, one core; gpod's map "
          f"given the graph's motion")
    for method in METHODS:
        r = res[method]
        stages = ', '.join(f'{k} {v:.1f}' for k, v in r['stages_median_ms'].items()
                           if k != 'total')
        recall = (f"{r['detected']}/{r['eligible']} = {r['recall']:.1%}" if r['eligible']
                  else 'no eligible obstacles')
        fpf = r['false_per_frame']
        false = f'{fpf:.3f}/frame' if fpf is not None else '-'
        print(f"  {method:5s} median {r['median_ms']:6.1f} ms (p90 {r['p90_ms']:6.1f}) = "
              f"{r['rate_hz']:5.1f} Hz [{stages}]; CPU median {r['median_cpu_ms']:.1f} ms "
              f"(p90 {r['p90_cpu_ms']:.1f}); recall (>=10 cm, <=5 m) {recall}, false {false}")
    if 'ratio_gpod_over_sgbm' in res:
        print(f"  ratio gpod/sgbm median time: {res['ratio_gpod_over_sgbm']:.2f}")


def _print_load() -> None:
    """The load average, against the cores: wall times include waiting for a core."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        return
    print(f'load average {load:.2f} on {os.cpu_count()} cores (wall times include waiting '
          f'for a core; CPU times do not)')


def bench(args) -> int:
    """`asmonc bench` with its parsed arguments (see `cli.bench`); the exit code."""
    root = Path(__file__).resolve().parents[2] / 'bags'
    bags = args.bags or [root / 'static_obstacles', root / 'walk_obstacles']
    if args.warmup < 0 or args.frames < 0 or args.large_frames < 1 or args.repeat < 1:
        print('asmonc bench: --warmup and --frames must be >= 0, --large-frames and '
              '--repeat >= 1', file=sys.stderr)
        return 2
    results: dict[str, dict] = {}       # 'WxH' -> bag -> numbers
    _print_load()
    for bag in bags:
        try:
            frames = load_frames(bag, args.frames)
        except bagio.BagError as exc:
            print(f'asmonc bench: {exc}', file=sys.stderr)
            return 2
        if len(frames) <= args.warmup:
            print(f'asmonc bench: {bag}: {len(frames)} pairs, not more than --warmup '
                  f'{args.warmup}', file=sys.stderr)
            return 2
        res = bench_frames(frames, args.warmup, args.repeat)
        cam = frames[0].cam
        results.setdefault(f'{cam.width}x{cam.height}', {})[str(bag)] = res
        _print(Path(bag).name, res)
    if not args.no_large:
        clear = max(args.warmup, 3)
        n = args.large_frames
        if args.frames:
            n = max(1, min(n, args.frames - clear))
        ks = list(range(clear)) + list(range(LARGE_FIRST_FULL_FRAME, LARGE_FIRST_FULL_FRAME + n))
        t0 = time.monotonic()
        frames = render_frames('static_obstacles', 0, ks, **LARGE_RIG)
        render_s = time.monotonic() - t0
        res = bench_frames(frames, clear, args.repeat)
        size = f'{LARGE_RIG["width"]}x{LARGE_RIG["height"]}'
        results.setdefault(size, {})['static_obstacles (rendered, seed 0)'] = res
        _print(f'static_obstacles (seed 0) rendered at 640x480, f = 600 px, in '
               f'{render_s:.0f} s ({clear} clear + {n} frames with obstacles)', res)
    if args.json:
        from asmonc_vision.eval.evaluation import json_ready
        args.json.write_text(json.dumps(json_ready(results), indent=2, allow_nan=False) + '\n')
    return 0
