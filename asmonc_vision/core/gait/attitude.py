"""Attitude from a 100 Hz IMU (gyroscope + accelerometer) by a complementary filter, and
its decimation to a compass-like 16 Hz stream -- to run the walk model on real walking
recorded with an IMU rather than a compass/inclinometer.

Frames: the IMU's axes are first mapped to REP 103 body axes (x forward, y left, z up)
with a fixed matrix; the attitude is that of the body in a world frame with z up and the
initial heading as yaw 0 (no magnetometer: yaw is the integrated gyroscope, its drift is
slow against a 0.5 s prediction).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from asmonc_vision.core.gait.rotations import matrix_to_rpy, rotvec_to_matrix

#: Mobilise-D lower-back IMU axes (x inferior->superior, y medio-lateral to the right,
#: z posterior->anterior; right-handed) -> REP 103 body axes (x forward, y left, z up)
MOBILISE_TO_BODY = np.array([[0.0, 0.0, 1.0],
                             [0.0, -1.0, 0.0],
                             [1.0, 0.0, 0.0]])


def tilt_from_accel(acc) -> tuple[float, float]:
    """(roll, pitch) in rad of a body whose accelerometer (body axes, any unit) reads
    `acc` at rest: the specific force points up, up_body = R^T (0, 0, 1)."""
    ax, ay, az = (float(v) for v in acc)
    return math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az))


def complementary_filter(acc, gyr, rate: float, time_constant: float = 1.0,
                         gate: float = 0.2) -> np.ndarray:
    """Attitude (roll, pitch, yaw) of every sample, rad, yaw continuous.

    The gyroscope is integrated (R <- R exp([w dt])); the accelerometer's gravity
    direction pulls roll and pitch back with time constant ``time_constant`` (Mahony's
    proportional correction w + k (a x g_est), k = 1 / time_constant); with ``gate`` > 0,
    samples whose acceleration is far from 1 g correct less (weight 1 - ||a| - 1| / gate,
    at least 0).

    Args:
        acc: (N, 3) specific force in body axes, g.
        gyr: (N, 3) angular velocity in body axes, rad/s.
        rate: sample rate, Hz.
        time_constant: s.
        gate: g; 0 = every sample corrects fully.
    Returns:
        (N, 3) roll, pitch, yaw, rad.
    """
    acc = np.asarray(acc, float)
    gyr = np.asarray(gyr, float)
    n = acc.shape[0]
    dt = 1.0 / rate
    k = 1.0 / time_constant
    r0, p0 = tilt_from_accel(acc[: max(1, int(rate // 2))].mean(axis=0))
    from asmonc_vision.core.gait.rotations import rpy_to_matrix
    R = rpy_to_matrix(np.array([r0, p0, 0.0]))
    out = np.empty((n, 3))
    for i in range(n):
        a = acc[i]
        na = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        w = gyr[i].copy()
        if na > 1e-6:
            g_est = R[2, :]                        # world up in body axes (R^T e_z)
            e = np.cross(a / na, g_est)
            trust = max(0.0, 1.0 - abs(na - 1.0) / gate) if gate > 0 else 1.0
            w += k * trust * e
        R = R @ rotvec_to_matrix(w * dt)
        if i % 100 == 0:                           # keep R orthonormal
            u, _, vt = np.linalg.svd(R)
            R = u @ vt
        out[i] = matrix_to_rpy(R)
    out[:, 2] = np.unwrap(out[:, 2])
    return out


def decimate_to(rpy, rate_in: float, rate_out: float = 16.0) -> tuple[np.ndarray, np.ndarray]:
    """Resample an attitude stream to ``rate_out`` (polyphase, anti-aliased, zero
    phase: like an instantaneous sensor sampled at that rate).

    Returns:
        (times (M,) s from the first input sample, rpy (M, 3) rad).
    """
    from fractions import Fraction

    fr = Fraction(rate_out / rate_in).limit_denominator(1000)
    y = signal.resample_poly(np.asarray(rpy, float), fr.numerator, fr.denominator, axis=0,
                             padtype='line')
    t = np.arange(y.shape[0]) / rate_out
    return t, y
