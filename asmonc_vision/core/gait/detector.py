"""The change detector of the walk model: walk start, walk stop, non-walking movement.

Molton et al. (1998, Section 5): "A simple change detector is used to identify when the
walk model movements exist ... to detect walk starts, stops, or non-walking movements
(such as sitting down). When no walking is detected the state estimates are frozen and
the current position becomes the prediction."

* Start: over the last ``detect_window`` seconds of prefiltered attitude, the walk model
  (offset + trend + pitch sinusoid at f, roll and yaw sinusoids at f/2, optionally the
  pitch harmonic at 2f) is fitted by linear least squares for every step frequency on a
  grid (batched normal equations). Walking starts when the best fit has a pitch
  amplitude of at least ``start_amplitude_deg`` and explains at least
  ``start_periodicity`` of the detrended pitch variance. The fit initialises the EKF.
* Stop: while walking, the pitch amplitude at the tracked frequency over the last
  ``stop_window`` seconds falls below ``stop_amplitude_deg`` (two samples running), or
* non-walking movement: the EKF's mean normalised innovation over ``nis_window``
  exceeds ``nis_threshold`` (the attitude moves in a way the walk model cannot follow),
  or the tracked frequency leaves [min_frequency, max_frequency].
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.gait.model import GaitConfig

_D2R = np.pi / 180.0
#: a refit replaces the tracked frequency only if it explains this much more of the
#: detrended pitch variance than the tracked frequency does
RELOCK_MARGIN = 0.15


@dataclass(frozen=True)
class WalkFit:
    """The best least-squares walk-model fit over a window, *measured* domain (as seen
    through the prefilter), referred to the window's last sample.

    Attributes:
        frequency: step frequency, Hz.
        amplitude, phase: (3,) roll, pitch, yaw sinusoid amplitude (rad) and phase (rad)
            at the last sample (measured = A sin(phase)).
        offset: (3,) fitted value of the offset + trend at the last sample, rad.
        trend: (3,) fitted slope, rad/s.
        periodicity: (3,) share of each axis's detrended variance explained by its
            sinusoid(s).
        harmonic: (amplitude, phase) of the pitch second harmonic (measured), rad.
        score: the grid criterion (weighted periodicity) of the best frequency.
    """

    frequency: float
    amplitude: np.ndarray
    phase: np.ndarray
    offset: np.ndarray
    trend: np.ndarray
    periodicity: np.ndarray
    harmonic: tuple[float, float]
    score: float


def fit_walk(tau: np.ndarray, z: np.ndarray, freqs: np.ndarray, harmonic: bool = True,
             weights=(0.0, 1.0, 0.0), recency: float = 0.0, scores: dict | None = None
             ) -> WalkFit | None:
    """Fit the walk model to a window for every step frequency in ``freqs``; return the
    best fit.

    Per axis the design is [1, tau, sin(2 pi k f tau), cos(2 pi k f tau)] (k = 1/2, 1,
    1/2). The trend columns are projected out once; the sinusoid pair of every grid
    frequency is solved in closed form (2 x 2 normal equations), from one sin/cos
    evaluation at f/2 and the double-angle formulas. The best frequency is then refitted
    with the pitch second harmonic (``harmonic``) for the initial values.

    Args:
        tau: (N,) sample times relative to the last sample (<= 0), s.
        z: (N, 3) roll, pitch, yaw (rad, yaw continuous).
        freqs: (F,) candidate step frequencies, Hz.
        harmonic: include the pitch second harmonic.
        weights: of each axis's periodicity in the grid criterion (default pitch only:
            over a short window a fraction of a stride looks like a trend, which would
            favour too low frequencies).
        recency: if > 0, samples are weighted by exp(tau / recency) (s), so that a walk
            that is speeding up is fitted by its latest steps.
        scores: if a dict, receives 'freqs' and 'score' (the criterion on the grid).
    Returns:
        WalkFit, or None when the window is too short to fit.
    """
    tau = np.asarray(tau, float)
    z = np.asarray(z, float)
    n = tau.size
    if n < 8:
        return None
    w_axes = np.asarray(weights, float)
    freqs = np.asarray(freqs, float)
    sw = np.exp(0.5 * tau / recency) if recency > 0 else np.ones(n)   # sqrt of weights
    z = z * sw[:, None]
    base = np.column_stack([sw, tau * sw])
    q, _ = np.linalg.qr(base)                                  # orthonormal trend basis
    zr = z - q @ (q.T @ z)                                     # detrended samples
    rss0 = np.maximum(np.sum(zr * zr, axis=0), 1e-18)

    def proj(m):                                               # m - Q Q^T m, rows of m
        return m - (m @ q) @ q.T

    w = np.pi * freqs[:, None] * tau[None, :]                   # (F, N): phase at f/2
    s1, c1 = np.sin(w) * sw, np.cos(w) * sw
    s1u, c1u = s1 / sw, c1 / sw
    s2, c2 = 2.0 * s1u * c1u * sw, (c1u * c1u - s1u * s1u) * sw  # at f (double angle)
    per = np.empty((freqs.size, 3))
    # roll and yaw share the columns at f/2: closed-form 2 x 2 normal equations
    S, C = proj(s1), proj(c1)
    ss, sc, cc = (S * S).sum(1), (S * C).sum(1), (C * C).sum(1)
    det = np.maximum(ss * cc - sc * sc, 1e-30)
    for a in (0, 2):
        sy, cy = S @ zr[:, a], C @ zr[:, a]
        per[:, a] = (cc * sy * sy - 2.0 * sc * sy * cy + ss * cy * cy) / det / rss0[a]
    # pitch at f: closed form too (the grid criterion uses the fundamental only, so
    # that f/2 cannot win by passing the pitch off as its "second harmonic")
    S, C = proj(s2), proj(c2)
    ss, sc, cc = (S * S).sum(1), (S * C).sum(1), (C * C).sum(1)
    det = np.maximum(ss * cc - sc * sc, 1e-30)
    sy, cy = S @ zr[:, 1], C @ zr[:, 1]
    per[:, 1] = (cc * sy * sy - 2.0 * sc * sy * cy + ss * cy * cy) / det / rss0[1]
    per = np.clip(per, 0.0, 1.0)
    score = per @ w_axes
    if scores is not None:
        scores['freqs'], scores['score'] = freqs, score
    k = int(np.argmax(score))
    f = float(freqs[k])
    amp, ph, off, tr = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    h = (0.0, 0.0)
    for a in range(3):
        mult = 1.0 if a == 1 else 0.5
        wk = 2.0 * np.pi * mult * f * tau
        cols = [np.sin(wk), np.cos(wk), np.ones(n), tau]
        if harmonic and a == 1:
            cols += [np.sin(2.0 * wk), np.cos(2.0 * wk)]
        c = lstsq(np.column_stack(cols) * sw[:, None], z[:, a])
        off[a], tr[a] = c[2], c[3]
        # A sin(w tau + phi) = A cos(phi) sin(w tau) + A sin(phi) cos(w tau)
        amp[a] = np.hypot(c[0], c[1])
        ph[a] = np.arctan2(c[1], c[0])
        if harmonic and a == 1:
            h = (float(np.hypot(c[4], c[5])), float(np.arctan2(c[5], c[4])))
    return WalkFit(frequency=f, amplitude=amp, phase=ph, offset=off,
                   trend=tr, periodicity=per[k].copy(), harmonic=h, score=float(score[k]))


def lstsq(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of a small, well-posed design X (N, p) by the normal
    equations (X^T X) c = X^T y (much faster than np.linalg.lstsq at these sizes)."""
    xt = X.T
    g = xt @ X
    g.flat[::g.shape[0] + 1] *= 1.0 + 1e-12
    return np.linalg.solve(g, xt @ y)


def amplitude_at(tau: np.ndarray, y: np.ndarray, f: float) -> float:
    """Least-squares amplitude (rad) of a sinusoid at f (Hz) on offset + trend in the
    window (tau (N,) s, y (N,) rad); 0 for fewer than 4 samples."""
    tau = np.asarray(tau, float)
    if tau.size < 4:
        return 0.0
    w = 2.0 * np.pi * f * tau
    X = np.column_stack([np.ones(tau.size), tau, np.sin(w), np.cos(w)])
    c = lstsq(X, np.asarray(y, float))
    return float(np.hypot(c[2], c[3]))


class WalkDetector:
    """Holds the recent prefiltered samples and takes the start/stop decisions.

    Args:
        config: the gait settings (detector fields).
    """

    def __init__(self, config: GaitConfig) -> None:
        self.cfg = config
        span = max(config.detect_window, config.stop_window, config.nis_window,
                   config.relock_window) + 0.5
        self._span = span
        self._t: deque[float] = deque()
        self._z: deque[np.ndarray] = deque()
        self._nis: deque[tuple[float, float]] = deque()
        step = 0.02
        self.freqs = np.arange(config.min_frequency, config.max_frequency + 1e-9, step)
        self._low_count = 0
        self._arrays = None
        #: running mean of the pitch amplitude while walking (rad), for the stop test
        self.reference_amplitude = 0.0
        self._ref_t: float | None = None

    def start_reference(self, amplitude: float) -> None:
        """Seed the running mean amplitude at a walk start (true amplitude, rad)."""
        self.reference_amplitude = float(amplitude)
        self._ref_t = None
        self._low_count = 0

    def clear(self) -> None:
        """Forget the samples (after a stop: a new start needs a fresh window)."""
        self._t.clear()
        self._z.clear()
        self._nis.clear()
        self._arrays = None

    def reset(self) -> None:
        """Forget the window (after a gap in the stream)."""
        self._arrays = None
        self._t.clear()
        self._z.clear()
        self._nis.clear()
        self._low_count = 0

    def push(self, t: float, z) -> None:
        """Add a prefiltered (3,) sample at time t (s)."""
        self._t.append(float(t))
        self._z.append(np.asarray(z, float))
        while self._t and self._t[0] < t - self._span:
            self._t.popleft()
            self._z.popleft()
        self._arrays = None

    def push_nis(self, t: float, nis_per_dof: float) -> None:
        """Record the EKF's normalised innovation squared per measurement dimension."""
        self._nis.append((float(t), float(nis_per_dof)))
        while self._nis and self._nis[0][0] < t - self.cfg.nis_window:
            self._nis.popleft()

    def window(self, seconds: float) -> tuple[np.ndarray, np.ndarray]:
        """(tau (N,), z (N, 3)) of the samples in the last `seconds` (tau <= 0)."""
        if not self._t:
            return np.zeros(0), np.zeros((0, 3))
        if self._arrays is None:
            t = np.fromiter(self._t, float, len(self._t))
            self._arrays = (t - t[-1], np.array(self._z))
        tau, z = self._arrays
        i = int(np.searchsorted(tau, -seconds - 1e-9))
        return tau[i:], z[i:]

    def span_seconds(self) -> float:
        """Time covered by the buffered samples, s."""
        return self._t[-1] - self._t[0] if len(self._t) > 1 else 0.0

    def check_start(self, prefilter) -> WalkFit | None:
        """The walk-model fit if walking appears to have started, else None."""
        c = self.cfg
        if self.span_seconds() < c.detect_window - 1.5 / c.sample_rate:
            return None
        tau, z = self.window(c.detect_window)
        # cheap gate: the detrended pitch variance must leave room for the amplitude
        zp = z[:, 1] - np.polyval(np.polyfit(tau, z[:, 1], 1), tau)
        g_max = prefilter.gain_phase(float(self.freqs[0]))[0]
        need = c.start_periodicity * 0.5 * (c.start_amplitude_deg * _D2R * g_max) ** 2
        if float(np.mean(zp * zp)) < need:
            return None
        fit = fit_walk(tau, z, self.freqs, c.pitch_harmonic, recency=c.detect_recency)
        if fit is None:
            return None
        edge = (fit.frequency <= self.freqs[0] + 1e-9) or (fit.frequency >= self.freqs[-1] - 1e-9)
        g = prefilter.gain_phase(fit.frequency)[0]
        if (not edge and fit.amplitude[1] / g >= c.start_amplitude_deg * _D2R
                and fit.periodicity[1] >= c.start_periodicity
                and max(fit.periodicity[0], fit.periodicity[2]) >= c.start_sway_periodicity):
            return fit
        return None

    def check_lock(self, f: float) -> WalkFit | None:
        """While walking: refit the walk model over ``relock_window`` (or what there is,
        at least ``detect_window``); the fit if it is periodic and its frequency differs
        from the tracked one ``f`` (Hz) by more than ``relock_tolerance``, else None."""
        c = self.cfg
        span = min(self.span_seconds(), c.relock_window)
        if span < c.detect_window - 1.5 / c.sample_rate:
            return None
        tau, z = self.window(span)
        # search near the tracked frequency (a cadence change), and at the
        # sub-/super-harmonic a bad lock may sit on
        near = self.freqs[np.abs(self.freqs - f) <= 0.2]
        grid = np.unique(np.r_[near, self.freqs[::4], f])
        sc: dict = {}
        fit = fit_walk(tau, z, grid, c.pitch_harmonic, scores=sc)
        if fit is None:
            return None
        current = float(sc['score'][np.argmin(np.abs(sc['freqs'] - f))])
        # relock only if the tracked frequency clearly no longer explains the pitch
        if (fit.periodicity[1] >= c.start_periodicity
                and abs(fit.frequency - f) > c.relock_tolerance
                and fit.score - current > RELOCK_MARGIN):
            return fit
        return None

    def check_stop(self, f: float, prefilter) -> str | None:
        """A reason to stop walking ('stop', 'movement', 'frequency'), or None."""
        c = self.cfg
        if not (c.min_frequency * 0.9 <= f <= c.max_frequency * 1.1):
            return 'frequency'
        if self._nis and len(self._nis) >= 3:
            mean = sum(v for _, v in self._nis) / len(self._nis)
            if mean > c.nis_threshold:
                return 'movement'
        tau, z = self.window(c.stop_window)
        if tau.size >= 4:
            g = prefilter.gain_phase(f)[0]
            amp = amplitude_at(tau, z[:, 1], f) / g
            t = self._t[-1]
            if self._ref_t is not None:
                a = min(1.0, (t - self._ref_t) / 3.0)
                self.reference_amplitude += a * (amp - self.reference_amplitude)
            self._ref_t = t
            limit = max(c.stop_amplitude_deg * _D2R, c.stop_fraction * self.reference_amplitude)
            self._low_count = self._low_count + 1 if amp < limit else 0
            if self._low_count >= 2:
                self._low_count = 0
                return 'stop'
        return None
