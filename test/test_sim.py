"""Tests of the simulator: geometry, motion, inclinometer, determinism, bag round trip."""
from __future__ import annotations

import dataclasses
import json
import math
import time

import cv2
import numpy as np
import pytest

from asmonc_vision.io import bagio
from asmonc_vision.core.camera import (MetricPlane, ground_range_bearing, plane_disparity,
                                       plane_from_metric)
from asmonc_vision.sim.geometry import (R_BODY_OPTICAL, RigPose, camera_poses,
                                        matrix_to_quaternion, quaternion_from_rpy,
                                        rpy_to_matrix)
from asmonc_vision.sim.inclinometer import InclinometerSettings, simulate_inclinometer
from asmonc_vision.sim.motion import GaitSettings, Leg, Trajectory
from asmonc_vision.sim.render import StereoRenderer
from asmonc_vision.sim.rig import LEFT_FRAME, RIGHT_FRAME, RigSettings
from asmonc_vision.sim.scenarios import (SCENARIOS, Scenario, make_scenario,
                                         simulate_frame)
from asmonc_vision.sim.truth import (MIN_PIXELS, analytic_nearest_top_point,
                                     ground_plane_truth, obstacle_truth)
from asmonc_vision.sim.world import (Box, Ground, World, bollard, kerb_up, post, step_down,
                                     wall)


def _pose(x=0.0, y=0.0, z=1.25, roll=0.0, pitch=20.0, yaw=0.0) -> RigPose:
    return RigPose(position=np.array([x, y, z]),
                   rpy=np.radians([roll, pitch, yaw]))


def _world(slope_deg=0.0, obstacles=()) -> World:
    return World(Ground(slope_deg=slope_deg, slope_yaw_deg=30.0), list(obstacles), seed=3)


# --------------------------------------------------------------------------- settings


def test_rig_defaults_are_the_papers_and_validated():
    rig = RigSettings()
    assert (rig.width, rig.height, rig.focal, rig.baseline) == (320, 240, 300.0, 0.35)
    assert rig.camera_height == 1.25 and rig.camera_pitch_deg == 20.0 and rig.fps == 10.0
    assert (rig.cx, rig.cy) == (159.5, 119.5)
    k, pl, pr = rig.matrices()
    assert pr[0, 3] == pytest.approx(-300.0 * 0.35)
    assert pl[0, 3] == 0.0 and k[0, 0] == k[1, 1] == 300.0
    cam = rig.camera()
    assert cam.fb == pytest.approx(105.0)
    with pytest.raises(ValueError, match='focal'):
        RigSettings(focal=-1.0)
    with pytest.raises(ValueError, match='baseline'):
        RigSettings(baseline=0.0)
    # the ground is seen from ~1.4 m to the horizon
    bottom = math.radians(20.0) + math.atan((239 - rig.cy) / rig.focal)
    assert 1.25 / math.tan(bottom) == pytest.approx(1.4, abs=0.05)


def test_rotations_roundtrip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        r, p, y = rng.uniform(-1, 1, 3)
        m = rpy_to_matrix(r, p, y)
        assert np.allclose(m @ m.T, np.eye(3), atol=1e-12)
        q = quaternion_from_rpy(r, p, y)
        assert np.allclose(q, matrix_to_quaternion(m), atol=1e-12)
    # positive pitch looks down (REP 103); the optical z axis is body x
    m = rpy_to_matrix(0.0, math.radians(20), 0.0) @ R_BODY_OPTICAL
    assert m[2, 2] < 0 and m[0, 0] == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------- geometry


@pytest.mark.parametrize('rig, slope', [(RigSettings(), 0.0), (RigSettings(), 5.0),
                                        (RigSettings(width=640, height=480, focal=600.0), 0.0)])
def test_ground_pixel_disparity_is_the_plane(rig, slope):
    """d = f B / z at the cyclopean coordinate equals plane_disparity(plane_from_metric)."""
    world = _world(slope)
    r = StereoRenderer(rig)
    cam = rig.camera()
    for pose in (_pose(), _pose(x=2.0, y=-1.0, z=1.33, roll=3.0, pitch=24.0, yaw=40.0)):
        if slope:
            pose = RigPose(position=pose.position + [0, 0, world.ground_height(
                *pose.position[:2])], rpy=pose.rpy)
        left, _ = camera_poses(pose, rig.baseline)
        depth, labels, _ = r.truth(world, 0.0, left)
        v, u = np.nonzero(labels == 0)
        assert u.size > 0.5 * rig.width * rig.height
        d = cam.fb / depth[v, u]
        plane = ground_plane_truth(world, 0.0, pose, left)
        abc = plane_from_metric(cam, plane)
        pred = plane_disparity(abc, u - d / 2.0, v)
        rel = np.abs(pred - d) / d
        assert rel.max() < 1e-6
        # the plane height is the camera height (up to roll/slope)
        assert 1.1 < plane.height < 1.4


def test_world_points_project_to_the_same_row():
    rig = RigSettings()
    rng = np.random.default_rng(1)
    pose = _pose(x=0.3, y=0.2, z=1.3, roll=4.0, pitch=17.0, yaw=-25.0)
    left, right = camera_poses(pose, rig.baseline)
    pts = np.column_stack([rng.uniform(1.5, 10, 50), rng.uniform(-3, 3, 50),
                           rng.uniform(0, 2, 50)])
    pts = left.to_world(left.to_optical(pts))  # round trip is exact
    pl, pr = left.to_optical(pts), right.to_optical(pts)
    assert np.allclose(pl[:, 1:], pr[:, 1:], atol=1e-12)   # same y, z: rectified
    vl = rig.focal * pl[:, 1] / pl[:, 2] + rig.cy
    vr = rig.focal * pr[:, 1] / pr[:, 2] + rig.cy
    ul = rig.focal * pl[:, 0] / pl[:, 2] + rig.cx
    ur = rig.focal * pr[:, 0] / pr[:, 2] + rig.cx
    assert np.allclose(vl, vr, atol=1e-9)
    assert np.allclose(ul - ur, rig.focal * rig.baseline / pl[:, 2], rtol=1e-9)
    # the core model agrees: project() gives the cyclopean coordinate
    u_c, v_c, d = rig.camera().project(pl)
    assert np.allclose(u_c, (ul + ur) / 2) and np.allclose(v_c, vl) and np.allclose(d, ul - ur)


def test_a_rig_off_its_calibration_parts_the_rows():
    """right_tilt_deg moves the right image's rows by f tan(tilt); right_roll_deg turns
    them about the optical axis (-f roll x); camera_roll_deg rolls the whole rig."""
    rig = RigSettings(right_tilt_deg=0.2, right_roll_deg=0.3, camera_roll_deg=5.0)
    pose = _pose(z=1.3)
    left, right = camera_poses(pose, rig.baseline, rig.right_misalignment)
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(3, 10, 40), rng.uniform(-2, 2, 40),
                           rng.uniform(0, 1.5, 40)])
    pl, pr = left.to_optical(pts), right.to_optical(pts)
    vl = rig.focal * pl[:, 1] / pl[:, 2] + rig.cy
    vr = rig.focal * pr[:, 1] / pr[:, 2] + rig.cy
    ur = rig.focal * pr[:, 0] / pr[:, 2] + rig.cx
    y = (vl - rig.cy) / rig.focal       # the tilt moves a row by f tilt (1 + y^2)
    expect = (rig.focal * math.radians(0.2) * (1 + y * y)
              - rig.focal * math.radians(0.3) * (ur - rig.cx) / rig.focal)
    assert np.allclose(vr - vl, expect, atol=0.05)
    assert np.all(np.abs(vr - vl) > 0.2)
    # a perfect rig's rows agree; the mounting roll goes into the rig's roll
    l0, r0 = camera_poses(pose, rig.baseline, RigSettings().right_misalignment)
    assert np.allclose(l0.rotation, r0.rotation)
    sc = make_scenario('clear_static', seed=1, rig=rig)
    assert math.degrees(sc.trajectory.pose(1.0).rpy[0]) == pytest.approx(5.0, abs=0.5)


def test_right_image_is_the_left_shifted_by_the_true_disparity():
    """Both cameras see the same world-fixed texture at consistent places."""
    rig = RigSettings(noise_sigma=0.0, right_gain=1.0, right_offset=0.0, vignetting=0.0)
    world = _world()
    r = StereoRenderer(rig)
    pose = _pose(roll=1.0, yaw=5.0)
    left, right = camera_poses(pose, rig.baseline)
    rad_l = r.radiance(world, 0.0, left)
    rad_r = r.radiance(world, 0.0, right)
    depth, labels, _ = r.truth(world, 0.0, left)
    v, u = np.mgrid[0:rig.height, 0:rig.width].astype(np.float32)
    d = (rig.focal * rig.baseline / depth).astype(np.float32)
    warped = cv2.remap(rad_r, u - d, v, cv2.INTER_LINEAR)
    m = (labels == 0) & (u - d > 2) & (v > 60)   # ground, near enough to be textured
    err = np.abs(warped - rad_l)[m].mean()
    err_unwarped = np.abs(rad_r - rad_l)[m].mean()
    assert err < 2.5, err
    assert err < 0.3 * err_unwarped
    # the texture is not trivially flat
    assert rad_l[m].std() > 10.0


def test_obstacle_pixels_have_more_disparity_than_the_ground():
    rig = RigSettings()
    obstacles = [Box(x=3.0, y=0.3, length=0.3, width=0.4, height=0.05, yaw_deg=30.0),
                 Box(x=4.0, y=-0.8, length=0.4, width=0.3, height=0.3, yaw_deg=-10.0),
                 bollard(3.5, 1.0), post(5.0, -1.5, round_=True),
                 kerb_up(8.0, 0.0, 5.0, rise=0.12)]
    world = _world(0.0, obstacles)
    r = StereoRenderer(rig)
    cam = rig.camera()
    pose = _pose(roll=1.5, pitch=21.0, yaw=3.0)
    left, _ = camera_poses(pose, rig.baseline)
    depth, labels, _ = r.truth(world, 0.0, left)
    abc = plane_from_metric(cam, ground_plane_truth(world, 0.0, pose, left))
    for ob in world.obstacles:
        v, u = np.nonzero(labels == ob.id)
        assert v.size > 10, ob.kind
        d = cam.fb / depth[v, u]
        excess = d - plane_disparity(abc, u - d / 2.0, v)
        assert excess.min() > 0.0, ob.kind
    # and a drop has less
    world = _world(0.0, [step_down(4.0, 0.0, 0.0, drop=0.15)])
    depth, labels, _ = r.truth(world, 0.0, left)
    v, u = np.nonzero(labels == 1)
    d = cam.fb / depth[v, u]
    assert v.size > 1000
    assert (d - plane_disparity(abc, u - d / 2.0, v)).max() < 0.0


def test_static_obstacles_ground_truth():
    sc = make_scenario('static_obstacles', seed=4)
    r = StereoRenderer(sc.rig)
    early = simulate_frame(sc, 5, r)        # t = 0.5 s: nothing yet
    assert early.obstacles == [] and (early.labels > 0).sum() == 0
    f = simulate_frame(sc, 45, r)           # t = 4.5 s: all six have appeared
    kinds = sorted(o.kind for o in f.obstacles)
    assert kinds == ['bollard', 'box', 'box', 'box', 'box', 'post']
    heights = sorted(round(o.height, 3) for o in f.obstacles if o.kind == 'box')
    assert heights == [0.05, 0.1, 0.2, 0.3]
    cam = sc.rig.camera()
    abc = plane_from_metric(cam, f.plane)
    ids = [o.id for o in f.obstacles]
    assert ids == sorted(ids) and min(ids) >= 1
    for o in f.obstacles:
        assert 2.0 - 1e-6 <= o.range <= 5.0 and abs(o.bearing) < math.radians(30)
        x, y, w, h = o.roi
        lab = f.labels[y:y + h, x:x + w] == o.id
        assert lab.sum() == o.pixels == (f.labels == o.id).sum()
        assert o.disparity_excess > 0
        if o.kind == 'box':
            # the reported top projects into (or next to) the box's pixels
            u_c, v_c, d = cam.project(o.position[None, :])
            ul = u_c[0] + d[0] / 2
            assert x - 2 <= ul <= x + w + 2 and y - 2 <= v_c[0] <= y + h + 2
            # its disparity excess matches Eq. (1) of the paper to first order
            predicted = d[0] - plane_disparity(abc, u_c, v_c)[0]
            assert predicted == pytest.approx(cam.fb / o.position[2] * o.height / 1.25,
                                              rel=0.15)
    # the camera pose is the left camera's: 1.25 m above the ground, B/2 left of centre
    assert f.left_pose.centre[2] == pytest.approx(f.pose.position[2], abs=0.02)
    assert f.plane.height == pytest.approx(1.25, abs=0.03)


def test_step_down_truth_is_negative():
    sc = make_scenario('step_down', seed=0, duration=6.0)
    f = simulate_frame(sc, sc.n_frames - 1)
    drops = [o for o in f.obstacles if o.kind == 'drop']
    assert len(drops) == 1
    d = drops[0]
    assert d.height == pytest.approx(-0.15, abs=0.01)
    assert d.disparity_excess < 0 and 1.5 < d.range < 4.0
    # its place is the nearest visible lower ground, just beyond the brink: in view
    uv = _left_uv(sc.rig.camera(), d.position)
    assert _in_image(sc.rig.camera(), uv) and _in_roi(d.roi, uv)


def _single_truth(obstacle, pose, rig=None, world_seed=1):
    """Render one obstacle's left-image truth: (ObstacleTruth or None, world, left, plane,
    depth, labels, faces)."""
    rig = rig if rig is not None else RigSettings()
    world = World(Ground(), [obstacle], seed=world_seed)
    left, _ = camera_poses(pose, rig.baseline)
    depth, labels, faces = StereoRenderer(rig, threads=1).truth(world, 0.0, left)
    plane = ground_plane_truth(world, 0.0, pose, left)
    obs = obstacle_truth(world, 0.0, pose, left, rig.camera(), plane, depth, labels, faces)
    assert len(obs) <= 1
    return (obs[0] if obs else None), world, left, plane, depth, labels, faces


def _left_uv(cam, point):
    """Left-image pixel (u, v) of a left optical-frame point."""
    u, v, d = cam.project(np.asarray(point, float)[None, :])
    return float(u[0] + d[0] / 2.0), float(v[0])


def _in_image(cam, uv, tol=0.5):
    return -tol <= uv[0] <= cam.width - 1 + tol and -tol <= uv[1] <= cam.height - 1 + tol


def _in_roi(roi, uv, tol=1.0):
    x, y, w, h = roi
    return x - tol <= uv[0] <= x + w - 1 + tol and y - tol <= uv[1] <= y + h - 1 + tol


@pytest.mark.parametrize('height', [2.4, 0.6])
def test_truth_of_a_wall_beside_the_path_is_in_view(height):
    """A wall parallel to the path 1.7 m to the right: its nearest point is abeam (out of
    view); the truth is where it enters the field of view."""
    rig = RigSettings()
    cam = rig.camera()
    pose = _pose(roll=1.0, pitch=21.0, yaw=2.0)
    o, world, left, plane, depth, labels, _ = _single_truth(
        wall(-3.0, -1.7, 12.0, -1.7, height=height), pose, rig)
    assert o is not None and o.kind == 'wall'
    assert o.height == pytest.approx(height, abs=1e-6)
    # range and bearing are those of a visible pixel's foot: that foot (the position
    # dropped to the ground: what the scorer compares) is in the image and in the roi.
    # (The position itself is the wall's top above it, which for a wall seen at the
    # image's edge is out of view: a point raised towards the camera projects outwards.)
    foot = o.position - o.height * np.asarray(plane.normal_up)
    uv = _left_uv(cam, foot)
    assert _in_image(cam, uv) and _in_roi(o.roi, uv), (uv, o.roi)
    # its bearing is that of a point in view: within the bearings of the image's ground
    v, u = np.nonzero(labels == 0)
    z = depth[v, u]
    pts = np.column_stack([(u - cam.cx) * z / cam.f, (v - cam.cy) * z / cam.f, z])
    rng_g, brg_g = ground_range_bearing(plane, pts)
    near = np.abs(rng_g - o.range) < 0.1
    assert brg_g[near].min() - 1e-3 <= o.bearing <= brg_g[near].max() + 1e-3
    assert math.radians(-32) < o.bearing < 0
    # and it is the nearest visible part (a robust minimum: the 21st nearest pixel, a few
    # pixels in from the corner where the wall leaves the image, ~3 cm per pixel here)
    v, u = np.nonzero(labels == o.id)
    z = depth[v, u]
    pts = np.column_stack([(u - cam.cx) * z / cam.f, (v - cam.cy) * z / cam.f, z])
    assert ground_range_bearing(plane, pts)[0].min() > o.range - 0.08
    # the former definition (nearest point of the whole wall) was abeam, out of view
    old = analytic_nearest_top_point(world.obstacles[0], left, plane)
    assert abs(ground_range_bearing(plane, old[None, :])[1][0]) > math.radians(60)


def test_truth_of_an_obstacle_cut_by_the_bottom_edge_is_in_view():
    """A 30 cm box being passed: its front is below the image's bottom edge; the truth is
    the nearest part of its top still in view."""
    rig = RigSettings()
    cam = rig.camera()
    pose = _pose(pitch=20.0)
    o, world, left, plane, _, labels, _ = _single_truth(
        Box(x=1.1, y=0.3, length=0.4, width=0.4, height=0.3, yaw_deg=10.0), pose, rig)
    assert o is not None
    x, y, w, h = o.roi
    assert y + h == cam.height                   # cut by the bottom edge
    uv = _left_uv(cam, o.position)
    assert _in_image(cam, uv) and _in_roi(o.roi, uv), (uv, o.roi)
    assert o.height == pytest.approx(0.3, abs=1e-6)
    # the former definition (the front edge of the top) is below the image
    old = analytic_nearest_top_point(world.obstacles[0], left, plane)
    assert _left_uv(cam, old)[1] > cam.height + 5
    r_old = ground_range_bearing(plane, old[None, :])[0][0]
    assert r_old + 0.05 < o.range < 1.3


def test_truth_of_a_box_in_full_view_is_its_nearest_point():
    """For obstacles wholly in view the nearest visible part is the nearest point."""
    rig = RigSettings()
    pose = _pose(roll=1.5, pitch=21.0, yaw=3.0)
    for ob in (Box(x=3.0, y=0.4, length=0.35, width=0.4, height=0.2, yaw_deg=25.0),
               Box(x=4.5, y=-0.8, length=0.3, width=0.45, height=0.05, yaw_deg=-40.0),
               Box(x=2.2, y=0.0, length=0.4, width=0.3, height=0.3, yaw_deg=0.0),
               bollard(3.5, 1.0)):
        o, world, left, plane, _, _, _ = _single_truth(ob, pose, rig)
        old = analytic_nearest_top_point(world.obstacles[0], left, plane)
        assert np.linalg.norm(o.position - old) < 0.03, ob
        r_old, b_old = ground_range_bearing(plane, old[None, :])
        assert o.range == pytest.approx(r_old[0], abs=0.03)
        assert o.range * abs(o.bearing - b_old[0]) < 0.03
        assert o.height == pytest.approx(ob.height, abs=1e-6)


def test_truth_needs_a_few_pixels_and_ignores_stray_ones():
    rig = RigSettings()
    cam = rig.camera()
    pose = _pose()
    box = Box(x=3.0, y=0.2, length=0.3, width=0.4, height=0.2)
    o, world, left, plane, depth, labels, faces = _single_truth(box, pose, rig)
    assert o is not None and o.pixels > 200
    v, u = np.nonzero(labels == 1)
    for keep in (MIN_PIXELS - 1, MIN_PIXELS):
        lab = np.zeros_like(labels)
        lab[v[:keep], u[:keep]] = 1
        obs = obstacle_truth(world, 0.0, pose, left, cam, plane, depth, lab, faces)
        if keep < MIN_PIXELS:
            assert obs == []                     # not in view
        else:
            assert len(obs) == 1 and obs[0].pixels == keep
            assert obs[0].roi == (int(u[:keep].min()), int(v[:keep].min()),
                                  int(u[:keep].max() - u[:keep].min() + 1),
                                  int(v[:keep].max() - v[:keep].min() + 1))
    # two stray pixels labelled with the box near the bottom of the image do not move it
    lab = labels.copy()
    lab[cam.height - 3, 150:152] = 1
    stray = obstacle_truth(world, 0.0, pose, left, cam, plane, depth, lab, faces)[0]
    assert stray.range == pytest.approx(o.range, abs=0.01)
    assert np.linalg.norm(stray.position - o.position) < 0.02


# --------------------------------------------------------------------------- motion


def _spectrum(x, fs):
    x = np.asarray(x) - np.mean(x)
    win = np.hanning(x.size)
    mag = np.abs(np.fft.rfft(x * win))
    return np.fft.rfftfreq(x.size, 1 / fs), mag


def test_walking_motion_frequencies():
    rig = RigSettings()
    traj = Trajectory([Leg(30.0, 1.2)], rig, None, start_speed=1.2, rng=7)
    fs = 100.0
    t = np.arange(0, 30.0, 1 / fs)
    p, rpy = traj.states(t)
    heading = traj.heading(t)
    fwd = np.stack([np.cos(heading), np.sin(heading)], 1)
    lat_dir = np.stack([-np.sin(heading), np.cos(heading)], 1)
    rel = p[:, :2] - traj.path(t)
    signals = {'pitch': rpy[:, 1], 'bob': p[:, 2], 'surge': np.sum(rel * fwd, 1),
               'roll': rpy[:, 0], 'yaw': rpy[:, 2] - heading, 'sway': np.sum(rel * lat_dir, 1)}
    f_step = traj.step_freq
    assert 1.7 < f_step < 2.1
    for name, x in signals.items():
        f, mag = _spectrum(x, fs)
        peak = f[np.argmax(mag[1:]) + 1]
        expect = f_step if name in ('pitch', 'bob', 'surge') else f_step / 2
        assert peak == pytest.approx(expect, abs=0.05), name
        # most of the energy is at that frequency (+/- 0.15 Hz)
        band = np.abs(f - expect) < 0.15
        assert (mag[band] ** 2).sum() > 0.6 * (mag ** 2).sum(), name
    # realistic amplitudes: a couple of degrees and centimetres
    assert 1.0 < np.degrees(np.ptp(rpy[:, 1])) / 2 < 3.5
    assert 1.0 < np.degrees(np.ptp(rpy[:, 0])) / 2 < 3.5
    assert 0.015 < np.ptp(p[:, 2]) / 2 < 0.05
    # walking speed
    assert np.hypot(*(traj.path(30.0) - traj.path(0.0))) == pytest.approx(36.0, rel=1e-3)


def test_stop_turn_and_determinism():
    rig = RigSettings()
    legs = [Leg(4.0, 1.2), Leg(1.5, 0.0, ramp=1.0), Leg(2.0, 0.0, turn_deg=90.0),
            Leg(3.0, 1.2)]
    a = Trajectory(legs, rig, None, start_speed=1.2, rng=3)
    b = Trajectory(legs, rig, None, start_speed=1.2, rng=3)
    c = Trajectory(legs, rig, None, start_speed=1.2, rng=4)
    t = np.linspace(0, 10.5, 500)
    assert np.array_equal(a.states(t)[1], b.states(t)[1])
    assert not np.allclose(a.states(t)[1], c.states(t)[1])
    # the motion dies out when stopped, and the heading turned 90 degrees
    walking = a.states(np.linspace(1, 3.5, 300))[1][:, 1]
    standing = a.states(np.linspace(5.2, 5.5, 30))[1][:, 1]
    assert np.ptp(standing) < 0.15 * np.ptp(walking)
    assert np.degrees(a.heading(10.5) - a.heading(0.0)) == pytest.approx(90.0)
    assert np.all(np.diff(a.heading(np.linspace(5.5, 7.5, 50))) >= 0)
    # extreme gait reaches the paper's extremes
    ext = Trajectory([Leg(10.0, 1.2)], rig, None, gait=GaitSettings.extreme(),
                     start_speed=1.2, rng=3)
    rpy = ext.states(np.linspace(0, 10, 2000))[1]
    assert np.degrees(np.ptp(rpy[:, 0])) / 2 > 3.5


def test_uphill_walk_follows_the_slope():
    sc = make_scenario('slope', seed=0)
    p, rpy = sc.trajectory.states(np.array([0.0, sc.duration]))
    rise = p[1, 2] - p[0, 2]
    run = np.hypot(*(p[1, :2] - p[0, :2]))
    assert math.degrees(math.atan2(rise, run)) == pytest.approx(5.0, abs=1.0)
    plane = ground_plane_truth(sc.world, 0.0, sc.trajectory.pose(0.0),
                               camera_poses(sc.trajectory.pose(0.0), sc.rig.baseline)[0])
    # the slope is seen as a plane tilted ~25 degrees to the optical axis
    tilt = math.degrees(math.asin(-plane.normal_up[2]))
    assert 22.0 < tilt < 29.0


# --------------------------------------------------------------------------- inclinometer


def test_inclinometer_rate_noise_and_lag():
    rig = RigSettings()
    traj = Trajectory([Leg(20.0, 1.2)], rig, None, start_speed=1.2, rng=11)
    s = InclinometerSettings()
    imu = simulate_inclinometer(traj, 20.0, s, rng=5)
    dt = np.diff(imu.times)
    assert np.allclose(dt, 1 / 16.0)
    assert 0.0 <= imu.times[0] < 1 / 16.0
    # its own clock: the phase to the camera frames (k / 10 s) varies with the seed
    firsts = [simulate_inclinometer(traj, 1.0, s, rng=k).times[0] for k in range(6)]
    assert all(0.0 <= f < 1 / 16.0 for f in firsts) and len(set(firsts)) == 6
    # quantised to 0.1 degree (roll, pitch)
    q = np.degrees(imu.rpy[:, :2]) / 0.1
    assert np.allclose(q, np.round(q), atol=1e-6)

    def best_lag(meas, shifts):
        errs = [np.mean((meas - traj.states(imu.times - d)[1][:, 1]) ** 2) for d in shifts]
        return shifts[int(np.argmin(errs))], min(errs)

    shifts = np.arange(0.0, 0.2, 0.002)
    lag, err = best_lag(imu.rpy[:, 1], shifts)
    omega = 2 * np.pi * traj.step_freq
    expect = math.atan(omega * s.lag) / omega          # first-order phase lag at f_step
    assert lag == pytest.approx(expect, abs=0.012)
    assert lag > 0.03
    # without the low-pass there is no lag, and the noise is as stated
    imu0 = simulate_inclinometer(traj, 20.0, dataclasses.replace(s, lag=0.0), rng=5)
    lag0, _ = best_lag(imu0.rpy[:, 1], shifts)
    assert lag0 < 0.006
    resid = np.degrees(imu0.rpy[:, :2] - imu0.rpy_true[:, :2])
    assert resid.std() == pytest.approx(math.sqrt(0.3 ** 2 + 0.1 ** 2 / 12), rel=0.15)
    assert imu.variance == pytest.approx(np.radians(0.3) ** 2 + np.radians(0.1) ** 2 / 12)


# --------------------------------------------------------------------------- determinism


def test_same_seed_same_images():
    sc1 = make_scenario('walk_obstacles', seed=2, duration=3.0)
    sc2 = make_scenario('walk_obstacles', seed=2, duration=3.0)
    sc3 = make_scenario('walk_obstacles', seed=3, duration=3.0)
    a, b, c = (simulate_frame(s, 25) for s in (sc1, sc2, sc3))
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert np.array_equal(a.labels, b.labels)
    assert not np.array_equal(a.left, c.left)
    # threads do not change the result
    e = simulate_frame(sc1, 25, StereoRenderer(sc1.rig, threads=1))
    assert np.array_equal(a.left, e.left) and np.array_equal(a.depth, e.depth)
    # camera noise differs between frames and cameras
    d = simulate_frame(sc1, 26)
    assert not np.array_equal(a.left, d.left)
    # right = gain * left + offset (brighter on average)
    assert 1.02 < (a.right.mean() - 4.0) / a.left.mean() < 1.08


def test_a_plain_face_shows_no_edges_but_its_outline():
    """``texture=0``: a face of one grey (a plain painted wall); 1 is the usual texture."""
    from asmonc_vision.sim.world import wall
    sc = make_scenario('plain_wall', seed=0)
    f = simulate_frame(sc, sc.n_frames - 1)          # stopped ~1.5 m before the wall
    obs = [o for o in f.obstacles if o.kind == 'wall']
    assert len(obs) == 1 and 1.0 < obs[0].range < 2.0

    def texture(img):
        # the wall covers the top rows: the spread of their column means (vertical
        # structure; the camera's pixel noise averages out), less a linear shading
        c = img.astype(float)[5:40, 10:-10].mean(axis=0)
        x = np.arange(len(c))
        return float(np.std(c - np.polyval(np.polyfit(x, c, 1), x)))

    (w,) = sc.world.obstacles
    assert w.texture == 0.0
    textured = dataclasses.replace(
        sc, world=World(sc.world.ground, [dataclasses.replace(w, texture=1.0, id=0)],
                        seed=sc.seed))
    plain, usual = texture(f.left), texture(simulate_frame(textured, sc.n_frames - 1).left)
    assert plain < 2.0 and usual > 3.0 * plain, (plain, usual)
    with pytest.raises(ValueError, match='texture'):
        wall(0.0, -1.0, 0.0, 1.0, texture=1.5)


@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_every_scenario_builds_and_renders(name):
    rig = RigSettings(width=160, height=120, focal=150.0)
    sc = make_scenario(name, seed=1, rig=rig)
    assert isinstance(sc, Scenario) and sc.n_frames == int(round(sc.duration * 10))
    f = simulate_frame(sc, sc.n_frames // 2)
    assert f.left.shape == (120, 160) and f.left.dtype == np.uint8
    assert 40 < f.left.mean() < 220
    assert f.left.std() > 8.0


# --------------------------------------------------------------------------- bag


def _small_scenario(tmp_seed: int = 0) -> Scenario:
    rig = RigSettings()
    world = World(Ground(), [Box(x=3.0, y=0.2, length=0.3, width=0.3, height=0.15),
                             bollard(4.0, -0.8)], seed=tmp_seed)
    traj = Trajectory([Leg(0.6, 1.2)], rig, world, start_speed=1.2, rng=tmp_seed)
    return Scenario('test', 'test scenario', tmp_seed, 0.6, rig, world, traj)


@pytest.mark.slow
def test_bag_roundtrip(tmp_path):
    from rosbags.rosbag2 import Reader

    from asmonc_vision.sim.bagwriter import EPOCH_NS, FRAME_TOPICS, write_bag

    sc = _small_scenario()
    out = tmp_path / 'bag'
    summary = write_bag(sc, out)
    assert summary.frames == 6 and summary.size_bytes > 0
    ts = bagio.typestore()
    names = {k: bagio.TOPICS[k][0] for k in FRAME_TOPICS + ('imu',)}
    meta = (out / 'metadata.yaml').read_text()
    assert 'storage_identifier: mcap' in meta
    assert '"scenario": "test"' in meta and '"seed": 0' in meta
    try:   # chunk compression, checked with the independent mcap reader if present
        from mcap.reader import make_reader
        with open(next(out.glob('*.mcap')), 'rb') as fh:
            chunks = make_reader(fh).get_summary().chunk_indexes
        assert chunks and all(c.compression == 'zstd' for c in chunks)
    except ImportError:
        assert b'zstd' in next(out.glob('*.mcap')).read_bytes()
    with Reader(out) as reader:
        topics = {c.topic: c for c in reader.connections}
        assert set(topics) == set(names.values())
        for k, name in names.items():
            assert topics[name].msgtype == bagio.TOPICS[k][1]
        counts = {c.topic: c.msgcount for c in reader.connections}
        for k in FRAME_TOPICS:
            assert counts[names[k]] == 6
        assert counts[names['imu']] in (9, 10)
        order, stamps = [], {}
        for conn, t, raw in reader.messages():
            msg = ts.deserialize_cdr(raw, conn.msgtype)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert stamp == t                      # bag time = header stamp
            assert t >= EPOCH_NS
            order.append((conn.topic, t))
            stamps.setdefault(conn.topic, []).append(t)
            if conn.topic == names['imu']:
                assert msg.header.frame_id == 'inclinometer_link'
                assert msg.angular_velocity_covariance[0] == -1.0
                assert msg.linear_acceleration_covariance[0] == -1.0
                cov = np.asarray(msg.orientation_covariance).reshape(3, 3)
                assert np.all(np.diag(cov) > 0) and cov[0, 1] == 0
                q = msg.orientation
                assert math.isclose(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2, 1.0,
                                    rel_tol=1e-9)
            elif conn.topic == names['gt_ground_plane']:
                assert msg.status == 1 and msg.num_features == 0
                assert msg.header.frame_id == LEFT_FRAME
                plane = MetricPlane(np.array([msg.normal.x, msg.normal.y, msg.normal.z]),
                                    msg.height)
                abc = plane_from_metric(sc.rig.camera(), plane)
                assert np.allclose(abc, [msg.a, msg.b, msg.c])
                assert 1.15 < msg.height < 1.35
            elif conn.topic == names['gt_obstacles']:
                assert msg.header.frame_id == LEFT_FRAME
                assert sorted(o.id for o in msg.obstacles) == [1, 2]
                assert all(o.roi.width > 0 and o.confidence == 1.0 for o in msg.obstacles)
            elif conn.topic == names['right_info']:
                assert msg.p[3] == pytest.approx(-300.0 * 0.35)
                assert msg.header.frame_id == RIGHT_FRAME
            elif conn.topic in (names['left_image'], names['right_image']):
                assert msg.encoding == 'mono8' and msg.step == msg.width == 320
                img = bagio.image_to_gray(msg.encoding, msg.height, msg.width, msg.step,
                                          msg.data)
                assert img.shape == (240, 320)
            elif conn.topic == names['gt_camera_pose']:
                assert msg.header.frame_id == 'world'
    # image stamps pair exactly, on the 10 Hz grid from the epoch
    left, right = stamps[names['left_image']], stamps[names['right_image']]
    assert left == right
    assert np.allclose(np.diff(left), 1e8)
    assert left[0] == EPOCH_NS
    # per frame, in order: infos, images, ground truth
    frame_topics = [tp for tp, _ in order if tp != names['imu']]
    assert frame_topics[:7] == [names[k] for k in FRAME_TOPICS]
    # imu interleaved by time
    times = [t for _, t in order]
    assert times == sorted(times)
    # the ground truth matches the simulation
    f = simulate_frame(sc, 0)
    assert f.obstacles[0].id == 1


def test_cli(tmp_path, capsys):
    from asmonc_vision.sim.cli import main

    assert main(['--list']) == 0
    assert 'walk_stop_turn' in capsys.readouterr().out
    assert main(['no_such_scenario', str(tmp_path / 'x')]) == 2
    assert 'unknown scenario' in capsys.readouterr().err
    busy = tmp_path / 'busy'
    busy.mkdir()
    (busy / 'keep.txt').write_text('x')
    assert main(['clear_static', str(busy)]) == 2
    assert main(['clear_static', str(busy), '--force']) == 2   # not a bag: refused
    assert (busy / 'keep.txt').exists()
    out = tmp_path / 'bag'
    assert main(['clear_static', str(out), '--duration', '0.2', '--width', '160',
                 '--height', '120', '--focal', '150', '--quiet']) == 0
    text = capsys.readouterr().out
    assert '2 stereo frames 160x120' in text
    assert main(['clear_static', str(out), '--duration', '0.1', '--quiet']) == 2
    assert main(['clear_static', str(out), '--duration', '0.1', '--quiet', '--force']) == 0
    # Other rig settings; wrong names, types and ranges are usage errors.
    capsys.readouterr()
    for bad, words in ((['--rig', 'baseline'], 'FIELD=VALUE'),
                       (['--rig', 'no_such=1'], "unknown rig setting 'no_such'"),
                       (['--rig', 'baseline=wide'], 'expected a float'),
                       (['--rig', 'baseline=9'], 'baseline')):
        assert main(['clear_static', str(tmp_path / 'bad'), '--quiet', *bad]) == 2
        assert words in capsys.readouterr().err
    assert not (tmp_path / 'bad').exists()
    rigged = tmp_path / 'rigged'
    assert main(['clear_static', str(rigged), '--duration', '0.1', '--quiet', '--width', '160',
                 '--height', '120', '--rig', 'baseline=0.2', '--rig', 'camera_height=1.0']) == 0
    from asmonc_vision.io.bagio import read_messages
    _, _, info = next(read_messages(rigged, ['/stereo/right/camera_info']))
    assert info.p[3] == pytest.approx(-info.p[0] * 0.2)     # Tx = -f B
    # Another walker: the paper's extreme motion, then a change of it; recorded in the
    # bag's metadata. Wrong gait settings are usage errors too.
    for bad, words in ((['--gait', 'wild'], 'FIELD=VALUE'),
                       (['--gait', 'no_such=1'], "unknown gait setting 'no_such'"),
                       (['--gait', 'pitch_amp_deg=99'], 'pitch_amp_deg')):
        assert main(['clear_static', str(tmp_path / 'bad'), '--quiet', *bad]) == 2
        assert words in capsys.readouterr().err
    walker = tmp_path / 'walker'
    assert main(['clear_walk', str(walker), '--duration', '0.1', '--quiet', '--width', '160',
                 '--height', '120', '--gait', 'extreme', '--gait', 'bob_amp=0.08']) == 0
    import yaml
    info = yaml.safe_load((walker / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    meta = json.loads(info['custom_data']['asmonc_vision.sim'])
    assert meta['gait']['pitch_amp_deg'] == 5.0 and meta['gait']['bob_amp'] == 0.08


@pytest.mark.slow
def test_render_speed_report(capsys):
    """Reports the render time (not asserted: machines differ)."""
    sc = make_scenario('walk_obstacles', seed=0, duration=4.0)
    r = StereoRenderer(sc.rig)
    simulate_frame(sc, 20, r)
    times = []
    for k in range(21, 25):
        t0 = time.perf_counter()
        simulate_frame(sc, k, r)
        times.append(time.perf_counter() - t0)
    left, _ = camera_poses(sc.trajectory.pose(2.0), sc.rig.baseline)
    t0 = time.perf_counter()
    for _ in range(3):
        r.radiance(sc.world, 2.0, left)
    per_image = (time.perf_counter() - t0) / 3
    with capsys.disabled():
        print(f'\n[sim] {sc.rig.width}x{sc.rig.height} ss{sc.rig.supersample}: '
              f'{per_image * 1e3:.0f} ms per image (radiance), '
              f'{min(times) * 1e3:.0f} ms per stereo frame with ground truth')
