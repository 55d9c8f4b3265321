"""PMF selection (step 3): iterative winner-take-all with uniqueness, and the whole
matcher (`pmf_match`, `match_edges`)."""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.edges import EdgeMap
from asmonc_vision.core.matching import kernels
from asmonc_vision.core.matching.candidates import candidate_matches, expand_ranges
from asmonc_vision.core.matching.support import link_support, support_links
from asmonc_vision.core.matching.types import Candidates, Matches, SupportLinks
from ..npfast import flat_nonzero


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
        starts = flat_nonzero(first)
        sizes = np.diff(np.append(starts, n))
        multi = sizes > 1
        # Members of the groups of two or more, in group order (indices into the input).
        pos = np.repeat(multi, sizes)
        idx = flat_nonzero(pos)
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
    accepted, support, _ = _select(cand, links, len(left), len(right), iterations,
                                   min_support)
    return accepted, support


def _select(cand: Candidates, links: SupportLinks, n_l: int, n_r: int, iterations: int,
            min_support: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`select_matches` (``n_l``, ``n_r``: the numbers of left and right edges), also
    returning the first round's support (M,) float64 (every candidate alive:
    ``link_support(links, links.weight)``)."""
    m = len(cand)
    accepted = np.zeros(m, bool)
    support = np.zeros(m)
    if m == 0:
        return accepted, support, support
    if kernels.nb_select is not None and len(links):
        return kernels.nb_select(cand.left, cand.right, n_l, n_r, links.cand, links.start,
                                 links.pair_cand, links.weight, max(int(iterations), 1),
                                 float(min_support))
    alive = np.ones(m, bool)
    by_left = _Groups(cand.left, n_l)
    by_right = _Groups(cand.right, n_r)
    taken_r = np.zeros(n_r, bool)
    matched_l = np.zeros(n_l, bool)
    rounds = max(int(iterations), 1)
    first = support
    for it in range(rounds):
        # A supporter is alive when it is an accepted match or neither of its edges is
        # used by one: exactly the candidates still alive here.
        if it == 0:
            support = first = link_support(links, links.weight)
            val: np.ndarray = support
        else:
            support = link_support(links, np.where(alive[links.pair_cand], links.weight, 0.0))
            val = np.where(alive, support, -np.inf)
        win = alive & (support > min_support) & by_left.unique_max(val)
        if win.any():
            win &= by_right.unique_max(val)
        if not (win & ~accepted).any():
            break
        accepted |= win
        if it == rounds - 1:
            break
        k = flat_nonzero(win)
        taken_r[cand.right[k]] = True
        matched_l[cand.left[k]] = True
        alive &= accepted | ~(matched_l[cand.left] | taken_r[cand.right])
    return accepted, support, first


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
    acc, support, first = _select(cand, links, len(left), len(right), iterations,
                                  min_support)
    k = flat_nonzero(acc)
    rival_match, rival_d, rival_ratio = match_rivals(cand, first, k)
    li = cand.left[k]
    rj = cand.right[k]
    m = Matches(u_left=left.u[li].astype(np.float32), u_right=right.u[rj].astype(np.float32),
                v=left.v[li].astype(np.int32), d=cand.d[k].astype(np.float32),
                strength=(0.5 * (left.strength[li] + right.strength[rj])).astype(np.float32),
                string_id=left.string_id[li].astype(np.int32),
                left_index=li.astype(np.int32), right_index=rj.astype(np.int32),
                support=support[k].astype(np.float32), precision=_precision(left, right, li, rj),
                rival_match=rival_match, rival_d=rival_d, rival_ratio=rival_ratio)
    return m, cand, support


def match_rivals(cand: Candidates, support: np.ndarray, k: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rivals of the accepted candidates ``k``: the other candidates of their left or
    of their right edge, with their first-round PMF support ``support`` (every
    candidate alive) over the match's. A rival nearly as well supported as the match
    makes it ambiguous (a uniqueness ratio, as in SGBM's): on a periodic pattern the
    candidates a period apart are supported alike, and the winner may be a period off.

    Args:
        cand: candidates (M).
        support: (M,) float64 first-round support (``link_support`` of all links).
        k: (K,) indices of the accepted candidates.
    Returns:
        (match (R,) int32: the index into ``k`` each rival rivals, ascending;
        d (R,) float32: the rival's disparity, pixels; ratio (R,) float32: its support
        over the match's).
    """
    n = k.shape[0]
    if n == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.float32), np.zeros(0, np.float32)
    own_l, own_r = cand.left[k], cand.right[k]
    lo_l = np.searchsorted(cand.left, own_l, 'left')
    hi_l = np.searchsorted(cand.left, own_l, 'right')
    if kernels.nb_rivals is not None:
        return kernels.nb_rivals(cand.left, cand.right, cand.d, support, k, lo_l, hi_l,
                                 int(cand.right.max()) + 1)
    o_l, c_l = expand_ranges(lo_l, hi_l)
    by_r = np.argsort(cand.right, kind='stable')
    s_r = cand.right[by_r]
    o_r, p_r = expand_ranges(np.searchsorted(s_r, own_r, 'left'),
                             np.searchsorted(s_r, own_r, 'right'))
    owner = np.concatenate((o_l, o_r))
    comp = np.concatenate((c_l, by_r[p_r]))
    keep = comp != k[owner]
    order = np.argsort(owner[keep], kind='stable')
    owner, comp = owner[keep][order], comp[keep][order]
    ratio = support[comp] / np.maximum(support[k[owner]], 1e-12)
    return owner.astype(np.int32), cand.d[comp].astype(np.float32), ratio.astype(np.float32)


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
