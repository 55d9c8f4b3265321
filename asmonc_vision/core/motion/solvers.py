"""Minimal and linear solvers for two-view and stereo motion, vectorised over hypotheses.

Every solver takes a stack of M minimal samples and returns every solution of each, with
a validity mask, so that RANSAC evaluates hundreds of hypotheses per numpy call.

* ``p3p_lambda_twist``: P3P after Persson & Nordberg (ECCV 2018), "Lambda Twist":
  one root of a cubic, an eigen-decomposition of a 3x3 matrix with a known zero
  eigenvalue, two quadratics, Gauss–Newton on the three depths.
* ``p3p_grunert``: Grunert's classic quartic (as reviewed by Haralick et al. 1994), the
  three-point method of Molton et al. 1998 (Section 4.1.2): the three points' depths
  along the rays from their inter-point distances, then the absolute orientation.
* ``kabsch``: least-squares rigid transform between point sets (Horn/Kabsch/Umeyama).
* ``fundamental_7pt``: the seven-point fundamental matrix (up to three solutions),
  ``fundamental_8pt``: the normalised linear (Hartley) one for refinement.
* ``decompose_essential``: the four (R, t) of an essential matrix and cheirality.

P3P convention: for bearings ``y_i`` (unit rays in the camera) and points ``x_i`` (in
the reference frame), solutions satisfy ``lambda_i * y_i = R @ x_i + t`` with
``lambda_i > 0``. Fundamental convention: ``x1^T F x0 = 0`` for pixels (u, v, 1) in
image 1 (current) and image 0 (previous).
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.motion.geometry import project_rotation, skew


def _cross_cols(d: np.ndarray) -> np.ndarray:
    """Cofactor matrices of (M, 3, 3) matrices (columns d1 x d2, d2 x d0, d0 x d1)."""
    c0, c1, c2 = d[..., :, 0], d[..., :, 1], d[..., :, 2]
    return np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=-1)


def _cubic_one_root(p2, p1, p0):
    """One real root of x^3 + p2 x^2 + p1 x + p0 (the largest when all three are real),
    with two Newton steps."""
    a = p1 - p2 * p2 / 3.0
    b = (2.0 * p2 ** 3 - 9.0 * p2 * p1) / 27.0 + p0
    c = b * b / 4.0 + a ** 3 / 27.0
    with np.errstate(invalid='ignore', divide='ignore'):
        sq = np.sqrt(np.maximum(c, 0.0))
        one = np.cbrt(-b / 2.0 + sq) + np.cbrt(-b / 2.0 - sq) - p2 / 3.0
        arg = np.clip(3.0 * b / (2.0 * np.where(a < 0, a, -1.0))
                      * np.sqrt(np.where(a < 0, -3.0 / a, 0.0)), -1.0, 1.0)
        three = 2.0 * np.sqrt(np.maximum(-a / 3.0, 0.0)) * np.cos(np.arccos(arg) / 3.0) - p2 / 3.0
    g = np.where(c > 0, one, three)
    for _ in range(2):
        f = ((g + p2) * g + p1) * g + p0
        df = (3.0 * g + 2.0 * p2) * g + p1
        with np.errstate(invalid='ignore', divide='ignore'):
            step = np.where(np.abs(df) > 1e-300, f / df, 0.0)
        g = g - step
    return g


def _refine_lambdas(lam, a, b, iters: int):
    """Gauss–Newton on |l_i y_i - l_j y_j|^2 = a_ij for depths lam (K, 3).

    a = (a12, a13, a23), b = (b12, b13, b23) (dot products of the bearings), each (K,).
    """
    a12, a13, a23 = a
    b12, b13, b23 = b
    for _ in range(iters):
        l1, l2, l3 = lam[:, 0], lam[:, 1], lam[:, 2]
        r = np.stack([l1 * l1 + l2 * l2 - 2 * b12 * l1 * l2 - a12,
                      l1 * l1 + l3 * l3 - 2 * b13 * l1 * l3 - a13,
                      l2 * l2 + l3 * l3 - 2 * b23 * l2 * l3 - a23], axis=-1)
        j = np.zeros(lam.shape[:1] + (3, 3))
        j[:, 0, 0] = 2 * l1 - 2 * b12 * l2
        j[:, 0, 1] = 2 * l2 - 2 * b12 * l1
        j[:, 1, 0] = 2 * l1 - 2 * b13 * l3
        j[:, 1, 2] = 2 * l3 - 2 * b13 * l1
        j[:, 2, 1] = 2 * l2 - 2 * b23 * l3
        j[:, 2, 2] = 2 * l3 - 2 * b23 * l2
        det = np.linalg.det(j)
        ok = np.abs(det) > 1e-12
        step = np.zeros_like(lam)
        if np.any(ok):
            step[ok] = np.linalg.solve(j[ok], r[ok][..., None])[..., 0]
        lam = lam - step
    return lam


def _pose_from_depths(y, x, lam):
    """(R, t) with lam_i y_i = R x_i + t from the three depths (K, 3), via the difference
    vectors (exact when the depths satisfy the distance constraints)."""
    p = lam[:, :, None] * y                                   # (K, 3, 3) points in camera
    v1, v2 = p[:, 0] - p[:, 1], p[:, 0] - p[:, 2]
    d1, d2 = x[:, 0] - x[:, 1], x[:, 0] - x[:, 2]
    yy = np.stack([v1, v2, np.cross(v1, v2)], axis=-1)
    xx = np.stack([d1, d2, np.cross(d1, d2)], axis=-1)
    ok = np.abs(np.linalg.det(xx)) > 1e-18
    r = np.full(yy.shape, np.nan)
    if np.any(ok):
        r[ok] = project_rotation(yy[ok] @ np.linalg.inv(xx[ok]))
    t = p[:, 0] - np.einsum('kij,kj->ki', r, x[:, 0])
    return r, t


def p3p_lambda_twist(y, x, refine_iters: int = 3):
    """Lambda Twist P3P for M samples.

    Args:
        y: (M, 3, 3) bearings (rows; need not be unit) of the three points, camera frame.
        x: (M, 3, 3) the three points (rows) in the reference frame, metres.
        refine_iters: Gauss–Newton iterations on the depths.
    Returns:
        R (M, 4, 3, 3), t (M, 4, 3), valid (M, 4) bool: up to four poses per sample with
        ``lambda y = R x + t``; invalid slots hold NaN.
    """
    y = np.asarray(y, float)
    x = np.asarray(x, float)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    m = y.shape[0]
    d12, d13, d23 = x[:, 0] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 2]
    a12, a13, a23 = (np.einsum('ki,ki->k', d, d) for d in (d12, d13, d23))
    b12 = np.einsum('ki,ki->k', y[:, 0], y[:, 1])
    b13 = np.einsum('ki,ki->k', y[:, 0], y[:, 2])
    b23 = np.einsum('ki,ki->k', y[:, 1], y[:, 2])
    z = np.zeros(m)
    d1 = np.stack([np.stack([a23, -a23 * b12, z], -1),
                   np.stack([-a23 * b12, a23 - a12, a12 * b23], -1),
                   np.stack([z, a12 * b23, -a12], -1)], axis=-2)
    d2 = np.stack([np.stack([a23, z, -a23 * b13], -1),
                   np.stack([z, -a13, a13 * b23], -1),
                   np.stack([-a23 * b13, a13 * b23, a23 - a13], -1)], axis=-2)
    cof1, cof2 = _cross_cols(d1), _cross_cols(d2)
    c3 = np.einsum('ki,ki->k', d2[:, :, 0], cof2[:, :, 0])
    c2 = np.einsum('kij,kij->k', d1, cof2)
    c1 = np.einsum('kij,kij->k', d2, cof1)
    c0 = np.einsum('ki,ki->k', d1[:, :, 0], cof1[:, :, 0])
    good = np.abs(c3) > 1e-14 * (np.abs(c2) + np.abs(c1) + np.abs(c0) + 1e-300)
    c3s = np.where(good, c3, 1.0)
    gamma = _cubic_one_root(c2 / c3s, c1 / c3s, c0 / c3s)
    d0 = d1 + gamma[:, None, None] * d2
    d0 = np.where(np.isfinite(d0), d0, 0.0)
    w, v = np.linalg.eigh(d0)
    order = np.argsort(np.abs(w), axis=1)
    rows = np.arange(m)
    sig1 = w[rows, order[:, 2]]
    sig2 = w[rows, order[:, 1]]
    e1 = v[rows, :, order[:, 2]]
    e2 = v[rows, :, order[:, 1]]
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = -sig2 / sig1
    good &= np.isfinite(ratio) & (ratio > -1e-9)
    s = np.sqrt(np.maximum(ratio, 0.0))

    lams, owners = [], []
    for sgn in (1.0, -1.0):
        n = e1 - sgn * s[:, None] * e2
        with np.errstate(invalid='ignore', divide='ignore'):
            w0 = -n[:, 1] / n[:, 0]
            w1 = -n[:, 2] / n[:, 0]
            qa = (a13 - a12) * w1 * w1 + 2.0 * a12 * b13 * w1 - a12
            qb = -2.0 * a13 * b12 * w1 + 2.0 * a12 * b13 * w0 - 2.0 * w0 * w1 * (a12 - a13)
            qc = (a13 - a12) * w0 * w0 - 2.0 * a13 * b12 * w0 + a13
            disc = qb * qb - 4.0 * qa * qc
            sq = np.sqrt(np.maximum(disc, 0.0))
            tau1 = np.where(qb > 0, 2.0 * qc / (-qb - sq), 2.0 * qc / (-qb + sq))
            tau2 = qc / (qa * tau1)
        for tau in (tau1, tau2):
            with np.errstate(invalid='ignore', divide='ignore'):
                l2 = np.sqrt(a23 / (tau * (tau - 2.0 * b23) + 1.0))
                l3 = tau * l2
                l1 = w0 * l2 + w1 * l3
            ok = good & (disc >= 0) & np.isfinite(tau) & (tau > 0) & np.isfinite(l2) & (l1 > 0)
            lam = np.stack([l1, l2, l3], axis=-1)
            lams.append(np.where(ok[:, None], lam, np.nan))
            owners.append(ok)
    lam = np.stack(lams, axis=1)                              # (M, 4, 3)
    valid = np.stack(owners, axis=1)                          # (M, 4)
    r_out = np.full((m, 4, 3, 3), np.nan)
    t_out = np.full((m, 4, 3), np.nan)
    if np.any(valid):
        k_idx, s_idx = np.nonzero(valid)
        lv = lam[k_idx, s_idx]
        aa = (a12[k_idx], a13[k_idx], a23[k_idx])
        bb = (b12[k_idx], b13[k_idx], b23[k_idx])
        lv = _refine_lambdas(lv, aa, bb, refine_iters)
        r, t = _pose_from_depths(y[k_idx], x[k_idx], lv)
        fine = (np.all(np.isfinite(r), axis=(1, 2)) & np.all(np.isfinite(t), axis=1)
                & np.all(lv > 0, axis=1))
        r_out[k_idx[fine], s_idx[fine]] = r[fine]
        t_out[k_idx[fine], s_idx[fine]] = t[fine]
        valid = np.zeros_like(valid)
        valid[k_idx[fine], s_idx[fine]] = True
    return r_out, t_out, valid


def _quartic_real_roots(coef):
    """Real roots of quartics (M, 5) (highest power first): (M, 4) with NaN for complex
    or missing roots; each polished by two Newton steps."""
    coef = np.asarray(coef, float)
    m = coef.shape[0]
    lead = coef[:, 0]
    ok = np.abs(lead) > 1e-14 * np.max(np.abs(coef), axis=1)
    comp = np.zeros((m, 4, 4))
    comp[:, 1:, :3] = np.eye(3)
    lead_s = np.where(ok, lead, 1.0)
    comp[:, 0, :] = -coef[:, 1:] / lead_s[:, None]
    roots = np.linalg.eigvals(comp)
    real = np.abs(roots.imag) <= 1e-6 * (1.0 + np.abs(roots.real))
    r = np.where(real & ok[:, None], roots.real, np.nan)
    for _ in range(2):
        f = np.zeros_like(r)
        df = np.zeros_like(r)
        for k in range(5):
            df = df * r + f
            f = f * r + coef[:, k:k + 1]
        with np.errstate(invalid='ignore', divide='ignore'):
            r = np.where(np.abs(df) > 1e-300, r - f / df, r)
    return r


def kabsch(a, b, w=None):
    """Least-squares rigid transforms ``b ≈ R a + t`` for stacks of point sets.

    Args:
        a, b: (..., K, 3) corresponding points; w: optional (..., K) weights >= 0.
    Returns:
        R (..., 3, 3), t (..., 3).
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if w is None:
        w = np.ones(a.shape[:-1])
    w = np.asarray(w, float)
    ws = np.sum(w, axis=-1, keepdims=True)
    ca = np.sum(a * w[..., None], axis=-2) / ws
    cb = np.sum(b * w[..., None], axis=-2) / ws
    h = np.einsum('...k,...ki,...kj->...ij', w, a - ca[..., None, :], b - cb[..., None, :])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
    dm = np.ones(u.shape[:-2] + (3,))
    dm[..., 2] = d
    r = np.swapaxes(vt, -1, -2) @ (dm[..., :, None] * np.swapaxes(u, -1, -2))
    t = cb - np.einsum('...ij,...j->...i', r, ca)
    return r, t


def p3p_grunert(y, x):
    """Grunert's three-point solution (the quartic in v = s3/s1, Haralick et al. 1994).

    The depths s_i of the three points along their rays follow from the inter-point
    distances (a = |x2 - x3|, b = |x1 - x3|, c = |x1 - x2|) and the angles between the
    rays; the motion is then the absolute orientation (``kabsch``) taking the points x
    to the points s_i y_i.

    Args / Returns: as ``p3p_lambda_twist``.
    """
    y = np.asarray(y, float)
    x = np.asarray(x, float)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    m = y.shape[0]
    a2 = np.sum((x[:, 1] - x[:, 2]) ** 2, axis=-1)
    b2 = np.sum((x[:, 0] - x[:, 2]) ** 2, axis=-1)
    c2 = np.sum((x[:, 0] - x[:, 1]) ** 2, axis=-1)
    ca = np.einsum('ki,ki->k', y[:, 1], y[:, 2])   # cos alpha: rays 2, 3
    cb = np.einsum('ki,ki->k', y[:, 0], y[:, 2])   # cos beta: rays 1, 3
    cg = np.einsum('ki,ki->k', y[:, 0], y[:, 1])   # cos gamma: rays 1, 2
    with np.errstate(invalid='ignore', divide='ignore'):
        amc = (a2 - c2) / b2
        apc = (a2 + c2) / b2
        bmc = (b2 - c2) / b2
        bma = (b2 - a2) / b2
        a4 = (amc - 1.0) ** 2 - 4.0 * c2 / b2 * ca * ca
        a3 = 4.0 * (amc * (1.0 - amc) * cb - (1.0 - apc) * ca * cg + 2.0 * c2 / b2 * ca * ca * cb)
        a2c = 2.0 * (amc * amc - 1.0 + 2.0 * amc * amc * cb * cb + 2.0 * bmc * ca * ca
                     - 4.0 * apc * ca * cb * cg + 2.0 * bma * cg * cg)
        a1 = 4.0 * (-amc * (1.0 + amc) * cb + 2.0 * a2 / b2 * cg * cg * cb
                    - (1.0 - apc) * ca * cg)
        a0 = (1.0 + amc) ** 2 - 4.0 * a2 / b2 * cg * cg
    coef = np.stack([a4, a3, a2c, a1, a0], axis=-1)
    fin = np.all(np.isfinite(coef), axis=1)
    coef[~fin] = 0.0
    v = _quartic_real_roots(coef)                             # (M, 4)
    with np.errstate(invalid='ignore', divide='ignore'):
        u = (((-1.0 + amc)[:, None] * v * v - 2.0 * (amc * cb)[:, None] * v
              + (1.0 + amc)[:, None]) / (2.0 * (cg[:, None] - v * ca[:, None])))
        s1 = np.sqrt(b2[:, None] / (1.0 + v * v - 2.0 * v * cb[:, None]))
    s2, s3 = u * s1, v * s1
    lam = np.stack([s1, s2, s3], axis=-1)                    # (M, 4, 3)
    valid = fin[:, None] & np.all(np.isfinite(lam), axis=-1) & np.all(lam > 0, axis=-1)
    r_out = np.full((m, 4, 3, 3), np.nan)
    t_out = np.full((m, 4, 3), np.nan)
    if np.any(valid):
        k_idx, s_idx = np.nonzero(valid)
        pts = lam[k_idx, s_idx][:, :, None] * y[k_idx]         # (K, 3, 3) points at time 1
        r, t = kabsch(x[k_idx], pts)
        r_out[k_idx, s_idx] = r
        t_out[k_idx, s_idx] = t
    return r_out, t_out, valid


# --- epipolar geometry -----------------------------------------------------------------

def hartley_normalisation(p) -> np.ndarray:
    """3x3 similarity moving pixels (N, 2) to zero mean and mean distance sqrt(2)."""
    p = np.asarray(p, float)
    c = p.mean(axis=0)
    s = np.sqrt(2.0) / max(float(np.mean(np.linalg.norm(p - c, axis=1))), 1e-12)
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def _apply(tm, p):
    return p @ tm[:2, :2].T + tm[:2, 2]


def _design(x0, x1):
    """Rows of the epipolar constraint x1^T F x0 = 0 for F flattened row-major."""
    u0, v0 = x0[..., 0], x0[..., 1]
    u1, v1 = x1[..., 0], x1[..., 1]
    one = np.ones_like(u0)
    return np.stack([u1 * u0, u1 * v0, u1, v1 * u0, v1 * v0, v1, u0, v0, one], axis=-1)


def fundamental_7pt(x0, x1, t0=None, t1=None):
    """Seven-point fundamental matrices for M samples.

    Args:
        x0, x1: (M, 7, 2) pixels in image 0 and image 1.
        t0, t1: Hartley normalisations (3, 3) to apply first (e.g. computed from all the
            matches); identity when None.
    Returns:
        F (M, 3, 3, 3), valid (M, 3): up to three solutions (unit Frobenius norm) with
        ``x1^T F x0 = 0`` in pixels.
    """
    x0 = np.asarray(x0, float)
    x1 = np.asarray(x1, float)
    t0 = np.eye(3) if t0 is None else t0
    t1 = np.eye(3) if t1 is None else t1
    a = _design(_apply(t0, x0), _apply(t1, x1))               # (M, 7, 9)
    _, _, vt = np.linalg.svd(a)
    f1 = vt[:, -1].reshape(-1, 3, 3)
    f2 = vt[:, -2].reshape(-1, 3, 3)

    def det_at(lam):
        return np.linalg.det(lam * f1 + (1.0 - lam) * f2)
    p0, p1, pm1, p2 = det_at(0.0), det_at(1.0), det_at(-1.0), det_at(2.0)
    c0 = p0
    c2 = (p1 + pm1) / 2.0 - c0
    c3 = (p2 - 4.0 * c2 - c0 - p1 + pm1) / 6.0
    c1 = (p1 - pm1) / 2.0 - c3
    m = x0.shape[0]
    scale = np.abs(c0) + np.abs(c1) + np.abs(c2) + np.abs(c3) + 1e-300
    ok = np.abs(c3) > 1e-12 * scale
    comp = np.zeros((m, 3, 3))
    comp[:, 1, 0] = comp[:, 2, 1] = 1.0
    c3s = np.where(ok, c3, 1.0)
    comp[:, 0, :] = -np.stack([c2, c1, c0], axis=-1) / c3s[:, None]
    roots = np.linalg.eigvals(comp)
    real = (np.abs(roots.imag) <= 1e-8 * (1.0 + np.abs(roots.real))) & ok[:, None]
    lam = np.where(real, roots.real, 0.0)
    f = lam[..., None, None] * f1[:, None] + (1.0 - lam[..., None, None]) * f2[:, None]
    f = np.swapaxes(t1, 0, 1)[None, None] @ f @ t0[None, None]
    f = f / np.linalg.norm(f, axis=(-2, -1), keepdims=True)
    f[~real] = np.nan
    return f, real


def fundamental_8pt(x0, x1, w=None) -> np.ndarray:
    """Normalised linear (eight-point) fundamental matrix from N >= 8 matches (N, 2),
    optionally weighted (N,), with rank 2 enforced; unit Frobenius norm."""
    x0 = np.asarray(x0, float)
    x1 = np.asarray(x1, float)
    t0, t1 = hartley_normalisation(x0), hartley_normalisation(x1)
    a = _design(_apply(t0, x0), _apply(t1, x1))
    if w is not None:
        a = a * np.sqrt(np.asarray(w, float))[:, None]
    _, _, vt = np.linalg.svd(a, full_matrices=False)
    f = vt[-1].reshape(3, 3)
    u, s, vt2 = np.linalg.svd(f)
    f = u @ np.diag([s[0], s[1], 0.0]) @ vt2
    f = t1.T @ f @ t0
    return f / np.linalg.norm(f)


def sampson_sq(f, x0, x1) -> np.ndarray:
    """Squared Sampson distances (px^2) of matches (N, 2) under F (..., 3, 3); (..., N)."""
    f = np.asarray(f, float)
    h0 = np.concatenate([x0, np.ones((x0.shape[0], 1))], axis=1)
    h1 = np.concatenate([x1, np.ones((x1.shape[0], 1))], axis=1)
    fx0 = np.einsum('...ij,nj->...ni', f, h0)
    ftx1 = np.einsum('...ji,nj->...ni', f, h1)
    num = np.einsum('ni,...ni->...n', h1, fx0) ** 2
    den = fx0[..., 0] ** 2 + fx0[..., 1] ** 2 + ftx1[..., 0] ** 2 + ftx1[..., 1] ** 2
    with np.errstate(invalid='ignore', divide='ignore'):
        return num / den


def essential_from_fundamental(f, k) -> np.ndarray:
    """``E = K^T F K`` projected onto the essential manifold (singular values 1, 1, 0)."""
    e = k.T @ f @ k
    u, _, vt = np.linalg.svd(e)
    return u @ np.diag([1.0, 1.0, 0.0]) @ vt


def decompose_essential(e) -> list[tuple[np.ndarray, np.ndarray]]:
    """The four motions (R, t_unit) with ``E ~ [t]x R`` (``X1 = R X0 + t``)."""
    u, _, vt = np.linalg.svd(e)
    if np.linalg.det(u) < 0:
        u = -u
    if np.linalg.det(vt) < 0:
        vt = -vt
    w = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    r1, r2 = u @ w @ vt, u @ w.T @ vt
    t = u[:, 2]
    return [(r1, t), (r1, -t), (r2, t), (r2, -t)]


def triangulate_two_view(r, t, m0, m1) -> tuple[np.ndarray, np.ndarray]:
    """Depths of normalised rays m0 (N, 3) in view 0 and m1 (N, 3) in view 1 with
    ``X1 = R X0 + t``, by least squares on ``z1 m1 = z0 R m0 + t``. Returns (z0, z1)."""
    rm0 = m0 @ r.T
    # [R m0, -m1] [z0, z1]^T = -t
    a11 = np.einsum('ni,ni->n', rm0, rm0)
    a12 = -np.einsum('ni,ni->n', rm0, m1)
    a22 = np.einsum('ni,ni->n', m1, m1)
    b1 = -rm0 @ t
    b2 = m1 @ t
    det = a11 * a22 - a12 * a12
    with np.errstate(invalid='ignore', divide='ignore'):
        z0 = (a22 * b1 - a12 * b2) / det
        z1 = (a11 * b2 - a12 * b1) / det
    return z0, z1


def choose_by_cheirality(e, m0, m1):
    """The (R, t_unit) of E that puts most matches in front of both cameras, with that
    count."""
    best, best_n = None, -1
    for r, t in decompose_essential(e):
        z0, z1 = triangulate_two_view(r, t, m0, m1)
        n = int(np.sum((z0 > 0) & (z1 > 0)))
        if n > best_n:
            best, best_n = (r, t), n
    return best[0], best[1], best_n


__all__ = ['p3p_lambda_twist', 'p3p_grunert', 'kabsch', 'fundamental_7pt', 'fundamental_8pt',
           'sampson_sq', 'essential_from_fundamental', 'decompose_essential',
           'choose_by_cheirality', 'triangulate_two_view', 'hartley_normalisation', 'skew']
