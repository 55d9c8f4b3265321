"""The walk model (Molton et al. 1998, Section 5) evaluated on simulated and real walking.

The measurements of `asmonc gait` (its help, `cli.gait`, says what each reports):
simulated walks (`evaluate_sim`) and fusion with visual motion (`evaluate_fusion`);
`gait_command` runs one. The real recordings: `eval.gait_real`.
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
              & held(t, run.walking, STEADY_AFTER) & inside)
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


def held(t, flags, span: float) -> np.ndarray:
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


def as_floats(v) -> list[float]:
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
        out[m] = {'pred_rms_walking_deg': as_floats(scoring.rms(pe)) if pe.size else None,
                  'motion_rms_walking_deg': as_floats(scoring.rms(me)) if me.size else None,
                  'samples': int(pe.shape[0])}
    return {'sigma_deg': sigma_deg, 'scenarios': list(scenarios), 'modes': out}


# ======================================================================= output

def fmt3(v) -> str:
    return ' / '.join('  -  ' if x is None else f'{x:5.2f}' for x in v)


def print_sim(summary: dict, file=sys.stdout) -> None:
    p = lambda s='': print(s, file=file)  # noqa: E731
    p('0.5 s-ahead prediction RMS, degrees, roll / pitch / yaw (vs the true attitude)')
    p(f'{"scenario":9} {"all samples":23} {"hold last":23} {"steady walking":23} '
      f'{"hold last":23}')
    for name, s in summary.items():
        p(f'{name:9} {fmt3(s["pred_rms_deg"]):23} {fmt3(s["hold_rms_deg"]):23} '
          f'{fmt3(s["pred_rms_walking_deg"]):23} {fmt3(s["hold_rms_walking_deg"]):23}')
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
        p(f'{name:9} phase {fmt3(s["phase_rms_pct"])}   start {d(sd)}   stop {d(st)}   '
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
        p(f'{m:26} {fmt3(a):24} {fmt3(b):24} {r["samples"]}')
    p('(visual motion alone observes no absolute roll/pitch/yaw: its attitude row drifts; '
      'the dropout rows cover only the 4 s dropouts)')


# ======================================================================= command

def gait_command(args) -> int:
    """`asmonc gait sim|fusion` with its parsed arguments (see `cli.gait`); the exit
    code."""
    from asmonc_vision.eval.evaluation import json_ready

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
    return 2
