"""The walk model's settings and state layout: `GaitConfig`, the state indices, and the
linear dynamics (the continuous system matrix and its discretisation).

The state vector and the model are described in `asmonc_vision.core.gait.model`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.gait.rotations import wrap_angle

I_F = 0
I_TH = 1
I_O = np.array([2, 3, 4])
I_R = 5
I_YA = 6
#: the main harmonic of each axis (roll, pitch, yaw): the stride sway and the step
K_MAIN = (1, 2, 1)
_D2R = math.pi / 180.0
#: while turning, the yaw harmonics' process noise (variance) is scaled by this
TURN_SWAY_SCALE = 0.01


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
    model_error_deg: float = param(1.0, 'added to the inclinometer noise (in quadrature) '
                                   'for what the walk model does not describe (higher '
                                   'harmonics, sway, posture), degrees', range=(0.0, 30.0))
    adaptive_model_error: bool = param(True, 'raise the model error of an axis to the '
                                       'running mean (3 s) of its squared post-fit '
                                       'residual while walking')
    egomotion_sigma_deg: float = param(0.5, 'noise of each visual-motion rotation '
                                       'increment per axis, degrees (TransformStamped '
                                       'carries no covariance)', range=(0.01, 30.0))
    egomotion_model_error_deg: float = param(1.0, 'added to each visual-motion increment\'s '
                                             'noise (in quadrature) for what the walk '
                                             'model does not describe, degrees',
                                             range=(0.0, 30.0))
    max_amplitude_deg: float = param(10.0, 'largest plausible gait amplitude of an axis, '
                                     'deg (a walk-start fit beyond it starts that axis '
                                     'at zero)', range=(0.1, 90.0))
    min_frequency: float = param(1.0, 'lowest step frequency, Hz', range=(0.2, 5.0))
    max_frequency: float = param(2.8, 'highest step frequency, Hz', range=(0.3, 6.0))
    prior_frequency: float = param(1.8, 'walk start and lock checks prefer step '
                                   'frequencies near this (a Gaussian weight on the grid '
                                   'criterion), Hz', range=(0.2, 6.0))
    prior_frequency_sd: float = param(0.4, 'spread of that preference, Hz (0 = none)',
                                      range=(0.0, 10.0))
    pitch_harmonics: int = param(4, 'harmonics of the stride frequency in pitch, k = 1 .. '
                                 'this (k = 2 is the step; 1 the stride asymmetry, 4 the '
                                 'second harmonic of the step)', range=(2, 6))
    sway_harmonics: int = param(2, 'harmonics of the stride frequency in roll and yaw, '
                                'k = 1 .. this (k = 1 is the sway, 2 the step)',
                                range=(1, 6))
    freq_noise: float = param(0.08, 'step frequency random walk, Hz/sqrt(s)',
                              range=(0.0, 10.0))
    phase_noise: float = param(0.05, 'random walk of the shared stride phase (timing '
                               'jitter of all axes together), rad/sqrt(s)',
                               range=(0.0, 10.0))
    amplitude_noise_deg: float = param(0.8, 'random walk of the sine and cosine '
                                       'coefficients of each axis\'s main harmonic (roll, '
                                       'yaw: the stride; pitch: the step), deg/sqrt(s)',
                                       range=(0.0, 30.0))
    harmonic_noise_deg: float = param(0.1, 'random walk of the coefficients of the other '
                                      'harmonics, deg/sqrt(s)', range=(0.0, 30.0))
    roll_offset_noise_deg: float = param(0.3, 'roll offset random walk while walking, '
                                         'deg/sqrt(s)', range=(0.0, 30.0))
    pitch_offset_noise_deg: float = param(0.6, 'pitch offset random walk while walking '
                                          '(uphill, posture), deg/sqrt(s)',
                                          range=(0.0, 30.0))
    yaw_offset_noise_deg: float = param(0.3, 'yaw offset random walk, deg/sqrt(s)',
                                        range=(0.0, 30.0))
    yaw_rate_noise_deg: float = param(0.5, 'walking straight: yaw rate random walk, '
                                      'deg/s/sqrt(s)', range=(0.0, 500.0))
    turn_yaw_rate_noise_deg: float = param(10.0, 'turning: yaw rate random walk, '
                                           'deg/s/sqrt(s)', range=(0.0, 500.0))
    turn_yaw_accel_noise_deg: float = param(30.0, 'turning: yaw acceleration random walk '
                                            '(walking straight it is zero), '
                                            'deg/s^2/sqrt(s)', range=(0.0, 1000.0))
    turn_start_rate: float = param(0.02, 'interacting multiple models: rate of switching '
                                   'from walking straight to turning, 1/s',
                                   range=(0.0, 100.0))
    turn_end_rate: float = param(0.5, 'interacting multiple models: rate of switching from '
                                 'turning to walking straight, 1/s', range=(0.0, 100.0))
    standing_offset_noise_deg: float = param(10.0, 'roll/pitch/yaw random walk while not '
                                             'walking, deg/sqrt(s)', range=(0.0, 100.0))
    iterations: int = param(2, 'most Gauss-Newton iterations of the iterated EKF update',
                            range=(1, 20))
    relock_window: float = param(2.5, 'while walking, the walk model is refitted over '
                                 'this window (at least 1.5 s of it) every relock_period '
                                 's; a frequency off by more than relock_tolerance that '
                                 'explains the gait clearly better re-initialises the '
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
                                          'sinusoid (a bend has none); relock: least '
                                          'share of the gait explained', range=(0.0, 1.0))
    stop_window: float = param(0.6, 'window of the walk-stop test (gait and motion '
                               'amplitude), s', range=(0.2, 5.0))
    stop_amplitude_deg: float = param(0.3, 'walk stop: both amplitudes below this, deg '
                                      '(absolute floor of the test below)',
                                      range=(0.0, 20.0))
    stop_fraction: float = param(0.6, 'walk stop: the gait amplitude (the part moving like '
                                 'the model) over the stop window below this share of '
                                 'its running mean while walking (3 s), and the motion '
                                 'amplitude below 0.8 of its own', range=(0.0, 1.0))
    nis_window: float = param(0.5, 'window of the mean normalised innovation, s',
                              range=(0.1, 5.0))
    nis_threshold: float = param(12.0, 'non-walking movement: mean normalised innovation '
                                 'squared per measurement above this', range=(1.0, 1000.0))
    skill_weighting: bool = param(True, 'predict the minimum-MSE combination of the walk '
                                  'model and the last measurement held, by their errors '
                                  '(mean squares and mean product) over the last '
                                  'skill_memory s (measured against the model\'s attitude '
                                  'horizon s later), per axis')
    skill_memory: float = param(0.5, 'memory of the skill weighting, s', range=(0.1, 60.0))
    fallback: bool = param(True, 'publish the last measurement held instead of the '
                           "prediction on an axis where the prediction's own RMS error "
                           'over fallback_window s exceeds holding\'s by the factor '
                           '1 + fallback_margin (core/gait/fallback.py)')
    fallback_window: float = param(15.0, 'window of the fallback rule\'s errors, s',
                                   range=(3.0, 600.0))
    fallback_margin: float = param(0.1, 'the fallback rule holds when RMS(model) > (1 + '
                                   'margin) RMS(hold), and returns to the model when '
                                   'RMS(model) < RMS(hold)', range=(0.0, 2.0))
    jump_deg: float = param(25.0, 'an inclinometer roll or pitch change larger than this '
                            'between two samples, at jump_rate_deg or faster, is a fault '
                            '(core/gait/jump.py), deg', range=(1.0, 180.0))
    jump_rate_deg: float = param(400.0, 'the rate of change (deg/s) above which a jump of '
                                 'jump_deg is a fault', range=(10.0, 100000.0))
    jump_settle: float = param(1.0, 'after a jump the inclinometer must stay at its new '
                               'attitude this long before the walk model restarts from it '
                               '(a spike that comes back is dropped), s', range=(0.1, 60.0))
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
    def harmonics(self) -> tuple[int, int, int]:
        """Number of stride harmonics of roll, pitch, yaw."""
        return (self.sway_harmonics, self.pitch_harmonics, self.sway_harmonics)

    @property
    def dim_x(self) -> int:
        """Number of states: f, theta, three offsets, the yaw rate and acceleration, and
        two coefficients per harmonic."""
        return 7 + 2 * sum(self.harmonics)


class StateLayout:
    """Where each coefficient sits in the state vector.

    Args:
        harmonics: number of stride harmonics of roll, pitch, yaw.
    Attributes:
        n: number of states.
        k: (M,) harmonic number of every (alpha, beta) pair, axis by axis.
        axis: (M,) its axis (0 roll, 1 pitch, 2 yaw).
        alpha, beta: (M,) state indices of its coefficients.
        main: (3,) position (in 0..M-1) of each axis's main harmonic (``K_MAIN``).
        oscillation: indices of the states frozen when not walking.
    """

    def __init__(self, harmonics) -> None:
        self.harmonics = tuple(int(k) for k in harmonics)
        ks, axes = [], []
        for a, n in enumerate(self.harmonics):
            ks += list(range(1, n + 1))
            axes += [a] * n
        self.k = np.array(ks, float)
        self.axis = np.array(axes, int)
        m = self.k.size
        self.alpha = 7 + 2 * np.arange(m)
        self.beta = self.alpha + 1
        self.n = 7 + 2 * m
        self.main = np.array([int(np.flatnonzero((self.axis == a) & (self.k == min(
            K_MAIN[a], self.harmonics[a])))[0]) for a in range(3)])
        self.oscillation = np.r_[I_F, I_TH, self.alpha, self.beta]
        #: (3, M) 0/1: row a sums axis a's harmonics
        self.sum_matrix = (self.axis[None, :] == np.arange(3)[:, None]).astype(float)
        self.k_row = self.k[None, :]
        self.k_main = self.k[self.main]

    def of_axis(self, a: int) -> np.ndarray:
        """Positions (in 0..M-1) of axis a's harmonics, k ascending."""
        return np.flatnonzero(self.axis == a)

    def names(self) -> list[str]:
        """State names, e.g. 'f', 'theta', 'o_roll', 'r', 'alpha_pitch_2'."""
        ax = ('roll', 'pitch', 'yaw')
        out = ['f', 'theta', 'o_roll', 'o_pitch', 'o_yaw', 'yaw_rate', 'yaw_accel']
        for k, a in zip(self.k, self.axis):
            out += [f'alpha_{ax[a]}_{int(k)}', f'beta_{ax[a]}_{int(k)}']
        return out


def wrap_phase(d: np.ndarray) -> np.ndarray:
    """A state difference with its stride-phase entry wrapped to [-pi, pi)."""
    d = np.array(d, float)
    d[I_TH] = wrap_angle(float(d[I_TH]))
    return d


def continuous_system(layout: StateLayout, walking: bool) -> np.ndarray:
    """The continuous-time system matrix A (dx/dt = A x): the stride phase advances with
    pi f, the yaw offset with r, the yaw rate with the yaw acceleration. Not walking,
    the phase stands still (frozen)."""
    a = np.zeros((layout.n, layout.n))
    if walking:
        a[I_TH, I_F] = np.pi
        a[I_O[2], I_R] = 1.0
        a[I_R, I_YA] = 1.0
    return a


def discretise(a: np.ndarray, qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of dx = A x dt + dw, cov(dw) = diag(qc) dt, for nilpotent A (A^3 = 0).

    F(s) = exp(A s) = I + A s + A^2 s^2 / 2;  F = F(dt);
    Q = int_0^dt F(s) Qc F(s)^T ds = sum_ij M_i Qc M_j^T dt^(i+j+1) / (i+j+1) with
    M_0 = I, M_1 = A, M_2 = A^2 / 2.
    """
    n = a.shape[0]
    a2 = a @ a
    f = np.eye(n) + a * dt + a2 * (dt * dt / 2.0)
    qcm = np.diag(qc)
    m = (np.eye(n), a, 0.5 * a2)
    q = np.zeros((n, n))
    for i in range(3):
        mq = m[i] @ qcm
        for j in range(3):
            p = i + j + 1
            q += (mq @ m[j].T) * (dt ** p / p)
    return f, q
