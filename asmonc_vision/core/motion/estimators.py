"""Robust stereo motion estimators: the paper's methods and the modern one.

Input: ``Correspondences`` of N features: their pixels in the previous left and right
images (a stereo match, so a 3-D point) and in the current left image (a temporal
match), and where known in the current right image. Output: ``MotionEstimate`` with the
egomotion ``T_p_c`` (``X_prev = R @ X_curr + t``; see ``geometry``).

Methods (``METHODS``):

* ``essential`` (Molton et al. 1998, 4.1.1, Table 3): the fundamental matrix of
  previous-left to current-left from seven points in RANSAC (Sampson distance), the
  essential matrix ``E = K^T F K`` from the known intrinsics decomposed into R and the
  translation direction (cheirality), absolute scale from the stereo points; least
  squares on the inliers: eight-point F, Sampson-error Gauss–Newton, scale fit.
* ``three_point`` (4.1.2, Table 2): stereo 3-D points at time 0, their rays at time 1,
  Grunert's P3P from the preserved inter-point distances then the absolute
  orientation, in RANSAC (left reprojection error); least squares on the inliers: points
  constrained to their rays, distances preserved (``refine_object_space``).
* ``stereo_3d`` (the paper's third method, "higher errors"): 3-D points from stereo at
  both times, absolute orientation of three in RANSAC, least squares (Kabsch) on all
  inliers.
* ``p3p_gn``: Lambda Twist P3P in LO-RANSAC scored in both current images, then
  Gauss–Newton/LM on the reprojection error in both current images (points fixed).
* ``stereo_ba`` (default, the modern method): as ``p3p_gn``, then the two-view stereo
  bundle adjustment (pose and points on all four images).
* ``opencv``: ``cv2.solvePnPRansac`` (AP3P) + ``cv2.solvePnPRefineLM`` on the current
  left image, for reference.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.motion.geometry import (adjoint, bearings, invert, project, skew,
                                                triangulate)
from asmonc_vision.core.motion.refine import (refine_essential, refine_joint,
                                              refine_object_space, refine_pose,
                                              scale_from_stereo)
from asmonc_vision.core.motion.solvers import (choose_by_cheirality, essential_from_fundamental,
                                               fundamental_7pt, fundamental_8pt,
                                               hartley_normalisation, kabsch, p3p_grunert,
                                               p3p_lambda_twist, sampson_sq)

METHODS = ('essential', 'three_point', 'stereo_3d', 'p3p_gn', 'stereo_ba', 'opencv')


@dataclass
class Correspondences:
    """N features matched across the two stereo pairs. Pixels (u, v) of the rectified
    images, (N, 2) float64; NaN rows where a feature has no match in that image.

    Attributes:
        prev_left, prev_right: the stereo match at the previous instant (required).
        curr_left: the temporal match in the current left image (required).
        curr_right: its stereo match in the current right image (optional: NaN rows).
    """

    prev_left: np.ndarray
    prev_right: np.ndarray
    curr_left: np.ndarray
    curr_right: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.prev_left)
        if self.curr_right is None:
            self.curr_right = np.full((n, 2), np.nan)
        for name in ('prev_left', 'prev_right', 'curr_left', 'curr_right'):
            a = np.asarray(getattr(self, name), float).reshape(-1, 2)
            if len(a) != n:
                raise ValueError(f'Correspondences.{name} has {len(a)} rows, expected {n}')
            setattr(self, name, a)

    def __len__(self) -> int:
        return len(self.prev_left)

    def subset(self, idx) -> 'Correspondences':
        assert self.curr_right is not None             # filled in __post_init__
        return Correspondences(self.prev_left[idx], self.prev_right[idx], self.curr_left[idx],
                               self.curr_right[idx])


@dataclass
class RansacSettings:
    """Robust estimation settings shared by every method.

    Attributes:
        threshold_px: inlier bound on the reprojection (or Sampson) error, pixels.
        max_iterations: most minimal samples drawn.
        confidence: stop once this sure that an all-inlier sample was drawn.
        batch: minimal samples solved per vectorised call.
        min_inliers: fewer inliers: the estimate is refused.
        huber_px: Huber threshold of the final least squares (0: plain), pixels.
        refine_iterations: Gauss–Newton/LM iterations of the final refinement.
        local_optimisation: LO-RANSAC (modern methods only).
    """

    threshold_px: float = 2.0
    max_iterations: int = 300
    confidence: float = 0.999
    batch: int = 64
    min_inliers: int = 12
    huber_px: float = 1.0
    refine_iterations: int = 8
    local_optimisation: bool = True


@dataclass
class MotionEstimate:
    """A motion estimate between the previous and the current stereo pair.

    Attributes:
        ok: False when no acceptable motion was found (then R, t are identity/zero).
        R, t: the egomotion ``T_p_c``: ``X_prev = R @ X_curr + t`` (t metres).
        inliers: (N,) bool over the input correspondences.
        cov: (6, 6) covariance of the left perturbation of ``T_p_c`` (previous-frame
            axes; translation m then rotation rad), or None.
        rms_px: reprojection RMS of the inliers after refinement, px (NaN if unknown).
        hypotheses: minimal samples drawn.
        reason: why ``ok`` is False ('' when ok).
        seconds: wall time of the estimate.
    """

    ok: bool
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    cov: np.ndarray | None = None
    rms_px: float = float('nan')
    hypotheses: int = 0
    reason: str = ''
    seconds: float = 0.0

    @property
    def num_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))


# --- RANSAC -----------------------------------------------------------------------------

def sample_indices(n: int, k: int, m: int, rng: np.random.Generator) -> np.ndarray:
    """m samples of k distinct indices in [0, n): (m, k) int."""
    idx = rng.integers(0, n, size=(m, k))
    for _ in range(50):
        s = np.sort(idx, axis=1)
        dup = np.any(s[:, 1:] == s[:, :-1], axis=1)
        if not np.any(dup):
            break
        idx[dup] = rng.integers(0, n, size=(int(dup.sum()), k))
    return idx


def ransac(n: int, k: int, hypothesize: Callable, residuals_sq: Callable, thr: float,
           rng: np.random.Generator, settings: RansacSettings,
           local_opt: Callable | None = None):
    """MSAC over models of k-point samples, vectorised in batches, adaptive stopping.

    Args:
        hypothesize: (m, k) sample indices -> (K, ...) model array (K may be 0).
        residuals_sq: (K, ...) models -> (K, n) squared errors, px^2 (NaN = outlier).
        thr: inlier bound, px.
        local_opt: optional (model, inlier mask) -> model or None, run whenever a new
            best model is found (LO-RANSAC: a least-squares fit on its inliers); its model
            is kept if it scores better.
    Returns:
        (best model or None, inlier mask (n,), hypotheses drawn).
    """
    thr2 = thr * thr
    best, best_cost, best_inl = None, np.inf, np.zeros(n, bool)
    drawn = 0
    needed = settings.max_iterations
    log_fail = math.log(max(1.0 - settings.confidence, 1e-12))

    def score(r2):
        r2 = np.where(np.isfinite(r2), r2, thr2)
        return np.sum(np.minimum(r2, thr2), axis=-1), r2 < thr2

    while drawn < needed:
        m = min(settings.batch, needed - drawn)
        idx = sample_indices(n, k, m, rng)
        drawn += m
        models = hypothesize(idx)
        if len(models) == 0:
            continue
        cost, inl = score(residuals_sq(models))
        j = int(np.argmin(cost))
        if cost[j] < best_cost:
            best, best_cost, best_inl = models[j], float(cost[j]), inl[j]
            if local_opt is not None and best_inl.sum() >= max(k + 3, 6):
                cand = local_opt(best, best_inl)
                if cand is not None:
                    c2, i2 = score(residuals_sq(cand[None])[0])
                    if c2 < best_cost:
                        best, best_cost, best_inl = cand, float(c2), i2
            w = best_inl.mean()
            if w > 0:
                p_good = w ** k
                if p_good >= 1.0:
                    needed = min(needed, drawn)
                else:
                    needed = min(settings.max_iterations,
                                 max(drawn, int(math.ceil(log_fail / math.log(1.0 - p_good)))))
    return best, best_inl, drawn


# --- helpers ----------------------------------------------------------------------------

def _pack(r, t):
    return np.concatenate([r.reshape(-1, 9), t.reshape(-1, 3)], axis=1)


def _unpack(m):
    m = np.asarray(m)
    if m.ndim == 1:
        return m[:9].reshape(3, 3), m[9:12]
    return m[:, :9].reshape(-1, 3, 3), m[:, 9:12]


def _reproj_sq(models, pts, z, cam: StereoCamera, off: float):
    """Squared reprojection errors (K, N) of points (N, 3) under models (K, 12) T_c_p."""
    r, t = _unpack(models)
    x1 = np.matmul(pts[None], np.swapaxes(r, 1, 2)) + t[:, None, :]
    with np.errstate(invalid='ignore', divide='ignore'):
        uv = project(x1, cam.f, cam.cx, cam.cy, off)
        e = np.sum((uv - z[None]) ** 2, axis=-1)
    return np.where(x1[..., 2] > 1e-6, e, np.nan)


def _finish(r_cp, t_cp, cov_cp, inliers, rms, drawn, t0) -> MotionEstimate:
    """MotionEstimate of T_p_c from a T_c_p solution and its covariance."""
    r, t = invert(r_cp, t_cp)
    cov = None
    if cov_cp is not None:
        # T_c_p <- exp(d) T_c_p  <=>  T_p_c <- T_p_c exp(-d) = exp(-Ad(T_p_c) d) T_p_c
        ad = adjoint(r, t)
        cov = ad @ cov_cp @ ad.T
    return MotionEstimate(True, r, t, inliers, cov, rms, drawn, '', time.perf_counter() - t0)


def _fail(n, reason, drawn, t0) -> MotionEstimate:
    return MotionEstimate(False, inliers=np.zeros(n, bool), hypotheses=drawn, reason=reason,
                          seconds=time.perf_counter() - t0)


# --- methods ----------------------------------------------------------------------------

def estimate_motion(method: str, corr: Correspondences, cam: StereoCamera,
                    settings: RansacSettings | None = None, rng=None) -> MotionEstimate:
    """Estimate the egomotion ``T_p_c`` from correspondences with one of ``METHODS``.

    Features whose previous stereo match has no positive disparity are ignored.

    Args:
        method: one of METHODS.
        corr: the correspondences.
        cam: the rectified stereo camera (f, cx, cy, baseline).
        settings: RANSAC and refinement settings (defaults: RansacSettings()).
        rng: seed or numpy Generator.
    """
    fn = {'essential': _essential, 'three_point': _three_point, 'stereo_3d': _stereo_3d,
          'p3p_gn': _p3p_gn, 'stereo_ba': _stereo_ba, 'opencv': _opencv}.get(method)
    if fn is None:
        raise ValueError(f"unknown motion method '{method}'; expected one of {', '.join(METHODS)}")
    settings = settings or RansacSettings()
    rng = np.random.default_rng(rng)
    t0 = time.perf_counter()
    n = len(corr)
    pts = triangulate(corr.prev_left, corr.prev_right, cam.f, cam.cx, cam.cy, cam.baseline)
    usable = (np.all(np.isfinite(pts), axis=1) & (pts[:, 2] > 0)
              & np.all(np.isfinite(corr.curr_left), axis=1))
    idx = np.nonzero(usable)[0]
    if idx.size < max(settings.min_inliers, 8):
        return _fail(n, f'too few matches ({idx.size})', 0, t0)
    est = fn(corr.subset(idx), pts[idx], cam, settings, rng, t0)
    full = np.zeros(n, bool)
    full[idx] = est.inliers
    est.inliers = full
    if est.ok and est.num_inliers < settings.min_inliers:
        return _fail(n, f'too few inliers ({est.num_inliers})', est.hypotheses, t0)
    return est


def _three_point_hyp(pts, rays, solver):
    def hyp(idx):
        r, t, v = solver(rays[idx], pts[idx])
        return _pack(r[v], t[v])
    return hyp


def _three_point(corr, pts, cam, st, rng, t0):
    rays = bearings(corr.curr_left, cam.f, cam.cx, cam.cy)
    best, inl, drawn = ransac(len(pts), 3, _three_point_hyp(pts, rays, p3p_grunert),
                              lambda m: _reproj_sq(m, pts, corr.curr_left, cam, 0.0),
                              st.threshold_px, rng, st)
    if best is None or inl.sum() < 4:
        return _fail(len(pts), 'no consistent motion', drawn, t0)
    r, t = _unpack(best)
    ref = refine_object_space(r, t, pts[inl], rays[inl])
    e = _reproj_sq(_pack(ref.R[None], ref.t[None]), pts, corr.curr_left, cam, 0.0)[0]
    inl = np.nan_to_num(e, nan=np.inf) < st.threshold_px ** 2
    rms = float(np.sqrt(np.mean(e[inl]))) if inl.any() else float('nan')
    return _finish(ref.R, ref.t, None, inl, rms, drawn, t0)


def _essential(corr, pts, cam, st, rng, t0):
    x0, x1 = corr.prev_left, corr.curr_left
    k = np.array([[cam.f, 0.0, cam.cx], [0.0, cam.f, cam.cy], [0.0, 0.0, 1.0]])
    n0, n1 = hartley_normalisation(x0), hartley_normalisation(x1)

    def hyp(idx):
        f, v = fundamental_7pt(x0[idx], x1[idx], n0, n1)
        return f[v]
    best, inl, drawn = ransac(len(pts), 7, hyp, lambda f: sampson_sq(f, x0, x1),
                              st.threshold_px, rng, st)
    if best is None or inl.sum() < 8:
        return _fail(len(pts), 'no consistent epipolar geometry', drawn, t0)
    f = fundamental_8pt(x0[inl], x1[inl])
    e = essential_from_fundamental(f, k)
    m0 = np.column_stack([(x0 - [cam.cx, cam.cy]) / cam.f, np.ones(len(x0))])
    m1 = np.column_stack([(x1 - [cam.cx, cam.cy]) / cam.f, np.ones(len(x1))])
    r, tu, _ = choose_by_cheirality(e, m0[inl], m1[inl])
    r, tu = refine_essential(r, tu, x0[inl], x1[inl], k)
    s = scale_from_stereo(r, tu, pts[inl], x1[inl], cam, threshold_px=st.threshold_px)
    t = s * tu
    e2 = sampson_sq(_fundamental_of(r, t, k), x0, x1)
    inl = np.nan_to_num(e2, nan=np.inf) < st.threshold_px ** 2
    rms = float(np.sqrt(np.mean(e2[inl]))) if inl.any() else float('nan')
    return _finish(r, t, None, inl, rms, drawn, t0)


def _fundamental_of(r, t, k):
    """Fundamental matrix of a motion T_c_p (pixels of the same camera K)."""
    kinv = np.linalg.inv(k)
    return kinv.T @ (skew(t) @ r) @ kinv


def _stereo_3d(corr, pts, cam, st, rng, t0):
    pts1 = triangulate(corr.curr_left, corr.curr_right, cam.f, cam.cx, cam.cy, cam.baseline)
    ok = np.all(np.isfinite(pts1), axis=1) & (pts1[:, 2] > 0)
    idx = np.nonzero(ok)[0]
    if idx.size < 8:
        return _fail(len(pts), f'too few current stereo matches ({idx.size})', 0, t0)
    p0, p1 = pts[idx], pts1[idx]
    zl, zr = corr.curr_left[idx], corr.curr_right[idx]

    def hyp(s):
        r, t = kabsch(p0[s], p1[s])
        return _pack(r, t)

    def res(m):
        return np.maximum(_reproj_sq(m, p0, zl, cam, 0.0), _reproj_sq(m, p0, zr, cam, cam.baseline))
    best, inl, drawn = ransac(len(idx), 3, hyp, res, st.threshold_px, rng, st)
    if best is None or inl.sum() < 4:
        return _fail(len(pts), 'no consistent motion', drawn, t0)
    r, t = kabsch(p0[inl], p1[inl])
    e = res(_pack(r[None], t[None]))[0]
    inl = np.nan_to_num(e, nan=np.inf) < st.threshold_px ** 2
    full = np.zeros(len(pts), bool)
    full[idx] = inl
    rms = float(np.sqrt(np.mean(e[inl]))) if inl.any() else float('nan')
    return _finish(r, t, None, full, rms, drawn, t0)


def _both_sq(models, pts, corr, cam):
    """Per-feature squared error: the worse of the current left and (where matched)
    right reprojection errors."""
    el = _reproj_sq(models, pts, corr.curr_left, cam, 0.0)
    er = _reproj_sq(models, pts, corr.curr_right, cam, cam.baseline)
    has_r = np.all(np.isfinite(corr.curr_right), axis=1)
    return np.where(has_r[None], np.fmax(el, er), el)


def _modern_ransac(corr, pts, cam, st, rng):
    rays = bearings(corr.curr_left, cam.f, cam.cx, cam.cy)

    def lo(model, inl):
        r, t = _unpack(model)
        ref = refine_pose(r, t, pts[inl], corr.curr_left[inl], corr.curr_right[inl], cam,
                          iters=3, huber_px=0.0)
        return _pack(ref.R[None], ref.t[None])[0]
    return ransac(len(pts), 3, _three_point_hyp(pts, rays, p3p_lambda_twist),
                  lambda m: _both_sq(m, pts, corr, cam), st.threshold_px, rng, st,
                  local_opt=lo if st.local_optimisation else None)


def _p3p_gn(corr, pts, cam, st, rng, t0, joint=False):
    best, inl, drawn = _modern_ransac(corr, pts, cam, st, rng)
    if best is None or inl.sum() < 4:
        return _fail(len(pts), 'no consistent motion', drawn, t0)
    r, t = _unpack(best)
    for rnd in range(2):
        if joint:
            ref = refine_joint(r, t, pts[inl], corr.prev_left[inl], corr.prev_right[inl],
                               corr.curr_left[inl], corr.curr_right[inl], cam,
                               iters=st.refine_iterations, huber_px=st.huber_px)
        else:
            ref = refine_pose(r, t, pts[inl], corr.curr_left[inl], corr.curr_right[inl],
                              cam, iters=st.refine_iterations, huber_px=st.huber_px)
        r, t = ref.R, ref.t
        # the inliers under the refined motion; refit once more if they changed
        e = _both_sq(_pack(r[None], t[None]), pts, corr, cam)[0]
        new = np.nan_to_num(e, nan=np.inf) < st.threshold_px ** 2
        if rnd == 1 or np.array_equal(new, inl) or new.sum() < 4:
            break
        inl = new
    return _finish(ref.R, ref.t, ref.cov, inl, ref.rms_px, drawn, t0)


def _stereo_ba(corr, pts, cam, st, rng, t0):
    return _p3p_gn(corr, pts, cam, st, rng, t0, joint=True)


def _opencv(corr, pts, cam, st, rng, t0):
    import cv2
    k = np.array([[cam.f, 0.0, cam.cx], [0.0, cam.f, cam.cy], [0.0, 0.0, 1.0]])
    cv2.setRNGSeed(int(rng.integers(0, 2 ** 31 - 1)))
    ok, rvec, tvec, inl_idx = cv2.solvePnPRansac(
        pts.astype(np.float64), corr.curr_left.astype(np.float64), k, None,
        iterationsCount=st.max_iterations, reprojectionError=st.threshold_px,
        confidence=st.confidence, flags=cv2.SOLVEPNP_AP3P)
    if not ok or inl_idx is None or len(inl_idx) < 4:
        return _fail(len(pts), 'no consistent motion', st.max_iterations, t0)
    inl = np.zeros(len(pts), bool)
    inl[inl_idx.ravel()] = True
    rvec, tvec = cv2.solvePnPRefineLM(pts[inl], corr.curr_left[inl], k, None, rvec, tvec)
    r, _ = cv2.Rodrigues(rvec)
    t = tvec.ravel()
    e = _reproj_sq(_pack(r[None], t[None]), pts, corr.curr_left, cam, 0.0)[0]
    inl = np.nan_to_num(e, nan=np.inf) < st.threshold_px ** 2
    rms = float(np.sqrt(np.mean(e[inl]))) if inl.any() else float('nan')
    return _finish(r, t, None, inl, rms, st.max_iterations, t0)


__all__ = ['METHODS', 'Correspondences', 'RansacSettings', 'MotionEstimate', 'estimate_motion',
           'ransac', 'sample_indices']
