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

from asmonc_vision.core.rotations import (R_BODY_OPTICAL, matrix_to_quaternion,  # noqa: F401
                                         matrix_to_rpy, rpy_to_quaternion)
from asmonc_vision.core.motion.geometry import so3_exp
from asmonc_vision.core.rotations import rpy_to_matrix as _rpy_to_matrix


def rpy_to_matrix(roll, pitch, yaw) -> np.ndarray:
    """Rotation matrices from REP 103 roll, pitch, yaw (fixed-axis XYZ = R_z R_y R_x).

    Args:
        roll, pitch, yaw: scalars or arrays of equal shape S, radians.
    Returns:
        (*S, 3, 3) float64 rotation(s) taking body vectors to world vectors.
    """
    return _rpy_to_matrix(np.stack(np.broadcast_arrays(*(np.asarray(a, float)
                                                         for a in (roll, pitch, yaw))), -1))


def quaternion_from_rpy(roll, pitch, yaw) -> np.ndarray:
    """Unit quaternion(s) (x, y, z, w), w >= 0, of REP 103 roll, pitch, yaw (radians):
    (*S, 4), the rotation taking body vectors to world vectors."""
    return rpy_to_quaternion(np.stack(np.broadcast_arrays(*(np.asarray(a, float)
                                                            for a in (roll, pitch, yaw))), -1))


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


def camera_poses(pose: RigPose, baseline: float, right_misalignment=None
                 ) -> tuple[CameraPose, CameraPose]:
    """Left and right optical frames of the rig at ``pose``.

    Args:
        pose: the body pose in the world.
        baseline: metres between the optical centres.
        right_misalignment: optional (3,) rotation vector, radians, in the right optical
            frame: the right camera's residual rotation after rectification (None or
            zeros: a perfectly rectified pair).
    Returns:
        (left, right) CameraPose; the right centre is the left moved +baseline along the
        optical x axis (rectified pair).
    """
    r_wb = pose.rotation
    r_wo = r_wb @ R_BODY_OPTICAL
    half = np.array([0.0, baseline / 2.0, 0.0])
    r_right = r_wo
    if right_misalignment is not None and np.any(right_misalignment):
        r_right = r_wo @ so3_exp(np.asarray(right_misalignment, float))
    left = CameraPose(rotation=r_wo, centre=np.asarray(pose.position, float) + r_wb @ half)
    right = CameraPose(rotation=r_right,
                       centre=np.asarray(pose.position, float) - r_wb @ half)
    return left, right

