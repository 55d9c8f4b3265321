"""Small boxes seen standing still, GPOD against the SGBM baseline (`asmonc smallbox`):
the scenes (`small_box_scene`, `scene_frames`), the scoring (`score_frame`, `summarise`)
and the measurement (`run_scene`, `measure`, `smallbox_command`). The command's help
(`cli.smallbox`) says what is reported.
"""
from __future__ import annotations

import json
import math
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from asmonc_vision.eval.evaluation import json_ready

METHODS = ('gpod', 'sgbm')
#: The row of GPOD's own per-frame detections, before its obstacle tracks.
PER_FRAME = 'gpod/frame'
#: A report's image region centre within this many pixels of the box's region is "on" it.
ON_BOX_MARGIN_PX = 4


# --- the scene -----------------------------------------------------------------------------

#: The rigs a scene can be seen by: the paper's (`RigSettings()`: 320 x 240, f = 300 px,
#: B = 0.35 m, 1.25 m up, 20 degrees down) and a level chest rig (`RigSettings.chest()`:
#: 640 x 480, f = 560 px, B = 0.12 m, 1.3 m up, 5 degrees down).
RIGS = ('backpack', 'chest')


def nominal_rig(rig: str):
    """The `asmonc_vision.sim.RigSettings` of a rig name in `RIGS`, at its nominal height
    and pitch (the campaign's walks draw them at random, `sim.scenes.scene_rig`)."""
    from asmonc_vision.sim import RigSettings

    if rig == 'backpack':
        return RigSettings()
    if rig == 'chest':
        return RigSettings.chest()
    raise ValueError(f"unknown rig '{rig}'; expected one of {', '.join(RIGS)}")


def small_box_scene(height: float, range_m: float, seed: int, box_frames: int = 20,
                    clear_frames: int = 5, rig: str = 'backpack'):
    """A wearer standing still (``rig``, `RIGS`; simulator) on a random pavement; after
    ``clear_frames`` obstacle-free frames a box of ``height`` (m) appears whose nearest
    footprint point is ``range_m`` away along the ground, for ``box_frames`` frames
    (random bearing within +-0.6 of the half field of view, size 0.2-0.45 x 0.25-0.5 m,
    yaw 0-90 degrees, an albedo contrasting with the pavement).

    Returns:
        an `asmonc_vision.sim.Scenario` of clear_frames + box_frames frames.
    """
    from asmonc_vision.sim import Box, Ground, Leg, Scenario, Trajectory, World
    from asmonc_vision.sim.scenarios import obstacle_albedo, random_pavement

    settings = nominal_rig(rig)
    rng = np.random.default_rng([seed, 77])
    ground = Ground(pavement=random_pavement(rng))
    bearing = float(rng.uniform(-0.6, 0.6) * math.atan((settings.width / 2)
                                                        / settings.focal))
    length, width = float(rng.uniform(0.2, 0.45)), float(rng.uniform(0.25, 0.5))
    yaw = float(rng.uniform(0.0, 90.0))
    cy, sy = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [length / 2, width / 2]
    reach = float(np.max(-(corners @ np.array([[cy, sy], [-sy, cy]]))
                         @ [math.cos(bearing), math.sin(bearing)]))
    dist = range_m + reach
    box = Box(x=dist * math.cos(bearing), y=dist * math.sin(bearing), length=length,
              width=width, height=height, yaw_deg=yaw,
              albedo=obstacle_albedo(rng, ground.pavement.brightness), name='box',
              appear=(clear_frames - 0.5) / settings.fps)
    world = World(ground, [box], seed=seed)
    duration = (clear_frames + box_frames) / settings.fps
    traj = Trajectory([Leg(duration + 1.0, 0.0)], settings, world,
                      rng=np.random.default_rng([seed, 5]))
    return Scenario('small_box', 'small box, standing', seed, duration, settings, world, traj)


def scene_frames(height: float, range_m: float, seed: int, box_frames: int = 20,
                 clear_frames: int = 5, cache: Path | None = None, rig: str = 'backpack'):
    """The rendered frames of `small_box_scene`: (camera, [(left, right, truths)]), truths
    being the frame's `ObstacleTruth`s; read from / written to ``cache`` if given."""
    path = None
    if cache is not None:
        path = Path(cache) / (f'smallbox_h{height:.3f}_r{range_m:.3f}_s{seed}'
                              f'_b{box_frames}_c{clear_frames}'
                              + ('' if rig == 'backpack' else f'_{rig}') + '.pkl')
        if path.exists():
            with open(path, 'rb') as fh:
                return pickle.load(fh)
    from asmonc_vision.sim import StereoRenderer, simulate_frame

    sc = small_box_scene(height, range_m, seed, box_frames, clear_frames, rig)
    renderer = StereoRenderer(sc.rig)
    frames = []
    for k in range(sc.n_frames):
        f = simulate_frame(sc, k, renderer)
        frames.append((f.left, f.right, list(f.obstacles)))
    out = (sc.rig.camera(), frames)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix('.tmp')
        with open(tmp, 'wb') as fh:
            pickle.dump(out, fh, protocol=pickle.HIGHEST_PROTOCOL)
        tmp.replace(path)
    return out


# --- scoring -------------------------------------------------------------------------------

def new_tally() -> dict:
    """Empty counts of one method over some frames."""
    return dict(frames=0, box_frames=0, found=0, found_on_box=0, false=0, range_err=[],
                bearing_err_deg=[], cpu_ms=0.0)


def score_frame(tally: dict, obstacles, truths, match_radius: float = 0.3) -> None:
    """Add one frame's reports (objects with range, bearing, roi, height; drop-offs,
    height < 0, ignored) to ``tally`` against the frame's true obstacles (the first one
    with positive height is the box)."""
    obs = [o for o in obstacles if o.height > 0]
    truth = [t for t in truths if t.height > 0]
    tally['frames'] += 1
    if not truth:
        tally['false'] += len(obs)
        return
    t = truth[0]
    txy = np.array([t.range * math.cos(t.bearing), t.range * math.sin(t.bearing)])
    x, y, w, h = t.roi
    m = ON_BOX_MARGIN_PX
    on_box = [x - m <= o.roi[0] + o.roi[2] / 2 <= x + w + m
              and y - m <= o.roi[1] + o.roi[3] / 2 <= y + h + m for o in obs]
    dist = [float(np.hypot(o.range * math.cos(o.bearing) - txy[0],
                           o.range * math.sin(o.bearing) - txy[1])) for o in obs]
    tally['box_frames'] += 1
    tally['found_on_box'] += any(on_box)
    near = [i for i, dd in enumerate(dist) if dd <= match_radius]
    if near:
        j = min(near, key=lambda i: dist[i])
        tally['found'] += 1
        tally['range_err'].append((obs[j].range - t.range) / t.range)
        db = (obs[j].bearing - t.bearing + math.pi) % (2 * math.pi) - math.pi
        tally['bearing_err_deg'].append(math.degrees(db))
    tally['false'] += sum(1 for i in range(len(obs)) if dist[i] > match_radius
                          and not on_box[i])


def merge(a: dict, b: dict) -> dict:
    """Sum of two tallies."""
    return {k: a[k] + b[k] for k in a}


def summarise(t: dict) -> dict:
    """Rates and medians of a tally: found / found_on_box (fraction of the box frames),
    false_per_frame, range_err_median / _p90 (fraction), bearing_err_median_deg / _p90,
    cpu_ms_per_frame."""
    re = np.abs(np.asarray(t['range_err'], float))
    be = np.abs(np.asarray(t['bearing_err_deg'], float))
    n = max(t['box_frames'], 1)

    def q(x, p):
        return float(np.percentile(x, p)) if x.size else float('nan')

    return dict(frames=t['frames'], box_frames=t['box_frames'], found=t['found'] / n,
                found_on_box=t['found_on_box'] / n, false=t['false'],
                false_per_frame=t['false'] / max(t['frames'], 1),
                range_err_median=q(re, 50), range_err_p90=q(re, 90),
                bearing_err_median_deg=q(be, 50), bearing_err_p90_deg=q(be, 90),
                cpu_ms_per_frame=t['cpu_ms'] / max(t['frames'], 1))


def make_detector(method: str, gpod_config=None, map_enabled: bool | None = None):
    """A fresh detector: 'gpod' (`core.perception.Perception`: GpodDetector with
    ``gpod_config`` or the defaults, then the evidence map when ``map_enabled``, None: its
    default) or 'sgbm' (SgbmBaseline, default SgbmConfig)."""
    if method == 'gpod':
        from asmonc_vision.core.evidence_map import EvidenceMapConfig
        from asmonc_vision.core.gpod import GpodConfig
        from asmonc_vision.core.perception import Perception
        return Perception(gpod_config or GpodConfig(),
                          EvidenceMapConfig() if map_enabled is None
                          else EvidenceMapConfig(enabled=map_enabled))
    if method == 'sgbm':
        from asmonc_vision.core.baseline import SgbmBaseline, SgbmConfig
        return SgbmBaseline(SgbmConfig())
    raise ValueError(f"unknown method '{method}'; expected one of {', '.join(METHODS)}")


def rows(methods) -> tuple[str, ...]:
    """The result rows of ``methods``: each method, and after 'gpod' its per-frame
    detections ('gpod/frame')."""
    out: list[str] = []
    for m in methods:
        out.append(m)
        if m == 'gpod':
            out.append(PER_FRAME)
    return tuple(out)


def run_scene(height: float, range_m: float, seed: int, box_frames: int = 20,
              clear_frames: int = 5, methods=METHODS, match_radius: float = 0.3,
              gpod_config=None, cache: Path | None = None,
              map_enabled: bool | None = None, rig: str = 'backpack') -> dict:
    """Render one scene (seen by ``rig``, `RIGS`) and run each method, fresh, on its
    frames in order.

    Returns:
        {row: tally} (see `rows`, `new_tally`, `score_frame`).
    """
    import cv2

    cv2.setNumThreads(1)
    cam, frames = scene_frames(height, range_m, seed, box_frames, clear_frames, cache, rig)
    rig_fps = nominal_rig(rig).fps
    out = {}
    for method in methods:
        det = make_detector(method, gpod_config, map_enabled)
        tally, per_frame = new_tally(), new_tally()
        period_ns = int(round(1e9 / rig_fps))
        for k, (left, right, truths) in enumerate(frames):
            t0 = time.process_time()
            if method == 'gpod':
                res = det.process(left, right, cam, stamp_ns=k * period_ns)
            else:
                res = det.process(left, right, cam)
            dt = (time.process_time() - t0) * 1e3
            tally['cpu_ms'] += dt
            score_frame(tally, res.obstacles, truths, match_radius)
            if method == 'gpod':
                per_frame['cpu_ms'] += dt
                score_frame(per_frame, res.detections, truths, match_radius)
        out[method] = tally
        if method == 'gpod':
            out[PER_FRAME] = per_frame
    return out


def _run_scene_job(job):
    return job[:3], run_scene(*job[:3], **job[3])


def measure(heights, ranges, seeds, box_frames: int = 20, clear_frames: int = 5,
            methods=METHODS, match_radius: float = 0.3, gpod_config=None, workers: int = 1,
            cache: Path | None = None, progress=None, map_enabled: bool | None = None,
            rig: str = 'backpack') -> dict:
    """Run every (height, range) cell over the seeds, seen by ``rig`` (`RIGS`).

    Returns:
        {(height, range): {row: tally}} (rows: see `rows`).
    """
    kw = dict(box_frames=box_frames, clear_frames=clear_frames, methods=tuple(methods),
              match_radius=match_radius, gpod_config=gpod_config, cache=cache,
              map_enabled=map_enabled, rig=rig)
    jobs = [(h, r, s, kw) for h in heights for r in ranges for s in seeds]
    cells: dict = {}
    total = len(jobs)

    def add(key, res):
        cell = cells.setdefault(key[:2], {m: new_tally() for m in rows(methods)})
        for m in rows(methods):
            cell[m] = merge(cell[m], res[m])

    if workers > 1 and total > 1:
        import multiprocessing as mp
        with mp.get_context('fork').Pool(min(workers, 2)) as pool:
            for i, (key, res) in enumerate(pool.imap_unordered(_run_scene_job, jobs)):
                add(key, res)
                if progress:
                    progress(i + 1, total)
    else:
        for i, job in enumerate(jobs):
            key, res = _run_scene_job(job)
            add(key, res)
            if progress:
                progress(i + 1, total)
    return cells


# --- command line --------------------------------------------------------------------------

def _cells(args) -> list[tuple[float, float]]:
    if not args.grid and len(args.heights) == len(args.ranges):
        return list(zip(args.heights, args.ranges))
    return [(h, r) for h in args.heights for r in args.ranges]


def format_table(cells: dict, methods) -> list[str]:
    """Printable lines: one per cell and method."""
    lines = [f"{'cell':<14}{'method':<11}{'found':>8}{'on box':>8}{'false/fr':>10}"
             f"{'|dr| med':>10}{'|db| med':>10}{'cpu ms':>8}"]
    for (h, r), per in cells.items():
        for m in rows(methods):
            s = summarise(per[m])
            lines.append(f"{h * 100:4.0f} cm @{r:4.1f} m {m:<11}{s['found']:>8.1%}"
                         f"{s['found_on_box']:>8.1%}{s['false_per_frame']:>10.3f}"
                         f"{s['range_err_median']:>10.1%}{s['bearing_err_median_deg']:>9.2f}°"
                         f"{s['cpu_ms_per_frame']:>8.1f}")
    return lines


def smallbox_command(args) -> int:
    """`asmonc smallbox` with its parsed arguments (see `cli.smallbox`); the exit
    status."""
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    pairs = _cells(args)
    t0 = time.time()
    cells: dict = {}

    def progress(done, total):
        if not args.quiet:
            print(f'\r  scenes {done}/{total}  {time.time() - t0:5.0f} s', end='',
                  file=sys.stderr, flush=True)

    # One cell at a time, in the order asked for (a cell's scenes may run in parallel).
    done = 0
    total = len(pairs) * len(seeds)
    for h, r in pairs:
        res = measure([h], [r], seeds, args.frames, args.clear_frames, args.method,
                      args.match_radius, workers=args.workers, cache=args.cache,
                      progress=lambda d, _t, base=done: progress(base + d, total),
                      map_enabled={'default': None, 'on': True, 'off': False}[args.map],
                      rig=args.rig)
        done += len(seeds)
        cells.update(res)
    if not args.quiet:
        print(file=sys.stderr)
    print(f'small boxes, standing still, {args.rig} rig: {len(seeds)} scene(s) x '
          f'{args.frames} frames per cell (+{args.clear_frames} clear), match radius '
          f'{args.match_radius} m, {time.time() - t0:.0f} s')
    for line in format_table(cells, args.method):
        print(line)
    if args.json is not None:
        out = {'rig': args.rig, 'seeds': seeds, 'frames': args.frames,
               'clear_frames': args.clear_frames,
               'match_radius': args.match_radius,
               'cells': [{'height': h, 'range': r,
                          **{m: summarise(per[m]) for m in rows(args.method)}}
                         for (h, r), per in cells.items()]}
        args.json.write_text(json.dumps(json_ready(out), indent=1, allow_nan=False))
    return 0
