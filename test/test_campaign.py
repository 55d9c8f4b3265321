"""`asmonc campaign`: the walk plan, the cache, one tiny walk end to end; sim.scenes."""
import argparse
import json
import re

import pytest

from asmonc_vision.cli import campaign as C
from asmonc_vision.core.surface_kernels import RULES
from asmonc_vision.sim.scenes import RIGS, SCENE_CLASSES, make_scene


def test_scenes_api():
    """Only the API another sim.scenes must keep: classes, rigs, make_scene."""
    assert RIGS == ('backpack', 'chest', 'narrow') and SCENE_CLASSES
    a = make_scene(SCENE_CLASSES[0], 1000, duration=2.0, rig='chest')
    chest = a.rig
    assert (chest.width, chest.height, chest.baseline) == (640, 480, 0.12)
    assert 1.2 <= chest.camera_height <= 1.4          # drawn from the seed within the kind
    assert chest.focal == pytest.approx(560.0, rel=0.05)         # 57 degrees across
    assert a.n_frames == 20
    b = make_scene(SCENE_CLASSES[0], 1000, duration=2.0)
    assert (b.rig.width, b.rig.height) == (320, 240)
    n = make_scene(SCENE_CLASSES[0], 1000, duration=2.0, rig='narrow').rig
    assert (n.width, n.height, n.focal, n.baseline) == (640, 400, 450.0, 0.075)
    assert 1.0 <= n.camera_height <= 1.6 and 8.0 <= n.camera_pitch_deg <= 30.0
    with pytest.raises(KeyError):
        make_scene('nowhere', 1)


def test_plan_walks_seed_ranges_and_rigs():
    w = C.plan_walks('tuning', 2.0, list(SCENE_CLASSES), list(RIGS), 20.0)
    assert len(w) == 6
    assert [x.seed for x in w] == list(range(1000, 1006))
    assert [x.scene_class for x in w] == list(SCENE_CLASSES[:6])
    assert {x.rig for x in w} == set(RIGS)
    b = C.plan_walks('blind', 0.1, list(SCENE_CLASSES), list(RIGS), 20.0)
    assert [x.seed for x in b] == [900000]
    # every class meets every rig within classes x rigs walks
    n = len(SCENE_CLASSES) * len(RIGS)
    every = C.plan_walks('tuning', n * 20 / 60, list(SCENE_CLASSES), list(RIGS), 20.0)
    assert len(every) == n
    assert {(x.scene_class, x.rig) for x in every} == {(c, r) for c in SCENE_CLASSES
                                                      for r in RIGS}
    with pytest.raises(ValueError):
        C.plan_walks('tuning', 1e6, list(SCENE_CLASSES), list(RIGS), 20.0)


def test_default_rigs_are_the_reported_sets():
    """A campaign without --rigs runs the backpack and chest rigs (the sets the docs
    report); the narrow module is a choice."""
    p = argparse.ArgumentParser()
    C.add_arguments(p)
    assert p.parse_args([]).rigs == ['backpack', 'chest']
    assert p.parse_args(['--rigs', 'narrow']).rigs == ['narrow']


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
            SCENE_CLASSES[0], '--rigs', 'backpack', '--cache', str(tmp_path / 'cache'),
            '--json', str(js), '--markdown', str(tmp_path / 'c.md'), '--no-progress']
    from asmonc_vision.cli.main import main
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert 'TUNING seeds 1000-1999: 1 walks' in out and 'ours (GPOD + map, no wait)' in out
    assert 'peer (SGBM)' in out and f'class {SCENE_CLASSES[0]}' in out
    doc = json.loads(js.read_text())
    (walk,) = doc['walks']
    assert walk['seed'] == 1000 and walk['frames'] == 15 and walk['render_s'] > 0
    assert set(walk['safety']) == {'gpod_map_lag', 'sgbm'}   # the system and its peer
    for m in ('gpod_map_lag', 'sgbm'):
        s = walk['safety'][m]
        assert s['frames'] == 15 and s['false_reports']['frames_scored'] == 15
    md = (tmp_path / 'c.md').read_text().splitlines()
    assert md[0] == '**TUNING seeds 1000-1999: 1 walks of 1.5 s**'
    assert md[2].startswith('|  | walks | min | ours (GPOD + map, no wait) warned |')
    assert md[3] == '|---' * 11 + '|'
    assert md[4].startswith(f'| class {SCENE_CLASSES[0]} | 1 | 0.0 | ')
    assert md[-1].startswith('| **all** | 1 |') and md[-1].count('|') == 12
    entries = list((tmp_path / 'cache').iterdir())
    assert len(entries) == 1 and (entries[0] / 'truth.json').is_file()
    assert main(argv) == 0                                    # rendered once, reused
    assert json.loads(js.read_text())['walks'][0]['render_s'] == 0.0
    assert 'render - (all cached)' in capsys.readouterr().out
    # the same walk named with --walk (cached), its events asked for
    assert main(['campaign', '--walk', f'{SCENE_CLASSES[0]}:1000:backpack', '--duration',
                 '1.5', '--cache', str(tmp_path / 'cache'), '--methods', 'gpod', '--events',
                 '--no-progress']) == 0
    out = capsys.readouterr().out
    assert f'1 walks of 1.5 s (tuning seeds), {SCENE_CLASSES[0]}:1000:backpack;' in out
    assert f'tuning {SCENE_CLASSES[0]}' in out and 'render 0 s' in out
    # --trace: every pair in the window, its status, the alarm in force and its reports
    assert main(['campaign', '--walk', f'{SCENE_CLASSES[0]}:1000:backpack', '--duration',
                 '1.5', '--cache', str(tmp_path / 'cache'), '--methods', 'gpod', '--trace',
                 '0.2', '0.6', '--no-progress']) == 0
    out = capsys.readouterr().out
    assert 'gpod: pairs from 0.2 to 0.6 s' in out
    rows = [ln.split() for ln in out.splitlines() if ln.startswith('         ')
            and ' s  ' in ln]
    assert [r[0] for r in rows] == ['0.20', '0.30', '0.40', '0.50', '0.60']
    assert all(r[2] in ('tracking', 'initialising', 'lost', '-') for r in rows)
    assert all(r[3] in ('CLEAR', 'CAUTION', 'WARNING', 'STOP', 'FAULT') for r in rows)
    # and how far the ground surface is known, with the rule that ended it
    known = [re.search(r'\|\s+ground known to (\d+\.\d) m(, then (rule_\w+) .+)?$', ln)
             for ln in out.splitlines() if ln.startswith('         ') and ' s  ' in ln]
    assert all(k is not None for k in known), out
    assert all(k.group(3) in (None, *RULES, 'rule_anchor') for k in known)
    assert main(['campaign', '--trace', '0', '1', '--no-progress']) == 2       # no --walk
    assert main(['campaign', '--walk', f'{SCENE_CLASSES[0]}:1000:backpack', '--trace', '2',
                 '1']) == 2


def test_parse_walk():
    w = C.parse_walk('kerb_ramp:1003:chest', 20.0)
    assert w == C.Walk('tuning', 'kerb_ramp', 1003, 'chest', 20.0)
    assert C.parse_walk('grate:900007:backpack', 10.0).seed_set == 'blind'
    for bad, why in (('kerb_ramp:1003', 'CLASS:SEED:RIG'), ('nowhere:1003:chest', 'nowhere'),
                     ('grate:1003:helmet', 'helmet'), ('grate:x:chest', "'x'"),
                     ('grate:5:chest', 'neither')):
        with pytest.raises(ValueError, match=why):
            C.parse_walk(bad, 20.0)
    from asmonc_vision.cli.main import main
    assert main(['campaign', '--walk', 'grate:5:chest']) == 2


def test_event_lines_name_each_false_alarm_and_each_unwarned_obstacle():
    from asmonc_vision.eval.safety import SafetyScore

    s = SafetyScore(false_alarm_events=[dict(t_s=7.7, level=1, level_name='CAUTION',
                                             obstacle_id=4, range_m=4.64, bearing_deg=1.2,
                                             nearest_true_m=1.39)],
                    path_obstacles=[dict(id=3, kind='drop', height_m=-0.12, outcome='late',
                                         first_t_s=2.5, first_range_m=6.1),
                                    dict(id=5, kind='', height_m=0.2, outcome='warned',
                                         first_t_s=1.0, first_range_m=5.0)])
    lines = C.event_lines({'scores': {'gpod': s}}, ['gpod'])
    assert len(lines) == 2
    assert lines[0] == ('      gpod: false CAUTION  at    7.7 s: range 4.6 m, bearing +1 deg, '
                        'nearest true obstacle 1.4 m')
    assert lines[1] == ('      gpod: obstacle 3 (drop, -12 cm): late, on the path at 2.5 s '
                        'from 6.1 m')
    # "all clear" in force with a hazard on the path (a drop whose plane took its lower
    # ground): said per walk, and counted under the table
    s.frames_on_path, s.frames_on_path_clear = 27, 18
    lines = C.event_lines({'scores': {'gpod': s}}, ['gpod'])
    assert lines[2] == ('      gpod: "all clear" in force in 18 of the 27 frames with a '
                        'hazard on the path')


def test_the_table_counts_all_clear_with_a_hazard_on_the_path():
    from asmonc_vision.eval.safety import SafetyScore

    walk = C.Walk('tuning', 'step_down', 1011, 'chest', 20.0)
    results = [{'walk': walk, 'scores': {'gpod': SafetyScore(
        frames_on_path=n, frames_on_path_clear=c)}} for n, c in ((27, 18), (40, 0))]
    out = C.table(results, ['gpod'], 'TUNING')
    assert out[-1] == ('frames on the path with "all clear" in force (a hazard there, the '
                       'wearer told the way is clear): ours (GPOD) 18/67')


def test_sim_bags_carry_the_footprints(tmp_path):
    """The bag writer stores every obstacle's footprint; the safety truth uses them."""
    import dataclasses

    import numpy as np

    from asmonc_vision.eval.truth import sim_metadata, truth_from_bag
    from asmonc_vision.sim.bagwriter import write_bag
    from asmonc_vision.sim.rig import RigSettings
    from asmonc_vision.sim.scenarios import make_scenario

    rig = dataclasses.replace(RigSettings(), width=80, height=60, focal=75.0)
    sc = make_scenario('walk_obstacles', seed=3, duration=0.1, rig=rig)
    seen = []
    write_bag(sc, tmp_path / 'bag', on_frame=seen.append)
    assert len(seen) == sc.n_frames
    fp = sim_metadata(tmp_path / 'bag')['footprints']
    assert [d['id'] for d in fp] == [ob.id for ob in sc.world.obstacles]
    kerb = [d for d in fp if d['kind'] == 'kerb']
    assert len(kerb) == 1 and kerb[0]['ground_region'] and kerb[0]['height'] == 0.12
    wall = next(d for d in fp if d['kind'] == 'wall')
    assert len(wall['polygon']) == 4 and not wall['ground_region'] and wall['height'] == 2.4
    truth = truth_from_bag(tmp_path / 'bag')
    assert len(truth.obstacles) == len(fp) and not any(o.points for o in truth.obstacles)
    assert len(truth.frames) == sc.n_frames
    np.testing.assert_allclose(truth.frames[0].heading, [1.0, 0.0], atol=0.05)


def test_walking_people_are_scored_where_they_are():
    """The footprint of a walking person in the bag metadata is its first place; the
    safety truth places it at each frame's stamp, from the scene rebuilt from the
    metadata, or, when that is not possible, from the listings."""
    import dataclasses

    import numpy as np

    from asmonc_vision.eval.truth import (listed_tracks, moving_tracks, scene_world,
                                          world_tracks)
    from asmonc_vision.sim.bagwriter import EPOCH_NS, stamp_ns
    from asmonc_vision.sim.footprints import world_footprints

    from asmonc_vision.sim.scenes import make_scene

    sc = make_scene('people_crossing', 1008, duration=20.0, rig='backpack')
    fp = world_footprints(sc.world)
    meta = {'scenario': sc.name, 'seed': sc.seed, 'duration': sc.duration,
            'rig': dataclasses.asdict(sc.rig), 'footprints': fp, 'epoch_ns': EPOCH_NS}
    world = scene_world(meta)
    assert world is not None and world_footprints(world) == fp
    assert scene_world(dict(meta, seed=sc.seed + 1)) is None
    people = [o for o in sc.world.obstacles if o.kind == 'person']
    stamps = [stamp_ns(t) for t in np.arange(0.0, 20.0, 0.1)]
    tracks = world_tracks(world, stamps, EPOCH_NS)
    assert sorted(tracks) == sorted(o.id for o in people)
    for o in people:
        st, feet = tracks[o.id]
        for k in (0, 75, 150):
            x, y, _ = o.place((int(st[k]) - EPOCH_NS) / 1e9)
            np.testing.assert_allclose(feet[k].mean(axis=0), [x, y], atol=1e-3)
        assert np.hypot(*(feet[-1].mean(axis=0) - feet[0].mean(axis=0))) > 5.0
    assert moving_tracks([], dict(meta, footprints=[dict(d, kind='box') for d in fp])) == (
        {}, False)
    assert listed_tracks([], {1}) == {}
