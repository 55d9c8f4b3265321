"""`asmonc eval`: the binned evaluation (eval.evaluation.SequenceEvaluation), the command
on the committed static bag, and scoring recorded outputs (--outputs)."""
import json
import math

import numpy as np
import pytest

from asmonc_vision.cli.main import main
from asmonc_vision.core.camera import MetricPlane
from asmonc_vision.eval.evaluation import (FrameObstacles, SequenceEvaluation, match_frame,
                                           plane_error)
from conftest import BAGS

STATIC = BAGS / 'static_obstacles'


def _frame(stamp, rows):
    """rows: (id, height, range, bearing_deg, roi)"""
    if not rows:
        return FrameObstacles.empty(stamp)
    rng = np.array([r[2] for r in rows], float)
    brg = np.radians([r[3] for r in rows])
    pos = np.stack([-rng * np.sin(brg), np.zeros_like(rng), rng * np.cos(brg)], axis=1)
    return FrameObstacles(stamp, np.array([r[0] for r in rows]), pos,
                          np.array([r[1] for r in rows], float), rng, brg,
                          np.array([r[4] for r in rows], int).reshape(-1, 4))


def _rot_x(deg):
    a = math.radians(deg)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def test_bins_false_rate_errors_and_plane():
    truth_rows = [(1, 0.03, 1.5, 0.0, (10, 200, 10, 10)),      # 0-5 cm, 1-2 m: missed
                  (2, 0.15, 3.5, 10.0, (100, 100, 10, 10)),    # 10-20 cm, 3-4 m: found
                  (3, 0.60, 6.0, -10.0, (200, 60, 10, 30)),    # >= 50 cm, 5-8 m: found
                  (4, 0.25, 0.5, 0.0, (150, 230, 10, 10))]     # nearer than 1 m: no bin
    det_rows = [(0, 0.14, 3.6, 10.5, (100, 100, 10, 10)),
                (0, 0.55, 5.9, -10.0, (200, 60, 10, 30)),
                (0, 0.30, 4.0, 40.0, (20, 20, 5, 5))]          # false
    t0 = 1_700_000_000_000_000_000
    truth_plane = MetricPlane(np.array([0.0, -np.cos(0.35), -np.sin(0.35)]), 1.25)
    tilted = MetricPlane(_rot_x(1.0) @ truth_plane.normal_up, 1.26)
    ev = SequenceEvaluation()
    for k in range(4):
        stamp = t0 + k * 100_000_000                          # 10 Hz
        ev.add_frame(_frame(stamp, det_rows), _frame(stamp, truth_rows),
                     plane=tilted if k else None, truth_plane=truth_plane,
                     latency_ms=10.0 + k, status='tracking' if k else 'initialising')
    ev.add_missing(t0 + 4 * 100_000_000)
    s = ev.summary()
    json.dumps(s, allow_nan=False)                            # strict JSON
    b = s['recall_bins']
    assert b['height_labels'] == ['0-5 cm', '5-10 cm', '10-20 cm', '20-50 cm', '>=50 cm']
    assert b['range_labels'] == ['1-2 m', '2-3 m', '3-4 m', '4-5 m', '5-8 m']
    elig, det = np.array(b['eligible']), np.array(b['detected'])
    assert elig.sum() == 12 and det.sum() == 8
    assert (elig[0, 0], det[0, 0]) == (4, 0)
    assert (elig[2, 2], det[2, 2]) == (4, 4)
    assert (elig[4, 4], det[4, 4]) == (4, 4)
    assert b['recall'][0][0] == 0.0 and b['recall'][1][1] is None
    # headline (>= 10 cm within 5 m): the 15 cm box (found) and the 25 cm one at 0.5 m
    # (missed; in no bin)
    assert (s['recall']['eligible'], s['recall']['detected']) == (8, 4)
    assert s['frames'] == 4 and s['missing_frames'] == 1
    assert s['camera_rate_hz'] == pytest.approx(10.0)
    assert s['false_obstacles']['total'] == 4
    assert s['false_obstacles']['per_frame'] == pytest.approx(1.0)
    assert s['false_obstacles']['per_minute'] == pytest.approx(600.0)   # 4 in 0.4 s
    assert s['range_error']['median_abs_m'] == pytest.approx(0.1)
    assert s['range_error']['median_abs_pct_of_range'] == pytest.approx(100 * 0.1 / 3.5)
    assert s['bearing_error']['median_abs_deg'] == pytest.approx(0.5)
    assert len(ev.matches) == 8                                # both found obstacles
    g = s['ground_plane']
    assert (g['frames_with_plane'], g['frames_without_plane']) == (3, 1)
    assert g['angle_median_deg'] == pytest.approx(1.0, abs=1e-6)
    assert g['height_median_mm'] == pytest.approx(10.0)
    assert s['latency_ms']['median'] == pytest.approx(11.5)
    assert s['status_counts'] == {'initialising': 1, 'tracking': 3}
    pooled = SequenceEvaluation.pooled([ev, ev]).summary()
    assert pooled['frames'] == 8 and np.array(pooled['recall_bins']['eligible']).sum() == 24
    assert pooled['recall']['obstacles_eligible'] == 2 * s['recall']['obstacles_eligible'] == 4
    assert pooled['false_obstacles']['per_minute'] == pytest.approx(600.0)


def test_eligible_obstacles_take_reports_first():
    # a 3 cm box nearer the camera and a 20 cm box 0.2 m behind it; one report between
    truth = _frame(1, [(1, 0.03, 3.0, 0.0, (0, 0, 1, 1)), (2, 0.20, 3.2, 0.0, (0, 0, 1, 1))])
    det = _frame(1, [(0, 0.2, 3.1, 0.0, (0, 0, 1, 1))])
    m = match_frame(det, truth)
    assert list(m.truth_det) == [-1, 0] and not m.false.any()


def test_plane_error_of_identical_planes_is_zero():
    p = MetricPlane(np.array([0.0, -1.0, 0.0]), 1.2)
    assert plane_error(p, p) == pytest.approx((0.0, 0.0), abs=1e-6)


@pytest.mark.slow
def test_eval_on_the_static_bag(tmp_path, capsys):
    out = tmp_path / 'eval.json'
    rc = main(['eval', str(STATIC), '--frames', '25', '--method', 'gpod', 'sgbm',
               '--json', str(out), '--plots', str(tmp_path / 'plots'), '--no-progress'])
    assert rc == 0
    text = capsys.readouterr().out
    assert 'recall per frame by true |height| x range' in text
    assert 'GPOD (ours)' in text and 'SGBM baseline' in text and '=== overview ===' in text
    doc = json.loads(out.read_text())
    assert [r['method'] for r in doc['runs']] == ['gpod', 'sgbm']
    for r in doc['runs']:
        assert r['frames'] == 25 and r['missing_frames'] == 0
        assert r['camera_rate_hz'] == pytest.approx(10.0)
        assert r['threshold_px'] == pytest.approx(1.7)
        b = r['recall_bins']
        elig = np.array(b['eligible'])
        det = np.array(b['detected'])
        # the 10-50+ cm rows within 5 m are exactly the headline recall
        assert elig[2:, :4].sum() == r['recall']['eligible'] > 0
        assert det[2:, :4].sum() == r['recall']['detected']
        assert r['latency_ms']['n'] == 25 and r['latency_ms']['median'] > 0
        assert r['ground_plane']['frames_with_plane'] >= 20
        assert r['ground_plane']['angle_median_deg'] < 2.0
        assert r['ground_plane']['height_median_abs_mm'] < 50
    gp = doc['runs'][0]
    assert gp['status_counts'].get('initialising', 0) >= 1    # GPOD calibrates first
    for r in doc['runs']:                  # the safety score, alarm logic replayed
        sf = r['safety']
        assert sf['frames'] == 25 and sf['false_reports']['frames_scored'] == 25
        assert sf['walking_s'] == 0.0      # standing still
        assert sf['false_alarms']['per_minute_walking'] is None
    pngs = sorted(p.name for p in (tmp_path / 'plots').iterdir())
    assert pngs == ['eval_range_error_static_obstacles_gpod.png',
                    'eval_range_error_static_obstacles_sgbm.png',
                    'eval_recall_static_obstacles_gpod.png',
                    'eval_recall_static_obstacles_sgbm.png']


def _write_outputs_bag(path, frames, skip=(), initialising=2, shift=0.05):
    """A bag as `asmonc run --out` records it: /obstacles (the truth moved `shift` m
    further away) and /ground_plane (the true plane, INITIALISING for the first frames)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from asmonc_vision.io import bagio
    from asmonc_vision.core.camera import plane_from_metric

    ts = bagio.typestore()
    T = ts.types
    P = bagio.MSG_PACKAGE
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c_obs = w.add_connection('/obstacles', f'{P}/msg/ObstacleArray', typestore=ts)
        c_pl = w.add_connection('/ground_plane', f'{P}/msg/GroundPlane', typestore=ts)
        for k, f in enumerate(frames):
            if k in skip:
                continue
            ns = f.stamp_ns
            hdr = T['std_msgs/msg/Header'](
                stamp=T['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9),
                frame_id='stereo_left_optical_frame')
            tr = f.truth
            obs = []
            if k >= initialising:
                for i in range(len(tr)):
                    obs.append(T[f'{P}/msg/Obstacle'](
                        id=0, position=T['geometry_msgs/msg/Point'](*map(float, tr.position[i])),
                        height=float(tr.height[i]), range=float(tr.range[i] + shift),
                        bearing=float(tr.bearing[i]), width=0.3, disparity_excess=3.0,
                        confidence=1.0, roi=T['sensor_msgs/msg/RegionOfInterest'](
                            x_offset=int(tr.roi[i, 0]), y_offset=int(tr.roi[i, 1]),
                            height=int(tr.roi[i, 3]), width=int(tr.roi[i, 2]),
                            do_rectify=False)))
            msg = T[f'{P}/msg/ObstacleArray'](header=hdr, obstacles=obs)
            w.write(c_obs, ns, ts.serialize_cdr(msg, f'{P}/msg/ObstacleArray'))
            pl = f.truth_plane
            a, b, c = plane_from_metric(f.cam, pl)
            gp = T[f'{P}/msg/GroundPlane'](
                header=hdr, a=float(a), b=float(b), c=float(c), covariance=np.zeros(9),
                num_features=100, residual_rms=0.5, status=0 if k < initialising else 1,
                normal=T['geometry_msgs/msg/Vector3'](*map(float, pl.normal_up)),
                height=float(pl.height))
            w.write(c_pl, ns, ts.serialize_cdr(gp, f'{P}/msg/GroundPlane'))


def test_eval_of_recorded_outputs(tmp_path, capsys):
    from asmonc_vision.io.frames import load_frames

    frames = load_frames(STATIC, 30, images=False)
    assert len(frames) == 30 and frames[0].left is None and frames[0].truth_plane is not None
    outputs = tmp_path / 'run_out'
    _write_outputs_bag(outputs, frames, skip=(29,))
    (outputs / 'summary.json').write_text('{}')                # as `asmonc run --out` leaves it
    out = tmp_path / 'eval.json'
    rc = main(['eval', str(STATIC), '--frames', '30', '--outputs', str(outputs),
               '--json', str(out), '--no-progress'])
    assert rc == 0
    assert 'recorded outputs' in capsys.readouterr().out
    r = json.loads(out.read_text())['runs'][0]
    assert r['source'] == 'recorded' and r['method'] == 'outputs'
    assert r['frames'] == 29 and r['missing_frames'] == 1
    assert r['recall']['eligible'] > 0
    assert r['recall']['recall'] == pytest.approx(1.0)
    assert r['false_obstacles']['total'] == 0
    assert r['range_error']['median_m'] == pytest.approx(0.05, abs=1e-4)
    assert r['status_counts'] == {'initialising': 2, 'tracking': 27}
    g = r['ground_plane']
    assert (g['frames_with_plane'], g['frames_without_plane']) == (27, 2)
    assert g['angle_median_deg'] == pytest.approx(0.0, abs=1e-3)
    assert g['height_median_abs_mm'] == pytest.approx(0.0, abs=1e-3)
    assert r['latency_ms']['n'] == 0
    assert r['path_warnings'] is None                         # no /alarms in that bag


def test_eval_of_recorded_outputs_scores_the_alarms(tmp_path, capsys):
    """The /alarms of a recorded run against the true obstacles on the path: the static
    bag's post stands 2.1 m ahead from 3 s on; a WARNING from then on warns of it in
    time, an alarm that comes a second late does not."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    from asmonc_vision.io import bagio
    from asmonc_vision.io.frames import load_frames

    frames = load_frames(STATIC, 0, images=False)
    base = tmp_path / 'base'
    _write_outputs_bag(base, frames)
    ts = bagio.typestore()
    T, P = ts.types, bagio.MSG_PACKAGE
    on_path = [f.stamp_ns for f in frames if f.truth is not None and any(
        abs(r * np.sin(b)) <= 0.5 and r <= 2.5 and h >= 0.05
        for r, b, h in zip(f.truth.range, f.truth.bearing, f.truth.height))]
    assert len(on_path) > 10

    def with_alarms(path, alarms):
        with Reader(base) as reader, Writer(path, version=9,
                                            storage_plugin=StoragePlugin.MCAP) as w:
            conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=ts)
                     for c in reader.connections}
            c_al = w.add_connection('/alarms', f'{P}/msg/Alarm', typestore=ts)
            for c, t, raw in reader.messages():
                w.write(conns[c.id], t, raw)
            for ns, level in alarms:
                hdr = T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
                    sec=ns // 10**9, nanosec=ns % 10**9), frame_id='')
                msg = T[f'{P}/msg/Alarm'](header=hdr, level=level, obstacle_id=0, range=2.0,
                                         bearing=0.0, text='obstacle')
                w.write(c_al, ns, ts.serialize_cdr(msg, f'{P}/msg/Alarm'))

    def score(alarms):
        path = tmp_path / f'out{len(list(tmp_path.iterdir()))}'
        with_alarms(path, alarms)
        js = tmp_path / 'eval.json'
        assert main(['eval', str(STATIC), '--outputs', str(path), '--json', str(js),
                     '--no-progress']) == 0
        run = json.loads(js.read_text())['runs'][0]
        return run['path_warnings'], run['safety']['warned_in_time']

    t0 = frames[0].stamp_ns
    pw, sw = score([(t0, 0), (on_path[0], 2)])
    assert (pw['on_path'], pw['warned_in_time'], pw['frames_unwarned']) == (1, 1, 0)
    assert (sw['on_path'], sw['warned']) == (1, 1)      # the safety score agrees
    assert 'warned in time 1' in capsys.readouterr().out
    pw, sw = score([(t0, 0), (on_path[10], 2)])
    assert (pw['warned_in_time'], pw['warned_late'], pw['frames_unwarned']) == (0, 1, 10)
    assert (sw['warned'], sw['late']) == (0, 1)


def test_eval_refuses_bad_input(tmp_path, capsys):
    assert main(['eval', str(STATIC), '--outputs', str(tmp_path), '--outputs',
                 str(tmp_path)]) == 2
    assert main(['eval', str(tmp_path / 'nope')]) == 2
    assert main(['eval', str(STATIC), '--threshold-px', '0']) == 2
    err = capsys.readouterr().err
    assert 'one --outputs per BAG' in err and 'does not exist' in err


def test_threshold_px_selects_gpod_fixed_threshold():
    from asmonc_vision.eval.bench import make_method
    det = make_method('gpod', 1.2)
    assert det.config.threshold.mode == 'fixed' and det.config.threshold.px == 1.2
