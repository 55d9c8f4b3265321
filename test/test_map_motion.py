"""The evidence map's motion predicted from the motions measured before each pair."""
from __future__ import annotations

import numpy as np
import pytest

from asmonc_vision.core.map_motion import MotionPredictor, relative, scale_motion
from asmonc_vision.core.motion.geometry import compose, so3_exp

STEP_NS = 100_000_000     # 10 Hz


def walk(n: int, seed: int = 0):
    """Poses of a swaying walk, ~1.2 m/s forward (z), turning slowly, bobbing."""
    rng = np.random.default_rng(seed)
    poses = [(np.eye(3), np.zeros(3))]
    for k in range(1, n):
        w = np.array([0.02 * np.sin(k), 0.03 + 0.01 * rng.standard_normal(), 0.0])
        t = np.array([0.01 * np.sin(0.5 * k), 0.02 * np.sin(1.3 * k), 0.12])
        poses.append(compose(*poses[-1], so3_exp(w), t))
    return poses


def pose_error(a, b) -> float:
    return float(np.linalg.norm(a[1] - b[1]))


def test_constant_translation_is_predicted_exactly():
    p = MotionPredictor()
    t = np.array([0.0, 0.0, 0.12])
    assert p.predict(0) is None                      # nothing measured yet
    p.add_motion(0, STEP_NS, np.eye(3), t)
    assert p.predict(STEP_NS) is None                # no previous pair given
    for k in range(2, 6):
        m = p.predict(k * STEP_NS)
        assert m is not None
        assert p.ahead_ns == STEP_NS                 # one pair past the newest measurement
        np.testing.assert_allclose(m[1], t, atol=1e-12)
        np.testing.assert_allclose(m[0], np.eye(3), atol=1e-12)
        p.add_motion((k - 1) * STEP_NS, k * STEP_NS, np.eye(3), t)


@pytest.mark.parametrize('lag', [1, 2])
def test_prediction_errors_are_corrected_not_summed(lag):
    """The chain of predicted motions stays within one extrapolation's error of the
    true pose over a long walk; summing per-pair extrapolations without the correction
    would drift far further."""
    poses = walk(150)
    p = MotionPredictor()
    chain, k0 = None, None
    worst = 0.0
    for k in range(len(poses)):
        j = k - lag                                  # motions of pairs <= k - lag are known
        if j >= 1:
            p.add_motion((j - 1) * STEP_NS, j * STEP_NS, *relative(poses[j - 1], poses[j]))
        m = p.predict(k * STEP_NS)
        if m is None:
            assert chain is None                     # only before the first measurements
            continue
        if chain is None:
            chain, k0 = (np.eye(3), np.zeros(3)), k - 1
        chain = compose(*chain, *m)
        worst = max(worst, pose_error(chain, relative(poses[k0], poses[k])))
    assert chain is not None
    extrapolation = max(pose_error(compose(*poses[k], *scale_motion(
        *relative(poses[k - 1], poses[k]), lag)), poses[k + lag]) for k in range(1, 140))
    # the error at the first pair and at this one, never more
    assert worst <= 2 * extrapolation + 1e-9
    assert worst < 0.15


def test_the_measured_pose_is_taken_once_it_is_in():
    poses = walk(10)
    p = MotionPredictor()
    for k in range(1, 10):
        p.add_motion((k - 1) * STEP_NS, k * STEP_NS, *relative(poses[k - 1], poses[k]))
        m = p.predict(k * STEP_NS)
        if k > 1:
            R, t = relative(poses[k - 1], poses[k])
            np.testing.assert_allclose(m[0], R, atol=1e-9)
            np.testing.assert_allclose(m[1], t, atol=1e-9)
            assert p.ahead_ns == 0
    assert p.measured == p.predictions == 8


def test_still_gives_the_identity():
    p = MotionPredictor()
    t = np.array([0.0, 0.0, 0.12])
    p.add_motion(0, STEP_NS, np.eye(3), t)
    p.predict(STEP_NS)
    m = p.predict(2 * STEP_NS, still=True)
    np.testing.assert_allclose(m[1], 0.0)
    np.testing.assert_allclose(m[0], np.eye(3))
    # the next pair moving: from where the map was held to the estimate
    m = p.predict(3 * STEP_NS)
    np.testing.assert_allclose(m[1], 2 * t, atol=1e-12)


def test_pose_input_equals_motion_input():
    poses = walk(12, seed=3)
    a, b = MotionPredictor(), MotionPredictor()
    for k in range(12):
        if k:
            a.add_motion((k - 1) * STEP_NS, k * STEP_NS, *relative(poses[k - 1], poses[k]))
        b.add_pose(k * STEP_NS, *poses[k])
        ma, mb = a.predict(k * STEP_NS + STEP_NS), b.predict(k * STEP_NS + STEP_NS)
        assert (ma is None) == (mb is None)
        if ma is not None:
            np.testing.assert_allclose(ma[1], mb[1], atol=1e-9)


def test_stale_or_implausible_measurements_give_no_motion():
    p = MotionPredictor(max_extrapolation_s=0.3)
    p.add_motion(0, STEP_NS, np.eye(3), [0.0, 0.0, 0.1])
    p.predict(2 * STEP_NS)
    assert p.predict(3 * STEP_NS) is not None
    assert p.predict(5 * STEP_NS) is None            # 0.4 s past the newest measurement
    # an odometry restarted at the origin: a 10 m jump in 0.1 s breaks the chain
    q = MotionPredictor()
    assert q.add_pose(0, np.eye(3), np.zeros(3)) is False
    assert q.add_pose(STEP_NS, np.eye(3), [0.0, 0.0, 0.1])
    assert not q.add_pose(2 * STEP_NS, np.eye(3), [0.0, 0.0, 10.0])
    assert q.predict(2 * STEP_NS) is None            # the pair of the break: no motion
    assert q.add_pose(3 * STEP_NS, np.eye(3), [0.0, 0.0, 10.1])
    for k in (3, 4):                                 # then measured, then extrapolated
        np.testing.assert_allclose(q.predict(k * STEP_NS)[1], [0.0, 0.0, 0.1], atol=1e-9)
    assert not p.add_motion(STEP_NS, STEP_NS, np.eye(3), np.zeros(3))   # not forward
    assert not p.add_motion(0, STEP_NS, np.eye(3), [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError):
        MotionPredictor(history=1)
