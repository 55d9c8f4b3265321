"""The walk model's filter step compiled by numba (``core.jit``); `WalkModelEKF`
(`asmonc_vision.core.gait.model`) runs these kernels when they compiled, else its numpy
path.
"""
from __future__ import annotations

import math

import numpy as np

from asmonc_vision.core.gait.state import _D2R, I_F, I_O, I_R, I_TH, I_YA
from asmonc_vision.core.jit import jit

# ---------------------------------------------------------------------- compiled kernels
# The filter step compiled by numba (``core.jit``): the model (``_model_kernel``), the
# IMM prediction (``_imm_predict_kernel``), the iterated EKF update of both models with
# the attitude measurement (``_imm_update_kernel``, ``_combine_kernel``) and the attitude
# prediction (``_predict_attitude_kernel``). Each is the numpy path of ``WalkModelEKF``
# beside it, equation by equation: the same operations in the same order and the same
# BLAS/LAPACK calls (matrix products, the 3 x 3 inverse as a solve, the determinant from
# the LU factors), so both give the same numbers (test_gait compares them); only the
# Python and numpy call overhead on these small arrays is gone. Without numba, or if
# compiling fails, the numpy path runs.

#: (1 deg/s^2)^2: the straight model's yaw acceleration variance (``_no_accel``)
_NO_ACCEL_VAR = (1.0 * _D2R) ** 2
#: the prefilter table of no prefilter (gain 1, no phase)
_NO_TABLE = np.zeros((0, 4))


def _wrap_kernel(a):
    """``wrap_angle`` of a float, [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _model_kernel(x, s, sy, walking, table, df, k, A, axis, alpha, beta):
    """``WalkModelEKF.model`` at state x (n,): (h (3,), H (3, n)).

    Args:
        s: time offset from the filter time, s;  sy: the yaw ramp's (s minus the DC
            delay of the prefilter, if any).
        table: the prefilter's (|H|, arg H, d|H|/df, d arg H/df) on the grid 0, df,
            2 df, ... Hz (``Prefilter._table``), or (0, 4) for the true attitude.
        k, A, axis, alpha, beta: the ``StateLayout`` (A its sum_matrix).
    """
    n = x.shape[0]
    H = np.zeros((3, n))
    H[0, 2] = 1.0
    H[1, 3] = 1.0
    H[2, 4] = 1.0
    r = x[5]
    ya = x[6]
    # h_a = o_a [+ r sy + a_yaw sy^2 / 2 for yaw]
    h = np.empty(3)
    h[0] = x[2]
    h[1] = x[3]
    h[2] = x[4] + r * sy + 0.5 * ya * sy * sy
    H[2, 5] = sy
    H[2, 6] = 0.5 * sy * sy
    if not walking:
        return h, H
    f = x[0]
    m = k.shape[0]
    g = np.ones(m)
    psi = np.zeros(m)
    dg = np.zeros(m)
    dpsi = np.zeros(m)
    if table.shape[0] > 0:
        # |H|, arg H and their derivatives at k f / 2 (``Prefilter.gain_phase_array``)
        top = table.shape[0] - 1.0 - 1e-9          # the table's last interval
        for j in range(m):
            u = min(max(0.5 * k[j] * f / df, 0.0), top)
            i = int(u)
            w = u - i
            v = 1.0 - w
            g[j] = table[i, 0] * v + table[i + 1, 0] * w
            psi[j] = table[i, 1] * v + table[i + 1, 1] * w
            dg[j] = table[i, 2] * v + table[i + 1, 2] * w
            dpsi[j] = table[i, 3] * v + table[i + 1, 3] * w
    adv = x[1] + math.pi * f * s                   # theta + pi f s
    ps = math.pi * s
    gval = np.empty(m)
    gder = np.empty(m)
    dfh = np.empty(m)
    for j in range(m):
        u = k[j] * adv + psi[j]                    # u = k (theta + pi f s) + arg H
        su = math.sin(u)
        cu = math.cos(u)
        al = x[alpha[j]]
        be = x[beta[j]]
        val = al * su + be * cu                    # the harmonic before the gain
        der = al * cu - be * su                    # its derivative by u
        gval[j] = g[j] * val
        H[axis[j], alpha[j]] = g[j] * su           # dh/dalpha
        H[axis[j], beta[j]] = g[j] * cu            # dh/dbeta
        gder[j] = g[j] * k[j] * der
        # dh/df: the gain and phase of H at k f / 2, and the phase advance k pi s
        dfh[j] = 0.5 * k[j] * dg[j] * val + g[j] * der * k[j] * (ps + 0.5 * dpsi[j])
    h += np.dot(A, gval)                           # each axis's harmonics summed
    H[:, 1] = np.dot(A, gder)                      # dh/dtheta
    H[:, 0] = np.dot(A, dfh)
    return h, H


def _mix_kernel(xs, Ps, w0, w1):
    """``WalkModelEKF._mix``: (sum_i w_i x_i, sum_i w_i (P_i + e_i e_i^T)), the
    stride-phase difference wrapped."""
    n = xs.shape[1]
    d = xs[1] - xs[0]
    d[1] = _nb_wrap(d[1])
    x = xs[0] + w1 * d
    ww = w0 * w1
    P = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            P[i, j] = w0 * Ps[0, i, j] + w1 * Ps[1, i, j] + ww * (d[i] * d[j])
    return x, P


def _combine_kernel(xs, Ps, mu, lo, hi):
    """``WalkModelEKF._no_accel(0)`` (xs, Ps in place), then ``_combine``: the mixture
    (x, P) of the models by mu, the stride phase wrapped and the step frequency kept
    within [lo, hi]."""
    n = xs.shape[1]
    xs[0, 6] = 0.0
    for i in range(n):
        Ps[0, 6, i] = 0.0
        Ps[0, i, 6] = 0.0
    Ps[0, 6, 6] = _NO_ACCEL_VAR
    x, P = _nb_mix(xs, Ps, mu[0], mu[1])
    x[1] = _nb_wrap(x[1])
    x[0] = min(max(x[0], lo), hi)
    return x, P


def _imm_predict_kernel(xs, Ps, mu, p01, p10, F0, Q0, F1, Q1, lo, hi):
    """``WalkModelEKF.predict_to``: the IMM interaction, each model's Kalman prediction
    (filterpy's arithmetic) and the combination; returns (xs, Ps, mu, x, P)."""
    Pi = np.array([[1.0 - p01, p01], [p10, 1.0 - p10]])
    c = np.maximum(np.dot(Pi.T, mu), 1e-12)       # c_j = sum_i Pi_ij mu_i
    nxs = np.empty_like(xs)
    nPs = np.empty_like(Ps)
    for j in range(2):
        # mu_i|j = Pi_ij mu_i / c_j;  x0_j, P0_j = the mixture by mu_i|j
        x0, P0 = _nb_mix(xs, Ps, Pi[0, j] * mu[0] / c[j], Pi[1, j] * mu[1] / c[j])
        F = F0 if j == 0 else F1
        Q = Q0 if j == 0 else Q1
        nxs[j] = np.dot(F, x0)                     # x = F x0
        nPs[j] = 1.0 * np.dot(np.dot(F, P0), F.T) + Q   # P = F P0 F^T + Q
    mu_new = c / (c[0] + c[1])                     # mu_j = c_j
    x, P = _nb_combine(nxs, nPs, mu_new, lo, hi)
    return nxs, nPs, mu_new, x, P


def _iekf_kernel(xp, P, z, R, s, sy, walking, table, df, k, A, axis, alpha, beta,
                 iterations, lo, hi):
    """``WalkModelEKF._update_one`` with the attitude measurement model (yaw residual
    wrapped): (x, P, y, S, S^-1 (first iterate), iterations used)."""
    n = xp.shape[0]
    eye3 = np.eye(3)
    xi = xp
    H = np.zeros((3, n))
    K = np.zeros((n, 3))
    y0 = np.zeros(3)
    S0 = np.zeros((3, 3))
    S0i = np.zeros((3, 3))
    used = 0
    for it in range(iterations):
        h, H = _nb_model(xi, s, sy, walking, table, df, k, A, axis, alpha, beta)
        y = z - h                                  # innovation
        y[2] = _nb_wrap(y[2])
        y = y - np.dot(H, xp - xi)
        PHt = np.dot(P, H.T)
        S = np.dot(H, PHt) + R                     # S = H P H^T + R
        S_inv = np.ascontiguousarray(np.linalg.solve(S, eye3))
        K = np.dot(PHt, S_inv)                     # K = P H^T S^-1
        if it == 0:
            y0, S0, S0i = y, S, S_inv
        x_new = xp + np.dot(K, y)                  # x = x^- + K y
        done = np.max(np.abs(x_new - xi)) < 1e-3
        xi = x_new
        used = it + 1
        if done:
            break
    IKH = np.eye(n) - np.dot(K, H)
    # Joseph form: P = (I - K H) P^- (I - K H)^T + K R K^T
    P_new = np.dot(np.dot(IKH, P), IKH.T) + np.dot(np.dot(K, R), K.T)
    xi = xi.copy()
    xi[1] = _nb_wrap(xi[1])
    xi[0] = min(max(xi[0], lo), hi)
    return xi, P_new, y0, S0, S0i, used


def _imm_update_kernel(xs, Ps, mu, z, R, s, sy, walking, table, df, k, A, axis, alpha,
                       beta, iterations, lo, hi):
    """``WalkModelEKF.update`` with the attitude measurement model up to the models'
    probabilities: each model's iterated update (xs, Ps in place). Returns (log N(y_j;
    0, S_j) (2,) up to a constant, y, S, y^T S^-1 y (first iterate, the more probable
    model), iterations used (by the last model))."""
    like = np.zeros(2)
    best = 0 if mu[0] >= mu[1] else 1
    nis_best = 0.0
    y_best = np.zeros(3)
    S_best = np.zeros((3, 3))
    used = 0
    for j in range(2):
        # an improbable model gets one Gauss-Newton step (a plain EKF update)
        its = iterations if mu[j] >= 0.1 else 1
        x, P, y, S, S_inv, used = _nb_iekf(xs[j], Ps[j], z, R, s, sy, walking, table, df,
                                           k, A, axis, alpha, beta, its, lo, hi)
        xs[j] = x
        Ps[j] = P
        nis = np.dot(np.dot(y, S_inv), y)
        # log N(y; 0, S) up to the common constant (det S from the LU factors)
        sign, logdet = np.linalg.slogdet(S)
        like[j] = -0.5 * nis - 0.5 * math.log(max(sign * np.exp(logdet), 1e-300))
        if j == best:
            nis_best = nis
            y_best, S_best = y, S
    return like, y_best, S_best, nis_best, used


def _predict_attitude_kernel(F, Q0, Q1, mu0, mu1, x, P, walking, k, A, axis, alpha, beta):
    """``WalkModelEKF.predict_attitude``: (h (3,), H Ps H^T (3, 3)) with xs = F x,
    Ps = F P F^T + mu_0 Q_0 + mu_1 Q_1, h, H = model(0, xs)."""
    Q = mu0 * Q0 + mu1 * Q1
    xs = np.dot(F, x)
    Ps = np.dot(np.dot(F, P), F.T) + Q
    h, H = _nb_model(xs, 0.0, 0.0, walking, _NO_TABLE, 1.0, k, A, axis, alpha, beta)
    return h, np.dot(np.dot(H, Ps), H.T)


# the kernels index the state by number: offsets 2-4, yaw rate 5, yaw acceleration 6
assert (I_F, I_TH, tuple(I_O), I_R, I_YA) == (0, 1, (2, 3, 4), 5, 6)
_nb_wrap = jit(_wrap_kernel)
_nb_model = jit(_model_kernel)
_nb_mix = jit(_mix_kernel)
_nb_combine = jit(_combine_kernel)
_nb_imm_predict = jit(_imm_predict_kernel)
_nb_iekf = jit(_iekf_kernel)
_nb_imm_update = jit(_imm_update_kernel)
_nb_predict_attitude = jit(_predict_attitude_kernel)
