"""The human walk model of Molton et al. (1998, Section 5) as an iterated extended
Kalman filter.

Each attitude axis of ``inclinometer_link`` (REP 103 roll, pitch, yaw in ``world``,
radians) is a periodic function of one shared gait phase on an offset:

    a(t) = o_a(t) + sum_k  alpha_ak sin(k theta(t)) + beta_ak cos(k theta(t)),
    theta' = pi f,        o_yaw' = r,   r' = a,

``theta`` the *stride* phase (one cycle per stride, two steps), ``f`` the step frequency
(Hz), k = 1 .. K_a the harmonics of the stride. The paper's model is the special case of
one harmonic per axis: pitch at the step frequency (k = 2), roll and yaw at half of it
(k = 1; Lee's gait-lab data). Real lower-back data also move at the stride frequency in
pitch (left/right asymmetry) and at the step in roll and yaw, so every axis carries
``sway_harmonics`` / ``pitch_harmonics`` harmonics. One phase for all axes keeps their
relative timing, so an axis with a clear signal times the others. The coefficients are
linear in the model, which leaves f and theta as the only nonlinear states.

The paper's "more flexible states" are random walks on every parameter (speed changes:
f and the coefficients; uphill walking: the pitch offset) plus the yaw rate ``r`` and
acceleration ``a`` (corner turning). A turn is a change of the dynamics, so two models run
as an interacting multiple model (IMM, Blom & Bar-Shalom): *straight* (r a slow random
walk, a = 0) and *turning* (r and a free, the yaw harmonics nearly frozen so that they do
not absorb the turn); each is the same iterated EKF with its own x and P, mixed before
every prediction, weighted by its measurement likelihood, and combined for the output.

State vector x (textbook symbols throughout: x, P, F, Q, H, R, z):

    index  0    1      2    3    4    5      6       7 ..
    state  f    theta  o_r  o_p  o_y  r      a       (alpha, beta) per harmonic: roll
                                                     k = 1..K_r, pitch 1..K_p, yaw 1..K_y
    unit   Hz   rad    rad  rad  rad  rad/s  rad/s2  rad

The dynamics are linear (the phase advances with f, the yaw offset with r, r with a),
so the prediction is the ordinary Kalman one (filterpy's ``KalmanFilter.predict``); the
measurements are nonlinear and use an iterated (Gauss-Newton) EKF update written here.
Because the model is a parametric function of time, a measurement made ``s`` seconds
before (s < 0) or after the filter time is predicted exactly by advancing the phase by
``pi f s`` -- which is how the visual-motion increments (over an interval in the past)
and the prediction horizon are handled.

Not walking (the change detector's verdict): the oscillation states (f, theta, the
coefficients) are frozen -- neither predicted nor updated -- and contribute nothing to
the attitude; the offsets (and the yaw rate) follow the measured attitude, which is then
the prediction.
"""
from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import KalmanFilter

from asmonc_vision.core.gait import kernels
from asmonc_vision.core.gait.kernels import _NO_ACCEL_VAR, _NO_TABLE
from asmonc_vision.core.gait.rotations import wrap_angle
from asmonc_vision.core.gait.state import (  # noqa: F401 - re-exported
    _D2R, I_F, I_O, I_R, I_TH, I_YA, K_MAIN, TURN_SWAY_SCALE, GaitConfig, StateLayout,
    continuous_system, discretise, wrap_phase)
from asmonc_vision.core.jit import warmed

#: the kernels the filter calls (set to None by `_warm_up` when one fails to compile)
_nb_combine = kernels._nb_combine
_nb_imm_predict = kernels._nb_imm_predict
_nb_imm_update = kernels._nb_imm_update
_nb_predict_attitude = kernels._nb_predict_attitude
_warm = False


class WalkModelEKF:
    """The walk model's iterated EKF (see the module doc for the state).

    Holds a filterpy ``KalmanFilter`` (x, P, F, Q) and the filter time ``t`` (s). The
    caller (``tracker.GaitTracker``) decides walking or not, supplies measurements with
    their time offsets, and initialises the oscillation when a walk starts.
    """

    def __init__(self, config: GaitConfig) -> None:
        self.cfg = config
        self.layout = lay = StateLayout(config.harmonics)
        n = lay.n
        self.n = n
        self.kf = KalmanFilter(dim_x=n, dim_z=3)
        self.t: float | None = None
        self.walking = False
        c = config
        q = np.zeros(n)
        q[I_F] = c.freq_noise ** 2
        q[I_TH] = c.phase_noise ** 2
        main = np.zeros(lay.k.size, bool)
        main[lay.main] = True
        qa = np.where(main, c.amplitude_noise_deg, c.harmonic_noise_deg) * _D2R
        q[lay.alpha] = q[lay.beta] = qa ** 2
        q[I_O] = (np.array([c.roll_offset_noise_deg, c.pitch_offset_noise_deg,
                            c.yaw_offset_noise_deg]) * _D2R) ** 2
        q[I_R] = (c.yaw_rate_noise_deg * _D2R) ** 2
        q[I_YA] = 0.0                       # walking straight: no yaw acceleration
        qs = np.zeros(n)
        qs[I_O] = (c.standing_offset_noise_deg * _D2R) ** 2
        qs[I_R] = q[I_R]
        qs[I_YA] = q[I_YA]
        q_turn, qs_turn = q.copy(), qs.copy()
        q_turn[I_R] = qs_turn[I_R] = (c.turn_yaw_rate_noise_deg * _D2R) ** 2
        q_turn[I_YA] = qs_turn[I_YA] = (c.turn_yaw_accel_noise_deg * _D2R) ** 2
        # while turning the yaw harmonics must not absorb the turn: they wander less
        yaw = np.r_[lay.alpha[lay.axis == 2], lay.beta[lay.axis == 2]]
        q_turn[yaw] *= TURN_SWAY_SCALE
        # continuous process noise by (walking, model): model 0 straight, 1 turning
        self._qc = {(True, 0): q, (False, 0): qs, (True, 1): q_turn, (False, 1): qs_turn}
        self._a = {w: continuous_system(lay, w) for w in (True, False)}
        #: the models' own estimates (x (2, n), P (2, n, n): rows straight, turning) and
        #: probabilities mu
        self._mx = np.zeros((2, n))
        self._mP = np.stack([np.eye(n), np.eye(n)])
        self.mu = np.array([1.0, 0.0])
        self._fq_cache: dict = {}
        self.last_nis: float = 0.0
        self.iterations_used = 0
        self._eye = np.eye(n)
        self._bounds = (0.9 * config.min_frequency, 1.1 * config.max_frequency)
        #: the coefficients of the state whose bytes are the key (``_harmonics``)
        self._coef_key: bytes | None = None
        self._coef_cache: dict = {}
        _warm_up(self)
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

    @property
    def turning(self) -> bool:
        """The turning model is the more probable one."""
        return bool(self.mu[1] > 0.5)

    def sync_models(self) -> None:
        """Copy the combined estimate into both models (after the caller changed x or P:
        a walk start, a stop, a reset). The straight model gets no yaw acceleration."""
        for j in range(2):
            self._mx[j] = self.x.copy()
            self._mP[j] = self.P.copy()
        self._no_accel(0)

    def coefficients(self, x: np.ndarray | None = None) -> np.ndarray:
        """(M,) complex coefficients alpha + i beta of every harmonic (a harmonic is
        Im[c exp(i k theta)] = alpha sin(k theta) + beta cos(k theta))."""
        x = self.x if x is None else x
        return x[self.layout.alpha] + 1j * x[self.layout.beta]

    def _harmonics(self, prefilter=None, lag: bool = False) -> np.ndarray:
        """``coefficients()`` of the current state, times the prefilter's response at
        k f / 2 if given (times 1 - that response if lag: what the prefilter and the
        sensor lag take away). Cached until the state changes (each sample asks for
        them several times); not to be modified."""
        x = self.x
        key = x.tobytes()
        if key != self._coef_key:
            self._coef_key = key
            self._coef_cache = {(None, False): self.coefficients(x)}
        ck = (prefilter, lag)
        c = self._coef_cache.get(ck)
        if c is None:
            c = self._coef_cache[(None, False)]
            if prefilter is not None:
                resp = prefilter.response(0.5 * self.layout.k * float(x[I_F]))
                c = c * (1.0 - resp) if lag else c * resp
            self._coef_cache[ck] = c
        return c

    def amplitude_phase(self, s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Amplitude (rad) and phase (rad) of each axis's main harmonic (roll, yaw: the
        stride; pitch: the step) at filter time + s: axis = A sin(phase) + the rest."""
        lay = self.layout
        c = self._harmonics()[lay.main]
        th = float(self.x[I_TH]) + (np.pi * float(self.x[I_F]) * s if self.walking else 0.0)
        return np.abs(c), wrap_angle(lay.k_main * th + np.arctan2(c.imag, c.real))

    def initialise(self, t: float, rpy, var) -> None:
        """Start (not walking) at time t from a (lag-free) attitude and its variances."""
        n = self.n
        x = np.zeros(n)
        x[I_F] = 0.5 * (self.cfg.min_frequency + self.cfg.max_frequency)
        x[I_O] = np.asarray(rpy, float)
        p = np.diag(np.full(n, 1e-6))
        p[I_O, I_O] = np.asarray(var, float)
        p[I_R, I_R] = (10.0 * _D2R) ** 2
        p[I_YA, I_YA] = (10.0 * _D2R) ** 2
        self.kf.x = x[:, None]
        self.kf.P = p
        self.t = float(t)
        self.walking = False
        self.mu = np.array([1.0, 0.0])
        self.sync_models()

    def start_walking(self, f: float, coefficients, offset, yaw_rate: float,
                      sigma: dict | None = None) -> None:
        """Switch the oscillation on with initial values (true-attitude domain, at the
        filter time, stride phase 0) and a fresh covariance for the oscillation states.

        Args:
            f: step frequency, Hz.
            coefficients: (M,) complex alpha + i beta per harmonic (``layout`` order).
            offset: (3,) rad.  yaw_rate: rad/s.
            sigma: initial standard deviations {'f' Hz, 'theta' rad, 'c' (main
                harmonics), 'c2' (the others), 'o' rad, 'r' rad/s}; c, c2 may be (M,)
                arrays.
        """
        lay = self.layout
        x = self.x.copy()
        x[I_F] = f
        x[I_TH] = 0.0
        c = np.asarray(coefficients, complex)
        x[lay.alpha], x[lay.beta] = c.real, c.imag
        x[I_O] = offset
        x[I_R] = yaw_rate
        x[I_YA] = 0.0
        s = {'f': 0.15, 'theta': 0.05, 'c': 0.5 * _D2R, 'c2': 0.5 * _D2R, 'o': 0.5 * _D2R,
             'r': 5.0 * _D2R, 'a': 10.0 * _D2R}
        if sigma:
            s.update(sigma)
        main = np.zeros(lay.k.size, bool)
        main[lay.main] = True
        sc = np.where(main, s['c'], s['c2'])
        d = np.zeros(self.n)
        d[I_F] = s['f'] ** 2
        d[I_TH] = s['theta'] ** 2
        d[lay.alpha] = d[lay.beta] = sc ** 2
        d[I_O] = s['o'] ** 2
        d[I_R] = s['r'] ** 2
        d[I_YA] = s['a'] ** 2
        self.kf.x = x[:, None]
        self.kf.P = np.diag(d)
        self.walking = True
        self._normalise()
        self.sync_models()

    def reset_yaw(self, coefficients, offset: float, rate: float, sigma_coefficient: float,
                  sigma_offset: float, sigma_rate: float, accel: float = 0.0,
                  sigma_accel: float = 20.0 * _D2R) -> None:
        """Re-initialise the yaw block (its harmonics, o_y, r) at the filter time, e.g.
        when a turn starts (the harmonics must not have absorbed the turn), dropping its
        correlations with the other states.

        Args:
            coefficients: (K_y,) complex yaw coefficients (relative to the stride phase).
        """
        lay = self.layout
        pos = lay.of_axis(2)
        idx = np.r_[lay.alpha[pos], lay.beta[pos], I_O[2], I_R, I_YA]
        x = self.kf.x[:, 0]
        c = np.asarray(coefficients, complex)
        x[lay.alpha[pos]], x[lay.beta[pos]] = c.real, c.imag
        x[I_O[2]], x[I_R], x[I_YA] = offset, rate, accel
        P = self.kf.P
        P[idx, :] = 0.0
        P[:, idx] = 0.0
        sc = sigma_coefficient if self.walking else 1e-3
        P[idx, idx] = np.r_[np.full(2 * pos.size, sc), sigma_offset, sigma_rate,
                            sigma_accel] ** 2
        self.sync_models()

    def oscillation_indices(self) -> np.ndarray:
        """Indices of the states frozen when not walking."""
        return self.layout.oscillation

    def stop_walking(self) -> None:
        """Freeze the oscillation: its states keep their last values, and their
        correlations with the offsets are dropped so that no later update moves them.
        The offsets take over the oscillation's current value (the attitude estimate
        does not jump)."""
        osc_now = self.oscillation(0.0)[0]
        for x in (self.kf.x[:, 0], self._mx[0], self._mx[1]):
            x[I_O] += osc_now
        self.walking = False
        osc = self.oscillation_indices()
        rest = np.setdiff1d(np.arange(self.n), osc)
        for P in (self.kf.P, self._mP[0], self._mP[1]):
            P[np.ix_(osc, rest)] = 0.0
            P[np.ix_(rest, osc)] = 0.0

    # ------------------------------------------------------------------ prediction
    def transition(self, dt: float, walking: bool | None = None, model: int | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """F and Q over dt seconds (dt >= 0) in the given (default: current) walking mode,
        of model 0 (straight), 1 (turning) or, by default, the more probable one."""
        w = self.walking if walking is None else walking
        m = int(self.turning) if model is None else int(model)
        key = (round(dt, 9), w, m)
        fq = self._fq_cache.get(key)
        if fq is None:
            fq = discretise(self._a[w], self._qc[(w, m)], dt)
            if len(self._fq_cache) > 256:
                self._fq_cache.clear()
            self._fq_cache[key] = fq
        return fq

    def predict_to(self, t: float) -> None:
        """Advance the filter to time t (s); nothing happens if t is not later.

        IMM interaction, then each model's Kalman prediction (filterpy), then the
        combination:
            Pi = [[1 - p01, p01], [p10, 1 - p10]], p01 = 1 - exp(-turn_start_rate dt), ...
            c_j = sum_i Pi_ij mu_i;  mu_i|j = Pi_ij mu_i / c_j
            x0_j = sum_i mu_i|j x_i;  P0_j = sum_i mu_i|j (P_i + (x_i - x0_j)(x_i - x0_j)^T)
            x_j = F x0_j;  P_j = F P0_j F^T + Q_j;  mu_j = c_j
        """
        if self.t is None or t <= self.t:
            return
        dt = t - self.t
        p01 = 1.0 - math.exp(-self.cfg.turn_start_rate * dt)
        p10 = 1.0 - math.exp(-self.cfg.turn_end_rate * dt)
        if _nb_imm_predict is not None:
            F0, Q0 = self.transition(dt, model=0)
            F1, Q1 = self.transition(dt, model=1)
            self._mx, self._mP, self.mu, x, P = _nb_imm_predict(
                self._mx, self._mP, self.mu, p01, p10, F0, Q0, F1, Q1, *self._bounds)
            self.kf.x, self.kf.P = x[:, None], P
            self.kf.F, self.kf.Q = F1, Q1
            self.t = float(t)
            return
        Pi = np.array([[1.0 - p01, p01], [p10, 1.0 - p10]])
        c = Pi.T @ self.mu                                   # c_j = sum_i Pi_ij mu_i
        c = np.maximum(c, 1e-12)
        mix = Pi * self.mu[:, None] / c[None, :]             # mu_i|j
        xs, Ps = self._mx, self._mP
        new_x, new_P = np.empty_like(xs), np.empty_like(Ps)
        for j in range(2):
            x0, P0 = self._mix(xs, Ps, mix[:, j])
            F, Q = self.transition(dt, model=j)
            self.kf.x, self.kf.P = x0[:, None], P0
            self.kf.F, self.kf.Q = F, Q
            self.kf.predict()          # x = F x;  P = F P F^T + Q
            new_x[j] = self.kf.x[:, 0]
            new_P[j] = self.kf.P
        self._mx, self._mP = new_x, new_P
        self.mu = c / c.sum()
        self._no_accel(0)
        self.t = float(t)
        self._combine()

    def _mix(self, xs, Ps, w) -> tuple[np.ndarray, np.ndarray]:
        """The mixture of the two models' estimates with weights w (summing to 1):
        sum_i w_i x_i and sum_i w_i (P_i + e_i e_i^T), e_i = x_i - mean (the stride-phase
        difference wrapped)."""
        ref = xs[0]
        d1 = xs[1] - ref
        d1[I_TH] = wrap_angle(float(d1[I_TH]))
        w0, w1 = float(w[0]), float(w[1])
        xm = ref + w1 * d1
        # sum_i w_i (P_i + e_i e_i^T) with e_0 = -w1 d1, e_1 = w0 d1
        P = w0 * Ps[0] + w1 * Ps[1] + (w0 * w1) * np.outer(d1, d1)
        return xm, P

    def _no_accel(self, j: int) -> None:
        """Model j has no yaw acceleration: a = 0, uncorrelated, variance (1 deg/s^2)^2."""
        self._mx[j][I_YA] = 0.0
        P = self._mP[j]
        P[I_YA, :] = 0.0
        P[:, I_YA] = 0.0
        P[I_YA, I_YA] = _NO_ACCEL_VAR

    def _combine(self) -> None:
        """The output: the probability-weighted mixture of the models."""
        x, P = self._mix(self._mx, self._mP, self.mu)
        self.kf.x = x[:, None]
        self.kf.P = P
        self._normalise()

    # ------------------------------------------------------------------ the model
    def model(self, s: float, prefilter=None, x: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        """Attitude (roll, pitch, yaw) at filter time + s and its Jacobian dh/dx (3, n).

        True attitude (prefilter None), per axis a, with u = k (theta + pi f s):

            h_a = o_a [+ r s for yaw] + sum_k alpha_ak sin(u) + beta_ak cos(u)

        Measured (through ``prefilter``, whose response H(f) includes the sensor lag),
        each harmonic (at k f / 2 Hz) scaled by |H| and advanced by arg H:

            h_a = o_a [+ r (s - tau_dc) for yaw]
                  + sum_k |H| (alpha_ak sin(u + arg H) + beta_ak cos(u + arg H))

        Args:
            s: time offset from the filter time, s (negative: the past).
            prefilter: a ``prefilter.Prefilter``: model the *measured* (prefiltered,
                sensor-lagged) attitude instead of the true one.
            x: state to evaluate (default the current estimate).
        Returns:
            (h (3,), H (3, n)).
        """
        x = self.x if x is None else x
        lay = self.layout
        H = np.zeros((3, self.n))
        H[0, I_O[0]] = H[1, I_O[1]] = H[2, I_O[2]] = 1.0
        r, ya = float(x[I_R]), float(x[I_YA])
        sy = s - prefilter.dc_delay if prefilter is not None else s
        h = np.array([x[I_O[0]], x[I_O[1]], x[I_O[2]] + r * sy + 0.5 * ya * sy * sy], float)
        H[2, I_R] = sy
        H[2, I_YA] = 0.5 * sy * sy
        if not self.walking:
            return h, H
        f = float(x[I_F])
        k = lay.k
        if prefilter is not None:
            g, psi, dg, dpsi = prefilter.gain_phase_array(0.5 * k * f)
        else:
            g, psi, dg, dpsi = 1.0, 0.0, 0.0, 0.0
        u = k * (float(x[I_TH]) + math.pi * f * s) + psi
        su, cu = np.sin(u), np.cos(u)
        al, be = x[lay.alpha], x[lay.beta]
        val = al * su + be * cu                      # the harmonic before the gain
        der = al * cu - be * su                      # its derivative by u
        ax = lay.axis
        A = lay.sum_matrix                           # (3, M): sums each axis's harmonics
        h += A @ (g * val)
        H[ax, lay.alpha] = g * su                    # dh/dalpha
        H[ax, lay.beta] = g * cu                     # dh/dbeta
        H[:, I_TH] = A @ (g * k * der)               # dh/dtheta
        # dh/df: the gain and phase of H at k f / 2, and the phase advance k pi s
        H[:, I_F] = A @ (0.5 * k * dg * val + g * der * k * (math.pi * s + 0.5 * dpsi))
        return h, H

    def attitude(self, s: float, prefilter=None) -> np.ndarray:
        """``model(s, prefilter)``'s attitude without the Jacobian (cheaper), (3,) rad."""
        x = self.x
        sy = s - prefilter.dc_delay if prefilter is not None else s
        o_r, o_p, o_y, r, ya = x[2:7].tolist()
        h = np.array([o_r, o_p, o_y + r * sy + 0.5 * ya * sy * sy])
        if self.walking:
            h += self.oscillation(s, prefilter)[0]
        return h

    def lag_correction(self, s: float, prefilter) -> np.ndarray:
        """``attitude(s) - attitude(s, prefilter)``: what the prefilter and the sensor lag
        do to the walk model's attitude at filter time + s, (3,) rad."""
        x = self.x
        ya = float(x[I_YA])
        dc = prefilter.dc_delay
        out = np.array([0.0, 0.0, float(x[I_R]) * dc + 0.5 * ya * (2.0 * s * dc - dc * dc)])
        if self.walking:
            lay = self.layout
            f = float(x[I_F])
            c = self._harmonics(prefilter, lag=True)
            u = lay.k * (float(x[I_TH]) + math.pi * f * s)
            out += lay.sum_matrix @ np.imag(c * np.exp(1j * u))
        return out

    def oscillation(self, s, prefilter=None) -> np.ndarray:
        """The oscillation part of the model (no offsets, no yaw ramp) at filter time + s
        for an array of offsets s (N,): (N, 3) rad, measured through ``prefilter`` if
        given. Zero when not walking."""
        s = np.array([s]) if isinstance(s, float) else np.atleast_1d(np.asarray(s, float))
        if not self.walking:
            return np.zeros((s.size, 3))
        lay = self.layout
        x = self.x
        f = float(x[I_F])
        c = self._harmonics(prefilter)
        u = lay.k_row * (float(x[I_TH]) + math.pi * f * s[:, None])
        val = np.imag(c * np.exp(1j * u))                          # (N, M)
        return val @ lay.sum_matrix.T

    def oscillation_amplitude(self, prefilter=None) -> np.ndarray:
        """(3,) amplitude of each axis's oscillation, rad: sqrt(sum_k |c_k|^2) (the
        sinusoid-equivalent sqrt(2) rms over a stride), measured through ``prefilter``
        if given; zero when not walking."""
        if not self.walking:
            return np.zeros(3)
        c = self._harmonics(prefilter)
        return np.sqrt(self.layout.sum_matrix @ np.square(np.abs(c)))

    def predict_attitude(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """True attitude at filter time + s (s >= 0) and its (3, 3) covariance.

        The covariance includes the process noise over s:
        Cov = H (F(s) P F(s)^T + Q(s)) H^T with H at the filter time evaluated for x(s),
        Q the models' probability-weighted process noise.
        """
        F, Q0 = self.transition(max(s, 0.0), model=0)
        Q1 = self.transition(max(s, 0.0), model=1)[1]
        if _nb_predict_attitude is not None:
            lay = self.layout
            return _nb_predict_attitude(F, Q0, Q1, float(self.mu[0]), float(self.mu[1]),
                                        np.ascontiguousarray(self.x),
                                        np.ascontiguousarray(self.P), self.walking, lay.k,
                                        lay.sum_matrix, lay.axis, lay.alpha, lay.beta)
        Q = self.mu[0] * Q0 + self.mu[1] * Q1
        xs = F @ self.x
        Ps = F @ self.P @ F.T + Q
        h, H = self.model(0.0, x=xs)
        return h, H @ Ps @ H.T

    def predict_models(self, s: float) -> np.ndarray:
        """Each IMM model's own prediction of the true attitude at filter time + s
        (s >= 0), (2, 3) rad, rows straight and turning: h(F_j(s) x_j) (the output of
        ``predict_attitude`` is that of their mixture).

        x_j(s) = F_j(s) x_j;  h_a = o_a + sum_k Im[(alpha_ak + i beta_ak) exp(i k theta)]
        (the yaw ramp is in F: o_y(s) = o_y + r s + a s^2 / 2)."""
        s = max(s, 0.0)
        xs = np.array([self.transition(s, model=0)[0] @ self._mx[0],
                       self.transition(s, model=1)[0] @ self._mx[1]])     # (2, n)
        out = xs[:, 2:5].copy()                                         # I_O
        if self.walking:
            lay = self.layout
            c = xs[:, lay.alpha] + 1j * xs[:, lay.beta]                # (2, M)
            u = lay.k_row * xs[:, I_TH:I_TH + 1]
            out += np.imag(c * np.exp(1j * u)) @ lay.sum_matrix.T
        return out

    # ------------------------------------------------------------------ updates
    def update(self, z, R, hfun, wrap_yaw: bool = True) -> float | None:
        """Iterated EKF update of each model with measurement z (m,), noise R (m, m), and
        the models' probabilities from their likelihoods.

        ``hfun(x) -> (h (m,), H (m, n))``. Each model iterates (Gauss-Newton)

            x_{i+1} = x^- + K_i (z - h(x_i) - H_i (x^- - x_i)),
            K_i = P^- H_i^T (H_i P^- H_i^T + R)^-1,

        until the step is tiny or ``iterations`` are done, then (Joseph form)
        P = (I - K H) P^- (I - K H)^T + K R K^T; its likelihood is N(y; 0, S) of the
        first iterate, mu_j ∝ mu_j N(y_j; 0, S_j) (a model with mu_j < 0.1 is updated with
        one step). ``z = None``: a missed measurement, nothing changes. Angle residuals of
        the third row are wrapped (yaw) if asked.

        Returns:
            The normalised innovation squared y^T S^-1 y (first iterate, more probable
            model), or None.
        """
        if z is None:
            return None
        z = np.asarray(z, float)
        like = np.zeros(2)
        best = int(np.argmax(self.mu))
        nis_best = 0.0
        for j in range(2):
            # an improbable model gets one Gauss-Newton step (a plain EKF update)
            its = self.cfg.iterations if self.mu[j] >= 0.1 else 1
            x, P, y, S, S_inv = self._update_one(self._mx[j], self._mP[j], z, R, hfun,
                                                 wrap_yaw, its)
            self._mx[j], self._mP[j] = x, P
            nis = float(y @ S_inv @ y)
            # log N(y; 0, S) up to the common constant
            like[j] = -0.5 * nis - 0.5 * math.log(max(np.linalg.det(S), 1e-300))
            if j == best:
                nis_best = nis
                self.last_y, self.last_S = y, S
        self._probabilities(like)
        self._no_accel(0)
        self._combine()
        self.last_nis = nis_best
        return nis_best

    def _probabilities(self, like: np.ndarray) -> None:
        """The models' probabilities after an update with log-likelihoods like (2,):
        mu_j ∝ mu_j N(y_j; 0, S_j), at least 1e-6 each."""
        # (numpy's log and exp; the rest as floats, the same arithmetic)
        lm0, lm1 = np.log(np.maximum(self.mu, 1e-300)).tolist()
        w0, w1 = lm0 + float(like[0]), lm1 + float(like[1])   # w = log mu + like
        wm = w0 if w0 >= w1 else w1
        w0, w1 = np.exp(np.array([w0 - wm, w1 - wm])).tolist()  # w = exp(w - max w)
        tot = w0 + w1
        m0, m1 = max(w0 / tot, 1e-6), max(w1 / tot, 1e-6)
        tot = m0 + m1
        self.mu = np.array([m0 / tot, m1 / tot])

    def _update_one(self, x_prior, P, z, R, hfun, wrap_yaw, iterations: int):
        """The iterated update of one model: (x, P, y, S, S^-1) (first-iterate y, S)."""
        xi = x_prior
        y0 = S0 = S0_inv = None
        K = H = None
        for it in range(iterations):
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
                y0, S0, S0_inv = y, S, S_inv
            x_new = x_prior + K @ y                            # x = x^- + K y
            done = float(np.max(np.abs(x_new - xi))) < 1e-3
            xi = x_new
            self.iterations_used = it + 1
            if done:
                break
        # iterations >= 1 (its settings range), so the loop has set K and H
        IKH = self._eye - K @ H  # type: ignore[operator]
        P_new = IKH @ P @ IKH.T + K @ R @ K.T  # type: ignore[union-attr]                 # Joseph form
        xi = xi.copy()
        xi[I_TH] = wrap_angle(float(xi[I_TH]))
        lo, hi = self.frequency_bounds
        xi[I_F] = min(max(float(xi[I_F]), lo), hi)
        return xi, P_new, y0, S0, S0_inv

    def update_attitude(self, z, R, s: float = 0.0, prefilter=None) -> float | None:
        """Update with an (optionally prefiltered) attitude measurement made at filter
        time + s. z: (3,) roll, pitch, yaw (rad, yaw continuous); R: (3, 3)."""
        if z is None or _nb_imm_update is None:
            return self.update(z, R, lambda x: self.model(s, prefilter, x))
        if prefilter is None:
            table, df, sy = _NO_TABLE, 1.0, s
        else:
            table, df, sy = prefilter._table, prefilter._df, s - prefilter.dc_delay
        lay = self.layout
        like, y, S, nis, its = _nb_imm_update(
            self._mx, self._mP, self.mu, np.asarray(z, float), np.ascontiguousarray(R, float),
            float(s), float(sy), bool(self.walking), table, df, lay.k, lay.sum_matrix,
            lay.axis, lay.alpha, lay.beta, int(self.cfg.iterations), *self._bounds)
        self._probabilities(like)
        # _no_accel(0), then _combine (the mixture) and _normalise
        x, P = _nb_combine(self._mx, self._mP, self.mu, *self._bounds)
        self.kf.x, self.kf.P = x[:, None], P
        self.last_y, self.last_S, self.last_nis = y, S, nis
        self.iterations_used = its
        return nis

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
        """Keep the stride phase wrapped (every harmonic is 2 pi periodic in it) and the
        step frequency within [0.9 min_frequency, 1.1 max_frequency] (the change
        detector treats a frequency at that bound as a lost lock)."""
        x = self.kf.x
        x[I_TH, 0] = wrap_angle(float(x[I_TH, 0]))
        lo, hi = self.frequency_bounds
        x[I_F, 0] = min(max(float(x[I_F, 0]), lo), hi)

    @property
    def frequency_bounds(self) -> tuple[float, float]:
        """The step frequency is kept within these, Hz."""
        return self._bounds


def _warm_up(ekf: WalkModelEKF) -> None:
    """Compile the filter-step kernels (or load them from numba's disk cache) on ekf's
    own state, once per process, before the first sample; a kernel that fails is
    dropped (its numpy path runs)."""
    global _warm, _nb_imm_predict, _nb_imm_update, _nb_combine, _nb_predict_attitude
    if _warm:
        return
    _warm = True
    lay = ekf.layout
    xs, Ps, mu = ekf._mx.copy(), ekf._mP.copy(), np.array([0.5, 0.5])
    F, Q = ekf.transition(0.0625, walking=True, model=0)
    z, R = np.zeros(3), np.eye(3)
    _nb_imm_predict = warmed(_nb_imm_predict, xs, Ps, mu, 0.01, 0.01, F, Q, F, Q, 1.0, 2.0)
    for table in (np.ones((8, 4)), _NO_TABLE):
        _nb_imm_update = warmed(_nb_imm_update, xs, Ps, mu, z, R, 0.0, 0.0, True, table, 0.5,
                                lay.k, lay.sum_matrix, lay.axis, lay.alpha, lay.beta, 2, 1.0,
                                2.0)
    _nb_combine = warmed(_nb_combine, xs, Ps, mu, 1.0, 2.0)
    _nb_predict_attitude = warmed(_nb_predict_attitude, F, Q, Q, 0.5, 0.5, xs[0], Ps[0], True,
                                  lay.k, lay.sum_matrix, lay.axis, lay.alpha, lay.beta)
    if _nb_combine is None:
        _nb_imm_update = None
