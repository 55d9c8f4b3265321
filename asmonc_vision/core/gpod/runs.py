"""Matched runs along edge strings (figural continuity): the links between a string's
matched pixels, their run lengths and smoothing along runs, half-occluded matches,
runs that hang over another depth of their own string or over its continuation on the
lower ground beyond a drop, and the cut of a string where it runs along the ground.
"""
from __future__ import annotations

import numpy as np

from ..edges import EdgeMap, chain_roots
from ..ground_plane import fast_median
from ..matching import Candidates, Matches
from . import kernels as kn
from ..npfast import flat_nonzero

#: ``[True]``, to prefix run-start masks (``np.concatenate``: ``np.r_`` costs ~20 us a call).
_TRUE = np.ones(1, bool)


def run_links(edges: EdgeMap, m: Matches, tolerance_px: float) -> np.ndarray:
    """The previous match in the same matched run of each match.

    A run is a maximal chain of matches on consecutive pixels of one edge string (rows
    v, v+1, ...) whose disparities differ by at most ``tolerance_px`` from one pixel to
    the next.

    Args:
        edges: the left EdgeMap the matches index (for ``string_prev``).
        m: the matches.
        tolerance_px: largest disparity step within a run, pixels.
    Returns:
        (K,) int64 index of the match one row up in the same run, -1 at a run's top.
    """
    k = len(m)
    if k == 0:
        return np.zeros(0, np.int64)
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    prev_edge = edges.string_prev[m.left_index]
    prev = np.where(prev_edge >= 0, feat_of_edge[np.maximum(prev_edge, 0)], -1)
    d = m.d
    link = (prev >= 0) & (np.abs(d - d[np.maximum(prev, 0)]) <= tolerance_px)
    return np.where(link, prev, -1)


def occluded_matches(right: EdgeMap, m: Matches, gradient_limit: float,
                     trusted: np.ndarray | None = None, neighbours: int = 16) -> np.ndarray:
    """Matches hidden in the right image behind a nearer surface (half-occlusion).

    A right edge string is one continuous curve in the right image. When it is matched,
    at nearby rows, to left edges whose disparities differ more than a continuous
    surface allows (disparity gradient ``|dd| / cyclopean distance`` above
    ``gradient_limit``, PMF's limit), the two cannot both be right: the nearer surface
    (larger disparity) is what the right camera sees along that edge, and the farther
    match is a left-image edge whose true partner is hidden behind it (typically the
    ground just left of a post, matched to the post's silhouette in the right image).
    The test is scale-free (a disparity gradient), so it holds at any focal length.
    Only a trusted nearer match (e.g. one in a matched run: figural continuity) hides
    another; an isolated mismatch of large disparity hides nothing.

    Args:
        right: the right EdgeMap the matches index (for ``string_id``).
        m: the matches.
        gradient_limit: largest disparity gradient along one surface.
        trusted: (K,) bool, the matches that may hide others (default all).
        neighbours: matches of the same right string compared on either side (in row
            order).
    Returns:
        (K,) bool, True for a match of the farther surface of such a pair.
    """
    k = len(m)
    occ = np.zeros(k, bool)
    if k < 2:
        return occ
    tr = np.ones(k, bool) if trusted is None else np.asarray(trusted, bool)
    if kn.nb_occluded_all is not None:
        # The same selection, order and pair tests, compiled (one pass).
        return kn.nb_occluded_all(right.string_id, m.right_index, np.ascontiguousarray(tr),
                                m.v, m.d, m.u_left, m.u_right, float(gradient_limit),
                                int(neighbours))
    rs = right.string_id[m.right_index].astype(np.int64)
    if not tr.any():
        return occ
    # only the right strings with a trusted match can hide anything
    has = np.zeros(int(rs.max()) + 1, bool)
    has[rs[tr]] = True
    sub = np.nonzero(has[rs])[0]
    order = sub[np.lexsort((m.v[sub], rs[sub]))]
    n = order.size
    rs_o = rs[order]
    tr_o = tr[order]
    d_o = m.d[order].astype(np.float64)
    u_o = 0.5 * (m.u_left[order].astype(np.float64) + m.u_right[order])
    v_o = m.v[order].astype(np.float64)
    if kn.nb_occluded is not None:
        occ[order[kn.nb_occluded(rs_o, tr_o, d_o, u_o, v_o, float(gradient_limit),
                               min(neighbours, n - 1))]] = True
        return occ
    for s in range(1, min(neighbours, n - 1) + 1):
        same = rs_o[s:] == rs_o[:-s]
        dd = d_o[s:] - d_o[:-s]
        dist = np.hypot(u_o[s:] - u_o[:-s], v_o[s:] - v_o[:-s])
        # the nearer of the pair (larger disparity) must be trusted
        near_ok = np.where(dd > 0, tr_o[s:], tr_o[:-s])
        bad = same & near_ok & (np.abs(dd) > gradient_limit * np.maximum(dist, 1.0))
        if not bad.any():
            continue
        i = np.nonzero(bad)[0]
        far = np.where(dd[i] > 0, i, i + s)       # the smaller disparity of the pair
        occ[order[far]] = True
    return occ


def matched_run_length(edges: EdgeMap, m: Matches, tolerance_px: float,
                       prev: np.ndarray | None = None) -> np.ndarray:
    """Length of the disparity-consistent matched run (see :func:`run_links`) that each
    match belongs to.

    Args:
        edges: the left EdgeMap the matches index (for ``string_prev``).
        m: the matches.
        tolerance_px: largest disparity step within a run, pixels.
        prev: :func:`run_links` of the matches, if already known.
    Returns:
        (K,) int64 run length (>= 1) of each match.
    """
    k = len(m)
    if k == 0:
        return np.zeros(0, np.int64)
    if prev is None:
        prev = run_links(edges, m, tolerance_px)
    root = chain_roots(prev)
    return np.bincount(root, minlength=k)[root]


#: Along an edge string, this many successive matched pixels on the ground (within the
#: threshold) separate its obstacle pixels into pieces, each judged on its own
#: (`string_pieces`).
_GROUND_BREAK_PX = 5


def string_pieces(sid: np.ndarray, v: np.ndarray, ground: np.ndarray,
                  min_break: int = _GROUND_BREAK_PX) -> np.ndarray:
    """Cut edge strings where they run along the ground.

    An edge string can pass from an obstacle onto the ground and on (a post's edge in
    line with a tile joint below it): pixels of it that stand out far below the obstacle,
    beyond a stretch of matched pixels on the ground, belong to something else (often a
    single noisy pixel), not to the obstacle whose string it is. Each string (pixels in
    row order) is cut at every run of at least ``min_break`` successive ``ground`` pixels.

    Args:
        sid: (N,) int edge-string id of each matched pixel.
        v: (N,) int image row of each pixel.
        ground: (N,) bool, the pixel is reliably matched on the ground plane.
        min_break: shortest run of ground pixels that cuts a string.
    Returns:
        (N,) int64 piece index of each pixel (pieces never span two strings).
    """
    n = sid.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort((v, sid))
    s_o, g_o = sid[order], ground[order]
    new_string = np.concatenate((_TRUE, s_o[1:] != s_o[:-1]))
    change = new_string | np.concatenate((_TRUE, g_o[1:] != g_o[:-1]))
    run_id = np.cumsum(change) - 1
    long_ground = g_o & (np.bincount(run_id)[run_id] >= min_break)
    piece_o = np.cumsum(new_string | (long_ground & change)) - 1
    piece = np.empty(n, np.int64)
    piece[order] = piece_o
    return piece


def hanging_runs(edges: EdgeMap, m: Matches, prev: np.ndarray, h: np.ndarray,
                 max_height: float, tolerance_px: float, slope: float,
                 only: np.ndarray | None = None, max_gap: int = 32,
                 solid: np.ndarray | None = None) -> np.ndarray:
    """Matches in runs that hang in the air over another depth: the run's lowest pixel is
    more than ``max_height`` metres above the ground, and the same edge string goes on
    below it (matched pixels within ``max_gap`` rows) but never at the run's disparity
    (within ``tolerance_px`` + ``slope`` px per row of the gap). On a
    repetitive texture a stretch of an edge matched a period off is such a run: a
    wall's vertical streaks 8 m away, matched 43 px off for 12 rows, made an obstacle
    "1.9 m away" out of a string whose other runs stand on the wall's foot. An edge of a
    real obstacle broken by a texture change goes on below at its own depth.

    Args:
        edges: the left EdgeMap the matches index; m: the matches.
        prev: :func:`run_links` of the matches.
        h: (K,) height of each match above the ground plane, metres.
        max_height: metres (``GpodConfig.detection.max_floating_height_m``).
        tolerance_px: largest disparity step within a run, pixels.
        slope: |b| of the plane, pixels of disparity per row.
        only: (K,) bool, or None: only the runs of edge strings with such a match are
            tested (the obstacle pixels: the rest cannot matter).
        max_gap: rows searched below a run's bottom.
        solid: (K,) bool, or None (every match): the matches that can hold a run up. A
            stray match or two at the run's depth below it is as likely a mismatch the
            same period off as the run: only a matched run of its own (figural
            continuity, ``detection.min_matched_run``) holds it up. A wall's streak matched 7 px off
            for 11 rows, 5 m away, was held up by two pixels matched alike 25 rows below.
    Returns:
        (K,) bool.
    """
    k = len(m)
    out = np.zeros(k, bool)
    if k == 0:
        return out
    solid = np.ones(k, bool) if solid is None else np.asarray(solid, bool)
    if kn.nb_hanging_all is not None:
        # The same run bottoms and walk, compiled (one pass).
        return kn.nb_hanging_all(edges.string_prev, m.left_index, m.string_id, m.d,
                               np.asarray(prev, np.int64), np.asarray(h, np.float64),
                               float(max_height), only is not None,
                               np.zeros(k, bool) if only is None else np.asarray(only, bool),
                               int(max_gap), float(tolerance_px), float(slope), solid)
    is_prev = np.zeros(k, bool)
    is_prev[prev[prev >= 0]] = True
    cand = ~is_prev & (h > max_height)                        # floating run bottoms
    if only is not None:
        # ... of edge strings with a match of ``only``.
        sid = m.string_id
        has: np.ndarray = np.zeros(int(sid.max()) + 1 if k else 0, bool)
        has[sid[only]] = True
        cand &= has[sid]
    bottom = flat_nonzero(cand)
    if bottom.size == 0:
        return out
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    below = np.full(len(edges), -1, np.int64)
    has = edges.string_prev >= 0
    below[edges.string_prev[has]] = flat_nonzero(has)
    if kn.nb_hanging is not None:
        return kn.nb_hanging(bottom, m.left_index.astype(np.int64), m.d.astype(np.float64),
                           below, feat_of_edge, prev.astype(np.int64), k, int(max_gap),
                           float(tolerance_px), float(slope), solid)
    d0 = m.d[bottom].astype(np.float64)
    # A run held up only by a run that hangs itself hangs too (two stretches matched
    # the same period off, one above the other, or a chain of them down an edge that
    # alternates between two matches): repeat until nothing changes. Each pass can only
    # add runs, so at most one pass per run bottom (and one to see no change).
    for _ in range(bottom.size + 1):
        e = m.left_index[bottom].astype(np.int64)
        seen = np.zeros(bottom.size, bool)      # a matched pixel below
        held = np.zeros(bottom.size, bool)      # ... at the run's depth, not hanging
        for r in range(1, max_gap + 1):
            live = ~held & (e >= 0)
            if not live.any():
                break
            e = np.where(live, below[np.maximum(e, 0)], -1)
            f = np.where(e >= 0, feat_of_edge[np.maximum(e, 0)], -1)
            hit = f >= 0
            seen |= hit
            fh = f[hit]
            held[hit] |= ((np.abs(m.d[fh] - d0[hit]) <= tolerance_px + slope * r)
                          & solid[fh] & ~out[fh])
        hang = seen & ~held
        new = np.zeros(k, bool)
        cur = bottom[hang]                      # whole runs, from the bottom up
        while cur.size:
            new[cur] = True
            cur = prev[cur]
            cur = cur[cur >= 0]
        if np.array_equal(new, out):
            break
        out = new
    return out


def _robust_row_slope(u: np.ndarray, v: np.ndarray, d: np.ndarray) -> float:
    """The slope b of ``d = a u + b v + c`` (pixels of disparity per image row) fitted to
    features (u, v, d: (N,) pixels, N >= 3) by least squares trimmed twice to the
    residuals within 2.5 robust sigmas (at least 0.5 px): the mismatches among a
    frame's features (any disparity, anywhere) flatten a plain least-squares slope."""
    a = np.column_stack((u, v, np.ones_like(u)))
    coef = np.linalg.lstsq(a, d, rcond=None)[0]
    for _ in range(2):
        r = d - a @ coef
        dev = np.abs(r - fast_median(r))
        keep = dev <= max(2.5 * 1.4826 * fast_median(dev), 0.5)
        if keep.sum() < 3:
            break
        coef = np.linalg.lstsq(a[keep], d[keep], rcond=None)[0]
    return float(coef[1])


def _matches_below(e: np.ndarray, below: np.ndarray, feat_of_edge: np.ndarray,
                   max_gap: int) -> np.ndarray:
    """(R, N) int64: the matches (-1: none) of the edge pixels 1..R rows below the edge
    pixels ``e`` along their strings (``below``: each edge pixel's next one down), R at
    most ``max_gap`` (fewer where every string has ended)."""
    under = np.full((max_gap, e.shape[0]), -1, np.int64)
    for r in range(max_gap):
        e = np.where(e >= 0, below[np.maximum(e, 0)], -1)
        if not (e >= 0).any():
            under = under[:r]
            break
        under[r] = np.where(e >= 0, feat_of_edge[np.maximum(e, 0)], -1)
    return under


def _continuations(edges: EdgeMap, m: Matches, prev: np.ndarray, bottoms: np.ndarray,
                   under: np.ndarray, lower: np.ndarray, feat_of_edge: np.ndarray,
                   max_gap: int) -> np.ndarray:
    """(N,) int64: the continuation of each run bottom of `continuation_alternatives`
    on lower ground (-1: none): its string's first ``lower`` match in ``under``, else
    the nearest ``lower`` match within ``max_gap`` rows above its run."""
    is_low = (under >= 0) & lower[np.maximum(under, 0)]
    ok = is_low.any(axis=0)
    found = np.full(bottoms.size, -1, np.int64)
    if ok.any():
        found[ok] = under[np.argmax(is_low[:, ok], axis=0), flat_nonzero(ok)]
    if not ok.all():
        top = chain_roots(prev)                 # each run's top
        miss = flat_nonzero(~ok)
        e = m.left_index[top[bottoms[miss]]].astype(np.int64)
        for _ in range(max_gap):
            live = (found[miss] < 0) & (e >= 0)
            if not live.any():
                break
            e = np.where(live, edges.string_prev[np.maximum(e, 0)], -1)
            f = np.where(e >= 0, feat_of_edge[np.maximum(e, 0)], -1)
            hit = (f >= 0) & lower[np.maximum(f, 0)]
            found[miss[hit]] = f[hit]
    return found


def continuation_alternatives(edges: EdgeMap, m: Matches, prev: np.ndarray,
                              cand: Candidates, select: np.ndarray, lower: np.ndarray,
                              plane_d: np.ndarray, tolerance_px: float, slope: float,
                              min_support: int, max_gap: int = 32) -> np.ndarray:
    """Matches of ``select`` in runs that hang over nothing at their depth, whose own
    edge string goes on on lower ground (a match of ``lower``: below the run, or above it
    where the run ends the string), and whose left edge also had a candidate match on
    that lower ground.

    An obstacle stands on the ground: below the foot of its edge the image shows nearer
    ground, never a lower ground farther away on the same edge line. A run of a string
    seen in front of its own continuation on the lower ground beyond a drop, that could
    equally have been matched on that lower ground, is a stretch of a repetitive pattern
    matched one period off: the paving joints beyond a kerb down, matched one joint
    spacing off for 10 rows, 43-54 px above the plane (an obstacle "0.9 m" away). The
    ambiguity test's ground-plane alternative cannot see it: the true depth is below the
    plane.

    Args:
        edges: the left EdgeMap the matches index; m: the matches; cand: the frame's
            candidate matches (of the same left EdgeMap).
        prev: :func:`run_links` of the matches.
        select: (K,) bool: the matches tested (the rest are False).
        lower: (K,) bool: matches on lower ground (below the plane by more than the
            threshold, within the deepest drop looked for).
        plane_d: (K,) float: the plane's disparity at each match, pixels.
        tolerance_px: largest disparity step within a run, pixels.
        slope: |b| of the plane, pixels of disparity per row.
        min_support: the lower ground must be seen: at least this many ``lower``
            matches lie on it (within ``tolerance_px``). Beyond a kerb down they are
            15-70 % of a frame's matches; scattered mismatches of obstacles' textures
            that look like a ground 0.7-1.2 m down, at most 1.4 % (`rules.LOWER_GROUND_FRACTION`).
        max_gap: rows searched below a run's bottom.
    Returns:
        (K,) bool. The run must hang: no matched pixel of its string within ``max_gap``
        rows below its bottom is at its depth (within ``tolerance_px + slope * r``, r
        rows down; an edge of a real obstacle broken by a mismatch goes on below at its
        own depth). The continuation is the string's first ``lower`` match there, or,
        where it has none there, its nearest ``lower`` match within ``max_gap`` rows
        above the run (a run that ends its string at a kerb's brink). The lower ground
        is taken parallel to the plane (its disparity a fixed fraction,
        the continuation's d / plane_d, of the plane's), and a match of the run has the
        alternative when one of its candidates lies within ``tolerance_px`` of that
        ground's disparity at it.
    """
    k = len(m)
    out = np.zeros(k, bool)
    sel = flat_nonzero(select)
    if sel.size == 0 or len(cand) == 0 or np.count_nonzero(lower) < min_support:
        return out
    bottoms, b_of = _run_bottoms(prev, sel)
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    below = np.full(len(edges), -1, np.int64)
    has_e = edges.string_prev >= 0
    below[edges.string_prev[has_e]] = flat_nonzero(has_e)
    # The matched pixels of each bottom's string in the max_gap rows below it.
    under = _matches_below(m.left_index[bottoms].astype(np.int64), below, feat_of_edge,
                           max_gap)
    d = m.d.astype(np.float64)
    pd = np.asarray(plane_d, np.float64)
    # The continuation: the first lower match below. (It is farther than the bottom
    # wherever the run hangs: a lower match nearer than the bottom is within the slope
    # allowance of its depth, below, and holds the run up.) Where the string has none
    # below (the run ends it, at a kerb's brink), the nearest lower match above the run.
    found = _continuations(edges, m, prev, bottoms, under, lower, feat_of_edge, max_gap)
    ratio, ok = _lower_ground(found, d, pd, lower, tolerance_px, min_support)
    if not ok.any():
        return out
    # Which matches of such runs had a candidate on that lower ground.
    mine = sel[ok[b_of]]
    has_alt = _candidates_at(edges, m, cand, mine, ratio[b_of[ok[b_of]]] * pd[mine],
                             tolerance_px)
    return _hanging_with_alternative(under, d, d[bottoms], sel, b_of, has_alt,
                                     tolerance_px, slope)


def _run_bottoms(prev: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bottom match of the run of each match in ``sel``.

    Args:
        prev: (K,) int64 :func:`run_links` of the matches.
        sel: (S,) int64 indices of matches.
    Returns:
        bottoms: (B,) int64 the distinct bottoms (last match down the run), sorted;
        b_of: (S,) int64 the index into ``bottoms`` of each match of ``sel``.
    """
    nxt = np.full(prev.shape[0], -1, np.int64)
    has = prev >= 0
    nxt[prev[has]] = flat_nonzero(has)
    jump = chain_roots(nxt)
    bottoms, b_of = np.unique(jump[sel], return_inverse=True)
    return bottoms, b_of


def _lower_ground(found: np.ndarray, d: np.ndarray, pd: np.ndarray, lower: np.ndarray,
                  tolerance_px: float, min_support: int) -> tuple[np.ndarray, np.ndarray]:
    """The lower ground of each continuation of `continuation_alternatives`, taken
    parallel to the plane: its disparity the continuation's fraction d / plane_d of the
    plane's. It must itself be seen: ``min_support`` ``lower`` matches on it (within
    ``tolerance_px``).

    Args:
        found: (B,) int64 the continuation match of each run bottom (-1: none).
        d: (K,) float64 the matches' disparities, pixels.
        pd: (K,) float64 the plane's disparity at each match, pixels.
        lower: (K,) bool matches on lower ground.
        tolerance_px: pixels of disparity.
        min_support: matches.
    Returns:
        ratio: (B,) float64 the fraction d / plane_d (NaN where there is no usable
        continuation); ok: (B,) bool, a lower ground that is seen.
    """
    ok = found >= 0
    ok[ok] = pd[found[ok]] > 0
    ratio = np.full(found.shape[0], np.nan)
    q = flat_nonzero(ok)
    ratio[q] = d[found[q]] / pd[found[q]]
    lo = flat_nonzero(lower)
    n_on = (np.abs(d[lo][None, :] - ratio[q, None] * pd[lo][None, :])
            <= tolerance_px).sum(axis=1)
    ok[q] = n_on >= min_support
    return ratio, ok


def _candidates_at(edges: EdgeMap, m: Matches, cand: Candidates, mine: np.ndarray,
                   target_d: np.ndarray, tolerance_px: float) -> np.ndarray:
    """Which matches ``mine`` had a candidate match (of their left edge pixel) within
    ``tolerance_px`` of a disparity ``target_d``.

    Args:
        edges: the left EdgeMap the matches and the candidates index.
        m: the matches; cand: the frame's candidate matches.
        mine: (M,) int64 indices of matches.
        target_d: (M,) float64 disparity looked for at each, pixels.
        tolerance_px: pixels.
    Returns:
        (K,) bool, False outside ``mine``.
    """
    n_edges = len(edges)
    t_d = np.full(n_edges, np.nan)
    le = m.left_index[mine]
    t_d[le] = target_d
    cl = cand.left
    with np.errstate(invalid='ignore'):
        alt = np.abs(cand.d - t_d[cl]) <= tolerance_px
    hit_edge = np.zeros(n_edges, bool)
    hit_edge[cl[alt]] = True
    has_alt = np.zeros(len(m), bool)
    has_alt[mine] = hit_edge[le]
    return has_alt


def _hanging_with_alternative(under: np.ndarray, d: np.ndarray, d0: np.ndarray,
                              sel: np.ndarray, b_of: np.ndarray, has_alt: np.ndarray,
                              tolerance_px: float, slope: float) -> np.ndarray:
    """The matches of ``sel`` with the alternative (``has_alt``) whose run hangs: no
    matched pixel below its bottom is at the bottom's depth (within ``tolerance_px +
    slope * r``, r rows down), other than such matches themselves (two stretches matched
    the same period off, one above the other).

    Args:
        under: (R, B) int64 :func:`_matches_below` of the run bottoms.
        d: (K,) float64 the matches' disparities, pixels; d0: (B,) float64 the bottoms'.
        sel: (S,) int64 the matches tested; b_of: (S,) int64 the bottom of each.
        has_alt: (K,) bool.
        tolerance_px: pixels; slope: |b| of the plane, pixels of disparity per row.
    Returns:
        (K,) bool.
    """
    out = np.zeros(has_alt.shape[0], bool)
    rows = np.arange(1, under.shape[0] + 1, dtype=np.float64)[:, None]
    near = (under >= 0) & (np.abs(d[np.maximum(under, 0)] - d0[None, :])
                           <= tolerance_px + slope * rows)
    for _ in range(under.shape[1] + 1):     # until nothing changes (runs only join)
        held = (near & ~out[np.maximum(under, 0)]).any(axis=0)
        new = np.zeros(has_alt.shape[0], bool)
        new[sel] = has_alt[sel] & ~held[b_of]
        if np.array_equal(new, out):
            break
        out = new
    return out


def smooth_along_runs(x: np.ndarray, prev: np.ndarray, window: int) -> np.ndarray:
    """Mean of x over a window of up to ``window`` consecutive pixels of each pixel's
    matched run, centred on it (shortened at the run's ends).

    Args:
        x: (K,) values per match.
        prev: (K,) :func:`run_links` of the matches.
        window: pixels (odd; 1 = no smoothing).
    Returns:
        (K,) float64.
    """
    x = np.asarray(x, np.float64)
    k = x.shape[0]
    half = max(int(window), 1) // 2
    if half == 0 or k == 0:
        return x.copy()
    nxt = np.full(k, -1, np.int64)
    has = prev >= 0
    nxt[prev[has]] = flat_nonzero(has)
    total, count = x.copy(), np.ones(k)
    for step in (prev, nxt):
        cur: np.ndarray = np.arange(k)
        for _ in range(half):
            ok = cur >= 0
            cur = np.where(ok, step[np.maximum(cur, 0)], -1)
            ok = cur >= 0
            total += np.where(ok, x[np.maximum(cur, 0)], 0.0)
            count += ok
    return total / count

