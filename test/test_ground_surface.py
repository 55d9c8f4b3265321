"""The ground surface ahead (core/ground_surface.py) on synthetic ground features.

Features are points of a ground whose height above the near plane is a known profile of
the distance ahead (a slope that starts 3 m ahead, a crest, a ramp), triangulated as a
stereo rig sees them (the disparity rounded with noise), plus boxes and kerbs that must
stay obstacles: the profile must not bend into a 10 cm step.
"""
import numpy as np
import pytest

from asmonc_vision.core import ground_surface as gs
from asmonc_vision.core import surface_steps
from asmonc_vision.core.camera import MetricPlane, StereoCamera, ground_axes
from asmonc_vision.core.ground_surface import (GroundSurface, GroundSurfaceConfig,
                                               depth_noise, fit_ground_surface)

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)
PITCH = np.radians(20.0)
H = 1.25
# the plane 1.25 m below the camera pitched 20 degrees down: normal (up) in the optical frame
PLANE = MetricPlane(normal_up=np.array([0.0, -np.cos(PITCH), -np.sin(PITCH)]), height=H)


def ground_points(profile, rng, n=4000, s_max=9.0, half_width=2.0, sigma_d=0.15):
    """(N, 3) points of the ground z = profile(s) above PLANE, seen through CAM with
    disparity noise sigma_d px (the points outside the image dropped)."""
    origin, fwd, left = ground_axes(PLANE)
    s = rng.uniform(1.5, s_max, n)
    lat = rng.uniform(-half_width, half_width, n)
    p = origin + s[:, None] * fwd + lat[:, None] * left + profile(s)[:, None] * PLANE.normal_up
    return _through_camera(p, rng, sigma_d)


def _through_camera(p, rng, sigma_d):
    u, v, d = CAM.project(p)
    ok = (u >= 0) & (u < CAM.width) & (v >= 0) & (v < CAM.height) & (d > 0)
    d = d[ok] + rng.normal(0.0, sigma_d, ok.sum())
    return CAM.triangulate(u[ok], v[ok], d)


def box_points(s_foot, lateral, height, width, rng, n=150, sigma_d=0.15, base=None):
    """Points of the front face of a box standing on the ground at s_foot (m)."""
    origin, fwd, left = ground_axes(PLANE)
    z0 = 0.0 if base is None else base
    lat = lateral + rng.uniform(-width / 2, width / 2, n)
    up = z0 + rng.uniform(0.0, height, n)
    p = origin + s_foot * fwd + lat[:, None] * left + up[:, None] * PLANE.normal_up
    return _through_camera(p, rng, sigma_d)


def slope_from(start, deg):
    g = np.tan(np.radians(deg))
    return lambda s: g * np.maximum(np.asarray(s) - start, 0.0)


def step_at(at, rise):
    return lambda s: np.where(np.asarray(s) >= at, rise, 0.0)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_slope_starting_ahead_becomes_ground(seed):
    rng = np.random.default_rng(seed)
    prof = slope_from(3.0, 5.0)
    pts = ground_points(prof, rng)
    surf = fit_ground_surface(pts, PLANE)
    assert surf.known_until_m >= 8.0, surf.checks
    s = np.linspace(2.0, 8.0, 13)
    assert np.max(np.abs(surf.profile(s) - prof(s))) < 0.05
    # the ground points stand less than 5 cm above it; above the plane by up to 44 cm
    s_pts, _, h_plane = surf.coordinates(pts)
    inside = s_pts <= 8.0
    assert np.percentile(np.abs(surf.height_above(pts[inside])), 99) < 0.08
    assert h_plane[inside].max() > 0.35


@pytest.mark.parametrize('profile', [
    slope_from(2.5, -5.0),                                   # a slope down starting ahead
    lambda s: 0.08 * np.clip(np.asarray(s) - 3.0, 0, 1.5),  # a kerb ramp (8 %) to 12 cm
    lambda s: slope_from(2.0, 3.0)(s) - slope_from(5.0, 6.0)(s),   # a crest at 5 m
])
def test_ramps_and_crests_are_ground(profile):
    rng = np.random.default_rng(5)
    pts = ground_points(profile, rng)
    surf = fit_ground_surface(pts, PLANE)
    assert surf.known_until_m >= 7.0, surf.checks
    s = np.linspace(2.0, surf.known_until_m, 11)
    assert np.max(np.abs(surf.profile(s) - profile(s))) < 0.05


def test_flat_ground_keeps_the_plane():
    rng = np.random.default_rng(3)
    surf = fit_ground_surface(ground_points(lambda s: 0.0 * s, rng), PLANE)
    assert surf.known_until_m >= 8.0
    assert np.max(np.abs(surf.knots_z)) < 0.02


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('at', [3.0, 3.5, 4.2])
@pytest.mark.parametrize('rise', [0.10, -0.10])
def test_a_step_of_10cm_is_not_a_slope(seed, at, rise):
    """A kerb up (or a drop) of 10 cm across the path: the profile does not bend into
    it; the ground beyond it is unknown, and the step stays 10 cm above (below) what the
    surface says."""
    rng = np.random.default_rng(seed)
    pts = ground_points(step_at(at, rise), rng)
    surf = fit_ground_surface(pts, PLANE)
    assert surf.known_until_m <= at + 1e-9, surf.checks
    assert np.max(np.abs(surf.profile(np.linspace(0, 9, 50)))) < 0.03
    beyond = surf.coordinates(pts)[0] > at + 0.2
    assert np.median(surf.height_above(pts[beyond])) == pytest.approx(rise, abs=0.03)


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('height', [0.05, 0.10])
@pytest.mark.parametrize('at', [2.5, 4.0])
def test_boxes_stay_obstacles(seed, height, at):
    """A box of 5-10 cm at 2-5 m on flat ground: the surface stays the plane under it."""
    rng = np.random.default_rng(seed)
    pts = np.vstack([ground_points(lambda s: 0.0 * s, rng),
                     box_points(at, 0.2, height, 0.3, rng)])
    surf = fit_ground_surface(pts, PLANE)
    assert abs(float(surf.profile(np.array([at]))[0])) < 0.02
    top = box_points(at, 0.2, 0.0, 0.3, rng, base=height)
    assert np.median(surf.height_above(top)) == pytest.approx(height, abs=0.02)


def test_box_on_a_slope_stays_an_obstacle():
    rng = np.random.default_rng(11)
    prof = slope_from(3.0, 5.0)
    origin, fwd, left = ground_axes(PLANE)
    pts = np.vstack([ground_points(prof, rng),
                     box_points(5.0, 0.0, 0.10, 0.3, rng, base=float(prof(5.0)))])
    surf = fit_ground_surface(pts, PLANE)
    top = box_points(5.0, 0.0, 0.0, 0.3, rng, base=float(prof(5.0)) + 0.10)
    assert np.median(surf.height_above(top)) == pytest.approx(0.10, abs=0.03)


def test_no_ground_ahead_is_unknown():
    rng = np.random.default_rng(4)
    near = ground_points(lambda s: 0.0 * s, rng, s_max=2.2)
    surf = fit_ground_surface(near, PLANE)
    assert surf.known_until_m == pytest.approx(2.0)
    assert surf.checks[0].refused_by == 'rule_support'
    empty = fit_ground_surface(np.zeros((0, 3)), PLANE)
    assert empty.known_until_m == pytest.approx(2.0) and not empty.bends


def test_surface_disparity_matches_the_ground():
    """The surface's disparity at a ground point's pixel is the point's disparity."""
    rng = np.random.default_rng(8)
    prof = slope_from(3.0, 5.0)
    surf = GroundSurface(PLANE, np.arange(2.0, 9.0), prof(np.arange(2.0, 9.0)), 8.0)
    pts = ground_points(prof, rng, s_max=8.0, sigma_d=0.0)
    u_c, v, d = CAM.project(pts)                  # cyclopean pixels
    assert np.allclose(surf.disparity(CAM, u_c, v), d, atol=1e-6)
    flat = GroundSurface.flat(PLANE, 2.0)
    from asmonc_vision.core.camera import plane_disparity, plane_from_metric
    assert np.allclose(flat.disparity(CAM, u_c, v),
                       plane_disparity(plane_from_metric(CAM, PLANE), u_c, v))


def test_settings_are_checked():
    with pytest.raises(ValueError, match='near_m'):
        GroundSurfaceConfig(near_m=9.0, far_m=8.0)
    with pytest.raises(ValueError, match='knot_spacing_m'):
        GroundSurfaceConfig(knot_spacing_m=0.0)


@pytest.mark.slow
def test_steps_and_slopes_over_many_seeds():
    """10 cm steps up and down at 2.6-6 m (10 seeds) are never bent into; 3-5 degree
    slopes up and down starting 2.5-5 m ahead (10 seeds) are followed within 5 cm."""
    bent = []
    for seed in range(10):
        for at in (2.6, 3.0, 3.3, 3.5, 3.8, 4.2, 5.0, 6.0):
            for rise in (0.1, -0.1):
                pts = ground_points(step_at(at, rise), np.random.default_rng(100 + seed))
                surf = fit_ground_surface(pts, PLANE)
                beyond = surf.coordinates(pts)[0] > at + 0.2
                if (np.max(np.abs(surf.profile(np.linspace(0, 10, 101)))) > 0.03
                        or abs(np.median(surf.height_above(pts[beyond])) - rise) > 0.03):
                    bent.append((seed, at, rise))
    assert not bent
    missed = []
    s = np.linspace(2.5, 8.0, 12)
    for seed in range(10):
        for start in (2.5, 3.0, 4.0, 5.0):
            for deg in (5.0, -5.0, 3.0):
                prof = slope_from(start, deg)
                surf = fit_ground_surface(ground_points(prof, np.random.default_rng(200 + seed)),
                                          PLANE)
                if surf.known_until_m < 8.0 or np.max(np.abs(surf.profile(s) - prof(s))) >= 0.05:
                    missed.append((seed, start, deg))
    assert not missed


def test_a_plane_that_is_off_is_not_bent_for():
    """rule_anchor: the near ground 3 cm below the plane (the plane off, as in a frame of
    a vigorous walk): no profile, the plane alone."""
    rng = np.random.default_rng(6)
    surf = fit_ground_surface(ground_points(lambda s: 0.0 * s - 0.03, rng), PLANE)
    assert surf.checks[0].refused_by == 'rule_anchor' and not surf.bends


# --- the noise at range, sparse far ground, the ground beyond the known -------------

#: the chest rig binned 2 x 2 (the detector's coarse pass): a short baseline, whose
#: ground features at 8-10 m are several cm apart in height from disparity noise alone
SHORT = StereoCamera(f=260.0, cx=159.5, cy=119.5, baseline=0.12, width=320, height=240)


def test_depth_noise_is_the_depth_change_per_disparity():
    """depth_noise is |dz/dd| sigma: the change of the triangulated depth per pixel of
    disparity, times sigma; it grows with the square of the depth."""
    rng = np.random.default_rng(1)
    pts = ground_points(slope_from(3.0, 4.0), rng, n=200, sigma_d=0.0)
    u, v, d = CAM.project(pts)
    sd = depth_noise(CAM, d, 0.25)
    dz = (CAM.triangulate(u, v, d + 1e-4) - CAM.triangulate(u, v, d - 1e-4))[:, 2] / 2e-4
    assert np.allclose(sd, np.abs(dz) * 0.25, rtol=1e-3)
    assert np.allclose(sd, 0.25 * pts[:, 2] ** 2 / CAM.fb)


def _short_rig_points(profile, rng, sigma_d=0.25, n=6000):
    """Ground points seen by SHORT with disparity noise sigma_d px, and their pixels."""
    origin, fwd, left = ground_axes(PLANE)
    s = rng.uniform(1.5, 10.0, n)
    lat = rng.uniform(-2.0, 2.0, n)
    p = origin + s[:, None] * fwd + lat[:, None] * left + profile(s)[:, None] * PLANE.normal_up
    u, v, d = SHORT.project(p)
    ok = (u >= 0) & (u < SHORT.width) & (v >= 0) & (v < SHORT.height) & (d > 0)
    u, v, d = u[ok], v[ok], d[ok] + rng.normal(0.0, sigma_d, ok.sum())
    return SHORT.triangulate(u, v, d), depth_noise(SHORT, d, sigma_d)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_far_ground_of_a_short_baseline_is_known_through_its_noise(seed):
    """A 4 degree rise from 4 m seen on a short baseline: its far segments spread by
    the disparity noise beyond rule_spread's 5 cm; told the features' height noise, the
    surface takes them and follows the rise to 9.5 m within 8 cm."""
    prof = slope_from(4.0, 4.0)
    pts, sd = _short_rig_points(prof, np.random.default_rng(seed))
    blind = fit_ground_surface(pts, PLANE)
    told = fit_ground_surface(pts, PLANE, depth_sd=sd)
    assert blind.known_until_m < 9.5
    assert told.known_until_m >= 9.5, told.checks
    s = np.linspace(2.0, 9.5, 16)
    assert np.max(np.abs(told.profile(s) - prof(s))) < 0.08


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_kerb_on_a_short_baseline_is_still_a_step(seed):
    """The depth noise widens rule_spread only: a 10 cm kerb up at 3.5 m is not bent
    into on the short baseline either (rule_step; a step down there is the limit of
    docs/ground.md)."""
    rise = 0.10
    pts, sd = _short_rig_points(step_at(3.5, rise), np.random.default_rng(10 + seed))
    surf = fit_ground_surface(pts, PLANE, depth_sd=sd)
    assert np.max(np.abs(surf.profile(np.linspace(0, 10, 101)))) < 0.03
    beyond = surf.coordinates(pts)[0] > 3.7
    assert np.median(surf.height_above(pts[beyond])) == pytest.approx(rise, abs=0.03)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_slope_goes_on_beyond_the_known_ground(seed):
    """A 5 degree rise from 3 m seen only to 7 m: beyond the known ground the surface
    goes on at the grade of its last two segments, not level (the rise at 9.5 m is then
    still ground)."""
    prof = slope_from(3.0, 5.0)
    pts = ground_points(prof, np.random.default_rng(seed), s_max=7.0)
    surf = fit_ground_surface(pts, PLANE)
    assert surf.known_until_m <= 7.0
    assert surf.tail_grade == pytest.approx(np.tan(np.radians(5.0)), abs=0.03)
    s = np.array([8.0, 9.0, 9.5])
    assert np.max(np.abs(surf.profile(s) - prof(s))) < 0.10


@pytest.mark.parametrize('seed', [0, 1])
def test_a_dip_is_ground_and_a_sharp_brow_is_not(seed):
    """Ground that bends up by 0.2 (a 6 degree fall into a 6 degree rise, at 4 m) is seen
    whole: ground. Ground that bends down as much may hide a drop beyond its brow: the
    surface stops there (unknown beyond), it does not follow the fall."""
    rng = np.random.default_rng(seed)
    dip = lambda s: 0.2 * np.maximum(np.asarray(s) - 4.0, 0.0)     # noqa: E731
    surf = fit_ground_surface(ground_points(dip, rng), PLANE)
    assert surf.known_until_m >= 7.0, surf.checks
    s = np.linspace(2.0, surf.known_until_m, 11)
    assert np.max(np.abs(surf.profile(s) - dip(s))) < 0.05
    brow = lambda s: -0.2 * np.maximum(np.asarray(s) - 4.0, 0.0)   # noqa: E731
    surf = fit_ground_surface(ground_points(brow, rng), PLANE)
    assert surf.known_until_m <= 5.0, surf.checks
    assert any(c.refused_by == 'rule_grade' and c.grade_change < -0.12 for c in surf.checks)
    # with the old symmetric limit of 0.12 the dip was refused too
    old = GroundSurfaceConfig(max_grade_rise=0.12)
    assert fit_ground_surface(ground_points(dip, rng), PLANE, old).known_until_m <= 5.0


@pytest.mark.parametrize('seed', [0, 3])
@pytest.mark.parametrize('rise', [0.10, 0.15, -0.10])
def test_a_step_at_a_knot_is_a_step(seed, rise):
    """A kerb up (or a drop) just at a knot has its far side all in the next segment: no
    step inside that segment, only a line that does not start where the surface is. It
    is a step there (not a slope that bends up by 0.1-0.15 within max_grade_rise)."""
    rng = np.random.default_rng(seed)
    for at in (3.0, 3.02, 4.0, 5.0, 5.02, 6.0):
        surf = fit_ground_surface(ground_points(step_at(at, rise), rng), PLANE)
        beyond = surf.known_until_m > at + 0.5
        assert not (beyond and abs(surf.profile(np.array([at + 0.5]))[0] - rise)
                    < abs(rise) / 2), (at, surf.checks)


def kerb_ramp(start, length, rise, half):
    """The ground's height (m) at (s, lat) m: a ramp rising ``rise`` over ``length`` from
    ``start`` ahead, |lat| <= ``half``, between kerbs of ``rise`` beside it; level at
    ``rise`` beyond."""
    def height(s, lat):
        ramp = rise * np.clip((np.asarray(s) - start) / length, 0.0, 1.0)
        kerb = np.where(np.asarray(s) >= start, rise, 0.0)
        return np.where(np.abs(lat) > half, kerb, ramp)
    return height


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('start', [2.9, 3.5, 4.3])
def test_a_kerb_ramp_is_ground_and_its_kerbs_are_not(seed, start):
    """A dropped kerb across the path (a 12 cm kerb whose middle 2 m is a 1.5 m ramp):
    the kerb beside the ramp is a step beside the path, not across it, so the surface
    follows the ramp up to the footway and stays known beyond; the kerbs' tops at the
    ramp's foot stay 12 cm above it."""
    rng = np.random.default_rng(seed)
    rise, length, half = 0.12, 1.5, 1.0
    height = kerb_ramp(start, length, rise, half)
    origin, fwd, left = ground_axes(PLANE)
    s = rng.uniform(1.5, 9.0, 4000)
    lat = rng.uniform(-2.0, 2.0, s.size)
    p = origin + s[:, None] * fwd + lat[:, None] * left + height(s, lat)[:, None] * PLANE.normal_up
    surf = fit_ground_surface(_through_camera(p, rng, 0.15), PLANE)
    assert surf.known_until_m >= start + length + 1.0, surf.checks
    ahead = np.linspace(start, start + length + 1.0, 12)
    assert np.max(np.abs(surf.profile(ahead) - height(ahead, 0.0))) < 0.04
    foot = origin + (start + 0.2) * fwd + 1.5 * left + rise * PLANE.normal_up
    assert surf.height_above(foot[None, :])[0] == pytest.approx(rise - 0.2 * rise / length,
                                                                abs=0.04)


def _ramp_between_kerbs(seed, start, across):
    """One segment's features (t m from its start, lat m to the left, h m above the
    plane; 1 cm noise): 140 beside the walking corridor on kerbs 13 cm high from
    ``start`` m on, and 60 in the corridor on a ramp rising 0.1 a metre from there (with
    ``across``: the kerb itself)."""
    rng = np.random.default_rng(seed)
    tc, lc = rng.uniform(0.0, 1.0, 60), rng.uniform(-0.55, 0.55, 60)
    hc = (np.where(tc > start, 0.13, 0.0) if across
          else 0.1 * np.clip(tc - start, 0.0, None))
    tb, lb = rng.uniform(0.0, 1.0, 140), rng.choice([-1.0, 1.0], 140) * rng.uniform(0.65, 1.7, 140)
    hb = np.where(tb > start, 0.13, 0.0)
    h = np.concatenate([hc, hb]) + rng.normal(0.0, 0.01, 200)
    return np.concatenate([tc, tb]), np.concatenate([lc, lb]), h


@pytest.mark.parametrize('start', [0.15, 0.5, 0.85])
def test_a_ramp_between_kerbs_is_a_bend_and_a_kerb_across_is_a_step(start):
    """rule_step's corridor test (`surface_steps.path_step`): most of a segment's features on the
    kerbs beside a kerb ramp step 13 cm, but the corridor's own line-plus-step finds a
    bend there, not a step: no step, in each of 20 seeds (the ramp is ground). With the
    kerb across the corridor too, the step is found in each (a kerb up ahead)."""
    c = gs.GroundSurfaceConfig()
    ray = np.full(200, -0.4)          # a chest rig 1.4 m up, 3.5 m ahead
    args = (ray, 0.0, 0.0, 1.0, c.step_half_width_m, c.max_grade_rise)
    for seed in range(20):
        ramp, _, _ = surface_steps.path_step(*_ramp_between_kerbs(seed, start, False), *args)
        kerb, at, _ = surface_steps.path_step(*_ramp_between_kerbs(seed, start, True), *args)
        assert abs(ramp) <= 0.04 < kerb, (seed, ramp, kerb)
        assert abs(at - start) <= 0.15, (seed, at, start)


def test_the_lowest_ground_does_not_rise_beyond_the_known():
    """A slope seen rising to 7 m goes on rising beyond for the obstacle test; the
    lowest ground it allows (for the drop test) is level there, as where a ramp reaches
    its top; the known part and a falling tail are the surface's own."""
    prof = slope_from(3.0, 5.0)
    surf = fit_ground_surface(ground_points(prof, np.random.default_rng(0), s_max=7.0), PLANE)
    assert surf.tail_grade > 0.05
    low = surf.lowest()
    assert low.tail_grade == 0.0
    known = np.linspace(2.0, surf.known_until_m, 9)
    assert np.allclose(low.profile(known), surf.profile(known))
    beyond = np.array([surf.known_until_m + 1.0, 9.0])
    assert np.allclose(low.profile(beyond), surf.profile(np.array([surf.known_until_m])))
    assert np.all(surf.profile(beyond) > low.profile(beyond) + 0.04)
    down = fit_ground_surface(ground_points(slope_from(3.0, -5.0), np.random.default_rng(0),
                                            s_max=7.0), PLANE)
    assert down.tail_grade < 0.0 and down.lowest() is down


def test_the_fall_limit_counts_from_level_where_the_ground_rose():
    """`fall_limit`: max_grade_fall from the last grade on level ground or unknown level;
    more by the grade the ground rose at; never less on a downhill. `level_grade`: the
    plane's grade against the inclinometer's up."""
    _, fwd, _ = ground_axes(PLANE)
    for grade in (-0.1, 0.0, 0.13):
        t = np.arctan(grade)
        assert gs.level_grade(PLANE, np.cos(t) * PLANE.normal_up + np.sin(t) * fwd) == \
            pytest.approx(grade)
    assert gs.level_grade(PLANE, None) is None
    assert gs.fall_limit(0.0, None, 0.12) == 0.12
    assert gs.fall_limit(0.05, None, 0.12) == 0.12
    assert gs.fall_limit(0.0, 0.0, 0.12) == 0.12
    assert gs.fall_limit(0.0, 0.1, 0.12) == pytest.approx(0.22)
    assert gs.fall_limit(0.05, 0.1, 0.12) == pytest.approx(0.27)
    assert gs.fall_limit(0.0, -0.1, 0.12) == 0.12


def _rounded_brow(start, g0, g1, centre, width):
    """The profile level to ``start``, then of grade g0 bending evenly to g1 over
    ``width`` m about ``centre`` (m along the ground): a rounded crest."""
    xs = np.linspace(0.0, 20.0, 4001)
    a, b = centre - width / 2, centre + width / 2
    g = np.where(xs < start, 0.0,
                 np.where(xs < a, g0, np.where(xs > b, g1, g0 + (g1 - g0) * (xs - a) / (b - a))))
    z = np.concatenate([[0.0], np.cumsum(0.5 * (g[1:] + g[:-1]) * np.diff(xs))])
    return lambda s: np.interp(np.asarray(s, float), xs, z)


def test_the_bend_error_is_a_share_of_the_grade_change_at_each_knot():
    """`GroundSurface.bent_error`: lag_share x |grade change| x spacing at each known
    knot (from level before the first, to the tail after the last), 0 beyond the known
    ground and on a straight profile; `shifted` moves the known knots only."""
    ks = np.arange(2.0, 9.0)
    kz = np.array([0.0, 0.0, 0.1, 0.2, 0.2, 0.0, 0.0])
    surf = GroundSurface(PLANE, ks, kz, known_until_m=6.0, tail_grade=-0.1)
    err = surf.bent_error(0.5)
    assert np.allclose(err, [0.0, 0.05, 0.0, 0.05, 0.05, 0.0, 0.0])
    assert not surf.bent_error(0.0).any()
    slope = GroundSurface(PLANE, ks, 0.05 * (ks - 2.0), 8.0, tail_grade=0.05)
    assert np.allclose(slope.bent_error(0.5), [0.025, 0, 0, 0, 0, 0, 0])
    up = surf.shifted(np.full(ks.shape, 0.01))
    assert np.allclose(up.knots_z, kz + np.where(ks <= 6.0, 0.01, 0.0))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_drop_margin_covers_a_rounded_brow_and_not_a_drop(seed):
    """On a rise that starts at 2.5 m and rounds over a crest at 5 m, the fitted profile's
    1 m segments lag the ground by a quarter of a pixel where it bends: the drop test's
    margin (`drop_margin`) covers all but 0.05 px of the ground below the profile, and
    takes less than a fifth of a 10 cm drop beyond the crest."""
    prof = _rounded_brow(2.5, 0.06, -0.05, 5.0, 1.5)
    surf = fit_ground_surface(ground_points(prof, np.random.default_rng(seed)), PLANE)
    assert surf.known_until_m > 8.0
    origin, fwd, _ = ground_axes(PLANE)
    s = np.linspace(2.0, 8.0, 121)
    u, v, d = CAM.project(origin + s[:, None] * fwd + prof(s)[:, None] * PLANE.normal_up)
    pd = surf.disparity(CAM, u, v)
    lag = GroundSurfaceConfig().lag_share
    below = np.max(pd - d)                         # the ground below the profile, px
    uncovered = np.max(pd - d - gs.drop_margin(surf, CAM, u, v, pd, lag))
    assert below > 0.2 and uncovered < 0.05, (below, uncovered)
    s = np.linspace(6.2, 7.0, 9)
    u, v, d = CAM.project(origin + s[:, None] * fwd + (prof(s) - 0.1)[:, None] * PLANE.normal_up)
    pd = surf.disparity(CAM, u, v)
    low = gs.drop_margin(surf, CAM, u, v, pd, lag)
    assert np.all(low < 0.2 * (pd - d)), (low, pd - d)


def test_the_surface_says_why_its_known_ground_ends():
    """`GroundSurface.ended_by` names the rule that refused the segment beyond the known
    ground with the number it judged; '' where no segment was refused."""
    rng = np.random.default_rng(4)
    kerb = fit_ground_surface(ground_points(step_at(4.5, 0.12), rng), PLANE)
    rule, number, unit = kerb.ended_by().split()
    assert rule == 'rule_step' and unit == 'cm'
    assert float(number) == pytest.approx(kerb.checks[-1].step_m * 100, abs=0.05)
    assert float(number) > 100 * GroundSurfaceConfig().max_step_m
    bare = fit_ground_surface(ground_points(lambda s: 0.0 * s, rng, s_max=5.0), PLANE)
    assert bare.ended_by().startswith('rule_support ')
    assert bare.ended_by().endswith(' features')
    assert GroundSurface.flat(PLANE, 2.0).ended_by() == ''


def _edge_features(seed, far, gap=0.0, n=200):
    """One segment's features (t m from its start, lat m to the left, h m above the
    plane; 1 cm noise), flat to 0.45 m, then ``far(t)`` beyond ``0.45 + gap`` m (the
    ground a drop hides just beyond its edge: none there)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 1.0, n)
    t = t[(t <= 0.45) | (t > 0.45 + gap)]
    lat = rng.uniform(-1.5, 1.5, t.size)
    h = np.where(t <= 0.45, 0.0, far(t)) + rng.normal(0.0, 0.01, t.size)
    return t, lat, h


def test_a_sharp_brow_is_a_bend_and_a_drop_a_step():
    """rule_step's bend test (`surface_steps.path_step`): ground falling at 0.15 a metre beyond a
    sharp brow in the middle of a segment is explained better by a bent line than by a
    line and a step: no step, the bend's change of grade for rule_grade instead (each
    of 20 seeds), where the rays graze it at 0.4 (seen whole). Where they graze it at
    0.2 the ground beyond falls at three quarters of the ray's grade, as the gap behind
    a drop's edge would: the step stands. A 10 cm drop, its far side hidden for 0.2 m
    beyond the edge, is a step however the rays fall."""
    c = gs.GroundSurfaceConfig()
    brow = lambda t: -0.15 * (t - 0.45)              # noqa: E731
    drop = lambda t: -0.10 + 0.0 * t                 # noqa: E731
    for seed in range(20):
        args = (0.0, 0.0, 1.0, c.step_half_width_m, c.max_grade_rise)
        t, lat, h = _edge_features(seed, brow)
        step, at, bend = surface_steps.path_step(t, lat, h, np.full(t.size, -0.4), *args)
        assert step == 0.0 and bend == pytest.approx(-0.15, abs=0.03), (seed, step, bend)
        step, at, bend = surface_steps.path_step(t, lat, h, np.full(t.size, -0.2), *args)
        assert step != 0.0 and np.isnan(bend), (seed, step, bend)
        t, lat, h = _edge_features(seed, drop, gap=0.2)
        for ray in (-0.4, -0.2):
            step, at, bend = surface_steps.path_step(t, lat, h, np.full(t.size, ray), *args)
            assert step == pytest.approx(-0.10, abs=0.02) and np.isnan(bend), (seed, step)
