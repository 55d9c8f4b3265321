"""The alarm logic (core, no ROS): levels, corridor, hysteresis, hold, faults, wording."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import yaml

from asmonc_vision.core.alarm import (TEXT_CLEAR, TEXT_GROUND_LOST, TEXT_NO_DATA,
                                      TEXT_NOT_STARTED, TEXT_STARTING, AlarmConfig, AlarmLevel,
                                      AlarmLogic, GroundStatus, ObstacleInfo, direction_words,
                                      obstacle_text, range_words)

L = AlarmLevel
REPO = Path(__file__).resolve().parent.parent


def ob(rng, bearing_deg=0.0, id=1, height=0.5, conf=1.0):
    return ObstacleInfo(id=id, range=rng, bearing=math.radians(bearing_deg), height=height,
                        confidence=conf)


def started(**cfg) -> AlarmLogic:
    """A logic that has seen a tracked ground and one empty frame at t=0 (so it is
    CLEAR, not starting). Its timeout is 1 s unless given: these tests feed lists up to
    0.9 s apart (the default 0.4 s timeout has its own tests)."""
    cfg.setdefault('timeout', 1.0)
    logic = AlarmLogic(AlarmConfig(**cfg), t0=0.0)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    d = logic.update(0.0, [])
    assert d is not None and d.level == L.CLEAR and d.text == TEXT_CLEAR
    return logic


# --- start-up and selection ----------------------------------------------------------

def test_starts_in_fault_starting_up():
    logic = AlarmLogic(AlarmConfig(), t0=5.0)
    assert logic.current.level == L.FAULT
    assert logic.current.text == TEXT_STARTING
    assert logic.fault == 'starting'
    # "starting up" is said once, not repeated, during the grace period
    assert logic.check_timeout(5.5) is None
    assert logic.check_timeout(14.0) is None


def test_no_data_ever_becomes_a_fault_after_the_grace_period():
    logic = AlarmLogic(AlarmConfig(startup_grace=3.0), t0=0.0)
    assert logic.check_timeout(2.9) is None
    d = logic.check_timeout(3.1)
    assert d.level == L.FAULT and d.text == TEXT_NOT_STARTED and logic.fault == 'not_started'


def test_a_slow_detector_start_is_not_taken_for_a_lost_ground():
    # The detector's first list comes after the grace (it compiled for 8 s): its ground
    # plane gets the grace from then on, and the wearer hears "starting up", not "cannot
    # see the ground", while it calibrates.
    logic = AlarmLogic(AlarmConfig(startup_grace=3.0, timeout=1.0), t0=0.0)
    assert logic.check_timeout(3.1).text == TEXT_NOT_STARTED
    d = logic.update(8.0, [])
    assert d.level == L.FAULT and d.text == TEXT_STARTING
    assert logic.update(8.1, []) is None and logic.check_timeout(8.9) is None
    logic.ground_status(9.0, GroundStatus.INITIALISING)
    logic.ground_status(9.5, GroundStatus.TRACKING)
    assert logic.update(9.6, []).level == L.CLEAR
    # ... but a ground plane that never comes is still a fault, a grace after the first list
    late = AlarmLogic(AlarmConfig(startup_grace=3.0), t0=0.0)
    late.update(8.0, [])
    assert late.update(10.9, []) is None
    assert late.update(11.1, []).text == TEXT_GROUND_LOST


def test_no_all_clear_before_the_ground_is_seen():
    # /obstacles may arrive before the first /ground_plane: an empty list then is no
    # evidence of a clear path.
    logic = AlarmLogic(AlarmConfig(), t0=0.0)
    assert logic.update(0.1, []) is None
    assert logic.current.level == L.FAULT and logic.current.text == TEXT_STARTING
    logic.ground_status(0.2, GroundStatus.TRACKING)
    d = logic.update(0.2, [])
    assert d.level == L.CLEAR and d.text == TEXT_CLEAR
    # the old behaviour, for detectors that publish no ground plane
    relaxed = AlarmLogic(AlarmConfig(require_ground_plane=False), t0=0.0)
    assert relaxed.update(0.1, []).level == L.CLEAR


def test_nearest_obstacle_in_corridor_is_the_target():
    logic = started()
    d = logic.update(0.1, [ob(4.0, id=7), ob(2.0, id=3), ob(3.0, id=9)])
    assert d.level == L.WARNING
    assert d.obstacle_id == 3
    assert d.range == pytest.approx(2.0)
    assert d.text == 'obstacle, 2 metres, ahead'


def test_obstacles_outside_corridor_or_range_are_ignored():
    logic = started()
    # 1 m away but 40 deg to the side: lateral 0.64 m > 0.5 m
    assert logic.update(0.1, [ob(1.0, 40.0)]) is None
    # beyond max range
    assert logic.update(0.2, [ob(5.5, 0.0)]) is None
    # too low, too unsure
    assert logic.update(0.3, [ob(1.0, height=0.02), ob(1.0, conf=0.1)]) is None
    assert logic.current.level == L.CLEAR
    # the same side obstacle farther right but still within the corridor: counts
    d = logic.update(0.4, [ob(1.0, 40.0), ob(2.0, -10.0, id=4)])
    assert d.level == L.WARNING and d.obstacle_id == 4
    assert d.text == 'obstacle, 2 metres, ahead'


def test_lateral_offset_is_range_times_sine_of_bearing():
    o = ob(2.0, 30.0)
    assert o.lateral == pytest.approx(1.0)
    logic = started(corridor_half_width=1.05)
    assert logic.update(0.1, [o]).level == L.WARNING
    logic = started(corridor_half_width=0.95)
    assert logic.update(0.1, [o]) is None


def test_levels_by_range_thresholds():
    for r, level in [(0.5, L.STOP), (1.2, L.STOP), (1.3, L.WARNING), (2.5, L.WARNING),
                     (2.6, L.CAUTION), (5.0, L.CAUTION)]:
        logic = started()
        d = logic.update(0.1, [ob(r)])
        assert d.level == level, r


def test_drops_alarm_by_their_depth():
    logic = started()
    assert logic.update(0.1, [ob(3.0, height=-0.03)]) is None  # shallower than min_height
    d = logic.update(0.2, [ob(3.0, height=-0.15)])
    assert d.level == L.CAUTION
    assert d.text == 'drop ahead, 3 metres'
    d = logic.update(0.3, [ob(1.0, height=-0.15)])
    assert d.level == L.STOP and d.text == 'stop, drop ahead, 1 metre'


# --- wording ---------------------------------------------------------------------------

def test_text_wording():
    assert obstacle_text(L.STOP, ob(1.1)) == 'stop, obstacle, 1 metre, ahead'
    assert obstacle_text(L.WARNING, ob(2.1, 15.0)) == 'obstacle, 2 metres, slightly left'
    assert obstacle_text(L.CAUTION, ob(4.4, -50.0)) == 'obstacle, 4.5 metres, right'
    assert obstacle_text(L.CAUTION, ob(2.9, height=-0.2)) == 'drop ahead, 3 metres'
    assert range_words(0.1) == 'half a metre'
    assert range_words(0.74) == 'half a metre'
    assert range_words(0.76) == '1 metre'
    assert range_words(1.26) == '1.5 metres'
    assert range_words(3.0) == '3 metres'
    assert direction_words(math.radians(5)) == 'ahead'
    assert direction_words(math.radians(-5)) == 'ahead'
    assert direction_words(math.radians(20)) == 'slightly left'
    assert direction_words(math.radians(-20)) == 'slightly right'
    assert direction_words(math.radians(45)) == 'left'
    assert direction_words(math.radians(-45)) == 'right'


# --- hysteresis, hold time, repeat -------------------------------------------------------

def test_hysteresis_prevents_chatter_around_a_threshold():
    logic = started(hold_time=0.0, repeat_period=60.0)
    decisions = []
    t = 0.0
    for k in range(40):  # range oscillating 2.4 <-> 2.65 around warning_range 2.5
        t += 0.1
        d = logic.update(t, [ob(2.4 if k % 2 == 0 else 2.65)])
        if d is not None:
            decisions.append(d)
    assert [d.level for d in decisions] == [L.WARNING]
    # clearly beyond threshold + hysteresis (2.8): steps down (hold_time 0)
    d = logic.update(t + 0.1, [ob(2.9)])
    assert d.level == L.CAUTION


def test_without_hysteresis_the_same_input_chatters():
    """The test above can fail: without hysteresis or hold the level flips."""
    logic = started(hysteresis=0.0, hold_time=0.0, repeat_period=60.0)
    n = 0
    for k in range(10):
        if logic.update(0.1 * (k + 1), [ob(2.4 if k % 2 == 0 else 2.65)]) is not None:
            n += 1
    assert n == 10


def test_hold_time_delays_stepping_down_but_never_stepping_up():
    logic = started(hold_time=1.0, repeat_period=60.0)
    assert logic.update(0.1, [ob(1.0)]).level == L.STOP
    # obstacle gone: the lower level must persist for 1 s
    assert logic.update(0.2, []) is None
    assert logic.update(0.7, []) is None
    assert logic.current.level == L.STOP
    # a brief return resets the hold
    assert logic.update(0.8, [ob(1.0)]) is None
    assert logic.update(0.9, []) is None
    assert logic.update(1.8, []) is None
    d = logic.update(1.95, [])
    assert d.level == L.CLEAR and d.text == TEXT_CLEAR
    # going up is immediate, even right after stepping down
    assert logic.update(2.0, [ob(1.0)]).level == L.STOP


def test_chatter_with_a_large_swing_is_held_by_the_hold_time():
    logic = started(hold_time=0.5, repeat_period=60.0)
    levels = []
    for k in range(30):  # 2.0 <-> 3.5 every 0.1 s: beyond the hysteresis
        d = logic.update(0.1 * (k + 1), [ob(2.0 if k % 2 == 0 else 3.5)])
        if d is not None:
            levels.append(d.level)
    assert levels == [L.WARNING]


def test_repeat_period_reannounces_non_clear_states_only():
    logic = started(repeat_period=2.0, timeout=2.0)
    assert logic.update(0.1, [ob(2.0)]).level == L.WARNING
    assert logic.update(1.0, [ob(1.9)]) is None
    d = logic.update(2.2, [ob(1.8)])
    assert d is not None and d.repeat and d.level == L.WARNING
    assert d.text == 'obstacle, 2 metres, ahead'
    clear = started(repeat_period=2.0)
    for k in range(50):
        assert clear.update(0.1 * (k + 1), []) is None


def test_target_change_is_announced_at_most_once_per_hold_time():
    logic = started(hold_time=1.0, repeat_period=60.0)
    assert logic.update(0.1, [ob(2.0, id=1)]).obstacle_id == 1
    assert logic.update(0.5, [ob(2.2, id=1), ob(2.0, 12.0, id=2)]) is None  # too soon
    d = logic.update(1.2, [ob(2.2, id=1), ob(2.0, 12.0, id=2)])
    assert d.obstacle_id == 2 and d.text == 'obstacle, 2 metres, slightly left'


def test_ground_lost_briefly_does_not_let_the_alarm_step_down():
    logic = started(hold_time=0.2, timeout=1.0)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    assert logic.update(0.1, [ob(1.0)]).level == L.STOP
    logic.ground_status(0.2, GroundStatus.LOST)
    for k in range(5):  # LOST: empty lists are no evidence of a clear path
        assert logic.update(0.3 + 0.1 * k, []) is None
    assert logic.current.level == L.STOP


def test_ground_lost_now_and_then_pauses_the_step_down_without_undoing_it():
    """A lower level steps down after hold_time of lists with the ground seen: a pair
    now and then with the ground LOST adds nothing to it and takes nothing from it (the
    plane lost in 1 pair of 6 held a FAULT "cannot see the way ahead" for 42 % of a
    held-out grate walk, 900020, backpack rig, long after the unseen ground had gone)."""
    def run(lost_every):
        logic = started(hold_time=1.0, timeout=1.0)
        logic.ground_status(0.0, GroundStatus.TRACKING)
        assert logic.update(0.1, [ob(1.0)]).level == L.STOP
        t_clear = None
        for k in range(1, 40):
            t = 0.1 + 0.1 * k
            logic.ground_status(t, GroundStatus.LOST if k % lost_every == 0
                                else GroundStatus.TRACKING)
            d = logic.update(t, [])
            if d is not None and d.level == L.CLEAR:
                t_clear = t
                break
        return t_clear
    # every pair seen: 1 s after the first empty list (0.2 s)
    assert run(1000) == pytest.approx(1.2)
    # 1 pair in 6 LOST: the same 1 s of seen pairs, and the LOST ones on top
    t = run(6)
    assert t is not None and 1.2 < t <= 1.2 + 0.1 * (1.0 / 0.5) + 1e-9
    # and "cannot see the way ahead" gives way to "all clear" the same way
    logic = started(hold_time=1.0, timeout=1.0)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    assert logic.update(0.1, [ob(3.0, height=math.nan, id=0)]).level == L.FAULT
    t_clear = None
    for k in range(1, 40):
        t = 0.1 + 0.1 * k
        logic.ground_status(t, GroundStatus.LOST if k % 6 == 0 else GroundStatus.TRACKING)
        d = logic.update(t, [])
        if d is not None and d.level == L.CLEAR:
            t_clear = t
            break
    assert t_clear is not None and t_clear <= 1.5


def test_a_repeat_without_a_target_gives_the_newest_range_seen():
    """Walking up to a wall: WARNING announced at 2.5 m, the wall then seen nearer at the
    same level (no new announcement), then the ground is LOST (the wall fills the view):
    the repeat must give the newest range measured, not the one announced."""
    logic = started(hold_time=1.0, timeout=3.0, repeat_period=2.0)
    d = logic.update(0.1, [ob(2.4, id=0)])
    assert d.level == L.WARNING and d.text == 'obstacle, 2.5 metres, ahead'
    for k, r in enumerate((2.2, 1.9, 1.6, 1.45)):
        assert logic.update(0.2 + 0.1 * k, [ob(r, id=0)]) is None
    logic.ground_status(0.6, GroundStatus.LOST)
    assert logic.update(0.7, []) is None
    d = logic.update(2.15, [])            # LOST for less than the timeout: held
    assert d is not None and d.repeat and d.level == L.WARNING
    assert d.text == 'obstacle, 1.5 metres, ahead' and d.range == pytest.approx(1.45)
    # after a fault or "all clear" the old target is forgotten
    logic = started(hold_time=0.5, repeat_period=2.0)
    logic.update(0.1, [ob(2.0)])
    assert logic.update(0.2, []) is None
    assert logic.update(0.8, []).text == TEXT_CLEAR
    assert logic._last_target is None


def test_a_repeat_does_not_name_a_target_glimpsed_long_ago():
    """WARNING announced about a passer-by (id 1); another report (id 2, nearer) comes
    too soon after to be announced, then none while the ground comes and goes (the level
    held): the repeat 2 s on says the announcement again, not the glimpse 1.6 s old,
    which has moved on. A target seen within hold_time is the repeat's."""
    logic = started(hold_time=1.0, timeout=3.0, repeat_period=2.0)
    assert logic.update(0.1, [ob(2.3, id=1)]).obstacle_id == 1
    assert logic.update(0.5, [ob(1.85, -8.0, id=2)]) is None      # within hold_time
    for k in range(15):                           # the ground LOST in every other pair
        logic.ground_status(0.6 + 0.1 * k, GroundStatus.LOST if k % 2 == 0
                            else GroundStatus.TRACKING)
        assert logic.update(0.6 + 0.1 * k, []) is None
    d = logic.update(2.1, [])
    assert d is not None and d.repeat and d.level == L.WARNING
    assert d.obstacle_id == 1 and d.range == pytest.approx(2.3)
    # seen within hold_time of the repeat: the repeat gives it
    logic = started(hold_time=1.5, timeout=3.0, repeat_period=2.0)
    logic.update(0.1, [ob(2.3, id=1)])
    logic.ground_status(0.2, GroundStatus.LOST)
    assert logic.update(1.5, [ob(1.85, -8.0, id=2)]) is None     # within hold_time
    d = logic.update(2.15, [])
    assert d is not None and d.repeat and d.obstacle_id == 2


# --- faults --------------------------------------------------------------------------------

def test_timeout_gives_fault_and_data_recovers():
    logic = started(timeout=1.0, repeat_period=2.0)
    assert logic.update(0.5, [ob(3.0)]).level == L.CAUTION
    assert logic.check_timeout(1.4) is None
    d = logic.check_timeout(1.6)
    assert d.level == L.FAULT and d.text == TEXT_NO_DATA
    assert logic.check_timeout(1.7) is None
    # the fault is repeated: a silent wearer would otherwise assume all is well
    d = logic.check_timeout(3.7)
    assert d.level == L.FAULT and d.repeat
    # data back, nothing there, with the detector's ground status: "all clear" once
    logic.ground_status(3.95, GroundStatus.TRACKING)
    d = logic.update(4.0, [])
    assert d.level == L.CLEAR and d.text == TEXT_CLEAR
    for k in range(1, 51):       # lists every 0.1 s: CLEAR is not repeated
        assert logic.update(4.0 + 0.1 * k, []) is None


def test_recovery_goes_straight_to_the_real_level():
    logic = started(timeout=1.0)
    logic.update(0.1, [])
    assert logic.check_timeout(2.0).level == L.FAULT
    logic.ground_status(2.05, GroundStatus.TRACKING)
    d = logic.update(2.1, [ob(2.0)])
    assert d.level == L.WARNING and d.obstacle_id == 1


@pytest.mark.parametrize('ground_first', [False, True])
def test_after_a_gap_the_ground_status_from_before_it_is_not_trusted(ground_first):
    # The detector died and was restarted: its first lists come before its ground plane.
    # The TRACKING status from before the gap must not let an empty list say "all clear".
    logic = started(timeout=1.0)
    logic.update(0.1, [])
    logic.ground_status(0.12, GroundStatus.TRACKING)   # the last frame's, after its list
    assert logic.check_timeout(1.2).text == TEXT_NO_DATA
    if ground_first:   # a stalled camera: the same detector, ground status first
        logic.ground_status(3.0, GroundStatus.TRACKING)
        assert logic.update(3.0, []).level == L.CLEAR
        return
    assert logic.update(3.0, []) is None               # still "detection has stopped"
    assert logic.current.level == L.FAULT and logic.current.text == TEXT_NO_DATA
    assert logic.check_timeout(3.05) is None
    # the restarted detector calibrates: "starting up", then the real level
    assert logic.ground_status(3.1, GroundStatus.INITIALISING).text == TEXT_STARTING
    assert logic.update(3.2, []) is None
    logic.ground_status(3.3, GroundStatus.TRACKING)
    assert logic.update(3.4, [ob(2.0)]).level == L.WARNING


def test_a_gap_over_before_the_check_said_it_holds_the_level_unannounced():
    # A list 0.42 s late (timeout 0.4, the check every 0.05 s missed it): when it comes,
    # detection has not stopped; its ground status follows it. Nothing is said, and the
    # level is held, not lowered on the stale status; then lists go on as before.
    logic = started(timeout=0.4, hold_time=0.5)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    assert logic.update(0.1, [ob(2.0)]).level == L.WARNING
    logic.ground_status(0.11, GroundStatus.TRACKING)
    assert logic.check_timeout(0.5) is None                   # 0.40 s: not yet over
    assert logic.update(0.52, []) is None                     # back, status stale: held
    assert logic.check_timeout(0.53) is None
    assert logic.current.level == L.WARNING
    logic.ground_status(0.53, GroundStatus.TRACKING)
    t, levels = 0.6, []
    while t < 1.5:
        d = logic.update(t, []) or logic.check_timeout(t + 0.05)
        levels += [d.level] if d else []
        t += 0.1
    assert levels == [L.CLEAR]                                # stepped down after hold_time


def test_lists_after_a_gap_with_no_ground_status_within_the_timeout_are_a_fault():
    logic = started(timeout=0.4)
    logic.update(0.1, [])
    logic.ground_status(0.11, GroundStatus.TRACKING)
    assert logic.update(0.52, []) is None                     # held, unannounced
    assert logic.update(0.62, []) is None
    d = logic.check_timeout(0.95)                              # no ground status since
    assert d.level == L.FAULT and d.text == TEXT_NO_DATA


def test_ground_lost_longer_than_timeout_is_a_fault():
    logic = started(timeout=1.0)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    logic.update(0.1, [])
    assert logic.ground_status(0.2, GroundStatus.LOST) is None
    t = 0.2
    d = None
    while d is None and t < 3.0:  # obstacle lists keep coming (empty)
        t += 0.1
        d = logic.update(t, []) or logic.check_timeout(t)
    assert d.level == L.FAULT and d.text == TEXT_GROUND_LOST
    assert t > 1.2
    logic.ground_status(t + 0.1, GroundStatus.TRACKING)
    d = logic.update(t + 0.2, [])
    assert d.level == L.CLEAR


def test_ground_initialising_is_a_starting_up_fault_said_once():
    logic = started()
    logic.ground_status(0.1, GroundStatus.TRACKING)
    d = logic.ground_status(0.2, GroundStatus.INITIALISING)
    assert d.level == L.FAULT and d.text == TEXT_STARTING
    assert logic.ground_status(0.3, GroundStatus.INITIALISING) is None
    # obstacle lists meanwhile do not turn it into "all clear"
    for k in range(10):
        assert logic.update(0.4 + 0.1 * k, []) is None
    assert logic.current.level == L.FAULT
    assert logic.ground_status(1.5, GroundStatus.TRACKING) is None
    assert logic.update(1.6, [ob(4.0)]).level == L.CAUTION


def test_ground_initialising_for_too_long_is_a_real_fault():
    logic = started(startup_grace=2.0)
    logic.ground_status(0.1, GroundStatus.INITIALISING)
    d = None
    t = 0.1
    while d is None and t < 5.0:
        t += 0.1
        d = logic.update(t, [])
    assert d.level == L.FAULT and d.text == TEXT_GROUND_LOST and t > 2.1


# --- settings --------------------------------------------------------------------------------

@pytest.mark.parametrize('field,value,words', [
    ('corridor_half_width', -0.1, ['corridor_half_width', '0.05', '5.0']),
    ('min_confidence', 1.5, ['min_confidence', '0.0', '1.0']),
    ('timeout', 0.0, ['timeout', '0.05', '60.0']),
])
def test_config_validation_names_field_and_range(field, value, words):
    with pytest.raises(ValueError) as e:
        AlarmConfig(**{field: value})
    for w in words:
        assert w in str(e.value)


def test_config_threshold_order_is_checked():
    with pytest.raises(ValueError, match='stop_range'):
        AlarmConfig(stop_range=3.0, warning_range=2.5)
    with pytest.raises(ValueError, match='caution_range'):
        AlarmConfig(caution_range=6.0, max_range=5.0)


def test_yaml_equals_dataclass_defaults():
    data = yaml.safe_load((REPO / 'config' / 'alarm.yaml').read_text())
    params = data['alarm_node']['ros__parameters']
    defaults = {f.name: f.default for f in dataclasses.fields(AlarmConfig)}
    assert params == defaults
    for k, v in params.items():
        assert type(v) is type(defaults[k]), k


def test_recovery_with_the_ground_lost_is_not_all_clear():
    # data back while the detector reports the ground LOST: an empty list is no evidence
    # that the path is clear, so the FAULT stays; an obstacle is still announced
    logic = AlarmLogic(AlarmConfig(), t0=0.0)
    logic.ground_status(0.0, GroundStatus.LOST)
    assert logic.update(0.1, []) is None
    assert logic.current.level == L.FAULT
    assert logic.update(0.2, [ob(2.0)]).level == L.WARNING
