"""The gait tracker: inclinometer stream -> prefilter -> change detector -> walk-model
EKF, with visual-motion increments fused into the same filter, and the prediction at
the horizon. This is everything the gait-filter node does, without ROS.

Times are seconds on any common clock (message stamps); angles radians, REP 103
roll/pitch/yaw of ``inclinometer_link`` in ``world``.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from asmonc_vision.core.gait.detector import WalkDetector, WalkFit
from asmonc_vision.core.gait.fallback import PredictionFallback
from asmonc_vision.core.gait.model import I_F, I_O, I_R, I_YA, GaitConfig, WalkModelEKF
from asmonc_vision.core.gait.prefilter import Prefilter
from asmonc_vision.core.gait.rotations import (
    egomotion_to_body,
    euler_rate_matrix,
    relative_rotation,
    rpy_increment,
    wrap_angle,
)
from asmonc_vision.core.jit import jit, warmed

_D2R = np.pi / 180.0
#: visual-motion increments whose normalised innovation exceeds this are outliers
#: (chi-square, 3 degrees of freedom, p = 0.001)
EGOMOTION_GATE = 16.27
#: the skill weighting's prior at a walk start: the model's mean squared error is this
#: share of holding's (expected from the fitted oscillation and the buffered samples)
SKILL_PRIOR = 1.0
#: ... and holding's rms error is at least this, rad
SKILL_FLOOR = 0.2 * _D2R
#: the skill shown on earlier walks (errors of model and holding while walking, a memory
#: of this many seconds) replaces that prior at a walk start once it holds this many
#: seconds of scored walking
SKILL_LONG_MEMORY = 10.0
SKILL_LONG_MIN = 1.0
#: least initial standard deviation of the offsets at a walk start, rad
START_OFFSET_SD = 0.5 * _D2R


def wrap_diff(a, b) -> np.ndarray:
    """a - b (3,) with the yaw difference wrapped."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d[2] = wrap_angle(float(d[2]))
    return d


def _towards(a: list, b: list, w: list) -> list:
    """a + w * wrap_diff(b, a) of three floats each."""
    d0, d1, d2 = b[0] - a[0], b[1] - a[1], wrap_angle(b[2] - a[2])
    return [a[0] + w[0] * d0, a[1] + w[1] * d1, a[2] + w[2] * d2]


def _nis2(y: np.ndarray, S: np.ndarray) -> float:
    """The roll and pitch part of the normalised innovation, y[:2]^T S[:2, :2]^-1 y[:2]."""
    if _nb_nis2 is not None:
        return _nb_nis2(y, S)
    return float(y[:2] @ np.linalg.solve(S[:2, :2], y[:2]))


# Compiled by numba (``core.jit``), each beside its numpy path (``_nis2``; the loop of
# ``GaitTracker._score_past``) with the same operations in the same order and the same
# LAPACK/BLAS calls: the same numbers (test_gait compares them).

def _wrap_kernel(a):
    """``wrap_angle`` of a float, [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _nis2_kernel(y, S):
    """``_nis2``."""
    return np.dot(y[:2], np.linalg.solve(S[:2, :2], y[:2]))


def _score_kernel(u, z0, zc, pm, held, y0, y1, a, e2m, e2h, emh, b, long_):
    """One prediction of ``GaitTracker._score_past`` scored (e2m, e2h, emh and, if b > 0,
    long_ updated in place): the truth z0 + u wrap_diff(zc, z0); the errors of the
    model's prediction pm (per IMM model its own yaw y0, y1) and of the held
    measurement; running means with weight a (b)."""
    d = zc - z0
    d[2] = _nb_wrap(d[2])
    truth = z0 + u * d
    em = pm - truth
    eh = held - truth
    em[2] = _nb_wrap(em[2])
    eh[2] = _nb_wrap(eh[2])
    for j in range(2):
        for i in range(3):
            e = em[i] if i < 2 else _nb_wrap((y0 if j == 0 else y1) - truth[2])
            e2m[j, i] += a * (e * e - e2m[j, i])
            emh[j, i] += a * (e * eh[i] - emh[j, i])
    for i in range(3):
        e2h[i] += a * (eh[i] * eh[i] - e2h[i])
    if b > 0.0:
        for i in range(3):
            long_[0, i] += b * (em[i] * em[i] - long_[0, i])
            long_[1, i] += b * (eh[i] * eh[i] - long_[1, i])
            long_[2, i] += b * (em[i] * eh[i] - long_[2, i])


_nb_wrap = jit(_wrap_kernel)
_nb_nis2 = jit(_nis2_kernel)
_nb_score = jit(_score_kernel)
_warm = False


def _warm_up() -> None:
    """Compile the tracker's kernels (or load them from numba's disk cache) once per
    process, before the first sample; a kernel that fails is dropped (its numpy path
    runs)."""
    global _warm, _nb_nis2, _nb_score
    if _warm:
        return
    _warm = True
    y, S = np.zeros(3), np.eye(3)
    _nb_nis2 = warmed(_nb_nis2, y, S)
    _nb_score = warmed(_nb_score, 1.0, y, y, y, y, 0.0, 0.0, 0.1, np.zeros((2, 3)),
                       np.zeros(3), np.zeros((2, 3)), 0.1, np.zeros((3, 3)))


#: visual-motion intervals ending more than this before the filter time are too old, s
EGOMOTION_MAX_AGE = 2.0


@dataclass(frozen=True)
class GaitEstimate:
    """The walk model's state and prediction at one stamp (GaitState's content).

    Attributes:
        stamp: s, the time the estimate refers to (latest inclinometer sample).
        walking: the change detector's verdict (False: oscillation frozen).
        step_frequency, step_frequency_variance: Hz, Hz^2.
        amplitude, phase, offset: (3,) roll, pitch, yaw: rad; phase at the stamp.
        yaw_rate: rad/s (turning).
        attitude: (3,) estimated true attitude at the stamp (lag-compensated), rad.
        horizon: s.
        predicted: (3,) attitude at stamp + horizon, rad (yaw continuous).
        predicted_covariance: (3, 3) rad^2.
        motion: (3, 3) rotation of inclinometer_link at stamp + horizon expressed in
            inclinometer_link at the stamp (the predicted camera-rig rotation): from the
            attitude now to attitude + w (model prediction - attitude), w the skill
            weights (holding predicts no motion).
        event: 'start', 'stop', 'movement', 'frequency', 'gap' when the walking verdict
            changed at this sample, 'relock' when the oscillation was re-initialised
            while walking, else None.
        predicted_model, predicted_model_covariance: the walk model's own prediction
            (``predicted`` weights it with the attitude held by their recent skill).
        fallback: (3,) bool, the axes whose ``predicted`` is the measurement held by the
            fallback rule (core/gait/fallback.py); None when the rule is off.
    """

    stamp: float
    walking: bool
    step_frequency: float
    step_frequency_variance: float
    amplitude: np.ndarray
    phase: np.ndarray
    offset: np.ndarray
    yaw_rate: float
    attitude: np.ndarray
    horizon: float
    predicted: np.ndarray
    predicted_covariance: np.ndarray
    motion: np.ndarray
    event: str | None = None
    predicted_model: np.ndarray | None = None
    predicted_model_covariance: np.ndarray | None = None
    fallback: np.ndarray | None = None


@dataclass
class TrackerStats:
    """Counters for diagnostics."""

    inclinometer: int = 0
    out_of_order: int = 0
    gaps: int = 0
    egomotion: int = 0
    egomotion_rejected: int = 0
    starts: int = 0
    stops: int = 0
    relocks: int = 0
    turns: int = 0
    last_event: str = ''
    events: list = field(default_factory=list)


class GaitTracker:
    """Runs the walk model on an inclinometer stream and optional visual motion.

    Args:
        config: gait settings.
        use_inclinometer_updates: False runs the inclinometer only through the change
            detector and for the start-up attitude (for evaluating visual motion alone).
    """

    def __init__(self, config: GaitConfig | None = None,
                 use_inclinometer_updates: bool = True) -> None:
        self.cfg = config if config is not None else GaitConfig()
        c = self.cfg
        self.prefilter = Prefilter(c.sample_rate, c.prefilter_cutoff, c.prefilter_order,
                                   c.sensor_lag)
        self.detector = WalkDetector(c)
        self.ekf = WalkModelEKF(c)
        self.stats = TrackerStats()
        self.use_inclinometer_updates = use_inclinometer_updates
        self._last_t: float | None = None
        self._last_any: float | None = None       # latest stamp of any accepted measurement
        self._settle = 0                          # prefiltered samples still settling
        self._resid2: np.ndarray = np.zeros(3)    # running mean squared post-fit residual
        self._next_lock_check = 0.0
        self._walk_start = 0.0
        self._was_turning = False
        # (t, model prediction, measurement, each IMM model's own yaw prediction (2,))
        self._past: deque = deque()
        self._zc_prev: tuple | None = None        # (t, lag-corrected measurement)
        self._z_raw: np.ndarray = np.zeros(3)     # latest raw measurement (yaw continuous)
        # running mean squared error of the model per IMM model (rows straight,
        # turning: they differ in yaw only, the roll and pitch columns are the same)
        self._e2m: np.ndarray = np.zeros((2, 3))
        self._e2h = np.zeros(3)                   # ... of "hold the attitude"
        self._emh = np.zeros((2, 3))              # ... and their mean product
        self._long = np.zeros((3, 3))             # the same over SKILL_LONG_MEMORY s walking
        self._long_n = 0.0                        # ... its weight (scored walking samples)
        self._last_yaw_raw = 0.0
        self._yaw_cont = 0.0
        self._default_var = (0.5 * _D2R) ** 2
        self._model_var = (c.model_error_deg * _D2R) ** 2
        self.fallback = (PredictionFallback(c.horizon, c.fallback_window, c.fallback_margin)
                         if c.fallback else None)
        self._pred_weighted: np.ndarray | None = None   # before the fallback rule
        _warm_up()

    @property
    def walking(self) -> bool:
        return self.ekf.walking

    @property
    def last_stamp(self) -> float | None:
        """Stamp of the latest accepted inclinometer sample, s."""
        return self._last_t

    # ------------------------------------------------------------------ inclinometer
    def add_inclinometer(self, t: float, rpy, var=None) -> GaitEstimate | None:
        """Process one inclinometer sample.

        Args:
            t: stamp, s.
            rpy: (3,) measured roll, pitch, yaw, rad (yaw may be wrapped).
            var: (3,) variances, rad^2 (None or non-positive: a default of (0.5 deg)^2;
                ignored when ``inclinometer_sigma_deg`` is set).
        Returns:
            The estimate at t, or None if the stamp is not later than the last one (the
            sample is ignored and counted in ``stats.out_of_order``).
        """
        t = float(t)
        rpy = np.asarray(rpy, float)
        if not all(map(math.isfinite, rpy.ravel().tolist())):
            raise ValueError(f'inclinometer angles must be finite, got {rpy}')
        if self._last_t is not None and t <= self._last_t:
            self.stats.out_of_order += 1
            return None
        c = self.cfg
        if c.inclinometer_sigma_deg > 0:
            v: np.ndarray = np.full(3, (c.inclinometer_sigma_deg * _D2R) ** 2)
        else:
            v = np.full(3, self._default_var) if var is None else np.asarray(var, float)
            if not all(math.isfinite(vi) and vi > 0 for vi in v.ravel().tolist()):
                v = np.where(np.isfinite(v) & (v > 0), v, self._default_var)
        event = None
        if self._last_t is None:
            self._yaw_cont = rpy[2]
        else:
            self._yaw_cont += wrap_angle(rpy[2] - self._last_yaw_raw)
            if t - self._last_t > c.max_gap:
                # restart the prefilter and the detector; the walk goes on (coasting on
                # the model) only if visual motion kept the filter informed meanwhile
                self.stats.gaps += 1
                self.prefilter.reset()
                self.detector.reset()
                self._settle = self.prefilter.settle_samples
                if self.ekf.walking and t - cast(float, self._last_any) > c.max_gap:
                    self.ekf.stop_walking()
                    event = 'gap'
        self._last_yaw_raw = rpy[2]
        z = np.array([rpy[0], rpy[1], self._yaw_cont])
        self._last_t = t
        self._last_any = t if self._last_any is None else max(self._last_any, t)
        self.stats.inclinometer += 1
        if self.ekf.t is None:
            self.ekf.initialise(t, z, v)
        zf = self.prefilter(z)                              # the prefiltered measurement
        self.ekf.predict_to(t)
        s = t - cast(float, self.ekf.t)                     # <= 0 if visual motion led
        # R: the unfiltered variance. The prefilter lowers the noise by its noise gain but
        # correlates it over about 1/gain samples, so the information per filtered sample
        # is about that of one raw sample.
        # model error: at least the configured one, more where the walk model fits worse
        # (an adaptive R: running mean of the squared post-fit residual, 3 s)
        floor = self._resid2 if self.ekf.walking else 0.0
        R = np.zeros((3, 3))
        R.flat[::4] = v + np.maximum(self._model_var, floor)        # diagonal
        settling = self._settle > 0
        if settling:
            self._settle -= 1
            nis = None
        elif self.use_inclinometer_updates or not self.ekf.walking:
            nis = self.ekf.update_attitude(zf, R, s, self.prefilter)
            if self.ekf.walking and c.adaptive_model_error:
                r = zf - self.ekf.attitude(s, self.prefilter)
                r[2] = wrap_angle(float(r[2]))
                a = 1.0 / (3.0 * c.sample_rate)
                self._resid2 += a * (r * r - self._resid2)
        else:
            nis = None
        if not settling:
            self.detector.push(t, zf)
            self._turn_check()
            if self.ekf.walking and nis is not None:
                # non-walking movement shows in roll and pitch (yaw jumps at turns)
                # (set by the update that returned nis)
                y, S = cast(np.ndarray, self.ekf.last_y), cast(np.ndarray, self.ekf.last_S)
                self.detector.push_nis(t, _nis2(y, S) / 2.0)
            if event is None:
                event = self._detect(t)
        if event is not None:
            self.stats.last_event = event
            self.stats.events.append((t, event))
        # the measurement with the known lag of its walk-model part undone:
        # z_c = z_f + (model(true) - model(through the prefilter and sensor lag))
        s = t - cast(float, self.ekf.t)
        zc = zf + self.ekf.lag_correction(s, self.prefilter)
        self._z_raw = z
        self._score_past(t, zc)
        self._zc_prev = (t, zc)
        if self.fallback is not None:
            self.fallback.score(t, zc)
        est = self.estimate(t, event)
        if self.fallback is not None:
            self.fallback.push(t, self._pred_weighted, z)
        yaw_j = self.ekf.predict_models(t - cast(float, self.ekf.t) + c.horizon)[:, 2]
        self._past.append((t, est.predicted_model, z, yaw_j))
        return est

    def _score_past(self, t: float, zc: np.ndarray) -> None:
        """Score the walk model's past predictions against "hold the measurement": every
        prediction made ``horizon`` s ago, and the measurement then, are compared with
        the measurement at the target time (interpolated between the latest two
        samples); running mean squared errors per axis over ``skill_memory`` s. The
        measurements are z_c: prefiltered, with the lag of their walk-model part undone
        (the true attitude plus noise where the model holds).

        Yaw is scored per IMM model: the straight and the turning model's own
        predictions (both, whichever was the more probable), so that each model's weight
        reflects its own skill — the straight model's errors at a turn's onset do not
        lower the turning model's weight once it has taken over, and errors both models
        share (a poor start fit) lower both."""
        h = self.cfg.horizon
        past = self._past
        a = 1.0 / max(self.cfg.skill_memory * self.cfg.sample_rate, 1.0)
        t0, z0 = self._zc_prev if self._zc_prev is not None else (t, zc)
        while past and past[0][0] + h <= t + 1e-9:
            ti, pm, held, yaw_j = past.popleft()
            u = 1.0 if t <= t0 else min(max((ti + h - t0) / (t - t0), 0.0), 1.0)
            b = 0.0                                  # the long memory's weight, walking
            if self.ekf.walking:
                b = 1.0 / max(SKILL_LONG_MEMORY * self.cfg.sample_rate, 1.0)
                self._long_n += 1.0
                b = max(b, 1.0 / self._long_n)
            if _nb_score is not None:
                _nb_score(u, z0, zc, pm, held, float(yaw_j[0]), float(yaw_j[1]), a,
                          self._e2m, self._e2h, self._emh, b, self._long)
                continue
            truth = z0 + u * wrap_diff(zc, z0)
            em = pm - truth
            eh = held - truth
            em[2], eh[2] = wrap_angle(em[2]), wrap_angle(eh[2])
            emj = np.array([em, em])                 # per model: own yaw error
            emj[:, 2] = [wrap_angle(float(y - truth[2])) for y in yaw_j]
            self._e2m += a * (emj * emj - self._e2m)
            self._e2h += a * (eh * eh - self._e2h)
            self._emh += a * (emj * eh - self._emh)
            if b > 0.0:
                self._long += b * (np.array([em * em, eh * eh, em * eh]) - self._long)

    def _turn_check(self) -> None:
        """Count turns (the IMM's turning model becoming the more probable one)."""
        turning = self.ekf.walking and self.ekf.turning
        if turning and not self._was_turning:
            self.stats.turns += 1
        self._was_turning = turning

    def _detect(self, t: float) -> str | None:
        if not self.ekf.walking:
            fit = self.detector.check_start(self.prefilter)
            if fit is not None:
                self._start(t, fit)
                self.stats.starts += 1
                self._walk_start = t
                self._next_lock_check = t + self.cfg.relock_period
                return 'start'
            return None
        d = cast(float, self.ekf.t) - t
        reason = self.detector.check_stop(
            float(self.ekf.x[I_F]),
            lambda tau: (self.ekf.oscillation(tau - d, self.prefilter),
                         self.ekf.oscillation_amplitude(self.prefilter)))
        if reason == 'frequency':
            # the tracked frequency ran off: a bad lock rather than a stop if the window
            # still holds a walk
            fit = self.detector.check_start(self.prefilter)
            if fit is not None:
                self._start(t, fit)
                self.stats.relocks += 1
                self._next_lock_check = t + self.cfg.relock_period
                return 'relock'
        if reason is not None:
            self.ekf.stop_walking()
            self.detector.clear()
            self._resid2[:] = 0.0
            self.stats.stops += 1
            return reason
        if t >= self._next_lock_check:
            early = t - self._walk_start < 3.0
            self._next_lock_check = t + self.cfg.relock_period * (1.0 if early else 4.0)
            fit = self.detector.check_lock(float(self.ekf.x[I_F]))
            if fit is not None:
                self._start(t, fit, relock=True)
                self.stats.relocks += 1
                return 'relock'
        return None

    def _start(self, t: float, fit: WalkFit, relock: bool = False) -> None:
        """Initialise the oscillation from the detector's fit (measured domain at t).

        A relock (walking already) keeps the tracked offsets and yaw rate, and during a
        turn the whole yaw block (the fit's straight trend cannot describe a turn). A
        start and a relock both restart the skill record (``_restart_skill``): it scored
        the oscillation that the new fit replaces."""
        pf = self.prefilter
        ekf = self.ekf
        lay = ekf.layout
        keep = ekf.walking and ekf.turning
        old = ekf.x.copy()
        old_P = ekf.P.copy()
        old_yaw = ekf.coefficients()[lay.of_axis(2)]
        f = fit.frequency
        d = cast(float, ekf.t) - t            # >= 0: the filter time may be ahead
        resp = pf.response(0.5 * lay.k * f)
        # measured -> true (divide by the response), then advance the phase to the
        # filter time (stride phase 0 there)
        c_meas = np.array([fit.harmonic(int(a), int(k)) for a, k in zip(lay.axis, lay.k)])
        coef = c_meas / resp * np.exp(1j * lay.k * np.pi * f * d)
        amp = np.abs(coef)
        coef[amp > self.cfg.max_amplitude_deg * _D2R] = 0.0    # implausible: not gait sway
        offset = fit.offset + fit.trend * pf.dc_delay
        offset[2] += fit.trend[2] * d
        rate = float(fit.trend[2])
        if relock:
            offset, rate = old[I_O].copy(), float(old[I_R])
        if keep:
            offset[2], rate = old[I_O[2]], old[I_R]
        # the initial spread of the roll and pitch offsets: the start fit's posterior of
        # offset + trend * delay, at least START_OFFSET_SD. A walk start shifts the trunk
        # (sideways onto the stance leg, forwards into the walk) and a 1 s window holds
        # less than a stride, so the level is uncertain by about the stride sway; an
        # offset held too tightly pushes that shift into the frequency and phase. (The
        # yaw level is a ramp whose rate has its own spread.)
        sigma = None
        if fit.offset_trend_cov is not None and not relock:
            g = np.array([1.0, pf.dc_delay])
            var = np.einsum('i,aij,j->a', g, fit.offset_trend_cov, g)     # g^T C_a g
            var[2] = 0.0
            sigma = {'o': np.sqrt(np.maximum(var, START_OFFSET_SD ** 2))}
        ekf.start_walking(f, coef, offset, rate, sigma)
        if keep:
            ekf.x[I_YA] = old[I_YA]
        pos = lay.of_axis(2)
        if keep:
            yb = np.r_[lay.alpha[pos], lay.beta[pos], I_O[2], I_R, I_YA]
            x = ekf.kf.x[:, 0]
            x[lay.alpha[pos]], x[lay.beta[pos]] = old_yaw.real, old_yaw.imag
            P = ekf.P
            P[yb, :] = 0.0
            P[:, yb] = 0.0
            P[np.ix_(yb, yb)] = old_P[np.ix_(yb, yb)]
            mu = ekf.mu.copy()
            ekf.sync_models()
            ekf.mu = mu
        self.detector.start_reference()
        if not relock:
            # the model error starts at what the start fit left unexplained
            self._resid2 = np.asarray(fit.residual, float) ** 2
        # the skill record belongs to the oscillation that made the predictions: a relock
        # replaces it by a new fit, so the record restarts from the prior as at a start
        self._restart_skill(f)

    def _restart_skill(self, f: float) -> None:
        """Restart the skill statistics from a prior (at a walk start or a relock: a new
        oscillation, whose predictions the record of the old one does not describe).

        Holding errs by the change over the horizon, E e_h^2 = the larger of the fitted
        oscillation's (mean over a stride) and the one seen in the buffered samples, plus
        SKILL_FLOOR^2; the model by E e_m^2 = SKILL_PRIOR E e_h^2 with E e_m e_h = 0
        (w = 0.5), or, once SKILL_LONG_MIN s of walking were scored, as on the earlier
        walks (the long memory, scaled to this E e_h^2). The pending predictions are
        dropped (they were made by the old oscillation).

        Args:
            f: the new step frequency, Hz (the stride over which the prior is taken).
        """
        ekf = self.ekf
        self._past.clear()
        h = self.cfg.horizon
        s = np.linspace(0.0, 2.0 / f, 16, endpoint=False)
        d = ekf.oscillation(s + h) - ekf.oscillation(s)
        e2 = np.mean(d * d, axis=0)
        tau, z = self.detector.window(2.0 / f)
        if tau.size and tau[-1] - tau[0] > h:
            zh = np.column_stack([np.interp(tau + h, tau, z[:, a]) for a in range(3)])
            m = tau + h <= tau[-1]
            seen = np.mean((zh[m] - z[m]) ** 2, axis=0)
            e2 = np.maximum(e2, seen)
        self._e2h = e2 + SKILL_FLOOR ** 2
        self._e2m = np.tile(SKILL_PRIOR * self._e2h, (2, 1))     # both IMM models
        self._emh = np.zeros((2, 3))
        if self._long_n >= SKILL_LONG_MIN * self.cfg.sample_rate:
            # the skill shown on earlier walks, scaled to this walk's holding error
            sc = self._e2h / np.maximum(self._long[1], 1e-12)
            self._e2m = np.tile(self._long[0] * sc, (2, 1))
            self._emh = np.tile(self._long[2] * sc, (2, 1))

    # ------------------------------------------------------------------ visual motion
    def add_egomotion(self, t_prev: float, t_cur: float, r_optical,
                      sigma: float | None = None) -> bool:
        """Fuse one visual-motion measurement (/egomotion).

        Args:
            t_prev, t_cur: stamps of the previous and the current camera frame, s.
            r_optical: (3, 3) rotation of the left camera from the previous frame to the
                current one (current camera axes in the previous camera frame, optical
                axes).
            sigma: per-axis noise of the increment, rad (default the configured one).
        Returns:
            True if used; False if ignored (no inclinometer yet, a bad interval, too
            old, or an outlier by its normalised innovation).
        """
        if self.ekf.t is None or not (t_cur > t_prev) or t_cur - t_prev > 1.0:
            return False
        if t_cur < self.ekf.t - EGOMOTION_MAX_AGE:
            self.stats.egomotion_rejected += 1
            return False
        self.ekf.predict_to(t_cur)
        s_a, s_b = t_prev - self.ekf.t, t_cur - self.ekf.t
        ref, _ = self.ekf.model(s_a)
        dz = rpy_increment(ref, egomotion_to_body(r_optical))  # attitude increment
        sig = (self.cfg.egomotion_sigma_deg * _D2R) if sigma is None else float(sigma)
        E = euler_rate_matrix(ref)
        R = (E @ E.T) * sig * sig             # rotation-vector noise -> angle increments
        R += np.eye(3) * (self.cfg.egomotion_model_error_deg * _D2R) ** 2
        # gate on the innovation before committing
        hb, Hb = self.ekf.model(s_b)
        ha, Ha = self.ekf.model(s_a)
        y = dz - (hb - ha)
        y[2] = wrap_angle(y[2])
        Hd = Hb - Ha
        S = Hd @ self.ekf.P @ Hd.T + R
        if float(y @ np.linalg.solve(S, y)) > EGOMOTION_GATE:
            self.stats.egomotion_rejected += 1
            return False
        self.ekf.update_increment(dz, R, s_a, s_b)
        self.stats.egomotion += 1
        self._last_any = max(self._last_any or t_cur, t_cur)
        return True

    # ------------------------------------------------------------------ output
    def skill_weights(self) -> np.ndarray:
        """(3,) weight of the walk model's prediction against holding the measurement,
        per axis: the minimum-MSE combination w em + (1 - w) eh of two correlated
        predictors, w_j = (E eh^2 - E em_j eh) / E (em_j - eh)^2 clipped to [0, 1] for
        each IMM model j (straight, turning; em_j its own error), w = sum_j mu_j w_j with
        the models' current probabilities (only at an inclinometer stamp: visual motion
        alone has no measurement to hold)."""
        return self.ekf.mu @ self.model_skill_weights()

    def model_skill_weights(self) -> np.ndarray:
        """(2, 3) the minimum-MSE weight w_j of each IMM model (rows straight, turning)
        and axis (roll and pitch the same for both)."""
        num = self._e2h - self._emh
        den = self._e2m + self._e2h - 2.0 * self._emh
        return (num / np.maximum(den, 1e-12)).clip(0.0, 1.0)

    def estimate(self, t: float | None = None, event: str | None = None) -> GaitEstimate:
        """The estimate at stamp t (default the latest inclinometer stamp)."""
        ekf = self.ekf
        if ekf.t is None:
            raise RuntimeError('no measurement yet')
        t = (self._last_t if self._last_t is not None else ekf.t) if t is None else t
        s = t - ekf.t
        x = ekf.x
        h = self.cfg.horizon
        att = ekf.attitude(s)
        if s + h >= 0:
            pred, cov = ekf.predict_attitude(s + h)
        else:
            pred, H = ekf.model(s + h)
            cov = H @ ekf.P @ H.T
        pred_model, cov_model = pred, cov
        target = pred                         # where the rig is predicted to turn to
        fresh = (self._zc_prev is not None
                 and abs(t - self._zc_prev[0]) <= 0.5 / self.cfg.sample_rate)
        if self.cfg.skill_weighting and fresh:
            # (as floats: 3-vectors, the arithmetic of the array expressions in comments)
            w = self.skill_weights().tolist()
            pm, att_l = pred_model.tolist(), att.tolist()
            # pred = held + w * wrap_diff(pred_model, held)
            pred = np.array(_towards(self._z_raw.tolist(), pm, w))
            # cov = w_i cov_ij w_j + diag((1 - w)^2 e2h)
            cv, e2h = cov.tolist(), self._e2h.tolist()
            cov = np.array([[w[i] * cv[i][j] * w[j]
                             + ((1.0 - w[i]) * (1.0 - w[i]) * e2h[i] if i == j else 0.0)
                             for j in range(3)] for i in range(3)])
            # the motion likewise: holding predicts none
            target = np.array(_towards(att_l, pm, w))
        self._pred_weighted = pred
        held = None
        if self.fallback is not None and fresh:
            held = self.fallback.holding.copy()
            if held.any():
                e2h_held = self.fallback.mean_squares()[1]
                pred = self.fallback.apply(pred, self._z_raw)
                target = np.where(held, att, target)
                cov = cov.copy()
                cov[held, :] = 0.0
                cov[:, held] = 0.0
                cov[held, held] = e2h_held[held]
        amplitude, phase = ekf.amplitude_phase(s)
        o_r, o_p, o_y, r, ya = x[2:7].tolist()                     # I_O, I_R, I_YA
        offset = np.array([o_r, o_p, o_y + (r * s + 0.5 * ya * s * s)])
        return GaitEstimate(
            stamp=float(t), walking=bool(ekf.walking), step_frequency=float(x[I_F]),
            step_frequency_variance=float(ekf.P[I_F, I_F]), amplitude=amplitude,
            phase=phase, offset=offset, yaw_rate=float(x[I_R]), attitude=att,
            horizon=h, predicted=pred, predicted_covariance=cov,
            motion=relative_rotation(att, target), event=event, predicted_model=pred_model,
            predicted_model_covariance=cov_model, fallback=held)
