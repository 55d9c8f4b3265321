"""PMF support (step 2): the links between mutually supporting candidates, and the
support they give."""
from __future__ import annotations

import cv2
import numpy as np

from asmonc_vision.core.edges import EdgeMap
from asmonc_vision.core.matching import kernels
from asmonc_vision.core.matching.types import Candidates, SupportLinks
from ..npfast import flat_nonzero


_SLACK = 1.0 + 1e-4


def _empty_links(m: int) -> SupportLinks:
    zi = np.zeros(0, np.int64)
    return SupportLinks(num_candidates=m, cand=zi, start=zi, pair_link=zi, pair_cand=zi,
                        pair_edge=zi, pair_right=zi, weight=np.zeros(0))


def _argsort(keys: np.ndarray) -> np.ndarray:
    """``np.argsort(keys)`` of a 1-D float64 array: its permutation, found by the stable
    sort when the keys are distinct (then every sort gives it; a frame's candidates,
    nearly in order, sort several times faster so), else (ties, NaN) by np.argsort."""
    order = np.argsort(keys, kind='stable')
    s = keys[order]
    if s.size and (np.isnan(s[-1]) or bool((s[1:] == s[:-1]).any())):
        return np.argsort(keys)
    return order


def _cell_table(s_cell: np.ndarray, size: int) -> np.ndarray:
    """(size + 1,) int: ``table[k]`` = number of the sorted cells ``s_cell`` below k."""
    m = s_cell.shape[0]
    if kernels.nb_cells is not None and m < 2 ** 31:
        return kernels.nb_cells(s_cell, size)
    first = np.ones(m, bool)
    first[1:] = s_cell[1:] != s_cell[:-1]
    at = flat_nonzero(first)
    count = np.diff(np.append(at, m))
    if m < 2 ** 31 and (count.size == 0 or int(count.max()) <= 255):
        # A one-row integral image is a fast prefix sum (numpy's cumsum is not).
        hist = np.zeros((1, size), np.uint8)
        hist[0, s_cell[at]] = count
        return cv2.integral(hist)[1]
    table = np.zeros(size + 1, np.int64)
    np.cumsum(np.bincount(s_cell, minlength=size), out=table[1:])
    return table


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
    col = np.floor(uc).astype(np.int64).clip(0, w - 1)
    order = _argsort(np.asarray((vc * w + col) * 2.0 + (uc - col)))
    s_uc64 = uc[order]
    s_d64 = cand.d[order].astype(np.float64)
    s_v = vc[order]
    # Support is symmetric: pairs are found once (rows below, or to the right on the
    # same row) and used both ways. All row offsets at once: window (dv, i) is the
    # range [lo, hi) of positions in row s_v[i] + dv within sqrt(rad^2 - dv^2) columns
    # (a hair more) of s_uc[i], from a table with r_int empty rows below the image.
    table = _cell_table(s_v * w + col[order], (h + r_int) * w)
    nd = r_int + 1
    dvs = np.arange(nd)
    half = (np.sqrt(np.maximum(rad * rad - dvs * dvs, 0.0)) + 1e-6)[:, None]
    if kernels.nb_pairs is not None:
        i, j, s2 = kernels.nb_pairs(table, half[:, 0], w, s_uc64, s_d64, s_v, rad * rad,
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
    s_d = s_d64.astype(np.float32)
    dd = s_d[j]
    dd -= np.repeat(np.tile(s_d, nd), cnt)
    keep = flat_nonzero(np.abs(dd, out=dd) <= np.float32(lim * rad * _SLACK))
    del dd
    j = j[keep]
    i = np.repeat(np.tile(pos.astype(np.int32), nd), cnt)[keep].astype(np.intp)
    del keep
    # Exact tests in double precision on the few that are left.
    dcu = s_uc64[j] - s_uc64[i]
    dv = (s_v[j] - s_v[i]).astype(np.float64)
    s2 = dcu * dcu + dv * dv
    dd = s_d64[j] - s_d64[i]
    keep = flat_nonzero((s2 <= rad * rad) & (dd * dd <= (lim * lim) * s2) & (s2 > 0.0))
    return order[i[keep]], order[j[keep]], s2[keep]


def _group_links(cand: Candidates, n_left: int, a: np.ndarray, b: np.ndarray,
                 s2: np.ndarray, tol: float) -> SupportLinks:
    """The SupportLinks of the mutually supporting candidate pairs (a, b) at squared
    separations s2 (``tol``: lim * rad, with slack)."""
    m = len(cand)
    if kernels.nb_group is not None:
        d_prev, d_next, monotonic = (_sibling_disparities(cand) if kernels.nb_siblings is None
                                     else kernels.nb_siblings(cand.left, cand.d))
        c, start, c2, sep2, n1 = kernels.nb_group(a, b, s2, cand.d, d_prev, d_next, monotonic,
                                           float(tol), cand.left, n_left)
        if kernels.nb_link_rows is not None:
            pair_link, pair_edge, pair_right = kernels.nb_link_rows(start, c2.size, c2, cand.left,
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
    grp = flat_nonzero(multi)
    if grp.size:
        one = flat_nonzero(~multi)
        n1 = one.size
        e2 = cand.left[c2[grp]]
        grp = grp[_lexsort_small(e2, c[grp], n_left, m)]
        sel = np.concatenate((one, grp))
        c, c2, sep2 = c[sel], c2[sel], sep2[sel]
        cg, e2 = c[n1:], cand.left[c2[n1:]]
        first = np.ones(cg.size, bool)
        first[1:] = (cg[1:] != cg[:-1]) | (e2[1:] != e2[:-1])
        start = np.concatenate((start[:n1], n1 + flat_nonzero(first)))
        pair_link = np.concatenate((pair_link[:n1], n1 + np.cumsum(first) - 1))
    np.sqrt(sep2, out=sep2)
    return SupportLinks(num_candidates=m, cand=c[start], start=start, pair_link=pair_link,
                        pair_cand=c2, pair_edge=cand.left[c2], pair_right=cand.right[c2],
                        weight=np.divide(1.0, sep2, out=sep2), num_single=n1)


def _lexsort_small(minor: np.ndarray, major: np.ndarray, n_minor: int,
                   n_major: int) -> np.ndarray:
    """Permutation sorting by (major, minor), both non-negative ints below n_major,
    n_minor; two stable radix sorts when they fit in 16 bits."""
    if n_minor < 65536 and n_major < 65536:
        p = np.argsort(minor.astype(np.uint16), kind='stable')
        return p[np.argsort(major[p].astype(np.uint16), kind='stable')]
    return np.lexsort((minor, major))


def link_support(links: SupportLinks, w: np.ndarray) -> np.ndarray:
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
    return link_support(links, w)
