"""The human walk model of Molton et al. (1998, Section 5) as an iterated extended
Kalman filter.

Each attitude axis of ``inclinometer_link`` (REP 103 roll, pitch, yaw in ``world``,
radians) is a sinusoid on an offset,

    roll(t)  = o_r + A_r sin(phi_r(t))                      phi_r' = 2 pi f / 2
    pitch(t) = o_p + A_p sin(phi_p(t)) [+ B sin(2 phi_p(t) + delta)]   phi_p' = 2 pi f
    yaw(t)   = o_y(t) + A_y sin(phi_y(t))     o_y' = r     phi_y' = 2 pi f / 2

with one shared base (step) frequency ``f`` (Hz): pitch at the step frequency, roll and
yaw at half of it (Lee's gait-lab data, as in the paper). The paper's "more flexible
states" are random walks on every parameter (speed changes: f and the amplitudes;
uphill walking: the pitch offset) plus a yaw-rate state ``r`` (corner turning), and an
optional second harmonic of pitch.

State vector x (textbook symbols throughout: x, P, F, Q, H, R, z):

    index  0      1    2      3    4    5      6    7    8      9    10   [11  12]
    state  f      A_r  phi_r  o_r  A_p  phi_p  o_p  A_y  phi_y  o_y  r    [B   delta]
    unit   Hz     rad  rad    rad  rad  rad    rad  rad  rad    rad  rad/s [rad rad]

The dynamics are linear (phases advance with f, the yaw offset with r), so the
prediction is the ordinary Kalman one (filterpy's ``KalmanFilter.predict``); the
measurements are nonlinear and use an iterated (Gauss-Newton) EKF update written here.
Because the model is a parametric function of time, a measurement made ``s`` seconds
before (s < 0) or after the filter time is predicted exactly by advancing the phases by
``2 pi k f s`` -- which is how the visual-motion increments (over an interval in the
past) and the prediction horizon are handled.

Not walking (the change detector's verdict): the oscillation states (f, amplitudes,
phases, harmonic) are frozen -- neither predicted nor updated -- and contribute nothing
to the attitude; the offsets (and the yaw rate) follow the measured attitude, which is
then the prediction.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter

from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.gait.rotations import wrap_angle

#: frequency multiple of each axis (roll, pitch, yaw) relative to the step frequency
K_AXIS = np.array([0.5, 1.0, 0.5])
I_F = 0
I_A = np.array([1, 4, 7])
I_PH = np.array([2, 5, 8])
I_O = np.array([3, 6, 9])
I_R = 10
I_B = 11
I_D = 12
STATE_NAMES = ('f', 'A_roll', 'phi_roll', 'o_roll', 'A_pitch', 'phi_pitch', 'o_pitch',
               'A_yaw', 'phi_yaw', 'o_yaw', 'yaw_rate', 'B_pitch2', 'delta_pitch2')
#: indices of the oscillation states (frozen when not walking), without the harmonic
_OSC = np.array([0, 1, 2, 4, 5, 7, 8])
_D2R = math.pi / 180.0


@dataclass(frozen=True)
class GaitConfig:
    """Walk model, prefilter and change detector. Frozen; validated on construction.

    Noise densities are per square-root second (random walks): a state with density q
    wanders by about q * sqrt(T) in T seconds.
    """

    horizon: float = param(0.5, 'prediction horizon, s (GaitState.predicted and '
                           '/gait/predicted_motion are for stamp + horizon)',
                           range=(0.0, 5.0))
    sample_rate: float = param(16.0, 'nominal inclinometer rate, Hz (the prefilter is '
                               'designed for it)', range=(1.0, 1000.0))
    sensor_lag: float = param(0.08, "the inclinometer's own first-order lag (time "
                              'constant), s; compensated in the measurement model',
                              range=(0.0, 2.0))
    prefilter_cutoff: float = param(6.0, 'Butterworth low-pass cut-off, Hz (below half '
                                    'the sample rate; 0 = no prefilter)', range=(0.0, 500.0))
    prefilter_order: int = param(2, 'Butterworth prefilter order', range=(1, 8))
    inclinometer_sigma_deg: float = param(0.0, 'inclinometer noise per angle, degrees; '
                                          '0 = use the Imu message covariance',
                                          range=(0.0, 30.0))
    model_error_deg: float = param(0.5, 'added to the inclinometer noise (in quadrature) '
                                   'for what the walk model does not describe (higher '
                                   'harmonics, sway, posture), degrees', range=(0.0, 30.0))
    adaptive_model_error: bool = param(True, 'raise the model error of an axis to the '
                                       'running mean (3 s) of its squared post-fit '
                                       'residual while walking')
    egomotion_sigma_deg: float = param(0.5, 'noise of each visual-motion rotation '
                                       'increment per axis, degrees (TransformStamped '
                                       'carries no covariance)', range=(0.01, 30.0))
    egomotion_model_error_deg: float = param(0.3, 'added to each visual-motion increment\'s '
                                             'noise (in quadrature) for what the walk '
                                             'model does not describe, degrees',
                                             range=(0.0, 30.0))
    max_amplitude_deg: float = param(10.0, 'largest plausible gait amplitude of an axis, '
                                     'deg (a walk-start fit beyond it starts that axis '
                                     'at zero)', range=(0.1, 90.0))
    min_frequency: float = param(1.0, 'lowest step frequency, Hz', range=(0.2, 5.0))
    max_frequency: float = param(2.8, 'highest step frequency, Hz', range=(0.3, 6.0))
    pitch_harmonic: bool = param(True, 'model a second harmonic of pitch (two more '
                                 'states)')
    freq_noise: float = param(0.08, 'step frequency random walk, Hz/sqrt(s)',
                              range=(0.0, 10.0))
    phase_noise: float = param(0.05, 'phase random walk, rad/sqrt(s)', range=(0.0, 10.0))
    amplitude_noise_deg: float = param(0.8, 'amplitude random walk, deg/sqrt(s)',
                                       range=(0.0, 30.0))
    roll_offset_noise_deg: float = param(0.3, 'roll offset random walk while walking, '
                                         'deg/sqrt(s)', range=(0.0, 30.0))
    pitch_offset_noise_deg: float = param(0.6, 'pitch offset random walk while walking '
                                          '(uphill, posture), deg/sqrt(s)',
                                          range=(0.0, 30.0))
    yaw_offset_noise_deg: float = param(0.3, 'yaw offset random walk, deg/sqrt(s)',
                                        range=(0.0, 30.0))
    yaw_rate_noise_deg: float = param(0.5, 'yaw rate random walk when not turning, '
                                      'deg/s/sqrt(s)', range=(0.0, 500.0))
    turn_yaw_rate_noise_deg: float = param(30.0, 'yaw rate random walk while a turn is '
                                           'detected, deg/s/sqrt(s)', range=(0.0, 500.0))
    turn_rate_deg: float = param(8.0, 'turn detected while the yaw trend over the last '
                                 'stride exceeds this, deg/s (ends below half of it)',
                                 range=(0.1, 360.0))
    standing_offset_noise_deg: float = param(10.0, 'roll/pitch/yaw random walk while not '
                                             'walking, deg/sqrt(s)', range=(0.0, 100.0))
    iterations: int = param(3, 'most Gauss-Newton iterations of the iterated EKF update',
                            range=(1, 20))
    relock_window: float = param(2.5, 'while walking, the walk model is refitted over '
                                 'this window every relock_period s; a frequency off by '
                                 'more than relock_tolerance re-initialises the '
                                 'oscillation, s', range=(0.5, 20.0))
    relock_period: float = param(0.25, 'interval of the refit in the first 3 s of a '
                                 'walk (later four times as long), s', range=(0.05, 60.0))
    relock_tolerance: float = param(0.1, 'frequency difference that re-initialises the '
                                    'oscillation, Hz', range=(0.01, 5.0))
    detect_window: float = param(1.0, 'window of the walk-start detector (least-'
                                 'squares fit of the walk model), s', range=(0.3, 10.0))
    detect_recency: float = param(0.5, 'the start fit weights samples by exp(tau / this) '
                                  '(tau <= 0 s before the latest), s; 0 = equal weights',
                                  range=(0.0, 10.0))
    start_amplitude_deg: float = param(0.6, 'walk start: least pitch amplitude, deg',
                                       range=(0.0, 20.0))
    start_periodicity: float = param(0.6, 'walk start: least share of the detrended '
                                     'pitch variance explained by the gait sinusoids',
                                     range=(0.0, 1.0))
    start_sway_periodicity: float = param(0.5, 'walk start: least share of the detrended '
                                          'roll or yaw variance explained by the stride '
                                          'sinusoid (a bend has none)', range=(0.0, 1.0))
    stop_window: float = param(0.6, 'window of the walk-stop test (amplitude at the '
                               'tracked frequency), s', range=(0.2, 5.0))
    stop_amplitude_deg: float = param(0.3, 'walk stop: pitch amplitude below this, deg '
                                      '(absolute floor of the test below)',
                                      range=(0.0, 20.0))
    stop_fraction: float = param(0.5, 'walk stop: pitch amplitude over the stop window '
                                 'below this share of its running mean while walking '
                                 '(3 s)', range=(0.0, 1.0))
    nis_window: float = param(0.5, 'window of the mean normalised innovation, s',
                              range=(0.1, 5.0))
    nis_threshold: float = param(12.0, 'non-walking movement: mean normalised innovation '
                                 'squared per measurement above this', range=(1.0, 1000.0))
    max_gap: float = param(0.5, 'an inclinometer gap longer than this restarts the '
                           'prefilter and the detector, s', range=(0.05, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.max_frequency <= self.min_frequency:
            raise ValueError(f'GaitConfig.max_frequency = {self.max_frequency} must exceed '
                             f'min_frequency = {self.min_frequency}')
        if self.prefilter_cutoff > 0 and self.prefilter_cutoff >= 0.5 * self.sample_rate:
            raise ValueError(f'GaitConfig.prefilter_cutoff = {self.prefilter_cutoff} Hz must '
                             f'be below half the sample rate ({0.5 * self.sample_rate} Hz)')

    @property
    def dim_x(self) -> int:
        """Number of states (13 with the pitch harmonic, else 11)."""
        return 13 if self.pitch_harmonic else 11


def continuous_system(n: int, walking: bool) -> np.ndarray:
    """The continuous-time system matrix A (dx/dt = A x): phases advance with f, the
    yaw offset with r. Not walking, the phases stand still (frozen)."""
    a = np.zeros((n, n))
    if walking:
        a[I_PH, I_F] = 2.0 * np.pi * K_AXIS
    a[I_O[2], I_R] = 1.0
    return a


def discretise(a: np.ndarray, qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of dx = A x dt + dw, cov(dw) = diag(qc) dt, for nilpotent A (A^2 = 0).

    F = exp(A dt) = I + A dt;  Q = int_0^dt F(s) Qc F(s)^T ds
      = Qc dt + (A Qc + Qc A^T) dt^2 / 2 + A Qc A^T dt^3 / 3.
    """
    n = a.shape[0]
    f = np.eye(n) + a * dt
    qcm = np.diag(qc)
    aq = a @ qcm
    q = qcm * dt + (aq + aq.T) * (dt * dt / 2.0) + (aq @ a.T) * (dt ** 3 / 3.0)
    return f, q


class WalkModelEKF:
    """The walk model's iterated EKF (see the module doc for the state).

    Holds a filterpy ``KalmanFilter`` (x, P, F, Q) and the filter time ``t`` (s). The
    caller (``tracker.GaitTracker``) decides walking or not, supplies measurements with
    their time offsets, and initialises the oscillation when a walk starts.
    """

    def __init__(self, config: GaitConfig) -> None:
        self.cfg = config
        n = config.dim_x
        self.n = n
        self.kf = KalmanFilter(dim_x=n, dim_z=3)
        self.t: float | None = None
        self.walking = False
        c = config
        q = np.zeros(n)
        q[I_F] = c.freq_noise ** 2
        q[I_PH] = c.phase_noise ** 2
        q[I_A] = (c.amplitude_noise_deg * _D2R) ** 2
        q[I_O] = (np.array([c.roll_offset_noise_deg, c.pitch_offset_noise_deg,
                            c.yaw_offset_noise_deg]) * _D2R) ** 2
        q[I_R] = (c.yaw_rate_noise_deg * _D2R) ** 2
        if c.pitch_harmonic:
            q[I_B] = (0.5 * c.amplitude_noise_deg * _D2R) ** 2
            q[I_D] = c.phase_noise ** 2
        qs = np.zeros(n)
        qs[I_O] = (c.standing_offset_noise_deg * _D2R) ** 2
        qs[I_R] = q[I_R]
        q_turn, qs_turn = q.copy(), qs.copy()
        q_turn[I_R] = qs_turn[I_R] = (c.turn_yaw_rate_noise_deg * _D2R) ** 2
        # while turning the yaw sinusoid must not absorb the turn: its amplitude and
        # phase wander ten times less
        q_turn[I_A[2]] *= 0.01
        q_turn[I_PH[2]] *= 0.01
        # continuous process noise by (walking, turning)
        self._qc = {(True, False): q, (False, False): qs, (True, True): q_turn,
                    (False, True): qs_turn}
        #: a turn is under way: the yaw rate may change fast (set by the tracker)
        self.turning = False
        self._a = {w: continuous_system(n, w) for w in (True, False)}
        self._fq_cache: dict = {}
        self.last_nis: float = 0.0
        self.iterations_used = 0
        self._eye = np.eye(n)
        #: innovation (first iterate) and its covariance of the latest update
        self.last_y: np.ndarray | None = None
        self.last_S: np.ndarray | None = None

    # ------------------------------------------------------------------ state access
    @property
    def x(self) -> np.ndarray:
        """The state as a flat (n,) view."""
        return self.kf.x[:, 0]

    @property
    def P(self) -> np.ndarray:  # noqa: N802 (textbook symbol)
        return self.kf.P

    def initialise(self, t: float, rpy, var) -> None:
        """Start (not walking) at time t from a (lag-free) attitude and its variances."""
        n = self.n
        x = np.zeros(n)
        x[I_F] = 0.5 * (self.cfg.min_frequency + self.cfg.max_frequency)
        x[I_O] = np.asarray(rpy, float)
        p = np.diag(np.full(n, 1e-6))
        p[I_O, I_O] = np.asarray(var, float)
        p[I_R, I_R] = (10.0 * _D2R) ** 2
        self.kf.x = x[:, None]
        self.kf.P = p
        self.t = float(t)
        self.walking = False

    def start_walking(self, f: float, amplitude, phase, offset, yaw_rate: float,
                      harmonic: tuple[float, float] = (0.0, 0.0),
                      sigma: dict | None = None) -> None:
        """Switch the oscillation on with initial values (true-attitude domain, at the
        filter time) and a fresh covariance for the oscillation states."""
        x = self.x.copy()
        x[I_F] = f
        x[I_A] = amplitude
        x[I_PH] = wrap_angle(phase)
        x[I_O] = offset
        x[I_R] = yaw_rate
        s = {'f': 0.15, 'A': 0.5 * _D2R, 'phi': 0.6, 'o': 0.5 * _D2R, 'r': 5.0 * _D2R,
             'B': 0.3 * _D2R, 'delta': 1.0}
        if sigma:
            s.update(sigma)
        p = np.zeros((self.n, self.n))
        d = np.zeros(self.n)
        d[I_F] = s['f'] ** 2
        d[I_A] = s['A'] ** 2
        d[I_PH] = s['phi'] ** 2
        d[I_O] = s['o'] ** 2
        d[I_R] = s['r'] ** 2
        if self.cfg.pitch_harmonic:
            x[I_B], x[I_D] = harmonic[0], wrap_angle(harmonic[1])
            d[I_B] = s['B'] ** 2
            d[I_D] = s['delta'] ** 2
        p[np.diag_indices(self.n)] = d
        self.kf.x = x[:, None]
        self.kf.P = p
        self.walking = True
        self._normalise()

    def reset_yaw(self, amplitude: float, phase: float, offset: float, rate: float,
                  sigma_amplitude: float, sigma_phase: float, sigma_offset: float,
                  sigma_rate: float) -> None:
        """Re-initialise the yaw block (A_y, phi_y, o_y, r) at the filter time, e.g. when a
        turn starts (the sinusoid must not have absorbed the turn), dropping its
        correlations with the other states."""
        idx = np.array([I_A[2], I_PH[2], I_O[2], I_R])
        x = self.kf.x[:, 0]
        x[idx] = (amplitude, phase, offset, rate)
        P = self.kf.P
        P[idx, :] = 0.0
        P[:, idx] = 0.0
        P[idx, idx] = np.array([sigma_amplitude, sigma_phase, sigma_offset, sigma_rate]) ** 2
        if not self.walking:
            P[I_A[2], I_A[2]] = P[I_PH[2], I_PH[2]] = 1e-6
        self._normalise()

    def oscillation_indices(self) -> np.ndarray:
        """Indices of the states frozen when not walking."""
        if self.cfg.pitch_harmonic:
            return np.r_[_OSC, I_B, I_D]
        return _OSC

    def stop_walking(self) -> None:
        """Freeze the oscillation: its states keep their last values, and their
        correlations with the offsets are dropped so that no later update moves them."""
        self.walking = False
        osc = self.oscillation_indices()
        rest = np.setdiff1d(np.arange(self.n), osc)
        P = self.kf.P
        P[np.ix_(osc, rest)] = 0.0
        P[np.ix_(rest, osc)] = 0.0

    # ------------------------------------------------------------------ prediction
    def transition(self, dt: float, walking: bool | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """F and Q over dt seconds (dt >= 0) in the given (default: current) mode."""
        w = self.walking if walking is None else walking
        key = (round(dt, 9), w, self.turning)
        fq = self._fq_cache.get(key)
        if fq is None:
            fq = discretise(self._a[w], self._qc[(w, self.turning)], dt)
            if len(self._fq_cache) > 256:
                self._fq_cache.clear()
            self._fq_cache[key] = fq
        return fq

    def predict_to(self, t: float) -> None:
        """Advance the filter to time t (s); nothing happens if t is not later."""
        if self.t is None or t <= self.t:
            return
        F, Q = self.transition(t - self.t)
        self.kf.F, self.kf.Q = F, Q
        self.kf.predict()              # x = F x;  P = F P F^T + Q
        self.t = float(t)
        self._normalise()

    # ------------------------------------------------------------------ the model
    def model(self, s: float, prefilter=None, x: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        """Attitude (roll, pitch, yaw) at filter time + s and its Jacobian dh/dx (3, n).

        True attitude (prefilter None), per axis a with k = (1/2, 1, 1/2):

            h_a = o_a [+ r s for yaw] + A_a sin(phi_a + 2 pi k_a f s) [+ pitch harmonic]

        Measured (through ``prefilter``, whose response H(f) includes the sensor lag):

            h_a = o_a [+ r (s - tau_dc) for yaw] + |H(k_a f)| A_a sin(phi_a + 2 pi k_a f s
                  + arg H(k_a f))

        Args:
            s: time offset from the filter time, s (negative: the past).
            prefilter: a ``prefilter.Prefilter``: model the *measured* (prefiltered,
                sensor-lagged) attitude instead of the true one.
            x: state to evaluate (default the current estimate).
        Returns:
            (h (3,), H (3, n)).
        """
        x = self.x if x is None else x
        H = np.zeros((3, self.n))
        H[0, 3] = H[1, 6] = H[2, 9] = 1.0
        r = float(x[I_R])
        sy = s - prefilter.dc_delay if prefilter is not None else s
        h0, h1, h2 = float(x[3]), float(x[6]), float(x[9]) + r * sy
        H[2, I_R] = sy
        if not self.walking:
            return np.array([h0, h1, h2]), H
        f = float(x[I_F])
        tw = 2.0 * math.pi
        out = [h0, h1, h2]
        dfsum = [0.0, 0.0, 0.0]
        for a, (ia, k) in enumerate(((1, 0.5), (4, 1.0), (7, 0.5))):
            if prefilter is not None:
                g, psi, dg, dpsi = prefilter.gain_phase(k * f)
            else:
                g, psi, dg, dpsi = 1.0, 0.0, 0.0, 0.0
            amp = float(x[ia])
            arg = float(x[ia + 1]) + tw * k * f * s + psi
            sn, cs = math.sin(arg), math.cos(arg)
            out[a] += g * amp * sn
            H[a, ia] = g * sn                                  # dh/dA
            H[a, ia + 1] = g * amp * cs                        # dh/dphi
            # d/df of g(kf) A sin(phi + 2 pi k f s + psi(kf))
            dfsum[a] = amp * k * (dg * sn + g * cs * (tw * s + dpsi))
        if self.cfg.pitch_harmonic:
            if prefilter is not None:
                g, psi, dg, dpsi = prefilter.gain_phase(2.0 * f)
            else:
                g, psi, dg, dpsi = 1.0, 0.0, 0.0, 0.0
            b = float(x[I_B])
            arg2 = 2.0 * float(x[5]) + float(x[I_D]) + tw * 2.0 * f * s + psi
            s2, c2 = math.sin(arg2), math.cos(arg2)
            out[1] += g * b * s2
            H[1, I_B] = g * s2
            H[1, I_D] = g * b * c2
            H[1, 5] += 2.0 * g * b * c2
            dfsum[1] += b * 2.0 * (dg * s2 + g * c2 * (tw * s + dpsi))
        H[0, 0], H[1, 0], H[2, 0] = dfsum
        return np.array(out), H

    def predict_attitude(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """True attitude at filter time + s (s >= 0) and its (3, 3) covariance.

        The covariance includes the process noise over s:
        Cov = H (F(s) P F(s)^T + Q(s)) H^T with H at the filter time evaluated for x(s).
        """
        F, Q = self.transition(max(s, 0.0))
        xs = F @ self.x
        Ps = F @ self.P @ F.T + Q
        h, H = self.model(0.0, x=xs)
        return h, H @ Ps @ H.T

    # ------------------------------------------------------------------ updates
    def update(self, z, R, hfun, wrap_yaw: bool = True) -> float | None:
        """Iterated EKF update with measurement z (m,), noise R (m, m).

        ``hfun(x) -> (h (m,), H (m, n))``. Iterates (Gauss-Newton)

            x_{i+1} = x^- + K_i (z - h(x_i) - H_i (x^- - x_i)),
            K_i = P^- H_i^T (H_i P^- H_i^T + R)^-1,

        until the step is tiny or ``iterations`` are done, then (Joseph form)
        P = (I - K H) P^- (I - K H)^T + K R K^T. ``z = None``: a missed measurement,
        nothing changes. Angle residuals of the third row are wrapped (yaw) if asked.

        Returns:
            The normalised innovation squared y^T S^-1 y of the first iterate, or None.
        """
        if z is None:
            return None
        z = np.asarray(z, float)
        x_prior = self.x.copy()
        P = self.P
        xi = x_prior
        nis = None
        for it in range(self.cfg.iterations):
            h, H = hfun(xi)
            y = z - h                                          # innovation
            if wrap_yaw and y.size >= 3:
                y[2] = wrap_angle(float(y[2]))
            y = y - H @ (x_prior - xi)
            PHt = P @ H.T
            S = H @ PHt + R                                    # S = H P H^T + R
            S_inv = np.linalg.inv(S)
            K = PHt @ S_inv                                    # K = P H^T S^-1
            if it == 0:
                nis = float(y @ S_inv @ y)
                self.last_y, self.last_S = y, S
            x_new = x_prior + K @ y                            # x = x^- + K y
            done = float(np.max(np.abs(x_new - xi))) < 1e-3
            xi = x_new
            self.iterations_used = it + 1
            if done:
                break
        IKH = self._eye - K @ H
        self.kf.P = IKH @ P @ IKH.T + K @ R @ K.T              # Joseph form
        self.kf.x = xi[:, None]
        self._normalise()
        self.last_nis = nis if nis is not None else 0.0
        return nis

    def update_attitude(self, z, R, s: float = 0.0, prefilter=None) -> float | None:
        """Update with an (optionally prefiltered) attitude measurement made at filter
        time + s. z: (3,) roll, pitch, yaw (rad, yaw continuous); R: (3, 3)."""
        return self.update(z, R, lambda x: self.model(s, prefilter, x))

    def update_increment(self, dz, R, s_a: float, s_b: float) -> float | None:
        """Update with an attitude increment dz = rpy(t_b) - rpy(t_a) (rad) of the true
        attitude (visual motion), the interval given as offsets s_a < s_b from the filter
        time. R: (3, 3)."""
        def hfun(x):
            hb, Hb = self.model(s_b, None, x)
            ha, Ha = self.model(s_a, None, x)
            return hb - ha, Hb - Ha
        return self.update(dz, R, hfun, wrap_yaw=True)

    # ------------------------------------------------------------------ helpers
    def _normalise(self) -> None:
        """Keep amplitudes positive (A sin(phi) = -A sin(phi + pi)) and phases wrapped."""
        x = self.kf.x[:, 0]
        neg = I_A[x[I_A] < 0]
        for ia in neg:
            x[ia] = -x[ia]
            x[ia + 1] += np.pi
            self.kf.P[ia, :] *= -1.0
            self.kf.P[:, ia] *= -1.0
        if self.cfg.pitch_harmonic and x[I_B] < 0:
            x[I_B] = -x[I_B]
            x[I_D] += np.pi
            self.kf.P[I_B, :] *= -1.0
            self.kf.P[:, I_B] *= -1.0
        x[I_PH] = wrap_angle(x[I_PH])
        if self.cfg.pitch_harmonic:
            x[I_D] = wrap_angle(x[I_D])
