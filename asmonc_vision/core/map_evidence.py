"""The evidence map's measurement model: a pair's matched edge pixels placed on the ground.

`pair_evidence` turns each match (u, v, d) into the foot of its 3-D point in the pair's
ground frame G (REP 103: x forward along the optical axis laid on the plane, y left, z up
along the plane's normal; origin below the left camera), its height above the plane and
that height's standard deviation from the disparity noise, ``σ_h = |h(d + σ_d) - h(d)|``.
`ground_frame` and `ground_motion` give G in the camera and G's horizontal motion between
two pairs. `core.evidence_map` enters the result into the map.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.camera import MetricPlane, StereoCamera, columns, ground_axes, sub_rows
from .npfast import flat_nonzero

@dataclass(frozen=True)
class PairEvidence:
    """The matched edge pixels of one pair, placed on the ground (`pair_evidence`).

    Attributes:
        xy: (N, 2) float64 foot of each pixel's 3-D point, m, ground frame G.
        height: (N,) float64 height above the plane, m (negative below).
        sigma_h: (N,) float64 standard deviation of the height from the disparity noise, m.
        kind: (N,) int8 1 raised, -1 drop, 0 ground (free), 2 none (unreliable; not used).
        weight: (N,) float64 how much each pixel's raised or drop evidence counts, 0..1
            (the probability that its match is right), or None (every pixel fully).
    """

    xy: np.ndarray
    height: np.ndarray
    sigma_h: np.ndarray
    kind: np.ndarray
    weight: np.ndarray | None = None


RAISED, DROP, GROUND, NONE = 1, -1, 0, 2


def pair_evidence(cam: StereoCamera, plane: MetricPlane, u: np.ndarray, v: np.ndarray,
                  d: np.ndarray, sigma_d: np.ndarray, kind: np.ndarray,
                  max_range_m: float, weight: np.ndarray | None = None) -> PairEvidence:
    """Measurement model: matched edge pixels to points on the ground with a height and σ.

    Args:
        cam: the rectified stereo camera.
        plane: the pair's ground plane, left optical frame.
        u, v, d: (N,) cyclopean column, row and disparity of each match, px.
        sigma_d: (N,) disparity noise of each match, px.
        kind: (N,) int8 RAISED, DROP, GROUND or NONE per match.
        max_range_m: matches whose foot is farther along the ground are dropped.
        weight: (N,) how much each match's raised or drop evidence counts, 0..1, or None
            (fully).
    Returns:
        PairEvidence of the matches kept (finite, d > 0, within range, ahead).
    """
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    d = np.asarray(d, float)
    # (the pixels kept, as indices: one selection for the six arrays)
    ok = flat_nonzero(np.isfinite(d) & (d > 0.05) & np.isfinite(u) & np.isfinite(v))
    u, v, d = u[ok], v[ok], d[ok]
    sd = np.asarray(sigma_d, float)[ok]
    kind = np.asarray(kind, np.int8)[ok]
    wt = np.asarray(weight, float)[ok] if weight is not None else None
    origin, fwd, left = ground_axes(plane)
    pts = cam.triangulate(u, v, d)
    h = plane.signed_height(pts)
    # σ_h: the height's change over one σ_d of disparity (first order)
    h2 = plane.signed_height(cam.triangulate(u, v, d + sd))
    sigma_h = np.abs(h2 - h) + 1e-4
    g = sub_rows(pts, origin)
    xy = columns(g @ fwd, g @ left)
    keep = flat_nonzero((xy[:, 0] > 0) & (np.hypot(xy[:, 0], xy[:, 1]) <= max_range_m))
    return PairEvidence(xy=xy[keep], height=h[keep], sigma_h=sigma_h[keep], kind=kind[keep],
                        weight=wt[keep] if wt is not None else None)


def ground_frame(plane: MetricPlane) -> tuple[np.ndarray, np.ndarray]:
    """(R_cam_G (3, 3), o (3,)): the ground frame G in the left optical frame,
    ``X_cam = R_cam_G g + o`` (columns: forward, left, up)."""
    origin, fwd, left = ground_axes(plane)
    return columns(fwd, left, np.asarray(plane.normal_up, float)), origin


def ground_motion(prev: MetricPlane, curr: MetricPlane, R: np.ndarray, t: np.ndarray
                  ) -> tuple[float, float, float]:
    """The horizontal motion (dx, dy m, dyaw rad) of the ground frame from the previous
    pair to this one, ``T_Gprev_Gcurr = T_Gprev_cam · T_prev_curr · T_cam_Gcurr``, given
    the camera motion ``X_prev = R X_curr + t`` (left optical frames, metres)."""
    Rp, op = ground_frame(prev)
    Rc, oc = ground_frame(curr)
    A = Rp.T @ np.asarray(R, float) @ Rc
    b = Rp.T @ (np.asarray(R, float) @ oc + np.asarray(t, float) - op)
    return float(b[0]), float(b[1]), math.atan2(A[1, 0], A[0, 0])
