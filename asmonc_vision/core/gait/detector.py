"""The change detector of the walk model: walk start, walk stop, non-walking movement.

Molton et al. (1998, Section 5): "A simple change detector is used to identify when the
walk model movements exist ... to detect walk starts, stops, or non-walking movements
(such as sitting down). When no walking is detected the state estimates are frozen and
the current position becomes the prediction."

* Start: over the last ``detect_window`` seconds of prefiltered attitude, offset + trend
  + sinusoids are fitted by linear least squares for every step frequency f on a grid
  (batched normal equations); the criterion is the paper's, pitch at the step (f), roll
  and yaw at the stride (f/2), weighted by a broad preference for usual cadences
  (``prior_frequency``). Walking starts when the best fit has a pitch amplitude of at
  least ``start_amplitude_deg``, explains at least ``start_periodicity`` of the
  detrended pitch variance, roll or yaw sway confirms it (a bend has none) and the
  criterion does not peak at the grid's edge. A ridge refit with all the model's stride
  harmonics initialises the EKF.
* Lock check: while walking, over 1.5-2.5 s, the criterion with pitch at the stride and
  the step, roll and yaw at the stride, all weighted (one stride in the window makes the
  stride components separable from a trend); a clearly better frequency re-initialises
  the oscillation ('relock').
* Stop: while walking, over the last ``stop_window`` seconds, the part of roll and pitch
  moving like the model (a matched filter) and their motion whatever its shape both fall
  well below their running means (two samples running), or
* non-walking movement: the EKF's mean normalised innovation over ``nis_window``
  exceeds ``nis_threshold`` (the attitude moves in a way the walk model cannot follow),
  or the tracked frequency reaches the bounds of [min_frequency, max_frequency]
  (widened by 10 %).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.gait.model import GaitConfig
from asmonc_vision.core.jit import jit, nb_pairwise_sum as _nb_pairwise_sum, warmed

_D2R = np.pi / 180.0
#: a refit replaces the tracked frequency only if it explains this much more of the
#: detrended pitch variance than the tracked frequency does
RELOCK_MARGIN = 0.15


@dataclass(frozen=True)
class WalkFit:
    """The best least-squares walk-model fit over a window, *measured* domain (as seen
    through the prefilter), referred to the window's last sample (stride phase 0 there).

    Attitude axis a in the window (tau <= 0 s before its last sample) is modelled as
    offset_a + trend_a tau + sum_k Im[c_ak exp(i k pi f tau)], k = 1 .. K_a (harmonics of
    the stride frequency f / 2).

    Attributes:
        frequency: step frequency, Hz.
        coefficients: per axis (roll, pitch, yaw) a (K_a,) complex array c_ak
            (alpha + i beta: alpha sin + beta cos).
        coefficient_sd: per axis a (K_a,) array, the posterior standard deviation of the
            real and imaginary parts (rad).
        offset: (3,) fitted value of the offset + trend at the last sample, rad.
        trend: (3,) fitted slope, rad/s.
        periodicity: (3,) share of each axis's detrended variance explained by the
            criterion's harmonics at this frequency.
        score: the grid criterion (weighted periodicity) of the best frequency.
        residual: (3,) rms residual of the refit per axis, rad (what the model does not
            describe, for the EKF's initial model error).
        offset_trend_cov: (3, 2, 2) per axis the posterior covariance of (offset, trend)
            (rad^2, rad^2/s, rad^2/s^2): over a window shorter than a stride the level is
            hardly separable from the stride sway and the trend.
    """

    frequency: float
    coefficients: tuple
    coefficient_sd: tuple
    offset: np.ndarray
    trend: np.ndarray
    periodicity: np.ndarray
    score: float
    residual: np.ndarray
    offset_trend_cov: np.ndarray | None = None

    def harmonic(self, axis: int, k: int) -> complex:
        """Coefficient of harmonic k of an axis (0 if not fitted)."""
        c = self.coefficients[axis]
        return complex(c[k - 1]) if 1 <= k <= c.size else 0j

    @property
    def amplitude(self) -> np.ndarray:
        """(3,) amplitude of each axis's main harmonic (roll, yaw: k = 1, the stride;
        pitch: k = 2, the step), rad."""
        return np.array([abs(self.harmonic(a, k)) for a, k in enumerate((1, 2, 1))])


#: the grid criterion's harmonics: the paper's model, pitch at the step (k = 2 of the
#: stride), roll and yaw at the stride (k = 1); only pitch is weighted by default. Right
#: for a walk start (over a 1 s window a stride sinusoid is hardly distinguishable from
#: a trend), but people whose pitch moves mainly at the stride lock it onto the stride.
PAPER_CRITERION = ((1,), (2,), (1,))
#: the criterion of the lock check over a longer window (at least 1.5 s, a stride and a
#: half): pitch at the stride and the step, roll and yaw at the stride, equally weighted
LOCK_CRITERION = (((1,), (1, 2), (1,)), (1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0))
#: the least window of the lock check, s
LOCK_MIN_WINDOW = 1.5
#: the motion amplitude's share of its running mean below which walking may stop
STOP_MOTION_FRACTION = 0.8


def _explained(zr: np.ndarray, cols: list[np.ndarray], proj) -> np.ndarray:
    """Share of the detrended samples zr (N,) explained, for every grid frequency, by the
    columns ``cols`` (each (F, N)), after projecting the trend out (batched normal
    equations)."""
    X = np.stack([proj(c) for c in cols], axis=2)              # (F, N, m)
    G = np.einsum('fni,fnj->fij', X, X)
    G += np.eye(G.shape[1])[None] * 1e-12 * np.trace(G, axis1=1, axis2=2)[:, None, None]
    b = np.einsum('fni,n->fi', X, zr)
    c = np.linalg.solve(G, b[..., None])[..., 0]
    return np.einsum('fi,fi->f', b, c)


def fit_walk(tau: np.ndarray, z: np.ndarray, freqs: np.ndarray,
             harmonics=(2, 4, 2), criterion=PAPER_CRITERION, weights=(0.0, 1.0, 0.0),
             recency: float = 0.0, scores: dict | None = None,
             prior_sd=(5.0 * _D2R, 1.0 * _D2R), noise_sd: float = 0.5 * _D2R,
             frequency_prior: tuple[float, float] | None = None) -> WalkFit | None:
    """Fit the walk model to a window for every step frequency in ``freqs``; return the
    best fit.

    The grid criterion is the weighted share of each axis's detrended variance explained
    by sinusoids at the ``criterion`` harmonics of the stride (batched normal equations;
    the trend columns are projected out once). The paper's criterion (the default) is
    pitch at the step frequency alone: over a short window a fraction of a stride looks
    like a trend, which would favour too low frequencies. The best frequency is then
    refitted with all model ``harmonics`` per axis by ridge regression: harmonic
    coefficients have a zero-mean prior (``prior_sd``: main harmonics, the others),
    samples the noise ``noise_sd``; this gives the initial values and their spread.

    Args:
        tau: (N,) sample times relative to the last sample (<= 0), s.
        z: (N, 3) roll, pitch, yaw (rad, yaw continuous).
        freqs: (F,) candidate step frequencies, Hz.
        harmonics: number of stride harmonics per axis in the refit.
        criterion: per axis, the stride harmonics of the grid criterion.
        weights: of each axis's periodicity in the grid criterion.
        recency: if > 0, samples are weighted by exp(tau / recency) (s), so that a walk
            that is speeding up is fitted by its latest steps.
        scores: if a dict, receives 'freqs', 'score', 'raw' (without the prior) and
            'periodicity' (F, 3) on the grid.
        prior_sd: (main, other) prior standard deviation of the coefficients, rad.
        noise_sd: sample noise of the refit, rad.
        frequency_prior: (mean, sd) Hz: the criterion is multiplied by the Gaussian
            exp(-(f - mean)^2 / (2 sd^2)) (a weak preference for usual cadences).
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
    zw = z * sw[:, None]
    per = _grid_periodicity(tau, zw, sw, freqs, criterion)
    raw = per @ w_axes
    score = raw
    if frequency_prior is not None and frequency_prior[1] > 0:
        score = raw * np.exp(-0.5 * ((freqs - frequency_prior[0]) / frequency_prior[1]) ** 2)
    if scores is not None:
        scores['freqs'], scores['score'], scores['periodicity'] = freqs, score, per
        scores['raw'] = raw
    i = int(np.argmax(score))
    f = float(freqs[i])
    coef, csd = [], []
    off, tr, res = np.empty(3), np.empty(3), np.empty(3)
    otc = np.zeros((3, 2, 2))
    main = (1, 2, 1)
    for a in range(3):
        c, cov, res[a] = _ridge_refit_axis(tau, zw[:, a], sw, f, harmonics[a], main[a],
                                           prior_sd, noise_sd)
        off[a], tr[a] = c[0], c[1]
        otc[a] = cov[:2, :2]
        coef.append(c[2::2] + 1j * c[3::2])
        csd.append(np.sqrt(0.5 * (np.diag(cov)[2::2] + np.diag(cov)[3::2])))
    return WalkFit(frequency=f, coefficients=tuple(coef), coefficient_sd=tuple(csd),
                   offset=off, trend=tr, periodicity=per[i].copy(), score=float(score[i]),
                   residual=res, offset_trend_cov=otc)


def _grid_periodicity(tau: np.ndarray, zw: np.ndarray, sw: np.ndarray, freqs: np.ndarray,
                      criterion) -> np.ndarray:
    """The grid criterion of `fit_walk` per axis: the share of the axis's detrended
    variance explained by sinusoids at its ``criterion`` harmonics of the stride, for
    every step frequency (the trend columns are projected out once).

    Args:
        tau: (N,) float64 sample times relative to the last sample (<= 0), s.
        zw: (N, 3) float64 roll, pitch, yaw (rad) times the samples' weights ``sw``.
        sw: (N,) float64 square roots of the samples' weights.
        freqs: (F,) float64 candidate step frequencies, Hz.
        criterion: per axis, the stride harmonics k (empty: the axis is not scored).
    Returns:
        (F, 3) float64 in [0, 1] (0 for an axis not scored).
    """
    base = np.column_stack([sw, tau * sw])
    q, _ = np.linalg.qr(base)                                  # orthonormal trend basis
    zr = zw - q @ (q.T @ zw)                                   # detrended samples
    rss0 = np.maximum(np.sum(zr * zr, axis=0), 1e-18)

    def proj(m):                                               # m - Q Q^T m, rows of m
        return m - (m @ q) @ q.T

    w = np.pi * freqs[:, None] * tau[None, :]                   # (F, N): stride phase
    cache: dict = {}

    def cols(k):
        if k not in cache:
            cache[k] = (np.sin(k * w) * sw, np.cos(k * w) * sw)
        return cache[k]

    per: np.ndarray = np.zeros((freqs.size, 3))
    for a in range(3):
        ks = criterion[a]
        if not ks:
            continue
        cc = [c for k in ks for c in cols(k)]
        per[:, a] = _explained(zr[:, a], cc, proj) / rss0[a]
    return np.clip(per, 0.0, 1.0)


def _ridge_refit_axis(tau: np.ndarray, zw_a: np.ndarray, sw: np.ndarray, f: float,
                      harmonics: int, main: int, prior_sd, noise_sd: float
                      ) -> tuple[np.ndarray, np.ndarray, float]:
    """The refit of one attitude axis at the step frequency ``f`` by ridge regression:
    offset + trend + ``harmonics`` stride harmonics, whose coefficients have a zero-mean
    prior, samples the noise ``noise_sd``: (X^T X / s^2 + L) c = X^T z / s^2,
    L = diag(1 / prior^2) (none on the offset and trend).

    Args:
        tau: (N,) float64 sample times relative to the last sample (<= 0), s.
        zw_a: (N,) float64 the axis's angle (rad) times the samples' weights ``sw``.
        sw: (N,) float64 square roots of the samples' weights.
        f: step frequency, Hz (the stride harmonic k is at k f / 2).
        harmonics: number K of stride harmonics.
        main: the main harmonic (prior ``prior_sd[0]``; the others ``prior_sd[1]``);
            K when K is smaller.
        prior_sd: (main, other) prior standard deviation of the coefficients, rad.
        noise_sd: sample noise, rad.
    Returns:
        c: (2 + 2K,) float64 offset (rad), trend (rad/s), then per harmonic k the sine
            and cosine coefficients (rad); cov: (2 + 2K, 2 + 2K) float64 their posterior
            covariance; the weighted rms residual, rad.
    """
    n = tau.size
    ks = np.arange(1, harmonics + 1)
    wk = np.pi * f * tau
    X = [np.ones(n), tau]
    for k in ks:
        X += [np.sin(k * wk), np.cos(k * wk)]
    X = np.column_stack(X) * sw[:, None]
    lam = np.zeros(X.shape[1])
    sd = np.where(ks == min(main, harmonics), prior_sd[0], prior_sd[1])
    lam[2::2] = lam[3::2] = (noise_sd / sd) ** 2
    G = X.T @ X + np.diag(lam)
    G.flat[::G.shape[0] + 1] *= 1.0 + 1e-12
    c = np.linalg.solve(G, X.T @ zw_a)
    cov = np.linalg.inv(G) * noise_sd ** 2
    e = X @ c - zw_a
    return c, cov, math.sqrt(float(e @ e) / float(sw @ sw))


class WalkDetector:
    """Holds the recent prefiltered samples and takes the start/stop decisions.

    Args:
        config: the gait settings (detector fields).
    """

    def __init__(self, config: GaitConfig) -> None:
        _warm_up()
        self.cfg = config
        span = max(config.detect_window, config.stop_window, config.nis_window,
                   config.relock_window) + 0.5
        self._span = span
        self._t: deque[float] = deque()
        self._z: deque[np.ndarray] = deque()
        self._nis: deque[tuple[float, float]] = deque()
        self._nis_values: deque[float] = deque()      # the values of _nis alone
        step = 0.02
        self.freqs = np.arange(config.min_frequency, config.max_frequency + 1e-9, step)
        self._low_count = 0
        # the samples of the deques as arrays (rows start:end), for ``window``
        self._tb = np.zeros(256)
        self._zb = np.zeros((256, 3))
        self._start = self._end = 0
        #: (mean, sd) of the step-frequency prior of the grid criteria, Hz (or None)
        self.frequency_prior = ((config.prior_frequency, config.prior_frequency_sd)
                                if config.prior_frequency_sd > 0 else None)
        #: running mean of the gait amplitude while walking (rad), for the stop test
        self.reference_amplitude = 0.0
        self._ref_t: float | None = None
        self._reference: np.ndarray = np.zeros(2)
        self._started: float | None = None

    def start_reference(self) -> None:
        """Restart the running mean gait amplitude at a walk start (the first stop test
        seeds it; no stop for ``stop_window`` s after the start)."""
        self.reference_amplitude = 0.0
        self._reference = np.zeros(2)
        self._ref_t = None
        self._low_count = 0
        self._started = self._t[-1] if self._t else None

    def clear(self) -> None:
        """Forget the samples (after a stop: a new start needs a fresh window)."""
        self._t.clear()
        self._z.clear()
        self._nis.clear()
        self._nis_values.clear()
        self._start = self._end = 0

    def reset(self) -> None:
        """Forget the window (after a gap in the stream)."""
        self._start = self._end = 0
        self._t.clear()
        self._z.clear()
        self._nis.clear()
        self._nis_values.clear()
        self._low_count = 0

    def push(self, t: float, z) -> None:
        """Add a prefiltered (3,) sample at time t (s)."""
        self._t.append(float(t))
        self._z.append(np.asarray(z, float))
        if self._end == self._tb.size:              # full: move the window to the front
            n = self._end - self._start
            size = self._tb.size * (2 if n > self._tb.size // 2 else 1)
            tb, zb = np.zeros(size), np.zeros((size, 3))
            tb[:n] = self._tb[self._start:self._end]
            zb[:n] = self._zb[self._start:self._end]
            self._tb, self._zb, self._start, self._end = tb, zb, 0, n
        self._tb[self._end] = self._t[-1]
        self._zb[self._end] = self._z[-1]
        self._end += 1
        while self._t and self._t[0] < t - self._span:
            self._t.popleft()
            self._z.popleft()
            self._start += 1

    def push_nis(self, t: float, nis_per_dof: float) -> None:
        """Record the EKF's normalised innovation squared per measurement dimension."""
        self._nis.append((float(t), float(nis_per_dof)))
        self._nis_values.append(float(nis_per_dof))
        while self._nis and self._nis[0][0] < t - self.cfg.nis_window:
            self._nis.popleft()
            self._nis_values.popleft()

    def window(self, seconds: float) -> tuple[np.ndarray, np.ndarray]:
        """(tau (N,), z (N, 3)) of the samples in the last `seconds` (tau <= 0)."""
        if not self._t:
            return np.zeros(0), np.zeros((0, 3))
        t = self._tb[self._start:self._end]
        tau = t - t[-1]
        i = int(np.searchsorted(tau, -seconds - 1e-9))
        return tau[i:], self._zb[self._start + i:self._end]

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
        sc: dict = {}
        fit = fit_walk(tau, z, self.freqs, c.harmonics, recency=c.detect_recency,
                       frequency_prior=self.frequency_prior, scores=sc)
        if fit is None:
            return None
        # a criterion peaking at the grid's edge (without the prior) is no gait: a bend,
        # a slow posture change
        i = int(np.argmax(sc['raw']))
        edge = i == 0 or i == self.freqs.size - 1
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
        if span < max(c.detect_window, LOCK_MIN_WINDOW) - 1.5 / c.sample_rate:
            return None
        tau, z = self.window(span)
        # search near the tracked frequency (a cadence change), and at the
        # sub-/super-harmonic a bad lock may sit on
        near = self.freqs[np.abs(self.freqs - f) <= 0.2]
        grid = np.unique(np.r_[near, self.freqs[::4], f])
        sc: dict = {}
        fit = fit_walk(tau, z, grid, c.harmonics, *LOCK_CRITERION, scores=sc,
                       frequency_prior=self.frequency_prior)
        if fit is None:
            return None
        current = float(sc['score'][np.argmin(np.abs(sc['freqs'] - f))])
        edge = (fit.frequency <= self.freqs[0] + 1e-9) or (fit.frequency >= self.freqs[-1] - 1e-9)
        # relock only if the tracked frequency clearly no longer explains the gait
        if (not edge and fit.score >= c.start_sway_periodicity
                and abs(fit.frequency - f) > c.relock_tolerance
                and fit.score - current > RELOCK_MARGIN):
            return fit
        return None

    def check_stop(self, f: float, oscillation) -> str | None:
        """A reason to stop walking ('stop', 'movement', 'frequency'), or None.

        Args:
            f: the tracked step frequency, Hz.
            oscillation: ``oscillation(tau) -> ((N, 3), (3,))``: the walk model's
                oscillation (measured domain, no offsets) at the window's sample times
                (tau <= 0 s before the latest sample), and each axis's amplitude
                sqrt(sum_k |c_k|^2) (measured domain).
        The stop test (``stop_amplitudes``, roll and pitch: turns bend the yaw): over the
        window (``stop_window``) the *gait amplitude* (a matched filter with the model's
        own oscillation, its frequency, phase and shape) below ``stop_fraction`` of its
        running mean (3 s),
        and the *motion amplitude* (whatever the shape) below ``STOP_MOTION_FRACTION``
        of its own, twice running, is a stop. The first is quick and phase-proof, the
        second keeps irregular real walking (which the model describes badly) from
        being taken for a stop.
        """
        c = self.cfg
        if not (c.min_frequency * 0.9 + 1e-6 < f < c.max_frequency * 1.1 - 1e-6):
            return 'frequency'
        if self._nis and len(self._nis) >= 3:
            mean = sum(self._nis_values) / len(self._nis)
            if mean > c.nis_threshold:
                return 'movement'
        tau, z = self.window(c.stop_window)
        if tau.size >= 4:
            axes = [0, 1]                                # roll, pitch: turns bend the yaw
            m, a = oscillation(tau)
            a0, a1 = float(a[0]), float(a[1])
            a_m = math.sqrt((a0 * a0 + a1 * a1) / 2.0)   # rms over the axes
            amp = stop_amplitudes(tau, z[:, axes], m[:, axes], a_m)
            t = self._t[-1]
            if self._ref_t is None:
                self._reference = np.array(amp)
            else:
                a = min(1.0, (t - self._ref_t) / 3.0)
                self._reference += a * (np.array(amp) - self._reference)
            self._ref_t = t
            ref = self._reference.tolist()
            self.reference_amplitude = ref[0]
            floor = c.stop_amplitude_deg * _D2R
            low = True
            # below max(floor, (stop_fraction, STOP_MOTION_FRACTION) * reference)
            for v, frac, r in zip(amp, (c.stop_fraction, STOP_MOTION_FRACTION), ref):
                lim = frac * r
                lim = floor if floor >= lim else lim    # as np.maximum (NaN passes)
                low = low and v < lim
            young = self._started is not None and t - self._started < c.stop_window
            low = low and not young
            self._low_count = self._low_count + 1 if low else 0
            if self._low_count >= 2:
                self._low_count = 0
                return 'stop'
        return None


_BASIS: dict = {}


def _trend_basis(tau: np.ndarray) -> np.ndarray:
    """Orthonormal basis (N, 2) of offset and trend over the sample times tau (the
    windows repeat at a steady rate: cached)."""
    key = tau.round(6).tobytes()
    q = _BASIS.get(key)
    if q is None:
        q, _ = np.linalg.qr(np.column_stack([np.ones(tau.size), tau]))
        if len(_BASIS) > 64:
            _BASIS.clear()
        _BASIS[key] = q
    return q


def stop_amplitudes(tau: np.ndarray, z: np.ndarray, m: np.ndarray, a_m: float
                    ) -> tuple[float, float]:
    """The two amplitudes of the stop test (rad, sinusoid-equivalent: sqrt(2) rms over
    the axes) of a window z (N, k) given the model's oscillation m (N, k) there and its
    amplitude a_m (rad: sqrt(mean over the axes of sum_k |c_k|^2), as sqrt(2) rms(m) over
    whole strides).

    Offset and trend of each axis are removed from both (subscript r). Over a window
    shorter than a stride that removes more or less of a sinusoid depending on its
    phase; both amplitudes are therefore referred to the model's full amplitude a_m:

        gait amplitude    beta a_m, beta = <z_r, m_r> / <m_r, m_r> (the part of the window
                          that moves like the model; least squares);
        motion amplitude  rms(z_r) / rms(m_r) a_m (how much the body moves, whatever the
                          shape, corrected for the detrending).

    Both are 0 when the model does not oscillate.
    """
    q = _trend_basis(tau)
    if _nb_stop_sums is not None and np.size(z) <= 128:
        mm, zm, zz = _nb_stop_sums(q, np.ascontiguousarray(z, float),
                                   np.ascontiguousarray(m, float))
    else:
        mm, zm, zz = _stop_sums(q, z, m)
    if mm <= 1e-18:
        return 0.0, 0.0
    beta = zm / mm
    return max(beta, 0.0) * a_m, math.sqrt(zz / mm) * a_m


def _stop_sums(q: np.ndarray, z: np.ndarray, m: np.ndarray) -> tuple[float, float, float]:
    """<m_r, m_r>, <z_r, m_r>, <z_r, z_r> of ``stop_amplitudes``, q the trend basis."""
    zr, mr = z - q @ (q.T @ z), m - q @ (q.T @ m)           # offset and trend removed
    total = np.add.reduce                                   # np.sum of all elements
    return (float(total(mr * mr, axis=None)), float(total(zr * mr, axis=None)),
            float(total(zr * zr, axis=None)))


# ``_stop_sums`` compiled by numba (``core.jit``) for windows of up to 128 values: the
# same BLAS products and numpy's own summation order, so the same numbers (test_gait
# compares them).

def _stop_sums_kernel(q, z, m):
    """``_stop_sums`` (z, m of up to 128 values)."""
    zr = z - np.dot(q, np.dot(q.T, z))
    mr = m - np.dot(q, np.dot(q.T, m))
    mm, zm, zz = (mr * mr).ravel(), (zr * mr).ravel(), (zr * zr).ravel()
    return (_nb_pairwise_sum(mm, 0, mm.size), _nb_pairwise_sum(zm, 0, zm.size),
            _nb_pairwise_sum(zz, 0, zz.size))


_nb_stop_sums = jit(_stop_sums_kernel)
_warm = False


def _warm_up() -> None:
    """Compile ``_nb_stop_sums`` (or load it from numba's disk cache) once per process,
    before the first sample; dropped (the numpy path runs) if that fails."""
    global _warm, _nb_stop_sums
    if not _warm:
        _warm = True
        _nb_stop_sums = warmed(_nb_stop_sums, np.ones((20, 2)), np.ones((20, 2)),
                               np.ones((20, 2)))
