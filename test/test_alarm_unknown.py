"""Unknown ahead: ground the detector cannot see (an obstacle list entry of NaN height)
is said as such, never as an obstacle's level and never as "all clear"."""
from __future__ import annotations

import math

import numpy as np

from asmonc_vision.core.alarm import (TEXT_CLEAR, AlarmConfig, AlarmLevel, AlarmLogic,
                                      GroundStatus, ObstacleInfo, unknown_text)
from asmonc_vision.eval.evaluation import FrameObstacles
from asmonc_vision.eval.safety import obstacle_reports

L = AlarmLevel


def ob(rng, bearing_deg=0.0, id=1, height=0.5, conf=1.0):
    return ObstacleInfo(id=id, range=rng, bearing=math.radians(bearing_deg), height=height,
                        confidence=conf)


def unknown(rng, bearing_deg=0.0, conf=0.9):
    return ob(rng, bearing_deg, id=0, height=math.nan, conf=conf)


def started(**cfg) -> AlarmLogic:
    """CLEAR after a tracked ground and an empty list at t = 0; a timeout of 3 s (these
    tests feed lists up to 1.7 s apart)."""
    cfg.setdefault('timeout', 3.0)
    logic = AlarmLogic(AlarmConfig(**cfg), t0=0.0)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    assert logic.update(0.0, []).text == TEXT_CLEAR
    return logic


def test_unknown_ahead_is_said_at_once_not_as_an_obstacle_and_not_as_clear():
    logic = started()
    d = logic.update(0.1, [unknown(2.2)])
    assert d.level == L.FAULT and d.text == unknown_text(2.2) == (
        'cannot see the way ahead, 2 metres, walk with care')
    assert logic.fault == 'unknown_ahead' and d.range == 2.2 and d.obstacle_id == 0
    assert logic.contact.level == L.CLEAR            # no obstacle for the sound cue
    # repeated every repeat_period with the newest range, not more often
    assert logic.update(0.5, [unknown(2.0)]) is None
    d = logic.update(2.2, [unknown(1.4)])
    assert d.repeat and d.text == unknown_text(1.4) and d.level == L.FAULT
    # gone: "all clear" only after hold_time
    assert logic.update(2.3, []) is None
    assert logic.update(2.9, []) is None
    assert logic.update(3.4, []).text == TEXT_CLEAR


def test_an_obstacle_outranks_the_unknown_and_the_unknown_replaces_clear():
    logic = started()
    assert logic.update(0.1, [unknown(3.0), ob(2.0)]).level == L.WARNING
    assert logic.update(0.2, [unknown(3.0)]) is None          # held for hold_time
    d = logic.update(1.3, [unknown(3.0)])
    assert d.level == L.FAULT and logic.fault == 'unknown_ahead'   # not "all clear"
    d = logic.update(1.4, [unknown(3.0), ob(4.0, id=7)])
    assert d.level == L.CAUTION and d.obstacle_id == 7         # an obstacle at once


def test_unknown_ground_outside_the_corridor_or_unsure_is_not_said():
    logic = started()
    assert logic.update(0.1, [unknown(2.0, bearing_deg=40.0)]) is None
    assert logic.update(0.2, [unknown(6.0)]) is None           # beyond max_range
    assert logic.update(0.3, [unknown(2.0, conf=0.1)]) is None
    assert logic.current.text == TEXT_CLEAR


def test_a_real_fault_outranks_the_unknown_and_recovers_to_it():
    logic = started()
    assert logic.update(0.1, [unknown(2.0)]).level == L.FAULT
    d = logic.check_timeout(3.2)                               # lists stopped
    assert d.level == L.FAULT and logic.fault == 'no_data'
    logic.update(3.3, [unknown(2.0)])                          # lists back: status stale
    logic.ground_status(3.3, GroundStatus.TRACKING)
    d = logic.update(3.4, [unknown(2.0)])
    assert logic.fault == 'unknown_ahead' and d.text == unknown_text(2.0)


def test_a_standing_wearer_is_not_told_the_unknown_again_and_again():
    logic = started()
    logic.gait(0.0, False)
    assert logic.update(0.1, [unknown(2.0)]).level == L.FAULT
    logic.gait(3.0, False)
    assert logic.update(3.0, [unknown(2.0)]) is None


def test_the_safety_score_counts_no_unknown_entry_as_a_report():
    fo = FrameObstacles(5, np.array([0, 3]), np.zeros((2, 3)), np.array([math.nan, 0.3]),
                        np.array([2.0, 3.0]), np.zeros(2), np.zeros((2, 4), int),
                        np.array([0.9, 0.8]))
    kept = obstacle_reports(fo)
    assert len(kept) == 1 and kept.ids.tolist() == [3] and kept.confidence.tolist() == [0.8]
    plain = FrameObstacles.empty(1)
    assert obstacle_reports(plain) is plain
