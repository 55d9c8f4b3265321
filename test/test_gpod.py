"""GPOD detector (core.gpod) and its debug drawing (core.draw).

The synthetic scenes are ray cast here (independently of asmonc_vision.sim): a textured
flat ground seen by the rig of Molton et al. (f = 300 px, B = 0.35 m, 320 x 240, 1.25 m
high, pitched down 20 degrees), optionally with textured boxes standing on it or a step
down in the ground.
"""
import dataclasses
import math

import cv2
import numpy as np
import pytest

from asmonc_vision.core.alarm import AlarmConfig
from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import override
from asmonc_vision.core.draw import draw_debug, excess_colours
from asmonc_vision.core.gpod import GpodConfig, GpodDetector, cluster_points_2d
from asmonc_vision.core.gpod import faces as gpod_faces
from asmonc_vision.core.gpod import grouping as gpod_grouping
from asmonc_vision.core.gpod import kernels as gk
from asmonc_vision.core.gpod import kernels_geometry as gkg
from asmonc_vision.core.gpod import nearest as gpod_nearest
from asmonc_vision.core.ground_plane import cyclopean_height

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)
HEIGHT = 1.25
PITCH = 20.0


def _texture_pyramid(rng, size=2048, sigma=1.5, contrast=45.0, mean=120.0):
    t = rng.normal(0.0, 1.0, (size, size)).astype(np.float32)
    t = cv2.GaussianBlur(t, (0, 0), sigma)
    t = mean + t / t.std() * contrast
    return [t] + [cv2.GaussianBlur(t, (0, 0), 0.6 * 2 ** i) for i in range(5)]


def _rotation(pitch_deg):
    """Columns: the camera's x, y, z axes in the level frame (X right, Y down, Z ahead)."""
    t = np.radians(pitch_deg)
    return np.stack([[1.0, 0.0, 0.0], [0.0, np.cos(t), -np.sin(t)],
                     [0.0, np.sin(t), np.cos(t)]], axis=1)


def render_pair(boxes=(), step=None, seed=0, noise=2.0, ss=2, texel=0.01, advance=0.0):
    """Rectified stereo pair of the level-frame scene.

    Args:
        boxes: (x0, x1, z0, z1, height) boxes standing on the ground, level frame, m.
        step: (z_step, depth): the ground drops by ``depth`` m beyond ``Z = z_step``.
        advance: the rig's place ahead of the level frame's origin, m (a walk forward).
    Returns:
        (left, right) uint8 images.
    """
    rng = np.random.default_rng(seed)
    ground = _texture_pyramid(rng)
    boxtex = _texture_pyramid(rng, mean=150.0)
    rot = _rotation(PITCH)
    h, w = CAM.height * ss, CAM.width * ss
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    uu = (uu + 0.5) / ss - 0.5
    vv = (vv + 0.5) / ss - 0.5
    rays = np.stack([(uu - CAM.cx) / CAM.f, (vv - CAM.cy) / CAM.f, np.ones_like(uu)], -1) @ rot.T
    out = []
    for cam_x in (0.0, CAM.baseline):
        o = rot @ np.array([cam_x, 0.0, 0.0]) + np.array([0.0, 0.0, advance])
        ry = rays[..., 1]
        with np.errstate(divide='ignore', invalid='ignore'):
            t = np.where(ry > 1e-9, (HEIGHT - o[1]) / ry, np.inf)
            if step is not None:
                z_step, depth = step
                beyond = o[2] + t * rays[..., 2] >= z_step
                t = np.where(beyond & (ry > 1e-9), (HEIGHT + depth - o[1]) / ry, t)
        hit = o + np.where(np.isfinite(t), t, 0.0)[..., None] * rays
        tex_a, tex_b = hit[..., 0], hit[..., 2]
        which = np.where(np.isfinite(t), 1, 0)
        for (x0, x1, z0, z1, bh) in boxes:
            lo = np.array([x0, HEIGHT - bh, z0])
            hi = np.array([x1, HEIGHT, z1])
            with np.errstate(divide='ignore', invalid='ignore'):
                t1 = (lo - o) / rays
                t2 = (hi - o) / rays
            tn = np.nanmax(np.minimum(t1, t2), axis=-1)
            tf = np.nanmin(np.maximum(t1, t2), axis=-1)
            hb = (tf >= tn) & (tn > 0) & (tn < t)
            q = o + tn[..., None] * rays
            axis = np.argmax(np.minimum(t1, t2), axis=-1)
            a = np.where(axis == 0, q[..., 2], q[..., 0]) + 7.0
            b = np.where(axis == 1, q[..., 2], q[..., 1]) + 3.0
            t = np.where(hb, tn, t)
            tex_a = np.where(hb, a, tex_a)
            tex_b = np.where(hb, b, tex_b)
            which = np.where(hb, 2, which)
        img = np.full((h, w), 90.0, np.float32)
        # Crude mip-mapping: texture blur from the pixel footprint, against aliasing.
        level = np.clip(np.floor(np.log2(np.maximum(t / (CAM.f * ss) / texel, 1e-9)) + 1),
                        0, 5).astype(int)
        mx = (tex_a / texel).astype(np.float32)
        my = (tex_b / texel).astype(np.float32)
        for k, pyr in ((1, ground), (2, boxtex)):
            for li, tex in enumerate(pyr):
                sel = (which == k) & (level == li)
                if sel.any():
                    img[sel] = cv2.remap(tex, mx, my, cv2.INTER_LINEAR,
                                         borderMode=cv2.BORDER_WRAP)[sel]
        img = cv2.resize(img, (CAM.width, CAM.height), interpolation=cv2.INTER_AREA)
        if cam_x > 0:
            img = img * 1.05 + 4.0                          # right camera gain and offset
        img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
        out.append(np.clip(img, 0, 255).astype(np.uint8))
    return out[0], out[1]


def to_left_optical(p_level):
    """Level-frame point (m) to the left optical frame."""
    return _rotation(PITCH).T @ np.asarray(p_level, float)


BOX = (0.3, 0.7, 4.0, 4.4, 0.25)        # 25 cm high, 4 m ahead, slightly right


_STEP_M = 0.2          # the walk's step between frames, m


@pytest.fixture(scope='module')
def walk():
    """The box scene seen from four places on a walk towards it, a step apart."""
    return [render_pair(boxes=[BOX], seed=2, advance=_STEP_M * (i + 1)) for i in range(4)]


@pytest.fixture(scope='module')
def scenes():
    free = render_pair(seed=2)
    box = render_pair(boxes=[BOX], seed=2)
    free2 = render_pair(seed=3)
    return {'free': free, 'box': box, 'free2': free2}


def _calibrated(pair, config=None, frames=3):
    det = GpodDetector(config or GpodConfig())
    results = [det.process(pair[0], pair[1], CAM) for _ in range(frames)]
    return det, results


# ---------------------------------------------------------------- configuration
def test_config_defaults_and_validation():
    c = GpodConfig()
    assert c.threshold.px == 1.7 and c.plane.update == 'refit'
    assert c.threshold.mode == 'sigma' and c.threshold.ceiling_px == 1.7
    assert c.matching.pmf_disparity_gradient_limit == 1.0
    with pytest.raises(ValueError, match='threshold.floor_px'):
        override(GpodConfig(), {'threshold.floor_px': 2.0, 'threshold.ceiling_px': 1.0})
    with pytest.raises(ValueError, match='threshold.mode'):
        override(GpodConfig(), {'threshold.mode': 'adaptive'})
    with pytest.raises(ValueError, match='threshold.px'):
        override(GpodConfig(), {'threshold.px': -1.0})
    with pytest.raises(ValueError, match='plane.update'):
        override(GpodConfig(), {'plane.update': 'kalman'})
    with pytest.raises(ValueError, match='matching.min_range_m'):
        override(GpodConfig(), {'matching.min_range_m': 50.0,
                                'matching.search_max_range_m': 20.0,
                                'detection.max_range_m': 10.0})
    with pytest.raises(ValueError, match='detection.max_range_m'):
        override(GpodConfig(), {'detection.max_range_m': 30.0, 'matching.search_max_range_m': 20.0})
    with pytest.raises(TypeError):
        override(GpodConfig(), {'drops.enabled': 'yes'})
    with pytest.raises(ValueError, match="GpodConfig has no setting 'threshold_k'"):
        override(GpodConfig(), {'threshold_k': 3.0})
    for f in dataclasses.fields(GpodConfig):
        assert f.metadata.get('description')


# ---------------------------------------------------------------- detection
def test_initialises_then_tracks_the_ground(scenes):
    det, results = _calibrated(scenes['free'])
    assert [r.status for r in results] == ['initialising', 'initialising', 'tracking']
    r = results[-1]
    assert [x.frame_index for x in results] == [1, 2, 3]
    assert r.plane_abc.shape == (3,) and r.plane_cov.shape == (3, 3)
    assert r.plane_num_features > 500 and r.plane_residual_rms < 0.5
    assert abs(r.metric_plane.height - HEIGHT) < 0.03
    up = to_left_optical([0.0, -1.0, 0.0])
    assert np.degrees(np.arccos(r.metric_plane.normal_up @ up)) < 1.0
    assert det.calibrated_plane is not None
    for stage in ('edges', 'matching', 'plane', 'obstacles', 'total'):
        assert r.timings_ms[stage] >= 0.0


def test_no_obstacles_on_flat_ground(scenes):
    for name in ('free', 'free2'):
        det, results = _calibrated(scenes[name])
        for _ in range(3):
            r = det.process(*scenes[name], CAM)
            assert r.status == 'tracking'
            # This texture (blurred noise, soft at near range) has one two-pixel string
            # of badly located edges ~2 px above the plane in 'free2': the least evidence
            # the detector acts on (detection.min_obstacle_pixels), detected with low confidence,
            # and reported below the alarm's min_confidence (0.3): the same images again
            # are one view, whose evidence does not add up over its frames (nor would two
            # pixels' reach it in tracks.confidence_frames (3) views). Nothing more may be
            # there.
            assert all(o.num_edge_pixels <= 2 and o.confidence < 0.2
                       for o in r.detections), [(o.height, o.range, o.roi) for o in r.obstacles]
            assert all(o.confidence < AlarmConfig().min_confidence for o in r.obstacles)
            assert len(r.obstacles) <= (0 if name == 'free' else 1)
            f = r.features
            assert len(f) > 1000
            ground = np.abs(f.excess) < r.threshold_px
            assert ground.mean() > 0.85
            assert f.is_obstacle.sum() <= 2 * len(r.obstacles)


def _views_confidence_check(det, pairs, motions, k, noisy):
    """Feeds ``pairs`` to ``det`` (fresh image noise each frame) with ``motions`` and
    checks every reported track's confidence: 1 - prod(1 - c) over its latest k views,
    each view's c the largest of its detections' in it (a view: a frame that moved and
    the still frames after it). Returns how many reports combined several views, and
    the largest of (report confidence - the largest detection confidence of its track)."""
    views: dict[int, list[tuple[int, float]]] = {}
    view, combined, over = 0, 0, 0.0
    for (left, right), motion in zip(pairs, motions):
        left, right = (np.clip(x + noisy.normal(0.0, 3.0, x.shape), 0, 255).astype(np.uint8)
                       for x in (left, right))
        r = det.process(left, right, CAM, motion=motion)
        view += not r.still
        for ob in r.obstacles:
            # detected now: its detection, by its strings (a track kept seen by another
            # detection's overlapping image region while the rig stands still has none)
            if ob.age_s == 0.0 and len(ob.string_ids):
                d = [o for o in r.detections
                     if np.array_equal(np.sort(o.string_ids), np.sort(ob.string_ids))]
                assert len(d) == 1
                seen = views.setdefault(ob.track_id, [])
                if seen and seen[-1][0] == view:
                    seen[-1] = (view, max(seen[-1][1], d[0].confidence))
                else:
                    seen.append((view, d[0].confidence))
            seen = [c for _, c in views[ob.track_id][-k:]]
            assert ob.confidence == pytest.approx(1.0 - np.prod([1.0 - c for c in seen]),
                                                  abs=1e-9)
            combined += len(seen) > 1 and max(seen) < 1.0
            over = max(over, ob.confidence - max(c for _, c in views[ob.track_id]))
    return combined, over


def test_track_confidence_accumulates_over_views_not_over_still_frames(scenes, walk):
    """A tracked obstacle's confidence is 1 - prod(1 - c) over its latest
    track_confidence_frames views, c a view's largest detection confidence; with 1, the
    latest view's alone. While the rig stands still its frames are one view: they repeat
    the same matches (and their errors), so the confidence is never more than that of
    its best detection. Walking, each frame is a new view, and the evidence adds up."""
    forward = to_left_optical([0.0, 0.0, _STEP_M])
    for k in (1, 3):
        det, _ = _calibrated(scenes['free'],
                             override(GpodConfig(), {'tracks.confidence_frames': k}))
        noisy = np.random.default_rng(5)
        combined, over = _views_confidence_check(det, [scenes['box']] * 6, [None] * 6, k,
                                                 noisy)
        assert combined == 0 and over <= 1e-9
        det, _ = _calibrated(scenes['free'],
                             override(GpodConfig(), {'tracks.confidence_frames': k}))
        combined, over = _views_confidence_check(
            det, walk, [(np.eye(3), forward)] * len(walk), k, noisy)
        assert (combined > 0) == (k > 1)                     # weak tracks seen again
        assert (over > 0.01) == (k > 1)
    with pytest.raises(ValueError, match='tracks.confidence_frames'):
        override(GpodConfig(), {'tracks.confidence_frames': 0})


def test_a_detection_of_weak_edges_has_the_confidence_of_its_weighted_pixels():
    """The confidence's pixel count weighs each pixel as the edge-string rule does: a
    weak edge (strength below obstacle_min_strength) counts (strength / it)^2 of a
    pixel. A few weak mismatched pixels (a tile's faint texture) then stay below the
    alarm's min_confidence until they are seen again; strong edges count fully."""
    cfg = GpodConfig()
    small = (0.3, 0.36, 3.0, 3.06, 0.06)                 # a 6 cm cube, 3 m ahead
    free, box = render_pair(seed=2), render_pair(boxes=[small], seed=2)

    def faded(pair, k):
        return [np.clip(120.0 + (x.astype(float) - 120.0) * k, 0, 255).astype(np.uint8)
                for x in pair]

    weakened = 0
    for k in (1.0, 0.35):                                # full contrast, faded to 35 %
        det, _ = _calibrated(faded(free, k))
        r = det.process(*faded(box, k), CAM)
        assert r.status == 'tracking' and r.detections
        f = r.features
        for o in r.detections:
            px = f.is_obstacle & np.isin(f.string_id, o.string_ids)
            assert px.sum() == o.num_edge_pixels
            w = np.minimum(f.strength[px] / cfg.detection.min_strength, 1.0) ** 2
            full = min(1.0, o.num_edge_pixels / cfg.detection.confidence_full_pixels)
            assert o.confidence <= min(1.0, w.sum() / cfg.detection.confidence_full_pixels) + 1e-9
            if k == 1.0:
                assert o.confidence == pytest.approx(full, abs=0.02)
            weakened += o.confidence < full - 0.02
    assert weakened > 0                                  # the faded cube's edges are weak


@pytest.mark.parametrize('mode', ['refit', 'fixed'])
def test_finds_the_box(scenes, mode):
    det, _ = _calibrated(scenes['free'], override(GpodConfig(), {'plane.update': mode}))
    r = det.process(*scenes['box'], CAM)
    assert r.status == 'tracking'
    assert len(r.obstacles) == 1, [(o.height, o.range) for o in r.obstacles]
    ob = r.obstacles[0]
    x0, x1, z0, z1, bh = BOX
    top_nearest = to_left_optical([0.5 * (x0 + x1), HEIGHT - bh, z0])
    assert np.linalg.norm(ob.position - top_nearest) < 0.3
    assert abs(ob.height - bh) < 0.3 * bh
    assert abs(ob.range - z0) < 0.3
    assert -0.2 < ob.bearing < 0.0                     # slightly to the right
    assert 0.1 < ob.width < 0.6
    assert ob.disparity_excess > r.threshold_px
    assert 0.5 < ob.confidence <= 1.0
    assert not ob.is_drop and ob.num_edge_pixels >= 10
    # The roi covers most of the box's image (silhouette edges may stay unmatched).
    x, y, w, h = ob.roi
    corners = [to_left_optical([xx, HEIGHT - hh, zz]) for xx in (x0, x1) for hh in (0.0, bh)
               for zz in (z0, z1)]
    us = [CAM.f * p[0] / p[2] + CAM.cx for p in corners]
    vs = [CAM.f * p[1] / p[2] + CAM.cy for p in corners]
    inter = (max(0.0, min(x + w, max(us)) - max(x, min(us)))
             * max(0.0, min(y + h, max(vs)) - max(y, min(vs))))
    union = w * h + (max(us) - min(us)) * (max(vs) - min(vs)) - inter
    assert inter / union > 0.4
    # Features: obstacle pixels are flagged and lie inside the roi.
    f = r.features
    assert f.is_obstacle.sum() >= ob.num_edge_pixels
    inside = ((f.u_left >= x - 1) & (f.u_left <= x + w) & (f.v >= y) & (f.v <= y + h))
    assert np.all(inside[f.is_obstacle])


def test_finds_a_step_down():
    free = render_pair(seed=4)
    drop = render_pair(step=(3.5, 0.3), seed=4)
    det, _ = _calibrated(free)
    r = det.process(*drop, CAM)
    assert r.status == 'tracking'
    drops = [o for o in r.obstacles if o.is_drop]
    assert drops, [(o.height, o.range) for o in r.obstacles]
    nearest = min(drops, key=lambda o: o.range)
    assert -0.45 < nearest.height < -0.15
    # Placed at the nearest visible lower ground: the ray grazing the brink (3.5 m) meets
    # the lower ground 0.3 m down at 3.5 (1.25 + 0.3) / 1.25 = 4.34 m.
    assert 4.25 < nearest.range < 4.6
    # The brink runs across the view: its nearest point is straight ahead (the median
    # direction of the drop's strings, used before, gave -2.9 degrees).
    assert abs(math.degrees(nearest.bearing)) < 1.5, math.degrees(nearest.bearing)
    assert nearest.disparity_excess < -r.threshold_px
    assert not [o for o in r.obstacles if not o.is_drop and o.range < 8.0]


def test_brink_bearings_at_the_foot_of_the_perpendicular():
    from asmonc_vision.core.gpod.grouping import _brink_bearings
    rng = np.random.default_rng(3)
    # A kerb 3 m ahead, turned 10 degrees: its nearest point lies at -10 degrees.
    a = math.radians(-10.0)
    n, t = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    along = np.linspace(-1.2, 1.4, 12)
    brink = 3.0 * n + along[:, None] * t + rng.normal(0.0, 0.02, (12, 1)) * n
    beyond = 3.0 * n + np.array([[0.3], [-0.8]]) * t + np.array([[0.4], [0.6]]) * n
    pts = np.vstack([brink, beyond])            # two strings start on the lower ground
    group = np.zeros(len(pts), np.int64)
    got = _brink_bearings(pts, group, np.array([0.3]))
    assert abs(math.degrees(got[0]) + 10.0) < 1.0, math.degrees(got[0])
    # Only the kerb's left part in view: its nearest seen end.
    part = brink[along > 0.5]
    end = part[np.argmin(part @ t)]
    got = _brink_bearings(part, np.zeros(len(part), np.int64), np.array([0.3]))
    assert abs(got[0] - math.atan2(end[1], end[0])) < math.radians(1.5)
    # Kept: too few points, or no line (a scatter).
    scatter = 3.0 * n + rng.normal(0.0, 0.5, (12, 2))
    for p in (brink[:3], scatter):
        np.testing.assert_array_equal(
            _brink_bearings(p, np.zeros(len(p), np.int64), np.array([0.3])), [0.3])


def test_plane_stays_on_the_ground_stood_on_before_a_step_down():
    """Standing 2 m before a 15 cm step down, the lower ground fills most of the view
    (more features, even in the nearer half by disparity) and once took the plane: the
    near ground then stood 15 cm 'high' and was reported as obstacles."""
    free = render_pair(seed=4)
    drop = render_pair(step=(2.0, 0.15), seed=4)
    det, _ = _calibrated(free)
    for k in range(8):
        r = det.process(*drop, CAM)
        assert r.status == 'tracking'
        assert abs(r.metric_plane.height - HEIGHT) < 0.03, (k, r.metric_plane.height)
        assert not [o for o in r.obstacles if not o.is_drop], k
    assert [o for o in r.obstacles if o.is_drop]


def test_calibrates_from_one_frame_when_the_walk_starts_at_once():
    """A plane fitted to the features of several frames taken from different poses is
    tilted between them (3 degrees on walk_stop_turn, whose wearer walks from the first
    frame: obstacles everywhere in the first tracked frame): when the window's joint
    plane and its latest frame's disagree, the latest frame alone calibrates."""
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.eval.evaluation import plane_error
    from conftest import BAGS
    det = GpodDetector(GpodConfig())
    first = None
    for f in load_frames(BAGS / 'walk_stop_turn', 4):
        r = det.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
        if r.metric_plane is not None and first is None:
            first = (r, f)
    assert first is not None
    angle, dh = plane_error(first[0].metric_plane, first[1].truth_plane)
    assert angle < 0.3 and abs(dh) < 0.01, (angle, dh)
    assert first[0].frame_index == 3 and not first[0].still


def test_a_calibration_keeps_the_joint_plane_that_holds_the_latest_frame():
    """When the window's joint plane and its latest frame's own disagree, the latest
    frame's own fit calibrates (the nearer of two grounds: before a kerb down), unless
    the two put the camera more than ``plane.init_max_step_m`` apart in height and the
    joint plane holds more of the latest frame's features. A frame of faint ground,
    clutter and a short line of near mismatches (35-50 px) can have, weighted by
    disparity cubed, that line for its own plane: the camera 0.49 m up (a level chest
    rig 1.40 m up), while 105 of its 300 features lie on the joint plane and 50 on the
    line (RANSAC draws the line or not, as on a walk). Over ten draws the joint plane is
    kept every time; with the bound at 0 (always the frame's own) the line is taken in
    at least one. (Two planes 15 cm apart, before a kerb down: the frame's own,
    test_the_paving_beyond_a_kerb_down_is_no_obstacle.)"""
    cam = StereoCamera(f=560.0, cx=319.5, cy=239.5, baseline=0.12, width=640, height=480)
    b = cam.baseline / 1.40
    ground = np.array([0.0, b, -b * cam.cy])           # d = b (v - cy): level, 1.40 m up
    line = np.array([0.009, 0.247, -55.2])             # a plane 0.49 m below the camera

    def calibrated_height(step: float, seed: int) -> float:
        rng = np.random.default_rng(seed)

        def features(n, abc, rows, sigma):
            u, v = rng.uniform(20, 620, n), rng.uniform(*rows, n)
            return u, v, abc[0] * u + abc[1] * v + abc[2] + rng.normal(0, sigma, n)

        frames = [features(400, ground, (260, 470), 0.15) for _ in range(2)]
        parts = [features(105, ground, (260, 470), 0.15),
                 features(50, line, (370, 420), 0.05)]
        cu, cv_ = rng.uniform(20, 620, 145), rng.uniform(260, 470, 145)
        parts.append((cu, cv_, rng.uniform(2.0, 50.0, 145)))         # clutter
        frames.append(tuple(np.concatenate(x) for x in zip(*parts)))
        det = GpodDetector(override(GpodConfig(), {'plane.init_max_step_m': step,
                                                    'plane.seed': seed}))
        for u, v, d in frames:
            status, _ = det._calibrate(u, v, d, np.ones_like(u), cam)
        assert status == 'tracking'
        return cyclopean_height(cam, det.calibrated_plane.abc)

    with_rule = [calibrated_height(0.3, seed) for seed in range(10)]
    without = [calibrated_height(0.0, seed) for seed in range(10)]
    assert all(abs(h - 1.40) < 0.03 for h in with_rule), with_rule
    assert any(abs(h - 0.49) < 0.03 for h in without), without


@pytest.mark.parametrize('scenario,seed', [('walk_stop_turn', 9013), ('slope', 9019),
                                           ('plain_wall', 9035), ('static_obstacles', 9001)])
def test_a_walking_start_calibrates_the_threshold_on_one_plane(scenario, seed):
    """The obstacle threshold comes from the calibration's residual spread. A wearer who
    walks from the first frame gives the window's frames planes a little apart (on
    slope 9019 each within 1 px of their joint plane): about the joint plane their
    spread was 0.75 px (plain_wall 9035: 1.24 px; walk_stop_turn 9013: 1.56 px, the
    threshold at its 1.7 px ceiling), against 0.2 px about each frame's own. Each frame
    must lie on the joint plane as tightly as on its own, else the latest frame alone
    calibrates. A standing
    start keeps the whole window (three frames' features)."""
    from asmonc_vision.sim.scenarios import make_scenario, simulate_frame
    sc = make_scenario(scenario, seed=seed)
    cam = sc.rig.camera()
    det = GpodDetector(GpodConfig())
    n_last = 0
    for k in range(GpodConfig().plane.init_frames):
        f = simulate_frame(sc, k)
        r = det.process(f.left, f.right, cam)
        n_last = len(r.features)
    assert r.status == 'tracking'
    assert 0.05 < det.sigma_px < 0.3, det.sigma_px
    assert r.threshold_px < 1.2, r.threshold_px
    standing = scenario == 'static_obstacles'
    assert (det.calibrated_plane.num_features > 1.5 * n_last) == standing


def test_no_texture_is_a_status_not_an_exception(scenes):
    blank = np.full((CAM.height, CAM.width), 128, np.uint8)
    det = GpodDetector()
    r = det.process(blank, blank, CAM)
    assert r.status == 'initialising' and r.plane_abc is None and r.obstacles == ()
    det, _ = _calibrated(scenes['free'])
    r = det.process(blank, blank, CAM)
    assert r.status == 'lost'
    assert r.plane_abc is None and r.metric_plane is None and len(r.features) == 0
    r = det.process(*scenes['free'], CAM)                # recovers at once
    assert r.status == 'tracking' and r.obstacles == ()
    det, _ = _calibrated(scenes['free'], override(GpodConfig(), {'plane.update': 'fixed'}))
    assert det.process(blank, blank, CAM).status == 'lost'
    assert det.process(*scenes['free'], CAM).status == 'tracking'


def test_bad_images_raise_and_camera_change_resets(scenes):
    det, _ = _calibrated(scenes['free'])
    left, right = scenes['free']
    with pytest.raises(ValueError):
        det.process(left[:, :300], right[:, :300], CAM)
    with pytest.raises(ValueError):
        det.process(left.astype(np.float32), right, CAM)
    with pytest.raises(ValueError):
        det.process(np.dstack([left] * 3), right, CAM)
    other = dataclasses.replace(CAM, baseline=0.3)
    r = det.process(left, right, other)
    assert r.status == 'initialising' and r.frame_index == 1
    det.reset()
    assert det.calibrated_plane is None


def test_refit_follows_a_pitch_change(scenes):
    """'refit' keeps the ground as the rig pitches by 2 degrees; 'fixed' would not."""
    global PITCH
    base = PITCH
    try:
        PITCH = base + 2.0
        tilted = render_pair(seed=2)
    finally:
        PITCH = base
    for mode, ok in (('refit', True), ('fixed', False)):
        det, _ = _calibrated(scenes['free'], override(GpodConfig(), {'plane.update': mode}))
        for _ in range(4):
            r = det.process(*tilted, CAM)
        assert r.status == 'tracking'
        f = r.features
        ground_ok = np.mean(np.abs(f.excess) < 1.0) > 0.8
        assert ground_ok == ok
        if ok:
            assert r.obstacles == ()
            assert abs(r.metric_plane.height - HEIGHT) < 0.05


# ---------------------------------------------------------------- helpers, drawing
@pytest.mark.parametrize('use_numba', [True, False])
def test_cluster_points_2d(monkeypatch, use_numba):
    gk.warm_up()
    if use_numba and gk.nb_link_groups is None:
        pytest.skip('numba not installed')
    if not use_numba:
        monkeypatch.setattr(gk, 'nb_link_groups', None)
    pts = np.array([[0.0, 0.0], [0.2, 0.0], [1.0, 0.0], [1.1, 0.05], [5.0, 5.0], [0.45, 0.0]])
    grp = np.array([0, 1, 2, 3, 4, 1])
    lab = cluster_points_2d(pts, grp, 0.3)
    assert lab[0] == lab[1] == lab[5] and lab[2] == lab[3] and lab[4] not in lab[:4]
    assert len(set(lab.tolist())) == 3
    assert cluster_points_2d(np.zeros((0, 2)), np.zeros(0, int), 0.3).size == 0


def test_cluster_points_2d_paths_agree(monkeypatch):
    """The compiled all-pairs kernel, the numpy all-pairs path and the numpy grid path
    give the same labels (numbered by each cluster's first group)."""
    gk.warm_up()
    if gk.nb_link_groups is None:
        pytest.skip('numba not installed')
    rng = np.random.default_rng(5)
    for n, spread in ((40, 2.0), (300, 3.0), (1500, 6.0)):
        g = rng.integers(0, n // 3, n)                 # strings of ~3 points each
        centre = rng.uniform(0.0, spread, (n // 3, 2))
        pts = centre[g] + rng.normal(0.0, 0.05, (n, 2))
        grp = g * 7                                    # sparse, unordered group ids
        ref = cluster_points_2d(pts, grp, 0.25)
        with monkeypatch.context() as mp:
            mp.setattr(gk, 'nb_link_groups', None)
            np.testing.assert_array_equal(cluster_points_2d(pts, grp, 0.25), ref)
            mp.setattr(gpod_grouping, '_PAIRWISE_POINTS', 0)          # the grid search
            np.testing.assert_array_equal(cluster_points_2d(pts, grp, 0.25), ref)
        assert 1 < ref.max() + 1 < n


def test_corner_search_compiled_equals_numpy(monkeypatch):
    """The compiled free-space test and contact-edge sampling of the hidden-corner search,
    and the compiled walk of `string_feet`, give exactly the numpy paths' results on a
    real frame (a box; random silhouette pairs around it, visible ground from the
    frame)."""
    from asmonc_vision.core import gpod
    det = GpodDetector(GpodConfig())
    for _ in range(2):
        det.process(*render_pair(seed=4), CAM)
    if gkg.nb_corner_free is None:
        pytest.skip('numba not installed')
    det.process(*render_pair(boxes=[(-0.4, 0.2, 3.0, 3.4, 0.3)], seed=4), CAM)
    ctx = det._ctx
    assert ctx is not None and ctx.ground_xy.shape[0] > 50
    rng = np.random.default_rng(3)
    mid = rng.uniform([2.5, -1.0], [4.5, 1.0], (60, 2))
    half = rng.uniform(0.1, 0.6, (60, 1)) * np.stack([np.cos(t := rng.uniform(0, 6.3, 60)),
                                                        np.sin(t)], axis=1)
    a, b, sig = mid - half, mid + half, rng.uniform(0.005, 0.05, 60)
    start = np.flatnonzero(ctx.usable)[::7]
    m_n = gkg._CORNER_ARC_POINTS
    n = mid[:, None, :] + rng.normal(0.0, 0.3, (60, m_n, 2))
    ok = rng.random((60, m_n)) < 0.8

    def run():
        return (gpod.hidden_corners(a, b, sig, ctx.ground_xy, ctx.contact_edge_scores),
                ctx.contact_edge_scores(a, n, b, ok),
                *gpod.string_feet(ctx, start))

    fast = run()
    assert np.isfinite(fast[0][:, 0]).sum() >= 3 and np.isnan(fast[0][:, 0]).sum() >= 3
    for name in ('nb_corner_free', 'nb_contact', 'nb_walk_down'):
        monkeypatch.setattr(gkg, name, None)
    for x, y in zip(fast, run()):
        np.testing.assert_array_equal(x, y)


def test_draw_debug(scenes):
    det, _ = _calibrated(scenes['free'])
    r = det.process(*scenes['box'], CAM)
    img = draw_debug(scenes['box'][0], r)
    assert img.shape == (CAM.height, CAM.width, 3) and img.dtype == np.uint8
    x, y, w, h = r.obstacles[0].roi
    assert (img[y + h - 1, x:x + w] == [0, 0, 255]).all(axis=1).mean() > 0.8   # red roi
    blank = np.zeros((CAM.height, CAM.width), np.uint8)
    r0 = GpodDetector().process(blank, blank, CAM)
    assert draw_debug(blank, r0).shape == (CAM.height, CAM.width, 3)
    col = excess_colours(np.array([0.0, 1.0, 5.0, -5.0, np.nan]), 1.7)
    assert col.shape == (5, 3) and tuple(col[4]) == (160, 160, 160)
    assert col[2, 2] == 255 and col[3, 0] == 255


def test_matched_run_length():
    from asmonc_vision.core.edges import detect_vertical_edges
    from asmonc_vision.core.gpod import matched_run_length
    from asmonc_vision.core.matching import Matches
    img = np.zeros((12, 40), np.uint8)
    img[:, 20:] = 200
    e = detect_vertical_edges(img)                # one string, rows 1..10
    k = len(e)
    d = np.full(k, 10.0, np.float32)
    d[5] = 20.0                                   # a disparity jump splits the run
    z = np.zeros(k, np.float32)
    m = Matches(u_left=e.u, u_right=e.u - d, v=e.v, d=d, strength=z, string_id=e.string_id,
                left_index=np.arange(k, dtype=np.int32), right_index=np.arange(k, dtype=np.int32),
                support=z)
    np.testing.assert_array_equal(matched_run_length(e, m, 1.0), [5, 5, 5, 5, 5, 1, 4, 4, 4, 4])


@pytest.mark.parametrize('use_numba', [True, False])
def test_occluded_matches_half_occlusion(monkeypatch, use_numba):
    """A right silhouette edge (one right string) matched, at alternate rows, to the post's
    own left edge (d = 90) and to a ground edge left of it (d = 60): the ground matches
    are hidden behind the post in the right image. An untrusted near match hides
    nothing, and a string matched at one consistent disparity is left alone."""
    from asmonc_vision.core.edges import detect_vertical_edges
    from asmonc_vision.core.gpod import occluded_matches
    from asmonc_vision.core.matching import Matches
    gk.warm_up()
    if use_numba and gk.nb_occluded is None:
        pytest.skip('numba not installed')
    if not use_numba:
        monkeypatch.setattr(gk, 'nb_occluded', None)
    img = np.zeros((12, 40), np.uint8)
    img[:, 20:] = 200
    e = detect_vertical_edges(img)                # the right image: one string, 10 rows
    k = len(e)
    near = np.arange(k) % 2 == 0
    d = np.where(near, 90.0, 60.0).astype(np.float32)
    z = np.zeros(k, np.float32)
    m = Matches(u_left=e.u + d, u_right=e.u, v=e.v, d=d, strength=z,
                string_id=np.where(near, 0, 1).astype(np.int32),
                left_index=np.arange(k, dtype=np.int32), right_index=np.arange(k, dtype=np.int32),
                support=z)
    np.testing.assert_array_equal(occluded_matches(e, m, 1.0), ~near)
    np.testing.assert_array_equal(occluded_matches(e, m, 1.0, trusted=np.zeros(k, bool)),
                                  np.zeros(k, bool))
    flat = dataclasses.replace(m, d=np.full(k, 60.0, np.float32), u_left=e.u + 60.0)
    assert not occluded_matches(e, flat, 1.0).any()


def test_result_plane_view(scenes):
    det, results = _calibrated(scenes['free'])
    r = results[-1]
    p = r.plane
    assert p is not None and p.updated
    np.testing.assert_array_equal(p.abc, r.plane_abc)
    assert p.num_features == r.plane_num_features and p.metric is r.metric_plane
    assert results[0].plane is None
    assert r.timings is r.timings_ms


# ---------------------------------------------------------------- threshold, averaging
def test_sigma_threshold_from_the_initial_fit(scenes):
    """'sigma': the threshold is k * sigma of the initial fit's residuals, within the floor
    and ceiling; per edge pixel from its edges' precision; 'fixed': threshold_px."""
    det, results = _calibrated(scenes['free'])
    r = results[-1]
    c = det.config
    assert np.isnan(results[0].sigma_px) and 0.05 < det.sigma_px < 0.5
    assert r.sigma_px == det.sigma_px
    assert r.threshold_px == pytest.approx(np.clip(c.threshold.k * det.sigma_px,
                                                   c.threshold.floor_px,
                                                   c.threshold.ceiling_px))
    thr = r.features.threshold
    assert thr.min() >= c.threshold.floor_px and thr.max() <= c.threshold.ceiling_px
    # Precise (sharp, contrasted) edges get lower thresholds than imprecise ones.
    key = r.features.strength
    assert np.median(thr[key > np.quantile(key, 0.8)]) < np.median(thr[key < np.quantile(key, 0.2)])
    det, results = _calibrated(scenes['free'], override(GpodConfig(), {'threshold.mode': 'fixed',
                                                                       'threshold.px': 1.3}))
    assert results[-1].threshold_px == 1.3 and np.all(results[-1].features.threshold == 1.3)
    det, results = _calibrated(scenes['free'],
                               override(GpodConfig(), {'threshold.sigma_per_edge': False}))
    assert np.all(results[-1].features.threshold == results[-1].threshold_px)


def test_excess_is_averaged_while_still_and_not_when_moving(scenes):
    rng = np.random.default_rng(7)

    def noisy(pair):
        return tuple(np.clip(p + rng.normal(0.0, 2.0, p.shape), 0, 255).astype(np.uint8)
                     for p in pair)

    # no smoothing along strings
    det, _ = _calibrated(scenes['free'], override(GpodConfig(), {'detection.string_window': 1}))
    feats = []
    for _ in range(6):
        r = det.process(*noisy(scenes['free']), CAM)
        assert r.still and r.status == 'tracking'
        feats.append(r.features)
    # The same edge pixels in the last two frames: their averaged excess changes much
    # less from frame to frame than their excess does (the camera noise is averaged).
    a, b = feats[-2], feats[-1]
    ka = a.v.astype(np.int64) * 1000 + np.rint(a.u_left).astype(np.int64)
    kb = b.v.astype(np.int64) * 1000 + np.rint(b.u_left).astype(np.int64)
    common, ia, ib = np.intersect1d(ka, kb, return_indices=True)
    ok = (np.abs(a.excess[ia]) < 1) & (np.abs(b.excess[ib]) < 1)
    assert ok.sum() > 1000
    raw = np.std(b.excess[ib][ok] - a.excess[ia][ok])
    mean = np.std(b.excess_mean[ib][ok] - a.excess_mean[ia][ok])
    assert mean < 0.5 * raw
    global PITCH
    base = PITCH
    try:
        PITCH = base + 2.0                   # the rig moves: the image shifts ~10 px
        tilted = render_pair(seed=2)
    finally:
        PITCH = base
    r = det.process(*tilted, CAM)
    assert not r.still
    np.testing.assert_allclose(r.features.excess_mean, r.features.excess, atol=1e-5)
    det.process(*tilted, CAM)
    r = det.process(*tilted, CAM)
    assert r.still                            # still again at the new pose


# ---------------------------------------------------------------- small boxes (simulator)
def small_box_detection(height, range_m, seeds, box_frames=20, clear_frames=5, config=None,
                        match_radius=0.3):
    """GpodDetector on `asmonc_vision.eval.smallbox.small_box_scene` for each seed: the
    tally of `asmonc_vision.eval.smallbox.score_frame` (frames with the box in view, found
    within ``match_radius``, found on the box, false reports, range and bearing errors).
    The full measurement, GPOD against SGBM: ``python -m asmonc_vision.cli.smallbox``."""
    from asmonc_vision.eval.smallbox import merge, new_tally, run_scene

    out = new_tally()
    for seed in seeds:
        out = merge(out, run_scene(height, range_m, seed, box_frames, clear_frames,
                                   methods=('gpod',), match_radius=match_radius,
                                   gpod_config=config)['gpod'])
    return out


@pytest.mark.parametrize('height, range_m, seed', [(0.04, 2.5, 1), (0.08, 5.0, 4)])
def test_small_box_standing_still(height, range_m, seed):
    """4 cm at 2.5 m and 8 cm at 5 m (the paper's 90 % targets), one scene each."""
    r = small_box_detection(height, range_m, [seed], box_frames=8, clear_frames=4)
    assert r['box_frames'] == 8
    assert r['found'] >= 7 and r['false'] == 0
    assert np.median(np.abs(r['range_err'])) < 0.03
    assert np.median(np.abs(r['bearing_err_deg'])) < 1.5


# ---------------------------------------------------------------- nearest point of an obstacle
def _rect(centre, length, width, yaw_deg):
    """Corners (4, 2) of a rectangle on the ground."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    half = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [length / 2, width / 2]
    return np.asarray(centre) + half @ np.array([[c, s], [-s, c]])


def _silhouette(corners):
    """The outermost corners in bearing (left, right) and the nearest corner."""
    b = np.arctan2(corners[:, 1], corners[:, 0])
    r = np.hypot(corners[:, 0], corners[:, 1])
    return corners[np.argmax(b)], corners[np.argmin(b)], corners[np.argmin(r)]


def test_soft_nearest_hedges_a_frontal_face_only():
    from asmonc_vision.core.gpod import soft_nearest
    frontal = np.array([[3.0, 0.2], [3.005, -0.2]])
    q = soft_nearest(frontal, np.array([0.02, 0.02]))
    assert abs(q[1]) < 0.02                               # the middle of the face
    yawed = np.array([[3.0, 0.2], [3.3, -0.2]])
    np.testing.assert_allclose(soft_nearest(yawed, np.array([0.02, 0.02])), yawed[0])


def test_soft_nearest_does_not_average_two_obstacles_side_by_side():
    """Feet as near as each other on two boxes side by side, ground seen between them:
    the nearest point is the nearer box's foot, not the empty middle (an unseen static
    scene reported a 20 cm and a 30 cm box 0.5 m apart at 3.9 m there, in 52 of 80
    frames). Ground only in front of a face, or seen far behind it (over a low box),
    leaves the middle."""
    from asmonc_vision.core.gpod import nearest_points, soft_nearest
    feet = np.array([[3.0, 0.3], [3.01, -0.3]])
    sr = np.array([0.05, 0.05])
    # a grid of ground features 2.6..4.5 m ahead, 0.8 m either side
    gx, gy = np.meshgrid(np.arange(2.6, 4.5, 0.04), np.arange(-0.8, 0.8, 0.04))
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    # Two boxes 0.3 m deep: ground everywhere but under them.
    def under(g, y0):
        return (np.abs(g[:, 1] - y0) < 0.15) & (g[:, 0] > 2.98) & (g[:, 0] < 3.3)

    between = grid[~under(grid, 0.45) & ~under(grid, -0.45)]
    q = soft_nearest(feet, sr, between)
    np.testing.assert_allclose(q, feet[0])
    q = nearest_points(feet, sr, np.zeros(2, np.int64), 1, between)[0]
    np.testing.assert_allclose(q, feet[0])
    # One 0.6 m face (a box 0.3 m deep, 20 cm high: its shadow hides 0.5 m more).
    hidden = (np.abs(grid[:, 1]) < 0.3) & (grid[:, 0] > 2.98) & (grid[:, 0] < 3.8)
    face = grid[~hidden]
    assert abs(soft_nearest(feet, sr, face)[1]) < 0.01
    assert abs(soft_nearest(feet, sr)[1]) < 0.01             # no ground given: as before
    # A lone matched feature behind the face (texture at the ground's disparity) is not
    # a gap.
    assert abs(soft_nearest(feet, sr, np.vstack([face, [[3.1, 0.0]]]))[1]) < 0.01


def test_hidden_corner_from_thales_and_the_contact_edges():
    """The near corner of a yawed box without a vertical edge: on the Thales arc over the
    silhouette corners, where the contact edges are; ruled out by visible ground."""
    from asmonc_vision.core.gpod import hidden_corner, nearest_point
    box = _rect((3.2, 0.1), 0.5, 0.3, 30.0)
    left, right, near = _silhouette(box)
    assert not any(np.allclose(near, p) for p in (left, right))

    def edges_at(corner):
        """A contact-edge score that peaks when the polyline bends at ``corner``."""
        return lambda a, n, b: -np.hypot(*(n - corner).T)

    q = hidden_corner(left, right, 0.01, np.zeros((0, 2)), edges_at(near))
    assert np.hypot(*(q - near)) < 0.05
    q = nearest_point(np.array([left, right]), np.array([0.01, 0.01]), np.zeros((0, 2)),
                      edges_at(near))
    assert np.hypot(*(q - near)) < 0.05
    # A string at the image border is the view's edge, not a silhouette: no corner.
    q = nearest_point(np.array([left, right]), np.array([0.01, 0.01]), np.zeros((0, 2)),
                      edges_at(near), at_border=np.array([False, True]))
    assert np.hypot(*(q - near)) > 0.05
    # Visible ground where the box would stand (inside the triangle left-near-right): the
    # corner is not there.
    ground = ((left + near + right) / 3.0)[None, :]
    q2 = hidden_corner(left, right, 0.01, ground, edges_at(near))
    assert q2 is None or np.hypot(*(q2 - near)) > 0.05
    # Ground features on the contact edges themselves do not rule it out.
    on_edges = np.array([left + t * (near - left) for t in (0.3, 0.6)]
                        + [right + t * (near - right) for t in (0.3, 0.6)])
    q3 = hidden_corner(left, right, 0.01, on_edges, edges_at(near))
    assert np.hypot(*(q3 - near)) < 0.05
    # A frontal face explains the edges as well as any corner: no hidden corner, and the
    # reported point is the middle of the face.
    flat = np.array([[3.0, 0.25], [3.0, -0.25]])
    def chord(a, n, b):                                   # edges along the face
        return -np.abs(n[:, 0] - 3.0)

    assert hidden_corner(flat[0], flat[1], 0.01, np.zeros((0, 2)), chord) is None
    q = nearest_point(flat, np.array([0.01, 0.01]), np.zeros((0, 2)), chord)
    assert abs(q[1]) < 0.01 and abs(q[0] - 3.0) < 0.01
    # A foot nearer than the outermost ones is the near corner itself.
    feet = np.array([left, near, right])
    np.testing.assert_allclose(nearest_point(feet, np.full(3, 0.01), np.zeros((0, 2)),
                                             edges_at(near)), near)


def test_a_hidden_corner_beyond_the_nearest_foot_is_not_the_nearest_point():
    """Two boxes 0.6 m apart join one cluster (cluster_radius_m): the contact edges may
    favour the far box's hidden corner, but the near box's foot is nearer (an unseen
    640x480 scene reported a 30 cm and a 10 cm box 0.4 m beyond the 10 cm one)."""
    from asmonc_vision.core.gpod import nearest_points
    feet = np.array([[3.07, -0.27], [3.16, -0.54], [3.44, -1.04], [3.27, -1.46]])
    sr = np.full(4, 0.02)
    group = np.zeros(4, np.int64)

    def prefer_far(a, n, b, ok):            # contact edges seen only at the far box
        s = -np.hypot(n[..., 0] - 3.15, n[..., 1] + 1.46)
        return np.where(ok, s, -np.inf)

    q = nearest_points(feet, sr, group, 1, np.zeros((0, 2)), prefer_far)[0]
    assert np.hypot(*q) <= np.hypot(*feet[0]) + 0.02, q
    # A real hidden near corner (nearer than both silhouette feet) is still taken.
    box = np.array([[3.3, -0.1], [3.3, -0.9]])
    q = nearest_points(box, np.full(2, 0.02), np.zeros(2, np.int64), 1, np.zeros((0, 2)),
                       lambda a, n, b, ok: np.where(ok, -np.abs(np.arctan2(
                           n[..., 1], n[..., 0]) + 0.08), -np.inf))[0]
    assert np.hypot(*q) < 3.25, q


def test_silhouette_owners_place_only_next_to_a_matching_obstacle():
    """A candidate silhouette edge (just under the thresholds) places a detected obstacle
    only if its foot is beside the obstacle's feet, its top at the obstacle's height and
    no visible ground separates them."""
    from asmonc_vision.core.gpod import silhouette_owners
    xy = np.array([[5.0, -0.2], [5.0, 0.2], [3.0, 1.0]])     # feet of obstacles 0, 0, 1
    g_lab = np.array([0, 0, 1])
    height = np.array([0.08, 0.3])
    xw = np.array([[5.1, 0.5],    # beside obstacle 0, at its height
                   [5.1, 0.5],    # the same foot, but too low a top
                   [6.5, 0.0],    # too far from any foot
                   [3.1, 1.2]])   # beside obstacle 1, at its height
    top = np.array([0.07, 0.02, 0.08, 0.25])
    no_ground = np.zeros((0, 2))
    np.testing.assert_array_equal(silhouette_owners(xw, top, xy, g_lab, height, 0.7, no_ground),
                                  [0, -1, -1, 1])
    # Visible ground between the obstacle's feet and a candidate in front: not its edge.
    front = np.array([[4.6, 0.3]])
    assert silhouette_owners(front, [0.08], xy, g_lab, height, 0.7, no_ground)[0] == 0
    ground = np.array([[4.85, 0.1]])
    assert silhouette_owners(front, [0.08], xy, g_lab, height, 0.7, lambda: ground)[0] == -1
    # Only the outermost candidate beyond the feet on either side is a silhouette.
    xw2 = np.array([[5.0, 0.45], [5.05, 0.35], [4.8, 0.1], [5.1, -0.5]])
    np.testing.assert_array_equal(
        silhouette_owners(xw2, np.full(4, 0.08), xy, g_lab, height, 0.7, no_ground),
        [0, -1, -1, 0])


def test_a_candidate_is_no_side_of_a_body_that_would_hide_visible_ground():
    """A candidate silhouette in front of a low obstacle claims the body between them.
    Ground seen right behind that body's face, where a body of their height would hide it
    from the camera (1.2 m up), says the candidate is something else (a noise string in
    front of a box); ground in front of the face, or beyond its shadow, says nothing."""
    from asmonc_vision.core.gpod import silhouette_owners
    xy = np.array([[5.0, 0.2]])                        # an 8 cm obstacle's foot
    g_lab = np.array([0])
    height = np.array([0.08])
    w = np.array([[4.6, 0.3]])                         # candidate, 0.41 m in front
    mid = 0.5 * (w[0] + xy[0])                         # the face w-p's middle

    def along(behind):                                 # ground on the ray through mid
        r = np.hypot(*mid)
        return np.array([mid * (r + b) / r for b in behind])

    shadow = np.hypot(*mid) * 0.08 / 1.2               # 0.32 m
    hidden = along([0.12, 0.15])
    kw = dict(sigma_w=np.array([0.03]), sigma=np.array([0.03]))
    assert silhouette_owners(w, [0.08], xy, g_lab, height, 0.7, hidden)[0] == 0
    assert silhouette_owners(w, [0.08], xy, g_lab, height, 0.7, hidden, 1.2, **kw)[0] == -1
    for seen in (along([-0.15, -0.1]), along([shadow + 0.05, shadow + 0.1]),
                 along([0.03, 0.05]), hidden[:1]):
        # in front; beyond the shadow; within the feet's range error; one point only
        assert silhouette_owners(w, [0.08], xy, g_lab, height, 0.7, seen, 1.2, **kw)[0] == 0
    # A taller body casts a longer shadow.
    far = along([shadow + 0.05, shadow + 0.1])
    assert silhouette_owners(w, [0.3], xy, g_lab, np.array([0.3]), 0.7, far, 1.2, **kw)[0] == -1


# ---------------------------------------------------------------- obstacle tracks
def test_tracks_bridge_a_missed_detection_and_end_when_the_obstacle_goes(scenes,
                                                                         monkeypatch):
    """While the rig stands still a detected obstacle keeps its track id; in a frame where
    its evidence dips (here: the frame's detections withheld) it is still reported at its
    tracked place, since its image region shows something above the ground; when the box
    is taken away the region shows ground and the track ends at once, although its coast
    time (1 s) has not run out."""
    det, res = _calibrated(scenes['free'])
    assert all(not r.obstacles for r in res)
    ids = set()
    for k in range(3):
        r = det.process(*scenes['box'], CAM, stamp_ns=(3 + k) * 100_000_000)
        assert r.still and len(r.obstacles) == 1 and r.obstacles[0].age_s == 0.0
        ids.add(r.obstacles[0].track_id)
    assert len(ids) == 1 and ids.pop() > 0
    tracked = r.obstacles[0]
    real_detect = det._detect

    def withheld(*a, **kw):
        features, _ = real_detect(*a, **kw)
        return features, ()

    monkeypatch.setattr(det, '_detect', withheld)
    r = det.process(*scenes['box'], CAM, stamp_ns=600_000_000)
    assert r.detections == () and len(r.obstacles) == 1
    ob = r.obstacles[0]
    assert ob.track_id == tracked.track_id and ob.age_s == pytest.approx(0.1)
    assert ob.range == pytest.approx(tracked.range, abs=0.02)
    assert ob.num_edge_pixels == 0 and ob.string_ids.size == 0
    monkeypatch.setattr(det, '_detect', real_detect)
    r = det.process(*scenes['free'], CAM, stamp_ns=700_000_000)
    assert r.still and r.detections == () and r.obstacles == ()


def test_tracks_off_reports_the_detections_only(scenes, monkeypatch):
    det, _ = _calibrated(scenes['free'], override(GpodConfig(), {'tracks.coast_s': 0.0}))
    for _ in range(3):
        r = det.process(*scenes['box'], CAM)
        assert len(r.obstacles) == 1 and r.obstacles[0].track_id > 0
    real_detect = det._detect
    monkeypatch.setattr(det, '_detect', lambda *a, **kw: (real_detect(*a, **kw)[0], ()))
    assert det.process(*scenes['box'], CAM).obstacles == ()


def test_a_small_box_track_is_not_ended_by_its_own_lowest_rows(monkeypatch):
    """An 8 cm box 5 m away (small-box scene seed 69, standing still) is detected in only
    6 of its 20 frames. In the others its silhouette edges are still matched, but their
    lowest rows are at the plane's disparity under either hypothesis (obstacle or ground),
    so they are no evidence that its place is free: its track bridges the gaps and it is
    found in every frame. When they counted as ground the track ended: 15 of 20. (Measured
    without the lone-face placement, which also places some of the detected frames; GPOD's
    own tracks: the evidence map, which reports from its cells instead, is off.)"""
    from asmonc_vision.eval import smallbox
    monkeypatch.setattr(gpod_faces, '_LONE_MAX_HEIGHT_M', 0.0)
    r = smallbox.run_scene(0.08, 5.0, 69, methods=('gpod',),
                           gpod_config=override(GpodConfig(), {'tracks.sure_hits': 0}),
                           map_enabled=False)
    assert r['gpod']['box_frames'] == 20
    assert r['gpod/frame']['found'] <= 10
    assert r['gpod']['found'] >= 19
    assert r['gpod']['false'] == 0


def test_a_small_box_that_appears_is_not_averaged_with_the_ground_it_stands_on(
        monkeypatch):
    """Standing still, the excess of each edge pixel is averaged over frames. When an 8 cm
    box appears 5 m away (small-box scene seed 49) its edge pixels' excess jumps by less
    than 1 px (temporal_gate_px): averaged with the ground's zero, it stayed under the
    threshold for two frames and was then misplaced for three. A jump as large as 0.75 of
    the pixel's threshold restarts the average: found in every frame from the first."""
    from asmonc_vision.eval import smallbox
    new = smallbox.run_scene(0.08, 5.0, 49, methods=('gpod',))
    assert new['gpod/frame']['found'] == 20 and new['gpod']['false'] == 0
    # the old count without the lone-face placement (it also places two misplaced frames)
    monkeypatch.setattr(gpod_faces, '_LONE_MAX_HEIGHT_M', 0.0)
    old = smallbox.run_scene(0.08, 5.0, 49, methods=('gpod',),
                             gpod_config=override(GpodConfig(), {'temporal.gate_thr': 0.0}))
    assert old['gpod/frame']['found'] <= 16


def test_a_low_box_seen_by_one_silhouette_is_placed_along_the_face_the_image_shows(
        monkeypatch):
    """A frontal 8 cm box 5 m away, 0.5 m wide (small-box scene seed 162, standing
    still): only its right end is an obstacle string (its left end lies on a paving joint
    and is matched at the ground's disparity), so it was reported at that end, 0.46 m
    from its nearest point (in the middle of its front face): never "found". Its front
    face shows as two parallel intensity edges, the contact line and the top outline:
    followed from the one foot (`lone_face_points`) it places the box within 0.3 m in 19
    of 20 frames, with no false report. With the search off: 0 of 20. (GPOD's own
    reports: the evidence map off; with it on the map places this box at its cells' nearest
    point, the string's end, as docs/map.md says under its limits.)"""
    from asmonc_vision.eval import smallbox
    new = smallbox.run_scene(0.08, 5.0, 162, methods=('gpod',), map_enabled=False)['gpod']
    assert new['box_frames'] == 20 and new['found'] >= 18 and new['false'] == 0
    assert max(abs(e) for e in new['range_err']) <= 0.05
    monkeypatch.setattr(gpod_faces, '_LONE_MAX_HEIGHT_M', 0.0)
    old = smallbox.run_scene(0.08, 5.0, 162, methods=('gpod',), map_enabled=False)['gpod']
    assert old['found'] <= 2 and old['found_on_box'] == 20


# ---------------------------------------------------------------- a face leaving the view
def _view_edge_camera(f=300.0, h=1.25, cx=159.5, cy=119.5):
    """A level pinhole looking along the ground's x axis, 1.25 m high: ground (N, 2)
    (x ahead, y left) -> image (u, v)."""
    def to_image(xy):
        x = np.maximum(xy[:, 0], 1e-6)
        return cx - f * xy[:, 1] / x, cy + f * h / x
    return to_image


def test_view_edge_points_extend_a_wall_to_the_view_edge():
    from asmonc_vision.core.gpod import view_edge_points
    to_image = _view_edge_camera()
    # A wall 1.9 m to the right: it leaves the view (u = 319) at x = 300 * 1.9 / 159.5.
    x_edge = 300.0 * 1.9 / 159.5
    feet = np.array([[x, -1.9] for x in (4.0, 4.3, 4.7, 5.2)])
    feet[:, 1] += [0.01, -0.01, 0.01, -0.01]
    group = np.zeros(4, np.int64)
    q = view_edge_points(feet, group, 1, to_image, 320, 240, np.zeros((0, 2)))[0]
    assert abs(q[0] - x_edge) < 0.02 and abs(q[1] + 1.9) < 0.02
    # Visible ground behind the extension: the wall ends inside the view.
    b = np.radians(np.linspace(-25.6, -27.8, 12))     # within the extension's bearings
    behind = np.stack([2.3 / np.tan(-b), np.full(12, -2.3)], axis=1)
    assert np.isnan(view_edge_points(feet, group, 1, to_image, 320, 240, behind)[0, 0])
    # A few features behind it (wall texture matched at the ground's disparity) do not.
    q2 = view_edge_points(feet, group, 1, to_image, 320, 240,
                          np.vstack([behind[:2], [[x, -1.5] for x in (3.7, 3.8, 3.9)]]))[0]
    np.testing.assert_allclose(q2, q, atol=1e-9)
    # Two objects in a row (a post and a bollard 0.8 m apart): the ground seen through
    # their line between them, as densely as in front of it, shows they are no face.
    pair = np.array([[4.3, -0.6], [4.25, -0.7], [3.9, -1.35], [3.85, -1.45]])
    gx, gy = np.meshgrid(np.linspace(3.0, 5.5, 26), np.linspace(-0.7, -1.35, 8))
    ground = np.stack([gx.ravel(), gy.ravel()], axis=1)
    g2 = np.zeros(4, np.int64)
    assert np.isfinite(view_edge_points(pair, g2, 1, to_image, 320, 240,
                                        ground[ground[:, 0] < 3.8])).all()
    assert np.isnan(view_edge_points(pair, g2, 1, to_image, 320, 240, ground)).all()
    # No extension: a corner (feet off one line); a face whose nearest point is inside
    # it (frontal); a face that would need more than its own span; too few feet.
    corner = np.array([[4.0, -1.9], [4.3, -1.9], [4.3, -1.5], [4.3, -1.2]])
    frontal = np.array([[4.0, y] for y in (-0.6, -0.2, 0.2, 0.6)])
    short = np.array([[x, -1.9] for x in (5.0, 5.1, 5.2)])
    for p in (corner, frontal, short, feet[:2]):
        g = np.zeros(len(p), np.int64)
        assert np.isnan(view_edge_points(p, g, 1, to_image, 320, 240, np.zeros((0, 2)))).all()


def test_view_edge_points_no_face_along_the_line_of_sight():
    """Feet err along the line of sight. The three strings of a post 4 m ahead (their feet
    0.1 m apart in range) and one string matched a period off, 2.9 m farther at almost
    the same bearing, lay on "a line" pointing at the camera (640x480 walker, seed
    8237): it was extended to the bottom of the view and the post reported 1.63 m
    away, 1.5 m tall. A line within _FACE_MIN_ANGLE_DEG of the line of sight is no face;
    the same feet turned 30 degrees across it still are."""
    from asmonc_vision.core.gpod import view_edge_points
    to_image = _view_edge_camera()
    b = np.radians(7.0)
    r = np.array([3.9, 4.0, 4.1, 6.8])
    feet = np.stack([r * np.cos(b), r * np.sin(b)], axis=1)
    group = np.zeros(4, np.int64)
    assert np.isnan(view_edge_points(feet, group, 1, to_image, 320, 240, np.zeros((0, 2)))).all()
    turn = np.radians(30.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    oblique = (feet - feet[0]) @ rot.T + feet[0]
    assert np.isfinite(view_edge_points(oblique, group, 1, to_image, 320, 240,
                                        np.zeros((0, 2)))).all()


def test_view_edge_points_see_through_the_gap_between_objects_in_a_row():
    """A post and a box 0.6 m apart, their feet on one line: the ground shows only
    through the gap between them (each hides the ground behind itself), which is too
    little against the whole span's near ground but plain within the gap's bearings. No
    "wall" is extended to the view's edge (it once put a WARNING 1.2 m nearer than
    anything, on clear pavement)."""
    from asmonc_vision.core import gpod
    to_image = _view_edge_camera()
    feet = np.array([[4.94, 0.28], [4.93, 0.18],                            # the post
                     [4.44, 0.67], [4.16, 1.12], [4.37, 0.70], [4.12, 1.11]])  # the box
    group = np.zeros(6, np.int64)
    c, d, _, _ = gpod_grouping._fit_line(feet)
    nrm = np.array([-d[1], d[0]]) * np.sign(np.array([-d[1], d[0]]) @ -c)   # towards us
    gx, gy = np.meshgrid(np.arange(2.0, 4.6, 0.1), np.arange(-0.5, 2.5, 0.1))
    front = np.stack([gx.ravel(), gy.ravel()], axis=1)
    front = front[(front - c) @ nrm > 0.15]
    bx, by = np.meshgrid(np.arange(4.6, 6.0, 0.14), np.arange(0.2, 1.0, 0.14))
    gap = np.stack([bx.ravel(), by.ravel()], axis=1)
    off, brg = (gap - c) @ nrm, np.degrees(np.arctan2(gap[:, 1], gap[:, 0]))
    gap = gap[(off < -0.2) & (off > -1.0) & (brg > 3.2) & (brg < 8.5)]   # between them
    q = gpod.view_edge_points(feet, group, 1, to_image, 320, 240, front)[0]
    assert np.isfinite(q).all()                   # with no ground beyond: a face, extended
    assert np.isnan(gpod.view_edge_points(feet, group, 1, to_image, 320, 240,
                                          np.vstack([front, gap]))).all()


def test_a_post_and_a_box_in_a_row_make_no_report_nearer_than_either():
    """Simulated static_obstacles, seed 1001 (found by a sweep of unseen seeds): a 30 cm
    box and a 2.2 m post 0.6 m apart, 4.2-4.9 m ahead, are one obstacle (the gap is
    narrower than cluster_radius_m). It was once placed 3.8 m away at the view's edge (a
    "wall" extended through the gap, `view_edge_points`), and at 7.3 s at 2.07 m (a
    noisy pixel far down the post's edge, continued by a tile joint, taken as the post's
    foot, `string_pieces`): a WARNING on clear pavement. No report may lie more than
    0.3 m nearer than every true obstacle, nor more than 0.3 m from all of them."""
    from asmonc_vision.sim.scenarios import make_scenario, simulate
    sc = make_scenario('static_obstacles', seed=1001, duration=7.5)
    cam = sc.rig.camera()
    det = GpodDetector(GpodConfig())
    bad = []
    for f in simulate(sc):
        r = det.process(f.left, f.right, cam)
        if r.status != 'tracking' or not f.obstacles:
            continue
        truth = np.array([[o.range * math.cos(o.bearing), o.range * math.sin(o.bearing)]
                          for o in f.obstacles])
        nearest_true = min(o.range for o in f.obstacles)
        for o in r.obstacles:
            xy = o.range * np.array([math.cos(o.bearing), math.sin(o.bearing)])
            far_from_all = np.min(np.hypot(*(truth - xy).T)) > 0.3
            if o.confidence >= 0.3 and far_from_all and (o.range < nearest_true - 0.3
                                                          or abs(o.bearing) > 0.45):
                bad.append((f.index, round(o.range, 2), round(math.degrees(o.bearing), 1)))
    assert not bad, bad


def test_string_pieces_cut_a_string_where_it_runs_along_the_ground():
    from asmonc_vision.core.gpod import string_pieces
    # string 7: 6 rows of obstacle, 5 on the ground, 1 stray pixel; string 3: 2 ground
    # pixels inside its obstacle run (noise) do not cut it; string 9: all ground.
    sid = np.array([7] * 12 + [3] * 8 + [9] * 6)
    v = np.concatenate([np.arange(10, 22), np.arange(40, 48), np.arange(5, 11)])
    ground = np.zeros(sid.size, bool)
    ground[6:11] = True                   # string 7, rows 16-20
    ground[14:16] = True                  # string 3, rows 42-43
    ground[20:] = True
    perm = np.random.default_rng(3).permutation(sid.size)      # any input order
    piece = np.empty(sid.size, np.int64)
    piece[perm] = string_pieces(sid[perm], v[perm], ground[perm])
    assert len(set(piece[:6])) == 1 and piece[11] != piece[0]        # the stray is apart
    assert len(set(piece[12:20])) == 1                                # not cut by 2
    assert not set(piece[12:20]) & set(piece[:12]) and not set(piece[20:]) & set(piece[:20])
    assert string_pieces(sid[:0], v[:0], ground[:0]).shape == (0,)
    # with a break of 6 the 5 ground rows no longer cut string 7
    assert len(set(string_pieces(sid, v, ground, min_break=6)[:12])) == 1


def test_wall_beside_the_path_is_reported_where_it_leaves_the_view():
    """A wall along the path on the right: its nearest visible point is where its foot
    leaves the image, not its nearest vertical edge inside the view."""
    wall = (1.9, 2.0, 1.5, 9.0, 2.0)
    det, _ = _calibrated(render_pair(seed=5))
    r = det.process(*render_pair(boxes=[wall], seed=5), CAM)
    assert r.status == 'tracking' and r.obstacles
    # The truth: the nearest point of the wall's inner foot (x = 1.9) inside the image.
    z = np.linspace(1.5, 9.0, 3001)
    p = np.array([to_left_optical([1.9, HEIGHT, zz]) for zz in z])
    u = CAM.f * p[:, 0] / p[:, 2] + CAM.cx
    v = CAM.f * p[:, 1] / p[:, 2] + CAM.cy
    seen = (u <= CAM.width - 1) & (v <= CAM.height - 1)
    z_near = z[seen][0]
    truth = np.array([z_near, -1.9])
    ob = min(r.obstacles, key=lambda o: abs(o.bearing - math.atan2(truth[1], truth[0])))
    got = ob.range * np.array([math.cos(ob.bearing), math.sin(ob.bearing)])
    # (its nearest vertical edge in the view is 0.17 m farther along the wall)
    assert np.hypot(*(got - truth)) < 0.08, (got, truth)


# ---------------------------------------------------------------- a face seen as two obstacles
def test_face_gap_points_bridge_a_blank_middle_only_where_no_ground_shows_through():
    from asmonc_vision.core.gpod import face_gap_points
    # A wall across the path 3 m ahead, its textured parts either side of a blank middle.
    feet = np.array([[3.0, y] for y in (1.2, 0.9, 0.6, -0.5, -0.8, -1.1)])
    feet[:, 0] += [0.01, -0.01, 0.0, 0.01, -0.01, 0.0]
    group = np.array([0, 0, 0, 1, 1, 1])
    q = np.array([[3.0, 0.6], [3.0, -0.5]])            # each part's own nearest foot
    front = np.array([[x, y] for x in (2.2, 2.5, 2.8) for y in (-0.3, 0.0, 0.3)])
    got = face_gap_points(feet, group, 2, q, front)
    assert np.isnan(got[0, 0])                          # the farther part stays
    np.testing.assert_allclose(got[1], [3.0, 0.0], atol=0.02)
    # Ground seen through the gap: two obstacles with a way between them.
    behind = np.array([[x, y] for x in (3.4, 3.8) for y in (-0.3, 0.0, 0.3)])
    assert np.isnan(face_gap_points(feet, group, 2, q, np.vstack([front, behind]))).all()
    # Ground just behind the gap as dense as just in front of it, though few against all
    # the near ground in its bearings: a way through (the share of the whole wedge once
    # bridged a bollard and a wall 3.6 m apart).
    near = np.array([[x, y] for x in np.linspace(1.2, 1.9, 8) for y in (-0.2, 0.0, 0.2)])
    beyond = np.array([[x, y] for x in (3.3, 3.6, 3.9) for y in (-0.25, 0.0, 0.25)])
    assert np.isfinite(face_gap_points(feet, group, 2, q, np.vstack([front, near]))[1]).all()
    assert np.isnan(face_gap_points(feet, group, 2, q,
                                    np.vstack([front, near, beyond]))).all()
    # Nothing seen in the gap (no ground features at all): no bridge.
    assert np.isnan(face_gap_points(feet, group, 2, q, np.zeros((0, 2)))).all()
    # The face's nearest point inside one part: nothing to bridge.
    side = feet + [0.0, 1.5]
    qs = q + [0.0, 1.5]
    assert np.isnan(face_gap_points(side, group, 2, qs, front + [0.0, 1.5])).all()
    # Not one line (a box in front of a wall part).
    bent = feet.copy()
    bent[3:, 0] -= 0.5
    assert np.isnan(face_gap_points(bent, group, 2, q, front)).all()


def test_wall_with_a_blank_middle_is_reported_at_its_nearest_point():
    """A wall across the path whose middle is plain: its textured sides are the only
    obstacle edges; the report is the wall's nearest point, in the blank middle."""
    z_wall, half, blank = 3.0, 1.5, 0.55
    wall = (-half, half, z_wall, z_wall + 0.1, 2.0)
    det, _ = _calibrated(render_pair(seed=6))
    left, right = (im.copy() for im in render_pair(boxes=[wall], seed=6))
    # Paint the middle of the wall's face plain in both images (right: shifted by its
    # disparity), from the top of the image down to the wall's foot.
    base = to_left_optical([0.0, HEIGHT, z_wall])
    v_base = int(CAM.f * base[1] / base[2] + CAM.cy)
    for img, shift in ((left, 0.0), (right, CAM.f * CAM.baseline / base[2])):
        cols = [CAM.f * to_left_optical([x, HEIGHT, z_wall])[0] / base[2] + CAM.cx - shift
                for x in (-blank, blank)]
        img[:v_base + 1, int(round(cols[0])):int(round(cols[1]))] = 150
    r = det.process(left, right, CAM)
    assert r.status == 'tracking' and r.detections
    nearest = min(r.detections, key=lambda o: o.range)
    assert abs(nearest.range - z_wall) < 0.1
    assert abs(math.degrees(nearest.bearing)) < 2.0, math.degrees(nearest.bearing)


def test_two_bodies_closer_than_the_cluster_radius_are_reported_each():
    """A 30 cm box and a 0.9 m block 0.45 m apart: one obstacle for the walking gap
    (cluster_radius_m 0.7 m), and each body also at its own nearest point."""
    near = (-0.9, -0.5, 2.8, 3.2, 0.3)
    far = (-0.05, 0.35, 3.5, 3.9, 0.9)
    det, _ = _calibrated(render_pair(seed=6))
    pair = render_pair(boxes=[near, far], seed=6)
    for _ in range(2):
        r = det.process(*pair, CAM)
    xy = np.array([[o.range * math.cos(o.bearing), o.range * math.sin(o.bearing)]
                   for o in r.obstacles if not o.is_drop])
    # Nearest points on the ground (x ahead, y left; the level frame's x is to the right).
    for x0, x1, z0, _z1, _h in (near, far):
        xs = np.clip(0.0, x0, x1)
        truth = np.array([z0, -xs])
        assert np.min(np.hypot(*(xy - truth).T)) < 0.3, (truth, xy)
    det0, _ = _calibrated(render_pair(seed=6),
                          override(GpodConfig(), {'detection.part_radius_m': 0.0}))
    for _ in range(2):
        r0 = det0.process(*pair, CAM)
    assert len([o for o in r0.obstacles if not o.is_drop]) < len(xy)


@pytest.mark.parametrize('boxes', [
    [(-0.8, -0.6, 3.0, 3.2, 1.0), (0.6, 0.8, 3.0, 3.2, 1.0)],      # two posts, 1.2 m apart
    [(-2.0, -0.6, 3.0, 3.1, 2.0), (0.6, 2.0, 3.0, 3.1, 2.0)],      # a wall with a 1.2 m gap
], ids=['posts', 'wall-gap'])
def test_a_way_between_two_obstacles_is_left_open(boxes):
    """Two obstacles in line with a way between them (the ground beyond is seen through
    it): nothing is reported in the way, whose middle lies straight ahead."""
    det, _ = _calibrated(render_pair(seed=7))
    r = det.process(*render_pair(boxes=boxes, seed=7), CAM)
    near = [o for o in r.detections if o.range < 4.0]
    assert len(near) >= 2
    assert all(abs(math.degrees(o.bearing)) > 5.0 for o in near), [
        (o.range, math.degrees(o.bearing)) for o in near]


def test_moved_roi_keeps_its_place_beside_the_foot():
    """A coasted obstacle's region follows its foot but keeps its offset from it: a
    foot placed beside the obstacle's edges (a wall's nearest point) once dragged the
    region onto empty pavement, a false report for half a second while turning."""
    from asmonc_vision.core.gpod import GpodObstacle
    from asmonc_vision.core.gpod.support import _moved_roi
    up = np.array([0.0, -1.0, 0.0])
    foot = np.array([-1.0, 1.25, 5.0])                  # projects to u = 99.5
    ob = GpodObstacle(position=foot + 0.5 * up, height=0.5, range=5.1, bearing=0.2,
                      width=0.1, disparity_excess=2.0, confidence=1.0,
                      roi=(140, 60, 8, 40), num_edge_pixels=20,
                      string_ids=np.zeros(0, np.int32))
    assert _moved_roi(ob, foot, up, CAM) == ob.roi      # not moved: the same region
    shifted = foot + np.array([0.5, 0.0, 0.0])          # moved 0.5 m right: +30 px
    x2, y2, w2, h2 = _moved_roi(ob, shifted, up, CAM)
    assert abs(x2 - 170) <= 1 and y2 == 60 and abs(w2 - 8) <= 1 and h2 == 40
    nearer = foot * 0.5                                 # twice as near: twice the size,
    x3, y3, w3, h3 = _moved_roi(ob, nearer, up, CAM)    # about the foot's image point
    assert abs(w3 - 16) <= 2 and y3 == 0, (w3, y3)     # (its top now above the image)
    u_f = CAM.cx + CAM.f * nearer[0] / nearer[2]
    assert abs((x3 - u_f) - 2 * (140 - (CAM.cx + CAM.f * foot[0] / foot[2]))) <= 2


def _one_string(n: int, shape: tuple[int, int] = (40, 100)):
    """A left EdgeMap of one vertical edge string of n pixels in column 50, rows 0..n-1
    (each pixel's string predecessor the one above it)."""
    from asmonc_vision.core.edges import EdgeMap
    v = np.arange(n, dtype=np.int32)
    z = np.zeros(n, np.float32)
    return EdgeMap(v=v, u_int=np.full(n, 50, np.int32), u=z + 50, strength=z + 20,
                   polarity=np.ones(n, np.int8), orientation=z,
                   string_id=np.zeros(n, np.int32),
                   string_prev=np.r_[-1, np.arange(n - 1)].astype(np.int32),
                   string_length=np.array([n], np.int32), shape=shape, threshold=4.0)


def test_hanging_runs():
    """A run of an edge string matched a period off (hanging in the air over the depth
    at which the string goes on below it) is found; a real edge broken by a gap, the
    same depth below, is not."""
    from asmonc_vision.core.gpod import hanging_runs, run_links
    from asmonc_vision.core.matching import Matches
    n = 12
    v = np.arange(n, dtype=np.int32)
    z = np.zeros(n, np.float32)
    edges = _one_string(n)
    keep = np.r_[0:6, 7:n]                               # row 6 unmatched (a gap)

    def matches(d):
        d = np.asarray(d, np.float32)[keep]
        i = keep.astype(np.int32)
        return Matches(u_left=z[keep] + 50, u_right=z[keep] + 50 - d, v=v[keep], d=d,
                       strength=z[keep] + 20, string_id=np.zeros(len(keep), np.int32),
                       left_index=i, right_index=i, support=z[keep] + 1)

    h = np.linspace(1.5, 0.0, n)[keep]                   # from 1.5 m down to the ground
    bad = matches([13.0] * 3 + [56.0] * 3 + [13.0] * 6)  # rows 3-5 a period off
    got = hanging_runs(edges, bad, run_links(edges, bad, 1.0), h, 0.5, 1.0, 0.1)
    np.testing.assert_array_equal(np.flatnonzero(got), [3, 4, 5])
    # Two stretches a period off, the upper held up only by the lower: both hang.
    two = matches([13.0] * 3 + [56.0] * 3 + [0.0] + [56.0] * 2 + [13.0] * 3)
    h2 = np.array([1.5, 1.4, 1.3, 1.0, 0.98, 0.96, 0.0, 0.92, 0.9, 0.2, 0.1, 0.0])[keep]
    got = hanging_runs(edges, two, run_links(edges, two, 1.0), h2, 0.5, 1.0, 0.1)
    np.testing.assert_array_equal(np.flatnonzero(got), [3, 4, 5, 6, 7])
    good = matches([13.0] * n)                           # the gap: the same depth below
    assert not hanging_runs(edges, good, run_links(edges, good, 1.0), h, 0.5, 1.0, 0.1).any()
    # Held up only by two stray pixels at its depth (rows 7-8, no run of their own as the
    # caller's detection.min_matched_run counts it): the run hangs once they may not hold it.
    stray = matches([56.0] * 4 + [13.0] * 2 + [0.0] + [56.0] * 2 + [13.0] * 3)
    hs = np.array([1.5, 1.4, 1.3, 1.2, 1.1, 1.0, 0.0, 0.4, 0.35, 0.2, 0.1, 0.0])[keep]
    links = run_links(edges, stray, 1.0)
    assert not hanging_runs(edges, stray, links, hs, 0.5, 1.0, 0.1).any()
    solid = ~np.isin(keep, [7, 8])
    got = hanging_runs(edges, stray, links, hs, 0.5, 1.0, 0.1, solid=solid)
    np.testing.assert_array_equal(np.flatnonzero(got), [0, 1, 2, 3])


@pytest.mark.parametrize('compiled', [True, False])
def test_hanging_runs_follow_a_long_chain_of_mismatched_stretches(monkeypatch, compiled):
    """An edge that alternates all the way down between its own depth and one a period
    off (a dark door's edge against the sky, matched to a post's edge 88 px away in
    every other stretch: wo8042 at 640x480, whose binned pass made a 1.4 m obstacle 1 m
    away of it, and a false STOP) hangs as a whole: each stretch is held up only by the
    one below it, and the lowest one by nothing. Four passes (the old limit) left the
    upper four standing."""
    from asmonc_vision.core.gpod import hanging_runs, run_links
    from asmonc_vision.core.matching import Matches
    if not compiled:
        monkeypatch.setattr(gk, 'nb_hanging_all', None)
        monkeypatch.setattr(gk, 'nb_hanging', None)
    elif gk.nb_hanging_all is None:
        pytest.skip('numba not installed')
    stretches = 8
    d = [13.0] * 3 + ([56.0] * 2 + [13.0] * 2) * stretches + [13.0] * 6
    n = len(d)
    v = np.arange(n, dtype=np.int32)
    z = np.zeros(n, np.float32)
    edges = _one_string(n, (80, 100))
    i = np.arange(n, dtype=np.int32)
    d = np.asarray(d, np.float32)
    m = Matches(u_left=z + 50, u_right=z + 50 - d, v=v, d=d, strength=z + 20,
                string_id=np.zeros(n, np.int32), left_index=i, right_index=i,
                support=z + 1)
    far = d < 20
    h = np.where(far, np.linspace(1.5, 0.0, n), 1.2)      # the mismatches hang 1.2 m up
    got = hanging_runs(edges, m, run_links(edges, m, 1.0), h, 0.5, 1.0, 0.1)
    np.testing.assert_array_equal(got, ~far)


def test_continuation_alternatives():
    """A run of an edge string matched a period off, well above the plane, with the
    string going on below it on lower ground (beyond a kerb down; or above it, where the
    run ends the string) and a candidate of its own on that ground, is found. It is not
    when the string goes on below at the run's own depth (a real edge broken by a
    mismatch), when the lower ground is not seen by enough matches, or when the run had no
    candidate on it."""
    from asmonc_vision.core.gpod import continuation_alternatives, run_links
    from asmonc_vision.core.matching import Candidates, Matches
    n = 30
    v = np.arange(n, dtype=np.int32)
    z = np.zeros(n, np.float32)
    edges = _one_string(n)
    pd = 20.0 + 0.25 * v                                 # the plane's disparity, b = 0.25
    low = 0.9 * pd                                       # a lower ground (ratio 0.9)
    run = (v >= 10) & (v < 20)

    def case(d, alternatives):
        d = np.asarray(d, np.float32)
        i = np.arange(n, dtype=np.int32)
        m = Matches(u_left=z + 50, u_right=z + 50 - d, v=v, d=d, strength=z + 20,
                    string_id=np.zeros(n, np.int32), left_index=i, right_index=i,
                    support=z + 1)
        cl = np.r_[i, i[run]] if alternatives else i
        cd = np.r_[d, low[run]] if alternatives else d.astype(np.float64)
        o = np.argsort(cl, kind='stable')
        cand = Candidates(left=cl[o].astype(np.intp), right=cl[o].astype(np.intp),
                          d=np.asarray(cd, np.float64)[o])
        lower = np.abs(d - low) < 0.01
        select = d - pd > 3.0
        return lambda support: continuation_alternatives(
            edges, m, run_links(edges, m, 1.0), cand, select, lower, pd, 1.0, 0.25,
            support)

    off = np.where(run, pd + 20.0, low)                  # rows 10-19 a period off
    got = case(off, True)
    np.testing.assert_array_equal(np.flatnonzero(got(15)), np.flatnonzero(run))
    assert not got(25).any()                             # 20 lower matches: too few
    assert not case(off, False)(15).any()                # no candidate on the lower ground
    # A box's edge at d = 40 (rows 10-19 and 22-29) broken by two rows matched on the
    # lower ground: the string goes on at its depth below, so the run is held up.
    box = np.where(run | (v >= 22), 40.0, low)
    assert not case(box, True)(10)[run].any()
    # The stretch a period off ends its string (at the kerb's brink): the lower ground
    # above it is its continuation.
    end = np.where(v >= 10, pd + 20.0, low)
    end_run = v >= 10
    run[:] = end_run                                     # its candidates
    np.testing.assert_array_equal(np.flatnonzero(case(end, True)(10)),
                                  np.flatnonzero(end_run))
    assert not case(end, True)(11).any()                 # 10 lower matches: too few


#: the kerb-down walks of the three tests below (simulator, step_down): name -> (seed,
#: rig settings, first frame the test uses)
KERB_WALKS = {
    'paving': (8022, dict(width=640, height=480, focal=600.0), 66),
    'creep': (8043, dict(camera_height=1.4, fps=15.0), 0),
    'predicted': (8084, dict(baseline=0.2, fps=15.0), 0),
}


def render_kerb_walk(name: str) -> list:
    """(left, right, left pose, true plane) of each frame of KERB_WALKS[name] the test
    uses, in order."""
    from asmonc_vision.sim import RigSettings, StereoRenderer, simulate_frame
    from asmonc_vision.sim.scenarios import step_down

    seed, rig, first = KERB_WALKS[name]
    sc = step_down(seed=seed, rig=RigSettings(**rig))
    rend = StereoRenderer(sc.rig)
    return [(f.left, f.right, f.left_pose, f.plane)
            for f in (simulate_frame(sc, k, rend) for k in range(first, sc.n_frames))]


@pytest.fixture(scope='module')
def kerb_walks():
    """name -> a future of `render_kerb_walk(name)`. The walks are rendered (most of these
    tests' time) two at a time, each in a process of its own (spawned: this process may
    hold ROS threads), while the first test detects on its frames."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=2,
                             mp_context=multiprocessing.get_context('spawn')) as pool:
        yield {name: pool.submit(render_kerb_walk, name) for name in KERB_WALKS}


def _kerb_scenario(name: str):
    from asmonc_vision.sim import RigSettings
    from asmonc_vision.sim.scenarios import step_down
    seed, rig, _ = KERB_WALKS[name]
    return step_down(seed=seed, rig=RigSettings(**rig))


def test_the_paving_beyond_a_kerb_down_is_no_obstacle(kerb_walks):
    """Standing 2.45 m before a 15 cm kerb down at 640 x 480 (simulator, step_down seed
    8022): the paving joints beyond the kerb, on the lower ground, were matched one joint
    spacing off in stretches of 10 rows, 43-54 px above the plane, as an obstacle 0.9 m
    away (10 of these 14 frames; a STOP alarm in the node graph). The kerb is reported as
    a drop, and nothing stands between it and the wearer."""
    sc = _kerb_scenario('paving')
    cam = sc.rig.camera()
    det, drops, near = GpodDetector(), 0, []
    frames = kerb_walks['paving'].result()
    assert len(frames) == sc.n_frames - 66
    for k, (left, right, _, _) in enumerate(frames, start=66):     # standing still
        r = det.process(left, right, cam)
        drops += any(o.is_drop and abs(o.range - 2.45) < 0.3 for o in r.detections)
        near += [(k, round(o.range, 2)) for o in r.detections
                 if not o.is_drop and o.range < 2.2]
    assert drops >= 12, drops
    assert not near, near


def test_a_start_before_a_kerb_down_calibrates_on_the_ground_underfoot(kerb_walks):
    """Starting 2.45 m before a 15 cm kerb down (the scene of the test above), the lower
    ground beyond it holds most of the features, and the calibration's sampling finds
    the strip before the edge in 1 of 8 RANSAC seeds. The nearest features standing
    above the plane so found, on a parallel plane a kerb higher, say it is the ground
    beyond the drop: the calibration takes the ground underfoot with every seed;
    without that test (`plane.init_near_share` 0) it takes the lower ground."""
    sc = _kerb_scenario('paving')
    cam = sc.rig.camera()
    frames = kerb_walks['paving'].result()
    truth = float(frames[0][3].height)

    def heights(share):
        out = []
        for seed in range(8):
            det = GpodDetector(override(GpodConfig(), {'plane.seed': seed,
                                                       'plane.init_near_share': share}))
            for left, right, _, _ in frames[:8]:
                det.process(left, right, cam)
                if det.calibrated_plane is not None:
                    break
            out.append(cyclopean_height(cam, det.calibrated_plane.abc))
        return np.array(out)
    with_test = heights(GpodConfig().plane.init_near_share)
    assert np.all(np.abs(with_test - truth) < 0.05), (with_test, truth)
    assert np.sum(heights(0.0) > truth + 0.1) >= 4


def test_the_plane_does_not_creep_onto_the_ground_beyond_a_kerb_down(kerb_walks):
    """Walking up to a 15 cm kerb down and standing 2.2 m before it, the camera 1.4 m
    high at 15 Hz (simulator, step_down seed 8043): most of the view is the lower ground.
    Standing, each refit was gated around the current plane; the lower ground leaked in
    4-10 m away, tilted the plane, and the tilted plane let more of it in: 0.1 -> 3.8
    degrees and 12 cm within 0.5 s, and the pavement before the kerb stood 20 cm up
    (a WARNING "obstacle, 2 metres" in the node graph). Gated around the plane the rig
    had when it stopped, the plane stays on the ground the wearer stands on."""
    from asmonc_vision.eval.evaluation import plane_error

    sc = _kerb_scenario('creep')
    cam = sc.rig.camera()
    det, worst, still, up = GpodDetector(), 0.0, 0, []
    frames = kerb_walks['creep'].result()
    assert len(frames) == sc.n_frames
    for k, (left, right, _, plane) in enumerate(frames):
        r = det.process(left, right, cam)
        if k < 96:                                      # walking up to the kerb
            continue
        still += r.still
        assert r.metric_plane is not None, k
        worst = max(worst, plane_error(r.metric_plane, plane)[0])
        up += [(k, round(o.range, 2), round(o.height, 2)) for o in r.detections
               if not o.is_drop and o.height >= 0.05 and o.range < 5.0
               and abs(o.range * math.sin(o.bearing)) <= 0.5]
    assert still >= 20, still
    assert worst < 1.0, worst
    assert not up, up


def test_the_plane_predicted_through_the_motion_stays_on_the_ground_stood_on(kerb_walks):
    """Stopping 2 m before a 15 cm kerb down, 15 Hz, a 0.2 m baseline (simulator,
    step_down seed 8084): most of the view is the lower ground. The rig moved again for
    two frames, just enough not to be still, and the refits, gated around the current
    plane (10 cm) and limited per frame to 8 degrees and 10 cm, took the lower ground:
    3.7 degrees and 106 mm off while the wearer stood, a false WARNING "obstacle,
    1.5 metres" in the node graph. With the camera's motion given, the plane is carried
    through it, the refits are gated 5 cm around the prediction and limited to 2 degrees
    and 5 cm from it, and the plane stays on the ground the wearer stands on."""
    from asmonc_vision.eval.evaluation import plane_error

    sc = _kerb_scenario('predicted')
    cam = sc.rig.camera()
    det, prev, errors, up, still = GpodDetector(), None, [], [], 0
    frames = kerb_walks['predicted'].result()
    assert len(frames) == sc.n_frames
    for k, (left, right, pose, plane) in enumerate(frames):
        motion = None
        if prev is not None:           # X_prev = R X + t, left optical frames
            motion = (prev.rotation.T @ pose.rotation,
                      prev.rotation.T @ (pose.centre - prev.centre))
        prev = pose
        r = det.process(left, right, cam, motion=motion)
        if k < 85:                                      # walking up to the kerb
            continue
        still += r.still
        assert r.metric_plane is not None, k
        errors.append(plane_error(r.metric_plane, plane))
        up += [(k, round(o.range, 2), round(o.height, 2)) for o in r.obstacles
               if not o.is_drop and o.height >= 0.05 and o.range < 5.0
               and abs(o.range * math.sin(o.bearing)) <= 0.5]
    errors = np.abs(np.array(errors))
    assert still >= 15, still
    assert errors[:, 0].max() < 0.6, errors[:, 0].max()      # degrees
    assert errors[:, 1].max() < 0.02, errors[:, 1].max()     # metres
    assert not up, up


@pytest.mark.parametrize('scenario, error_m', [('clear_walk', 0.04), ('clear_static', 0.08)])
def test_a_wrong_motion_does_not_take_the_plane_off_the_ground(scenario, error_m):
    """The visual egomotion was once 4 cm off in one frame (walk_obstacles seed 8076, a
    0.2 m baseline): the plane carried through it was 3 cm off the ground, the refits
    were rejected as too far from it, and the ground showed as a drop, a false WARNING
    "drop ahead, 1.5 metres". The change limits (5 cm, 2 degrees) leave room for such
    an error while walking (the camera bobs 2-3 cm between frames), and a refit close to
    the plane before the motion is accepted as well. Standing still, a motion (8 cm
    off here) is not used at all: carried through it, the plane the rig stopped with
    stayed off the ground for as long as the wearer stood (a drop in every frame)."""
    from asmonc_vision.eval.evaluation import plane_error
    from asmonc_vision.sim import StereoRenderer, make_scenario, simulate_frame

    sc = make_scenario(scenario, seed=3, duration=3.0)
    rend, cam = StereoRenderer(sc.rig), sc.rig.camera()
    det, prev, worst, drops = GpodDetector(), None, np.zeros(2), []
    for k in range(sc.n_frames):
        f = simulate_frame(sc, k, rend)
        motion = None
        if prev is not None:
            motion = (prev.rotation.T @ f.left_pose.rotation,
                      prev.rotation.T @ (f.left_pose.centre - prev.centre))
            if k in (12, 20):                               # off, down or up
                err = error_m if k == 12 else -error_m
                motion = (motion[0], motion[1] + np.array([0.0, err, 0.0]))
        prev = f.left_pose
        r = det.process(f.left, f.right, cam, motion=motion)
        if k < 5:
            continue
        assert r.metric_plane is not None, k
        worst = np.maximum(worst, np.abs(plane_error(r.metric_plane, f.plane)))
        drops += [(k, round(o.range, 2)) for o in r.obstacles if o.is_drop]
    assert worst[0] < 0.5 and worst[1] < 0.015, worst
    assert not drops, drops


def test_same_object_only_for_a_nearer_or_close_placement():
    """While standing, a detection keeps an overlapping track seen as the same obstacle
    placed elsewhere (its far corner; boxes reported together at the nearest) -- but not
    a detection metres beyond the track: then the track's placement was wrong (a pole's
    foot once followed down a paving joint to 1.1 m, the pole then seen at 7 m), and it
    must end instead of being reported, and alarmed, for as long as the wearer stands."""
    from asmonc_vision.core.gpod import GpodObstacle
    from asmonc_vision.core.gpod.grouping import _same_object

    def ob(rng, roi, bearing=0.0):
        return GpodObstacle(position=np.zeros(3), height=1.0, range=rng, bearing=bearing,
                            width=0.1, disparity_excess=5.0, confidence=1.0, roi=roi,
                            num_edge_pixels=20, string_ids=np.zeros(0, np.int32))

    track = ob(1.13, (200, 11, 5, 229))                 # the wrong placement
    pole = ob(6.95, (200, 1, 5, 67))                    # the same column, far away
    assert _same_object(track, pole)                    # by the image alone it would be
    assert not _same_object(track, pole, radius=0.7)
    assert _same_object(ob(3.6, (150, 60, 20, 30)), ob(2.3, (140, 60, 40, 60)), radius=0.7)
    assert _same_object(ob(2.5, (150, 60, 20, 30)), ob(2.9, (152, 58, 20, 30)), radius=0.7)
    assert not _same_object(ob(2.5, (150, 60, 20, 30)), ob(2.6, (10, 60, 20, 30)), radius=0.7)


def test_hanging_runs_compiled_equals_numpy(monkeypatch):
    """The compiled walk of `hanging_runs` (numba, optional) marks the same matches as
    the numpy one, on a real walking frame."""
    from asmonc_vision.core.gpod import hanging_runs, run_links
    det = GpodDetector(GpodConfig())
    det.process(*render_pair(seed=3), CAM)
    if gk.nb_hanging is None:
        pytest.skip('numba not installed')
    from asmonc_vision.core.edges import detect_vertical_edges
    from asmonc_vision.core.matching import pmf_match
    left, right = render_pair(boxes=[(-0.5, 0.0, 3.0, 3.3, 1.2)], seed=3)
    el, er = detect_vertical_edges(left), detect_vertical_edges(right)
    m = pmf_match(el, er, 0.5, 60.0)[0]
    prev = run_links(el, m, 1.0)
    rng = np.random.default_rng(2)
    h = rng.uniform(0.0, 1.5, len(m))
    solid = rng.uniform(size=len(m)) < 0.7
    fast = hanging_runs(el, m, prev, h, 0.5, 1.0, 0.1)
    fast_s = hanging_runs(el, m, prev, h, 0.5, 1.0, 0.1, solid=solid)
    monkeypatch.setattr(gk, 'nb_hanging', None)
    monkeypatch.setattr(gk, 'nb_hanging_all', None)
    slow = hanging_runs(el, m, prev, h, 0.5, 1.0, 0.1)
    slow_s = hanging_runs(el, m, prev, h, 0.5, 1.0, 0.1, solid=solid)
    assert slow.any() and not slow.all()
    assert slow_s.sum() > slow.sum()              # fewer matches hold runs up
    np.testing.assert_array_equal(fast, slow)
    np.testing.assert_array_equal(fast_s, slow_s)


def test_a_noisy_camera_makes_no_obstacles_on_clear_pavement():
    """A dark, noisy camera (pixel noise sigma 5 grey levels, against 2 on the paper's
    rig): its noise makes weak vertical edges, which match wrongly and stood up as
    strings of 3-8 obstacle pixels, 20-30 per 80 frames of clear pavement, and one
    gave a false WARNING. Edges weaker than obstacle_min_edge_snr times the gradient
    noise (estimated in the image) now count less."""
    from asmonc_vision.sim.rig import RigSettings
    from asmonc_vision.sim.scenarios import make_scenario, simulate
    sc = make_scenario('clear_walk', seed=806, duration=6.0, rig=RigSettings(noise_sigma=5.0))
    cam = sc.rig.camera()
    det = GpodDetector(GpodConfig())
    tracking, false = 0, []
    for f in simulate(sc):
        r = det.process(f.left, f.right, cam)
        tracking += r.status == 'tracking'
        false += [(f.index, round(o.range, 2), round(o.confidence, 2)) for o in r.detections
                  if o.height >= 0.05]
    assert abs(det.image_noise_sigma - 5.0) < 0.5
    assert tracking >= 50
    assert len(false) <= 2, false


# ---------------------------------------------------------------- compiled paths (speed)
# The detector's compiled loops (numba), each beside its numpy
# path; these tests check that both give exactly the same results (bit for bit).

#: The gpod kernels checked here, each with a numpy path beside it.
_NEW_GPOD_KERNELS = ('nb_extremes', 'nb_soft_args', 'nb_arcs', 'nb_contact_bounds',
                     'nb_owners', 'nb_group_quantile', 'nb_extent', 'nb_runs',
                     'nb_occluded_all', 'nb_hanging_all', 'nb_still',
                     'nb_temporal', 'nb_thin')
_NEW_MATCHING_KERNELS = ('nb_candidates', 'nb_cells', 'nb_siblings', 'nb_link_rows')
#: the modules of the gpod kernels
_GPOD = (gk, gkg)


def _holder(modules, name):
    """The module of ``modules`` (one or a tuple) that has ``name``."""
    modules = modules if isinstance(modules, tuple) else (modules,)
    return next(m for m in modules if hasattr(m, name))


def _need_numba():
    from asmonc_vision.core import gpod
    from asmonc_vision.core.matching import kernels as mt
    gk.warm_up()
    if any(getattr(_holder(_GPOD, k), k) is None for k in _NEW_GPOD_KERNELS) or any(
            getattr(mt, k) is None for k in _NEW_MATCHING_KERNELS):
        pytest.skip('numba not installed')
    return gpod, mt


def _without(monkeypatch, modules, names):
    for name in names:
        monkeypatch.setattr(_holder(modules, name), name, None)


def _compiled_equals_numpy(monkeypatch, module, names, run):
    """``run()`` (a sequence of arrays) with the kernels ``names`` of ``module`` (one or a
    tuple of modules), then
    without them (their numpy paths): equal element by element. Returns both runs."""
    fast = run()
    _without(monkeypatch, module, names)
    slow = run()
    assert len(fast) == len(slow)
    for x, y in zip(fast, slow):
        np.testing.assert_array_equal(x, y)
    return fast, slow


@pytest.fixture(scope='module')
def box_frame():
    """A detector after a frame with two boxes (its context: matches, runs, ground)."""
    det = GpodDetector(GpodConfig())
    for _ in range(2):
        det.process(*render_pair(seed=4), CAM)
    pair = render_pair(boxes=[(-0.4, 0.2, 3.0, 3.4, 0.3), (0.6, 0.9, 4.5, 4.8, 0.6)], seed=4)
    r = det.process(*pair, CAM)
    return det, pair, r


def test_candidate_and_link_kernels_equal_the_numpy_path(box_frame, monkeypatch):
    """The compiled candidate search, cell table, sibling disparities and link rows of
    the matcher give the numpy paths' arrays (values and dtypes)."""
    _, mt = _need_numba()
    from asmonc_vision.core.edges import detect_vertical_edges
    from asmonc_vision.core.matching import Candidates, candidate_matches, support_links
    _, (left, right), _ = box_frame
    el, er = detect_vertical_edges(left), detect_vertical_edges(right)
    settings = [(0.1, 105.0, 0.5, 30.0), (5.0, 40.0, 0.6, 25.0), (0.5, 80.0, 0.2, 45.0),
                (20.0, 20.5, 0.5, 30.0)]
    fast = [candidate_matches(el, er, lo, hi, min_strength_ratio=r, max_orientation_diff_deg=o)
            for lo, hi, r, o in settings]
    c = fast[0]
    links = [support_links(el, er, c, support_radius=3.0)]
    o = np.lexsort((np.random.default_rng(1).random(len(c)), c.left))   # non-monotonic
    shuffled = Candidates(c.left[o], c.right[o], c.d[o])
    links.append(support_links(el, er, shuffled, support_radius=3.0))
    # siblings by ascending disparity, every third candidate twice: steps of zero
    # among positive ones (monotonic)
    o = np.lexsort((c.d, c.left))
    o = np.repeat(o, np.where(np.arange(o.size) % 3 == 0, 2, 1))
    doubled = Candidates(c.left[o], c.right[o], c.d[o])
    links.append(support_links(el, er, doubled, support_radius=3.0))
    _without(monkeypatch, mt, _NEW_MATCHING_KERNELS)
    slow = [candidate_matches(el, er, lo, hi, min_strength_ratio=r, max_orientation_diff_deg=o)
            for lo, hi, r, o in settings]
    assert len(slow[0]) > 2000 and len(slow[3]) > 0
    assert len(slow[1]) < len(slow[2])
    for x, y in zip(fast, slow):
        for a, b in ((x.left, y.left), (x.right, y.right), (x.d, y.d)):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
    for x, cand in zip(links, (c, shuffled, doubled)):
        y = support_links(el, er, cand, support_radius=3.0)
        assert x.num_single == y.num_single
        for f in ('cand', 'start', 'pair_link', 'pair_cand', 'pair_edge', 'pair_right',
                  'weight'):
            assert getattr(x, f).dtype == getattr(y, f).dtype, f
            np.testing.assert_array_equal(getattr(x, f), getattr(y, f))


def test_body_gap_kernel_decides_as_body_gap():
    """The compiled body-gap test answers as `_body_gap` whenever it answers (0 or 1),
    and leaves to it (-1) only a ground point within rounding distance of the strip."""
    gpod, _ = _need_numba()
    rng = np.random.default_rng(7)
    counts = {0: 0, 1: 0, -1: 0}
    for _ in range(3000):
        a = rng.uniform([2.0, -1.5], [5.0, 1.5])
        b = a + rng.normal(0.0, 0.4, 2)
        g = a + rng.uniform(-0.6, 0.9, (int(rng.integers(0, 300)), 2))
        k = gkg.nb_body_gap(g, a[0], a[1], b[0], b[1])
        counts[k] += 1
        if k >= 0:
            assert bool(k) == gpod_nearest._body_gap(g, a, b)
    assert counts[0] > 300 and counts[1] > 300 and counts[-1] == 0
    # Points exactly on the strip's sides (at along = 0.1 m, behind = 0.3 m): undecided
    # unless the others decide.
    a, b = np.array([3.0, -0.5]), np.array([3.0, 0.5])
    t, nrm = np.array([0.0, 1.0]), np.array([1.0, 0.0])
    inside = a + 0.5 * t + 0.15 * nrm + np.array([[0.0, 0.01 * i] for i in range(4)])
    edge = a + 0.1 * t + 0.2 * nrm
    g = np.vstack([inside, edge[None]])
    assert gkg.nb_body_gap(g, a[0], a[1], b[0], b[1]) == -1
    assert gkg.nb_body_gap(np.vstack([g, inside[:1]]), a[0], a[1], b[0], b[1]) == 1
    assert gkg.nb_body_gap(inside, a[0], a[1], b[0], b[1]) == 0


def test_soft_nearest_groups_compiled_equals_numpy(monkeypatch):
    """The soft nearest points of many groups at once, compiled, are `soft_nearest`'s:
    its weights (numpy's exp), body gaps, sums in numpy's order (groups of 1-20 feet,
    and one of 140, beyond the compiled pairwise sum)."""
    gpod, _ = _need_numba()
    rng = np.random.default_rng(11)
    sizes = np.r_[rng.integers(1, 21, 60), 140]
    group = np.repeat(np.arange(sizes.size), sizes)
    rng.shuffle(group)
    centre = rng.uniform([2.0, -2.0], [6.0, 2.0], (sizes.size, 2))
    xy = centre[group] + rng.normal(0.0, 0.3, (group.size, 2))
    # In most groups the two first feet are equal and the nearest: the first counts.
    order = np.argsort(group, kind='stable')
    first = np.searchsorted(group[order], np.arange(sizes.size))
    for k in np.flatnonzero(sizes >= 2)[::2]:
        i, j = order[first[k]], order[first[k] + 1]
        xy[i] = xy[j] = 0.8 * centre[k]
    # sigmas whose square numpy's scalar power (libm's pow) rounds unlike s * s
    s = rng.uniform(0.01, 0.3, 20000)
    s = s[np.array([np.float64(x) ** 2 for x in s]) != s * s]
    sr = s[rng.integers(0, s.size, group.size)]
    gx, gy = np.meshgrid(np.arange(1.5, 7.0, 0.05), np.arange(-2.5, 2.5, 0.05))
    ground = np.stack([gx.ravel(), gy.ravel()], axis=1)
    want = np.ones(sizes.size, bool)
    want[::7] = False
    fast, _ = _compiled_equals_numpy(
        monkeypatch, _GPOD, ('nb_soft_args',),
        lambda: [gpod_nearest._soft_nearest_groups(xy, sr, group, sizes.size, want, g)
                 for g in (None, ground, lambda: ground)])
    assert np.isnan(fast[1][~want]).all() and np.isfinite(fast[1][want]).all()
    # the visible ground separated some feet from their group's nearest one
    assert (np.abs(fast[0] - fast[1]) > 1e-9).any()


def test_nearest_points_compiled_equals_numpy(box_frame, monkeypatch):
    """`nearest_points` with its per-obstacle choices, corner arcs and contact patches
    compiled gives the numpy path's points, on a real frame's ground and image."""
    gpod, _ = _need_numba()
    det, _, _ = box_frame
    ctx = det._ctx
    rng = np.random.default_rng(3)
    n_g = 40
    sizes = rng.integers(1, 7, n_g)
    group = np.repeat(np.arange(n_g), sizes)
    centre = rng.uniform([2.5, -1.2], [5.0, 1.2], (n_g, 2))
    xy = centre[group] + rng.normal(0.0, 0.25, (group.size, 2))
    xy[1::3] = xy[::3][:xy[1::3].shape[0]]           # equal feet: the first of them counts
    sr = rng.uniform(0.005, 0.05, group.size)
    border = rng.random(group.size) < 0.1

    def run():
        return [gpod.nearest_points(xy, sr, group, n_g + 2, lambda: ctx.ground_xy,
                                    ctx.contact_edge_scores, border),
                gpod.nearest_points(xy, sr, group, n_g, ctx.ground_xy),
                gpod.hidden_corners(xy[:30], xy[30:60], sr[:30], ctx.ground_xy,
                                    ctx.contact_edge_scores)]

    fast, _ = _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_extremes', 'nb_soft_args',
                                                         'nb_arcs', 'nb_contact_bounds'), run)
    assert np.isnan(fast[0][n_g:]).all() and np.isfinite(fast[0][:n_g]).all()
    assert np.isfinite(fast[2][:, 0]).sum() >= 2


def test_outline_evidence_compiled_equals_numpy(box_frame, monkeypatch):
    """The lone-face search's evidence (`_FrameContext.outline_evidence`) compiled gives
    the numpy path's values, on a real frame's image: feet near and far, faces low and
    high (raised lines partly out of the image), every direction."""
    gpod, _ = _need_numba()
    det, _, _ = box_frame
    ctx = det._ctx
    feet = [np.array([3.0, 0.3]), np.array([4.6, -0.8]), np.array([2.2, 1.1])]

    def run():
        out = []
        for foot in feet:
            for h in (0.04, 0.3, 1.5):
                _, ev, sep, shift = ctx.outline_evidence(foot, h, gpod_faces._LONE_PHI)
                out += [ev, sep, shift]
        return out

    fast, _ = _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_outline',), run)
    assert max(float(x.max()) for x in fast[0::3]) > 10.0     # edges were seen
    # the separation is the raise's part across the lines
    assert all(np.all(sep <= shift + 1e-9) for sep, shift in zip(fast[1::3], fast[2::3]))


def test_the_compiled_outline_patch_gives_numpys_samples_and_patch(box_frame, monkeypatch):
    """The lone-face search's samples and gradient patch compiled
    (`kernels_geometry.nb_outline_patch`) give the numpy path's, byte for byte, and so
    its evidence: feet near, far and beside the view, faces low and high (raised lines
    partly out of the image), all directions and some."""
    gpod, _ = _need_numba()
    if gkg.nb_outline_patch is None:
        pytest.skip('numba not installed')
    det, _, _ = box_frame
    ctx = det._ctx
    feet = [np.array([3.0, 0.3]), np.array([4.6, -0.8]), np.array([2.2, 1.1]),
            np.array([0.6, 2.5]), np.array([7.5, -3.0])]
    phis = [gpod_faces._LONE_PHI, gpod_faces._LONE_PHI[5:23], gpod_faces._LONE_PHI[:1]]

    def run():
        return [x for foot in feet for h in (0.04, 0.3, 1.5) for phi in phis
                for x in ctx.outline_evidence(foot, h, phi)]

    fast, slow = _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_outline_patch',), run)
    assert all(x.tobytes() == y.tobytes() and x.dtype == y.dtype for x, y in zip(fast, slow))


def test_lone_face_test_compiled_equals_numpy(box_frame, monkeypatch):
    """The lone-face search's bar, running sums, ends and tests compiled
    (`kernels_geometry.nb_lone_support`) give the numpy path's, on a real frame's
    evidence and on random evidence with ties, zeros and NaNs; and `lone_face_points`
    the same points either way."""
    gpod, _ = _need_numba()
    det, _, _ = box_frame
    ctx = det._ctx
    consts = (gpod_faces._LONE_BAR, gpod_faces._LONE_STEP_M, gpod_faces._LONE_MIN_M,
              gpod_faces._LONE_MIN_SEP_PX, gpod_faces._LONE_MIN_SEP_FRACTION)

    def numpy_test(ev, sep, shift, floor):
        bar_k, step, min_m, min_px, min_frac = consts
        bar = max(bar_k * float(gpod_faces._row_median(ev.mean(axis=1))), floor)
        gain = np.cumsum(ev - bar, axis=1)
        end = np.argmax(gain, axis=1)
        support = gain[np.arange(ev.shape[0]), end]
        ok = ((support > 0.0) & ((end + 1) * step >= min_m)
              & (gpod_faces._row_median(sep) >= min_px)
              & (gpod_faces._row_median(sep / np.maximum(shift, 1e-9)) >= min_frac))
        return ok, end, support

    cases = []
    for foot in (np.array([3.0, 0.3]), np.array([4.6, -0.8]), np.array([2.2, 1.1])):
        for h in (0.04, 0.3, 1.5):
            _, ev, sep, shift = ctx.outline_evidence(foot, h, gpod_faces._LONE_PHI)
            cases += [(ev, sep, shift, 0.0), (ev, sep, shift, 6.0),
                      (ev[:1], sep[:1], shift[:1], 0.0), (ev[:2], sep[:2], shift[:2], 1.0)]
    rng = np.random.default_rng(3)
    for n_d in (1, 2, 5, 36):
        ev = np.round(rng.exponential(5.0, (n_d, 35)), 1)
        sep = rng.uniform(0.0, 6.0, (n_d, 35))
        shift = np.where(rng.random((n_d, 35)) < 0.1, 0.0, sep / rng.uniform(0.3, 1.0))
        cases.append((ev, sep, shift, 0.0))
        for arr in (ev, sep, shift):
            bad = arr.copy()
            bad[rng.random(bad.shape) < 0.05] = np.nan
            cases.append((bad if arr is ev else ev, bad if arr is sep else sep,
                          bad if arr is shift else shift, 0.5))
    n_ok = 0
    for ev, sep, shift, floor in cases:
        want = numpy_test(ev, sep, shift, floor)
        got = gkg.nb_lone_support(np.ascontiguousarray(ev), np.ascontiguousarray(sep),
                                  np.ascontiguousarray(shift), consts[0], floor, *consts[1:])
        for a, b in zip(got, want):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
        n_ok += int(want[0].sum())
    assert n_ok > 0

    xy = np.array([[3.0, 0.3], [4.6, -0.8], [2.2, 1.1], [2.25, 1.12]])
    group = np.array([0, 1, 2, 2])
    args = (xy, group, 3, xy[[0, 1, 3]], np.array([0.1, 0.25, 0.05]), np.zeros(4, bool))
    _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_lone_support',),
                           lambda: [gpod.lone_face_points(ctx, *args, f) for f in (0.0, 5.0)])


def _face_image(ctx, foot, phi, height, face_band):
    """A flat grey left image (100) with one bright (160) region in the frame's view:
    with ``face_band``, the band between the ground line from ``foot`` along ``phi``
    (0.6 m) and the same line raised by ``height`` (a box's face: two parallel edges);
    without, the half-plane on one side of that ground line (one edge)."""
    d = np.array([math.cos(phi), math.sin(phi)])
    g = np.stack([foot, foot + 0.6 * d])
    u, v = ctx.to_image(g)
    img = np.full(ctx._left.shape, 100, np.uint8)
    if face_band:
        p3 = ctx.origin[None, :] + g[:, :1] * ctx.fwd + g[:, 1:] * ctx.lft
        ut, vt = ctx.cam.project_left(p3 + height * ctx.metric.normal_up)
        poly = np.array([[u[0], v[0]], [u[1], v[1]], [ut[1], vt[1]], [ut[0], vt[0]]])
    else:
        e = np.array([u[1] - u[0], v[1] - v[0]]) * 50.0
        n = np.array([-e[1], e[0]])
        p0 = np.array([u[0], v[0]])
        poly = np.array([p0 - e, p0 + e, p0 + e + n, p0 - e + n])
    cv2.fillPoly(img, [np.round(poly * 16).astype(np.int32)], 160, cv2.LINE_AA, 4)
    return cv2.GaussianBlur(img, (0, 0), 0.6)


def test_a_lone_face_must_cross_its_raise(box_frame, monkeypatch):
    """A single edge leading from a low obstacle's foot nearly along the line of sight
    (a paving joint towards the camera) meets its own copy raised by the obstacle's
    height: both lines of the face test see it. It lies 2.5 px or more across itself
    (the pixel bar) but at only 0.7 of the raise, and is no face: the foot stays. A box's
    face across the line of sight (two edges, crossing the raise at right angles) moves
    it; and without the fraction the single edge would have moved it too."""
    import copy
    from asmonc_vision.core import gpod
    det, _, _ = box_frame
    ctx = copy.copy(det._ctx)
    ctx._ground_xy = np.zeros((0, 2))           # no visible ground for the faces to hide
    foot, h = np.array([2.5, -0.5]), 0.04
    args = (np.array([foot]), np.zeros(1, np.int64), 1, np.array([foot]), np.array([h]),
            np.zeros(1, bool), 4.0)
    steep = math.radians(190.0)                 # 21 deg off the line of sight, towards us
    ctx._left = _face_image(ctx, foot, steep, h, face_band=False)
    _, ev, sep, shift = ctx.outline_evidence(foot, h, np.array([steep]))
    reach = slice(0, 15)                        # 0.3 m along it
    assert np.median(ev[0, reach]) > 10.0 and np.median(sep[0, reach]) >= 2.5
    assert np.median(sep[0, reach] / shift[0, reach]) < 0.75
    assert np.isnan(gpod.lone_face_points(ctx, *args)).all()
    with monkeypatch.context() as m:
        m.setattr(gpod_faces, '_LONE_MIN_SEP_FRACTION', 0.0)
        moved = gpod.lone_face_points(ctx, *args)[0]
    assert np.hypot(*moved) < np.hypot(*foot) - 0.1
    across = math.radians(100.0)
    ctx._left = _face_image(ctx, foot, across, h, face_band=True)
    _, _, sep, shift = ctx.outline_evidence(foot, h, np.array([across]))
    assert np.median(sep[0, reach] / shift[0, reach]) > 0.95
    q = gpod.lone_face_points(ctx, *args)[0]
    assert np.hypot(*q) < np.hypot(*foot) - 0.05
    assert abs(math.atan2(q[1] - foot[1], q[0] - foot[0]) - across) < math.radians(10.0)


def test_silhouette_owners_compiled_equals_numpy(monkeypatch):
    """The compiled `silhouette_owners` (nearest matching obstacle, outermost candidate
    per side, free-space test against the visible ground) assigns as the numpy path."""
    gpod, _ = _need_numba()
    rng = np.random.default_rng(5)
    cases = []
    for _ in range(40):
        n_c = int(rng.integers(1, 5))
        s_n = int(rng.integers(1, 12))
        g_lab = np.sort(rng.integers(0, n_c, s_n))
        g_lab[:n_c] = np.arange(min(n_c, s_n))
        centre = rng.uniform([3.0, -1.0], [5.0, 1.0], (n_c, 2))
        xy = centre[g_lab] + rng.normal(0.0, 0.2, (s_n, 2))
        height = rng.uniform(0.05, 0.5, n_c)
        w_n = int(rng.integers(0, 10))
        xw = centre[rng.integers(0, n_c, w_n)] + rng.normal(0.0, 0.5, (w_n, 2))
        top = rng.uniform(0.02, 0.6, w_n)
        ground = rng.uniform([2.5, -1.5], [5.5, 1.5], (int(rng.integers(0, 300)), 2))
        # every other case with the hidden-ground test (a camera 0.8-1.6 m up)
        cam_h = float(rng.uniform(0.8, 1.6)) if len(cases) % 2 else math.inf
        cases.append((xw, top, xy, g_lab, height, 0.7, ground, cam_h,
                      rng.uniform(0.0, 0.08, w_n), rng.uniform(0.0, 0.08, s_n)))
    fast, _ = _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_owners',),
                                     lambda: [gpod.silhouette_owners(*c) for c in cases])
    flat = np.concatenate(fast)
    assert (flat >= 0).sum() > 10 and (flat < 0).sum() > 10


def test_group_quantile_and_thinning_compiled_equal_numpy(monkeypatch):
    """The compiled per-group quantile and the thinning of `cluster_points_2d` give the
    numpy paths' values and labels."""
    gpod, _ = _need_numba()
    rng = np.random.default_rng(9)
    data = []
    for _ in range(200):
        n_g = int(rng.integers(1, 9))
        n = int(rng.integers(1, 50))
        g = rng.integers(0, n_g, n)
        x = np.round(rng.normal(0.0, 1.0, n), int(rng.integers(0, 3)))   # with ties
        data.append((g, x, float(rng.choice([0.1, 0.5, 0.9, 0.25])), n_g))
    pts = [rng.uniform(0.0, 3.0, (int(rng.integers(1, 400)), 2)) for _ in range(20)]
    grp = [rng.integers(0, 60, p.shape[0]) * 3 for p in pts]
    _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_group_quantile', 'nb_thin'),
                           lambda: ([gpod_grouping._group_quantile(*d) for d in data]
                                    + [cluster_points_2d(p, g, 0.25)
                                       for p, g in zip(pts, grp)]))


def test_run_and_string_kernels_equal_numpy(box_frame, monkeypatch):
    """On a real frame's matches: the compiled runs (links, lengths, smoothing), the
    half-occlusion test with its ordering, the hanging runs with their run bottoms and
    the ground candidates of the ambiguity test equal the numpy paths'."""
    gpod, _ = _need_numba()
    from asmonc_vision.core.edges import detect_vertical_edges
    from asmonc_vision.core.matching import pmf_match
    det, (left, right), _ = box_frame
    el, er = detect_vertical_edges(left), detect_vertical_edges(right)
    m, cand, _ = pmf_match(el, er, 0.5, 80.0)
    assert len(cand) > len(m) > 1000
    # disparities on a quarter-pixel grid: steps of exactly the tolerance occur
    m = dataclasses.replace(m, d=(np.round(m.d * 4.0) / 4.0).astype(np.float32))
    rng = np.random.default_rng(4)
    x = rng.normal(0.0, 1.0, len(m))
    perm = rng.permutation(len(m))                  # matches in no particular order
    shuffled = dataclasses.replace(m, **{f.name: getattr(m, f.name)[perm]
                                         for f in dataclasses.fields(m)})
    k_runs = [gk.nb_runs(el.string_prev, m.left_index, m.d, len(el), np.float32(tol),
                            win, x) for tol, win in ((1.0, 5), (0.3, 3), (1.0, 1))]
    trusted = rng.random(len(m)) < 0.7
    h = rng.uniform(0.0, 1.5, len(m))
    only = rng.random(len(m)) < 0.3
    prev = k_runs[0][0]

    def rest():
        return ([gpod.occluded_matches(er, m, 1.0, trusted),
                 gpod.occluded_matches(er, m, 0.5),
                 gpod.occluded_matches(er, shuffled, 1.0, trusted[perm]),
                 gpod.occluded_matches(er, shuffled, 0.5, trusted[perm], neighbours=1)]
                + [gpod.hanging_runs(el, m, prev, h, top, 1.0, 0.1, sel)
                   for top in (0.2, 0.5, 1.0) for sel in (None, only)])

    _, slow = _compiled_equals_numpy(monkeypatch, _GPOD,
                                     ('nb_runs', 'nb_occluded_all', 'nb_hanging_all',
                                      'nb_occluded', 'nb_hanging'), rest)
    assert all(y.any() and not y.all() for y in slow)
    np.testing.assert_array_equal(slow[2], slow[0][perm])
    # (a match's neighbours are its string's matches in row order, whatever their order)
    key = rng.integers(0, 50, 1000)
    rows = np.flatnonzero(rng.random(1000) < 0.6)
    np.testing.assert_array_equal(gk.nb_stable_order(key, rows, 50),
                                  rows[np.argsort(key[rows], kind='stable')])
    for (pk, rk, sk, nk), (tol, win) in zip(k_runs, ((1.0, 5), (0.3, 3), (1.0, 1))):
        p = gpod.run_links(el, m, tol)
        np.testing.assert_array_equal(pk, p)
        np.testing.assert_array_equal(rk, gpod.matched_run_length(el, m, tol, p))
        np.testing.assert_array_equal(sk, gpod.smooth_along_runs(x, p, win))
        nxt = np.full(len(m), -1, np.int64)
        nxt[p[p >= 0]] = np.flatnonzero(p >= 0)
        np.testing.assert_array_equal(nk, nxt)
    assert (k_runs[0][1] > 1).any() and (k_runs[1][0] < 0).sum() > (k_runs[0][0] < 0).sum()


def test_detector_outputs_equal_without_the_new_kernels(monkeypatch):
    """The whole detector, with the compiled kernels and without them (the numpy
    paths), gives the same results, field for field: calibration, standing still
    (averaged excess), walking frames with boxes, and a step down."""
    gpod, mt = _need_numba()
    frames = ([render_pair(seed=6)] * 3
              + [render_pair(boxes=[(-0.5, 0.0, 3.0, 3.3, 0.2), (0.4, 0.8, 4.2, 4.6, 0.5)],
                             seed=6)] * 3
              + [render_pair(boxes=[(-0.3, 0.3, 2.5 + 0.2 * i, 2.9 + 0.2 * i, 0.3)],
                             seed=10 + i) for i in range(3)]
              + [render_pair(step=(4.0, 0.2), seed=8)] * 2)

    def run():
        det = GpodDetector(GpodConfig())
        return [det.process(left, right, CAM, stamp_ns=100_000_000 * i)
                for i, (left, right) in enumerate(frames)]

    def same(x, y, where):
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, where
            np.testing.assert_array_equal(x, y, err_msg=where)
        elif dataclasses.is_dataclass(x):
            for f in dataclasses.fields(x):
                if f.name != 'timings_ms':
                    same(getattr(x, f.name), getattr(y, f.name), f'{where}.{f.name}')
        elif isinstance(x, (tuple, list)):
            assert len(x) == len(y), where
            for i, (a, b) in enumerate(zip(x, y)):
                same(a, b, f'{where}[{i}]')
        elif isinstance(x, float) and math.isnan(x):
            assert math.isnan(y), where
        else:
            assert x == y, where

    fast = run()
    assert any(r.still for r in fast) and not all(r.still for r in fast[3:])
    assert sum(len(r.detections) for r in fast) >= 6
    assert any(o.is_drop for r in fast for o in r.detections)
    _without(monkeypatch, _GPOD, _NEW_GPOD_KERNELS)
    _without(monkeypatch, mt, _NEW_MATCHING_KERNELS)
    for i, (x, y) in enumerate(zip(fast, run())):
        same(x, y, f'frame {i}')
        same(x.metric_plane, y.metric_plane, f'frame {i} plane')


def test_stillness_and_temporal_kernels_equal_numpy(box_frame, monkeypatch):
    """The compiled stillness test (edge pixels within one column of the previous
    frame's) and running average of the excess give the numpy paths' decisions, sums
    and state, for edges shifted by 0-2 columns and rows."""
    gpod, _ = _need_numba()
    from asmonc_vision.core.edges import detect_vertical_edges
    det, (left, _), r = box_frame
    el0 = detect_vertical_edges(left)
    shifted = [detect_vertical_edges(np.roll(left, (dv, du), axis=(0, 1)))
               for dv, du in ((0, 0), (0, 1), (0, -1), (0, 2), (1, 0))]
    from asmonc_vision.core.matching import pmf_match
    rng = np.random.default_rng(2)
    m = pmf_match(el0, detect_vertical_edges(left), 0.0, 10.0)[0]     # matches to average
    excess = [rng.normal(0.0, 1.0, len(m)) for _ in range(3)]
    thr = rng.uniform(0.3, 1.5, len(m))

    def run():
        d = GpodDetector(override(det.config, {'temporal.still_overlap': 0.5}))
        still = []
        for el in shifted:
            d._prev_edges = None
            d._stillness(el0)
            still.append(d._stillness(el))
            still.append(d._prev_edges.copy())
        sums = []
        d._acc = None
        for i, ex in enumerate(excess):
            sums.append(d._temporal_excess(m, ex, i > 0, el0.shape, thr if i else None))
            sums.extend(d._acc)
        return still + sums

    fast, _ = _compiled_equals_numpy(monkeypatch, _GPOD, ('nb_still', 'nb_temporal'), run)
    decisions = fast[0:10:2]
    assert decisions[0] and decisions[1] and decisions[2] and not decisions[3]
    assert not np.array_equal(fast[-3], excess[2])          # averaged with the sums


@pytest.fixture(scope='module')
def bollard_walk():
    """The camera and frames 78-92 of walk_obstacles seed 3002 (simulator), rendered once
    for the cases below."""
    from asmonc_vision.sim import StereoRenderer, make_scenario, simulate_frame

    sc = make_scenario('walk_obstacles', seed=3002)
    rend = StereoRenderer(sc.rig)
    return sc.rig.camera(), [simulate_frame(sc, k, rend) for k in range(78, 93)]


@pytest.mark.parametrize('missing', [(), (89, 90), (88, 89, 90, 91, 92)])
def test_an_obstacle_walked_up_to_is_still_reported_once_its_foot_leaves_the_view(
        missing, bollard_walk):
    """The paper's rig sees the ground from about 1.4 m, the alarm stops at 1.2 m: an
    84 cm bollard walked up to (simulator, true camera motion as the tracks' input) must
    go on being reported, coasted, at its true place once its foot has left the bottom
    of the image -- not dropped there as passed. With the motion of two pairs missing
    (a missed /egomotion) the tracks are carried by the motion before
    (``tracks.motion_hold_frames``); with five missing, the bollard is held where it was
    last placed once the hold runs out, not forgotten."""
    cam, frames = bollard_walk
    det, prev, near = GpodDetector(), None, []
    for f in frames:
        k = f.index
        motion = None
        if prev is not None and k not in missing:       # X_prev = R X_curr + t
            motion = (prev.rotation.T @ f.left_pose.rotation,
                      prev.rotation.T @ (f.left_pose.centre - prev.centre))
        prev = f.left_pose
        r = det.process(f.left, f.right, cam, stamp_ns=int(round(f.time * 1e9)),
                        motion=motion)
        bollard = [o for o in f.obstacles if o.kind == 'bollard' and o.height > 0.8]
        if bollard and bollard[0].range < 1.2:
            t = bollard[0]
            txy = t.range * np.array([math.cos(t.bearing), math.sin(t.bearing)])
            err = [float(np.hypot(*(o.range * np.array([math.cos(o.bearing),
                                                        math.sin(o.bearing)]) - txy)))
                   for o in r.obstacles if o.height > 0]
            best = int(np.argmin(err)) if err else -1
            near.append((t.range, min(err, default=math.inf),
                         [o for o in r.obstacles if o.height > 0][best].age_s
                         if best >= 0 else None))
    assert len(near) >= 3, near                         # 1.10, 0.98, 0.87, 0.81 m
    # carried by a guessed motion for two pairs the place is less sure (measured 0.16 m);
    # held in place after that, it lags the walk by ~0.12 m a pair (measured 0.14, 0.28,
    # 0.41, 0.42 m), but it is still reported
    tol = 0.5 if len(missing) > 2 else 0.25 if missing else 0.12
    assert all(e <= tol for _, e, _ in near), near
    assert any(age is not None and age > 0 for _, _, age in near), near   # coasted


def test_a_whole_placed_at_a_lower_body_takes_that_body_s_description():
    """An obstacle joined from parts and reported at one part's nearest point is
    described by that part when it is another, lower body: a two-pixel blip of the
    ground 0.7 m in front of an 18 cm box once made an '18 cm obstacle, confidence 1, 2
    metres ahead' (a false WARNING on a static scene; the box stood 20 degrees right).
    Parts of a like height (one box's two silhouette edges), a low part with no ground
    seen between it and the rest (a wall's end at the image's border, seen only near its
    foot) and a whole placed between its parts keep the whole's description."""
    from asmonc_vision.core.gpod import GpodObstacle, described_by_part
    up = np.array([0.0, -0.94, -0.34])

    def ob(rng, bearing_deg, height, conf, roi, n):
        return GpodObstacle(position=np.array([0.0, 1.0, rng]) + height * up, height=height,
                            range=rng, bearing=math.radians(bearing_deg), width=0.6,
                            disparity_excess=3.0 * height / 0.18, confidence=conf, roi=roi,
                            num_edge_pixels=n, string_ids=np.array([80, 129, 133], np.int32))

    whole = ob(2.06, 1.2, 0.18, 1.0, (40, 131, 124, 49), 37)
    blip = ob(1.91, -1.0, 0.03, 0.13, (163, 185, 2, 6), 2)
    edge_a = ob(2.64, 12.8, 0.18, 0.9, (96, 131, 3, 20), 18)
    edge_b = ob(2.71, 23.1, 0.18, 0.85, (40, 133, 4, 22), 17)
    # the pavement seen everywhere but under the box (2.45-2.95 m ahead, 0.5-1.1 m left)
    gx, gy = np.meshgrid(np.arange(1.0, 4.0, 0.05), np.arange(-1.0, 1.5, 0.05))
    ground = np.stack([gx.ravel(), gy.ravel()], axis=1)
    ground = ground[~((ground[:, 0] > 2.45) & (ground[:, 1] > 0.5))]
    out = described_by_part([whole], [blip, edge_a, edge_b], np.zeros(3, np.int64), 0.35,
                            up, ground)
    got = out[0]
    assert (got.height, got.confidence, got.roi, got.num_edge_pixels) == (0.03, 0.13,
                                                                          blip.roi, 2)
    assert got.range == whole.range and got.bearing == whole.bearing
    assert got.width == whole.width and np.array_equal(got.string_ids, whole.string_ids)
    assert np.allclose(got.position - got.height * up, whole.position - whole.height * up)
    # no ground seen behind the line from the low part to the highest: one body
    near = ground[ground[:, 0] < 1.8]
    assert described_by_part([whole], [blip, edge_a, edge_b], np.zeros(3, np.int64), 0.35,
                             up, near)[0] is whole
    # the nearer part as high as the whole (a box's near edge): the whole's own
    near_edge = ob(1.95, -0.5, 0.16, 0.6, (150, 150, 3, 20), 12)
    assert described_by_part([whole], [near_edge, edge_a], np.zeros(2, np.int64), 0.35,
                             up, ground)[0] is whole
    # placed between two parts within 0.35 m of both (a hidden corner), or a whole of
    # one part: its own
    low, high = ob(2.0, 0.0, 0.03, 0.13, (160, 150, 2, 6), 2), ob(2.0, 8.0, 0.18, 1.0,
                                                                  (120, 140, 20, 20), 30)
    between = ob(2.0, 4.0, 0.18, 1.0, (120, 140, 42, 20), 32)
    assert described_by_part([between], [low, high], np.zeros(2, np.int64), 0.35,
                             up, ground)[0] is between
    assert described_by_part([between, whole], [low, high], np.array([1, 1]), 0.35,
                             up, ground)[0] is between


def test_a_noisy_camera_standing_still_is_still():
    """The rig counts as still when its strong edges stay in place. On a camera of pixel
    noise sigma 4 the weak edges come and go with the noise: standing still, 0.68 of all
    its edge pixels stayed in place, under still_overlap (0.8), so a standing wearer was
    taken for walking (no averaging over frames, no still view). A walk is still seen
    as one."""
    from asmonc_vision.sim.rig import RigSettings
    from asmonc_vision.sim.scenarios import make_scenario, simulate
    for name, still in (('clear_static', True), ('clear_walk', False)):
        sc = make_scenario(name, seed=8073, duration=1.0, rig=RigSettings(noise_sigma=4.0))
        cam = sc.rig.camera()
        det = GpodDetector(GpodConfig())
        flags = [det.process(f.left, f.right, cam).still for f in simulate(sc)]
        if still:
            assert all(flags[1:]), flags
        else:
            assert not any(flags[3:]), flags          # walking from the start


def _plane_off_px(abc, truth_plane, cam) -> float:
    """Largest disparity error (px) of the plane ``abc`` against the true ground plane
    (metric, left optical frame) at nine points of the image's lower part."""
    from asmonc_vision.core.camera import plane_disparity, plane_from_metric
    uu, vv = np.meshgrid([40.0, 160.0, 280.0], [140.0, 190.0, 235.0])
    return float(np.abs(plane_disparity(abc, uu, vv)
                        - plane_disparity(plane_from_metric(cam, truth_plane), uu, vv)).max())


def test_smooth_slabs_walked_on_without_motion_keep_the_plane_or_lose_it():
    """A clear walk on smooth concrete slabs (1.5 m, faint texture; simulator clear_walk
    seed 8113 with that pavement), with no camera motion (the egomotion node finds too
    few corners there). The only vertical edges are the joints along the walk, which
    forward motion keeps in place: the rig looked still, the plane stayed anchored where
    it "stopped" while the body's pitch sway moved the ground 4-5 px, and a refit from
    the pixels along one joint turned the plane about that joint. In 16 of the 80
    frames the plane was over 1 px off at the image's lower half, and obstacles and
    drop-offs stood all over the clear pavement (WARNING "drop, 1.5 metres"). Now a
    still-anchored refit that finds no ground refits as when moving, and a fit whose
    inliers lie along one line is refused: the plane is right, or the status is lost
    (a fault the wearer hears), in all but a few frames."""
    import dataclasses

    from asmonc_vision.sim import StereoRenderer, simulate_frame
    from asmonc_vision.sim import scenarios

    def smooth(rng):
        p = random_pavement(rng)
        return dataclasses.replace(p, tile_length=1.5, tile_width=1.5, grout_width=0.01,
                                   grout_brightness=p.brightness - 35, tile_spread=0.05,
                                   texture_contrast=0.06)
    random_pavement = scenarios.random_pavement
    scenarios.random_pavement = smooth
    try:
        sc = scenarios.make_scenario('clear_walk', seed=8113)
    finally:
        scenarios.random_pavement = random_pavement
    rend, cam = StereoRenderer(sc.rig), sc.rig.camera()
    det = GpodDetector(GpodConfig())
    off, lost, false = [], 0, []
    for k in range(sc.n_frames):
        f = simulate_frame(sc, k, rend)
        r = det.process(f.left, f.right, cam)
        if r.status == 'lost':
            lost += 1
        elif r.status == 'tracking' and _plane_off_px(r.plane_abc, f.plane, cam) > 1.0:
            off.append(k)
        false += [k for o in r.obstacles if o.confidence >= 0.3 and o.range <= 5.0
                  and abs(o.height) >= 0.05 and o.num_edge_pixels > 0]
    # measured: 2 frames off (65, 74), 13 of the 80 lost, no false report
    assert len(off) <= 3, off
    assert lost <= 15, lost
    assert len(false) <= 2, false


def test_weakly_textured_ground_lowers_the_edge_threshold_to_find_the_plane():
    """A walk towards obstacles on asphalt-like ground (the simulator's walk_obstacles,
    seed 8115, its pavement without joints or tile shades: a faint mottled texture
    only), no camera motion given. At the usual 4 grey levels per pixel the lower half of
    the image has under one edge per row: the calibration took a plane through chance
    matches, 2-4 px off at the image's lower part in most frames (the ground read as a
    drop, obstacles hidden in it). The threshold is now lowered there to the image's
    noise floor, and the plane is right."""
    from asmonc_vision.sim import StereoRenderer, simulate_frame
    from asmonc_vision.sim import scenarios

    def asphalt(rng):
        return dataclasses.replace(random_pavement(rng), grout_width=0.0, tile_spread=0.0,
                                   texture_contrast=0.2)
    random_pavement = scenarios.random_pavement
    scenarios.random_pavement = asphalt
    try:
        sc = scenarios.make_scenario('walk_obstacles', seed=8115, duration=6.0)
    finally:
        scenarios.random_pavement = random_pavement
    rend, cam = StereoRenderer(sc.rig), sc.rig.camera()
    frames = [simulate_frame(sc, k, rend) for k in range(sc.n_frames)]
    runs = {}
    for density in (GpodConfig().edges.min_density, 0.0):
        det = GpodDetector(override(GpodConfig(), {'edges.min_density': density}))
        tracked, off, thr = 0, [], []
        for k, f in enumerate(frames):
            r = det.process(f.left, f.right, cam)
            thr.append(r.edge_threshold)
            if r.status == 'tracking':
                tracked += 1
                if _plane_off_px(r.plane_abc, f.plane, cam) > 1.0:
                    off.append(k)
        runs[density] = tracked, off, float(np.median(thr))
    tracked, off, thr = runs[GpodConfig().edges.min_density]
    assert tracked >= len(frames) - 3, runs
    assert len(off) <= 3, runs
    noise_floor = GpodConfig().edges.noise_floor_snr * 0.433 * 2.0   # pixel noise 2
    assert noise_floor * 0.9 <= thr < 3.0, runs
    # without it (seen: 17 frames tracked, all 17 over 1 px off)
    tracked0, off0, thr0 = runs[0.0]
    assert thr0 == GpodConfig().edges.threshold
    assert len(off0) >= tracked0 // 2, runs


@pytest.mark.parametrize('ground_fraction, fraction, want', [
    (0.06, 0.1, 'initialising'), (0.06, 0.0, 'tracking'), (0.5, 0.1, 'tracking')])
def test_the_initial_plane_must_hold_a_part_of_the_features(ground_fraction, fraction, want):
    """On ground with no clear edges (an asphalt-like texture in the simulator) most
    matches are wrong, and the calibration took a plane through 41 of 1238 features (3 %):
    every later frame stood on it, with two false STOPs. Features of which only 6 % lie
    on a plane leave the detector initialising (the alarm says "starting up", then
    "cannot see the ground"), though the plane is found (RANSAC run long enough to find
    it surely); half on it calibrate."""
    from asmonc_vision.core.camera import MetricPlane, plane_from_metric
    pitch = math.radians(20.0)
    abc = plane_from_metric(CAM, MetricPlane(
        normal_up=np.array([0.0, -math.cos(pitch), -math.sin(pitch)]), height=1.25))
    rng = np.random.default_rng(5)
    n = 1000
    u, v = rng.uniform(0, 319, n), rng.uniform(60, 239, n)
    d = rng.uniform(2.0, 30.0, n)                         # mismatches
    on = rng.random(n) < ground_fraction
    d[on] = abc[0] * u[on] + abc[1] * v[on] + abc[2] + rng.normal(0.0, 0.1, on.sum())
    det = GpodDetector(override(GpodConfig(), {'plane.init_frames': 1,
                                               'plane.init_min_inlier_fraction': fraction,
                                               'plane.ransac_iterations': 30000}))
    status, _ = det._update_plane(u, v, d, np.full(n, 10.0), CAM)
    assert status == want


@pytest.mark.parametrize('bound, want', [(0.03, 'initialising'), (0.0, 'tracking')])
def test_the_initial_plane_must_be_fixed_by_its_features(bound, want):
    """On the chest rig over a plain pavement the full-size images' only edges were the
    joints of a kerb across the view and a few ground matches just before it (tuning
    kerb_ramp 1023): a plane through that band fits any tilt, and the calibration took
    a plane 2.13 m below the camera (truly 1.38 m) and 8 degrees off. Here: a kerb's joints 5 m
    ahead of the paper's rig and 30 ground features 4.0-4.9 m ahead. Without the bound
    on the camera height's standard deviation the plane is metres off; with it the
    detector waits for features that fix the ground. Ground seen 2-8 m ahead
    calibrates with it, within 1 cm of the true height."""
    th, h = math.radians(20.0), 1.25

    def project(fwd, left, up):
        y = h - up
        pts = np.stack([-left, y * math.cos(th) - fwd * math.sin(th),
                        y * math.sin(th) + fwd * math.cos(th)], -1)
        return CAM.project(pts)

    rng = np.random.default_rng(3)
    lat, up = np.meshgrid(np.arange(-3.0, 3.01, 0.5), np.linspace(0.0, 0.15, 12))
    fwd = np.concatenate([5.0 + rng.normal(0.0, 0.02, lat.size), rng.uniform(4.0, 4.9, 30)])
    lat = np.concatenate([lat.ravel(), rng.uniform(-3.0, 3.0, 30)])
    up = np.concatenate([up.ravel(), np.zeros(30)])
    u, v, d = project(fwd, lat, up)
    d = d + rng.normal(0.0, 0.1, d.shape)
    det = GpodDetector(override(GpodConfig(), {'plane.init_frames': 1,
                                               'plane.init_max_height_sd_m': bound}))
    status, _ = det._update_plane(u, v, d, np.full(u.shape, 10.0), CAM)
    assert status == want
    if status == 'tracking':
        assert abs(det.calibrated_plane.metric.height - h) > 0.5
    ground = GpodDetector(override(GpodConfig(), {'plane.init_frames': 1}))
    u, v, d = project(rng.uniform(2.0, 8.0, 400), rng.uniform(-3.0, 3.0, 400), np.zeros(400))
    status, _ = ground._update_plane(u, v, d + rng.normal(0.0, 0.1, 400),
                                     np.full(400, 10.0), CAM)
    assert status == 'tracking'
    assert abs(ground.calibrated_plane.metric.height - h) < 0.01


@pytest.fixture(scope='module')
def vigorous_walk():
    """The camera and every frame of clear_walk seed 8202 with `GaitSettings.extreme`
    (simulator), rendered once for the cases below."""
    from asmonc_vision.sim import StereoRenderer, make_scenario, simulate
    from asmonc_vision.sim.motion import GaitSettings

    sc = make_scenario('clear_walk', seed=8202, gait=GaitSettings.extreme())
    return sc.rig.camera(), list(simulate(sc, StereoRenderer(sc.rig)))


@pytest.mark.parametrize('missing', [(52,), tuple(range(10, 80, 3))])
def test_a_vigorous_walker_frame_without_motion_does_not_leave_the_plane_off(
        missing, vigorous_walk):
    """The paper's extreme walking motion (5 degrees of sway, 10 cm bob; simulator
    clear_walk seed 8202 with `GaitSettings.extreme`) moves the ground by 10 px of
    disparity between frames. In the node graph the /egomotion of one frame (52) was
    missing: the refit within refit_gate_px (8 px) of the unmoved plane found no ground,
    the plane was carried over the frame unmoved, and then carried through the later
    motions, 10-20 px off, for motion_coast_frames (10): every feature was a drop,
    "stop, drop ahead, 1 metre" on a clear pavement. Now such a frame is refitted with
    the wider refit_retry_gate_px, and a plane carried over a frame without motion gets
    neither the narrow gate nor the long coast until a refit. Also with every third
    motion missing, the plane is right or lost (a fault the wearer hears), in all but a
    frame or two."""
    cam, frames = vigorous_walk
    det = GpodDetector(GpodConfig())
    prev, off, lost, false = None, [], [], []
    for k, f in enumerate(frames):
        motion = None
        if prev is not None and k not in missing:
            motion = (prev.rotation.T @ f.left_pose.rotation,
                      prev.rotation.T @ (f.left_pose.centre - prev.centre))
        prev = f.left_pose
        r = det.process(f.left, f.right, cam, motion=motion)
        if r.status == 'lost':
            lost.append(k)
        elif r.status == 'tracking' and _plane_off_px(r.plane_abc, f.plane, cam) > 1.0:
            off.append(k)
        false += [k for o in r.obstacles if o.confidence >= 0.3 and o.range <= 5.0
                  and abs(o.height) >= 0.05]
    if len(missing) == 1:
        assert not off and not false and not lost, (off, false, lost)
    else:
        assert len(off) <= 2 and len(false) <= 2 and len(lost) <= 8, (off, false, lost)


def _ground_features(n: int, rng, shift: float = 0.0):
    """n features (u, v, d) on the paper rig's ground plane, d shifted by ``shift`` px."""
    from asmonc_vision.core.camera import MetricPlane, plane_from_metric
    pitch = math.radians(PITCH)
    abc = plane_from_metric(CAM, MetricPlane(
        normal_up=np.array([0.0, -math.cos(pitch), -math.sin(pitch)]), height=HEIGHT))
    u, v = rng.uniform(0, 319, n), rng.uniform(60, 239, n)
    d = abc[0] * u + abc[1] * v + abc[2] + shift + rng.normal(0.0, 0.1, n)
    return u, v, d


@pytest.mark.parametrize('view, still, want', [
    ('ground below', False, 'lost'), ('ground above', False, 'lost'),
    ('wall', False, 'tracking'), ('ground below', True, 'tracking')])
def test_an_unconfirmed_plane_is_carried_without_motion_only_where_it_may_be(view, still,
                                                                             want):
    """A frame of a walk with no camera motion and no refit (the ground moved farther
    than both refit gates): the plane used to be carried over it anyway, for
    max_coast_frames. If the near half of the features then lies below the plane, or
    above it with the ground's slope, the plane is off, and every feature is a drop
    (smooth slabs: 'drop, 1.5 metres' with confidence 1) or an obstacle: lost. Above it
    as a wall (an obstacle filling the near view, no ground slope) it is still carried,
    and standing still it always is (the ground has not moved). The ground's slope is
    told among 30 % mismatches (which flatten a plain least-squares slope to nothing: a
    vigorous walker's ground 1.7 px above the plane was taken for a wall)."""
    rng = np.random.default_rng(8)
    det = GpodDetector(override(GpodConfig(), {'plane.init_frames': 1}))
    u, v, d = _ground_features(600, rng)
    assert det._update_plane(u, v, d, np.full(600, 10.0), CAM)[0] == 'tracking'
    if view == 'wall':
        u, v = rng.uniform(0, 319, 600), rng.uniform(0, 239, 600)
        d = 70.0 + rng.normal(0.0, 0.1, 600)            # a wall 1.5 m ahead
    else:
        u, v, d = _ground_features(600, rng, shift=-25.0 if view == 'ground below' else 25.0)
        bad = rng.random(600) < 0.3          # mismatches: any disparity, anywhere
        d[bad] = rng.uniform(2.0, 80.0, bad.sum())
    status, updated = det._update_plane(u, v, d, np.full(600, 10.0), CAM, still=still)
    assert (status, updated) == (want, False)


def test_the_right_cameras_gain_is_the_median_ratio_of_the_spreads():
    rng = np.random.default_rng(12)
    det, off = GpodDetector(), GpodDetector(override(GpodConfig(), {'image.right_gain_frames': 0}))
    gains = []
    for g in (0.7, 0.7, 0.5, 0.7, 0.7):      # one pair off (content that differs)
        left = np.clip(rng.normal(110, 30, (60, 80)), 0, 255).astype(np.uint8)
        right = np.clip(np.rint(g * left.astype(float) + 15), 0, 255).astype(np.uint8)
        gains.append(det._right_gain(left, right))
        assert off._right_gain(left, right) == 1.0
    assert gains[0] == pytest.approx(1 / 0.7, rel=0.01)
    assert gains[-1] == pytest.approx(1 / 0.7, rel=0.01)      # the median ignores the 0.5
    flat = np.full((60, 80), 90, np.uint8)
    assert det._right_gain(flat, flat) == pytest.approx(gains[-1])   # no contrast: kept
    with pytest.raises(ValueError, match='image.right_gain_frames'):
        override(GpodConfig(), {'image.right_gain_frames': -1})


def test_a_right_camera_with_its_own_gain_gives_no_phantom():
    """Two cameras with their own gain: the right one at 1.5 and -25 grey levels, in a
    walk that starts facing a striped wall 7-8 m off (walk_stop_turn 9016; true camera
    motion). Compared on the cameras' raw scales, the strength test let an edge string
    of the wall match the next stripe 7 px over for nine rows at its bottom; its foot was
    placed by that disparity at 4.7 m: a 1.15 m obstacle at confidence 1, 2.5 m before
    the wall (a false "obstacle, 4.5 metres, ahead" through the graph, at 1.7 s), and
    another 1.5 m before it at 3.6 s. With the strengths compared on one scale, an
    11-row stretch of a streak matched 7 px off (at 0.7 s) was held up by two stray
    pixels matched alike 25 rows below (`hanging_runs`' ``solid``). Now every confident
    report within 6 m lies within 0.5 m of an obstacle of the world."""
    from asmonc_vision.sim import RigSettings, StereoRenderer, make_scenario, simulate_frame

    sc = make_scenario('walk_stop_turn', seed=9016,
                       rig=RigSettings(right_gain=1.5, right_offset=-25.0))
    rend, cam = StereoRenderer(sc.rig), sc.rig.camera()
    tops = [np.asarray(ob.top_polygon())[:, :2].astype(np.float32)
            for ob in sc.world.obstacles if hasattr(ob, 'top_polygon')]
    assert tops
    det, prev, far, reports = GpodDetector(), None, [], 0
    for k in range(40):
        f = simulate_frame(sc, k, rend)
        motion = None
        if prev is not None:                               # X_prev = R X_curr + t
            motion = (prev.rotation.T @ f.left_pose.rotation,
                      prev.rotation.T @ (f.left_pose.centre - prev.centre))
        prev = f.left_pose
        r = det.process(f.left, f.right, cam, stamp_ns=int(round(f.time * 1e9)),
                        motion=motion)
        yaw = f.pose.rpy[2]
        for o in r.obstacles:
            if o.confidence < 0.3 or o.range > 6.0:
                continue
            reports += 1
            p = f.pose.position[:2] + o.range * np.array([math.cos(yaw + o.bearing),
                                                          math.sin(yaw + o.bearing)])
            dist = max(0.0, min(-cv2.pointPolygonTest(t, (float(p[0]), float(p[1])), True)
                                for t in tops))
            if dist > 0.5:
                far.append((k, round(o.range, 2), round(math.degrees(o.bearing), 1),
                            round(o.height, 2), round(dist, 2)))
    assert reports > 20                         # the wall and the box ahead are reported
    assert not far, far


def test_every_named_rule_left_out_the_papers_test_alone_decides():
    """With the lists of `GpodConfig.rules` empty a frame still gives its features
    and detections, and the box is still found; the rules only take evidence out (bar
    drop_region, which level ground never meets), so no rule gives an obstacle pixel."""
    bare = override(GpodConfig(), {'rules.pixels': (), 'rules.strings': (),
                                   'rules.drops': (), 'rules.placement': ()})
    pair = render_pair(boxes=[BOX], seed=2)
    _, ruled = _calibrated(pair, frames=4)
    _, plain = _calibrated(pair, bare, frames=4)
    assert ruled[-1].status == plain[-1].status == 'tracking'
    assert ruled[-1].obstacles and plain[-1].obstacles
    n_ruled = int(ruled[-1].features.is_obstacle.sum())
    n_plain = int(plain[-1].features.is_obstacle.sum())
    assert n_plain >= n_ruled > 0



@pytest.mark.parametrize('tilt_deg, bound, want', [(0.0, 20.0, 'tracking'),
                                                   (40.0, 20.0, 'initialising'),
                                                   (40.0, 0.0, 'tracking')])
def test_the_initial_plane_must_be_near_the_inclinometers_up(tilt_deg, bound, want):
    """A pedestrian starts on ground no steeper than a ramp; a calibration through a
    wall's or a kerb's edges can lie at any angle (tuning slope_ahead 1007, chest rig:
    the binned pass took a plane 76 degrees off the ground, 73 degrees off the
    inclinometer's up, and never recovered from it). Here: the paper's rig over ground
    2-8 m ahead, the pair's up direction the true one, or turned 40 degrees about the
    optical axis (the plane is then 40 degrees from it): refused with the 20 degree
    bound, taken without one."""
    th, h = math.radians(20.0), 1.25
    rng = np.random.default_rng(4)
    fwd, left = rng.uniform(2.0, 8.0, 400), rng.uniform(-3.0, 3.0, 400)
    pts = np.stack([-left, h * math.cos(th) - fwd * math.sin(th),
                    h * math.sin(th) + fwd * math.cos(th)], -1)
    u, v, d = CAM.project(pts)
    up = np.array([0.0, -math.cos(th), -math.sin(th)])
    a = math.radians(tilt_deg)
    turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                     [0.0, 0.0, 1.0]])
    det = GpodDetector(override(GpodConfig(), {'plane.init_frames': 1,
                                               'plane.init_max_tilt_deg': bound}))
    det._up = turn @ up
    status, _ = det._update_plane(u, v, d + rng.normal(0.0, 0.1, 400), np.full(400, 10.0),
                                  CAM)
    assert status == want
    if status == 'tracking':
        assert abs(det.calibrated_plane.metric.height - h) < 0.01


def _kerb_frame(rng, up: float, n: int = 400, h: float = 1.25):
    """Features of a level ground ``up`` metres above the ground the paper's rig (1.25 m
    high, pitched 20 degrees down) stands on, 2-8 m ahead, +-3 m across: the arguments
    of `_update_plane`."""
    th = math.radians(20.0)
    fwd, left = rng.uniform(2.0, 8.0, n), rng.uniform(-3.0, 3.0, n)
    y = h - up
    pts = np.stack([-left, y * math.cos(th) - fwd * math.sin(th),
                    y * math.sin(th) + fwd * math.cos(th)], -1)
    u, v, d = CAM.project(pts)
    return u, v, d + rng.normal(0.0, 0.1, n), np.full(n, 10.0), CAM


def _lost_detector(rng, max_change: float) -> GpodDetector:
    """The paper's rig calibrated 1.25 m above the ground, then lost on frames with a
    few features."""
    det = GpodDetector(override(GpodConfig(), {
        'plane.init_frames': 1, 'plane.recover_max_height_change_m': max_change}))
    assert det._update_plane(*_kerb_frame(rng, 0.0))[0] == 'tracking'
    for _ in range(4):
        status, _ = det._update_plane(*_kerb_frame(rng, 0.0, n=10))
    assert status == 'lost'
    return det


@pytest.mark.parametrize('max_change', [0.1, 1.0])
def test_a_lost_plane_recovers_only_at_the_height_the_rig_is_carried(max_change):
    """Lost, the plane is recovered from the nearer half of the features with no gate;
    before a kerb up (tuning kerb_up 1005 and 1019, chest rig: the raised footway filled
    it) or at the edge of a drop (the lower ground) that half can be another level, and
    every feature of the ground underfoot then stands off it. The wearer carries the rig
    at a steady height above the ground underfoot: a recovered plane whose camera height
    is more than ``plane.recover_max_height_change_m`` from both the anchor height and
    the calibrated one is refused. Here a level 0.15 m lower 2-8 m ahead: refused at
    0.1 m (still lost, and the ground it stands on is taken next), taken at 1.0 m."""
    rng = np.random.default_rng(5)
    det = _lost_detector(rng, max_change)
    status, _ = det._update_plane(*_kerb_frame(rng, -0.15))
    assert status == ('lost' if max_change < 0.15 else 'tracking')
    if status == 'tracking':            # the lower level taken as the ground underfoot
        assert abs(_plane_height(det) - 1.40) < 0.02
        return
    status, _ = det._update_plane(*_kerb_frame(rng, 0.0))
    assert status == 'tracking'
    assert abs(_plane_height(det) - 1.25) < 0.02


def test_a_lost_plane_recovers_at_the_calibrated_height_when_the_anchor_went_off():
    """The anchor height (the calibrated height and the latest held refits' free
    heights) can go off with the plane: on tuning stop_turn 1001 (chest rig, a wall
    after the turn) the free heights stood 0.5-0.9 m above the true one, and a recovery
    bound at the anchor alone refused every later recovery, 0-3 cm off the truth, and
    left the pass lost. A recovery within ``plane.recover_max_height_change_m`` of the
    calibrated height is taken too: here the anchor pushed 0.45 m high, the ground the
    wearer stands on is recovered; a level 0.2 m lower than that ground (0.25 m from the
    anchor) is not."""
    rng = np.random.default_rng(7)
    det = _lost_detector(rng, 0.1)
    det._heights.extend([1.70] * 10)                 # free heights gone 0.45 m high
    assert det._anchor_height() > 1.6
    status, _ = det._update_plane(*_kerb_frame(rng, -0.2))
    assert status == 'lost'
    status, _ = det._update_plane(*_kerb_frame(rng, 0.0))
    assert status == 'tracking'
    assert abs(_plane_height(det) - 1.25) < 0.02


def _plane_height(det: GpodDetector) -> float:
    """The camera height above the detector's current plane, m."""
    from asmonc_vision.core.gpod.support import _state_metric
    return _state_metric(CAM, det._abc).height


def test_replaced_is_dataclasses_replace():
    """`results.replaced` gives dataclasses.replace's obstacle (every field the same
    object), and refuses an unknown field alike."""
    from asmonc_vision.core.gpod import GpodObstacle
    from asmonc_vision.core.gpod.results import replaced
    ob = GpodObstacle(position=np.array([0.1, 0.2, 3.0]), height=0.3, range=3.0, bearing=0.1,
                      width=0.2, disparity_excess=4.0, confidence=0.5, roi=(1, 2, 3, 4),
                      num_edge_pixels=9, string_ids=np.array([1, 2], np.int32))
    changes = dict(track_id=7, confidence=0.9, position=np.array([0.0, 0.0, 2.0]))
    a, b = replaced(ob, **changes), dataclasses.replace(ob, **changes)
    assert type(a) is type(b)
    assert all(getattr(a, f.name) is getattr(b, f.name) for f in dataclasses.fields(b))
    assert ob.track_id == 0 and ob.confidence == 0.5
    with pytest.raises(TypeError):
        replaced(ob, colour=1)


def test_face_gap_points_with_a_split_are_each_sets_own():
    """`face_gap_points` of two sets of obstacles at once (``split``) gives each set's
    points of a call on that set alone, byte for byte: no pair across the sets."""
    from asmonc_vision.core.gpod import face_gap_points
    rng = np.random.default_rng(5)
    front = np.array([[x, y] for x in (1.6, 2.0, 2.4, 2.8) for y in (-0.6, -0.3, 0.0, 0.3, 0.6)])
    for trial in range(40):
        n_a, n_b = int(rng.integers(1, 5)), int(rng.integers(1, 5))
        sets = []
        for n in (n_a, n_b):
            # walls across the path in parts, blank middles, some noise
            sizes = rng.integers(1, 5, n)
            group = np.repeat(np.arange(n), sizes)
            y = np.concatenate([rng.uniform(-1.5, 1.5) + 0.3 * np.arange(k) for k in sizes])
            x = 3.0 + rng.normal(0.0, 0.01 if trial % 2 else 0.2, y.size)
            xy = np.column_stack([x, y])
            q = np.array([xy[group == k][np.argmin(np.hypot(*xy[group == k].T))]
                          for k in range(n)])
            sets.append((xy, group, q))
        (xa, ga, qa), (xb, gb, qb) = sets
        both = face_gap_points(np.vstack([xa, xb]), np.concatenate([ga, gb + n_a]),
                               n_a + n_b, np.vstack([qa, qb]), front, split=n_a)
        alone = np.vstack([face_gap_points(xa, ga, n_a, qa, front),
                           face_gap_points(xb, gb, n_b, qb, front)])
        assert both.tobytes() == alone.tobytes(), trial
        # without a split, the same sets as one may join across them
        assert face_gap_points(np.vstack([xa, xb]), np.concatenate([ga, gb + n_a]),
                               n_a + n_b, np.vstack([qa, qb]), front).shape == both.shape


def _parts_apart(det, whole, idx, label, radius, sign, min_pixels, hh, g2, m, excess, cam,
                 metric, fwd, lft):
    """The wholes and parts described by two `_describe` calls (the former `_parts`):
    the reference of the one call with a split."""
    from asmonc_vision.core.gpod.faces import _ground_points, described_by_part
    fine = cluster_points_2d(g2, m.string_id[idx], radius)
    pairs = np.unique(label * (int(fine.max()) + 1) + fine)
    n_parts = np.bincount(pairs // (int(fine.max()) + 1), minlength=int(label.max()) + 1)
    sel = n_parts[label] > 1
    if not sel.any():
        return whole, []
    _, part = np.unique(fine[sel], return_inverse=True)
    parts = det._describe(idx[sel], part.astype(np.int64), sign, min_pixels, hh[sel],
                          g2[sel], m, excess, cam, metric, fwd, lft)
    owner = np.zeros(len(parts), np.int64)
    owner[part] = label[sel]
    ctx = det._ctx
    whole = described_by_part(whole, parts, owner, radius, metric.normal_up,
                              lambda: ctx.ground_xy)
    at, p_at = _ground_points(whole), _ground_points(parts)
    far = np.hypot(p_at[:, None, 0] - at[None, :, 0],
                   p_at[:, None, 1] - at[None, :, 1]).min(axis=1) > radius
    return whole, [p for p, f in zip(parts, far.tolist()) if f]


def test_wholes_and_parts_described_at_once_equal_two_descriptions(monkeypatch):
    """`Detection._parts` describes the wholes and their parts in one `_describe` (the
    clusters split in two sets for the placement rules): the obstacles are those of a
    description of the wholes and one of the parts, field for field and byte for byte,
    on the walk_obstacles bag's frames (boxes and poles in several parts)."""
    from conftest import BAGS
    from asmonc_vision.core.gpod import detection as gdet
    from asmonc_vision.eval import bench
    from asmonc_vision.io.frames import load_frames
    frames = load_frames(BAGS / 'walk_obstacles', 40)
    ego = bench.egomotion_results(frames)
    seen = {'frames': 0, 'split': 0, 'obstacles': 0}
    merged = gdet.Detection._parts

    def check(self, idx, label, radius, sign, min_pixels, hh, g2, m, excess, cam, metric,
              fwd, lft):
        got = merged(self, idx, label, radius, sign, min_pixels, hh, g2, m, excess, cam,
                     metric, fwd, lft)
        whole = self._describe(idx, label, sign, min_pixels, hh, g2, m, excess, cam, metric,
                               fwd, lft)
        want = whole
        if whole:
            w, parts = _parts_apart(self, whole, idx, label, radius, sign, min_pixels, hh,
                                    g2, m, excess, cam, metric, fwd, lft)
            want = w + parts
            seen['split'] += bool(parts) or len(w) != len(whole)
        seen['frames'] += 1
        seen['obstacles'] += len(got)
        assert len(got) == len(want)
        for a, b in zip(got, want):
            for f in dataclasses.fields(a):
                x, y = getattr(a, f.name), getattr(b, f.name)
                if isinstance(x, np.ndarray):
                    assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), f.name
                elif isinstance(x, float):
                    assert np.float64(x).tobytes() == np.float64(y).tobytes(), f.name
                else:
                    assert x == y, f.name
        return got

    monkeypatch.setattr(gdet.Detection, '_parts', check)
    bench.run_method(frames, 'gpod', map_enabled=False, egomotion=True, ego_results=ego)
    assert seen['frames'] >= 20 and seen['split'] >= 5 and seen['obstacles'] >= 40, seen


def test_new_obstacle_is_the_dataclass_init():
    """`results.new_obstacle` gives GpodObstacle(...)'s obstacle: the same type, every
    field the same object in the same order (defaults included), equal and frozen."""
    import pickle

    from asmonc_vision.core.gpod import GpodObstacle
    from asmonc_vision.core.gpod.results import new_obstacle
    fields = dict(position=np.array([0.1, 0.2, 3.0]), height=0.3, range=3.0, bearing=0.1,
                  width=0.2, disparity_excess=4.0, confidence=0.5, roi=(1, 2, 3, 4),
                  num_edge_pixels=9, string_ids=np.array([1, 2], np.int32))
    for extra in ({}, {'track_id': 4, 'age_s': 0.25}):
        a, b = new_obstacle(**fields, **extra), GpodObstacle(**fields, **extra)
        assert type(a) is type(b)
        assert list(vars(a)) == list(vars(b))
        assert all(vars(a)[k] is vars(b)[k] for k in vars(b))
        assert repr(a) == repr(b)
        assert pickle.loads(pickle.dumps(a)).__dict__.keys() == vars(b).keys()
        with pytest.raises(dataclasses.FrozenInstanceError):
            a.height = 1.0         # type: ignore[misc]


def test_global_threshold_is_pixel_thresholds_global_one(box_frame):
    """`global_threshold` is `pixel_thresholds`' second value, bit for bit: before the
    calibration, after it (the sigma mode, its ceiling), and in the fixed mode."""
    det, _, _ = box_frame
    fresh = GpodDetector(GpodConfig())
    fixed = GpodDetector(override(GpodConfig(), {'threshold.mode': 'fixed'}))
    for d in (det, fresh, fixed):
        want = d.pixel_thresholds(np.zeros(0))[1]
        got = d.global_threshold()
        assert type(got) is type(want)
        assert np.float64(got).tobytes() == np.float64(want).tobytes()
    assert math.isfinite(det._sigma)
