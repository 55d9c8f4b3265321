"""Debug drawing of a GPOD result over the left image (OpenCV, BGR)."""
from __future__ import annotations

import cv2
import numpy as np

from .gpod import GpodResult

#: BGR colours.
_GREY = (160, 160, 160)
_RED = (0, 0, 255)
_BLUE = (255, 128, 0)
_WHITE = (255, 255, 255)
_BLACK = (0, 0, 0)
_STATUS_COLOUR = {'initialising': (0, 200, 255), 'tracking': (0, 200, 0), 'lost': (0, 0, 255)}


def excess_colours(excess: np.ndarray, threshold_px: float) -> np.ndarray:
    """BGR colour per feature from its disparity excess over the ground plane.

    Ground features (|excess| < threshold) run from green (0) to yellow (at the
    threshold, either sign); above the threshold orange to red; below it (drops)
    cyan to blue. NaN (no plane) is grey.

    Args:
        excess: (K,) disparity minus plane disparity, pixels (NaN allowed).
        threshold_px: obstacle threshold, pixels (> 0).
    Returns:
        (K, 3) uint8 BGR.
    """
    e = np.asarray(excess, np.float64)
    k = e.shape[0]
    out = np.empty((k, 3), np.float64)
    out[:] = _GREY
    t = max(float(threshold_px), 1e-6)
    ok = np.isfinite(e)
    r = np.zeros(k)
    r[ok] = e[ok] / t
    g_ = ok & (np.abs(r) <= 1.0)
    a = np.abs(r[g_])
    out[g_] = np.stack([np.zeros_like(a), np.full_like(a, 220.0), 220.0 * a], axis=1)
    hi = ok & (r > 1.0)
    s = np.clip((r[hi] - 1.0) / 2.0, 0.0, 1.0)
    out[hi] = np.stack([np.zeros_like(s), 165.0 * (1.0 - s), np.full_like(s, 255.0)], axis=1)
    lo = ok & (r < -1.0)
    s = np.clip((-r[lo] - 1.0) / 2.0, 0.0, 1.0)
    out[lo] = np.stack([np.full_like(s, 255.0), 255.0 * (1.0 - s), np.zeros_like(s)], axis=1)
    return out.astype(np.uint8)


def draw_debug(left_gray: np.ndarray, result: GpodResult) -> np.ndarray:
    """The left image with matched edges coloured by excess, obstacles and status.

    Matched edge pixels are coloured by :func:`excess_colours` (pixels of obstacle
    strings drawn in full red, drop strings in blue); each obstacle gets its ROI and a
    label "height cm / range m" (drops "drop cm / range m"); the status, plane and
    timing are written at the top left.

    Args:
        left_gray: (H, W) uint8 left image.
        result: the GpodResult of this image pair.
    Returns:
        (H, W, 3) uint8 BGR image.
    """
    img = np.asarray(left_gray)
    if img.ndim != 2:
        raise ValueError(f'left_gray must be (H, W), got shape {img.shape}')
    out = cv2.cvtColor(img.astype(np.uint8, copy=False), cv2.COLOR_GRAY2BGR)
    h, w = img.shape
    f = result.features
    if len(f):
        col = excess_colours(f.excess, result.threshold_px)
        col[f.string_class > 0] = _RED
        col[f.string_class < 0] = _BLUE
        uu = np.clip(np.rint(f.u_left).astype(np.int64), 0, w - 1)
        vv = np.clip(f.v.astype(np.int64), 0, h - 1)
        out[vv, uu] = col
    scale = max(0.35, min(w, h) / 600.0)
    thick = 1 if min(w, h) < 600 else 2
    for ob in result.obstacles:
        x, y, bw, bh = ob.roi
        colour = _BLUE if ob.is_drop else _RED
        cv2.rectangle(out, (int(x), int(y)), (int(x + bw - 1), int(y + bh - 1)), colour, thick)
        label = (f'drop {-ob.height * 100:.0f}cm {ob.range:.1f}m' if ob.is_drop
                 else f'{ob.height * 100:.0f}cm {ob.range:.1f}m')
        ty = int(y) - 3 if y > 12 else int(y + bh + 10)
        _text(out, label, (int(x), ty), scale, colour, thick)
    status = result.status.upper()
    if result.plane_abc is not None:
        a, b, c = result.plane_abc
        status += f'  d={a:.3f}u+{b:.3f}v{c:+.1f}'
    if result.metric_plane is not None:
        status += f'  h={result.metric_plane.height:.2f}m'
    _text(out, status, (4, int(14 * scale / 0.35 * 0.9) + 2), scale,
          _STATUS_COLOUR.get(result.status, _WHITE), thick)
    tot = result.timings_ms.get('total')
    info = f'{len(f)} matches  {len(result.obstacles)} obstacles'
    if tot is not None:
        info += f'  {tot:.0f} ms'
    _text(out, info, (4, int(28 * scale / 0.35 * 0.9) + 2), scale, _WHITE, thick)
    return out


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float,
          colour: tuple[int, int, int], thick: int) -> None:
    """Text with a dark outline so that it reads on any background."""
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, _BLACK, thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)
