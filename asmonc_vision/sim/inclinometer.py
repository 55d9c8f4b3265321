"""The compass/inclinometer (Molton et al. 1998, Sections 4-5): roll, pitch, yaw at 16 Hz.

It reports the rig's true orientation (body frame ``inclinometer_link``: x forward, y
left, z up, fixed to the rig, axes aligned with the cameras) in the world, through a
first-order low-pass (the paper's phase lag), plus Gaussian noise, then quantised.
Samples are on the sensor's own clock: ``t_k = t_first + k / rate`` with ``t_first``
drawn in [0, 1 / rate) from the seed, independent of the camera frames.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.config import check_fields, param


@dataclass(frozen=True)
class InclinometerSettings:
    """Compass/inclinometer model. Frozen; validated on construction."""

    rate: float = param(16.0, 'sample rate, Hz', range=(1.0, 1000.0))
    noise_deg: float = param(0.3, 'Gaussian noise standard deviation per angle, degrees',
                             range=(0.0, 10.0))
    quantum_deg: float = param(0.1, 'output resolution, degrees (0 = none)',
                               range=(0.0, 5.0))
    lag: float = param(0.08, 'first-order low-pass time constant (phase lag), seconds',
                       range=(0.0, 2.0))

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def variance(self) -> float:
        """Variance (rad^2) of each reported angle: noise plus quantisation."""
        q = np.radians(self.quantum_deg)
        return float(np.radians(self.noise_deg) ** 2 + q * q / 12.0)


@dataclass(frozen=True)
class InclinometerSamples:
    """A stream of inclinometer samples.

    Attributes:
        times: (N,) float64 seconds since the start of the simulation.
        rpy: (N, 3) float64 measured roll, pitch, yaw, radians (yaw wrapped to (-pi, pi]).
        rpy_true: (N, 3) float64 true orientation at the same instants (yaw unwrapped).
        variance: rad^2 per angle (for the covariance diagonal).
    """

    times: np.ndarray
    rpy: np.ndarray
    rpy_true: np.ndarray
    variance: float


def simulate_inclinometer(trajectory, duration: float,
                          settings: InclinometerSettings | None = None,
                          rng: int | np.random.Generator | None = 0) -> InclinometerSamples:
    """Sample the inclinometer over [0, duration).

    Args:
        trajectory: anything with ``states(t) -> (positions, rpy)`` (``motion.Trajectory``).
        duration: seconds.
        settings: the sensor model.
        rng: seed or Generator (clock phase and noise).
    Returns:
        InclinometerSamples.
    """
    s = settings if settings is not None else InclinometerSettings()
    rng = np.random.default_rng(rng)
    period = 1.0 / s.rate
    t_first = rng.uniform(0.0, period)
    times = t_first + period * np.arange(max(int(np.ceil((duration - t_first) / period)), 0))
    times = times[times < duration]
    _, true = trajectory.states(times) if times.size else (None, np.zeros((0, 3)))
    if s.lag > 0 and times.size:
        # y(t) = integral_0^inf x(t - u) exp(-u / tau) / tau du, with x(t < 0) = x(0)
        span = 8.0 * s.lag
        m = 400
        du = span / m
        u = (np.arange(m) + 0.5) * du
        w = np.exp(-u / s.lag) * (1.0 - np.exp(-du / s.lag)) / np.exp(-du / (2 * s.lag))
        tail = np.exp(-span / s.lag)
        tt = np.maximum(times[:, None] - u[None, :], 0.0)
        _, x = trajectory.states(tt.ravel())
        x = x.reshape(times.size, m, 3)
        _, x_tail = trajectory.states(np.maximum(times - span, 0.0))
        lagged = np.einsum('nmk,m->nk', x, w) + tail * x_tail
        lagged /= (w.sum() + tail)
    else:
        lagged = true.copy()
    meas = lagged + rng.normal(0.0, np.radians(s.noise_deg), lagged.shape)
    if s.quantum_deg > 0:
        q = np.radians(s.quantum_deg)
        meas = np.round(meas / q) * q
    meas[:, 2] = np.mod(meas[:, 2] + np.pi, 2 * np.pi) - np.pi
    return InclinometerSamples(times=times, rpy=meas, rpy_true=true, variance=s.variance)
