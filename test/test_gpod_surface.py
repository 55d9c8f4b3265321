"""GPOD with the ground surface ahead (GpodConfig.surface) on rendered stereo pairs of a
walkway whose profile bends ahead (the simulator's ground is one plane, so the pairs are
ray-cast here: a textured height profile z(s) along the walking direction, no
obstacles), seen by the paper's rig (320 x 240, f = 300 px, B = 0.35 m, 1.25 m high,
pitched 20 degrees down) standing still.

Everything the detector reports on these pairs is false: the ground only bends.
"""
import functools

import cv2
import numpy as np
import pytest

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import override
from asmonc_vision.core.gpod import GpodConfig, GpodDetector, rules
from asmonc_vision.core.ground_surface import fall_limit

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)
PITCH = np.radians(20.0)
H = 1.25


def _texture(rng, cell=0.02, size=(900, 500)):
    """A pavement-like texture: noise blobs of a few cm, grey levels (s, l grid)."""
    t = rng.normal(0.0, 1.0, (size[0] // 4, size[1] // 4)).astype(np.float32)
    t = cv2.resize(t, (size[1], size[0]), interpolation=cv2.INTER_CUBIC)
    t += 0.5 * rng.normal(0.0, 1.0, size).astype(np.float32)
    t = cv2.GaussianBlur(t, (0, 0), 1.0)
    return 110.0 + 28.0 * t / t.std()


KNOTS = np.arange(0.0, 18.01, 0.25)


def render(profile, rng, knots=KNOTS):
    """The left and right (H, W) uint8 images of the ground z = profile(s) (piecewise
    linear between ``knots``), level across, 2 grey levels of noise."""
    tex = _texture(np.random.default_rng(99))
    zs = profile(knots)
    images = []
    for cx_off in (0.0, CAM.baseline):
        v, u = np.mgrid[0:CAM.height, 0:CAM.width].astype(np.float64)
        x = (u - CAM.cx) / CAM.f
        y = (v - CAM.cy) / CAM.f
        # ray in the level frame: forward s, up z; camera looks down by PITCH
        fwd = np.cos(PITCH) - y * np.sin(PITCH)          # per unit depth along the axis
        up = -(np.sin(PITCH) + y * np.cos(PITCH))
        depth = np.full(u.shape, np.inf)
        for k in range(knots.size - 1):
            g = (zs[k + 1] - zs[k]) / (knots[k + 1] - knots[k])
            # H + t*up = zs[k] + g (t*fwd - knots[k])
            with np.errstate(divide='ignore', invalid='ignore'):
                t = (zs[k] - g * knots[k] - H) / (up - g * fwd)
            s = t * fwd
            ok = (t > 0) & (s >= knots[k]) & (s <= knots[k + 1]) & (t < depth)
            depth = np.where(ok, t, depth)
        s = depth * fwd
        lat = cx_off + depth * x                          # to the right of the left camera
        mx = (lat + 5.0) / 0.02
        my = s / 0.02
        img = cv2.remap(tex, mx.astype(np.float32), my.astype(np.float32), cv2.INTER_LINEAR,
                        borderValue=150.0)
        img[~np.isfinite(depth)] = 150.0
        img = img + rng.normal(0.0, 2.0, img.shape)
        images.append(np.clip(img, 0, 255).astype(np.uint8))
    return images


def rise_from(start, deg):
    g = np.tan(np.radians(deg))
    return lambda s: g * np.maximum(np.asarray(s) - start, 0.0)


PROFILES = {
    'flat': lambda s: 0.0 * np.asarray(s),
    'rise 5 deg from 3 m': rise_from(3.0, 5.0),
    'fall 5 deg from 3 m': rise_from(3.0, -5.0),
    'crest at 5 m': lambda s: rise_from(2.5, 4.0)(s) - rise_from(5.0, 7.0)(s),
}


@functools.lru_cache(maxsize=None)
def rendered(profile, frames: int, seed: int) -> tuple:
    """The first ``frames`` pairs `render` gives for this profile and seed (the same for
    the detector with and without the surface: rendered once)."""
    rng = np.random.default_rng(seed)
    return tuple(tuple(render(profile, rng)) for _ in range(frames))


def reports_ahead(profile, surface: bool, frames: int = 4, seed: int = 0,
                  from_m: float = 3.0) -> list[int]:
    """Per tracked frame, the obstacles reported from ``from_m`` ahead (where the ground
    bends; nearer, this renderer's coarse texture gives a few 5-8 cm reports on flat
    ground too, with or without the surface)."""
    # the plane alone: no surface, and no bend.min_grade either (which takes a
    # steady bend's reports on its own)
    bend = GpodConfig().bend.min_grade if surface else 0.0
    det = GpodDetector(override(GpodConfig(), {'surface.enabled': surface, 'bend.min_grade': bend}))
    out = []
    for left, right in rendered(profile, frames, seed):
        r = det.process(left.copy(), right.copy(), CAM)
        if r.status == 'tracking':
            out.append(len([o for o in r.obstacles if o.range >= from_m]))
    return out


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('name', ['rise 5 deg from 3 m', 'fall 5 deg from 3 m',
                                  'crest at 5 m'])
@pytest.mark.slow
def test_a_bend_ahead_is_ground(name, seed):
    """With the surface at most two reports per frame from 3 m on, and at most a quarter of
    those of the plane alone or one frame's two (up to 30 per frame on the rise; a drop of
    45 cm on the fall and the crest)."""
    with_surface = reports_ahead(PROFILES[name], True, seed=seed)
    plane_only = reports_ahead(PROFILES[name], False, seed=seed)
    assert len(with_surface) >= 2 and max(with_surface) <= 2, with_surface
    assert sum(with_surface) <= max(0.25 * sum(plane_only), 2), (with_surface, plane_only)
    if name.startswith('rise'):
        assert sum(plane_only) >= 5 * len(plane_only)        # the case it is for


@pytest.mark.slow
def test_flat_ground_unchanged():
    flat = PROFILES['flat']
    assert reports_ahead(flat, True, from_m=0.0) == reports_ahead(flat, False, from_m=0.0)


if __name__ == '__main__':
    # The table of docs/ground.md: reports from 3 m per tracked frame, seeds 0-2.
    for name, prof in PROFILES.items():
        row = [np.mean(sum((reports_ahead(prof, surf, seed=s) for s in (0, 1, 2)), []))
               for surf in (False, True)]
        print(f'{name:22s} plane alone {row[0]:5.2f}   with the surface {row[1]:5.2f}')



def _along(s, lat, h):
    """Points (N, 3) in the left optical frame of the rig above: ground coordinates s
    (forward), lat (left), height h above the plane, m."""
    from asmonc_vision.core.camera import MetricPlane, ground_axes
    plane = MetricPlane(normal_up=np.array([0.0, -np.cos(PITCH), -np.sin(PITCH)]), height=H)
    o, fwd, left = ground_axes(plane)
    return (o + s[:, None] * fwd + lat[:, None] * left + h[:, None] * plane.normal_up,
            plane)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_ground_bending_away_is_no_drop_nor_obstacle_but_a_step_is(seed):
    """`rules.bending_ground`: drop pixels along a joint running ahead beyond a brow (their
    depth grows by 0.19 a metre from 3.3 to 5.5 m, 2 cm of noise) are ground falling
    away; those of the level lower ground beyond a 12 cm drop (the same joint, the same
    noise) stay a drop, and so do those of ground falling as steeply from 15 cm below
    (a drop onto a slope down); the same heights mirrored above the ground (ground rising
    beyond a dip; a 12 cm kerb's top; a rise from 15 cm up) likewise."""
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(3.3, 5.5, 30))
    lat = 0.5 + 0.02 * rng.normal(size=30)
    sid = np.repeat([0, 1], 15)
    drop = np.ones(30, bool)
    for h, falling in ((-0.19 * (s - 3.0), True), (np.full(30, -0.12), False),
                       (-0.15 - 0.19 * (s - 3.3), False)):
        h = h + rng.normal(0.0, 0.02, 30)
        pts, plane = _along(s, lat, h)
        got = rules.bending_ground(GpodConfig(), drop, pts, h, plane, 2, sid, 1.0, -1.0)
        assert got.tolist() == [falling, falling]
        # mirrored: ground rising beyond a dip is ground, a kerb's level top is not
        pts, plane = _along(s, lat, -h)
        got = rules.bending_ground(GpodConfig(), drop, pts, -h, plane, 2, sid, 0.7, 1.0)
        assert got.tolist() == [falling, falling]


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_short_or_gentle_bend_is_ground_but_a_short_look_at_lower_ground_is_a_drop(seed):
    """`rules.bending_ground` on what a walker sees of a bend in a few frames: a joint
    beyond a brow seen over 0.6 m (falling 0.16 a metre from 2 cm below the ground), and
    the level top of a kerb ramp seen from the ramp over 3 m (falling at the ramp's
    grade, 0.06 a metre), are ground; the level lower ground of a 12 cm drop seen over
    0.6 m stays a drop; with bend.min_span_m above the 0.6 m the short look is
    not judged at all."""
    rng = np.random.default_rng(seed)
    sid = np.repeat([0, 1], 12)
    drop = np.ones(24, bool)
    short = np.sort(rng.uniform(2.4, 3.0, 24))
    long_ = np.sort(rng.uniform(3.0, 6.0, 24))
    lat = 0.1 + 0.02 * rng.normal(size=24)
    noise = rng.normal(0.0, 0.01, 24)
    brow = -0.02 - 0.16 * (short - 2.4) + noise
    for s, h, bend in ((short, brow, True),
                       (long_, -0.03 - 0.06 * (long_ - 3.0) + noise, True),
                       (short, -0.12 + noise, False)):
        pts, plane = _along(s, lat, h)
        got = rules.bending_ground(GpodConfig(), drop, pts, h, plane, 2, sid, 1.0, -1.0)
        assert got.tolist() == [bend, bend]
    pts, plane = _along(short, lat, brow)
    det = GpodDetector(override(GpodConfig(), {'bend.min_span_m': 0.8}))
    assert rules.bending_ground(det.config, drop, pts, brow, plane, 2, sid, 1.0, -1.0).tolist() == [
        False, False]



def _risen_evidence(s, lat, h, sid, n_s, known_until):
    """`rules.FrameEvidence` of obstacle strings ``sid`` (K,) with their pixels at ground
    coordinates s, lat (m) and heights h (m) above a surface known up to ``known_until``
    m (the plane of the rig above beyond it); every pixel reliably matched."""
    from types import SimpleNamespace

    from asmonc_vision.core.ground_surface import GroundSurface
    pts, plane = _along(s, lat, h)
    surface = GroundSurface(plane, np.array([2.0, known_until]), np.zeros(2), known_until)
    k = s.size
    return rules.FrameEvidence(
        m=SimpleNamespace(string_id=np.asarray(sid)), el=None, er=None, cand=None,
        metric=plane, pd=np.zeros(k), pts=pts, h=np.asarray(h, float), excess=np.zeros(k),
        ex_mean=np.zeros(k), thr=np.ones(k), prev=np.full(k, -1), run=np.full(k, 9),
        usable=np.ones(k, bool), below=np.zeros(k, bool), slope=1.0, weight=np.ones(k),
        min_px=2.0, n_s=n_s, obst=np.ones(k, bool), drop=np.zeros(k, bool),
        obst_string=np.ones(n_s, bool), surface=surface)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_string_floating_within_the_rise_beyond_the_known_ground_is_that_ground(seed):
    """Rule ``risen_ground``: beyond a surface known to 3 m, the rim of a manhole cover
    5.3-5.8 m ahead lying 0.45-0.5 m above the surface's continuation (a rise the surface
    did not follow: 0.57 m at most at max_grade_rise 0.25) is ground; a box's edge there
    coming down from 0.5 m to the ground, a kerb's top 12 cm up, a string as high but
    nearer than the known ground ends, and one higher than the ground can have risen
    (0.45-0.7 m at 3.5 m: 0.12 m at most) stay obstacles. risen.min_height_m = 0 is off."""
    rng = np.random.default_rng(seed)
    n = 12
    s_rim = np.sort(rng.uniform(5.3, 5.8, n))
    cases = [
        (s_rim, rng.uniform(0.45, 0.5, n), True),                    # the manhole rim
        (np.full(n, 5.5) + rng.normal(0, 0.01, n), np.linspace(0.0, 0.5, n), False),  # a box
        (s_rim, np.full(n, 0.12) + rng.normal(0, 0.01, n), False),   # a kerb's top
        (np.sort(rng.uniform(2.3, 2.8, n)), rng.uniform(0.45, 0.5, n), False),  # nearer
        (np.sort(rng.uniform(3.4, 3.6, n)), rng.uniform(0.45, 0.7, n), False),  # too high
    ]
    s = np.concatenate([c[0] for c in cases])
    h = np.concatenate([c[1] for c in cases])
    sid = np.repeat(np.arange(len(cases)), n)
    lat = 0.2 * rng.normal(size=s.size)
    ev = _risen_evidence(s, lat, h, sid, len(cases), known_until=3.0)
    rules.STRING_RULES['risen_ground'](GpodConfig(), ev)
    assert ev.obst_string.tolist() == [not risen for _, _, risen in cases]
    ev = _risen_evidence(s, lat, h, sid, len(cases), known_until=3.0)
    rules.STRING_RULES['risen_ground'](override(GpodConfig(), {'risen.min_height_m': 0.0}), ev)
    assert ev.obst_string.all()


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_bend_is_judged_from_where_its_strings_leave_the_ground(seed):
    """`rules.bending_ground` with ``lead``: a joint running ahead over a brow 4 m off (the
    ground beyond falling 0.19 a metre, 1 cm of noise), whose pixels count as drop pixels
    only deeper than 12 cm (the threshold there), has a line whose near end is 12 cm off:
    no bend by that end alone, but a bend where its own pixels lead up to it. The same
    joint over a 15 cm drop onto ground falling as steeply (the 0.45 m beyond the edge
    hidden), over a flight of steps (0.55 a metre, steeper than ground a pedestrian
    walks: max_grade), and beyond a gap in the joint stays a drop. (The wearer walks up
    a 0.13 grade: the ground may fall by 0.25 a metre, `ground_surface.fall_limit`.)"""
    rng = np.random.default_rng(seed)
    s = np.arange(2.0, 7.0, 0.03)
    s = s + rng.uniform(-0.01, 0.01, s.size)
    lat = 0.5 + 0.01 * rng.normal(size=s.size)
    noise = rng.normal(0.0, 0.01, s.size)
    brow = -0.19 * np.maximum(s - 4.0, 0.0) + noise
    step = np.where(s < 4.0, 0.0, -0.15 - 0.19 * (s - 4.0)) + noise
    stairs = -0.55 * np.maximum(s - 4.0, 0.0) + noise
    seen = ~((s >= 4.0) & (s < 4.45))                 # the drop hides what lies below its edge
    gap = ~((s >= 4.0) & (s < 4.6))
    sid = np.zeros(s.size, int)
    c = GpodConfig()
    cap = fall_limit(0.0, 0.13, c.surface.max_grade_fall)
    assert cap == pytest.approx(0.25)
    for h, keep, grade_cap, bend in ((brow, np.ones(s.size, bool), cap, True),
                                     (step, seen, cap, False),
                                     (stairs, np.ones(s.size, bool), cap, False),
                                     (stairs, np.ones(s.size, bool), 0.6, True),
                                     (brow, gap, cap, False),
                                     (brow, np.ones(s.size, bool), 0.12, False)):
        pts, plane = _along(s[keep], lat[keep], h[keep])
        hk, sk = h[keep], sid[keep]
        drop = hk < -0.12
        assert not rules.bending_ground(c, drop, pts, hk, plane, 1, sk, 1.0, -1.0)[0]
        got = rules.bending_ground(c, drop, pts, hk, plane, 1, sk, 1.0, -1.0, lead=~drop,
                                   max_grade=grade_cap)
        assert got[0] == bend, (bend, grade_cap)
