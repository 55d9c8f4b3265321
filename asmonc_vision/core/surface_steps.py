"""A segment's step and bend tests (`ground_surface`'s ``rule_step``).

The ground surface ahead (`core.ground_surface`) fits its profile one segment (1 m) at
a time and refuses a segment with a step in it: a kerb up or a drop across the walking
corridor is a line plus a step in the features' heights, a slope a line. This module
holds the tests that tell them apart, from a segment's features alone:

* `best_step`: the line plus a step at each of 9 places that explains the features
  best, and whether that step is one (it cuts the line's residual sum by a quarter, or
  it is significant against the features' scatter, t >= `STEP_T`);
* `corridor_step`: the walking corridor's own line plus a step at the same place (a
  kerb beside a kerb ramp steps beside the path, not across it);
* `best_bend`: a line with one bend, continuous there, at the same 9 places (a sharp
  brow or the foot of a slope is a bend; a step's far side starts higher or lower);
* `boundary_step`: a step at the segment's start (a kerb or a drop just at a knot);
* `path_step`: the verdict, as `ground_surface._segment` takes it.

`core.surface_kernels` repeats them in numba with identical results. Features are
(t, lat, h): metres from the segment's start along the ground, to the left, above the
near plane; ``ray`` the grade (dh/ds) of each feature's ray. No ROS here.
"""
from __future__ import annotations

import math

import numpy as np

from .ground_plane import fast_median

#: `best_step`: a step whose t statistic is at least this is one, whatever share of
#: the residual sum it explains (the best of 9 splits of pure noise: below 4 but for
#: about 1 segment in 2 000).
STEP_T = 4.0
#: `boundary_step`: a step at a segment's start counts from this height (m): the
#: surface's knot lags a sharp bend by up to about 5 cm (its stiff prior), which is no
#: step; a 10 cm kerb or drop at a knot is.
KNOT_STEP_M = 0.07
#: `path_step`: a bend down is one the camera sees whole if the ground beyond it falls
#: at most this share of the grade of the rays that graze it (a drop's gap, bridged by
#: a bent line, falls as steeply as the ray); the rays within this distance (m) of it.
BEND_RAY_SHARE = 0.5
BEND_RAY_BAND_M = 0.25


def best_step(t: np.ndarray, h: np.ndarray, length: float, splits: int = 9
               ) -> tuple[float, float, float]:
    """The step that best explains a segment's features beside a line: for each split
    t* at 1/(splits+1) .. splits/(splits+1) of the segment, least squares of
    h = c + g t + delta [t > t*] over the features (t: (N,) m from the segment's start,
    h: (N,) m). Returns (delta m, t* m, its residual sum m^2) of the split whose
    residual sum is least; delta is 0 (a slope has no step) unless that sum is at most
    3/4 of the line's alone or the step is significant against the features' own scatter (its t
    statistic, sqrt((rss_line - rss) / (rss / (N - 3))), at least ``STEP_T``: a kerb
    among noisy far features cuts the residual sum by less than a quarter, yet by many
    times the noise). NaNs with fewer than 3 features on either side of every split.

    Every split is solved at once from the sums of the normal equations (A^T A) x =
    A^T h, A = [1, t, [t > t*]] (Cramer's rule); the residual sum is h^T h - x^T A^T h.
    The sums are numpy's (pairwise), as `surface_kernels` repeats them."""
    none = (math.nan, math.nan, math.nan)
    if t.size < 6:
        return none
    t, h, (n, st, stt, sh, sth, shh) = _sums(t, h)
    # the line alone: rss = h^T h - x^T A^T h with A = [1, t]
    det = n * stt - st * st
    if det <= 1e-12 * max(n * stt, 1e-300):
        return none
    c0 = (stt * sh - st * sth) / det
    g0 = (n * sth - st * sh) / det
    rss_line = max(shh - (c0 * sh + g0 * sth), 0.0)
    cuts = length * np.arange(1, splits + 1) / (splits + 1)          # (K,)
    after = t[None, :] > cuts[:, None]                              # (K, N)
    na = after.sum(axis=1).astype(float)
    valid = np.minimum(na, n - na) >= 3
    if not valid.any():
        return none
    coef, rss = _line_and(after.astype(float), t, h, (n, st, stt, sh, sth, shh), valid)
    k = int(np.argmin(rss))
    best_rss = max(float(rss[k]), 0.0)
    significant = rss_line - best_rss >= STEP_T ** 2 * best_rss / max(n - 3.0, 1.0)
    delta = float(coef[k, 2]) if best_rss <= 0.75 * rss_line or significant else 0.0
    return delta, float(cuts[k]), best_rss


def best_bend(t: np.ndarray, h: np.ndarray, length: float, splits: int = 9
               ) -> tuple[float, float, float, float]:
    """The bend that best explains a segment's features: for each split t* of
    `best_step`, least squares of h = c + g t + k max(t - t*, 0) over the features
    (t: (N,) m from the segment's start, h: (N,) m): a line that bends by k (rise per
    metre) at t*, continuous there. Returns (its residual sum m^2, g, k, t* m) of the
    split whose residual sum is least; NaNs with fewer than 3 features on either side of
    every split. A sharp brow or the foot of a slope is a bend: its far side starts where
    its near side ends; a kerb or a drop is a step, whose far side starts higher or
    lower."""
    none = (math.nan, math.nan, math.nan, math.nan)
    if t.size < 6:
        return none
    t, h, sums = _sums(t, h)
    n = sums[0]
    cuts = length * np.arange(1, splits + 1) / (splits + 1)          # (K,)
    na = (t[None, :] > cuts[:, None]).sum(axis=1).astype(float)
    valid = np.minimum(na, n - na) >= 3
    if not valid.any():
        return none
    coef, rss = _line_and(np.maximum(t[None, :] - cuts[:, None], 0.0), t, h, sums, valid)
    k = int(np.argmin(rss))
    return max(float(rss[k]), 0.0), float(coef[k, 1]), float(coef[k, 2]), float(cuts[k])


def _sums(t, h) -> tuple[np.ndarray, np.ndarray, tuple[float, ...]]:
    """Features t, h (N,) as float arrays and their sums (n, sum t, sum t^2, sum h,
    sum t h, sum h^2), numpy's (pairwise)."""
    t = np.asarray(t, float)
    h = np.asarray(h, float)
    return t, h, (float(t.size), float(t.sum()), float(np.sum(t * t)), float(h.sum()),
                  float(np.sum(t * h)), float(np.sum(h * h)))


def _line_and(x: np.ndarray, t: np.ndarray, h: np.ndarray, sums: tuple,
              valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of h = c + g t + k x for each row of ``x`` (K, N) at once, from the
    sums of the normal equations (A^T A) y = A^T h, A = [1, t, x] (Cramer's rule), for
    the ``valid`` (K,) rows: (y (K, 3), the residual sums h^T h - y^T A^T h (K,), inf
    where not valid). ``sums``: `_sums`' of t, h (N,)."""
    n, st, stt, sh, sth, shh = sums
    k = x.shape[0]
    sx, sxt = x.sum(axis=1), (x * t[None, :]).sum(axis=1)
    sxx, shx = (x * x).sum(axis=1), (x * h[None, :]).sum(axis=1)
    ata = np.empty((k, 3, 3))
    ata[:, 0, 0], ata[:, 0, 1], ata[:, 0, 2] = n, st, sx
    ata[:, 1, 0], ata[:, 1, 1], ata[:, 1, 2] = st, stt, sxt
    ata[:, 2, 0], ata[:, 2, 1], ata[:, 2, 2] = sx, sxt, sxx
    ath = np.stack([np.full(k, sh), np.full(k, sth), shx], axis=1)          # (K, 3)
    ata[~valid] = np.eye(3)                         # placeholders, never chosen
    coef = np.stack(solve3(ata, ath), axis=1)                             # (K, 3)
    return coef, np.where(valid, shh - np.sum(coef * ath, axis=1), np.inf)


def solve3(m: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The solutions (x0, x1, x2), each (K,), of the 3x3 systems m x = r (m: (K, 3, 3),
    r: (K, 3)) by Cramer's rule, as `surface_kernels` computes them."""
    def e(i, j):
        return m[:, i, j]
    r0, r1, r2 = r[:, 0], r[:, 1], r[:, 2]
    det = (e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
           - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
           + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0)))
    x0 = (r0 * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
          - e(0, 1) * (r1 * e(2, 2) - e(1, 2) * r2)
          + e(0, 2) * (r1 * e(2, 1) - e(1, 1) * r2)) / det
    x1 = (e(0, 0) * (r1 * e(2, 2) - e(1, 2) * r2)
          - r0 * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
          + e(0, 2) * (e(1, 0) * r2 - r1 * e(2, 0))) / det
    x2 = (e(0, 0) * (e(1, 1) * r2 - r1 * e(2, 1))
          - e(0, 1) * (e(1, 0) * r2 - r1 * e(2, 0))
          + r0 * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0))) / det
    return x0, x1, x2


def boundary_step(t: np.ndarray, h: np.ndarray, z_a: float) -> float:
    """The step (m, > 0 up) at a segment's start: how far the features' own line (least
    squares of h = c + g t over t (N,) m from the start, h (N,) m) starts from the
    surface's height there, ``c - z_a``, if significant against the features' scatter (t
    statistic at least ``STEP_T``), else 0 (also with fewer than 6 features). A kerb or a
    drop just at a knot has all its far side in the next segment: no step inside it,
    only a line that does not start where the surface is (a slope's does)."""
    if t.size < 6:
        return 0.0
    tm = float(t.mean())
    sxx = float(np.sum((t - tm) ** 2))
    if sxx <= 1e-12:
        return 0.0
    g = float(np.sum((t - tm) * (h - h.mean()))) / sxx
    c0 = float(h.mean()) - g * tm
    res = h - (c0 + g * t)
    sd = math.sqrt(float(np.sum(res * res)) / max(t.size - 2, 1))
    se = sd * math.sqrt(1.0 / t.size + tm * tm / sxx)
    delta = c0 - z_a
    return delta if abs(delta) >= STEP_T * max(se, 1e-9) else 0.0


def corridor_step(t: np.ndarray, h: np.ndarray, cut: float) -> float:
    """The corridor's own step (m) at ``cut`` m: least squares of
    h = c + g t + delta [t > cut] over its features (t: (N,) m from the segment's start,
    h: (N,) m); NaN with fewer than 3 features on either side, or t constant on each.
    The line has the corridor's own slope: a ramp in the corridor that starts inside
    the segment is a bend, whose line-plus-step steps little (in the segment's middle
    not at all), where a kerb across the path steps its whole height."""
    t = np.asarray(t, float)
    h = np.asarray(h, float)
    after = t > cut
    n, na = float(t.size), float(np.count_nonzero(after))
    if min(na, n - na) < 3 or (np.ptp(t[after]) == 0.0 and np.ptp(t[~after]) == 0.0):
        return math.nan
    st, stt = float(t.sum()), float(np.sum(t * t))
    sh, sth = float(h.sum()), float(np.sum(t * h))
    sta, sha = float(np.where(after, t, 0.0).sum()), float(np.where(after, h, 0.0).sum())
    ata = np.array([[[n, st, na], [st, stt, sta], [na, sta, na]]])
    ath = np.array([[sh, sth, sha]])
    return float(solve3(ata, ath)[2][0])


def path_step(t: np.ndarray, lat: np.ndarray, h: np.ndarray, ray: np.ndarray,
               z_a: float, grade: float, length: float, half_width: float, max_rise: float
               ) -> tuple[float, float, float]:
    """The step (m, > 0 up) of the ground ahead and where it is (m from the segment's
    start; NaN with no step) in a segment's features (t: (N,) m from its
    start, lat: (N,) m to the left, h: (N,) m; ray: (N,) the grade of each feature's
    ray, dh/ds along it, NaN unknown), and the change of grade (rise per metre, from
    the previous segment's ``grade``) of the bent line that explains them better than
    that step, the larger of its two pieces' (NaN: none).

    The step is inside the segment (`best_step`) if the walking corridor
    (|lat| <= ``half_width``) shows it too (its own line-plus-step at the same place,
    `corridor_step`, steps at least half as much the same way, when it has 3 features
    on each side), or at the segment's start (`boundary_step`) if larger and at least
    KNOT_STEP_M. A kerb across the path steps in the corridor; a kerb beside the path
    (beside a kerb ramp) does not: it is an obstacle beside the path, not a step of the
    ground ahead, and the ramp between them is a line or a bend.

    A step inside the segment is a bend instead when a bent line (`best_bend`)
    explains the features significantly better (its residual sum below the step's by
    a t statistic of at least STEP_T), and the bend is one the camera could see whole,
    after a piece that is ground: its near piece's grade within ``max_rise`` of
    ``grade``, then bending up by at most ``max_rise``, or bending down to a grade less
    than BEND_RAY_SHARE of the grade of the rays that graze it (the median ``ray`` of
    the features within BEND_RAY_BAND_M of the bend). A sharp brow falls away from the
    rays and its far side is seen from its edge on. A drop hides the ground just beyond
    its edge along the grazing ray, and a bent line through the gap falls as steeply as
    that ray; a kerb up is a face, far steeper than max_rise."""
    delta, cut, rss_step = best_step(t, h, length)
    step = abs(delta)
    if step > 0.0:
        path = np.abs(lat) <= half_width
        own = corridor_step(t[path], h[path], cut)
        if math.isfinite(own) and own * math.copysign(1.0, delta) < 0.5 * step:
            step = 0.0
    bend = math.nan
    if step > 0.0:
        rss_bend, g, k, bend_at = best_bend(t, h, length)
        near = np.abs(t - bend_at) <= BEND_RAY_BAND_M
        rays = ray[near][np.isfinite(ray[near])]
        graze = fast_median(rays) if rays.size else math.nan
        seen = abs(g - grade) <= max_rise and (
            k <= max_rise if k >= 0.0 else g + k > BEND_RAY_SHARE * graze)
        better = rss_step - rss_bend >= STEP_T ** 2 * rss_bend / max(t.size - 3.0, 1.0)
        if better and seen:
            step = 0.0
            bend = g - grade if abs(g - grade) > abs(g + k - grade) else g + k - grade
    at_start = boundary_step(t, h, z_a)
    if abs(at_start) >= KNOT_STEP_M and abs(at_start) > step:
        return at_start, 0.0, bend
    return (delta, cut, bend) if step > 0.0 else (0.0, math.nan, bend)
