"""The small-box measurement (asmonc_vision.eval.smallbox): scene, scoring, command."""
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from asmonc_vision.cli import smallbox as smallbox_cli
from asmonc_vision.eval import smallbox


def _report(rng, bearing_deg, roi=(0, 0, 4, 4), height=0.05):
    return SimpleNamespace(range=rng, bearing=math.radians(bearing_deg), roi=roi,
                           height=height)


def test_score_frame_found_on_box_and_false():
    truth = [_report(2.5, 0.0, roi=(100, 100, 40, 20))]
    t = smallbox.new_tally()
    smallbox.score_frame(t, [], [])                                   # clear, nothing
    smallbox.score_frame(t, [_report(3.0, 10.0)], [])                 # clear, one false
    near = _report(2.55, 1.0, roi=(100, 100, 10, 10))                 # found (and on box)
    off_on_box = _report(3.2, 5.0, roi=(130, 105, 8, 8))              # on the box, not near
    elsewhere = _report(4.0, -20.0, roi=(10, 10, 5, 5))               # false
    drop = _report(2.5, 0.0, height=-0.2)                             # drops are ignored
    smallbox.score_frame(t, [near, off_on_box, elsewhere, drop], truth)
    smallbox.score_frame(t, [off_on_box], truth)                      # on box only
    assert t['frames'] == 4 and t['box_frames'] == 2
    assert t['found'] == 1 and t['found_on_box'] == 2 and t['false'] == 2
    assert t['range_err'] == [pytest.approx(0.02)]
    assert t['bearing_err_deg'] == [pytest.approx(1.0)]
    s = smallbox.summarise(t)
    assert s['found'] == 0.5 and s['found_on_box'] == 1.0
    assert s['false_per_frame'] == 0.5 and s['range_err_median'] == pytest.approx(0.02)
    assert smallbox.summarise(smallbox.new_tally())['found'] == 0.0


@pytest.mark.slow
def test_scene_places_the_box_at_the_range():
    sc = smallbox.small_box_scene(0.04, 2.5, seed=3, box_frames=3, clear_frames=2)
    assert sc.n_frames == 5
    cam, frames = smallbox.scene_frames(0.04, 2.5, 3, box_frames=3, clear_frames=2)
    assert cam.width == 320 and len(frames) == 5
    assert [bool(tr) for _, _, tr in frames] == [False, False, True, True, True]
    truth = frames[-1][2][0]
    assert abs(truth.height - 0.04) < 0.005 and abs(truth.range - 2.5) < 0.05


def test_the_chest_rig_sees_the_box_at_the_range():
    """``rig='chest'``: the level chest rig (640 x 480, f = 560 px) sees the same kind of
    scene, the box's nearest point at the range asked for."""
    sc = smallbox.small_box_scene(0.05, 3.0, seed=4, box_frames=2, clear_frames=1,
                                  rig='chest')
    assert sc.rig == smallbox.nominal_rig('chest')
    cam, frames = smallbox.scene_frames(0.05, 3.0, 4, box_frames=2, clear_frames=1,
                                        rig='chest')
    assert (cam.width, cam.height, cam.f) == (640, 480, 560.0) and len(frames) == 3
    truth = frames[-1][2][0]
    assert abs(truth.height - 0.05) < 0.005 and abs(truth.range - 3.0) < 0.05


def test_an_unknown_rig_is_an_error():
    with pytest.raises(ValueError, match="unknown rig 'helmet'"):
        smallbox.nominal_rig('helmet')


def test_cells_pair_or_grid():
    p = SimpleNamespace(heights=[0.04, 0.08], ranges=[2.5, 5.0], grid=False)
    assert smallbox._cells(p) == [(0.04, 2.5), (0.08, 5.0)]
    p.grid = True
    assert len(smallbox._cells(p)) == 4
    assert smallbox._cells(SimpleNamespace(heights=[0.05], ranges=[2.0, 3.0], grid=False)) \
        == [(0.05, 2.0), (0.05, 3.0)]


@pytest.mark.slow
def test_command_runs_both_methods_on_the_same_frames(tmp_path, capsys):
    out = tmp_path / 'sb.json'
    rc = smallbox_cli.main(['--heights', '0.08', '--ranges', '2.5', '--seeds', '1',
                        '--frames', '3', '--clear-frames', '3', '--json', str(out),
                        '--cache', str(tmp_path / 'cache'), '--quiet'])
    assert rc == 0
    text = capsys.readouterr().out
    assert 'gpod' in text and 'gpod/frame' in text and 'sgbm' in text
    res = json.loads(out.read_text())
    cell = res['cells'][0]
    assert cell['height'] == 0.08 and cell['range'] == 2.5
    for m in ('gpod', 'gpod/frame', 'sgbm'):
        assert cell[m]['frames'] == 6 and cell[m]['box_frames'] == 3
        assert 0.0 <= cell[m]['found'] <= 1.0 and np.isfinite(cell[m]['cpu_ms_per_frame'])
    assert cell['gpod']['found'] == 1.0                  # 8 cm at 2.5 m: easy
    assert list((tmp_path / 'cache').glob('*.pkl'))      # frames kept for the next run


def test_unknown_method_is_an_error():
    with pytest.raises(ValueError, match='unknown method'):
        smallbox.make_detector('stereo')
