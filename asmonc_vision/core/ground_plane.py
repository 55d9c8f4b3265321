"""Robust least-squares fit of the ground plane in disparity space (Molton et al. 1998).

The ground disparity is linear in the cyclopean image coordinates: ``d = a*u + b*v + c``
(see :mod:`asmonc_vision.core.camera`). :func:`fit_ground_plane` fits (a, b, c) to matched
edge features robustly -- RANSAC on minimal triples followed by least squares on the
inliers, or iteratively trimmed least squares -- and checks that the result is a
plausible ground below the cameras. Fits that fail return None; data never raise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import surface_kernels
from .jit import jit, warmed
from .camera import MetricPlane, StereoCamera, metric_from_plane, vector_norm
from .config import check_fields, param
from .npfast import flat_nonzero

#: Fitting methods accepted by :func:`fit_ground_plane`.
METHODS = ('ransac', 'trimmed')


@dataclass(frozen=True)
class PlausiblePlaneConfig:
    """The bounds a fitted plane must meet to be taken for the ground (see
    :func:`plane_is_plausible`); the settings of GPOD and of the SGBM baseline derive from
    it."""

    min_camera_height_m: float = param(
        0.2, 'A plane is plausible only if the left camera is at least this high above it, '
        'metres', range=(0.0, 100.0))
    max_camera_height_m: float = param(
        5.0, 'A plane is plausible only if the left camera is at most this high above it, '
        'metres', range=(0.01, 1000.0))
    max_plane_tilt_deg: float = param(
        75.0, "A plane is plausible only if its up normal is within this angle of the "
        "camera's up axis (-y), degrees", range=(1.0, 90.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.min_camera_height_m >= self.max_camera_height_m:
            raise ValueError(
                f'{type(self).__name__}.min_camera_height_m = {self.min_camera_height_m} must '
                f'be less than max_camera_height_m = {self.max_camera_height_m}')

    def plausibility(self) -> dict[str, float]:
        """The keyword arguments of :func:`plane_is_plausible` for these bounds."""
        return dict(min_height_m=self.min_camera_height_m,
                    max_height_m=self.max_camera_height_m,
                    max_tilt_deg=self.max_plane_tilt_deg)


@dataclass(frozen=True)
class PlaneFit:
    """A fitted ground plane ``d = a*u + b*v + c`` (cyclopean pixels).

    Attributes:
        abc: (3,) float64 plane parameters (a: px/px, b: px/px, c: px).
        cov: (3, 3) float64 covariance of (a, b, c) from the inlier residuals.
        num_features: number of inlier features used in the final least squares.
        residual_rms: RMS disparity residual of the inliers, pixels.
        inliers: (N,) bool mask over the input features.
        metric: the plane in the left optical frame, or None when no camera was given.
        residual_sigma: robust spread (1.4826 * MAD) of the inliers' residuals, pixels.
    """

    abc: np.ndarray
    cov: np.ndarray
    num_features: int
    residual_rms: float
    inliers: np.ndarray
    metric: MetricPlane | None
    residual_sigma: float = float('nan')


def lsq_plane(u: np.ndarray, v: np.ndarray, d: np.ndarray, w: np.ndarray | None = None,
              ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Least-squares plane ``d = a*u + b*v + c``, optionally weighted.

    Args:
        u, v, d: (N,) cyclopean columns, rows and disparities, pixels (N >= 3).
        w: (N,) non-negative weights, or None for ordinary least squares. The weights
            are relative (scaled to mean 1); the covariance assumes residuals of variance
            ``sigma^2 / w``.
    Returns:
        (abc (3,), cov (3, 3), residual_rms px (unweighted)), or None when degenerate
        (fewer than 3 points, zero weights, or the (u, v) points do not span a plane).
    """
    n = u.shape[0]
    if n < 3:
        return None
    if w is None:
        sw = float(n)
        mu, mv = float(u.mean()), float(v.mean())
        uu, vv = u - mu, v - mv
        wu, wv, wd, w1 = uu, vv, d, None
    else:
        w = np.asarray(w, np.float64)
        mean_w = float(w.mean())
        if not (np.isfinite(mean_w) and mean_w > 0):
            return None
        w = w / mean_w
        sw = float(w.sum())
        mu, mv = float(w @ u) / sw, float(w @ v) / sw
        uu, vv = u - mu, v - mv
        wu, wv, wd, w1 = w * uu, w * vv, w * d, w
    # Normal equations of the centred problem (the cross terms with the constant vanish).
    suu, suv, svv = float(wu @ uu), float(wu @ vv), float(wv @ vv)
    # Degenerate when the (u, v) scatter is (nearly) a line or a point.
    tr, det = (suu + svv) / n, (suu * svv - suv * suv) / (n * n)
    ev0 = 0.5 * tr - math.sqrt(max(0.25 * tr * tr - det, 0.0))
    if not (math.isfinite(ev0) and ev0 >= 0.25):          # < 0.5 px spread across
        return None
    ata = np.array([[suu, suv, 0.0], [suv, svv, 0.0], [0.0, 0.0, sw]])
    rhs = np.array([float(wd @ uu), float(wd @ vv), float(wd.sum())])
    try:
        ata_inv = np.linalg.inv(ata)
    except np.linalg.LinAlgError:
        return None
    p = ata_inv @ rhs
    res = d - (p[0] * uu + p[1] * vv + p[2])
    rms = float(np.sqrt(res @ res / n))
    sigma2 = float((res * res).sum() if w1 is None else (w1 * res) @ res) / max(n - 3, 1)
    # Back to (a, b, c): c = p2 - a*mu - b*mv, a linear map J of p.
    jac = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-mu, -mv, 1.0]])
    abc = jac @ p
    cov = jac @ (sigma2 * ata_inv) @ jac.T
    return abc, cov, rms


def _plausible_mask(cam: StereoCamera, a: np.ndarray, b: np.ndarray, c: np.ndarray,
                    min_height_m: float, max_height_m: float, max_tilt_deg: float) -> np.ndarray:
    """Vectorised :func:`plane_is_plausible` for many hypotheses (cyclopean height)."""
    wz = (c + a * cam.cx + b * cam.cy) / cam.f
    norm = np.sqrt(a * a + b * b + wz * wz) / cam.baseline
    with np.errstate(divide='ignore', invalid='ignore'):
        height = 1.0 / norm
        up_y = (b / cam.baseline) / norm            # = -normal_up[1] = n_down[1]
    # The left camera's height differs from the cyclopean one by at most B/2.
    slack = 0.5 * cam.baseline
    return (np.isfinite(height) & (up_y > np.cos(np.deg2rad(max_tilt_deg)))
            & (height >= min_height_m - slack) & (height <= max_height_m + slack))


@dataclass(frozen=True)
class _Prior:
    """`fit_ground_plane`'s soft prior on the plane's orientation: a plane whose upward
    normal is the angle t from ``up`` costs ``cost * (t / scale)^2`` more (in the fit's
    weighted squared disparity residuals, px^2)."""

    up: np.ndarray          # (3,) unit vector, left optical frame
    scale: float            # radians
    cost: float             # px^2 (weighted)

    def angles(self, cam: StereoCamera, a: np.ndarray, b: np.ndarray, c: np.ndarray
               ) -> np.ndarray:
        """The angles (radians) of the upward normals of the planes (a, b, c) (each
        (k,)) from ``up``."""
        wz = (c + a * cam.cx + b * cam.cy) / cam.f
        norm = np.sqrt(a * a + b * b + wz * wz)
        # the upward normal is -(a, b, wz) / norm (see `_plausible_mask`)
        dot = -(a * float(self.up[0]) + b * float(self.up[1]) + wz * float(self.up[2]))
        with np.errstate(divide='ignore', invalid='ignore'):
            return np.arccos(np.clip(dot / norm, -1.0, 1.0))

    def penalty(self, cam: StereoCamera, a: np.ndarray, b: np.ndarray, c: np.ndarray
                ) -> np.ndarray:
        """The (k,) costs of the planes (a, b, c) (each (k,)), px^2."""
        return self.cost * (self.angles(cam, a, b, c) / self.scale) ** 2

    def rows(self, cam: StereoCamera, abc: np.ndarray) -> np.ndarray | None:
        """(2, 3) R with ``|R abc|^2 ~ (t / scale)^2`` near ``abc`` (t the angle of its
        normal from ``up``, first order), or None for a degenerate plane: the plane's
        ``x = M abc = n_down / h`` projected on two axes across ``up``, over ``|x|``."""
        m = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                      [cam.cx / cam.f, cam.cy / cam.f, 1.0 / cam.f]])
        norm = vector_norm(m @ abc)
        if not (math.isfinite(norm) and norm > 0.0):
            return None
        helper = np.eye(3)[int(np.argmin(np.abs(self.up)))]
        e1 = np.cross(self.up, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(self.up, e1)
        return np.stack([e1, e2]) @ m / (norm * self.scale)


def _ransac_best(u: np.ndarray, v: np.ndarray, d: np.ndarray, threshold: float,
                 iterations: int, rng: np.random.Generator, cam: StereoCamera | None = None,
                 bounds: tuple[float, float, float] = (0.1, 10.0, 75.0),
                 weights: np.ndarray | None = None, confidence: float = 0.99,
                 batch: int = 16, max_score_points: int = 1000,
                 min_support_fraction: float = 0.0,
                 prior: _Prior | None = None) -> np.ndarray | None:
    """Best minimal-sample plane by MSAC score (truncated squared residual, optionally
    weighted per point by ``weights``).

    Hypotheses are drawn in batches; sampling stops once the number drawn exceeds the
    usual adaptive bound ``log(1 - confidence) / log(1 - w^3)`` (w the inlier fraction of
    the best hypothesis so far), or ``iterations``. With ``cam``, only hypotheses that
    are a plausible ground (``bounds`` = min height, max height, max tilt) are scored,
    so that a dominant non-ground plane (a wall, a car) cannot win. A hypothesis within
    ``threshold`` of fewer than ``min_support_fraction`` of the (scored) points is not a
    candidate: weighted by a power of the disparity, a few dozen wrong matches at large
    disparity (a long baseline searched from 1 m) outweigh thousands on the ground.
    With ``cam`` and ``prior``, each hypothesis's score adds its cost
    (`_Prior.penalty`, the prior's cost per point weight times the points' total
    weight).

    Returns:
        (3,) abc of the best hypothesis, or None if no usable sample was drawn.
    """
    n = u.shape[0]
    sel = rng.choice(n, size=max_score_points, replace=False) if n > max_score_points else None
    us, vs, ds = (u, v, d) if sel is None else (u[sel], v[sel], d[sel])
    ws = None if weights is None else (weights if sel is None else weights[sel])
    t2 = threshold * threshold
    w_total = float(us.shape[0] if ws is None else ws.sum())
    best, best_score, needed, drawn = None, np.inf, float(iterations), 0
    while drawn < min(needed, iterations):
        k = int(min(batch, iterations - drawn))
        drawn += k
        idx = rng.integers(0, n, size=(k, 3))
        pu, pv, pd = u[idx], v[idx], d[idx]                   # (k, 3) each
        u0, v0, d0 = pu[:, 0], pv[:, 0], pd[:, 0]
        au, av, ad = pu[:, 1] - u0, pv[:, 1] - v0, pd[:, 1] - d0
        bu, bv, bd = pu[:, 2] - u0, pv[:, 2] - v0, pd[:, 2] - d0
        # Normal (nu, nv, nd) = cross product of the two edges (as np.cross).
        nu = av * bd - ad * bv
        nv = ad * bu - au * bd
        nd = au * bv - av * bu
        good = np.abs(nd) > 1.0                               # (u, v) triangle area > 0.5 px^2
        if not good.all():
            nu, nv, nd, u0, v0, d0 = nu[good], nv[good], nd[good], u0[good], v0[good], d0[good]
        a = -nu / nd
        b = -nv / nd
        c = d0 - a * u0 - b * v0
        if cam is not None and a.size:
            ok = _plausible_mask(cam, a, b, c, *bounds)
            a, b, c = a[ok], b[ok], c[ok]
        if a.size == 0:
            continue
        # res = ds - (a*us + b*vs + c), sq = res^2; trunc = min(sq, t2); the share of the
        # points with sq <= t2
        trunc, within = _residuals(a, b, c, us, vs, ds, t2)
        score = trunc.sum(axis=1) if ws is None else trunc @ ws
        if prior is not None and cam is not None:
            score += prior.penalty(cam, a, b, c) * w_total
        if min_support_fraction > 0.0:
            score[within < min_support_fraction] = np.inf
        j = int(np.argmin(score))
        if np.isfinite(score[j]) and score[j] < best_score:
            best_score = float(score[j])
            best = np.array([a[j], b[j], c[j]])
            w = float(within[j])
            if w >= 1.0:
                needed = 0.0
            elif w > 0.0:
                needed = math.log(1.0 - confidence) / math.log(1.0 - w ** 3)
    return best


def _residuals(a: np.ndarray, b: np.ndarray, c: np.ndarray, us: np.ndarray,
               vs: np.ndarray, ds: np.ndarray, t2: float) -> tuple[np.ndarray, np.ndarray]:
    """The truncated squared residuals of the points (us, vs, ds) (N,) float64 px
    against the planes (a, b, c) (K,) float64: ((K, N) float64 ``min(res^2, t2)``, res
    = ``ds - (a us + b vs + c)``; (K,) float64 the share of the points with ``res^2 <=
    t2``), in numpy's arithmetic (`residuals_kernel` where it compiled: the same
    values)."""
    if nb_residuals is not None:
        return nb_residuals(a, b, c, us, vs, ds, float(t2))
    sq = np.multiply(a[:, None], us[None, :])
    sq += b[:, None] * vs[None, :]
    sq += c[:, None]
    np.subtract(ds[None, :], sq, out=sq)
    np.multiply(sq, sq, out=sq)
    return np.minimum(sq, t2), np.mean(sq <= t2, axis=1)


def residuals_kernel(a, b, c, us, vs, ds, t2):
    """`_residuals` as loops (for numba): each residual's operations in numpy's order
    (``(a u + b v) + c``, subtracted from d, squared), the minimum propagating NaN as
    np.minimum does, the share a count over N (np.mean's sum of ones, exact)."""
    k, n = a.shape[0], us.shape[0]
    trunc = np.empty((k, n))
    within = np.empty(k)
    for i in range(k):
        ai, bi, ci = a[i], b[i], c[i]
        cnt = 0
        for j in range(n):
            r = ds[j] - ((ai * us[j] + bi * vs[j]) + ci)
            sq = r * r
            if sq <= t2:
                cnt += 1
            trunc[i, j] = t2 if sq > t2 else sq
        within[i] = cnt / n if n else np.nan
    return trunc, within


#: ``residuals_kernel`` compiled (None without numba, or when `warm_up` failed)
nb_residuals = jit(residuals_kernel)


def warm_up() -> None:
    """Compile (or load from numba's cache) `residuals_kernel` before the first frame;
    without numba, or if that fails, `_residuals` takes the numpy path."""
    global nb_residuals
    z = np.zeros(2)
    nb_residuals = warmed(nb_residuals, z, z, z, z, z, z, 1.0)


def fast_median(x: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D array of finite values (the same arithmetic,
    without its overhead)."""
    n = x.shape[0]
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    p = np.partition(x, (k - 1, k))
    return float((p[k - 1] + p[k]) / 2.0)


def fast_percentile(x: np.ndarray, q: float) -> float:
    """``np.percentile(x, q)`` of a non-empty 1-D array of finite values, q in [0, 100]
    (numpy's 'linear' method and arithmetic, `surface_kernels.sorted_percentile`, on the
    array partitioned around the two order statistics it reads), without a sort."""
    n = x.shape[0]
    lo = min(math.floor((n - 1) * (q / 100.0)), n - 1)
    p = np.partition(x, (lo, min(lo + 1, n - 1)))
    return float(surface_kernels.sorted_percentile(p, q / 100.0))


def plane_is_plausible(cam: StereoCamera, abc: np.ndarray, *, min_height_m: float = 0.1,
                       max_height_m: float = 10.0, max_tilt_deg: float = 75.0,
                       ) -> MetricPlane | None:
    """The metric plane of (a, b, c) if it is a ground below the cameras, else None.

    A plausible ground has its upward normal pointing up in the image (``normal_up``
    has negative y in the optical frame, y being down), within ``max_tilt_deg`` of the
    optical frame's up axis (-y), and lies ``min_height_m`` .. ``max_height_m`` below the
    left camera.
    """
    abc = np.asarray(abc, float)
    if abc.shape != (3,) or not np.all(np.isfinite(abc)):
        return None
    metric = metric_from_plane(cam, abc)
    if metric is None:
        return None
    up_y = -float(metric.normal_up[1])
    if up_y <= np.cos(np.deg2rad(max_tilt_deg)):
        return None
    if not (min_height_m <= metric.height <= max_height_m):
        return None
    return metric


def fit_ground_plane(u, v, d, *, cam: StereoCamera | None = None, method: str = 'ransac',
                     inlier_threshold_px: float = 1.0, iterations: int = 1000,
                     weights: np.ndarray | None = None,
                     refine_iterations: int = 3, trim_fraction: float = 0.2,
                     min_features: int = 10, min_height_m: float = 0.1,
                     max_height_m: float = 10.0, max_tilt_deg: float = 75.0,
                     min_spread_px: float = 0.0, min_support_fraction: float = 0.0,
                     up_prior: np.ndarray | None = None, prior_scale_deg: float = 0.0,
                     prior_cost: float = 0.0, rng=None) -> PlaneFit | None:
    """Robust least-squares ground plane ``d = a*u + b*v + c`` from matched features.

    ``'ransac'``: the best of at most ``iterations`` random minimal triples (MSAC score
    with ``inlier_threshold_px``; adaptive stopping at 99% confidence), then least squares
    on its inliers, re-selecting inliers (``|residual| <= inlier_threshold_px``) and
    refitting ``refine_iterations`` times.
    ``'trimmed'``: least squares on all, then ``refine_iterations`` times drop the
    ``trim_fraction`` largest residuals of the current inliers and refit; the final
    inliers are those within ``max(inlier_threshold_px, 2.5 * rms)``.
    ``weights`` weight the points in the RANSAC score and the final least squares (e.g.
    a power of the disparity, so that of two competing surfaces the nearer one -- the
    ground the wearer stands on -- wins, and far features, where the ground is least
    flat and least well measured, count less).

    Args:
        u, v, d: (N,) cyclopean column, row, disparity of each feature, pixels.
        cam: if given, the fit must be a plausible ground below the cameras
            (see :func:`plane_is_plausible`) and ``PlaneFit.metric`` is filled.
        method: 'ransac' or 'trimmed'.
        inlier_threshold_px: inlier residual bound, pixels of disparity (> 0).
        iterations: most RANSAC hypotheses (>= 1).
        weights: (N,) non-negative point weights (RANSAC score and 'ransac' least
            squares), or None (all 1).
        refine_iterations: inlier re-selection / trimming rounds (>= 0).
        trim_fraction: fraction trimmed per round for 'trimmed', in [0, 0.9].
        min_features: least number of inliers for a valid fit (>= 3).
        min_height_m, max_height_m, max_tilt_deg: plausibility bounds (with ``cam``).
        min_spread_px: least spread of the inliers across their main direction in the
            image (the standard deviation of (u, v) along the minor principal axis),
            pixels (>= 0; 0: any). Inliers along one line (the only grout joint of
            smooth slabs) leave the plane free to turn about it.
        min_support_fraction: 'ransac': least fraction of the features (unweighted)
            within ``inlier_threshold_px`` of a hypothesis for it to be scored, in
            [0, 1] (0: any). With ``weights`` growing with the disparity, the
            best-scored plane can otherwise be a chance consensus of a few wrong matches
            at large disparity.
        up_prior: (3,) the world's up direction in the left optical frame (gravity, from
            an inclinometer), or None: with ``cam``, 'ransac' and ``prior_scale_deg``,
            ``prior_cost`` > 0, a plane whose upward normal is the angle t from it costs
            as much as ``prior_cost * (t / prior_scale_deg)^2`` of the features (by
            weight) lying ``inlier_threshold_px`` off it, in the RANSAC score and (two
            pseudo-observations) the final least squares: features that leave the tilt
            free (a narrow band of ground rows, obstacles' vertical edges) cannot tilt it.
        prior_scale_deg, prior_cost: that prior's angle scale (degrees) and cost (a
            fraction of the features); 0: no prior.
        rng: int seed or numpy Generator (RANSAC sampling).
    Returns:
        The PlaneFit, or None when the fit fails (too few points, degenerate, or not a
        plausible ground).
    Raises:
        ValueError: unknown method or bad argument values (never for the data).
    """
    _check_arguments(method, inlier_threshold_px, min_spread_px)
    min_features = max(int(min_features), 3)
    data = _finite_data(u, v, d, weights, min_features)
    if data is None:
        return None
    uf, vf, df, wf, finite = data
    n = finite.shape[0]
    thr = float(inlier_threshold_px)
    prior = _prior(cam, up_prior, prior_scale_deg, prior_cost * thr * thr)
    if method == 'ransac':
        found = _fit_ransac(uf, vf, df, wf, thr, iterations, refine_iterations, min_features,
                            np.random.default_rng(rng), cam,
                            (min_height_m, max_height_m, max_tilt_deg), min_support_fraction,
                            prior)
    else:
        found = _fit_trimmed(uf, vf, df, thr, refine_iterations, trim_fraction, min_features)
    if found is None:
        return None
    inl, fit = found
    abc, cov, rms = fit
    if int(inl.sum()) < min_features or not np.all(np.isfinite(abc)):
        return None
    if min_spread_px > 0 and _minor_spread(uf[inl], vf[inl]) < min_spread_px:
        return None
    metric = None
    if cam is not None:
        metric = plane_is_plausible(cam, abc, min_height_m=min_height_m,
                                    max_height_m=max_height_m, max_tilt_deg=max_tilt_deg)
        if metric is None:
            return None
    mask = np.zeros(n, bool)
    sel = flat_nonzero(inl)
    mask[flat_nonzero(finite)[sel]] = True
    res = df[sel] - (abc[0] * uf[sel] + abc[1] * vf[sel] + abc[2])
    sigma = float(1.4826 * fast_median(np.abs(res - fast_median(res))))
    return PlaneFit(abc=np.asarray(abc, np.float64), cov=np.asarray(cov, np.float64),
                    num_features=int(inl.sum()), residual_rms=float(rms), inliers=mask,
                    metric=metric, residual_sigma=sigma)


def _check_arguments(method: str, inlier_threshold_px: float, min_spread_px: float) -> None:
    """ValueError for `fit_ground_plane`'s bad argument values."""
    if method not in METHODS:
        raise ValueError(f'method must be one of {METHODS}, got {method!r}')
    if not inlier_threshold_px > 0:
        raise ValueError(f'inlier_threshold_px must be > 0, got {inlier_threshold_px}')
    if not min_spread_px >= 0:
        raise ValueError(f'min_spread_px must be >= 0, got {min_spread_px}')


def _prior(cam: StereoCamera | None, up, scale_deg: float, cost: float) -> _Prior | None:
    """`fit_ground_plane`'s orientation prior (``cost``: px^2 per unit weight), or None
    when it has none (no camera, no or a degenerate up vector, a zero scale or cost)."""
    if cam is None or up is None or not (scale_deg > 0.0 and cost > 0.0):
        return None
    up = np.asarray(up, np.float64).reshape(3)
    norm = vector_norm(up)
    if not (math.isfinite(norm) and norm > 1e-9):
        return None
    return _Prior(up=up / norm, scale=math.radians(scale_deg), cost=float(cost))


def _finite_data(u, v, d, weights, min_features: int):
    """(u, v, d, weights of the finite features (weights None or clipped to >= 0, 0 where
    not finite), the mask of those features), or None when fewer than ``min_features``
    are finite. Raises ValueError for inputs of different lengths."""
    u = np.asarray(u, np.float64).ravel()
    v = np.asarray(v, np.float64).ravel()
    d = np.asarray(d, np.float64).ravel()
    if not (u.shape == v.shape == d.shape):
        raise ValueError(f'u, v, d must have the same length, got {u.shape}, {v.shape}, {d.shape}')
    n = u.shape[0]
    finite = np.isfinite(u) & np.isfinite(v) & np.isfinite(d)
    n_finite = int(np.count_nonzero(finite))
    if n_finite < min_features:
        return None
    everything = n_finite == n
    uf, vf, df = (u, v, d) if everything else (u[finite], v[finite], d[finite])
    wf = None
    if weights is not None:
        w_all = np.asarray(weights, np.float64).ravel()
        if w_all.shape != u.shape:
            raise ValueError(f'weights must have the length of u, got {w_all.shape} vs {u.shape}')
        w_f = w_all if everything else w_all[finite]
        wf = np.where(np.isfinite(w_f), np.maximum(w_f, 0.0), 0.0)
    return uf, vf, df, wf, finite


def _fit_ransac(uf, vf, df, wf, thr: float, iterations: int, refine_iterations: int,
                min_features: int, gen, cam, bounds: tuple, min_support_fraction: float,
                prior: _Prior | None = None):
    """`fit_ground_plane`'s 'ransac' method: (inliers, lsq_plane fit) or None (with
    ``prior``: `_lsq_prior` in place of `lsq_plane`)."""
    abc = _ransac_best(uf, vf, df, thr, max(int(iterations), 1), gen, cam=cam,
                       bounds=bounds, weights=wf,
                       min_support_fraction=float(min_support_fraction), prior=prior)
    if abc is None:
        return None
    inl = np.abs(df - (abc[0] * uf + abc[1] * vf + abc[2])) <= thr
    rounds = max(int(refine_iterations), 0) + 1
    for it in range(rounds):
        sel = flat_nonzero(inl)
        if sel.size < min_features:
            return None
        fit = lsq_plane(uf[sel], vf[sel], df[sel], None if wf is None else wf[sel])
        if fit is not None and prior is not None:
            w_total = float(uf.shape[0] if wf is None else wf.sum())
            fit = _lsq_prior(cam, uf[sel], vf[sel], df[sel], None if wf is None else wf[sel],
                             prior, w_total, abc)
        if fit is None:
            return None
        abc = fit[0]
        new = np.abs(df - (abc[0] * uf + abc[1] * vf + abc[2])) <= thr
        if it == rounds - 1 or np.array_equal(new, inl):
            break           # ``fit`` is the least squares on ``inl``
        inl = new
    return inl, fit


def _lsq_prior(cam: StereoCamera, u: np.ndarray, v: np.ndarray, d: np.ndarray,
               w: np.ndarray | None, prior: _Prior, w_total: float, abc0: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """`lsq_plane` of the features (u, v, d) (N,) with weights ``w`` (None: 1) plus the
    orientation prior's two pseudo-observations (`_Prior.rows`, linearised at ``abc0``)
    weighted by its cost times ``w_total`` (the total weight of all the features): the
    least squares of ``sum w r^2 + cost * w_total * (t / scale)^2``. Same returns."""
    rows = prior.rows(cam, abc0)
    if rows is None:
        return None
    n = u.shape[0]
    ww = np.ones(n) if w is None else np.asarray(w, np.float64)
    mean_w = float(ww.mean())
    if not (np.isfinite(mean_w) and mean_w > 0):
        return None
    ww = ww / mean_w
    a_mat = np.stack([u, v, np.ones(n)], axis=1)
    ata = (a_mat * ww[:, None]).T @ a_mat + (prior.cost * w_total / mean_w) * (rows.T @ rows)
    try:
        ata_inv = np.linalg.inv(ata)
    except np.linalg.LinAlgError:
        return None
    abc = ata_inv @ ((a_mat * ww[:, None]).T @ d)
    res = d - a_mat @ abc
    rms = float(np.sqrt(res @ res / n))
    sigma2 = float((ww * res) @ res) / max(n - 3, 1)
    return abc, sigma2 * ata_inv, rms


def _fit_trimmed(uf, vf, df, thr: float, refine_iterations: int, trim_fraction: float,
                 min_features: int):
    """`fit_ground_plane`'s 'trimmed' method: (inliers, lsq_plane fit) or None."""
    inl = np.ones(uf.shape[0], bool)
    fit = lsq_plane(uf, vf, df)
    if fit is None:
        return None
    frac = min(max(float(trim_fraction), 0.0), 0.9)
    for _ in range(max(int(refine_iterations), 0)):
        abc = fit[0]
        res = np.abs(df - (abc[0] * uf + abc[1] * vf + abc[2]))
        k = int(inl.sum())
        keep = int(np.ceil(k * (1.0 - frac)))
        if keep < min_features:
            break
        cut = np.partition(res[inl], keep - 1)[keep - 1]
        inl = inl & (res <= cut)
        fit = lsq_plane(uf[inl], vf[inl], df[inl])
        if fit is None:
            return None
    abc = fit[0]
    res = np.abs(df - (abc[0] * uf + abc[1] * vf + abc[2]))
    inl = res <= max(thr, 2.5 * fit[2])
    if int(inl.sum()) < min_features:
        return None
    fit = lsq_plane(uf[inl], vf[inl], df[inl])
    if fit is None:
        return None
    return inl, fit


def _minor_spread(u: np.ndarray, v: np.ndarray) -> float:
    """Standard deviation (pixels) of the points (u, v) (N,) along the minor principal
    axis of their scatter: about 0 for points on one line."""
    if u.shape[0] < 3:
        return 0.0
    du, dv = u - u.mean(), v - v.mean()
    suu, svv, suv = float(du @ du), float(dv @ dv), float(du @ dv)
    # the smaller eigenvalue of the 2 x 2 scatter matrix [[suu, suv], [suv, svv]]
    lam = 0.5 * (suu + svv) - math.sqrt(max(0.25 * (suu - svv) ** 2 + suv ** 2, 0.0))
    return math.sqrt(max(lam, 0.0) / u.shape[0])


def cyclopean_height(cam: StereoCamera, abc: np.ndarray) -> float:
    """The height of the cyclopean centre above the plane ``abc`` (3,), metres (inf for
    a plane of zero disparity everywhere)."""
    a, b, c = (float(x) for x in abc)
    wz = (c + a * cam.cx + b * cam.cy) / cam.f
    norm = math.sqrt(a * a + b * b + wz * wz) / cam.baseline
    return 1.0 / norm if norm > 0.0 else math.inf


def lsq_plane_at_height(cam: StereoCamera, u: np.ndarray, v: np.ndarray, d: np.ndarray,
                        height: float, w: np.ndarray | None = None) -> np.ndarray | None:
    """Least-squares plane ``d = a*u + b*v + c`` whose cyclopean centre lies ``height``
    metres above it: only its orientation is fitted.

    The plane is ``d = B * (x . r)`` with ``r = (u - cx, v - cy, f)`` and ``|x| = 1 / height``
    (x the downward normal over the height); the constrained least squares is
    ``(A^T W A + lam I) x = A^T W d`` with the multiplier lam that puts x on that sphere,
    found by bisection in the eigenbasis of ``A^T W A``.

    Args:
        cam: the rectified stereo camera.
        u, v, d: (N,) cyclopean columns, rows and disparities, pixels (N >= 2).
        height: the cyclopean centre's height above the plane, metres (> 0).
        w: (N,) non-negative weights, or None (all 1).
    Returns:
        (3,) abc, or None when degenerate (too few points, or a solution that is not
        unique).
    """
    if u.shape[0] < 2 or not (height > 0.0 and math.isfinite(height)):
        return None
    A = cam.baseline * np.stack([u - cam.cx, v - cam.cy, np.full(u.shape[0], cam.f)], axis=1)
    Aw = A if w is None else A * np.asarray(w, np.float64)[:, None]
    ata = Aw.T @ A
    atd = Aw.T @ d
    lam_i, Q = np.linalg.eigh(ata)
    g = Q.T @ atd
    target = 1.0 / (height * height)
    if not (np.all(np.isfinite(lam_i)) and np.all(np.isfinite(g))) or abs(g[0]) < 1e-12:
        return None

    def norm2(lam: float) -> float:
        return float(np.sum((g / (lam_i + lam)) ** 2))

    lo = -lam_i[0] + 1e-12 * max(abs(lam_i[-1]), 1.0)
    hi = max(abs(lam_i[-1]), 1.0)
    while norm2(hi) > target:
        hi *= 4.0
        if hi > 1e30:
            return None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if norm2(mid) > target:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * max(abs(hi), 1.0):
            break
    x = Q @ (g / (lam_i + 0.5 * (lo + hi)))
    B = cam.baseline
    return np.array([B * x[0], B * x[1], B * (cam.f * x[2] - cam.cx * x[0] - cam.cy * x[1])])


def predict_plane(cam: StereoCamera, abc: np.ndarray, R: np.ndarray, t: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """The ground plane carried through a camera motion (the prediction of the paper's
    dynamic ground-plane recalibration).

    The plane ``d = a*u + b*v + c`` is ``w . X = 1`` for cyclopean points X on it, with
    ``w = n_down / h`` (n_down the plane's downward unit normal, h the cyclopean centre's
    height above it) linear in (a, b, c): ``w = M (a, b, c)``, ``M = [[1, 0, 0], [0, 1, 0],
    [cx/f, cy/f, 1/f]] / B``. A motion ``X_prev = R X_curr + t`` of the left optical frame
    is ``X_prev = R X_curr + t_c`` of the cyclopean one (``t_c = R o + t - o``, o = (B/2, 0,
    0) the cyclopean centre in the left frame), so the plane seen now is
    ``w' = R^T w / s`` with ``s = 1 - w . t_c`` (the ratio of the camera's new height to
    its old one).

    Args:
        cam: the rectified stereo camera.
        abc: (3,) float64 plane (a: px/px, b: px/px, c: px) in the previous pair.
        R: (3, 3) rotation, t: (3,) translation (m) of the left camera from the previous
            pair to this one, ``X_prev = R X_curr + t`` (left optical frames, x right,
            y down, z forward; `/egomotion`'s convention).
    Returns:
        (abc', F): the (3,) plane in this pair and the (3, 3) Jacobian d abc' / d abc
        (the Kalman filter's state transition, ``P' = F P F^T + Q``); None when the
        camera would not be above the plane after the motion (s <= 0) or the input is
        not finite.
    """
    abc = np.asarray(abc, np.float64).reshape(3)
    R = np.asarray(R, np.float64).reshape(3, 3)
    t = np.asarray(t, np.float64).reshape(3)
    if not (np.all(np.isfinite(abc)) and np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return None
    M = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                  [cam.cx / cam.f, cam.cy / cam.f, 1.0 / cam.f]]) / cam.baseline
    M_inv = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                      [-cam.cx, -cam.cy, cam.f]]) * cam.baseline
    o = np.array([cam.baseline / 2.0, 0.0, 0.0])
    t_c = R @ o + t - o
    w = M @ abc
    s = 1.0 - float(w @ t_c)
    if not np.isfinite(s) or s <= 1e-6:
        return None
    Rt_w = R.T @ w
    w_new = Rt_w / s
    # d w' / d w = R^T / s + (R^T w) t_c^T / s^2
    J_w = R.T / s + np.outer(Rt_w, t_c) / s ** 2
    return M_inv @ w_new, M_inv @ J_w @ M
