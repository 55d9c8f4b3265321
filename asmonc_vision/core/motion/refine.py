"""Least-squares refinement of a stereo motion on its inliers.

All functions work with ``T_c_p = (R, t)``: ``X_curr = R @ X_prev + t`` (the static
scene seen from the previous left camera, moved into the current one). Pixels are of
the rectified pair described by a ``core.camera.StereoCamera`` (f, cx, cy, baseline):
the right camera sits at +baseline along the optical x axis.

* ``refine_pose``: Gauss–Newton / Levenberg–Marquardt on the reprojection error of the
  previous-frame stereo points in the current left *and* right images (pose only, the
  points held fixed), Huber-weighted.
* ``refine_joint``: the two-view stereo bundle adjustment: pose and every point,
  reprojection error in all four images (previous left/right, current left/right),
  solved with the Schur complement (3x3 blocks per point). This is the maximum
  likelihood motion for image noise: the points' depths, which stereo alone measures
  poorly at range, are re-estimated from all four views.
* ``refine_object_space``: the paper's least squares for the three-point method: the
  points at time 1 constrained to their rays, inter-point distances preserved
  (absolute orientation to the closest points on the rays, iterated: "orthogonal
  iteration", Lu, Hager & Mjolsness 2000).
* ``refine_essential``: Sampson-error Gauss–Newton on (R, translation direction).
* ``scale_from_stereo``: the translation's length from the stereo points (the paper's
  "a single match between the left and right cameras at the previous instant").

Covariances are of the left perturbation ``δ = (ρ, φ)`` of ``T_c_p``
(``T ← (exp(φ), ρ) T``), 6x6, ordered (translation, rotation), scaled by the residual
variance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.motion.geometry import so3_exp, skew
from asmonc_vision.core.motion.solvers import kabsch, sampson_sq


@dataclass
class Refined:
    """Result of a refinement.

    Attributes:
        R, t: ``T_c_p``.
        points: (N, 3) previous left-frame points (re-estimated by ``refine_joint``,
            else the input), metres.
        cov: (6, 6) covariance of the left perturbation of ``T_c_p`` or None.
        rms_px: root mean square reprojection error of the weighted observations, px.
        iterations: iterations run.
    """

    R: np.ndarray
    t: np.ndarray
    points: np.ndarray
    cov: np.ndarray | None
    rms_px: float
    iterations: int


def _proj_jac(x, cam: StereoCamera, off: float):
    """Pixels (N, 2) and d(pixel)/dX (N, 2, 3) of points (N, 3) for a camera at x = off."""
    z = x[:, 2]
    iz = 1.0 / z
    xo = x[:, 0] - off
    uv = np.stack([cam.f * xo * iz + cam.cx, cam.f * x[:, 1] * iz + cam.cy], axis=-1)
    j = np.zeros((x.shape[0], 2, 3))
    fz = cam.f * iz
    j[:, 0, 0] = fz
    j[:, 0, 2] = -fz * xo * iz
    j[:, 1, 1] = fz
    j[:, 1, 2] = -fz * x[:, 1] * iz
    return uv, j


def _huber_w(r, k):
    """Huber weights of 2-D residuals (N, 2) with threshold k px (k <= 0: all 1)."""
    if k <= 0:
        return np.ones(r.shape[0])
    n = np.linalg.norm(r, axis=1)
    return np.where(n <= k, 1.0, k / np.maximum(n, 1e-12))


def _retract(r, t, d):
    rot = so3_exp(d[3:])
    return rot @ r, rot @ t + d[:3]


def _pose_terms(r, t, pts, obs, cam, huber):
    """Cost, H (6,6), g (6,) and residual count of the current-image observations.

    obs: [(pixels (N, 2) or None, x offset)], NaN rows skipped.
    """
    x1 = pts @ r.T + t
    h = np.zeros((6, 6))
    g = np.zeros(6)
    cost = 0.0
    nobs = 0
    for z, off in obs:
        if z is None:
            continue
        ok = np.all(np.isfinite(z), axis=1) & (x1[:, 2] > 1e-6)
        if not np.any(ok):
            continue
        xo = x1[ok]
        uv, jp = _proj_jac(xo, cam, off)
        res = uv - z[ok]
        w = _huber_w(res, huber)
        jc = np.concatenate([jp, -jp @ skew(xo)], axis=2).reshape(-1, 6)   # (2n, 6)
        ww = np.repeat(w, 2)
        jw = jc * ww[:, None]
        h += jw.T @ jc
        g += jw.T @ res.ravel()
        cost += float(ww @ (res.ravel() ** 2))
        nobs += int(ok.sum())
    return cost, h, g, nobs


def _converged(old_cost, new_cost, step) -> bool:
    return bool((old_cost - new_cost) <= 1e-8 * max(old_cost, 1e-12)
                or np.linalg.norm(step) < 1e-9)


def refine_pose(r, t, points, curr_left, curr_right, cam: StereoCamera, iters: int = 10,
                huber_px: float = 1.0) -> Refined:
    """LM on the reprojection error of fixed previous-frame points in the current images.

    Args:
        r, t: initial ``T_c_p``.
        points: (N, 3) previous left-frame points, metres.
        curr_left: (N, 2) current left pixels; curr_right: (N, 2) current right pixels
            with NaN rows where there is no right match (or None).
        huber_px: Huber threshold on each 2-D residual (<= 0: plain least squares).
    """
    obs = [(curr_left, 0.0), (curr_right, cam.baseline)]
    lam = 1e-4
    cost, h, g, nobs = _pose_terms(r, t, points, obs, cam, huber_px)
    it = 0
    for it in range(1, iters + 1):  # noqa: B007 - the count is returned
        a = h + lam * np.diag(np.diag(h) + 1e-9)
        try:
            d = -np.linalg.solve(a, g)
        except np.linalg.LinAlgError:
            break
        r2, t2 = _retract(r, t, d)
        c2, h2, g2, n2 = _pose_terms(r2, t2, points, obs, cam, huber_px)
        if c2 <= cost:
            done = _converged(cost, c2, d)
            r, t, cost, h, g, nobs = r2, t2, c2, h2, g2, n2
            lam = max(lam / 10.0, 1e-9)
            if done:
                break
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    dof = max(2 * nobs - 6, 1)
    sigma2 = cost / dof
    try:
        cov = np.linalg.inv(h) * sigma2
    except np.linalg.LinAlgError:
        cov = None
    return Refined(r, t, points, cov, float(np.sqrt(cost / max(nobs, 1))), it)


def _joint_terms(r, t, pts, obs0, obs1, cam, huber):
    """Cost, camera block H_cc (6,6), g_c (6,), per-point blocks H_cp (N,6,3),
    H_pp (N,3,3), g_p (N,3), and observation count."""
    n = pts.shape[0]
    hcc = np.zeros((6, 6))
    gc = np.zeros(6)
    hcp = np.zeros((n, 6, 3))
    hpp = np.zeros((n, 3, 3))
    gp = np.zeros((n, 3))
    cost = 0.0
    nobs = 0
    for z, off in obs0:                                       # previous images: points only
        ok = np.all(np.isfinite(z), axis=1) & (pts[:, 2] > 1e-6)
        uv, jp = _proj_jac(pts[ok], cam, off)
        res = uv - z[ok]
        w = _huber_w(res, huber)
        jpw = np.swapaxes(jp, 1, 2) * w[:, None, None]                 # (n, 3, 2)
        hpp[ok] += jpw @ jp
        gp[ok] += (jpw @ res[:, :, None])[:, :, 0]
        cost += float(w @ np.sum(res * res, axis=1))
        nobs += int(ok.sum())
    x1 = pts @ r.T + t
    for z, off in obs1:                                       # current images: pose + points
        if z is None:
            continue
        ok = np.all(np.isfinite(z), axis=1) & (x1[:, 2] > 1e-6)
        if not np.any(ok):
            continue
        xo = x1[ok]
        uv, jx = _proj_jac(xo, cam, off)
        res = uv - z[ok]
        w = _huber_w(res, huber)
        jc = np.concatenate([jx, -jx @ skew(xo)], axis=2)              # (n, 2, 6)
        jpt = jx @ r                                                    # (n, 2, 3)
        jcw = np.swapaxes(jc, 1, 2) * w[:, None, None]                  # (n, 6, 2)
        jptw = np.swapaxes(jpt, 1, 2) * w[:, None, None]                # (n, 3, 2)
        flat = jc.reshape(-1, 6)
        ww = np.repeat(w, 2)
        hcc += (flat * ww[:, None]).T @ flat
        gc += (flat * ww[:, None]).T @ res.ravel()
        hcp[ok] += jcw @ jpt
        hpp[ok] += jptw @ jpt
        gp[ok] += (jptw @ res[:, :, None])[:, :, 0]
        cost += float(w @ np.sum(res * res, axis=1))
        nobs += int(ok.sum())
    return cost, hcc, gc, hcp, hpp, gp, nobs


def refine_joint(r, t, points, prev_left, prev_right, curr_left, curr_right,
                 cam: StereoCamera, iters: int = 10, huber_px: float = 1.0) -> Refined:
    """Two-view stereo bundle adjustment: pose and points on all four images.

    Args:
        r, t: initial ``T_c_p``; points: (N, 3) initial previous left-frame points.
        prev_left, prev_right: (N, 2) the stereo match in the previous pair (required).
        curr_left: (N, 2); curr_right: (N, 2) with NaN rows, or None.
    Returns:
        Refined with the re-estimated points; ``cov`` is the pose block of the inverse
        Hessian (the Schur complement's inverse), times the residual variance.
    """
    pts = np.array(points, float)
    obs0 = [(prev_left, 0.0), (prev_right, cam.baseline)]
    obs1 = [(curr_left, 0.0), (curr_right, cam.baseline)]
    lam = 1e-4
    terms = _joint_terms(r, t, pts, obs0, obs1, cam, huber_px)
    it = 0
    s_mat = None
    eye3 = np.eye(3)
    for it in range(1, iters + 1):  # noqa: B007 - the count is returned
        cost, hcc, gc, hcp, hpp, gp, nobs = terms
        hpp_d = hpp + lam * (hpp * eye3 + 1e-9 * eye3)
        hcc_d = hcc + lam * np.diag(np.diag(hcc) + 1e-9)
        try:
            hpp_inv = np.linalg.inv(hpp_d)
        except np.linalg.LinAlgError:
            break
        w_blk = hcp @ hpp_inv                                          # (N, 6, 3)
        s_mat = hcc_d - np.sum(w_blk @ np.swapaxes(hcp, 1, 2), axis=0)
        rhs = -gc + np.sum((w_blk @ gp[:, :, None])[:, :, 0], axis=0)
        try:
            dc = np.linalg.solve(s_mat, rhs)
        except np.linalg.LinAlgError:
            break
        dp = -(hpp_inv @ (gp + np.swapaxes(hcp, 1, 2) @ dc)[:, :, None])[:, :, 0]
        r2, t2 = _retract(r, t, dc)
        pts2 = pts + dp
        new = _joint_terms(r2, t2, pts2, obs0, obs1, cam, huber_px)
        if new[0] <= cost:
            done = _converged(cost, new[0], dc)
            r, t, pts, terms = r2, t2, pts2, new
            lam = max(lam / 10.0, 1e-9)
            if done:
                break
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    cost, hcc, gc, hcp, hpp, gp, nobs = terms
    dof = max(2 * nobs - 6 - 3 * pts.shape[0], 1)
    sigma2 = cost / dof
    cov = None
    try:
        hpp_inv = np.linalg.inv(hpp + 1e-12 * eye3)
        s_mat = hcc - np.sum(hcp @ hpp_inv @ np.swapaxes(hcp, 1, 2), axis=0)
        cov = np.linalg.inv(s_mat) * sigma2
    except np.linalg.LinAlgError:
        pass
    return Refined(r, t, pts, cov, float(np.sqrt(cost / max(nobs, 1))), it)


def refine_object_space(r, t, points, rays, iters: int = 30, tol: float = 1e-10) -> Refined:
    """The paper's three-point least squares on the inliers: points at time 1 on their
    rays, distances preserved.

    Alternates (a) each point moved by the motion and dropped onto its ray at time 1
    (the closest point on the ray) and (b) the rigid transform from the time-0 points
    to those (``kabsch``), until the motion stops changing.

    Args:
        points: (N, 3) previous left-frame points (from stereo); rays: (N, 3) current
            left-image rays (any length).
    """
    u = np.asarray(rays, float)
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    it = 0
    for it in range(1, iters + 1):  # noqa: B007 - the count is returned
        x1 = points @ r.T + t
        q = u * np.einsum('ni,ni->n', u, x1)[:, None]
        r2, t2 = kabsch(points, q)
        step = np.linalg.norm(r2 - r) + np.linalg.norm(t2 - t)
        r, t = r2, t2
        if step < tol:
            break
    return Refined(r, t, np.asarray(points, float), None, float('nan'), it)


def _sampson_px(r, t_unit, x0, x1, k):
    e = skew(t_unit) @ r
    kinv = np.linalg.inv(k)
    f = kinv.T @ e @ kinv
    return sampson_sq(f, x0, x1)


def _sphere_basis(t):
    a = np.array([1.0, 0.0, 0.0]) if abs(t[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(t, a)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(t, b1)


def refine_essential(r, t_unit, x0, x1, k, iters: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Newton on the Sampson distances (px) of matches x0 -> x1 (N, 2) over the
    rotation and the translation direction (5 degrees of freedom, numerical Jacobian).

    Returns the refined (R, t_unit) of ``T_c_p``.
    """
    def resid(rr, tt):
        return np.sqrt(np.maximum(_sampson_px(rr, tt, x0, x1, k), 0.0))

    def apply(rr, tt, d):
        b1, b2 = _sphere_basis(tt)
        tn = tt + d[3] * b1 + d[4] * b2
        return so3_exp(d[:3]) @ rr, tn / np.linalg.norm(tn)
    cost = float(np.sum(resid(r, t_unit) ** 2))
    eps = 1e-6
    for _ in range(iters):
        r0 = resid(r, t_unit)
        jac = np.empty((r0.size, 5))
        for i in range(5):
            d = np.zeros(5)
            d[i] = eps
            rp, tp = apply(r, t_unit, d)
            d[i] = -eps
            rm, tm = apply(r, t_unit, d)
            jac[:, i] = (resid(rp, tp) - resid(rm, tm)) / (2 * eps)
        try:
            step = -np.linalg.lstsq(jac, r0, rcond=None)[0]
        except np.linalg.LinAlgError:
            break
        r2, t2 = apply(r, t_unit, step)
        c2 = float(np.sum(resid(r2, t2) ** 2))
        if c2 < cost:
            r, t_unit, cost = r2, t2, c2
            if np.linalg.norm(step) < 1e-10:
                break
        else:
            break
    return r, t_unit


def scale_from_stereo(r, t_unit, points, curr_left, cam: StereoCamera, iters: int = 5,
                      threshold_px: float | None = None) -> float:
    """Length s of the translation ``t = s t_unit`` from stereo points (N, 3) at time 0
    and their current left pixels (N, 2): the median of the per-point linear estimates,
    then Gauss–Newton on the left reprojection error (of the points reprojecting within
    ``threshold_px`` at each step, if given: a wrong stereo match, invisible to the
    epipolar test, then does not bias the scale)."""
    a = points @ r.T
    m = np.stack([(curr_left[:, 0] - cam.cx) / cam.f, (curr_left[:, 1] - cam.cy) / cam.f,
                  np.ones(len(curr_left))], axis=1)
    mxa = np.cross(m, a)
    mxt = np.cross(m, np.broadcast_to(t_unit, m.shape))
    den = np.einsum('ni,ni->n', mxt, mxt)
    with np.errstate(invalid='ignore', divide='ignore'):
        per = -np.einsum('ni,ni->n', mxa, mxt) / den
    per = per[np.isfinite(per)]
    s = float(np.median(per)) if per.size else 0.0
    for _ in range(iters):
        x1 = a + s * t_unit
        uv, jp = _proj_jac(x1, cam, 0.0)
        res2 = uv - curr_left
        if threshold_px is not None:
            keep = np.sum(res2 * res2, axis=1) < threshold_px ** 2
            if keep.sum() < 1:
                break
            res2, jp = res2[keep], jp[keep]
        res = res2.ravel()
        j = (jp @ t_unit).ravel()
        jj = float(j @ j)
        if jj <= 0:
            break
        s -= float(j @ res) / jj
    return s


__all__ = ['Refined', 'refine_pose', 'refine_joint', 'refine_object_space', 'refine_essential',
           'scale_from_stereo']
