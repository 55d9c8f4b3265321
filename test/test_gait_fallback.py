"""The walk model's fallback rule (hold the last measurement where the prediction's own
recent error is worse) and the inclinometer jump rule, alone, in the tracker and in the
gait node."""
from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from asmonc_vision.core.gait import GaitConfig, GaitTracker  # noqa: E402
from asmonc_vision.core.gait.fallback import FALLBACK_MIN_SCORED, PredictionFallback  # noqa: E402
from asmonc_vision.core.gait.jump import JumpRule  # noqa: E402

RATE = 16.0
D = math.radians


def _feed(fb: PredictionFallback, t, z, pred, held):
    for i in range(len(t)):
        fb.score(t[i], z[i])
        fb.push(t[i], pred[i], held[i])


def _signal(n: int, seed: int = 0):
    """A pitch oscillation at 1 Hz sampled at 16 Hz, with the true value 0.5 s later."""
    t = np.arange(n) / RATE
    z = np.zeros((n, 3))
    z[:, 1] = D(3.0) * np.sin(2 * np.pi * t)
    return t, z


def test_a_good_model_is_kept_and_a_bad_one_falls_back_per_axis():
    t, z = _signal(400)
    truth_later = np.zeros_like(z)
    truth_later[:, 1] = D(3.0) * np.sin(2 * np.pi * (t + 0.5))
    fb = PredictionFallback(0.5, 15.0, 0.1)
    # pitch: the model predicts the future exactly, far better than holding
    _feed(fb, t, z, truth_later, z)
    assert not fb.holding.any()
    m2, h2, n = fb.mean_squares()
    assert n > 0 and m2[1] < 1e-12 < h2[1]
    assert fb.apply(truth_later[-1], z[-1]) == pytest.approx(truth_later[-1])

    # pitch: a model off by 5 deg (holding errs by at most 2 x 3 deg) -> hold pitch only
    fb = PredictionFallback(0.5, 15.0, 0.1)
    bad = truth_later.copy()
    bad[:, 1] += D(5.0)
    _feed(fb, t, z, bad, z)
    assert fb.holding.tolist() == [False, True, False]
    out = fb.apply(bad[-1], z[-1])
    assert out[1] == z[-1, 1] and out[0] == bad[-1, 0]


def test_nothing_is_decided_before_enough_predictions_are_scored_and_old_ones_age_out():
    t, z = _signal(200)
    fb = PredictionFallback(0.5, 3.0, 0.1)
    bad = z + np.array([0.0, D(10.0), 0.0])
    n_early = int((0.5 + FALLBACK_MIN_SCORED) * RATE) - 2
    _feed(fb, t[:n_early], z[:n_early], bad[:n_early], z[:n_early])
    assert not fb.holding.any()                       # too few scored yet
    _feed(fb, t[n_early:100], z[n_early:100], bad[n_early:100], z[n_early:100])
    assert fb.holding[1]
    # the model becomes exact: once the window (3 s) has forgotten the bad record, back
    good = np.zeros_like(z)
    good[:, 1] = D(3.0) * np.sin(2 * np.pi * (t + 0.5))
    _feed(fb, t[100:], z[100:], good[100:], z[100:])
    assert not fb.holding.any()
    assert fb.switches == 2
    assert fb.mean_squares()[2] <= 3.0 * RATE + 1


def test_the_margin_is_a_hysteresis():
    """A model 5 % worse than holding: within a margin of 10 % it stays; with no margin
    it falls back, and once holding, the same errors keep holding under a margin of
    10 % (back only when the model is better)."""
    t, z = _signal(600)
    future = np.roll(z, -8, axis=0)                   # the measurement 0.5 s later
    held = np.zeros_like(z)                           # holding errs by -future
    pred = -0.05 * future                             # the model by -1.05 future
    fb = PredictionFallback(0.5, 15.0, 0.1)
    _feed(fb, t[:300], z[:300], pred[:300], held[:300])
    assert not fb.holding[1]
    fb = PredictionFallback(0.5, 15.0, 0.0)
    _feed(fb, t[:300], z[:300], pred[:300], held[:300])
    assert fb.holding[1]
    fb.margin = 0.1
    _feed(fb, t[300:], z[300:], pred[300:], held[300:])
    assert fb.holding[1] and fb.switches == 1


def test_settings_are_validated():
    with pytest.raises(ValueError):
        PredictionFallback(0.5, 0.0, 0.1)
    with pytest.raises(ValueError):
        GaitConfig(fallback_window=1.0)
    with pytest.raises(ValueError):
        GaitConfig(fallback_margin=-0.1)
    with pytest.raises(ValueError):
        GaitConfig(jump_deg=0.0)


def test_the_tracker_publishes_the_held_measurement_on_falling_back_axes():
    """A real daily-living walk (stops, turns, irregular steps), where the walk model
    is at times worse than holding: the fallback rule holds there, the estimate says
    which axes it holds and carries the measurement on them, and over the walk the
    result is no worse than the model alone."""
    from asmonc_vision.eval import gait_real as gait
    from asmonc_vision.eval.gait_walks import DEFAULT_DATA

    assert (DEFAULT_DATA / 'data_csv').is_dir(), \
        f'the real walking recordings are missing: {DEFAULT_DATA}'
    rec = gait.load_real(DEFAULT_DATA, tests=('Test11',))[0]
    cfg = gait.real_config()
    off = GaitTracker(dataclasses.replace(cfg, fallback=False))
    on = GaitTracker(cfg)
    e_model, e_fall, holding = [], [], 0
    for i in range(rec.times.size - 8):
        t, z = float(rec.times[i]), rec.rpy[i]
        a = off.add_inclinometer(t, z, gait.REAL_SIGMA ** 2)
        b = on.add_inclinometer(t, z, gait.REAL_SIGMA ** 2)
        assert a.fallback is None and b.fallback is not None
        if b.fallback.any():
            held = np.flatnonzero(b.fallback)
            holding += 1
            assert b.predicted[held] == pytest.approx(z[held])
            assert np.all(np.diag(b.predicted_covariance)[held] > 0)
        else:
            assert b.predicted == pytest.approx(a.predicted)
        later = np.interp(t + 0.5, rec.times, rec.rpy[:, 1])
        e_model.append(a.predicted[1] - later)
        e_fall.append(b.predicted[1] - later)
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    assert on.fallback.switches >= 1 and holding > 0
    assert rms(e_fall) <= rms(e_model)


# --- the jump rule -----------------------------------------------------------------

def test_a_spike_is_rejected_and_the_stream_goes_on():
    rule = JumpRule(25.0, 400.0, 1.0)
    t = np.arange(40) / RATE
    verdicts = []
    for i, ti in enumerate(t):
        pitch = D(2.0) * math.sin(ti) + (D(90.0) if 10 <= i < 14 else 0.0)
        verdicts.append(rule.check(ti, [0.0, pitch, 0.0]))
    assert verdicts[:10] == ['ok'] * 10
    assert verdicts[10:14] == ['jump', 'held', 'held', 'held']
    assert verdicts[14:] == ['ok'] * 26
    assert rule.jumps == 1 and not rule.faulty


def test_a_new_attitude_that_holds_is_accepted_after_settling_and_slow_changes_are_no_jump():
    rule = JumpRule(25.0, 400.0, 1.0)
    v = [rule.check(i / RATE, [0.0, D(90.0) if i >= 5 else 0.0, 0.0]) for i in range(40)]
    assert v[5] == 'jump' and set(v[6:21]) == {'held'} and v[21] == 'settled'
    assert set(v[22:]) == {'ok'}
    # 30 deg over 0.5 s (60 deg/s: a deep bend) is a movement, not a jump
    rule = JumpRule(25.0, 400.0, 1.0)
    assert rule.check(0.0, [0, 0, 0]) == 'ok'
    assert rule.check(0.5, [0, D(30.0), 0]) == 'ok'
    # yaw is not judged (a compass wraps and swings)
    assert rule.check(0.5625, [0, D(30.0), D(170.0)]) == 'ok'
    with pytest.raises(ValueError):
        JumpRule(25.0, 0.0, 1.0)


# --- the gait node -----------------------------------------------------------------

ROS_DOMAIN_OFFSET = 71
DEADLINE = 30.0


def test_the_gait_node_reports_a_jump_and_keeps_it_out_of_its_filter(ros):
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import Imu

    from asmonc_vision.eval import gait_walks as ev
    from asmonc_vision.nodes.common import RESULT_QOS, SENSOR_QOS
    from asmonc_vision.nodes.compass_node import imu_message
    from asmonc_vision.nodes.conversions import ns_to_stamp
    from asmonc_vision.nodes.gait_node import GaitFilterNode
    from asmonc_vision_msgs.msg import GaitState

    t0_ns = 1_700_000_000_000_000_000
    ctx, add, spin_until, spin_for = ros.ctx, ros.add, ros.spin_until, ros.spin_for
    probe = add(Node('gait_jump_probe', context=ctx))
    states: list = []
    diags = ros.diagnostics(probe, 'gait_filter_node')
    probe.create_subscription(GaitState, '/gait/state', states.append, RESULT_QOS)
    pub = probe.create_publisher(Imu, '/inclinometer/imu', SENSOR_QOS)
    node = add(GaitFilterNode(context=ctx, parameter_overrides=[
        Parameter('timeout', value=2.0)]))
    spin_until(lambda: pub.get_subscription_count() > 0, 'the node to subscribe')
    case = ev.make_case('walk', 0)
    n = int(np.searchsorted(case.imu_times, 10.0))
    jump = range(n - 40, n - 35)                      # 5 samples (0.3 s) 90 deg off
    for i in range(n):
        rpy = case.imu_rpy[i].copy()
        if i in jump:
            rpy[1] += D(90.0)
        t = float(case.imu_times[i])
        pub.publish(imu_message(rpy, np.full(3, case.imu_variance),
                                ns_to_stamp(t0_ns + int(round(t * 1e9))), 'inclinometer_link'))
        spin_for(0.004)
    spin_until(lambda: len(states) >= n - 3, f'{n} GaitState messages')
    # (best effort: a sample may be lost under load)
    assert node.counts['imu_jumps'] == 1 and 1 <= node.counts['imu_jump_samples'] <= 5
    assert node.counts['resets'] == 0
    spin_until(lambda: any('jump' in s.message and s.level == b'\x01' for s in diags),
               'a jump WARN')
    # not poisoned: still walking, no jump in the states, the prediction still good
    # (the stream's own states: on a loaded machine the node may also publish a
    # "silent" hold stamped by its clock between two samples)
    states = [s for s in states if abs(s.header.stamp.sec - t0_ns // 10 ** 9) < 3600]
    pitch = np.array([s.predicted[1] for s in states])
    assert np.ptp(pitch) < D(10.0)             # the walk's pitch spans < 5 deg; 90 is off
    last = states[-1]
    assert last.walking
    stamp_s = last.header.stamp.sec + last.header.stamp.nanosec * 1e-9 - t0_ns * 1e-9
    _, truth = case.walker.states(np.array([stamp_s + 0.5]))
    assert abs(math.degrees(last.predicted[1] - truth[0, 1])) < 1.5
