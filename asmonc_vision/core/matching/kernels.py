"""The compiled loops of matching (numba, optional) and their warm-up.

Each kernel has a numpy path beside it in the module that calls it, with the same tests
and order of summation: identical results. The handles ``nb_*`` are None without numba
(or after a failed warm-up); the callers read them from this module at call time.
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.jit import jit


def search_left(a: np.ndarray, x: float, start: int) -> int:
    """``np.searchsorted(a, x, side='left')`` of an ascending float64 array (for numba):
    the first index with ``a[i] >= x`` (len(a) if none), found by walking from
    ``start`` (the previous answer: queries come nearly in order)."""
    n = a.shape[0]
    i = min(max(start, 0), n)
    while i < n and a[i] < x:
        i += 1
    while i > 0 and not a[i - 1] < x:
        i -= 1
    return i


def search_right(a: np.ndarray, x: float, start: int) -> int:
    """``np.searchsorted(a, x, side='right')`` of an ascending float64 array (for
    numba): the first index with ``a[i] > x`` (len(a) if none), walking from ``start``."""
    n = a.shape[0]
    i = min(max(start, 0), n)
    while i < n and a[i] <= x:
        i += 1
    while i > 0 and a[i - 1] > x:
        i -= 1
    return i


def candidates_kernel(pol_l, v_l, u_l, s_l, o_l, pol_r, v_r, u_r, s_r, o_r, h, width,
                       d_min, d_max, ratio, max_dori):
    """:func:`candidate_matches` as loops (for numba), with its keys, searches and tests.

    Args:
        pol_l, v_l, u_l, s_l, o_l: (N_l,) polarity (int8), row (int32), sub-pixel column,
            strength and orientation (float32) of the left edges; ``*_r`` of the right.
        h: image height, rows; width: image width, pixels (float).
        d_min, d_max: disparity range, pixels.
        ratio: float32 least strength ratio; max_dori: largest orientation difference,
            radians (float64).
    Returns:
        (left (M,) intp, right (M,) intp, d (M,) float64) as `Candidates`.
    """
    n_l, n_r = pol_l.shape[0], pol_r.shape[0]
    # The key of an edge: ((polarity plane * h + row) * span + u), float64, as numpy's;
    # the right edges sorted by (plane, index): each plane is in (row, column) order.
    span = width + abs(d_max) + abs(d_min) + 4.0
    order_r = np.empty(n_r, np.intp)
    n0 = 0
    for j in range(n_r):
        if not pol_r[j] < 0:
            order_r[n0] = j
            n0 += 1
    k = n0
    for j in range(n_r):
        if pol_r[j] < 0:
            order_r[k] = j
            k += 1
    key_r = np.empty(n_r)
    for k in range(n_r):
        j = order_r[k]
        plane = np.int64(1) if pol_r[j] < 0 else np.int64(0)
        key_r[k] = np.float64(plane * h + np.int64(v_r[j])) * span + np.float64(u_r[j])
    lo = np.empty(n_l, np.intp)
    hi = np.empty(n_l, np.intp)
    total = 0
    a, b = 0, 0
    for neg in (False, True):           # the left edges by plane: keys nearly in order
        for i in range(n_l):
            if (pol_l[i] < 0) != neg:
                continue
            plane = np.int64(1) if neg else np.int64(0)
            key = np.float64(plane * h + np.int64(v_l[i])) * span + np.float64(u_l[i])
            a = nb_search_left(key_r, key - d_max, a)
            b = nb_search_right(key_r, key - d_min, b)
            lo[i] = a
            hi[i] = b
            total += max(b - a, 0)
    li = np.empty(total, np.intp)
    rj = np.empty(total, np.intp)
    d = np.empty(total)
    two_pi = np.float32(2.0 * np.pi)
    n = 0
    for i in range(n_l):
        sl, ol, ul = s_l[i], o_l[i], np.float64(u_l[i])
        for p in range(lo[i], hi[i]):
            j = order_r[p]
            sr = s_r[j]
            # min(sl, sr) >= ratio * max(sl, sr), in single precision (as numpy's)
            if not (min(sl, sr) >= ratio * max(sl, sr)):
                continue
            dori = abs(ol - o_r[j])
            dori = min(dori, two_pi - dori)
            if not (np.float64(dori) <= max_dori):
                continue
            li[n] = i
            rj[n] = j
            d[n] = ul - np.float64(u_r[j])
            n += 1
    return li[:n], rj[:n], d[:n]


def cells_kernel(s_cell, size):
    """:func:`_cell_table` as a loop (for numba): (size + 1,) int32 (M < 2^31),
    ``table[k]`` the number of the sorted cells ``s_cell`` (M,) below k (a count per
    cell, then its prefix sum)."""
    table = np.zeros(size + 1, np.int32)
    for c in s_cell:
        table[c + 1] += 1
    for k in range(1, size + 1):
        table[k] += table[k - 1]
    return table


def siblings_kernel(left, d):
    """:func:`_sibling_disparities` as a loop (for numba): the disparities (M,) float64
    of the previous and next candidate of the same left edge (NaN if none), and whether
    they are monotonic within every left edge (all steps <= 0, or all >= 0)."""
    m = left.shape[0]
    d_prev = np.full(m, np.nan)
    d_next = np.full(m, np.nan)
    all_le, all_ge = True, True
    for k in range(1, m):
        if left[k] == left[k - 1]:
            d_prev[k] = d[k - 1]
            d_next[k - 1] = d[k]
            step = d[k] - d[k - 1]
            all_le = all_le and step <= 0.0
            all_ge = all_ge and step >= 0.0
    return d_prev, d_next, all_le or all_ge


def link_rows_kernel(start, n, c2, c_left, c_right):
    """The per-supporter rows of :class:`SupportLinks` (for numba): (n,) int64 link of
    each supporter (``start`` (Q,) ascending, the links' first supporters), and the left
    and right edges of the supporting candidates ``c2`` (n,)."""
    pair_link = np.empty(n, np.int64)
    q_n = start.shape[0]
    for q in range(q_n):
        end = start[q + 1] if q + 1 < q_n else n
        for p in range(start[q], end):
            pair_link[p] = q
    pair_edge = np.empty(n, c_left.dtype)
    pair_right = np.empty(n, c_right.dtype)
    for p in range(n):
        pair_edge[p] = c_left[c2[p]]
        pair_right[p] = c_right[c2[p]]
    return pair_link, pair_edge, pair_right


def pairs_kernel(table, half, w, s_uc, s_d64, s_v, rad2, lim2):
    """The loops of :func:`_neighbour_pairs` (for numba): the same windows and tests, in
    the same order (row offset, then candidate, then window position) as numpy's (its
    single-precision pre-test only skips pairs that the exact tests reject)."""
    nd = half.shape[0]
    m = s_uc.shape[0]
    lo = np.empty((nd, m), np.int32)          # (table values: < M < 2^31)
    hi = np.empty((nd, m), np.int32)
    tot = 0
    for k in range(nd):
        hk = half[k]
        for i in range(m):
            ui = s_uc[i]
            base = (s_v[i] + k) * w
            a = np.int64(table[base + max(np.int64(np.floor(ui - hk)), 0)])
            if k == 0:
                a = max(a, i + 1)
            b = np.int64(table[base + min(np.int64(np.floor(ui + hk)), w - 1) + 1])
            lo[k, i] = a
            hi[k, i] = b
            tot += max(b - a, 0)
    oi = np.empty(tot, np.int64)
    oj = np.empty(tot, np.int64)
    os2 = np.empty(tot, np.float64)
    n = 0
    for k in range(nd):
        for i in range(m):
            ui = s_uc[i]
            di = s_d64[i]
            vi = s_v[i]
            # Branch-free: write every pair, advance past the kept ones.
            for j in range(lo[k, i], hi[k, i]):
                dcu = s_uc[j] - ui
                dv = np.float64(s_v[j] - vi)
                s2 = dcu * dcu + dv * dv
                dd = s_d64[j] - di
                oi[n] = i
                oj[n] = j
                os2[n] = s2
                n += (s2 <= rad2) & (dd * dd <= lim2 * s2) & (s2 > 0.0)
    return oi[:n], oj[:n], os2[:n]


def group_kernel(a, b, s2, d, d_prev, d_next, monotonic, tol, c_left, n_left):
    """The loops of :func:`_group_links` (for numba), same order and arithmetic: returns
    (link candidate, link start, supporter, weight, number of single links)."""
    npair = a.shape[0]
    n = 2 * npair
    multi = np.empty(n, np.bool_)
    for k in range(npair):
        ak = a[k]
        bk = b[k]
        if monotonic:
            da = d[ak]
            db = d[bk]
            multi[k] = abs(d_prev[bk] - da) <= tol or abs(d_next[bk] - da) <= tol
            multi[npair + k] = abs(d_prev[ak] - db) <= tol or abs(d_next[ak] - db) <= tol
        else:
            multi[k] = not (np.isnan(d_prev[bk]) and np.isnan(d_next[bk]))
            multi[npair + k] = not (np.isnan(d_prev[ak]) and np.isnan(d_next[ak]))
    n_multi = 0
    for k in range(n):
        n_multi += multi[k]
    n1 = n - n_multi
    grp = np.empty(n_multi, np.int64)
    key = np.empty(n_multi, np.int64)
    c = np.empty(n, np.int64)
    c2 = np.empty(n, np.int64)
    w = np.empty(n, np.float64)
    # link k < npair: candidate a[k] supported by b[k]; k >= npair: the reverse
    q1 = 0
    q2 = 0
    for k in range(n):
        kp = k if k < npair else k - npair
        ck = a[kp] if k < npair else b[kp]
        sk = b[kp] if k < npair else a[kp]
        s2k = s2[kp]
        if multi[k]:
            grp[q2] = k
            key[q2] = ck * n_left + c_left[sk]
            q2 += 1
        else:
            c[q1] = ck
            c2[q1] = sk
            w[q1] = 1.0 / np.sqrt(s2k)
            q1 += 1
    order = np.argsort(key, kind='mergesort')
    start = np.empty(n, np.int64)
    l_cand = np.empty(n, np.int64)
    for k in range(n1):
        start[k] = k
        l_cand[k] = c[k]
    nl = n1
    prev = -1
    for t in range(n_multi):
        k = grp[order[t]]
        kk = key[order[t]]
        kp = k if k < npair else k - npair
        ck = a[kp] if k < npair else b[kp]
        sk = b[kp] if k < npair else a[kp]
        s2k = s2[kp]
        p = n1 + t
        c[p] = ck
        c2[p] = sk
        w[p] = 1.0 / np.sqrt(s2k)
        if t == 0 or kk != prev:
            start[nl] = p
            l_cand[nl] = ck
            nl += 1
        prev = kk
    return l_cand[:nl], start[:nl], c2, w, n1


def select_kernel(c_left, c_right, n_l, n_r, l_cand, l_start, pair_cand, weight, rounds,
                   min_support):
    """:func:`select_matches` as loops (for numba), with the same arithmetic: a link's
    best alive weight (a maximum: exact), summed per candidate in link order (as
    ``np.bincount``), strict maxima per left and right edge. Returns (accepted (M,) bool,
    support (M,) float64 of the last round, support of the first round: every
    candidate alive, as ``link_support`` of all links gives it).

    The candidates that are not alive take no part in the maxima (numpy's -inf values:
    never a group's strict maximum, nor one above ``min_support``), and a round's
    winners are accepted and their edges taken in one pass (when a round accepts none
    anew, the loop ends and nothing taken is read)."""
    m = c_left.shape[0]
    nq = l_cand.shape[0]
    npair = weight.shape[0]
    accepted = np.zeros(m, np.bool_)
    alive = np.ones(m, np.bool_)
    support = np.zeros(m)
    first = support
    taken_r = np.zeros(n_r, np.bool_)
    matched_l = np.zeros(n_l, np.bool_)
    gmax_l = np.empty(n_l)
    cnt_l = np.empty(n_l, np.int64)
    gmax_r = np.empty(n_r)
    cnt_r = np.empty(n_r, np.int64)
    for it in range(rounds):
        if it > 0:
            support = np.zeros(m)
        for q in range(nq):
            end = l_start[q + 1] if q + 1 < nq else npair
            best = -np.inf
            for p in range(l_start[q], end):
                wp = weight[p] if (it == 0 or alive[pair_cand[p]]) else 0.0
                if wp > best:
                    best = wp
            support[l_cand[q]] += best
        if it == 0:
            first = support
        gmax_l[:] = -np.inf
        gmax_r[:] = -np.inf
        cnt_l[:] = 0
        cnt_r[:] = 0
        for c in range(m):
            if not alive[c]:
                continue
            x = support[c]
            e = c_left[c]
            if x > gmax_l[e]:
                gmax_l[e] = x
                cnt_l[e] = 1
            elif x == gmax_l[e]:
                cnt_l[e] += 1
            r = c_right[c]
            if x > gmax_r[r]:
                gmax_r[r] = x
                cnt_r[r] = 1
            elif x == gmax_r[r]:
                cnt_r[r] += 1
        new = False
        for c in range(m):
            if not alive[c]:
                continue
            x = support[c]
            e = c_left[c]
            r = c_right[c]
            if (x > min_support and x == gmax_l[e] and cnt_l[e] == 1 and x == gmax_r[r]
                    and cnt_r[r] == 1):
                if not accepted[c]:
                    new = True
                    accepted[c] = True
                taken_r[r] = True
                matched_l[e] = True
        if not new or it == rounds - 1:
            break
        for c in range(m):
            alive[c] = alive[c] and (accepted[c] or not (matched_l[c_left[c]]
                                                         or taken_r[c_right[c]]))
    return accepted, support, first


def rivals_kernel(c_left, c_right, d, support, k, lo_l, hi_l, n_r):
    """:func:`match_rivals` as loops (for numba), with the same order and arithmetic:
    per accepted candidate ``k[i]`` (ascending i), the other candidates of its left edge
    (``lo_l[i]``..``hi_l[i]``, ascending) and then those of its right edge (ascending
    index, as a stable sort by right edge lists them; ``n_r`` > every right index);
    returns (owner int32, d float32, support ratio float32)."""
    m = c_left.shape[0]
    n = k.shape[0]
    first = np.zeros(n_r + 1, np.int64)        # candidates per right edge, as offsets
    for c in range(m):
        first[c_right[c] + 1] += 1
    for r in range(n_r):
        first[r + 1] += first[r]
    by_r = np.empty(m, np.int64)
    fill = first[:n_r].copy()
    for c in range(m):
        by_r[fill[c_right[c]]] = c
        fill[c_right[c]] += 1
    cap = 0
    for i in range(n):
        r = c_right[k[i]]
        cap += (hi_l[i] - lo_l[i]) + (first[r + 1] - first[r])
    owner = np.empty(cap, np.int32)
    rd = np.empty(cap, np.float32)
    ratio = np.empty(cap, np.float32)
    j = 0
    for i in range(n):
        ki = k[i]
        s = support[ki]
        den = s if not s < 1e-12 else 1e-12
        r = c_right[ki]
        for half in range(2):
            a = lo_l[i] if half == 0 else first[r]
            b = hi_l[i] if half == 0 else first[r + 1]
            for p in range(a, b):
                c = p if half == 0 else by_r[p]
                if c == ki:
                    continue
                owner[j] = i
                rd[j] = np.float32(d[c])
                ratio[j] = np.float32(support[c] / den)
                j += 1
    return owner[:j].copy(), rd[:j].copy(), ratio[:j].copy()


#: the compiled kernels (None without numba: the numpy paths are used)
nb_search_left = jit(search_left)
nb_search_right = jit(search_right)
nb_candidates = jit(candidates_kernel) if nb_search_left is not None else None
nb_cells = jit(cells_kernel)
nb_siblings = jit(siblings_kernel)
nb_link_rows = jit(link_rows_kernel)
nb_pairs = jit(pairs_kernel)
nb_group = jit(group_kernel)
nb_select = jit(select_kernel)
nb_rivals = jit(rivals_kernel)


def warm_up() -> bool:
    """Compile (or load from the disk cache) the numba kernels on tiny inputs of the
    real argument types, so that the first frame does not pay for it; without numba, or
    if compiling fails, the numpy paths are used. Returns whether numba is in use."""
    global nb_pairs, nb_select, nb_group, nb_candidates, nb_cells, nb_siblings, \
        nb_link_rows, nb_rivals
    if (nb_pairs is None or nb_select is None or nb_group is None
            or nb_candidates is None or nb_cells is None or nb_siblings is None
            or nb_link_rows is None or nb_rivals is None):
        nb_pairs = nb_select = nb_group = None
        nb_candidates = nb_cells = nb_siblings = nb_link_rows = nb_rivals = None
        return False
    i64, f64 = np.zeros(2, np.int64), np.zeros(2)
    i8, i32, f32 = np.ones(2, np.int8), np.zeros(2, np.int32), np.ones(2, np.float32)
    try:
        for table in (np.zeros(9, np.int32), np.zeros(9, np.int64)):
            nb_pairs(table, np.ones(2), 2, f64, f64, i64, 9.0, 1.0)
        nb_select(i64, i64, 2, 2, i64, i64, i64, f64, 3, 0.5)
        for mono in (True, False):
            nb_group(i64, i64, f64 + 1.0, f64, f64, f64, mono, 3.0, i64, 2)
        nb_candidates(i8, i32, f32, f32, f32, i8, i32, f32, f32, f32, 2, 2.0, 0.5, 1.0,
                       np.float32(0.5), 0.5)
        nb_cells(i64, 2)
        nb_siblings(i64, f64)
        nb_link_rows(i64, 2, i64, i64, i64)
        nb_rivals(i64, i64, f64, f64, i64, i64, i64 + 1, 1)
    except Exception:       # pragma: no cover - a broken numba/llvmlite install
        nb_pairs = nb_select = nb_group = None
        nb_candidates = nb_cells = nb_siblings = nb_link_rows = nb_rivals = None
        return False
    return True
