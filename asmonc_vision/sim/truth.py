"""Ground truth of a rendered frame: the ground plane under the rig and the obstacles.

Definitions (CONVENTIONS.md):

* The ground plane is the plane of the ground under the rig (the base plane, or the
  terrace the rig stands on), in the left optical frame.
* An obstacle is reported when at least one left-image pixel centre sees it.
  ``position`` is the point of its top surface nearest, along the ground, to the point
  below the left camera (analytic for boxes and cylinders, whether or not that point is
  in view; for a terrace, the nearest *visible* point of its top, i.e. of the raised
  kerb or of the lower ground beyond a drop). ``height`` is that point's signed height
  above the rig's ground plane (negative for a drop); ``range``/``bearing`` come from
  ``core.camera.ground_range_bearing``; ``roi`` is the bounding box of its pixels;
  ``width`` the lateral extent (across the walking direction, along the ground) of its
  visible pixels; ``disparity_excess`` the largest true disparity minus the plane's
  over its pixels (the most negative one for a drop).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.camera import (MetricPlane, StereoCamera, ground_range_bearing,
                                       plane_disparity, plane_from_metric)
from asmonc_vision.sim.geometry import CameraPose, RigPose
from asmonc_vision.sim.world import Terrace, World


@dataclass(frozen=True)
class ObstacleTruth:
    """One obstacle as it really is, in the left optical frame.

    Attributes:
        id: stable obstacle id (>= 1).
        kind: 'box', 'post', 'bollard', 'door', 'wall', 'kerb', 'drop'.
        position: (3,) float64 metres, the top point (see module doc).
        height: metres above the ground plane (negative for a drop).
        range: metres along the ground; bearing: radians, positive left.
        width: metres; disparity_excess: pixels.
        roi: (x_offset, y_offset, width, height) pixels in the left image.
        pixels: number of left pixel centres that see it.
    """

    id: int
    kind: str
    position: np.ndarray
    height: float
    range: float
    bearing: float
    width: float
    disparity_excess: float
    roi: tuple[int, int, int, int]
    pixels: int


def ground_plane_truth(world: World, t: float, pose: RigPose, left: CameraPose
                       ) -> MetricPlane:
    """The ground plane under the rig in the left optical frame.

    Args:
        world: the scene; t: seconds; pose: the rig pose; left: the left optical frame.
    Returns:
        MetricPlane (unit normal pointing up, height of the left optical centre, m).
    """
    n, off = world.ground_plane(float(pose.position[0]), float(pose.position[1]), t)
    normal_up = left.rotation.T @ n
    height = float(n @ left.centre - off)
    return MetricPlane(normal_up=normal_up, height=height)


def _plane_frame(plane: MetricPlane):
    """Origin foot, forward and left unit vectors of the ground plane (optical frame)."""
    n = np.asarray(plane.normal_up, float)
    fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
    fwd /= np.linalg.norm(fwd)
    left = np.cross(n, fwd)
    return -plane.height * n, fwd, left, n


def _nearest_on_polygon(poly2: np.ndarray, q: np.ndarray) -> tuple[int, int, float] | None:
    """Nearest point of a convex 2-D polygon (M, 2) to q (2,): (i, j, s) meaning the point
    poly[i] + s (poly[j] - poly[i]); None when q is inside."""
    m = len(poly2)
    best, arg = np.inf, None
    inside = True
    area = np.sum(poly2[:, 0] * np.roll(poly2[:, 1], -1) - np.roll(poly2[:, 0], -1) * poly2[:, 1])
    sign = 1.0 if area > 0 else -1.0
    for i in range(m):
        j = (i + 1) % m
        a, b = poly2[i], poly2[j]
        e = b - a
        if sign * (e[0] * (q[1] - a[1]) - e[1] * (q[0] - a[0])) < 0:
            inside = False
        s = float(np.clip(np.dot(q - a, e) / max(np.dot(e, e), 1e-18), 0.0, 1.0))
        d = float(np.sum((a + s * e - q) ** 2))
        if d < best:
            best, arg = d, (i, j, s)
    return None if inside else arg


def _finite_top_point(ob, left: CameraPose, plane: MetricPlane) -> np.ndarray:
    """Nearest-along-the-ground point of a box/cylinder top, left optical frame (3,)."""
    top = left.to_optical(ob.top_polygon())
    origin, fwd, lft, n = _plane_frame(plane)
    q2 = (top - origin) @ np.column_stack([fwd, lft])
    hit = _nearest_on_polygon(q2, np.zeros(2))
    if hit is None:
        # the foot below the camera is under the top: the point of the (horizontal) top
        # face on the ground normal through that foot, origin + lam n
        up = left.rotation.T @ np.array([0.0, 0.0, 1.0])
        lam = float((top[0] - origin) @ up) / float(n @ up)
        return origin + lam * n
    i, j, s = hit
    return top[i] + s * (top[j] - top[i])


def obstacle_truth(world: World, t: float, pose: RigPose, left: CameraPose,
                   cam: StereoCamera, plane: MetricPlane, depth: np.ndarray,
                   labels: np.ndarray, faces: np.ndarray) -> list[ObstacleTruth]:
    """Ground truth of the obstacles visible in the left image.

    Args:
        world, t: the scene at time t (s).
        pose: the rig pose; left: the left optical frame; cam: the stereo camera.
        plane: the ground plane under the rig (``ground_plane_truth``).
        depth, labels, faces: (H, W) per-pixel truth from ``StereoRenderer.truth``.
    Returns:
        list of ObstacleTruth, by increasing id.
    """
    abc = plane_from_metric(cam, plane)
    origin, fwd, lft, n = _plane_frame(plane)
    under = world.terrace_at(float(pose.position[0]), float(pose.position[1]), t)
    out: list[ObstacleTruth] = []
    for ob in world.active(t):
        if under is not None and ob.id == under.id:
            continue
        vs, us = np.nonzero(labels == ob.id)
        if vs.size == 0:
            continue
        z = depth[vs, us]
        pts = np.column_stack([(us - cam.cx) * z / cam.f, (vs - cam.cy) * z / cam.f, z])
        d = cam.fb / z
        excess = d - plane_disparity(abc, us - d / 2.0, vs)
        lateral = (pts - origin) @ lft
        if isinstance(ob, Terrace):
            top = faces[vs, us] == 0
            cand = pts[top] if top.any() else pts
            g = (cand - origin) @ np.column_stack([fwd, lft])
            pos = cand[int(np.argmin(np.sum(g * g, axis=1)))]
            negative = ob.rise < 0
        else:
            pos = _finite_top_point(ob, left, plane)
            negative = False
        rng_, brg = ground_range_bearing(plane, pos[None, :])
        out.append(ObstacleTruth(
            id=int(ob.id), kind=ob.kind, position=np.asarray(pos, float),
            height=float(plane.signed_height(pos[None, :])[0]), range=float(rng_[0]),
            bearing=float(brg[0]), width=float(lateral.max() - lateral.min()),
            disparity_excess=float(excess.min() if negative else excess.max()),
            roi=(int(us.min()), int(vs.min()), int(us.max() - us.min() + 1),
                 int(vs.max() - vs.min() + 1)),
            pixels=int(vs.size)))
    return out
