"""rule_ground_step (core/map_steps.py): a step of the ground ahead as map evidence.

On synthetic ground features (test_ground_surface's): a kerb up or a step down across
the path is taken where the ground surface ends by rule_step, at its place and with its
height; flat ground, a slope and a box are not steps; the evidence lies across the
corridor just beyond the step.
"""
import dataclasses

import numpy as np
import pytest

from asmonc_vision.core.ground_surface import fit_ground_surface
from asmonc_vision.core.map_settings import EvidenceMapConfig, GroundStepConfig
from asmonc_vision.core.map_evidence import DROP, RAISED
from asmonc_vision.core.map_steps import GroundStep, ground_step, step_evidence, with_step

from test_ground_surface import PLANE, box_points, ground_points, slope_from, step_at


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('rise', [0.10, -0.15])
def test_a_kerb_up_or_a_step_down_across_the_path_is_taken(seed, rise):
    rng = np.random.default_rng(seed)
    pts = ground_points(step_at(4.5, rise), rng)
    surf = fit_ground_surface(pts, PLANE)
    assert surf.checks[-1].refused_by in ('rule_step', 'rule_grade'), surf.checks
    step = ground_step(surf, pts, GroundStepConfig())
    assert step is not None
    assert step.at_m == pytest.approx(4.5, abs=0.2)
    assert step.height_m == pytest.approx(rise, abs=0.03)
    assert 0.0 < step.sigma_m < 0.01
    # its support: the far side's features on its level, beyond it
    s, _, h = surf.coordinates(pts[step.far])
    assert np.all(s >= step.at_m - 0.1) and np.all(s <= step.at_m + GroundStepConfig().band_m)
    assert np.all(np.abs(h - rise) <= 0.5 * abs(rise))
    # the surface's segment that ends at a kerb may place the step short of it (a level
    # chest rig sees little ground before the kerb): a step up lies where the features
    # of its raised side begin; a drop's lower side begins beyond the edge (hidden
    # behind it), so a drop stays where the segment put it
    short = dataclasses.replace(surf.checks[-1], step_at_m=4.2)
    short_surf = dataclasses.replace(surf, checks=surf.checks[:-1] + (short,))
    step = ground_step(short_surf, pts, GroundStepConfig())
    assert step is not None
    assert step.at_m == pytest.approx(4.5 if rise > 0 else 4.2, abs=0.06)
    assert step.height_m == pytest.approx(rise, abs=0.03)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_flat_ground_a_slope_and_a_box_are_no_steps(seed):
    rng = np.random.default_rng(seed)
    cfg = GroundStepConfig()
    for pts in (ground_points(lambda s: 0.0 * s, rng),
                ground_points(slope_from(3.0, 5.0), rng),
                np.concatenate([ground_points(lambda s: 0.0 * s, rng),
                                box_points(4.0, 0.0, 0.3, 0.4, rng)])):
        assert ground_step(fit_ground_surface(pts, PLANE), pts, cfg) is None


def test_a_step_under_the_least_height_or_switched_off_is_not_taken():
    rng = np.random.default_rng(5)
    pts = ground_points(step_at(4.5, 0.10), rng)
    surf = fit_ground_surface(pts, PLANE)
    assert ground_step(surf, pts, GroundStepConfig()) is not None
    assert ground_step(surf, pts, GroundStepConfig(min_step_m=0.2)) is None
    assert ground_step(surf, pts, GroundStepConfig(enabled=False)) is None
    assert ground_step(None, pts, GroundStepConfig()) is None
    # too little of the far side on its level: not taken
    assert ground_step(surf, pts, GroundStepConfig(min_features=100000)) is None


def test_the_evidence_lies_across_the_corridor_just_beyond_the_step():
    rng = np.random.default_rng(3)
    pts = ground_points(step_at(5.0, 0.12), rng)
    cfg = GroundStepConfig()
    step = ground_step(fit_ground_surface(pts, PLANE), pts, cfg)
    assert step is not None
    cell = EvidenceMapConfig().cell_m
    xy, height, sigma = step_evidence(step, cfg, cell)
    assert xy.shape == (height.shape[0], 2) and sigma.shape == height.shape
    assert xy[:, 0].min() == pytest.approx(step.at_m + 0.5 * cell)
    assert xy[:, 0].max() <= step.at_m + cfg.depth_m + 1e-9
    assert xy[:, 1].min() == pytest.approx(-cfg.half_width_m)
    assert xy[:, 1].max() == pytest.approx(cfg.half_width_m)
    # one point in every cell across the corridor's width at each depth
    assert len(np.unique(np.round(xy[:, 1] / cell))) == round(2 * cfg.half_width_m / cell) + 1
    assert np.all(height == step.height_m) and np.all(sigma == step.sigma_m)


@pytest.mark.parametrize('rise', [0.10, -0.15])
def test_a_pairs_evidence_takes_the_step_as_raised_or_drop_points(rise):
    from asmonc_vision.core.map_evidence import GROUND, NONE, PairEvidence
    cfg = EvidenceMapConfig()
    ev = PairEvidence(xy=np.array([[3.0, 0.0], [4.0, 0.1]]), height=np.array([0.0, 0.2]),
                      sigma_h=np.array([0.01, 0.02]), kind=np.array([GROUND, NONE], np.int8),
                      weight=np.array([0.5, 0.7]))
    step = GroundStep(at_m=4.5, height_m=rise, sigma_m=0.004, far=np.zeros(0, bool))
    out = with_step(ev, step, cfg.steps, cfg.cell_m, 3)
    xy, h, sg = step_evidence(step, cfg.steps, cfg.cell_m, 1 if rise > 0 else 3)
    assert np.array_equal(out.xy, np.concatenate([ev.xy, xy]))
    assert np.array_equal(out.kind[:2], ev.kind)
    assert np.all(out.kind[2:] == (RAISED if rise > 0 else DROP))
    assert np.all(out.height[2:] == rise) and np.all(out.sigma_h[2:] == 0.004)
    assert np.array_equal(out.weight, np.concatenate([ev.weight, np.ones(len(h))]))
    # a drop has min_drop_pixels points at each place, a step up one
    assert len(out.kind) - 2 == len(step_evidence(step, cfg.steps, cfg.cell_m)[1]) * (
        1 if rise > 0 else 3)
    assert with_step(dataclasses.replace(ev, weight=None), step, cfg.steps, cfg.cell_m,
                     3).weight is None


def test_settings_refuse_values_out_of_range():
    with pytest.raises(ValueError, match='min_step_m'):
        GroundStepConfig(min_step_m=-0.1)
    with pytest.raises(ValueError, match='band_m'):
        GroundStepConfig(band_m=0.0)


def test_kerbs_either_side_of_a_ramp_are_no_step_of_the_path():
    """A kerb up 12 cm at 4.5 m to the left and right of the walking line, and between
    them a ramp rising to the same height over a metre: the surface may end at a step
    (the kerbs' features outnumber the ramp's), but the corridor does not show it; a
    kerb across the whole path is taken."""
    from asmonc_vision.core.camera import ground_axes
    from test_ground_surface import _through_camera
    origin, fwd, left = ground_axes(PLANE)
    cfg = GroundStepConfig()
    for seed in range(3):
        rng = np.random.default_rng(seed)
        s = rng.uniform(1.5, 9.0, 4000)
        lat = rng.uniform(-2.0, 2.0, 4000)
        kerb = np.where(s >= 4.5, 0.12, 0.0)
        ramp = np.clip((s - 4.5) / 1.0, 0.0, 1.0) * 0.12
        for across, taken in ((kerb, True), (np.where(np.abs(lat) <= 0.9, ramp, kerb), False)):
            p = origin + s[:, None] * fwd + lat[:, None] * left + across[:, None] * PLANE.normal_up
            pts = _through_camera(p, rng, 0.15)
            step = ground_step(fit_ground_surface(pts, PLANE), pts, cfg)
            assert (step is not None) == taken, (seed, taken, step)


@pytest.mark.parametrize('rise', [0.10, -0.15])
def test_the_map_confirms_a_step_seen_from_pair_to_pair(rise):
    """A rig walking towards a kerb up (or a step down) across the path 6 m ahead in the
    world, whose pixels all read as ground: each pair enters its ground and the step's
    evidence (its far side not seen free):
    the map confirms a thing (a drop) at the step with the step's height within a few
    pairs; without the step's evidence, nothing."""
    from asmonc_vision.core.evidence_map import EvidenceMap
    from asmonc_vision.core.map_evidence import GROUND, PairEvidence
    from test_evidence_map import evidence, ground_grid, step_motion
    cfg = EvidenceMapConfig()
    sc = cfg.steps

    def pair(cam_x: float, stepped: bool) -> PairEvidence:
        at = 6.0 - cam_x
        ground = ground_grid(cam_x + 2.0, cam_x + 8.0)
        if stepped:     # its far side within band_m is not ground seen free
            ground = ground[~((ground[:, 0] >= 6.0) & (ground[:, 0] <= 6.0 + sc.band_m))]
        ev = evidence([(ground, GROUND, None)], cam_x)
        if not stepped:
            return ev
        step = GroundStep(at_m=at, height_m=rise, sigma_m=0.005, far=np.zeros(0, bool))
        return with_step(ev, step, sc, cfg.cell_m, cfg.min_drop_pixels)

    for stepped in (True, False):
        emap = EvidenceMap(cfg)
        objects = ()
        xs = np.arange(0.0, 1.21, 0.12)          # 1.2 m/s at 10 Hz
        for i, x in enumerate(xs):
            motion = None if i == 0 else step_motion(x - xs[i - 1])
            objects = emap.update(0.1 * i, PLANE, pair(x, stepped), motion, False)
        found = [o for o in objects if (o.height < 0) == (rise < 0)]
        if not stepped:
            assert not found, found
            continue
        assert found, objects
        o = min(found, key=lambda o: float(np.hypot(*o.nearest_xy)))
        assert float(np.hypot(*o.nearest_xy)) == pytest.approx(6.0 - xs[-1], abs=0.25)
        assert o.height == pytest.approx(rise, abs=0.02)
