"""`asmonc bench`: both methods timed and scored, at 320x240 (a bag) and 640x480 (rendered)."""
import json

import numpy as np
import pytest

from asmonc_vision.eval.bench import render_frames, time_detector
from asmonc_vision.io.frames import load_pairs
from asmonc_vision.cli.main import main
from conftest import BAGS


def test_bench_prints_both_methods_at_both_sizes(tmp_path, capsys):
    out = tmp_path / 'bench.json'
    rc = main(['bench', str(BAGS / 'static_obstacles'), '--frames', '6', '--warmup', '2',
               '--large-frames', '1', '--repeat', '2', '--json', str(out)])
    assert rc == 0
    lines = capsys.readouterr().out.splitlines()
    assert sum('fastest of 2 passes' in ln for ln in lines) == 2
    gpod = [ln for ln in lines if ln.strip().startswith('gpod ')]
    sgbm = [ln for ln in lines if ln.strip().startswith('sgbm ')]
    assert len(gpod) == 2 and len(sgbm) == 2, lines
    assert all('median' in ln and 'recall' in ln and 'CPU median' in ln for ln in gpod + sgbm)
    assert lines[0].startswith('load average')
    assert sum('ratio gpod/sgbm' in ln for ln in lines) == 2
    assert any('640x480' in ln for ln in lines)
    doc = json.loads(out.read_text())
    small = next(iter(doc['320x240'].values()))
    assert small['gpod']['frames'] == 4 and small['gpod']['size'] == '320x240'
    assert small['sgbm']['median_ms'] > 0 and small['ratio_gpod_over_sgbm'] > 0
    assert 0 < small['gpod']['median_cpu_ms'] <= small['gpod']['p90_cpu_ms']
    large = doc['640x480']['static_obstacles (rendered, seed 0)']
    assert large['gpod']['size'] == '640x480' and large['sgbm']['frames'] == 1
    assert large['sgbm']['eligible'] > 0          # the obstacles are in the rendered frame


def test_fastest_pass_takes_each_frames_minimum():
    from asmonc_vision.eval.bench import FrameRun, fastest_pass
    a = [FrameRun(1, 'tracking', 'A1', None, 5.0, {'edges': 1.0}, 4.0),
         FrameRun(2, 'tracking', 'A2', None, 9.0, {'edges': 2.0}, 8.0)]
    b = [FrameRun(1, 'tracking', 'B1', None, 6.0, {'edges': 0.5}, 3.0),
         FrameRun(2, 'tracking', 'B2', None, 7.0, {'edges': 3.0}, 7.5)]
    best = fastest_pass([a, b])
    assert [r.latency_ms for r in best] == [5.0, 7.0]
    assert [r.cpu_ms for r in best] == [3.0, 7.5]
    assert [r.timings['edges'] for r in best] == [0.5, 2.0]
    assert [r.obstacles for r in best] == ['A1', 'A2']        # the first pass's outputs
    assert fastest_pass([a]) is a


def test_bench_refuses_too_few_pairs(capsys):
    assert main(['bench', str(BAGS / 'clear_static'), '--frames', '3', '--warmup', '5',
                 '--no-large']) == 2
    assert 'warmup' in capsys.readouterr().err


def test_loaders_and_the_old_timing_api():
    pairs = load_pairs(BAGS / 'clear_static', limit=4)
    assert len(pairs) == 4 and pairs[0][0].shape == (240, 320) and pairs[0][2].f == 300.0
    r = time_detector(pairs, warmup=1)
    assert r['frames'] == 3 and r['median_ms'] > 0 and 'matching' in r['stages_median_ms']
    frames = render_frames('static_obstacles', 0, [40], width=160, height=120, focal=150.0)
    f = frames[0]
    assert f.left.shape == (120, 160) and f.cam.f == 150.0
    assert len(f.truth) >= 4 and np.all(f.truth.range > 1.0)
    assert abs(f.truth_plane.height - 1.25) < 0.1


def test_run_method_gives_gpod_the_inclinometer_up_direction(monkeypatch):
    """Each pair gets the up direction of the latest inclinometer sample at or before it
    (none before the first sample), as the detector node takes /inclinometer/imu."""
    from asmonc_vision.core.perception import Perception
    from asmonc_vision.core.rotations import gravity_up_optical
    from asmonc_vision.eval.bench import run_method
    from asmonc_vision.io.frames import load_frames

    frames = load_frames(BAGS / 'clear_static', limit=3)
    assert frames[0].inclinometer is None
    for f in frames[1:]:
        assert 0 < f.stamp_ns - f.inclinometer[0] < 0.2e9
    seen = []
    original = Perception.process

    def process(self, *args, up=None, **kwargs):
        seen.append(up)
        return original(self, *args, up=up, **kwargs)

    monkeypatch.setattr(Perception, 'process', process)
    run_method(frames, 'gpod')
    assert seen[0] is None
    for f, up in zip(frames[1:], seen[1:]):
        assert np.allclose(up, gravity_up_optical(f.inclinometer[1]))
        assert up[1] < -0.9                       # the rig looks ahead, about level


def test_run_method_keeps_the_egomotion_the_node_would_publish():
    """With the egomotion estimator, each pair keeps the translation the egomotion node
    publishes (from the pair before; none for the first), for the walking speed of the
    alarm replay: on the bundled walk about 0.1 m a pair along the optical axis."""
    from asmonc_vision.eval.bench import run_method
    from asmonc_vision.io.frames import load_frames

    frames = load_frames(BAGS / 'walk_obstacles')[30:42]      # walking from pair 20
    runs = run_method(frames, 'sgbm', egomotion=True)
    assert runs[0].ego_t is None
    steps = [r.ego_t for r in runs[1:] if r.ego_t is not None]
    assert len(steps) >= 8
    z = np.array([s[2] for s in steps])
    assert np.all((z > 0.02) & (z < 0.3)), z
    assert all(r.ego_t is None for r in run_method(frames[:3], 'sgbm'))


def test_bench_times_gpod_as_the_graph_runs_it():
    """bench's GPOD pass is the campaign's gpod_map_lag (the map given the egomotion of the
    pairs MAP_MOTION_LAG before, through the predictor), fed the estimator's results
    computed once beforehand: the same outputs as run_method running the estimator."""
    from asmonc_vision.cli.campaign import MAP_MOTION_LAG
    from asmonc_vision.eval import bench
    from asmonc_vision.io.frames import load_frames

    assert bench.MAP_MOTION_LAG == MAP_MOTION_LAG
    frames = load_frames(BAGS / 'walk_obstacles', 14)
    ego = bench.egomotion_results(frames)
    assert len(ego) == 14 and sum(e.ok for e in ego) >= 10
    timed = bench.bench_runs(frames, 'gpod', ego)
    ref = bench.run_method(frames, 'gpod', map_enabled=True, egomotion=True,
                           motion_lag=MAP_MOTION_LAG)
    assert [r.status for r in timed] == [r.status for r in ref]
    assert all(_same_obstacles(a.obstacles, b.obstacles) for a, b in zip(timed, ref))
    assert sum(len(r.obstacles) for r in ref) > 0
    assert all('map' in r.timings for r in timed)
    with pytest.raises(ValueError):
        bench.run_method(frames[:3], 'gpod', egomotion=True, ego_results=ego)


def _same_obstacles(a, b) -> bool:
    """Two FrameObstacles bit for bit (every field, NaN heights too)."""
    def same(x, y):
        if x is None or y is None:
            return x is y
        x, y = np.asarray(x), np.asarray(y)
        return x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
    return a.stamp_ns == b.stamp_ns and all(
        same(getattr(a, k), getattr(b, k))
        for k in ('ids', 'position', 'height', 'range', 'bearing', 'roi', 'confidence'))
