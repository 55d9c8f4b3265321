"""asmonc motion tables / eval / corners (asmonc_vision/cli/motion.py), small runs."""
import argparse
import json

import pytest

from asmonc_vision.cli import motion
from conftest import BAGS


def _run(argv):
    p = argparse.ArgumentParser(prog='asmonc motion')
    motion.add_arguments(p)
    args = p.parse_args(argv)
    return args.func(args)


def test_tables_print_ours_beside_the_paper(capsys, tmp_path):
    out = tmp_path / 't.json'
    assert _run(['tables', '--trials', '3', '--noise', '0.5', '--points', '30',
                 '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'paper Table 2 (three point)' in text and 'paper Table 3 (essential)' in text
    assert 'stereo_ba (modern, default)' in text and '30% wrong matches' in text
    assert 'minimal point sets' in text
    doc = json.loads(out.read_text())
    assert set(doc['runs']) == {'clean', 'outliers', 'minimal'}
    assert len(doc['runs']['clean']['0.5']['stereo_ba']['mean']) == 6
    assert doc['paper']['three_point']['0.5'] == [35, 37, 39, 0.26, 0.72, 0.68]


def test_eval_on_a_walking_bag(capsys, tmp_path):
    out = tmp_path / 'e.json'
    assert _run(['eval', str(BAGS / 'walk_obstacles'), '--frames', '6', '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert 'walk_obstacles: 6 pairs (320x240), motions 5' in text
    assert 'per-frame error' in text and 'time per frame on one core: median' in text
    r = json.loads(out.read_text())[str(BAGS / 'walk_obstacles')]
    assert r['errors']['pitch']['median'] < 0.3          # the target
    assert r['statuses'] == {'first_frame': 1, 'ok': 5}


def test_eval_params_file_and_bad_input(capsys, tmp_path):
    params = tmp_path / 'p.yaml'
    params.write_text('egomotion_node:\n  ros__parameters:\n    motion:\n'
                      '      method: three_point\n      threshold_px: 2\n')
    assert _run(['eval', str(BAGS / 'clear_walk'), '--frames', '3',
                 '--params-file', str(params)]) == 0
    assert 'method three_point' in capsys.readouterr().out
    params.write_text('egomotion_node:\n  ros__parameters:\n    motion:\n      nope: 1\n')
    assert _run(['eval', str(BAGS / 'clear_walk'), '--params-file', str(params)]) == 2
    assert 'unknown motion settings' in capsys.readouterr().err
    # an estimator setting outside motion. is not dropped in silence
    params.write_text('egomotion_node:\n  ros__parameters:\n    min_inliers: 12\n')
    assert _run(['eval', str(BAGS / 'clear_walk'), '--params-file', str(params)]) == 2
    err = capsys.readouterr().err
    assert "unknown egomotion_node settings" in err and "['min_inliers']" in err
    assert 'go under motion.' in err
    assert _run(['eval', str(tmp_path / 'missing')]) == 2
    assert 'does not exist' in capsys.readouterr().err
    assert _run(['tables', '--methods', 'bogus']) == 2


def test_corners(capsys):
    assert _run(['corners', '--trials', '3']) == 0
    text = capsys.readouterr().out
    assert 'wang_brady' in text and 'shi_tomasi' in text and 'X_line' in text


@pytest.mark.parametrize('sub', ['tables', 'eval', 'corners'])
def test_help(sub, capsys):
    with pytest.raises(SystemExit):
        _run([sub, '--help'])
    assert 'usage' in capsys.readouterr().out
