"""core.motion.pipeline: images to frame-to-frame motion, on frames of a committed bag."""
import dataclasses

import numpy as np
import pytest

from asmonc_vision.cli.motion import load_sequence
from asmonc_vision.core.motion import (FIRST, IMPLAUSIBLE, NO_MOTION, OK, TOO_FEW_FEATURES,
                                       TOO_FEW_MATCHES, EgomotionConfig, EgomotionEstimator)
from asmonc_vision.core.motion.geometry import compose, invert, rotation_error_components
from conftest import BAGS


@pytest.fixture(scope='module')
def walk():
    return load_sequence(BAGS / 'walk_obstacles', 12)


def _truth(a, b):
    return compose(*invert(*a['pose']), *b['pose'])


def _errors(motion, truth):
    deg = np.degrees(np.abs(rotation_error_components(motion.R, truth[0])))
    return deg, float(np.linalg.norm(motion.t - truth[1])) * 1e3


def test_walking_frames_give_accurate_motions(walk):
    est = EgomotionEstimator()
    results = [est.process(f['left'], f['right'], f['cam'], f['stamp_ns']) for f in walk[:8]]
    assert results[0].status == FIRST
    assert all(r.status == OK for r in results[1:]), [r.message for r in results]
    for prev, cur, r in zip(walk, walk[1:8], results[1:]):
        assert r.reference_stamp_ns == prev['stamp_ns']
        deg, mm = _errors(r.motion, _truth(prev, cur))
        assert deg.max() < 0.15 and mm < 10.0
        assert r.n_inliers >= 40 and r.n_stereo >= r.n_matches >= r.n_inliers
        assert r.motion.cov is not None and np.all(np.linalg.eigvalsh(r.motion.cov) > 0)
        assert {'detect', 'match', 'solve', 'cpu', 'wall'} <= set(r.timings_ms)
    assert results[-1].predicted            # the constant-velocity prediction was used


def test_blank_pair_keeps_the_reference(walk):
    est = EgomotionEstimator()
    a, b, c = walk[8], walk[9], walk[10]
    assert est.process(a['left'], a['right'], a['cam'], a['stamp_ns']).status == FIRST
    black = np.zeros_like(b['left'])
    r = est.process(black, black, b['cam'], b['stamp_ns'])
    assert r.status == TOO_FEW_FEATURES and r.motion is None
    assert 'too few features' in r.message
    r = est.process(c['left'], c['right'], c['cam'], c['stamp_ns'])
    assert r.status == OK and r.reference_stamp_ns == a['stamp_ns']
    deg, mm = _errors(r.motion, _truth(a, c))           # across the blank pair: 0.2 s
    assert deg.max() < 0.15 and mm < 10.0


def test_unrelated_views_give_no_motion_not_a_wrong_one(walk):
    far = load_sequence(BAGS / 'walk_stop_turn', 60)[-1]      # 6 s into another walk
    est = EgomotionEstimator()
    est.process(walk[0]['left'], walk[0]['right'], walk[0]['cam'], walk[0]['stamp_ns'])
    r = est.process(far['left'], far['right'], far['cam'], walk[0]['stamp_ns'] + 100_000_000)
    assert r.status in (TOO_FEW_MATCHES, NO_MOTION, IMPLAUSIBLE) and r.motion is None
    # the new view became the reference: the next pair is matched against it
    assert est.reference is not None and est.reference.stamp_ns == walk[0]['stamp_ns'] + 100_000_000


def test_explicit_prediction_and_the_paper_methods(walk):
    a, b = walk[3], walk[4]
    truth = _truth(a, b)
    for method in ('three_point', 'p3p_gn'):
        est = EgomotionEstimator(EgomotionConfig(method=method))
        est.process(a['left'], a['right'], a['cam'], a['stamp_ns'])
        r = est.process(b['left'], b['right'], b['cam'], b['stamp_ns'], prediction=truth)
        assert r.status == OK and r.predicted
        deg, mm = _errors(r.motion, truth)
        assert deg.max() < 0.2 and mm < 15.0


def test_settings_are_validated():
    with pytest.raises(ValueError, match=r'EgomotionConfig\.min_ncc = 2\.0 is out of range'):
        EgomotionConfig(min_ncc=2.0)
    with pytest.raises(ValueError, match=r"EgomotionConfig\.method = 'x' is not one of"):
        EgomotionConfig(method='x')
    cfg = EgomotionConfig()
    assert dataclasses.replace(cfg, threshold_px=2.0).ransac_settings().threshold_px == 2.0
