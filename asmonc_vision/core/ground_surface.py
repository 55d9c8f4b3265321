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
* ``rule_grade``: the grade falls by at most ``max_grade_fall`` or rises by at most
  ``max_grade_rise`` from the previous segment (a ramp or a slope's start, not a wall).
  Ground that bends up is seen whole, and a kerb up in it is a step (``rule_step``);
  ground that bends down may hide a drop beyond its edge, so a fall is held to less;
* ``rule_step``: no step of more than ``max_step_m`` inside the segment: the features
  are fitted by a line plus a step at each of 9 places along the segment, and the best
  of these, if it cuts the line's residual sum by a quarter or is significant against
  the features' scatter, must have a step of at most ``max_step_m`` (a kerb of 10 cm is
  a line plus a step; a slope is a line) where the walking corridor
  (``step_half_width_m``) shows it too (a kerb beside a kerb ramp is an obstacle beside
  the path, not a step of the ground ahead), and where a line with one bend in it does
  not explain the features significantly better (t >= 4) as ground the camera sees
  whole (a sharp brow: its far side starts where its near side ends, and falls less
  than half as steeply as the rays that graze it; the gap a drop hides behind its edge,
  bridged by a bent line, falls as steeply as the ray); such a bend is judged by
  ``rule_grade`` instead, by the larger change of grade of its two pieces; nor at its
  start: the features' own line must start where the surface is, within 7 cm (a knot
  lags a sharp bend by up to about 5 cm) or its own uncertainty (t < 4) (a kerb or a
  drop just at a knot has all its far side in the next segment, a line that starts 10
  cm up or down; a slope's starts on the surface);
* ``rule_spread``: the residuals' robust spread is at most ``max_spread_m`` beyond what
  the features' disparity noise explains (``depth_sd``: a feature moves along its ray,
  several cm across the ground at 9 m on a short baseline).

Before any segment, ``rule_anchor``: the features of the last ``knot_spacing_m`` before
the first knot (when there are ``min_features`` of them) must lie on the plane (median
height within ``anchor_max_m``); if not, the plane itself is off and no profile is fitted
(it would bend to make up for the plane, not for the ground).

The first segment that fails ends the known surface: beyond ``known_until_m`` the ground
is *unknown* (for the obstacle test the surface goes on at ``tail_grade``, the grade the
last two segments agree on, and the caller is told how far it knows the ground).
Points are judged against the surface by their height above it
(`GroundSurface.height_above`), or in disparity by the surface's disparity at their
pixel (`GroundSurface.disparity`: the ray's first intersection with the profile, solved
exactly per segment). The drop test allows the ground below it by `drop_margin`: a rise
beyond the known ground may end (`GroundSurface.lowest`), and where the profile bends
its straight segments lag the ground by up to ``lag_share`` times the change of grade
times the knot spacing (`GroundSurface.bent_error`).

Frames: the left optical frame (REP 103: x right, y down, z forward, metres); pixels
are cyclopean (u, v) with disparity d (docs/CONVENTIONS.md). No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from . import surface_kernels
from .camera import MetricPlane, StereoCamera, ground_axes, sub_rows
from .config import check_fields, param
from .ground_plane import fast_median, fast_percentile
from .npfast import flat_nonzero
from .surface_steps import (BEND_RAY_BAND_M, BEND_RAY_SHARE, KNOT_STEP_M, STEP_T,
                            path_step)


@dataclass(frozen=True)
class GroundSurfaceConfig:
    """Settings of the ground surface ahead (``GpodConfig.surface``; in ROS ``gpod.surface.*``)."""

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
        'max_grade_rise above it, max_grade_fall below it)', range=(0.01, 5.0))
    smoothness_m: float = param(
        0.05, "Prior on a knot's height: its straight continuation from the previous "
        'segment, with this standard deviation, metres (small = stiff)',
        range=(0.001, 10.0))
    max_grade_fall: float = param(
        0.12, 'Largest fall of the grade (rise per metre) from one segment to the next, '
        'the ground bending down (0.12: about 7 degrees; a drop may hide beyond such an '
        'edge)', range=(0.0, 2.0))
    max_grade_rise: float = param(
        0.25, 'Largest rise of the grade (rise per metre) from one segment to the next, '
        'the ground bending up (0.25: about 14 degrees, a dip from a 7 degree fall into a '
        '7 degree rise; a kerb up is a step, rule_step)', range=(0.0, 2.0))
    max_step_m: float = param(
        0.04, 'Largest step inside a segment (the best line-plus-step fit of its '
        'features, when it cuts the residuals of the line alone by a quarter), metres: a step (a '
        'kerb) is not a slope', range=(0.001, 1.0))
    step_half_width_m: float = param(
        0.6, 'A step inside a segment counts when the features within this distance of '
        'the walking line show it too (their own line-plus-step there steps at least half '
        'as much), metres: a kerb beside the path (beside a kerb ramp) is '
        'an obstacle there, not a step of the ground ahead', range=(0.1, 50.0))
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
    lag_share: float = param(
        0.25, "The profile's straight 1 m segments lag a rounded bend: the drop test "
        'allows the ground to lie this share of the change of grade at each knot times '
        'the knot spacing below the profile there (0.25: the least-squares lag of a line '
        'across a sharp bend; 2.3 cm where a crest bends by 0.09 at a knot; a 10 cm drop '
        'is far beyond it); 0 = off', range=(0.0, 2.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.near_m >= self.far_m:
            raise ValueError(f'GroundSurfaceConfig.near_m = {self.near_m} must be less than '
                             f'far_m = {self.far_m}')


@dataclass(frozen=True)
class SegmentCheck:
    """Why a segment was taken or not: the rule that refused it ('' = taken) and its
    numbers (features, width m, grade change (rise per metre, > 0 where the ground bends
    up), step m (> 0: the ground steps up), spread m; for 'rule_anchor' the
    near ground's median height above the plane as step_m) and where the step is
    (``step_at_m``: metres along the ground, NaN with no step)."""

    refused_by: str
    features: int
    width_m: float
    grade_change: float
    step_m: float
    spread_m: float
    step_at_m: float = math.nan


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
        tail_grade: the grade (rise per metre) of the surface beyond the last known knot:
            that of the last known segment (the ground is taken to go on as it was seen
            to go; 0 when no segment was taken or the profile is the plane itself).
        knots_sd: (K,) float64 standard deviation of each known knot's height from its
            features (`knot_sd`), metres (0 at the first knot, NaN beyond the known
            ground), or None (not taken).
    """

    plane: MetricPlane
    knots_s: np.ndarray
    knots_z: np.ndarray
    known_until_m: float
    checks: tuple[SegmentCheck, ...] = ()
    tail_grade: float = 0.0
    knots_sd: np.ndarray | None = None

    @classmethod
    def flat(cls, plane: MetricPlane, near_m: float = 0.0) -> 'GroundSurface':
        """The plane alone (no profile), known nowhere beyond ``near_m``."""
        return cls(plane, np.array([near_m]), np.zeros(1), near_m)

    def ended_by(self) -> str:
        """Why the known ground ends at ``known_until_m``, for logs and diagnostics: the
        rule that refused the segment beyond it and the number it judged ('rule_step
        7.5 cm', 'rule_support 12 features', 'rule_grade +0.31' (change of grade, rise per
        metre), 'rule_spread 9.0 cm', 'rule_anchor +3.1 cm' (the near ground's height above
        the plane)), or '' when no segment was refused (the profile reaches ``far_m``, or
        no features lie ahead of its first knot)."""
        if not self.checks or not self.checks[-1].refused_by:
            return ''
        c = self.checks[-1]
        number = {'rule_support': f'{c.features} features',
                  'rule_grade': f'{c.grade_change:+.2f}',
                  'rule_step': f'{c.step_m * 100:+.1f} cm',
                  'rule_spread': f'{c.spread_m * 100:.1f} cm',
                  'rule_anchor': f'{c.step_m * 100:+.1f} cm'}.get(c.refused_by, '')
        return f'{c.refused_by} {number}'.strip()

    @property
    def bends(self) -> bool:
        """Whether the profile leaves the plane anywhere."""
        return bool(np.any(self.knots_z != 0.0)) or self.tail_grade != 0.0

    def lowest(self) -> 'GroundSurface':
        """The lowest ground this surface allows: beyond the known ground a rise may end
        where it was last seen (a ramp or a slope reaches its top, the ground beyond it
        level), so the tail does not rise; the surface itself where it does not."""
        if self.tail_grade <= 0.0:
            return self
        return replace(self, tail_grade=0.0)

    def bent_error(self, lag_share: float) -> np.ndarray:
        """(K,) float64 bound (m, >= 0) on how far the ground may lie from the profile
        at each knot because the profile lags a rounded bend: ``lag_share`` times the
        change of grade at the knot (from the plane's, 0, before the first knot; to
        ``tail_grade`` after the last known one) times the spacing to its neighbours
        (mean of the two). 0 beyond the known ground."""
        out = np.zeros(self.knots_s.shape)
        ks, kz = self._known_knots()
        if lag_share <= 0.0 or ks.size < 2:
            return out
        spacing = np.diff(ks)
        grades = np.concatenate([[0.0], np.diff(kz) / np.maximum(spacing, 1e-9),
                                 [self.tail_grade]])
        gaps = np.concatenate([[spacing[0]], spacing, [spacing[-1]]])
        out[:ks.size] = (lag_share * np.abs(np.diff(grades))
                         * 0.5 * (gaps[:-1] + gaps[1:]))
        return out

    def shifted(self, dz: np.ndarray) -> 'GroundSurface':
        """The surface with its known knots moved up by dz (K,) m (the first knot too:
        the plane before it stays)."""
        return replace(self, knots_z=np.where(self.known, self.knots_z + dz, self.knots_z))

    def profile(self, s: np.ndarray) -> np.ndarray:
        """(N,) surface height above the plane (m) at distances s (N,) along the ground
        (m): 0 before the first knot, at ``tail_grade`` after the last known knot."""
        s = np.asarray(s, float)
        ks, kz = self._known_knots()
        out = np.interp(s, ks, kz, left=0.0, right=kz[-1])
        if self.tail_grade != 0.0:
            out = out + self.tail_grade * np.maximum(s - ks[-1], 0.0)
        return out

    @property
    def known(self) -> np.ndarray:
        """(K,) bool: the knots on the known ground (at most ``known_until_m``)."""
        return self.knots_s <= self.known_until_m + 1e-9

    def _known_knots(self) -> tuple[np.ndarray, np.ndarray]:
        keep = self.known
        return self.knots_s[keep], self.knots_z[keep]

    def coordinates(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (N, 3) in the left optical frame, metres -> (s, l, h): distance along
        the ground ahead, to the left, and height above the plane, metres, (N,) each."""
        origin, fwd, left = ground_axes(self.plane)
        p = sub_rows(np.asarray(points, float).reshape(-1, 3), origin)
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
        pieces.append((ks[-1], np.inf, kz[-1], self.tail_grade))
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


def depth_noise(cam: StereoCamera, d, sigma_px) -> np.ndarray:
    """(N,) standard deviation (m) of the depth of points triangulated with disparity d
    (N,) px whose disparity has the standard deviation ``sigma_px`` (scalar or (N,)) px:
    ``z^2 sigma / (f B) = f B sigma / d^2`` (a few mm near the wearer, tens of cm at 9 m
    on a short baseline). A point moves along its ray by this; its height above a
    ground of grade g by the ray's change of height less g times its change of
    distance ahead (`fit_ground_surface`)."""
    d = np.maximum(np.asarray(d, float), 1e-6)
    return cam.fb * np.asarray(sigma_px, float) / (d * d)


def _first_knot(s: np.ndarray, h: np.ndarray, c: GroundSurfaceConfig) -> float:
    """Where the profile starts: near_m, or where the ground is first seen if that is
    farther (a car's cameras see the road from 5 m): the 5th percentile of the
    distances of the features on the plane."""
    on_plane = np.abs(h) <= c.gate_m
    if np.count_nonzero(on_plane) >= c.min_features:
        return max(c.near_m, fast_percentile(s[on_plane], 5.0))   # (finite s)
    return c.near_m


def fit_ground_surface(points: np.ndarray, plane: MetricPlane,
                       config: GroundSurfaceConfig | None = None,
                       depth_sd: np.ndarray | None = None, flatten: bool = True
                       ) -> GroundSurface:
    """Fit the surface ahead to matched features.

    Args:
        points: (N, 3) float features in the left optical frame, metres (triangulated
            matches; obstacles among them are outvoted by the robust fit and the
            rules).
        plane: the near ground plane (left optical frame).
        config: the settings (defaults if None).
        depth_sd: (N,) the standard deviation of each point's depth from its disparity
            noise, metres (`depth_noise`), or None (none): a segment's residual spread
            is judged beyond what this noise explains (``rule_spread``).
        flatten: a profile within ``min_bend_m`` of the plane is the plane itself
            (`flattened`); False: the profile as fitted (for `core.surface_tracking`,
            which flattens what it fuses).
    Returns:
        The GroundSurface; with no feature support ahead, the plane alone with
        ``known_until_m = near_m`` (a return value, never an exception).
    """
    c = config if config is not None else GroundSurfaceConfig()
    surface = GroundSurface.flat(plane, c.near_m)
    pts = np.asarray(points, float).reshape(-1, 3)
    s, lat, h = surface.coordinates(pts)
    # how far each point's (s, h) moves for one standard deviation of its depth: along
    # its ray, (ds/dz, dh/dz) times depth_sd
    e_s, e_h = np.zeros(s.shape), np.zeros(s.shape)
    if depth_sd is not None and s.size:
        _, fwd, _ = ground_axes(plane)
        sz = np.broadcast_to(np.asarray(depth_sd, float), s.shape)
        z = np.where(np.abs(pts[:, 2]) > 1e-9, pts[:, 2], 1e-9)
        e_s, e_h = sz * (pts @ fwd) / z, sz * (pts @ plane.normal_up) / z
    use = flat_nonzero(np.abs(lat) <= c.half_width_m)    # (one selection for five)
    feats = (s[use], lat[use], h[use], e_s[use], e_h[use])
    s, lat, h = feats[:3]
    first = _first_knot(s, h, c)
    if first >= c.far_m - 0.5 * c.knot_spacing_m:
        return GroundSurface.flat(plane, first)
    # rule_anchor: the profile starts on the plane, so the ground just before its first
    # knot must lie on the plane; if it does not, the plane is off (a frame of a
    # vigorous walk) and a profile would bend to make up for it, not for the ground.
    anchor = (s >= first - c.knot_spacing_m) & (s < first) & (np.abs(h) <= c.gate_m)
    if np.count_nonzero(anchor) >= c.min_features:
        offset = fast_median(h[anchor])      # (finite: |h| <= gate_m)
        if abs(offset) > c.anchor_max_m:
            knots_s = _nominal_knots(first, first, c)
            return GroundSurface(plane, knots_s, np.zeros(knots_s.size), first,
                                 (SegmentCheck('rule_anchor',
                                               int(np.count_nonzero(anchor)), math.nan,
                                               math.nan, offset, math.nan),))
    ks, kz = [first], [0.0]
    grade = 0.0                       # the grade of the last segment (the plane: 0)
    checks: list[SegmentCheck] = []
    while ks[-1] < c.far_m - 1e-6:
        s_a, z_a = ks[-1], kz[-1]
        check, length, z_b = _segment(feats, s_a, z_a, grade, c)
        checks.append(check)
        if check.refused_by:
            break
        ks.append(s_a + length)
        kz.append(z_b)
        grade = (z_b - z_a) / length
    known = ks[-1]
    rest = _nominal_knots(known, ks[-1], c)[1:]
    knots_s = np.concatenate([np.array(ks), rest])
    knots_z = np.concatenate([np.array(kz), np.zeros(rest.size)])
    knots_sd = np.concatenate([knot_sd(s, h, np.array(ks), np.array(kz), checks, c),
                               np.full(rest.size, np.nan)])
    out = GroundSurface(plane, knots_s, knots_z, float(known), tuple(checks),
                        tail_grade(knots_s, knots_z, known), knots_sd)
    return flattened(out, c.min_bend_m) if flatten else out


def drop_margin(surface: GroundSurface, cam: StereoCamera, u, v, pd: np.ndarray,
                lag_share: float) -> np.ndarray | float:
    """How far (px, >= 0) the lowest ground a bending ``surface`` allows lies below its
    disparity ``pd`` (N,) px at cyclopean pixels (u, v) (N,) px: the drop test's margin,
    (N,), or 0.0 where the surface allows no lower ground.

    Beyond the known ground a rise may end (`GroundSurface.lowest`), and where the
    profile bends its 1 m segments may lag the ground by `GroundSurface.bent_error`
    (``lag_share``). Computed through the lowered surface's own disparity, so a bound
    in metres weighs what the ray's grazing angle makes it (a few cm on ground falling
    away beyond a brow is a pixel or more)."""
    err = surface.bent_error(lag_share)
    if surface.tail_grade <= 0.0 and float(np.max(err, initial=0.0)) <= 1e-4:
        return 0.0
    pd_low = surface.lowest().shifted(-err).disparity(cam, u, v)
    return np.where(np.isfinite(pd_low), np.maximum(pd - pd_low, 0.0), 0.0)


def level_grade(plane: MetricPlane, up: np.ndarray | None) -> float | None:
    """The plane's grade along the walking direction against gravity (rise per metre,
    > 0 rising ahead), from ``up`` (3,), the world's up direction in the left optical
    frame (the inclinometer's); None without it."""
    if up is None:
        return None
    u = np.asarray(up, float).reshape(3)
    norm = float(np.linalg.norm(u))
    if not math.isfinite(norm) or norm < 1e-9:
        return None
    _, fwd, _ = ground_axes(plane)
    sin_t = float(fwd @ u) / norm
    return sin_t / math.sqrt(max(1.0 - sin_t * sin_t, 1e-12))


def fall_limit(grade: float, level: float | None, max_grade_fall: float) -> float:
    """The largest fall of the ground's grade beyond ground of ``grade`` (relative to the
    plane, rise per metre) that is still ground a pedestrian walks, the plane's own grade
    against gravity being ``level`` (`level_grade`; None: unknown).

    Walkable ground is judged against gravity, not against the ground the wearer stands
    on: it may fall to ``max_grade_fall`` below level, or that much below the grade
    before where that already falls. On level ground (or unknown level) that is
    ``max_grade_fall``; after a rise of grade g (a crest's near side) it is
    ``max_grade_fall + g`` (a crest from 7 degrees up to 7 degrees down falls by 0.25).

    Returns:
        The limit (>= max_grade_fall), rise per metre.
    """
    if level is None:
        return max_grade_fall
    return max_grade_fall + max(level + grade, 0.0)


def tail_grade(knots_s: np.ndarray, knots_z: np.ndarray, known_until_m: float) -> float:
    """The grade (rise per metre) of the surface beyond its known ground: the one the
    last two known segments agree on (the smaller of theirs if they rise or fall alike,
    else level; the plane's, 0, before the first): a slope seen over two segments goes
    on; one segment bent towards a kerb does not carry. Knots (K,) m along the ground
    and above the plane."""
    keep = knots_s <= known_until_m + 1e-9
    ks, kz = knots_s[keep], knots_z[keep]
    grades = np.diff(kz) / np.maximum(np.diff(ks), 1e-9)
    grade = float(grades[-1]) if grades.size else 0.0
    before = float(grades[-2]) if grades.size > 1 else 0.0
    return float(min(grade, before, key=abs)) if grade * before > 0.0 else 0.0


def flattened(surface: GroundSurface, min_bend_m: float) -> GroundSurface:
    """The surface, or the plane itself (knots at 0, level tail) when its known knots
    are all within ``min_bend_m`` (m) of it: a profile fitted to flat ground wanders by
    a few cm, which would shift the obstacle test."""
    kz = surface.knots_z[surface.known]
    if kz.size and np.max(np.abs(kz)) > min_bend_m:
        return surface
    return replace(surface, knots_z=np.zeros_like(surface.knots_z), tail_grade=0.0)


def knot_sd(s: np.ndarray, h: np.ndarray, ks: np.ndarray, kz: np.ndarray,
            checks: list, c: GroundSurfaceConfig) -> np.ndarray:
    """(K,) standard deviation (m) of the known knots' heights (ks, kz: (K,) m), from
    the features (s, h: (N,) m along the ground, above the plane) of each segment taken
    (its check's robust spread as their noise). The far knot of the line z_a (1 - t) +
    z_b t fitted by least squares to heights h_i at t_i has
    ``var z_b = sigma^2 / sum t_i^2 + (sum t_i (1 - t_i) / sum t_i^2)^2 var z_a``
    (the near knot's error carried through the line; the prior, which would lower it,
    ignored). The first knot is the plane's (0); NaN from a segment without features
    or spread on."""
    out = np.zeros(ks.size)
    kernel = surface_kernels.nb_knot_sums
    sums = None
    if kernel is not None and ks.size > 1:
        # the same sums of every segment, compiled (`surface_kernels.knot_sums_kernel`)
        sums = kernel(np.ascontiguousarray(s, np.float64), np.ascontiguousarray(h, np.float64),
                      np.asarray(ks, np.float64), np.asarray(kz, np.float64), float(c.gate_m))
    for k in range(1, ks.size):
        if sums is not None:
            stt, stc = float(sums[0][k]), float(sums[1][k])
        else:
            s_a, length = ks[k - 1], ks[k] - ks[k - 1]
            t = (s - s_a) / length
            line = kz[k - 1] * (1.0 - t) + kz[k] * t
            on = (t >= 0.0) & (t < 1.0) & (np.abs(h - line) <= c.gate_m)
            tt = t[on]
            stt = float(np.sum(tt * tt))
            stc = float(np.sum(tt * (1.0 - tt)))
        sigma = checks[k - 1].spread_m
        if stt <= 0.0 or not math.isfinite(sigma):
            out[k:] = np.nan
            break
        carry = stc / stt
        out[k] = math.sqrt(max(sigma, 1e-3) ** 2 / stt + carry * carry * out[k - 1] ** 2)
    return out


def _nominal_knots(first: float, last: float, c: GroundSurfaceConfig) -> np.ndarray:
    """The knots from ``last`` on at knot_spacing_m out to far_m (the last one at far_m),
    ``first`` <= ``last`` (for the record of a surface refused there)."""
    n = max(int(math.ceil((c.far_m - last) / c.knot_spacing_m - 1e-9)), 0)
    out = last + c.knot_spacing_m * np.arange(n + 1)
    if n:
        out[-1] = min(out[-1], c.far_m)
    return out


def _segment(feats: tuple, s_a: float, z_a: float, grade: float, c: GroundSurfaceConfig
             ) -> tuple[SegmentCheck, float, float]:
    """One segment of the profile from (s_a, z_a) after a segment of ``grade``, fitted to
    the features ``feats`` = (s, lat, h, e_s, e_h) (N,) float64 m each (e_s, e_h: how far
    a feature's s and h move for one standard deviation of its depth): (its check, its
    length (knot_spacing_m, less at far_m), its far knot's height). Compiled
    (`surface_kernels.segment_kernel`) where numba is, else `_segment_numpy`: the same
    results."""
    kernel = surface_kernels.nb_segment
    if kernel is None:
        return _segment_numpy(feats, s_a, z_a, grade, c)
    length = min(c.knot_spacing_m, c.far_m - s_a)
    rule, n_in, width, change, step, spread, z_b, step_at = kernel(
        *feats, float(s_a), float(z_a), float(grade), float(length), c.gate_m,
        c.max_grade_rise, c.max_grade_fall, c.min_features, c.min_width_m, c.smoothness_m,
        c.step_half_width_m, c.max_step_m, c.max_spread_m, STEP_T, KNOT_STEP_M,
        BEND_RAY_SHARE, BEND_RAY_BAND_M)
    return (SegmentCheck(surface_kernels.RULES[rule], int(n_in), float(width), float(change),
                         float(step), float(spread), s_a + float(step_at)), length, float(z_b))


def _segment_numpy(feats: tuple, s_a: float, z_a: float, grade: float,
                   c: GroundSurfaceConfig) -> tuple[SegmentCheck, float, float]:
    """`_segment` in numpy."""
    s, lat, h, e_s, e_h = feats
    length = min(c.knot_spacing_m, c.far_m - s_a)
    z_line = z_a + grade * (s - s_a)            # the straight continuation
    above = h - z_line
    inseg = ((s >= s_a) & (s < s_a + length) & (above <= c.gate_m + length * c.max_grade_rise)
             & (above >= -(c.gate_m + length * c.max_grade_fall)))
    n_in = int(inseg.sum())
    ss, ll, hh = s[inseg], lat[inseg], h[inseg]
    width = float(np.subtract(*np.percentile(ll, [90, 10]))) if n_in else 0.0
    halves = (int(np.count_nonzero(ss < s_a + 0.5 * length)),
              int(np.count_nonzero(ss >= s_a + 0.5 * length)))
    z_b = z_a + grade * length
    if n_in < c.min_features or width < c.min_width_m or min(halves) < c.min_features // 4:
        return SegmentCheck('rule_support', n_in, width, math.nan, math.nan, math.nan), \
            length, z_b
    z_b = _fit_segment(ss, hh, s_a, z_a, length, z_b, c.smoothness_m,
                       scale=max(c.gate_m, 1e-3))
    new_grade = (z_b - z_a) / length
    change = new_grade - grade              # > 0: the ground bends up
    res = hh - (z_a + (z_b - z_a) * (ss - s_a) / length)
    # a feature's noise about the segment: its depth's, along its ray, across the line
    dd = np.abs(e_h[inseg] - new_grade * e_s[inseg])
    on = np.abs(res) <= np.maximum(c.gate_m, 2.5 * dd)
    # a step across the walking corridor inside the segment, or at its start
    es = e_s[inseg][on]
    with np.errstate(invalid='ignore', divide='ignore'):
        ray = np.where(es > 0.0, e_h[inseg][on] / es, np.nan)
    step, step_at, bend = path_step(ss[on] - s_a, ll[on], hh[on], ray, z_a, grade, length,
                                     c.step_half_width_m, c.max_grade_rise)
    if math.isfinite(bend) and abs(bend) > abs(change):
        change = bend           # a bend inside the segment: rule_grade judges its pieces
    spread = _mad(res[on])
    # the spread of a segment is the ground's own unevenness and the disparity noise
    noise = float(np.median(dd[on])) if on.any() else 0.0
    refused = ''
    for name, bad in (('rule_grade', not -c.max_grade_fall <= change <= c.max_grade_rise),
                      ('rule_step', not abs(step) <= c.max_step_m),
                      ('rule_spread', not spread <= math.hypot(c.max_spread_m, noise))):
        if bad:
            refused = name
            break
    return SegmentCheck(refused, n_in, width, change, step, spread, s_a + step_at), length, z_b
