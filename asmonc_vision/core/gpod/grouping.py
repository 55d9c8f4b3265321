"""Grouping on the ground: obstacle strings clustered by the proximity of their feet
(`cluster_points_2d`), per-group quantiles, the bearing of a straight drop-off brink,
and whether two reports are one object.
"""
from __future__ import annotations

import math

import numpy as np

from . import kernels as kn
from .results import GpodObstacle
from ..npfast import flat_nonzero

#: A drop's brink taken for a straight line (`_brink_bearings`): at least this many edge
#: strings' nearest lower ground, spanning this many metres, within this orthogonal RMS.
_BRINK_MIN_POINTS = 4
_BRINK_MIN_SPAN_M = 0.5
_BRINK_MAX_RMS_M = 0.1
#: ... with at least this fraction of the points left after dropping those more than
#: _BRINK_MAX_RMS_M behind the line (strings that start on the lower ground).
_BRINK_MIN_KEPT = 0.5

#: `cluster_points_2d` links up to this many (thinned) points by testing all pairs, more
#: on a grid.
_PAIRWISE_POINTS = 256
#: ... and, compiled (`_link_groups_kernel`), up to this many.
_JIT_PAIRWISE_POINTS = 4096


def _normal_cdf(x: np.ndarray) -> np.ndarray:
    """Standard normal CDF (Abramowitz & Stegun 7.1.26 erf, |error| < 1.5e-7)."""
    z = np.abs(np.asarray(x, np.float64)) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.3275911 * z)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
                                                       + t * (-1.453152027 + t * 1.061405429))))
    erf = 1.0 - poly * np.exp(-z * z)
    return 0.5 * (1.0 + np.sign(x) * erf)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of an undirected graph with n nodes and edges (a, b).

    Returns:
        (n,) int64 label of each node, 0..C-1 in order of first node.
    """
    if a.size <= _PAIRWISE_POINTS:
        # Few edges: union-find in Python (labels as below: by each component's first node).
        parent = list(range(n))

        def root(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for x, y in zip(a.tolist(), b.tolist()):
            rx, ry = root(x), root(y)
            if rx != ry:
                parent[max(rx, ry)] = min(rx, ry)
        out: list[int] = []
        names: dict[int, int] = {}
        for x in range(n):
            out.append(names.setdefault(root(x), len(names)))
        return np.array(out, np.int64)
    label = np.arange(n, dtype=np.int64)
    if a.size:
        while True:
            la, lb = label[a], label[b]
            m = np.minimum(la, lb)
            new: np.ndarray = label.copy()
            np.minimum.at(new, la, m)
            np.minimum.at(new, lb, m)
            while True:                       # pointer jumping to the roots
                nxt = new[new]
                if np.array_equal(nxt, new):
                    break
                new = nxt
            if np.array_equal(new, label):
                break
            label = new
    _, comp = np.unique(label, return_inverse=True)
    return comp.astype(np.int64)


def cluster_points_2d(points: np.ndarray, group: np.ndarray, radius: float) -> np.ndarray:
    """Single-linkage clustering of groups of 2-D points.

    Two groups join when any of their points are within ``radius`` of each other (to
    within ``radius / 4``: points of one group are thinned to one per square of side
    ``radius / 4`` first); the points of one group always stay together.

    Args:
        points: (N, 2) float64 coordinates, metres.
        group: (N,) int group id of each point (e.g. edge string), >= 0.
        radius: linking distance, metres (> 0).
    Returns:
        (N,) int64 cluster label of each point, 0..C-1.
    """
    n = points.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    if kn.nb_link_groups is not None and kn.nb_thin is not None:
        # The same groups, thinning and links, compiled (the labels do not depend on the
        # order of the thinned points).
        g, pts, gr, n_g = kn.nb_thin(np.ascontiguousarray(points, np.float64),
                                   np.asarray(group, np.int64), float(radius) / 4.0)
        if n_g > 0 and pts.shape[0] <= _JIT_PAIRWISE_POINTS:
            return kn.nb_link_groups(pts, gr, n_g, float(radius) * float(radius))[g]
    _, g = np.unique(group, return_inverse=True)
    g = g.astype(np.int64)
    n_g = int(g.max()) + 1
    # Thin: one point per (group, fine cell).
    fine = np.floor((points - points.min(axis=0)) / (radius / 4.0)).astype(np.int64)
    fkey = (g * (int(fine[:, 0].max()) + 1) + fine[:, 0]) * (int(fine[:, 1].max()) + 1) + fine[:, 1]
    _, rep = np.unique(fkey, return_index=True)
    pts, gr = points[rep], g[rep]
    nr = pts.shape[0]
    if kn.nb_link_groups is not None and nr <= _JIT_PAIRWISE_POINTS:
        # All pairs, union-find, compiled: the same links and labels as below.
        return kn.nb_link_groups(pts, gr, n_g, float(radius) * float(radius))[g]
    if nr <= _PAIRWISE_POINTS:
        # Few points: all pairs at once (the same links as the grid search below).
        pi, pj = np.nonzero(gr[:, None] != gr[None, :])
        diff = pts[pi] - pts[pj]
        close = np.einsum('ij,ij->i', diff, diff) <= radius * radius
        a, b = gr[pi[close]], gr[pj[close]]
        if a.size:
            pair = np.unique(a * n_g + b)
            a, b = pair // n_g, pair % n_g
        return _components(n_g, a, b)[g]
    cell = np.floor((pts - pts.min(axis=0)) / radius).astype(np.int64) + 1
    span = int(cell[:, 1].max()) + 3
    key = cell[:, 0] * span + cell[:, 1]
    order = np.argsort(key, kind='stable')
    skey = key[order]
    src, dst = [], []
    for ox, oz in ((0, 0), (1, -1), (1, 0), (1, 1), (0, 1)):
        target = skey + ox * span + oz
        lo = np.searchsorted(skey, target, side='left')
        hi = np.searchsorted(skey, target, side='right')
        cnt = hi - lo
        tot = int(cnt.sum())
        if tot == 0:
            continue
        i = np.repeat(np.arange(nr), cnt)
        j = np.arange(tot) + np.repeat(lo - (np.cumsum(cnt) - cnt), cnt)
        pi, pj = order[i], order[j]
        ok = gr[pi] != gr[pj]
        pi, pj = pi[ok], pj[ok]
        diff = pts[pi] - pts[pj]
        close = np.einsum('ij,ij->i', diff, diff) <= radius * radius
        src.append(gr[pi[close]])
        dst.append(gr[pj[close]])
    a = np.concatenate(src) if src else np.zeros(0, np.int64)
    b = np.concatenate(dst) if dst else np.zeros(0, np.int64)
    if a.size:
        pair = np.unique(a * n_g + b)
        a, b = pair // n_g, pair % n_g
    return _components(n_g, a, b)[g]


def _fit_line(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Total least squares line through ground points p (N, 2), metres: (centroid (2,),
    unit direction (2,), (N,) coordinates along it from the centroid, orthogonal RMS
    residual)."""
    c = p.mean(axis=0)
    _, sv, vt = np.linalg.svd(p - c, full_matrices=False)
    d = vt[0]
    return c, d, (p - c) @ d, float(sv[1]) / math.sqrt(p.shape[0])


def _brink_bearings(xy: np.ndarray, group: np.ndarray, bearing: np.ndarray) -> np.ndarray:
    """The bearing of the nearest point of each drop's brink, where it is a straight
    line: a kerb down is seen along its whole width at nearly one range, and the
    nearest visible lower ground lies at the foot of the perpendicular from the camera's
    foot to the line (or at the line's seen end nearer to it).

    Args:
        xy: (S, 2) ground points, metres: the nearest lower ground of each of the
            drops' edge strings near their nearest range.
        group: (S,) drop of each point, 0..len(bearing)-1.
        bearing: (G,) radians, the drops' bearings so far (kept where the points are
            fewer than ``_BRINK_MIN_POINTS``, span less than ``_BRINK_MIN_SPAN_M`` or
            lie off one line by more than ``_BRINK_MAX_RMS_M``).
    Returns:
        (G,) radians.
    """
    out = bearing.copy()
    counts = np.bincount(group, minlength=bearing.shape[0])
    for k in flat_nonzero(counts >= _BRINK_MIN_POINTS):
        p = xy[group == k]
        n_all = p.shape[0]
        # The brink is the near boundary of the lower ground: a string that starts
        # beyond it (texture on the lower ground) is dropped and the line refitted
        # (most of the strings must stay: a scatter has no brink).
        for _ in range(3):
            c, d, _, rms = _fit_line(p)
            n_fit = p.shape[0]
            nrm = np.array([-d[1], d[0]])
            behind = math.copysign(1.0, float(nrm @ c)) * ((p - c) @ nrm)
            keep = behind <= _BRINK_MAX_RMS_M
            if keep.all() or np.count_nonzero(keep) < _BRINK_MIN_POINTS:
                break
            p = p[keep]
        # (after three trimmings the last fit's line with the points it kept)
        along = (p - c) @ d
        rms *= math.sqrt(n_fit / p.shape[0])
        if (keep.sum() < max(_BRINK_MIN_POINTS, _BRINK_MIN_KEPT * n_all)
                or float(along.max() - along.min()) < _BRINK_MIN_SPAN_M
                or rms > _BRINK_MAX_RMS_M):
            continue
        t = float(np.clip(-(c @ d), along.min(), along.max()))
        q = c + t * d
        out[k] = math.atan2(q[1], q[0])
    return out


def _same_object(a: GpodObstacle, b: GpodObstacle, radius: float = math.inf) -> bool:
    """Whether detection ``b`` may be track ``a``'s obstacle reported at another point:
    their image regions overlap by at least half the smaller one, and ``b`` lies no more
    than ``radius`` metres farther than ``a``."""
    if b.range - a.range > radius:
        return False
    ax, ay, aw, ah = a.roi
    bx, by, bw, bh = b.roi
    ix = min(ax + aw, bx + bw) - max(ax, bx)
    iy = min(ay + ah, by + bh) - max(ay, by)
    if ix <= 0 or iy <= 0:
        return False
    return ix * iy >= 0.5 * min(aw * ah, bw * bh)


def _group_quantile(group: np.ndarray, x: np.ndarray, q: float, n_groups: int) -> np.ndarray:
    """``np.quantile(x[group == k], q)`` (linear interpolation) for k = 0..n_groups-1
    (NaN for an empty group)."""
    out = np.full(n_groups, np.nan)
    if x.size == 0:
        return out
    if kn.nb_group_quantile is not None:
        return kn.nb_group_quantile(np.ascontiguousarray(group, np.int64),
                                    np.ascontiguousarray(x, np.float64),
                                    float(q), n_groups)
    order = np.lexsort((x, group))
    g, xs = group[order], x[order]
    count = np.bincount(g, minlength=n_groups)
    start = np.cumsum(count) - count
    has = count > 0
    pos = q * (count[has] - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, count[has] - 1)
    frac = pos - lo
    s = start[has]
    out[has] = xs[s + lo] + (xs[s + hi] - xs[s + lo]) * frac
    return out

