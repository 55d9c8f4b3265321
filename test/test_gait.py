"""The walk model (core.gait): prefilter response, model Jacobian, the tracker on the
simulator's walker (prediction, phase, walk start/stop, turns, uphill, a bend), visual
motion fused in, dropouts, out-of-order stamps, speed. Fixed seeds throughout."""
import math
import time

import numpy as np
import pytest

from asmonc_vision.cli import gait as ev
from asmonc_vision.core.gait import GaitConfig, GaitTracker, scoring
from asmonc_vision.core.gait.attitude import complementary_filter, decimate_to
from asmonc_vision.core.gait.model import I_A, I_B, I_D, I_F, I_O, I_PH, I_R, WalkModelEKF
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


def test_model_jacobian_matches_finite_differences():
    cfg = GaitConfig()
    ekf = WalkModelEKF(cfg)
    ekf.initialise(0.0, np.radians([1.0, 20.0, 30.0]), np.full(3, 1e-4))
    ekf.start_walking(1.85, np.radians([2.0, 1.8, 2.5]), [0.3, -1.2, 2.0],
                      np.radians([0.5, 21.0, 30.0]), math.radians(4.0),
                      harmonic=(math.radians(0.3), 0.7))
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


def test_state_layout_is_the_documented_one():
    assert (I_F, I_R, I_B, I_D) == (0, 10, 11, 12)
    assert list(I_A) == [1, 4, 7] and list(I_PH) == [2, 5, 8] and list(I_O) == [3, 6, 9]


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


# ---------------------------------------------------------------- the simulated walker

def _run(name, seed, config=None, **kw):
    case = ev.make_case(name, seed)
    run = ev.run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, config, **kw)
    return case, run, ev.score_sim(case, run)


def test_straight_walk_prediction_phase_and_start_stop():
    case, run, sc = _run('walk', 0)
    pred = _rms(sc['pred_err_walk'])
    hold = _rms(sc['hold_err_walk'])
    assert pred[1] <= 0.5 and pred[0] <= 0.7 and pred[2] <= 0.8, pred
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


# ---------------------------------------------------------------- speed

def test_filter_step_is_well_under_a_millisecond():
    case = ev.make_case('walk', 3)
    tr = GaitTracker()
    cpu = []
    for t, z in zip(case.imu_times, case.imu_rpy):
        c0 = time.thread_time()
        tr.add_inclinometer(t, z, np.full(3, case.imu_variance))
        cpu.append(time.thread_time() - c0)
    cpu = np.array(cpu) * 1e3
    assert np.median(cpu) < 1.0, np.median(cpu)
