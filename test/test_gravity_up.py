"""The inclinometer's up direction in the left optical frame (core.rotations) and the
ground-plane fit's orientation prior built on it (core.ground_plane)."""
import math

import numpy as np
import pytest

from asmonc_vision.core.camera import MetricPlane, StereoCamera, plane_from_metric
from asmonc_vision.core.ground_plane import fit_ground_plane
from asmonc_vision.core.rotations import (R_BODY_OPTICAL, gravity_up_optical,
                                          rpy_to_matrix, rpy_to_quaternion, up_for_pair)


def test_level_rig_is_up_along_minus_y():
    up = gravity_up_optical([0.0, 0.0, 0.0, 1.0])
    assert np.allclose(up, [0.0, -1.0, 0.0])


@pytest.mark.parametrize('pitch_deg', [-10.0, 5.0, 20.0])
def test_pitch_down_leans_up_against_the_optical_axis(pitch_deg):
    p = math.radians(pitch_deg)              # REP 103 pitch, positive = nose down
    up = gravity_up_optical(rpy_to_quaternion([0.0, p, 0.0]))
    assert np.allclose(up, [0.0, -math.cos(p), -math.sin(p)])


def test_roll_right_down_tilts_up_to_the_left_in_the_image():
    r = math.radians(8.0)                    # REP 103 roll, positive = right side down
    up = gravity_up_optical(rpy_to_quaternion([r, 0.0, 0.0]))
    # right down: up leans towards the image's left (optical -x)
    assert np.allclose(up, [-math.sin(r), -math.cos(r), 0.0])


@pytest.mark.parametrize('seed', range(5))
def test_matches_the_rotation_matrix_and_ignores_yaw(seed):
    rng = np.random.default_rng(seed)
    rpy = rng.uniform([-0.3, -0.5, -3.0], [0.3, 0.5, 3.0])
    up = gravity_up_optical(rpy_to_quaternion(rpy))
    # optical vectors -> world: R_world_body R_BODY_OPTICAL; world up taken back
    expected = (rpy_to_matrix(rpy) @ R_BODY_OPTICAL).T @ np.array([0.0, 0.0, 1.0])
    assert np.allclose(up, expected)
    assert np.isclose(np.linalg.norm(up), 1.0)
    rpy2 = rpy.copy()
    rpy2[2] += 1.0
    assert np.allclose(gravity_up_optical(rpy_to_quaternion(rpy2)), up)


def test_up_for_pair_only_within_the_age():
    q = np.array([0.0, 0.0, 0.0, 2.0])       # any norm
    assert np.allclose(up_for_pair((1_000_000_000, q), 1_200_000_000, 0.25), [0, -1, 0])
    assert np.allclose(up_for_pair((1_300_000_000, q), 1_200_000_000, 0.25), [0, -1, 0])
    assert up_for_pair((1_000_000_000, q), 1_300_000_000, 0.25) is None
    assert up_for_pair(None, 1_300_000_000, 0.25) is None
    assert up_for_pair((1_000_000_000, np.zeros(4)), 1_000_000_000, 0.25) is None


# -- the prior in the ground-plane fit ---------------------------------------------------

#: the chest rig: 640x480, f = 560 px, B = 0.12 m
CHEST = StereoCamera(f=560.0, cx=319.5, cy=239.5, baseline=0.12, width=640, height=480)


def _up(pitch_deg):
    t = math.radians(pitch_deg)
    return np.array([0.0, -math.cos(t), -math.sin(t)])


def _scarce_scene(seed, pitch_deg=2.0, height=1.335):
    """A plain pavement: 300 noisy ground features in the bottom 50 rows, and the long
    vertical edge strings of 6 obstacles standing on it (one feature per row): the
    ground's tilt is nearly free, and a plane tilted towards the strings (flatter in
    the rows) takes more of them."""
    rng = np.random.default_rng(seed)
    plane = MetricPlane(normal_up=_up(pitch_deg), height=height)
    abc = plane_from_metric(CHEST, plane)
    u = [rng.uniform(0, 639, 300)]
    v = [rng.uniform(430, 479, 300)]
    d = [abc[0] * u[0] + abc[1] * v[0] + abc[2] + rng.normal(0, 0.4, 300)]
    for _ in range(6):
        uc, foot = rng.uniform(40, 600), rng.uniform(300, 420)
        rows = np.arange(foot - rng.uniform(60, 150), foot)
        u.append(uc + rng.normal(0, 0.5, rows.size))
        v.append(rows)
        d.append(abc[0] * uc + abc[1] * foot + abc[2] + rng.normal(0, 0.25, rows.size))
    return plane, np.concatenate(u), np.concatenate(v), np.concatenate(d)


def _fit(u, v, d, seed, up=None, cost=0.02):
    return fit_ground_plane(u, v, d, cam=CHEST, weights=d ** 3, min_features=30,
                            min_spread_px=3.0, up_prior=up, prior_scale_deg=3.0,
                            prior_cost=cost, rng=seed)


def _errors(fit, plane):
    if fit is None:
        return math.inf, math.inf
    cos = float(np.clip(fit.metric.normal_up @ plane.normal_up, -1.0, 1.0))
    return abs(fit.metric.height - plane.height), math.degrees(math.acos(cos))


def test_the_prior_holds_the_plane_where_ground_features_are_scarce():
    """Without the prior half the fits tilt towards the obstacles' edges (the camera 20-60
    cm too high); with an up direction 1.5 degrees off (the inclinometer's lag in the
    gait's sway) every fit is within 3 degrees and 0.16 m, and on average less than half
    as far off."""
    without, with_prior = [], []
    for seed in range(8):
        plane, u, v, d = _scarce_scene(seed)
        without.append(_errors(_fit(u, v, d, seed), plane))
        with_prior.append(_errors(_fit(u, v, d, seed, up=_up(2.0 + 1.5)), plane))
    h0, h1 = np.array(without)[:, 0], np.array(with_prior)[:, 0]
    assert np.sum(h0 > 0.2) >= 4
    assert np.all(h1 < 0.16) and np.all(np.array(with_prior)[:, 1] < 3.0)
    assert h1.mean() < 0.6 * h0.mean()


def test_ground_features_outweigh_the_prior_on_a_slope():
    """Well-spread ground features on a 7 degree slope: the fit with a level up
    direction finds the slope (the prior does not flatten it)."""
    rng = np.random.default_rng(3)
    plane = MetricPlane(normal_up=_up(2.0 + 7.0), height=1.3)
    abc = plane_from_metric(CHEST, plane)
    u, v = rng.uniform(0, 639, 800), rng.uniform(260, 479, 800)
    d = abc[0] * u + abc[1] * v + abc[2] + rng.normal(0, 0.3, 800)
    h, a = _errors(_fit(u, v, d, 0, up=_up(2.0)), plane)
    assert h < 0.02 and a < 0.5


def test_no_prior_without_a_camera_or_a_cost():
    plane, u, v, d = _scarce_scene(1)
    base = _fit(u, v, d, 1)
    for fit in (_fit(u, v, d, 1, up=_up(2.0), cost=0.0),
                _fit(u, v, d, 1, up=np.zeros(3))):
        assert np.array_equal(fit.abc, base.abc)

