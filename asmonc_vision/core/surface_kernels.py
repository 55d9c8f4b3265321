"""The ground surface's segment test (`ground_surface._segment`), compiled.

One segment of the profile is fitted and judged from a few hundred features with some
sixty small numpy calls (selections, medians, percentiles, 3x3 solves), about 0.4 ms a
segment and 3 ms a frame in call overheads alone. `segment_kernel` does the same
arithmetic in one numba function: the same sums in the same order (numpy's pairwise
summation, `pairwise_sum`), the same order statistics, numpy's linear interpolation of
percentiles and the same closed-form 3x3 solve, so that it gives results identical to
the numpy path (`ground_surface._segment_numpy`; tested on random and recorded
features). Without numba the numpy path runs.

Arguments are float64 arrays of the features (N,) in metres (s along the ground ahead,
lat to the left, h above the plane, e_s and e_h: how far s and h move for one standard
deviation of the feature's depth) and the segment's scalars; see `segment_kernel`.
"""
from __future__ import annotations

import math

import numpy as np

from .jit import jit as _jit
from .jit import nb_pairwise_sum as nb_pairwise_leaf   # numpy's sum of <= 128 values
from .jit import warmed as _warmed

#: `segment_kernel`'s verdicts, in the order the rules are tried
RULES = ('', 'rule_support', 'rule_grade', 'rule_step', 'rule_spread')


def pairwise_sum(a, lo, hi):
    """``a[lo:hi].sum()`` of a contiguous float64 array exactly as numpy adds it: up to
    128 values `jit.pairwise_sum_kernel`'s sum, above that the sums of the two halves
    (split at a multiple of 8) added, each summed alike (numpy's recursion, on an
    explicit stack: numba cannot call a recursive function from another compiled
    one)."""
    if hi - lo <= 128:
        return nb_pairwise_leaf(a, lo, hi)
    los = np.empty(64, np.int64)
    his = np.empty(64, np.int64)
    phase = np.zeros(64, np.int64)
    left = np.empty(64)
    top = 0
    los[0], his[0] = lo, hi
    ret = 0.0
    while top >= 0:
        a_lo, a_hi = los[top], his[top]
        n = a_hi - a_lo
        if n <= 128:
            ret = nb_pairwise_leaf(a, a_lo, a_hi)
            top -= 1
            continue
        n2 = n // 2
        n2 -= n2 % 8
        if phase[top] == 0:              # the left half first
            phase[top] = 1
            top += 1
            los[top], his[top], phase[top] = a_lo, a_lo + n2, 0
        elif phase[top] == 1:            # the left half's sum is in ret: the right half
            left[top] = ret
            phase[top] = 2
            top += 1
            los[top], his[top], phase[top] = a_lo + n2, a_hi, 0
        else:                            # both: their sum goes to the caller
            ret = left[top] + ret
            top -= 1
    return ret


def _total(a):
    return nb_pairwise_sum(a, 0, a.shape[0])


def _percentile(x, q):
    """``np.percentile(x, 100 q)`` for q in [0, 1] (numpy's 'linear' method: the order
    statistics around (n - 1) q and numpy's interpolation between them)."""
    return nb_sorted_percentile(np.sort(x), q)


def sorted_percentile(xs, q):
    """`_percentile` of the array ``xs``, sorted (or partitioned so that the two order
    statistics around (n - 1) q are in place)."""
    n = xs.shape[0]
    virtual = (n - 1) * q
    lo = int(math.floor(virtual))
    hi = lo + 1
    if lo >= n - 1:
        lo = hi = n - 1
    gamma = virtual - math.floor(virtual)
    a, b = xs[lo], xs[hi]
    diff = b - a
    if gamma >= 0.5:
        return b - diff * (1.0 - gamma)
    return a + diff * gamma


def _median(x):
    """``np.median(x)`` of a non-empty array (the middle order statistic, or the mean of
    the two middle ones as numpy takes it: their sum halved). The order statistics by
    selection (np.partition; the largest below the middle by a scan); a zero or NaN
    among them by the sort (`_sorted_median`), whose choice between -0.0 and 0.0 it is."""
    n = x.shape[0]
    k = n // 2
    p = np.partition(x, k)
    hi = p[k]
    lo = hi
    if n % 2 == 0:
        lo = p[0]
        for i in range(1, k):
            if p[i] > lo:
                lo = p[i]
    if lo == 0.0 or hi == 0.0 or lo != lo or hi != hi:
        return nb_sorted_median(x)
    return hi if n % 2 else (lo + hi) / 2.0


def _sorted_median(x):
    """`_median` by a full sort."""
    xs = np.sort(x)
    k = xs.shape[0] // 2
    if xs.shape[0] % 2:
        return xs[k]
    return (xs[k - 1] + xs[k]) / 2.0


def _fit_line_knot(t, h, z_a, z_prior, sigma_prior, scale, iterations):
    """`ground_surface._fit_segment` with t = (s - s_a) / length precomputed."""
    z_b = z_prior
    n = t.shape[0]
    wtt = np.empty(n)
    wth = np.empty(n)
    for _ in range(iterations):
        for i in range(n):
            res = h[i] - (z_a + (z_b - z_a) * t[i])
            x = min(max(abs(res) / scale, 0.0), 1.0)
            y = 1.0 - x * x
            w = y * y
            wtt[i] = w * t[i] * t[i]
            wth[i] = w * t[i] * (h[i] - z_a + z_a * t[i])
        a = nb_total(wtt) / scale ** 2 + 1.0 / sigma_prior ** 2
        b = nb_total(wth) / scale ** 2 + z_prior / sigma_prior ** 2
        z_b = b / a
    return z_b


def _solve3(m, r):
    """The solution of the 3x3 system m x = r by Cramer's rule (m: (3, 3), r: (3,))."""
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
           - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    x0 = (r[0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
          - m[0, 1] * (r[1] * m[2, 2] - m[1, 2] * r[2])
          + m[0, 2] * (r[1] * m[2, 1] - m[1, 1] * r[2])) / det
    x1 = (m[0, 0] * (r[1] * m[2, 2] - m[1, 2] * r[2])
          - r[0] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
          + m[0, 2] * (m[1, 0] * r[2] - r[1] * m[2, 0])) / det
    x2 = (m[0, 0] * (m[1, 1] * r[2] - r[1] * m[2, 1])
          - m[0, 1] * (m[1, 0] * r[2] - r[1] * m[2, 0])
          + r[0] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])) / det
    return x0, x1, x2


def _sums(t, h):
    """`surface_steps._sums`: (n, sum t, sum t^2, sum h, sum t h, sum h^2)."""
    return (float(t.shape[0]), nb_total(t), nb_total(t * t), nb_total(h), nb_total(t * h),
            nb_total(h * h))


def _column_fit(n, st, stt, sh, sth, shh, sx, sxt, sxx, shx, m, r):
    """`surface_steps._line_and` for one column x from its sums (sx, sxt, sxx, shx:
    sum x, x t, x^2, x h) and the features' (n .. shh), in the 3x3 work arrays m, r:
    (g, k, residual sum)."""
    m[0, 0], m[0, 1], m[0, 2] = n, st, sx
    m[1, 0], m[1, 1], m[1, 2] = st, stt, sxt
    m[2, 0], m[2, 1], m[2, 2] = sx, sxt, sxx
    r[0], r[1], r[2] = sh, sth, shx
    x0, x1, x2 = nb_solve3(m, r)
    return x1, x2, shh - (((0.0 + x0 * sh) + x1 * sth) + x2 * shx)


def _best_step(t, h, length, splits, step_t):
    """`surface_steps.best_step` (delta, cut, rss), NaNs when it has none."""
    nan = math.nan
    if t.shape[0] < 6:
        return nan, nan, nan
    n, st, stt, sh, sth, shh = nb_sums(t, h)
    det = n * stt - st * st
    if det <= 1e-12 * max(n * stt, 1e-300):
        return nan, nan, nan
    c0 = (stt * sh - st * sth) / det
    g0 = (n * sth - st * sh) / det
    rss_line = max(shh - (c0 * sh + g0 * sth), 0.0)
    best_k = -1
    best_rss = math.inf
    best = (nan, nan)
    m = np.empty((3, 3))
    r = np.empty(3)
    masked_t = np.empty(t.shape[0])
    masked_h = np.empty(t.shape[0])
    any_valid = False
    for k in range(splits):
        cut = length * (k + 1) / (splits + 1)
        na = 0
        for i in range(t.shape[0]):
            if t[i] > cut:
                na += 1
                masked_t[i], masked_h[i] = t[i], h[i]
            else:
                masked_t[i], masked_h[i] = 0.0, 0.0
        fna = float(na)
        if min(fna, n - fna) < 3:
            continue
        any_valid = True
        sta, sha = nb_total(masked_t), nb_total(masked_h)
        x1, x2, rss = nb_column_fit(n, st, stt, sh, sth, shh, fna, sta, fna, sha, m, r)
        if rss < best_rss:
            best_rss, best_k = rss, k
            best = (x2, cut)
    if not any_valid or best_k < 0:
        return nan, nan, nan
    best_rss = max(best_rss, 0.0)
    significant = rss_line - best_rss >= step_t ** 2 * best_rss / max(n - 3.0, 1.0)
    delta = best[0] if best_rss <= 0.75 * rss_line or significant else 0.0
    return delta, best[1], best_rss


def _best_bend(t, h, length, splits):
    """`surface_steps.best_bend` (rss, g, k, cut), NaNs when it has none."""
    nan = math.nan
    if t.shape[0] < 6:
        return nan, nan, nan, nan
    n, st, stt, sh, sth, shh = nb_sums(t, h)
    m = np.empty((3, 3))
    r = np.empty(3)
    rt = np.empty(t.shape[0])
    best_rss = math.inf
    best = (nan, nan, nan)
    for k in range(splits):
        cut = length * (k + 1) / (splits + 1)
        rt[:] = np.maximum(t - cut, 0.0)
        na = np.count_nonzero(rt > 0.0)         # the features beyond the bend
        if min(float(na), n - float(na)) < 3:
            continue
        x1, x2, rss = nb_column_fit(n, st, stt, sh, sth, shh, nb_total(rt), nb_total(rt * t),
                                    nb_total(rt * rt), nb_total(rt * h), m, r)
        if rss < best_rss:
            best_rss = rss
            best = (x1, x2, cut)
    if best_rss == math.inf:
        return nan, nan, nan, nan
    return max(best_rss, 0.0), best[0], best[1], best[2]


def _boundary_step(t, h, z_a, step_t):
    """`surface_steps.boundary_step`."""
    n = t.shape[0]
    if n < 6:
        return 0.0
    tm = nb_total(t) / n
    dt = t - tm
    sxx = nb_total(dt * dt)
    if sxx <= 1e-12:
        return 0.0
    hm = nb_total(h) / n
    g = nb_total(dt * (h - hm)) / sxx
    c0 = hm - g * tm
    res = h - (c0 + g * t)
    sd = math.sqrt(nb_total(res * res) / max(n - 2, 1))
    se = sd * math.sqrt(1.0 / n + tm * tm / sxx)
    delta = c0 - z_a
    return delta if abs(delta) >= step_t * max(se, 1e-9) else 0.0


def _corridor_step(t, lat, h, half_width, cut):
    """`surface_steps.corridor_step` of the features with |lat| <= half_width."""
    n_c = 0
    for i in range(t.shape[0]):
        if abs(lat[i]) <= half_width:
            n_c += 1
    tc = np.empty(n_c)
    hc = np.empty(n_c)
    ta = np.empty(n_c)
    ha = np.empty(n_c)
    j = na = 0
    lo_a = lo_b = math.inf
    hi_a = hi_b = -math.inf
    for i in range(t.shape[0]):
        if abs(lat[i]) <= half_width:
            tc[j], hc[j] = t[i], h[i]
            if t[i] > cut:
                ta[j], ha[j] = t[i], h[i]
                na += 1
                lo_a, hi_a = min(lo_a, t[i]), max(hi_a, t[i])
            else:
                ta[j], ha[j] = 0.0, 0.0
                lo_b, hi_b = min(lo_b, t[i]), max(hi_b, t[i])
            j += 1
    n, fna = float(n_c), float(na)
    if min(fna, n - fna) < 3 or (hi_a - lo_a == 0.0 and hi_b - lo_b == 0.0):
        return math.nan
    m = np.empty((3, 3))
    r = np.empty(3)
    st, stt, sta = nb_total(tc), nb_total(tc * tc), nb_total(ta)
    m[0, 0], m[0, 1], m[0, 2] = n, st, fna
    m[1, 0], m[1, 1], m[1, 2] = st, stt, sta
    m[2, 0], m[2, 1], m[2, 2] = fna, sta, fna
    r[0], r[1], r[2] = nb_total(hc), nb_total(tc * hc), nb_total(ha)
    return nb_solve3(m, r)[2]


def _path_step(t, lat, h, ray, z_a, grade, length, half_width, max_rise, step_t,
               knot_step, ray_share, ray_band):
    """`surface_steps.path_step`."""
    delta, cut, rss_step = nb_best_step(t, h, length, 9, step_t)
    step = abs(delta)
    if step > 0.0:
        own = nb_corridor_step(t, lat, h, half_width, cut)
        if math.isfinite(own) and own * math.copysign(1.0, delta) < 0.5 * step:
            step = 0.0
    bend = math.nan
    if step > 0.0:
        rss_bend, g, k, bend_at = nb_best_bend(t, h, length, 9)
        n_r = 0
        rays = np.empty(t.shape[0])
        for i in range(t.shape[0]):
            if abs(t[i] - bend_at) <= ray_band and math.isfinite(ray[i]):
                rays[n_r] = ray[i]
                n_r += 1
        graze = nb_median(rays[:n_r]) if n_r else math.nan
        if k >= 0.0:
            seen = abs(g - grade) <= max_rise and k <= max_rise
        else:
            seen = abs(g - grade) <= max_rise and g + k > ray_share * graze
        better = rss_step - rss_bend >= step_t ** 2 * rss_bend / max(t.shape[0] - 3.0, 1.0)
        if better and seen:
            step = 0.0
            bend = g - grade if abs(g - grade) > abs(g + k - grade) else g + k - grade
    at_start = nb_boundary_step(t, h, z_a, step_t)
    if abs(at_start) >= knot_step and abs(at_start) > step:
        return at_start, 0.0, bend
    if step > 0.0:
        return delta, cut, bend
    return 0.0, math.nan, bend


def segment_kernel(s, lat, h, e_s, e_h, s_a, z_a, grade, length, gate, max_rise, max_fall,
                   min_features, min_width, smoothness, step_half_width, max_step,
                   max_spread, step_t, knot_step, ray_share, ray_band):
    """`ground_surface._segment_numpy`'s verdict on one segment, compiled.

    Args:
        s, lat, h, e_s, e_h: (N,) float64 features (m; see the module).
        s_a, z_a, grade: the segment's start (m along the ground, m above the plane) and
            the previous segment's grade.
        length: the segment's length (m); the other scalars are `GroundSurfaceConfig`'s
            (gate_m, max_grade_rise, max_grade_fall, min_features, min_width_m,
            smoothness_m, step_half_width_m, max_step_m, max_spread_m) and
            `surface_steps.STEP_T`, `KNOT_STEP_M`, `BEND_RAY_SHARE`,
            `BEND_RAY_BAND_M`.
    Returns:
        (rule index into `RULES` (0: taken), features in the segment, width m, grade
        change, step m (> 0 up), spread m, far knot's height m, the step's place m from
        the segment's start (NaN: none)).
    """
    nan = math.nan
    n_all = s.shape[0]
    lim_hi = gate + length * max_rise
    lim_lo = -(gate + length * max_fall)
    sel = np.empty(n_all, np.int64)
    n_in = 0
    for i in range(n_all):
        above = h[i] - (z_a + grade * (s[i] - s_a))
        if s[i] >= s_a and s[i] < s_a + length and above <= lim_hi and above >= lim_lo:
            sel[n_in] = i
            n_in += 1
    sel = sel[:n_in]
    ss, ll, hh = s[sel], lat[sel], h[sel]
    width = 0.0
    if n_in:
        ls = np.sort(ll)
        width = nb_sorted_percentile(ls, 0.9) - nb_sorted_percentile(ls, 0.1)
    first = 0
    for i in range(n_in):
        if ss[i] < s_a + 0.5 * length:
            first += 1
    z_b = z_a + grade * length
    if n_in < min_features or width < min_width or min(first, n_in - first) < min_features // 4:
        return 1, n_in, width, nan, nan, nan, z_b, nan
    t = (ss - s_a) / length
    z_b = nb_fit_line_knot(t, hh, z_a, z_b, smoothness, max(gate, 1e-3), 5)
    new_grade = (z_b - z_a) / length
    change = new_grade - grade
    res = hh - (z_a + (z_b - z_a) * (ss - s_a) / length)
    dd = np.abs(e_h[sel] - new_grade * e_s[sel])
    on = np.abs(res) <= np.maximum(gate, 2.5 * dd)
    idx = np.flatnonzero(on)
    es, eh = e_s[sel][idx], e_h[sel][idx]
    ray = np.empty(idx.shape[0])
    for i in range(idx.shape[0]):
        ray[i] = eh[i] / es[i] if es[i] > 0.0 else nan
    step, step_at, bend = nb_path_step(ss[idx] - s_a, ll[idx], hh[idx], ray, z_a, grade,
                                       length, step_half_width, max_rise, step_t,
                                       knot_step, ray_share, ray_band)
    if math.isfinite(bend) and abs(bend) > abs(change):
        change = bend
    if idx.shape[0]:
        r_on = res[idx]
        spread = 1.4826 * nb_median(np.abs(r_on - nb_median(r_on)))
        noise = nb_median(dd[idx])
    else:
        spread = nan
        noise = 0.0
    rule = 0
    if not -max_fall <= change <= max_rise:
        rule = 2
    elif not abs(step) <= max_step:
        rule = 3
    elif not spread <= math.hypot(max_spread, noise):
        rule = 4
    return rule, n_in, width, change, step, spread, z_b, step_at


def knot_sums_kernel(s, h, ks, kz, gate):
    """The sums of `ground_surface.knot_sd` (for numba): for each knot k >= 1 of the
    known profile (ks, kz: (K,) m), over the features (s, h: (N,) float64 m) on the
    segment before it (t = (s - ks[k-1]) / its length in [0, 1), within ``gate`` m of
    its line), (K,) float64 each: sum t^2 and sum t (1 - t), in numpy's order (its
    pairwise summation of the features in their order); 0 at k = 0."""
    n_k, n = ks.shape[0], s.shape[0]
    stt = np.zeros(n_k)
    stc = np.zeros(n_k)
    t2 = np.empty(n)
    tc = np.empty(n)
    for k in range(1, n_k):
        s_a, length = ks[k - 1], ks[k] - ks[k - 1]
        z_a, z_b = kz[k - 1], kz[k]
        m = 0
        for i in range(n):
            t = (s[i] - s_a) / length
            line = z_a * (1.0 - t) + z_b * t
            if t >= 0.0 and t < 1.0 and abs(h[i] - line) <= gate:
                t2[m] = t * t
                tc[m] = t * (1.0 - t)
                m += 1
        stt[k] = nb_pairwise_sum(t2, 0, m)
        stc[k] = nb_pairwise_sum(tc, 0, m)
    return stt, stc


nb_pairwise_sum = _jit(pairwise_sum)
nb_total = _jit(_total)
nb_sorted_percentile = _jit(sorted_percentile)
nb_percentile = _jit(_percentile)
nb_sorted_median = _jit(_sorted_median)
nb_median = _jit(_median)
nb_fit_line_knot = _jit(_fit_line_knot)
nb_solve3 = _jit(_solve3)
nb_column_fit = _jit(_column_fit)
nb_sums = _jit(_sums)
nb_best_step = _jit(_best_step)
nb_best_bend = _jit(_best_bend)
nb_boundary_step = _jit(_boundary_step)
nb_corridor_step = _jit(_corridor_step)
nb_path_step = _jit(_path_step)
nb_segment = _jit(segment_kernel)
nb_knot_sums = _jit(knot_sums_kernel)
_warm = False


def warm_up() -> None:
    """Compile (or load from numba's cache) `segment_kernel` and `knot_sums_kernel`
    before the first frame; without numba, or if it fails, the numpy path is used."""
    global _warm, nb_segment, nb_knot_sums
    if _warm:
        return
    _warm = True
    x = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5])
    z = np.zeros(8)
    nb_segment = _warmed(nb_segment, x, x - 1.75, z, z, z, 0.0, 0.0, 0.0, 1.0, 0.05, 0.1,
                         0.05, 4, 0.5, 0.05, 0.6, 0.06, 0.02, 4.0, 0.07, 0.5, 0.25)
    nb_knot_sums = _warmed(nb_knot_sums, x, z, np.array([0.0, 1.0]), np.zeros(2), 0.05)
