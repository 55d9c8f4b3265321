"""Row-wise stereo matching of vertical edges with PMF-style support.

After Pollard, Mayhew & Frisby (PMF, 1985), as used by GPOD (Molton et al. 1998, Sec. 2.1):

1. Candidates (:func:`candidate_matches`): every left edge is paired with the right edges
   of the same row whose disparity ``d = u_left - u_right`` lies in ``[d_min, d_max]``,
   of the same polarity, with compatible strength (ratio of the weaker to the stronger at
   least ``min_strength_ratio``) and orientation (gradient directions within
   ``max_orientation_diff_deg``).
2. Support (:func:`support_links`, :func:`pmf_support`): a candidate c = (e, r) gets
   support from every *other* left edge e' within ``support_radius`` pixels of e (left
   image) that has a live match (e', r') compatible with c under the disparity-gradient
   limit ``|d' - d| <= limit * |cyclopean separation|``. Each neighbouring edge
   contributes once (PMF counts only the best match of each neighbour), with weight
   ``1 / distance`` between e and e'. The compatible right edges r' of a neighbour
   lie in an interval of columns on its row (the disparity-gradient limit solved
   exactly for the sub-pixel positions), so each (candidate, neighbour edge) link looks
   only at the one or two right edges of the right polarity in that interval, found in
   O(1) from a (polarity, row, column) table, instead of testing every pair of
   candidates; those must pass the candidate tests too. Neighbourhoods are on integer
   pixel positions (a disc of ``support_radius``).
3. Selection (:func:`select_matches`): winner-take-all with uniqueness in both images:
   a candidate is accepted when its support is above ``min_support`` and strictly the
   largest among the live candidates of both its left and its right edge. Competitors of
   accepted matches die, support is recomputed from the survivors (a neighbour edge that
   has been matched now supports only through its accepted match), for ``iterations``
   rounds (1 = one-pass). This is iterative PMF in outline; a fuller version (relaxation,
   string-level consistency) can replace :func:`select_matches` alone.

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

    Link q says: candidate ``cand[q]`` is supported, with weight ``weight[q]``, by its
    neighbouring left edge if any of the link's *supporters* is alive. Supporter pair p
    belongs to link ``pair_link[p]``: (``pair_edge[p]``, ``pair_right[p]``) is an
    admissible candidate of the neighbouring edge compatible with ``cand[q]`` under the
    disparity-gradient limit. Links without supporters are not stored.

    Attributes:
        num_candidates: M.
        cand: (Q,) int32 supported candidate.
        weight: (Q,) float32 ``1 / distance`` between the two left edges, 1/pixels.
        pair_link: (P,) int32 link of each supporter.
        pair_edge: (P,) int32 supporting left edge (index into the left EdgeMap).
        pair_right: (P,) int32 supporting right edge (index into the right EdgeMap).
    """

    num_candidates: int
    cand: np.ndarray
    weight: np.ndarray
    pair_link: np.ndarray
    pair_edge: np.ndarray
    pair_right: np.ndarray

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


def _empty_links(m: int) -> SupportLinks:
    zi = np.zeros(0, np.int32)
    return SupportLinks(num_candidates=m, cand=zi, weight=np.zeros(0, np.float32),
                        pair_link=zi, pair_edge=zi, pair_right=zi)


def _polarity_row_table(edges: EdgeMap) -> tuple[np.ndarray, np.ndarray]:
    """Lookup of the edges of one polarity on one row by column.

    Args:
        edges: an EdgeMap (sorted by row, then column).
    Returns:
        (table, order): ``order`` (N,) int64 lists the edge indices of polarity +1, then
        those of polarity -1, each sorted by (row, column); ``table`` (2 * H * (W + 1),)
        int64 holds at ``(p * H + v) * (W + 1) + c`` the position in ``order`` of the
        first edge of polarity plane p (0: +1, 1: -1) on row v with column >= c. The
        edges of plane p, row v, columns c0..c1 are
        ``order[table[base + c0] : table[base + c1 + 1]]``, base = (p * H + v) * (W + 1).
    """
    h, w = edges.shape
    plane = (edges.polarity < 0).astype(np.int64)
    occ = np.zeros(2 * h * (w + 1), np.int64)
    occ[(plane * h + edges.v) * (w + 1) + edges.u_int + 1] = 1
    order = np.r_[np.flatnonzero(plane == 0), np.flatnonzero(plane == 1)]
    return np.cumsum(occ), order


def support_links(left: EdgeMap, right: EdgeMap, cand: Candidates, d_min: float,
                  d_max: float, *, support_radius: float = 3.0,
                  disparity_gradient_limit: float = 1.0, min_strength_ratio: float = 0.5,
                  max_orientation_diff_deg: float = 30.0) -> SupportLinks:
    """Links from every candidate to the neighbouring left edges that may support it.

    For candidate c = (e, r) with disparity d and a left edge e' (with candidates)
    within ``support_radius`` of e (integer pixel positions, e' != e), offset
    ``(du, dv)`` with sub-pixel du, a candidate (e', r') is compatible when
    ``d' = d + x`` with x in :func:`disparity_gradient_interval` (exact, sub-pixel), i.e.
    ``u_right(r')`` in ``[u_right(r) + du - x_hi, u_right(r) + du - x_lo]``, d' in
    ``[d_min, d_max]``, and (e', r') passes the candidate tests (polarity, strength,
    orientation; use the same settings as :func:`candidate_matches`). Only the few right
    edges of the right polarity in that interval are looked at, found in O(1) from a
    (polarity, row, column) table.

    Args:
        left, right: the EdgeMaps the candidates index.
        cand: candidates from :func:`candidate_matches`.
        d_min, d_max: the disparity range used for the candidates, pixels.
        support_radius: neighbourhood radius, pixels (>= 1).
        disparity_gradient_limit: PMF disparity-gradient limit, in (0, 2).
        min_strength_ratio, max_orientation_diff_deg: candidate tests, as for
            :func:`candidate_matches`.
    Returns:
        The SupportLinks.
    """
    m = len(cand)
    lim = float(disparity_gradient_limit)
    if not 0.0 < lim < 2.0:
        raise ValueError(f'disparity_gradient_limit must be in (0, 2), got {lim}')
    if m == 0:
        return _empty_links(0)
    # Left edges that have candidates (ranks k), each one's range of candidates.
    new_edge = np.ones(m, bool)
    new_edge[1:] = cand.left[1:] != cand.left[:-1]
    first_cand = np.flatnonzero(new_edge)
    edges = cand.left[first_cand].astype(np.int64)
    n_e = edges.size
    count = np.diff(np.r_[first_cand, m])
    # Neighbouring edge pairs (k1, k2) from an index image padded by the radius.
    du_o, dv_o = disc_offsets(support_radius)
    pad = int(np.floor(support_radius))
    h, w = left.shape
    wp = w + 2 * pad
    rank_img = np.full((h + 2 * pad) * wp, -1, np.int32)
    flat = (left.v[edges].astype(np.int64) + pad) * wp + left.u_int[edges] + pad
    rank_img[flat] = np.arange(n_e, dtype=np.int32)
    nb = rank_img[flat[:, None] + (dv_o * wp + du_o)[None, :]]
    k1, j = np.nonzero(nb >= 0)
    e2 = edges[nb[k1, j]]
    ul = left.u.astype(np.float64)
    du = ul[e2] - ul[edges[k1]]
    dv = dv_o[j].astype(np.float64)
    x_lo, x_hi = disparity_gradient_interval(du, dv, lim)
    wgt = (1.0 / np.sqrt(du * du + dv * dv)).astype(np.float32)
    # Per edge pair: u_right(r') bounds relative to u_right(r), and absolute bounds
    # from the disparity range, and the table base of the neighbour's polarity and row.
    off_lo = (du - x_hi).astype(np.float32)
    off_hi = (du - x_lo).astype(np.float32)
    ul2 = ul[e2]
    abs_lo = (ul2 - d_max).astype(np.float32)
    abs_hi = (ul2 - d_min).astype(np.float32)
    base = (((left.polarity[e2] < 0).astype(np.int64) * h + left.v[e2]) * (w + 1))
    # One link per (candidate of k1, edge pair).
    pair, c = _expand(first_cand[k1], first_cand[k1] + count[k1])
    ur_c = right.u[cand.right[c]]
    a = np.maximum(ur_c + off_lo[pair], abs_lo[pair])
    b = np.minimum(ur_c + off_hi[pair], abs_hi[pair])
    # Right edges of the neighbour's polarity whose integer column may hold [a, b].
    col_lo = np.clip(np.ceil(a - 0.5), 0, w).astype(np.int64)
    col_hi = np.clip(np.floor(b + 0.5) + 1, 0, w).astype(np.int64)
    table, order = _polarity_row_table(right)
    bp = base[pair]
    lo = table[bp + col_lo]
    n_in = table[bp + np.maximum(col_hi, col_lo)] - lo
    q = np.flatnonzero(n_in > 0)
    pair, c, a, b, lo, n_in = pair[q], c[q], a[q], b[q], lo[q], n_in[q]
    e2c = e2[pair]
    # Enumerate those right edges (rarely more than one or two per link).
    links, rights = [], []
    sel = np.arange(q.size)
    for k in range(int(n_in.max()) if q.size else 0):
        sel = sel[n_in[sel] > k]
        links.append(sel)
        rights.append(order[lo[sel] + k])
    link = np.concatenate(links) if links else np.zeros(0, np.int64)
    r2 = np.concatenate(rights) if rights else np.zeros(0, np.int64)
    e2p = e2c[link]
    ur2 = right.u[r2]
    ok = (ur2 >= a[link]) & (ur2 <= b[link])
    sl = left.strength[e2p]
    sr = right.strength[r2]
    ok &= np.minimum(sl, sr) >= min_strength_ratio * np.maximum(sl, sr)
    dori = np.abs(left.orientation[e2p] - right.orientation[r2])
    ok &= np.minimum(dori, 2.0 * np.pi - dori) <= np.deg2rad(max_orientation_diff_deg)
    link, r2, e2p = link[ok], r2[ok], e2p[ok]
    if link.size == 0:
        return _empty_links(m)
    # Keep links with supporters; renumber the supporters' links.
    has = np.zeros(q.size, bool)
    has[link] = True
    new_index = np.cumsum(has) - 1
    return SupportLinks(num_candidates=m, cand=c[has].astype(np.int32),
                        weight=wgt[pair[has]], pair_link=new_index[link].astype(np.int32),
                        pair_edge=e2p.astype(np.int32), pair_right=r2.astype(np.int32))


def pmf_support(links: SupportLinks, taken_right: np.ndarray | None = None,
                left_match: np.ndarray | None = None) -> np.ndarray:
    """Support of every candidate from the live matches of its neighbouring edges.

    A supporter (e', r') is alive when it is an accepted match, or when neither e' nor r'
    is used by an accepted match. A link gives its weight when any supporter is alive.

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
    if left_match is None or taken_right is None:
        return np.bincount(links.cand, weights=links.weight, minlength=m)
    lm = left_match[links.pair_edge]
    alive = np.where(lm >= 0, lm == links.pair_right, ~taken_right[links.pair_right])
    live = np.bincount(links.pair_link[alive], minlength=len(links)) > 0
    return np.bincount(links.cand, weights=np.where(live, links.weight, 0.0), minlength=m)


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
                   iterations: int = 2, min_support: float = 0.5
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


def match_edges(left: EdgeMap, right: EdgeMap, d_min: float, d_max: float, *,
                min_strength_ratio: float = 0.5, max_orientation_diff_deg: float = 30.0,
                support_radius: float = 3.0, disparity_gradient_limit: float = 1.0,
                iterations: int = 2, min_support: float = 0.5) -> Matches:
    """Match left edges to right edges row by row (candidates, PMF support, selection).

    Args:
        left, right: EdgeMaps of the rectified left and right images (same shape).
        d_min, d_max: disparity range, pixels (e.g. ``f*B / max_range``, ``f*B / min_range``).
        min_strength_ratio: least ratio weaker/stronger edge strength, 0..1.
        max_orientation_diff_deg: largest gradient-direction difference, degrees.
        support_radius: PMF neighbourhood radius in the left image, pixels.
        disparity_gradient_limit: PMF disparity-gradient limit, in (0, 2).
        iterations: PMF selection rounds (>= 1).
        min_support: least support of an accepted match (>= 0).
    Returns:
        Matches sorted by (v, u_left).
    """
    cand = candidate_matches(left, right, d_min, d_max, min_strength_ratio=min_strength_ratio,
                             max_orientation_diff_deg=max_orientation_diff_deg)
    links = support_links(left, right, cand, d_min, d_max, support_radius=support_radius,
                          disparity_gradient_limit=disparity_gradient_limit,
                          min_strength_ratio=min_strength_ratio,
                          max_orientation_diff_deg=max_orientation_diff_deg)
    acc, support = select_matches(cand, links, left, right, iterations=iterations,
                                  min_support=min_support)
    li = cand.left[acc]
    rj = cand.right[acc]
    return Matches(u_left=left.u[li].astype(np.float32), u_right=right.u[rj].astype(np.float32),
                   v=left.v[li].astype(np.int32), d=cand.d[acc].astype(np.float32),
                   strength=(0.5 * (left.strength[li] + right.strength[rj])).astype(np.float32),
                   string_id=left.string_id[li].astype(np.int32),
                   left_index=li.astype(np.int32), right_index=rj.astype(np.int32),
                   support=support[acc].astype(np.float32))
