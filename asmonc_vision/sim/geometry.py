"""Rotations and rig poses for the simulator (pure numpy).

Frames (REP 103):

* ``world``: z up, metres.
* body / ``inclinometer_link``: x forward, y left, z up, fixed to the rig, origin at the
  midpoint of the stereo baseline. Its x axis is the cameras' optical axis, so the
  nominal body pitch equals the camera tilt (positive pitch = nose down, REP 103).
* optical frames: x right, y down, z forward. The left camera is at body y = +B/2,
  the right at body y = -B/2. Both share the body orientation (rectified pair).

Angles are radians unless a name ends in ``_deg``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Rotation taking optical-frame vectors to body-frame vectors: optical z = body x,
#: optical x = -body y, optical y = -body z.
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0],
                           [-1.0, 0.0, 0.0],
                           [0.0, -1.0, 0.0]])


def rpy_to_matrix(roll, pitch, yaw) -> np.ndarray:
    """Rotation matrices from REP 103 roll, pitch, yaw (fixed-axis XYZ = R_z R_y R_x).

    Args:
        roll, pitch, yaw: scalars or arrays of equal shape S, radians.
    Returns:
        (*S, 3, 3) float64 rotation(s) taking body vectors to world vectors.
    """
    r, p, y = (np.asarray(a, float) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    m = np.empty(np.broadcast(r, p, y).shape + (3, 3))
    m[..., 0, 0] = cy * cp
    m[..., 0, 1] = cy * sp * sr - sy * cr
    m[..., 0, 2] = cy * sp * cr + sy * sr
    m[..., 1, 0] = sy * cp
    m[..., 1, 1] = sy * sp * sr + cy * cr
    m[..., 1, 2] = sy * sp * cr - cy * sr
    m[..., 2, 0] = -sp
    m[..., 2, 1] = cp * sr
    m[..., 2, 2] = cp * cr
    return m


def matrix_to_rpy(m) -> np.ndarray:
    """REP 103 (roll, pitch, yaw) of rotation matrices (*S, 3, 3); returns (*S, 3) radians."""
    m = np.asarray(m, float)
    roll = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    pitch = np.arcsin(np.clip(-m[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def quaternion_from_rpy(roll, pitch, yaw) -> np.ndarray:
    """Unit quaternion(s) (x, y, z, w) of REP 103 roll, pitch, yaw (radians).

    Returns:
        (*S, 4) float64, the rotation taking body vectors to world vectors, with w >= 0.
    """
    r, p, y = (np.asarray(a, float) / 2.0 for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    q = np.stack([sr * cp * cy - cr * sp * sy,
                  cr * sp * cy + sr * cp * sy,
                  cr * cp * sy - sr * sp * cy,
                  cr * cp * cy + sr * sp * sy], axis=-1)
    return np.where(q[..., 3:4] < 0, -q, q)


def matrix_to_quaternion(m) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w >= 0, of one 3x3 rotation matrix. Returns (4,)."""
    m = np.asarray(m, float)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


@dataclass(frozen=True)
class RigPose:
    """The rig's (body frame's) pose in the world at one instant.

    Attributes:
        position: (3,) float64, metres, world: the baseline midpoint.
        rpy: (3,) float64, radians: REP 103 roll, pitch, yaw of the body in the world.
    """

    position: np.ndarray
    rpy: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) body-to-world rotation."""
        return rpy_to_matrix(*self.rpy)


@dataclass(frozen=True)
class CameraPose:
    """One optical frame in the world: ``X_world = rotation @ X_optical + centre``.

    Attributes:
        rotation: (3, 3) float64, optical-to-world rotation.
        centre: (3,) float64, the optical centre in the world, metres.
    """

    rotation: np.ndarray
    centre: np.ndarray

    def to_optical(self, points_world) -> np.ndarray:
        """World points (N, 3) to this optical frame (N, 3), metres."""
        p = np.asarray(points_world, float).reshape(-1, 3)
        return (p - self.centre) @ self.rotation

    def to_world(self, points_optical) -> np.ndarray:
        """Optical-frame points (N, 3) to the world (N, 3), metres."""
        p = np.asarray(points_optical, float).reshape(-1, 3)
        return p @ self.rotation.T + self.centre


def camera_poses(pose: RigPose, baseline: float) -> tuple[CameraPose, CameraPose]:
    """Left and right optical frames of the rig at ``pose``.

    Args:
        pose: the body pose in the world.
        baseline: metres between the optical centres.
    Returns:
        (left, right) CameraPose; the right centre is the left moved +baseline along the
        optical x axis (rectified pair).
    """
    r_wb = pose.rotation
    r_wo = r_wb @ R_BODY_OPTICAL
    half = np.array([0.0, baseline / 2.0, 0.0])
    left = CameraPose(rotation=r_wo, centre=np.asarray(pose.position, float) + r_wb @ half)
    right = CameraPose(rotation=r_wo, centre=np.asarray(pose.position, float) - r_wb @ half)
    return left, right
