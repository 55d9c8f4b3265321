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


def _walk_up_to_a_drop_and_lose_the_ground(**cfg):
    """A wearer walking at 1.2 m/s is warned of a drop 3.3 m ahead (WARNING by time to
    contact), the drop seen in every pair up to t = 0.5 s; then the ground is LOST in
    every pair (the whole view is the lower ground, as for a level chest camera 2.5 m
    before a step down). Returns the logic and the decisions after the loss, (t, d)."""
    logic = started(timeout=0.4, **cfg)
    out = []
    for k in range(6):
        t = 0.1 * k
        logic.walk_motion(t, 1.2, 0.0)
        logic.ground_status(t, GroundStatus.TRACKING)
        d = logic.update(t, [box(3.3 - 1.2 * t, height=-0.2, id=7)])
        if k == 0:
            assert d.level == AlarmLevel.WARNING and d.text == 'drop ahead, 3.5 metres'
    for k in range(6, 40):
        t = 0.1 * k
        logic.walk_motion(t, 1.2, 0.0)
        d = logic.update(t, [])                   # (lists first, as the node publishes)
        d2 = logic.ground_status(t, GroundStatus.LOST)
        d3 = logic.check_timeout(t + 0.05)
        out += [(t, x) for x in (d, d2, d3) if x is not None]
    return logic, out


def test_a_hazard_walked_up_to_keeps_its_level_while_the_ground_is_lost():
    """lost_hold: the drop announced is carried by the distance walked; its level rises
    to STOP as it comes within stop_time (1.5 s at 1.2 m/s: 1.8 m, at 1.25 s), the
    announcement says where it now is, and FAULT "cannot see the ground" comes once it
    was seen lost_hold ago (2 s: at 2.5 s), not at the timeout (0.9 s); never before."""
    logic, out = _walk_up_to_a_drop_and_lose_the_ground()
    levels = [(round(t, 2), d.level) for t, d in out]
    stop = [t for t, d in out if d.level == AlarmLevel.STOP]
    fault = [t for t, d in out if d.level == AlarmLevel.FAULT]
    assert stop and fault, levels
    # where the drop now is: 2.7 m at 0.5 s less 1.2 m/s since; STOP from 1.8 m, the
    # first list after 1.25 s
    assert stop[0] == pytest.approx(1.3), levels
    first = next(d for t, d in out if d.level == AlarmLevel.STOP)
    assert first.text.startswith('stop, drop ahead') and first.obstacle_id == 7
    assert first.range == pytest.approx(2.7 - 1.2 * (first.t - 0.5), abs=0.01)
    assert min(fault) == pytest.approx(2.5, abs=0.11), levels
    assert all(d.level != AlarmLevel.FAULT for t, d in out if t < 2.45), levels
    assert out[-1][1].level == AlarmLevel.FAULT and logic.fault == 'ground_lost'


def test_without_lost_hold_a_lost_ground_is_a_fault_after_the_timeout():
    """lost_hold 0: FAULT once the ground has been LOST for the timeout, whatever was
    announced."""
    _, out = _walk_up_to_a_drop_and_lose_the_ground(lost_hold=0.0)
    fault = [t for t, d in out if d.level == AlarmLevel.FAULT]
    assert fault and min(fault) <= 0.6 + 0.4 + 0.1 + 1e-9
    assert not any(d.level == AlarmLevel.STOP for _, d in out)


def test_a_hazard_walked_past_while_the_ground_is_lost_is_a_fault():
    """The drop carried by the walk leaves the path (passed, or out of the corridor):
    FAULT then, before lost_hold has passed."""
    logic = started(timeout=0.4)
    for k in range(3):
        logic.walk_motion(0.1 * k, 1.5, 0.0)
        logic.ground_status(0.1 * k, GroundStatus.TRACKING)
        logic.update(0.1 * k, [box(1.0, height=-0.2, id=3)])
    assert logic.current.level == AlarmLevel.STOP
    fault_t = None
    for k in range(3, 30):
        t = 0.1 * k
        logic.walk_motion(t, 1.5, 0.0)
        for d in (logic.update(t, []), logic.ground_status(t, GroundStatus.LOST)):
            if d is not None and d.level == AlarmLevel.FAULT and fault_t is None:
                fault_t = t
    # the drop 1.0 m ahead at 0.2 s is passed at 0.2 + 1.0 / 1.5 = 0.87 s (the
    # hysteresis keeps it in the path to -0 m: forward >= 0)
    assert fault_t is not None and fault_t <= 1.0 + 1e-9


def test_a_wide_drop_beside_the_walking_line_is_held_through_the_walking_directions_sway():
    """The drop's nearest point lies 0.53 m beside the walking line, in the corridor
    along the cameras' axis when last seen (the walking direction 1 degree right); the
    walking direction then sways 2 degrees left, which puts it out of both corridors:
    held all the same (it was in the path), and FAULT only when lost_hold has passed."""
    logic = started(timeout=0.4)
    for k in range(3):
        t = 0.1 * k
        logic.walk_motion(t, 1.1, math.radians(-1.0))
        logic.ground_status(t, GroundStatus.TRACKING)
        logic.update(t, [box(3.5 - 1.1 * t, bearing_deg=8.0, height=-0.3, id=5)])
    assert logic.current.level == AlarmLevel.WARNING
    levels = []
    for k in range(3, 30):
        t = 0.1 * k
        logic.walk_motion(t, 1.1, math.radians(2.0))
        for d in (logic.update(t, []), logic.ground_status(t, GroundStatus.LOST),
                  logic.check_timeout(t + 0.05)):
            if d is not None:
                levels.append((round(t, 2), d.level))
    fault = [t for t, lv in levels if lv == AlarmLevel.FAULT]
    assert fault and min(fault) >= 2.2 - 1e-9, levels


def test_a_ground_lost_for_less_than_the_timeout_holds_the_level_unmoved():
    """A pair or two without the ground: the level is held as it was, not raised by
    where the walk since would have brought the target (a passer-by misplaced by a
    tenth of a second of dead reckoning was a new, false, WARNING: stop_turn 1205,
    chest rig); lost_hold's carrying starts once the ground has been LOST for the
    timeout."""
    logic = started(timeout=0.4)
    logic.ground_status(0.0, GroundStatus.TRACKING)
    assert logic.update(0.1, [box(2.6, id=4)]).level == AlarmLevel.CAUTION  # standing
    logic.walk_motion(0.15, 1.5, 0.0)           # 2.6 / 1.5 = 1.7 s: would be WARNING
    logic.ground_status(0.15, GroundStatus.LOST)
    for t in (0.2, 0.3, 0.4, 0.5):
        logic.walk_motion(t, 1.5, 0.0)
        assert logic.update(t, []) is None, t
    assert logic.current.level == AlarmLevel.CAUTION
    # LOST for longer than the timeout: carried by the walk since it was seen (0.5 s
    # at 1.5 m/s: 1.85 m, 1.2 s to contact), STOP
    logic.walk_motion(0.6, 1.5, 0.0)
    d = logic.update(0.6, [])
    assert d is not None and d.level == AlarmLevel.STOP and d.obstacle_id == 4
    assert d.range == pytest.approx(2.6 - 1.5 * 0.5)
