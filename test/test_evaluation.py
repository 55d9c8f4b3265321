"""Scoring detections against ground truth (eval.evaluation)."""
import numpy as np
import pytest

from asmonc_vision.eval.evaluation import FrameObstacles, score_sequence


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
        1: _frame(1, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI),
                      (2, 1.0, 1.0, 4.0, 0.05, 4.0, -0.2, ROI)]),
        2: _frame(2, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI)]),
        3: _frame(3, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI)]),
    }
    det = {
        # frame 1: obstacle 1 found (0.1 m off), obstacle 2 too low to count, a false one
        1: _frame(1, [(0, 0.1, 1.0, 3.0, 0.2, 3.1, 0.01, ROI),
                      (0, -2.0, 1.0, 6.0, 0.3, 6.0, 0.3, FAR_ROI)]),
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
    truth = {5: _frame(5, [(1, 0.0, 1.0, 3.0, 0.2, 3.0, 0.0, ROI),
                           (2, 0.2, 1.0, 3.0, 0.2, 3.1, 0.0, ROI)])}
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


def test_a_report_of_a_true_obstacle_that_has_left_the_view_is_remembered_not_false():
    """Truth lists obstacles in view only; carried by the true poses, an obstacle listed
    earlier explains a later report at its place (remembered), but nothing else does."""
    from asmonc_vision.core.camera import MetricPlane
    from asmonc_vision.eval.evaluation import out_of_view_truth

    plane = MetricPlane(normal_up=np.array([0.0, -1.0, 0.0]), height=1.2)
    s = 100_000_000                                       # 10 Hz, ns
    # the camera walks 0.5 m forward per frame along the world's z; the obstacle's foot
    # stands 3 m ahead of the first frame; it is listed while at 3.0 and 2.5 m only
    truth, poses = {}, {}
    for k in range(8):
        poses[k * s] = (np.eye(3), np.array([0.0, 0.0, 0.5 * k]))
        z = 3.0 - 0.5 * k
        truth[k * s] = (_frame(k * s, [(7, 0.0, 0.7, z, 0.5, z, 0.0, ROI)]) if k < 2
                        else FrameObstacles.empty(k * s))
    away = out_of_view_truth(truth, poses, {k: plane for k in poses})
    assert len(away[0]) == 0 and len(away[s]) == 0       # listed: not remembered
    assert set(away[2 * s].ids) == {7}
    assert away[2 * s].range == pytest.approx([2.0, 2.0])   # both listed feet, carried
    assert away[2 * s].position[:, 1] == pytest.approx([0.7, 0.7])  # top: 0.5 m up
    assert len(away[7 * s]) == 0                          # passed: behind the camera
    det = {2 * s: _frame(2 * s, [(3, 0.05, 1.2, 2.0, 0.5, 2.0, 0.02, FAR_ROI),
                                 (4, 1.5, 1.2, 2.6, 0.5, 3.0, -0.5, FAR_ROI)])}
    score, _ = score_sequence(det, {2 * s: truth[2 * s]}, away)
    assert (score.remembered, score.false_obstacles) == (1, 1)
    score, _ = score_sequence(det, {2 * s: truth[2 * s]})  # without the poses: both false
    assert (score.remembered, score.false_obstacles) == (0, 2)
    assert score.as_dict()['remembered_out_of_view'] == 0
    # beyond the memory an obstacle is forgotten
    assert len(out_of_view_truth(truth, poses, {k: plane for k in poses},
                                 memory_s=0.05)[2 * s]) == 0


# --- warnings in time -----------------------------------------------------------------------

def _approach(ranges, lateral=0.0, height=0.2, oid=7, t0=1_000_000_000, dt=100_000_000):
    """Truth of one obstacle walked up to: frame k at t0 + k dt, at ranges[k] along the
    ground, ``lateral`` m to the left (None in ranges: out of view in that frame)."""
    out = {}
    for k, r in enumerate(ranges):
        s = t0 + k * dt
        if r is None:
            out[s] = FrameObstacles.empty(s)
            continue
        rr = float(np.hypot(r, lateral))
        b = float(np.arctan2(lateral, r))
        out[s] = _frame(s, [(oid, -lateral, 1.0, r, height, rr, b, ROI)])
    return out


def _alarm(stamp, level):
    return {'stamp_ns': int(stamp), 'level': level}


T0, DT = 1_000_000_000, 100_000_000
RANGES = [4.5, 4.0, 3.5, 3.0, 2.5, 2.0, 1.5, 1.2]


def test_alarm_level_in_force_at_each_frame():
    from asmonc_vision.eval.evaluation import alarm_levels_at
    st = [T0 + k * DT for k in range(6)]
    # starting-up FAULT stamped on another clock (wall time), then CLEAR and CAUTION on frames
    alarms = [_alarm(1_800_000_000_000_000_000, 4), _alarm(st[1], 0), _alarm(st[3], 1),
              _alarm(1_800_000_000_500_000_000, 4)]      # a timer FAULT after frame 3's CAUTION
    lv = alarm_levels_at(st, alarms)
    # the first FAULT counts from before the frames; the last one right after the CAUTION
    assert lv.tolist() == [4, 0, 0, 4, 4, 4]
    assert alarm_levels_at(st, []).tolist() == [-1] * 6


def test_an_obstacle_warned_before_it_comes_onto_the_path():
    from asmonc_vision.eval.evaluation import path_warnings, path_warnings_summary
    truth = _approach(RANGES)
    alarms = [_alarm(T0, 0), _alarm(T0 + 2 * DT, 1), _alarm(T0 + 5 * DT, 2)]  # CAUTION at 3.5 m
    (o,) = path_warnings(truth, alarms)
    assert o.id == 7 and o.frames_on_path == 4 and o.frames_unwarned == 0
    assert o.first_on_path_m == pytest.approx(2.5) and o.nearest_m == pytest.approx(1.2)
    assert o.warned_at_m == pytest.approx(3.5) and o.warned_in_time
    s = path_warnings_summary([o], {})
    assert (s['on_path'], s['warned_in_time'], s['warned_late'], s['never_warned']) == (1, 1, 0, 0)


def test_an_obstacle_warned_late_or_never():
    from asmonc_vision.eval.evaluation import path_warnings, path_warnings_summary
    truth = _approach(RANGES)
    # the warning comes at 1.5 m: two frames on the path (2.5, 2.0 m) went unwarned
    (late,) = path_warnings(truth, [_alarm(T0, 0), _alarm(T0 + 6 * DT, 3)])
    assert late.warned_at_m == pytest.approx(1.5) and not late.warned_in_time
    assert late.frames_unwarned == 2 and late.nearest_unwarned_m == pytest.approx(2.0)
    # all clear throughout
    (never,) = path_warnings(truth, [_alarm(T0, 0)])
    assert never.warned_at_m is None and never.frames_unwarned == 4
    assert never.nearest_unwarned_m == pytest.approx(1.2)
    # a FAULT in force is neither a warning nor silence
    (fault,) = path_warnings(truth, [_alarm(T0, 4)])
    assert fault.frames_fault == 4 and fault.frames_unwarned == 0 and fault.warned_at_m is None
    s = path_warnings_summary([late, never], {'warning_range': 2.5})
    assert (s['warned_in_time'], s['warned_late'], s['never_warned']) == (0, 1, 1)
    assert s['frames_unwarned'] == 6 and s['criteria'] == {'warning_range': 2.5}


def test_only_obstacles_in_the_corridor_high_enough_count():
    from asmonc_vision.core.alarm import AlarmConfig
    from asmonc_vision.eval.evaluation import path_warnings
    assert path_warnings(_approach(RANGES, lateral=0.8), []) == []      # beside the path
    assert path_warnings(_approach(RANGES, height=0.03), []) == []      # too low
    assert len(path_warnings(_approach(RANGES, height=-0.15), [])) == 1  # a drop counts
    assert path_warnings(_approach(RANGES, lateral=0.8), [],
                         config=AlarmConfig(corridor_half_width=1.0))
    assert path_warnings(_approach([4.5, 4.0, 3.5, 3.0]), []) == []     # never within 2.5 m


def test_an_obstacle_walked_up_to_counts_at_its_remembered_place():
    """Out of view (below the image) it is taken at its remembered place: silence there
    counts as unwarned."""
    from asmonc_vision.eval.evaluation import path_warnings
    seen = [4.0, 3.0, 2.4, None, None]
    truth = _approach(seen)
    remembered = {s: (_frame(s, [(7, 0.0, 1.0, r, 0.2, r, 0.0, (0, 0, 0, 0))]) if r else
                      FrameObstacles.empty(s))
                  for s, r in zip(sorted(truth), [None, None, None, 1.9, 1.4])}
    alarms = [_alarm(T0, 0), _alarm(T0 + DT, 2), _alarm(T0 + 3 * DT, 0)]
    (o,) = path_warnings(truth, alarms, remembered)
    assert o.frames_on_path == 3 and o.nearest_m == pytest.approx(1.4)
    assert o.warned_in_time and o.frames_unwarned == 2
    assert o.nearest_unwarned_m == pytest.approx(1.4)
    (o2,) = path_warnings(truth, alarms)                     # without the remembered places
    assert o2.frames_on_path == 1 and o2.frames_unwarned == 0
