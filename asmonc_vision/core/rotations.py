"""Rotations shared by the core, the simulator and the nodes (pure numpy).

Roll, pitch, yaw are REP 103 fixed-axis XYZ angles (R = Rz(yaw) Ry(pitch) Rx(roll)),
radians, of the rotation taking body vectors to world vectors; quaternions are
(x, y, z, w) with w >= 0, as in geometry_msgs. Frames: docs/CONVENTIONS.md.
"""
from __future__ import annotations

import math

import numpy as np

#: Rotation taking left-optical-frame vectors to inclinometer_link vectors.
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0],
                           [-1.0, 0.0, 0.0],
                           [0.0, -1.0, 0.0]])


def wrap_angle(a):
    """Angles wrapped to [-pi, pi) (scalar or array, radians)."""
    if isinstance(a, float):
        return (a + math.pi) % (2.0 * math.pi) - math.pi
    return (np.asarray(a, float) + np.pi) % (2.0 * np.pi) - np.pi


def rpy_to_matrix(rpy) -> np.ndarray:
    """(..., 3) roll, pitch, yaw (rad) -> (..., 3, 3) rotation body -> world."""
    rpy = np.asarray(rpy, float)
    r, p, y = rpy[..., 0], rpy[..., 1], rpy[..., 2]
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    m = np.empty(rpy.shape[:-1] + (3, 3))
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
    """(..., 3, 3) rotation body -> world -> (..., 3) roll, pitch, yaw (rad), yaw in
    (-pi, pi]."""
    m = np.asarray(m, float)
    roll = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    pitch = np.arcsin(np.clip(-m[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def rpy_to_quaternion(rpy) -> np.ndarray:
    """(..., 3) roll, pitch, yaw (rad) -> (..., 4) unit quaternion (x, y, z, w), w >= 0,
    of the rotation body -> world (the orientation of sensor_msgs/Imu)."""
    h = np.asarray(rpy, float) / 2.0
    cr, sr = np.cos(h[..., 0]), np.sin(h[..., 0])
    cp, sp = np.cos(h[..., 1]), np.sin(h[..., 1])
    cy, sy = np.cos(h[..., 2]), np.sin(h[..., 2])
    q = np.stack([sr * cp * cy - cr * sp * sy,
                  cr * sp * cy + sr * cp * sy,
                  cr * cp * sy - sr * sp * cy,
                  cr * cp * cy + sr * sp * sy], axis=-1)
    return np.where(q[..., 3:4] < 0, -q, q)


def quaternion_to_matrix(q) -> np.ndarray:
    """(..., 4) quaternion (x, y, z, w), any norm > 0 -> (..., 3, 3) rotation matrix.

    Raises:
        ValueError: a quaternion of (near) zero norm or not finite.
    """
    q = np.asarray(q, float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(q)) or np.any(n < 1e-9):
        raise ValueError('quaternion is zero or not finite')
    x, y, z, w = np.moveaxis(q / n, -1, 0)
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def quaternion_to_rpy(q) -> np.ndarray:
    """(..., 4) quaternion (x, y, z, w) -> (..., 3) roll, pitch, yaw (rad)."""
    return matrix_to_rpy(quaternion_to_matrix(q))


def matrix_to_quaternion(m) -> np.ndarray:
    """(3, 3) rotation -> (4,) unit quaternion (x, y, z, w) with w >= 0."""
    m = np.asarray(m, float)
    t = np.trace(m)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
                      (m[1, 0] - m[0, 1]) / s, s / 4.0])
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
        q = np.empty(4)
        q[i] = s / 4.0
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
        q[3] = (m[k, j] - m[j, k]) / s
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def rotvec_to_matrix(v) -> np.ndarray:
    """(..., 3) rotation vector (axis * angle, rad) -> (..., 3, 3) (Rodrigues)."""
    v = np.asarray(v, float)
    th = np.linalg.norm(v, axis=-1)[..., None, None]
    k = np.zeros(v.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2] = -v[..., 2], v[..., 1]
    k[..., 1, 0], k[..., 1, 2] = v[..., 2], -v[..., 0]
    k[..., 2, 0], k[..., 2, 1] = -v[..., 1], v[..., 0]
    small = th < 1e-8
    a = np.where(small, 1.0, np.sin(th) / np.where(small, 1.0, th))
    b = np.where(small, 0.5, (1 - np.cos(th)) / np.where(small, 1.0, th * th))
    return np.eye(3) + a * k + b * (k @ k)


def gravity_up_optical(q) -> np.ndarray:
    """The world's up direction (against gravity) in the left optical frame, from the
    inclinometer's orientation.

    Args:
        q: (4,) quaternion (x, y, z, w), any norm > 0: the rotation taking
            ``inclinometer_link`` vectors to world vectors (world z up), as
            `/inclinometer/imu` carries it (the mount rotation already applied by the
            compass node).
    Returns:
        (3,) unit vector in the left optical frame (x right, y down, z forward): for a
        level rig (0, -1, 0); for cameras pitched down by p (nose down),
        (0, -cos p, -sin p) (up leans back, against the optical axis).
    Raises:
        ValueError: a quaternion of (near) zero norm or not finite.
    """
    r = quaternion_to_matrix(np.asarray(q, float).reshape(4))
    up_body = r[2, :]                       # R^T (0, 0, 1): world up in the body frame
    return R_BODY_OPTICAL.T @ up_body


def up_for_pair(sample: tuple[int, np.ndarray] | None, stamp_ns: int, max_age_s: float
                ) -> np.ndarray | None:
    """The world's up direction in the left optical frame for a stereo pair, from an
    inclinometer sample (`gravity_up_optical`).

    Args:
        sample: (stamp_ns, (4,) quaternion x, y, z, w) of the inclinometer's orientation
            (world -> inclinometer_link), or None.
        stamp_ns: the pair's stamp.
        max_age_s: the sample counts only if stamped at most this long from the pair, s.
    Returns:
        (3,) unit vector, or None (no sample, too far in time, or a degenerate
        quaternion).
    """
    if sample is None or abs(int(sample[0]) - int(stamp_ns)) > max_age_s * 1e9:
        return None
    try:
        return gravity_up_optical(sample[1])
    except ValueError:
        return None
