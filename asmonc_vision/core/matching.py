"""Row-wise stereo matching of vertical edges with PMF (Pollard, Mayhew & Frisby 1985).

After Pollard, Mayhew & Frisby (PMF, 1985), as used by GPOD (Molton et al. 1998, Sec. 2.1):

1. Candidates (:func:`candidate_matches`): every left edge is paired with the right edges
   of the same row whose disparity ``d = u_left - u_right`` lies in ``[d_min, d_max]``,
   of the same polarity, with compatible strength (ratio of the weaker to the stronger at
   least ``min_strength_ratio``) and orientation (gradient directions within
   ``max_orientation_diff_deg``).
2. Support (:func:`support_links`, :func:`pmf_support`), as published: a candidate
   c = (e, r) is supported by the candidates c' of the *other* left edges whose
   cyclopean positions ``((u_left + u_right) / 2, v)`` lie within ``support_radius`` of
   c's (the cyclopean image) and that satisfy the disparity-gradient limit with it,
   ``|d' - d| <= limit * |cyclopean separation|`` (limit 1 in PMF); each contributes
   ``1 / separation``, and each neighbouring left edge contributes at most once, with its
   best such match. (Candidates sharing an edge with c have a disparity gradient of 2
   and never support it.)
3. Selection (:func:`select_matches`), PMF's iterative winner-take-all with uniqueness:
   a candidate is accepted when its support is above ``min_support`` and strictly the
   largest among the live candidates of both its left and its right edge; the
   competitors of accepted matches (other candidates of their left or right edge) are
   removed, and the support is recomputed from what is left -- a neighbouring edge that
   has been matched supports only through its accepted match -- for ``iterations``
   rounds.

Disparities are sub-pixel, from the sub-pixel edge positions in both images.

The pair, grouping and selection loops run compiled by numba when it is installed
(:func:`warm_up`), with the numpy paths' tests and order of summation: identical results.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .edges import EdgeMap
from .jit import jit as _jit


@dataclass(frozen=True)
class Candidates:
    """Candidate matches, grouped by left edge (sorted by left index, then right index).

    Attributes:
        left: (M,) int64 (intp) index into the left EdgeMap.
        right: (M,) int64 (intp) index into the right EdgeMap.
        d: (M,) float64 sub-pixel disparity, pixels.
    """

    left: np.ndarray
    right: np.ndarray
    d: np.ndarray

    def __len__(self) -> int:
        return int(self.left.shape[0])


@dataclass(frozen=True)
class SupportLinks:
    """PMF neighbourhood: one link per (candidate, neighbouring left edge).

    Link q says: candidate ``cand[q]`` is supported by one neighbouring left edge, with
    the weight of the best *alive* one of the link's supporters. Supporter p belongs
    to link ``pair_link[p]`` (the supporters of a link are contiguous, from
    ``start[q]``): candidate ``pair_cand[p]`` = (``pair_edge[p]``, ``pair_right[p]``)
    of the neighbouring edge, whose cyclopean position is within the support radius of
    the supported candidate's and which satisfies the disparity-gradient limit with it;
    ``weight[p]`` is ``1 / cyclopean separation``. Links without supporters are not
    stored. The first ``num_single`` links have one supporter each (link q is supporter
    q); links are in no particular order of candidate.

    Attributes:
        num_candidates: M.
        cand: (Q,) int64 supported candidate.
        start: (Q,) int64 index of the link's first supporter (ascending).
        pair_link: (P,) int64 link of each supporter (ascending).
        pair_cand: (P,) int64 supporting candidate (index into the Candidates).
        pair_edge: (P,) int64 its left edge (index into the left EdgeMap).
        pair_right: (P,) int64 its right edge (index into the right EdgeMap).
        weight: (P,) float64 ``1 / distance`` between the two candidates' cyclopean
            positions, 1/pixels.
        num_single: how many of the links, first, have a single supporter (0: unknown).
    """

    num_candidates: int
    cand: np.ndarray
    start: np.ndarray
    pair_link: np.ndarray
    pair_cand: np.ndarray
    pair_edge: np.ndarray
    pair_right: np.ndarray
    weight: np.ndarray
    num_single: int = 0

    def __len__(self) -> int:
        return int(self.cand.shape[0])


@dataclass(frozen=True)
class Matches:
    """Accepted edge matches of one stereo pair.

    Attributes:
        u_left: (K,) float32 sub-pixel column in the left image, pixels.
        u_right: (K,) float32 sub-pixel column in the right image, pixels.
        v: (K,) int32 row (the same in both rectified images).
        d: (K,) float32 disparity ``u_left - u_right``, pixels.
        strength: (K,) float32 mean edge strength of the two edges, grey levels / pixel.
        string_id: (K,) int32 edge-string id of the left edge (see EdgeMap).
        left_index: (K,) int32 index into the left EdgeMap.
        right_index: (K,) int32 index into the right EdgeMap.
        support: (K,) float32 final PMF support.
        precision: (K,) float32 ``1 / sqrt(1/cL^2 + 1/cR^2)`` of the left and right edges'
            curvatures c (``EdgeMap.curvature``): the disparity's noise is about
            ``0.7 * gradient noise / precision`` pixels. None if unknown.
    """

    u_left: np.ndarray
    u_right: np.ndarray
    v: np.ndarray
    d: np.ndarray
    strength: np.ndarray
    string_id: np.ndarray
    left_index: np.ndarray
    right_index: np.ndarray
    support: np.ndarray
    precision: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.v.shape[0])

    @property
    def u(self) -> np.ndarray:
        """(K,) float64 cyclopean column ``(u_left + u_right) / 2``, pixels."""
        return 0.5 * (self.u_left.astype(np.float64) + self.u_right)


def _expand(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand index ranges [lo_i, hi_i) to (owner i, index) pairs, vectorised.

    Returns:
        (owner, index): int64 arrays of length sum(hi - lo), grouped by owner and
        ascending within each owner.
    """
    counts = np.maximum(hi - lo, 0)
    total = int(counts.sum())
    if total == 0:
        z = np.zeros(0, np.int64)
        return z, z
    owner = np.repeat(np.arange(lo.shape[0]), counts)
    idx = np.arange(total) + np.repeat(lo - (np.cumsum(counts) - counts), counts)
    return owner, idx


def candidate_matches(left: EdgeMap, right: EdgeMap, d_min: float, d_max: float, *,
                      min_strength_ratio: float = 0.5,
                      max_orientation_diff_deg: float = 30.0,
                      right_gain: float = 1.0) -> Candidates:
    """All admissible (left edge, right edge) pairs on the same row.

    Args:
        left, right: edge maps of the rectified left and right images (same shape).
        d_min, d_max: disparity search range, pixels (``d_min <= d <= d_max``).
        min_strength_ratio: least ratio of the weaker to the stronger edge, 0..1.
        max_orientation_diff_deg: largest difference of gradient directions, degrees.
        right_gain: > 0, the factor that puts the right image's grey levels on the
            left's scale (two cameras with their own gain): the strength test compares
            each left strength with the right one times this.
    Returns:
        Candidates grouped by left edge.
    """
    if left.shape != right.shape:
        raise ValueError(f'left and right edge maps differ in shape: {left.shape} vs {right.shape}')
    if len(left) == 0 or len(right) == 0 or d_max < d_min:
        z = np.zeros(0, np.intp)
        return Candidates(z, z, np.zeros(0))
    if not right_gain > 0:
        raise ValueError(f'right_gain must be > 0, got {right_gain}')
    right_strength = (right.strength if right_gain == 1.0
                      else right.strength * np.float32(right_gain))
    if (_nb_candidates is not None and type(min_strength_ratio) in (float, int)
            and type(max_orientation_diff_deg) in (float, int)):
        # The same keys, ranges and tests, compiled (one pass, no temporaries).
        li, rj, d = _nb_candidates(
            left.polarity, left.v, left.u, left.strength, left.orientation,
            right.polarity, right.v, right.u, right_strength, right.orientation,
            int(left.shape[0]), float(left.shape[1]), float(d_min), float(d_max),
            np.float32(min_strength_ratio), float(np.deg2rad(max_orientation_diff_deg)))
        return Candidates(left=li, right=rj, d=d)
    # Right edges of the same polarity and row, within the disparity range: one
    # contiguous range of the right edges sorted by (polarity, row, column).
    h = left.shape[0]
    span = float(left.shape[1]) + abs(float(d_max)) + abs(float(d_min)) + 4.0
    plane_r = (right.polarity < 0).astype(np.int64)
    order_r = np.r_[np.flatnonzero(plane_r == 0), np.flatnonzero(plane_r == 1)]
    key_r = ((plane_r * h + right.v) * span + right.u)[order_r]
    plane_l = (left.polarity < 0).astype(np.int64)
    order_l = np.r_[np.flatnonzero(plane_l == 0), np.flatnonzero(plane_l == 1)]
    key_l = (((plane_l * h + left.v) * span + left.u)[order_l])
    # Queries in ascending order (numpy's binary search is much faster on sorted keys).
    lo = np.empty(len(left), np.intp)
    hi = np.empty(len(left), np.intp)
    lo[order_l] = np.searchsorted(key_r, key_l - d_max, side='left')
    hi[order_l] = np.searchsorted(key_r, key_l - d_min, side='right')
    li, pos = _expand(lo, hi)
    rj = order_r[pos]
    sl = left.strength[li]
    sr = right_strength[rj]
    ok = np.minimum(sl, sr) >= min_strength_ratio * np.maximum(sl, sr)
    dori = np.abs(left.orientation[li] - right.orientation[rj])
    dori = np.minimum(dori, 2.0 * np.pi - dori)
    ok &= dori <= np.deg2rad(max_orientation_diff_deg)
    keep = np.flatnonzero(ok)
    li, rj = li[keep], rj[keep]
    return Candidates(left=li, right=rj, d=left.u[li].astype(np.float64) - right.u[rj])


def _search_left(a: np.ndarray, x: float, start: int) -> int:
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


def _search_right(a: np.ndarray, x: float, start: int) -> int:
    """``np.searchsorted(a, x, side='right')`` of an ascending float64 array (for
    numba): the first index with ``a[i] > x`` (len(a) if none), walking from ``start``."""
    n = a.shape[0]
    i = min(max(start, 0), n)
    while i < n and a[i] <= x:
        i += 1
    while i > 0 and a[i - 1] > x:
        i -= 1
    return i


def _candidates_kernel(pol_l, v_l, u_l, s_l, o_l, pol_r, v_r, u_r, s_r, o_r, h, width,
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
            a = _nb_search_left(key_r, key - d_max, a)
            b = _nb_search_right(key_r, key - d_min, b)
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
    return li[:n].copy(), rj[:n].copy(), d[:n].copy()


def disc_offsets(radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Integer pixel offsets (du, dv) with ``0 < du^2 + dv^2 <= radius^2``.

    Returns:
        (du, dv): int64 arrays, ordered by dv then du.
    """
    rad = int(np.floor(radius))
    dv, du = np.mgrid[-rad:rad + 1, -rad:rad + 1]
    keep = (du * du + dv * dv <= radius * radius) & ((du != 0) | (dv != 0))
    return du[keep].astype(np.int64), dv[keep].astype(np.int64)


def disparity_gradient_interval(du_left, dv, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """Disparity differences allowed by the disparity-gradient limit.

    For two matches whose left edges are ``(du_left, dv)`` apart, the disparity gradient
    ``|x| / |(du_left - x/2, dv)|`` (x the disparity difference; cyclopean separation, as
    ``u_c = u_left - d/2``) is at most ``limit`` exactly when x lies in the returned
    closed interval.

    Args:
        du_left: (N,) left-image column differences (neighbour minus centre), pixels.
        dv: (N,) or scalar row differences, pixels.
        limit: disparity-gradient limit, 0 < limit < 2.
    Returns:
        (lo, hi): (N,) float64 bounds on ``d_neighbour - d_centre``, pixels.
    """
    a = np.asarray(du_left, np.float64)
    l2 = float(limit) ** 2
    # x^2 <= l2 ((a - x/2)^2 + dv^2)  <=>  qa x^2 + qb x + qc <= 0, qa > 0 for limit < 2.
    qa = 1.0 - 0.25 * l2
    qb = l2 * a
    qc = -l2 * (a * a + np.asarray(dv, np.float64) ** 2)
    root = np.sqrt(qb * qb - 4.0 * qa * qc)
    return (-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)


#: Relative slack of the single-precision disparity pre-filter of :func:`support_links`.
_SLACK = 1.0 + 1e-4


def _empty_links(m: int) -> SupportLinks:
    zi = np.zeros(0, np.int64)
    return SupportLinks(num_candidates=m, cand=zi, start=zi, pair_link=zi, pair_cand=zi,
                        pair_edge=zi, pair_right=zi, weight=np.zeros(0))


def _cell_table(s_cell: np.ndarray, size: int) -> np.ndarray:
    """(size + 1,) int: ``table[k]`` = number of the sorted cells ``s_cell`` below k."""
    m = s_cell.shape[0]
    if _nb_cells is not None:
        return _nb_cells(s_cell, size)
    first = np.ones(m, bool)
    first[1:] = s_cell[1:] != s_cell[:-1]
    at = np.flatnonzero(first)
    count = np.diff(np.append(at, m))
    if m < 2 ** 31 and (count.size == 0 or int(count.max()) <= 255):
        # A one-row integral image is a fast prefix sum (numpy's cumsum is not).
        hist = np.zeros((1, size), np.uint8)
        hist[0, s_cell[at]] = count
        return cv2.integral(hist)[1]
    table = np.zeros(size + 1, np.int64)
    np.cumsum(np.bincount(s_cell, minlength=size), out=table[1:])
    return table


def _cells_kernel(s_cell, size):
    """:func:`_cell_table` as a loop (for numba): (size + 1,) int64, ``table[k]`` the
    number of the sorted cells ``s_cell`` (M,) below k (a count per cell, then its
    prefix sum)."""
    table = np.zeros(size + 1, np.int64)
    for c in s_cell:
        table[c + 1] += 1
    for k in range(1, size + 1):
        table[k] += table[k - 1]
    return table


def _siblings_kernel(left, d):
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


def _link_rows_kernel(start, n, c2, c_left, c_right):
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


def _sibling_disparities(cand: Candidates) -> tuple[np.ndarray, np.ndarray, bool]:
    """(M,) float64 disparities of the previous and the next candidate of the same left
    edge (NaN if none), and whether the disparities are monotonic within each left edge
    (they are when the right edges are sorted by column): then these are a candidate's
    nearest siblings in disparity on either side."""
    m = len(cand)
    same = cand.left[1:] == cand.left[:-1]
    step = np.diff(cand.d)
    d_prev = np.full(m, np.nan)
    d_next = np.full(m, np.nan)
    d_prev[1:] = np.where(same, cand.d[:-1], np.nan)
    d_next[:-1] = np.where(same, cand.d[1:], np.nan)
    return d_prev, d_next, bool(np.all(step[same] <= 0.0) or np.all(step[same] >= 0.0))


def support_links(left: EdgeMap, right: EdgeMap, cand: Candidates, d_min: float = 0.0,
                  d_max: float = np.inf, *, support_radius: float = 3.0,
                  disparity_gradient_limit: float = 1.0, min_strength_ratio: float = 0.5,
                  max_orientation_diff_deg: float = 30.0) -> SupportLinks:
    """The PMF neighbourhood of every candidate (Pollard, Mayhew & Frisby 1985).

    Candidate c' = (e', r') of another left edge e' supports c = (e, r) when their
    cyclopean positions ``((u_left + u_right) / 2, v)`` (sub-pixel) are at most
    ``support_radius`` apart and their disparity gradient
    ``|d' - d| / cyclopean separation`` is at most ``disparity_gradient_limit``, with
    weight ``1 / cyclopean separation``. Candidates sharing an edge with c have a
    disparity gradient of 2 and never support it. The supporters are grouped into one
    link per (c, e'): a neighbouring edge contributes only its best compatible match
    (see :func:`pmf_support`). Supporters are candidates themselves, so they passed
    the candidate tests (polarity, strength, orientation, disparity range).

    The neighbours are found in the cyclopean image directly: candidates are bucketed by
    (row, cyclopean column); each pair is found once and used both ways (support is
    symmetric), after a single-precision disparity pre-test and the exact tests in
    double precision. Two supporters of one candidate can share their left edge only if
    their disparities are within ``2 * limit * radius``: supporters without such a
    sibling make single-supporter links (the first ``num_single``), only the others are
    grouped by sorting.

    Args:
        left, right: the EdgeMaps the candidates index.
        cand: candidates from :func:`candidate_matches`.
        d_min, d_max, min_strength_ratio, max_orientation_diff_deg: not used (the
            candidates already obey them); kept for the call signature.
        support_radius: neighbourhood radius in the cyclopean image, pixels (>= 1).
        disparity_gradient_limit: PMF disparity-gradient limit, in (0, 2).
    Returns:
        The SupportLinks.
    """
    m = len(cand)
    lim = float(disparity_gradient_limit)
    if not 0.0 < lim < 2.0:
        raise ValueError(f'disparity_gradient_limit must be in (0, 2), got {lim}')
    if m == 0:
        return _empty_links(0)
    rad = float(support_radius)
    a, b, s2 = _neighbour_pairs(left, right, cand, rad, lim)
    if a.size == 0:
        return _empty_links(m)
    return _group_links(cand, len(left), a, b, s2, lim * rad * _SLACK)


def _neighbour_pairs(left: EdgeMap, right: EdgeMap, cand: Candidates, rad: float,
                     lim: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every unordered pair of candidates that support each other (:func:`support_links`):
    (a, b) candidate indices, a's left edge not b's, and their squared cyclopean
    separation s2 (px^2)."""
    m = len(cand)
    # Candidates as points (v, cyclopean u, d), sorted by (v, u). For every candidate and
    # row offset, the candidates in the columns that the radius may reach come from a
    # (row, column) table of positions in the sorted order; a cheap disparity test
    # thins them before the exact one. The work is done in the sorted order (contiguous
    # reads) and mapped back at the end.
    h, w = left.shape
    r_int = int(np.floor(rad))
    uc = 0.5 * (left.u[cand.left].astype(np.float64) + right.u[cand.right])
    vc = left.v[cand.left].astype(np.int64)
    col = np.clip(np.floor(uc).astype(np.int64), 0, w - 1)
    order = np.argsort((vc * w + col) * 2.0 + (uc - col))
    s_uc64 = uc[order]
    s_d64 = cand.d[order].astype(np.float64)
    s_d = s_d64.astype(np.float32)
    s_v = vc[order]
    # Support is symmetric: pairs are found once (rows below, or to the right on the
    # same row) and used both ways. All row offsets at once: window (dv, i) is the
    # range [lo, hi) of positions in row s_v[i] + dv within sqrt(rad^2 - dv^2) columns
    # (a hair more) of s_uc[i], from a table with r_int empty rows below the image.
    table = _cell_table(s_v * w + col[order], (h + r_int) * w)
    nd = r_int + 1
    dvs = np.arange(nd)
    half = (np.sqrt(np.maximum(rad * rad - dvs * dvs, 0.0)) + 1e-6)[:, None]
    if _nb_pairs is not None:
        i, j, s2 = _nb_pairs(table, half[:, 0], w, s_uc64, s_d64, s_v, rad * rad,
                             lim * lim)
        return order[i], order[j], s2
    base = (s_v * w)[None, :] + (dvs * w)[:, None]
    lo = table[base + np.maximum(np.floor(s_uc64[None, :] - half).astype(np.int64), 0)]
    hi = table[base + np.minimum(np.floor(s_uc64[None, :] + half).astype(np.int64), w - 1)
               + 1]
    del table, base
    pos = np.arange(m)
    lo[0] = np.maximum(lo[0], pos + 1)
    cnt = np.maximum(hi - lo, 0).ravel()
    tot = int(cnt.sum())
    if tot == 0:
        z = np.zeros(0, np.intp)
        return z, z, np.zeros(0)
    # The expanded pairs are the bulk of the memory: few, small temporaries, in place
    # (fresh pages cost more than the arithmetic).
    j = np.repeat(lo.ravel() - (np.cumsum(cnt) - cnt), cnt)
    j += np.arange(tot)
    # Cheap single-precision pre-test (index lists: boolean masks are slow).
    dd = s_d[j]
    dd -= np.repeat(np.tile(s_d, nd), cnt)
    keep = np.flatnonzero(np.abs(dd, out=dd) <= np.float32(lim * rad * _SLACK))
    del dd
    j = j[keep]
    i = np.repeat(np.tile(pos.astype(np.int32), nd), cnt)[keep].astype(np.intp)
    del keep
    # Exact tests in double precision on the few that are left.
    dcu = s_uc64[j] - s_uc64[i]
    dv = (s_v[j] - s_v[i]).astype(np.float64)
    s2 = dcu * dcu + dv * dv
    dd = s_d64[j] - s_d64[i]
    keep = np.flatnonzero((s2 <= rad * rad) & (dd * dd <= (lim * lim) * s2) & (s2 > 0.0))
    return order[i[keep]], order[j[keep]], s2[keep]


def _pairs_kernel(table, half, w, s_uc, s_d64, s_v, rad2, lim2):
    """The loops of :func:`_neighbour_pairs` (for numba): the same windows and tests, in
    the same order (row offset, then candidate, then window position) as numpy's (its
    single-precision pre-test only skips pairs that the exact tests reject)."""
    nd = half.shape[0]
    m = s_uc.shape[0]
    lo = np.empty((nd, m), np.int64)
    hi = np.empty((nd, m), np.int64)
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


_nb_pairs = _jit(_pairs_kernel)
_nb_select = None          # set after _select_kernel
_nb_group = None
_nb_search_left = _jit(_search_left)
_nb_search_right = _jit(_search_right)
_nb_candidates = _jit(_candidates_kernel) if _nb_search_left is not None else None
_nb_cells = _jit(_cells_kernel)
_nb_siblings = _jit(_siblings_kernel)
_nb_link_rows = _jit(_link_rows_kernel)


def _group_links(cand: Candidates, n_left: int, a: np.ndarray, b: np.ndarray,
                 s2: np.ndarray, tol: float) -> SupportLinks:
    """The SupportLinks of the mutually supporting candidate pairs (a, b) at squared
    separations s2 (``tol``: lim * rad, with slack)."""
    m = len(cand)
    if _nb_group is not None:
        d_prev, d_next, monotonic = (_sibling_disparities(cand) if _nb_siblings is None
                                     else _nb_siblings(cand.left, cand.d))
        c, start, c2, sep2, n1 = _nb_group(a, b, s2, cand.d, d_prev, d_next, monotonic,
                                           float(tol), cand.left, n_left)
        if _nb_link_rows is not None:
            pair_link, pair_edge, pair_right = _nb_link_rows(start, c2.size, c2, cand.left,
                                                             cand.right)
        else:
            pair_link = np.repeat(np.arange(start.size), np.diff(np.append(start, c2.size)))
            pair_edge, pair_right = cand.left[c2], cand.right[c2]
        return SupportLinks(num_candidates=m, cand=c, start=start, pair_link=pair_link,
                            pair_cand=c2, pair_edge=pair_edge,
                            pair_right=pair_right, weight=sep2, num_single=int(n1))
    # Each pair (a, b) is used both ways: a supported by b, and b by a. Links group the
    # supporters by (supported candidate, supporter's left edge). Two supporters of c
    # on one left edge both lie within lim * rad of c's disparity, so a supporter can
    # share its link only if a sibling next to it in disparity does too (disparities
    # are monotonic along a left edge's candidates); the others are single-supporter
    # links, stored first, unsorted, and only the rest are sorted into groups.
    d_prev, d_next, monotonic = _sibling_disparities(cand)
    if monotonic:
        da, db = cand.d[a], cand.d[b]
        with np.errstate(invalid='ignore'):
            multi_ab = (np.abs(d_prev[b] - da) <= tol) | (np.abs(d_next[b] - da) <= tol)
            multi_ba = (np.abs(d_prev[a] - db) <= tol) | (np.abs(d_next[a] - db) <= tol)
        del da, db
    else:           # any supporter with a sibling may share a link
        sib = ~np.isnan(d_prev) | ~np.isnan(d_next)
        multi_ab, multi_ba = sib[b], sib[a]
    c = np.concatenate((a, b))          # supported
    c2 = np.concatenate((b, a))         # supporter
    sep2 = np.concatenate((s2, s2))
    multi = np.concatenate((multi_ab, multi_ba))
    del multi_ab, multi_ba
    n1 = c.size
    start = np.arange(n1)
    pair_link = start
    grp = np.flatnonzero(multi)
    if grp.size:
        one = np.flatnonzero(~multi)
        n1 = one.size
        e2 = cand.left[c2[grp]]
        grp = grp[_lexsort_small(e2, c[grp], n_left, m)]
        sel = np.concatenate((one, grp))
        c, c2, sep2 = c[sel], c2[sel], sep2[sel]
        cg, e2 = c[n1:], cand.left[c2[n1:]]
        first = np.ones(cg.size, bool)
        first[1:] = (cg[1:] != cg[:-1]) | (e2[1:] != e2[:-1])
        start = np.concatenate((start[:n1], n1 + np.flatnonzero(first)))
        pair_link = np.concatenate((pair_link[:n1], n1 + np.cumsum(first) - 1))
    np.sqrt(sep2, out=sep2)
    return SupportLinks(num_candidates=m, cand=c[start], start=start, pair_link=pair_link,
                        pair_cand=c2, pair_edge=cand.left[c2], pair_right=cand.right[c2],
                        weight=np.divide(1.0, sep2, out=sep2), num_single=n1)


def _group_kernel(a, b, s2, d, d_prev, d_next, monotonic, tol, c_left, n_left):
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
    cand_of = np.concatenate((a, b))
    sup_of = np.concatenate((b, a))
    s2_of = np.concatenate((s2, s2))
    q1 = 0
    q2 = 0
    for k in range(n):
        ck = cand_of[k]
        sk = sup_of[k]
        s2k = s2_of[k]
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
        ck = cand_of[k]
        sk = sup_of[k]
        s2k = s2_of[k]
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


def _lexsort_small(minor: np.ndarray, major: np.ndarray, n_minor: int,
                   n_major: int) -> np.ndarray:
    """Permutation sorting by (major, minor), both non-negative ints below n_major,
    n_minor; two stable radix sorts when they fit in 16 bits."""
    if n_minor < 65536 and n_major < 65536:
        p = np.argsort(minor.astype(np.uint16), kind='stable')
        return p[np.argsort(major[p].astype(np.uint16), kind='stable')]
    return np.lexsort((minor, major))


def _link_support(links: SupportLinks, w: np.ndarray) -> np.ndarray:
    """Support of every candidate from the (alive-masked) weights of the supporters."""
    m = links.num_candidates
    if len(links) == 0:
        return np.zeros(m)
    s = min(int(links.num_single), w.size)
    if s == w.size:
        best = w
    elif s == 0:
        best = np.maximum.reduceat(w, links.start)
    else:
        best = np.concatenate((w[:s], np.maximum.reduceat(w[s:], links.start[s:] - s)))
    return np.bincount(links.cand, weights=best, minlength=m)


def pmf_support(links: SupportLinks, taken_right: np.ndarray | None = None,
                left_match: np.ndarray | None = None) -> np.ndarray:
    """PMF support of every candidate: the sum over its neighbouring edges of the
    weight of each one's best alive compatible match.

    A supporter (e', r') is alive when it is an accepted match, or when neither e' nor r'
    is used by an accepted match (a competitor of an accepted match has been removed).

    Args:
        links: the SupportLinks of M candidates.
        taken_right: (N_right,) bool, right edges used by accepted matches; None = none.
        left_match: (N_left,) int, accepted right edge of each left edge, -1 if none;
            None = none (then every supporter is alive).
    Returns:
        (M,) float64 support.
    """
    w = links.weight
    if len(links) and left_match is not None and taken_right is not None:
        lm = left_match[links.pair_edge]
        alive = np.where(lm >= 0, lm == links.pair_right, ~taken_right[links.pair_right])
        w = np.where(alive, w, 0.0)
    return _link_support(links, w)


class _Groups:
    """Candidates grouped by one of their edges, for strict-maximum tests per group.
    Only groups of two or more are kept: the single candidate of a group is always its
    strict maximum."""

    def __init__(self, group: np.ndarray, num_groups: int) -> None:
        g = np.asarray(group)
        n = g.shape[0]
        order = None
        if n > 1 and not np.all(g[1:] >= g[:-1]):
            order = (np.argsort(g.astype(np.uint16), kind='stable') if num_groups <= 65536
                     else np.argsort(g, kind='stable'))
            g = g[order]
        first = np.ones(n, bool)
        first[1:] = g[1:] != g[:-1]
        starts = np.flatnonzero(first)
        sizes = np.diff(np.append(starts, n))
        multi = sizes > 1
        # Members of the groups of two or more, in group order (indices into the input).
        pos = np.repeat(multi, sizes)
        idx = np.flatnonzero(pos)
        self.members = idx if order is None else order[idx]
        self.sizes = sizes[multi]
        self.starts = np.cumsum(self.sizes) - self.sizes
        self.n = n

    def unique_max(self, values: np.ndarray) -> np.ndarray:
        """(M,) bool: whether each element is strictly the largest of its group."""
        out = np.ones(self.n, bool)
        if self.members.size:
            x = values[self.members]
            at_best = x == np.repeat(np.maximum.reduceat(x, self.starts), self.sizes)
            n_best = np.add.reduceat(at_best.astype(np.int32), self.starts)
            out[self.members] = at_best & np.repeat(n_best == 1, self.sizes)
        return out


def select_matches(cand: Candidates, links: SupportLinks, left: EdgeMap, right: EdgeMap, *,
                   iterations: int = 3, min_support: float = 0.5
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Winner-take-all with uniqueness in both images, iterated PMF-style.

    Args:
        cand: candidates (M).
        links: their SupportLinks.
        left, right: the EdgeMaps.
        iterations: rounds of (support, accept winners, remove competitors), >= 1.
        min_support: a winner needs support strictly above this (>= 0).
    Returns:
        (accepted (M,) bool, support (M,) float64 from the last round).
    """
    m = len(cand)
    accepted = np.zeros(m, bool)
    support = np.zeros(m)
    if m == 0:
        return accepted, support
    n_l, n_r = len(left), len(right)
    if _nb_select is not None and len(links):
        return _nb_select(cand.left, cand.right, n_l, n_r, links.cand, links.start,
                          links.pair_cand, links.weight, max(int(iterations), 1),
                          float(min_support))
    alive = np.ones(m, bool)
    by_left = _Groups(cand.left, n_l)
    by_right = _Groups(cand.right, n_r)
    taken_r = np.zeros(n_r, bool)
    matched_l = np.zeros(n_l, bool)
    rounds = max(int(iterations), 1)
    for it in range(rounds):
        # A supporter is alive when it is an accepted match or neither of its edges is
        # used by one: exactly the candidates still alive here.
        if it == 0:
            support = _link_support(links, links.weight)
            val = support
        else:
            support = _link_support(links, np.where(alive[links.pair_cand], links.weight, 0.0))
            val = np.where(alive, support, -np.inf)
        win = alive & (support > min_support) & by_left.unique_max(val)
        if win.any():
            win &= by_right.unique_max(val)
        if not (win & ~accepted).any():
            break
        accepted |= win
        if it == rounds - 1:
            break
        k = np.flatnonzero(win)
        taken_r[cand.right[k]] = True
        matched_l[cand.left[k]] = True
        alive &= accepted | ~(matched_l[cand.left] | taken_r[cand.right])
    return accepted, support


def _select_kernel(c_left, c_right, n_l, n_r, l_cand, l_start, pair_cand, weight, rounds,
                   min_support):
    """:func:`select_matches` as loops (for numba), with the same arithmetic: a link's
    best alive weight (a maximum: exact), summed per candidate in link order (as
    ``np.bincount``), strict maxima per left and right edge."""
    m = c_left.shape[0]
    nq = l_cand.shape[0]
    npair = weight.shape[0]
    accepted = np.zeros(m, np.bool_)
    alive = np.ones(m, np.bool_)
    support = np.zeros(m)
    win = np.zeros(m, np.bool_)
    taken_r = np.zeros(n_r, np.bool_)
    matched_l = np.zeros(n_l, np.bool_)
    gmax_l = np.empty(n_l)
    cnt_l = np.empty(n_l, np.int64)
    gmax_r = np.empty(n_r)
    cnt_r = np.empty(n_r, np.int64)
    val = np.empty(m)
    for it in range(rounds):
        support[:] = 0.0
        for q in range(nq):
            end = l_start[q + 1] if q + 1 < nq else npair
            best = -np.inf
            for p in range(l_start[q], end):
                wp = weight[p] if (it == 0 or alive[pair_cand[p]]) else 0.0
                if wp > best:
                    best = wp
            support[l_cand[q]] += best
        for c in range(m):
            val[c] = support[c] if (it == 0 or alive[c]) else -np.inf
        gmax_l[:] = -np.inf
        gmax_r[:] = -np.inf
        cnt_l[:] = 0
        cnt_r[:] = 0
        for c in range(m):
            x = val[c]
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
            e = c_left[c]
            r = c_right[c]
            wc = (alive[c] and support[c] > min_support and val[c] == gmax_l[e]
                  and cnt_l[e] == 1 and val[c] == gmax_r[r] and cnt_r[r] == 1)
            win[c] = wc
            if wc and not accepted[c]:
                new = True
        if not new:
            break
        for c in range(m):
            if win[c]:
                accepted[c] = True
        if it == rounds - 1:
            break
        for c in range(m):
            if win[c]:
                taken_r[c_right[c]] = True
                matched_l[c_left[c]] = True
        for c in range(m):
            alive[c] = alive[c] and (accepted[c] or not (matched_l[c_left[c]]
                                                         or taken_r[c_right[c]]))
    return accepted, support


def pmf_match(left: EdgeMap, right: EdgeMap, d_min: float, d_max: float, *,
              min_strength_ratio: float = 0.5, max_orientation_diff_deg: float = 30.0,
              support_radius: float = 3.0, disparity_gradient_limit: float = 1.0,
              iterations: int = 3, min_support: float = 0.5, right_gain: float = 1.0
              ) -> tuple[Matches, Candidates, np.ndarray]:
    """:func:`match_edges`, also returning every candidate and its final support.

    ``right_gain`` (> 0) is the factor that puts the right image's grey levels on the
    left's scale, for the strength test only (`candidate_matches`); the matches'
    strengths are the edges' own.

    Returns:
        (matches, candidates, support (M,) float64 of each candidate in the last round).
    """
    cand = candidate_matches(left, right, d_min, d_max, min_strength_ratio=min_strength_ratio,
                             max_orientation_diff_deg=max_orientation_diff_deg,
                             right_gain=right_gain)
    links = support_links(left, right, cand, d_min, d_max, support_radius=support_radius,
                          disparity_gradient_limit=disparity_gradient_limit)
    acc, support = select_matches(cand, links, left, right, iterations=iterations,
                                  min_support=min_support)
    k = np.flatnonzero(acc)
    li = cand.left[k]
    rj = cand.right[k]
    m = Matches(u_left=left.u[li].astype(np.float32), u_right=right.u[rj].astype(np.float32),
                v=left.v[li].astype(np.int32), d=cand.d[k].astype(np.float32),
                strength=(0.5 * (left.strength[li] + right.strength[rj])).astype(np.float32),
                string_id=left.string_id[li].astype(np.int32),
                left_index=li.astype(np.int32), right_index=rj.astype(np.int32),
                support=support[k].astype(np.float32), precision=_precision(left, right, li, rj))
    return m, cand, support


def _precision(left: EdgeMap, right: EdgeMap, li: np.ndarray, rj: np.ndarray) -> np.ndarray | None:
    """Combined curvature ``1 / sqrt(1/cL^2 + 1/cR^2)`` of matched edges (see Matches)."""
    if left.curvature is None or right.curvature is None:
        return None
    cl = np.maximum(left.curvature[li].astype(np.float64), 1e-6)
    cr = np.maximum(right.curvature[rj].astype(np.float64), 1e-6)
    return (1.0 / np.sqrt(1.0 / (cl * cl) + 1.0 / (cr * cr))).astype(np.float32)


def match_edges(left: EdgeMap, right: EdgeMap, d_min: float, d_max: float, *,
                min_strength_ratio: float = 0.5, max_orientation_diff_deg: float = 30.0,
                support_radius: float = 3.0, disparity_gradient_limit: float = 1.0,
                iterations: int = 3, min_support: float = 0.5) -> Matches:
    """Match left edges to right edges row by row: candidates, PMF support, selection.

    Args:
        left, right: EdgeMaps of the rectified left and right images (same shape).
        d_min, d_max: disparity range, pixels (e.g. ``f*B / max_range``, ``f*B / min_range``).
        min_strength_ratio: least ratio weaker/stronger edge strength, 0..1.
        max_orientation_diff_deg: largest gradient-direction difference, degrees.
        support_radius: PMF neighbourhood radius in the cyclopean image, pixels.
        disparity_gradient_limit: PMF disparity-gradient limit, in (0, 2).
        iterations: PMF winner-take-all rounds (>= 1).
        min_support: least support of an accepted match (>= 0).
    Returns:
        Matches sorted by (v, u_left).
    """
    return pmf_match(left, right, d_min, d_max, min_strength_ratio=min_strength_ratio,
                     max_orientation_diff_deg=max_orientation_diff_deg,
                     support_radius=support_radius,
                     disparity_gradient_limit=disparity_gradient_limit,
                     iterations=iterations, min_support=min_support)[0]


_nb_select = _jit(_select_kernel)
_nb_group = _jit(_group_kernel)


def warm_up() -> bool:
    """Compile (or load from the disk cache) the numba kernels on tiny inputs of the
    real argument types, so that the first frame does not pay for it; without numba, or
    if compiling fails, the numpy paths are used. Returns whether numba is in use."""
    global _nb_pairs, _nb_select, _nb_group, _nb_candidates, _nb_cells, _nb_siblings, \
        _nb_link_rows
    if (_nb_pairs is None or _nb_select is None or _nb_group is None
            or _nb_candidates is None or _nb_cells is None or _nb_siblings is None
            or _nb_link_rows is None):
        _nb_pairs = _nb_select = _nb_group = None
        _nb_candidates = _nb_cells = _nb_siblings = _nb_link_rows = None
        return False
    i64, f64 = np.zeros(2, np.int64), np.zeros(2)
    i8, i32, f32 = np.ones(2, np.int8), np.zeros(2, np.int32), np.ones(2, np.float32)
    try:
        for table in (np.zeros(9, np.int32), np.zeros(9, np.int64)):
            _nb_pairs(table, np.ones(2), 2, f64, f64, i64, 9.0, 1.0)
        _nb_select(i64, i64, 2, 2, i64, i64, i64, f64, 3, 0.5)
        for mono in (True, False):
            _nb_group(i64, i64, f64 + 1.0, f64, f64, f64, mono, 3.0, i64, 2)
        _nb_candidates(i8, i32, f32, f32, f32, i8, i32, f32, f32, f32, 2, 2.0, 0.5, 1.0,
                       np.float32(0.5), 0.5)
        _nb_cells(i64, 2)
        _nb_siblings(i64, f64)
        _nb_link_rows(i64, 2, i64, i64, i64)
    except Exception:       # pragma: no cover - a broken numba/llvmlite install
        _nb_pairs = _nb_select = _nb_group = None
        _nb_candidates = _nb_cells = _nb_siblings = _nb_link_rows = None
        return False
    return True
