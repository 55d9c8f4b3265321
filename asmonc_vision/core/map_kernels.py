"""The evidence map's inner loops compiled by numba (``core.jit``); `EvidenceMap`
(`asmonc_vision.core.evidence_map`) runs each when it compiled, else its numpy path
(test_evidence_map compares both):

* `rays_kernel`, the sight-line test of `EvidenceMap._rays`. Its numpy path builds the
  (cells x sight lines) arrays of the same arithmetic (the same operations in the same
  order, in float64: both give the same counts). The kernel tests only the sight lines
  whose bearing is near a cell's: most pass far beside a cell, and those it skips fail
  the first test.
* `count_kernel`, the pixel counts per cell of `EvidenceMap._enter`. Its numpy path
  counts with ``np.bincount`` over the whole grid (n x n cells) and finds the cells of
  each kind with ``np.flatnonzero``; the kernel adds each pixel to grids kept between
  pairs (zero but at the cells of the pair before, which it clears first) and lists the
  cells it touched: the same integer counts and cells, without a pass over the grid.
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.jit import jit, warmed


def rays_kernel(p, top, gh, R, height, lateral_m, stop_m):
    """Sight lines passing through raised cells, counted on each side of them.

    Args:
        p: (M, 2) float64 the cells' evidence points on the ground (x ahead, y left, m).
        top: (M,) float64 the height a sight line must pass below at each cell, m.
        gh: (N, 2) float64 the sight lines' unit directions on the ground.
        R: (N,) float64 the ranges of their ground points, m.
        height: the camera's height above the ground, m.
        lateral_m: a sight line within this of a cell's point passes through it, m.
        stop_m: the sight lines end this short of their ground point, m.
    Returns:
        (left, right): (M,) int64 each, the sight lines through each cell with the cell
        on their left (lateral offset > 0) and on their right (<= 0): those within
        ``lateral_m`` of it, that reach it (along the line: beyond 0.3 m, before
        ``R - stop_m``) and pass lower than ``top`` there (``height (1 - along / R)``).

    Only the sight lines whose bearing is within ``asin(lateral_m / r)`` (and a margin
    far above the rounding) of a cell's, r its range, are tested: the others pass more
    than ``lateral_m`` beside it or behind the camera (a line of bearing θ passes a point
    at range r and bearing φ at ``r sin(φ - θ)``, ahead of the camera only with
    ``|φ - θ| < 90°``). The tests are those of every line, so the counts are the same.
    Directions shorter than 0.5 (a ground point within 1 µm of the camera's foot) are
    tested against every cell.
    """
    m, n = p.shape[0], gh.shape[0]
    left = np.zeros(m, np.int64)
    right = np.zeros(m, np.int64)
    if m < _RAYS_SORT_MIN_CELLS:        # few cells: every line (sorting would cost more)
        for i in range(m):
            nb_rays_count(p, top, gh, R, height, lateral_m, stop_m, left, right, i,
                          np.arange(n))
        return left, right
    # the sight lines by bearing; the short directions apart
    ang = np.empty(n)
    short = np.zeros(n, np.bool_)
    for j in range(n):
        ang[j] = np.arctan2(gh[j, 1], gh[j, 0])
        short[j] = gh[j, 0] * gh[j, 0] + gh[j, 1] * gh[j, 1] < 0.25
    order = np.argsort(ang)
    n_long = 0
    for k in range(n):
        if not short[order[k]]:
            order[n_long] = order[k]
            n_long += 1
    long_ = order[:n_long]
    s_ang = ang[long_]
    shorts = np.flatnonzero(short)
    for i in range(m):
        px, py = p[i, 0], p[i, 1]
        r = np.hypot(px, py)
        sw = (lateral_m + 1e-9) / max(r * (1.0 - 1e-9), 1e-300)
        lo, hi = 0, n_long
        if sw < 1.0:
            phi = np.arctan2(py, px)
            w = np.arcsin(sw) + 1e-6
            if phi - w > -np.pi and phi + w < np.pi:
                lo = np.searchsorted(s_ang, phi - w, 'left')
                hi = np.searchsorted(s_ang, phi + w, 'right')
        nb_rays_count(p, top, gh, R, height, lateral_m, stop_m, left, right, i,
                      long_[lo:hi])
        nb_rays_count(p, top, gh, R, height, lateral_m, stop_m, left, right, i, shorts)
    return left, right


#: `rays_kernel` sorts the sight lines by bearing from this many cells on
_RAYS_SORT_MIN_CELLS = 24


def _rays_count(p, top, gh, R, height, lateral_m, stop_m, left, right, i, lines):
    """`rays_kernel`'s tests of cell ``i`` against the sight lines ``lines`` (int64
    indices), counted into ``left[i]`` and ``right[i]``."""
    px, py, ti = p[i, 0], p[i, 1], top[i]
    for j in lines:
        gx, gy = gh[j, 0], gh[j, 1]
        lateral = gx * py - gy * px
        if not abs(lateral) <= lateral_m:
            continue
        along = px * gx + py * gy
        if not (along > 0.3 and along < R[j] - stop_m):
            continue
        if height * (1.0 - along / R[j]) < ti:
            if lateral > 0:
                left[i] += 1
            else:
                right[i] += 1


def count_kernel(flat, kind, sure, n_r, n_d, n_g, n_sure, pair, prev_r, prev_d, prev_g):
    """Count a pair's pixels per cell into grids kept between pairs.

    Args:
        flat: (S,) int64 each pixel's flat cell index (inside the grid).
        kind: (S,) int8 each pixel's kind: 1 raised, -1 drop, 0 ground (others: none).
        sure: (S,) bool the ground pixels whose height is known finely.
        n_r, n_d, n_g, n_sure, pair: (n * n,) int64 grids, zero but at the cells
            ``prev_r``, ``prev_d``, ``prev_g`` of the pair before (int64, cleared here
            first: n_r and pair at prev_r, n_d and pair at prev_d, n_g and n_sure at
            prev_g); filled with this pair's raised, drop, ground and sure ground pixels
            per cell, and pair = raised + drop.
    Returns:
        (u_r, u_d, u_g): (K,) int64 each, ascending: the cells with raised, drop and
        ground pixels (``np.flatnonzero`` of n_r, n_d, n_g).
    """
    for c in prev_r:
        n_r[c] = 0
        pair[c] = 0
    for c in prev_d:
        n_d[c] = 0
        pair[c] = 0
    for c in prev_g:
        n_g[c] = 0
        n_sure[c] = 0
    s = flat.shape[0]
    u_r = np.empty(s, np.int64)
    u_d = np.empty(s, np.int64)
    u_g = np.empty(s, np.int64)
    kr = kd = kg = 0
    for i in range(s):
        c = flat[i]
        k = kind[i]
        if k == 1:
            if n_r[c] == 0:
                u_r[kr] = c
                kr += 1
            n_r[c] += 1
            pair[c] += 1
        elif k == -1:
            if n_d[c] == 0:
                u_d[kd] = c
                kd += 1
            n_d[c] += 1
            pair[c] += 1
        elif k == 0:
            if n_g[c] == 0:
                u_g[kg] = c
                kg += 1
            n_g[c] += 1
            if sure[i]:
                n_sure[c] += 1
    return np.sort(u_r[:kr]), np.sort(u_d[:kd]), np.sort(u_g[:kg])


#: ``count_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_count = jit(count_kernel)


class PixelCounts:
    """A pair's pixels per cell of an (n * n)-cell grid, `count_kernel` when it compiled
    (into grids kept between calls), else numpy's bincounts: the same integers.

    Attributes:
        pair: (n * n,) int64 the raised and drop pixels per cell of the latest `count`.
    """

    def __init__(self, cells: int) -> None:
        self.cells = int(cells)
        self._grids: np.ndarray | None = None       # n_r, n_d, n_g, n_sure, pair
        self._counted: tuple[np.ndarray, ...] = (np.zeros(0, np.int64),) * 3
        self.pair: np.ndarray = np.zeros(self.cells, np.int64)

    def count(self, flat: np.ndarray, kind: np.ndarray, sure: np.ndarray,
              use_kernel: bool = True) -> tuple[np.ndarray, ...]:
        """(n_r, n_d, n_g, n_sure), (n * n,) int64 each: the raised (kind 1), drop (-1),
        ground (0) and ``sure`` ground pixels of each cell; and (u_r, u_d, u_g), (K,)
        int64 each, the cells with raised, drop and ground pixels, ascending. ``flat``
        (S,) int64 cells of the pixels (in the grid), ``kind`` (S,) int8, ``sure`` (S,)
        bool (ground pixels only). The grids returned are valid until the next call."""
        if nb_count is not None and use_kernel:
            if self._grids is None:
                self._grids = np.zeros((5, self.cells), np.int64)
            n_r, n_d, n_g, n_sure, pair = self._grids
            u_r, u_d, u_g = nb_count(flat, kind, sure, n_r, n_d, n_g, n_sure, pair,
                                     *self._counted)
            self._counted = (u_r, u_d, u_g)
            self.pair = pair
            return n_r, n_d, n_g, n_sure, u_r, u_d, u_g
        n2 = self.cells
        n_r = np.bincount(flat[kind == 1], minlength=n2)
        n_d = np.bincount(flat[kind == -1], minlength=n2)
        n_g = np.bincount(flat[kind == 0], minlength=n2)
        n_sure = np.bincount(flat[sure], minlength=n2)
        self.pair = n_r + n_d
        return (n_r, n_d, n_g, n_sure,
                np.flatnonzero(n_r), np.flatnonzero(n_d), np.flatnonzero(n_g))


#: ``_rays_count`` compiled, for ``rays_kernel`` to call (None without numba)
nb_rays_count = jit(_rays_count)
#: ``rays_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_rays = jit(rays_kernel) if nb_rays_count is not None else None
_warm = False


def warm_up() -> None:
    """Compile the kernels once per process (or load them from numba's disk cache), before
    the first pair: an `EvidenceMap` calls this when it is made."""
    global _warm, nb_rays, nb_count
    if _warm:
        return
    _warm = True
    nb_rays = warmed(nb_rays, np.zeros((1, 2)), np.zeros(1), np.ones((1, 2)), np.ones(1),
                     1.0, 0.03, 0.2)
    z = np.zeros(4, np.int64)
    nb_count = warmed(nb_count, np.array([1, 2]), np.array([1, 0], np.int8),
                      np.array([False, True]), z.copy(), z.copy(), z.copy(), z.copy(),
                      z.copy(), np.array([3]), np.array([3]), np.array([3]))
