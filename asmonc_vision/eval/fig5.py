"""The paper's Fig. 5 -- detection probability against obstacle height, per range --
from the model (`model_report`, `plot_model`) and measured with the simulator and
GpodDetector (`run_empirical`, `empirical_report`, `plot_empirical`). `asmonc fig5`'s
help (`cli.fig5`) says what each reports.
"""
from __future__ import annotations

import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from asmonc_vision.eval.detection_model import (PAPER_SIGMA_PX, PAPER_THRESHOLD_PX,
                                                ModelRig, fig5_curves, min_height_for)
from asmonc_vision.eval.evaluation import json_ready

#: Ranges (m) of the table columns and of the empirical boxes.
RANGES_M = (2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)
#: Heights (cm) of the model table.
TABLE_HEIGHTS_CM = tuple(range(1, 21))
#: Ranges (m) at which the 90% heights are printed.
P90_RANGES_M = (2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)
#: Box heights (cm) of the empirical run.
EMPIRICAL_HEIGHTS_CM = (2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0)
#: A report within this distance (m) of a box on the ground detects it.
MATCH_RADIUS_M = 0.3
#: Ground features closer than this (px) to an obstacle or the sky are left out of sigma.
SIGMA_MARGIN_PX = 4


def fig5_command(args) -> int:
    """`asmonc fig5` with its parsed arguments (see `cli.fig5`); the exit code."""
    for name in ('focal', 'baseline', 'height'):
        if not getattr(args, name) > 0:
            print(f'asmonc fig5: --{name} must be > 0', file=sys.stderr)
            return 2
    if args.sigma is not None and not args.sigma > 0:
        print('asmonc fig5: --sigma must be > 0', file=sys.stderr)
        return 2
    if args.min_pixels < 1:
        print('asmonc fig5: --min-pixels must be >= 1', file=sys.stderr)
        return 2
    if args.empirical:
        return _run_empirical_cli(args)
    try:
        rig = ModelRig(args.focal, args.baseline, args.height, args.pitch_deg)
    except ValueError as exc:
        print(f'asmonc fig5: {exc}', file=sys.stderr)
        return 2
    threshold = PAPER_THRESHOLD_PX if args.threshold is None else args.threshold
    sigma = PAPER_SIGMA_PX if args.sigma is None else args.sigma
    print(model_report(rig, threshold, sigma, args.min_pixels))
    if args.png is not None:
        plot_model(rig, threshold, sigma, args.min_pixels, args.png)
        print(f'figure: {args.png}')
    if args.json is not None:
        heights = np.array(TABLE_HEIGHTS_CM) / 100.0
        grid = fig5_curves(rig, heights, RANGES_M, threshold, sigma, args.min_pixels)
        p90 = min_height_for(0.9, np.array(P90_RANGES_M), rig, threshold, sigma,
                             args.min_pixels)
        _write_json(args.json, {
            'rig': rig.describe(), 'threshold_px': threshold, 'sigma_px': sigma,
            'min_pixels': args.min_pixels, 'heights_cm': list(TABLE_HEIGHTS_CM),
            'ranges_m': list(RANGES_M), 'probability': grid.tolist(),
            'p90_height_m': dict(zip(map(str, P90_RANGES_M), map(float, p90)))})
    return 0


# --------------------------------------------------------------------------- model


def model_report(rig: ModelRig, threshold: float, sigma: float, min_pixels: int = 1,
                 heights_cm=TABLE_HEIGHTS_CM, ranges_m=RANGES_M) -> str:
    """The model's table (probability per height and range) and the 90% heights."""
    grid = fig5_curves(rig, np.asarray(heights_cm, float) / 100.0, ranges_m, threshold,
                       sigma, min_pixels)
    lines = [f'Detection probability of one vertical edge (Molton et al. 1998, Sec. 2.3): '
             f'{rig.describe()},',
             f'threshold {threshold:g} px, sigma {sigma:g} px, an edge string is an obstacle '
             f'with >= {min_pixels} pixel(s) beyond the threshold',
             '',
             'height   ' + ''.join(f'{r:>7g} m' for r in ranges_m)]
    for h, row in zip(heights_cm, grid):
        lines.append(f'{h:4g} cm  ' + ''.join(f'{100 * p:8.1f}%' for p in row))
    p90 = min_height_for(0.9, np.array(P90_RANGES_M), rig, threshold, sigma, min_pixels)
    lines += ['', '90% detection height:']
    lines += [f'  {r:4g} m: {_cm(h)}' for r, h in zip(P90_RANGES_M, p90)]
    return '\n'.join(lines)


def _cm(h: float) -> str:
    return f'{100 * h:5.1f} cm' if math.isfinite(h) else '  none (not below 0.99 H)'


def plot_model(rig: ModelRig, threshold: float, sigma: float, min_pixels: int,
               path: Path, ranges_m=RANGES_M) -> None:
    """Plot Fig. 5: detection probability against obstacle height, one curve per range."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    heights = np.linspace(0.0, 0.25, 251)
    grid = fig5_curves(rig, heights, ranges_m, threshold, sigma, min_pixels)
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=100)
    colours = plt.cm.viridis(np.linspace(0.0, 0.9, len(ranges_m)))
    for j, (r, c) in enumerate(zip(ranges_m, colours)):
        ax.plot(100 * heights, grid[:, j], color=c, label=f'{r:g} m')
    ax.axhline(0.9, color='0.5', lw=0.8, ls='--')
    if (rig == ModelRig() and threshold == PAPER_THRESHOLD_PX and sigma == PAPER_SIGMA_PX
            and min_pixels == 1):
        ax.plot([6.0, 12.0], [0.9, 0.9], 'kx', ms=8,
                label='paper: 90% at 6 cm (2.5 m), 12 cm (5 m)')
    ax.set_xlabel('obstacle height S (cm)')
    ax.set_ylabel('detection probability')
    ax.set_xlim(0, 25)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(title='range', fontsize=8, loc='lower right')
    ax.set_title(f'Fig. 5 model: threshold {threshold:g} px, sigma {sigma:g} px, '
                 f'>= {min_pixels} px\n{rig.describe()}', fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# --------------------------------------------------------------------------- empirical


def _wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n (95% for z = 1.96)."""
    if n == 0:
        return float('nan'), float('nan')
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def _footprint(x: float, y: float, length: float, width: float, yaw_deg: float) -> np.ndarray:
    """(4, 2) world corners of a box footprint."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    loc = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * [length / 2, width / 2]
    return loc @ np.array([[c, s], [-s, c]]) + [x, y]


def _distance_to_polygon(poly: np.ndarray, q: np.ndarray) -> float:
    """Distance (m) from q (2,) to the boundary of the polygon (M, 2)."""
    best = np.inf
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        e = b - a
        s = float(np.clip(np.dot(q - a, e) / np.dot(e, e), 0.0, 1.0))
        best = min(best, float(np.linalg.norm(a + s * e - q)))
    return best


def _distance_to_footprint(poly: np.ndarray, q: np.ndarray) -> float:
    """Distance (m) from q (2,) to a convex polygon (M, 2): 0 inside."""
    e = np.roll(poly, -1, axis=0) - poly
    cross = e[:, 0] * (q[1] - poly[:, 1]) - e[:, 1] * (q[0] - poly[:, 0])
    if np.all(cross >= 0) or np.all(cross <= 0):
        return 0.0
    return _distance_to_polygon(poly, q)


def place_boxes(rng: np.random.Generator, height_m: float, ranges_m, rig,
                ground_brightness: float) -> list:
    """One box per range, alternately left and right of the walking direction, its
    nearest footprint point ``range`` m (along the ground) from the point below the left
    camera of a rig at the world origin looking along world x.

    The rng draws the side to start with, and per box: footprint 0.2-0.45 x 0.25-0.5 m,
    yaw 0-90 deg, lateral offset (0.1 m to well inside the view), and a shade clearly
    darker or brighter than the ground.
    """
    from asmonc_vision.sim.world import Box

    half_fov = math.atan((rig.width / 2.0) / rig.focal)
    foot = np.array([0.0, rig.baseline / 2.0])        # below the left camera
    side = 1.0 if rng.random() < 0.5 else -1.0
    boxes = []
    for r in ranges_m:
        length = float(rng.uniform(0.2, 0.45))
        width = float(rng.uniform(0.25, 0.5))
        yaw = float(rng.uniform(0.0, 90.0))
        max_lat = max(0.2, r * math.tan(0.6 * half_fov) - 0.3)
        lat = foot[1] + side * float(rng.uniform(0.1, max_lat))
        if rng.random() < 0.5:
            albedo = float(rng.uniform(40.0, max(ground_brightness - 45.0, 45.0)))
        else:
            albedo = float(rng.uniform(min(ground_brightness + 45.0, 200.0), 215.0))
        x = r + 0.2
        for _ in range(4):       # nearest footprint point at range r
            x += r - _distance_to_polygon(_footprint(x, lat, length, width, yaw), foot)
        boxes.append(Box(x=x, y=lat, length=length, width=width, height=float(height_m),
                         yaw_deg=yaw, albedo=albedo, name=f'box {100 * height_m:g} cm '
                         f'at {r:g} m'))
        side = -side
    return boxes


def _frame_obstacles(items, stamp: int = 0):
    """eval.evaluation.FrameObstacles of GpodObstacle or ObstacleTruth items."""
    from asmonc_vision.eval.evaluation import FrameObstacles

    if not items:
        return FrameObstacles.empty(stamp)
    return FrameObstacles(
        stamp_ns=stamp, ids=np.array([getattr(o, 'id', 0) for o in items], int),
        position=np.array([o.position for o in items], float).reshape(-1, 3),
        height=np.array([o.height for o in items], float),
        range=np.array([o.range for o in items], float),
        bearing=np.array([o.bearing for o in items], float),
        roi=np.array([o.roi for o in items], int).reshape(-1, 4))


class _FeatureLog:
    """The features of one seed's frames: on the ground (away from obstacles and the
    sky) their raw excess, the excess the detector thresholds (its time average while
    still, when it reports one), the pixel's threshold, the edge strength and the true
    ground range; on the boxes (within a pixel of one) their thresholds and strengths."""

    KEYS = ('ground_excess', 'ground_tested', 'ground_threshold', 'ground_strength',
            'ground_range', 'box_threshold', 'box_strength')

    def __init__(self):
        self.parts: dict[str, list] = {k: [] for k in self.KEYS}

    def add(self, res, ground_ok, on_box, pix_range, width: int, height: int) -> None:
        f = res.features
        if not len(f):
            return
        ui = np.clip(np.rint(f.u_left).astype(int), 0, width - 1)
        vi = np.clip(f.v.astype(int), 0, height - 1)
        sel = ground_ok[vi, ui] & np.isfinite(f.excess)
        box = on_box[vi, ui]
        tested = getattr(f, 'excess_mean', None)
        tested = f.excess if tested is None else np.asarray(tested)
        thr = getattr(f, 'threshold', None)
        thr = (np.full(len(f), res.threshold_px, np.float32) if thr is None
               else np.asarray(thr, np.float32))
        strength = getattr(f, 'strength', None)
        strength = (np.full(len(f), np.nan, np.float32) if strength is None
                    else np.asarray(strength, np.float32))
        p = self.parts
        p['ground_excess'].append(f.excess[sel].astype(np.float32))
        p['ground_tested'].append(tested[sel].astype(np.float32))
        p['ground_threshold'].append(thr[sel])
        p['ground_strength'].append(strength[sel])
        p['ground_range'].append(pix_range[vi[sel], ui[sel]].astype(np.float32))
        p['box_threshold'].append(thr[box])
        p['box_strength'].append(strength[box])

    def arrays(self) -> dict:
        return {k: np.concatenate(v) if v else np.zeros(0, np.float32)
                for k, v in self.parts.items()}


class _SeedScene:
    """The still rig of one seed on its pavement: the renderer, the clear view, and the
    rays through the left pixel centres (optical frame, z = 1) for the ground range."""

    def __init__(self, seed: int, rig_kw: dict, threads: int):
        import zlib

        from asmonc_vision.sim import (Ground, RigPose, RigSettings, StereoRenderer, World,
                                       camera_poses)
        from asmonc_vision.sim.scenarios import random_pavement

        self.seed = seed
        self.rig = rig = RigSettings(**rig_kw)
        self.cam = cam = rig.camera()
        self.salt = zlib.crc32(b'fig5')
        self.rng = np.random.default_rng([seed, self.salt])
        self.ground = Ground(pavement=random_pavement(self.rng))
        self.pose = RigPose(position=np.array([0.0, 0.0, rig.camera_height]),
                            rpy=np.array([0.0, rig.pitch, 0.0]))
        self.left_cam, self.right_cam = camera_poses(self.pose, rig.baseline)
        self.renderer = StereoRenderer(rig, threads=threads)
        self.clear_rad = self.radiance(World(self.ground, [], seed=seed))
        vv, uu = np.mgrid[0:rig.height, 0:rig.width]
        self.rays = np.stack([(uu - cam.cx) / cam.f, (vv - cam.cy) / cam.f,
                              np.ones(uu.shape)], -1)

    def radiance(self, world) -> tuple:
        return (self.renderer.radiance(world, 0.0, self.left_cam),
                self.renderer.radiance(world, 0.0, self.right_cam))

    def pair(self, rad, noise_rng) -> tuple:
        rig = self.rig
        return (self.renderer.sensor(rad[0], rig.left_gain, rig.left_offset, noise_rng),
                self.renderer.sensor(rad[1], rig.right_gain, rig.right_offset, noise_rng))


def _seed_job(seed: int, heights_m: list, ranges_m: list, frames: int, rig_kw: dict,
              config_kw: dict, threads: int) -> dict:
    """All scenes of one seed: per box height, calibrate a fresh detector on the clear
    pavement, then run it on ``frames`` frames with the boxes. Returns plain data."""
    import cv2

    from asmonc_vision.core.config import override
    from asmonc_vision.core.gpod import GpodConfig

    cv2.setNumThreads(1)
    scene = _SeedScene(seed, rig_kw, threads)
    config = override(GpodConfig(), config_kw)
    out = {'seed': seed, 'cases': [], 'missing': [], 'false_obstacles': 0, 'frames': 0,
           'not_tracking': 0}
    log = _FeatureLog()
    for hi, h in enumerate(heights_m):
        _height_job(scene, config, hi, h, ranges_m, frames, out, log)
    arrays = log.arrays()
    return {'seed': seed, 'cases': out['cases'], 'missing': out['missing'], **arrays,
            'false_obstacles': out['false_obstacles'], 'frames': out['frames'],
            'not_tracking': out['not_tracking']}


def _height_job(scene: _SeedScene, config, hi: int, h: float, ranges_m: list, frames: int,
                out: dict, log: _FeatureLog) -> None:
    """One box height of a seed: its scene, a detector calibrated on the clear pavement
    and run on ``frames`` frames; adds to ``out`` ('cases': (height index, range index,
    truth range, frames, detected: a report within the match radius of the box's
    footprint, detected_strict: of its truth point (score_frame)); 'missing': (height
    index, range index) of boxes not in view; counts) and to ``log``."""
    from scipy import ndimage

    from asmonc_vision.core.camera import ground_range_bearing
    from asmonc_vision.core.gpod import GpodDetector
    from asmonc_vision.eval.evaluation import DetectionScore, score_frame
    from asmonc_vision.sim import World, ground_plane_truth, obstacle_truth

    rig, cam, seed = scene.rig, scene.cam, scene.seed
    boxes = place_boxes(scene.rng, h, ranges_m, rig, scene.ground.pavement.brightness)
    world = World(scene.ground, boxes, seed=seed)
    rad = scene.radiance(world)
    depth, labels, faces = scene.renderer.truth(world, 0.0, scene.left_cam)
    plane = ground_plane_truth(world, 0.0, scene.pose, scene.left_cam)
    truth = obstacle_truth(world, 0.0, scene.pose, scene.left_cam, cam, plane, depth,
                           labels, faces)
    truth_fo = _frame_obstacles(truth)
    seen = {o.id for o in truth}
    out['missing'] += [(hi, j) for j in range(len(ranges_m)) if j + 1 not in seen]
    # ground pixels away from obstacles and the sky, and their ranges
    ground_ok = ~ndimage.binary_dilation(labels != 0, iterations=SIGMA_MARGIN_PX)
    on_box = ndimage.binary_dilation(labels > 0, iterations=1)
    pts = scene.rays * depth[..., None]
    pix_range = np.full(depth.shape, np.nan)
    fin = np.isfinite(depth)
    pix_range[fin] = ground_range_bearing(plane, pts[fin])[0]
    det = GpodDetector(config)
    noise = np.random.default_rng([seed, scene.salt, hi, 1])
    for _ in range(config.plane.init_frames + 5):
        res = det.process(*scene.pair(scene.clear_rad, noise), cam)
        if res.status != 'initialising':
            break
    score = DetectionScore()
    feet = [_footprint(b.x, b.y, b.length, b.width, b.yaw_deg) for b in boxes]
    near_box = np.zeros(len(boxes), int)
    for _ in range(frames):
        res = det.process(*scene.pair(rad, noise), cam)
        out['frames'] += 1
        if res.status != 'tracking':
            out['not_tracking'] += 1
        # per-frame detection, as the model: each frame's own detections (no tracks)
        found = [o for o in res.detections if not o.is_drop]
        score_frame(_frame_obstacles(found), truth_fo, score,
                    match_radius=MATCH_RADIUS_M, min_height=0.0, max_range=math.inf)
        # world (x, y) of each report: the rig stands at the origin looking along x,
        # so the point below the left camera is (0, B/2)
        xy = [np.array([o.range * math.cos(o.bearing),
                        rig.baseline / 2.0 + o.range * math.sin(o.bearing)]) for o in found]
        for j, poly in enumerate(feet):
            if any(_distance_to_footprint(poly, q) <= MATCH_RADIUS_M for q in xy):
                near_box[j] += 1
        log.add(res, ground_ok, on_box, pix_range, rig.width, rig.height)
    out['false_obstacles'] += score.false_obstacles
    for j in range(len(ranges_m)):
        rec = score.obstacles.get(j + 1)
        if rec is None:
            continue
        t = next(o for o in truth if o.id == j + 1)
        out['cases'].append((hi, j, float(t.range), rec.frames_eligible, int(near_box[j]),
                             rec.frames_detected))


def _box_bootstrap(detected: list, frames: list, n: int = 2000) -> list:
    """95% interval of the pooled rate sum(detected) / sum(frames), resampling the boxes
    (the frames of one box are strongly correlated: they differ only in camera noise)."""
    if not frames or sum(frames) == 0:
        return [float('nan'), float('nan')]
    d = np.asarray(detected, float)
    f = np.asarray(frames, float)
    idx = np.random.default_rng(0).integers(0, d.size, (n, d.size))
    rates = d[idx].sum(axis=1) / np.maximum(f[idx].sum(axis=1), 1)
    return [float(np.quantile(rates, 0.025)), float(np.quantile(rates, 0.975))]


def _crossing(heights_cm: list, rates: list, level: float) -> float | None:
    """Height (cm) where the measured rate first reaches ``level``, interpolated linearly
    between grid heights; None if it never does."""
    prev = None
    for h, p in zip(heights_cm, rates):
        if not math.isfinite(p):
            continue
        if p >= level:
            if prev is None or prev[1] >= level:
                return float(h)
            h0, p0 = prev
            return float(h0 + (level - p0) * (h - h0) / (p - p0))
        prev = (h, p)
    return None


def sigma_stats(excess: np.ndarray, threshold) -> dict:
    """Spread of the ground features' disparity excess, px: robust (MAD) sigma, plain
    std, std within +-5 px, mean, median, the fraction beyond the threshold (a number, or
    one per feature) and the sigma of a zero-mean Gaussian with that upper-tail fraction
    at the median threshold."""
    from scipy.special import ndtri

    e = np.asarray(excess, float)
    t = np.broadcast_to(np.asarray(threshold, float), e.shape)
    ok = np.isfinite(e) & np.isfinite(t)
    e, t = e[ok], t[ok]
    if e.size == 0:
        return {'n': 0}
    med = float(np.median(e))
    above = float(np.mean(e > t))
    threshold = float(np.median(t))
    core = e[np.abs(e) <= 5.0]
    return {'n': int(e.size), 'sigma_mad': float(1.4826 * np.median(np.abs(e - med))),
            'std': float(np.std(e)), 'std_within_5px': float(np.std(core)),
            'mean': float(np.mean(e)), 'median': med, 'frac_above_threshold': above,
            'sigma_tail': (float(threshold / -ndtri(above)) if 0 < above < 0.5
                           else float('nan'))}


def run_empirical(seeds: int = 20, frames: int = 4, heights_m=None, ranges_m=RANGES_M,
                  rig_kw: dict | None = None, config_kw: dict | None = None,
                  jobs: int = 2, first_seed: int = 0, sigma_px: float | None = None,
                  progress=None, keep: dict | None = None) -> dict:
    """Measure GpodDetector's detection rate of boxes per height and range.

    Args:
        seeds: scenes per box height (seed first_seed .. first_seed + seeds - 1).
        frames: frames with the boxes per scene, after the calibration frames.
        heights_m: box heights, metres (default EMPIRICAL_HEIGHTS_CM).
        ranges_m: box ranges, metres (one box per range per scene).
        rig_kw: RigSettings overrides (default the paper's rig).
        config_kw: GpodConfig overrides (default the detector's defaults).
        jobs: worker processes (1 = in this process). Results do not depend on it.
        sigma_px: sigma for the model columns; None = the measured robust sigma.
        progress: callable(str) for progress lines, or None.
        keep: if a dict, ``keep['excess']`` receives the ground features' excesses
            (px, within the ranges +- 0.5 m), for the histogram.
    Returns:
        A JSON-able dict: the rig and detector settings; ``sigma`` (ground features'
        excess as thresholded) and variants; ``models`` (the model variants compared:
        >= 1 px and >= min_obstacle_pixels at the median threshold of the boxes' edges,
        and the average over that threshold's deciles); ``cells``, per (height, range):
        ``cases`` (box-frames), ``detected``/``rate`` (a report within the match radius of
        the footprint), ``ci95`` (Wilson), ``ci95_boxes`` (bootstrap over boxes),
        ``detected_strict``/``rate_strict`` (score_frame), ``mean_true_range_m``,
        ``model_p`` (per model key); ``agreement`` and ``crossings`` (50% / 90% heights,
        cm) per model; false obstacles, frames and the elapsed time.
    """
    from asmonc_vision.core.config import to_dict
    from asmonc_vision.core.config import override
    from asmonc_vision.core.gpod import GpodConfig
    from asmonc_vision.sim import RigSettings

    heights_m = [h / 100.0 for h in EMPIRICAL_HEIGHTS_CM] if heights_m is None else list(
        map(float, heights_m))
    ranges_m = list(map(float, ranges_m))
    rig_kw = dict(rig_kw or {})
    config_kw = dict(config_kw or {})
    rig = RigSettings(**rig_kw)
    config = override(GpodConfig(), config_kw)
    t0 = time.perf_counter()
    seed_list = list(range(first_seed, first_seed + seeds))
    results = _run_seeds(seed_list, (heights_m, ranges_m, frames, rig_kw, config_kw), jobs,
                         progress or (lambda s: None), t0)
    st = _sigma_and_thresholds(results, ranges_m, config, sigma_px, keep)
    threshold, sigma_model = st['threshold'], st['sigma_model']
    model_rig = ModelRig(rig.focal, rig.baseline, rig.camera_height, rig.camera_pitch_deg)
    m_det = config.detection.min_obstacle_pixels
    models = _models(st['deciles'], threshold, m_det, sigma_model)

    def model_p(md: dict, hs, rs) -> np.ndarray:
        return np.mean([fig5_curves(model_rig, hs, rs, t, sigma_model, md['min_pixels'])
                        for t in md['thresholds_px']], axis=0)

    cells = _cells(results, heights_m, ranges_m, models, model_p)
    out = {
        'command': None,
        'rig': {'focal': rig.focal, 'baseline': rig.baseline, 'camera_height': rig.camera_height,
                'pitch_deg': rig.camera_pitch_deg, 'width': rig.width, 'height': rig.height,
                'noise_sigma': rig.noise_sigma},
        'detector': {'threshold_px': threshold, 'threshold_q10_q50_q90_px': st['thr_q'],
                     'box_threshold_q10_q50_q90_px': st['thr_box_q'],
                     'box_threshold_deciles_px': st['deciles'],
                     'config_threshold_px': config.threshold.px,
                     'threshold_mode': config.threshold.mode,
                     'plane_update': config.plane.update,
                     'min_obstacle_pixels': m_det,
                     'min_matched_run': config.detection.min_matched_run,
                     'init_frames': config.plane.init_frames},
        'seeds': seed_list, 'frames_per_scene': frames, 'heights_cm': [100 * h for h in heights_m],
        'ranges_m': ranges_m, 'match_radius_m': MATCH_RADIUS_M,
        'sigma': st['sig'], 'sigma_raw_excess': st['sig_raw'], 'sigma_box_strength': st['sig_box'],
        'sigma_by_range': st['by_range'],
        'sigma_model_px': sigma_model, 'detector_config': to_dict(config),
        'models': models, 'cells': cells, 'agreement': _agreement(cells, models),
        'crossings': _crossings(cells, ranges_m, models, model_p),
        'false_obstacles': sum(r['false_obstacles'] for r in results),
        'frames': sum(r['frames'] for r in results),
        'frames_not_tracking': sum(r['not_tracking'] for r in results),
        'elapsed_s': time.perf_counter() - t0,
    }
    return out


def _run_seeds(seed_list: list, job_args: tuple, jobs: int, say, t0: float) -> list[dict]:
    """`_seed_job` of every seed, in this process or ``jobs`` workers; sorted by seed."""
    results = []
    if jobs <= 1:
        for k, s in enumerate(seed_list):
            results.append(_seed_job(s, *job_args, threads=2))
            say(f'fig5: seed {s} done ({k + 1}/{len(seed_list)}), '
                f'{time.perf_counter() - t0:.0f} s')
    else:
        import multiprocessing
        ctx = multiprocessing.get_context('spawn')
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            futs = {pool.submit(_seed_job, s, *job_args, threads=1): s for s in seed_list}
            for k, fut in enumerate(as_completed(futs)):
                results.append(fut.result())
                say(f'fig5: seed {futs[fut]} done ({k + 1}/{len(seed_list)}), '
                    f'{time.perf_counter() - t0:.0f} s')
    results.sort(key=lambda r: r['seed'])
    return results


def _sigma_and_thresholds(results: list[dict], ranges_m: list, config, sigma_px,
                          keep: dict | None) -> dict:
    """The thresholds the boxes' edges faced and the ground features' sigma (overall,
    of box-like strengths, raw, per range), and the sigma the model uses."""
    raw = np.concatenate([r['ground_excess'] for r in results])
    excess = np.concatenate([r['ground_tested'] for r in results])
    g_thr = np.concatenate([r['ground_threshold'] for r in results])
    g_rng = np.concatenate([r['ground_range'] for r in results])
    lo_r, hi_r = min(ranges_m) - 0.5, max(ranges_m) + 0.5
    in_span = (g_rng >= lo_r) & (g_rng <= hi_r)
    g_str = np.concatenate([r['ground_strength'] for r in results])
    b_thr = np.concatenate([r['box_threshold'] for r in results])
    b_str = np.concatenate([r['box_strength'] for r in results])
    b_thr = b_thr[np.isfinite(b_thr)]
    # The detector's threshold may be per pixel (by edge strength): the model takes the
    # median threshold of the features on the boxes (what the obstacle's edges face), and
    # sigma from the ground features of the same edge strengths as the boxes' (10-90%).
    thr_span = g_thr[in_span & np.isfinite(g_thr)]
    thr_q = ([float(np.quantile(thr_span, q)) for q in (0.1, 0.5, 0.9)] if thr_span.size
             else [config.threshold.px] * 3)
    thr_box_q = ([float(np.quantile(b_thr, q)) for q in (0.1, 0.5, 0.9)] if b_thr.size
                 else thr_q)
    threshold = thr_box_q[1]
    fin_b = b_str[np.isfinite(b_str)]
    like_box = in_span.copy()
    if fin_b.size:
        s_lo, s_hi = np.quantile(fin_b, [0.1, 0.9])
        like_box &= (g_str >= s_lo) & (g_str <= s_hi)
    sig = sigma_stats(excess[in_span], g_thr[in_span])
    sig_box = sigma_stats(excess[like_box], g_thr[like_box])
    sig_raw = sigma_stats(raw[in_span], g_thr[in_span])
    if keep is not None:
        keep['excess'] = excess[in_span]
    by_range = []
    for r in ranges_m:
        m = np.abs(g_rng - r) <= 0.5
        by_range.append({'range_m': r, **sigma_stats(excess[m], g_thr[m])})
    sigma_model = (sig_box.get('sigma_mad', sig.get('sigma_mad', PAPER_SIGMA_PX))
                   if sigma_px is None else sigma_px)
    if not (sigma_model and math.isfinite(sigma_model) and sigma_model > 0):
        sigma_model = PAPER_SIGMA_PX
    deciles = ([float(np.quantile(b_thr, q)) for q in np.arange(0.05, 1.0, 0.1)]
               if b_thr.size else [threshold])
    return {'thr_q': thr_q, 'thr_box_q': thr_box_q, 'threshold': threshold, 'sig': sig,
            'sig_box': sig_box, 'sig_raw': sig_raw, 'by_range': by_range,
            'sigma_model': sigma_model, 'deciles': deciles}


def _models(deciles: list, threshold: float, m_det: int, sigma_model: float) -> list[dict]:
    """The model variants compared with the measured rates."""
    models = [{'key': 'min1', 'min_pixels': 1, 'thresholds_px': [threshold],
               'label': f'one vertical edge, >= 1 px, threshold {threshold:.2f} px'}]
    if m_det != 1:
        models.append({'key': f'min{m_det}', 'min_pixels': m_det, 'thresholds_px': [threshold],
                       'label': f'one vertical edge, >= {m_det} px, threshold '
                                f'{threshold:.2f} px'})
    if max(deciles) - min(deciles) > 1e-3:
        models.append({'key': f'mix_min{m_det}', 'min_pixels': m_det, 'thresholds_px': deciles,
                       'label': f'>= {m_det} px, averaged over the deciles of the boxes\' '
                                'edge thresholds'})
    for md in models:
        md['sigma_px'] = sigma_model
    return models


def _cells(results: list[dict], heights_m: list, ranges_m: list, models: list,
           model_p) -> list[dict]:
    """Per (height, range): the measured rates with their intervals, and the models'."""
    cells = []
    for hi, h in enumerate(heights_m):
        for j, r in enumerate(ranges_m):
            n = k = ks = 0
            rngs, per_box, frames_box = [], [], []
            for res in results:
                for (a, b, tr, fe, fd, fs) in res['cases']:
                    if a == hi and b == j:
                        n += fe
                        k += fd
                        ks += fs
                        rngs.append(tr)
                        per_box.append(fd)
                        frames_box.append(fe)
            invisible = sum((hi, j) in map(tuple, res['missing']) for res in results)
            mean_r = float(np.mean(rngs)) if rngs else r
            lo, hi_ = _wilson(k, n)
            cells.append({'height_cm': round(100 * h, 3), 'range_m': r, 'cases': n,
                          'detected': k, 'rate': k / n if n else float('nan'),
                          'ci95': [lo, hi_], 'detected_strict': ks,
                          'rate_strict': ks / n if n else float('nan'), 'boxes': len(rngs),
                          'boxes_not_in_view': invisible,
                          'boxes_detected_in_any_frame': int(sum(x > 0 for x in per_box)),
                          'boxes_mixed': int(sum(0 < x < fe
                                                 for x, fe in zip(per_box, frames_box))),
                          'ci95_boxes': _box_bootstrap(per_box, frames_box),
                          'mean_true_range_m': mean_r,
                          'model_p': {md['key']: float(model_p(md, [h], [mean_r])[0, 0])
                                      for md in models}})
    return cells


def _agreement(cells: list[dict], models: list[dict]) -> dict:
    """Per model: the mean absolute difference from the measured rates, in points."""
    valid = [c for c in cells if c['cases']]
    agreement = {}
    for md in models:
        key = md['key']
        # cells where the measured or the modelled rate is neither ~0 nor ~1
        trans = [c for c in valid if max(c['rate'], c['model_p'][key]) >= 0.05
                 and min(c['rate'], c['model_p'][key]) <= 0.95]
        agreement[key] = {
            'mean_abs_diff_points': (100 * float(np.mean([abs(c['rate'] - c['model_p'][key])
                                                          for c in valid])) if valid else None),
            'mean_abs_diff_points_transition': (
                100 * float(np.mean([abs(c['rate'] - c['model_p'][key]) for c in trans]))
                if trans else None),
            'transition_cells': len(trans)}
    return agreement


def _crossings(cells: list[dict], ranges_m: list, models: list[dict], model_p) -> list[dict]:
    """Per range: the 50% and 90% heights (cm), measured and per model."""
    fine = np.linspace(0.0, 0.6, 601)
    crossings = []
    for r in ranges_m:
        col = [c for c in cells if c['range_m'] == r]
        hs = [c['height_cm'] for c in col]
        rates = [c['rate'] if c['cases'] else float('nan') for c in col]
        row = {'range_m': r, 'measured': [_crossing(hs, rates, lv) for lv in (0.5, 0.9)]}
        for md in models:
            p = model_p(md, fine, [r])[:, 0]
            row[md['key']] = [_crossing(list(100 * fine), list(p), lv) for lv in (0.5, 0.9)]
        crossings.append(row)
    return crossings


def empirical_report(res: dict) -> str:
    """The measured tables and sigma, as text: rates (%) per height (rows) and range
    (columns) -- a report near the box's footprint, near its truth point (the strict
    ``score_frame`` convention), and each model variant's."""
    heights = res['heights_cm']
    ranges = res['ranges_m']
    cells = {(c['height_cm'], c['range_m']): c for c in res['cells']}
    det = res['detector']
    sig = res['sigma']
    nan = float('nan')

    def table(title: str, get) -> list[str]:
        out = [title, 'height ' + ''.join(f'{r:>6g} m' for r in ranges)]
        for h in heights:
            vals = []
            for r in ranges:
                c = cells[(round(h, 3), r)]
                v = get(c) if c['cases'] else nan
                vals.append(f'{100 * v:7.0f}%' if math.isfinite(v) else f'{"--":>8}')
            out.append(f'{h:4g} cm' + ''.join(vals))
        return out + ['']

    n_cases = max((c['cases'] for c in res['cells']), default=0)
    q10, q50, q90 = det['threshold_q10_q50_q90_px']
    b10, b50, b90 = det['box_threshold_q10_q50_q90_px']
    r = res['rig']
    lines = [f"GpodDetector (plane {det['plane_update']}, threshold mode "
             f"{det['threshold_mode']}: median {b50:.2f} px on the boxes' edges (10-90% "
             f"{b10:.2f}-{b90:.2f}), {q50:.2f} px on the ground's ({q10:.2f}-{q90:.2f}); "
             f"min_obstacle_pixels {det['min_obstacle_pixels']}, min_matched_run "
             f"{det['min_matched_run']}) on boxes, {len(res['seeds'])} seeds x "
             f"{res['frames_per_scene']} frames = up to {n_cases} (box, frame) cases per cell; "
             f"rig f {r['focal']:g} px, I {r['baseline']:g} m, H {r['camera_height']:g} m, "
             f"pitch {r['pitch_deg']:g} deg, standing still", '']
    lines += table(f'measured: a report within {res["match_radius_m"]:g} m of the box\'s '
                   'footprint on the ground', lambda c: c['rate'])
    lines += table(f'measured, strict: within {res["match_radius_m"]:g} m of the box\'s '
                   'truth point (its nearest visible part, eval.evaluation)',
                   lambda c: c['rate_strict'])
    for md in res['models']:
        lines += table(f"model, {md['label']}, sigma {md['sigma_px']:.3f} px",
                       lambda c, k=md['key']: c['model_p'][k])
    raw = res.get('sigma_raw_excess', {})
    lines += [f"ground-feature excess as thresholded (ground range {min(ranges) - 0.5:g}-"
              f"{max(ranges) + 0.5:g} m, n = {sig.get('n', 0)}): sigma (MAD) "
              f"{sig.get('sigma_mad', nan):.3f} px (single-frame excess: "
              f"{raw.get('sigma_mad', nan):.3f} px), std {sig.get('std', nan):.3f} px (within "
              f"+-5 px {sig.get('std_within_5px', nan):.3f}), median "
              f"{sig.get('median', nan):+.3f} px, beyond the threshold "
              f"{100 * sig.get('frac_above_threshold', nan):.2f}% (Gaussian tail sigma "
              f"{sig.get('sigma_tail', nan):.3f} px); ground features as strong as the boxes' "
              f"edges: sigma (MAD) {res['sigma_box_strength'].get('sigma_mad', nan):.3f} px",
              'sigma (MAD) by range: ' + ', '.join(
                  f"{b['range_m']:g} m {b.get('sigma_mad', nan):.2f}"
                  for b in res['sigma_by_range']),
              f"the models use sigma {res['sigma_model_px']:.3f} px", '',
              'mean |measured - model| (points of detection rate): all cells / the cells '
              'where either is between 5% and 95%']
    for md in res['models']:
        ag = res['agreement'][md['key']]
        lines.append(f"  {md['key']:>9}: {_fmt(ag['mean_abs_diff_points'])} / "
                     f"{_fmt(ag['mean_abs_diff_points_transition'])} "
                     f"({ag['transition_cells']} cells)")
    lines += ['', 'height (cm) detected 50% / 90% of the time:',
              '   range   measured' + ''.join(f"{md['key']:>15}" for md in res['models'])]
    for c in res['crossings']:
        pairs = [c['measured']] + [c[md['key']] for md in res['models']]
        lines.append(f"  {c['range_m']:4g} m " + ''.join(
            f'{_fmt(a):>7} /{_fmt(b):>5}  ' for a, b in pairs).rstrip())
    lines += ['',
              f"false obstacles: {res['false_obstacles']} in {res['frames']} frames; frames "
              f"without a tracked plane: {res['frames_not_tracking']}; "
              f"{res['elapsed_s']:.0f} s"]
    return '\n'.join(lines)


def _fmt(x) -> str:
    return '--' if x is None or not math.isfinite(x) else f'{x:.1f}'


def plot_empirical(res: dict, path: Path, excess: np.ndarray | None = None) -> None:
    """Measured rates (markers, Wilson 95% intervals) over the model's curves (measured
    sigma, the detector's threshold), one panel per range, and sigma's panel."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    ranges = res['ranges_m']
    det = res['detector']
    r = res['rig']
    rig = ModelRig(r['focal'], r['baseline'], r['camera_height'], r['pitch_deg'])
    sigma = res['sigma_model_px']
    thr = det['threshold_px']
    hmax = max(res['heights_cm']) * 1.1
    hs = np.linspace(0.0, hmax / 100.0, 200)
    n_pan = len(ranges) + 1
    cols = 4
    rows = int(math.ceil(n_pan / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(11, 2.6 * rows + 0.5), dpi=80,
                             squeeze=False)
    styles = [dict(color='C0', lw=1.2), dict(color='C0', lw=1.0, ls='--'),
              dict(color='C2', lw=1.4)]
    for ax, rr in zip(axes.ravel(), ranges):
        cells = [c for c in res['cells'] if c['range_m'] == rr and c['cases']]
        for md, st in zip(res['models'], styles):
            p = np.mean([fig5_curves(rig, hs, [rr], t, sigma, md['min_pixels'])[:, 0]
                         for t in md['thresholds_px']], axis=0)
            thr_txt = (f"T {md['thresholds_px'][0]:.2f} px" if len(md['thresholds_px']) == 1
                       else "T: deciles on the boxes' edges")
            ax.plot(100 * hs, p, label=f"model, >= {md['min_pixels']} px, {thr_txt}", **st)
        ax.plot(100 * hs, fig5_curves(rig, hs, [rr], PAPER_THRESHOLD_PX, PAPER_SIGMA_PX, 1)[:, 0],
                color='0.6', lw=0.8, ls=':', label='paper: T 1.7 px, sigma 1, >= 1 px')
        if cells:
            h = np.array([c['height_cm'] for c in cells])
            p = np.array([c['rate'] for c in cells])
            lo = np.array([c['ci95'][0] for c in cells])
            hi = np.array([c['ci95'][1] for c in cells])
            yerr = [np.maximum(p - lo, 0.0), np.maximum(hi - p, 0.0)]
            ax.errorbar(h, p, yerr=yerr, fmt='o', color='C3', ms=4, capsize=2,
                        label='measured: report within 0.3 m of the footprint (Wilson 95%)')
            ax.plot(h, [c['rate_strict'] for c in cells], 'o', mfc='none', color='C1', ms=6,
                    label='measured: within 0.3 m of the truth point')
        ax.set_title(f'{rr:g} m', fontsize=9)
        ax.set_xlim(0, hmax)
        ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.set_xlabel('box height (cm)', fontsize=8)
    axes.ravel()[0].set_ylabel('detection rate', fontsize=8)
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    ax = axes.ravel()[len(ranges)]
    sig = res['sigma']
    if excess is not None and excess.size:
        bins = np.linspace(-5, 5, 101)
        ax.hist(np.clip(excess, -5, 5), bins=bins, density=True, color='0.6')
        x = np.linspace(-5, 5, 400)
        ax.plot(x, np.exp(-0.5 * ((x - sig['median']) / sigma) ** 2)
                / (sigma * math.sqrt(2 * math.pi)), color='C0', lw=1)
        ax.axvline(thr, color='C3', lw=0.8, ls='--')
        ax.set_yscale('log')
        ax.set_ylim(1e-4, 5.0)
    ax.set_title(f"ground excess: sigma {sig.get('sigma_mad', float('nan')):.2f} px (MAD)",
                 fontsize=9)
    ax.set_xlabel('excess (px, clipped to +-5)', fontsize=8)
    ax.tick_params(labelsize=7)
    for extra in axes.ravel()[n_pan:]:
        extra.axis('off')
    fig.suptitle(f"Fig. 5, measured: GpodDetector (threshold {det['threshold_mode']}, median "
                 f"{thr:.2f} px on the boxes' edges, plane {det['plane_update']}) on simulated "
                 f"boxes, {len(res['seeds'])} seeds x {res['frames_per_scene']} frames\n"
                 f"models: one vertical edge, sigma {sigma:.2f} px (measured), exact geometry "
                 f"of the rig pitched {r['pitch_deg']:g} deg", fontsize=9)
    fig.legend(handles, labels, loc='lower center', ncol=3, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def _write_json(path: Path, obj: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(json_ready(obj), indent=1, allow_nan=False) + '\n')


def _parse_params(items: list, cls) -> dict:
    """NAME=VALUE strings to settings of the dataclass ``cls`` (a group's as
    GROUP.NAME), typed as its defaults."""
    from asmonc_vision.core.config import flat_fields

    fields = dict(flat_fields(cls))
    out = {}
    for item in items:
        name, sep, text = item.partition('=')
        name = name.strip()
        if not sep or name not in fields:
            raise ValueError(f'--param {item!r}: expected NAME=VALUE with NAME one of '
                             f'{cls.__name__} settings')
        default = fields[name].default
        if isinstance(default, bool):
            if text.lower() not in ('true', 'false', '1', '0'):
                raise ValueError(f'--param {name}: expected true or false, got {text!r}')
            out[name] = text.lower() in ('true', '1')
        elif isinstance(default, int):
            out[name] = int(text)
        elif isinstance(default, float):
            out[name] = float(text)
        else:
            out[name] = text
    return out


def _run_empirical_cli(args) -> int:
    from asmonc_vision.core.config import override
    from asmonc_vision.core.gpod import GpodConfig
    from asmonc_vision.sim import RigSettings

    if args.seeds < 1 or args.frames < 1 or args.jobs < 1:
        print('asmonc fig5: --seeds, --frames and --jobs must be >= 1', file=sys.stderr)
        return 2
    rig_kw = {'focal': args.focal, 'baseline': args.baseline, 'camera_height': args.height}
    if args.pitch_deg is not None:
        rig_kw['camera_pitch_deg'] = args.pitch_deg
    config_kw = {}
    if args.threshold is not None:
        config_kw['threshold.px'] = args.threshold
    if args.plane_update is not None:
        config_kw['plane.update'] = args.plane_update
    try:
        config_kw.update(_parse_params(args.param, GpodConfig))
        RigSettings(**rig_kw)
        override(GpodConfig(), config_kw)
    except (ValueError, TypeError) as exc:
        print(f'asmonc fig5: {exc}', file=sys.stderr)
        return 2
    if any(h <= 0 for h in args.heights_cm) or any(r <= 0 for r in args.ranges):
        print('asmonc fig5: --heights-cm and --ranges must be > 0', file=sys.stderr)
        return 2
    excess_holder = {}

    def progress(s: str) -> None:
        print(s, file=sys.stderr, flush=True)

    res = run_empirical(args.seeds, args.frames, [h / 100.0 for h in args.heights_cm],
                        args.ranges, rig_kw, config_kw, args.jobs, args.first_seed,
                        args.sigma, progress, keep=excess_holder)
    res['command'] = 'asmonc ' + ' '.join(sys.argv[1:])
    print(empirical_report(res))
    if args.png is not None:
        plot_empirical(res, args.png, excess_holder.get('excess'))
        print(f'figure: {args.png}')
    if args.json is not None:
        _write_json(args.json, res)
        print(f'json: {args.json}')
    return 0
