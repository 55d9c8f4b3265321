"""The alarm policy by time to contact (core.alarm): walking direction, speed, gait."""
import math

import pytest

from asmonc_vision.core.alarm import (AlarmConfig, AlarmLevel, AlarmLogic, GroundStatus,
                                      ObstacleInfo)
from asmonc_vision.core.walking import WalkingSpeed


def started(**cfg) -> AlarmLogic:
    """A CLEAR logic on a tracked ground; timeout 1 s unless given (some tests leave up to
    0.7 s between lists)."""
    cfg.setdefault('timeout', 1.0)
    logic = AlarmLogic(AlarmConfig(**cfg), t0=0.0)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    logic.update(0.0, [])
    assert logic.current.level == AlarmLevel.CLEAR
    return logic


def box(r, bearing_deg=0.0, height=0.2, id=1):
    return ObstacleInfo(id=id, range=r, bearing=math.radians(bearing_deg), height=height)


def test_walking_raises_the_level_by_time_to_contact():
    # 4 m ahead: CAUTION by range; at 1.4 m/s that is 2.9 s: WARNING (lead time 3 s)
    standing = started()
    assert standing.update(0.1, [box(4.0)]).level == AlarmLevel.CAUTION
    walking = started()
    walking.walk_motion(0.1, 1.4, 0.0)
    d = walking.update(0.1, [box(4.0)])
    assert d.level == AlarmLevel.WARNING
    assert d.time_to_contact == pytest.approx(4.0 / 1.4)
    assert walking.contact.moving and walking.contact.target.id == 1


def test_standing_keeps_the_range_floor():
    logic = started()
    logic.gait(0.1, False)
    logic.walk_motion(0.1, 1.4, 0.0)    # the walk model says standing: it wins
    d = logic.update(0.1, [box(2.0)])
    assert d.level == AlarmLevel.WARNING and math.isinf(d.time_to_contact)


def test_corridor_follows_the_walking_direction():
    # 3 m away, 20 deg left of the camera's axis: 1.03 m aside, outside a 0.5 m corridor;
    # walking 20 deg left it is straight ahead.
    ob = box(3.0, 20.0)
    logic = started()
    assert logic.update(0.1, [ob]) is None
    logic.walk_motion(0.2, 1.0, math.radians(20.0))
    d = logic.update(0.2, [ob])
    assert d is not None and d.level == AlarmLevel.WARNING
    # said from the walking direction; the bearing stays the cameras' (as on /obstacles)
    assert d.bearing == pytest.approx(math.radians(20.0)) and 'ahead' in d.text
    off = started(follow_walking_direction=False)
    off.walk_motion(0.2, 1.0, math.radians(20.0))
    assert off.update(0.2, [ob]) is None


def test_an_obstacle_where_the_wearer_faces_counts_too():
    # walking 20 deg left of the camera's axis: a box 3 m straight ahead of the cameras
    # (1.03 m right of the walking line) is in the corridor along the axis and counts;
    # one 40 deg right is in neither and does not
    logic = started()
    logic.walk_motion(0.1, 1.0, math.radians(20.0))
    assert logic.update(0.1, [box(3.0, -40.0)]) is None
    d = logic.update(0.2, [box(3.0, 0.0)])
    assert d is not None and d.level == AlarmLevel.WARNING
    assert d.bearing == pytest.approx(0.0, abs=1e-9) and 'right' in d.text


def test_a_drop_comes_first_within_a_level_then_least_time_to_contact():
    logic = started()
    drop = box(2.4, 0.0, -0.15, id=7)
    near = box(1.8, 0.0, 0.3, id=8)
    d = logic.update(0.1, [near, drop])      # both WARNING by range
    assert d.level == AlarmLevel.WARNING and d.obstacle_id == 7 and d.text.startswith('drop')
    stop = box(1.0, 0.0, 0.3, id=9)          # a higher level outranks the drop
    d = logic.update(0.2, [near, drop, stop])
    assert d.level == AlarmLevel.STOP and d.obstacle_id == 9


def test_a_standing_wearer_is_not_told_again_and_again():
    logic = started(repeat_period=2.0)
    logic.gait(0.1, False)
    assert logic.update(0.1, [box(2.0)]).level == AlarmLevel.WARNING
    for k in range(2, 60):                   # 6 s standing before it: no repeat
        logic.gait(0.1 * k, False)
        assert logic.update(0.1 * k, [box(2.0)]) is None
    # walking again: the repeat comes back
    logic.gait(6.1, True)
    logic.walk_motion(6.1, 0.8, 0.0)
    d = logic.update(6.1, [box(2.0)])
    assert d is not None and d.repeat
    # unknown motion (no walk model, no egomotion) keeps the periodic repeat
    plain = started(repeat_period=2.0, timeout=3.0)
    plain.update(0.1, [box(2.0)])
    assert plain.update(2.2, [box(2.0)]).repeat


def test_stale_motion_is_not_used():
    logic = started(motion_timeout=0.5)
    logic.walk_motion(0.0, 1.4, 0.0)
    assert logic.moving(0.4) and not logic.moving(0.6)
    assert logic.update(0.7, [box(4.0)]).level == AlarmLevel.CAUTION


def test_time_levels_have_hysteresis():
    logic = started()
    logic.walk_motion(0.1, 1.0, 0.0)
    assert logic.update(0.1, [box(2.9)]).level == AlarmLevel.WARNING   # 2.9 s
    logic.walk_motion(0.2, 1.0, 0.0)
    assert logic.update(0.2, [box(3.3)]) is None                     # 3.3 s < 3 + 0.5: held
    assert logic.current.level == AlarmLevel.WARNING


def test_bad_time_order_is_refused():
    with pytest.raises(ValueError, match='stop_time'):
        AlarmConfig(stop_time=3.0, warning_time=3.0)


def test_walking_speed_from_egomotion_steps():
    w = WalkingSpeed(tau=0.3)
    # 10 Hz, 0.12 m per step along the optical axis pitched 20 deg down, drifting left
    pitch = math.radians(20.0)
    for k in range(30):
        step = (-0.02, 0.12 * math.sin(pitch), 0.12 * math.cos(pitch))
        w.update(0.1 * k, step, 0.1)
    assert w.speed == pytest.approx(math.hypot(0.12, 0.02) / 0.1, rel=1e-6)
    assert math.degrees(w.heading) == pytest.approx(math.degrees(math.atan2(0.02, 0.12)),
                                                    abs=1e-6)
    # a jump faster than a walker is ignored, as are bad steps
    assert w.update(3.1, (0.0, 0.0, 1.0), 0.1) == pytest.approx(w.speed)
    assert w.update(3.2, (math.nan, 0, 0), 0.1) == pytest.approx(w.speed)


@pytest.mark.parametrize('speed, said', [(1.2, 2.0 - 1.2 * 0.5), (5.0, None)])
def test_a_repeat_describes_the_last_target_where_it_is_now(speed, said):
    """A level held on the target last seen (2 m ahead) half a second ago, repeated while
    the wearer walks straight at it: said at its range less the distance walked since;
    once walked past (at 5 m/s), the announcement is repeated as it was."""
    logic = started()
    logic.walk_motion(0.0, speed, 0.0)
    first = logic.update(0.0, [box(2.2)])
    assert first.level >= AlarmLevel.WARNING
    for k in range(1, 16):                           # seen until 1.5 s
        logic.walk_motion(k * 0.1, speed, 0.0)
        assert logic.update(k * 0.1, [box(2.0)]) is None
    logic.walk_motion(2.0, speed, 0.0)
    d = logic.update(2.0, [])                        # held, and due for a repeat
    assert d is not None and d.repeat and d.level == first.level and d.obstacle_id == 1
    assert d.range == pytest.approx(said if said is not None else first.range)
