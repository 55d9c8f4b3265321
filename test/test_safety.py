"""The safety score (asmonc_vision/eval/safety.py) on hand-made walks, and the offline
alarm replay (eval/alarm_replay.py)."""
import math

import numpy as np
import pytest

from asmonc_vision.core.alarm import AlarmConfig, AlarmLevel
from asmonc_vision.eval.evaluation import FrameObstacles
from asmonc_vision.eval.alarm_replay import replay_alarms
from asmonc_vision.eval.safety import (SafetyCriteria, SafetyTruth, TrueObstacle, TruthFrame,
                                       corridor_range, format_safety, polygon_distance,
                                       score_safety, walking_mask)

#: left optical frame looking along world +x, level: optical z = world x, x = -y, y = -z
R_X = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
S0 = 1_700_000_000 * 10**9
DT = 100_000_000   # 10 Hz


def rect(x0, x1, y0, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)


def walk(n=40, speed=1.0, visible=None):
    """Frames at 10 Hz of a camera walking along +x from x = 0 at ``speed`` m/s."""
    return [TruthFrame(S0 + k * DT, R_X, np.array([speed * k * 0.1, 0.0, 1.25]),
                       dict(visible or {})) for k in range(n)]


def alarm(k, level, oid=0, rng=0.0, brg=0.0, extra_ns=0):
    return {'stamp_ns': S0 + k * DT + extra_ns, 'level': int(level), 'obstacle_id': oid,
            'range': rng, 'bearing': brg}


BOX = TrueObstacle(1, 0.20, rect(3.0, 3.3, -0.1, 0.1), kind='box')


def test_geometry_helpers():
    sq = rect(0, 1, 0, 1)
    assert polygon_distance(sq, np.array([0.5, 0.5])) == 0.0
    assert polygon_distance(sq[::-1], np.array([0.5, 0.5])) == 0.0
    assert polygon_distance(sq, np.array([2.0, 0.5])) == pytest.approx(1.0)
    f = walk(1)[0]
    # in the corridor from 3 m; a footprint straddling its edge is clipped to it
    assert corridor_range(BOX, f, 0.5, 5.0) == pytest.approx(3.0)
    side = TrueObstacle(2, 0.2, rect(2.0, 2.2, 0.4, 1.0))
    assert corridor_range(side, f, 0.5, 5.0) == pytest.approx(math.hypot(2.0, 0.4))
    assert corridor_range(TrueObstacle(3, 0.2, rect(2.0, 2.2, 0.6, 1.0)), f, 0.5, 5.0) is None
    assert corridor_range(TrueObstacle(4, 0.2, rect(-2, -1, -0.1, 0.1)), f, 0.5, 5.0) is None
    assert corridor_range(TrueObstacle(5, 0.2, rect(5.5, 6, -0.1, 0.1)), f, 0.5, 5.0) is None


def test_warned_when_the_alarm_is_stamped_exactly_at_the_first_frame_on_the_path():
    # the box's near edge at 3 m comes within 2.5 m at x = 0.5 m, frame 5
    truth = SafetyTruth([BOX], walk(25))
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR), alarm(5, AlarmLevel.CAUTION, 1, 2.5)])
    assert (s.on_path, s.warned, s.late, s.never, s.under_fault) == (1, 1, 0, 0, 0)
    assert s.path_obstacles[0]['first_t_s'] == pytest.approx(0.5)
    assert s.path_obstacles[0]['first_range_m'] == pytest.approx(2.5)
    # one nanosecond later is late: CLEAR was in force at the first frame on the path
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR),
                             alarm(5, AlarmLevel.CAUTION, 1, 2.5, extra_ns=1)])
    assert (s.warned, s.late, s.never) == (0, 1, 0)
    assert s.frames_on_path_clear == 1
    # the frames on the path: x from 0.5 to 2.4, 20
    assert s.frames_on_path == 20


def test_what_the_warning_of_a_warned_obstacle_was_about():
    """Warned in time counts any CAUTION or higher in force (the definition); what that
    warning was about is told apart. At the box's first pair on the path (x = 0.5 m, the
    box 2.5 m ahead): a CAUTION placed on the box, stamped two pairs before, is about
    *itself*; a STOP about a bin 1 m ahead beside the path is *nearer* (it outranks the
    box); a CAUTION about a post 2.9 m off is *farther*: the box was not the nearest thing
    the alarm knew of, so it went unseen, warned by chance."""
    post = TrueObstacle(2, 1.0, rect(2.9, 3.0, 1.4, 1.5), kind='post')
    bin_ = TrueObstacle(3, 0.8, rect(1.4, 1.6, 0.7, 0.9), kind='bin')
    truth = SafetyTruth([BOX, post, bin_], walk(25))
    cases = [(alarm(3, AlarmLevel.CAUTION, 1, 2.7), 'itself'),
             (alarm(5, AlarmLevel.STOP, 3, math.hypot(1.0, 0.8), math.atan2(0.8, 1.0)),
              'nearer'),
             (alarm(5, AlarmLevel.CAUTION, 2, math.hypot(2.45, 1.45), math.atan2(1.45, 2.45)),
              'farther')]
    for a, want in cases:
        s = score_safety(truth, [a])
        assert (s.on_path, s.warned) == (1, 1)
        assert s.path_obstacles[0]['warned_by'] == want
        assert s.warned_by_farther == int(want == 'farther')
        told = any('(box, 20 cm): warned by an alarm about something farther off' in ln
                   for ln in format_safety(s.as_dict()))
        assert told == (want == 'farther')
    # not warned: nothing to tell
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR)])
    assert (s.warned, s.warned_by_farther) == (0, 0)
    assert s.path_obstacles[0]['warned_by'] is None


def test_cue_lead_is_the_range_where_the_cue_began_over_the_walking_speed():
    # walking at 1 m/s towards the box (near edge at 3 m): a CAUTION at frame 0 (3.0 m)
    # leads contact by 3 s; one at frame 2 (2.8 m) by 2.8 s: warned in time both, cued
    # 3 s ahead only the first
    truth = SafetyTruth([BOX], walk(25))
    s = score_safety(truth, [alarm(0, AlarmLevel.CAUTION, 1, 3.0)])
    assert (s.warned, s.cued_ahead) == (1, 1)
    assert s.path_obstacles[0]['cue_lead_s'] == pytest.approx(3.0)
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR), alarm(2, AlarmLevel.CAUTION, 1, 2.8)])
    assert (s.warned, s.cued_ahead) == (1, 0)
    assert s.path_obstacles[0]['cue_lead_s'] == pytest.approx(2.8)
    # at 2 m/s the same 3 m are 1.5 s
    s = score_safety(SafetyTruth([BOX], walk(15, speed=2.0)), [alarm(0, AlarmLevel.CAUTION)])
    assert s.path_obstacles[0]['cue_lead_s'] == pytest.approx(1.5) and s.cued_ahead == 0
    # a standing wearer has no contact time: a cue counts as ahead
    s = score_safety(SafetyTruth([TrueObstacle(1, 0.2, rect(2.0, 2.3, -0.1, 0.1))],
                                 walk(10, speed=0.0)), [alarm(0, AlarmLevel.WARNING)])
    assert s.cued_ahead == 1 and s.path_obstacles[0]['cued_standing']
    assert 'cued at least 3 s before contact 1/1' in '\n'.join(format_safety(s.as_dict()))


def test_an_obstacle_that_comes_into_the_corridor_late_is_cued_at_entry_or_not():
    # the box steps into the path at frame 8 (x = 0.8 m: 2.2 m, 2.2 s before contact at
    # 1 m/s), as a passer-by does: no cue could lead by more than 2.2 s
    late = TrueObstacle(1, 0.2, rect(3.0, 3.3, -0.1, 0.1), appear_ns=S0 + 8 * DT, kind='box')
    truth = SafetyTruth([late], walk(25))
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR), alarm(8, AlarmLevel.CAUTION, 1, 2.2)])
    o = s.path_obstacles[0]
    assert o['corridor_lead_s'] == pytest.approx(2.2) and o['cue_lead_s'] == pytest.approx(2.2)
    assert (s.cued_ahead, s.cued_at_entry) == (0, 1)
    assert 'and 1 that came into the corridor later' in '\n'.join(format_safety(s.as_dict()))
    # cued three pairs after it came: neither
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR), alarm(11, AlarmLevel.CAUTION, 1, 1.9)])
    assert (s.cued_ahead, s.cued_at_entry) == (0, 0)
    assert s.path_obstacles[0]['cue_lead_s'] == pytest.approx(1.9)


def test_fault_at_the_first_frame_on_the_path_counts_apart_and_clear_is_never():
    truth = SafetyTruth([BOX], walk(25))
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR), alarm(5, AlarmLevel.FAULT),
                             alarm(6, AlarmLevel.WARNING, 1, 2.4)])
    assert (s.warned, s.late, s.never, s.under_fault) == (0, 0, 0, 1)
    assert s.frames_on_path_fault == 1 and s.frames_on_path_clear == 0
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR)])
    assert (s.warned, s.late, s.never) == (0, 0, 1)
    assert s.frames_on_path_clear == s.frames_on_path == 20
    # nothing said at all counts as no warning, not as a FAULT
    s = score_safety(truth, [])
    assert s.never == 1 and s.frames_on_path_clear == 20


def test_low_side_and_drop_obstacles_on_the_path():
    low = TrueObstacle(2, 0.05, rect(3.0, 3.3, -0.1, 0.1))
    beside = TrueObstacle(3, 0.5, rect(2.0, 3.0, 0.6, 0.9))
    drop = TrueObstacle(4, -0.15, rect(3.5, 7.5, -3.0, 3.0), ground_region=True, kind='drop')
    s = score_safety(SafetyTruth([low, beside, drop], walk(20)), [alarm(0, AlarmLevel.CLEAR)])
    assert [o['id'] for o in s.path_obstacles] == [4]
    assert s.path_obstacles[0]['first_range_m'] == pytest.approx(2.5)
    assert s.never == 1


def test_terrace_under_the_wearer_is_ground():
    kerb = TrueObstacle(5, 0.12, rect(1.0, 5.0, -3.0, 3.0), ground_region=True)
    truth = SafetyTruth([kerb], walk(30))
    assert truth.present(truth.frames[5]) == [kerb]
    assert truth.present(truth.frames[15]) == []


def test_false_alarm_events_per_minute_of_walking():
    truth = SafetyTruth([BOX], walk(600))          # 60 s walking at 1 m/s
    alarms = [alarm(0, AlarmLevel.CLEAR),
              alarm(1, AlarmLevel.CAUTION, 7, 2.0),      # 2 m short of the box: false
              alarm(21, AlarmLevel.CAUTION, 7, 0.2),     # a repeat, same level and id
              alarm(22, AlarmLevel.WARNING, 7, 0.5, 1.2),  # level changed: a new event
              alarm(30, AlarmLevel.WARNING, 1, 0.05),    # the box at x 3 - 3.3: true
              alarm(40, AlarmLevel.WARNING, 7, 2.0, 1.2)]  # id changed, far off: new event
    s = score_safety(truth, alarms)
    assert len(s.false_alarm_events) == 3
    assert s.alarms_false == 4 and s.alarms_warning == 5
    e = s.false_alarm_events[0]
    assert e['t_s'] == pytest.approx(0.1) and e['level_name'] == 'CAUTION'
    assert e['nearest_true_m'] == pytest.approx(0.9)       # alarm at x 2.1, box at 3.0
    walking_s = s.walking_s
    assert walking_s == pytest.approx(60.0, abs=0.2)
    assert s.false_alarms_per_minute == pytest.approx(3 / (walking_s / 60))


def test_an_obstacle_out_of_view_or_behind_still_counts_for_false_alarms():
    # the wearer has walked past the box (x 3.0-3.3) to x = 3.9: an alarm 0.3 m behind
    # falls on it (out of view, behind the camera) and is not false
    truth = SafetyTruth([BOX], walk(40))
    s = score_safety(truth, [alarm(39, AlarmLevel.STOP, 1, 0.45, math.pi)])
    assert s.alarms_false == 0 and not s.false_alarm_events
    # standing still: no walking time, no rate
    still = SafetyTruth([BOX], walk(40, speed=0.0))
    s = score_safety(still, [alarm(3, AlarmLevel.CAUTION, 2, 1.0)])
    assert len(s.false_alarm_events) == 1
    assert s.walking_s == 0.0 and s.false_alarms_per_minute is None


def test_obstacle_not_yet_there_does_not_excuse_an_alarm():
    late = TrueObstacle(1, 0.2, rect(3.0, 3.3, -0.1, 0.1), appear_ns=S0 + 20 * DT)
    truth = SafetyTruth([late], walk(10, speed=0.0))
    s = score_safety(truth, [alarm(2, AlarmLevel.CAUTION, 1, 3.0)])
    assert s.alarms_false == 1


def reports(stamp, rows):
    """FrameObstacles from (range, bearing, height) rows."""
    a = np.array(rows, float).reshape(-1, 3)
    n = len(a)
    return FrameObstacles(stamp, np.arange(1, n + 1), np.zeros((n, 3)), a[:, 2], a[:, 0],
                          a[:, 1], np.zeros((n, 4), int))


def test_false_reports_and_recall_with_drops():
    drop = TrueObstacle(2, -0.15, rect(4.0, 8.0, -3.0, 3.0), ground_region=True)
    frames = walk(3, speed=0.0, visible={1: 30, 2: 500})
    truth = SafetyTruth([BOX, drop], frames)
    det = {frames[0].stamp_ns: reports(frames[0].stamp_ns, [(3.05, 0.0, 0.2),   # on the box
                                                            (3.0, 0.4, 0.2),    # 1.2 m off
                                                            (4.1, 0.0, 0.15)]),  # +h on drop
           frames[1].stamp_ns: reports(frames[1].stamp_ns, [(4.1, 0.0, -0.12),  # the drop
                                                            (3.1, 0.02, 0.1),  # the box
                                                            (3.2, 0.0, 0.1)]),  # 2nd on box
           }
    s = score_safety(truth, [], det)
    assert s.frames_scored == 2 and s.frames_missing == 1
    assert s.reports == 6
    assert s.false_reports == 2          # 1.2 m off the box; positive report on the drop
    assert s.false_reports_per_frame == pytest.approx(1.0)
    # recall: frame 0 finds the box only; frame 1 both (one report each, one to one)
    assert (s.recall_found, s.recall_eligible) == (3, 4)
    # tolerance grows with range: 10 % of 5 m is 0.5 m
    far = TrueObstacle(3, 0.3, rect(5.0, 5.2, -0.1, 0.1))
    f = walk(1, speed=0.0, visible={3: 100})
    s = score_safety(SafetyTruth([far], f), [],
                     {f[0].stamp_ns: reports(f[0].stamp_ns, [(5.45, 0.0, 0.3)])})
    assert s.false_reports == 0 and s.recall_found == 1


def test_recall_needs_pixels_in_both_images():
    frames = walk(1, speed=0.0, visible={1: 19})
    s = score_safety(SafetyTruth([BOX], frames), [],
                     {frames[0].stamp_ns: reports(frames[0].stamp_ns, [(3.0, 0.0, 0.2)])})
    assert s.recall_eligible == 0 and s.false_reports == 0
    s = score_safety(SafetyTruth([BOX], frames), [],
                     {frames[0].stamp_ns: reports(frames[0].stamp_ns, [])},
                     SafetyCriteria(recall_min_pixels=10))
    assert (s.recall_found, s.recall_eligible) == (0, 1)
    assert s.as_dict()['recall']['bin_eligible'][3][2] == 1     # 20-50 cm x 3-4 m


def test_walking_mask_window():
    frames = walk(10, speed=0.0) + [
        TruthFrame(S0 + (10 + k) * DT, R_X, np.array([0.1 * k, 0.0, 1.25])) for k in range(20)]
    w, iv = walking_mask(SafetyTruth([], frames), 0.2, 1.0)
    assert not w[:5].any() and w[12:].all()
    assert iv.sum() == pytest.approx(3.0)


def test_fault_while_walking_is_its_share_of_the_walking_time():
    """FAULT in force while standing (starting up) does not count; FAULT while walking
    does, each frame for its interval, whatever cleared it."""
    frames = walk(10, speed=0.0) + [
        TruthFrame(S0 + (10 + k) * DT, R_X, np.array([0.1 * k, 0.0, 1.25])) for k in range(40)]
    truth = SafetyTruth([], frames)
    s = score_safety(truth, [alarm(0, AlarmLevel.FAULT), alarm(10, AlarmLevel.CLEAR),
                             alarm(25, AlarmLevel.FAULT), alarm(35, AlarmLevel.CAUTION, 3, 2.0),
                             alarm(40, AlarmLevel.FAULT)])
    walking, interval = walking_mask(truth, SafetyCriteria().walking_speed,
                                     SafetyCriteria().walking_window_s)
    i = np.arange(50)
    fault = (i < 10) | ((i >= 25) & (i < 35)) | (i >= 40)
    want = float(interval[walking & fault].sum())
    # the 2 s walked under FAULT, and the last standing frames that the centred window
    # already counts as walking (at most half the window)
    assert 2.0 - 1e-6 <= want <= 2.0 + 0.5 * SafetyCriteria().walking_window_s
    assert s.walking_fault_s == pytest.approx(want)
    assert s.fault_share_walking == pytest.approx(want / s.walking_s)
    m = type(s).merge([s, s])
    assert m.walking_fault_s == pytest.approx(2 * want)
    assert m.as_dict()['fault_share_walking'] == pytest.approx(want / s.walking_s)
    # no walking: no share
    still = score_safety(SafetyTruth([], walk(10, speed=0.0)), [alarm(0, AlarmLevel.FAULT)])
    assert still.walking_fault_s == 0.0 and still.fault_share_walking is None


def test_scores_merge():
    truth = SafetyTruth([BOX], walk())
    a = score_safety(truth, [alarm(0, AlarmLevel.CLEAR)])
    b = score_safety(truth, [alarm(0, AlarmLevel.CAUTION, 1, 3.0)])
    m = type(a).merge([a, b])
    assert (m.on_path, m.warned, m.never) == (2, 1, 1)
    assert m.as_dict()['warned_in_time']['on_path'] == 2


def test_replay_alarms_as_the_node():
    empty = FrameObstacles.empty
    near = lambda s: reports(s, [(2.0, 0.0, 0.2)])  # noqa: E731
    outs = [(S0 + k * DT, 'tracking', empty(S0 + k * DT)) for k in range(5)]
    outs += [(S0 + 5 * DT, 'tracking', near(S0 + 5 * DT))]
    outs += [(S0 + 25 * DT, 'tracking', empty(S0 + 25 * DT))]   # 2 s without an answer
    outs += [(S0 + 26 * DT, 'tracking', empty(S0 + 26 * DT))]
    al = replay_alarms(outs)
    levels = [(a['stamp_ns'] - S0, AlarmLevel(a['level']).name) for a in al]
    assert levels[0] == (-1, 'FAULT')                      # starting up
    # the first list comes before the first TRACKING /ground_plane: CLEAR on the second
    assert levels[1] == (DT, 'CLEAR')
    assert levels[2] == (5 * DT, 'WARNING')
    assert al[2]['range'] == pytest.approx(2.0)
    # the node's timer: no /obstacles for more than the timeout after 0.5 s -> FAULT
    fault = [a for a in al[3:] if a['level'] == AlarmLevel.FAULT]
    timeout = AlarmConfig().timeout
    assert fault and (fault[0]['stamp_ns'] - S0) / 1e9 == pytest.approx(0.5 + timeout,
                                                                          abs=0.06)
    # lists back: the ground status from before the gap is stale, so the level comes with
    # the first list after a fresh TRACKING status (the node's order: list, then status)
    assert al[-1]['level'] == AlarmLevel.CLEAR and al[-1]['stamp_ns'] == S0 + 26 * DT


def test_replay_alarms_with_egomotion_levels_by_time_to_contact_as_the_node():
    """Given the pairs' /egomotion (1.2 m/s straight ahead), the replay gives the logic
    the walking speed as the alarm node does: an obstacle 3.3 m ahead is 2.75 s away,
    WARNING by time to contact (by range alone, CAUTION); a motion with no pair before
    it (the first) or after a gap of a second or more gives no speed."""
    step = np.array([0.0, 0.0, 0.12])            # optical z forward, 0.1 s
    ahead = lambda s: reports(s, [(3.3, 0.0, 0.2)])  # noqa: E731
    outs = [(S0 + k * DT, 'tracking', ahead(S0 + k * DT)) for k in range(12)]
    levels = {}
    for name, motions in (('none', None), ('walking', [step] * 12),
                          ('gaps', [step if k % 11 == 0 else None for k in range(12)])):
        al = replay_alarms(outs, motions=motions)
        levels[name] = [AlarmLevel(a['level']).name for a in al if a['level'] < 4]
    assert set(levels['none']) == {'CAUTION'}
    assert set(levels['walking']) == {'WARNING'}
    assert set(levels['gaps']) == {'CAUTION'}
    with pytest.raises(ValueError, match='motions'):
        replay_alarms(outs, motions=[step])


def test_run_summary_has_the_safety_score():
    """`asmonc run`'s summary scores the recorded /alarms and /obstacles: here the
    static bag's truth reported back as the detections (nothing false), and a WARNING
    about the post from the first frame it is on the path."""
    import threading
    from types import SimpleNamespace

    from asmonc_vision.replay.summary import read_truth, summarise
    from asmonc_vision.eval.truth import truth_from_bag
    from conftest import BAGS

    bag = BAGS / 'static_obstacles'
    truth = read_truth(bag)
    st = truth_from_bag(bag)
    # the bundled bags carry every obstacle's footprint polygon in their metadata
    assert st is not None and st.obstacles
    assert all(not o.points and len(o.footprint) >= 3 for o in st.obstacles)
    first = min(truth)
    on = score_safety(st, [alarm(0, AlarmLevel.CLEAR)]).path_obstacles
    assert len(on) == 1
    t_on = first + int(round(on[0]['first_t_s'] * 1e9))
    alarms = [{'stamp_ns': first, 'level': 0, 'obstacle_id': 0, 'range': 0.0, 'bearing': 0.0},
              {'stamp_ns': t_on, 'level': 2, 'obstacle_id': on[0]['id'],
               'range': on[0]['first_range_m'], 'bearing': 0.0}]
    mon = SimpleNamespace(lock=threading.Lock(), detections=dict(truth), alarms=alarms,
                          gait_states=0, gait_walking=0)
    args = SimpleNamespace(bag=bag, rate=1.0, match_radius=0.3, min_height=0.1, max_range=5.0,
                           params_file=[])
    s = summarise(mon, truth, len(truth), args, None, st)['safety']
    assert s['warned_in_time']['warned'] == 1 and s['warned_in_time']['on_path'] == 1
    assert s['false_reports']['total'] == 0 and s['false_reports']['frames_scored'] == len(truth)
    assert s['false_alarms']['events'] == 0
    assert s['recall']['recall'] == 1.0


def test_a_moving_obstacle_is_scored_where_it_is_at_each_frame():
    """A person crossing the path 3 m ahead: its footprint follows its track, so a
    report on it at each frame is not false, and a report where it stood at the start
    is; it is on the path only while it crosses the corridor."""
    frames = walk(30, speed=0.0, visible={1: 100})
    stamps = np.array([f.stamp_ns for f in frames], np.int64)
    ys = np.linspace(-3.0, 3.0, len(frames))
    feet = [rect(3.0, 3.3, y - 0.2, y + 0.2) for y in ys]
    person = TrueObstacle(1, 1.7, feet[0], kind='person', track=(stamps, feet))
    truth = SafetyTruth([person], frames)
    assert np.array_equal(truth.present(frames[20])[0].footprint, feet[20])
    assert np.array_equal(person.placed(S0 - DT).footprint, feet[0])
    on_track = {f.stamp_ns: FrameObstacles(
        f.stamp_ns, np.array([7]), np.zeros((1, 3)), np.array([1.7]),
        np.array([math.hypot(3.15, y)]), np.array([math.atan2(y, 3.15)]),
        np.zeros((1, 4), int)) for f, y in zip(frames, ys)}
    at_start = {f.stamp_ns: FrameObstacles(
        f.stamp_ns, np.array([7]), np.zeros((1, 3)), np.array([1.7]),
        np.array([math.hypot(3.15, ys[0])]), np.array([math.atan2(ys[0], 3.15)]),
        np.zeros((1, 4), int)) for f in frames}
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR)], on_track)
    assert s.false_reports == 0 and s.recall == 1.0
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR)], at_start)
    tol = 0.1 * math.hypot(3.15, ys[0])          # the report tolerance there (> 0.3 m)
    assert s.false_reports == int(np.sum(np.abs(ys - ys[0]) - 0.2 > tol)) > len(frames) // 2
    s = score_safety(truth, [alarm(0, AlarmLevel.CLEAR)], on_track, SafetyCriteria(
        on_path_range=4.0))
    assert s.on_path == 1 and 0 < s.frames_on_path < len(frames)
