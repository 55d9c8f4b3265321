"""The nearest point of an obstacle from its feet: the soft nearest point of a frontal
face, the hidden near corner of a rectangular footprint (Thales circle, free ground,
contact edges), per obstacle (`nearest_points`).
"""
from __future__ import annotations

import math

import numpy as np

from . import kernels_geometry as kg
from .kernels_geometry import (
    _ARC_LIN,
    _BODY_GAP_BAND_M,
    _BODY_GAP_END_M,
    _BODY_GAP_SPAN_M,
    _CORNER_SIGMAS,
    _FACE_BEHIND_MIN,
    _FREE_SPACE_MARGIN_M,
)
from ..npfast import flat_nonzero


def soft_nearest(xy: np.ndarray, sr: np.ndarray, ground_xy=None) -> np.ndarray:
    """The expected nearest of points with uncertain ranges: their mean weighted by
    ``exp(-dr^2 / 2(s_i^2 + s_0^2))``, dr the range beyond the nearest point's (whose
    sigma is s_0). Points as near as the nearest to within their noise share the weight
    (a frontal face: its middle), clearly farther ones do not count.

    Args:
        xy: (S, 2) ground coordinates of the feet, metres; sr: (S,) their range sigmas.
        ground_xy: (G, 2) visible ground, or a callable returning it, or None. Given,
            a foot that visible ground separates from the nearest one (`_body_gap`: two
            obstacles side by side, not one face) does not share the weight.
    Returns:
        (2,) ground coordinates, metres.
    """
    r = np.hypot(xy[:, 0], xy[:, 1])
    j = int(np.argmin(r))
    w = np.exp(-0.5 * (r - r[j]) ** 2 / np.maximum(sr ** 2 + sr[j] ** 2, 1e-12))
    if ground_xy is not None:
        far = flat_nonzero((w > 0.01) & (np.hypot(*(xy - xy[j]).T) > _BODY_GAP_SPAN_M))
        if far.size:
            g = ground_xy() if callable(ground_xy) else ground_xy
            for i in far.tolist():
                if _body_gap(g, xy[j], xy[i]):
                    w[i] = 0.0
    return (w[:, None] * xy).sum(axis=0) / w.sum()


def _body_gap(ground: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether visible ground (G, 2) separates the feet a and b ((2,), metres, ground
    coordinates from the camera): at least ``_FACE_BEHIND_MIN`` features in the strip
    ``_BODY_GAP_BAND_M`` behind the segment a-b (away from the camera), more than
    ``_BODY_GAP_END_M`` from its ends along it."""
    e = b - a
    length = float(np.hypot(*e))
    if ground.shape[0] == 0 or length <= 2.0 * _BODY_GAP_END_M:
        return False
    t = e / length
    nrm = np.array([-t[1], t[0]])
    if nrm @ (0.5 * (a + b)) < 0.0:         # pointing away from the camera
        nrm = -nrm
    rel = ground - a
    along, behind = rel @ t, rel @ nrm
    lo, hi = _BODY_GAP_BAND_M
    inside = ((along > _BODY_GAP_END_M) & (along < length - _BODY_GAP_END_M)
              & (behind > lo) & (behind < hi))
    return int(np.count_nonzero(inside)) >= _FACE_BEHIND_MIN


def _soft_nearest_groups(xy: np.ndarray, sr: np.ndarray, group: np.ndarray, n_groups: int,
                         want: np.ndarray, ground_xy=None) -> np.ndarray:
    """`soft_nearest` of the feet of each group ``want`` at once.

    Args:
        xy: (S, 2) ground coordinates of the feet, metres; sr: (S,) their range sigmas.
        group: (S,) int64 group of each foot, 0..n_groups-1.
        want: (n_groups,) bool, the groups to compute (each with at least one foot).
        ground_xy: as `soft_nearest`'s (an array, a callable returning one, or None).
    Returns:
        (n_groups, 2) float64, NaN for the groups not wanted.
    """
    out = np.full((n_groups, 2), np.nan)
    if not want.any():
        return out
    if kg.nb_soft_args is None:
        order = np.argsort(group, kind='stable')
        first = np.searchsorted(group[order], np.arange(n_groups), side='left')
        last = np.searchsorted(group[order], np.arange(n_groups), side='right')
        for k in flat_nonzero(want).tolist():
            sel = order[first[k]:last[k]]
            out[k] = soft_nearest(xy[sel], sr[sel], ground_xy)
        return out
    xy = np.ascontiguousarray(xy, np.float64)
    idx, start, near, arg = kg.nb_soft_args(xy, np.ascontiguousarray(sr, np.float64),
                                          np.asarray(group, np.int64), want, n_groups, 2.0)
    w = np.exp(arg)                  # numpy's exp (the compiled one differs in last bits)
    if ground_xy is None:
        far = np.zeros(idx.shape[0], bool)
        g: np.ndarray = np.zeros((0, 2))
    else:
        far = kg.nb_soft_far(xy, idx, start, near, w)
        g = np.zeros((0, 2))
        if far.any():
            g = ground_xy() if callable(ground_xy) else ground_xy
            g = np.ascontiguousarray(g, np.float64)
    q, undecided = kg.nb_soft_finish(xy, idx, start, near, w, far, g)
    out[want] = q[want]
    for k in flat_nonzero(undecided).tolist():     # left to numpy
        sel = idx[start[k]:start[k + 1]]
        out[k] = soft_nearest(xy[sel], sr[sel], g)
    return out


def _ground_inside(g: np.ndarray, a: np.ndarray, n: np.ndarray, b: np.ndarray,
                   margin: float, job: np.ndarray | None = None) -> np.ndarray:
    """(T, M) bool: whether any of the ground points g (P, 2) of search ``job[p]`` lies
    inside the triangle a[t]-n[t, k]-b[t] by more than ``margin`` from each side (never
    for a degenerate triangle); a, b (T, 2), n (T, M, 2), job (P,) (None: all points
    belong to every search)."""
    t_n, m = n.shape[:2]
    out = np.zeros((t_n, m), bool)
    if g.shape[0] == 0:
        return out
    if job is None:
        job = np.repeat(np.arange(t_n), g.shape[0])
        g = np.tile(g, (t_n, 1))
    gx, gy = g[:, None, 0], g[:, None, 1]

    def side(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """(P, M) signed distance of each point from the line p0 -> p1 of its search
        (left positive); p0, p1 (T, M, 2)."""
        e = p1 - p0
        length = np.maximum(np.hypot(e[..., 0], e[..., 1]), 1e-12)[job]
        ex, ey = e[job, :, 0], e[job, :, 1]
        return (ex * (gy - p0[job, :, 1]) - ey * (gx - p0[job, :, 0])) / length

    aa = np.broadcast_to(a[:, None, :], n.shape)
    bb = np.broadcast_to(b[:, None, :], n.shape)
    area2 = ((n[..., 0] - a[:, None, 0]) * (b[:, None, 1] - a[:, None, 1])
             - (n[..., 1] - a[:, None, 1]) * (b[:, None, 0] - a[:, None, 0]))
    sgn = np.where(area2 > 0, 1.0, -1.0)[job]
    inside = ((sgn * side(aa, n) > margin) & (sgn * side(n, bb) > margin)
              & (sgn * side(bb, aa) > margin))
    np.logical_or.at(out, job, inside)
    return out & (np.abs(area2) > 1e-12)


def hidden_corners(a: np.ndarray, b: np.ndarray, sigma: np.ndarray, ground_xy,
                   score) -> np.ndarray:
    """`hidden_corner` of several pairs of silhouette feet at once.

    Args:
        a, b: (T, 2) ground coordinates of the silhouette feet of each search.
        sigma: (T,) their range sigmas, metres.
        ground_xy: (G, 2) visible ground, or a callable returning it (only called when
            a search gets that far).
        score: ``score(a (T', 2), n (T', M, 2), b (T', 2), ok (T', M)) -> (T', M)``, the
            contact-edge score of the candidates ``ok`` (others -inf)
            (`_FrameContext.contact_edge_scores`).
    Returns:
        (T, 2) the hidden corner of each search, NaN where there is none.
    """
    t_n = a.shape[0]
    out = np.full((t_n, 2), np.nan)
    if kg.nb_arcs is not None:
        # The same circles and arcs, compiled (one pass over the searches).
        ok_t, c_all, rho_all, a0_all, span_all = kg.nb_arcs(
            np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64),
            np.ascontiguousarray(sigma, np.float64))
        jobs = flat_nonzero(ok_t)
        if not jobs.size:
            return out
        cj, rj, a0j, spanj = c_all[jobs], rho_all[jobs], a0_all[jobs], span_all[jobs]
    else:
        job_list: list[int] = []
        cs, rhos, a0s, spans = [], [], [], []
        for t in range(t_n):
            at, bt = a[t], b[t]
            c = 0.5 * (at + bt)
            rho = 0.5 * float(np.hypot(*(bt - at)))
            cn = float(np.hypot(*c))
            if rho <= _CORNER_SIGMAS * sigma[t] or cn <= rho:   # no corner could bulge enough
                continue
            a0 = math.atan2(at[1] - c[1], at[0] - c[0])
            span = (math.atan2(bt[1] - c[1], bt[0] - c[0]) - a0) % (2 * math.pi)  # a -> b, ccw
            if (math.atan2(-c[1], -c[0]) - a0) % (2 * math.pi) > span:   # the near half is cw
                span -= 2 * math.pi
            job_list.append(t)
            cs.append(c)
            rhos.append(rho)
            a0s.append(a0)
            spans.append(span)
        if not job_list:
            return out
        jobs = np.array(job_list)
        cj, rj, a0j, spanj = np.array(cs), np.array(rhos), np.array(a0s), np.array(spans)
    aj, bj = a[jobs], b[jobs]
    ang = a0j[:, None] + _ARC_LIN * spanj[:, None]
    n = cj[:, None, :] + rj[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], axis=2)
    margin = _FREE_SPACE_MARGIN_M
    g = ground_xy() if callable(ground_xy) else ground_xy
    if g.size and kg.nb_corner_free is not None:      # the same tests, compiled
        ok = kg.nb_corner_free(np.ascontiguousarray(g, np.float64), aj, bj, cj, rj, n, margin)
    elif g.size:
        # Only ground inside a search's circle (its triangles are inscribed) and off its
        # chord by more than the margin can be inside one of its triangles (a cheap test
        # of every ground point, the exact one of the few left).
        # Ground within the bounding box of all the circles first (one cheap pass).
        lo = (cj - rj[:, None]).min(axis=0) - margin
        hi = (cj + rj[:, None]).max(axis=0) + margin
        g = g[(g[:, 0] >= lo[0]) & (g[:, 0] <= hi[0]) & (g[:, 1] >= lo[1]) & (g[:, 1] <= hi[1])]
        ex, ey = (aj - bj)[:, 0:1], (aj - bj)[:, 1:2]
        chord = np.maximum(np.hypot(ex, ey), 1e-12)
        off = np.abs(ex * (g[None, :, 1] - bj[:, 1:2]) - ey * (g[None, :, 0] - bj[:, 0:1]))
        dx, dy = g[None, :, 0] - cj[:, 0:1], g[None, :, 1] - cj[:, 1:2]
        near = ((off > (margin * 0.999) * chord)
                & (dx * dx + dy * dy < (rj[:, None] * 1.001) ** 2))
        job, gi = np.nonzero(near)
        ok = ~_ground_inside(g[gi], aj, n, bj, margin, job)
    else:
        ok = np.ones(n.shape[:2], bool)
    live = ok.any(axis=1)
    if not live.any():
        return out
    jobs, aj, bj, n, ok = jobs[live], aj[live], bj[live], n[live], ok[live]
    best = np.argmax(score(aj, n, bj, ok), axis=1)
    q = n[np.arange(jobs.size), best]
    e = bj - aj
    rho = rj[live]
    bulge = np.abs(e[:, 0] * (q[:, 1] - aj[:, 1]) - e[:, 1] * (q[:, 0] - aj[:, 0])) / (2.0 * rho)
    keep = bulge > _CORNER_SIGMAS * sigma[jobs]
    out[jobs[keep]] = q[keep]
    return out


def _single_score(score):
    """A batched score (`hidden_corners`) from a single one ``score(a, n, b) -> (M,)``."""
    def batched(a, n, b, ok):
        out = np.full(ok.shape, -np.inf)
        for t in range(ok.shape[0]):
            out[t, ok[t]] = score(a[t], n[t][ok[t]], b[t])
        return out
    return batched


def hidden_corner(a: np.ndarray, b: np.ndarray, sigma: float, ground_xy: np.ndarray,
                  score) -> np.ndarray | None:
    """The near corner hidden between the silhouette feet a and b (ground, (2,) each).

    If a and b are corners of a rectangular footprint whose corner n between them has no
    vertical edge, the angle a-n-b is right: n lies on the near half of the circle with
    diameter ab (Thales). Of ``_CORNER_ARC_POINTS`` candidates on that arc, those whose
    triangle a-n-b holds visible ground (a ground feature more than
    ``_FREE_SPACE_MARGIN_M`` inside: free space seen through it) are impossible; of the
    others the one whose contact polyline a-n-b the image's edges follow best
    (``score(a, n, b) -> (M,)``) is taken. None when the camera's foot is inside the
    circle, no candidate is possible, or the best one lies within ``_CORNER_SIGMAS``
    ``sigma`` (the feet's range sigma) of the chord ab: the straight face ab explains the
    image as well (a frontal face, no hidden corner). See `hidden_corners` (batched).
    """
    q = hidden_corners(np.asarray(a, np.float64)[None], np.asarray(b, np.float64)[None],
                       np.array([float(sigma)]), ground_xy, _single_score(score))[0]
    return None if np.isnan(q[0]) else q


def nearest_points(xy: np.ndarray, sr: np.ndarray, group: np.ndarray, n_groups: int,
                   ground_xy, score=None, at_border: np.ndarray | None = None
                   ) -> np.ndarray:
    """`nearest_point` of the feet of several obstacles at once (their hidden-corner
    searches batched, `hidden_corners`).

    Args:
        xy: (S, 2) ground coordinates of the feet, sr (S,) their range sigmas.
        group: (S,) obstacle of each foot, 0..n_groups-1.
        ground_xy: (G, 2) visible ground, or a callable returning it (called only when a
            search or `soft_nearest` needs it).
        score: batched contact-edge score (`hidden_corners`), or None (no search).
        at_border: (S,) bool, feet of strings at the image's left or right border.
    Returns:
        (n_groups, 2) ground coordinates of each obstacle's nearest point (NaN without
        feet).
    """
    out = np.full((n_groups, 2), np.nan)
    if xy.shape[0] == 0:
        return out
    if kg.nb_extremes is not None and kg.nb_soft_args is not None:
        return _nearest_points_compiled(xy, sr, group, n_groups, ground_xy, score,
                                        at_border)
    order = np.argsort(group, kind='stable')
    g_s = group[order]
    first = np.searchsorted(g_s, np.arange(n_groups), side='left')
    last = np.searchsorted(g_s, np.arange(n_groups), side='right')
    brg_all = np.arctan2(xy[:, 1], xy[:, 0])
    r_all = np.hypot(xy[:, 0], xy[:, 1])
    search, pair, soft = [], [], []

    for k in range(n_groups):
        sel = order[first[k]:last[k]]
        if sel.size == 0:
            continue
        if sel.size == 1:
            out[k] = xy[sel[0]]
            continue
        brg, r, s = brg_all[sel], r_all[sel], sr[sel]
        i, j = int(np.argmax(brg)), int(np.argmin(brg))
        kk = int(np.argmin(r))
        # A foot between the outermost ones and clearly nearer than both is the near
        # corner (a foot on a frontal face, e.g. of a texture stripe, is not clearly nearer).
        seen = kk not in (i, j) and (min(r[i], r[j]) - r[kk]
                                     > _CORNER_SIGMAS * math.hypot(s[kk], max(s[i], s[j])))
        border = at_border is not None and bool(at_border[sel[i]] or at_border[sel[j]])
        if score is not None and not seen and not border and i != j:
            search.append(k)
            pair.append((sel[i], sel[j], float(max(s[i], s[j]))))
        else:
            soft.append(k)
    if search:
        ii, jj, sg = (np.array(x) for x in zip(*pair))
        q = hidden_corners(xy[ii], xy[jj], sg, ground_xy, score)
        for k, qk in zip(search, q):
            if np.isnan(qk[0]):
                soft.append(k)
                continue
            # A corner beyond the nearest foot is not the nearest point (two bodies
            # in one cluster: the corner of the far one, the near one's foot nearer).
            sel = order[first[k]:last[k]]
            qs = soft_nearest(xy[sel], sr[sel], ground_xy)
            out[k] = qk if np.hypot(*qk) <= np.hypot(*qs) else qs
    for k in soft:
        sel = order[first[k]:last[k]]
        out[k] = soft_nearest(xy[sel], sr[sel], ground_xy)
    return out


def _nearest_points_compiled(xy: np.ndarray, sr: np.ndarray, group: np.ndarray,
                             n_groups: int, ground_xy, score,
                             at_border: np.ndarray | None) -> np.ndarray:
    """`nearest_points` with its per-obstacle loop compiled (`_extremes_kernel`) and the
    soft nearest points of all obstacles at once (`_soft_nearest_groups`): the same
    tests and arithmetic, so the same points (S >= 1 feet)."""
    out = np.full((n_groups, 2), np.nan)
    group = np.asarray(group, np.int64)
    brg_all = np.arctan2(xy[:, 1], xy[:, 0])
    r_all = np.hypot(xy[:, 0], xy[:, 1])
    count, i, j, kk = kg.nb_extremes(group, n_groups, brg_all, r_all)
    single = count == 1
    out[single] = xy[i[single]]
    multi = count > 1
    # A foot between the outermost ones and clearly nearer than both is the near corner
    # (a foot on a frontal face, e.g. of a texture stripe, is not clearly nearer).
    seen = np.zeros(n_groups, bool)
    for k in flat_nonzero(multi & (kk != i) & (kk != j)).tolist():
        ri, rj, rk = r_all[i[k]], r_all[j[k]], r_all[kk[k]]
        si, sj, sk = sr[i[k]], sr[j[k]], sr[kk[k]]
        seen[k] = min(ri, rj) - rk > _CORNER_SIGMAS * math.hypot(sk, max(si, sj))
    search = multi & ~seen & (i != j)
    if at_border is not None:
        search &= ~(at_border[np.maximum(i, 0)] | at_border[np.maximum(j, 0)])
    if score is None:
        search[:] = False
    soft = multi & ~search
    found = np.zeros(n_groups, bool)
    ks = flat_nonzero(search)
    if ks.size:
        ii, jj = i[ks], j[ks]
        si, sj = sr[ii], sr[jj]
        q = hidden_corners(xy[ii], xy[jj], np.where(sj > si, sj, si).astype(np.float64),
                           ground_xy, score)
        hit = ~np.isnan(q[:, 0])
        soft[ks[~hit]] = True
        found[ks[hit]] = True
        qk = np.full((n_groups, 2), np.nan)
        qk[ks[hit]] = q[hit]
    qs = _soft_nearest_groups(xy, sr, group, n_groups, soft | found, ground_xy)
    out[soft] = qs[soft]
    if found.any():
        # A corner beyond the nearest foot is not the nearest point (two bodies in one
        # cluster: the corner of the far one, the near one's foot nearer).
        f = flat_nonzero(found)
        nearer = np.hypot(qk[f, 0], qk[f, 1]) <= np.hypot(qs[f, 0], qs[f, 1])
        out[f] = np.where(nearer[:, None], qk[f], qs[f])
    return out


def nearest_point(xy: np.ndarray, sr: np.ndarray, ground_xy: np.ndarray,
                  score=None, at_border: np.ndarray | None = None) -> np.ndarray:
    """The nearest point on the ground of an obstacle from the feet of its edge strings.

    Args:
        xy: (S, 2) ground coordinates of the feet (`string_feet`), S >= 1.
        sr: (S,) their range sigmas, metres.
        ground_xy: (G, 2) visible ground (ground features).
        score: the contact-edge score ``score(a, n, b) -> (M,)``
            (`_FrameContext.contact_edge_score`), or None to skip the hidden-corner search.
        at_border: (S,) bool, feet of strings at the image's left or right border (the
            view's edge, not the obstacle's silhouette: no hidden corner next to them).
    Returns:
        (2,) ground coordinates: the nearest foot when it lies between the outermost
        feet in bearing and is clearly (``_CORNER_SIGMAS``) nearer than both (the near
        corner is seen; `soft_nearest`); else the hidden corner between the outermost
        feet, if there is one (`hidden_corner`); else `soft_nearest` of the feet.
        See `nearest_points` (batched).
    """
    return nearest_points(xy, sr, np.zeros(xy.shape[0], np.int64), 1, ground_xy,
                          None if score is None else _single_score(score), at_border)[0]

