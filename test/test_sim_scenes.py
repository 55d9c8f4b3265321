"""Tests of the widened simulator: profiled ground, surfaces and markings, people, camera
realism, the chest rig and the scene registry (``sim.scenes``)."""
from __future__ import annotations

import dataclasses
import math
import zlib

import cv2
import numpy as np
import pytest

from asmonc_vision.sim.geometry import RigPose, camera_poses
from asmonc_vision.sim.people import walker
from asmonc_vision.sim.relief import GroundProfile, slope_change
from asmonc_vision.sim.render import StereoRenderer, exposure_gains
from asmonc_vision.sim.rig import RigSettings
from asmonc_vision.sim.scenarios import make_scenario, simulate_frame
from asmonc_vision.sim.scenes import (ALL_CLASSES, CLEAR_CLASSES, CORRIDOR, RIGS,
                                      build_scene, make_scene)
from asmonc_vision.sim.surfaces import Marking
from asmonc_vision.sim.truth import (analytic_nearest_top_point, ground_plane_truth,
                                     obstacle_truth)
from asmonc_vision.sim.world import Ground, PavementSettings, World

SMALL = RigSettings(width=160, height=120, focal=150.0)


def _pose(x=0.0, y=0.0, z=1.25, pitch=20.0, yaw=0.0, roll=0.0) -> RigPose:
    return RigPose(position=np.array([x, y, z]), rpy=np.radians([roll, pitch, yaw]))


def _march(world: World, o: np.ndarray, d: np.ndarray, t_max: float = 60.0) -> float:
    """Independent ray / ground intersection: march along the ray on
    ``world.ground_height`` (not the renderer's piecewise planes), then bisect."""
    ts = np.linspace(1e-3, t_max, 12001)
    p = o[None, :] + ts[:, None] * d[None, :]
    above = p[:, 2] - world.ground_height(p[:, 0], p[:, 1]) > 0
    k = int(np.argmax(~above))
    if above[k]:
        return math.inf
    lo, hi = ts[k - 1], ts[k]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        q = o + mid * d
        if q[2] - float(world.ground_height(q[0], q[1])) > 0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# --------------------------------------------------------------------------- ground


@pytest.mark.parametrize('profile', [
    slope_change(0.0, 0.0, 0.0, 4.0, 0.0, 5.0),                     # a slope starts ahead
    slope_change(0.0, 0.0, 10.0, 3.5, 6.0, 0.0),                    # a slope ends ahead
    GroundProfile(0.0, 0.0, 0.0, (3.0, 6.0), (0.1, -0.08, 0.0)),    # a crest
    slope_change(0.0, 0.0, 0.0, 4.0, -6.0, 6.0, rounding=2.0),      # a rounded dip
], ids=['slope_starts', 'slope_ends', 'crest', 'dip'])
def test_a_profiled_ground_renders_at_the_depth_its_surface_implies(profile):
    ground = Ground(slope_deg=math.degrees(math.atan(0.03)), slope_yaw_deg=90.0)  # camber
    world = World(ground, [], seed=1, profile=profile)
    rig = SMALL
    pose = _pose(z=float(world.ground_height(0.0, 0.0)) + 1.25)
    r = StereoRenderer(rig, threads=1)
    left, _ = camera_poses(pose, rig.baseline)
    depth, labels, _ = r.truth(world, 0.0, left)
    assert np.all(labels[depth < np.inf] == 0)            # all of it is ground
    vs, us = np.mgrid[0:rig.height:9, 0:rig.width:13]
    checked = 0
    for v, u in zip(vs.ravel(), us.ravel()):
        if not depth[v, u] < 40.0:
            continue
        d = left.rotation @ np.array([(u - rig.cx) / rig.focal, (v - rig.cy) / rig.focal, 1.0])
        t = _march(world, left.centre, d)
        # the ray parameter is the depth (optical z = 1): so is the disparity f B / z
        assert depth[v, u] == pytest.approx(t, rel=1e-6, abs=1e-6)
        checked += 1
    assert checked > 50
    # beyond the first break the ground really is not the plane under the wearer
    plane = ground_plane_truth(world, 0.0, pose, left)
    far = depth[:40][np.isfinite(depth[:40])]
    z_plane = plane.height / np.maximum(
        plane.normal_up @ np.stack([(np.arange(rig.width) - rig.cx) / rig.focal,
                                    np.full(rig.width, (10 - rig.cy) / rig.focal),
                                    np.ones(rig.width)]), 1e-9)
    assert far.size and not np.allclose(depth[10], z_plane, rtol=1e-3)


def test_the_images_of_a_slope_ahead_show_its_disparity():
    """Beyond the break the right image is the left shifted by the disparity the slope
    implies (f B / depth), not by the disparity of the plane under the wearer."""
    rig = RigSettings(noise_sigma=0.0, blur_sigma=0.0, vignetting=0.0, right_gain=1.0,
                      right_offset=0.0)
    world = World(Ground(pavement=PavementSettings(kind='asphalt')), [], seed=3,
                  profile=slope_change(0.0, 0.0, 0.0, 3.5, 0.0, 8.0))
    pose = _pose()
    img = StereoRenderer(rig, threads=1).render(world, 0.0, pose, rng=0)
    left, _ = camera_poses(pose, rig.baseline)
    plane = ground_plane_truth(world, 0.0, pose, left)
    rows = slice(20, 90)                       # the slope, 4.4-8 m ahead
    v, u = np.mgrid[0:rig.height, 0:rig.width].astype(np.float32)
    d_true = (rig.focal * rig.baseline / img.depth).astype(np.float32)
    rays = np.stack([(u - rig.cx) / rig.focal, (v - rig.cy) / rig.focal, np.ones_like(u)])
    d_plane = (-rig.focal * rig.baseline * np.tensordot(plane.normal_up, rays, 1)
               / plane.height).astype(np.float32)
    assert np.all(np.abs(d_true[rows] - d_plane[rows]) > 1.0)

    def residual(d):   # the right image moved back by the disparity d, minus the left
        warped = cv2.remap(img.right.astype(np.float32), u - d, v, cv2.INTER_LINEAR)
        diff = np.abs(warped - img.left.astype(np.float32))[rows, 60:-60]
        return float(diff.mean())

    assert residual(d_true) < 2.0 and residual(d_plane) > 2.0 * residual(d_true)


def test_the_ground_plane_truth_is_the_piece_under_the_wearer():
    profile = slope_change(0.0, 0.0, 0.0, 3.0, 0.0, 6.0)
    world = World(Ground(), [], seed=0, profile=profile)
    for x, deg in ((1.0, 0.0), (5.0, 6.0)):
        pose = _pose(x=x, z=float(world.ground_height(x, 0.0)) + 1.25, pitch=0.0)
        left, _ = camera_poses(pose, 0.35)
        plane = ground_plane_truth(world, 0.0, pose, left)
        # optical frame: y down, z forward; the up normal tilts back (-z) on an uphill
        tilt = math.degrees(math.atan2(-plane.normal_up[2], -plane.normal_up[1]))
        assert tilt == pytest.approx(deg, abs=1e-6)
        assert plane.height == pytest.approx(1.25 * math.cos(math.radians(deg)), abs=1e-6)
    gx, _ = world.ground_gradient(np.array([1.0, 5.0]), np.zeros(2))
    assert np.allclose(gx, [0.0, math.tan(math.radians(6.0))])


def test_a_kerb_ramp_is_ground_and_its_kerbs_are_beside_the_path():
    sc = build_scene('kerb_ramp', 4, 12.0, SMALL, realism=False)
    world = sc.world
    kerbs = world.terraces
    assert len(kerbs) == 2 and all(k.kind == 'kerb' and 0.10 <= k.rise <= 0.15 for k in kerbs)
    # along the path the ground rises from 0 to the kerb's height with no step
    x = np.linspace(0.0, 20.0, 4001)
    z = world.ground_height(x, np.zeros_like(x))
    assert np.max(np.abs(np.diff(z))) <= 0.10 * 0.005 + 1e-9   # grade <= 1:10, no step
    assert z[0] == 0.0 and z[-1] == pytest.approx(kerbs[0].rise)
    # beside the ramp there is a step (the kerb)
    s0 = kerbs[0].polygon[0][0]
    half = kerbs[0].polygon[0][1]
    y = half + 0.05
    assert float(world.ground_height(s0 + 0.01, y)) - float(
        world.ground_height(s0 - 0.01, y)) == pytest.approx(kerbs[0].rise)
    # seen from 2 m before the ramp: the ramp is ground (depth as its surface implies)
    pose = _pose(x=s0 - 2.0, z=1.25)
    r = StereoRenderer(SMALL, threads=1)
    left, _ = camera_poses(pose, SMALL.baseline)
    depth, labels, _ = r.truth(world, 0.0, left)
    u = int(round(SMALL.cx))
    for v in range(SMALL.height // 2, SMALL.height, 6):
        d = left.rotation @ np.array([0.0, (v - SMALL.cy) / SMALL.focal, 1.0])
        assert labels[v, u] == 0
        assert depth[v, u] == pytest.approx(_march(world, left.centre, d), rel=1e-6)
    obs = obstacle_truth(world, 0.0, pose, left, SMALL.camera(),
                         ground_plane_truth(world, 0.0, pose, left), depth, labels,
                         np.zeros_like(labels))
    assert {o.id for o in obs} == {1, 2}
    assert all(abs(o.range * math.sin(o.bearing)) > CORRIDOR for o in obs)


# --------------------------------------------------------------------------- surfaces


def test_markings_change_the_image_but_are_not_obstacles():
    marks = [Marking('grate', 3.0, 0.0, 0.0, 0.4, 0.8, fill='grate', albedo=80.0,
                     period=0.04, bar=0.02),
             Marking('manhole', 4.5, 0.6, 0.0, 0.6, 0.6, shape='ellipse', fill='manhole',
                     albedo=70.0, period=0.05, bar=0.02),
             Marking('zebra', 6.0, 0.0, 0.0, 3.5, 3.0, fill='stripes', period=1.0, bar=0.5),
             Marking('shadow', 2.5, -0.8, 30.0, 3.0, 0.15, fill='multiply', factor=0.5,
                     edge=0.03),
             Marking('stain', 3.5, 1.0, 0.0, 0.8, 0.5, shape='ellipse', fill='multiply',
                     factor=0.7, wobble=0.2)]
    pose = _pose()
    r = StereoRenderer(RigSettings(), threads=1)
    for kind in ('tiles', 'asphalt', 'concrete'):
        ground = Ground(pavement=PavementSettings(kind=kind))
        plain = r.render(World(ground, [], seed=2), 0.0, pose, rng=5)
        marked = r.render(World(ground, [], seed=2, markings=marks), 0.0, pose, rng=5)
        assert np.array_equal(plain.labels, marked.labels)
        assert set(np.unique(marked.labels)) <= {0, -1}
        assert np.array_equal(plain.depth, marked.depth)
        diff = np.abs(plain.left.astype(int) - marked.left.astype(int))
        assert diff.max() > 60                              # the marks are drawn ...
        assert np.count_nonzero(diff[:30] > 3) == 0         # ... not far beyond them
        left, _ = camera_poses(pose, 0.35)
        world = World(ground, [], seed=2, markings=marks)
        assert obstacle_truth(world, 0.0, pose, left, r.rig.camera(),
                              ground_plane_truth(world, 0.0, pose, left), marked.depth,
                              marked.labels, marked.faces) == []


# --------------------------------------------------------------------------- people


def test_a_person_moves_and_the_truth_follows_it():
    track = ((0.0, 4.0, 2.5), (5.0, 4.0, -2.5))        # crossing right at 1 m/s
    world = World(Ground(), [walker(track, height=1.7)], seed=0)
    r = StereoRenderer(SMALL, threads=1)
    pose = _pose(pitch=10.0)
    left, _ = camera_poses(pose, SMALL.baseline)
    places = []
    for t in (2.0, 2.5, 3.0):
        img = r.render(world, t, pose, rng=1)
        plane = ground_plane_truth(world, t, pose, left)
        obs = obstacle_truth(world, t, pose, left, SMALL.camera(), plane, img.depth,
                             img.labels, img.faces)
        assert [o.kind for o in obs] == ['person']
        p = left.to_world(obs[0].position)[0]
        person = world.active(t)[0]
        # the truth's point is the nearest point of the person's top where it is at t
        # (it walks along -y, turned to face that way)
        assert person.yaw_deg == pytest.approx(-90.0)
        assert person.y == pytest.approx(2.5 - t)
        near = analytic_nearest_top_point(person, left, plane)
        assert np.linalg.norm(obs[0].position - near) < 0.04
        assert p[2] == pytest.approx(1.7, abs=1e-6)
        assert obs[0].height == pytest.approx(1.7, abs=1e-3)
        places.append(person.y)
        # where it was half a second before is ground again
        if t > 2.0:
            old = walker(((0.0, 4.0, places[-2]),), height=1.7)
            ou = SMALL.cx - SMALL.focal * places[-2] / (4.0 - old.width / 2)
            col = img.labels[:, int(np.clip(round(ou), 0, SMALL.width - 1))]
            assert 1 not in col


# --------------------------------------------------------------------------- camera


def test_the_right_image_residual_is_measurable_and_camera_info_unchanged():
    base = RigSettings(noise_sigma=0.0)
    shifted = dataclasses.replace(base, right_shift_px=0.3)
    world = World(Ground(), [], seed=4)
    pose = _pose()
    a = StereoRenderer(base, threads=1).render(world, 0.0, pose, rng=0)
    b = StereoRenderer(shifted, threads=1).render(world, 0.0, pose, rng=0)
    assert np.array_equal(a.left, b.left)
    (dx, dy), _ = cv2.phaseCorrelate(a.right.astype(np.float64), b.right.astype(np.float64))
    assert dy == pytest.approx(0.3, abs=0.08) and abs(dx) < 0.05
    assert all(np.array_equal(m1, m2) for m1, m2 in zip(base.matrices(), shifted.matrices()))
    rotated = dataclasses.replace(base, right_rotation_deg=0.1)
    c = StereoRenderer(rotated, threads=1).render(world, 0.0, pose, rng=0)
    # a rotation about the principal point: rows far left and right move oppositely
    cols = base.width // 5
    (_, dy_l), _ = cv2.phaseCorrelate(a.right[:, :cols].astype(np.float64),
                                      c.right[:, :cols].astype(np.float64))
    (_, dy_r), _ = cv2.phaseCorrelate(a.right[:, -cols:].astype(np.float64),
                                      c.right[:, -cols:].astype(np.float64))
    assert dy_l * dy_r < 0 and abs(dy_l - dy_r) > 0.2


def test_motion_blur_gain_drift_and_realism_off():
    rig = RigSettings(noise_sigma=0.0, width=160, height=120, focal=150.0)
    blurred = dataclasses.replace(rig, exposure_time=0.02, exposure_samples=6)
    world = World(Ground(), [], seed=1)

    def pose_at(t):   # turning at 90 degrees/s
        return _pose(yaw=90.0 * t)

    sharp = StereoRenderer(rig, threads=1).render(world, 1.0, pose_at(1.0), rng=0)
    soft = StereoRenderer(blurred, threads=1).render(world, 1.0, pose_at(1.0), rng=0,
                                                     pose_at=pose_at)

    def energy(img):
        return float(np.mean(np.abs(np.diff(img.astype(float), axis=1))))

    assert energy(soft.left) < 0.8 * energy(sharp.left)
    assert np.array_equal(sharp.depth, soft.depth)       # truth at the frame time
    # auto-exposure drift: slow, bounded, a little different per camera
    drift = dataclasses.replace(rig, gain_drift=0.08, gain_drift_period=4.0)
    g = np.array([exposure_gains(drift, 3, t) for t in np.arange(0.0, 20.0, 0.1)])
    assert np.all(np.abs(g - 1.0) <= 0.08 * 1.25 + 1e-9) and g.std(axis=0).min() > 0.01
    assert np.abs(np.diff(g, axis=0)).max() < 0.02
    assert 0.002 < np.abs(g[:, 0] - g[:, 1]).max() < 0.08 * 0.5
    assert exposure_gains(rig, 3, 5.0) == (1.0, 1.0)
    sc = make_scene('clear_walk', 5, duration=2.0, realism=False)
    assert not sc.rig.realism
    sc = make_scene('clear_walk', 5, duration=2.0, realism=True)
    assert sc.rig.realism and 0.1 <= abs(sc.rig.right_shift_px) <= 0.4


#: crc32 of frames of existing scenarios (seed 2) rendered before the simulator widened.
OLD_IMAGES = {('static_obstacles', 5): (3908764459, 232843323),
              ('walk_obstacles', 20): (1321633137, None),
              ('step_down', 30): (None, 1563854495)}


@pytest.mark.parametrize('name,k', sorted(OLD_IMAGES))
def test_existing_scenarios_render_as_before(name, k):
    f = simulate_frame(make_scenario(name, seed=2), k)
    crc_l, crc_r = OLD_IMAGES[(name, k)]
    if crc_l is not None:
        assert zlib.crc32(f.left.tobytes()) == crc_l
    if crc_r is not None:
        assert zlib.crc32(f.right.tobytes()) == crc_r


# --------------------------------------------------------------------------- scenes


def test_the_rigs():
    chest = RigSettings.chest()
    assert (chest.width, chest.height, chest.baseline, chest.camera_height) == (
        640, 480, 0.12, 1.3)
    narrow = RigSettings.narrow()
    assert (narrow.width, narrow.height, narrow.focal, narrow.baseline) == (
        640, 400, 450.0, 0.075)
    assert RIGS == ('backpack', 'chest', 'narrow')
    for seed in range(4):
        sc = make_scene('camber', seed, duration=1.0, rig='chest')
        assert sc.rig.width == 640 and 0.0 <= sc.rig.camera_pitch_deg <= 10.0
        assert make_scene('camber', seed, duration=1.0).rig.width == 320
        sn = make_scene('camber', seed, duration=1.0, rig='narrow').rig
        assert sn.height == 400 and 1.0 <= sn.camera_height <= 1.6
        assert 8.0 <= sn.camera_pitch_deg <= 30.0
    shares = [make_scene('grate', s, duration=0.5).rig.realism for s in range(40)]
    assert 0.4 <= np.mean(shares) <= 0.8
    with pytest.raises(KeyError):
        make_scene('no_such', 0)
    with pytest.raises(ValueError):
        make_scene('grate', 0, rig='helmet')


def _path_offsets(sc, ob_xy):
    """Lateral distance (m) of a point from the planned path and how far ahead of the
    path's start it lies along it."""
    t = np.linspace(0.0, sc.duration, 400)
    xy = sc.trajectory.path(t)
    d = np.hypot(*(xy - np.asarray(ob_xy)).T)
    return float(d.min())


@pytest.mark.parametrize('scene_class', ALL_CLASSES)
def test_every_scene_class_renders_with_consistent_truth(scene_class):
    sc = build_scene(scene_class, 7, 10.0, SMALL, realism=False)
    assert sc.name == scene_class and sc.n_frames == 100
    again = build_scene(scene_class, 7, 10.0, SMALL, realism=False)
    assert sc.describe() == again.describe()
    r = StereoRenderer(sc.rig)
    for k in (25, 70):
        f = simulate_frame(sc, k, r)
        assert f.left.shape == (120, 160) and 25 < f.left.mean() < 230 and f.left.std() > 4
        for o in f.obstacles:
            lateral = abs(o.range * math.sin(o.bearing))
            if scene_class in CLEAR_CLASSES and o.range < 5.0:
                assert lateral > CORRIDOR, (k, o)
    obstacles = [o for o in sc.world.obstacles if not hasattr(o, 'polygon')]
    if scene_class in CLEAR_CLASSES:
        assert all(_path_offsets(sc, (o.x, o.y)) > CORRIDOR + 0.3 for o in obstacles)
    if scene_class == 'pavement_obstacles':
        assert sum(_path_offsets(sc, (o.x, o.y)) < CORRIDOR for o in obstacles) >= 2
    if scene_class.startswith('people'):
        assert any(o.kind == 'person' for o in sc.world.obstacles)


def test_a_scene_class_writes_a_contract_bag(tmp_path, capsys):
    from asmonc_vision.io import bagio
    from asmonc_vision.sim.cli import main

    out = tmp_path / 'bag'
    assert main(['people_crossing', str(out), '--seed', '3', '--duration', '0.2',
                 '--width', '160', '--height', '120', '--focal', '150', '--quiet',
                 '--realism', 'on']) == 0
    assert '2 stereo frames 160x120' in capsys.readouterr().out
    from rosbags.rosbag2 import Reader
    with Reader(out) as reader:
        names = {c.topic for c in reader.connections}
    assert {bagio.TOPICS[k][0] for k in ('left_image', 'right_image', 'gt_obstacles',
                                         'gt_ground_plane', 'imu')} <= names
    # a name that is both a scenario and a scene class: the scenario unless --scene
    assert main(['step_down', str(tmp_path / 'sd'), '--scene', '--duration', '0.1',
                 '--width', '160', '--height', '120', '--focal', '150', '--quiet']) == 0
    import json

    import yaml
    info = yaml.safe_load((tmp_path / 'sd' / 'metadata.yaml').read_text())
    meta = json.loads(info['rosbag2_bagfile_information']['custom_data']['asmonc_vision.sim'])
    assert meta['scenario'] == 'step_down' and 'across the path' in meta['description']


@pytest.mark.parametrize('seed', [0, 1])
def test_a_kerb_crossed_is_the_ground_under_the_wearer_after(seed):
    """kerb_cross: the wearer walks over a kerb up (seed 0) or down (seed 1) and on. The
    camera's height changes by the kerb's (within the gait's bob); before the crossing
    the kerb is an obstacle ahead in the truth; after it the terrace is the ground under
    the wearer (the truth's plane, the camera its own height above it), no obstacle."""
    sc = build_scene('kerb_cross', seed, 20.0, SMALL, realism=False)
    edge = [o for o in sc.world.obstacles if hasattr(o, 'polygon')][0]
    assert (edge.rise > 0) == (seed == 0)
    start, end = (sc.trajectory.pose(t).position for t in (1.0, 19.5))
    assert sc.world.terrace_at(start[0], start[1]) is None
    assert sc.world.terrace_at(end[0], end[1]) is edge
    assert end[2] - start[2] == pytest.approx(edge.rise, abs=0.05)
    r = StereoRenderer(sc.rig)
    before, after = simulate_frame(sc, 30, r), simulate_frame(sc, 195, r)
    assert any(o.id == edge.id and o.range > 2.0 for o in before.obstacles)
    assert not after.obstacles
    # the camera stays its own height above the ground under it: the terrace's top
    assert after.plane.height == pytest.approx(before.plane.height, abs=0.06)
