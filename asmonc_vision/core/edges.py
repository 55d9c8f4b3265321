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

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .jit import jit, warmed
from .npfast import flat_nonzero

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


#: Immerkaer's (1996) noise mask, the difference of two 3x3 Laplacians. It is blind to
#: constant and linear intensity, and its response to white pixel noise of standard
#: deviation s has standard deviation 6 s (the root of the sum of its squared weights).
_NOISE_MASK = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
_NOISE_GAIN = 6.0
#: median |N(0, 1)|
_MEDIAN_ABS_NORMAL = 0.6744897501960817


def image_noise_sigma(image: np.ndarray, robust: bool = True) -> float:
    """The standard deviation of an image's pixel noise, grey levels.

    Immerkaer's estimator (J. Immerkaer, "Fast noise variance estimation", CVIU 64(2),
    1996), made robust: the median of the absolute response to ``_NOISE_MASK`` over the
    image (its border excluded), divided by that of white noise of unit deviation. Image
    structure (edges, texture) fills the tail of the responses and moves the median
    little, so a textured scene is not taken for a noisy one. The noise is assumed white
    and the same over the image.

    Args:
        image: (H, W) grey image, uint8 (an exact integer path) or any real dtype; at
            least 3 x 3.
        robust: the median (above); False: Immerkaer's own mean absolute response times
            sqrt(pi / 2), which image structure raises (float32 arithmetic).
    Returns:
        The noise standard deviation (>= 0), grey levels.
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 3 or img.shape[1] < 3:
        raise ValueError(f'image must be 2-D and at least 3 x 3, got shape {img.shape}')
    if not robust:
        r = cv2.filter2D(img.astype(np.float32), cv2.CV_32F, _NOISE_MASK)[1:-1, 1:-1]
        return math.sqrt(0.5 * math.pi) * float(np.abs(r).mean()) / _NOISE_GAIN
    if img.dtype == np.uint8:
        # |response| <= 16 * 255: int16 holds it exactly; the median from its histogram,
        # interpolated within the median's bin of unit width.
        r = cv2.filter2D(img, cv2.CV_16S, _NOISE_MASK)[1:-1, 1:-1]
        hist = np.bincount(np.abs(r).ravel())
        cum = np.cumsum(hist)
        half = 0.5 * float(cum[-1])
        k = int(np.searchsorted(cum, half))
        below = float(cum[k - 1]) if k else 0.0
        med = max(k - 0.5 + (half - below) / max(float(hist[k]), 1.0), 0.0)
    else:
        r = cv2.filter2D(img.astype(np.float32), cv2.CV_32F, _NOISE_MASK)[1:-1, 1:-1]
        med = float(np.median(np.abs(r)))
    return med / (_MEDIAN_ABS_NORMAL * _NOISE_GAIN)


def gradient_noise_gain(blur_sigma: float = 0.0) -> float:
    """The standard deviation of ``|dI/du|`` (as :func:`horizontal_gradient` and
    :func:`detect_vertical_edges` measure it, grey levels per pixel) per grey level of
    white pixel noise: the root of the sum of the squared weights of the normalised Sobel
    kernel, after the optional Gaussian pre-blur (sqrt(12) / 8 = 0.433 without).

    Args:
        blur_sigma: the edges' Gaussian pre-blur, pixels (0 = none).
    Returns:
        The gain (> 0), dimensionless.
    """
    if not blur_sigma > 0:
        return math.sqrt(12.0) * _SOBEL_NORM
    half = int(math.ceil(4.0 * blur_sigma)) + 1
    impulse = np.zeros((2 * half + 1, 2 * half + 1), np.float32)
    impulse[half, half] = 1.0
    kernel, _ = horizontal_gradient(impulse, blur_sigma)
    return float(np.sqrt(np.sum(kernel.astype(np.float64) ** 2)))


#: The densities of :func:`textured_edge_threshold` are candidates per row of the lower
#: half of the paper's 320 x 240 image: counts divided by these 120 rows. A larger image
#: needs as many edges for a ground plane, not as dense ones (and its faint texture gives
#: less gradient per pixel), so the counts are not scaled with the image size.
DENSITY_ROWS = 120.0


def textured_edge_threshold(image: np.ndarray, abs_threshold: float, *,
                            min_density: float, target_density: float, floor: float,
                            first_row_fraction: float = 0.5,
                            blur_sigma: float = 0.0) -> float:
    """The edge threshold for an image whose lower rows show too few vertical edges.

    Weakly textured ground (asphalt, plain concrete, large flags) has few vertical edges
    as strong as ``abs_threshold``, and without them there is no ground plane, or one
    through chance matches. The rows from ``first_row_fraction`` of the height down to
    the bottom (where a rig pitched down sees the near ground) are searched for edge
    candidates: maxima of ``|dI/du|`` along a row (as :func:`detect_vertical_edges` finds
    them, before its angle test). With at least ``min_density`` times ``DENSITY_ROWS`` of
    them at ``abs_threshold`` (a density per row of the paper's 320 x 240 image, whatever
    this image's size), that threshold is returned unchanged. Otherwise it is lowered
    until they number ``target_density`` times ``DENSITY_ROWS``, but not below ``floor``
    (set it from the pixel noise, e.g.
    a multiple of ``gradient_noise_gain() * image_noise_sigma()``, so that the edges
    added are texture, not noise; the target bounds the edges added if the noise is
    underestimated).

    Args:
        image: (H, W) grey image (uint8 or float).
        abs_threshold: the usual threshold, grey levels per pixel (>= 0).
        min_density: edge candidates per row of a 320 x 240 image's lower half (the
            count over ``DENSITY_ROWS``) below which the threshold is lowered (>= 0;
            0 = never lower).
        target_density: the same density that the lowered threshold keeps
            (>= min_density).
        floor: the least threshold returned, grey levels per pixel (>= 0).
        first_row_fraction: the first row searched, as a fraction of the height, [0, 1).
        blur_sigma: the edges' Gaussian pre-blur, pixels (0 = none).
    Returns:
        The threshold, grey levels per pixel: ``abs_threshold``, or a value in
        ``[floor, abs_threshold)`` (``abs_threshold`` when ``floor`` is not below it).
    Raises:
        ValueError: a non-2-D image, ``first_row_fraction`` outside [0, 1), or
            ``target_density`` below ``min_density``.
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f'image must be 2-D (H, W), got shape {img.shape}')
    if not 0.0 <= first_row_fraction < 1.0:
        raise ValueError(f'first_row_fraction must be in [0, 1), got {first_row_fraction}')
    if target_density < min_density:
        raise ValueError(f'target_density ({target_density}) must be at least '
                         f'min_density ({min_density})')
    thr = float(abs_threshold)
    h, w = img.shape
    if not min_density > 0 or h < 3 or w < 5 or not floor < thr:
        return thr
    r0 = min(max(int(first_row_fraction * h), 1), h - 2)
    band = img[r0 - 1:h]
    have = int(math.ceil(min_density * DENSITY_ROWS))
    need = int(math.ceil(target_density * DENSITY_ROWS))
    if img.dtype == np.uint8 and not blur_sigma > 0:
        # Integer Sobel sums (8 times |dI/du|, exact in float32 after / 8), compared as
        # detect_vertical_edges does. Most images have the edges: they are only counted.
        amag = np.abs(cv2.Sobel(band, cv2.CV_16S, 1, 0, ksize=3,
                                borderType=cv2.BORDER_REFLECT_101)[1:-1])
        thr_c = int(np.clip(np.ceil(np.float32(thr) * np.float32(8.0)), 0, 1021))
        if _nb_peak_count is not None and _nb_peak_count(amag, thr_c) >= have:
            return thr
        scale = np.float32(_SOBEL_NORM)
    else:
        amag = np.abs(horizontal_gradient(band, blur_sigma)[0][1:-1])
        scale = np.float32(1.0)
    c = amag[:, 2:-2]
    peaks = c[(c > amag[:, 1:-3]) & (c >= amag[:, 3:-1])].astype(np.float32) * scale
    if int(np.count_nonzero(peaks >= np.float32(thr))) >= have:
        return thr
    if peaks.size < need:
        return max(float(floor), 0.0)
    # The need-th strongest candidate, as the threshold that keeps need of them.
    t_need = float(np.partition(peaks, peaks.size - need)[peaks.size - need])
    return min(thr, max(float(floor), t_need, 0.0))


def _peak_count_kernel(amag, thr_c):
    """The number of row maxima (strictly above the left neighbour, not below the right
    one) of at least ``thr_c`` in the integer |Sobel sums| ``amag`` (H, W) int16, columns
    2 to W - 3 of every row (for numba; the numpy path of `textured_edge_threshold`)."""
    h, w = amag.shape
    n = 0
    for r in range(h):
        row = amag[r]
        for c in range(2, w - 2):
            m = row[c]
            n += np.int64((m > row[c - 1]) & (m >= row[c + 1]) & (m >= thr_c))
    return n


def detect_vertical_edges(image: np.ndarray, *, abs_threshold: float = 4.0,
                          rel_threshold: float = 0.0, max_angle_deg: float = 60.0,
                          min_string_length: int = 1, blur_sigma: float = 0.0) -> EdgeMap:
    """Vertical edges of a grey image, with sub-pixel position, polarity and strings.

    A pixel is an edge when its ``|dI/du|`` is a maximum along its row (strictly greater
    than the left neighbour, not less than the right one), at least the threshold
    ``max(abs_threshold, rel_threshold * mean(|dI/du|))``, and the edge is within
    ``max_angle_deg`` of vertical (gradient within that angle of horizontal). The first
    and last rows, and the first and last two columns, are never edges.

    A uint8 image without blur takes an integer path (16-bit Sobel sums, exactly 8 times
    the float derivatives) with the same result as the float path.

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
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f'image must be 2-D (H, W), got shape {img.shape}')
    thr = float(abs_threshold)
    if img.dtype == np.uint8 and not blur_sigma > 0:
        # Integer Sobel sums (|sum| <= 1020): the float derivative is sum / 8 exactly.
        sx = cv2.Sobel(img, cv2.CV_16S, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT_101)
        amag = np.abs(sx)
        gx_flat, gy_src, mag_flat, scale = sx.ravel(), img, amag.ravel(), np.float32(_SOBEL_NORM)
        if rel_threshold > 0:
            thr = max(thr, float(rel_threshold) * float((amag * scale).mean()))
    else:
        gx, gy = horizontal_gradient(img, blur_sigma)
        amag = np.abs(gx)
        gx_flat, gy_src, mag_flat, scale = gx.ravel(), gy, amag.ravel(), None
        if rel_threshold > 0:
            thr = max(thr, float(rel_threshold) * float(amag.mean()))
    h, w = img.shape
    if h < 3 or w < 3:
        return _empty(h, w, thr)
    # Non-maximum suppression along rows. The Sobel response of the first and last two
    # columns is distorted by the border reflection, so edges start at column 2.
    if w < 5:
        return _empty(h, w, thr)
    c = amag[1:-1, 2:-2]
    left = amag[1:-1, 1:-3]
    right = amag[1:-1, 3:-1]
    if scale is not None:
        # |sum| / 8 >= float32(thr)  <=>  |sum| >= ceil(8 * float32(thr)) (as the float
        # path compares in single precision).
        t8 = np.float32(thr) * np.float32(8.0)
        thr_c: float = 1021 if np.isnan(t8) else int(np.clip(np.ceil(t8), -1, 1021))
    else:
        thr_c = thr
    # Angle of the edge from the vertical = angle of the gradient from the horizontal.
    cos_max = np.cos(np.deg2rad(min(max(max_angle_deg, 0.0), 90.0)))
    if scale is not None and _nb_edges is not None:
        # The same edges, sub-pixel positions and strings in one compiled pass (integer
        # Sobel sums s: (s / 8)^2 >= cos^2 (...) / 64 scales exactly by 64).
        vv, uu, u_sub, peak, pol, gxe, gye, sid, prev, slen, curv = _nb_edges(
            amag, gy_src, sx, int(thr_c), float(cos_max * cos_max),
            int(max(min_string_length, 1)))
        ori = np.arctan2(gye, gxe).astype(np.float32)
        return EdgeMap(v=vv, u_int=uu, u=u_sub, strength=peak, polarity=pol,
                       orientation=ori, string_id=sid, string_prev=prev,
                       string_length=slen, shape=(h, w), threshold=thr, curvature=curv)
    return _edges_numpy(c, left, right, thr_c, thr, h, w, scale, gx_flat, gy_src, mag_flat,
                        cos_max, min_string_length)


def _edges_numpy(c, left, right, thr_c, thr: float, h: int, w: int, scale, gx_flat, gy_src,
                 mag_flat, cos_max: float, min_string_length: int) -> EdgeMap:
    """`detect_vertical_edges`'s numpy path from the row maxima on: the edges, their
    sub-pixel positions, strength and strings (``scale``: the integer Sobel path's)."""
    k = flat_nonzero((c > left) & (c >= right) & (c >= thr_c))
    vv = (k // (w - 4) + 1).astype(np.int32)
    uu = (k % (w - 4) + 2).astype(np.int32)
    flat = vv.astype(np.intp) * w + uu
    if scale is not None:
        gxe = gx_flat[flat] * scale
        gye = _sobel_v_at(gy_src, vv, uu) * scale
        ml = mag_flat[flat - 1] * scale
        mr = mag_flat[flat + 1] * scale
    else:
        gxe = gx_flat[flat]
        gye = gy_src.ravel()[flat]
        ml = mag_flat[flat - 1]
        mr = mag_flat[flat + 1]
    keep = gxe * gxe >= (cos_max * cos_max) * (gxe * gxe + gye * gye)
    if not keep.all():
        sel = flat_nonzero(keep)
        vv, uu, gxe, gye, ml, mr = (a[sel] for a in (vv, uu, gxe, gye, ml, mr))
    mc = np.abs(gxe)
    denom = ml - 2.0 * mc + mr          # < 0 at a strict maximum
    with np.errstate(divide='ignore', invalid='ignore'):
        off = np.where(denom < 0, 0.5 * (ml - mr) / denom, 0.0)
    off = np.clip(off, -0.5, 0.5).astype(np.float32)
    u_sub = uu.astype(np.float32) + off
    pol = np.where(gxe >= 0, 1, -1).astype(np.int8)
    sid, slen, prev = _link_strings(vv, uu, u_sub, pol, h, w)
    if min_string_length > 1 and sid.size:
        keep = slen[sid] >= min_string_length
        if not keep.all():
            sel = flat_nonzero(keep)
            kept_strings = np.zeros(slen.shape[0], bool)
            kept_strings[sid[sel]] = True
            new_id = np.cumsum(kept_strings, dtype=np.int32) - 1
            new_index = np.full(keep.shape[0], -1, np.int32)
            new_index[sel] = np.arange(sel.size, dtype=np.int32)
            kept: list[np.ndarray] = [a[sel] for a in (vv, uu, u_sub, pol, prev, gxe, gye, ml,
                                                       mr, mc, denom, off)]
            vv, uu, u_sub, pol, prev, gxe, gye, ml, mr, mc, denom, off = kept
            prev = np.where(prev >= 0, new_index[np.maximum(prev, 0)], -1).astype(np.int32)
            sid = new_id[sid[sel]]
            slen = slen[kept_strings]
    curv = np.maximum(-denom, 0.0).astype(np.float32)
    peak = (mc - 0.25 * (ml - mr) * off).astype(np.float32)
    ori = np.arctan2(gye, gxe).astype(np.float32)
    return EdgeMap(v=vv, u_int=uu, u=u_sub, strength=peak, polarity=pol, orientation=ori,
                   string_id=sid.astype(np.int32), string_prev=prev.astype(np.int32),
                   string_length=slen.astype(np.int32), shape=(h, w), threshold=thr,
                   curvature=curv)


def _sobel_v_at(img: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The 3x3 Sobel sum along v (8 * dI/dv) of a uint8 image at interior pixels,
    float32 (exact)."""
    w = img.shape[1]
    f = img.ravel()
    below = (v.astype(np.intp) + 1) * w + u
    above = below - 2 * w
    lo = f[below - 1].astype(np.int16) + 2 * f[below].astype(np.int16) + f[below + 1]
    hi = f[above - 1].astype(np.int16) + 2 * f[above].astype(np.int16) + f[above + 1]
    return (lo - hi).astype(np.float32)


def _empty(h: int, w: int, thr: float) -> EdgeMap:
    i = np.zeros(0, np.int32)
    f = np.zeros(0, np.float32)
    return EdgeMap(v=i, u_int=i, u=f, strength=f, polarity=np.zeros(0, np.int8),
                   orientation=f, string_id=i, string_prev=i, string_length=i, shape=(h, w),
                   threshold=thr, curvature=f)


def chain_roots(parent: np.ndarray) -> np.ndarray:
    """The root of every element of a forest of chains, by pointer jumping.

    Args:
        parent: (N,) int index of each element's parent, -1 at a root.
    Returns:
        (N,) int64 index of the root each element's chain ends at.
    """
    root = np.where(parent >= 0, parent, np.arange(parent.shape[0]))
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


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
    # Edge index + 1 per pixel (0: none), padded by a row above and a column each side,
    # one plane per polarity (parents share the child's polarity).
    wp = w + 2
    size = (h + 1) * wp
    idx = np.zeros(2 * size, np.int32)
    flat = (v.astype(np.intp) + 1) * wp + u + 1 + size * (pol < 0)
    idx[flat] = np.arange(1, n + 1, dtype=np.int32)
    # Candidate parents in the row above: same column first, then the nearer diagonal.
    up = flat - wp
    p0 = idx[up].astype(np.intp) - 1
    pl = idx[up - 1].astype(np.intp) - 1
    pr = idx[up + 1].astype(np.intp) - 1
    ok0, okl, okr = p0 >= 0, pl >= 0, pr >= 0
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
    root = chain_roots(parent)
    is_root = root == np.arange(n)
    new_id = np.cumsum(is_root, dtype=np.int32) - 1
    sid = new_id[root]
    slen = np.bincount(sid, minlength=int(new_id[-1]) + 1).astype(np.int32)
    return sid, slen, parent.astype(np.int32)


def _maxima_kernel(amag, img, sx, thr_c, cos2):
    """The uint8 path's row maxima and angle test as loops (for numba), with integer
    Sobel sums: returns (v, u, s_u, s_v, s_left, s_right) int32 of the kept edges in
    (v, u) order, s_u the sum along u at the edge, s_v the sum along v, s_left and
    s_right the |sum along u| of its row neighbours (all 8 times the derivatives)."""
    h, w = amag.shape
    cap = (h - 2) * (w - 4) + 1
    ov = np.empty(cap, np.int32)
    ou = np.empty(cap, np.int32)
    osx = np.empty(cap, np.int32)
    osy = np.empty(cap, np.int32)
    oml = np.empty(cap, np.int32)
    omr = np.empty(cap, np.int32)
    # First pass: the maxima's positions. The threshold first: most pixels fail it (a
    # well-predicted branch, faster than writing every pixel's position branch-free).
    k = 0
    for r in range(1, h - 1):
        for c in range(2, w - 2):
            m = amag[r, c]
            if m >= thr_c and m > amag[r, c - 1] and m >= amag[r, c + 1]:
                ov[k] = r
                ou[k] = c
                k += 1
    n = 0
    for i in range(k):
        r = ov[i]
        c = ou[i]
        gx = np.int32(sx[r, c])
        gy = (np.int32(img[r + 1, c - 1]) + 2 * np.int32(img[r + 1, c])
              + np.int32(img[r + 1, c + 1])
              - np.int32(img[r - 1, c - 1]) - 2 * np.int32(img[r - 1, c])
              - np.int32(img[r - 1, c + 1]))
        gx2 = np.float64(gx * gx)
        if gx2 >= cos2 * (gx2 + np.float64(gy * gy)):
            ov[n] = r
            ou[n] = c
            osx[n] = gx
            osy[n] = gy
            oml[n] = amag[r, c - 1]
            omr[n] = amag[r, c + 1]
            n += 1
    return ov[:n], ou[:n], osx[:n], osy[:n], oml[:n], omr[:n]


def _link_kernel(v, u, u_sub, pol, w):
    """:func:`_link_strings` as loops over the rows (for numba), with the same rules and
    float32 comparisons: returns (string_id, string_length, parent) int32."""
    n = v.shape[0]
    wp = w + 2
    above = np.full((2, wp), -1, np.int64)     # edge index per (polarity, column + 1)
    parent = np.full(n, -1, np.int32)
    via = np.zeros(n, np.int8)                 # 1: diagonal parent up-left, 2: up-right
    straight = np.zeros(n, np.bool_)
    cost_l = np.full(n, np.inf, np.float32)
    cost_r = np.full(n, np.inf, np.float32)
    sid = np.empty(n, np.int32)
    slen = np.zeros(n, np.int32)
    ns = 0
    a0 = 0
    a1 = 0                                     # the edges in `above`: a0..a1-1
    i = 0
    while i < n:
        row = v[i]
        j = i
        while j < n and v[j] == row:
            j += 1
        if a1 > a0 and v[a0] != row - 1:       # the row above has no edges
            for k in range(a0, a1):
                above[0 if pol[k] > 0 else 1, u[k] + 1] = -1
            a0 = a1 = i
        for k in range(i, j):
            p = 0 if pol[k] > 0 else 1
            c = u[k] + 1
            p0 = above[p, c]
            pl = above[p, c - 1]
            pr = above[p, c + 1]
            dl = np.float32(0.0)
            dr = np.float32(0.0)
            if pl >= 0:
                dl = abs(u_sub[pl] - u_sub[k])
            if pr >= 0:
                dr = abs(u_sub[pr] - u_sub[k])
            if p0 >= 0:
                parent[k] = p0
                straight[p0] = True
            elif pl >= 0 and (pr < 0 or dl <= dr):
                parent[k] = pl
                via[k] = 1
                cost_l[pl] = dl
            elif pr >= 0:
                parent[k] = pr
                via[k] = 2
                cost_r[pr] = dr
        for k in range(i, j):
            q = parent[k]
            if via[k] == 1 and (straight[q] or cost_r[q] < cost_l[q]):
                parent[k] = -1
            elif via[k] == 2 and (straight[q] or cost_l[q] <= cost_r[q]):
                parent[k] = -1
            if parent[k] >= 0:
                sid[k] = sid[parent[k]]
            else:
                sid[k] = ns
                ns += 1
            slen[sid[k]] += 1
        for k in range(a0, a1):
            above[0 if pol[k] > 0 else 1, u[k] + 1] = -1
        for k in range(i, j):
            above[0 if pol[k] > 0 else 1, u[k] + 1] = k
        a0 = i
        a1 = j
        i = j
    return sid, slen[:ns].copy(), parent


_nb_maxima = jit(_maxima_kernel)
_nb_link = jit(_link_kernel)


def _edges_kernel(amag, img, sx, thr_c, cos2, min_len):
    """The uint8 path of :func:`detect_vertical_edges` after the Sobel sums, as loops
    (for numba), with the numpy path's float32 arithmetic: returns (v, u_int, u,
    strength, polarity, gx, gy, string_id, string_prev, string_length, curvature), gx and
    gy the float32 derivatives (for the orientation)."""
    w = amag.shape[1]
    vv, uu, sxe, sye, sml, smr = _nb_maxima(amag, img, sx, thr_c, cos2)
    n = vv.shape[0]
    eighth = np.float32(0.125)
    gxe = np.empty(n, np.float32)
    gye = np.empty(n, np.float32)
    u_sub = np.empty(n, np.float32)
    peak = np.empty(n, np.float32)
    curv = np.empty(n, np.float32)
    pol = np.empty(n, np.int8)
    for i in range(n):
        gx = np.float32(sxe[i]) * eighth
        ml = np.float32(sml[i]) * eighth
        mr = np.float32(smr[i]) * eighth
        mc = abs(gx)
        denom = ml - np.float32(2.0) * mc + mr          # < 0 at a strict maximum
        off = np.float32(0.0)
        if denom < 0:
            off = np.float32(0.5) * (ml - mr) / denom
            off = min(max(off, np.float32(-0.5)), np.float32(0.5))
        gxe[i] = gx
        gye[i] = np.float32(sye[i]) * eighth
        u_sub[i] = np.float32(uu[i]) + off
        peak[i] = mc - np.float32(0.25) * (ml - mr) * off
        curv[i] = max(-denom, np.float32(0.0))
        pol[i] = 1 if gx >= 0 else -1
    sid, slen, prev = _nb_link(vv, uu, u_sub, pol, w)
    if n == 0 or min_len <= 1:
        return vv, uu, u_sub, peak, pol, gxe, gye, sid, prev, slen, curv
    # Drop the short strings; renumber strings and parents in order.
    new_id = np.full(slen.shape[0], -1, np.int32)
    ns = 0
    for s in range(slen.shape[0]):
        if slen[s] >= min_len:
            new_id[s] = ns
            ns += 1
    new_index = np.full(n, -1, np.int32)
    m = 0
    for i in range(n):
        if new_id[sid[i]] >= 0:
            new_index[i] = m
            m += 1
    if m == n:
        return vv, uu, u_sub, peak, pol, gxe, gye, sid, prev, slen, curv
    o_slen = np.empty(ns, np.int32)
    for s in range(slen.shape[0]):
        if new_id[s] >= 0:
            o_slen[new_id[s]] = slen[s]
    j = 0
    for i in range(n):
        if new_index[i] >= 0:
            vv[j] = vv[i]
            uu[j] = uu[i]
            u_sub[j] = u_sub[i]
            peak[j] = peak[i]
            pol[j] = pol[i]
            gxe[j] = gxe[i]
            gye[j] = gye[i]
            curv[j] = curv[i]
            prev[j] = new_index[prev[i]] if prev[i] >= 0 else -1
            sid[j] = new_id[sid[i]]
            j += 1
    return (vv[:m], uu[:m], u_sub[:m], peak[:m], pol[:m], gxe[:m], gye[:m], sid[:m],
            prev[:m], o_slen, curv[:m])


_nb_edges = jit(_edges_kernel) if _nb_maxima is not None else None
_nb_peak_count = jit(_peak_count_kernel)


def warm_up() -> bool:
    """Compile (or load from numba's disk cache) the edge kernel on a tiny image, so
    that the first frame does not pay for it; without numba, or if compiling fails, the
    numpy path is used. Returns whether numba is in use."""
    global _nb_edges, _nb_peak_count
    img = np.zeros((3, 5), np.uint8)
    s = np.zeros((3, 5), np.int16)
    _nb_edges = warmed(_nb_edges, s, img, s, 1, 0.5, 3)
    _nb_peak_count = warmed(_nb_peak_count, s, 1)
    return _nb_edges is not None
