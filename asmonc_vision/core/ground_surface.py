"""The ground ahead as a surface: the near plane continued by a height profile.

GPOD's ground model is one plane, ``d = a*u + b*v + c`` (Molton et al. 1998), fitted
to the ground near the wearer. A walkway that starts to rise a few metres ahead stands
above that plane's continuation by ``(s - s_start) * tan(slope)`` (25 cm at 3 m past
the start of a 5 degree rise), which the obstacle test reports as obstacles. Here the
plane stays the model near the wearer and is continued ahead by a piecewise-linear
profile of the ground's height above the plane along the walking direction (the
road-profile idea of v-disparity methods, Labayrade et al. 2002, and of Wedel et al.
2009's B-spline road surface, in metric space):

    surface height above the plane  z(s) = z_k + (z_{k+1} - z_k) (s - s_k) / (s_{k+1} - s_k)
    for knots s_0 < s_1 < ... (metres along the ground from the point below the camera),
    z(s) = 0 for s <= s_0 (the plane itself near the wearer).

The knot heights are fitted from near to far, one segment at a time, to the features
near the profile's continuation (a robust line from the previous knot, Tukey-weighted
IRLS with a prior towards the straight continuation, ``smoothness_m``). A segment is
taken only if it is ground, not an obstacle or a step:

* ``rule_support``: at least ``min_features`` features, a quarter of them in each
  half of the segment, spread across at least ``min_width_m`` of the path (a box or a
  post is narrow; the ground is wide);
* ``rule_grade``: the grade changes by at most ``max_grade_change`` from the previous
  segment (a ramp or a slope's start, not a wall);
* ``rule_step``: no step of more than ``max_step_m`` inside the segment: the features
  are fitted by a line plus a step at each of 9 places along the segment, and the best
  of these, if it cuts the line's residual sum by a quarter, must have a step of at most
  ``max_step_m`` (a kerb of 10 cm is a line plus a step; a slope is a line);
* ``rule_spread``: the residuals' robust spread is at most ``max_spread_m``.

Before any segment, ``rule_anchor``: the features of the last ``knot_spacing_m`` before
the first knot (when there are ``min_features`` of them) must lie on the plane (median
height within ``anchor_max_m``); if not, the plane itself is off and no profile is fitted
(it would bend to make up for the plane, not for the ground).

The first segment that fails ends the known surface: beyond ``known_until_m`` the ground
is *unknown* (the profile is held level at its last knot for the obstacle test, and the
caller is told how far it knows the ground). Points are judged against the surface by
their height above it (`GroundSurface.height_above`), or in disparity by the surface's
disparity at their pixel (`GroundSurface.disparity`: the ray's first intersection with
the profile, solved exactly per segment).

Frames: the left optical frame (REP 103: x right, y down, z forward, metres); pixels
are cyclopean (u, v) with disparity d (docs/CONVENTIONS.md). No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .camera import MetricPlane, StereoCamera, ground_axes
from .config import check_fields, param


@dataclass(frozen=True)
class GroundSurfaceConfig:
    """Settings of the ground surface ahead (``GpodConfig.surface_*``)."""

    enabled: bool = param(
        True, 'Judge obstacles against the ground surface ahead (the near plane continued '
        'by a height profile along the walking direction) rather than against the plane '
        'alone')
    near_m: float = param(
        2.0, 'The plane alone is the ground up to this distance along the ground, or up '
        'to where the ground is first seen if that is farther (the 5th percentile of the '
        'distances of the features on the plane), metres: the first knot of the profile',
        range=(0.0, 50.0))
    far_m: float = param(
        10.0, 'The profile is fitted out to this distance along the ground, metres',
        range=(0.5, 100.0))
    knot_spacing_m: float = param(
        1.0, 'Distance between the knots of the profile, metres', range=(0.1, 20.0))
    half_width_m: float = param(
        2.0, 'Features within this distance of the walking line take part, metres',
        range=(0.1, 50.0))
    gate_m: float = param(
        0.15, "Features within this height of the profile's straight continuation take "
        'part in a segment\'s fit, metres (plus a segment\'s length times '
        'max_grade_change)', range=(0.01, 5.0))
    smoothness_m: float = param(
        0.05, "Prior on a knot's height: its straight continuation from the previous "
        'segment, with this standard deviation, metres (small = stiff)',
        range=(0.001, 10.0))
    max_grade_change: float = param(
        0.12, 'Largest change of the grade (rise per metre) from one segment to the next '
        '(0.12: about 7 degrees)', range=(0.0, 2.0))
    max_step_m: float = param(
        0.04, 'Largest step inside a segment (the best line-plus-step fit of its '
        'features, when it cuts the residuals of the line alone by a quarter), metres: a step (a '
        'kerb) is not a slope', range=(0.001, 1.0))
    max_spread_m: float = param(
        0.05, "Largest robust spread (1.4826 MAD) of a segment's residuals, metres",
        range=(0.001, 1.0))
    min_features: int = param(
        30, 'Least number of features a segment is fitted from', range=(3, 100000))
    min_bend_m: float = param(
        0.05, 'The profile is used only if it leaves the plane by more than this somewhere, '
        'metres: within it the plane alone (a profile fitted to flat ground wanders by a '
        'few cm, which would shift the obstacle test)', range=(0.0, 1.0))
    anchor_max_m: float = param(
        0.02, 'rule_anchor: largest median height of the ground just before the first '
        'knot above (or below) the plane, metres', range=(0.001, 1.0))
    min_width_m: float = param(
        0.8, "Least width (10th to 90th percentile across the path) of a segment's "
        'features, metres: the ground is wide, an obstacle narrow', range=(0.0, 50.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.near_m >= self.far_m:
            raise ValueError(f'GroundSurfaceConfig.near_m = {self.near_m} must be less than '
                             f'far_m = {self.far_m}')


@dataclass(frozen=True)
class SegmentCheck:
    """Why a segment was taken or not: the rule that refused it ('' = taken) and its
    numbers (features, width m, grade change, step m, spread m; for 'rule_anchor' the
    near ground's median height above the plane as step_m)."""

    refused_by: str
    features: int
    width_m: float
    grade_change: float
    step_m: float
    spread_m: float


@dataclass(frozen=True)
class GroundSurface:
    """The near plane continued by a height profile (see the module doc).

    Attributes:
        plane: the near plane (left optical frame).
        knots_s: (K,) float64 knot distances along the ground, metres, increasing.
        knots_z: (K,) float64 surface height above the plane at the knots, metres
            (knots_z[0] = 0).
        known_until_m: the surface is known (supported by features) up to this distance
            along the ground; knots_s[-1] when all segments were taken, knots_s[0] (the
            first knot: near_m, or where the ground is first seen) when none.
        checks: one SegmentCheck per segment tried, near to far.
    """

    plane: MetricPlane
    knots_s: np.ndarray
    knots_z: np.ndarray
    known_until_m: float
    checks: tuple[SegmentCheck, ...] = ()

    @classmethod
    def flat(cls, plane: MetricPlane, near_m: float = 0.0) -> 'GroundSurface':
        """The plane alone (no profile), known nowhere beyond ``near_m``."""
        return cls(plane, np.array([near_m]), np.zeros(1), near_m)

    @property
    def bends(self) -> bool:
        """Whether the profile leaves the plane anywhere."""
        return bool(np.any(self.knots_z != 0.0))

    def profile(self, s: np.ndarray) -> np.ndarray:
        """(N,) surface height above the plane (m) at distances s (N,) along the ground
        (m): 0 before the first knot, level after the last known knot."""
        s = np.asarray(s, float)
        ks, kz = self._known_knots()
        return np.interp(s, ks, kz, left=0.0, right=kz[-1])

    def _known_knots(self) -> tuple[np.ndarray, np.ndarray]:
        keep = self.knots_s <= self.known_until_m + 1e-9
        return self.knots_s[keep], self.knots_z[keep]

    def coordinates(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (N, 3) in the left optical frame, metres -> (s, l, h): distance along
        the ground ahead, to the left, and height above the plane, metres, (N,) each."""
        origin, fwd, left = ground_axes(self.plane)
        p = np.asarray(points, float).reshape(-1, 3) - origin
        return p @ fwd, p @ left, p @ self.plane.normal_up

    def height_above(self, points: np.ndarray) -> np.ndarray:
        """(N,) height of points (N, 3) (left optical frame, m) above the surface, m."""
        s, _, h = self.coordinates(points)
        return h - self.profile(s)

    def disparity(self, cam: StereoCamera, u, v) -> np.ndarray:
        """(N,) disparity (px) of the surface at cyclopean pixels (u, v) (N,) px: the
        ray's nearest intersection with the plane before the first knot, a profile
        segment, or the level continuation beyond the last known knot; NaN for a ray
        that meets none of them (above the horizon)."""
        u = np.asarray(u, float).ravel()
        v = np.asarray(v, float).ravel()
        n = np.asarray(self.plane.normal_up, float)
        origin, fwd, _ = ground_axes(self.plane)
        r = np.stack([(u - cam.cx) / cam.f, (v - cam.cy) / cam.f, np.ones_like(u)], axis=1)
        o = np.array([cam.baseline / 2.0, 0.0, 0.0]) - origin   # cyclopean centre
        # A point at depth z on the ray: s(z) = s0 + z*sr, h(z) = h0 + z*hr.
        s0, h0 = float(o @ fwd), float(o @ n)
        sr, hr = r @ fwd, r @ n
        ks, kz = self._known_knots()
        # pieces: (s_from, s_to, height at s_from, grade) of z(s)
        pieces = [(-np.inf, ks[0], 0.0, 0.0)]
        for k in range(ks.size - 1):
            pieces.append((ks[k], ks[k + 1], kz[k],
                           (kz[k + 1] - kz[k]) / (ks[k + 1] - ks[k])))
        pieces.append((ks[-1], np.inf, kz[-1], 0.0))
        best = np.full(u.shape, np.inf)
        with np.errstate(divide='ignore', invalid='ignore'):
            for s_a, s_b, z_a, g in pieces:
                # h0 + z hr = z_a + g (s0 + z sr - s_a)   (the ray meets the piece's line)
                base = z_a + g * (s0 - s_a) if np.isfinite(s_a) else z_a
                depth = (base - h0) / (hr - g * sr)
                s_hit = s0 + depth * sr
                ok = (depth > 0) & (s_hit >= s_a - 1e-9) & (s_hit <= s_b + 1e-9)
                best = np.where(ok & (depth < best), depth, best)
        out = cam.fb / best
        out[~np.isfinite(best)] = np.nan
        return out


def _tukey(res: np.ndarray, c: float) -> np.ndarray:
    """Tukey biweight weights of residuals (N,) for the scale c (same units)."""
    x = np.clip(np.abs(res) / c, 0.0, 1.0)
    return (1.0 - x * x) ** 2


def _mad(x: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if x.size else math.nan


def _fit_segment(s: np.ndarray, h: np.ndarray, s_a: float, z_a: float, length: float,
                 z_prior: float, sigma_prior: float, scale: float, iterations: int = 5
                 ) -> float:
    """The far knot's height z_b of the line z_a + (z_b - z_a) (s - s_a) / length
    through features (s, h) (N,) m: Tukey-weighted least squares (scale m) with the
    prior z_b ~ N(z_prior, sigma_prior^2), a few IRLS rounds from the prior."""
    t = (s - s_a) / length                    # (N,) in [0, 1]: d height / d z_b
    z_b = z_prior
    for _ in range(iterations):
        res = h - (z_a + (z_b - z_a) * t)
        w = _tukey(res, scale)
        # minimise sum w (h - z_a - (z_b - z_a) t)^2 / scale^2 + (z_b - z_prior)^2 / sp^2
        a = float(np.sum(w * t * t)) / scale ** 2 + 1.0 / sigma_prior ** 2
        b = (float(np.sum(w * t * (h - z_a + z_a * t))) / scale ** 2
             + z_prior / sigma_prior ** 2)
        z_b = b / a
    return z_b


def _best_step(t: np.ndarray, h: np.ndarray, length: float, splits: int = 9) -> float:
    """The height (m) of the step that best explains a segment's features beside a
    line: for each split t* at 1/(splits+1) .. splits/(splits+1) of the segment,
    least squares of h = c + g t + delta [t > t*] over the features (t: (N,) m from the
    segment's start, h: (N,) m); the |delta| of the split whose residual sum is least
    if it is at most 3/4 of the line's alone, else 0 (a slope has no step). NaN with
    fewer than 3 features on either side of every split.

    Every split is solved at once from the sums of the normal equations (A^T A) x =
    A^T h, A = [1, t, [t > t*]]; the residual sum is h^T h - x^T A^T h (a few
    microseconds where a least-squares call per split took tens)."""
    if t.size < 6:
        return math.nan
    t = np.asarray(t, float)
    h = np.asarray(h, float)
    n, st, stt = float(t.size), float(t.sum()), float(t @ t)
    sh, sth, shh = float(h.sum()), float(t @ h), float(h @ h)
    # the line alone: rss = h^T h - x^T A^T h with A = [1, t]
    det = n * stt - st * st
    if det <= 1e-12 * max(n * stt, 1e-300):
        return math.nan
    c0 = (stt * sh - st * sth) / det
    g0 = (n * sth - st * sh) / det
    rss_line = max(shh - (c0 * sh + g0 * sth), 0.0)
    cuts = length * np.arange(1, splits + 1) / (splits + 1)          # (K,)
    after = t[None, :] > cuts[:, None]                              # (K, N)
    na = after.sum(axis=1).astype(float)
    valid = np.minimum(na, n - na) >= 3
    if not valid.any():
        return math.nan
    sta = after @ t
    sha = after @ h
    ata = np.empty((splits, 3, 3))
    ata[:, 0, 0], ata[:, 0, 1], ata[:, 0, 2] = n, st, na
    ata[:, 1, 0], ata[:, 1, 1], ata[:, 1, 2] = st, stt, sta
    ata[:, 2, 0], ata[:, 2, 1], ata[:, 2, 2] = na, sta, na
    ath = np.stack([np.full(splits, sh), np.full(splits, sth), sha], axis=1)   # (K, 3)
    ata[~valid] = np.eye(3)                         # placeholders, never chosen
    coef = np.linalg.solve(ata, ath[:, :, None])[:, :, 0]                   # (K, 3)
    rss = np.where(valid, shh - np.sum(coef * ath, axis=1), np.inf)
    k = int(np.argmin(rss))
    best_rss = max(float(rss[k]), 0.0)
    return abs(float(coef[k, 2])) if best_rss <= 0.75 * rss_line else 0.0


def fit_ground_surface(points: np.ndarray, plane: MetricPlane,
                       config: GroundSurfaceConfig | None = None) -> GroundSurface:
    """Fit the surface ahead to matched features.

    Args:
        points: (N, 3) float features in the left optical frame, metres (triangulated
            matches; obstacles among them are outvoted by the robust fit and the
            rules).
        plane: the near ground plane (left optical frame).
        config: the settings (defaults if None).
    Returns:
        The GroundSurface; with no feature support ahead, the plane alone with
        ``known_until_m = near_m`` (a return value, never an exception).
    """
    c = config if config is not None else GroundSurfaceConfig()
    surface = GroundSurface.flat(plane, c.near_m)
    s, lat, h = surface.coordinates(points)
    use = np.abs(lat) <= c.half_width_m
    s, lat, h = s[use], lat[use], h[use]
    # The profile starts at near_m, or where the ground is first seen if that is
    # farther (a car's cameras see the road from 5 m): the 5th percentile of the
    # distances of the features on the plane.
    on_plane = np.abs(h) <= c.gate_m
    first = c.near_m
    if np.count_nonzero(on_plane) >= c.min_features:
        first = max(c.near_m, float(np.percentile(s[on_plane], 5)))
    if first >= c.far_m - 0.5 * c.knot_spacing_m:
        return GroundSurface.flat(plane, first)
    n_seg = max(int(math.ceil((c.far_m - first) / c.knot_spacing_m - 1e-9)), 1)
    knots_s = first + c.knot_spacing_m * np.arange(n_seg + 1)
    knots_s[-1] = min(knots_s[-1], c.far_m)
    knots_z = np.zeros(n_seg + 1)
    grade = 0.0                       # the previous segment's rise per metre
    known = first
    checks: list[SegmentCheck] = []
    # rule_anchor: the profile starts on the plane, so the ground just before its first
    # knot must lie on the plane; if it does not, the plane is off (a frame of a
    # vigorous walk) and a profile would bend to make up for it, not for the ground.
    anchor = (s >= first - c.knot_spacing_m) & (s < first) & on_plane
    if np.count_nonzero(anchor) >= c.min_features:
        offset = float(np.median(h[anchor]))
        if abs(offset) > c.anchor_max_m:
            checks.append(SegmentCheck('rule_anchor', int(np.count_nonzero(anchor)),
                                       math.nan, math.nan, offset, math.nan))
            return GroundSurface(plane, knots_s, knots_z, known, tuple(checks))
    for k in range(n_seg):
        s_a, s_b = knots_s[k], knots_s[k + 1]
        length = s_b - s_a
        z_a = knots_z[k]
        z_line = z_a + grade * (s - s_a)            # the straight continuation
        gate = c.gate_m + length * c.max_grade_change
        inseg = (s >= s_a) & (s < s_b) & (np.abs(h - z_line) <= gate)
        n_in = int(inseg.sum())
        ss, ll, hh = s[inseg], lat[inseg], h[inseg]
        width = float(np.subtract(*np.percentile(ll, [90, 10]))) if n_in else 0.0
        refused = ''
        z_b, step, spread, change = z_a + grade * length, math.nan, math.nan, math.nan
        halves = (int(np.count_nonzero(ss < s_a + 0.5 * length)),
                  int(np.count_nonzero(ss >= s_a + 0.5 * length)))
        if n_in < c.min_features or width < c.min_width_m or min(halves) < c.min_features // 4:
            refused = 'rule_support'
        else:
            z_b = _fit_segment(ss, hh, s_a, z_a, length, z_a + grade * length,
                               c.smoothness_m, scale=max(c.gate_m, 1e-3))
            new_grade = (z_b - z_a) / length
            change = abs(new_grade - grade)
            res = hh - (z_a + (z_b - z_a) * (ss - s_a) / length)
            on = np.abs(res) <= c.gate_m
            step = _best_step(ss[on] - s_a, hh[on], length)
            spread = _mad(res[on])
            for name, bad in (('rule_grade', change > c.max_grade_change),
                              ('rule_step', not step <= c.max_step_m),
                              ('rule_spread', not spread <= c.max_spread_m)):
                if bad:
                    refused = name
                    break
        checks.append(SegmentCheck(refused, n_in, width, change, step, spread))
        if refused:
            break
        knots_z[k + 1] = z_b
        grade = (z_b - z_a) / length
        known = float(s_b)
    if np.max(np.abs(knots_z)) <= c.min_bend_m:
        knots_z[:] = 0.0                 # flat within the noise: the plane itself
    return GroundSurface(plane, knots_s, knots_z, known, tuple(checks))
