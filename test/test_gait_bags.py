"""`asmonc gait bags`: the walk model on a committed walking bag, with the visual motion
of the egomotion estimator (no ROS)."""
import numpy as np
import pytest

from asmonc_vision.eval import gait_bags
from asmonc_vision.core.gait import scoring

from conftest import BAGS


@pytest.fixture(scope='module')
def walk():
    return gait_bags.load_bag(BAGS / 'walk_obstacles')


def test_bag_streams_agree_with_each_other(walk):
    # the rig attitude from the camera's ground-truth pose (through the fixed mounting)
    # is what the inclinometer measures: 0.3 deg noise, 0.1 deg steps, an 80 ms lag
    att, speed = gait_bags._truth(walk)
    # (the lag taken as a delay: 0.3 / 0.53 / 0.35 deg; with none 0.53 / 1.15 / 0.75 deg;
    # a wrong camera mounting would be tens of degrees off)
    d = scoring.angle_errors_deg(walk.imu_rpy, att(walk.imu_times - 0.08))
    assert walk.imu_times.size > 100 and walk.frame_times.size == 75
    assert np.sqrt(np.mean(d ** 2, axis=0)).max() < 0.8, np.sqrt(np.mean(d ** 2, axis=0))
    # the spline passes through the poses; the walker stands for 1.1 s, then walks
    assert np.allclose(att(walk.frame_times), walk.truth_rpy)
    assert speed(0.3)[0] < 0.2 and 1.0 < speed(5.0)[0] < 1.4
    # a visual motion per pair after the first, each from its reference frame
    assert len(walk.egomotion) >= 70 and walk.motion_status.get('ok', 0) >= 70
    for t_prev, t_cur, r in walk.egomotion:
        assert 0 < t_cur - t_prev <= 0.21
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-9)


def test_fusion_on_the_bag(walk):
    res = gait_bags.evaluate_bag(walk)
    assert set(res) == set(gait_bags.MODES)
    n = res['fused']['attitude_err'].shape[0]
    assert n > 30                               # steady walking from ~3.6 s on
    rms = {m: scoring.rms(r['attitude_err']) for m, r in res.items()
           if r['attitude_err'].size}
    # the walk model with both sources predicts the attitude 0.5 s ahead to under a
    # degree (0.18 / 0.22 / 0.64 deg), and no worse than with the inclinometer alone
    # (0.19 / 0.38 / 0.65 deg)
    assert np.all(rms['fused'] < 0.8), rms['fused']
    assert np.all(rms['fused'] <= rms['inclinometer'] + 0.02), (rms['fused'],
                                                               rms['inclinometer'])
    # visual motion alone observes no absolute roll and yaw: those drift
    assert rms['egomotion'][2] > rms['fused'][2]
    assert res['fused']['egomotion_used'] > 40 and res['inclinometer']['egomotion_used'] == 0
    summary = gait_bags.summarise({'walk': res})
    assert summary['fused']['samples'] == n


def _counts(bag):
    """{topic: message count} of a bag."""
    from rosbags.rosbag2 import Reader

    with Reader(bag) as r:
        return {c.topic: c.msgcount for c in r.connections}


def _copy_without(src, dst, drop):
    """A copy of the bag `src` at `dst` without the topics whose names start with `drop`
    (which `src` has), every other topic's messages intact: a refusal of the copy is for
    the dropped topics alone."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    from asmonc_vision.io import bagio

    ts = bagio.typestore()
    with Reader(src) as r, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        keep = [c for c in r.connections if not c.topic.startswith(drop)]
        out = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts) for c in keep}
        for c, t, raw in r.messages(connections=keep):
            w.write(out[c.id], t, raw)
    before = _counts(src)
    assert any(t.startswith(drop) and n > 0 for t, n in before.items()), before
    assert _counts(dst) == {t: n for t, n in before.items() if not t.startswith(drop)}
    return dst


def test_a_bag_without_ground_truth_is_refused(tmp_path):
    bag = _copy_without(BAGS / 'clear_static', tmp_path / 'no_truth', '/ground_truth/')
    with pytest.raises(ValueError, match='no /ground_truth/camera_pose'):
        gait_bags.load_bag(bag)


def test_a_bag_without_inclinometer_is_refused(tmp_path):
    bag = _copy_without(BAGS / 'clear_static', tmp_path / 'no_imu', '/inclinometer/')
    with pytest.raises(ValueError, match='no /inclinometer/imu'):
        gait_bags.load_bag(bag)


def test_the_copies_are_readable_but_for_the_dropped_topic(tmp_path):
    from asmonc_vision.eval.motion_bags import load_sequence

    frames = load_sequence(_copy_without(BAGS / 'clear_static', tmp_path / 'a', '/inclinometer/'))
    assert len(frames) == 30 and all(f['pose'] is not None for f in frames)
    frames = load_sequence(_copy_without(BAGS / 'clear_static', tmp_path / 'b', '/ground_truth/'))
    assert len(frames) == 30 and all(f['pose'] is None for f in frames)


def test_a_missing_bag_is_refused(tmp_path):
    from asmonc_vision.io import bagio

    with pytest.raises(bagio.BagError):
        gait_bags.load_bag(tmp_path / 'nothing_here')


def test_the_command(tmp_path, capsys):
    import json

    from asmonc_vision.cli.main import main

    out = tmp_path / 'bags.json'
    assert main(['gait', 'bags', str(BAGS / 'clear_walk'), '--json', str(out)]) == 0
    doc = json.loads(out.read_text())
    assert set(doc['summary']) == set(gait_bags.MODES)
    assert 'clear_walk' in doc['bags']
    assert 'fused' in capsys.readouterr().out
    assert main(['gait', 'bags', str(tmp_path / 'missing')]) == 2
