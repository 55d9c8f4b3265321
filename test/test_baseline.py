"""The SGBM baseline (core.baseline): settings, plane fit, a tall box, a clear pavement."""
import numpy as np
import pytest

from asmonc_vision.core.baseline import SgbmBaseline, SgbmConfig, fit_disparity_plane
from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.eval.evaluation import frame_from_detections, score_sequence
from conftest import BAGS


def test_num_disparities_from_min_range_rounded_up_to_16():
    cfg = SgbmConfig()
    assert cfg.num_disparities(StereoCamera(300.0, 159.5, 119.5, 0.35, 320, 240)) == 112
    assert cfg.num_disparities(StereoCamera(600.0, 319.5, 239.5, 0.35, 640, 480)) == 224
    assert SgbmConfig(min_range_m=2.0).num_disparities(
        StereoCamera(300.0, 159.5, 119.5, 0.35, 320, 240)) == 64


@pytest.mark.parametrize('bad', [dict(block_size=4), dict(p2_factor=4.0), dict(mode='bm'),
                                 dict(threshold_px=0.0)])
def test_bad_settings_are_refused(bad):
    with pytest.raises((ValueError, TypeError)):
        SgbmConfig(**bad)


def test_ransac_plane_ignores_outliers():
    rng = np.random.default_rng(1)
    n = 4000
    u = rng.uniform(0, 320, n)
    v = rng.uniform(120, 240, n)
    d = 0.01 * u + 0.35 * v - 40.0 + rng.normal(0, 0.2, n)
    out = rng.random(n) < 0.3
    d[out] += rng.uniform(3, 30, out.sum())            # obstacles: more disparity
    abc, inl, rms = fit_disparity_plane(u, v, d, rng=0)
    assert abc == pytest.approx([0.01, 0.35, -40.0], abs=0.05)
    assert not inl[out].any() or inl[out].mean() < 0.05
    assert rms < 0.3
    assert fit_disparity_plane(u[:2], v[:2], d[:2], rng=0) is None


def test_featureless_pair_is_lost_not_an_error():
    cam = StereoCamera(300.0, 159.5, 119.5, 0.35, 320, 240)
    img = np.full((240, 320), 128, np.uint8)
    res = SgbmBaseline().process(img, img, cam)
    assert res.status == 'lost' and res.obstacles == () and res.plane is None
    with pytest.raises(ValueError):
        SgbmBaseline().process(img[:100], img, cam)


def _tall_box_clip(n_frames=3):
    from asmonc_vision.sim import (Box, Ground, Leg, RigSettings, Scenario, StereoRenderer,
                                   Trajectory, World, simulate_frame)
    rig = RigSettings()
    world = World(Ground(), [Box(x=3.0, y=0.3, length=0.4, width=0.4, height=0.5,
                                 yaw_deg=20.0, albedo=50.0, name='tall box')], seed=4)
    traj = Trajectory([Leg(1.0, 0.0)], rig, world, rng=4)
    sc = Scenario('tall_box', 'a 50 cm box 3 m ahead', 4, 1.0, rig, world, traj)
    r = StereoRenderer(rig)
    return rig.camera(), [simulate_frame(sc, k, r) for k in range(n_frames)]


@pytest.mark.slow
def test_finds_a_tall_box_where_it_is():
    cam, frames = _tall_box_clip()
    base = SgbmBaseline()
    det, truth = {}, {}
    for k, f in enumerate(frames):
        res = base.process(f.left, f.right, cam)
        assert res.status == 'tracking'
        # the plane is the true ground to within a degree and a few centimetres
        ang = np.degrees(np.arccos(np.clip(res.plane.metric.normal_up @ f.plane.normal_up, -1, 1)))
        assert ang < 1.0 and abs(res.plane.metric.height - f.plane.height) < 0.05
        det[k] = frame_from_detections(k, res.obstacles)
        truth[k] = frame_from_detections(k, f.obstacles)
    score, _ = score_sequence(det, truth)
    assert score.eligible == len(frames) and score.detected == len(frames)
    assert score.false_obstacles == 0
    box = [o for o in base.process(frames[-1].left, frames[-1].right, cam).obstacles
           if abs(o.range - 2.8) < 0.4][0]
    assert 0.3 < box.height < 0.7 and box.num_pixels > 50


def test_no_obstacles_on_a_clear_pavement():
    from asmonc_vision.io.frames import load_pairs
    base = SgbmBaseline()
    found = 0
    for left, right, cam in load_pairs(BAGS / 'clear_static', limit=8):
        res = base.process(left, right, cam)
        assert res.status == 'tracking'
        found += len(res.obstacles)
    assert found <= 1
