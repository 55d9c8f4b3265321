"""Obstacle tracks (core.obstacle_tracks): Kalman filtering, gating, coasting, births and
deaths, and camera motion as the input. No ROS."""
import numpy as np
import pytest

from asmonc_vision.core.obstacle_tracks import ObstacleTracker

STILL = (np.eye(3), np.zeros(3))
R1 = np.eye(3) * 0.05 ** 2


def step(tr, stamp, feet, free=None):
    """One frame: predict with the identity, update with ``feet`` (K, 3)."""
    feet = np.asarray(feet, float).reshape(-1, 3)
    tr.predict(stamp, STILL)
    return tr.update(feet, np.repeat(R1[None], len(feet), 0), list(range(len(feet))), free)


def test_static_obstacle_keeps_its_id_and_the_filter_beats_one_measurement():
    rng = np.random.default_rng(3)
    truth = np.array([0.3, 1.2, 2.5])
    tr = ObstacleTracker(process_noise_m=0.0)
    ids, err_meas, err_track = set(), [], []
    for k in range(30):
        z = truth + rng.normal(0, 0.03, 3)      # within the modelled R = (0.05 m)² I
        out = step(tr, 0.1 * k, [z])
        assert len(out) == 1 and out[0].index == 0 and out[0].age_s == 0.0
        ids.add(out[0].track_id)
        err_meas.append(np.linalg.norm(z - truth))
        err_track.append(np.linalg.norm(out[0].foot - truth))
    assert ids == {1}
    assert np.mean(err_track[10:]) < 0.5 * np.mean(err_meas[10:])
    # P shrinks like R / n for a static point (no process noise)
    assert np.allclose(np.diag(out[0].foot_cov), 0.05 ** 2 / 30, rtol=1e-6)


def test_coasting_bridges_missed_frames_then_the_track_ends():
    tr = ObstacleTracker(coast_s=0.25, min_hit_fraction=0.0)
    p = [0.0, 1.2, 3.0]
    step(tr, 0.0, [p])
    step(tr, 0.1, [p])
    out = step(tr, 0.2, [])                 # missed: z = None
    assert len(out) == 1 and out[0].index == -1 and out[0].age_s == pytest.approx(0.1)
    assert np.allclose(out[0].foot, p)
    assert step(tr, 0.3, [])[0].age_s == pytest.approx(0.2)
    assert step(tr, 0.4, []) == []          # 0.3 s > coast_s
    assert len(tr) == 0


def test_a_track_seen_in_too_few_frames_is_not_coasted():
    tr = ObstacleTracker(coast_s=10.0, min_hit_fraction=0.5)
    step(tr, 0.0, [[0.0, 1.2, 3.0]])
    assert len(step(tr, 0.1, [])) == 1      # 1 of 2 frames
    assert step(tr, 0.2, []) == []          # 1 of 3 frames: ended


def test_a_track_seen_often_enough_is_coasted_whatever_its_hit_fraction():
    # seen in 3 frames, then missed: 3 of 7 frames is under the fraction, but 3 sure hits
    # carry it on until coast_s; without sure_hits it ends at 3 of 7
    p = [0.0, 1.2, 5.0]
    for sure, alive_until in ((3, 1.2), (0, 0.5)):
        tr = ObstacleTracker(coast_s=1.0, min_hit_fraction=0.5, sure_hits=sure)
        for k in range(3):
            step(tr, 0.1 * k, [p])
        alive = [len(step(tr, 0.1 * k, [])) == 1 for k in range(3, 15)]
        last = 0.1 * (2 + sum(alive))
        assert alive == sorted(alive, reverse=True)          # ends once, stays ended
        assert last == pytest.approx(alive_until), sure
    # two hits are not sure: 2 of 5 frames ends it
    tr = ObstacleTracker(coast_s=1.0, min_hit_fraction=0.5, sure_hits=3)
    step(tr, 0.0, [p])
    step(tr, 0.1, [p])
    assert [len(step(tr, 0.1 * k, [])) for k in range(2, 5)] == [1, 1, 0]


def test_confirm_hits():
    tr = ObstacleTracker(confirm_hits=2, min_hit_fraction=0.0)
    step(tr, 0.0, [[0.0, 1.2, 3.0]])
    assert step(tr, 0.1, []) == []          # one detection is not carried on


def test_free_space_ends_an_undetected_track_at_once():
    tr = ObstacleTracker(coast_s=5.0)
    step(tr, 0.0, [[0.0, 1.2, 3.0]])
    seen = []

    def free(payload, foot):
        seen.append((payload, foot))
        return True

    assert step(tr, 0.1, [], free) == []
    assert seen and seen[0][0] == 0 and np.allclose(seen[0][1], [0.0, 1.2, 3.0])


def test_an_obstacle_walked_up_to_is_remembered_below_the_view():
    """A sure track whose place has left the view is carried for unseen_coast_s, not
    coast_s; the free-space test still ends it; a track not sure ends at once."""
    p = [0.0, 1.2, 1.0]
    below = lambda payload, foot: True       # noqa: E731  (every place out of view)

    def run(hits, free=None):
        tr = ObstacleTracker(coast_s=0.3, min_hit_fraction=0.5, sure_hits=3,
                             unseen_coast_s=2.0)
        for k in range(hits):
            step(tr, 0.1 * k, [p])
        alive = 0
        for k in range(hits, hits + 40):
            tr.predict(0.1 * k, STILL)
            out = tr.update(np.zeros((0, 3)), np.zeros((0, 3, 3)), [], free, None, below)
            if not out:
                break
            assert out[0].age_s > 0 and np.allclose(out[0].foot, p)
            alive += 1
        return alive

    assert run(3) == 20                      # 2.0 s after the last detection, not 0.3 s
    assert run(2) == 0                       # 2 hits are not sure: out of view ends it
    assert run(3, free=lambda payload, foot: True) == 0
    # without the unseen test the same track ends after coast_s
    tr = ObstacleTracker(coast_s=0.3, min_hit_fraction=0.5, sure_hits=3, unseen_coast_s=2.0)
    for k in range(3):
        step(tr, 0.1 * k, [p])
    assert [len(step(tr, 0.1 * k, [])) for k in range(3, 7)] == [1, 1, 1, 0]
    with pytest.raises(ValueError, match='unseen_coast_s'):
        ObstacleTracker(unseen_coast_s=-1.0)


def test_an_unknown_motion_ends_the_tracks_but_holds_the_sure_ones_below_the_view():
    """With no motion known, tracks end -- except a sure track the hold test keeps (an
    obstacle below the view): it stays where it was, more uncertain, and update ends it
    as usual after unseen_coast_s."""
    near, ahead = [0.0, 1.2, 1.0], [0.5, 1.2, 3.0]
    below = lambda payload, foot: foot[2] < 2.0      # noqa: E731  (the near one is)

    def tracker(hits):
        tr = ObstacleTracker(coast_s=0.3, min_hit_fraction=0.5, sure_hits=3,
                             unseen_coast_s=0.5)
        for k in range(hits):
            step(tr, 0.1 * k, [near, ahead])
        return tr

    tr = tracker(3)
    p0 = tr._P[0].copy()
    cov = 0.15 ** 2 * np.eye(3)
    tr.predict(0.3, None, cov, hold=below)
    assert len(tr) == 1 and np.allclose(tr._x[0], near)         # the one in view ended
    assert np.allclose(tr._P[0], p0 + cov + 0.05 ** 2 * 0.1 * np.eye(3))
    alive = []
    for k in range(3, 12):
        if k > 3:
            tr.predict(0.1 * k, None, cov, hold=below)
        out = tr.update(np.zeros((0, 3)), np.zeros((0, 3, 3)), [], None, None,
                        lambda payload, foot: True)
        alive.append(len(out))
    assert alive == [1, 1, 1, 1, 1, 0, 0, 0, 0]      # 0.5 s after its last detection
    # not sure (2 hits): ends; no hold test: all end, as before
    tr = tracker(2)
    tr.predict(0.2, None, cov, hold=below)
    assert len(tr) == 0
    tr = tracker(3)
    tr.predict(0.3, None)
    assert len(tr) == 0


def test_gating_a_far_detection_starts_a_new_track():
    tr = ObstacleTracker(min_hit_fraction=0.0)
    step(tr, 0.0, [[0.0, 1.2, 3.0]])
    out = step(tr, 0.1, [[0.6, 1.2, 3.0]])   # 0.6 m away: d² = 0.36 / (2 · 0.0025) = 72
    assert [o.index for o in out] == [0, -1]
    assert out[0].track_id == 2 and out[1].track_id == 1
    # nearest neighbour: of two detections the nearer one updates the track
    tr = ObstacleTracker()
    step(tr, 0.0, [[0.0, 1.2, 3.0]])
    out = step(tr, 0.1, [[0.09, 1.2, 3.0], [0.02, 1.2, 3.0]])
    by_index = {o.index: o.track_id for o in out}
    assert by_index[1] == 1 and by_index[0] == 2


def test_camera_motion_is_the_input():
    """The camera walks 0.5 m forward and turns 5 degrees left between frames: the track
    follows the obstacle into the new frame and keeps its id."""
    tr = ObstacleTracker(process_noise_m=0.0, min_hit_fraction=0.0)
    world = np.array([0.4, 1.2, 4.0])        # the obstacle in the first camera frame
    tr.predict(0.0, None)
    tr.update(world[None], R1[None], ['a'])
    a = np.radians(5.0)
    # the current frame's orientation in the previous one: a yaw left is a rotation
    # about the optical -y axis (y down)
    Rc = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    tc = np.array([0.0, 0.0, 0.5])
    cur = Rc.T @ (world - tc)                # X_prev = R X_curr + t
    tr.predict(0.1, (Rc, tc))
    out = tr.update(np.zeros((0, 3)), np.zeros((0, 3, 3)), [])
    assert np.allclose(out[0].foot, cur)     # coasted through the motion
    tr.predict(0.2, STILL)
    out = tr.update(cur[None] + 0.01, R1[None], ['b'])
    assert len(out) == 1 and out[0].track_id == 1 and out[0].payload == 'b'
    # unknown motion: the tracks cannot be carried and end
    tr.predict(0.3, None)
    assert len(tr) == 0


def test_time_going_back_ends_the_tracks():
    tr = ObstacleTracker()
    step(tr, 1.0, [[0.0, 1.2, 3.0]])
    tr.predict(0.5, STILL)
    assert len(tr) == 0


@pytest.mark.parametrize('kw', [dict(coast_s=-1.0), dict(gate_chi2=0.0),
                                dict(process_noise_m=-0.1), dict(confirm_hits=0),
                                dict(min_hit_fraction=1.5), dict(sure_hits=-1)])
def test_bad_settings_name_the_field(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        ObstacleTracker(**kw)


def test_mismatched_inputs_raise():
    tr = ObstacleTracker()
    tr.predict(0.0, STILL)
    with pytest.raises(ValueError):
        tr.update(np.zeros((2, 3)), np.zeros((1, 3, 3)), [0, 1])


def test_a_detection_of_the_same_obstacle_elsewhere_keeps_the_track_seen():
    """A far-corner report of the obstacle (outside the gate, but the same obstacle by
    the caller's test) keeps the near track seen without moving it; a detection of
    another obstacle does not."""
    near, far = [0.0, 1.2, 3.0], [0.5, 1.2, 3.4]
    same = lambda a, b: {a, b} == {'box-near', 'box-far'}    # noqa: E731
    tr = ObstacleTracker(coast_s=0.15, min_hit_fraction=0.5)
    tr.predict(0.0, STILL)
    tr.update(np.array([near]), R1[None], ['box-near'])
    for k in range(1, 6):                   # 0.5 s, beyond coast_s
        tr.predict(0.1 * k, STILL)
        out = tr.update(np.array([far]), R1[None], ['box-far'], same_object=same)
        ids = {o.payload: o for o in out}
        assert set(ids) == {'box-near', 'box-far'}
        assert ids['box-near'].age_s == 0.0 and np.allclose(ids['box-near'].foot, near)
    tr = ObstacleTracker(coast_s=0.15, min_hit_fraction=0.5)
    tr.predict(0.0, STILL)
    tr.update(np.array([near]), R1[None], ['box-near'])
    for k in range(1, 4):
        tr.predict(0.1 * k, STILL)
        out = tr.update(np.array([far]), R1[None], ['post'], same_object=same)
    assert [o.payload for o in out] == ['post']
