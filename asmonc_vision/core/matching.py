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
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .edges import EdgeMap


@dataclass(frozen=True)
class Candidates:
    """Candidate matches, grouped by left edge (sorted by left index, then right index).

    Attributes:
        left: (M,) int32 index into the left EdgeMap.
        right: (M,) int32 index into the right EdgeMap.
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
    stored.

    Attributes:
        num_candidates: M.
        cand: (Q,) int32 supported candidate.
        start: (Q,) int64 index of the link's first supporter (ascending).
        pair_link: (P,) int32 link of each supporter (ascending).
        pair_cand: (P,) int32 supporting candidate (index into the Candidates).
        pair_edge: (P,) int32 its left edge (index into the left EdgeMap).
        pair_right: (P,) int32 its right edge (index into the right EdgeMap).
        weight: (P,) float64 ``1 / distance`` between the two candidates' cyclopean
            positions, 1/pixels.
    """

    num_candidates: int
    cand: np.ndarray
    start: np.ndarray
    pair_link: np.ndarray
    pair_cand: np.ndarray
    pair_edge: np.ndarray
    pair_right: np.ndarray
    weight: np.ndarray

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
                      max_orientation_diff_deg: float = 30.0) -> Candidates:
    """All admissible (left edge, right edge) pairs on the same row.

    Args:
        left, right: edge maps of the rectified left and right images (same shape).
        d_min, d_max: disparity search range, pixels (``d_min <= d <= d_max``).
        min_strength_ratio: least ratio of the weaker to the stronger edge, 0..1.
        max_orientation_diff_deg: largest difference of gradient directions, degrees.
    Returns:
        Candidates grouped by left edge.
    """
    if left.shape != right.shape:
        raise ValueError(f'left and right edge maps differ in shape: {left.shape} vs {right.shape}')
    if len(left) == 0 or len(right) == 0 or d_max < d_min:
        z = np.zeros(0, np.int32)
        return Candidates(z, z, np.zeros(0))
    # Right edges of the same polarity and row, within the disparity range: one
    # contiguous range of the right edges sorted by (polarity, row, column).
    h = left.shape[0]
    span = float(left.shape[1]) + abs(float(d_max)) + abs(float(d_min)) + 4.0
    plane_r = (right.polarity < 0).astype(np.int64)
    order_r = np.r_[np.flatnonzero(plane_r == 0), np.flatnonzero(plane_r == 1)]
    key_r = ((plane_r * h + right.v) * span + right.u)[order_r]
    key_l = ((left.polarity < 0).astype(np.int64) * h + left.v) * span + left.u
    lo = np.searchsorted(key_r, key_l - d_max, side='left')
    hi = np.searchsorted(key_r, key_l - d_min, side='right')
    li, pos = _expand(lo, hi)
    rj = order_r[pos]
    sl = left.strength[li]
    sr = right.strength[rj]
    ok = np.minimum(sl, sr) >= min_strength_ratio * np.maximum(sl, sr)
    dori = np.abs(left.orientation[li] - right.orientation[rj])
    dori = np.minimum(dori, 2.0 * np.pi - dori)
    ok &= dori <= np.deg2rad(max_orientation_diff_deg)
    li, rj = li[ok], rj[ok]
    return Candidates(left=li.astype(np.int32), right=rj.astype(np.int32),
                      d=left.u[li].astype(np.float64) - right.u[rj])


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
    zi = np.zeros(0, np.int32)
    return SupportLinks(num_candidates=m, cand=zi, start=np.zeros(0, np.int64), pair_link=zi,
                        pair_cand=zi, pair_edge=zi, pair_right=zi, weight=np.zeros(0))


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
    double precision.

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
    # Candidates as points (v, cyclopean u, d), sorted by (v, u). For every candidate and
    # row offset, the candidates in the columns that the radius may reach come from a
    # (row, column) table of positions in the sorted order; a cheap disparity test
    # thins them before the exact one. The work is done in the sorted order (contiguous
    # reads) and mapped back at the end.
    h, w = left.shape
    uc = 0.5 * (left.u[cand.left].astype(np.float64) + right.u[cand.right])
    vc = left.v[cand.left].astype(np.int64)
    col = np.clip(np.floor(uc).astype(np.int64), 0, w - 1)
    cell = vc * w + col
    order = np.argsort(cell * 2.0 + (uc - col), kind='stable')
    s_cell = cell[order]
    s_uc64 = uc[order]
    s_d64 = cand.d[order].astype(np.float64)
    s_d = s_d64.astype(np.float32)
    table = np.zeros(h * w + 1, np.int64)
    np.cumsum(np.bincount(s_cell, minlength=h * w), out=table[1:])
    r_int = int(np.floor(rad))
    s_v = vc[order]
    c_lo = np.maximum(np.floor(s_uc64 - rad).astype(np.int64), 0)
    c_hi = np.minimum(np.floor(s_uc64 + rad).astype(np.int64), w - 1)
    lim2 = lim * lim
    rad2 = rad * rad
    dmax = lim * rad
    # Support is symmetric: pairs are found once (rows below, or to the right on the
    # same row) and used both ways.
    own, oth, sep = [], [], []
    for dv in range(0, r_int + 1):
        row = s_v + dv
        inside = row < h
        base = np.where(inside, row, 0) * w
        lo = np.where(inside, table[base + c_lo], 0)
        hi = np.where(inside, table[base + c_hi + 1], 0)
        if dv == 0:
            lo = np.maximum(lo, np.arange(m) + 1)
        i, j = _expand(lo, hi)
        if i.size == 0:
            continue
        dd = s_d[j] - s_d[i]
        near = np.abs(dd) <= dmax * _SLACK
        i, j = i[near], j[near]
        # Exact tests in double precision on the few that are left.
        dcu = s_uc64[j] - s_uc64[i]
        s2 = dcu * dcu + float(dv * dv)
        dd = s_d64[j] - s_d64[i]
        ok = (s2 <= rad2) & (dd * dd <= lim2 * s2) & (s2 > 0.0)
        own.append(i[ok])
        oth.append(j[ok])
        sep.append(s2[ok])
    if not own:
        return _empty_links(m)
    i = np.concatenate(own)
    j = np.concatenate(oth)
    c = order[np.r_[i, j]]
    c2 = order[np.r_[j, i]]
    sep2 = np.tile(np.concatenate(sep), 2)
    if c.size == 0:
        return _empty_links(m)
    # Links: supporters grouped by (supported candidate, supporter's left edge).
    e2 = cand.left[c2].astype(np.int64)
    srt = _lexsort_small(e2, c, len(left), m)
    c, c2, sep2, e2 = c[srt], c2[srt], sep2[srt], e2[srt]
    gkey = c * (len(left) + 1) + e2
    first = np.ones(c.size, bool)
    first[1:] = gkey[1:] != gkey[:-1]
    start = np.flatnonzero(first)
    pair_link = (np.cumsum(first) - 1).astype(np.int32)
    return SupportLinks(num_candidates=m, cand=c[start].astype(np.int32), start=start,
                        pair_link=pair_link, pair_cand=c2.astype(np.int32),
                        pair_edge=cand.left[c2].astype(np.int32),
                        pair_right=cand.right[c2].astype(np.int32),
                        weight=1.0 / np.sqrt(sep2))


def _lexsort_small(minor: np.ndarray, major: np.ndarray, n_minor: int,
                   n_major: int) -> np.ndarray:
    """Permutation sorting by (major, minor), both non-negative ints below n_major,
    n_minor; two stable radix sorts when they fit in 16 bits."""
    if n_minor < 65536 and n_major < 65536:
        p = np.argsort(minor.astype(np.uint16), kind='stable')
        return p[np.argsort(major[p].astype(np.uint16), kind='stable')]
    return np.lexsort((minor, major))


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
    m = links.num_candidates
    if len(links) == 0:
        return np.zeros(m)
    w = links.weight
    if left_match is not None and taken_right is not None:
        lm = left_match[links.pair_edge]
        alive = np.where(lm >= 0, lm == links.pair_right, ~taken_right[links.pair_right])
        w = np.where(alive, w, 0.0)
    best = np.maximum.reduceat(w, links.start)
    return np.bincount(links.cand, weights=best, minlength=m)


def _unique_max(values: np.ndarray, group: np.ndarray, order: np.ndarray,
                num_groups: int) -> np.ndarray:
    """Whether each element is strictly the largest of its group.

    Args:
        values: (M,) float64 (use -inf for excluded elements).
        group: (M,) int group of each element.
        order: (M,) permutation sorting ``group`` ascending.
        num_groups: number of groups G (> max(group)).
    Returns:
        (M,) bool.
    """
    best = np.full(num_groups, -np.inf)
    if values.size:
        g = group[order]
        starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
        best[g[starts]] = np.maximum.reduceat(values[order], starts)
    at_best = values == best[group]
    n_best = np.bincount(group[at_best], minlength=num_groups)
    return at_best & (n_best[group] == 1)


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
    alive = np.ones(m, bool)
    order_l = np.arange(m)                                   # grouped by left already
    order_r = np.argsort(cand.right, kind='stable')
    taken_r = None
    left_match = None
    for _ in range(max(int(iterations), 1)):
        support = pmf_support(links, taken_r, left_match)
        val = np.where(alive, support, -np.inf)
        win = (alive & (support > min_support)
               & _unique_max(val, cand.left, order_l, n_l)
               & _unique_max(val, cand.right, order_r, n_r))
        if not (win & ~accepted).any():
            break
        accepted |= win
        taken_r = np.zeros(n_r, bool)
        taken_r[cand.right[accepted]] = True
        left_match = np.full(n_l, -1, np.int64)
        left_match[cand.left[accepted]] = cand.right[accepted]
        alive &= accepted | ~((left_match[cand.left] >= 0) | taken_r[cand.right])
    return accepted, support


def pmf_match(left: EdgeMap, right: EdgeMap, d_min: float, d_max: float, *,
              min_strength_ratio: float = 0.5, max_orientation_diff_deg: float = 30.0,
              support_radius: float = 3.0, disparity_gradient_limit: float = 1.0,
              iterations: int = 3, min_support: float = 0.5
              ) -> tuple[Matches, Candidates, np.ndarray]:
    """:func:`match_edges`, also returning every candidate and its final support.

    Returns:
        (matches, candidates, support (M,) float64 of each candidate in the last round).
    """
    cand = candidate_matches(left, right, d_min, d_max, min_strength_ratio=min_strength_ratio,
                             max_orientation_diff_deg=max_orientation_diff_deg)
    links = support_links(left, right, cand, d_min, d_max, support_radius=support_radius,
                          disparity_gradient_limit=disparity_gradient_limit)
    acc, support = select_matches(cand, links, left, right, iterations=iterations,
                                  min_support=min_support)
    li = cand.left[acc]
    rj = cand.right[acc]
    m = Matches(u_left=left.u[li].astype(np.float32), u_right=right.u[rj].astype(np.float32),
                v=left.v[li].astype(np.int32), d=cand.d[acc].astype(np.float32),
                strength=(0.5 * (left.strength[li] + right.strength[rj])).astype(np.float32),
                string_id=left.string_id[li].astype(np.int32),
                left_index=li.astype(np.int32), right_index=rj.astype(np.int32),
                support=support[acc].astype(np.float32), precision=_precision(left, right, li, rj))
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
