"""Ground truth of a rendered frame: the ground plane under the rig and the obstacles.

Definitions (CONVENTIONS.md, bags/README.md):

* The ground plane is the plane of the ground under the rig (the base plane, the
  terrace the rig stands on, or the piece of a profiled ground there: slopes, crests,
  dips and ramps are ground, never obstacles), in the left optical frame.
* Obstacles are taken as they are at the frame time (``World.active``): a walking
  person is where it is then.
* An obstacle is reported when at least ``MIN_PIXELS`` left-image pixel centres see it
  (the renderer's label map at the rendered resolution); fewer means it is not in view.
* Its place is the **nearest visible part** of it. Each of its pixels gives a 3-D point
  (left optical frame, from the depth map) and that point's *foot*, its orthogonal
  projection onto the ground plane (along the plane normal). The chosen foot is the one
  whose distance along the ground from the point below the left camera has rank
  min(floor(``NEAREST_QUANTILE`` (N - 1)), ``NEAREST_MAX_RANK``) among the N pixels,
  i.e. the 2nd-percentile nearest, but never beyond the 21st nearest: a robust minimum
  that a few stray pixel centres (a lone pixel at a silhouette, or seen past another
  obstacle's edge) cannot pull, and that does not place a large obstacle (a wall filling
  half the image, the lower ground beyond a drop: tens of thousands of pixels)
  measurably beyond its nearest visible part. For N <= 50 it is the nearest pixel.
  So a wall beside the path is placed where it enters the field of view, and an
  obstacle being passed where the image's bottom edge cuts it, not at its unseen
  nearest point. For an obstacle wholly in view this is, to within a few cm, the point
  of its footprint nearest to the camera's foot (``analytic_nearest_top_point``, the
  former definition).
* ``position`` is that foot raised along the plane normal to the obstacle's top surface
  (the horizontal top face of a box, wall, door, post or bollard; a kerb's raised top;
  for a drop the lower ground, so the nearest visible lower ground just beyond the
  brink). It need not itself be in view (a 2.4 m wall's top usually is not), but its
  foot is that of a visible point. ``height`` is its signed height above the rig's
  ground plane (the obstacle's height, negative for a drop); ``range``/``bearing`` come
  from ``core.camera.ground_range_bearing`` (so they are the foot's); ``roi`` is the
  bounding box of its pixels; ``width`` the lateral extent (across the walking
  direction, along the ground) of its pixels' feet; ``disparity_excess`` the largest
  true disparity minus the plane's over its pixels (the most negative one for a drop).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.camera import (MetricPlane, StereoCamera, ground_range_bearing,
                                       plane_disparity, plane_from_metric)
from asmonc_vision.sim.geometry import CameraPose, RigPose
from asmonc_vision.sim.world import Terrace, World

#: Fewest left-image pixel centres that must see an obstacle for it to be listed.
MIN_PIXELS = 4
#: Quantile of the pixels' ground distances taken as the obstacle's "nearest" foot ...
NEAREST_QUANTILE = 0.02
#: ... but never further down the ranking than this (0-based) rank.
NEAREST_MAX_RANK = 20


@dataclass(frozen=True)
class ObstacleTruth:
    """One obstacle as it really is, in the left optical frame.

    Attributes:
        id: stable obstacle id (>= 1).
        kind: 'box', 'post', 'bollard', 'door', 'wall', 'kerb', 'drop', 'person'.
        position: (3,) float64 metres, the top point above the nearest visible foot
            (see module doc).
        height: metres above the ground plane (negative for a drop).
        range: metres along the ground; bearing: radians, positive left.
        width: metres; disparity_excess: pixels.
        roi: (x_offset, y_offset, width, height) pixels in the left image: the
            bounding box of its pixels.
        pixels: number of left pixel centres that see it (>= MIN_PIXELS).
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


def analytic_nearest_top_point(ob, left: CameraPose, plane: MetricPlane) -> np.ndarray:
    """The point of a box/cylinder top nearest, along the ground, to the point below the
    left camera, whether or not it is in view (the former ground-truth definition; for an
    obstacle wholly in view the truth's position agrees with it to within a few cm).

    Args:
        ob: a Box or Cylinder (``top_polygon()``); left: the left optical frame;
        plane: the ground plane under the rig.
    Returns:
        (3,) float64, left optical frame.
    """
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


def _top_plane(ob, world: World, left: CameraPose) -> tuple[np.ndarray, float]:
    """The plane of an obstacle's top in the left optical frame: (unit up u (3,), c) with
    u . X = c on it. A box's or cylinder's top face is horizontal at ``z_top``; a
    terrace's top (raised kerb, or the lower ground beyond a drop) is the base ground
    plane moved by ``rise`` vertically."""
    if isinstance(ob, Terrace):
        n_w, off = world.ground.plane
        n_w = np.asarray(n_w, float)
        off = float(off) + ob.rise * float(n_w[2])
    else:
        n_w, off = np.array([0.0, 0.0, 1.0]), float(ob.z_top)
    return left.rotation.T @ n_w, off - float(n_w @ np.asarray(left.centre, float))


def _nearest_index(dist: np.ndarray) -> int:
    """Index of the robust minimum of ``dist`` (N,), N >= 1: the element of rank
    min(floor(NEAREST_QUANTILE (N - 1)), NEAREST_MAX_RANK) in increasing order."""
    k = min(int(NEAREST_QUANTILE * (dist.size - 1)), NEAREST_MAX_RANK)
    if k == 0:
        return int(np.argmin(dist))
    part = np.argpartition(dist, k)
    return int(part[k])


def obstacle_truth(world: World, t: float, pose: RigPose, left: CameraPose,
                   cam: StereoCamera, plane: MetricPlane, depth: np.ndarray,
                   labels: np.ndarray, faces: np.ndarray) -> list[ObstacleTruth]:
    """Ground truth of the obstacles visible in the left image (see the module doc).

    Args:
        world, t: the scene at time t (s).
        pose: the rig pose; left: the left optical frame; cam: the stereo camera.
        plane: the ground plane under the rig (``ground_plane_truth``).
        depth, labels, faces: (H, W) per-pixel truth from ``StereoRenderer.truth``
            (``faces`` is not needed by the definition; kept for the interface).
    Returns:
        list of ObstacleTruth, by increasing id; obstacles seen by fewer than
        ``MIN_PIXELS`` pixel centres are left out.
    """
    abc = plane_from_metric(cam, plane)
    origin, fwd, lft, n = _plane_frame(plane)
    ground_axes = np.column_stack([fwd, lft])
    under = world.terrace_at(float(pose.position[0]), float(pose.position[1]), t)
    active = [ob for ob in world.active(t) if under is None or ob.id != under.id]
    if not active:
        return []
    # one pass over the label map for all obstacles: pixels grouped by label
    flat = labels.ravel()
    sel = np.flatnonzero(flat > 0)
    sel = sel[np.argsort(flat[sel], kind='stable')]
    sorted_ids = flat[sel]
    out: list[ObstacleTruth] = []
    for ob in active:
        lo, hi = np.searchsorted(sorted_ids, [ob.id, ob.id + 1])
        if hi - lo < MIN_PIXELS:
            continue
        idx = sel[lo:hi]
        vs, us = np.divmod(idx, labels.shape[1])
        z = depth.ravel()[idx]
        pts = np.column_stack([(us - cam.cx) * z / cam.f, (vs - cam.cy) * z / cam.f, z])
        d = cam.fb / z
        excess = d - plane_disparity(abc, us - d / 2.0, vs)
        g = (pts - origin) @ ground_axes          # feet, (forward, left) on the ground
        i = _nearest_index(np.hypot(g[:, 0], g[:, 1]))
        foot = origin + ground_axes @ g[i]
        up, c = _top_plane(ob, world, left)
        pos = foot + (c - float(up @ foot)) / float(n @ up) * n
        rng_, brg = ground_range_bearing(plane, pos[None, :])
        negative = isinstance(ob, Terrace) and ob.rise < 0
        out.append(ObstacleTruth(
            id=int(ob.id), kind=ob.kind, position=np.asarray(pos, float),
            height=float(plane.signed_height(pos[None, :])[0]), range=float(rng_[0]),
            bearing=float(brg[0]), width=float(g[:, 1].max() - g[:, 1].min()),
            disparity_excess=float(excess.min() if negative else excess.max()),
            roi=(int(us.min()), int(vs.min()), int(us.max() - us.min() + 1),
                 int(vs.max() - vs.min() + 1)),
            pixels=int(idx.size)))
    return out
