"""The binned second pass on large images: the 2 x 2 binned pair and camera
(`bin_pair`), and whether a coarse obstacle is consistent with the full-size matches.
"""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from ..camera import StereoCamera
from .results import GpodFeatures, GpodObstacle


def bin_pair(left: np.ndarray, right: np.ndarray, cam: StereoCamera
             ) -> tuple[np.ndarray, np.ndarray, StereoCamera]:
    """A rectified pair binned 2 x 2, and its camera.

    Each binned pixel is the mean of a 2 x 2 block (an odd last row or column is dropped),
    so a faint texture's gradient per pixel doubles while the pixel noise halves. The
    binned pixel (i, j) is centred on the full-size point (2 i + 0.5, 2 j + 0.5): f
    halves and the principal point moves to ((cx - 0.5) / 2, (cy - 0.5) / 2), so points
    triangulated in the binned pair lie in the same left optical frame, metres.

    Args:
        left, right: (H, W) uint8 rectified images, H, W >= 2.
        cam: their camera.
    Returns:
        (left, right) (H // 2, W // 2) uint8, and the binned camera.
    """
    h, w = cam.height // 2, cam.width // 2
    if h < 1 or w < 1:
        raise ValueError(f'cannot bin a {cam.width}x{cam.height} pair 2 x 2')
    out = tuple(cv2.resize(np.ascontiguousarray(img[:2 * h, :2 * w]), (w, h),
                           interpolation=cv2.INTER_AREA) for img in (left, right))
    cam_b = dataclasses.replace(cam, f=cam.f / 2.0, cx=(cam.cx - 0.5) / 2.0,
                                cy=(cam.cy - 0.5) / 2.0, width=w, height=h)
    return out[0], out[1], cam_b


#: The binned pass: a full-size matched pixel within this of twice a binned pixel's
#: disparity agrees with it, pixels (`_coarse_consistent`).
_COARSE_AGREE_PX = 2.0


def _disparity_image(f: GpodFeatures, cam: StereoCamera) -> np.ndarray:
    """(H, W) float32 disparity of the matched left edge pixels at their rounded column,
    NaN elsewhere, pixels."""
    out = np.full((cam.height, cam.width), np.nan, np.float32)
    col = np.clip(np.rint(f.u_left).astype(np.int64), 0, cam.width - 1)
    out[f.v.astype(np.int64), col] = f.d
    return out


def _coarse_consistent(ob: GpodObstacle, coarse: GpodFeatures, fine_d: np.ndarray) -> bool:
    """Whether the full-size matches do not contradict a binned-pass obstacle.

    Each of the obstacle's binned pixels (u, v, d) (those beyond the threshold on its
    edge strings) is looked up in the full-size pair at rows 2v, 2v + 1 and columns
    within 2 of 2u + 0.5. It agrees when there are full-size matches there and all have
    a disparity within ``_COARSE_AGREE_PX`` of 2d; it is contradicted when one does not
    (the full-size pass, with finer neighbours to tell them apart, matched the edge
    elsewhere, or the place is ambiguous: a door's edge matched both to itself and to a
    pole a period off). A faint surface leaves most of its pixels unmatched at full
    size: neither.

    Args:
        ob: a detection of the binned pass; coarse: that pass's features.
        fine_d: (H, W) the full-size pass's `_disparity_image`.
    Returns:
        False when more of its pixels are contradicted than agree.
    """
    sel = np.isin(coarse.string_id, ob.string_ids) & (coarse.is_obstacle | coarse.is_drop)
    if not sel.any():
        return True
    h, w = fine_d.shape
    u = np.rint(2.0 * coarse.u_left[sel] + 0.5).astype(np.int64)
    v = 2 * coarse.v[sel].astype(np.int64)
    d = 2.0 * coarse.d[sel].astype(np.float64)
    rows = np.clip(v[:, None] + np.array([0, 1])[None, :], 0, h - 1)[:, :, None]   # (k, 2, 1)
    cols = np.clip(u[:, None] + np.arange(-2, 3)[None, :], 0, w - 1)[:, None, :]   # (k, 1, 5)
    vals = fine_d[rows, cols].reshape(len(d), -1)                                 # (k, 10)
    seen = np.isfinite(vals)
    with np.errstate(invalid='ignore'):
        bad = (seen & ~(np.abs(vals - d[:, None]) <= _COARSE_AGREE_PX)).any(axis=1)
    agree = seen.any(axis=1) & ~bad
    return int(bad.sum()) <= int(agree.sum())

