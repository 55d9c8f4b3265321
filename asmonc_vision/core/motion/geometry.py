"""Rigid motions, rectified stereo projection and triangulation (pure numpy).

Conventions (docs/motion.md, docs/CONVENTIONS.md):

* Optical frames (REP 103): x right, y down, z forward, metres. Pixel (u, v): u column,
  v row, origin at the centre of the top-left pixel.
* A rigid motion is a pair ``(R, t)``: ``R`` (3, 3) float64 rotation, ``t`` (3,) metres.
  ``T_a_b = (R, t)`` maps points given in frame b into frame a: ``X_a = R @ X_b + t``;
  so ``t`` is frame b's origin expressed in frame a and the columns of ``R`` are b's axes
  in a.
* The *egomotion* between a previous frame p and the current frame c is ``T_p_c``
  (``X_prev = R @ X_curr + t``): ``t`` is where the left camera is now, in the previous
  left optical frame, and ``R`` its new orientation there.
* Internally the solvers estimate ``T_c_p`` (``X_curr = R @ X_prev + t``), the
  transform of the static scene points from the previous camera into the current one;
  ``invert`` converts.
* Six-vectors (twists, covariances) are ordered (translation ρ, rotation φ), as the
  ROS pose covariance (x, y, z, rot x, rot y, rot z). A perturbation ``δ`` acts on the
  left: ``T ← exp(δ) T``.
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.camera import columns
from asmonc_vision.core.rotations import matrix_to_quaternion, quaternion_to_matrix  # noqa: F401


def skew(w) -> np.ndarray:
    """Cross-product matrices ``[w]x`` of vectors (..., 3); returns (..., 3, 3)."""
    w = np.asarray(w, float)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1] = -w[..., 2]
    out[..., 0, 2] = w[..., 1]
    out[..., 1, 0] = w[..., 2]
    out[..., 1, 2] = -w[..., 0]
    out[..., 2, 0] = -w[..., 1]
    out[..., 2, 1] = w[..., 0]
    return out


def so3_exp(w) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3) (axis * angle, rad)."""
    w = np.asarray(w, float)
    if w.shape == (3,):
        return _so3_exp_one(w)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    k = skew(w)
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta ** 2 / 6.0, np.sin(th) / th)
    b = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(th)) / th ** 2)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a * k + b * (k @ k)


def _so3_exp_one(w: np.ndarray) -> np.ndarray:
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    th2 = x * x + y * y + z * z
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = th2 ** 0.5
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th2
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + a * k + b * (k @ k)


def so3_log(r) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3); angle in [0, pi]."""
    r = np.asarray(r, float)
    tr = np.clip((np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(tr)
    v = columns(r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                r[..., 1, 0] - r[..., 0, 1])
    s = np.sin(theta)
    small = theta < 1e-6
    fac = np.where(small, 0.5 + theta ** 2 / 12.0, theta / (2.0 * np.where(small, 1.0, s)))
    w = v * fac[..., None]
    # near pi the antisymmetric part vanishes: take the axis from the symmetric part
    near_pi = theta > np.pi - 1e-3
    if np.any(near_pi):
        rr = r[near_pi]
        th = theta[near_pi]
        b = (rr + np.swapaxes(rr, -1, -2)) / 2.0 - np.eye(3) * np.cos(th)[:, None, None]
        axes = np.empty((rr.shape[0], 3))
        for i in range(rr.shape[0]):
            j = int(np.argmax(np.diag(b[i])))
            ax = b[i][:, j] / np.sqrt(max(b[i][j, j], 1e-300))
            if np.dot(ax, v[near_pi][i]) < 0:
                ax = -ax
            axes[i] = ax / np.linalg.norm(ax)
        w[near_pi] = axes * th[:, None]
    return w


def project_rotation(m) -> np.ndarray:
    """The nearest rotation (Frobenius) to matrices (..., 3, 3)."""
    u, _, vt = np.linalg.svd(np.asarray(m, float))
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


def invert(r, t) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of ``(R, t)`` (one motion or stacks (..., 3, 3), (..., 3))."""
    r = np.asarray(r, float)
    t = np.asarray(t, float)
    rt = np.swapaxes(r, -1, -2)
    return rt, -np.einsum('...ij,...j->...i', rt, t)


def compose(r_ab, t_ab, r_bc, t_bc) -> tuple[np.ndarray, np.ndarray]:
    """``T_a_c = T_a_b T_b_c``."""
    return r_ab @ r_bc, r_ab @ t_bc + t_ab


def adjoint(r, t) -> np.ndarray:
    """6x6 adjoint of ``(R, t)`` for (ρ, φ) ordering: ``exp(Ad δ) = T exp(δ) T^-1``."""
    out = np.zeros((6, 6))
    out[:3, :3] = r
    out[3:, 3:] = r
    out[:3, 3:] = skew(t) @ r
    return out


def rotation_error_components(r_est, r_true) -> np.ndarray:
    """Rotation error as a rotation vector in the reference (previous) frame's axes.

    ``log(R_est R_true^T)``: (..., 3) radians about optical x (pitch: the lateral
    axis), y (yaw: the vertical axis) and z (roll: the optical axis).
    """
    return so3_log(np.asarray(r_est, float) @ np.swapaxes(np.asarray(r_true, float), -1, -2))


# --- rectified stereo -----------------------------------------------------------------

def project(points, f: float, cx: float, cy: float, x_offset: float = 0.0) -> np.ndarray:
    """Pixels (..., 2) of points (..., 3) seen by a camera at ``x_offset`` m along x.

    The right camera of a rectified pair is the left moved by the baseline along x:
    ``x_offset = B``. Points must have z > 0.
    """
    p = np.asarray(points, float)
    z = p[..., 2]
    return np.stack([f * (p[..., 0] - x_offset) / z + cx, f * p[..., 1] / z + cy], axis=-1)


def triangulate(left, right, f: float, cx: float, cy: float, baseline: float) -> np.ndarray:
    """Left optical-frame points (N, 3) from rectified left/right pixels (N, 2).

    Depth from the disparity ``d = u_left - u_right`` (px, > 0): ``z = f B / d``; the row
    is the mean of the two rows (their noise averages). Non-positive disparities give
    NaN.
    """
    left = np.asarray(left, float)
    right = np.asarray(right, float)
    d = left[..., 0] - right[..., 0]
    with np.errstate(divide='ignore', invalid='ignore'):
        z = np.where(d > 0, f * baseline / d, np.nan)
    v = 0.5 * (left[..., 1] + right[..., 1])
    return np.stack([(left[..., 0] - cx) * z / f, (v - cy) * z / f, z], axis=-1)


def bearings(pixels, f: float, cx: float, cy: float) -> np.ndarray:
    """Unit rays (..., 3) of pixels (..., 2) in the camera's optical frame."""
    p = np.asarray(pixels, float)
    b = np.stack([(p[..., 0] - cx) / f, (p[..., 1] - cy) / f, np.ones(p.shape[:-1])], axis=-1)
    return b / np.linalg.norm(b, axis=-1, keepdims=True)
