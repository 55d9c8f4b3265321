"""The evidence map (core.evidence_map) and the Perception stage, without ROS.

Scenes are built from geometry: a rig like the paper's (f = 300 px, B = 0.35 m, 320x240,
cameras 1.25 m above flat ground pitched down 20 degrees) walking along the ground's x;
the matched edge pixels of each pair are made from world points (a box's silhouette
edges, ground texture) and fed through `pair_evidence`, the map's measurement model.
"""
import dataclasses
import math

import numpy as np
import pytest

from asmonc_vision.core.camera import MetricPlane, StereoCamera
from asmonc_vision.core.evidence_map import EvidenceMap, EvidenceMapConfig, MapObject
from asmonc_vision.core.map_drop_hold import DropHold, nearest_ground_in_view
from asmonc_vision.core.map_step_up import stepped_onto
from asmonc_vision.core.map_evidence import (DROP, GROUND, NONE, RAISED, PairEvidence,
                                             pair_evidence)
from asmonc_vision.core.map_reports import (CORRIDOR_ID_BASE, MAP_ID_BASE,
                                            objects_to_obstacles)

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)
H = 1.25
PITCH = math.radians(20.0)
PLANE = MetricPlane(normal_up=np.array([0.0, -math.cos(PITCH), -math.sin(PITCH)]), height=H)
FWD_OPT = np.array([0.0, -math.sin(PITCH), math.cos(PITCH)])   # world forward, optical


def to_optical(pw: np.ndarray, cam_x: float, cam_y: float = 0.0) -> np.ndarray:
    """World points (N, 3) (x forward, y left, z up; ground z = 0) to the left optical
    frame of the rig at (cam_x, cam_y), heading +x."""
    dx, dy, dz = pw[:, 0] - cam_x, pw[:, 1] - cam_y, pw[:, 2] - H
    s, c = math.sin(PITCH), math.cos(PITCH)
    return np.stack([-dy, -s * dx - c * dz, c * dx - s * dz], axis=1)


def matches(pw: np.ndarray, cam_x: float, kind: int, extra_px=None, cam_y: float = 0.0):
    """Cyclopean (u, v, d) and kinds of world points seen in the image; ``extra_px``
    (N,) is added to each disparity (a mismatch)."""
    p = to_optical(pw, cam_x, cam_y)
    u, v, d = CAM.project(np.where(p[:, 2:3] > 0.1, p, np.array([0, 0, 1.0])))
    ok = (p[:, 2] > 0.1) & (u >= 0) & (u < CAM.width) & (v >= 0) & (v < CAM.height)
    if extra_px is not None:
        d = d + extra_px
    return u[ok], v[ok], d[ok], np.full(int(ok.sum()), kind, np.int8)


def hidden(pw: np.ndarray, cam_x: float, occluders) -> np.ndarray:
    """(N,) bool: ground points hidden from the rig at cam_x by the front faces of
    boxes (x, y, height, half width)."""
    out = np.zeros(len(pw), bool)
    for x, y, h, hw in occluders:
        t = (x - cam_x) / np.maximum(pw[:, 0] - cam_x, 1e-9)
        behind = pw[:, 0] > x
        y_at = pw[:, 1] * t
        z_at = H * (1.0 - t)
        out |= behind & (np.abs(y_at - y) <= hw) & (z_at <= h)
    return out


def evidence(parts, cam_x: float, cam_y: float = 0.0, occluders=()) -> PairEvidence:
    """PairEvidence of [(world points, kind, extra disparity or None)] for the rig at
    cam_x, through the measurement model; ground points behind the ``occluders``' front
    faces (x, y, height, half width) are not seen."""
    us, vs, ds, ks = [], [], [], []
    for pw, kind, extra in parts:
        if kind == GROUND and occluders:
            pw = pw[~hidden(pw, cam_x, occluders)]
        u, v, d, k = matches(pw, cam_x, kind, extra, cam_y)
        us.append(u), vs.append(v), ds.append(d), ks.append(k)
    u, v, d, k = (np.concatenate(a) for a in (us, vs, ds, ks))
    return pair_evidence(CAM, PLANE, u, v, d, np.full(u.shape, 0.3), k, 8.0)


def box_edges(x: float, y: float, height: float, half_width: float = 0.15) -> np.ndarray:
    """World points of a box's two front silhouette edges (vertical, 1 cm apart), above
    5 cm (the detector's obstacle pixels)."""
    z = np.arange(0.05, height + 1e-9, 0.01)
    return np.concatenate([np.stack([np.full_like(z, x), np.full_like(z, y + s), z], 1)
                           for s in (-half_width, half_width)])


def ground_grid(x0: float, x1: float, y0: float = -1.5, y1: float = 1.5,
                step: float = 0.05, holes=()) -> np.ndarray:
    """World ground points (z = 0) on a grid, without those in the (x0, x1, y0, y1) holes."""
    gx, gy = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step))
    p = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    for a, b, c, d in holes:
        p = p[~((p[:, 0] >= a) & (p[:, 0] <= b) & (p[:, 1] >= c) & (p[:, 1] <= d))]
    return p


def step_motion(s: float):
    """T_prev_curr of a step s forward: X_prev = I X_curr + s * forward."""
    return np.eye(3), s * FWD_OPT


def walk(emap: EvidenceMap, scene, xs, still=False, stamp0=0.0, occluders=()):
    """Feed the map the pairs of a walk through cam positions xs; ``scene(cam_x)`` gives
    the pair's parts. Returns the objects of each pair."""
    out = []
    prev = None
    for i, x in enumerate(xs):
        motion = None if prev is None else step_motion(x - prev)
        out.append(emap.update(stamp0 + 0.1 * i, PLANE,
                               evidence(scene(x), x, occluders=occluders), motion, still))
        prev = x
    return out


def nearest(objects):
    return [(float(np.hypot(*o.nearest_xy)), o) for o in objects]


# ------------------------------------------------------------------ measurement model
def test_measurement_model_heights_and_sigma():
    box = box_edges(3.0, 0.0, 0.3)
    u, v, d, k = matches(box, 0.0, RAISED)
    ev = pair_evidence(CAM, PLANE, u, v, d, np.full(u.shape, 0.3), k, 8.0)
    assert np.allclose(ev.height, np.concatenate([np.arange(0.05, 0.3001, 0.01)] * 2),
                       atol=1e-6)
    assert np.allclose(ev.xy[:, 0], 3.0, atol=1e-6)
    # σ_h grows with range: a disparity error of 0.3 px is worth more height farther
    far = box_edges(6.0, 0.0, 0.3)
    u2, v2, d2, k2 = matches(far, 0.0, RAISED)
    ev2 = pair_evidence(CAM, PLANE, u2, v2, d2, np.full(u2.shape, 0.3), k2, 8.0)
    assert np.median(ev2.sigma_h) > 1.5 * np.median(ev.sigma_h) > 0
    # beyond max_range nothing is entered
    ev3 = pair_evidence(CAM, PLANE, u2, v2, d2, np.full(u2.shape, 0.3), k2, 5.0)
    assert ev3.xy.shape[0] == 0


# ------------------------------------------------------------------ motion of the grid
def test_the_grid_moves_with_the_camera():
    cfg = EvidenceMapConfig(enabled=True)
    emap = EvidenceMap(cfg)
    ground = ground_grid(1.5, 8.0, holes=[(4.0, 4.3, 0.35, 0.65)])

    def scene(x):
        return [(box_edges(4.0, 0.5, 0.3), RAISED, None), (ground, GROUND, None)]
    xs = np.arange(0.0, 1.21, 0.12)
    objs = walk(emap, scene, xs, occluders=[(4.0, 0.5, 0.3, 0.15)])
    (r, ob), = nearest(objs[-1])
    # the box stands at x = 4.0, y = +0.5 in the world: 4.0 - 1.2 ahead, 0.5 left now
    assert ob.nearest_xy[0] == pytest.approx(4.0 - xs[-1], abs=0.06)
    assert ob.nearest_xy[1] == pytest.approx(0.5 - 0.15, abs=0.06)
    assert ob.height == pytest.approx(0.3, abs=0.03)
    # the map is re-centred by whole cells as the wearer walks on: nothing lost
    for _ in range(12):
        emap.update(emap._stamp_s + 0.1, PLANE, None, step_motion(0.12), False)
    (r2, ob2), = nearest(emap.objects)
    assert ob2.nearest_xy[0] == pytest.approx(ob.nearest_xy[0] - 12 * 0.12, abs=0.06)
    assert np.abs(emap.pose[:2] - emap.origin - cfg.radius_m).max() < cfg.recentre_m


def test_a_turn_moves_the_objects_round_the_wearer():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    box = box_edges(3.0, 0.0, 0.3)
    for i in range(4):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0),
                    None if i == 0 else (np.eye(3), np.zeros(3)), True)
    (r, ob), = nearest(emap.objects)
    # turn 20 degrees left on the spot: about the optical frame's "up" axis
    yaw = math.radians(20.0)
    n = -PLANE.normal_up
    K = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    R = np.eye(3) + math.sin(yaw) * K + (1 - math.cos(yaw)) * K @ K   # Rodrigues
    emap.update(0.5, PLANE, None, (R, np.zeros(3)), False)
    (r2, ob2), = nearest(emap.objects)
    b1 = math.atan2(ob.nearest_xy[1], ob.nearest_xy[0])
    b2 = math.atan2(ob2.nearest_xy[1], ob2.nearest_xy[0])
    assert r2 == pytest.approx(r, abs=0.02)
    assert abs(abs(b2 - b1) - yaw) < math.radians(1.0)


# ------------------------------------------------------------------ confirmation
def test_confirmation_needs_two_viewpoints():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, min_baseline_m=0.3))
    box = box_edges(4.0, 0.0, 0.2)
    ground = ground_grid(1.5, 8.0, holes=[(4.0, 4.3, -0.15, 0.15)])

    def scene(x):
        return [(box, RAISED, None), (ground, GROUND, None)]
    objs = walk(emap, scene, np.arange(0.0, 0.61, 0.1), occluders=[(4.0, 0.0, 0.2, 0.15)])
    found = [len(o) > 0 for o in objs]
    # evidence strong enough from the second pair on, but one viewpoint until 0.3 m
    assert found == [False, False, False, True, True, True, True]


def test_a_still_rig_confirms_after_separate_frames():
    cfg = EvidenceMapConfig(enabled=True, still_min_frames=3)
    emap = EvidenceMap(cfg)
    box = box_edges(3.0, 0.0, 0.05)        # a 5 cm box at 3 m
    found = []
    for i in range(6):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True)
        found.append(len(emap.objects) > 0)
    assert found == [False, False, True, True, True, True]


def test_a_mismatch_a_standing_rig_repeats_is_confirmed_a_measured_limit():
    """A few mismatched pixels 3.8 m ahead, 6-7 cm high, seen alike in each of the three
    pairs the wearer stands at the start and gone once the view moves (step_down 1003 on
    the chest rig): a still rig has no parallax to tell them from a thing, and with
    `still_min_frames` (2) still pairs counting as two views they are confirmed (a false
    alarm event there). With four they are not, but a box set down before a standing
    wearer is then reported two pairs later too (docs/map.md, Limits)."""
    blip = np.array([[3.8, 0.10, 0.06], [3.8, 0.10, 0.065], [3.8, 0.11, 0.07],
                     [3.8, 0.11, 0.06]])
    xs = [0.0, 0.0, 0.0, 0.12, 0.24, 0.36, 0.48]

    def found(still_min_frames):
        emap = EvidenceMap(EvidenceMapConfig(enabled=True, still_min_frames=still_min_frames))
        out, prev = [], None
        for i, x in enumerate(xs):
            parts = [(ground_grid(2.0, 8.0, holes=[(3.7, 3.9, 0.0, 0.2)]), GROUND, None)]
            if i < 3:
                parts.append((blip, RAISED, None))
            motion = None if prev is None else step_motion(x - prev)
            out.append(len(emap.update(0.1 * i, PLANE, evidence(parts, x), motion,
                                       0 < i < 3)) > 0)
            prev = x
        return out
    assert found(EvidenceMapConfig().still_min_frames) == [False, False] + [True] * 5
    assert not any(found(4))


def test_moving_without_a_motion_clears_the_map():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, motion_gap_frames=2))
    box = box_edges(3.0, 0.0, 0.3)
    for i in range(4):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True)
    assert emap.objects
    for i in range(4, 6):       # moving, motion unknown: held for 2 pairs
        emap.update(0.1 * i, PLANE, None, None, False)
        assert emap.objects
    emap.update(0.6, PLANE, None, None, False)
    assert not emap.objects and not (emap.L_r > 0).any()
    assert emap.placed_pairs == 1       # the Perception stage passes the detector's reports


# ------------------------------------------------------------------ mismatches
def joints_scene(x0: float, x1: float, period: float, box=(5.0, 1.2, 0.2)):
    """Paving joints running forward, a lateral period ``period`` apart, over x0..x1 m,
    every joint pixel matched one period off (its disparity too large by f P / Z, so it
    is seen raised, nearer than the joint, on the sight line of the joint: k = P / B,
    the false point at Z / (1 + k), H k / (1 + k) high, sliding along with the wearer
    by k / (1 + k) of each step); correctly matched ground texture around; a real box.
    Returns (scene(cam_x), occluders)."""
    jx, jy = np.meshgrid(np.arange(x0, x1, 0.1), np.arange(-0.6, 0.61, period))
    joints = np.stack([jx.ravel(), jy.ravel(), np.zeros(jx.size)], 1)
    bx, by, bh = box
    ground = ground_grid(1.5, 8.0, step=0.1, holes=[(bx, bx + 0.3, by - 0.15, by + 0.15)])

    def scene(x):
        z = to_optical(joints, x)[:, 2]
        p_px = CAM.f * period / np.maximum(z, 0.1)            # one period in the image
        return [(joints, RAISED, p_px), (box_edges(bx, by, bh), RAISED, None),
                (ground, GROUND, None)]
    return scene, [(bx, by, bh, 0.15)]


def test_a_compact_mismatch_that_slides_with_the_wearer_is_not_confirmed():
    """A short stretch of joints 0.45 m apart (k = 1.3): the false points rise 0.7 m and
    slide by 56 % of each step; over a 0.5 m baseline they leave their cells, the ground
    seen there clears them, and only the box is reported."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, min_baseline_m=0.5))
    scene, occ = joints_scene(3.0, 3.31, 0.45)
    ev = evidence(scene(0.0)[:1], 0.0)
    assert np.median(ev.height) > 0.5                     # they do stand out
    xs = np.arange(0.0, 2.41, 0.12)
    objs = walk(emap, scene, xs, occluders=occ)
    for x, obs in zip(xs, objs):
        for ob in obs:
            assert ob.nearest_xy[1] > 0.8, (x, ob.nearest_xy)    # the box only
    assert all(len(o) == 1 for o in objs[5:])
    # with the shorter baseline the same false points are confirmed (a measured limit)
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, min_baseline_m=0.3))
    objs = walk(emap, scene, xs, occluders=occ)
    assert any(ob.nearest_xy[1] < 0.8 for obs in objs for ob in obs)


def test_an_extended_repetitive_pattern_is_a_measured_limit():
    """Joints 0.3 m apart over 4 m, all matched a period off: the false points form a
    sheet that covers the same cells from view to view (only its ends move), so the map
    confirms it: rejecting such mismatches is the per-pair detector's job (see
    docs/map.md)."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, min_baseline_m=0.5))
    scene, occ = joints_scene(3.0, 7.0, 0.3)
    objs = walk(emap, scene, np.arange(0.0, 1.21, 0.12), occluders=occ)
    assert any(ob.nearest_xy[1] < 0.8 for ob in objs[-1])


def test_scattered_mismatches_are_not_confirmed():
    """Stains, markings: a few raised pixels at random places each pair (2-6 cm above
    the ground, 1-8 m ahead), never twice at one place: nothing is reported, while a
    real box among them is."""
    rng = np.random.default_rng(5)
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    ground = ground_grid(1.5, 8.0, step=0.1, holes=[(4.0, 4.3, -0.15, 0.15)])
    xs = np.arange(0.0, 3.01, 0.12)
    reports = []
    used = np.zeros((0, 2))
    for i, x in enumerate(xs):
        spots = np.column_stack([x + rng.uniform(1.5, 8.0, 40), rng.uniform(-1.5, 1.5, 40),
                                 rng.uniform(0.02, 0.06, 40)])
        # never within 0.3 m of an earlier one
        far = np.array([np.all(np.hypot(*(used - p[:2]).T) > 0.3) for p in spots])
        spots = spots[far][:12]
        used = np.vstack([used, spots[:, :2]])
        spots = np.repeat(spots, 4, axis=0)            # a few pixels each
        parts = [(spots, RAISED, None), (ground, GROUND, None)]
        if x < 2.0:
            parts.append((box_edges(4.0, 0.0, 0.2), RAISED, None))
        ev = evidence(parts, x, occluders=[(4.0, 0.0, 0.2, 0.15)] if x < 2.0 else ())
        objs = emap.update(0.1 * i, PLANE, ev, None if i == 0 else step_motion(0.12), False)
        reports.append([o for o in objs if abs(o.nearest_xy[1]) > 0.3
                        or abs(o.nearest_xy[0] - (4.0 - x)) > 0.3])
    assert sum(len(r) for r in reports) == 0
    assert len(emap.objects) == 1            # the box, passed below the view, remembered


def test_a_small_period_is_a_measured_limit():
    """A grate's bars 5 cm apart (k = P / B = 0.14): the false points slide by 12 % of
    each step, 6 cm over a 0.5 m baseline, within a cell: the map confirms them."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, min_baseline_m=0.5))
    jx, jy = np.meshgrid(np.arange(3.0, 3.5, 0.05), np.arange(-0.3, 0.31, 0.05))
    grate = np.stack([jx.ravel(), jy.ravel(), np.zeros(jx.size)], 1)

    def scene(x):
        z = to_optical(grate, x)[:, 2]
        return [(grate, RAISED, CAM.f * 0.05 / np.maximum(z, 0.1))]
    objs = walk(emap, scene, np.arange(0.0, 0.73, 0.12))
    assert objs[-1]


@pytest.mark.parametrize('weigh', [True, False])
def test_evidence_counts_by_how_sure_its_match_is(weigh):
    """A cell's raised evidence of a pair counts hit_logodds times the weight of its
    surest pixel (1 - the share of its rivals that say otherwise); with weigh_by_rivals
    off, fully."""
    cfg = EvidenceMapConfig(enabled=True, weigh_by_rivals=weigh)
    emap = EvidenceMap(cfg)
    ev = pair_evidence(CAM, PLANE, np.array([100.0, 101.0, 220.0]), np.array([150.0] * 3),
                       np.array([40.0, 40.0, 40.0]), np.full(3, 0.3),
                       np.array([RAISED] * 3, np.int8), 8.0,
                       weight=np.array([1 / 3, 1 / 2, 1 / 4]))
    emap.update(0.0, PLANE, ev, None, True)
    got = np.sort(emap.L_r[emap.L_r > 0])
    if weigh:        # the two near pixels share a cell: its surest one, 1/2, counts
        assert got == pytest.approx([cfg.hit_logodds / 4, cfg.hit_logodds / 2], abs=1e-6)
    else:
        assert got == pytest.approx([cfg.hit_logodds] * 2, abs=1e-6)


def test_a_box_whose_matches_each_have_a_rival_is_confirmed_a_little_later():
    """A kerb face's matches may have one rival on the ground as well supported (weight
    1/2): the box is still confirmed, two pairs later than with sure matches."""
    box = box_edges(4.0, 0.0, 0.2)
    ground = ground_grid(1.5, 8.0, holes=[(4.0, 4.3, -0.15, 0.15)])
    first = {}
    for w in (1.0, 0.5):
        emap = EvidenceMap(EvidenceMapConfig(enabled=True, min_baseline_m=0.1))
        prev = None
        for i, x in enumerate(np.arange(0.0, 1.01, 0.1)):
            ev = evidence([(box, RAISED, None), (ground, GROUND, None)], x,
                          occluders=[(4.0, 0.0, 0.2, 0.15)])
            ev = PairEvidence(ev.xy, ev.height, ev.sigma_h, ev.kind, np.full(len(ev.kind), w))
            objs = emap.update(0.1 * i, PLANE, ev, None if prev is None else step_motion(
                x - prev), False)
            prev = x
            if objs and w not in first:
                first[w] = i
    assert first[1.0] == 1 and first[0.5] == 3


def _appear_walk(appear_min_pixels: int, thing: np.ndarray, seen_in, still: bool = False,
                 hole=(4.7, 5.4, -0.4, 0.4), pairs: int = 12) -> list:
    """Ground seen for six pairs, then ``thing`` (world points, raised) in the pairs
    ``seen_in``, the ground around it unmatched from then on (too few matches there to
    clear a cell): the map's objects of each pair."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, appear_min_pixels=appear_min_pixels))
    xs = np.zeros(pairs) if still else np.arange(pairs) * 0.12
    count = [0]

    def scene(x):
        k = count[0]
        count[0] += 1
        if k < 6:
            return [(ground_grid(2.0, 8.0), GROUND, None)]
        parts = [(ground_grid(2.0, 8.0, holes=[hole]), GROUND, None)]
        return parts + ([(thing, RAISED, None)] if k in seen_in else [])
    return walk(emap, scene, xs, still=still)


def test_a_mismatch_that_comes_and_goes_over_ground_seen_is_not_confirmed():
    """Two raised pixels 5 m ahead where the ground was seen, in one pair and again three
    pairs later (far ground judged against a plane that is off for a pair does this):
    they add to what the ground said and are not confirmed; starting from 0 at each
    raised pair (appear_min_pixels 1) they were."""
    blip = np.array([[5.0, 0.0, 0.10], [5.0, 0.0, 0.12]])
    assert not _appear_walk(4, blip, (6, 9))[-1]
    assert _appear_walk(1, blip, (6, 9))[-1]


@pytest.mark.parametrize('still', [False, True])
def test_a_thing_that_appears_over_ground_seen_is_confirmed(still):
    """A box set down 5 m ahead where the ground was seen (a passer-by stepping in), then
    seen in every pair, is confirmed in the same pair as when every raised pair starts
    from 0 (its face puts many pixels in its cells); so is one seen by two pixels a
    pair while walking (its second view is the later gate), and standing one pair
    later."""
    def first(appear, thing):
        out = _appear_walk(appear, thing, range(6, 12), still=still)
        return next(i for i, o in enumerate(out) if o)
    box = box_edges(5.0, 0.0, 0.3)
    assert first(4, box) == first(1, box) <= (7 if still else 9)
    weak = np.array([[5.0, 0.0, 0.10], [5.0, 0.0, 0.12]])
    assert first(4, weak) - first(1, weak) == (1 if still else 0)


def test_a_face_seen_in_one_pair_of_three_over_ground_seen_is_confirmed():
    """A kerb face seen only now and then (a short baseline at 2.5-3 m) puts many pixels
    in its cells each time: it starts from 0 as a thing that appears, and is confirmed
    when seen again."""
    face = box_edges(5.0, 0.0, 0.15)
    out = _appear_walk(4, face, (6, 9), pairs=10)
    assert out[-1] and not out[-2]


# ------------------------------------------------------------------ clearing, passers-by
def test_ground_seen_where_a_thing_stood_clears_it():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    box = box_edges(3.0, 0.0, 0.3)
    for i in range(4):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True)
    assert emap.objects
    ground = ground_grid(2.0, 5.0, step=0.03)
    cleared_after = None
    for i in range(4, 10):
        emap.update(0.1 * i, PLANE, evidence([(ground, GROUND, None)], 0.0), None, True)
        if not emap.objects and cleared_after is None:
            cleared_after = i - 3
    assert cleared_after is not None and cleared_after <= 2
    assert not emap.two_views.any()


def test_the_compiled_sight_line_test_gives_numpys_cells():
    """`map_kernels.rays_kernel` (the compiled `map_sight.seen_through`) clears the same cells
    as its numpy path: raised cells of all heights and spreads, sight lines on both sides,
    through them, short of them and beyond them."""
    from asmonc_vision.core import map_kernels
    if map_kernels.nb_rays is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(3)
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    box = box_edges(3.0, 0.0, 0.3)
    emap.update(0.0, PLANE, evidence([(box, RAISED, None)], 0.0), None, True)
    n = emap.n
    cells = rng.choice(n * n, 300, replace=False)
    emap.L_r.reshape(-1)[cells] = rng.uniform(-1.0, 3.0, cells.size).astype(np.float32)
    emap.h_x.reshape(-1)[cells] = rng.uniform(0.0, 1.5, cells.size).astype(np.float32)
    emap.h_P.reshape(-1)[cells] = rng.uniform(0.0, 0.05, cells.size).astype(np.float32)
    xy = emap.to_world(np.column_stack([rng.uniform(0.5, 6.0, cells.size),
                                        rng.uniform(-1.0, 1.0, cells.size)]))
    emap.pt_xy.reshape(-1, 2)[cells] = xy.astype(np.float32)
    ground = np.column_stack([rng.uniform(0.3, 8.0, 800), rng.uniform(-2.0, 2.0, 800)])
    n_r = rng.integers(0, 3, n * n)
    got = emap._rays(ground, n_r)
    want = emap._rays(ground, n_r, use_kernel=False)
    assert want.size > 0
    np.testing.assert_array_equal(got, want)


def test_a_passer_by_leaves_no_ghost_trail():
    """A person (a tall thing 0.4 m wide) crossing the path 3 m ahead at 1.4 m/s while
    the wearer stands still: the ground seen where the person was clears those cells
    as fast as they filled."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    reported_behind = 0
    for i in range(20):
        py = -1.5 + 0.14 * i
        person = box_edges(3.0, py, 1.7, half_width=0.2)
        ground = ground_grid(2.0, 5.0, step=0.05, holes=[(2.9, 3.5, py - 0.3, py + 0.3)])
        emap.update(0.1 * i, PLANE, evidence([(person, RAISED, None), (ground, GROUND, None)],
                                             0.0), None, True)
        for ob in emap.objects:
            lat = ob.far_xy[:, 1]
            # any reported cell more than 0.45 m behind the person's near side is a ghost
            if (lat < py - 0.2 - 0.45).any():
                reported_behind += 1
    assert reported_behind == 0
    # and nothing is left once the person has gone
    ground = ground_grid(2.0, 5.0, step=0.05)
    for i in range(20, 23):
        emap.update(0.1 * i, PLANE, evidence([(ground, GROUND, None)], 0.0), None, True)
    assert not emap.objects


def _crossing(emap: EvidenceMap, steps: int, cam=CAM, hide_at=None):
    """A person (a tall thing 0.4 m wide) crossing the path 3 m ahead at 1.4 m/s over
    plain ground (no ground matches near it) while the wearer stands still; ``hide_at`` (lateral
    position) puts a nearer thing (at 1.5 m) there. Returns, per pair, whether a region
    more than 0.45 m behind the person's near side (a ghost) is reported."""
    ghosts = []
    for i in range(steps):
        py = -1.2 + 0.14 * min(i, 10)
        parts = [(ground_grid(6.5, 7.5, -4.0, 4.0, step=0.25), GROUND, None)]  # far, sparse
        if i <= 10:                  # the person's clothes: matched all across
            body = np.concatenate([box_edges(3.0, py + dy, 1.7, half_width=0.0)
                                   for dy in np.arange(-0.2, 0.21, 0.05)])
            parts.append((body, RAISED, None))
        if hide_at is not None:
            parts.append((box_edges(1.5, hide_at, 1.0, half_width=0.25), RAISED, None))
        ev = evidence(parts, 0.0)
        emap.update(0.1 * i, PLANE, ev, None, True, cam)
        ghosts.append(any((o.far_xy[:, 1] < py - 0.2 - 0.45).any() and o.far_xy[:, 0].min() > 2.5
                          for o in emap.objects))
    return ghosts


def test_a_passer_by_over_plain_ground_fades_when_not_seen_again():
    """With no ground matched where the person walked, only the person not being seen
    again in plain view clears the cells left behind: within a few pairs (without the
    rule the trail is kept for seconds)."""
    ghosts = _crossing(EvidenceMap(EvidenceMapConfig(enabled=True, unseen_report_s=0.0)), 16)
    kept = _crossing(EvidenceMap(EvidenceMapConfig(enabled=True, miss_logodds=0.0,
                                                   unseen_report_s=0.0)), 16)
    assert sum(ghosts) <= 4 < sum(kept)
    assert not ghosts[-1] and kept[-1]


def test_where_a_passer_by_was_is_not_reported_once_unseen():
    """The cells a passer-by left stay in the map while they fade, but once their last
    evidence is older than unseen_report_s and the pair, in plain view there, saw
    nothing, they are not reported: the wearer is warned of where the person is, not
    where they were (here with no fading at all, miss_logodds 0)."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, miss_logodds=0.0))
    ghosts = _crossing(emap, 16)
    assert not any(ghosts)
    assert emap.confirmed().sum() > 0        # still in the map: only not reported
    kept = _crossing(EvidenceMap(EvidenceMapConfig(enabled=True, miss_logodds=0.0,
                                                   unseen_report_s=0.0)), 16)
    assert sum(kept) > 4


def test_a_thing_out_of_sight_is_not_faded():
    """A confirmed thing hidden behind a nearer one, or out of the image (no camera
    given), is kept in the map: only a thing in plain view that is not seen again fades.
    While hidden and unseen for longer than unseen_report_s it is not reported (the
    nearer thing is); seen again, it is reported at once."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    box = box_edges(4.0, 0.0, 0.5)
    for i in range(4):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True, CAM)
    assert emap.objects
    # a nearer thing with a textured face (matched all across) in front of it
    front = np.concatenate([box_edges(2.0, dy, 1.0, half_width=0.0)
                            for dy in np.arange(-0.3, 0.31, 0.05)])
    beyond = ground_grid(5.0, 7.0)
    for i in range(4, 10):           # hidden by a nearer thing in front of it
        emap.update(0.1 * i, PLANE, evidence([(front, RAISED, None), (beyond, GROUND, None)],
                                             0.0, occluders=[(2.0, 0.0, 1.0, 0.3)]),
                    None, True, CAM)
    kept = emap.pt_xy.reshape(-1, 2)[np.flatnonzero(emap.confirmed())]
    assert (kept[:, 0] > 3.5).any()
    assert not any(o.far_xy[:, 0].min() > 3.5 for o in emap.objects)
    emap.update(1.0, PLANE, evidence([(box, RAISED, None)], 0.0), None, True, CAM)
    assert any(o.far_xy[:, 0].min() > 3.5 for o in emap.objects)
    emap2 = EvidenceMap(EvidenceMapConfig(enabled=True))
    for i in range(4):
        emap2.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True, CAM)
    for i in range(4, 10):           # in plain view (ground seen beyond), not seen again
        emap2.update(0.1 * i, PLANE, evidence([(beyond, GROUND, None)], 0.0), None, True, CAM)
    assert not any(o.far_xy[:, 0].min() > 0.5 for o in emap2.objects)


def _near_passer_by(emap: EvidenceMap) -> list[bool]:
    """A person (clothes matched all across, 0.5 m wide) stands 1.25 m ahead for 1 s
    while the wearer stands still, then is gone; plain ground but for a sparse patch far
    beyond. The person's foot is below the image all along (the ground shows from 1.4 m
    on), their body up to the camera's height in it. Returns, per pair once the
    person has gone, whether anything is reported within 1.6 m ahead."""
    far_sparse = ground_grid(6.5, 7.5, -4.0, 4.0, step=0.25)
    body = np.concatenate([box_edges(1.25, dy, 1.7, half_width=0.0)
                           for dy in np.arange(-0.25, 0.26, 0.05)])
    out = []
    for i in range(20):
        parts = [(far_sparse, GROUND, None)] + ([(body, RAISED, None)] if i < 10 else [])
        emap.update(0.1 * i, PLANE, evidence(parts, 0.0), None, True, CAM)
        if i == 9:
            assert any(o.nearest_xy[0] < 1.6 for o in emap.objects)   # the person, there
        if i >= 10:
            out.append(any(o.nearest_xy[0] < 1.6 for o in emap.objects))
    return out


def test_a_passer_by_near_the_wearer_seen_above_the_foot_is_not_remembered(monkeypatch):
    """A thing near the wearer shows its upper part, not its foot: once the person has
    gone, their body's place in the image (the point at _SEEN_SHARE of its height) is
    in plain view with nothing seen there, so the cells fade and are not reported
    after unseen_report_s. Judged by the foot alone (the share 0), they are reported
    for as long as the wearer stands there."""
    import asmonc_vision.core.evidence_map as em
    gone = _near_passer_by(EvidenceMap(EvidenceMapConfig(enabled=True)))
    assert sum(gone) <= 4 and not any(gone[4:])
    monkeypatch.setattr(em, '_SEEN_SHARE', 0.0)
    assert all(_near_passer_by(EvidenceMap(EvidenceMapConfig(enabled=True))))


def _walk_past(emap: EvidenceMap, moved_in: bool, height: float = 0.4):
    """The wearer stands 2 s, then walks 2.25 m on. A thing 0.6 m wide and ``height``
    tall at 3 m: with ``moved_in`` a passer-by who steps in where the ground was seen (ground all
    round for 1 s first) and walks off unseen over plain ground; else a box that stands
    there from the first pair (its ground never seen) and is seen while in the image.
    Returns the objects reported
    within 1.2 m ahead once the spot is below the view (the last pair)."""
    far_sparse = ground_grid(6.5, 7.5, -4.0, 4.0, step=0.25)
    body = np.concatenate([box_edges(3.0, dy, height, half_width=0.0)
                           for dy in np.arange(-0.3, 0.31, 0.05)])
    x = 0.0
    for i in range(35):
        if i < 20:
            there = i >= 10 if moved_in else True
            parts = [(ground_grid(1.5, 6.0, step=0.05,
                                  holes=[(2.8, 3.6, -0.5, 0.5)] if there else []),
                      GROUND, None)]
            if there:
                parts.append((body, RAISED, None))
            motion = None
        else:                       # walks on 0.15 m a pair: the box is seen while in
            x += 0.15               # the image, nothing where the passer-by was
            parts = [(far_sparse, GROUND, None)] + ([] if moved_in else [(body, RAISED, None)])
            motion = step_motion(0.15)
        emap.update(0.1 * i, PLANE, evidence(parts, x), motion, i < 20, CAM)
    return [o for o in emap.objects if not o.is_drop and o.nearest_xy[0] < 1.2]


def test_a_thing_that_moved_in_is_not_remembered_out_of_view():
    """Raised evidence that begins where the ground was seen finely just before is a
    thing that moved in (moved_in_s): once out of the image (below it, walked up to) and
    not seen for unseen_report_s, it is not reported; a box the wearer walks up to
    (its ground never seen) is reported from memory there; with moved_in_s = 0 the
    passer-by is too (here with no fading at all, miss_logodds 0)."""
    cfg = dict(enabled=True, miss_logodds=0.0)
    assert not _walk_past(EvidenceMap(EvidenceMapConfig(**cfg)), moved_in=True)
    assert _walk_past(EvidenceMap(EvidenceMapConfig(**cfg)), moved_in=False)
    assert _walk_past(EvidenceMap(EvidenceMapConfig(**cfg, moved_in_s=0.0)), moved_in=True)


def test_a_step_of_the_ground_seen_as_ground_first_is_remembered_out_of_view():
    """The raised side of a kerb is ground: seen as ground (under the pixel threshold)
    before the kerb is measured, its raised evidence begins where the ground was seen.
    Lower than moved_in_min_height_m (0.3 m) it is no thing that moved in: once below
    the view it is reported from memory. Counted as one (moved_in_min_height_m 0) it is
    forgotten there, as a passer-by is, and the wearer standing at it hears "all
    clear"."""
    cfg = dict(enabled=True, miss_logodds=0.0)
    assert _walk_past(EvidenceMap(EvidenceMapConfig(**cfg)), moved_in=True, height=0.12)
    assert not _walk_past(EvidenceMap(EvidenceMapConfig(**cfg, moved_in_min_height_m=0.0)),
                          moved_in=True, height=0.12)


# ------------------------------------------------------------------ drops, ids, output
def test_a_drop_is_confirmed_as_a_drop():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    # the lower ground beyond a kerb 15 cm down at x = 4 m, seen from the walk
    lower = ground_grid(4.0, 5.0, -0.8, 0.8, step=0.1)
    lower[:, 2] = -0.15
    ground = ground_grid(1.5, 3.95, step=0.1)

    def scene(x):
        return [(lower, DROP, None), (ground, GROUND, None)]
    objs = walk(emap, scene, np.arange(0.0, 0.61, 0.12))
    drops = [o for o in objs[-1] if o.is_drop]
    assert len(drops) == 1 and not [o for o in objs[-1] if not o.is_drop]
    assert drops[0].height == pytest.approx(-0.15, abs=0.03)
    assert drops[0].nearest_xy[0] == pytest.approx(4.0 - 0.6, abs=0.08)


@pytest.mark.parametrize('width, reported', [(0.1, False), (0.2, False), (0.3, True),
                                             (1.6, True)])
def test_a_drop_is_wide(width, reported):
    """A strip of lower ground 15 cm down at x = 4 m, one cell deep, seen from a walk,
    0.1-1.6 m wide across the path: a drop the wearer can step off (a kerb, a step
    down) is wide, so a drop region of fewer than min_drop_cells (3) cells is not
    reported (a brow seen at a grazing angle leaves a cell or two of lower ground);
    with min_drop_cells 1 it is."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    lower = ground_grid(4.01, 4.05, 0.01, 0.01 + width - 0.02, step=0.05)
    lower[:, 2] = -0.15
    ground = ground_grid(1.5, 3.95, step=0.1)
    objs = walk(emap, lambda x: [(lower, DROP, None), (ground, GROUND, None)],
                np.arange(0.0, 0.61, 0.12))
    assert bool([o for o in objs[-1] if o.is_drop]) == reported
    one = EvidenceMap(EvidenceMapConfig(enabled=True, min_drop_cells=1))
    objs = walk(one, lambda x: [(lower, DROP, None), (ground, GROUND, None)],
                np.arange(0.0, 0.61, 0.12))
    assert [o for o in objs[-1] if o.is_drop]


@pytest.mark.parametrize('weighs', [True, False])
def test_ground_seen_for_long_outweighs_three_pairs_below_it(weighs):
    """Ground a few metres ahead seen for 7 pairs of a walk, then below the plane in 3
    (the far ground of a bend, or a plane off for a few pairs): with drop_weighs_ground
    the ground seen before outweighs them and no drop is reported; without, the three
    pairs alone confirm a drop. Lower ground seen only below the plane is a drop either way."""
    patch = ground_grid(4.0, 4.6, -0.6, 0.6, step=0.1)
    low = patch.copy()
    low[:, 2] = -0.15
    ground = ground_grid(1.5, 3.95, step=0.1)
    xs = np.arange(0.0, 1.4, 0.15)

    def scene(x):
        seen_low = x > 1.0
        return [(low if seen_low else patch, DROP if seen_low else GROUND, None),
                (ground, GROUND, None)]
    emap = EvidenceMap(EvidenceMapConfig(enabled=True, drop_weighs_ground=weighs))
    objs = walk(emap, scene, xs)
    assert bool([o for o in objs[-1] if o.is_drop]) == (not weighs)
    fresh = EvidenceMap(EvidenceMapConfig(enabled=True, drop_weighs_ground=weighs))
    objs = walk(fresh, lambda x: [(low, DROP, None), (ground, GROUND, None)], xs)
    assert [o for o in objs[-1] if o.is_drop]


@pytest.mark.parametrize('sigma, clears', [(0.01, True), (0.1, False)])
def test_only_ground_measured_finely_takes_from_drop_evidence(sigma, clears):
    """Ground seen in a cell takes free_logodds from its raised evidence whatever its
    noise, but from its drop evidence only when its height is known to
    drop_clear_max_sigma_m (3.3 cm: a 10 cm drop at 3 sigma): far ground measured
    coarsely cannot tell the lower ground beyond a drop from the ground before it."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    xy = np.tile([[3.02, 0.02]], (3, 1))
    drop = PairEvidence(xy=xy, height=np.full(3, -0.15), sigma_h=np.full(3, 0.02),
                        kind=np.full(3, DROP, np.int8))
    emap.update(0.0, PLANE, drop, None, True)
    cell = int(np.argmax(emap.L_d))
    before = float(emap.L_d.flat[cell])
    ground = PairEvidence(xy=xy, height=np.zeros(3), sigma_h=np.full(3, sigma),
                          kind=np.full(3, GROUND, np.int8))
    emap.update(0.0, PLANE, ground, None, True)
    after = float(emap.L_d.flat[cell])
    assert before > 0.5
    assert (after < before - 1.0) == clears
    assert (after == pytest.approx(before)) == (not clears)


def test_a_drop_seen_intermittently_is_reported_from_memory():
    """A drop's lower side is hidden by its edge on most pairs; pairs that see nothing
    there (ground matched only nearer) do not stop it being reported, however old its
    last evidence (unseen_report_s leaves drops alone); a raised thing in the same
    place is not reported once unseen for longer than unseen_report_s."""
    lower = ground_grid(4.0, 5.0, -0.8, 0.8, step=0.1)
    lower[:, 2] = -0.15
    ground = ground_grid(1.5, 3.95, step=0.1)
    box = box_edges(4.0, 0.0, 0.3, half_width=0.3)
    reported = {}
    for kind in (DROP, RAISED):
        emap = EvidenceMap(EvidenceMapConfig(enabled=True, miss_logodds=0.0))
        thing = lower if kind == DROP else box
        for i in range(4):
            emap.update(0.1 * i, PLANE, evidence([(thing, kind, None), (ground, GROUND, None)],
                                                 0.0), None, True, CAM)
        for i in range(4, 12):      # 0.8 s with only the nearer ground seen
            emap.update(0.1 * i, PLANE, evidence([(ground, GROUND, None)], 0.0), None, True,
                        CAM)
        reported[kind] = [o for o in emap.objects if o.is_drop == (kind == DROP)]
    assert reported[DROP] and not reported[RAISED]


def test_the_nearest_ground_in_view():
    """The bottom row's centre sight line of the paper's rig (pitched down 20 degrees,
    1.25 m up; the bottom row 21.7 degrees below the axis) meets the ground 1.40 m
    ahead; a camera pitched up 30 degrees sees no ground there."""
    assert nearest_ground_in_view(CAM, PLANE) == pytest.approx(
        H / math.tan(PITCH + math.atan((CAM.height - 1 - CAM.cy) / CAM.f)), abs=1e-6)
    up = math.radians(-30.0)
    tilted = MetricPlane(normal_up=np.array([0.0, -math.cos(up), -math.sin(up)]), height=H)
    assert nearest_ground_in_view(CAM, tilted) == math.inf


def _to_the_edge(hold: bool, stand_s: float = 0.0, end_x: float = 3.6) -> list:
    """A step 15 cm down at x = 4 m, confirmed from the walk while its edge is in view;
    from x = 2.5 m (the edge 1.5 m ahead, at the bottom of
    the view) the pair's plane is the lower ground's, against which the lower ground is
    ground seen free and nothing nearer is seen; the wearer walks to ``end_x`` and
    stands ``stand_s``. The objects of the last pair."""
    emap = EvidenceMap(EvidenceMapConfig(
        enabled=True, hold=dataclasses.replace(EvidenceMapConfig().hold, enabled=hold)))
    lower = ground_grid(4.0, 5.5, -0.8, 0.8, step=0.1)
    lower[:, 2] = -0.15
    seen_free = lower.copy()
    seen_free[:, 2] = 0.0
    ground = ground_grid(1.0, 3.95, step=0.1)

    def scene(x):
        if x < 2.45:
            return [(lower, DROP, None), (ground, GROUND, None)]
        return [(seen_free, GROUND, None)]
    xs = np.arange(0.0, end_x + 1e-9, 0.12)
    for i, x in enumerate(xs):
        motion = None if i == 0 else step_motion(x - xs[i - 1])
        emap.update(0.1 * i, PLANE, evidence(scene(x), x), motion, False, CAM)
    t0 = 0.1 * len(xs)
    for i in range(int(round(stand_s / 0.1))):
        emap.update(t0 + 0.1 * i, PLANE, evidence(scene(xs[-1]), xs[-1]), None, True, CAM)
    return list(emap.objects)


@pytest.mark.parametrize('hold', [True, False])
def test_a_drop_whose_edge_left_the_view_is_held_to_the_edge(hold):
    """rule_drop_hold: a confirmed drop whose nearest point is within margin_m of the
    nearest ground in view is not cleared by the lower ground seen free against a plane
    fitted beyond its edge, nor by standing before it (no decay): it is reported at the
    edge, 0.4 m ahead, after 3 s standing there. Without the rule the lower ground seen
    free clears it and the wearer is told the way is clear."""
    drops = [o for o in _to_the_edge(hold, stand_s=3.0) if o.is_drop]
    assert bool(drops) == hold
    if hold:
        assert drops[0].nearest_xy[0] == pytest.approx(4.0 - 3.6, abs=0.15)
        assert drops[0].height == pytest.approx(-0.15, abs=0.03)


def test_the_hold_takes_only_drops_confirmed_before_they_reached_the_view_bottom():
    """DropHold.cells on the paper's rig (nearest ground in view 1.40 m, reach 2.40 m
    with margin_m 1 m): a region first confirmed 3 m ahead is held once 2 m ahead; one
    first confirmed 2 m ahead (the far side of a crest, confirmed against a plane fitted
    to the rising ground before the brow) is not; once the wearer has passed the held
    one's nearest point its cells nearer than the reach are let go, and it is not held
    again."""
    hold = DropHold(EvidenceMapConfig().hold)
    before = np.zeros(100, bool)
    a, b = np.array([10, 11, 12]), np.array([20, 21])

    def pair(xa, xb=None):
        cells = a if xb is None else np.concatenate([a, b])
        region = np.array([5] * 3 + ([] if xb is None else [6] * 2))
        x = np.asarray(list(xa) + ([] if xb is None else list(xb)), float)
        w = np.stack([x, np.zeros_like(x)], 1)
        return hold.cells(cells, region, w, lambda p: p, CAM, PLANE, before,
                          np.full(x.size, -0.2))

    held, gone = pair([3.0, 3.1, 3.2])
    assert held.size == 0 and gone.size == 0 and before[a].all()
    held, gone = pair([2.0, 2.1, 2.2], [2.0, 2.1])
    assert held.tolist() == a.tolist() and gone.size == 0 and not before[b].any()
    held, gone = pair([-0.1, 0.5, 3.0])
    assert held.size == 0 and gone.tolist() == [10, 11]
    held, gone = pair([0.5, 0.6, 1.6])
    assert held.size == 0 and gone.size == 0


def test_stepping_down_lets_go_the_lower_ground_held_apart_but_not_a_second_step():
    """DropHold.cells (reach 2.40 m, ``level_tol_m`` 6 cm): a drop 20 cm deep is held in
    two regions (the part below the view, 5, and the part in view, 6, as the map
    reports them), with a second step 40 cm down beyond (7). Once the wearer has passed
    region 5's nearest point, region 6's cells nearer than the reach are let go too
    and none of its cells is held again, as they slip below the view; the second step
    stays held."""
    hold = DropHold(EvidenceMapConfig().hold)
    before = np.zeros(100, bool)
    cells = np.array([10, 11, 20, 21, 22, 30, 31])
    region = np.array([5, 5, 6, 6, 6, 7, 7])
    h = np.array([-0.20, -0.21, -0.22, -0.19, -0.23, -0.41, -0.40])

    def pair(x):
        x = np.asarray(x, float)
        w = np.stack([x, np.zeros_like(x)], 1)
        return hold.cells(cells, region, w, lambda p: p, CAM, PLANE, before, h)

    pair([3.0, 3.1, 3.5, 3.6, 3.7, 4.0, 4.1])            # all confirmed from afar
    held, gone = pair([1.0, 1.1, 1.5, 1.6, 2.6, 2.0, 2.1])
    assert held.tolist() == [10, 11, 20, 21, 22, 30, 31] and gone.size == 0
    held, gone = pair([-0.1, 0.0, 0.4, 0.5, 2.6, 0.9, 1.0])
    assert gone.tolist() == [10, 11, 20, 21]
    assert held.tolist() == [30, 31]
    assert not before[[10, 11, 20, 21, 22]].any() and before[[30, 31]].all()
    # region 6's far cell slips below the view: not held
    held, gone = pair([-0.3, -0.2, 0.2, 0.3, 1.0, 0.7, 0.8])
    assert held.tolist() == [30, 31] and gone.size == 0


def test_a_held_drop_is_let_go_once_walked_past():
    """Past its edge (the wearer stepped down) the drop is behind the wearer and not
    held or reported."""
    assert not [o for o in _to_the_edge(True, end_x=4.8) if o.is_drop]


@pytest.mark.parametrize('pixels, taken', [(1, False), (2, True), (3, True), (4, True)])
def test_a_cell_takes_drop_evidence_from_min_drop_pixels(pixels, taken):
    """A cell takes a pair's drop evidence when it holds at least min_drop_pixels (2)
    drop pixels of that pair and no raised one, whatever their number beyond that (odd
    or even)."""
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    xy = np.tile([[3.02, 0.02]], (pixels, 1))
    ev = PairEvidence(xy=xy, height=np.full(pixels, -0.15), sigma_h=np.full(pixels, 0.02),
                      kind=np.full(pixels, DROP, np.int8))
    emap.update(0.0, PLANE, ev, None, True)
    assert (emap.L_d.max() > 0.0) == taken
    raised = PairEvidence(xy=np.vstack([xy, [[3.02, 0.02]]]),
                          height=np.append(ev.height, 0.2), sigma_h=np.full(pixels + 1, 0.02),
                          kind=np.append(ev.kind, np.int8(RAISED)))
    emap2 = EvidenceMap(EvidenceMapConfig(enabled=True))
    emap2.update(0.0, PLANE, raised, None, True)
    assert emap2.L_d.max() <= 0.0            # a raised pixel in the cell: no drop there


def test_ids_are_stable_and_distinct():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    a, b = box_edges(4.0, -1.0, 0.3), box_edges(5.0, 1.0, 0.3)
    ground = ground_grid(1.5, 8.0, step=0.1, holes=[(4.0, 4.3, -1.15, -0.85),
                                                    (5.0, 5.3, 0.85, 1.15)])

    def scene(x):
        return [(a, RAISED, None), (b, RAISED, None), (ground, GROUND, None)]
    objs = walk(emap, scene, np.arange(0.0, 1.81, 0.12),
                occluders=[(4.0, -1.0, 0.3, 0.15), (5.0, 1.0, 0.3, 0.15)])
    ids = [{(o.nearest_xy[1] > 0): o.object_id for o in obs} for obs in objs[4:]]
    assert all(len(i) == 2 for i in ids)
    assert all(i == ids[0] for i in ids) and ids[0][True] != ids[0][False]


def test_objects_as_obstacles_confirm_detector_reports():
    from asmonc_vision.core.gpod import GpodObstacle

    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    box = box_edges(3.0, 0.0, 0.3)
    for i in range(4):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True, CAM)
    (_, ob), = nearest(emap.objects)

    def report(x, y, track_id):
        foot = to_optical(np.array([[x, y, 0.0]]), 0.0)[0]
        return GpodObstacle(position=foot + 0.3 * PLANE.normal_up, height=0.3, range=x,
                            bearing=math.atan2(y, x), width=0.3, disparity_excess=3.0,
                            confidence=0.5, roi=(100, 100, 20, 20), num_edge_pixels=30,
                            string_ids=np.zeros(0, np.int32), track_id=track_id)
    on_box, elsewhere = report(3.05, 0.0, 7), report(4.5, -1.0, 8)
    out = objects_to_obstacles(emap.objects, CAM, PLANE, [on_box, elsewhere], 0.3)
    assert [o.track_id for o in out] == [7]
    assert out[0].confidence == pytest.approx(ob.confidence)
    assert out[0].position == pytest.approx(on_box.position)
    # with no report to confirm, the map places the obstacle itself
    own = objects_to_obstacles(emap.objects, CAM, PLANE, [elsewhere], 0.3)
    assert len(own) == 1 and own[0].track_id == ob.object_id + MAP_ID_BASE
    assert own[0].range == pytest.approx(3.0, abs=0.06)
    assert own[0].height == pytest.approx(0.3, abs=0.03)
    x, y, w, h = own[0].roi
    u, v = CAM.project_left(to_optical(np.array([[3.0, 0.0, 0.15]]), 0.0))
    assert x <= u[0] <= x + w and y <= v[0] <= y + h


def test_a_report_on_ground_the_map_has_seen_is_not_confirmed_by_a_thing_nearby():
    """A detector report 0.4 m in front of a confirmed box, on ground the map saw finely
    all around it (a pair's misfit of the ground near a kerb), is not confirmed by the
    box's cells within attach_m; a report at the box's own front is."""
    from asmonc_vision.core.gpod import GpodObstacle

    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    box = box_edges(3.0, 0.0, 0.3)
    ground = ground_grid(1.5, 4.5, holes=[(2.9, 3.4, -0.3, 0.3)])

    def scene(x):
        return [(box, RAISED, None), (ground, GROUND, None)]
    xs = np.arange(0.0, 0.61, 0.12)
    walk(emap, scene, xs)
    cam_x = float(xs[-1])
    assert emap.objects

    def report(x, y):
        foot = to_optical(np.array([[x, y, 0.0]]), cam_x)[0]
        return GpodObstacle(position=foot + 0.1 * PLANE.normal_up, height=0.1,
                            range=x - cam_x, bearing=0.0, width=0.3, disparity_excess=1.0,
                            confidence=0.5, roi=(100, 100, 20, 20), num_edge_pixels=30,
                            string_ids=np.zeros(0, np.int32), track_id=5)
    front, misfit = report(2.95, 0.0), report(2.55, 0.0)
    feet = np.array([[2.95 - cam_x, 0.0], [2.55 - cam_x, 0.0]])
    seen = emap.ground_seen_around(feet, 0.1 * (len(xs) - 1), 3.0)
    assert seen.tolist() == [False, True]
    # seen long ago, it no longer counts
    assert not emap.ground_seen_around(feet, 0.1 * (len(xs) - 1) + 3.5, 3.0).any()
    # points off the grid (a far report, a wall at the map's edge) are not seen ground
    far = np.array([[50.0, 0.0], [2.95 - cam_x, -40.0], [-30.0, 0.0], [2.55 - cam_x, 0.0]])
    assert emap.ground_seen_around(far, 0.1 * (len(xs) - 1), 3.0).tolist() == [
        False, False, False, True]
    def judge(xy):
        return emap.ground_seen_around(xy, 0.1 * (len(xs) - 1), 3.0)
    out = objects_to_obstacles(emap.objects, CAM, PLANE, [misfit], 0.5, 0.0, judge)
    assert [o.track_id for o in out] != [5]
    assert out[0].range == pytest.approx(3.0 - cam_x, abs=0.1)
    # without the map's ground, the misfit is taken for the box
    assert [o.track_id for o in objects_to_obstacles(emap.objects, CAM, PLANE, [misfit],
                                                      0.5)] == [5]
    assert [o.track_id for o in objects_to_obstacles(emap.objects, CAM, PLANE, [front],
                                                      0.5, 0.0, judge)] == [5]


def test_a_thing_beside_the_path_that_reaches_into_it_is_reported_there():
    """A kerb running along the path whose nearest point (its corner) is just beside the
    walking corridor: the detector's report of the corner is confirmed, and the kerb's
    part in the corridor farther on is reported too (the alarm sees one point of each
    report)."""
    from asmonc_vision.core.gpod import GpodObstacle

    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    # the kerb's side face along the path: from (2.0, 0.55) to (3.5, 0.40) (angled in)
    s = np.linspace(0.0, 1.0, 16)
    kerb = np.concatenate([box_edges(2.0 + 1.5 * a, 0.55 - 0.15 * a, 0.1, 0.0)[:1]
                           for a in s])
    for i in range(4):
        emap.update(0.1 * i, PLANE, evidence([(kerb, RAISED, None)], 0.0), None, True, CAM)
    assert emap.objects
    foot = to_optical(np.array([[2.0, 0.55, 0.0]]), 0.0)[0]
    corner = GpodObstacle(position=foot + 0.1 * PLANE.normal_up, height=0.1,
                          range=float(np.hypot(2.0, 0.55)), bearing=math.atan2(0.55, 2.0),
                          width=0.2, disparity_excess=1.0, confidence=0.5,
                          roi=(100, 100, 20, 20), num_edge_pixels=30,
                          string_ids=np.zeros(0, np.int32), track_id=7)
    out = objects_to_obstacles(emap.objects, CAM, PLANE, [corner], 0.3, 0.5)
    assert [o.track_id for o in out][0] == 7
    (part,) = [o for o in out if o.track_id != 7]
    assert part.track_id >= CORRIDOR_ID_BASE
    lateral = part.range * math.sin(part.bearing)
    assert lateral <= 0.5 and part.range == pytest.approx(np.hypot(2.5, 0.5), abs=0.15)
    # off: only the corner
    assert [o.track_id for o in objects_to_obstacles(emap.objects, CAM, PLANE, [corner],
                                                     0.3, 0.0)] == [7]


def test_occupancy_and_placement_in_the_camera():
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    assert emap.grid_in_camera() is None
    box = box_edges(3.0, 0.0, 0.3)
    for i in range(3):
        emap.update(0.1 * i, PLANE, evidence([(box, RAISED, None)], 0.0), None, True)
    occ = emap.occupancy()
    assert occ.dtype == np.int8 and occ.shape == (emap.n, emap.n)
    assert occ.max() >= 80 and (occ == -1).mean() > 0.9
    R, corner = emap.grid_in_camera()
    iy, ix = np.unravel_index(int(np.argmax(occ)), occ.shape)
    c = emap.config.cell_m
    centre = corner + R @ np.array([(ix + 0.5) * c, (iy + 0.5) * c, 0.0])
    box_foot = to_optical(np.array([[3.0, 0.0, 0.0]]), 0.0)[0]
    assert np.linalg.norm(centre - box_foot) < 0.25


def test_settings_are_checked():
    with pytest.raises(ValueError):
        EvidenceMapConfig(cell_m=0.0)
    with pytest.raises(ValueError):
        EvidenceMapConfig(report_logodds=5.0, max_logodds=3.0)


# ------------------------------------------------------------------ the stage
@pytest.mark.slow
def test_perception_with_the_map_off_is_the_detector():
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.core.gpod import GpodDetector
    from asmonc_vision.core.perception import Perception
    from conftest import BAGS

    frames = load_frames(BAGS / 'static_obstacles', 24)[20:24]
    p = Perception(map_config=EvidenceMapConfig(enabled=False))
    d = GpodDetector()
    for f in load_frames(BAGS / 'static_obstacles', 24):
        a = p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
        b = d.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
    assert p.map is None
    assert [(o.range, o.track_id) for o in a.obstacles] == \
        [(o.range, o.track_id) for o in b.obstacles]
    assert frames


def test_perception_with_the_map_reports_confirmed_obstacles():
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.core.perception import Perception
    from conftest import BAGS

    p = Perception(map_config=EvidenceMapConfig(enabled=True))
    frames = load_frames(BAGS / 'static_obstacles', 26)
    for f in frames:
        res = p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
    assert 'map' in res.timings_ms
    # the boxes appear at 2 s, standing still: confirmed after still_min_frames
    assert len(res.obstacles) >= 3
    assert all(o.confidence > 0.5 for o in res.obstacles)
    # each match's contrary rivals weigh its evidence: 1 - their share of the support
    c = res.features.contrary_rival_share
    assert c is not None and c.shape == res.features.d.shape
    assert (c >= 0).all() and (c < 1).all() and (c > 0).any() and (c == 0).any()
    ev = p.evidence(res, frames[-1].cam)
    assert ev.weight is not None
    inv = 1.0 - ev.weight
    assert (np.abs(inv[:, None] - c[None, :].astype(float)).min(1) < 1e-6).all()



@pytest.mark.parametrize('pass_height', [1.0, 0.0])
def test_a_tall_report_passes_the_map_unconfirmed(pass_height):
    """A detector report at least pass_height_m tall where the map holds nothing (a
    person walking towards the wearer: new cells every pair) is published; a low one
    there is not (a mismatch); with pass_height_m 0 neither is (chains of moving reports
    off: `test_moving_reports.py`)."""
    import dataclasses
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.core.perception import Perception
    from conftest import BAGS

    p = Perception(map_config=EvidenceMapConfig(enabled=True, pass_height_m=pass_height,
                                                moving_min_height_m=0.0))
    real = p.detector.process

    def with_two_more(*a, **k):
        r = real(*a, **k)
        if not r.obstacles:
            return r
        ob = r.obstacles[0]
        aside = ob.position + np.array([2.5, 0.0, 0.0])       # 2.5 m to its right
        more = (dataclasses.replace(ob, position=aside, height=1.6, track_id=901),
                dataclasses.replace(ob, position=aside + np.array([0.0, 0.0, 1.0]),
                                    height=0.3, track_id=902))
        return dataclasses.replace(r, obstacles=r.obstacles + more)

    p.detector.process = with_two_more
    for f in load_frames(BAGS / 'static_obstacles', 26):
        res = p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
    assert p.map.placed_pairs >= p.map_config.min_placed_pairs
    ids = {o.track_id for o in res.obstacles}
    assert (901 in ids) == (pass_height > 0)
    assert 902 not in ids
    assert len(ids - {901}) >= 3                 # the boxes, confirmed by the map


# ------------------------------------------------------------------ the node
def test_detector_node_publishes_the_map(ros_context):
    from nav_msgs.msg import OccupancyGrid
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from asmonc_vision.nodes.detector_node import MAP_QOS
    from conftest import BAGS, spin_until
    from test_detector_node import detector_graph, load_frames as node_frames

    frames = node_frames(BAGS / 'static_obstacles', [0, 1, 2, 3, 30, 31, 32, 33])
    with detector_graph(ros_context, [Parameter('map.enabled', value=True),
                                      Parameter('publish_debug_image', value=False)]) as g:
        det, ex, send, got = g
        listener = Node('map_listener', context=ros_context)
        maps = []
        listener.create_subscription(OccupancyGrid, '/obstacle_map', maps.append, MAP_QOS)
        ex.add_node(listener)
        try:
            assert spin_until(ex, lambda: det.pub_map.get_subscription_count() >= 1)
            for i, f in enumerate(frames):
                send(*f)
                assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
            assert spin_until(ex, lambda: len(maps) >= 4, timeout=5)
        finally:
            ex.remove_node(listener)
            listener.destroy_node()
    m = maps[-1]
    n = det.perception.map.n
    assert (m.info.width, m.info.height) == (n, n)
    assert m.info.resolution == pytest.approx(0.1)
    assert m.header.frame_id == 'stereo_left_optical_frame'
    data = np.array(m.data, np.int8)
    assert data.size == n * n and data.min() >= -1 and data.max() <= 100
    assert (data >= 80).sum() >= 3             # the boxes, standing still: confirmed
    # the obstacles published are the map's: confident, and ids given
    last = got['obstacles'][-1].obstacles
    assert len(last) >= 3 and all(o.confidence > 0.5 and o.id > 0 for o in last)


def test_a_passer_by_reported_pair_after_pair_passes_the_map_a_blinking_one_does_not():
    """A 0.8 m detector report that comes 0.1 m nearer each pair where the map holds
    nothing (a passer-by's legs) is published from the third pair of its chain on; one
    that shows in every other pair only (a mismatch that comes and goes) never is."""
    import dataclasses
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.core.perception import Perception
    from conftest import BAGS

    p = Perception(map_config=EvidenceMapConfig(enabled=True))
    real = p.detector.process
    n = {'i': 0}

    def with_two_more(*a, **k):
        r = real(*a, **k)
        if not r.obstacles:          # the bag's first pairs show nothing to copy
            return r
        i = n['i']
        n['i'] += 1
        ob = r.obstacles[0]
        rg = 4.0 - 0.1 * i
        def at(r, b, tid):           # on the right (b < 0) or left, where no box is
            return dataclasses.replace(ob, position=np.array([-r * np.sin(b), 0.4,
                                                              r * np.cos(b)]),
                                       height=0.8, range=r, bearing=b, track_id=tid)
        more = [at(rg, -0.8, 903)] + ([at(2.0, 0.9, 904)] if i % 2 == 0 else [])
        return dataclasses.replace(r, obstacles=r.obstacles + tuple(more))

    p.detector.process = with_two_more
    seen = []
    for f in load_frames(BAGS / 'static_obstacles', 26):
        res = p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
        if n['i'] >= 1:
            seen.append({o.track_id for o in res.obstacles})
    assert p.map.placed_pairs >= p.map_config.min_placed_pairs
    assert len(seen) >= 5
    assert [903 in s for s in seen] == [False, False] + [True] * (len(seen) - 2), seen
    assert not any(904 in s for s in seen)


@pytest.mark.parametrize('enter', ['all', 'ground', 'none'])
def test_a_pair_whose_plane_was_carried_over_while_moving_enters_what_the_setting_names(
        enter):
    """A pair whose refit failed (its plane carried over from the pair before) while the
    rig moved enters into the map what ``carried_plane_evidence`` names: all its evidence,
    its ground pixels alone, or nothing; one whose plane was carried while the rig stood
    still (the plane is still right) enters all of it."""
    import dataclasses
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.core.perception import Perception
    from conftest import BAGS

    p = Perception(map_config=EvidenceMapConfig(enabled=True, carried_plane_evidence=enter))
    real_process, real_update = p.detector.process, p.map.update
    n, kinds = {'i': 0}, {}

    def carried(*a, **k):
        r = real_process(*a, **k)
        i = n['i']
        n['i'] += 1
        if r.status == 'tracking' and i % 3 == 1:        # carried over, moving
            return dataclasses.replace(r, plane_updated=False, still=False)
        if r.status == 'tracking' and i % 3 == 2:        # carried over, standing
            return dataclasses.replace(r, plane_updated=False, still=True)
        return r

    def update(stamp_s, plane, ev, *a):
        if ev is not None:
            kinds[n['i'] - 1] = set(np.unique(ev.kind).tolist())
        return real_update(stamp_s, plane, ev, *a)

    p.detector.process, p.map.update = carried, update
    for f in load_frames(BAGS / 'static_obstacles', 27):
        p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
    tracked = range(21, 27)                           # the boxes' tracks counted
    moving = [i for i in tracked if i % 3 == 1]
    standing = [i for i in tracked if i % 3 == 2]
    # the bag's pairs see its boxes raised and the pavement as ground
    assert all({GROUND, RAISED} <= kinds[i] for i in standing), kinds
    if enter == 'none':
        assert not set(moving) & set(kinds)
    elif enter == 'ground':
        assert all(kinds[i] <= {GROUND, NONE} and GROUND in kinds[i] for i in moving), kinds
    else:
        assert all({GROUND, RAISED} <= kinds[i] for i in moving), kinds


def test_after_the_map_was_cleared_reports_chained_over_pairs_go_out_a_ghost_does_not():
    """At a start the detector's reports go out as they are; once the map had confirmed
    and was cleared (as it is when the camera's motion is unknown while walking), until
    it has placed min_placed_pairs pairs in a row again the detector's raised reports go
    out once chained over unmapped_frames pairs: the bundled bag's boxes, seen before
    the clear, go on at once; a mismatch seen in one pair only does not."""
    import dataclasses
    from asmonc_vision.core.gpod import GpodObstacle
    from asmonc_vision.core.perception import Perception
    from asmonc_vision.io.frames import load_frames
    from conftest import BAGS

    cfg = EvidenceMapConfig(enabled=True)
    p = Perception(map_config=cfg)
    real_process = p.detector.process
    ghost = GpodObstacle(position=np.array([3.7, 0.9, 5.3]), height=0.31, range=6.5,
                         bearing=-0.6, width=0.5, disparity_excess=3.0, confidence=0.9,
                         roi=(100, 150, 40, 10), num_edge_pixels=30,
                         string_ids=np.zeros(0, np.int32))
    clear_at, ghost_at = 30, 31
    own, out, placed, i = [], [], [], {'n': 0}

    def process(*a, **k):
        r = real_process(*a, **k)
        if i['n'] == ghost_at:
            r = dataclasses.replace(r, obstacles=r.obstacles + (ghost,))
        own.append(len(r.obstacles))
        return r

    p.detector.process = process
    for f in load_frames(BAGS / 'static_obstacles', 40):
        if i['n'] == clear_at:
            p.map.reset()
        out.append(p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns).obstacles)
        placed.append(p.map.placed_pairs)
        i['n'] += 1
    assert p.past_start
    # before the clear the map had confirmed: the detector's first reports went out
    # only after min_placed_pairs pairs had been placed, or at once if it had
    first = own.index(next(k for k in own if k > 0))
    assert first < clear_at and own[first + 1:clear_at].count(0) == 0, own
    unmapped = [j for j in range(clear_at, 40) if placed[j] < cfg.min_placed_pairs]
    assert ghost_at in unmapped and len(unmapped) >= 3, placed
    assert all(o.height != 0.31 for reps in out for o in reps)
    # the boxes, chained since before the clear, go out through it; a report new since
    # the clear does not at once
    assert all(own[clear_at - 1] <= len(out[j]) < own[j] for j in (clear_at, ghost_at)), (
        own, out)
    assert all(len(out[j]) >= own[clear_at - 1] for j in unmapped), (own, out)


@pytest.mark.parametrize('start_raw_s', [60.0, 1.0])
def test_at_a_start_the_detectors_reports_go_out_as_they_are(start_raw_s):
    """Until the map has first placed min_placed_pairs pairs in a row (here never) the
    detector's reports, a one-pair ghost too, go out as they are for start_raw_s after
    the first plane: at a start nothing is held back (the paper's small box standing
    still is found from the first pairs). A map that has not taken over by then lacks
    the motion: the reports go out chained, the boxes on, the ghost not."""
    import dataclasses
    from asmonc_vision.core.gpod import GpodObstacle
    from asmonc_vision.core.perception import Perception
    from asmonc_vision.io.frames import load_frames
    from conftest import BAGS

    p = Perception(map_config=EvidenceMapConfig(enabled=True, min_placed_pairs=1000,
                                                start_raw_s=start_raw_s))
    real_process, n = p.detector.process, {'i': 0}
    ghost = GpodObstacle(position=np.array([3.7, 0.9, 5.3]), height=0.31, range=6.5,
                         bearing=-0.6, width=0.5, disparity_excess=3.0, confidence=0.9,
                         roi=(100, 150, 40, 10), num_edge_pixels=30,
                         string_ids=np.zeros(0, np.int32))
    own = []

    def process(*a, **k):
        r = real_process(*a, **k)
        n['i'] += 1
        if n['i'] == 25:
            r = dataclasses.replace(r, obstacles=r.obstacles + (ghost,))
        own.append(r.obstacles)
        return r

    p.detector.process = process
    frames = load_frames(BAGS / 'static_obstacles', 30)
    out = [p.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns).obstacles
           for f in frames]
    assert any(own)
    if start_raw_s > 10:
        assert not p.past_start
        assert out == own
        return
    assert p.past_start
    t = np.array([(f.stamp_ns - frames[0].stamp_ns) * 1e-9 for f in frames])
    assert t[24] > start_raw_s + 0.1                  # the ghost comes after the start
    early = t < start_raw_s - 0.1
    assert [o for o, e in zip(out, early) if e] == [o for o, e in zip(own, early) if e]
    assert all(o.height != 0.31 for reps in out for o in reps)
    assert all(len(out[j]) == len(own[j]) for j in range(26, 30)), (own, out)


def test_the_compiled_guard_gives_the_dilated_grids_cells():
    """`map_kernels.near_kernel` (`EvidenceMap._near`: marked cells within a square of
    given cells) gives the dilated grid's booleans at the cells (`map_grid.dilate`),
    at the grid's borders and corners too, for the guards' radii."""
    from asmonc_vision.core import map_grid, map_kernels
    if map_kernels.nb_near is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(7)
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    n = emap.n
    corners = np.array([0, n - 1, n * (n - 1), n * n - 1, n, 2 * n - 1], np.int64)
    for size in (0, 1, 5, 40, 400):
        marked = np.concatenate((rng.integers(0, n * n, size), corners[:size % 4]))
        cells = np.concatenate((rng.integers(0, n * n, 300), corners, marked[:3] + 1))
        cells = np.clip(cells, 0, n * n - 1).astype(np.int64)
        for radius in (0, 1, 2, 3):
            got = map_kernels.nb_near(marked.astype(np.int64), n, cells, radius)
            want = map_grid.dilate(emap._grid_of(marked), radius).reshape(-1)[cells] > 0
            np.testing.assert_array_equal(got, want)


def test_the_compiled_surest_weights_give_numpys():
    """`map_kernels.surest_kernel` (`EvidenceMap._surest`: the surest pixel's weight per
    cell) gives the maxima ``np.maximum.at`` takes into a zero grid, NaN included."""
    from asmonc_vision.core import map_kernels
    if map_kernels.nb_surest is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(11)
    n2 = 180 * 180
    for size in (0, 1, 30, 2000):
        flat = rng.integers(0, n2, size).astype(np.int64)
        flat[: size // 2] = flat[0] if size else 0
        weight = rng.random(size)
        if size > 5:
            weight[3] = np.nan
            weight[4] = -0.5
        cells = np.unique(np.concatenate((flat[::3], rng.integers(0, n2, 7))))
        got = map_kernels.nb_surest(flat, weight, cells)
        best = np.zeros(n2)
        with np.errstate(invalid='ignore'):
            np.maximum.at(best, flat, weight)
        np.testing.assert_array_equal(got, best[cells])


def test_the_compiled_pixel_counts_give_numpys():
    """`map_kernels.count_kernel` (the compiled `EvidenceMap._count`, into grids kept
    between pairs) gives numpy's bincounts and cells, pair after pair (the cells of the
    pair before cleared), and the map entered through either holds the same cells."""
    from asmonc_vision.core import map_kernels
    if map_kernels.nb_count is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(5)
    emap = EvidenceMap(EvidenceMapConfig(enabled=True))
    n2 = emap.n * emap.n
    for size in (0, 1, 50, 3000, 400):
        flat = rng.integers(0, n2, size).astype(np.int64)
        flat[: size // 3] = flat[0] if size else 0          # a crowded cell
        kind = rng.choice(np.array([RAISED, DROP, GROUND, NONE], np.int8), size)
        sure = (kind == GROUND) & (rng.random(size) < 0.5)     # ground of known height
        got = emap._count(flat, kind, sure)
        got_pair = emap._pair_count.copy()
        want = emap._count(flat, kind, sure, use_kernel=False)
        for a, b in zip(got, want):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(got_pair, emap._pair_count)
    # a walk's evidence entered with the kernel and without: the same map
    kernel = map_kernels.nb_count
    maps = []
    for use in (kernel, None):
        map_kernels.nb_count = use
        try:
            m = EvidenceMap(EvidenceMapConfig(enabled=True))
            for i in range(6):
                box = box_edges(3.0 - 0.1 * i, 0.2, 0.3)
                ground = ground_grid(1.0, 5.0, step=0.1)
                m.update(0.1 * i, PLANE, evidence([(box, RAISED, None), (ground, GROUND, None)],
                                                  0.0), None, True)
            maps.append(m)
        finally:
            map_kernels.nb_count = kernel
    a, b = maps
    assert a.objects and len(a.objects) == len(b.objects)
    for x, y in zip(a.objects, b.objects):
        assert x.object_id == y.object_id and x.height == y.height
        assert x.fresh_pixels == y.fresh_pixels and x.confidence == y.confidence
    for name in ('L_r', 'L_d', 'h_x', 'h_P', 'pt_xy', 'two_views'):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize('threads', [1, 0])
def test_grid_operations_on_the_box_give_the_whole_grids(threads):
    """`map_grid.dilate` and `map_grid.label_regions` worked out on the box of the
    non-zero cells (found from the mask, or from its cells given) give what they give
    over the whole grid: the same cells and the
    regions in the same order (cv2.connectedComponents' labels), with OpenCV on one
    thread and on its default."""
    import cv2

    from asmonc_vision.core import map_grid
    old = cv2.getNumThreads()
    cv2.setNumThreads(threads)
    try:
        rng = np.random.default_rng(11)
        for trial in range(60):
            mask = np.zeros((180, 180), bool)
            for _ in range(rng.integers(0, 12)):
                y, x = rng.integers(0, 180, 2)
                h, w = rng.integers(1, 9, 2)
                mask[y:y + h, x:x + w] = rng.random((min(h, 180 - y), min(w, 180 - x))) < 0.7
            if trial % 10 == 0:
                mask[0, 179] = mask[179, 0] = True               # at the grid's corners
            for r in (0, 1, 2, 3):
                np.testing.assert_array_equal(map_grid.dilate(mask, r),
                                              map_grid.dilate(mask, r, whole=True))
                got = map_grid.label_regions(mask, r)
                known = map_grid.label_regions(mask, r, cells=np.flatnonzero(mask))
                want = map_grid.label_regions(mask, r, whole=True)
                assert len(got) == len(want) == len(known)
                for a, b, k in zip(got, want, known):
                    assert a.dtype == b.dtype == k.dtype
                    np.testing.assert_array_equal(a, b)
                    np.testing.assert_array_equal(k, b)
    finally:
        cv2.setNumThreads(old)


@pytest.mark.parametrize('cells', [5, 400])
def test_the_compiled_sight_line_test_at_its_edges(cells):
    """`map_kernels.rays_kernel`, which tests only the sight lines near a cell's bearing
    when it has many cells, counts as numpy's path tests every line: cells at the
    camera's foot, nearer than ``ray_lateral_m``, behind the wearer and beside it (bearings
    near ±180° and ±90°), sight lines to a ground point at the foot (no direction) and
    lines exactly along a cell's bearing."""
    from asmonc_vision.core import map_kernels
    if map_kernels.nb_rays is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(17)
    lat = 0.03
    r = np.concatenate([[0.0, 0.01, 0.029, 0.031, 0.3, 0.31], rng.uniform(0.0, 8.0, cells)])
    phi = np.concatenate([[0.0, np.pi, -np.pi, np.pi / 2, -np.pi / 2, 3.1],
                          rng.uniform(-np.pi, np.pi, cells)])
    p = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    top = rng.uniform(-0.5, 1.5, p.shape[0])
    ground = np.column_stack([rng.uniform(-2.0, 8.0, 700), rng.uniform(-4.0, 4.0, 700)])
    k = min(40, cells)
    ground[:k] = p[6:6 + k] * rng.uniform(1.0, 3.0, (k, 1))    # along the cells' bearings
    ground[40:44] = 0.0                                         # at the foot
    ground[44:48] = 1e-7
    R = np.hypot(ground[:, 0], ground[:, 1])
    gh = ground / np.maximum(R, 1e-6)[:, None]
    left, right = map_kernels.nb_rays(p, top, gh, R, 1.4, lat, 0.2)
    # numpy's path (`map_sight.seen_through`): each cell against each line
    along = p[:, 0:1] * gh[None, :, 0] + p[:, 1:2] * gh[None, :, 1]
    lateral = gh[None, :, 0] * p[:, 1:2] - gh[None, :, 1] * p[:, 0:1]
    with np.errstate(divide='ignore', invalid='ignore'):
        h_ray = 1.4 * (1.0 - along / R[None, :])
        through = ((np.abs(lateral) <= lat) & (along > 0.3) & (along < R[None, :] - 0.2)
                   & (h_ray < top[:, None]))
    assert through.sum() > (0 if cells < 10 else 20)
    np.testing.assert_array_equal(left, np.count_nonzero(through & (lateral > 0), axis=1))
    np.testing.assert_array_equal(right, np.count_nonzero(through & (lateral <= 0), axis=1))


def _drop(oid: int, cells) -> MapObject:
    """A confirmed drop region of the map at ``cells`` ((k, 2) points in G, m), 20 cm
    deep, nearest point its nearest cell."""
    g = np.asarray(cells, float).reshape(-1, 2)
    near = g[int(np.argmin(np.hypot(g[:, 0], g[:, 1])))]
    return MapObject(object_id=oid, is_drop=True, nearest_xy=near, far_xy=g, height=-0.2,
                     width=0.3, confidence=0.9, cells=len(g), fresh_pixels=5, age_s=0.0)


def _joint(x0: float, y: float, length: float = 0.6) -> np.ndarray:
    """Cells of lower ground along a slab joint running ahead from (x0, y)."""
    n = int(round(length / 0.1))
    return np.column_stack([x0 + 0.1 * np.arange(n), np.full(n, y)])


def test_a_drop_seen_on_both_sides_of_the_path_is_reported_where_its_edge_crosses_it():
    """step_down 900011 (chest rig): the lower ground beyond a step down is matched along
    a slab joint on either side of the path, nothing in the middle; the edge between the
    two sides' nearest points crosses the walking corridor, and is reported there."""
    from asmonc_vision.core.map_reports import SPAN_ID_BASE, drop_spans
    from asmonc_vision.core.map_settings import DropSpanConfig

    left, right = _drop(6, _joint(4.34, 0.95)), _drop(7, _joint(4.23, -1.04))
    cfg = DropSpanConfig()
    (ob, xy), = drop_spans([left, right], cfg, 0.5)
    assert ob is right                       # the nearer side gives its id
    assert xy[1] == 0.0 and xy[0] == pytest.approx(4.34 - 0.11 * 0.95 / 1.99, abs=1e-6)
    out = objects_to_obstacles([left, right], CAM, PLANE, span=cfg,
                               corridor_half_width=0.5)
    (edge,) = [o for o in out if o.track_id >= SPAN_ID_BASE]
    assert edge.track_id == 7 + SPAN_ID_BASE and edge.height == pytest.approx(-0.2)
    assert abs(edge.bearing) < 1e-6 and edge.range == pytest.approx(xy[0], abs=0.05)
    # off, or without the walking corridor: the two sides alone
    for kw in ({'span': DropSpanConfig(enabled=False), 'corridor_half_width': 0.5},
               {'span': cfg, 'corridor_half_width': 0.0}):
        assert all(o.track_id < SPAN_ID_BASE
                   for o in objects_to_obstacles([left, right], CAM, PLANE, **kw))


def test_drops_that_do_not_make_an_edge_across_the_path_are_not_joined():
    from asmonc_vision.core.map_reports import drop_spans
    from asmonc_vision.core.map_settings import DropSpanConfig

    cfg = DropSpanConfig()
    left, right = _drop(1, _joint(4.3, 0.95)), _drop(2, _joint(4.2, -1.0))
    # one side only
    assert drop_spans([left], cfg, 0.5) == []
    # too far apart across the path, or too skewed to be an edge across it
    assert drop_spans([left, _drop(2, _joint(4.2, -2.2))], cfg, 0.5) == []
    assert drop_spans([left, _drop(2, _joint(3.0, -1.0))], cfg, 0.5) == []
    assert len(drop_spans([left, _drop(2, _joint(3.4, -1.0))], cfg, 0.5)) == 1
    # a drop already in the corridor is reported as it is
    assert drop_spans([left, right, _drop(3, _joint(4.5, 0.1))], cfg, 0.5) == []
    # drops along both sides of a raised walkway: their lower ground goes on towards
    # the wearer, below the view (a region of its own)
    below = _drop(4, _joint(1.0, 0.95, 2.5))
    assert drop_spans([left, right, below], cfg, 0.5) == []
    assert len(drop_spans([left, right, below], DropSpanConfig(min_lead_m=5.0), 0.5)) == 1
    # the map saw ground at the crossing (a ramp between two kerbs down)
    seen = []

    def ramp(xy):
        seen.append(np.array(xy))
        return np.array([True, False])
    assert drop_spans([left, right], cfg, 0.5, ramp) == []
    assert seen[0][:, 1].tolist() == [0.0, 0.0]
    assert seen[0][1, 0] - seen[0][0, 0] == pytest.approx(cfg.ground_margin_m)
    assert len(drop_spans([left, right], cfg, 0.5, lambda xy: np.zeros(len(xy), bool))) == 1
    # raised regions do not count
    raised = dataclasses.replace(right, is_drop=False, height=0.2)
    assert drop_spans([left, raised], cfg, 0.5) == []


def test_the_compiled_height_update_gives_numpys():
    """`map_kernels.heights_kernel` (the compiled `enter_heights` of `EvidenceMap._enter`)
    leaves the cells' heights, variances, evidence points and last hits exactly as its
    numpy path does: crowded cells, ties and NaN heights, new and known cells, cells of
    a kind not entered."""
    from asmonc_vision.core import map_kernels
    if map_kernels.nb_heights is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(11)
    n2 = 400
    for size in (0, 1, 7, 300, 3000):
        flat = rng.integers(0, n2, size).astype(np.int64)
        flat[: size // 3] = flat[0] if size else 0          # a crowded cell
        kind = rng.choice(np.array([RAISED, DROP, GROUND, NONE], np.int8), size)
        h = np.round(rng.normal(0.0, 0.3, size), 2)          # ties
        h[rng.random(size) < 0.05] = np.nan
        sh = rng.uniform(0.0, 0.1, size)
        w = rng.normal(0.0, 3.0, (size, 2))
        cells = [np.unique(flat[kind == k]) for k in (RAISED, DROP)]
        raised, dropc = (c[rng.random(c.size) < 0.8] for c in cells)
        state = (rng.normal(0, 1, n2).astype(np.float32),
                 np.where(rng.random(n2) < 0.5, np.inf, rng.uniform(0, 0.1, n2)).astype(np.float32),
                 rng.normal(0, 3, (n2, 2)).astype(np.float32), rng.uniform(0, 9, n2))
        got = [a.copy() for a in state]
        want = [a.copy() for a in state]
        map_kernels.enter_heights(flat, kind, h, sh, w, raised, dropc, *got, 12.5)
        map_kernels.enter_heights(flat, kind, h, sh, w, raised, dropc, *want, 12.5,
                                  use_kernel=False)
        for a, b in zip(got, want):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_bearing_bins_are_the_clipped_degrees():
    """`map_sight.bearing_bin` gives ndarray.clip's bins byte for byte (int64),
    behind, beside, at the camera's foot and for NaN or infinite points."""
    from asmonc_vision.core.map_sight import BINS as _BINS
    from asmonc_vision.core.map_sight import bearing_bin as _bearing_bin
    rng = np.random.default_rng(2)
    xy = np.vstack([rng.normal(0.0, 3.0, (500, 2)), [[0.0, 0.0], [-0.0, 0.0], [np.nan, 1.0],
                                                     [np.inf, 0.0], [1.0, -np.inf],
                                                     [-1.0, 1e-12], [-1.0, -1e-12]]])
    with np.errstate(invalid='ignore'):
        b = np.degrees(np.arctan2(xy[:, 1], xy[:, 0])) + 90.0
        want = b.astype(np.int64).clip(0, _BINS - 1)
        got = _bearing_bin(xy)
    assert got.dtype == want.dtype and got.tobytes() == want.tobytes()


def _any_box(mask, pad=0, align=1):
    """The bounding box of `map_grid.nonzero_box` through mask.any (its former way)."""
    rows = np.flatnonzero(mask.any(axis=1))
    if not rows.size:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    y0, x0 = max(int(rows[0]) - pad, 0), max(int(cols[0]) - pad, 0)
    y0 -= y0 % align
    x0 -= x0 % align
    return (y0, min(int(rows[-1]) + pad + 1, mask.shape[0]),
            x0, min(int(cols[-1]) + pad + 1, mask.shape[1]))


def test_nonzero_box_is_the_box_of_the_rows_and_columns_with_any():
    """`map_grid.nonzero_box` from the non-zero cells' flat indices gives the box of
    the rows and columns that hold any (mask.any), for bool, uint8 and float masks
    (NaN counts), empty, full, single cells, borders, strided views, pads and aligns."""
    from asmonc_vision.core import map_grid
    rng = np.random.default_rng(6)
    masks = [np.zeros((180, 180), bool), np.ones((7, 5), np.uint8), np.zeros((1, 1), bool)]
    for _ in range(300):
        n0, n1 = rng.integers(1, 60, 2)
        m = rng.random((n0, n1)) < rng.choice([0.002, 0.02, 0.3])
        masks += [m, m.astype(np.uint8), m[::2, 1::3]]
    f = np.zeros((9, 11))
    f[3, 7] = np.nan
    f[5, 2] = -0.5
    masks += [f, np.eye(6, dtype=bool)[:, ::-1]]
    for m in masks:
        for pad, align in ((0, 1), (1, 1), (2, 2), (3, 2), (40, 1)):
            assert map_grid.nonzero_box(m, pad, align) == _any_box(m, pad, align)


def _footway(x0: float, x1: float, level: float = 0.18, rng=None) -> tuple:
    """Confirmed raised cells of a footway from x0 to x1 ahead (G, m), 0.1 m apart,
    0.6 m wide, at ``level`` +- 2 cm; its kerb face at x0, 8 cm."""
    rng = rng or np.random.default_rng(0)
    xs, ys = np.meshgrid(np.arange(x0, x1, 0.1), np.arange(-0.3, 0.31, 0.1))
    xy = np.stack([xs.ravel(), ys.ravel()], 1)
    h = level + rng.uniform(-0.02, 0.02, len(xy))
    h[np.isclose(xy[:, 0], x0)] = 0.08
    return xy, h


def test_step_up_lets_go_the_footway_walked_onto_and_keeps_what_stands_on_it():
    """stepped_onto (behind_m 0.15, depth 0.45, level_tol 6 cm, margin 1 m; the view from
    1.4 m): a 18 cm footway confirmed from below the kerb, whose kerb is now 0.6 m
    behind the wearer, is let go up to the reach (2.4 m) with its kerb face; a post
    60 cm high on it and the footway beyond the reach stay."""
    cfg = EvidenceMapConfig().step_up
    xy, h = _footway(-0.6, 3.0)
    xy = np.vstack([xy, [[1.0, 0.0], [1.1, 0.0]]])
    h = np.concatenate([h, [0.6, 0.6]])
    go, walked = stepped_onto(xy, h, 1.4, cfg)
    assert walked.sum() >= 4 * 5 and go[walked].all()
    assert go[(xy[:, 0] < 2.4) & (h < 0.3)].all()
    assert not go[xy[:, 0] >= 2.4].any() and not go[h > 0.5].any()


@pytest.mark.parametrize('case', ['before', 'wall', 'disabled', 'few'])
def test_step_up_needs_raised_ground_of_a_step_walked_over(case):
    """Nothing is let go when the wearer stands before the kerb (its cells begin 5 cm
    ahead), when what lies behind the wearer is a wall's height (the map's pose error),
    with the rule disabled, or with fewer than min_cells walked over."""
    cfg = EvidenceMapConfig().step_up
    x0, level = (0.05, 0.18) if case == 'before' else (-0.6, 0.18)
    if case == 'wall':
        level = 1.2
    xy, h = _footway(x0, 3.0, level)
    if case == 'disabled':
        cfg = dataclasses.replace(cfg, enabled=False)
    if case == 'few':
        keep = ~((xy[:, 0] < -0.1) & (np.abs(xy[:, 1]) > 0.05))
        xy, h = xy[keep], h[keep]
        cfg = dataclasses.replace(cfg, min_cells=6)
    go, walked = stepped_onto(xy, h, 1.4, cfg)
    assert not go.any() and not walked.any()


def test_the_map_lets_go_the_footway_under_the_wearer():
    """EvidenceMap: confirmed footway cells around the wearer (entered from below its
    kerb) are not reported after a pair once the wearer stands 0.5 m onto it, and a low
    box apart from it still is; with rule_step_up disabled the footway is reported at
    the wearer's feet."""
    for enabled in (True, False):
        cfg = EvidenceMapConfig()
        cfg = dataclasses.replace(cfg, step_up=dataclasses.replace(cfg.step_up,
                                                                   enabled=enabled))
        m = EvidenceMap(cfg)
        m.update(0.0, PLANE, None, None, True, CAM)
        xy, h = _footway(-0.5, 1.2)
        # a 10 cm box apart from the footway, 2 m ahead, stays
        xy = np.vstack([xy, [[2.0, 0.0], [2.1, 0.0]]])
        h = np.concatenate([h, [0.1, 0.1]])
        flat, inside = m._cells(m.to_world(xy))
        assert inside.all()
        m.L_r.reshape(-1)[flat] = 3.0
        m.two_views.reshape(-1)[flat] = True
        m.h_x.reshape(-1)[flat] = h
        m.h_P.reshape(-1)[flat] = 1e-4
        m.pt_xy.reshape(-1, 2)[flat] = m.to_world(xy)
        m.last_hit_s.reshape(-1)[flat] = 0.0
        objs = [o for o in m.update(0.1, PLANE, None, (np.eye(3), np.zeros(3)), True, CAM)
                if not o.is_drop]
        assert len(objs) == (1 if enabled else 2)
        near = min(float(np.hypot(*o.nearest_xy)) for o in objs)
        assert near == (pytest.approx(2.0, abs=0.1) if enabled else
                        pytest.approx(0.0, abs=0.2))
