"""Scoring detections against ground truth (core.evaluation)."""
import numpy as np
import pytest

from asmonc_vision.core.evaluation import FrameObstacles, score_sequence


def _frame(stamp, rows):
    """rows: (id, x, y, z, height, range, bearing, roi)"""
    if not rows:
        return FrameObstacles.empty(stamp)
    return FrameObstacles(stamp, np.array([r[0] for r in rows]),
                          np.array([r[1:4] for r in rows], float),
                          np.array([r[4] for r in rows], float),
                          np.array([r[5] for r in rows], float),
                          np.array([r[6] for r in rows], float),
                          np.array([r[7] for r in rows], int))


ROI = (100, 100, 20, 20)
FAR_ROI = (0, 0, 5, 5)


def test_detected_missed_false_and_dropped():
    truth = {
        1: _frame(1, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI), (2, 1.0, 1.0, 4.0, 0.05, 4.0, -0.2, ROI)]),
        2: _frame(2, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI)]),
        3: _frame(3, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI)]),
    }
    det = {
        # frame 1: obstacle 1 found (0.1 m off), obstacle 2 too low to count, a false one
        1: _frame(1, [(0, 0.1, 1.0, 3.0, 0.2, 3.1, 0.01, ROI), (0, -2.0, 1.0, 6.0, 0.3, 6.0, 0.3, FAR_ROI)]),
        # frame 2: a report ~0.6 m away on the ground misses, but it lies on the
        # obstacle's roi: not false
        2: _frame(2, [(0, 0.5, 1.0, 3.0, 0.2, 3.0, -0.2, ROI)]),
        # frame 3: missing (dropped)
    }
    score, missing = score_sequence(det, truth, match_radius=0.3, min_height=0.1, max_range=5)
    assert missing == [3]
    assert score.frames == 2
    assert (score.eligible, score.detected) == (2, 1)
    assert score.recall == pytest.approx(0.5)
    assert score.false_obstacles == 1 and score.frames_with_false == 1
    assert score.range_errors == [pytest.approx(0.1)]
    assert score.obstacles[1].frames_eligible == 2 and score.obstacles[1].detected
    assert score.obstacles[2].frames_eligible == 0
    d = score.as_dict()
    assert d['recall'] == pytest.approx(0.5) and d['obstacles']['1']['detected']


def test_one_detection_finds_one_obstacle_only():
    truth = {5: _frame(5, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI), (2, 0.2, 1.0, 3.0, 0.2, 3.1, 0.0, ROI)])}
    det = {5: _frame(5, [(0, 0.1, 1.0, 3.0, 0.2, 3.05, 0.0, ROI)])}
    score, _ = score_sequence(det, truth)
    assert score.detected == 1 and score.false_obstacles == 0


def test_no_truth_no_recall():
    score, _ = score_sequence({1: FrameObstacles.empty(1)}, {1: FrameObstacles.empty(1)})
    assert np.isnan(score.recall) and score.false_per_frame == 0


def test_matching_is_on_the_ground_not_at_the_top():
    # A tall post: its true top is 2 m up, the detector sees only its visible part.
    truth = {1: _frame(1, [(1, 0.0, -0.8, 3.0, 2.0, 3.0, 0.05, ROI)])}
    det = {1: _frame(1, [(0, 0.0, 0.2, 3.0, 1.0, 3.05, 0.06, ROI)])}
    score, _ = score_sequence(det, truth, match_radius=0.3)
    assert score.detected == 1
