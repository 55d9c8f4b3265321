"""The walk model (core.gait): prefilter response, model Jacobian, the tracker on the
simulator's walker (prediction, phase, walk start/stop, turns, uphill, a bend), visual
motion fused in, dropouts, out-of-order stamps, speed. Fixed seeds throughout."""
import math

import numpy as np
import pytest

from asmonc_vision.eval import gait_walks as ev
from asmonc_vision.core.gait import GaitConfig, GaitTracker, scoring
from asmonc_vision.core.gait.attitude import complementary_filter, decimate_to
from asmonc_vision.core.gait.detector import WalkDetector, fit_walk, stop_amplitudes
from asmonc_vision.core.gait.model import (I_F, I_O, I_R, I_TH, I_YA, StateLayout,
                                           WalkModelEKF, continuous_system, discretise)
from asmonc_vision.core.gait.prefilter import Prefilter
from asmonc_vision.core.gait.rotations import (R_BODY_OPTICAL, egomotion_to_body,
                                               rpy_increment, rpy_to_matrix)


def _rms(x):
    return scoring.rms(np.asarray(x))


# ---------------------------------------------------------------- building blocks

@pytest.mark.parametrize('f', [0.9, 1.9, 3.8])
def test_prefilter_response_is_what_the_filter_does(f):
    pf = Prefilter(16.0, 4.0, 2, sensor_lag=0.0)
    t = np.arange(200) / 16.0
    x = 0.03 * np.sin(2 * np.pi * f * t + 0.4)
    y = np.array([pf(np.array([xi, 0.0, 0.0]))[0] for xi in x])
    H = pf.response(f)
    expect = 0.03 * abs(H) * np.sin(2 * np.pi * f * t + 0.4 + np.angle(H))
    assert np.max(np.abs(y[100:] - expect[100:])) < 1e-6
    g, psi, _, _ = pf.gain_phase(f)
    assert g == pytest.approx(abs(H), rel=1e-4)
    assert math.remainder(psi - np.angle(H), 2 * math.pi) == pytest.approx(0.0, abs=1e-4)


def _walking_ekf(cfg=None):
    ekf = WalkModelEKF(cfg or GaitConfig())
    ekf.initialise(0.0, np.radians([1.0, 20.0, 30.0]), np.full(3, 1e-4))
    rng = np.random.default_rng(5)
    m = ekf.layout.k.size
    coef = np.radians(rng.uniform(0.2, 2.0, m)) * np.exp(1j * rng.uniform(0, 6.28, m))
    ekf.start_walking(1.85, coef, np.radians([0.5, 21.0, 30.0]), math.radians(4.0))
    ekf.x[I_TH] = 0.7
    ekf.x[I_YA] = math.radians(-3.0)
    return ekf


def test_model_jacobian_matches_finite_differences():
    ekf = _walking_ekf()
    pf = Prefilter(16.0, 6.0, 2, sensor_lag=0.08)
    x0 = ekf.x.copy()
    for s in (0.0, -0.35, 0.5):
        for filt in (None, pf):
            h, H = ekf.model(s, filt, x0)
            num = np.zeros_like(H)
            for i in range(ekf.n):
                d = np.zeros(ekf.n)
                d[i] = 1e-6
                num[:, i] = (ekf.model(s, filt, x0 + d)[0] - ekf.model(s, filt, x0 - d)[0]) / 2e-6
            assert np.allclose(H, num, atol=2e-5), (s, filt, np.abs(H - num).max())


def test_each_imm_model_predicts_with_its_own_state():
    ekf = _walking_ekf()
    ekf.x[I_YA] = 0.0                          # walking straight: no yaw acceleration
    ekf.sync_models()
    ekf.mu = np.array([1.0, 0.0])
    ekf._mx[1][I_R] += 0.2                     # the turning model turns 0.2 rad/s faster
    ekf._mx[1][I_YA] = 0.4
    p = ekf.predict_models(0.5)
    assert p[0] == pytest.approx(ekf.predict_attitude(0.5)[0], abs=1e-12)
    assert p[1, :2] == pytest.approx(p[0, :2], abs=1e-12)
    assert p[1, 2] - p[0, 2] == pytest.approx(0.2 * 0.5 + 0.5 * 0.4 * 0.25, abs=1e-9)


def test_state_layout_is_the_documented_one():
    assert (I_F, I_TH, I_R, I_YA) == (0, 1, 5, 6) and list(I_O) == [2, 3, 4]
    lay = StateLayout((2, 4, 2))
    assert lay.n == 7 + 2 * 8 == GaitConfig().dim_x
    assert list(lay.k) == [1, 2, 1, 2, 3, 4, 1, 2] and list(lay.axis) == [0, 0, 1, 1, 1, 1, 2, 2]
    assert list(lay.alpha) == list(range(7, 23, 2)) and list(lay.beta) == list(range(8, 24, 2))
    # the main harmonics: roll and yaw at the stride (k = 1), pitch at the step (k = 2)
    assert [int(lay.k[i]) for i in lay.main] == [1, 2, 1]
    assert list(lay.axis[lay.main]) == [0, 1, 2]
    assert lay.names()[:7] == ['f', 'theta', 'o_roll', 'o_pitch', 'o_yaw', 'yaw_rate',
                               'yaw_accel']


def test_discretisation_is_the_integral_of_the_continuous_model():
    lay = StateLayout((1, 2, 1))
    a = continuous_system(lay, True)
    qc = np.linspace(0.1, 1.0, lay.n) ** 2
    dt = 0.0625
    F, Q = discretise(a, qc, dt)
    assert F == pytest.approx(np.eye(lay.n) + a * dt + a @ a * dt * dt / 2, abs=1e-15)
    s = (np.arange(4000) + 0.5) * dt / 4000          # midpoint rule of int F Qc F^T ds
    Qn = sum((np.eye(lay.n) + a * si + a @ a * si * si / 2) @ np.diag(qc)
             @ (np.eye(lay.n) + a * si + a @ a * si * si / 2).T for si in s) * dt / 4000
    assert Q == pytest.approx(Qn, rel=1e-6, abs=1e-12)


def test_settings_are_validated():
    with pytest.raises(ValueError, match='max_frequency'):
        GaitConfig(min_frequency=2.0, max_frequency=1.5)
    with pytest.raises(ValueError, match='prefilter_cutoff'):
        GaitConfig(prefilter_cutoff=9.0)
    with pytest.raises(ValueError, match='horizon'):
        GaitConfig(horizon=-1.0)


def test_egomotion_rotation_becomes_attitude_increments():
    # the rig pitches 5 deg further down (REP 103 pitch +5 deg about body y)
    r_body = rpy_to_matrix(np.radians([0.0, 5.0, 0.0]))
    r_opt = R_BODY_OPTICAL.T @ r_body @ R_BODY_OPTICAL       # as the camera sees it
    assert egomotion_to_body(r_opt) == pytest.approx(r_body)
    d = rpy_increment(np.radians([0.0, 20.0, 30.0]), egomotion_to_body(r_opt))
    assert np.degrees(d) == pytest.approx([0.0, 5.0, 0.0], abs=1e-9)
    # in the optical frame that is a rotation about optical x (= -body y) by -5 deg
    expect = np.array([[1.0, 0.0, 0.0],
                       [0.0, math.cos(math.radians(5.0)), math.sin(math.radians(5.0))],
                       [0.0, -math.sin(math.radians(5.0)), math.cos(math.radians(5.0))]])
    assert r_opt == pytest.approx(expect)


def test_complementary_filter_recovers_a_swaying_attitude():
    rate = 100.0
    t = np.arange(1500) / rate
    pitch = np.radians(10.0 + 3.0 * np.sin(2 * np.pi * 1.7 * t))
    roll = np.radians(2.0 * np.sin(2 * np.pi * 0.85 * t))
    rpy = np.column_stack([roll, pitch, np.zeros_like(t)])
    R = rpy_to_matrix(rpy)
    acc = R[:, 2, :]                                  # specific force of gravity, body axes
    dr = np.gradient(rpy, 1 / rate, axis=0)
    # body rates from Euler rates (yaw rate 0): w = [dr - sin(p) dy, cos(r) dp, -sin(r) dp]
    gyr = np.column_stack([dr[:, 0], np.cos(roll) * dr[:, 1], -np.sin(roll) * dr[:, 1]])
    est = complementary_filter(acc, gyr, rate, time_constant=1.0)
    assert np.degrees(np.abs(est[200:, :2] - rpy[200:, :2])).max() < 0.3
    t16, y16 = decimate_to(est, rate, 16.0)
    assert t16[1] == pytest.approx(1 / 16) and y16.shape[0] == pytest.approx(240, abs=1)


def test_scoring_helpers():
    t = np.arange(10.0)
    f = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0, 0], bool)
    assert scoring.bouts(t, f) == [(1.0, 3.0), (5.0, 8.0)]
    m = scoring.match_events([1.0, 5.0, 9.0], [1.2, 5.4, 20.0])
    assert list(m.delays) == pytest.approx([0.2, 0.4]) and m.missed == 1 and m.false == 1
    assert scoring.phase_error_percent(0.1, 2 * np.pi + 0.1) == pytest.approx(0.0, abs=1e-9)


def test_heading_references_of_a_constant_rate_turn():
    # heading 0 until t = 1 s, then turning at 0.5 rad/s
    class Walker:
        def heading(self, t):
            return 0.5 * np.maximum(np.asarray(t, float) - 1.0, 0.0)

    t = np.array([0.2, 0.8, 1.05, 1.2, 3.0])
    ref = ev.heading_references(Walker(), t, horizon=0.5, delays=(0.0, 0.1, 0.3))
    assert ref.shape == (5, 5)
    d = math.degrees
    # the rate: before the turn nothing is turning, so every predictor misses the part of
    # the turn inside the horizon (t = 0.8: 0.3 s of it); once turning it is exact
    assert ref[:, 0] == pytest.approx([0.0, d(0.15), 0.0, 0.0, 0.0], abs=1e-6)
    # once turning, the acceleration is that of the ramp (none)
    assert ref[2:, 1] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)
    # the turn known 0 / 0.1 / 0.3 s after it begins (at t = 1.0), perfect afterwards
    assert ref[:, 2] == pytest.approx([0.0, d(0.15), 0.0, 0.0, 0.0], abs=1e-6)
    assert ref[:, 3] == pytest.approx([0.0, d(0.15), d(0.25), 0.0, 0.0], abs=1e-6)
    assert ref[:, 4] == pytest.approx([0.0, d(0.15), d(0.25), d(0.25), 0.0], abs=1e-6)
    # no turn at all: no errors; no heading: None
    class Straight:
        def heading(self, t):
            return np.full(np.shape(t), 0.3)
    assert not np.any(ev.heading_references(Straight(), t))
    assert ev.heading_references(object(), t) is None
    # the simulated turns: each later knowledge costs more
    case = ev.make_case('turn', 0)
    r = ev.heading_references(case.walker, np.arange(1.0, 24.0, 0.0625))
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    assert rms[0] > rms[1] > 0.5 and np.all(np.diff(rms[2:]) > 0) and rms[2] > 0.1, rms


# ---------------------------------------------------------------- the simulated walker

def _run(name, seed, config=None, **kw):
    case = ev.make_case(name, seed)
    run = ev.run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, config, **kw)
    return case, run, ev.score_sim(case, run)


def test_straight_walk_prediction_phase_and_start_stop():
    case, run, sc = _run('walk', 0)
    pred = _rms(sc['pred_err_walk'])
    hold = _rms(sc['hold_err_walk'])
    # measured on this walk (seed 0): roll 0.19, pitch 0.29, yaw 0.84 deg RMS; the yaw is
    # above the 0.7 deg target, which `asmonc gait sim` scores pooled over seeds
    assert pred[0] <= 0.25 and pred[1] <= 0.35 and pred[2] <= 0.85, pred
    assert np.all(pred < 0.5 * hold)
    assert np.all(_rms(sc['phase_err_walk']) <= 2.5)
    assert sc['start_delays'].size == 1 and sc['stop_delays'].size == 1
    assert np.all(np.abs(np.r_[sc['start_delays'], sc['stop_delays']]) <= 0.5)
    assert sc['false'] == 0 and sc['missed'] == 0
    # the frequency is the walker's step frequency (speed-dependent cadence)
    assert np.median(np.abs(sc['frequency_err_walk'])) < 0.05


def test_stops_and_restarts():
    case, run, sc = _run('stop', 0)
    assert sc['start_delays'].size == 2 and sc['stop_delays'].size == 2
    assert np.all(np.abs(np.r_[sc['start_delays'], sc['stop_delays']]) <= 0.5)
    pred = _rms(sc['pred_err_walk'])
    assert pred[1] <= 0.5 and pred[0] <= 0.7 and pred[2] <= 0.7, pred
    # not walking: the frozen model predicts the current attitude
    standing = ~run.walking & (run.times > 14) & (run.times < 15)
    assert standing.any()
    assert np.degrees(np.abs(run.predicted[standing, 1] - run.attitude[standing, 1])).max() < 0.5


def test_turning_and_uphill_keep_the_model():
    _, run, sc = _run('turn', 0)
    pred, hold = _rms(sc['pred_err_walk']), _rms(sc['hold_err_walk'])
    assert pred[2] < 0.75 * hold[2]                 # yaw through two turns
    assert pred[1] <= 0.5
    assert run.walking[run.times > 3].all()         # never taken for a stop
    _, run, sc = _run('uphill', 0)
    pred = _rms(sc['pred_err_walk'])
    assert pred[1] <= 0.5 and run.walking[run.times > 3].all()


def test_a_bend_is_not_walking():
    _, run, _ = _run('bend', 0)
    assert not run.walking.any()


def test_out_of_order_and_bad_samples():
    tr = GaitTracker()
    assert tr.add_inclinometer(1.0, [0.0, 0.3, 0.0]) is not None
    assert tr.add_inclinometer(0.9, [0.0, 0.3, 0.0]) is None
    assert tr.add_inclinometer(1.0, [0.0, 0.3, 0.0]) is None
    assert tr.stats.out_of_order == 2
    with pytest.raises(ValueError):
        tr.add_inclinometer(1.1, [np.nan, 0.3, 0.0])
    est = tr.add_inclinometer(1.0625, [0.0, 0.3, 3.1])
    assert est.walking is False and est.predicted[1] == pytest.approx(0.3, abs=0.01)


def test_inclinometer_gap_stops_the_walk_without_visual_motion():
    case = ev.make_case('walk', 1)
    run = ev.run_tracker(case.imu_times, case.imu_rpy, case.imu_variance,
                         drop_inclinometer=(12.0, 14.0))
    events = [e for _, e in run.events]
    assert 'gap' in events
    assert run.walking[(run.times > 18) & (run.times < 24)].all()    # found again


# ---------------------------------------------------------------- fusion

def test_fusion_beats_either_source_and_survives_dropouts():
    sigma = 0.2
    cfg = GaitConfig(egomotion_sigma_deg=sigma)
    case = ev.make_case('walk', 2)
    ego = ev.simulate_egomotion(case.walker, case.duration, sigma, rng=7)
    res = {}
    for mode, kw in {'imu': {}, 'ego': dict(egomotion=ego, use_inclinometer=False),
                     'fused': dict(egomotion=ego)}.items():
        run = ev.run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, cfg, **kw)
        res[mode] = ev.score_sim(case, run)
    pitch = {m: _rms(r['pred_err_walk'])[1] for m, r in res.items()}
    motion = {m: float(np.sqrt(np.sum(_rms(r['motion_err_walk']) ** 2))) for m, r in res.items()}
    # pitch (the critical angle for DGPR) 0.5 s ahead, and the predicted rig rotation
    # over the horizon (all three axes)
    assert pitch['fused'] < pitch['imu'] and pitch['fused'] < pitch['ego'], pitch
    assert motion['fused'] < motion['imu'] and motion['fused'] < motion['ego'], motion

    # either source silent for 4 s: the walk model goes on
    for drop in ('drop_egomotion', 'drop_inclinometer'):
        run = ev.run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, cfg,
                             egomotion=ego, **{drop: (12.0, 16.0)})
        inside = (run.times > 12.5) & (run.times < 16.0)
        assert run.walking[inside].all(), drop
        _, th = case.walker.states(run.times[inside] + 0.5)
        err = scoring.angle_errors_deg(run.predicted[inside], th)
        assert _rms(err)[1] < 0.8 and _rms(err)[0] < 0.8, (drop, _rms(err))


# ---------------------------------------------------------------- the stride model

def _stride_walk(seed: int, f_stride: float = 0.9, duration: float = 14.0):
    """A synthetic 16 Hz attitude stream whose pitch moves mainly at the *stride*
    frequency (as two of the three real lower-back recordings do): standing 2 s, then
    walking. Returns (t, rpy, truth(t) -> rpy)."""
    rng = np.random.default_rng(seed)
    d = np.radians

    def truth(t):
        t = np.asarray(t, float)
        env = np.clip((t - 2.0) / 0.8, 0.0, 1.0)
        th = 2 * np.pi * f_stride * t
        roll = d(1.5) * np.sin(th + 0.5) + d(0.4) * np.sin(2 * th + 2.0)
        pitch = d(12.0) + d(1.8) * np.sin(th + 1.0) + d(0.9) * np.sin(2 * th - 0.4)
        yaw = d(30.0) + d(3.0) * np.sin(th + 2.5) + d(0.5) * np.sin(2 * th)
        return np.column_stack([roll * env, pitch - d(12.0) * (1 - env) * 0 + (pitch - d(12.0))
                                * (env - 1), yaw]) if False else np.column_stack(
            [env * roll, d(12.0) + env * (pitch - d(12.0)), d(30.0) + env * (yaw - d(30.0))])

    t = np.arange(int(duration * 16)) / 16.0
    rpy = truth(t) + rng.normal(0.0, d(0.1), (t.size, 3))
    return t, rpy, truth


def test_pitch_at_the_stride_locks_onto_the_step_frequency():
    """The paper's model puts pitch at the step frequency only; with pitch mainly at the
    stride it would lock at half the cadence. The stride-harmonic model finds the step
    frequency (twice the stride's) and predicts pitch well."""
    t, rpy, truth = _stride_walk(1)
    cfg = GaitConfig(sensor_lag=0.0)
    run = ev.run_tracker(t, rpy, math.radians(0.1) ** 2, cfg)
    late = run.times > 7.0
    assert run.walking[late].all()
    assert np.median(run.frequency[late]) == pytest.approx(1.8, abs=0.08)
    err = scoring.angle_errors_deg(run.predicted[late], truth(run.times[late] + 0.5))
    hold = scoring.angle_errors_deg(rpy[late], truth(run.times[late] + 0.5))
    assert _rms(err)[1] < 0.5 * _rms(hold)[1], (_rms(err), _rms(hold))


def _initiation_walk(seed: int, lean_deg: float = 4.0, shift_deg: float = 2.0,
                     f_step: float = 1.8, duration: float = 8.0):
    """A synthetic 16 Hz walk whose start shifts the trunk, as a real gait initiation
    does: from t = 2 s the gait builds up over 0.8 s while the pitch leans forward by
    ``lean_deg`` (a half-cosine over 1.5 s) and the roll shifts sideways by up to
    ``shift_deg`` and back. Returns (t, rpy, truth(t) -> rpy)."""
    rng = np.random.default_rng(seed)
    d = np.radians

    def truth(t):
        t = np.asarray(t, float)
        env = np.clip((t - 2.0) / 0.8, 0.0, 1.0)
        u = np.clip((t - 2.0) / 1.5, 0.0, 1.0)
        th = np.pi * f_step * t
        roll = env * (d(1.5) * np.sin(th + 0.5) + d(0.4) * np.sin(2 * th + 2.0)) \
            + d(shift_deg) * np.sin(np.pi * u)
        pitch = d(12.0) + env * (d(0.8) * np.sin(th + 1.0) + d(1.5) * np.sin(2 * th - 0.4)) \
            + d(lean_deg) * (0.5 - 0.5 * np.cos(np.pi * u))
        yaw = d(30.0) + env * (d(3.0) * np.sin(th + 2.5) + d(0.5) * np.sin(2 * th))
        return np.column_stack([roll, pitch, yaw])

    t = np.arange(int(duration * 16)) / 16.0
    return t, truth(t) + rng.normal(0.0, d(0.1), (t.size, 3)), truth


def test_a_trunk_shift_at_the_walk_start_goes_into_the_offsets():
    """At a walk start the roll and pitch offsets start with the start fit's own
    uncertainty (a 1 s window holds less than a stride), not a fixed 0.5 deg: the trunk's
    lean and sideways shift of a gait initiation then move the offsets instead of pulling
    the step frequency away (with the fixed spread it ran 0.3 Hz off and needed a
    relock) and the 0.5 s roll/pitch prediction follows."""
    cfg = GaitConfig(sensor_lag=0.0)
    for seed in (0, 1):
        t, rpy, truth = _initiation_walk(seed)
        tr = GaitTracker(cfg)
        rows = []
        for ti, zi in zip(t, rpy):
            est = tr.add_inclinometer(ti, zi, np.full(3, math.radians(0.1) ** 2))
            if est.event == 'start':
                sd = np.degrees(np.sqrt(np.diag(tr.ekf.P)[I_O]))
                assert sd[2] == pytest.approx(0.5)                # yaw: as before
                assert np.all(sd[:2] > 0.8), sd                   # roll, pitch: the fit's
            rows.append((ti, est.walking, est.step_frequency, est.predicted))
        assert [e for _, e in tr.stats.events] == ['start']    # no relock, no stop
        tt = np.array([r[0] for r in rows])
        walking = np.array([r[1] for r in rows])
        sel = walking & (tt >= 2.5) & (tt <= 5.0)
        freq = np.array([r[2] for r in rows])[sel]
        assert np.max(np.abs(freq - 1.8)) < 0.2, freq
        pred = np.array([r[3] for r in rows])[sel]
        err = _rms(scoring.angle_errors_deg(pred, truth(tt[sel] + 0.5)))
        assert err[0] < 1.45 and err[1] < 1.45, err


def test_turning_model_takes_over_in_a_turn_only():
    case = ev.make_case('turn', 1)
    tr = GaitTracker()
    mu = []
    for t, z in zip(case.imu_times, case.imu_rpy):
        tr.add_inclinometer(t, z, np.full(3, case.imu_variance))
        mu.append(tr.ekf.mu[1])
    mu = np.array(mu)
    t = case.imu_times
    rate = np.degrees(np.abs(np.gradient(case.walker.traj.heading(t), t)))
    # the turning model takes over at the turns' beginnings (the straight one, mixed
    # with it, then carries on at a steady rate)
    for t0, t1 in ((6.0, 8.0), (15.0, 16.5)):
        assert mu[(t > t0) & (t < t1)].max() > 0.8
    assert np.median(mu[(rate < 1.0) & (t > 3)]) < 0.1           # walking straight
    assert tr.stats.turns >= 2
    assert np.all(np.abs(mu - np.clip(mu, 0.0, 1.0)) == 0.0)


def test_skill_weighting_keeps_the_turning_model_through_a_turn():
    """At a turn's onset the straight model mispredicts for half a second, and holding
    the measurement then errs more for the rest of the turn. With the yaw skill scored
    per IMM model, those errors must not make the prediction fall back on holding once
    the turning model has taken over: through two turns the skill-weighted yaw prediction
    is no worse than the model's own (with one skill for the mixture it was 18 % worse),
    and while the turning model leads, the weight stays on it."""
    case = ev.make_case('turn', 0)
    tr = GaitTracker()
    rows = []
    for t, z in zip(case.imu_times, case.imu_rpy):
        est = tr.add_inclinometer(t, z, np.full(3, case.imu_variance))
        rows.append((t, est.predicted[2], est.predicted_model[2], tr.ekf.mu[1],
                     tr.skill_weights()[2]))
    t, pred, model, mu, w = (np.array(c) for c in zip(*rows))
    sel = (t > 3.0) & (t + 0.5 < case.duration)
    truth = case.walker.states(t[sel] + 0.5)[1][:, 2]
    err_w = np.degrees(np.sqrt(np.mean((pred[sel] - truth) ** 2)))
    err_m = np.degrees(np.sqrt(np.mean((model[sel] - truth) ** 2)))
    assert err_w <= err_m, (err_w, err_m)
    turning = sel & (mu > 0.5)
    assert turning.sum() > 32 and np.mean(w[turning]) > 0.6, np.mean(w[turning])
    # the models' weights differ in yaw only
    rw = tr.model_skill_weights()
    assert rw[0, :2] == pytest.approx(rw[1, :2])


def test_skill_weighting_falls_back_on_the_measurement():
    """A walk whose phase jumps at random about every half second: the model locks on and
    then mispredicts; weighting it by its recent skill must keep the prediction near
    holding the measurement, and much better than the model alone."""
    rng = np.random.default_rng(4)
    t = np.arange(16 * 20) / 16.0
    jumps = np.cumsum(rng.uniform(-3.0, 3.0, t.size) * (rng.uniform(size=t.size) < 1 / 8))
    th = 2 * np.pi * 0.9 * t + jumps
    env = np.clip((t - 2.0) / 0.8, 0.0, 1.0)[:, None]
    rpy = np.radians(env * np.column_stack([1.5 * np.sin(th), 2.0 * np.sin(2 * th + 0.3),
                                            3.0 * np.sin(th + 2.0)]))
    rpy += np.radians([0.0, 12.0, 30.0])
    res = {}
    for on in (True, False):
        run = ev.run_tracker(t, rpy, math.radians(0.1) ** 2,
                             GaitConfig(sensor_lag=0.0, skill_weighting=on, fallback=False))
        sel = run.walking & (run.times > 6) & (run.times + 0.5 < t[-1])
        later = np.column_stack([np.interp(run.times + 0.5, t, rpy[:, a]) for a in range(3)])
        res[on] = _rms(scoring.angle_errors_deg(run.predicted[sel], later[sel]))
        hold = _rms(scoring.angle_errors_deg(rpy[sel], later[sel]))
    assert np.sum(res[True] ** 2) < 0.6 * np.sum(res[False] ** 2), res
    assert np.all(res[True] < 1.2 * hold), (res, hold)


def test_a_relock_restarts_the_skill_record():
    """The skill record (E em^2, E em eh) scores the predictions of the oscillation that
    made them. A relock replaces the oscillation by a new fit, so the record restarts
    from the walk-start prior (here the skill of the walk so far, the long memory), as at
    a start. Before, the old oscillation's record went on: on HA/001 Test5 Trial2 a
    pitch weight of 1 learnt during a forward lean (raw minimum-MSE weight 2-2.5, both
    predictors lagging it) was applied to the oscillation refitted over that lean,
    10 deg off (pitch -22 % against holding; now 0 %)."""
    t, rpy, _ = _stride_walk(1, duration=9.0)
    tr = GaitTracker(GaitConfig(sensor_lag=0.0))
    for ti, zi in zip(t, rpy):
        tr.add_inclinometer(ti, zi, np.full(3, math.radians(0.1) ** 2))
    assert tr.walking and tr.stats.relocks == 0
    w_walk = tr.model_skill_weights()
    assert np.all(w_walk[:, 1] > 0.5), w_walk           # the model predicts pitch well
    # a record that says the current oscillation mispredicts (w ~ 0.01) ...
    tr._e2m[:] = 100.0 * tr._e2h
    tr._emh[:] = 0.0
    assert np.all(tr.model_skill_weights() < 0.02)
    # ... belongs to it, not to the oscillation a relock fits
    tau, z = tr.detector.window(2.0)
    fit = fit_walk(tau, z, np.arange(1.0, 2.81, 0.02), tr.cfg.harmonics)
    tr._start(float(t[-1]), fit, relock=True)
    w = tr.model_skill_weights()
    assert np.all(w[:, 1] > 0.5), w
    assert not tr._past                                  # no scoring of the old predictions


def test_stop_amplitudes_do_not_depend_on_the_phase():
    tau = np.arange(-9, 1) / 16.0                              # a 0.6 s window
    for phase in np.linspace(0.0, 2 * np.pi, 7):
        m = np.radians(2.0) * np.column_stack([np.sin(2 * np.pi * 0.95 * tau + phase),
                                               np.sin(2 * np.pi * 1.9 * tau + phase)])
        a_m = np.radians(2.0)                                  # the model's amplitude
        g, a = stop_amplitudes(tau, m + 0.3, m, a_m)          # offsets do not count
        assert np.degrees([g, a]) == pytest.approx([2.0, 2.0], rel=1e-6)
        g, a = stop_amplitudes(tau, 0.4 * m + 0.01 * tau[:, None], m, a_m)
        assert np.degrees([g, a]) == pytest.approx([0.8, 0.8], rel=1e-6)
    assert stop_amplitudes(tau, np.zeros((10, 2)), np.zeros((10, 2)), 0.0) == (0.0, 0.0)


def test_walk_fit_finds_the_stride_harmonics():
    t, rpy, truth = _stride_walk(0)
    pf = Prefilter(16.0, 0.0)
    sel = (t > 6.0) & (t <= 8.5)
    tau = t[sel] - t[sel][-1]
    det = WalkDetector(GaitConfig())
    from asmonc_vision.core.gait.detector import LOCK_CRITERION
    fit = fit_walk(tau, truth(t[sel]), det.freqs, (2, 4, 2), *LOCK_CRITERION)
    assert fit.frequency == pytest.approx(1.8, abs=0.03)
    # pitch: 1.8 deg at the stride (k = 1), 0.9 deg at the step (k = 2)
    assert np.degrees(abs(fit.harmonic(1, 1))) == pytest.approx(1.8, abs=0.1)
    assert np.degrees(abs(fit.harmonic(1, 2))) == pytest.approx(0.9, abs=0.1)
    assert np.degrees(fit.residual).max() < 0.05
    assert pf.response(1.0) == 1.0


def test_vector_response_lookup_matches_the_scalar_one():
    pf = Prefilter(16.0, 6.0, 2, sensor_lag=0.08)
    f = np.array([0.45, 0.9, 1.85, 3.7, 7.9])
    vec = pf.gain_phase_array(f)
    for i, fi in enumerate(f):
        assert [v[i] for v in vec] == pytest.approx(pf.gain_phase(float(fi)))


def test_lag_correction_is_the_difference_of_the_model_attitudes():
    ekf = _walking_ekf()
    pf = Prefilter(16.0, 6.0, 2, sensor_lag=0.08)
    for s in (0.0, -0.3, 0.4):
        expect = ekf.model(s)[0] - ekf.model(s, pf)[0]
        # (model() interpolates the response from tables: 1e-8 rad)
        assert ekf.lag_correction(s, pf) == pytest.approx(expect, abs=1e-7)
        assert ekf.attitude(s, pf) == pytest.approx(ekf.model(s, pf)[0], abs=1e-7)


# ---------------------------------------------------------------- compiled kernels

def _kernels():
    """(module, name) of every numba kernel of the filter step (``core.jit``)."""
    from asmonc_vision.core.gait import detector, model, tracker
    return ([(model, n) for n in ('_nb_imm_predict', '_nb_imm_update', '_nb_combine',
                                  '_nb_predict_attitude')]
            + [(detector, '_nb_stop_sums'), (tracker, '_nb_nis2'), (tracker, '_nb_score')])


def _need_kernels():
    GaitTracker()                               # compiles (or loads) the kernels
    if any(getattr(mod, name) is None for mod, name in _kernels()):
        pytest.skip('numba not installed')


def _numpy_path(mp):
    """Switch the kernels off: the numpy path runs."""
    for mod, name in _kernels():
        mp.setattr(mod, name, None)


def test_compiled_filter_step_equals_the_numpy_path(monkeypatch):
    """The filter step's kernels give what its numpy path gives, sample by sample, over
    walk starts, stops and turns: the same operations and BLAS/LAPACK calls (bit-identical
    where numba's BLAS is numpy's; 1e-12 rad allowed)."""
    _need_kernels()
    for name in ('stop', 'turn'):
        case = ev.make_case(name, 0)
        runs = []
        for numpy_path in (False, True):
            with monkeypatch.context() as mp:
                if numpy_path:
                    _numpy_path(mp)
                runs.append(ev.run_tracker(case.imu_times, case.imu_rpy, case.imu_variance))
        a, b = runs
        assert a.events == b.events and a.events, name
        for f in ('walking', 'attitude', 'predicted', 'predicted_std', 'phase', 'frequency',
                  'motion'):
            np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=0, atol=1e-12,
                                       err_msg=f'{name} {f}')


@pytest.mark.parametrize('mu_turn', [0.3, 0.05])        # both iterated / the turn one step
def test_compiled_imm_prediction_and_update_equal_the_numpy_path(monkeypatch, mu_turn):
    _need_kernels()
    pf = Prefilter(16.0, 6.0, 2, sensor_lag=0.08)
    z = np.radians([1.4, 20.1, 31.0])
    R = np.diag(np.radians([1.2, 1.0, 1.5]) ** 2)
    out = []
    for numpy_path in (False, True):
        with monkeypatch.context() as mp:
            if numpy_path:
                _numpy_path(mp)
            ekf = _walking_ekf()
            ekf.mu = np.array([1.0 - mu_turn, mu_turn])
            ekf._mx[1][I_R] += 0.1                       # the models differ
            ekf._mx[1][I_TH] += 0.2
            ekf.predict_to(1.0 / 16.0)
            got = [ekf.mu.copy(), ekf._mx.copy(), ekf._mP.copy(), ekf.x.copy(), ekf.P.copy()]
            got.append(ekf.update_attitude(z, R, -0.02, pf))           # measured attitude
            got += [ekf.mu.copy(), ekf._mx.copy(), ekf._mP.copy(), ekf.x.copy(),
                    ekf.P.copy(), ekf.last_y, ekf.last_S, ekf.iterations_used]
            got += list(ekf.predict_attitude(0.5))
            ekf.update_attitude(z + 0.01, R)                           # true attitude
            got += [ekf.x.copy(), ekf.P.copy(), ekf.mu.copy()]
            ekf.stop_walking()                                         # not walking
            ekf.predict_to(2.0 / 16.0)
            ekf.update_attitude(z, R, 0.0, pf)
            got += [ekf.x.copy(), ekf.P.copy(), ekf.mu.copy()]
            got += list(ekf.predict_attitude(0.5))
            out.append(got)
    for i, (a, b) in enumerate(zip(*out)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13, err_msg=str(i))


@pytest.mark.parametrize('n', [4, 7, 8, 10, 37, 64])    # numpy sums 8 at a time from 8 on
def test_compiled_stop_test_sums_equal_the_numpy_path(n):
    from asmonc_vision.core.gait import detector
    _need_kernels()
    rng = np.random.default_rng(n)
    tau = (np.arange(n) - n + 1) / 16.0
    z, m = rng.normal(0.0, 0.02, (n, 2)), rng.normal(0.0, 0.02, (n, 2))
    q = detector._trend_basis(tau)
    assert detector._nb_stop_sums(q, z, m) == pytest.approx(detector._stop_sums(q, z, m),
                                                            rel=1e-13, abs=0.0)


def test_compiled_normalised_innovation_equals_the_numpy_path(monkeypatch):
    from asmonc_vision.core.gait import tracker
    _need_kernels()
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.normal(size=(3, 3))
        S, y = a @ a.T + np.eye(3), rng.normal(size=3)
        with monkeypatch.context() as mp:
            mp.setattr(tracker, '_nb_nis2', None)
            expect = tracker._nis2(y, S)
        assert tracker._nis2(y, S) == pytest.approx(expect, rel=1e-13, abs=0.0)
