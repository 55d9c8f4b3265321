"""Corners with sub-pixel positions, normalised cross-correlation patches, and matching.

Corner detectors (``detect_corners``):

* ``'shi_tomasi'`` (default): minimum eigenvalue of the structure tensor
  (``cv2.goodFeaturesToTrack``), then sub-pixel by the condition of
  ``cv2.cornerSubPix`` (the point where every gradient in the window is orthogonal to
  the vector to it), solved for all corners at once (``subpix_refine``). See
  docs/motion.md for the measured localisation error that made it the default.
* ``'wang_brady'``: Wang & Brady (1995), the detector of the paper: on the Gaussian-
  smoothed image, the corner response ``C = (d2I/dt2)^2 - S |grad I|^2`` where ``t`` is
  the unit tangent to the edge (perpendicular to the gradient): large where an edge turns
  sharply, while the ``S`` term suppresses straight edges. Local maxima above a threshold
  with enough gradient, sub-pixel by a quadratic fit of ``C`` over 3x3.

Matching is by the normalised cross-correlation (NCC) of small square windows sampled
bilinearly at the corners' sub-pixel positions (each window reduced to zero mean and
unit norm, so NCC is a dot product and insensitive to the gain and offset difference of
the two cameras):

* ``match_stereo``: left to right corners on the same row (rectified images) within a
  row tolerance and a disparity range; best NCC both ways (mutual), above a minimum and
  clear of the second best by a margin.
* ``match_temporal``: previous to current corners within a search radius of a predicted
  position (the previous position, or where a motion prediction puts the point), with
  the same acceptance rules.

Pixel (u, v): u column, v row, origin at the centre of the top-left pixel (the
convention of ``cv2`` sub-pixel positions as well).
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from ..jit import jit, warmed

DETECTORS = ('shi_tomasi', 'wang_brady')


def _grid_spread(pts: np.ndarray, score: np.ndarray, shape, cells: tuple[int, int],
                 max_corners: int) -> np.ndarray:
    """Keep at most max_corners, sharing them among grid cells (strongest first in each)
    so that weakly textured regions still contribute. Returns indices into pts."""
    if len(pts) <= max_corners:
        return np.arange(len(pts))
    h, w = shape
    gy, gx = cells
    cell = (np.clip((pts[:, 1] * gy / h).astype(int), 0, gy - 1) * gx
            + np.clip((pts[:, 0] * gx / w).astype(int), 0, gx - 1))
    order = np.lexsort((-score, cell))
    rank = np.empty(len(pts), int)
    sorted_cells = cell[order]
    starts = np.r_[0, np.nonzero(np.diff(sorted_cells))[0] + 1]
    counts = np.diff(np.r_[starts, len(order)])
    rank[order] = np.arange(len(order)) - np.repeat(starts, counts)
    keep = np.lexsort((-score, rank))[:max_corners]
    return np.sort(keep)


def subpix_refine(img: np.ndarray, pts: np.ndarray, half_window: int = 5, iters: int = 4,
                  return_strength: bool = False, tol: float = 0.005, return_ok: bool = False):
    """Sub-pixel corners by the condition of ``cv2.cornerSubPix``, for all corners at once.

    The corner q is where every image gradient g_i in the window around it is orthogonal
    to the vector from q to its pixel p_i: ``sum w_i g_i g_i^T (p_i - q) = 0``, so
    ``q = (sum w_i G_i)^-1 sum w_i G_i p_i`` with ``G_i = g_i g_i^T`` and Gaussian
    weights ``w_i = exp(-|p_i - q|^2 / half_window^2)`` centred on the current q (as
    cv2.cornerSubPix), iterated towards the fixed point, so the result moves with the
    image content whatever its sub-pixel phase. The windows (gradients at the pixels
    nearest q) are gathered for every corner in one numpy operation: 4.5 ms of CPU for 300
    corners and 11x11 windows where cv2.cornerSubPix took 27 ms (a bag image); the
    accuracy on synthetic corners is the same or better (docs/motion.md). With numba the
    same steps run compiled, corner by corner (`_subpix_kernel`: the corners of a pair in 14 ms
    instead of 20 on the bundled walks, `asmonc motion eval`; the motions unchanged).

    Args:
        img: (H, W) uint8 or float.
        pts: (N, 2) initial (u, v) pixels.
        half_window: window half size, pixels.
        iters: most fixed-point iterations (4: a clear corner converges in 2-3; more
            lets weak, edge-like ones wander along their edge); tol: stop when no corner
            moves more, px.
    Returns:
        (N, 2) float64 refined corners; a corner whose system is singular or that moves
        more than ``half_window`` stays where it was. With ``return_strength``, also
        (N,) the smaller eigenvalue of the window's weighted mean structure tensor at the
        last window, (grey levels / px)^2: the corner's strength in absolute terms
        (about 1 for camera noise of 2 grey levels, tens for a clear corner). With
        ``return_ok``, also (N,) bool: False where the refinement left the window or its
        system was singular (no well-defined corner; the corner is returned unmoved).
    """
    pts = np.asarray(pts, float).reshape(-1, 2)
    hw = int(half_window)
    f = img if img.dtype == np.float32 else img.astype(np.float32)
    h, w = f.shape
    if len(pts) == 0 or hw <= 0 or h <= 2 * hw + 4 or w <= 2 * hw + 4:
        out: list[np.ndarray] = [pts.copy()]
        if return_strength:
            out.append(np.zeros(len(pts)))
        if return_ok:
            out.append(np.zeros(len(pts), bool))
        return tuple(out) if len(out) > 1 else out[0]
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8).ravel()
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8).ravel()
    if _nb_subpix is not None and not _NUMPY_ONLY[0]:
        qc, strength_c, alive_c = _nb_subpix(gx, gy, w, h, pts, hw, max(int(iters), 1),
                                             float(tol))
        res = [qc]
        if return_strength:
            res.append(strength_c)
        if return_ok:
            res.append(alive_c)
        return tuple(res) if len(res) > 1 else res[0]
    r = np.arange(-hw - 1, hw + 2)                     # one pixel more: q is off-centre
    dy, dx = (a.ravel().astype(np.float32) for a in np.meshgrid(r, r, indexing='ij'))
    off = (dy * w + dx).astype(int)
    inv = np.float32(1.0 / (hw * hw))
    q: np.ndarray = pts.copy()
    alive = np.ones(len(pts), bool)
    sa = sb = sc = ws = np.zeros(len(pts), np.float32)
    for _ in range(max(int(iters), 1)):
        cur = np.rint(q).astype(int)
        cur[:, 0] = np.clip(cur[:, 0], hw + 1, w - 2 - hw)
        cur[:, 1] = np.clip(cur[:, 1], hw + 1, h - 2 - hw)
        idx = (cur[:, 1] * w + cur[:, 0])[:, None] + off[None, :]
        ax, ay = gx[idx], gy[idx]                                   # (N, K)
        fx = (cur[:, 0] - q[:, 0]).astype(np.float32)[:, None] + dx[None]   # p_i - q
        fy = (cur[:, 1] - q[:, 1]).astype(np.float32)[:, None] + dy[None]
        wt = np.exp(-(fx * fx + fy * fy) * inv)
        axx, axy, ayy = ax * ax * wt, ax * ay * wt, ay * ay * wt
        sa, sb, sc = axx.sum(1), axy.sum(1), ayy.sum(1)
        ws = wt.sum(1)
        bx = (axx * fx + axy * fy).sum(1)
        by = (axy * fx + ayy * fy).sum(1)
        saf, sbf, scf = sa.astype(float), sb.astype(float), sc.astype(float)
        det = saf * scf - sbf * sbf
        ok = det > 1e-9 * (saf + scf) ** 2
        with np.errstate(invalid='ignore', divide='ignore'):
            du = (scf * bx - sbf * by) / det                         # q_new - q
            dv = (saf * by - sbf * bx) / det
        step = np.where(ok & alive, np.hypot(du, dv), 0.0)
        nq = q + np.where((ok & alive)[:, None], np.stack([du, dv], axis=1), 0.0)
        far = np.any(np.abs(nq - pts) > hw, axis=1) | ~ok
        alive &= ~far
        q = np.where(alive[:, None], nq, pts)
        if np.all(step[alive] < tol):
            break
    out = [q]
    if return_strength:
        strength = ((sa + sc) / 2 - np.sqrt(((sa - sc) / 2) ** 2 + sb * sb)) / np.maximum(ws, 1e-9)
        out.append(strength.astype(float))
    if return_ok:
        out.append(alive)
    return tuple(out) if len(out) > 1 else out[0]


def _subpix_kernel(gx, gy, w, h, pts, hw, iters, tol):
    """`subpix_refine`'s iterations for numba: the same steps corner by corner, its sums
    in double precision (the numpy path adds in single precision: the corners agree to
    about 1e-4 px). gx, gy: (H*W,) float32 gradients; pts: (N, 2) float64. Returns
    (q (N, 2), strength (N,), alive (N,) bool)."""
    n = pts.shape[0]
    q = pts.copy()
    alive = np.ones(n, np.bool_)
    strength = np.zeros(n)
    inv = 1.0 / (hw * hw)
    for _ in range(iters):
        worst = 0.0
        for i in range(n):
            cx = min(max(int(np.rint(q[i, 0])), hw + 1), w - 2 - hw)
            cy = min(max(int(np.rint(q[i, 1])), hw + 1), h - 2 - hw)
            ox = cx - q[i, 0]
            oy = cy - q[i, 1]
            sa = sb = sc = ws = bx = by = 0.0
            for dy in range(-hw - 1, hw + 2):
                row = (cy + dy) * w + cx
                fy = oy + dy
                for dx in range(-hw - 1, hw + 2):
                    fx = ox + dx
                    wt = math.exp(-(fx * fx + fy * fy) * inv)
                    ax = gx[row + dx]
                    ay = gy[row + dx]
                    axx = ax * ax * wt
                    axy = ax * ay * wt
                    ayy = ay * ay * wt
                    sa += axx
                    sb += axy
                    sc += ayy
                    ws += wt
                    bx += axx * fx + axy * fy
                    by += axy * fx + ayy * fy
            strength[i] = ((sa + sc) / 2 - math.sqrt(((sa - sc) / 2) ** 2 + sb * sb)) \
                / max(ws, 1e-9)
            det = sa * sc - sb * sb
            ok = det > 1e-9 * (sa + sc) ** 2
            if not alive[i]:
                continue
            if not ok:
                alive[i] = False
                q[i, 0], q[i, 1] = pts[i, 0], pts[i, 1]
                continue
            du = (sc * bx - sb * by) / det
            dv = (sa * by - sb * bx) / det
            nx, ny = q[i, 0] + du, q[i, 1] + dv
            if abs(nx - pts[i, 0]) > hw or abs(ny - pts[i, 1]) > hw:
                alive[i] = False
                q[i, 0], q[i, 1] = pts[i, 0], pts[i, 1]
                continue
            q[i, 0], q[i, 1] = nx, ny
            worst = max(worst, math.hypot(du, dv))
        if worst < tol:
            break
    return q, strength, alive


#: the kernel compiled and warmed (None without numba: the numpy path)
_nb_subpix = warmed(jit(_subpix_kernel), np.zeros(400, np.float32), np.zeros(400, np.float32),
                    20, 20, np.full((1, 2), 9.0), 3, 2, 0.005)
#: tests set [True] to run the numpy path
_NUMPY_ONLY = [False]


def corner_strength(img: np.ndarray, pts: np.ndarray, half_window: int = 5) -> np.ndarray:
    """Absolute strength of corners (N,): the smaller eigenvalue of the Gaussian-weighted
    mean structure tensor over the window at each corner's nearest pixel,
    (grey levels / px)^2 (see ``subpix_refine``)."""
    return subpix_refine(img, pts, max(int(half_window), 2), iters=1, return_strength=True)[1]


def shi_tomasi_corners(img: np.ndarray, max_corners: int = 300, quality: float = 0.005,
                       min_distance: float = 5.0, block_size: int = 5, border: int = 6,
                       subpix_half_window: int = 5, grid: tuple[int, int] = (4, 4),
                       min_strength: float = 0.0, drop_unrefined: bool = True) -> np.ndarray:
    """Shi–Tomasi corners refined by ``cv2.cornerSubPix``.

    Args:
        img: (H, W) uint8 or float32.
        max_corners: most corners returned (spread over a ``grid`` of cells).
        quality: minimum eigenvalue relative to the strongest corner's.
        min_distance: pixels between corners.
        block_size: structure tensor window, pixels.
        border: corners closer than this to the image edge are dropped, pixels.
        subpix_half_window: sub-pixel window half size (``subpix_refine``; 0: none).
        min_strength: corners weaker than this in absolute terms (``corner_strength``,
            (grey levels / px)^2; camera noise alone gives about 1) are dropped, so a dark
            or blank view gives no corners rather than noise.
        drop_unrefined: drop corners whose sub-pixel refinement left the window (no
            well-defined corner there: its position would not be repeatable).
    Returns:
        (N, 2) float64 (u, v) pixels.
    """
    h, w = img.shape
    mask = np.zeros((h, w), np.uint8)
    mask[border:h - border, border:w - border] = 255
    c = cv2.goodFeaturesToTrack(img, maxCorners=4 * max_corners, qualityLevel=quality,
                                minDistance=min_distance, mask=mask, blockSize=block_size,
                                useHarrisDetector=False)
    if c is None:
        return np.zeros((0, 2))
    c = c.reshape(-1, 2).astype(np.float32)
    # goodFeaturesToTrack returns the strongest first: use the rank as the score
    keep = _grid_spread(c.astype(float), -np.arange(len(c), dtype=float), (h, w), grid,
                        max_corners)
    c = np.ascontiguousarray(c[keep])
    c = c.astype(float)
    if subpix_half_window > 0 and len(c):
        c, strength, ok = subpix_refine(img, c, subpix_half_window, return_strength=True,
                                        return_ok=True)
        keep_c = strength >= min_strength
        if drop_unrefined:
            keep_c &= ok
        c = c[keep_c]
    elif min_strength > 0 and len(c):
        c = c[corner_strength(img, c) >= min_strength]
    inside = ((c[:, 0] >= border) & (c[:, 0] <= w - 1 - border)
              & (c[:, 1] >= border) & (c[:, 1] <= h - 1 - border))
    return c[inside]


def wang_brady_response(img: np.ndarray, sigma: float = 1.0, s: float = 0.05
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Wang–Brady corner response C and squared gradient magnitude, float32 (H, W).

    ``C = (d2I/dt2)^2 - s |grad I|^2`` on the image smoothed by a Gaussian of ``sigma``
    px, with ``d2I/dt2 = (Ixx Iy^2 - 2 Ixy Ix Iy + Iyy Ix^2) / |grad I|^2``.
    """
    f: np.ndarray = img.astype(np.float32)
    if sigma > 0:
        f = cv2.GaussianBlur(f, (0, 0), sigma)
    ix = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8)
    iy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8)
    ixx = cv2.Sobel(f, cv2.CV_32F, 2, 0, ksize=3, scale=1 / 4)
    iyy = cv2.Sobel(f, cv2.CV_32F, 0, 2, ksize=3, scale=1 / 4)
    ixy = cv2.Sobel(f, cv2.CV_32F, 1, 1, ksize=3, scale=1 / 4)
    g2 = ix * ix + iy * iy
    dtt = (ixx * iy * iy - 2 * ixy * ix * iy + iyy * ix * ix) / np.maximum(g2, 1e-6)
    return dtt * dtt - s * g2, g2


#: Wang–Brady smoothing displacement: the response peak of a corner lies this many
#: smoothing sigmas inside it, against the gradient (measured on synthetic 60-120 degree
#: corners, ``experiment.render_corner``; W&B derive it analytically for 90 degrees)
WB_DISPLACEMENT = 1.5


def wang_brady_corners(img: np.ndarray, max_corners: int = 300, sigma: float = 1.0,
                       s: float = 0.05, rel_threshold: float = 0.005, min_gradient: float = 1.5,
                       min_distance: int = 5, border: int = 6,
                       grid: tuple[int, int] = (4, 4),
                       displacement_correction: float = WB_DISPLACEMENT,
                       min_strength: float = 0.0) -> np.ndarray:
    """Wang–Brady corners with sub-pixel positions (quadratic fit of C over 3x3).

    Args:
        img: (H, W) uint8.
        sigma, s: smoothing (px) and the edge suppression weight of the response.
        rel_threshold: C must exceed this fraction of the image's largest C.
        min_gradient: |grad I| must exceed this (grey levels per pixel).
        min_distance: non-maximum suppression radius, pixels.
        displacement_correction: each corner is moved this many ``sigma`` along the
            local gradient direction (W&B's correction of the displacement that
            smoothing causes; 0: none).
        min_strength: as ``shi_tomasi_corners``.
    Returns:
        (N, 2) float64 (u, v) pixels.
    """
    c, g2 = wang_brady_response(img, sigma, s)
    h, w = c.shape
    k = 2 * int(min_distance) + 1
    dil = cv2.dilate(c, np.ones((k, k), np.uint8))
    cmax = float(c.max()) if c.size else 0.0
    cand = (c >= dil) & (c > rel_threshold * cmax) & (c > 0) & (g2 > min_gradient ** 2)
    cand[:border, :] = cand[-border:, :] = False
    cand[:, :border] = cand[:, -border:] = False
    vv, uu = np.nonzero(cand)
    if vv.size == 0:
        return np.zeros((0, 2))
    score = c[vv, uu]
    keep = _grid_spread(np.stack([uu, vv], 1).astype(float), score, (h, w), grid, max_corners)
    vv, uu = vv[keep], uu[keep]
    # quadratic fit over the 3x3 neighbourhood: C ~ a + b.x + x^T H x / 2
    cx0 = c[vv, uu]
    cxp, cxm = c[vv, uu + 1], c[vv, uu - 1]
    cyp, cym = c[vv + 1, uu], c[vv - 1, uu]
    cpp, cpm = c[vv + 1, uu + 1], c[vv - 1, uu + 1]
    cmp_, cmm = c[vv + 1, uu - 1], c[vv - 1, uu - 1]
    gx = (cxp - cxm) / 2
    gy = (cyp - cym) / 2
    hxx = cxp - 2 * cx0 + cxm
    hyy = cyp - 2 * cx0 + cym
    hxy = (cpp - cpm - cmp_ + cmm) / 4
    det = hxx * hyy - hxy * hxy
    with np.errstate(invalid='ignore', divide='ignore'):
        du = -(hyy * gx - hxy * gy) / det
        dv = -(hxx * gy - hxy * gx) / det
    ok = (det > 0) & (hxx < 0) & (np.abs(du) <= 1) & (np.abs(dv) <= 1)
    du = np.where(ok, du, 0.0)
    dv = np.where(ok, dv, 0.0)
    out = np.stack([uu + du, vv + dv], axis=1).astype(float)
    if displacement_correction:
        f = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 2.0 * max(sigma, 0.5))
        gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3)[vv, uu]
        gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)[vv, uu]
        gn = np.hypot(gx, gy)
        okg = gn > 1e-6
        shift = displacement_correction * sigma
        out[okg, 0] += shift * gx[okg] / gn[okg]
        out[okg, 1] += shift * gy[okg] / gn[okg]
    if min_strength > 0 and len(out):
        out = out[corner_strength(img, out) >= min_strength]
    return out


def detect_corners(img: np.ndarray, method: str = 'shi_tomasi', max_corners: int = 300,
                   min_distance: float = 5.0, border: int = 6, subpix_half_window: int = 5,
                   quality: float = 0.005, min_strength: float = 0.0) -> np.ndarray:
    """Corners of a uint8 image with sub-pixel positions: (N, 2) float64 (u, v).

    ``subpix_half_window`` and ``quality`` apply to 'shi_tomasi' only."""
    if method == 'shi_tomasi':
        return shi_tomasi_corners(img, max_corners=max_corners, min_distance=min_distance,
                                  border=border, subpix_half_window=subpix_half_window,
                                  quality=quality, min_strength=min_strength)
    if method == 'wang_brady':
        return wang_brady_corners(img, max_corners=max_corners,
                                  min_distance=int(round(min_distance)), border=border,
                                  min_strength=min_strength)
    raise ValueError(f"unknown corner detector '{method}'; expected one of {DETECTORS}")


def patches(img: np.ndarray, pts: np.ndarray, half: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Normalised windows around sub-pixel points, for NCC by dot product.

    Args:
        img: (H, W) uint8 or float32.
        pts: (N, 2) (u, v) pixels.
        half: window half size: windows are (2 half + 1)^2 pixels, sampled bilinearly.
    Returns:
        (desc (N, (2 half + 1)^2) float32 with zero mean and unit norm,
         valid (N,) bool: False for windows leaving the image or without texture).
    """
    n = len(pts)
    size = 2 * half + 1
    if n == 0:
        return np.zeros((0, size * size), np.float32), np.zeros(0, bool)
    off = np.arange(-half, half + 1, dtype=np.float32)
    mx = (pts[:, 0].astype(np.float32)[:, None, None] + off[None, None, :]).repeat(size, axis=1)
    my = (pts[:, 1].astype(np.float32)[:, None, None] + off[None, :, None]).repeat(size, axis=2)
    mx = mx.reshape(n * size, size)
    my = my.reshape(n * size, size)
    src = img if img.dtype == np.float32 else img.astype(np.float32)
    win = cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    d = win.reshape(n, size * size)
    d = d - d.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(d, axis=1)
    h, w = img.shape
    valid = ((pts[:, 0] >= half) & (pts[:, 0] <= w - 1 - half) & (pts[:, 1] >= half)
             & (pts[:, 1] <= h - 1 - half) & (norm > 1e-3 * size))
    d = d / np.maximum(norm, 1e-6)[:, None]
    return d.astype(np.float32), valid


def _mutual_best(score: np.ndarray, min_ncc: float, margin: float) -> np.ndarray:
    """For a gated NCC matrix (Na, Nb) (-inf where not a candidate), the b index matched
    to each a (-1 for none): mutual best, >= min_ncc, and better than the second best in
    both its row and its column by ``margin``."""
    na, nb = score.shape
    out = np.full(na, -1, int)
    if na == 0 or nb == 0:
        return out
    rows = np.arange(na)
    best_b = np.argmax(score, axis=1)
    best = score[rows, best_b]
    best_a = np.argmax(score, axis=0)
    ok = (best_a[best_b] == rows) & (best >= min_ncc)
    if margin > 0:
        if nb > 1:
            second_row = np.partition(score, nb - 2, axis=1)[:, nb - 2]
        else:
            second_row = np.full(na, -np.inf)
        if na > 1:
            second_col = np.partition(score, na - 2, axis=0)[na - 2, :]
        else:
            second_col = np.full(nb, -np.inf)
        with np.errstate(invalid='ignore'):
            ok &= (best - second_row >= margin) & (best - second_col[best_b] >= margin)
    out[ok] = best_b[ok]
    return out


def match_stereo(left_pts: np.ndarray, left_desc: np.ndarray, right_pts: np.ndarray,
                 right_desc: np.ndarray, row_tol: float = 1.0, min_disparity: float = 0.5,
                 max_disparity: float = 120.0, min_ncc: float = 0.8, margin: float = 0.02
                 ) -> np.ndarray:
    """Left-to-right corner matches of a rectified pair.

    Candidates: ``|v_l - v_r| <= row_tol`` and ``min_disparity <= u_l - u_r <=
    max_disparity``; accepted: mutual best NCC, >= min_ncc, clear of the second best by
    ``margin``.

    Returns:
        (N_left,) int: the matched right corner index, -1 for none.
    """
    if len(left_pts) == 0 or len(right_pts) == 0:
        return np.full(len(left_pts), -1, int)
    dv = np.abs(left_pts[:, None, 1] - right_pts[None, :, 1])
    du = left_pts[:, None, 0] - right_pts[None, :, 0]
    gate = (dv <= row_tol) & (du >= min_disparity) & (du <= max_disparity)
    score = np.where(gate, left_desc @ right_desc.T, -np.inf)
    return _mutual_best(score, min_ncc, margin)


def match_temporal(prev_desc: np.ndarray, predicted: np.ndarray, curr_pts: np.ndarray,
                   curr_desc: np.ndarray, radius: float, min_ncc: float = 0.8,
                   margin: float = 0.02) -> np.ndarray:
    """Previous-to-current corner matches within ``radius`` px of the predicted positions.

    Args:
        prev_desc: (Np, D) windows of the previous corners.
        predicted: (Np, 2) where each previous corner is expected now (NaN: skip it).
        curr_pts, curr_desc: the current corners and their windows.
        radius: search radius, px.
    Returns:
        (Np,) int: the matched current corner index, -1 for none.
    """
    if len(predicted) == 0 or len(curr_pts) == 0:
        return np.full(len(predicted), -1, int)
    d2 = np.sum((predicted[:, None, :] - curr_pts[None, :, :]) ** 2, axis=-1)
    gate = np.nan_to_num(d2, nan=np.inf) <= radius * radius
    score = np.where(gate, prev_desc @ curr_desc.T, -np.inf)
    return _mutual_best(score, min_ncc, margin)


__all__ = ['DETECTORS', 'WB_DISPLACEMENT', 'detect_corners', 'shi_tomasi_corners',
           'wang_brady_corners', 'wang_brady_response', 'subpix_refine', 'corner_strength',
           'patches', 'match_stereo', 'match_temporal']
