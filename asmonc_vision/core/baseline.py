"""The baseline a ROS user would pick today: dense OpenCV StereoSGBM and a disparity plane.

Per stereo pair, with no state between frames:

1. **Disparity** by ``cv2.StereoSGBM`` (semi-global block matching, Hirschmüller 2008)
   on the rectified mono8 pair. Parameters (see `SgbmConfig`):

   * ``minDisparity = 0``; ``numDisparities = f·B / min_range_m`` rounded *up* to a
     multiple of 16 (112 px on the paper's rig, f·B = 105 px·m, min range 1 m; 224 px at
     640×480 with f = 600), so that everything farther than ``min_range_m`` is searched.
   * ``blockSize = 5``; smoothness penalties ``P1 = 8·blockSize²``, ``P2 = 32·blockSize²``
     (the values OpenCV's documentation and samples recommend for one channel).
   * ``uniquenessRatio = 10`` %, ``speckleWindowSize = 100`` px, ``speckleRange = 2``
     (×16 internally), ``disp12MaxDiff = 1`` px (left-right check), ``preFilterCap = 63``,
     ``mode = MODE_SGBM`` (5 paths, one pass).
   * OpenCV leaves the leftmost ``numDisparities`` columns without a disparity. With
     ``pad_left`` (default) the pair is padded on the left by ``numDisparities`` columns
     (edge pixels replicated) and the padding cropped off afterwards, so that every
     pixel whose match lies inside the right image can get a disparity, as with GPOD.
     It costs time (a wider image); ``pad_left = False`` is plain ``stereo_image_proc``.

2. **Ground plane** ``d = a·u + b·v + c`` in cyclopean coordinates (``u = u_left - d/2``,
   as `core.camera`): RANSAC on minimal triples (``ransac_iterations`` = 100) over at most
   ``fit_max_points`` (2000) valid pixels drawn at random (``rng``) from the lower part
   of the image (rows below ``fit_from_row`` × height), the hypothesis with most pixels
   within ``plane_inlier_px`` (1 px) wins, then least squares on its inliers among all
   the lower image's valid pixels (twice). The plane must
   put the left camera between ``min_camera_height_m`` and ``max_camera_height_m`` above
   the ground and tilt its normal at most ``max_plane_tilt_deg`` from the camera's up
   axis, or the frame is ``'lost'`` (no obstacles).

3. **Obstacles**, searched where the plane is ground within ``max_range_m`` (plane
   disparity >= f·B/max_range_m) and among disparities up to f·B/min_range_m (the
   rounding of numDisparities adds a few nearer ones): pixels whose disparity exceeds
   the plane's by more than ``threshold_px`` (1.7 px, the paper's threshold), at most
   ``max_obstacle_height_m`` above the ground and whose foot is within ``max_range_m``;
   a morphological opening (``opening_px``) removes isolated pixels; 8-connected
   components of at least ``min_component_fraction`` of the image's pixels are
   obstacles. The search region keeps out the sky and the far field, where SGBM's
   mismatches in textureless regions pile up at the top of the search range (points
   at head height ~1 m ahead; without it, ~2 false obstacles per frame on the bundled
   bags). Each obstacle is described as GPOD describes one (same fields, via
   `core.camera`): its height is the 90th percentile of its pixels' heights above the
   plane, its foot the median of the nearest tenth of its pixels' feet along the
   ground, its position the top above that foot, its range and bearing those of
   `core.camera.ground_range_bearing`, its roi the component's box extended down to
   the foot's row. No drop-offs.

Use: ``SgbmBaseline(SgbmConfig()).process(left, right, cam)`` -> `SgbmResult` (status
``'tracking'`` or ``'lost'``, obstacles, plane, timings).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .camera import MetricPlane, StereoCamera, ground_range_bearing
from .config import param
from .ground_plane import PlausiblePlaneConfig, plane_is_plausible

#: StereoSGBM modes by name.
SGBM_MODES = ('sgbm', 'hh', '3way', 'hh4')


@dataclass(frozen=True)
class SgbmConfig(PlausiblePlaneConfig):
    """Settings of the SGBM baseline (validated on construction)."""

    # --- StereoSGBM ----------------------------------------------------------------
    min_range_m: float = param(
        1.0, 'Nearest depth searched, metres along the optical axis: numDisparities = '
        'f*B/min_range_m rounded up to a multiple of 16', range=(0.05, 100.0))
    block_size: int = param(5, 'SGBM matched block size, pixels (odd)', range=(1, 51))
    p1_factor: float = param(
        8.0, 'SGBM P1 (penalty of a disparity change of 1 px) = p1_factor * block_size^2',
        range=(0.0, 1000.0))
    p2_factor: float = param(
        32.0, 'SGBM P2 (penalty of larger disparity changes) = p2_factor * block_size^2 '
        '(must exceed P1)', range=(0.0, 10000.0))
    uniqueness_ratio: int = param(
        10, 'SGBM uniquenessRatio: margin, percent, by which the best cost must win',
        range=(0, 100))
    speckle_window_px: int = param(
        100, 'SGBM speckleWindowSize: largest disparity blob treated as noise, pixels '
        '(0 = no speckle filter)', range=(0, 10000))
    speckle_range_px: int = param(
        2, 'SGBM speckleRange: largest disparity variation within a blob, pixels',
        range=(0, 64))
    disp12_max_diff_px: int = param(
        1, 'SGBM disp12MaxDiff: left-right consistency tolerance, pixels (-1 = off)',
        range=(-1, 100))
    pre_filter_cap: int = param(63, 'SGBM preFilterCap (x-derivative clip)', range=(1, 63))
    texture_threshold: float = param(
        0.0, 'Texture threshold (as StereoBM\'s textureThreshold, which StereoSGBM lacks): '
        'pixels whose block (block_size square) has a mean |horizontal Sobel derivative| of '
        'the left image below this get no disparity, grey levels per pixel (0 = off)',
        range=(0.0, 255.0))
    mode: str = param('sgbm', "SGBM mode: 'sgbm' (5 paths), 'hh' (8 paths, full-image "
                      "memory), '3way' (faster), 'hh4'", choices=SGBM_MODES)
    pad_left: bool = param(
        True, 'Pad the pair on the left by numDisparities columns so that the left band '
        'OpenCV leaves without disparity is matched too (costs time)')
    # --- ground plane ----------------------------------------------------------------
    fit_from_row: float = param(
        0.5, 'The plane is fitted on valid pixels below this fraction of the image height '
        '(the lower image: mostly ground)', range=(0.0, 0.95))
    fit_max_points: int = param(
        2000, 'At most this many pixels (drawn at random) take part in the RANSAC search '
        '(the least-squares refinement uses all of them)',
        range=(10, 10000000))
    ransac_iterations: int = param(100, 'RANSAC hypotheses per frame', range=(1, 100000))
    plane_inlier_px: float = param(
        1.0, 'RANSAC inlier bound, pixels of disparity', range=(0.05, 20.0))
    min_plane_inliers: int = param(
        100, 'Least number of inlier pixels for a valid plane', range=(3, 10000000))
    # --- obstacles -------------------------------------------------------------------
    threshold_px: float = param(
        1.7, 'Disparity excess over the plane above which a pixel is an obstacle pixel, '
        'pixels (the paper\'s 1.7)', range=(0.05, 50.0))
    max_range_m: float = param(
        10.0, 'Obstacles are searched only where the plane is ground nearer than this '
        '(plane disparity >= f*B/max_range_m), and pixels whose foot is farther than this '
        'along the ground are ignored, metres', range=(0.1, 1000.0))
    max_obstacle_height_m: float = param(
        2.5, 'Pixels higher than this above the plane are ignored (overhead), metres',
        range=(0.05, 100.0))
    opening_px: int = param(
        1, 'Radius of the morphological opening of the obstacle mask, pixels (0 = none)',
        range=(0, 20))
    min_component_fraction: float = param(
        2.5e-4, 'Least area of an obstacle component as a fraction of the image '
        '(19 px at 320x240, 77 px at 640x480)', range=(0.0, 1.0))
    seed: int = param(0, 'Seed of the random generator of the RANSAC plane fit',
                      range=(0, 2 ** 31 - 1))

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.block_size % 2 == 0:
            raise ValueError(f'SgbmConfig.block_size = {self.block_size} must be odd')
        if self.p2_factor <= self.p1_factor:
            raise ValueError(f'SgbmConfig.p2_factor = {self.p2_factor} must exceed '
                             f'p1_factor = {self.p1_factor}')

    def num_disparities(self, cam: StereoCamera) -> int:
        """numDisparities for a camera: f*B/min_range_m rounded up to a multiple of 16."""
        return max(16, int(math.ceil(cam.fb / self.min_range_m / 16.0)) * 16)


@dataclass(frozen=True)
class SgbmObstacle:
    """One obstacle found by the baseline (fields as `core.gpod.GpodObstacle`).

    Attributes:
        position: (3,) the obstacle's top above its foot (the median of the nearest tenth
            of its pixels' feet), metres, left optical frame.
        height: metres above the ground plane.
        range: metres along the ground from the point below the left camera to the foot.
        bearing: radians, positive left.
        width: metres, lateral extent of the component's feet.
        disparity_excess: pixels, largest excess over the plane in the component.
        confidence: 0..1 (the component's area relative to 10x the least area, capped).
        roi: (x, y, w, h) in the left image.
        num_pixels: pixels of the component.
    """

    position: np.ndarray
    height: float
    range: float
    bearing: float
    width: float
    disparity_excess: float
    confidence: float
    roi: tuple[int, int, int, int]
    num_pixels: int


@dataclass(frozen=True)
class SgbmPlane:
    """The frame's ground plane: ``abc`` (d = a*u + b*v + c), ``metric`` (left optical
    frame), ``num_inliers`` and ``residual_rms`` (px) of the fit."""

    abc: np.ndarray
    metric: MetricPlane
    num_inliers: int
    residual_rms: float


@dataclass(frozen=True)
class SgbmResult:
    """What the baseline found in one stereo pair.

    Attributes:
        status: 'tracking' (a plausible plane was fitted) or 'lost'.
        obstacles: nearest first (empty when lost).
        plane: the ground plane, or None when lost.
        disparity: (H, W) float32 disparity map of the left image, pixels (NaN = none).
        num_disparities: the SGBM search range used.
        timings_ms: stage -> ms ('sgbm', 'plane', 'obstacles', 'total').
    """

    status: str
    obstacles: tuple[SgbmObstacle, ...]
    plane: SgbmPlane | None
    disparity: np.ndarray
    num_disparities: int
    timings_ms: dict

    @property
    def timings(self) -> dict:
        """Alias of ``timings_ms``."""
        return self.timings_ms

    @property
    def metric_plane(self) -> MetricPlane | None:
        return self.plane.metric if self.plane is not None else None


def fit_disparity_plane(u: np.ndarray, v: np.ndarray, d: np.ndarray, rng, *,
                        iterations: int = 100, inlier_px: float = 1.0,
                        max_points: int = 2000) -> tuple[np.ndarray, np.ndarray, float] | None:
    """RANSAC plane ``d = a*u + b*v + c`` then least squares on the inliers (twice).

    Args:
        u, v, d: (N,) cyclopean columns, rows, disparities (pixels).
        rng: int seed or numpy Generator (subsampling and the minimal triples).
        iterations: RANSAC hypotheses; inlier_px: inlier bound (px);
        max_points: at most this many points (drawn at random) are used.
    Returns:
        (abc (3,), inliers (N,) bool over the input, residual RMS px), or None when no
        plane can be fitted (fewer than 3 points, degenerate).
    """
    rng = np.random.default_rng(rng)
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    d = np.asarray(d, float)
    n = u.size
    if n < 3:
        return None
    sel = rng.choice(n, max_points, replace=False) if n > max_points else np.arange(n)
    A = np.stack([u[sel], v[sel], np.ones(sel.size)], axis=1)
    ds = d[sel]
    tri = rng.integers(0, sel.size, (iterations, 3))   # repeated points: det = 0, skipped
    M = A[tri]                                    # (I, 3, 3)
    det = np.linalg.det(M)
    ok = np.abs(det) > 1e-6
    if not ok.any():
        return None
    hyp = np.linalg.solve(M[ok], ds[tri[ok]][..., None])[..., 0]   # (I', 3)
    us, vs = A[:, 0][:, None], A[:, 1][:, None]
    res = us * hyp[:, 0][None, :] + vs * hyp[:, 1][None, :] + hyp[:, 2][None, :] - ds[:, None]
    counts = np.count_nonzero(np.abs(res) <= inlier_px, axis=0)
    abc = hyp[int(np.argmax(counts))]
    inl = np.abs(abc[0] * u + abc[1] * v + abc[2] - d) <= inlier_px
    for _ in range(2):
        if inl.sum() < 3:
            return None
        ui, vi, di = u[inl], v[inl], d[inl]
        abc, *_ = np.linalg.lstsq(np.stack([ui, vi, np.ones(ui.size)], axis=1), di, rcond=None)
        inl = np.abs(abc[0] * u + abc[1] * v + abc[2] - d) <= inlier_px
    if inl.sum() < 3:
        return None
    res = abc[0] * u[inl] + abc[1] * v[inl] + abc[2] - d[inl]
    return np.asarray(abc, float), inl, float(np.sqrt(np.mean(res ** 2)))


class SgbmBaseline:
    """Dense SGBM disparity, RANSAC disparity plane, connected components (module doc).

    Call :meth:`process` on each rectified pair; frames are independent, except that the
    RANSAC generator (seeded by ``config.seed``) runs on from frame to frame.
    """

    def __init__(self, config: SgbmConfig | None = None) -> None:
        self.config = config if config is not None else SgbmConfig()
        self._rng = np.random.default_rng(self.config.seed)
        self._matcher: object | None = None
        self._matcher_nd: int | None = None

    def _sgbm(self, nd: int):
        import cv2

        if self._matcher is None or self._matcher_nd != nd:
            c = self.config
            modes = {'sgbm': cv2.STEREO_SGBM_MODE_SGBM, 'hh': cv2.STEREO_SGBM_MODE_HH,
                     '3way': cv2.STEREO_SGBM_MODE_SGBM_3WAY, 'hh4': cv2.STEREO_SGBM_MODE_HH4}
            bs = c.block_size
            self._matcher = cv2.StereoSGBM.create(
                minDisparity=0, numDisparities=nd, blockSize=bs,
                P1=int(round(c.p1_factor * bs * bs)), P2=int(round(c.p2_factor * bs * bs)),
                disp12MaxDiff=c.disp12_max_diff_px, preFilterCap=c.pre_filter_cap,
                uniquenessRatio=c.uniqueness_ratio, speckleWindowSize=c.speckle_window_px,
                speckleRange=c.speckle_range_px, mode=modes[c.mode])
            self._matcher_nd = nd
        return self._matcher

    def disparity(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera
                  ) -> tuple[np.ndarray, int]:
        """(H, W) float32 SGBM disparity of the left image (NaN where none), and
        numDisparities."""
        import cv2

        nd = self.config.num_disparities(cam)
        matcher = self._sgbm(nd)
        pad = nd if self.config.pad_left else 0
        weak = self.weak_texture(left)
        if pad:
            left = cv2.copyMakeBorder(left, 0, 0, pad, 0, cv2.BORDER_REPLICATE)
            right = cv2.copyMakeBorder(right, 0, 0, pad, 0, cv2.BORDER_REPLICATE)
        raw = matcher.compute(left, right)[:, pad:]
        disp = raw.astype(np.float32) / 16.0
        # valid: inside the search range, and the match inside the real right image
        uu = np.arange(disp.shape[1], dtype=np.float32)[None, :]
        bad = (raw < 0) | (disp <= 0) | (uu - disp < -0.5)
        if weak is not None:
            bad |= weak
        disp[bad] = np.nan
        return disp, nd

    def weak_texture(self, left: np.ndarray) -> np.ndarray | None:
        """(H, W) bool: pixels whose block has too little texture (``texture_threshold``),
        or None when the threshold is off."""
        import cv2

        t = self.config.texture_threshold
        if t <= 0:
            return None
        gx = np.abs(cv2.Sobel(left, cv2.CV_32F, 1, 0, ksize=3)) / 4.0   # grey levels / px
        bs = self.config.block_size
        return cv2.blur(gx, (bs, bs), borderType=cv2.BORDER_REPLICATE) < t

    def process(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera) -> SgbmResult:
        """Detect obstacles in one rectified stereo pair.

        Raises:
            ValueError: images that are not 2-D uint8 arrays of the camera's size.
        """
        import cv2

        for name, img in (('left', left), ('right', right)):
            if not isinstance(img, np.ndarray) or img.dtype != np.uint8 or img.ndim != 2:
                raise ValueError(f'{name} image must be a 2-D uint8 array')
            if img.shape != (cam.height, cam.width):
                raise ValueError(f'{name} image is {img.shape[1]}x{img.shape[0]}, camera '
                                 f'is {cam.width}x{cam.height}')
        c = self.config
        t0 = time.perf_counter()
        disp, nd = self.disparity(left, right, cam)
        t1 = time.perf_counter()
        h, w = disp.shape
        vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
        valid = np.isfinite(disp)
        uc = uu - np.where(valid, disp, 0.0) / 2.0        # cyclopean column
        low = valid & (vv >= c.fit_from_row * h)
        fit = fit_disparity_plane(uc[low], vv[low], disp[low].astype(np.float64), self._rng,
                                  iterations=c.ransac_iterations, inlier_px=c.plane_inlier_px,
                                  max_points=c.fit_max_points)
        plane = None
        if fit is not None and int(fit[1].sum()) >= c.min_plane_inliers:
            metric = plane_is_plausible(cam, fit[0], **c.plausibility())
            if metric is not None:
                plane = SgbmPlane(abc=np.asarray(fit[0], float), metric=metric,
                                  num_inliers=int(fit[1].sum()), residual_rms=fit[2])
        t2 = time.perf_counter()
        obstacles: tuple[SgbmObstacle, ...] = ()
        if plane is not None:
            obstacles = self._obstacles(disp, valid, uc, vv, cam, plane, cv2)
        t3 = time.perf_counter()
        timings = {'sgbm': (t1 - t0) * 1e3, 'plane': (t2 - t1) * 1e3,
                   'obstacles': (t3 - t2) * 1e3, 'total': (t3 - t0) * 1e3}
        return SgbmResult(status='tracking' if plane is not None else 'lost',
                          obstacles=obstacles, plane=plane, disparity=disp,
                          num_disparities=nd, timings_ms=timings)

    def _obstacles(self, disp, valid, uc, vv, cam: StereoCamera, plane: SgbmPlane, cv2
                   ) -> tuple[SgbmObstacle, ...]:
        c = self.config
        a, b, cc = plane.abc
        pd = a * uc + b * vv + cc
        excess = np.where(valid, disp - pd, -np.inf)
        # The search region: where the plane is ground within max_range_m (so the sky
        # and the far field, where SGBM's textureless mismatches pile up at the top of
        # the search range, are not searched), and disparities within min_range_m.
        cand = ((excess > c.threshold_px) & (pd >= cam.fb / c.max_range_m)
                & (disp <= cam.fb / c.min_range_m))
        iy, ix = np.nonzero(cand)
        if iy.size == 0:
            return ()
        metric = plane.metric
        n_up = metric.normal_up
        pts = cam.triangulate(uc[iy, ix], vv[iy, ix], disp[iy, ix])
        hh = metric.signed_height(pts)
        feet = pts - hh[:, None] * n_up[None, :]
        rng_ = np.linalg.norm(feet + metric.height * n_up[None, :], axis=1)
        keep = (hh <= c.max_obstacle_height_m) & (rng_ <= c.max_range_m)
        mask = np.zeros(disp.shape, np.uint8)
        mask[iy[keep], ix[keep]] = 1
        if c.opening_px > 0:
            size = 2 * c.opening_px + 1
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((size, size), np.uint8))
        n_lab, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        min_area = max(1, int(math.ceil(c.min_component_fraction * cam.width * cam.height)))
        fwd = np.array([0.0, 0.0, 1.0]) - n_up[2] * n_up
        fwd /= np.linalg.norm(fwd)
        lft = np.cross(n_up, fwd)
        origin = -metric.height * n_up
        # The opening only removes pixels: every component pixel is a candidate.
        lab_c = labels[iy, ix]
        order = np.argsort(lab_c, kind='stable')
        bounds = np.flatnonzero(np.r_[True, np.diff(lab_c[order]) != 0, True])
        out = []
        for s0, s1 in zip(bounds[:-1], bounds[1:]):
            k = order[s0:s1]
            lab = int(lab_c[k[0]])
            if lab == 0 or int(stats[lab, cv2.CC_STAT_AREA]) < min_area:
                continue
            out.append(self._describe(k, int(stats[lab, cv2.CC_STAT_AREA]), min_area, pts, hh,
                                      feet, excess[iy[k], ix[k]], stats[lab], cam, metric,
                                      fwd, lft, origin))
        out.sort(key=lambda o: o.range)
        return tuple(out)

    def _describe(self, k, area, min_area, pts, hh, feet, ex, stat, cam, metric, fwd, lft,
                  origin) -> SgbmObstacle:
        import cv2

        height = float(np.quantile(hh[k], 0.9))
        g = feet[k] - origin[None, :]
        g2 = np.stack([g @ fwd, g @ lft], axis=1)
        r = np.hypot(g2[:, 0], g2[:, 1])
        near = r <= np.quantile(r, 0.1)
        foot = np.median(feet[k][near], axis=0)
        position = foot + height * metric.normal_up
        rr, bb = ground_range_bearing(metric, position[None, :])
        centre = np.median(g2, axis=0)
        norm = float(np.hypot(*centre))
        across = np.array([-centre[1], centre[0]]) / norm if norm > 1e-9 else np.array([0.0, 1.0])
        lat = g2 @ across
        x0, y0 = int(stat[cv2.CC_STAT_LEFT]), int(stat[cv2.CC_STAT_TOP])
        x1 = x0 + int(stat[cv2.CC_STAT_WIDTH]) - 1
        y1 = y0 + int(stat[cv2.CC_STAT_HEIGHT]) - 1
        if foot[2] > 1e-6:
            v_foot = cam.f * foot[1] / foot[2] + cam.cy
            if np.isfinite(v_foot):
                y1 = max(y1, int(round(min(v_foot, cam.height - 1))))
        return SgbmObstacle(
            position=position.astype(np.float64), height=height, range=float(rr[0]),
            bearing=float(bb[0]), width=float(lat.max() - lat.min()),
            disparity_excess=float(ex.max()),
            confidence=float(min(1.0, area / (10.0 * min_area))),
            roi=(x0, y0, x1 - x0 + 1, y1 - y0 + 1), num_pixels=area)
