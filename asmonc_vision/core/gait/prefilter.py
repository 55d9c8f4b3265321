"""The digital Butterworth prefilter of the inclinometer stream and the known response
of everything between the true attitude and the filtered measurement.

Molton et al. (1998, Section 5) filter the noisy compass signals with a digital
Butterworth filter and note that "compensation for the phase lag introduced by the
filter ... is fairly straightforward as the signals are largely at one frequency, and
the phase response of the filter is known". Here the compensation is exact for every
sinusoid of the walk model: the measurement model evaluates the complex response

    H(f) = H_butter(exp(j 2 pi f / fs)) * 1 / (1 + j 2 pi f tau)

(the prefilter times the sensor's own first-order lag ``tau``) at each axis's
frequency, so a state sinusoid ``A sin(phi)`` of the *true* attitude is measured as
``|H| A sin(phi + arg H)``. Offsets pass with gain 1; a ramp (the yaw offset while
turning) is delayed by the DC group delay.
"""
from __future__ import annotations

import numpy as np
from scipy import signal


_MINUS_2J_PI = -2j * np.pi
_2J_PI = 2j * np.pi


def _polyval(p: list, x: np.ndarray) -> np.ndarray:
    """``np.polyval(p, x)`` (p floats, highest power first; x complex), its first step
    0 x + p_0 = p_0 taken directly (the same numbers, fewer numpy calls)."""
    if len(p) < 2 or p[0] == 0.0:
        return np.polyval(p, x)
    y = p[0] * x + p[1]
    for pv in p[2:]:
        y = y * x + pv
    return y


class Prefilter:
    """A causal low-pass Butterworth filter run sample by sample on (roll, pitch, yaw).

    Args:
        rate: the design sample rate, Hz (the inclinometer's nominal rate).
        cutoff: the -3 dB frequency, Hz; 0 disables the filter (H = 1).
        order: filter order.
        sensor_lag: the sensor's own first-order time constant, s (part of the response
            model only; the filter does not undo it).
    Raises:
        ValueError: cutoff at or above the Nyquist frequency.
    """

    def __init__(self, rate: float, cutoff: float, order: int = 2,
                 sensor_lag: float = 0.0) -> None:
        if cutoff > 0 and cutoff >= 0.5 * rate:
            raise ValueError(f'prefilter cutoff {cutoff} Hz must be below the Nyquist '
                             f'frequency {0.5 * rate} Hz of the {rate} Hz stream')
        self.rate = float(rate)
        self.cutoff = float(cutoff)
        self.order = int(order)
        self.sensor_lag = float(sensor_lag)
        if cutoff > 0:
            b, a = signal.butter(self.order, cutoff / (0.5 * rate))
        else:
            b, a = np.array([1.0]), np.array([1.0])
        self.b = np.asarray(b, float)
        self.a = np.asarray(a, float)
        n = max(len(self.a), len(self.b))
        self._b = np.pad(self.b, (0, n - len(self.b)))
        self._a = np.pad(self.a, (0, n - len(self.a)))
        self._zi_unit = signal.lfilter_zi(self.b, self.a) if n > 1 else np.zeros(0)
        self._z: list | None = None                 # (n - 1) x 3 filter state (floats)
        self._bl = self._b.tolist()                 # the coefficients as floats
        self._al = self._a.tolist()
        self._b_rev = self.b[::-1].tolist()         # ... highest power of z^-1 first
        self._a_rev = self.a[::-1].tolist()
        self._resp_key: bytes | None = None
        self._resp_value: np.ndarray | None = None
        h = signal.lfilter(self.b, self.a, np.r_[1.0, np.zeros(int(20 * rate) + 64)])
        #: white-noise variance gain sum(h^2): R of the filtered stream = gain * R
        self.noise_gain = float(np.sum(h * h))
        e = np.cumsum(h * h)
        #: samples until the filter has forgotten a restart (99.9 % of the impulse
        #: response energy); measurements before that are not used by the EKF
        self.settle_samples = int(np.searchsorted(e, 0.999 * e[-1])) + 1 if cutoff > 0 else 0
        k = np.arange(h.size)
        #: DC group delay of prefilter + sensor lag, s (a ramp lags by this much)
        self.dc_delay = float(np.sum(k * h) / np.sum(h)) / self.rate + self.sensor_lag
        # gain and phase tables (0 .. Nyquist) for fast look-up in the EKF
        self._df = 0.5 * self.rate / 4096.0
        grid = np.arange(4097) * self._df
        resp = self.response(grid)
        self._g = np.abs(resp)
        self._p = np.unwrap(np.angle(resp))
        self._dg = np.gradient(self._g, self._df)
        self._dp = np.gradient(self._p, self._df)
        self._table = np.column_stack([self._g, self._p, self._dg, self._dp])
        self._last_key: bytes | None = None
        self._last_value: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the filter state (the next sample restarts it in steady state)."""
        self._z = None

    def __call__(self, x) -> np.ndarray:
        """Filter one (3,) sample; returns the (3,) filtered sample.

        The first sample after a reset initialises the state as if the input had been
        constant before (no start transient).
        """
        x = np.asarray(x, float)
        if self._a.size == 1:
            return x.copy()
        if self._z is None:
            self._z = (self._zi_unit[:, None] * x[None, :]).tolist()
        z = self._z
        b, a = self._bl, self._al
        n = len(z)
        out = []
        # direct form II transposed, per angle (floats: the same arithmetic as on arrays):
        # y = b0 x + z0;  z_i = b_{i+1} x + z_{i+1} - a_{i+1} y;  z_{n-1} = b_n x - a_n y
        for j, xj in enumerate(x.tolist()):
            y = b[0] * xj + z[0][j]
            for i in range(n - 1):
                z[i][j] = b[i + 1] * xj + z[i + 1][j] - a[i + 1] * y
            z[n - 1][j] = b[n] * xj - a[n] * y
            out.append(y)
        return np.array(out)

    def response(self, f) -> np.ndarray:
        """Complex response H(f) of prefilter times sensor lag at frequencies f (Hz)."""
        f = np.asarray(f, float)
        key = f.tobytes()
        if key == self._resp_key and self._resp_value is not None:   # asked again
            return self._resp_value
        zinv = np.exp(_MINUS_2J_PI * f / self.rate)
        num = _polyval(self._b_rev, zinv)
        den = _polyval(self._a_rev, zinv)
        h = num / den / (1.0 + _2J_PI * f * self.sensor_lag)
        self._resp_key, self._resp_value = key, h
        return h

    def gain_phase(self, f: float) -> tuple[float, float, float, float]:
        """|H|, arg H (rad, unwrapped from 0 Hz) and their derivatives with respect to f
        (per Hz) at one frequency f (Hz), interpolated from tables (fast, scalar)."""
        u = f / self._df
        if not u >= 0.0:
            u = 0.0
        i = int(u)
        if i >= 4096:
            i, w = 4095, 1.0
        else:
            w = u - i
        v = 1.0 - w
        g, p, dg, dp = self._g, self._p, self._dg, self._dp
        return (v * g[i] + w * g[i + 1], v * p[i] + w * p[i + 1],
                v * dg[i] + w * dg[i + 1], v * dp[i] + w * dp[i + 1])

    def gain_phase_array(self, f) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``gain_phase`` for an array of frequencies f (Hz): four arrays of f's shape
        (frequencies beyond the Nyquist frequency are clamped to it)."""
        f = np.asarray(f, float)
        key = f.tobytes()
        if key == self._last_key and self._last_value is not None:   # asked again for f
            return self._last_value
        u = np.clip(f / self._df, 0.0, 4096.0 - 1e-9)
        i = u.astype(int)
        w = (u - i)[..., None]
        tab = self._table
        v = tab[i] * (1.0 - w) + tab[i + 1] * w
        value = (v[..., 0], v[..., 1], v[..., 2], v[..., 3])
        self._last_key, self._last_value = key, value
        return value
