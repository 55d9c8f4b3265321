"""Small helpers of the detector's stages: the features of a pass (with each match's
share of contrary rivals), plane agreement and metric planes, stillness from a motion,
ground candidates, a moved report's image region, noise keys and MAD sigma.
"""
from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from ..camera import MetricPlane, StereoCamera
from ..edges import EdgeMap
from ..ground_plane import plane_is_plausible
from ..matching import Matches
from ..motion.geometry import so3_log
from . import kernels as kn
from .results import GpodFeatures, GpodObstacle

#: Largest camera translation (m) and rotation (rad) between two frames of a rig seen
#: standing still (its edges within a pixel) that is taken as a real motion
_STILL_MAX_TRANSLATION_M = 0.02
_STILL_MAX_ROTATION_RAD = math.radians(1.0)


class _Pass(NamedTuple):
    """One detector pass over a pair (`GpodDetector._frame_pass`)."""

    status: str
    updated: bool
    metric: MetricPlane | None
    features: GpodFeatures
    detections: tuple[GpodObstacle, ...]
    threshold: float
    el: EdgeMap
    er: EdgeMap
    still: bool
    timings: dict[str, float]
    #: the camera's motion since the previous pair as `GpodDetector.process` takes it
    #: (a callable resolved once the plane was calibrated), or None
    motion: tuple | Callable[[], tuple | None] | None = None


def _state_metric(cam: StereoCamera, abc: np.ndarray) -> MetricPlane | None:
    """The metric plane of a plane state (a, b, c): any plane below the camera, however
    high or tilted (None: not below the camera, or not finite)."""
    return plane_is_plausible(cam, abc, min_height_m=0.0, max_height_m=float('inf'),
                              max_tilt_deg=90.0)


def _still_motion(motion: tuple) -> bool:
    """Whether a camera motion (R (3, 3), t (3,) m, ...) is small enough for a rig seen
    standing still: |t| <= 2 cm and a rotation of at most 1 degree."""
    return (float(np.linalg.norm(np.asarray(motion[1], float))) <= _STILL_MAX_TRANSLATION_M
            and float(np.linalg.norm(so3_log(motion[0]))) <= _STILL_MAX_ROTATION_RAD)


def _planes_agree(abc0: np.ndarray, abc1: np.ndarray, cam: StereoCamera,
                  tol_px: float) -> bool:
    """Whether two planes ``d = a*u + b*v + c`` ((3,) each) differ by at most ``tol_px``
    pixels of disparity over the image's lower half (where the ground is seen): at its
    four corners, the largest difference of a linear function."""
    uu = np.array([0.0, cam.width - 1.0, 0.0, cam.width - 1.0])
    vv = np.array([cam.cy, cam.cy, cam.height - 1.0, cam.height - 1.0])
    dd = np.asarray(abc0, float) - np.asarray(abc1, float)
    return bool(np.max(np.abs(dd[0] * uu + dd[1] * vv + dd[2])) <= tol_px)


def _below_view(cam: StereoCamera, foot: np.ndarray) -> bool:
    """Whether a foot ((3,) metres, left optical frame) is in front of the camera but
    projects below the left image's bottom row: ground nearer than the camera sees, where
    an obstacle the wearer walks up to goes (from about 1.4 m on the paper's rig)."""
    if foot[2] <= 1e-3:
        return False
    return float(cam.project_left(np.asarray(foot, float))[1][0]) > cam.height - 1


def _moved_roi(ob: GpodObstacle, foot: np.ndarray, normal_up: np.ndarray,
               cam: StereoCamera, require_in_view: bool = False
               ) -> tuple[int, int, int, int] | None:
    """The left-image region (x, y, w, h) of obstacle ``ob`` moved to stand on ``foot``
    ((3,) metres, left optical frame; ``normal_up`` the plane's unit normal): its region
    carried with its foot's image point and scaled about it by the change of depth, so
    that it keeps its place beside and above the foot (a foot placed off the obstacle's
    edges -- a wall's nearest point, the near one of two boxes -- must not drag the
    region off them); clipped to the image (at least 1 x 1). With ``require_in_view``,
    None when the moved region lies wholly outside the image (an obstacle walked up to,
    below the view)."""
    old_foot = ob.position - ob.height * normal_up
    ends = np.stack([old_foot, foot]).astype(float)
    ends[:, 2] = np.maximum(ends[:, 2], 1e-3)
    (u0, u1), (v0, v1) = cam.project_left(ends)
    scale = ends[0, 2] / ends[1, 2]
    x, y, w, h = ob.roi
    xa, xb = u1 + (x - u0) * scale, u1 + (x + w - 1 - u0) * scale
    ya, yb = v1 + (y - v0) * scale, v1 + (y + h - 1 - v0) * scale
    if require_in_view and (xb < 0 or xa > cam.width - 1 or yb < 0 or ya > cam.height - 1):
        return None
    x0 = int(np.clip(np.floor(xa), 0, cam.width - 1))
    x1 = int(np.clip(np.ceil(xb), 0, cam.width - 1))
    y0 = int(np.clip(np.floor(ya), 0, cam.height - 1))
    y1 = int(np.clip(np.ceil(yb), 0, cam.height - 1))
    return (x0, y0, max(x1 - x0 + 1, 1), max(y1 - y0 + 1, 1))


def _features(m: Matches, excess: np.ndarray, obst: np.ndarray | None = None,
              drop: np.ndarray | None = None, sclass: np.ndarray | None = None,
              excess_mean: np.ndarray | None = None,
              threshold: np.ndarray | None = None,
              contrary_rival_share: np.ndarray | None = None) -> GpodFeatures:
    """GpodFeatures of the matches (no pixel flagged when the flags are None)."""
    k = len(m)
    z = np.zeros(k, bool)
    return GpodFeatures(u_left=m.u_left, u_right=m.u_right, v=m.v, d=m.d, excess=excess,
                        is_obstacle=z if obst is None else obst,
                        is_drop=z.copy() if drop is None else drop,
                        string_class=np.zeros(k, np.int8) if sclass is None else sclass,
                        string_id=m.string_id, strength=m.strength,
                        excess_mean=excess if excess_mean is None else excess_mean,
                        threshold=threshold,
                        contrary_rival_share=contrary_rival_share)


def _noise_key(m: Matches) -> np.ndarray:
    """What the disparity noise of a match is binned by for ``threshold.sigma_per_edge``: the
    precision of its edges' sub-pixel positions (their gradient curvature,
    ``Matches.precision``), or the edge strength when that is unknown."""
    return m.precision if m.precision is not None else m.strength


def _mad_sigma(x: np.ndarray) -> float:
    """Robust standard deviation, 1.4826 * median absolute deviation (NaN if empty)."""
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return float('nan')
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def contrary_rival_share(m: Matches, pd: np.ndarray, thr: np.ndarray,
                          raised: np.ndarray) -> np.ndarray | None:
    """(K,) float32: per match, the first-round PMF support of its rivals that say
    otherwise, over that of the match and all its rivals (`match_rivals`: the other
    candidates of its left or right edge); None when the matcher gave no rivals. For a
    ``raised`` (K,) pixel the rivals on the ground or below it say otherwise (disparity at
    most the ground's ``pd`` (K,) plus the pixel's threshold ``thr`` (K,), pixels), for
    every other pixel (a drop) those on the ground or above it. Were the supports
    likelihoods, the chance that the pixel is not what its match says: the ground matched
    wrongly. A rival on the same side of the ground (a wall's texture matched elsewhere
    on the wall) is another reading of the same kind."""
    if m.rival_match is None or m.rival_ratio is None or m.rival_d is None:
        return None
    k = len(m)
    j = m.rival_match
    if kn.nb_rival_share is not None:
        # The same sums in the same order, compiled (one pass over the rivals).
        return kn.nb_rival_share(j, m.rival_ratio, m.rival_d, np.asarray(pd, np.float64),
                                 np.asarray(thr, np.float64), np.asarray(raised, bool), k)
    r = m.rival_ratio.astype(np.float64)
    rd = m.rival_d.astype(np.float64)
    total = 1.0 + np.bincount(j, weights=r, minlength=k)
    pd_j, thr_j = pd[j], thr[j]
    contrary = np.where(raised[j], rd <= pd_j + thr_j, rd >= pd_j - thr_j)
    return (np.bincount(j[contrary], weights=r[contrary], minlength=k) / total
            ).astype(np.float32)
