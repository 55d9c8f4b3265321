"""Evaluate the walk model (Molton et al. 1998, Section 5) on simulated and real walking.

    asmonc gait sim    [--scenarios walk stop turn uphill bend] [--seeds N] [--json F]
    asmonc gait fusion [--seeds N] [--egomotion-sigma DEG] [--json F]
    asmonc gait real   [--data DIR] [--json F]
    asmonc gait bags   [BAG ...] [--cache DIR] [--json F]
    asmonc gait figs   [--out DIR] [--data DIR]

sim: the simulator's walker (``sim.motion.Trajectory``) and 16 Hz inclinometer
(``sim.inclinometer``, 0.3 deg noise, 0.1 deg steps, 80 ms lag), in memory, several
seeds per scenario: *walk* (stand, walk, stand), *stop* (two walks with stops), *turn*
(walking through a 90 deg and a 60 deg turn with speed changes), *uphill* (walking onto
a 6 deg slope: the trunk leans forward), *bend* (standing, bending 25 deg forward and
back: a non-walking movement that must not start the walk model). Reported: RMS error
of the 0.5 s-ahead prediction per axis against the true attitude (all samples after the
first second, and steady walking), with "hold the last measurement" on the same samples;
gait-phase RMS error in % of the cycle (pitch: the step; roll, yaw: the stride); delay
of the detected walk starts and stops after the true ones (walking = speed >= 0.6 m/s,
half the nominal speed); the time per filter step.

fusion: the same walks with visual motion (/egomotion: the left camera's rotation from
frame to frame at 10 Hz with Gaussian noise) fused into the filter; the 0.5 s-ahead
prediction of the absolute attitude and of the rig's rotation over the horizon (what
DGPR needs), for the inclinometer alone, visual motion alone and both, and with either
source dropped for 4 s.

real: the Mobilise-D lower-back IMU recordings (../shared/data/gait_lowback): attitude
at 100 Hz by a complementary filter (3 s), decimated to 16 Hz as a compass would give it,
the walk model run on it; the 0.5 s-ahead prediction against "hold the last value" on
the straight walks (Test5) within the reference walking bouts, the daily-living walk
(Test11) likewise, with two references (an oracle-aided benchmark, not a bound: a
Fourier-combiner Kalman filter given each bout's own stride frequency and start; and the
upper bound of the model family, a non-causal fit of each bout); walk starts/stops against the
reference bouts (INDIP MicroWB: precision and recall within 0.5 s and 1 s); the tracked step
frequency against the reference cadence.

figs: the paper's Figs. 13-15 redrawn from these runs (docs/gait_fig13.png, ...).
"""
from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmonc_vision.core.evaluation import json_ready
from asmonc_vision.core.gait import GaitConfig, GaitTracker
from asmonc_vision.core.gait import scoring
from asmonc_vision.core.gait.rotations import (R_BODY_OPTICAL, rotvec_to_matrix,
                                               rpy_to_matrix)

HORIZON = 0.5
#: truth "walking": speed at least this (half the simulator's nominal 1.2 m/s)
WALK_SPEED = 0.6
#: "steady walking": walking (truth) for at least this long before and through the horizon
STEADY_AFTER = 2.0
SIM_SCENARIOS = ('walk', 'stop', 'turn', 'uphill', 'bend')
DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / 'shared' / 'data' / 'gait_lowback'
REPO = Path(__file__).resolve().parents[2]


# ======================================================================= simulation

class _Blend:
    """A trajectory whose attitude blends from `a` to `b` by a smoothstep over
    [t0, t0 + ramp] (same walker in both: only the slope lean differs)."""

    def __init__(self, a, b, t0: float, ramp: float) -> None:
        self.a, self.b, self.t0, self.ramp = a, b, t0, ramp
        self.duration = a.duration
        self.step_freq, self.phase = a.step_freq, a.phase

    def _w(self, t):
        x = np.clip((np.asarray(t, float) - self.t0) / self.ramp, 0.0, 1.0)
        return x * x * (3 - 2 * x)

    def states(self, t):
        pa, ra = self.a.states(t)
        _, rb = self.b.states(t)
        w = self._w(np.atleast_1d(t))[:, None]
        return pa, ra + w * (rb - ra)

    def speed(self, t):
        return self.a.speed(t)

    def gait_phase(self, t):
        return self.a.gait_phase(t)


class _Bend:
    """A trajectory plus a forward bend: pitch + depth * (1 - cos) / 2 over [t0, t0 + T]."""

    def __init__(self, traj, t0: float, period: float, depth_deg: float) -> None:
        self.traj, self.t0, self.period, self.depth = traj, t0, period, math.radians(depth_deg)
        self.duration = traj.duration
        self.step_freq, self.phase = traj.step_freq, traj.phase

    def states(self, t):
        p, r = self.traj.states(t)
        u = np.clip((np.atleast_1d(np.asarray(t, float)) - self.t0) / self.period, 0.0, 1.0)
        r = r.copy()
        r[:, 1] += self.depth * 0.5 * (1.0 - np.cos(2.0 * np.pi * u))
        return p, r

    def speed(self, t):
        return self.traj.speed(t)

    def gait_phase(self, t):
        return self.traj.gait_phase(t)


class _Walker:
    """``sim.motion.Trajectory`` with its gait phase exposed (for the phase truth)."""

    def __init__(self, traj) -> None:
        self.traj = traj
        self.duration = traj.duration
        self.step_freq, self.phase = traj.step_freq, traj.phase

    def states(self, t):
        return self.traj.states(t)

    def speed(self, t):
        return self.traj.speed(t)

    def gait_phase(self, t):
        """The walker's step phase (rad): the argument of the step-frequency sinusoids
        before each channel's own phase is added."""
        return np.interp(np.asarray(t, float), self.traj._t, self.traj._gait_phase)


@dataclass(frozen=True)
class SimCase:
    """One simulated walk: the walker (``states``, ``speed``, ``gait_phase``) and its
    inclinometer stream."""

    name: str
    seed: int
    walker: object
    duration: float
    imu_times: np.ndarray
    imu_rpy: np.ndarray
    imu_variance: float


def make_case(name: str, seed: int) -> SimCase:
    """Build simulated scenario `name` for `seed` (walker, speeds, turns and noise from
    the seed)."""
    from asmonc_vision.sim.inclinometer import InclinometerSettings, simulate_inclinometer
    from asmonc_vision.sim.motion import Leg, Trajectory
    from asmonc_vision.sim.rig import RigSettings

    rig = RigSettings()
    salt = SIM_SCENARIOS.index(name) if name in SIM_SCENARIOS else 99
    rng = np.random.default_rng([seed, 0x6A17, salt])
    walker_rng = np.random.default_rng([seed, 0x6A17, salt, 1])
    v = float(rng.uniform(1.05, 1.35))
    if name == 'walk':
        legs = [Leg(3.0, 0.0), Leg(22.0, v, ramp=1.0), Leg(4.0, 0.0, ramp=1.0)]
        walker = _Walker(Trajectory(legs, rig, None, rng=walker_rng))
    elif name == 'stop':
        v2 = float(rng.uniform(0.9, 1.3))
        legs = [Leg(2.5, 0.0), Leg(9.0, v, ramp=1.0), Leg(4.0, 0.0, ramp=1.0),
                Leg(9.0, v2, ramp=1.0), Leg(4.0, 0.0, ramp=1.0)]
        walker = _Walker(Trajectory(legs, rig, None, rng=walker_rng))
    elif name == 'turn':
        sgn = float(rng.choice([-1.0, 1.0]))
        legs = [Leg(6.0, v), Leg(4.0, v * 0.85, turn_deg=90.0 * sgn, ramp=1.5),
                Leg(5.0, v * 1.15, ramp=2.0), Leg(3.0, v, turn_deg=-60.0 * sgn, ramp=1.0),
                Leg(7.0, v * 0.9, ramp=2.0)]
        walker = _Walker(Trajectory(legs, rig, None, start_speed=v, rng=walker_rng))
    elif name == 'uphill':
        from asmonc_vision.sim.world import Ground, World

        legs = [Leg(25.0, v)]
        flat = Trajectory(legs, rig, None, start_speed=v, rng=np.random.default_rng(
            [seed, 0x6A17, salt, 1]))
        hill = Trajectory(legs, rig, World(Ground(slope_deg=6.0)), start_speed=v,
                          rng=np.random.default_rng([seed, 0x6A17, salt, 1]))
        walker = _Blend(_Walker(flat), _Walker(hill), t0=8.0, ramp=2.5)
    elif name == 'bend':
        legs = [Leg(14.0, 0.0)]
        walker = _Bend(_Walker(Trajectory(legs, rig, None, rng=walker_rng)), t0=5.0,
                       period=3.0, depth_deg=25.0)
    else:
        raise ValueError(f"unknown scenario '{name}' (one of {', '.join(SIM_SCENARIOS)})")
    duration = float(sum(leg.duration for leg in legs))
    imu = simulate_inclinometer(walker, duration, InclinometerSettings(),
                                rng=np.random.default_rng([seed, 0x6A17, salt, 2]))
    return SimCase(name, seed, walker, duration, imu.times, imu.rpy, imu.variance)


def simulate_egomotion(walker, duration: float, sigma_deg: float, rate: float = 10.0,
                       rng=0) -> list[tuple[float, float, np.ndarray]]:
    """Visual motion like /egomotion: (t_prev, t_cur, R) per camera frame, R the left
    camera's rotation from the previous frame to the current one (optical axes), with
    Gaussian rotation-vector noise of sigma_deg per axis."""
    rng = np.random.default_rng(rng)
    t = rng.uniform(0, 1.0 / rate) + np.arange(int(duration * rate)) / rate
    t = t[t < duration]
    _, rpy = walker.states(t)
    r_wc = rpy_to_matrix(rpy) @ R_BODY_OPTICAL                  # optical -> world
    out = []
    for k in range(1, t.size):
        r = r_wc[k - 1].T @ r_wc[k]
        noise = rng.normal(0.0, math.radians(sigma_deg), 3)
        out.append((float(t[k - 1]), float(t[k]), r @ rotvec_to_matrix(noise)))
    return out


@dataclass
class TrackerRun:
    """A tracker's outputs at every inclinometer sample."""

    times: np.ndarray            # (N,) s
    walking: np.ndarray          # (N,) bool
    attitude: np.ndarray         # (N, 3) rad
    predicted: np.ndarray        # (N, 3) rad, for times + horizon
    predicted_std: np.ndarray    # (N, 3) rad
    phase: np.ndarray            # (N, 3) rad
    frequency: np.ndarray        # (N,) Hz
    motion: np.ndarray           # (N, 3, 3)
    step_cpu: np.ndarray         # (N,) s of thread CPU time per inclinometer step
    events: list
    egomotion_used: int = 0


def run_tracker(times, rpy, variance, config: GaitConfig | None = None,
                egomotion=None, use_inclinometer: bool = True,
                drop_inclinometer: tuple[float, float] | None = None,
                drop_egomotion: tuple[float, float] | None = None) -> TrackerRun:
    """Run a GaitTracker over an inclinometer stream (and visual motion), in time order.

    Args:
        times, rpy: (N,), (N, 3) inclinometer stamps (s) and angles (rad).
        variance: per-angle variance (rad^2), scalar or (N, 3).
        egomotion: None or [(t_prev, t_cur, R_optical)], applied at t_cur.
        use_inclinometer: False = the inclinometer only detects walking and gives the
            start attitude; the walk model is driven by visual motion alone.
        drop_inclinometer, drop_egomotion: (t0, t1): that source is silent in between.
    """
    cfg = config if config is not None else GaitConfig()
    tr = GaitTracker(cfg, use_inclinometer_updates=use_inclinometer)
    var = np.broadcast_to(np.asarray(variance, float), (len(times), 3)) \
        if np.ndim(variance) else np.full((len(times), 3), float(variance))
    ego = list(egomotion or [])
    j = 0
    rows = []
    last = None
    for i, t in enumerate(times):
        while j < len(ego) and ego[j][1] <= t:
            tp, tc, r = ego[j]
            j += 1
            if drop_egomotion and drop_egomotion[0] <= tc <= drop_egomotion[1]:
                continue
            tr.add_egomotion(tp, tc, r)
        if drop_inclinometer and drop_inclinometer[0] <= t <= drop_inclinometer[1] \
                and last is not None:
            rows.append((t, tr.estimate(t), 0.0))          # silent: the model's estimate
            continue
        c0 = time.thread_time()
        est = tr.add_inclinometer(t, rpy[i], var[i])
        c1 = time.thread_time()
        last = est
        rows.append((t, est, c1 - c0))
    return TrackerRun(
        times=np.array([r[0] for r in rows]),
        walking=np.array([r[1].walking for r in rows]),
        attitude=np.array([r[1].attitude for r in rows]),
        predicted=np.array([r[1].predicted for r in rows]),
        predicted_std=np.array([np.sqrt(np.diag(r[1].predicted_covariance)) for r in rows]),
        phase=np.array([r[1].phase for r in rows]),
        frequency=np.array([r[1].step_frequency for r in rows]),
        motion=np.array([r[1].motion for r in rows]),
        step_cpu=np.array([r[2] for r in rows]), events=list(tr.stats.events),
        egomotion_used=tr.stats.egomotion)


def motion_increments(run: TrackerRun) -> np.ndarray:
    """(N, 3) the published predicted rig rotation over the horizon (``motion``) as
    attitude increments: rpy(R(attitude) motion) - attitude, rad (yaw wrapped)."""
    from asmonc_vision.core.gait.rotations import matrix_to_rpy, wrap_angle

    d = matrix_to_rpy(rpy_to_matrix(run.attitude) @ run.motion) - run.attitude
    d[:, 0] = wrap_angle(d[:, 0])
    d[:, 2] = wrap_angle(d[:, 2])
    return d


def _truth_walking(walker, t) -> np.ndarray:
    return walker.speed(np.asarray(t, float)) >= WALK_SPEED


def score_sim(case: SimCase, run: TrackerRun, horizon: float = HORIZON) -> dict:
    """Errors of one run against the simulator's truth (see the module doc)."""
    t = run.times
    w = case.walker
    _, truth_h = w.states(t + horizon)
    _, truth_now = w.states(t)
    pred_err = scoring.angle_errors_deg(run.predicted, truth_h)
    hold = case.imu_rpy[np.searchsorted(case.imu_times, t)]
    hold_err = scoring.angle_errors_deg(hold, truth_h)
    tw = _truth_walking(w, t)
    inside = (t >= 1.0) & (t + horizon <= case.duration)
    steady = (tw & _truth_walking(w, t - STEADY_AFTER) & _truth_walking(w, t + horizon)
              & _held(t, run.walking, STEADY_AFTER) & inside)
    valid = inside
    # phases: pitch at the step, roll and yaw at the stride
    gp = w.gait_phase(t)
    ph = w.phase
    true_phase = np.column_stack([gp / 2 + ph['roll'], gp + ph['pitch'], gp / 2 + ph['yaw']])
    phase_err = scoring.phase_error_percent(run.phase, true_phase)
    up_true, down_true = scoring.transitions(t, tw)
    up_det, down_det = scoring.transitions(t, run.walking)
    acquisition = None
    if tw[0] and up_det.size:
        # walking from the first sample: the first detection is the acquisition time
        acquisition = float(up_det[0] - t[0])
        up_det = up_det[1:]
    starts = scoring.match_events(up_true, up_det)
    stops = scoring.match_events(down_true, down_det)
    # the predicted change of attitude over the horizon (what DGPR needs) against the
    # true change: (pred - est. now) - (truth(t + h) - truth(t))
    rel_err = scoring.angle_errors_deg(motion_increments(run), truth_h - truth_now)
    heading_ref = heading_references(w, t, horizon)
    return {
        'pred_err': pred_err[valid], 'hold_err': hold_err[valid],
        'pred_err_walk': pred_err[steady], 'hold_err_walk': hold_err[steady],
        'phase_err_walk': phase_err[steady], 'motion_err': rel_err[valid],
        'motion_err_walk': rel_err[steady],
        'start_delays': starts.delays, 'stop_delays': stops.delays,
        'missed': starts.missed + stops.missed,
        'false': starts.false + stops.false,
        'acquisition': acquisition,
        'n_true_events': int(up_true.size + down_true.size),
        'heading_ref_walk': heading_ref[steady] if heading_ref is not None
        else np.zeros((0, 2 + len(ONSET_DELAYS))),
        'step_cpu': run.step_cpu, 'frequency_err_walk': run.frequency[steady]
        - w.step_freq * np.power(np.maximum(w.speed(t[steady]), 1e-3) / 1.2, 0.3),
    }


def _heading_function(walker):
    """The walker's heading(t) (rad, unwrapped), or None (unwrapping the scenario
    wrappers down to ``sim.motion.Trajectory``)."""
    w = walker
    for _ in range(4):
        if w is None or hasattr(w, 'heading'):
            break
        w = getattr(w, 'a', None) or getattr(w, 'traj', None)
    return getattr(w, 'heading', None)


#: detection delays of the turn-onset references (``heading_references``), s
ONSET_DELAYS = (0.0, 0.1, 0.2, 0.3)


def heading_references(walker, t, horizon: float = HORIZON,
                       delays=ONSET_DELAYS) -> np.ndarray | None:
    """Errors (deg) of oracle yaw predictors at `horizon`, which know the simulated stride
    sway exactly and see no noise or lag, so that only the walking direction's change is
    left: (N, 2 + len(delays)) columns

    * *rate*: the heading's true current rate extrapolated (the "yaw drift" state with a
      perfect estimate);
    * *rate and acceleration*: its true rate and acceleration extrapolated (the turning
      model's states, perfect);
    * *turn known d s after its start*, one column per d in `delays`: perfect — the
      turn's whole future course known — from d s after a turn begins, and no turn
      predicted before (the latest turn begun by the target time is not yet known).
      With d = 0 only the samples predicted before a turn begins err.

    A turn begins where the heading starts to change after standing still. The first two
    are not bounds of causal prediction in general: a predictor that knew the simulated
    turns' shape (a smoothstep: a constant third derivative) could beat them. The others
    show how soon a turn would have to be detected. None if the walker has no heading."""
    heading = _heading_function(walker)
    if heading is None:
        return None
    t = np.asarray(t, float)
    dt = 1e-3
    h0, h1 = heading(t), heading(t + horizon)
    hm, hp = heading(t - dt), heading(t + dt)
    rate = (hp - hm) / (2 * dt)
    acc = (hp - 2 * h0 + hm) / (dt * dt)
    e_rate = h1 - (h0 + horizon * rate)
    e_acc = e_rate - 0.5 * horizon * horizon * acc
    cols = [e_rate, e_acc]
    if t.size:
        grid = np.arange(min(t.min(), 0.0), t.max() + horizon + 2 * dt, dt)
        moving = np.abs(np.diff(heading(grid))) > 1e-9 * dt
        onsets = grid[1:-1][moving[1:] & ~moving[:-1]]
    else:
        onsets = np.zeros(0)
    since = np.full(t.size, np.inf)          # since the latest turn's start, s
    if onsets.size:
        k = np.searchsorted(onsets, t + horizon, side='right') - 1
        since = np.where(k >= 0, t - onsets[np.maximum(k, 0)], np.inf)
    for d in delays:
        cols.append(np.where(since < d, h1 - h0, 0.0))
    return np.degrees(np.column_stack(cols))


def _held(t, flags, span: float) -> np.ndarray:
    """True where `flags` has been true for the last `span` seconds (and is now)."""
    t = np.asarray(t, float)
    f = np.asarray(flags, bool)
    since = np.full(t.size, -np.inf)
    start = None
    for i in range(t.size):
        if f[i]:
            start = t[i] if start is None else start
            since[i] = start
        else:
            start = None
    return f & (t - since >= span)


def _pool(results: list[dict], key: str) -> np.ndarray:
    arrs = [r[key] for r in results if np.size(r[key])]
    if not arrs:
        return np.zeros((0,))
    return np.concatenate(arrs, axis=0)


def summarise_sim(results: list[dict]) -> dict:
    """Pool the per-run errors of one scenario (RMS over all samples of all seeds)."""
    def r3(key):
        return _pooled_rms(results, key) or [None] * 3

    sd, st = _pool(results, 'start_delays'), _pool(results, 'stop_delays')
    cpu = _pool(results, 'step_cpu') * 1e3
    return {
        'runs': len(results),
        'pred_rms_deg': r3('pred_err'), 'hold_rms_deg': r3('hold_err'),
        'pred_rms_walking_deg': r3('pred_err_walk'), 'hold_rms_walking_deg': r3('hold_err_walk'),
        'motion_rms_deg': r3('motion_err'),
        'yaw_reference_rms_walking_deg': _pooled_rms(results, 'heading_ref_walk'),
        'phase_rms_pct': r3('phase_err_walk'),
        'start_delay_s': _stats(sd), 'stop_delay_s': _stats(st),
        'missed_events': int(sum(r['missed'] for r in results)),
        'false_events': int(sum(r['false'] for r in results)),
        'acquisition_s': _stats([r['acquisition'] for r in results
                                 if r['acquisition'] is not None]),
        'true_events': int(sum(r['n_true_events'] for r in results)),
        'step_ms': {'median': float(np.median(cpu)), 'p90': float(np.percentile(cpu, 90)),
                    'p99': float(np.percentile(cpu, 99)), 'max': float(cpu.max())},
    }


def _pooled_rms(results: list[dict], key: str) -> list | None:
    """Column RMS of (N, k) arrays pooled over runs, or None if there are no rows."""
    a = _pool(results, key)
    if not a.size:
        return None
    return [float(v) for v in np.sqrt(np.mean(np.square(a.reshape(len(a), -1)), axis=0))]


def _floats(v) -> list[float]:
    return [float(x) for x in v]


def _stats(x) -> dict:
    x = np.asarray(x, float)
    if not x.size:
        return {'n': 0}
    return {'n': int(x.size), 'mean': float(x.mean()), 'median': float(np.median(x)),
            'max': float(x.max()), 'min': float(x.min()),
            'within_0.5s': int(np.sum(np.abs(x) <= 0.5))}


def evaluate_sim(scenarios=SIM_SCENARIOS, seeds=range(5), config: GaitConfig | None = None,
                 progress=None) -> dict:
    """Run every scenario for every seed; {scenario: summary}."""
    out = {}
    for name in scenarios:
        res = []
        for seed in seeds:
            case = make_case(name, seed)
            run = run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, config)
            res.append(score_sim(case, run))
            if progress:
                progress(f'  {name} seed {seed} done')
        out[name] = summarise_sim(res)
    return out


def evaluate_fusion(seeds=range(5), sigma_deg: float = 0.5, config: GaitConfig | None = None,
                    scenarios=('walk', 'turn'), progress=None) -> dict:
    """Inclinometer alone, visual motion alone, both, and both with either dropped
    (4 s from 12 s): RMS of the 0.5 s prediction (absolute attitude and the rotation
    over the horizon) in steady walking; the dropout rows over the dropout window."""
    modes = {
        'inclinometer': dict(ego=False, inc=True),
        'egomotion': dict(ego=True, inc=False),
        'fused': dict(ego=True, inc=True),
        'fused_drop_egomotion': dict(ego=True, inc=True, drop_ego=(12.0, 16.0)),
        'fused_drop_inclinometer': dict(ego=True, inc=True, drop_inc=(12.0, 16.0)),
    }
    acc = {m: [] for m in modes}
    base = config if config is not None else GaitConfig()
    config = dataclasses.replace(base, egomotion_sigma_deg=sigma_deg)   # matched noise
    for name in scenarios:
        for seed in seeds:
            case = make_case(name, seed)
            ego = simulate_egomotion(case.walker, case.duration, sigma_deg,
                                     rng=np.random.default_rng([seed, 0xE60, 3]))
            for m, o in modes.items():
                run = run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, config,
                                  egomotion=ego if o['ego'] else None,
                                  use_inclinometer=o['inc'],
                                  drop_inclinometer=o.get('drop_inc'),
                                  drop_egomotion=o.get('drop_ego'))
                sc = score_sim(case, run)
                window = o.get('drop_inc') or o.get('drop_ego')
                if window is not None:
                    # errors inside the dropout only (steady walking)
                    t = run.times
                    tw = (_truth_walking(case.walker, t)
                          & _truth_walking(case.walker, t - STEADY_AFTER) & run.walking
                          & (t + HORIZON <= case.duration))
                    _, th = case.walker.states(t + HORIZON)
                    sel = tw & (t >= window[0]) & (t <= window[1])
                    sc['pred_err_walk'] = scoring.angle_errors_deg(run.predicted, th)[sel]
                    _, tn = case.walker.states(t)
                    sc['motion_err_walk'] = scoring.angle_errors_deg(
                        motion_increments(run), th - tn)[sel]
                acc[m].append(sc)
            if progress:
                progress(f'  fusion {name} seed {seed} done')
    out = {}
    for m, res in acc.items():
        pe, me = _pool(res, 'pred_err_walk'), _pool(res, 'motion_err_walk')
        out[m] = {'pred_rms_walking_deg': _floats(scoring.rms(pe)) if pe.size else None,
                  'motion_rms_walking_deg': _floats(scoring.rms(me)) if me.size else None,
                  'samples': int(pe.shape[0])}
    return {'sigma_deg': sigma_deg, 'scenarios': list(scenarios), 'modes': out}


# ======================================================================= output

def _fmt3(v) -> str:
    return ' / '.join('  -  ' if x is None else f'{x:5.2f}' for x in v)


def print_sim(summary: dict, file=sys.stdout) -> None:
    p = lambda s='': print(s, file=file)  # noqa: E731
    p('0.5 s-ahead prediction RMS, degrees, roll / pitch / yaw (vs the true attitude)')
    p(f'{"scenario":9} {"all samples":23} {"hold last":23} {"steady walking":23} '
      f'{"hold last":23}')
    for name, s in summary.items():
        p(f'{name:9} {_fmt3(s["pred_rms_deg"]):23} {_fmt3(s["hold_rms_deg"]):23} '
          f'{_fmt3(s["pred_rms_walking_deg"]):23} {_fmt3(s["hold_rms_walking_deg"]):23}')
    p()
    p('gait phase RMS error, % of the cycle (roll / pitch / yaw), steady walking; walk '
      'start and stop delays, s')
    for name, s in summary.items():
        sd, st = s['start_delay_s'], s['stop_delay_s']

        def d(x):
            if not x.get('n'):
                return 'none'
            return (f'n={x["n"]} median {x["median"]:+.2f} max {x["max"]:+.2f} '
                    f'({x["within_0.5s"]}/{x["n"]} within 0.5 s)')
        p(f'{name:9} phase {_fmt3(s["phase_rms_pct"])}   start {d(sd)}   stop {d(st)}   '
          f'missed {s["missed_events"]}/{s["true_events"]}, false {s["false_events"]}')
    p()
    delays = ' / '.join(f'{d:g}' for d in ONSET_DELAYS)
    p('yaw references, steady walking, RMS degrees: oracles that know the stride sway and '
      'see no noise or lag, predicting the walking direction by its true rate | true rate '
      'and acceleration | its whole course, but a turn only once it is known, '
      f'{delays} s after it begins (see heading_references)')
    for name, s in summary.items():
        ref = s.get('yaw_reference_rms_walking_deg')
        if ref and s['pred_rms_walking_deg'][2] is not None:
            known = ' / '.join(f'{v:.2f}' for v in ref[2:])
            p(f'{name:9} {ref[0]:5.2f} | {ref[1]:5.2f} | {known}   '
              f'(walk model yaw {s["pred_rms_walking_deg"][2]:.2f})')
    p()
    allcpu = [s['step_ms'] for s in summary.values()]
    p('filter step (thread CPU time per inclinometer sample), ms: ' + ', '.join(
        f'{n} median {c["median"]:.3f} p99 {c["p99"]:.2f} max {c["max"]:.2f}'
        for n, c in zip(summary, allcpu)))


def print_fusion(res: dict, file=sys.stdout) -> None:
    p = lambda s='': print(s, file=file)  # noqa: E731
    p(f'fusion ({", ".join(res["scenarios"])}; visual motion 10 Hz, sigma '
      f'{res["sigma_deg"]} deg per frame): RMS in steady walking, degrees, roll / pitch / yaw')
    p(f'{"source":26} {"0.5 s-ahead attitude":24} {"rotation over the 0.5 s":24} samples')
    for m, r in res['modes'].items():
        a = r['pred_rms_walking_deg'] or [None] * 3
        b = r['motion_rms_walking_deg'] or [None] * 3
        p(f'{m:26} {_fmt3(a):24} {_fmt3(b):24} {r["samples"]}')
    p('(visual motion alone observes no absolute roll/pitch/yaw: its attitude row drifts; '
      'the dropout rows cover only the 4 s dropouts)')


# ======================================================================= CLI

def add_arguments(p) -> None:
    sub = p.add_subparsers(dest='gait_command', required=True)
    s = sub.add_parser('sim', help='simulated walks: prediction, phase, start/stop')
    s.add_argument('--scenarios', nargs='+', default=list(SIM_SCENARIOS),
                   choices=SIM_SCENARIOS)
    s.add_argument('--seeds', type=int, default=5, help='seeds 0..N-1 per scenario')
    s.add_argument('--json', type=Path, default=None)
    f = sub.add_parser('fusion', help='inclinometer + visual motion, dropouts')
    f.add_argument('--seeds', type=int, default=5)
    f.add_argument('--egomotion-sigma', type=float, default=0.5,
                   help='visual-motion noise per frame and axis, degrees (default 0.5)')
    f.add_argument('--json', type=Path, default=None)
    r = sub.add_parser('real', help='Mobilise-D lower-back IMU walks')
    r.add_argument('--data', type=Path, default=DEFAULT_DATA)
    r.add_argument('--json', type=Path, default=None)
    b = sub.add_parser('bags', help='walking bags: inclinometer + the egomotion '
                       "estimator's visual motion, fused, against the ground truth")
    from asmonc_vision.cli import gait_bags
    gait_bags.add_arguments(b)
    g = sub.add_parser('figs', help="the paper's Figs. 13-15 as PNGs")
    g.add_argument('--out', type=Path, default=REPO / 'docs')
    g.add_argument('--data', type=Path, default=DEFAULT_DATA)
    p.set_defaults(func=run)


def run(args) -> int:
    cmd = args.gait_command
    if cmd == 'sim':
        if args.seeds < 1:
            print('asmonc gait sim: --seeds must be >= 1', file=sys.stderr)
            return 2
        summary = evaluate_sim(args.scenarios, range(args.seeds))
        print_sim(summary)
        if args.json:
            args.json.write_text(json.dumps(json_ready(summary), indent=1, allow_nan=False))
        return 0
    if cmd == 'fusion':
        if args.seeds < 1 or not args.egomotion_sigma > 0:
            print('asmonc gait fusion: --seeds >= 1 and --egomotion-sigma > 0 needed',
                  file=sys.stderr)
            return 2
        out = {}
        for name in ('walk', 'turn'):
            res = evaluate_fusion(range(args.seeds), args.egomotion_sigma, scenarios=(name,))
            print_fusion(res)
            print()
            out[name] = res
        if args.json:
            args.json.write_text(json.dumps(json_ready(out), indent=1, allow_nan=False))
        return 0
    if cmd == 'real':
        try:
            res = evaluate_real(args.data)
        except FileNotFoundError as exc:
            print(f'asmonc gait real: {exc}', file=sys.stderr)
            return 2
        print_real(res)
        if args.json:
            args.json.write_text(json.dumps(json_ready(res), indent=1, allow_nan=False))
        return 0
    if cmd == 'bags':
        from asmonc_vision.cli import gait_bags
        return gait_bags.run(args)
    if cmd == 'figs':
        for path in draw_figures(args.out, args.data):
            print(f'figure: {path}')
        return 0
    return 2


# ======================================================================= real walking

REAL_RATE = 100.0
#: "steady" part of a reference bout: without its first and last second
REAL_TRIM = 1.0
#: time constant of the complementary filter for the real recordings, s: long enough
#: that walking accelerations (0.1-0.3 g at the step) leak little into the tilt (about
#: k / omega = 1 / (tau 2 pi 1.8 Hz), 3 %), short enough for the gyroscope's drift
REAL_ATTITUDE_TIME_CONSTANT = 3.0
#: event tolerances of the walk start/stop precision and recall, s
EVENT_TOLERANCES = (0.5, 1.0)


@dataclass(frozen=True)
class RealRecording:
    """One Mobilise-D lower-back recording, as a 16 Hz compass would give it."""

    name: str                      # e.g. 'HA/001 Test5 Trial1'
    times: np.ndarray              # (M,) s from the recording's start
    rpy: np.ndarray                # (M, 3) rad
    bouts: list                    # reference walking bouts [(start, end)] s
    reference: str                 # 'INDIP', 'Stereophoto' or 'none'
    turns: list                    # reference turns [(start, end, angle_deg)]
    cadence: list = dataclasses.field(default_factory=list)   # per bout, steps/s (or nan)


def _bouts_of(standards) -> tuple[list, str, list, list]:
    for ref in ('INDIP', 'Stereophoto'):
        s = getattr(standards, ref, None)
        if s is None:
            continue
        mw = np.atleast_1d(getattr(s, 'MicroWB', np.array([])))
        items = [m for m in mw if hasattr(m, 'Start')]
        if items:
            bouts = [(float(m.Start), float(m.End)) for m in items]
            cadence = [float(np.nanmean(np.atleast_1d(getattr(m, 'Cadence', np.nan))))
                       / 60.0 for m in items]
            turns = []
            for m in items:
                ts, te, ta = (np.atleast_1d(getattr(m, k, [])).astype(float)
                              for k in ('Turn_Start', 'Turn_End', 'Turn_Angle'))
                turns += list(zip(ts, te, ta))
            return bouts, ref, turns, cadence
    return [], 'none', [], []


def load_real(data: Path, tests=('Test5', 'Test11')) -> list[RealRecording]:
    """The lower-back recordings (CSV: acc in g, gyr in deg/s, 100 Hz) with their
    reference bouts from data.mat; attitude by the complementary filter
    (``REAL_ATTITUDE_TIME_CONSTANT``), decimated to 16 Hz.

    Raises:
        FileNotFoundError: the data directory is missing.
    """
    import scipy.io as sio

    from asmonc_vision.core.gait.attitude import (MOBILISE_TO_BODY, complementary_filter,
                                                  decimate_to)

    csv_root, mat_root = Path(data) / 'data_csv', Path(data) / 'data' / 'lab'
    if not csv_root.is_dir():
        raise FileNotFoundError(f'no gait data at {data} (expected data_csv/ and data/lab/)')
    out = []
    for f in sorted(csv_root.glob('*/*/TimeMeasure1_Test*_Trial*.csv')):
        group, pid = f.parent.parent.name, f.parent.name
        _, test, trial = f.stem.split('_')
        if test not in tests:
            continue
        a = np.loadtxt(f, delimiter=',', skiprows=1)
        acc = a[:, 1:4] @ MOBILISE_TO_BODY.T
        gyr = np.radians(a[:, 4:7]) @ MOBILISE_TO_BODY.T
        rpy100 = complementary_filter(acc, gyr, REAL_RATE, REAL_ATTITUDE_TIME_CONSTANT)
        t16, rpy16 = decimate_to(rpy100, REAL_RATE, 16.0)
        bouts, ref, turns, cadence = [], 'none', [], []
        mat = mat_root / group / pid / 'data.mat'
        if mat.exists():
            d = sio.loadmat(mat, squeeze_me=True, struct_as_record=False)['data']
            tr = getattr(getattr(d.TimeMeasure1, test), trial)
            bouts, ref, turns, cadence = _bouts_of(tr.Standards)
        out.append(RealRecording(f'{group}/{pid} {test} {trial}', t16, rpy16, bouts, ref,
                                 turns, cadence))
    return out


#: the walk model for the real recordings: the attitude comes from a complementary filter
#: decimated without lag (no compass lag to compensate); everything else as default
def real_config(config: GaitConfig | None = None) -> GaitConfig:
    base = config if config is not None else GaitConfig()
    return dataclasses.replace(base, sensor_lag=0.0)


#: nominal noise of the decimated complementary-filter attitude, rad
REAL_SIGMA = math.radians(0.1)


def window_fit_prediction(times, rpy, horizon: float = HORIZON, window: float = 2.0,
                          config: GaitConfig | None = None) -> np.ndarray:
    """A reference predictor: at every sample, fit the walk model's stride harmonics by
    least squares to the last `window` seconds (best step frequency on the grid by the
    lock check's criterion; the trend is fitted but not extrapolated) and evaluate it
    `horizon` ahead. No filtering, no state. NaN where the window is not full."""
    from asmonc_vision.core.gait.detector import LOCK_CRITERION, fit_walk

    cfg = config if config is not None else GaitConfig()
    freqs = np.arange(cfg.min_frequency, cfg.max_frequency + 1e-9, 0.02)
    t = np.asarray(times, float)
    out = np.full((t.size, 3), np.nan)
    for i in range(t.size):
        if t[i] - t[0] < window:
            continue
        m = (t > t[i] - window) & (t <= t[i])
        fit = fit_walk(t[m] - t[i], rpy[m], freqs, cfg.harmonics, *LOCK_CRITERION)
        if fit is None:
            continue
        for a in range(3):
            c = fit.coefficients[a]
            k = np.arange(1, c.size + 1)
            out[i, a] = fit.offset[a] + float(np.sum(np.imag(
                c * np.exp(1j * k * np.pi * fit.frequency * horizon))))
    return out


def _harmonic_design(tau, f_stride: float, ks, trend: bool = False) -> np.ndarray:
    cols = [np.ones_like(tau)] + ([tau] if trend else [])
    for k in ks:
        cols += [np.sin(2 * np.pi * k * f_stride * tau), np.cos(2 * np.pi * k * f_stride * tau)]
    return np.column_stack(cols)


def bout_stride_frequency(t, y, ks=(1, 2)) -> tuple[float, float]:
    """Non-causal: the stride frequency (Hz, 0.6-1.3) whose harmonics ``ks`` (with
    offset and trend) fit the whole bout best, and that fit's rms residual (rad)."""
    tau = np.asarray(t, float) - t[0]
    best = (np.inf, 0.0)
    for f in np.arange(0.6, 1.3, 0.005):
        X = _harmonic_design(tau, f, ks, trend=True)
        r = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        best = min(best, (float(np.sqrt(np.mean(r * r))), float(f)))
    return best[1], best[0]


#: the oracle-aided Fourier-combiner benchmark's settings (the best on these recordings,
#: pooled: optimistic): stride harmonics, random walks of offset and coefficients
#: (deg / sqrt(s)), measurement noise (deg), initial coefficient spread (deg)
FLC_BOUND = {'ks': (1, 2, 3), 'q_offset': 2.0, 'q_coef': 0.25, 'r': 1.0, 'p0': 3.0}


def fourier_combiner_bound(rec: RealRecording, horizon: float = HORIZON, axis: int = 1
                           ) -> np.ndarray:
    """An oracle-aided benchmark (not an upper bound) for a causal walk model on a
    recording: a linear Kalman filter of the stride harmonics (a Fourier linear
    combiner), started at each reference bout's start (known only afterwards) and
    *given* the bout's own stride frequency (found non-causally over the whole bout,
    ``bout_stride_frequency``), predicting ``horizon`` ahead; its noise levels were
    chosen on these recordings. Started 1 s before the reference start it is hardly
    better than holding the last value (docs/gait.md, section 4.3). NaN outside the
    bouts."""
    s = FLC_BOUND
    t = rec.times
    out = np.full(t.size, np.nan)
    d = math.radians
    for b0, b1 in rec.bouts:
        m = (t >= b0) & (t <= b1)
        if m.sum() < 8:
            continue
        f0, _ = bout_stride_frequency(t[m], rec.rpy[m, axis])
        n = 1 + 2 * len(s['ks'])
        idx = np.flatnonzero(m)
        x = np.zeros(n)
        x[0] = rec.rpy[idx[0], axis]
        P = np.eye(n) * d(s['p0']) ** 2
        P[0, 0] = d(1.0) ** 2
        dt = 1.0 / 16.0
        Q = np.diag([d(s['q_offset']) ** 2] + [d(s['q_coef']) ** 2] * (n - 1)) * dt
        for i in idx:
            tau = np.array([t[i] - t[idx[0]]])
            H = _harmonic_design(tau, f0, s['ks'])[0]
            P = P + Q                                      # P = P + Q (random walks)
            S = H @ P @ H + d(s['r']) ** 2                 # S = H P H^T + R
            K = P @ H / S                                  # K = P H^T S^-1
            x = x + K * (rec.rpy[i, axis] - H @ x)         # x = x + K (z - H x)
            P = P - np.outer(K, H @ P)                     # P = (I - K H) P
            out[i] = _harmonic_design(tau + horizon, f0, s['ks'])[0] @ x
    return out


def score_real(rec: RealRecording, run: TrackerRun, horizon: float = HORIZON) -> dict:
    """0.5 s-ahead prediction vs the later measured attitude, and vs holding the last
    value, for samples whose t and t + horizon lie inside a reference bout; reference
    predictors; detected walk starts/stops against the reference bouts; the tracked
    step frequency against the reference cadence."""
    t = run.times
    later = np.column_stack([np.interp(t + horizon, rec.times, rec.rpy[:, a]) for a in range(3)])
    in_bout = np.zeros(t.size, bool)
    steady = np.zeros(t.size, bool)
    for s, e in rec.bouts:
        in_bout |= (t >= s) & (t + horizon <= e)
        steady |= (t >= s + REAL_TRIM) & (t + horizon <= e - REAL_TRIM)
    pe_all = scoring.angle_errors_deg(run.predicted, later)
    he_all = scoring.angle_errors_deg(rec.rpy[:t.size], later)
    sel = np.flatnonzero(in_bout)
    wf = np.full((t.size, 3), np.nan)
    if sel.size:
        lo = max(0, sel[0] - 40)
        wf[lo:sel[-1] + 1] = window_fit_prediction(t[lo:sel[-1] + 1],
                                                   rec.rpy[lo:sel[-1] + 1], horizon)
    fit_err = scoring.angle_errors_deg(wf, later)
    flc = fourier_combiner_bound(rec, horizon)
    flc_err = np.degrees(flc - later[:, 1])
    floor = []
    for s, e in rec.bouts:
        m = (rec.times >= s) & (rec.times <= e)
        if m.sum() >= 8:
            floor.append((int(m.sum()), bout_stride_frequency(rec.times[m], rec.rpy[m, 1])[1]))
    up, down = scoring.transitions(t, run.walking)
    events = {}
    for tol in EVENT_TOLERANCES:
        events[f'start_{tol:g}s'] = scoring.event_precision_recall(
            [b[0] for b in rec.bouts], up, tol)
        events[f'end_{tol:g}s'] = scoring.event_precision_recall(
            [b[1] for b in rec.bouts], down, tol)
    cad = []
    for (s, e), c in zip(rec.bouts, rec.cadence or [np.nan] * len(rec.bouts)):
        m = (t >= s) & (t <= e) & run.walking
        if m.any() and np.isfinite(c):
            cad.append((float(np.median(run.frequency[m])), c))
    detected = scoring.bouts(t, run.walking)
    return {'name': rec.name, 'reference': rec.reference, 'n': int(in_bout.sum()),
            'pred_err': pe_all[in_bout], 'hold_err': he_all[in_bout],
            'pred_err_steady': pe_all[steady], 'hold_err_steady': he_all[steady],
            'fit_err': fit_err[in_bout], 'flc_err': flc_err[in_bout],
            'floor': floor, 'events': events, 'cadence': cad,
            'detected_bouts': len(detected),
            'short_bouts': sum(1 for a, b in detected if b - a < 2.0),
            'bouts': len(rec.bouts),
            'walking_share': float(np.mean(run.walking[in_bout])) if in_bout.any()
            else float('nan')}


def _gain(p, h) -> float:
    return float(100.0 * (1.0 - p / h)) if h > 0 else float('nan')


def evaluate_real(data: Path = DEFAULT_DATA, config: GaitConfig | None = None,
                  recordings=None) -> dict:
    """Run the walk model on every recording; per-recording and pooled results."""
    cfg = real_config(config)
    recs = recordings if recordings is not None else load_real(data)
    rows = []
    for rec in recs:
        run = run_tracker(rec.times, rec.rpy, REAL_SIGMA ** 2, cfg)
        rows.append(score_real(rec, run))
    out = {'recordings': []}
    for r in rows:
        rec = {'name': r['name'], 'reference': r['reference'], 'samples': r['n'],
               'bouts': r['bouts'], 'walking_share_in_bouts': r['walking_share']}
        if r['n']:
            p, h = scoring.rms(r['pred_err']), scoring.rms(r['hold_err'])
            fl = r['flc_err'][np.isfinite(r['flc_err'])]
            rec.update({'pred_rms_deg': _floats(p), 'hold_rms_deg': _floats(h),
                        'pitch_gain_pct': _gain(p[1], h[1]),
                        'bound_pitch_gain_pct': _gain(float(np.sqrt(np.mean(fl ** 2))), h[1])
                        if fl.size else None})
        out['recordings'].append(rec)
    for test in ('Test5', 'Test11'):
        sel = [r for r in rows if f' {test} ' in r['name'] and r['n']]
        if not sel:
            continue
        cat = lambda k, sel=sel: np.concatenate([r[k] for r in sel])  # noqa: E731
        p, h = scoring.rms(cat('pred_err')), scoring.rms(cat('hold_err'))
        ps, hs = scoring.rms(cat('pred_err_steady')), scoring.rms(cat('hold_err_steady'))
        fe = cat('fit_err')
        fe = fe[np.all(np.isfinite(fe), 1)]
        fl = cat('flc_err')
        fl = fl[np.isfinite(fl)]
        floor_n = sum(n for r in sel for n, _ in r['floor'])
        floor = math.sqrt(sum(n * v * v for r in sel for n, v in r['floor']) / floor_n)
        ev = {}
        for key in sel[0]['events']:
            m = sum(r['events'][key][0] for r in sel)
            nd = sum(r['events'][key][1] for r in sel)
            nt = sum(r['events'][key][2] for r in sel)
            ev[key] = {'matched': m, 'detected': nd, 'true': nt,
                       'precision': m / nd if nd else float('nan'),
                       'recall': m / nt if nt else float('nan')}
        cad = [c for r in sel for c in r['cadence']]
        out[test] = {
            'samples': int(cat('pred_err').shape[0]), 'bouts': int(sum(r['bouts'] for r in sel)),
            'pred_rms_deg': _floats(p), 'hold_rms_deg': _floats(h),
            'improvement_pct': [_gain(a, b) for a, b in zip(p, h)],
            'steady_samples': int(cat('pred_err_steady').shape[0]),
            'steady_pred_rms_deg': _floats(ps), 'steady_hold_rms_deg': _floats(hs),
            'steady_improvement_pct': [_gain(a, b) for a, b in zip(ps, hs)],
            'window_fit_rms_deg': _floats(scoring.rms(fe)) if fe.size else None,
            'bound_pitch_rms_deg': float(np.sqrt(np.mean(fl ** 2))) if fl.size else None,
            'bound_pitch_gain_pct': _gain(float(np.sqrt(np.mean(fl ** 2))), h[1])
            if fl.size else None,
            'floor_pitch_rms_deg': math.degrees(floor),
            'floor_pitch_gain_pct': _gain(math.degrees(floor), h[1]),
            'events': ev,
            'cadence': [{'tracked_hz': a, 'reference_hz': b} for a, b in cad],
            'detected_bouts': int(sum(r['detected_bouts'] for r in sel)),
            'detected_short_bouts': int(sum(r['short_bouts'] for r in sel))}
    return out


def print_real(res: dict, file=sys.stdout) -> None:
    p = lambda s='': print(s, file=file)  # noqa: E731
    p('Mobilise-D lower-back IMU: attitude by complementary filter (tau '
      f'{REAL_ATTITUDE_TIME_CONSTANT:g} s), decimated to 16 Hz; 0.5 s-ahead prediction inside '
      'the reference walking bouts (RMS, degrees, roll / pitch / yaw)')
    p(f'{"recording":22} {"ref":11} {"n":>4}  {"walk model":21} {"hold last":21} '
      f'{"pitch gain":>10} {"oracle":>6} walking')
    for r in res['recordings']:
        if not r['samples']:
            p(f'{r["name"]:22} {r["reference"]:11} {0:4d}  (no reference bout)')
            continue
        b = r['bound_pitch_gain_pct']
        p(f'{r["name"]:22} {r["reference"]:11} {r["samples"]:4d}  '
          f'{_fmt3(r["pred_rms_deg"]):21} {_fmt3(r["hold_rms_deg"]):21} '
          f'{r["pitch_gain_pct"]:+9.0f}% {b:+5.0f}% {r["walking_share_in_bouts"]:6.2f}')
    for test in ('Test5', 'Test11'):
        if test not in res:
            continue
        x = res[test]
        p()
        p(f'{test}: {x["samples"]} samples in {x["bouts"]} bouts: walk model '
          f'{_fmt3(x["pred_rms_deg"])}, hold last {_fmt3(x["hold_rms_deg"])}; improvement '
          + ' / '.join(f'{v:+.0f}%' for v in x['improvement_pct']))
        p(f'  bouts without their first and last {REAL_TRIM:.0f} s ({x["steady_samples"]} '
          f'samples): walk model {_fmt3(x["steady_pred_rms_deg"])}, hold last '
          f'{_fmt3(x["steady_hold_rms_deg"])}; improvement '
          + ' / '.join(f'{v:+.0f}%' for v in x['steady_improvement_pct']))
        if x.get('window_fit_rms_deg'):
            p(f'  reference, causal least-squares fit of the stride harmonics over the last '
              f'2 s: {_fmt3(x["window_fit_rms_deg"])}')
        if x.get('bound_pitch_rms_deg') is not None:
            p(f'  pitch references: oracle-aided Fourier combiner (each bout\'s own stride '
              f'frequency and start; not a bound) {x["bound_pitch_rms_deg"]:.2f} deg '
              f'({x["bound_pitch_gain_pct"]:+.0f}%); upper bound of the model family, '
              f'non-causal fit of a whole bout (stride harmonics 1, 2, own frequency, trend), '
              f'leaves {x["floor_pitch_rms_deg"]:.2f} deg ({x["floor_pitch_gain_pct"]:+.0f}%)')
        ev = x['events']
        p('  walk start / end vs reference bouts: ' + '; '.join(
            f'{k.replace("_", " within ")}: precision {v["matched"]}/{v["detected"]}, recall '
            f'{v["matched"]}/{v["true"]}' for k, v in ev.items()))
        p(f'  detected bouts {x["detected_bouts"]} ({x["detected_short_bouts"]} shorter than '
          '2 s; a reference MicroWB has at least 2 strides)')
        if x['cadence']:
            c = np.array([[d['tracked_hz'], d['reference_hz']] for d in x['cadence']])
            e = c[:, 0] / c[:, 1] - 1.0
            p('  tracked step frequency vs reference cadence: '
              f'median error {100 * np.median(e):+.0f}%, '
              f'{int(np.sum(np.abs(e) <= 0.1))}/{e.size} bouts within 10 %')


# ======================================================================= figures

def draw_figures(out: Path, data: Path = DEFAULT_DATA) -> list[Path]:
    """The paper's Figs. 13-15 redrawn (PNG): 13 roll during walking, sensor output and
    filtered; 14 pitch during straight walking, measured and predicted 0.5 s earlier;
    15 yaw in a complex walk (turns, speed changes), measured and predicted 0.5 s
    earlier. Simulated walker, and the real lower-back recordings where present."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    cfg = GaitConfig()
    deg = np.degrees

    # --- Fig. 13: roll, sensor output and filtered (simulated compass)
    case = make_case('walk', 0)
    from asmonc_vision.core.gait.prefilter import Prefilter

    tr = GaitTracker(cfg)
    pf = Prefilter(cfg.sample_rate, cfg.prefilter_cutoff, cfg.prefilter_order)
    filt, att = [], []
    for t, z in zip(case.imu_times, case.imu_rpy):
        est = tr.add_inclinometer(t, z, np.full(3, case.imu_variance))
        filt.append(pf(z))
        att.append(est.attitude)
    filt, att = np.array(filt), np.array(att)
    t = case.imu_times
    _, truth = case.walker.states(t)
    sel = (t > 8) & (t < 16)
    fig, ax = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    ax[0].plot(t[sel], deg(case.imu_rpy[sel, 0]), 'k.-', lw=0.8, ms=3)
    ax[0].set_ylabel('roll, deg')
    ax[0].set_title('(a) sensor output (16 Hz compass: 0.3 deg noise, 0.1 deg steps, '
                    '80 ms lag)', fontsize=9)
    ax[1].plot(t[sel], deg(filt[sel, 0]), 'k-', lw=1.2, label='Butterworth prefilter '
               f'({cfg.prefilter_order}nd order, {cfg.prefilter_cutoff:g} Hz)')
    ax[1].plot(t[sel], deg(att[sel, 0]), 'r--', lw=1.2,
               label='walk model (lags compensated)')
    ax[1].plot(t[sel], deg(truth[sel, 0]), color='0.6', lw=3, alpha=0.5, zorder=0,
               label='true roll')
    ax[1].set_ylabel('roll, deg')
    ax[1].set_xlabel('time, s')
    ax[1].set_title('(b) filtered', fontsize=9)
    ax[1].legend(fontsize=7, loc='upper right')
    fig.suptitle('Fig. 13. Roll during walking (simulated walker)', fontsize=10)
    fig.tight_layout()
    paths.append(out / 'gait_fig13.png')
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    # --- Fig. 14: pitch during straight walking, measured and predicted 0.5 s earlier
    run = run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, cfg)
    real = None
    try:
        recs = [r for r in load_real(data, tests=('Test5',)) if r.name == 'HA/001 Test5 Trial1']
        real = recs[0] if recs else None
    except FileNotFoundError:
        real = None
    rows = 3 if real is not None else 2
    fig, ax = plt.subplots(rows, 1, figsize=(8, 2.6 * rows))
    sel = (run.times > 8) & (run.times < 14)
    ax[0].plot(run.times[sel], deg(case.imu_rpy[sel, 1]), 'k.-', lw=0.8, ms=3)
    ax[0].set_title('(a) measured (simulated 16 Hz compass)', fontsize=9)
    ax[1].plot(run.times[sel] + HORIZON, deg(run.predicted[sel, 1]), 'r.-', lw=0.8, ms=3,
               label='predicted 0.5 s earlier')
    _, tp = case.walker.states(run.times[sel] + HORIZON)
    ax[1].plot(run.times[sel] + HORIZON, deg(tp[:, 1]), color='0.6', lw=3, alpha=0.5,
               zorder=0, label='true pitch')
    ax[1].set_xlim(ax[0].get_xlim())
    ax[1].set_title('(b) predicted half a second earlier', fontsize=9)
    ax[1].legend(fontsize=7, loc='upper right')
    if real is not None:
        rr = run_tracker(real.times, real.rpy, REAL_SIGMA ** 2, real_config(cfg))
        s, e = real.bouts[0]
        m = (rr.times > s - 1.0) & (rr.times < e + 1.0)
        ax[2].plot(rr.times[m], deg(real.rpy[m, 1]), 'k.-', lw=0.8, ms=3, label='measured')
        ax[2].plot(rr.times[m] + HORIZON, deg(rr.predicted[m, 1]), 'r.-', lw=0.8, ms=3,
                   label='predicted 0.5 s earlier')
        ax[2].axvspan(s, e, color='g', alpha=0.08, label='reference walking bout')
        ax[2].set_title(f'(c) real: Mobilise-D lower-back IMU, {real.name}', fontsize=9)
        ax[2].legend(fontsize=7, loc='upper left')
    for a in ax:
        a.set_ylabel('pitch, deg')
    ax[-1].set_xlabel('time, s')
    fig.suptitle('Fig. 14. Pitch during walking', fontsize=10)
    fig.tight_layout()
    paths.append(out / 'gait_fig14.png')
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    # --- Fig. 15: yaw in a complex walk (turns, speed changes)
    case = make_case('turn', 0)
    run = run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, cfg)
    real11 = None
    try:
        recs = [r for r in load_real(data, tests=('Test11',)) if r.name == 'MS/001 Test11 Trial1']
        real11 = recs[0] if recs else None
    except FileNotFoundError:
        real11 = None
    rows = 2 if real11 is not None else 1
    fig, ax = plt.subplots(rows, 1, figsize=(8, 3.0 * rows), squeeze=False)
    ax = ax[:, 0]
    yaw_m = np.unwrap(case.imu_rpy[:, 2])
    ax[0].plot(run.times, deg(yaw_m), 'k-', lw=1.0, label='measured')
    ax[0].plot(run.times + HORIZON, deg(run.predicted[:, 2]), 'r:', lw=1.4,
               label='predicted 0.5 s earlier')
    ax[0].set_title('(a) simulated: walk, 90 deg turn, speed change, 60 deg turn back',
                    fontsize=9)
    if real11 is not None:
        rr = run_tracker(real11.times, real11.rpy, REAL_SIGMA ** 2, real_config(cfg))
        s, e = real11.bouts[3] if len(real11.bouts) > 3 else real11.bouts[0]
        m = (rr.times > s - 2) & (rr.times < e + 2)
        ax[1].plot(rr.times[m], deg(real11.rpy[m, 2]), 'k-', lw=1.0, label='measured')
        ax[1].plot(rr.times[m] + HORIZON, deg(rr.predicted[m, 2]), 'r:', lw=1.4,
                   label='predicted 0.5 s earlier')
        ax[1].axvspan(s, e, color='g', alpha=0.08, label='reference walking bout')
        ax[1].set_title(f'(b) real: {real11.name} (daily-living walk with turns)',
                        fontsize=9)
    for a in ax:
        a.set_ylabel('yaw, deg')
        a.legend(fontsize=7, loc='best')
    ax[-1].set_xlabel('time, s')
    fig.suptitle('Fig. 15. Yaw during a complex walk', fontsize=10)
    fig.tight_layout()
    paths.append(out / 'gait_fig15.png')
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths


def main(argv: list[str] | None = None) -> int:
    """``python -m asmonc_vision.cli.gait ...``: the same as ``asmonc gait ...``."""
    from asmonc_vision.cli.main import main as asmonc_main
    return asmonc_main(['gait', *(sys.argv[1:] if argv is None else argv)])


if __name__ == '__main__':
    sys.exit(main())
