"""The evidence map's inner loops compiled by numba (``core.jit``); `EvidenceMap`
(`asmonc_vision.core.evidence_map`, and `core.map_sight` for the sight lines) runs each
when it compiled, else its numpy path (test_evidence_map compares both):

* `rays_kernel`, the sight-line test of `map_sight.seen_through`. Its numpy path builds the
  (cells x sight lines) arrays of the same arithmetic (the same operations in the same
  order, in float64: both give the same counts). The kernel tests only the sight lines
  whose bearing is near a cell's: most pass far beside a cell, and those it skips fail
  the first test.
* `heights_kernel`, the cells' height filter and evidence points of
  `EvidenceMap._enter` (`enter_heights`): the same per-cell arithmetic in the same
  precisions and the same sums in the pixels' order as its numpy path, without numpy's
  sorts and selections.
* `count_kernel`, the pixel counts per cell of `EvidenceMap._enter`. Its numpy path
  counts with ``np.bincount`` over the whole grid (n x n cells) and finds the cells of
  each kind with ``np.flatnonzero``; the kernel adds each pixel to grids kept between
  pairs (zero but at the cells of the pair before, which it clears first) and lists the
  cells it touched: the same integer counts and cells, without a pass over the grid.
* `near_kernel`, whether a pair's marked cells lie near given cells (`EvidenceMap`'s
  guards). Its numpy path dilates the marked cells' grid by the square
  (`map_grid.dilate`) and reads it at the cells; the kernel looks in each cell's square
  only: the same booleans, without the grid's dilation.
* `surest_kernel`, the surest pixel's weight per cell of `EvidenceMap._enter`. Its
  numpy path takes the maxima into a zero grid (``np.maximum.at``) and reads the
  cells; the kernel finds each pixel's cell among the cells: the same maxima.
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.jit import jit, warmed
from asmonc_vision.core.map_evidence import DROP, RAISED
from asmonc_vision.core.npfast import flat_nonzero


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


def near_kernel(marked, n, cells, radius):
    """(C,) bool: whether any of the ``marked`` cells ((K,) int64 flat indices of an
    n x n grid) lies within ``radius`` cells in x and in y of each of ``cells`` ((C,)
    int64 flat indices), the square cut at the grid's border (for numba): the
    ``cv2.dilate`` of the marked cells' grid by the square, read at the cells."""
    grid = np.zeros(n * n, np.bool_)
    for k in range(marked.shape[0]):
        grid[marked[k]] = True
    out = np.zeros(cells.shape[0], np.bool_)
    for i in range(cells.shape[0]):
        y, x = cells[i] // n, cells[i] % n
        x0, x1 = max(x - radius, 0), min(x + radius, n - 1)
        found = False
        for yy in range(max(y - radius, 0), min(y + radius, n - 1) + 1):
            for xx in range(x0, x1 + 1):
                if grid[yy * n + xx]:
                    found = True
                    break
            if found:
                break
        out[i] = found
    return out


#: ``near_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_near = jit(near_kernel)


def surest_kernel(flat, weight, cells):
    """(K,) float64: the largest of 0 and the ``weight`` (P,) float64 of the pixels in
    each of ``cells`` ((K,) int64 flat indices, ascending, distinct), ``flat`` (P,) int64
    the pixels' cells (for numba): ``np.maximum.at`` of the weights into a zero grid,
    read at the cells (NaN propagated as np.maximum does), without the grid."""
    k = cells.shape[0]
    best = np.zeros(k)
    for p in range(flat.shape[0]):
        i = np.searchsorted(cells, flat[p])
        if i < k and cells[i] == flat[p]:
            b, w = best[i], weight[p]
            if b == b and (w != w or w > b):
                best[i] = w
    return best


#: ``surest_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_surest = jit(surest_kernel)


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
                flat_nonzero(n_r), flat_nonzero(n_d), flat_nonzero(n_g))


def enter_heights(flat: np.ndarray, kind: np.ndarray, h: np.ndarray, sh: np.ndarray,
                  w: np.ndarray, raised: np.ndarray, dropc: np.ndarray, x: np.ndarray,
                  P: np.ndarray, pts: np.ndarray, last_hit: np.ndarray, stamp_s: float,
                  use_kernel: bool = True) -> None:
    """The height and evidence point of each cell a pair's raised (drop) evidence enters
    (`EvidenceMap._enter`), in place: per cell, the pair's highest raised point (drop:
    lowest) is z, R = sigma_h^2, a Kalman update of the cell's height x and variance P
    (a cell of P = inf takes z and R); its evidence point moves to the mean of the
    pair's points there (all the way for a new cell, else 0.3 of the way); its last hit
    is ``stamp_s``.

    Args:
        flat: (S,) int64 the pixels' cells (flat indices into the grid).
        kind: (S,) int8 each pixel's kind (RAISED, DROP, ...).
        h, sh: (S,) float64 the pixels' heights and their standard deviations, m.
        w: (S, 2) float64 the pixels' points in W, m.
        raised, dropc: (K,) int64 the cells (ascending) whose raised (drop) evidence
            enters.
        x, P: (n * n,) float32 the cells' heights (m) and variances (m^2), updated.
        pts: (n * n, 2) float32 the cells' evidence points in W (m), updated.
        last_hit: (n * n,) float64 each cell's last evidence, s, updated.
    """
    if nb_heights is not None and use_kernel:
        # the same arithmetic, compiled (`heights_kernel`)
        nb_heights(flat, kind, h, sh, w, raised, dropc, x, P, pts, last_hit, float(stamp_s))
        return
    here = np.zeros(x.shape[0], bool)       # the cells of the kind (np.isin over the grid)
    for cells, sel, sign in ((raised, kind == RAISED, 1.0), (dropc, kind == DROP, -1.0)):
        if not cells.size:
            continue
        here[cells] = True
        fi, hi, si, wi = flat[sel], h[sel] * sign, sh[sel], w[sel]
        o = np.lexsort((-hi, fi))
        fo = fi[o]
        head = np.concatenate((_HEAD, fo[1:] != fo[:-1]))
        top = o[head]
        cell = fi[top]
        # each pixel's cell as its rank among the pair's cells of the kind (the sums
        # per cell below over those, in the pixels' order, as over the grid)
        rank = np.empty(fi.size, np.int64)
        rank[o] = np.cumsum(head) - 1
        keep = here[cell]
        here[cells] = False
        cell, z, R = cell[keep], sign * hi[top][keep], si[top][keep] ** 2
        P0 = P[cell]
        new = ~np.isfinite(P0)
        # y = z - H x; S = H P Hᵀ + R; K = P Hᵀ S⁻¹; x = x + K y; P = (1 - K H) P
        with np.errstate(invalid='ignore'):
            Kg = np.where(new, 1.0, P0 / (P0 + R))
        x[cell] = np.where(new, z, x[cell] + Kg * (z - x[cell]))
        P[cell] = np.where(new, R, (1.0 - Kg) * np.where(new, 0.0, P0))
        # the cell's evidence point: mean of the pair's points there, smoothed
        cnt = np.bincount(rank)[keep]
        mx = np.bincount(rank, weights=wi[:, 0])[keep] / cnt
        my = np.bincount(rank, weights=wi[:, 1])[keep] / cnt
        a = np.where(new, 1.0, 0.3)
        pts[cell, 0] = (1 - a) * pts[cell, 0] + a * mx
        pts[cell, 1] = (1 - a) * pts[cell, 1] + a * my
        last_hit[cell] = stamp_s


_HEAD = np.ones(1, bool)


def heights_kernel(flat, kind, h, sh, w, raised, dropc, x, P, pts, last_hit, stamp_s):
    """`enter_heights` (for numba): per kind, the pixels of each cell (a stable sort by
    cell), its top pixel (the first of the highest, as numpy's lexsort orders them: a
    NaN height after every number), the sums of its points in the pixels' order, and
    the cell's update in numpy's precisions (float64 arithmetic, float32 storage)."""
    for kk in range(2):
        cells = raised if kk == 0 else dropc
        code = RAISED if kk == 0 else DROP
        sign = 1.0 if kk == 0 else -1.0
        if cells.shape[0] == 0:
            continue
        m = 0
        for i in range(kind.shape[0]):
            if kind[i] == code:
                m += 1
        idx = np.empty(m, np.int64)
        m = 0
        for i in range(kind.shape[0]):
            if kind[i] == code:
                idx[m] = i
                m += 1
        fi = np.empty(m, np.int64)
        for j in range(m):
            fi[j] = flat[idx[j]]
        o = np.argsort(fi, kind='mergesort')
        slot = np.empty(m, np.int64)       # each pixel's cell, as its rank
        n_c = 0
        for j in range(m):
            if j == 0 or fi[o[j]] != fi[o[j - 1]]:
                n_c += 1
            slot[o[j]] = n_c - 1
        top = np.full(n_c, -1, np.int64)
        cnt = np.zeros(n_c, np.int64)
        sx = np.zeros(n_c)
        sy = np.zeros(n_c)
        for j in range(m):              # the pixels' order
            i = idx[j]
            c = slot[j]
            cnt[c] += 1
            sx[c] += w[i, 0]
            sy[c] += w[i, 1]
            t = top[c]
            if t < 0:
                top[c] = j
            else:
                hj, ht = h[i] * sign, h[idx[t]] * sign
                if hj > ht or (ht != ht and hj == hj):
                    top[c] = j
        for c in range(n_c):
            j = top[c]
            i = idx[j]
            cell = fi[j]
            k = np.searchsorted(cells, cell)
            if k >= cells.shape[0] or cells[k] != cell:
                continue
            z = sign * (h[i] * sign)
            R = sh[i] * sh[i]
            P0 = np.float64(P[cell])
            mx = sx[c] / cnt[c]
            my = sy[c] / cnt[c]
            if not np.isfinite(P0):
                x[cell] = np.float32(z)
                P[cell] = np.float32(R)
                a = 1.0
            else:
                Kg = P0 / (P0 + R)
                xc = np.float64(x[cell])
                x[cell] = np.float32(xc + Kg * (z - xc))
                P[cell] = np.float32((1.0 - Kg) * P0)
                a = 0.3
            pts[cell, 0] = np.float32((1 - a) * np.float64(pts[cell, 0]) + a * mx)
            pts[cell, 1] = np.float32((1 - a) * np.float64(pts[cell, 1]) + a * my)
            last_hit[cell] = stamp_s


#: ``heights_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_heights = jit(heights_kernel)


#: ``_rays_count`` compiled, for ``rays_kernel`` to call (None without numba)
nb_rays_count = jit(_rays_count)
#: ``rays_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_rays = jit(rays_kernel) if nb_rays_count is not None else None
_warm = False


def warm_up() -> None:
    """Compile the kernels once per process (or load them from numba's disk cache), before
    the first pair: an `EvidenceMap` calls this when it is made."""
    global _warm, nb_rays, nb_count, nb_heights, nb_near, nb_surest
    if _warm:
        return
    _warm = True
    nb_near = warmed(nb_near, np.array([1, 2]), 3, np.array([0, 8]), 1)
    nb_surest = warmed(nb_surest, np.array([1, 2]), np.ones(2), np.array([2]))
    nb_rays = warmed(nb_rays, np.zeros((1, 2)), np.zeros(1), np.ones((1, 2)), np.ones(1),
                     1.0, 0.03, 0.2)
    z = np.zeros(4, np.int64)
    nb_count = warmed(nb_count, np.array([1, 2]), np.array([1, 0], np.int8),
                      np.array([False, True]), z.copy(), z.copy(), z.copy(), z.copy(),
                      z.copy(), np.array([3]), np.array([3]), np.array([3]))
    f4 = np.zeros(4, np.float32)
    nb_heights = warmed(nb_heights, np.array([1, 2]), np.array([1, -1], np.int8), np.ones(2),
                        np.ones(2), np.ones((2, 2)), np.array([1]), np.array([2]), f4.copy(),
                        np.full(4, np.inf, np.float32), np.zeros((4, 2), np.float32),
                        np.zeros(4), 1.0)
