"""Vertical edges and edge strings, as the features of GPOD (Molton et al. 1998, Sec. 2.1).

Vertical edges are found with the horizontal-gradient Sobel operator (which responds to
vertical edges), thinned by non-maximum suppression along each row, thresholded on the
gradient magnitude, and located to sub-pixel accuracy by a parabola through the gradient
magnitude of the maximum and its two row neighbours. Each edge carries its polarity (sign
of the horizontal gradient) and orientation (gradient direction from the Sobel pair).

Edge *strings* are chains of vertically connected edge pixels: an edge in row v links to
an edge of the same polarity in row v-1 whose column differs by at most one pixel. Each
edge links to at most one edge above and one below (the nearest in sub-pixel column), so
strings are simple chains, not trees. The paper's rule "an edge string is an obstacle if
any of its pixels is" works on these strings.

Everything is vectorised with numpy/OpenCV; the only Python loop is over the log2 of the
longest string length (pointer jumping).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: Sobel 3x3 normalisation: the kernel sums |weights| to 8 on each side, so that
#: ``sobel / 8`` is the intensity derivative in grey levels per pixel.
_SOBEL_NORM = 1.0 / 8.0


@dataclass(frozen=True)
class EdgeMap:
    """Vertical edge pixels of one image, sorted by (row, column).

    Attributes:
        v: (N,) int32 image row of each edge pixel.
        u_int: (N,) int32 image column of the non-maximum-suppression maximum.
        u: (N,) float32 sub-pixel column (pixels, same origin as ``u_int``), within
            ``u_int +- 0.5``.
        strength: (N,) float32 peak magnitude of the horizontal intensity derivative,
            grey levels per pixel (parabola vertex value).
        polarity: (N,) int8, +1 when the image gets brighter to the right, -1 darker.
        orientation: (N,) float32 gradient direction ``atan2(dI/dv, dI/du)`` in radians,
            (-pi, pi]; 0 for a vertical dark-to-bright edge, pi for bright-to-dark.
        string_id: (N,) int32 edge-string id, 0..S-1.
        string_prev: (N,) int32 index of the edge above in the same string (row v-1),
            -1 at the top of a string.
        string_length: (S,) int32 number of pixels of each string.
        shape: (H, W) of the image.
        threshold: magnitude threshold that was applied, grey levels per pixel.
        curvature: (N,) float32 ``2*m(u) - m(u-1) - m(u+1)`` of the gradient magnitude m
            at the maximum (> 0), grey levels per pixel^3: the sub-pixel position's noise
            is about ``0.7 * gradient noise / curvature`` pixels, so it measures how
            precisely the edge is located (sharp, contrasted edges: large). None if not
            computed.
    """

    v: np.ndarray
    u_int: np.ndarray
    u: np.ndarray
    strength: np.ndarray
    polarity: np.ndarray
    orientation: np.ndarray
    string_id: np.ndarray
    string_prev: np.ndarray
    string_length: np.ndarray
    shape: tuple[int, int]
    threshold: float
    curvature: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.v.shape[0])

    @property
    def num_strings(self) -> int:
        """Number of edge strings S."""
        return int(self.string_length.shape[0])


def horizontal_gradient(image: np.ndarray,
                        blur_sigma: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Sobel derivatives of an image, in grey levels per pixel.

    Args:
        image: (H, W) grey image, any real dtype (uint8 typically).
        blur_sigma: standard deviation (pixels) of an optional Gaussian pre-blur; 0 = none.
    Returns:
        (gx, gy): (H, W) float32 derivatives along u (columns) and v (rows).
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f'image must be 2-D (H, W), got shape {img.shape}')
    img = img.astype(np.float32, copy=False)
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), float(blur_sigma))
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, scale=_SOBEL_NORM,
                   borderType=cv2.BORDER_REFLECT_101)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, scale=_SOBEL_NORM,
                   borderType=cv2.BORDER_REFLECT_101)
    return gx, gy


def detect_vertical_edges(image: np.ndarray, *, abs_threshold: float = 4.0,
                          rel_threshold: float = 0.0, max_angle_deg: float = 60.0,
                          min_string_length: int = 1, blur_sigma: float = 0.0) -> EdgeMap:
    """Vertical edges of a grey image, with sub-pixel position, polarity and strings.

    A pixel is an edge when its ``|dI/du|`` is a maximum along its row (strictly greater
    than the left neighbour, not less than the right one), at least the threshold
    ``max(abs_threshold, rel_threshold * mean(|dI/du|))``, and the edge is within
    ``max_angle_deg`` of vertical (gradient within that angle of horizontal). The first
    and last rows, and the first and last two columns, are never edges.

    Args:
        image: (H, W) grey image (uint8 or float).
        abs_threshold: absolute magnitude threshold, grey levels per pixel (>= 0).
        rel_threshold: threshold relative to the image contrast, as a multiple of the
            mean ``|dI/du|`` over the image (>= 0; 0 disables it).
        max_angle_deg: largest angle of an edge from the vertical, degrees (0..90].
        min_string_length: edges of strings shorter than this (pixels) are dropped.
        blur_sigma: Gaussian pre-blur sigma, pixels (0 = none).
    Returns:
        The EdgeMap, sorted by (v, u_int), string ids relabelled 0..S-1.
    """
    gx, gy = horizontal_gradient(image, blur_sigma)
    h, w = gx.shape
    mag = np.abs(gx)
    thr = float(abs_threshold)
    if rel_threshold > 0:
        thr = max(thr, float(rel_threshold) * float(mag.mean()))
    if h < 3 or w < 3:
        return _empty(h, w, thr)
    # Non-maximum suppression along rows. The Sobel response of the first and last two
    # columns is distorted by the border reflection, so edges start at column 2.
    if w < 5:
        return _empty(h, w, thr)
    c = mag[1:-1, 2:-2]
    left = mag[1:-1, 1:-3]
    right = mag[1:-1, 3:-1]
    cand = (c > left) & (c >= right) & (c >= thr)
    vv, uu = np.nonzero(cand)
    vv = vv.astype(np.int32) + 1
    uu = uu.astype(np.int32) + 2
    gxe = gx[vv, uu]
    gye = gy[vv, uu]
    # Angle of the edge from the vertical = angle of the gradient from the horizontal.
    cos_max = np.cos(np.deg2rad(min(max(max_angle_deg, 0.0), 90.0)))
    keep = gxe * gxe >= (cos_max * cos_max) * (gxe * gxe + gye * gye)
    if not keep.all():
        vv, uu, gxe, gye = vv[keep], uu[keep], gxe[keep], gye[keep]
    ml = mag[vv, uu - 1]
    mc = np.abs(gxe)
    mr = mag[vv, uu + 1]
    denom = ml - 2.0 * mc + mr          # < 0 at a strict maximum
    with np.errstate(divide='ignore', invalid='ignore'):
        off = np.where(denom < 0, 0.5 * (ml - mr) / denom, 0.0)
    off = np.clip(off, -0.5, 0.5).astype(np.float32)
    curv = np.maximum(-denom, 0.0).astype(np.float32)
    peak = (mc - 0.25 * (ml - mr) * off).astype(np.float32)
    u_sub = uu.astype(np.float32) + off
    pol = np.where(gxe >= 0, 1, -1).astype(np.int8)
    ori = np.arctan2(gye, gxe).astype(np.float32)
    sid, slen, prev = _link_strings(vv, uu, u_sub, pol, h, w)
    if min_string_length > 1 and sid.size:
        keep = slen[sid] >= min_string_length
        kept_strings = np.zeros(slen.shape[0], bool)
        kept_strings[sid[keep]] = True
        new_id = np.cumsum(kept_strings, dtype=np.int32) - 1
        new_index = np.cumsum(keep, dtype=np.int32) - 1
        vv, uu, u_sub, peak, pol, ori, prev, curv = (
            a[keep] for a in (vv, uu, u_sub, peak, pol, ori, prev, curv))
        prev = np.where(prev >= 0, new_index[np.maximum(prev, 0)], -1).astype(np.int32)
        sid = new_id[sid[keep]]
        slen = slen[kept_strings]
    return EdgeMap(v=vv, u_int=uu, u=u_sub, strength=peak, polarity=pol, orientation=ori,
                   string_id=sid.astype(np.int32), string_prev=prev.astype(np.int32),
                   string_length=slen.astype(np.int32), shape=(h, w), threshold=thr,
                   curvature=curv)


def _empty(h: int, w: int, thr: float) -> EdgeMap:
    i = np.zeros(0, np.int32)
    f = np.zeros(0, np.float32)
    return EdgeMap(v=i, u_int=i, u=f, strength=f, polarity=np.zeros(0, np.int8),
                   orientation=f, string_id=i, string_prev=i, string_length=i, shape=(h, w),
                   threshold=thr, curvature=f)


def _link_strings(v: np.ndarray, u: np.ndarray, u_sub: np.ndarray, pol: np.ndarray,
                  h: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chain edges into strings (same polarity, consecutive rows, |du| <= 1).

    Args:
        v, u: (N,) int32 rows and columns of the edges, sorted by (v, u).
        u_sub: (N,) float32 sub-pixel columns.
        pol: (N,) int8 polarities.
        h, w: image size.
    Returns:
        (string_id (N,) int32 in 0..S-1 numbered by first pixel, string_length (S,) int32,
        parent (N,) int32 index of the edge above in the string or -1).
    """
    n = v.shape[0]
    if n == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, np.int32)
    idx = np.full((h, w), -1, np.int32)
    idx[v, u] = np.arange(n, dtype=np.int32)
    # Candidate parents in the row above: same column first, then the nearer diagonal.
    vp = np.maximum(v - 1, 0)
    ul = np.maximum(u - 1, 0)
    ur = np.minimum(u + 1, w - 1)
    above = v > 0
    p0 = np.where(above, idx[vp, u], -1)
    pl = np.where(above, idx[vp, ul], -1)
    pr = np.where(above, idx[vp, ur], -1)

    def valid(p: np.ndarray) -> np.ndarray:
        """Parent candidates that exist and share the child's polarity."""
        return (p >= 0) & (pol[np.maximum(p, 0)] == pol)

    ok0, okl, okr = valid(p0), valid(pl), valid(pr)
    dl = np.abs(u_sub[np.maximum(pl, 0)] - u_sub)
    dr = np.abs(u_sub[np.maximum(pr, 0)] - u_sub)
    use_l = okl & (~okr | (dl <= dr))
    parent = np.where(ok0, p0, np.where(use_l, pl, np.where(okr, pr, -1)))
    # A parent keeps only its nearest child (strings are chains, not trees): a child
    # straight below always wins; of two diagonal children, the nearer in sub-pixel u.
    via_l = ~ok0 & use_l
    via_r = ~ok0 & ~use_l & okr
    straight = np.zeros(n, bool)
    straight[p0[ok0]] = True
    cost_l = np.full(n, np.inf, np.float32)
    cost_r = np.full(n, np.inf, np.float32)
    cost_l[pl[via_l]] = dl[via_l]
    cost_r[pr[via_r]] = dr[via_r]
    lose_l = via_l & (straight[pl] | (cost_r[pl] < cost_l[pl]))
    lose_r = via_r & (straight[pr] | (cost_l[pr] <= cost_r[pr]))
    parent[lose_l | lose_r] = -1
    # Root of every chain by pointer jumping.
    root = np.where(parent >= 0, parent, np.arange(n, dtype=np.int32)).astype(np.int32)
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    is_root = root == np.arange(n)
    new_id = np.cumsum(is_root, dtype=np.int32) - 1
    sid = new_id[root]
    slen = np.bincount(sid, minlength=int(new_id[-1]) + 1).astype(np.int32)
    return sid, slen, parent.astype(np.int32)
