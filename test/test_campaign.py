"""`asmonc campaign`: the walk plan, the cache, one tiny walk end to end; sim.scenes."""
import json

import pytest

from asmonc_vision.cli import campaign as C
from asmonc_vision.sim.scenes import RIGS, SCENE_CLASSES, make_scene, rig_settings


def test_scenes_api():
    assert RIGS == ('backpack', 'chest')
    assert set(SCENE_CLASSES) <= {'walk_obstacles', 'clear_walk', 'walk_stop_turn', 'slope',
                                  'step_down'}
    chest = rig_settings('chest')
    assert (chest.width, chest.height, chest.focal, chest.baseline) == (640, 480, 520.0, 0.12)
    assert (chest.camera_height, chest.camera_pitch_deg) == (1.3, 5.0)
    a = make_scene('clear_walk', 1000, duration=2.0, rig='chest')
    assert a.rig == chest and a.n_frames == 20
    with pytest.raises(KeyError):
        make_scene('nowhere', 1)
    with pytest.raises(ValueError):
        make_scene('clear_walk', 1, realism=True)


def test_plan_walks_seed_ranges_and_rigs():
    w = C.plan_walks('tuning', 2.0, list(SCENE_CLASSES), list(RIGS), 20.0)
    assert len(w) == 6
    assert [x.seed for x in w] == list(range(1000, 1006))
    assert [x.scene_class for x in w[:5]] == list(SCENE_CLASSES)
    assert {x.rig for x in w} == set(RIGS)
    b = C.plan_walks('blind', 0.1, list(SCENE_CLASSES), list(RIGS), 20.0)
    assert [x.seed for x in b] == [900000]
    # every class meets every rig within classes x rigs walks
    ten = C.plan_walks('tuning', 10 * 20 / 60, list(SCENE_CLASSES), list(RIGS), 20.0)
    assert {(x.scene_class, x.rig) for x in ten} == {(c, r) for c in SCENE_CLASSES
                                                    for r in RIGS}
    with pytest.raises(ValueError):
        C.plan_walks('tuning', 1e6, list(SCENE_CLASSES), list(RIGS), 20.0)


def test_cache_key_depends_on_everything():
    w = C.Walk('tuning', 'clear_walk', 1000, 'backpack', 20.0)
    k = C.cache_key(w, 'v1')
    assert k == C.cache_key(w, 'v1')
    assert len({k, C.cache_key(w, 'v2'),
                C.cache_key(C.Walk('blind', 'clear_walk', 1001, 'backpack', 20.0), 'v1'),
                C.cache_key(C.Walk('tuning', 'clear_walk', 1000, 'chest', 20.0), 'v1'),
                C.cache_key(C.Walk('tuning', 'clear_walk', 1000, 'backpack', 10.0), 'v1')}) == 5


def test_one_walk_end_to_end_and_cached(tmp_path, capsys):
    js = tmp_path / 'c.json'
    argv = ['campaign', '--minutes', '0.01', '--duration', '1.5', '--tuning', '--classes',
            'step_down', '--rigs', 'backpack', '--cache', str(tmp_path / 'cache'),
            '--json', str(js), '--no-progress']
    from asmonc_vision.cli.main import main
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert 'TUNING seeds 1000-1999: 1 walks' in out and 'ours (GPOD)' in out
    assert 'peer (SGBM)' in out and 'class step_down' in out
    doc = json.loads(js.read_text())
    (walk,) = doc['walks']
    assert walk['seed'] == 1000 and walk['frames'] == 15 and walk['render_s'] > 0
    for m in ('gpod', 'sgbm'):
        s = walk['safety'][m]
        assert s['frames'] == 15 and s['false_reports']['frames_scored'] == 15
    entries = list((tmp_path / 'cache').iterdir())
    assert len(entries) == 1 and (entries[0] / 'truth.json').is_file()
    assert main(argv) == 0                                    # rendered once, reused
    assert json.loads(js.read_text())['walks'][0]['render_s'] == 0.0
    assert 'render - (all cached)' in capsys.readouterr().out
