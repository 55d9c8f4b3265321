"""The gait tracker: inclinometer stream -> prefilter -> change detector -> walk-model
EKF, with visual-motion increments fused into the same filter, and the prediction at
the horizon. This is everything the gait-filter node does, without ROS.

Times are seconds on any common clock (message stamps); angles radians, REP 103
roll/pitch/yaw of ``inclinometer_link`` in ``world``.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from asmonc_vision.core.gait.detector import WalkDetector, WalkFit, lstsq
from asmonc_vision.core.gait.model import I_A, I_F, I_O, I_PH, I_R, K_AXIS, GaitConfig, \
    WalkModelEKF
from asmonc_vision.core.gait.prefilter import Prefilter
from asmonc_vision.core.gait.rotations import (egomotion_to_body, euler_rate_matrix,
                                               relative_rotation, rpy_increment,
                                               wrap_angle)

_D2R = np.pi / 180.0
#: visual-motion increments whose normalised innovation exceeds this are outliers
#: (chi-square, 3 degrees of freedom, p = 0.001)
EGOMOTION_GATE = 16.27
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
            inclinometer_link at the stamp (the predicted camera-rig rotation).
        event: 'start', 'stop', 'movement', 'frequency', 'gap' when the walking verdict
            changed at this sample, 'relock' when the oscillation was re-initialised
            while walking, else None.
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
        self._resid2 = np.zeros(3)                # running mean squared post-fit residual
        self._next_lock_check = 0.0
        self._walk_start = 0.0
        self._sway_history: deque = deque()       # (t, A_yaw, phi_yaw) while walking straight
        self._last_yaw_raw = 0.0
        self._yaw_cont = 0.0
        self._default_var = (0.5 * _D2R) ** 2

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
        if not np.all(np.isfinite(rpy)):
            raise ValueError(f'inclinometer angles must be finite, got {rpy}')
        if self._last_t is not None and t <= self._last_t:
            self.stats.out_of_order += 1
            return None
        c = self.cfg
        if c.inclinometer_sigma_deg > 0:
            v = np.full(3, (c.inclinometer_sigma_deg * _D2R) ** 2)
        else:
            v = np.full(3, self._default_var) if var is None else np.asarray(var, float)
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
                if self.ekf.walking and t - self._last_any > c.max_gap:
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
        s = t - self.ekf.t                                  # <= 0 if visual motion led
        # R: the unfiltered variance. The prefilter lowers the noise by its noise gain but
        # correlates it over about 1/gain samples, so the information per filtered sample
        # is about that of one raw sample.
        # model error: at least the configured one, more where the walk model fits worse
        # (an adaptive R: running mean of the squared post-fit residual, 3 s)
        floor = self._resid2 if self.ekf.walking else 0.0
        R = np.diag(v + np.maximum((c.model_error_deg * _D2R) ** 2, floor))
        settling = self._settle > 0
        if settling:
            self._settle -= 1
            nis = None
        elif self.use_inclinometer_updates or not self.ekf.walking:
            nis = self.ekf.update_attitude(zf, R, s, self.prefilter)
            if self.ekf.walking and c.adaptive_model_error:
                r = zf - self.ekf.model(s, self.prefilter)[0]
                r[2] = wrap_angle(float(r[2]))
                a = 1.0 / (3.0 * c.sample_rate)
                self._resid2 += a * (r * r - self._resid2)
        else:
            nis = None
        if not settling:
            self.detector.push(t, zf)
            self._turn_check(t)
            if self.ekf.walking and nis is not None:
                # non-walking movement shows in roll and pitch (yaw jumps at turns)
                y, S = self.ekf.last_y, self.ekf.last_S
                self.detector.push_nis(t, float(y[:2] @ np.linalg.solve(S[:2, :2], y[:2]))
                                       / 2.0)
            if event is None:
                event = self._detect(t)
        if event is not None:
            self.stats.last_event = event
            self.stats.events.append((t, event))
        return self.estimate(t, event)

    def _turn_check(self, t: float) -> None:
        """Turn detection (the flexible yaw rate; the paper's "corner turning").

        The yaw over the last stride is fitted with offset + trend + the stride sinusoid
        (so the sway cancels). A trend above ``turn_rate_deg`` starts a turn: the yaw
        block is re-initialised from the fit (the sinusoid may have absorbed the turn's
        beginning) and the yaw rate gets the larger turning process noise, the yaw
        sinusoid a smaller one, until the trend falls below half the threshold.
        """
        ekf = self.ekf
        f = float(ekf.x[I_F]) if ekf.walking else 0.0
        span = 2.0 / f if f > 0 else 1.0
        tau, z = self.detector.window(span)
        if tau.size < 6:
            return
        one = np.ones(tau.size)
        sway = []
        if f > 0:
            w = np.pi * f * tau
            sway = [np.sin(w), np.cos(w)]
        # detection: the mean trend over the stride (robust); the values to start from:
        # a quadratic trend (its slope at the window's end follows the turn closely)
        mean_slope = float(lstsq(np.column_stack([one, tau] + sway), z[:, 2])[1])
        thr = self.cfg.turn_rate_deg * _D2R
        hist = self._sway_history
        if abs(mean_slope) > thr and not ekf.turning:
            ekf.turning = True
            pf = self.prefilter
            d = ekf.t - t
            # the sway as it was before the turn began (the filter has been absorbing
            # the turn's start into the sinusoid since): some 3/4 stride ago
            amp, phase = float(ekf.x[I_A[2]]), float(ekf.x[I_PH[2]])
            if f > 0 and hist:
                back = t - 0.75 * span
                tb, ab, pb = hist[0]
                for item in hist:
                    if item[0] <= back:
                        tb, ab, pb = item
                amp, phase = ab, pb + np.pi * f * (ekf.t - tb)
                w = np.pi * f * tau
                sway_fit = amp * np.sin(phase - np.pi * f * (ekf.t - t) + w
                                        + float(np.angle(pf.response(0.5 * f)))) \
                    * float(np.abs(pf.response(0.5 * f)))
            else:
                sway_fit = 0.0
            # offset and rate: a quadratic trend through the yaw without that sway
            c = np.polyfit(tau, z[:, 2] - sway_fit, 2)
            slope = float(c[1])
            offset = float(c[2]) + slope * (pf.dc_delay + d)
            ekf.reset_yaw(amp, phase, offset, slope, 0.1 * _D2R, 0.05, 0.5 * _D2R,
                          0.3 * abs(slope) + 2.0 * _D2R)
            hist.clear()
        elif abs(mean_slope) < 0.5 * thr:
            ekf.turning = False
        if ekf.walking and not ekf.turning:
            hist.append((ekf.t, float(ekf.x[I_A[2]]), float(ekf.x[I_PH[2]])))
            while hist and hist[0][0] < ekf.t - 2.0:
                hist.popleft()

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
        reason = self.detector.check_stop(float(self.ekf.x[I_F]), self.prefilter)
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
        turn the whole yaw block (the fit's straight trend cannot describe a turn)."""
        pf = self.prefilter
        keep = self.ekf.walking and self.ekf.turning
        old = self.ekf.x.copy()
        old_P = self.ekf.P.copy()
        f = fit.frequency
        d = self.ekf.t - t                    # >= 0: the filter time may be ahead
        H = pf.response(np.r_[K_AXIS * f, 2.0 * f])
        g, psi = np.abs(H), np.angle(H)
        amp = fit.amplitude / g[:3]
        amp[amp > self.cfg.max_amplitude_deg * _D2R] = 0.0     # implausible: not gait sway
        phase = fit.phase - psi[:3] + 2.0 * np.pi * K_AXIS * f * d
        offset = fit.offset + fit.trend * pf.dc_delay
        offset[2] += fit.trend[2] * d
        harmonic = (fit.harmonic[0] / g[3],
                    fit.harmonic[1] - psi[3] + 2.0 * np.pi * 2.0 * f * d - 2.0 * phase[1])
        rate = float(fit.trend[2])
        if relock:
            offset, rate = old[I_O].copy(), float(old[I_R])
        if keep:
            amp[2], phase[2], offset[2], rate = old[I_A[2]], old[I_PH[2]], old[I_O[2]], old[I_R]
        self.ekf.start_walking(f, amp, phase, offset, rate, harmonic)
        if keep:
            yb = np.array([I_A[2], I_PH[2], I_O[2], I_R])
            P = self.ekf.P
            P[yb, :] = 0.0
            P[:, yb] = 0.0
            P[np.ix_(yb, yb)] = old_P[np.ix_(yb, yb)]
        self.detector.start_reference(float(amp[1]))

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
    def estimate(self, t: float | None = None, event: str | None = None) -> GaitEstimate:
        """The estimate at stamp t (default the latest inclinometer stamp)."""
        ekf = self.ekf
        if ekf.t is None:
            raise RuntimeError('no measurement yet')
        t = (self._last_t if self._last_t is not None else ekf.t) if t is None else t
        s = t - ekf.t
        x = ekf.x
        h = self.cfg.horizon
        att, _ = ekf.model(s)
        if s + h >= 0:
            pred, cov = ekf.predict_attitude(s + h)
        else:
            pred, H = ekf.model(s + h)
            cov = H @ ekf.P @ H.T
        if ekf.walking:
            phase = wrap_angle(x[I_PH] + 2.0 * np.pi * K_AXIS * x[I_F] * s)
        else:
            phase = x[I_PH].copy()
        offset = x[I_O].copy()
        offset[2] += x[I_R] * s
        return GaitEstimate(
            stamp=float(t), walking=bool(ekf.walking), step_frequency=float(x[I_F]),
            step_frequency_variance=float(ekf.P[I_F, I_F]), amplitude=x[I_A].copy(),
            phase=phase, offset=offset, yaw_rate=float(x[I_R]), attitude=att,
            horizon=h, predicted=pred, predicted_covariance=cov,
            motion=relative_rotation(att, pred), event=event)
