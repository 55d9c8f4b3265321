"""Compiled inner loops (numba) of the edge-run, match, clustering, extent and
temporal-averaging stages, each the loop form of a numpy path kept beside its caller with
the same arithmetic; ``nb_*`` is None without numba. `warm_up` compiles all of GPOD's
kernels (also `kernels_geometry`) once per process.
"""
from __future__ import annotations

import math

import numpy as np

from ..edges import warm_up as edges_warm_up
from ..jit import jit as _jit
from ..jit import warmed as _warmed
from ..matching import warm_up as matching_warm_up
from ..surface_kernels import warm_up as surface_warm_up
from ..ground_plane import warm_up as plane_warm_up
from . import kernels_geometry

#: The compiled thinning (`_thin_kernel`) counts cells up to this many columns plus rows.
_THIN_MAX_CELLS = 1 << 16


def _thin_kernel(points, group, cell):
    """The groups and thinning of :func:`cluster_points_2d` (for numba): (N,) int64 the
    rank of each point's group among the distinct groups, the thinned points (nr, 2) and
    their groups (nr,) -- the first point of each (group, cell), cells of side ``cell``
    from the points' minimum, in the order of the cell keys (counting sorts by group,
    column and row) -- and the number of groups (-1, nothing thinned, when the points
    span more than ``_THIN_MAX_CELLS`` cells across: the numpy path thins them)."""
    n = points.shape[0]
    g_lo, g_hi = group[0], group[0]
    for i in range(n):
        g_lo, g_hi = min(g_lo, group[i]), max(g_hi, group[i])
    gk = np.empty(n, np.int64)
    for i in range(n):
        gk[i] = group[i] - g_lo
    order = nb_stable_order(gk, np.arange(n), g_hi - g_lo + 1)
    g = np.empty(n, np.int64)
    n_g = 0
    for t in range(n):
        i = order[t]
        if t > 0 and group[i] != group[order[t - 1]]:
            n_g += 1
        g[i] = n_g
    n_g += 1
    lo0, lo1 = points[0, 0], points[0, 1]
    for i in range(1, n):
        lo0, lo1 = min(lo0, points[i, 0]), min(lo1, points[i, 1])
    f0 = np.empty(n, np.int64)
    f1 = np.empty(n, np.int64)
    m0, m1 = 0, 0
    for i in range(n):
        f0[i] = np.int64(math.floor((points[i, 0] - lo0) / cell))
        f1[i] = np.int64(math.floor((points[i, 1] - lo1) / cell))
        m0, m1 = max(m0, f0[i]), max(m1, f1[i])
    if m0 + m1 > _THIN_MAX_CELLS:           # points too far apart to count cells: numpy
        return g, np.empty((0, 2)), np.empty(0, np.int64), -1
    key = np.empty(n, np.int64)
    for i in range(n):
        key[i] = (g[i] * (m0 + 1) + f0[i]) * (m1 + 1) + f1[i]
    # stably by the key, i.e. by (group, f0, f1): the first of equal keys first
    ko = nb_stable_order(g, nb_stable_order(f0, nb_stable_order(f1, np.arange(n), m1 + 1),
                                              m0 + 1), n_g)
    nr = 0
    for t in range(n):
        if t == 0 or key[ko[t]] != key[ko[t - 1]]:
            nr += 1
    pts = np.empty((nr, 2))
    gr = np.empty(nr, np.int64)
    nr = 0
    for t in range(n):
        i = ko[t]
        if t == 0 or key[i] != key[ko[t - 1]]:
            pts[nr, 0], pts[nr, 1] = points[i, 0], points[i, 1]
            gr[nr] = g[i]
            nr += 1
    return g, pts, gr, n_g


nb_thin = _jit(_thin_kernel)


def _link_groups_kernel(pts, gr, n_g, r2):
    """The links and components of :func:`cluster_points_2d` (for numba), all pairs of
    the thinned points ``pts`` (nr, 2) of groups ``gr`` (nr,): (n_g,) int64 label of
    each group, 0..C-1 in order of each component's first group (as `_components`)."""
    parent = np.arange(n_g)
    nr = pts.shape[0]
    for i in range(nr):
        gi = gr[i]
        for j in range(i + 1, nr):
            gj = gr[j]
            if gj == gi:
                continue
            dx = pts[i, 0] - pts[j, 0]
            dy = pts[i, 1] - pts[j, 1]
            if dx * dx + dy * dy <= r2:
                x = gi
                while parent[x] != x:
                    parent[x] = parent[parent[x]]
                    x = parent[x]
                y = gj
                while parent[y] != y:
                    parent[y] = parent[parent[y]]
                    y = parent[y]
                if x != y:
                    if x < y:
                        parent[y] = x
                    else:
                        parent[x] = y
    label = np.empty(n_g, np.int64)
    name = np.full(n_g, -1, np.int64)
    n_c = 0
    for x in range(n_g):
        r = x
        while parent[r] != r:
            r = parent[r]
        if name[r] < 0:
            name[r] = n_c
            n_c += 1
        label[x] = name[r]
    return label


nb_link_groups = _jit(_link_groups_kernel)


def _runs_kernel(string_prev, left_index, d, n_edges, tol, window, x):
    """`run_links`, `matched_run_length` and `smooth_along_runs` of the matches (for
    numba), with their tests and order of summation.

    Args:
        string_prev: (E,) int32 the left EdgeMap's ``string_prev``; left_index (K,) int32,
            d (K,) float32 the matches' left edges and disparities; n_edges: E.
        tol: float32 largest disparity step within a run, pixels.
        window: smoothing window, pixels; x (K,) float64 the values smoothed.
    Returns:
        prev (K,) int64 the match one row up in the same run (-1 at a run's top); run
        (K,) int64 its run's length; smooth (K,) float64 the mean of x over up to
        ``window // 2`` pixels of the run on either side (in the order: itself, up, down);
        nxt (K,) int64 the match one row down (-1 at a run's bottom).
    """
    k = left_index.shape[0]
    feat_of_edge = np.full(n_edges, -1, np.int64)
    for i in range(k):
        feat_of_edge[left_index[i]] = i
    prev = np.full(k, -1, np.int64)
    for i in range(k):
        pe = string_prev[left_index[i]]
        if pe >= 0:
            p = feat_of_edge[pe]
            if p >= 0 and abs(d[i] - d[p]) <= tol:
                prev[i] = p
    nxt = np.full(k, -1, np.int64)
    for i in range(k):
        if prev[i] >= 0:
            nxt[prev[i]] = i
    # run lengths: the matches per run top
    root = np.empty(k, np.int64)
    for i in range(k):
        p = prev[i]
        if p < 0:
            root[i] = i
        elif p < i:
            root[i] = root[p]
        else:
            r = p
            while prev[r] >= 0:
                r = prev[r]
            root[i] = r
    size = np.zeros(k, np.int64)
    for i in range(k):
        size[root[i]] += 1
    run = np.empty(k, np.int64)
    for i in range(k):
        run[i] = size[root[i]]
    half = max(window, 1) // 2
    smooth = x.copy()
    if half > 0:
        for i in range(k):
            total, count = x[i], 1.0
            c = i
            for _ in range(half):
                c = prev[c] if c >= 0 else -1
                total += x[c] if c >= 0 else 0.0
                count += 1.0 if c >= 0 else 0.0
            c = i
            for _ in range(half):
                c = nxt[c] if c >= 0 else -1
                total += x[c] if c >= 0 else 0.0
                count += 1.0 if c >= 0 else 0.0
            smooth[i] = total / count
    return prev, run, smooth, nxt


nb_runs = _jit(_runs_kernel)


def _occluded_kernel(rs_o, tr_o, d_o, u_o, v_o, gradient_limit, neighbours):
    """The pair loop of :func:`occluded_matches` (for numba), same tests: (n,) bool,
    the farther match of each offending pair, in the sorted order."""
    n = rs_o.shape[0]
    far = np.zeros(n, np.bool_)
    for s in range(1, neighbours + 1):
        for i in range(n - s):
            j = i + s
            if rs_o[j] != rs_o[i]:
                continue
            dd = d_o[j] - d_o[i]
            if not (tr_o[j] if dd > 0 else tr_o[i]):
                continue
            if gradient_limit > 0 and abs(dd) <= gradient_limit:
                continue        # within limit * max(dist, 1) >= limit, whatever dist
            dist = math.hypot(u_o[j] - u_o[i], v_o[j] - v_o[i])
            if abs(dd) > gradient_limit * max(dist, 1.0):
                far[i if dd > 0 else j] = True
    return far


def _stable_order(key, rows, n_keys):
    """``rows[np.argsort(key[rows], kind='stable')]`` for int keys 0..n_keys-1 (for
    numba): a counting sort."""
    count = np.zeros(n_keys + 1, np.int64)
    for r in rows:
        count[key[r] + 1] += 1
    for q in range(n_keys):
        count[q + 1] += count[q]
    out = np.empty(rows.shape[0], np.int64)
    for r in rows:
        out[count[key[r]]] = r
        count[key[r]] += 1
    return out


def _occluded_all_kernel(r_string, right_index, tr, v, d, u_left, u_right, gradient_limit,
                         neighbours):
    """`occluded_matches` (for numba): the matches of the right strings with a trusted
    match, in the order of ``np.lexsort((v, right string))``, the same coordinates
    (float64 d, cyclopean u, v) and `_occluded_kernel`'s pair tests; (K,) bool."""
    k = right_index.shape[0]
    occ = np.zeros(k, np.bool_)
    if k < 2:
        return occ
    rs = np.empty(k, np.int64)
    n_rs, n_v, any_tr = 0, 0, False
    for i in range(k):
        rs[i] = r_string[right_index[i]]
        n_rs = max(n_rs, rs[i] + 1)
        n_v = max(n_v, np.int64(v[i]) + 1)
        any_tr = any_tr or tr[i]
    if not any_tr:
        return occ
    has = np.zeros(n_rs, np.bool_)
    for i in range(k):
        if tr[i]:
            has[rs[i]] = True
    n = 0
    for i in range(k):
        n += has[rs[i]]
    sub = np.empty(n, np.int64)
    n = 0
    for i in range(k):
        if has[rs[i]]:
            sub[n] = i
            n += 1
    vk = np.empty(k, np.int64)
    for i in range(k):
        vk[i] = v[i]
    order = nb_stable_order(rs, nb_stable_order(vk, sub, n_v), n_rs)
    rs_o = np.empty(n, np.int64)
    tr_o = np.empty(n, np.bool_)
    d_o = np.empty(n)
    u_o = np.empty(n)
    v_o = np.empty(n)
    for t in range(n):
        i = order[t]
        rs_o[t], tr_o[t], d_o[t] = rs[i], tr[i], np.float64(d[i])
        u_o[t] = 0.5 * (np.float64(u_left[i]) + np.float64(u_right[i]))
        v_o[t] = np.float64(v[i])
    far = nb_occluded(rs_o, tr_o, d_o, u_o, v_o, gradient_limit, min(neighbours, n - 1))
    for t in range(n):
        if far[t]:
            occ[order[t]] = True
    return occ


nb_occluded = _jit(_occluded_kernel)
nb_stable_order = _jit(_stable_order)
nb_occluded_all = _jit(_occluded_all_kernel)
_warm = False


def _hanging_kernel(bottom, left_index, d, below, feat_of_edge, prev, k, max_gap, tol,
                    slope, solid):
    """:func:`hanging_runs` after its candidate run bottoms, as loops (for numba): the
    same walk, tests and passes."""
    out = np.zeros(k, np.bool_)
    new = np.zeros(k, np.bool_)
    for _ in range(bottom.shape[0] + 1):
        new[:] = False
        for i in range(bottom.shape[0]):
            b = bottom[i]
            e = left_index[b]
            seen = False
            held = False
            for r in range(1, max_gap + 1):
                e = below[e]
                if e < 0:
                    break
                f = feat_of_edge[e]
                if f < 0:
                    continue
                seen = True
                if abs(d[f] - d[b]) <= tol + slope * r and solid[f] and not out[f]:
                    held = True
                    break
            if seen and not held:
                c = b
                while c >= 0:
                    new[c] = True
                    c = prev[c]
        same = True
        for j in range(k):
            if new[j] != out[j]:
                same = False
                out[j] = new[j]
        if same:
            break
    return out


def _hanging_all_kernel(string_prev, left_index, string_id, d, prev, h, max_height, use_only,
                        only, max_gap, tol, slope, solid):
    """`hanging_runs` (for numba): its candidate run bottoms (no match below in the run,
    higher than ``max_height``; of strings with an ``only`` match when ``use_only``), the
    edges below each edge and `_hanging_kernel`'s walk; (K,) bool."""
    k = left_index.shape[0]
    is_prev = np.zeros(k, np.bool_)
    for i in range(k):
        if prev[i] >= 0:
            is_prev[prev[i]] = True
    n_s = 0
    for i in range(k):
        n_s = max(n_s, np.int64(string_id[i]) + 1)
    has = np.zeros(n_s, np.bool_)
    for i in range(k):
        if only[i]:
            has[string_id[i]] = True
    n_b = 0
    cand = np.zeros(k, np.bool_)
    for i in range(k):
        cand[i] = (not is_prev[i] and h[i] > max_height
                   and (has[string_id[i]] if use_only else True))
        n_b += cand[i]
    if n_b == 0:
        return np.zeros(k, np.bool_)
    bottom = np.empty(n_b, np.int64)
    n_b = 0
    for i in range(k):
        if cand[i]:
            bottom[n_b] = i
            n_b += 1
    n_e = string_prev.shape[0]
    feat_of_edge = np.full(n_e, -1, np.int64)
    li = np.empty(k, np.int64)
    d64 = np.empty(k)
    for i in range(k):
        feat_of_edge[left_index[i]] = i
        li[i] = left_index[i]
        d64[i] = d[i]
    below = np.full(n_e, -1, np.int64)
    for e in range(n_e):
        if string_prev[e] >= 0:
            below[string_prev[e]] = e
    return nb_hanging(bottom, li, d64, below, feat_of_edge, prev, k, max_gap, tol, slope,
                       solid)


nb_hanging = _jit(_hanging_kernel)
nb_hanging_all = _jit(_hanging_all_kernel)


def _extent_kernel(label, n_c, g2, mx, my, norm, ex, ul, vv, sid, high):
    """The per-obstacle extremes of `GpodDetector._describe` (for numba), every group
    0..n_c-1 non-empty.

    Args:
        label: (N,) int64 obstacle of each pixel; g2 (N, 2) its foot on the ground, m;
            mx, my, norm (n_c,): each obstacle's median foot and its distance (>= 1e-9).
        ex: (N,) float64 disparity excess; ul (N,) float32 column, vv (N,) int32 row,
            sid (N,) int32 edge string of each pixel; high: obstacles (the largest
            excess), else drops (the smallest).
    Returns:
        lo_lat, hi_lat (n_c,) the extremes of the feet's lateral offset
        ``(y mx - x my) / norm``; exc (n_c,) the excess extreme; x0, x1 (n_c,) int64 the
        floor / ceil of the columns' extremes; y0, y1 (n_c,) int64 the rows' extremes;
        sid_u (U,) int32 each obstacle's strings, ascending, from sid_start (n_c + 1,).
    """
    lo_lat = np.full(n_c, np.inf)
    hi_lat = np.full(n_c, -np.inf)
    exc = np.empty(n_c)
    u_lo = np.empty(n_c, np.float32)
    u_hi = np.empty(n_c, np.float32)
    y0 = np.empty(n_c, np.int64)
    y1 = np.empty(n_c, np.int64)
    seen = np.zeros(n_c, np.bool_)
    for i in range(label.shape[0]):
        k = label[i]
        lat = (g2[i, 1] * mx[k] - g2[i, 0] * my[k]) / norm[k]
        if not seen[k]:
            seen[k] = True
            lo_lat[k] = hi_lat[k] = lat
            exc[k] = ex[i]
            u_lo[k] = u_hi[k] = ul[i]
            y0[k] = y1[k] = vv[i]
            continue
        lo_lat[k] = min(lo_lat[k], lat)
        hi_lat[k] = max(hi_lat[k], lat)
        exc[k] = max(exc[k], ex[i]) if high else min(exc[k], ex[i])
        u_lo[k] = min(u_lo[k], ul[i])
        u_hi[k] = max(u_hi[k], ul[i])
        y0[k] = min(y0[k], np.int64(vv[i]))
        y1[k] = max(y1[k], np.int64(vv[i]))
    x0 = np.empty(n_c, np.int64)
    x1 = np.empty(n_c, np.int64)
    for k in range(n_c):
        x0[k] = np.int64(math.floor(u_lo[k]))
        x1[k] = np.int64(math.ceil(u_hi[k]))
    # the distinct strings of each obstacle, ascending: the pixels by (obstacle, string)
    n_p = label.shape[0]
    sk = np.empty(n_p, np.int64)
    n_s = 0
    for i in range(n_p):
        sk[i] = sid[i]
        n_s = max(n_s, sk[i] + 1)
    by = nb_stable_order(label, nb_stable_order(sk, np.arange(n_p), n_s), n_c)
    sid_u = np.empty(n_p, np.int32)
    sid_start = np.zeros(n_c + 1, np.int64)
    n = 0
    for t in range(n_p):
        i = by[t]
        if t == 0 or label[i] != label[by[t - 1]] or sid[i] != sid[by[t - 1]]:
            sid_u[n] = sid[i]
            n += 1
            sid_start[label[i] + 1] = n
    for k in range(n_c):                  # (every obstacle has pixels)
        sid_start[k + 1] = max(sid_start[k + 1], sid_start[k])
    return lo_lat, hi_lat, exc, x0, x1, y0, y1, sid_u[:n].copy(), sid_start


nb_extent = _jit(_extent_kernel)


def _still_kernel(prev, use, v, u_int, h, w):
    """`GpodDetector._stillness` (for numba): the (h, w + 2) bool image of the edge
    pixels (rows ``v``, columns ``u_int`` + 1), and, when ``use``, how many of them were
    within one column of an edge pixel of ``prev`` (the previous frame's image)."""
    img = np.zeros((h, w + 2), np.bool_)
    hits = 0
    for i in range(v.shape[0]):
        r, c = v[i], u_int[i]
        img[r, c + 1] = True
        if use and (prev[r, c] or prev[r, c + 1] or prev[r, c + 2]):
            hits += 1
    return img, hits


def _temporal_kernel(v, u_left, excess, thr, gate_thr, gate_px, thr_factor, lam, use, ps,
                     pw, h, w):
    """`GpodDetector._temporal_excess` (for numba), with its arithmetic.

    Args:
        v: (K,) int32 rows, u_left (K,) float32 columns of the matches; excess (K,)
            float64 their (smoothed) excess, pixels.
        thr: (K,) float64 their thresholds, used when ``gate_thr``: the gate is
            ``min(gate_px, thr_factor * thr)``, else ``gate_px``.
        lam: the running average's decay; use: average with the previous sums ps, pw
            (h, w) float32 (the rig stood still).
    Returns:
        (K,) float64 sums and weights (the averaged excess is their ratio), and the new
        (h, w) float32 running sums and weights at the matches' pixels.
    """
    k = v.shape[0]
    s_new = excess.copy()
    w_new = np.ones(k)
    uu = np.empty(k, np.int64)
    for i in range(k):
        uu[i] = min(max(np.int64(np.rint(u_left[i])), 0), w - 1)
    if use:
        for i in range(k):
            r = v[i]
            # the largest previous weight at the column, left, right (the first of equals)
            best = min(max(uu[i], 0), w - 1)
            wb = pw[r, best]
            for dc in (-1, 1):
                col = min(max(uu[i] + dc, 0), w - 1)
                if not math.isnan(wb) and (math.isnan(pw[r, col]) or pw[r, col] > wb):
                    best, wb = col, pw[r, col]
            w0 = np.float64(wb)
            s0 = np.float64(ps[r, best])
            gate = gate_px
            if gate_thr:
                g = thr_factor * thr[i]
                if g < gate or math.isnan(g):
                    gate = g
            if w0 > 0 and abs(excess[i] - s0 / w0) <= gate:
                s_new[i] = s_new[i] + lam * s0
                w_new[i] = w_new[i] + lam * w0
    acc_s = np.zeros((h, w), np.float32)
    acc_w = np.zeros((h, w), np.float32)
    for i in range(k):
        acc_s[v[i], uu[i]] = np.float32(s_new[i])
        acc_w[v[i], uu[i]] = np.float32(w_new[i])
    return s_new, w_new, acc_s, acc_w


nb_still = _jit(_still_kernel)
nb_temporal = _jit(_temporal_kernel)



def _rival_share_kernel(j, ratio, rival_d, pd, thr, raised, k):
    """`support.contrary_rival_share` (for numba): one pass over the rivals in their
    order (np.bincount's sums). j (R,) int32 the match of each rival, ratio and rival_d
    (R,) float32 its support ratio and disparity; pd, thr (K,) float64 the ground's
    disparity and the threshold at each match, raised (K,) bool. Returns (K,) float32."""
    total = np.zeros(k)
    num = np.zeros(k)
    for i in range(j.shape[0]):
        q = j[i]
        r = np.float64(ratio[i])
        total[q] += r
        d = np.float64(rival_d[i])
        if raised[q]:
            contrary = d <= pd[q] + thr[q]
        else:
            contrary = d >= pd[q] - thr[q]
        if contrary:
            num[q] += r
    out = np.empty(k, np.float32)
    for q in range(k):
        out[q] = np.float32(num[q] / (1.0 + total[q]))
    return out


def _rivals_on_ground_kernel(j, strong, rival_d, pd, thr, d, k):
    """The rival tests of `rules.periodic_matches` and `rules.ambiguous_drops` (for
    numba), one pass over the rivals ``strong`` (R,) bool (j (R,) int32 the match of
    each rival, rival_d (R,) float32 its disparity): per match (K,), how many strong
    rivals it has (int64), whether one of them lies on the ground (within ``thr`` of
    ``pd``, (K,) float64 px), and whether one on the ground lies nearer than the match
    (a larger disparity than its own ``d`` (K,) float32)."""
    n_strong = np.zeros(k, np.int64)
    ground = np.zeros(k, np.bool_)
    nearer = np.zeros(k, np.bool_)
    for i in range(j.shape[0]):
        if not strong[i]:
            continue
        q = j[i]
        n_strong[q] += 1
        rd = np.float64(rival_d[i])
        if abs(rd - pd[q]) <= thr[q]:
            ground[q] = True
            if rd > np.float64(d[q]):
                nearer[q] = True
    return n_strong, ground, nearer


nb_rival_share = _jit(_rival_share_kernel)
nb_rivals_on_ground = _jit(_rivals_on_ground_kernel)

def _by_group(group, n_groups):
    """The rows of each group (for numba): (N,) int64 row indices by group, ascending
    within each (a stable counting sort), and (n_groups + 1,) int64 group starts."""
    start = np.zeros(n_groups + 1, np.int64)
    for g in group:
        start[g + 1] += 1
    for k in range(n_groups):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    rows = np.empty(group.shape[0], np.int64)
    for i in range(group.shape[0]):
        g = group[i]
        rows[fill[g]] = i
        fill[g] += 1
    return rows, start


def _group_quantile_kernel(group, x, q, n_groups):
    """`_group_quantile` (for numba): each group's values sorted, then numpy's linear
    interpolation between the order statistics at ``q * (count - 1)``."""
    out = np.full(n_groups, np.nan)
    rows, start = nb_by_group(group, n_groups)
    for k in range(n_groups):
        c = start[k + 1] - start[k]
        if c == 0:
            continue
        xs = nb_sorted(x[rows[start[k]:start[k + 1]]])
        pos = q * np.float64(c - 1)
        lo = np.int64(math.floor(pos))
        hi = min(lo + 1, c - 1)
        out[k] = xs[lo] + (xs[hi] - xs[lo]) * (pos - np.float64(lo))
    return out


def _sorted(x):
    """``np.sort(x)`` (for numba; one compiled sort that the kernels share)."""
    return np.sort(x)


nb_by_group = _jit(_by_group)
nb_sorted = _jit(_sorted)
nb_group_quantile = _jit(_group_quantile_kernel) if nb_by_group is not None else None


def warm_up() -> None:
    """Compile the numba kernels once per process (see `matching.warm_up`), before the
    first frame; falls back to the numpy paths if numba is missing or fails."""
    global _warm, nb_occluded, nb_hanging, nb_link_groups, nb_group_quantile, nb_extent, \
        nb_runs, nb_occluded_all, nb_hanging_all, nb_still, nb_temporal, nb_thin, \
        nb_rival_share, nb_rivals_on_ground
    if _warm:
        return
    _warm = True
    edges_warm_up()
    surface_warm_up()
    plane_warm_up()
    if not matching_warm_up() or nb_occluded is None:
        nb_occluded = nb_hanging = nb_link_groups = None
        nb_group_quantile = nb_extent = nb_runs = nb_occluded_all = None
        nb_hanging_all = nb_still = nb_temporal = nb_thin = None
        nb_rival_share = nb_rivals_on_ground = None
        kernels_geometry.warm_up(False)
        return
    kernels_geometry.warm_up(True)
    f2, f1, i1 = np.zeros((1, 2)), np.zeros(1), np.zeros(1, np.int64)
    nb_group_quantile = _warmed(nb_group_quantile, i1, f1, 0.5, 1)
    v1, u1 = np.zeros(1, np.int32), np.zeros(1, np.float32)
    nb_still = _warmed(nb_still, np.zeros((1, 3), bool), True, v1, v1, 1, 1)
    nb_temporal = _warmed(nb_temporal, v1, u1, f1, f1, True, 0.5, 0.75, 0.8, True,
                          np.zeros((1, 1), np.float32), np.ones((1, 1), np.float32), 1, 1)
    nb_runs = _warmed(nb_runs, np.full(1, -1, np.int32), np.zeros(1, np.int32),
                      np.zeros(1, np.float32), 1, np.float32(1.0), 5, f1)
    nb_extent = _warmed(nb_extent, i1, 1, f2, f1, f1, f1 + 1.0, f1,
                        np.zeros(1, np.float32), np.zeros(1, np.int32), np.zeros(1, np.int32),
                        True)
    nb_link_groups = _warmed(nb_link_groups, np.zeros((2, 2)), np.arange(2), 2, 1.0)
    nb_thin = _warmed(nb_thin, np.zeros((2, 2)), np.arange(2), 0.1)
    z, i = np.zeros(2), np.zeros(1, np.int64)
    nb_occluded = _warmed(nb_occluded, np.zeros(2, np.int64), np.ones(2, bool), z, z, z,
                          1.0, 1)
    i32, f32 = np.zeros(2, np.int32), np.zeros(2, np.float32)
    nb_occluded_all = (None if nb_occluded is None else _warmed(
        nb_occluded_all, i32, i32, np.ones(2, bool), i32, f32, f32, f32, 1.0, 16))
    nb_hanging = _warmed(nb_hanging, i, i, np.zeros(1), i - 1, i, i - 1, 1, 2, 1.0, 0.1,
                         np.ones(1, bool))
    nb_hanging_all = (None if nb_hanging is None else _warmed(
        nb_hanging_all, np.full(1, -1, np.int32), np.zeros(1, np.int32),
        np.zeros(1, np.int32), np.zeros(1, np.float32), i - 1, np.ones(1), 0.5, True,
        np.ones(1, bool), 32, 1.0, 0.1, np.ones(1, bool)))
    j1, r1, b1 = np.zeros(1, np.int32), np.ones(1, np.float32), np.ones(1, bool)
    nb_rival_share = _warmed(nb_rival_share, j1, r1, r1, f1, f1, b1, 1)
    nb_rivals_on_ground = _warmed(nb_rivals_on_ground, j1, b1, r1, f1, f1, r1, 1)
