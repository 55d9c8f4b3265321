"""Compiled inner loops (numba) of the ground geometry: the contact-edge and outline
sampling, the walk down to a string's foot, the soft nearest points, the hidden-corner
search and the silhouette owners; each the loop form of a numpy path kept beside its
caller. Compiled by `warm_up` (called from `kernels.warm_up`); ``nb_*`` is None without
numba.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import jit as _jit
from ..jit import nb_pairwise_sum as _nb_pairwise_sum
from ..jit import warmed as _warmed

#: Candidate positions of a hidden near corner on the Thales arc (`hidden_corner`).
_CORNER_ARC_POINTS = 33
#: A hidden corner must bulge beyond the chord between its neighbours by more than this
#: many range sigmas of their feet (else the straight face explains the image as well).
_CORNER_SIGMAS = 2.0
#: A ground feature must lie this far (metres) inside a hypothesised footprint to rule
#: it out (features on its sides are its own contact edges; feet and ground features are
#: located to a few centimetres).
_FREE_SPACE_MARGIN_M = 0.05
#: Least number of ground features that show the ground behind a face's line
#: (`view_edge_points`) or between two bodies (`soft_nearest`).
_FACE_BEHIND_MIN = 5
#: `soft_nearest` averages the nearest foot with the feet as near as it only over one
#: body: not with a foot more than _BODY_GAP_SPAN_M away from it when at least
#: _FACE_BEHIND_MIN ground features lie between the two, _BODY_GAP_BAND_M[0] to [1]
#: metres behind the line joining them and _BODY_GAP_END_M clear of either foot. Behind
#: a face (a box's front, its side) the body and its shadow hide that strip; between two
#: obstacles side by side the ground is seen there.
_BODY_GAP_SPAN_M = 0.2
_BODY_GAP_BAND_M = (0.05, 0.3)
_BODY_GAP_END_M = 0.1
#: A candidate silhouette's top must be at the obstacle's height within this factor
#: (`silhouette_owners`).
_WEAK_HEIGHT_RATIO = 2.0
#: A candidate silhouette is no side of an obstacle when at least this many ground
#: features are seen where the body between it and the obstacle's feet would hide them
#: (`_face_hides_kernel`).
_FACE_HIDDEN_MIN = 2


def _outline_kernel(points, origin, fwd, lft, nup, height, f, cx, cy, gx, gy, x0, y0,
                    img_w, img_h):
    """`_FrameContext.outline_evidence` after the sample points (for numba): the same
    arithmetic in the same order; gx, gy the gradient patch at (x0, y0) of the img_w x
    img_h image; returns (evidence, separation, shift), (D, S) each."""
    n_d, n_s = points.shape[0], points.shape[1]
    grad = np.zeros((2, n_d, n_s))
    uu = np.empty((2, n_d, n_s))
    vv = np.empty((2, n_d, n_s))
    nus = np.empty((2, n_d))
    nvs = np.empty((2, n_d))
    for line in range(2):
        lift = 0.0 if line == 0 else height
        for d in range(n_d):
            for k in range(n_s):
                px, py = points[d, k, 0], points[d, k, 1]
                q0 = origin[0] + px * fwd[0] + py * lft[0] + lift * nup[0]
                q1 = origin[1] + px * fwd[1] + py * lft[1] + lift * nup[1]
                q2 = max(origin[2] + px * fwd[2] + py * lft[2] + lift * nup[2], 1e-6)
                uu[line, d, k] = f * q0 / q2 + cx
                vv[line, d, k] = f * q1 / q2 + cy
            du = uu[line, d, n_s - 1] - uu[line, d, 0]
            dv = vv[line, d, n_s - 1] - vv[line, d, 0]
            length = max(math.hypot(du, dv), 1e-9)
            nu, nv = -dv / length, du / length
            nus[line, d], nvs[line, d] = nu, nv
            for k in range(n_s):
                u, v = uu[line, d, k], vv[line, d, k]
                if not (u >= 0 and u <= img_w - 1 and v >= 0 and v <= img_h - 1):
                    continue
                best = 0.0
                for off in (-1.0, 0.0, 1.0):
                    ui = int(min(max(np.rint(u + off * nu), 0.0), img_w - 1.0))
                    vi = int(min(max(np.rint(v + off * nv), 0.0), img_h - 1.0))
                    val = abs(np.float64(gx[vi - y0, ui - x0]) * nu
                              + np.float64(gy[vi - y0, ui - x0]) * nv)
                    best = max(best, val)
                grad[line, d, k] = best
    ev = np.empty((n_d, n_s))
    sep = np.empty((n_d, n_s))
    shift = np.empty((n_d, n_s))
    for d in range(n_d):
        for k in range(n_s):
            ev[d, k] = min(grad[0, d, k], grad[1, d, k])
            sep[d, k] = abs((uu[1, d, k] - uu[0, d, k]) * nus[0, d]
                            + (vv[1, d, k] - vv[0, d, k]) * nvs[0, d])
            shift[d, k] = math.hypot(uu[1, d, k] - uu[0, d, k], vv[1, d, k] - vv[0, d, k])
    return ev, sep, shift


nb_outline = _jit(_outline_kernel)


def _outline_patch_kernel(foot, cos_d, sin_d, steps, origin, fwd, lft, nup, height, f, cx,
                          cy, img_w, img_h):
    """`_FrameContext.outline_evidence` up to its gradient patch (for numba): the same
    arithmetic in the same order. Returns (the samples (D, S, 2), x0, x1, y0, y1, ok);
    not ok (a bound not finite: the numpy path raises) leaves the bounds 0."""
    n_d, n_s = cos_d.shape[0], steps.shape[0]
    points = np.empty((n_d, n_s, 2))
    u_lo = v_lo = math.inf
    u_hi = v_hi = -math.inf
    for i in range(n_d + 1):           # the foot, then each direction's far end
        ex, ey = foot[0], foot[1]
        if i:
            for k in range(n_s):
                points[i - 1, k, 0] = foot[0] + steps[k] * cos_d[i - 1]
                points[i - 1, k, 1] = foot[1] + steps[k] * sin_d[i - 1]
            ex, ey = points[i - 1, n_s - 1, 0], points[i - 1, n_s - 1, 1]
        e0 = origin[0] + ex * fwd[0] + ey * lft[0]
        e1 = origin[1] + ex * fwd[1] + ey * lft[1]
        e2 = origin[2] + ex * fwd[2] + ey * lft[2]
        for lift in range(2):
            q0, q1, q2 = e0, e1, e2
            if lift:
                q0, q1, q2 = e0 + height * nup[0], e1 + height * nup[1], e2 + height * nup[2]
            q2 = q2 if (q2 >= 1e-6 or q2 != q2) else 1e-6
            u, v = f * q0 / q2 + cx, f * q1 / q2 + cy
            u_lo, u_hi, v_lo, v_hi = min(u_lo, u), max(u_hi, u), min(v_lo, v), max(v_hi, v)
            if not (math.isfinite(u) and math.isfinite(v)):
                return points, 0, 0, 0, 0, False
    x0 = int(min(max(math.floor(u_lo) - 3.0, 0.0), img_w - 1.0))
    x1 = int(min(max(math.ceil(u_hi) + 4.0, x0 + 1.0), float(img_w)))
    y0 = int(min(max(math.floor(v_lo) - 3.0, 0.0), img_h - 1.0))
    y1 = int(min(max(math.ceil(v_hi) + 4.0, y0 + 1.0), float(img_h)))
    return points, x0, x1, y0, y1, True


nb_outline_patch = _jit(_outline_patch_kernel)


def _sorted_median_kernel(x):
    """``faces._row_median`` of a 1-D float array (for numba; numpy's sort: NaN last,
    NaN if any)."""
    s = np.sort(x)
    n = s.shape[0]
    if s[n - 1] != s[n - 1]:
        return np.nan
    if n % 2:
        return s[n // 2]
    return (s[n // 2 - 1] + s[n // 2]) / 2.0


def _lone_support_kernel(ev, sep, shift, bar_factor, noise_floor, step_m, min_m,
                         min_sep_px, min_sep_fraction):
    """`faces.lone_face_points`' test of one foot's faces after `_outline_kernel` (for
    numba): ev, sep, shift (D, S) float64 C-contiguous. The bar: ``bar_factor`` times
    the median of the rows' means (numpy's pairwise sums over S), at least
    ``noise_floor``; each row's running sum of (ev - bar) (numpy's cumsum), its first
    largest (numpy's argmax, NaN first) ``end`` and that sum ``support``; returns
    ((D,) bool ok, (D,) int64 end, (D,) float64 support), ok where the support is
    positive, the face (end + 1) * step_m >= min_m long, its row medians of sep and of
    sep / max(shift, 1e-9) at least min_sep_px and min_sep_fraction."""
    n_d, n_s = ev.shape[0], ev.shape[1]
    flat = ev.reshape(n_d * n_s)
    means = np.empty(n_d)
    for d in range(n_d):
        means[d] = _nb_pairwise_sum(flat, d * n_s, (d + 1) * n_s) / n_s
    bar = bar_factor * nb_sorted_median(means)
    if noise_floor > bar:
        bar = noise_floor
    ok = np.zeros(n_d, np.bool_)
    end = np.zeros(n_d, np.int64)
    support = np.empty(n_d)
    row = np.empty(n_s)
    for d in range(n_d):
        # np.cumsum's running sum, np.argmax's first largest (the first NaN)
        g = ev[d, 0] - bar
        mp = g
        best = 0
        for k in range(1, n_s):
            if mp != mp:
                break
            g = g + (ev[d, k] - bar)
            if not g <= mp:
                mp = g
                best = k
        end[d] = best
        support[d] = mp
        if not (mp > 0.0 and (best + 1) * step_m >= min_m):
            continue
        if not nb_sorted_median(sep[d]) >= min_sep_px:
            continue
        for k in range(n_s):
            sh = shift[d, k]
            row[k] = sep[d, k] / (sh if (sh >= 1e-9 or sh != sh) else 1e-9)
        ok[d] = nb_sorted_median(row) >= min_sep_fraction
    return ok, end, support


nb_sorted_median = _jit(_sorted_median_kernel)
nb_lone_support = _jit(_lone_support_kernel)


def _contact_bounds_kernel(ua, va, ub, vb, un, vn, ok, img_w, img_h):
    """The patch of each search of `_FrameContext.contact_edge_scores` (for numba): the
    bounding box of its feet (ua, va), (ub, vb) (T,) and candidates ``ok`` (un, vn)
    (T, M), pixels, widened by 3 (4 past the far side), within the image: (T,) int64
    x0, x1, y0, y1 each (x1, y1 exclusive), as numpy's floor, ceil and clipping give."""
    t_n, m = ok.shape
    x0 = np.empty(t_n, np.int64)
    x1 = np.empty(t_n, np.int64)
    y0 = np.empty(t_n, np.int64)
    y1 = np.empty(t_n, np.int64)
    for t in range(t_n):
        u_lo, u_hi = min(ua[t], ub[t]), max(ua[t], ub[t])
        v_lo, v_hi = min(va[t], vb[t]), max(va[t], vb[t])
        for k in range(m):
            if ok[t, k]:
                u_lo, u_hi = min(u_lo, un[t, k]), max(u_hi, un[t, k])
                v_lo, v_hi = min(v_lo, vn[t, k]), max(v_hi, vn[t, k])
        x0[t] = min(max(np.int64(math.floor(u_lo)) - 3, 0), img_w - 1)
        x1[t] = min(max(np.int64(math.ceil(u_hi)) + 4, x0[t] + 1), img_w)
        y0[t] = min(max(np.int64(math.floor(v_lo)) - 3, 0), img_h - 1)
        y1[t] = min(max(np.int64(math.ceil(v_hi)) + 4, y0[t] + 1), img_h)
    return x0, x1, y0, y1


nb_contact_bounds = _jit(_contact_bounds_kernel)


def _contact_kernel(ua, va, ub, vb, un, vn, ok, x0, x1, y0, y1, gx0, gy0, gx, gy):
    """The sampling of `_FrameContext.contact_edge_scores` (for numba): the same samples,
    clipping and arithmetic, the mean of 16 samples as numpy's pairwise sum; (T, M)."""
    t_n, m = ok.shape
    out = np.full((t_n, m), -np.inf)
    best = np.empty(16)
    for t in range(t_n):
        fx, fy = np.float64(x0[t]), np.float64(y0[t])
        w_max, h_max = x1[t] - x0[t] - 1, y1[t] - y0[t] - 1
        ox, oy = x0[t] - gx0, y0[t] - gy0
        for k in range(m):
            if not ok[t, k]:
                continue
            u1, v1 = un[t, k] - fx, vn[t, k] - fy
            tot = 0.0
            lsum = 0.0
            for s in range(2):
                u0 = (ua[t] if s == 0 else ub[t]) - fx
                v0 = (va[t] if s == 0 else vb[t]) - fy
                du, dv = u1 - u0, v1 - v0
                length = math.hypot(du, dv)
                nu = -dv / max(length, 1e-9)
                nv = du / max(length, 1e-9)
                for i in range(16):
                    ti = (i + 0.5) / 16.0
                    uu, vv = u0 + ti * du, v0 + ti * dv
                    bi = 0.0
                    for o in range(3):
                        off = o - 1.0
                        ui = min(max(np.int64(np.rint(uu + off * nu)), 0), w_max)
                        vi = min(max(np.int64(np.rint(vv + off * nv)), 0), h_max)
                        val = abs(np.float64(gx[vi + oy, ui + ox]) * nu
                                  + np.float64(gy[vi + oy, ui + ox]) * nv)
                        bi = val if o == 0 else max(bi, val)
                    best[i] = bi
                # numpy's pairwise sum of 16: eight partial sums, then a tree
                r0, r1 = best[0] + best[8], best[1] + best[9]
                r2, r3 = best[2] + best[10], best[3] + best[11]
                r4, r5 = best[4] + best[12], best[5] + best[13]
                r6, r7 = best[6] + best[14], best[7] + best[15]
                mean = (((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))) / 16.0
                tot += mean * length
                lsum += length
            out[t, k] = tot / max(lsum, 1e-9)
    return out


nb_contact = _jit(_contact_kernel)


def _walk_down_kernel(start, nxt, exm, sig, k, steps):
    """The walk of `string_feet` down each matched run (for numba): from each start,
    follow ``nxt`` while there is a next pixel and the excess is above ``k`` sigmas, at
    most ``steps`` times; (S,) int64 the pixels reached."""
    out = start.copy()
    for s in range(out.shape[0]):
        c = out[s]
        for _ in range(steps):
            n = nxt[c]
            if n < 0 or not exm[c] > k * sig[c]:
                break
            c = n
        out[s] = c
    return out


nb_walk_down = _jit(_walk_down_kernel)


#: Relative rounding slack of the compiled `_body_gap` test (`_body_gap_kernel`): its
#: sums of products may differ from numpy's BLAS products (fused multiply-adds) in the
#: last bits; ground points this close to the strip's sides leave the decision to numpy.
_GAP_SLACK = 1e-12


def _body_gap_kernel(g, ax, ay, bx, by):
    """`_body_gap` (for numba) of the feet (ax, ay), (bx, by) and ground g (G, 2): 1 when
    it is sure to be True, 0 when sure to be False, -1 when a ground point (or the
    camera's side of the segment) lies within rounding distance of the strip's sides
    (``_GAP_SLACK`` times the size of the products): then only `_body_gap` decides.

    The same quantities as `_body_gap`: e = b - a, t = e / |e|, nrm = (-t_y, t_x) turned
    towards the camera's far side (nrm . (a + b) / 2 >= 0), and for each ground point
    p - a its coordinates along t and along nrm."""
    ex, ey = bx - ax, by - ay
    length = math.hypot(ex, ey)
    if g.shape[0] == 0 or length <= 2.0 * _BODY_GAP_END_M:
        return 0
    tx, ty = ex / length, ey / length
    nx, ny = -ty, tx
    mx, my = 0.5 * (ax + bx), 0.5 * (ay + by)
    p0, p1 = nx * mx, ny * my
    side = p0 + p1
    if abs(side) <= _GAP_SLACK * (abs(p0) + abs(p1)):
        return -1
    if side < 0.0:                     # pointing away from the camera
        nx, ny = -nx, -ny
    lo, hi = _BODY_GAP_BAND_M
    end0, end1 = _BODY_GAP_END_M, length - _BODY_GAP_END_M
    sure, maybe = 0, 0
    for p in range(g.shape[0]):
        rx, ry = g[p, 0] - ax, g[p, 1] - ay
        q0, q1 = rx * tx, ry * ty
        along = q0 + q1
        ta = _GAP_SLACK * (abs(q0) + abs(q1))
        q0, q1 = rx * nx, ry * ny
        behind = q0 + q1
        tb = _GAP_SLACK * (abs(q0) + abs(q1))
        if (along > end0 - ta and along < end1 + ta and behind > lo - tb
                and behind < hi + tb):
            maybe += 1
            if (along > end0 + ta and along < end1 - ta and behind > lo + tb
                    and behind < hi - tb):
                sure += 1
                if sure >= _FACE_BEHIND_MIN:
                    return 1
    return 0 if maybe < _FACE_BEHIND_MIN else -1


def _first_min(x, k, best):
    """Whether x[k] replaces x[best] as ``np.argmin``'s answer scanning in order: smaller,
    or the first NaN (which numpy returns)."""
    return not math.isnan(x[best]) and (math.isnan(x[k]) or x[k] < x[best])


def _soft_args_kernel(xy, sr, group, want, n_groups, two):
    """The per-foot exponents of `soft_nearest` for the feet of the groups ``want``
    (n_groups,) bool (for numba). ``two`` is 2.0, passed at run time: the nearest
    foot's sigma squared is ``pow(s_near, 2)`` as numpy squares a scalar (libm's pow,
    which the compiler would otherwise turn into s * s).

    Returns:
        idx (P,) int64 the feet by group, ascending within each (as ``np.argsort(group,
        kind='stable')``); start (n_groups + 1,) int64 each group's first row in idx;
        near (n_groups,) int64 each group's nearest foot (``np.argmin`` of the range,
        first of equals), -1 for none; arg (P,) float64
        ``-0.5 (r - r_near)^2 / max(s^2 + s_near^2, 1e-12)`` (numpy's operations).
    """
    s_n = group.shape[0]
    start = np.zeros(n_groups + 1, np.int64)
    for i in range(s_n):
        if want[group[i]]:
            start[group[i] + 1] += 1
    for k in range(n_groups):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    idx = np.empty(start[n_groups], np.int64)
    r = np.empty(s_n)
    for i in range(s_n):
        k = group[i]
        if want[k]:
            idx[fill[k]] = i
            fill[k] += 1
            r[i] = math.hypot(xy[i, 0], xy[i, 1])
    near = np.full(n_groups, -1, np.int64)
    arg = np.empty(idx.shape[0])
    for k in range(n_groups):
        if start[k] == start[k + 1]:
            continue
        j = idx[start[k]]
        for p in range(start[k] + 1, start[k + 1]):
            if nb_first_min(r, idx[p], j):
                j = idx[p]
        near[k] = j
        rj, sj2 = r[j], math.pow(sr[j], two)
        for p in range(start[k], start[k + 1]):
            i = idx[p]
            dr = r[i] - rj
            den = sr[i] * sr[i] + sj2
            if not (den >= 1e-12 or math.isnan(den)):     # np.maximum(den, 1e-12)
                den = 1e-12
            arg[p] = -0.5 * (dr * dr) / den
    return idx, start, near, arg


def _soft_far_kernel(xy, idx, start, near, w):
    """(P,) bool: the feet of `_soft_args_kernel`'s rows that `soft_nearest` tests for a
    body gap: weight above 0.01 and more than ``_BODY_GAP_SPAN_M`` from the nearest foot
    (for numba)."""
    far = np.zeros(idx.shape[0], np.bool_)
    for k in range(near.shape[0]):
        j = near[k]
        for p in range(start[k], start[k + 1]):
            i = idx[p]
            far[p] = (w[p] > 0.01 and math.hypot(xy[i, 0] - xy[j, 0], xy[i, 1] - xy[j, 1])
                      > _BODY_GAP_SPAN_M)
    return far


def _soft_finish_kernel(xy, idx, start, near, w, far, g):
    """The weighted means of `soft_nearest` (for numba): per group, the weights w (P,)
    with those of the ``far`` feet that visible ground g (G, 2) separates from the
    nearest foot set to 0 (`_body_gap_kernel`), then sum(w xy) / sum(w) in numpy's order
    (the products' column sums in order, the weights' pairwise).

    Returns:
        ((n_groups, 2) float64 the points, NaN for groups without feet; (n_groups,) bool,
        the groups left to numpy (a body-gap test too close to call, or more than 128
        feet), their point not computed).
    """
    n_g = near.shape[0]
    out = np.full((n_g, 2), np.nan)
    undecided = np.zeros(n_g, np.bool_)
    ww = w.copy()
    for k in range(n_g):
        j = near[k]
        if j < 0:
            continue
        if start[k + 1] - start[k] > 128:       # numpy sums more values by halves
            undecided[k] = True
            continue
        for p in range(start[k], start[k + 1]):
            if not far[p]:
                continue
            i = idx[p]
            gap = nb_body_gap(g, xy[j, 0], xy[j, 1], xy[i, 0], xy[i, 1])
            if gap < 0:
                undecided[k] = True
                break
            if gap == 1:
                ww[p] = 0.0
        if undecided[k]:
            continue
        sx, sy = 0.0, 0.0
        for p in range(start[k], start[k + 1]):
            i = idx[p]
            sx += ww[p] * xy[i, 0]
            sy += ww[p] * xy[i, 1]
        den = _nb_pairwise_sum(ww, start[k], start[k + 1])
        out[k, 0] = sx / den
        out[k, 1] = sy / den
    return out, undecided


nb_first_min = _jit(_first_min)
nb_body_gap = _jit(_body_gap_kernel)
nb_soft_args = _jit(_soft_args_kernel)
nb_soft_far = _jit(_soft_far_kernel)
nb_soft_finish = _jit(_soft_finish_kernel)


def _inside_by_kernel(ax, ay, nx, ny, bx, by, gx, gy, sgn, margin):
    """Whether the point g lies more than ``margin`` inside the triangle a-n-b of
    orientation ``sgn`` (+1 counter-clockwise), metres (for numba): each side's signed
    distance side(p0, p1) from the line p0 -> p1 (left positive) times sgn exceeds it
    (`_ground_inside`'s arithmetic)."""
    e0x, e0y = nx - ax, ny - ay                             # a -> n
    l0 = max(math.hypot(e0x, e0y), 1e-12)
    if not sgn * ((e0x * (gy - ay) - e0y * (gx - ax)) / l0) > margin:
        return False
    e1x, e1y = bx - nx, by - ny                             # n -> b
    l1 = max(math.hypot(e1x, e1y), 1e-12)
    if not sgn * ((e1x * (gy - ny) - e1y * (gx - nx)) / l1) > margin:
        return False
    e2x, e2y = ax - bx, ay - by                             # b -> a
    l2 = max(math.hypot(e2x, e2y), 1e-12)
    return sgn * ((e2x * (gy - by) - e2y * (gx - bx)) / l2) > margin


nb_inside_by = _jit(_inside_by_kernel)


def _corner_free_kernel(g, a, b, c, r, n, margin):
    """The free-space test of `hidden_corners` (for numba): (T, M) bool, whether no ground
    point g (G, 2) lies inside the triangle a[t]-n[t, k]-b[t] by more than ``margin``
    (c, r (T, 2), (T,): the searches' circles). The same prefilters and arithmetic as
    the numpy path (bounding box of all circles, off the chord and inside the circle,
    then `_ground_inside`)."""
    t_n, m = n.shape[0], n.shape[1]
    ok = np.ones((t_n, m), np.bool_)
    lo0, lo1, hi0, hi1 = np.inf, np.inf, -np.inf, -np.inf
    for t in range(t_n):
        lo0 = min(lo0, c[t, 0] - r[t])
        lo1 = min(lo1, c[t, 1] - r[t])
        hi0 = max(hi0, c[t, 0] + r[t])
        hi1 = max(hi1, c[t, 1] + r[t])
    lo0 -= margin
    lo1 -= margin
    hi0 += margin
    hi1 += margin
    area2 = np.empty(m)
    for t in range(t_n):
        ax, ay, bx, by = a[t, 0], a[t, 1], b[t, 0], b[t, 1]
        ex, ey = ax - bx, ay - by
        chord = max(math.hypot(ex, ey), 1e-12)
        rr = (r[t] * 1.001) ** 2
        for k in range(m):
            area2[k] = ((n[t, k, 0] - ax) * (by - ay) - (n[t, k, 1] - ay) * (bx - ax))
        for p in range(g.shape[0]):
            gx, gy = g[p, 0], g[p, 1]
            if not (gx >= lo0 and gx <= hi0 and gy >= lo1 and gy <= hi1):
                continue
            off = abs(ex * (gy - by) - ey * (gx - bx))
            dx, dy = gx - c[t, 0], gy - c[t, 1]
            if not (off > (margin * 0.999) * chord and dx * dx + dy * dy < rr):
                continue
            for k in range(m):
                if not ok[t, k] or not abs(area2[k]) > 1e-12:
                    continue
                sgn = 1.0 if area2[k] > 0 else -1.0
                if nb_inside_by(ax, ay, n[t, k, 0], n[t, k, 1], bx, by, gx, gy, sgn,
                                 margin):
                    ok[t, k] = False
    return ok


nb_corner_free = _jit(_corner_free_kernel)


#: The candidates' positions along the Thales arc, 0..1 (`hidden_corners`).
_ARC_LIN = np.linspace(0.0, 1.0, _CORNER_ARC_POINTS)


def _arcs_kernel(a, b, sigma):
    """The circles and near arcs of `hidden_corners`' searches (for numba), with its
    arithmetic (libm's hypot and atan2, Python's float modulo).

    Args:
        a, b: (T, 2) silhouette feet, metres; sigma: (T,) their range sigmas.
    Returns:
        ok (T,) bool, the searches whose corner could bulge enough (rho > 2 sigma) and
        whose circle leaves out the camera's foot; c (T, 2) the circles' centres
        (a + b) / 2, rho (T,) their radii |b - a| / 2; a0 (T,) the angle of a from c,
        span (T,) the near arc from a to b, radians (negative: clockwise).
    """
    t_n = a.shape[0]
    ok = np.zeros(t_n, np.bool_)
    c = np.empty((t_n, 2))
    rho = np.empty(t_n)
    a0 = np.empty(t_n)
    span = np.empty(t_n)
    two_pi = 2 * math.pi
    for t in range(t_n):
        cx, cy = 0.5 * (a[t, 0] + b[t, 0]), 0.5 * (a[t, 1] + b[t, 1])
        c[t, 0], c[t, 1] = cx, cy
        r = 0.5 * math.hypot(b[t, 0] - a[t, 0], b[t, 1] - a[t, 1])
        rho[t] = r
        if r <= _CORNER_SIGMAS * sigma[t] or math.hypot(cx, cy) <= r:
            continue
        ang0 = math.atan2(a[t, 1] - cy, a[t, 0] - cx)
        sp = (math.atan2(b[t, 1] - cy, b[t, 0] - cx) - ang0) % two_pi      # a -> b, ccw
        if (math.atan2(-cy, -cx) - ang0) % two_pi > sp:                    # near half cw
            sp -= two_pi
        ok[t] = True
        a0[t] = ang0
        span[t] = sp
    return ok, c, rho, a0, span


nb_arcs = _jit(_arcs_kernel)


def _extremes_kernel(group, n_groups, brg, r):
    """Per group of feet (for numba): the number of feet, and the feet of largest and
    smallest bearing and of smallest range, (n_groups,) int64 each (-1 for none): the
    first of equals, or the first NaN, as ``np.argmax`` / ``np.argmin`` over the group's
    feet in order."""
    count = np.zeros(n_groups, np.int64)
    i_max = np.full(n_groups, -1, np.int64)
    i_min = np.full(n_groups, -1, np.int64)
    i_near = np.full(n_groups, -1, np.int64)
    for p in range(group.shape[0]):
        k = group[p]
        if count[k] == 0:
            i_max[k] = i_min[k] = i_near[k] = p
        else:
            b, bm = brg[p], brg[i_max[k]]
            if not math.isnan(bm) and (math.isnan(b) or b > bm):
                i_max[k] = p
            if nb_first_min(brg, p, i_min[k]):
                i_min[k] = p
            if nb_first_min(r, p, i_near[k]):
                i_near[k] = p
        count[k] += 1
    return count, i_max, i_min, i_near


nb_extremes = _jit(_extremes_kernel)


def _owners_kernel(xw, top, xy, g_lab, height, radius, cam_h, sw, sf, bw, bf, g_all):
    """`silhouette_owners` (for numba), with its tests and arithmetic; ``bw``, ``bf``
    (W,), (S,) the bearings of the candidates and feet (numpy's arctan2), ``g_all``
    (G, 2) the visible ground.

    Returns:
        (W,) int64 obstacle of each candidate, -1 for none.
    """
    w_n, s_n = xw.shape[0], xy.shape[0]
    m_ = _FREE_SPACE_MARGIN_M
    lab = np.full(w_n, -1, np.int64)
    for w in range(w_n):
        best, j = np.inf, 0
        tp = top[w]
        for q in range(s_n):
            hk = height[g_lab[q]]
            d = math.hypot(xw[w, 0] - xy[q, 0], xw[w, 1] - xy[q, 1])
            if (d <= radius and tp * _WEAK_HEIGHT_RATIO >= hk and tp <= _WEAK_HEIGHT_RATIO * hk
                    and d < best):
                best, j = d, q
        if best < np.inf:
            lab[w] = g_lab[j]
    out = np.full(w_n, -1, np.int64)
    n_k = 0
    for w in range(w_n):
        n_k = max(n_k, lab[w] + 1)
    for k in range(n_k):
        # its feet, their bearings' extremes, its candidates
        n_f = 0
        b_hi, b_lo = -np.inf, np.inf
        for q in range(s_n):
            if g_lab[q] == k:
                n_f += 1
                b_hi = max(b_hi, bf[q])
                b_lo = min(b_lo, bf[q])
        if n_f == 0:
            continue
        f = np.empty((n_f, 2))
        sf_k = np.empty(n_f)
        n_f = 0
        for q in range(s_n):
            if g_lab[q] == k:
                f[n_f, 0], f[n_f, 1] = xy[q, 0], xy[q, 1]
                sf_k[n_f] = sf[q]
                n_f += 1
        for sgn in (1.0, -1.0):
            # the candidates beyond the feet on this side, outermost first (stable)
            side = np.empty(w_n, np.int64)
            n_side = 0
            for w in range(w_n):
                if lab[w] != k:
                    continue
                tol = m_ / max(math.hypot(xw[w, 0], xw[w, 1]), 1e-9)
                if (bw[w] > b_hi + tol) if sgn > 0 else (bw[w] < b_lo - tol):
                    side[n_side] = w
                    n_side += 1
            # outermost first: by -sgn * bearing, stably (insertion sort; a few each)
            for t in range(1, n_side):
                w, kw = side[t], -sgn * bw[side[t]]
                q = t
                while q > 0 and -sgn * bw[side[q - 1]] > kw:
                    side[q] = side[q - 1]
                    q -= 1
                side[q] = w
            for t in range(n_side):
                w = side[t]
                if n_f >= 2 and nb_separated(xw[w, 0], xw[w, 1], f, g_all, m_):
                    continue
                if nb_face_hides(xw[w, 0], xw[w, 1], sw[w], f, sf_k, g_all,
                                  height[k] / cam_h, m_, _FACE_HIDDEN_MIN):
                    continue
                out[w] = k
                break
    return out


def _face_hides_kernel(wx, wy, sw, f, sf, g_all, h_ratio, margin, need):
    """Whether ``need`` or more ground points of g_all (G, 2) would be hidden by a body
    standing on the segments from w = (wx, wy) to the points f (F, 2), of height
    ``h_ratio`` times the camera's (for numba; ground coordinates from the point below
    the camera, metres; ``sw``, ``sf`` (F,) the range sigmas of w and f).

    The camera's ray to a ground point g at range r passes below the height h at
    horizontal distances beyond r (1 - h / H). A vertical face on a segment w-p that the
    ray crosses there, between r (1 - h / H) + ``margin`` and r - ``margin`` - sigma
    (the larger range sigma of w and p: where the face is) and more than ``margin`` from
    both of the segment's ends, hides g. A body whose footprint holds w and p (convex:
    its silhouette edge at w) holds the segment.
    """
    if g_all.shape[0] == 0 or f.shape[0] == 0 or not h_ratio > 0.0:
        return False
    # bearing and range window of the points that can be behind a segment
    b_lo = b_hi = math.atan2(wy, wx)
    r_lo = r_hi = math.hypot(wx, wy)
    for i in range(f.shape[0]):
        b = math.atan2(f[i, 1], f[i, 0])
        r = math.hypot(f[i, 0], f[i, 1])
        b_lo, b_hi = min(b_lo, b), max(b_hi, b)
        r_lo, r_hi = min(r_lo, r), max(r_hi, r)
    r_hi = r_hi / max(1.0 - h_ratio, 1e-6)
    count = 0
    for p in range(g_all.shape[0]):
        gx, gy = g_all[p, 0], g_all[p, 1]
        rg = math.hypot(gx, gy)
        if not (rg > r_lo and rg < r_hi + margin):      # rg > r_lo >= 0
            continue
        bg = math.atan2(gy, gx)
        if not (bg > b_lo and bg < b_hi):
            continue
        ux, uy = gx / rg, gy / rg
        s_lo = rg * (1.0 - h_ratio) + margin
        for i in range(f.shape[0]):
            s_hi = rg - margin - max(sw, sf[i])
            if not s_lo < s_hi:
                continue
            ex, ey = f[i, 0] - wx, f[i, 1] - wy
            den = ux * ey - uy * ex                 # cross(u, e)
            le = math.hypot(ex, ey)
            if abs(den) < 1e-12 or le <= 2.0 * margin:
                continue
            s_c = (wx * ey - wy * ex) / den         # cross(w, e) / cross(u, e)
            t_c = (wx * uy - wy * ux) / den         # cross(w, u) / cross(u, e)
            if (s_c > s_lo and s_c < s_hi and t_c * le > margin
                    and (1.0 - t_c) * le > margin):
                count += 1
                break
        if count >= need:
            return True
    return False


nb_face_hides = _jit(_face_hides_kernel)


def _separated_kernel(wx, wy, f, g_all, margin):
    """`_separated` (for numba): whether a ground point of g_all (G, 2) lies more than
    ``margin`` inside a triangle w-p-q, p, q two of the points f (F, 2) (`_ground_inside`'s
    arithmetic, triangles a = p, n = w, b = q)."""
    if g_all.shape[0] == 0:
        return False
    lo0, lo1, hi0, hi1 = wx, wy, wx, wy
    for i in range(f.shape[0]):
        lo0, hi0 = min(lo0, f[i, 0]), max(hi0, f[i, 0])
        lo1, hi1 = min(lo1, f[i, 1]), max(hi1, f[i, 1])
    lo0, lo1, hi0, hi1 = lo0 - margin, lo1 - margin, hi0 + margin, hi1 + margin
    for p in range(g_all.shape[0]):
        gx, gy = g_all[p, 0], g_all[p, 1]
        if not (gx >= lo0 and gx <= hi0 and gy >= lo1 and gy <= hi1):
            continue
        for i in range(f.shape[0]):
            ax, ay = f[i, 0], f[i, 1]
            for j in range(i + 1, f.shape[0]):
                bx, by = f[j, 0], f[j, 1]
                area2 = (wx - ax) * (by - ay) - (wy - ay) * (bx - ax)
                if not abs(area2) > 1e-12:
                    continue
                sgn = 1.0 if area2 > 0 else -1.0
                if nb_inside_by(ax, ay, wx, wy, bx, by, gx, gy, sgn, margin):
                    return True
    return False


nb_separated = _jit(_separated_kernel)
nb_owners = (_jit(_owners_kernel) if nb_separated is not None and nb_face_hides is not None
              else None)


def warm_up(compiled: bool) -> None:
    """Compile these kernels (called by `kernels.warm_up`); ``compiled`` False: numba is
    missing or failed, and the numpy paths are used."""
    global nb_corner_free, nb_contact, nb_walk_down, nb_extremes, nb_soft_args, nb_arcs, \
        nb_contact_bounds, nb_owners, nb_outline, nb_face_hides, nb_lone_support, \
        nb_outline_patch
    if not compiled:
        nb_corner_free = nb_contact = nb_walk_down = nb_extremes = nb_soft_args = None
        nb_arcs = nb_contact_bounds = nb_owners = nb_outline = nb_face_hides = None
        nb_lone_support = nb_outline_patch = None
        return
    f2, f1, i1 = np.zeros((1, 2)), np.zeros(1), np.zeros(1, np.int64)
    nb_corner_free = _warmed(nb_corner_free, f2, f2, f2, f2, f1 + 1.0, np.zeros((1, 1, 2)),
                             0.05)
    nb_contact = _warmed(nb_contact, f1, f1, f1, f1, f2[:, :1], f2[:, :1],
                         np.ones((1, 1), bool), i1, i1 + 1, i1, i1 + 1, 0, 0,
                         np.zeros((1, 1), np.float32), np.zeros((1, 1), np.float32))
    nb_walk_down = _warmed(nb_walk_down, i1, i1 - 1, f1, f1, 2.0, 1)
    nb_arcs = _warmed(nb_arcs, f2, f2, f1)
    # (also called on its own, by `faces.lone_face_points`)
    nb_face_hides = _warmed(nb_face_hides, 0.0, 0.0, 0.0, f2, f1, f2, 0.5,
                            _FREE_SPACE_MARGIN_M, _FACE_HIDDEN_MIN)
    nb_owners = _warmed(nb_owners, f2, f1, np.zeros((2, 2)), np.zeros(2, np.int64), f1 + 1.0,
                        0.5, 1.2, f1, np.zeros(2), f1, np.zeros(2), f2)
    nb_contact_bounds = _warmed(nb_contact_bounds, f1, f1, f1, f1, f2[:, :1], f2[:, :1],
                                np.ones((1, 1), bool), 2, 2)
    g32 = np.zeros((2, 2), np.float32)
    nb_outline = _warmed(nb_outline, np.ones((1, 2, 2)), np.zeros(3), np.zeros(3),
                         np.zeros(3), np.zeros(3), 0.1, 300.0, 1.0, 1.0, g32, g32, 0, 0, 2, 2)
    nb_outline_patch = _warmed(nb_outline_patch, f2[0], f1, f1, f1 + 0.02, np.zeros(3),
                               np.zeros(3), np.zeros(3), np.zeros(3), 0.1, 300.0, 1.0, 1.0,
                               2, 2)
    nb_lone_support = _warmed(nb_lone_support, np.ones((2, 3)), np.ones((2, 3)),
                              np.ones((2, 3)), 2.0, 0.0, 0.02, 0.1, 2.5, 0.8)
    # The soft nearest points (four kernels, one switch) and the per-obstacle extremes.
    one = np.ones(1, bool)
    soft = _warmed(nb_soft_args, f2, f1 + 1.0, i1, one, 1, 2.0)
    if soft is not None:
        idx, start, near, arg = soft(f2, f1 + 1.0, i1, one, 1, 2.0)
        ok = (_warmed(nb_soft_far, f2, idx, start, near, f1 + 1.0) is not None
              and _warmed(nb_soft_finish, f2, idx, start, near, f1 + 1.0, one, f2)
              is not None)
        soft = soft if ok else None
    nb_soft_args = soft
    nb_extremes = _warmed(nb_extremes, i1, 1, f1, f1) if soft is not None else None
