"""Ground Plane Obstacle Detection (GPOD), after Molton, Se, Brady et al. (1998), Sec. 2.

Per stereo pair:

1. Vertical edges in both images and edge strings (:mod:`.edges`).
2. Row-wise PMF matching of the edges (:mod:`.matching`): features (u_left, u_right, v, d).
3. The ground plane ``d = a*u + b*v + c`` (cyclopean, :mod:`.ground_plane`): calibrated
   from the features of the first ``init_frames`` frames (assumed obstacle-free, as in
   the paper, but fitted robustly anyway), then either kept fixed (``'fixed'``, the
   paper's GPOD) or refitted every frame (``'refit'``, so that a walking wearer keeps a
   plane): a coarse robust fit on the nearer half of the features within
   ``refit_gate_px`` of the predicted plane, then a fine fit on the features within
   ``refit_gate_m`` of the coarse plane, accepted if it moved the plane plausibly little
   and smoothed by a constant-plane Kalman filter. This is a step towards the paper's
   dynamic recalibration, which will add a motion model to the prediction. The RANSAC
   fits weigh features by disparity cubed: of two surfaces, the near one -- the ground
   the wearer stands on -- wins.
4. Obstacles: a matched edge pixel whose disparity exceeds the plane's by more than
   ``threshold_px`` (1.7 px in the paper) is an obstacle pixel, if it lies in a run of at
   least ``min_matched_run`` disparity-consistent matched pixels of its edge string
   (figural continuity: isolated mismatches never make obstacles). An edge string is an
   obstacle if at least ``min_obstacle_pixels`` of its pixels are (1 is the paper's
   rule "any pixel"; the default 2 also rejects single-pixel excursions of far ground).
   Pixels below the plane by more than the threshold (a disparity deficit where the
   ground should be) make drop-offs: hazards with negative height. Obstacle strings are
   clustered by the proximity of their feet on the ground, and each cluster is reported
   with its top, height, range, bearing, width, disparity excess, confidence and image
   region.

Status per frame: ``'initialising'`` (not enough calibration frames yet), ``'tracking'``
(a plane is valid for this frame, refitted or carried over for up to
``max_coast_frames``) or ``'lost'`` (no plane could be fitted or carried over). A frame
without a plane is a return value, never an exception.
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from .camera import MetricPlane, StereoCamera, ground_range_bearing, plane_disparity
from .config import check_fields, param
from .edges import EdgeMap, detect_vertical_edges
from .ground_plane import PlaneFit, fit_ground_plane, plane_is_plausible
from .matching import Matches, match_edges

#: Detector statuses (GroundPlane.msg: INITIALISING = 0, TRACKING = 1, LOST = 2).
STATUSES = ('initialising', 'tracking', 'lost')


@dataclass(frozen=True)
class GpodConfig:
    """Settings of the GPOD detector (validated on construction)."""

    # --- detection ---------------------------------------------------------------
    threshold_px: float = param(
        1.7, 'Disparity excess over the ground plane above which an edge pixel is an '
        'obstacle, pixels (Molton et al. 1998 use 1.7)', range=(0.05, 50.0))
    min_range_m: float = param(
        1.0, 'Nearest depth searched by the matcher, metres along the optical axis '
        '(largest disparity f*B/min_range)', range=(0.05, 100.0))
    max_range_m: float = param(
        10.0, 'Obstacles whose foot is farther than this along the ground are not reported, '
        'metres', range=(0.1, 1000.0))
    search_max_range_m: float = param(
        1000.0, 'Farthest depth searched by the matcher, metres (smallest disparity '
        'f*B/this); keep it far beyond max_range_m so that distant features find their '
        'true match rather than a wrong one inside the range', range=(0.1, 1.0e6))
    # --- ground plane ------------------------------------------------------------
    init_frames: int = param(
        3, 'Frames, assumed obstacle-free, whose features calibrate the initial ground '
        'plane (accumulated, fitted robustly)', range=(1, 1000))
    plane_update: str = param(
        'refit', "'fixed': keep the calibrated plane (the paper's GPOD); 'refit': robust "
        'refit every frame from features near the predicted plane, smoothed',
        choices=('fixed', 'refit'))
    refit_gate_px: float = param(
        8.0, 'Features within this disparity of the predicted plane take part in the '
        'coarse per-frame refit (wide enough for the walking motion between frames), '
        'pixels', range=(0.1, 100.0))
    refit_gate_m: float = param(
        0.1, 'Features within this height of the coarse plane take part in the fine '
        'per-frame refit, metres (keeps the ground beyond a step or on a kerb out)',
        range=(0.001, 100.0))
    refit_process_noise_px: float = param(
        1.0, "'refit': expected change of the ground disparity from one frame to the next "
        '(walking motion), pixels; the per-frame refits are smoothed by a Kalman filter '
        'that weighs this against the fit covariance (small = smooth, large = follow the '
        'fit)', range=(0.001, 100.0))
    plane_method: str = param(
        'ransac', 'Robust plane fit: RANSAC then least squares on the inliers, or '
        'iteratively trimmed least squares', choices=('ransac', 'trimmed'))
    plane_inlier_px: float = param(
        1.0, 'Inlier bound of the robust plane fit, pixels of disparity', range=(0.05, 20.0))
    ransac_iterations: int = param(
        1000, 'Most RANSAC hypotheses per plane fit (it stops earlier once 99% sure)',
        range=(1, 100000))
    min_plane_features: int = param(
        30, 'Least number of inlier features for a valid plane fit', range=(3, 1000000))
    max_coast_frames: int = param(
        2, "'refit': frames the last plane may be carried over when a refit fails "
        '(status tracking, plane not updated) before the status becomes lost',
        range=(0, 100000))
    refit_max_height_change_m: float = param(
        0.1, "'refit': a refit that moves the camera height by more than this from the "
        'current plane is rejected (another surface, e.g. the ground beyond a step), metres',
        range=(0.001, 100.0))
    refit_max_angle_change_deg: float = param(
        8.0, "'refit': a refit that turns the plane normal by more than this from the "
        'current plane is rejected, degrees', range=(0.01, 90.0))
    recover_height_tolerance: float = param(
        0.3, "'refit': when lost (gated refits failed for longer than max_coast_frames), "
        'an ungated refit is accepted if its camera height is within this fraction of the '
        'calibrated one',
        range=(0.0, 10.0))
    recover_max_angle_deg: float = param(
        25.0, "'refit': ... and its normal within this angle of the calibrated normal, "
        'degrees', range=(0.0, 90.0))
    min_camera_height_m: float = param(
        0.2, 'A plane is plausible only if the left camera is at least this high above it, '
        'metres', range=(0.0, 100.0))
    max_camera_height_m: float = param(
        5.0, 'A plane is plausible only if the left camera is at most this high above it, '
        'metres', range=(0.01, 1000.0))
    max_plane_tilt_deg: float = param(
        75.0, "A plane is plausible only if its up normal is within this angle of the "
        "camera's up axis (-y), degrees", range=(1.0, 90.0))
    # --- edges ---------------------------------------------------------------------
    edge_threshold: float = param(
        4.0, 'Least horizontal intensity gradient of a vertical edge, grey levels per pixel',
        range=(0.0, 255.0))
    edge_rel_threshold: float = param(
        0.0, 'Least horizontal gradient as a multiple of the mean |dI/du| of the image '
        '(0 = off); the larger of the two thresholds applies', range=(0.0, 100.0))
    edge_max_angle_deg: float = param(
        60.0, 'Largest angle of an edge from the vertical, degrees', range=(1.0, 90.0))
    edge_blur_sigma: float = param(
        0.0, 'Gaussian pre-blur of the images before the Sobel operator, pixels (0 = none)',
        range=(0.0, 10.0))
    min_string_length: int = param(
        3, 'Edge strings shorter than this many pixels are dropped', range=(1, 100000))
    # --- matching ------------------------------------------------------------------
    match_min_strength_ratio: float = param(
        0.5, 'Least ratio of the weaker to the stronger edge strength of a match',
        range=(0.0, 1.0))
    match_max_orientation_diff_deg: float = param(
        30.0, 'Largest difference of gradient directions of a match, degrees',
        range=(0.0, 180.0))
    pmf_support_radius_px: float = param(
        3.0, 'PMF support neighbourhood radius in the left image, pixels', range=(1.0, 30.0))
    pmf_disparity_gradient_limit: float = param(
        1.0, 'PMF disparity-gradient limit (1.0 in PMF)', range=(0.05, 1.95))
    pmf_iterations: int = param(
        2, 'PMF winner-take-all rounds (1 = one pass)', range=(1, 50))
    pmf_min_support: float = param(
        0.5, 'Least PMF support of an accepted match (sum of 1/distance)', range=(0.0, 1000.0))
    # --- obstacles -----------------------------------------------------------------
    min_matched_run: int = param(
        5, 'An obstacle or drop pixel counts only within a run of at least this many '
        'consecutive matched pixels of its edge string whose disparities agree (figural '
        'continuity; isolated mismatches never make obstacles)', range=(1, 100000))
    string_disparity_tolerance_px: float = param(
        1.0, 'Largest disparity difference between consecutive pixels of one matched run, '
        'pixels', range=(0.01, 100.0))
    min_obstacle_pixels: int = param(
        2, 'Obstacle pixels an edge string needs to be an obstacle; 1 is the rule of '
        'Molton et al. (any pixel), 2 rejects single-pixel excursions of far ground',
        range=(1, 100000))
    detect_drops: bool = param(
        True, 'Report drop-offs (disparity below the ground plane) as negative obstacles')
    min_drop_pixels: int = param(
        3, 'Pixels below the plane by more than the threshold that an edge string needs '
        'to be a drop-off', range=(1, 100000))
    min_drop_cluster_pixels: int = param(
        15, 'Drop pixels a drop-off needs in all (a drop is a region, not a lone string)',
        range=(1, 1000000))
    drop_cluster_radius_m: float = param(
        1.0, 'Drop strings whose feet are closer than this join one drop-off, metres',
        range=(0.01, 100.0))
    max_drop_depth_m: float = param(
        1.5, 'Pixels more than this far below the plane are ignored (mismatches), metres',
        range=(0.01, 100.0))
    max_obstacle_height_m: float = param(
        2.5, 'Pixels higher than this above the plane are ignored (overhead, no hazard), '
        'metres', range=(0.05, 100.0))
    cluster_radius_m: float = param(
        0.5, 'Obstacle strings whose feet on the ground are closer than this join one '
        'obstacle (a gap narrower than this cannot be walked through), metres',
        range=(0.01, 10.0))
    disparity_sigma_px: float = param(
        1.0, 'Standard deviation of the disparity excess of ground features, pixels (the '
        "paper's sigma = 1), for the confidence", range=(0.01, 20.0))
    confidence_full_pixels: int = param(
        20, 'Obstacle pixels at which the confidence is no longer reduced for small '
        'evidence (confidence = P(any pixel truly beyond the threshold) * '
        'min(1, pixels / this))', range=(1, 100000))
    seed: int = param(0, 'Seed of the random generator of the robust plane fit',
                      range=(0, 2 ** 31 - 1))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.min_range_m >= self.search_max_range_m:
            raise ValueError(f'GpodConfig.min_range_m = {self.min_range_m} must be less than '
                             f'search_max_range_m = {self.search_max_range_m}')
        if self.max_range_m > self.search_max_range_m:
            raise ValueError(f'GpodConfig.max_range_m = {self.max_range_m} must not exceed '
                             f'search_max_range_m = {self.search_max_range_m}')
        if self.min_camera_height_m >= self.max_camera_height_m:
            raise ValueError(
                f'GpodConfig.min_camera_height_m = {self.min_camera_height_m} must be less '
                f'than max_camera_height_m = {self.max_camera_height_m}')


@dataclass(frozen=True)
class GpodObstacle:
    """One obstacle (or drop-off, with negative height) found in a stereo pair.

    Attributes:
        position: (3,) float64 the obstacle's top (for a drop: the lowest point seen),
            above its nearest foot, metres, left optical frame.
        height: metres above the ground plane (negative for a drop-off).
        range: metres along the ground from the point below the left camera to the foot.
        bearing: radians in the ground plane from the walking direction, positive left.
        width: metres, lateral extent of the feet seen (0 for a single edge string).
        disparity_excess: pixels, measured minus plane disparity, largest in magnitude
            over the obstacle's pixels (negative for a drop-off).
        confidence: 0..1.
        roi: (x, y, w, h) ints, region in the left image (from the top of the obstacle
            down to its foot on the ground).
        num_edge_pixels: matched edge pixels beyond the threshold in the obstacle.
        string_ids: (k,) int32 ids of its edge strings (left EdgeMap).
    """

    position: np.ndarray
    height: float
    range: float
    bearing: float
    width: float
    disparity_excess: float
    confidence: float
    roi: tuple[int, int, int, int]
    num_edge_pixels: int
    string_ids: np.ndarray

    @property
    def is_drop(self) -> bool:
        """True for a drop-off (a step down), i.e. negative height."""
        return self.height < 0


@dataclass(frozen=True)
class GpodFeatures:
    """Matched edge features of one frame, for drawing and diagnostics.

    Attributes:
        u_left: (K,) float32 sub-pixel column in the left image, pixels.
        u_right: (K,) float32 sub-pixel column in the right image, pixels.
        v: (K,) int32 row, pixels.
        d: (K,) float32 disparity, pixels.
        excess: (K,) float32 disparity minus plane disparity, pixels (NaN without plane).
        is_obstacle: (K,) bool, pixel beyond the obstacle threshold (counted).
        is_drop: (K,) bool, pixel below the plane by more than the threshold (counted).
        string_class: (K,) int8 class of the pixel's edge string: 1 obstacle, -1 drop,
            0 ground / unclassified.
        string_id: (K,) int32 edge-string id (left EdgeMap).
    """

    u_left: np.ndarray
    u_right: np.ndarray
    v: np.ndarray
    d: np.ndarray
    excess: np.ndarray
    is_obstacle: np.ndarray
    is_drop: np.ndarray
    string_class: np.ndarray
    string_id: np.ndarray

    def __len__(self) -> int:
        return int(self.v.shape[0])


@dataclass(frozen=True)
class GpodPlane:
    """The ground plane of one frame, ``d = a*u + b*v + c`` (cyclopean pixels).

    Attributes:
        abc: (3,) float64 (a, b, c).
        cov: (3, 3) float64 covariance of (a, b, c).
        num_features: features used by the last plane fit.
        residual_rms: RMS disparity residual of the last plane fit, pixels.
        metric: the plane in the left optical frame.
        updated: True when the plane was (re)fitted on this frame.
    """

    abc: np.ndarray
    cov: np.ndarray
    num_features: int
    residual_rms: float
    metric: MetricPlane
    updated: bool


@dataclass(frozen=True)
class GpodResult:
    """Everything GPOD found in one stereo pair.

    Attributes:
        status: 'initialising' | 'tracking' | 'lost'.
        frame_index: frames processed since the last reset, counting this one (1-based).
        plane_abc: (3,) float64 plane (a, b, c) used for this frame, or None.
        plane_cov: (3, 3) float64 covariance of plane_abc, or None.
        plane_num_features: features used by the last plane fit (0 if none).
        plane_residual_rms: RMS residual of the last plane fit, pixels (NaN if none).
        plane_updated: True when the plane was (re)fitted on this frame.
        metric_plane: the plane in the left optical frame, or None.
        obstacles: obstacles and drop-offs, nearest first.
        features: the matched edge features.
        threshold_px: the obstacle threshold used, pixels.
        num_edges: (left, right) numbers of edge pixels.
        timings_ms: stage -> milliseconds ('edges', 'matching', 'plane', 'obstacles',
            'total').
    """

    status: str
    frame_index: int
    plane_abc: np.ndarray | None
    plane_cov: np.ndarray | None
    plane_num_features: int
    plane_residual_rms: float
    plane_updated: bool
    metric_plane: MetricPlane | None
    obstacles: tuple[GpodObstacle, ...]
    features: GpodFeatures
    threshold_px: float
    num_edges: tuple[int, int]
    timings_ms: dict[str, float]

    @property
    def plane(self) -> GpodPlane | None:
        """The plane fields as one object, or None when the frame has no plane."""
        if self.plane_abc is None or self.metric_plane is None:
            return None
        return GpodPlane(abc=self.plane_abc, cov=self.plane_cov,
                         num_features=self.plane_num_features,
                         residual_rms=self.plane_residual_rms, metric=self.metric_plane,
                         updated=self.plane_updated)

    @property
    def timings(self) -> dict[str, float]:
        """Alias of ``timings_ms`` (stage -> milliseconds)."""
        return self.timings_ms


def _normal_cdf(x: np.ndarray) -> np.ndarray:
    """Standard normal CDF (Abramowitz & Stegun 7.1.26 erf, |error| < 1.5e-7)."""
    z = np.abs(np.asarray(x, np.float64)) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.3275911 * z)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
                                                       + t * (-1.453152027 + t * 1.061405429))))
    erf = 1.0 - poly * np.exp(-z * z)
    return 0.5 * (1.0 + np.sign(x) * erf)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of an undirected graph with n nodes and edges (a, b).

    Returns:
        (n,) int64 label of each node, 0..C-1 in order of first node.
    """
    label = np.arange(n, dtype=np.int64)
    if a.size:
        while True:
            la, lb = label[a], label[b]
            m = np.minimum(la, lb)
            new = label.copy()
            np.minimum.at(new, la, m)
            np.minimum.at(new, lb, m)
            while True:                       # pointer jumping to the roots
                nxt = new[new]
                if np.array_equal(nxt, new):
                    break
                new = nxt
            if np.array_equal(new, label):
                break
            label = new
    _, comp = np.unique(label, return_inverse=True)
    return comp.astype(np.int64)


def cluster_points_2d(points: np.ndarray, group: np.ndarray, radius: float) -> np.ndarray:
    """Single-linkage clustering of groups of 2-D points.

    Two groups join when any of their points are within ``radius`` of each other (to
    within ``radius / 4``: points of one group are thinned to one per square of side
    ``radius / 4`` first); the points of one group always stay together.

    Args:
        points: (N, 2) float64 coordinates, metres.
        group: (N,) int group id of each point (e.g. edge string), >= 0.
        radius: linking distance, metres (> 0).
    Returns:
        (N,) int64 cluster label of each point, 0..C-1.
    """
    n = points.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    _, g = np.unique(group, return_inverse=True)
    g = g.astype(np.int64)
    n_g = int(g.max()) + 1
    # Thin: one point per (group, fine cell).
    fine = np.floor((points - points.min(axis=0)) / (radius / 4.0)).astype(np.int64)
    fkey = (g * (int(fine[:, 0].max()) + 1) + fine[:, 0]) * (int(fine[:, 1].max()) + 1) + fine[:, 1]
    _, rep = np.unique(fkey, return_index=True)
    pts, gr = points[rep], g[rep]
    nr = pts.shape[0]
    cell = np.floor((pts - pts.min(axis=0)) / radius).astype(np.int64) + 1
    span = int(cell[:, 1].max()) + 3
    key = cell[:, 0] * span + cell[:, 1]
    order = np.argsort(key, kind='stable')
    skey = key[order]
    src, dst = [], []
    for ox, oz in ((0, 0), (1, -1), (1, 0), (1, 1), (0, 1)):
        target = skey + ox * span + oz
        lo = np.searchsorted(skey, target, side='left')
        hi = np.searchsorted(skey, target, side='right')
        cnt = hi - lo
        tot = int(cnt.sum())
        if tot == 0:
            continue
        i = np.repeat(np.arange(nr), cnt)
        j = np.arange(tot) + np.repeat(lo - (np.cumsum(cnt) - cnt), cnt)
        pi, pj = order[i], order[j]
        ok = gr[pi] != gr[pj]
        pi, pj = pi[ok], pj[ok]
        diff = pts[pi] - pts[pj]
        close = np.einsum('ij,ij->i', diff, diff) <= radius * radius
        src.append(gr[pi[close]])
        dst.append(gr[pj[close]])
    a = np.concatenate(src) if src else np.zeros(0, np.int64)
    b = np.concatenate(dst) if dst else np.zeros(0, np.int64)
    if a.size:
        pair = np.unique(a * n_g + b)
        a, b = pair // n_g, pair % n_g
    return _components(n_g, a, b)[g]


def matched_run_length(edges: EdgeMap, m: Matches, tolerance_px: float) -> np.ndarray:
    """Length of the disparity-consistent matched run that each match belongs to.

    A run is a maximal chain of matches on consecutive pixels of one edge string (rows
    v, v+1, ...) whose disparities differ by at most ``tolerance_px`` from one pixel to
    the next.

    Args:
        edges: the left EdgeMap the matches index (for ``string_prev``).
        m: the matches.
        tolerance_px: largest disparity step within a run, pixels.
    Returns:
        (K,) int64 run length (>= 1) of each match.
    """
    k = len(m)
    if k == 0:
        return np.zeros(0, np.int64)
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    prev_edge = edges.string_prev[m.left_index]
    prev = np.where(prev_edge >= 0, feat_of_edge[np.maximum(prev_edge, 0)], -1)
    d = m.d.astype(np.float64)
    link = (prev >= 0) & (np.abs(d - d[np.maximum(prev, 0)]) <= tolerance_px)
    root = np.where(link, prev, np.arange(k))
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    return np.bincount(root, minlength=k)[root]


class GpodDetector:
    """The GPOD obstacle detector with ground-plane calibration and per-frame refit.

    Call :meth:`process` on every rectified stereo pair, in order. The detector keeps
    the ground plane between frames; it resets itself when the camera changes, and
    :meth:`reset` starts a new calibration.
    """

    def __init__(self, config: GpodConfig | None = None) -> None:
        self.config = config if config is not None else GpodConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the ground plane and the calibration frames (status 'initialising')."""
        self._cam: StereoCamera | None = None
        self._rng = np.random.default_rng(self.config.seed)
        self._init_window: deque = deque(maxlen=self.config.init_frames)
        self._frame = 0
        self._calib: PlaneFit | None = None
        self._abc: np.ndarray | None = None
        self._cov: np.ndarray | None = None
        self._last_fit: PlaneFit | None = None
        self._coast = 0

    @property
    def calibrated_plane(self) -> PlaneFit | None:
        """The plane fitted on the calibration frames, or None while initialising."""
        return self._calib

    # ------------------------------------------------------------------ helpers
    def _check_images(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera) -> None:
        """Raise ValueError unless both images are 2-D uint8 of the camera's size."""
        for name, img in (('left', left), ('right', right)):
            if not isinstance(img, np.ndarray):
                raise ValueError(f'{name} image must be a numpy array, got {type(img).__name__}')
            if img.dtype != np.uint8 or img.ndim != 2:
                raise ValueError(f'{name} image must be a 2-D uint8 array (H, W), got '
                                 f'{img.dtype} with shape {img.shape}')
            if img.shape != (cam.height, cam.width):
                raise ValueError(f'{name} image shape {img.shape} differs from the camera '
                                 f'size (height {cam.height}, width {cam.width})')

    def _fit(self, u, v, d, cam: StereoCamera) -> PlaneFit | None:
        """Robust, plausibility-checked plane fit of features (u, v, d) with the settings."""
        c = self.config
        # Weighted by disparity cubed: of two competing surfaces (the ground here and the
        # ground beyond a step), the nearer one is the one the wearer stands on; far
        # features, least flat and least well measured, count little.
        return fit_ground_plane(
            u, v, d, cam=cam, method=c.plane_method, inlier_threshold_px=c.plane_inlier_px,
            iterations=c.ransac_iterations, weights=np.maximum(d, 0.0) ** 3,
            min_features=c.min_plane_features,
            min_height_m=c.min_camera_height_m, max_height_m=c.max_camera_height_m,
            max_tilt_deg=c.max_plane_tilt_deg, rng=self._rng)

    def _near_calibration(self, fit: PlaneFit) -> bool:
        """Whether an ungated refit is close enough to the calibrated plane to trust."""
        c = self.config
        cal = self._calib.metric if self._calib is not None else None
        if cal is None or fit.metric is None:
            return False
        if abs(fit.metric.height - cal.height) > c.recover_height_tolerance * cal.height:
            return False
        cosang = float(np.clip(np.dot(fit.metric.normal_up, cal.normal_up), -1.0, 1.0))
        return math.degrees(math.acos(cosang)) <= c.recover_max_angle_deg

    def _close_to_current(self, fit: PlaneFit, cam: StereoCamera) -> bool:
        """Whether a refit is within the per-frame change limits of the current plane."""
        c = self.config
        cur = plane_is_plausible(cam, self._abc, min_height_m=0.0, max_height_m=float('inf'),
                                 max_tilt_deg=90.0)
        if cur is None or fit.metric is None:
            return False
        if abs(fit.metric.height - cur.height) > c.refit_max_height_change_m:
            return False
        cosang = float(np.clip(np.dot(fit.metric.normal_up, cur.normal_up), -1.0, 1.0))
        return math.degrees(math.acos(cosang)) <= c.refit_max_angle_change_deg

    def _update_plane(self, u, v, d, cam: StereoCamera) -> tuple[str, bool]:
        """Advance the plane state with this frame's features. Returns (status, updated)."""
        c = self.config
        if self._calib is None:
            self._init_window.append((u, v, d))
            if len(self._init_window) < c.init_frames:
                return 'initialising', False
            uu, vv, dd = (np.concatenate(x) for x in zip(*self._init_window))
            fit = self._fit(uu, vv, dd, cam)
            if fit is None:
                return 'initialising', False
            self._calib = self._last_fit = fit
            self._abc, self._cov = fit.abc.copy(), fit.cov.copy()
            self._init_window.clear()
            return 'tracking', True
        enough = u.shape[0] >= c.min_plane_features
        if c.plane_update == 'fixed':
            # The plane is known, but a frame with too few features cannot vouch that
            # nothing stands on it: lost, as in 'refit' mode.
            return ('tracking', False) if enough else ('lost', False)
        fit = None
        current = plane_is_plausible(cam, self._abc, min_height_m=0.0,
                                     max_height_m=float('inf'), max_tilt_deg=90.0)
        if enough and current is not None:
            # Coarse refit from the nearer half of the features near the predicted plane
            # in disparity (a gate wide enough for walking motion), then a fine refit
            # from all features near the coarse plane in disparity *and* metric height,
            # so that another surface (the ground beyond a step, a kerb top) cannot
            # take over.
            gate = np.abs(d - plane_disparity(self._abc, u, v)) <= c.refit_gate_px
            if gate.any():      # the coarse fit sees only the nearer half: the ground here
                gate &= d >= np.median(d[gate])
            coarse = self._fit(u[gate], v[gate], d[gate], cam)
            if coarse is not None:
                height = coarse.metric.signed_height(cam.triangulate(u, v, d))
                gate = ((np.abs(d - plane_disparity(coarse.abc, u, v)) <= c.refit_gate_px)
                        & (np.abs(height) <= c.refit_gate_m))
                fit = self._fit(u[gate], v[gate], d[gate], cam)
            if fit is not None and not self._close_to_current(fit, cam):
                fit = None
        if fit is None and enough and self._coast >= c.max_coast_frames:
            # Lost: recover from the nearer half of the features (the ground the wearer
            # stands on, rather than the ground beyond a step) if the result is near the
            # calibration.
            near = d >= np.median(d)
            ungated = self._fit(u[near], v[near], d[near], cam)
            if ungated is not None and self._near_calibration(ungated):
                fit = ungated
        if fit is None:
            if self._coast < c.max_coast_frames and enough:
                self._coast += 1
                return 'tracking', False
            self._coast = c.max_coast_frames      # stay lost until a refit succeeds
            return 'lost', False
        # Kalman filter, constant-plane model: predict with the walking process noise,
        # update with the refit and its covariance.
        sq = c.refit_process_noise_px ** 2
        q = np.diag([sq / (0.5 * cam.width) ** 2, sq / (0.5 * cam.height) ** 2, sq])
        p_pred = self._cov + q
        gain = p_pred @ np.linalg.inv(p_pred + fit.cov)
        self._abc = self._abc + gain @ (fit.abc - self._abc)
        self._cov = (np.eye(3) - gain) @ p_pred
        self._last_fit = fit
        self._coast = 0
        return 'tracking', True

    # ------------------------------------------------------------------ main
    def process(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera) -> GpodResult:
        """Detect obstacles in one rectified stereo pair.

        Args:
            left, right: (H, W) uint8 rectified grey images, H = cam.height, W = cam.width.
            cam: the rectified stereo camera. A camera different from the previous
                call's resets the detector.
        Returns:
            The GpodResult (status 'initialising', 'tracking' or 'lost').
        Raises:
            ValueError: images that are not 2-D uint8 arrays of the camera's size.
        """
        t_start = time.perf_counter()
        self._check_images(left, right, cam)
        if self._cam is not None and cam != self._cam:
            self.reset()
        self._cam = cam
        self._frame += 1
        c = self.config
        timings: dict[str, float] = {}

        t0 = time.perf_counter()
        edge_kw = dict(abs_threshold=c.edge_threshold, rel_threshold=c.edge_rel_threshold,
                       max_angle_deg=c.edge_max_angle_deg, min_string_length=c.min_string_length,
                       blur_sigma=c.edge_blur_sigma)
        el = detect_vertical_edges(left, **edge_kw)
        er = detect_vertical_edges(right, **edge_kw)
        t1 = time.perf_counter()
        timings['edges'] = (t1 - t0) * 1e3

        d_min, d_max = self.disparity_range(cam)
        m = match_edges(el, er, d_min, d_max, min_strength_ratio=c.match_min_strength_ratio,
                        max_orientation_diff_deg=c.match_max_orientation_diff_deg,
                        support_radius=c.pmf_support_radius_px,
                        disparity_gradient_limit=c.pmf_disparity_gradient_limit,
                        iterations=c.pmf_iterations, min_support=c.pmf_min_support)
        t2 = time.perf_counter()
        timings['matching'] = (t2 - t1) * 1e3

        u = m.u
        v = m.v.astype(np.float64)
        d = m.d.astype(np.float64)
        status, updated = self._update_plane(u, v, d, cam)
        t3 = time.perf_counter()
        timings['plane'] = (t3 - t2) * 1e3

        metric = None
        obstacles: tuple[GpodObstacle, ...] = ()
        if status == 'tracking':
            metric = plane_is_plausible(cam, self._abc, min_height_m=0.0,
                                        max_height_m=float('inf'), max_tilt_deg=90.0)
        if status == 'tracking' and metric is not None:
            features, obstacles = self._detect(m, u, v, d, cam, metric, d_min, d_max, el)
        else:
            if status == 'tracking':          # smoothing made an implausible plane
                status = 'lost'
            features = _features(m, np.full(len(m), np.nan, np.float32))
        t4 = time.perf_counter()
        timings['obstacles'] = (t4 - t3) * 1e3
        timings['total'] = (t4 - t_start) * 1e3

        have_plane = status == 'tracking'
        fit = self._last_fit
        return GpodResult(
            status=status, frame_index=self._frame,
            plane_abc=self._abc.copy() if have_plane else None,
            plane_cov=self._cov.copy() if have_plane else None,
            plane_num_features=fit.num_features if (fit is not None and have_plane) else 0,
            plane_residual_rms=(fit.residual_rms if (fit is not None and have_plane)
                                else float('nan')),
            plane_updated=bool(updated and have_plane), metric_plane=metric if have_plane else None,
            obstacles=obstacles, features=features, threshold_px=c.threshold_px,
            num_edges=(len(el), len(er)), timings_ms=timings)

    def disparity_range(self, cam: StereoCamera) -> tuple[float, float]:
        """Disparity search range (d_min, d_max) of the matcher, pixels, from
        ``search_max_range_m`` and ``min_range_m`` (d_max at most the image width - 1)."""
        d_min = cam.fb / self.config.search_max_range_m
        d_max = min(cam.fb / self.config.min_range_m, float(cam.width - 1))
        return d_min, max(d_max, d_min)

    # ------------------------------------------------------------------ obstacles
    def _detect(self, m: Matches, u, v, d, cam: StereoCamera, metric: MetricPlane,
                d_min: float, d_max: float, el: EdgeMap
                ) -> tuple[GpodFeatures, tuple[GpodObstacle, ...]]:
        c = self.config
        pd = plane_disparity(self._abc, u, v)
        excess = d - pd
        pts = cam.triangulate(u, v, d)
        h = metric.signed_height(pts)
        feet = pts - h[:, None] * metric.normal_up[None, :]
        ground_range = np.linalg.norm(feet + metric.height * metric.normal_up[None, :], axis=1)
        reliable = matched_run_length(el, m, c.string_disparity_tolerance_px) >= c.min_matched_run
        in_range = ground_range <= c.max_range_m
        obst = (excess > c.threshold_px) & (h <= c.max_obstacle_height_m) & reliable & in_range
        drop = np.zeros_like(obst)
        if c.detect_drops:
            # Below the plane where the plane itself is within the detection range.
            pd_far = cam.fb / c.max_range_m
            drop = ((excess < -c.threshold_px) & (pd >= pd_far) & (pd <= d_max)
                    & (h >= -c.max_drop_depth_m) & reliable & in_range)
        sid = m.string_id
        n_s = max(el.num_strings, int(sid.max()) + 1 if sid.size else 0)
        n_obst = np.bincount(sid[obst], minlength=n_s)
        n_drop = np.bincount(sid[drop], minlength=n_s)
        obst_string = n_obst >= c.min_obstacle_pixels
        drop_string = ~obst_string & (n_drop >= c.min_drop_pixels)
        obst &= obst_string[sid]
        drop &= drop_string[sid]
        sclass = np.where(obst_string[sid], 1, np.where(drop_string[sid], -1, 0)).astype(np.int8)
        features = _features(m, excess.astype(np.float32), obst, drop, sclass)
        found: list[GpodObstacle] = []
        for sel, sign, radius, min_px in (
                (obst, 1.0, c.cluster_radius_m, 1),
                (drop, -1.0, c.drop_cluster_radius_m, c.min_drop_cluster_pixels)):
            idx = np.flatnonzero(sel)
            if idx.size:
                found.extend(self._clusters(idx, sign, radius, min_px, m, pts, h, excess,
                                            cam, metric))
        found.sort(key=lambda o: o.range)
        return features, tuple(found)

    def _clusters(self, idx: np.ndarray, sign: float, radius: float, min_pixels: int,
                  m: Matches, pts: np.ndarray, h: np.ndarray, excess: np.ndarray,
                  cam: StereoCamera, metric: MetricPlane) -> list[GpodObstacle]:
        """Cluster the selected pixels (by string, feet proximity) into obstacles; drop
        clusters of fewer than ``min_pixels`` pixels."""
        c = self.config
        n_up = metric.normal_up
        p = pts[idx]
        hh = h[idx]
        feet = p - hh[:, None] * n_up[None, :]
        fwd = np.array([0.0, 0.0, 1.0]) - n_up[2] * n_up
        fwd /= np.linalg.norm(fwd)
        lft = np.cross(n_up, fwd)
        origin = -metric.height * n_up
        g = feet - origin[None, :]
        g2 = np.stack([g @ fwd, g @ lft], axis=1)
        label = cluster_points_2d(g2, m.string_id[idx], radius)
        rng_px = np.hypot(g2[:, 0], g2[:, 1])
        out = []
        order = np.argsort(label, kind='stable')
        bounds = np.flatnonzero(np.r_[True, np.diff(label[order]) != 0, True])
        for s0, s1 in zip(bounds[:-1], bounds[1:]):
            k = order[s0:s1]
            if k.size < min_pixels:
                continue
            out.append(self._describe(idx[k], sign, hh[k], feet[k], g2[k], rng_px[k], m,
                                      excess, cam, metric, fwd, lft))
        return out

    def _describe(self, ids, sign, hh, feet, g2, rng_px, m: Matches, excess, cam, metric,
                  fwd, lft) -> GpodObstacle:
        c = self.config
        n = ids.size
        height = float(np.quantile(hh, 0.9 if sign > 0 else 0.1))
        r_near = np.quantile(rng_px, 0.1 if sign > 0 else 0.02)   # a drop starts at its near edge
        near = int(np.argmin(np.abs(rng_px - r_near)))
        foot = feet[near]
        position = foot + height * metric.normal_up
        rng_, brg = ground_range_bearing(metric, position[None, :])
        # Lateral extent of the feet across the line of sight to their median.
        centre = np.median(g2, axis=0)
        norm = float(np.hypot(*centre))
        across = np.array([-centre[1], centre[0]]) / norm if norm > 1e-9 else np.array([0.0, 1.0])
        lat = g2 @ across
        width = float(lat.max() - lat.min())
        ex = excess[ids]
        exc = float(ex.max()) if sign > 0 else float(ex.min())
        z = (np.abs(ex) - c.threshold_px) / c.disparity_sigma_px
        p_i = np.clip(_normal_cdf(z), 0.0, 1.0 - 1e-12)
        p_any = 1.0 - math.exp(float(np.sum(np.log1p(-p_i))))
        conf = p_any * min(1.0, n / c.confidence_full_pixels)
        ul = m.u_left[ids]
        vv = m.v[ids]
        x0, x1 = int(np.floor(ul.min())), int(np.ceil(ul.max()))
        y0, y1 = int(vv.min()), int(vv.max())
        if sign > 0 and foot[2] > 1e-6:      # extend down to where the obstacle meets the ground
            v_foot = cam.f * foot[1] / foot[2] + cam.cy
            if np.isfinite(v_foot):
                y1 = max(y1, int(round(min(v_foot, cam.height - 1))))
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, cam.width - 1), min(y1, cam.height - 1)
        roi = (x0, y0, max(x1 - x0 + 1, 1), max(y1 - y0 + 1, 1))
        return GpodObstacle(
            position=position.astype(np.float64), height=height, range=float(rng_[0]),
            bearing=float(brg[0]), width=width, disparity_excess=exc,
            confidence=float(np.clip(conf, 0.0, 1.0)), roi=roi, num_edge_pixels=int(n),
            string_ids=np.unique(m.string_id[ids]).astype(np.int32))


def _features(m: Matches, excess: np.ndarray, obst: np.ndarray | None = None,
              drop: np.ndarray | None = None, sclass: np.ndarray | None = None) -> GpodFeatures:
    """GpodFeatures of the matches (no pixel flagged when the flags are None)."""
    k = len(m)
    z = np.zeros(k, bool)
    return GpodFeatures(u_left=m.u_left, u_right=m.u_right, v=m.v, d=m.d, excess=excess,
                        is_obstacle=z if obst is None else obst,
                        is_drop=z.copy() if drop is None else drop,
                        string_class=np.zeros(k, np.int8) if sclass is None else sclass,
                        string_id=m.string_id)
