"""The ground surface carried through the camera's motion (core/surface_tracking.py).

Synthetic ground features (test_ground_surface's rig: 320x240, f 300, B 0.35 m, 1.25 m
high, pitched 20 degrees down) of a ramp ahead, seen from two places 0.5 m apart along
the ground: the second pair's features end before the ramp's top (too few of them
farther), and the carried profile must know the top there; a step the second pair sees
must not be overruled; a knot's standard deviation must match its scatter over seeds.
"""
from dataclasses import replace

import numpy as np
import pytest

from asmonc_vision.core.camera import ground_axes
from asmonc_vision.core.ground_surface import (GroundSurfaceConfig, depth_noise,
                                               fit_ground_surface, flattened, knot_sd)
from asmonc_vision.core.surface_tracking import SurfaceTracker, SurfaceTrackingConfig

from test_ground_surface import CAM, PLANE, ground_points



def RAMP(s):
    """A ramp 12 cm high over 1.5 m from 3 m ahead (m above the plane at s m)."""
    return 0.08 * np.clip(np.asarray(s) - 3.0, 0.0, 1.5)


def _moved(points, ds):
    """Points (N, 3) of the first pair's frame seen from a camera moved ds metres
    forward along the ground; the motion (R, t) with X_prev = R X_curr + t."""
    _, fwd, _ = ground_axes(PLANE)
    t = ds * fwd
    return points - t[None, :], (np.eye(3), t)


def _fit(points, sigma_d=0.15, flatten=False):
    d = CAM.project(points)[2]
    return fit_ground_surface(points, PLANE, GroundSurfaceConfig(),
                              depth_noise(CAM, d, np.full(d.size, sigma_d)), flatten=flatten)


def _cut(points, s_max):
    """The points nearer than s_max along the ground (a pair that sees no farther)."""
    origin, fwd, _ = ground_axes(PLANE)
    return points[(points - origin) @ fwd < s_max]


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_carried_profile_knows_the_ground_the_pair_cannot_see(seed):
    rng = np.random.default_rng(seed)
    first = ground_points(RAMP, rng, s_max=8.0)
    tracker = SurfaceTracker()
    s1 = tracker.update(_fit(first), None, 0.05)
    assert s1.known_until_m >= 7.0, s1.checks
    # 0.5 m on: this pair's features reach 3.8 m (the ramp's top is at 4 m, the pair
    # knows the ground to 4 m at most)
    second_world = ground_points(RAMP, rng, s_max=8.0)
    second, motion = _moved(_cut(second_world, 4.3), 0.5)
    alone = _fit(second)
    assert alone.known_until_m <= 4.0 and alone.checks[-1].refused_by == 'rule_support'
    fused = tracker.update(alone, motion, 0.05)
    assert fused.known_until_m >= 6.0
    # the level ground beyond the ramp's top (12 cm up from 4 m on in the new pair's
    # frame) is ground
    s = np.array([5.0, 6.0])
    assert np.max(np.abs(fused.profile(s) - RAMP(s + 0.5))) < 0.03
    # the pair alone would take the ground beyond as level or at the ramp's grade: off
    assert np.max(np.abs(alone.profile(s) - RAMP(s + 0.5))) > 0.03


def test_the_carried_profile_is_relevelled_to_a_plane_that_tilted():
    """The pair's plane tilted by 0.5 degrees from the last (its heights 3.5 cm more at
    4 m from the first knot): the carried knots beyond its known ground are read with
    that tilt, not as they were."""
    rng = np.random.default_rng(11)
    tracker = SurfaceTracker()
    first = _fit(ground_points(RAMP, rng, s_max=8.0))
    tracker.update(first, None, 0.05)
    tilt = np.tan(np.radians(0.5))
    second = _fit(_cut(ground_points(RAMP, rng, s_max=8.0), 4.3))
    assert second.checks[-1].refused_by == 'rule_support'
    s0 = second.knots_s[0]
    known = second.knots_s <= second.known_until_m
    lifted = replace(second, knots_z=np.where(known, second.knots_z
                                              + tilt * (second.knots_s - s0), 0.0))
    fused = tracker.update(lifted, (np.eye(3), np.zeros(3)), 0.05)
    s = np.array([5.5, 6.5])
    want = RAMP(s) + tilt * (s - s0)
    assert fused.known_until_m >= 6.5
    assert np.max(np.abs(fused.profile(s) - want)) < 0.015
    # a carried knot is less sure the farther it lies from what both saw
    far = fused.knots_s > second.known_until_m + 0.1
    sd = fused.knots_sd[far & (fused.knots_s <= fused.known_until_m)]
    assert np.all(np.diff(sd) > 0)


def test_a_step_the_pair_sees_is_not_overruled():
    rng = np.random.default_rng(4)
    tracker = SurfaceTracker()
    tracker.update(_fit(ground_points(lambda s: 0.0 * s, rng, s_max=8.0)), None, 0.05)
    # a 12 cm kerb up 3.5 m ahead appears (it was not there: the carried ground is flat)
    def kerb(s):
        return np.where(np.asarray(s) >= 3.5, 0.12, 0.0)

    second, motion = _moved(ground_points(kerb, rng, s_max=8.0), 0.0)
    alone = _fit(second)
    assert alone.checks[-1].refused_by in ('rule_step', 'rule_grade'), alone.checks
    fused = tracker.update(alone, motion, 0.05)
    assert fused.known_until_m == alone.known_until_m
    assert fused.profile(np.array([4.5]))[0] == pytest.approx(
        flattened(alone, 0.05).profile(np.array([4.5]))[0])


def test_fusion_tightens_and_an_outlying_knot_replaces_the_carried():
    rng = np.random.default_rng(7)
    tracker = SurfaceTracker()
    a = _fit(ground_points(RAMP, rng, s_max=8.0))
    tracker.update(a, None, 0.05)
    b = _fit(ground_points(RAMP, rng, s_max=8.0))
    fused = tracker.update(b, (np.eye(3), np.zeros(3)), 0.05)
    both = (np.isfinite(b.knots_sd) & (b.knots_sd > 0)
            & (b.knots_s <= a.known_until_m) & (b.knots_s >= a.knots_s[0]))
    assert both.sum() >= 4, (a.knots_sd, b.knots_sd)
    assert np.all(fused.knots_sd[both] < b.knots_sd[both]), (fused.knots_sd, b.knots_sd)
    # one knot 10 cm off what was carried (the ground is not what it was seen to be)
    c = _fit(ground_points(RAMP, rng, s_max=8.0))
    z = c.knots_z.copy()
    k = int(np.argmin(np.abs(c.knots_s - 5.0)))
    assert c.knots_s[k] <= c.known_until_m
    z[k] += 0.1
    fused2 = tracker.update(replace(c, knots_z=z), (np.eye(3), np.zeros(3)), 0.05)
    assert fused2.knots_z[k] == pytest.approx(z[k])


def test_no_motion_restarts_from_the_pair():
    rng = np.random.default_rng(3)
    tracker = SurfaceTracker()
    tracker.update(_fit(ground_points(RAMP, rng, s_max=8.0)), None, 0.05)
    b = _fit(_cut(ground_points(RAMP, rng, s_max=8.0), 4.3))
    fused = tracker.update(b, None, 0.05)
    assert fused.known_until_m == b.known_until_m
    np.testing.assert_allclose(fused.knots_z, b.knots_z)


def test_knot_sd_matches_the_scatter_of_the_knots():
    """Over 40 seeds of flat ground, each known knot's spread against its mean stated
    standard deviation: within a factor of 2 (the robust spread and the ignored prior
    make it an estimate, not an exact bound)."""
    heights, sds = [], []
    for seed in range(40):
        surf = _fit(ground_points(lambda s: 0.0 * s, np.random.default_rng(100 + seed),
                                  s_max=7.0))
        if surf.known_until_m < 6.0:
            continue
        at = np.array([3.5, 4.5, 5.5])           # the knots' heights and sds there
        heights.append(surf.profile(at))
        sds.append(np.interp(at, surf.knots_s, surf.knots_sd))
    assert len(heights) >= 30
    scatter = np.array(heights).std(axis=0)
    stated = np.array(sds).mean(axis=0)
    assert np.all(scatter < 2.0 * stated) and np.all(scatter > 0.5 * stated), (scatter, stated)


def test_knot_sd_is_nan_where_a_segment_has_no_features():
    s = np.array([2.2, 2.5, 2.8])
    h = np.zeros(3)
    from asmonc_vision.core.ground_surface import SegmentCheck
    checks = [SegmentCheck('', 3, 1.0, 0.0, 0.0, 0.01), SegmentCheck('', 0, 1.0, 0.0, 0.0, 0.01)]
    out = knot_sd(s, h, np.array([2.0, 3.0, 4.0]), np.zeros(3), checks, GroundSurfaceConfig())
    assert out[0] == 0.0 and np.isfinite(out[1]) and np.isnan(out[2])


def test_settings_are_validated():
    with pytest.raises(ValueError, match='gate_sigmas'):
        SurfaceTrackingConfig(gate_sigmas=0.0)
