"""Rotations for the walk model (pure numpy): REP 103 roll/pitch/yaw, quaternions,
rotation vectors, and the camera's visual motion turned into attitude increments.

Frames (docs/CONVENTIONS.md): ``world`` z up; ``inclinometer_link`` x along the cameras'
optical axis, y left, z up (so a standing wearer reads pitch ~ +20 deg, nose down);
the left optical frame has optical z = body x, optical x = -body y, optical y = -body z.
Roll, pitch, yaw are REP 103 fixed-axis XYZ angles (R = Rz(yaw) Ry(pitch) Rx(roll)),
radians, of the rotation taking body vectors to world vectors.
"""
from __future__ import annotations

import math

import numpy as np

from asmonc_vision.core.rotations import (R_BODY_OPTICAL, matrix_to_quaternion,  # noqa: F401
                                         matrix_to_rpy, quaternion_to_matrix,
                                         quaternion_to_rpy, rotvec_to_matrix, rpy_to_matrix,
                                         rpy_to_quaternion, wrap_angle)


def egomotion_to_body(r_optical) -> np.ndarray:
    """The left camera's rotation from the previous frame to the current one (the
    rotation part of /egomotion: current camera axes in the previous camera frame,
    optical axes) as the same rotation of inclinometer_link in its previous body frame:
    ``R_body = R_BO R_optical R_BO^T`` (both frames are fixed to the rig)."""
    return R_BODY_OPTICAL @ np.asarray(r_optical, float) @ R_BODY_OPTICAL.T


def rpy_increment(rpy_ref, r_body_increment) -> np.ndarray:
    """Attitude increment (droll, dpitch, dyaw), rad, of a body-frame rotation increment.

    With the attitude ``rpy_ref`` at the start of the interval (only its roll and pitch
    matter to first order), the end attitude is ``R(rpy_ref) @ r_body_increment``; the
    increment is the difference of the REP 103 angles, yaw difference wrapped.
    """
    r0 = np.asarray(rpy_ref, float)
    r1 = matrix_to_rpy(rpy_to_matrix(r0) @ np.asarray(r_body_increment, float))
    d = r1 - r0
    d[..., 0] = wrap_angle(d[..., 0])
    d[..., 2] = wrap_angle(d[..., 2])
    return d


def euler_rate_matrix(rpy) -> np.ndarray:
    """E (3, 3) with d(roll, pitch, yaw) = E @ (body-frame small rotation vector), at the
    attitude rpy (rad): the map that turns a body rotation's noise into the noise of the
    attitude increments, Cov = E Sigma E^T."""
    r, p = float(rpy[0]), float(rpy[1])
    sr, cr, tp, cp = math.sin(r), math.cos(r), math.tan(p), math.cos(p)
    return np.array([[1.0, sr * tp, cr * tp],
                     [0.0, cr, -sr],
                     [0.0, sr / cp, cr / cp]])


def relative_rotation(rpy_a, rpy_b) -> np.ndarray:
    """Rotation of the body at attitude ``rpy_b`` expressed in the body frame at
    ``rpy_a``: ``R(a)^T R(b)`` (..., 3, 3)."""
    a, b = np.asarray(rpy_a, float), np.asarray(rpy_b, float)
    if a.shape == (3,) and b.shape == (3,):                 # one pair: floats (faster)
        ra, rb = _rpy_to_matrix_1(*a.tolist()), _rpy_to_matrix_1(*b.tolist())
    else:
        ra, rb = rpy_to_matrix(a), rpy_to_matrix(b)
    return np.swapaxes(ra, -1, -2) @ rb


def _rpy_to_matrix_1(r: float, p: float, y: float) -> np.ndarray:
    """``rpy_to_matrix`` of one attitude (math's sin and cos: the values of numpy's)."""
    cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])
