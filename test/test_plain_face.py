"""The plain-face check (`core.plain_face`): a face with faint texture standing where the
corridor's ground stops showing is told from the ground going on, from a blank face and
from a repetitive pattern; the detector reports it as an obstacle."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from asmonc_vision.core.camera import MetricPlane, StereoCamera
from asmonc_vision.core.config import override
from asmonc_vision.core.gpod import GpodConfig, GpodDetector
from asmonc_vision.core.plain_face import check_face
from asmonc_vision.core.unseen_ground import is_unknown

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)
PITCH = math.radians(20.0)
HEIGHT = 1.25
UP = np.array([0.0, -math.cos(PITCH), -math.sin(PITCH)])       # left optical frame
FWD = np.array([0.0, -math.sin(PITCH), math.cos(PITCH)])
LEFT = np.array([-1.0, 0.0, 0.0])
METRIC = MetricPlane(normal_up=UP, height=HEIGHT)
ORIGIN = -HEIGHT * UP                                          # the ground below the camera


def _field(rng: np.random.Generator, cell_m: float, extent_m: float) -> tuple:
    """A smooth random texture over extent_m x extent_m metres (blobs a few cells wide,
    no preferred direction), zero mean, unit standard deviation: (image, cell_m)."""
    n = int(extent_m / cell_m)
    t = cv2.GaussianBlur(rng.standard_normal((n, n)).astype(np.float32), (0, 0), 2.0)
    return (t - t.mean()) / t.std(), cell_m


def _sample(tex: tuple, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The texture at metres (a, b) from its centre, bilinear (0 outside)."""
    img, cell = tex
    n = img.shape[0]
    return cv2.remap(img, (a / cell + n / 2).astype(np.float32),
                     (b / cell + n / 2).astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)


def _render(face_m: float | None, face_texture, ground_texture, rng: np.random.Generator,
            face_albedo: float = 40.0, face_contrast: float = 1.5,
            noise: float = 2.5, ground_contrast: float = 25.0,
            bend: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The paper's rig (f 300 px, B 0.35 m, 1.25 m up, 20 degrees down) before textured
    ground and, at ``face_m`` along the ground (None: none), a wall across the walking
    direction, 2.4 m tall: ``face_albedo`` grey levels with ``face_texture`` (a function
    of the face's (lateral, height), metres, to a unit texture) times
    ``face_contrast`` grey levels; the ground 120 grey levels with a texture of
    ``ground_contrast``, bent at ``bend`` = (metres along it, grade) if given (a crest's
    brow: grade < 0); pixel noise of ``noise`` grey levels. (left, right) uint8."""
    uu, vv = np.meshgrid(np.arange(CAM.width, dtype=np.float64),
                         np.arange(CAM.height, dtype=np.float64))
    ray = np.stack([(uu - CAM.cx) / CAM.f, (vv - CAM.cy) / CAM.f, np.ones_like(uu)], -1)
    images = []
    for centre in (np.zeros(3), np.array([CAM.baseline, 0.0, 0.0])):
        rel = centre - ORIGIN
        img = np.full(uu.shape, 90.0)
        with np.errstate(divide='ignore', invalid='ignore'):
            t_g = -(rel @ UP) / (ray @ UP)
            if bend is not None:
                # beyond s0 the ground is up . p = g (fwd . p - s0)
                s0, g = bend
                t_b = (g * (rel @ FWD - s0) - rel @ UP) / (ray @ UP - g * (ray @ FWD))
                beyond = ~(t_g > 0) | (rel @ FWD + t_g * (ray @ FWD) > s0)
                t_g = np.where(beyond, np.where(t_b > 0, t_b, -1.0), t_g)
            t_f = ((face_m - rel @ FWD) / (ray @ FWD) if face_m is not None
                   else np.full(uu.shape, np.inf))
        p_g = rel + t_g[..., None] * ray
        p_f = rel + np.where(np.isfinite(t_f), t_f, 0.0)[..., None] * ray
        on_f = np.isfinite(t_f) & (t_f > 0) & ((p_f @ UP) >= 0.0) & ((p_f @ UP) <= 2.4)
        on_g = (t_g > 0) & ~(on_f & (t_f < t_g))
        g = 120.0 + ground_contrast * _sample(ground_texture, p_g @ LEFT, p_g @ FWD)
        img[on_g] = g[on_g]
        if face_m is not None:
            f = face_albedo + face_contrast * face_texture(p_f @ LEFT, p_f @ UP)
            img[on_f] = f[on_f]
        img = img + rng.normal(0.0, noise, img.shape)
        images.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    return images[0], images[1]


def _scene(seed: int, face_m: float | None, kind: str = 'blobs', **kw):
    rng = np.random.default_rng(seed)
    ground = _field(rng, 0.01, 16.0)
    blobs = _field(rng, 0.01, 8.0)
    faces = {
        'blobs': lambda a, b: _sample(blobs, a, b),
        'blank': lambda a, b: np.zeros_like(a),
        # bars 7 cm apart: about 8 px in the image 2.5 m ahead, a peak every 8 px
        'bars': lambda a, b: np.sin(2.0 * math.pi * a / 0.07),
    }
    return _render(face_m, faces[kind], ground, rng, **kw)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_faint_face_is_confirmed_at_its_range(seed):
    """A dark wall with blobs of texture of 1.5 grey levels (2.5 of pixel noise), 2.5 m
    ahead: confirmed, within 0.1 m of its range (measured NCC 0.5, the ground's 0 and
    the rival ranges' at most 0.22), though no edge threshold would take its texture."""
    left, right = _scene(seed, 2.5)
    fc = check_face(left, right, CAM, METRIC, 2.55, 0.5, 1.0)
    assert fc is not None
    assert fc.confirmed(0.25, 0.15), fc
    assert abs(fc.range - 2.5) <= 0.1, fc
    assert fc.score > fc.ground + 0.3, fc
    assert fc.height == pytest.approx(1.0)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_blank_face_stays_unknown(seed):
    """A wall with no texture at all shows pixel noise alone: nothing matches, and the
    check does not say a face stands there (the ground stays unknown)."""
    left, right = _scene(seed, 2.5, 'blank')
    fc = check_face(left, right, CAM, METRIC, 2.55, 0.5, 1.0)
    assert fc is None or not fc.confirmed(0.25, 0.15), fc
    assert fc is None or fc.score < 0.2, fc


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_ground_going_on_is_no_face(seed):
    """No wall: the image above a near edge at 2.5 m is ground, which matches as ground
    and not as a face."""
    left, right = _scene(seed, None)
    fc = check_face(left, right, CAM, METRIC, 2.5, 0.5, 1.0)
    assert fc is not None
    assert not fc.confirmed(0.25, 0.15), fc
    assert fc.ground > fc.score, fc


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_face_deep_in_the_band_is_found_out_to_its_far_end(seed):
    """On faint ground (texture of 3 grey levels) the edges end short of the wall: a
    band from 2.5 m whose wall stands at 4 m. Swept out to the band's far end (5 m),
    the face is confirmed within 0.15 m of 4 m; swept as far as the near edge alone
    allows (1 m beyond it), it is not (the face lies beyond the sweep and the
    tolerance)."""
    left, right = _scene(seed, 4.0, ground_contrast=3.0)
    fc = check_face(left, right, CAM, METRIC, 2.5, 0.5, 1.0, far_m=5.0)
    assert fc is not None and fc.confirmed(0.25, 0.15), fc
    assert abs(fc.range - 4.0) <= 0.15, fc
    near_only = check_face(left, right, CAM, METRIC, 2.5, 0.5, 1.0)
    assert near_only is not None and not near_only.confirmed(0.25, 0.15), near_only


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_ground_going_on_is_no_face_out_to_the_far_end(seed):
    """No wall, swept out to 5 m, on the same faint ground and on the usual: the ground
    matches as ground, no face is confirmed."""
    for contrast in (3.0, 25.0):
        left, right = _scene(seed, None, ground_contrast=contrast)
        fc = check_face(left, right, CAM, METRIC, 2.5, 0.5, 1.0, far_m=5.0)
        assert fc is not None and not fc.confirmed(0.25, 0.15), (contrast, fc)


@pytest.mark.parametrize('seed,grade', [(0, -0.1), (1, -0.2), (2, -0.3)])
def test_ground_falling_away_beyond_a_brow_is_ground_not_a_face(seed, grade, monkeypatch):
    """Faint ground that falls away beyond a brow at 2.5 m (grade -0.1 to -0.3) is no
    face, and is explained as the ground bent at the band's edge: measured NCC 0.5-0.6
    for the bent ground against -0.05 to 0.08 for the level ground going on, which
    alone would leave a face at the brow little to beat."""
    import asmonc_vision.core.plain_face as plain_face
    left, right = _scene(seed, None, ground_contrast=3.0, bend=(2.5, grade))
    fc = check_face(left, right, CAM, METRIC, 2.5, 0.5, 1.0, far_m=5.0)
    assert fc is not None and not fc.confirmed(0.25, 0.15), fc
    monkeypatch.setattr(plain_face, 'BEND_GRADES', ())
    level = check_face(left, right, CAM, METRIC, 2.5, 0.5, 1.0, far_m=5.0)
    assert fc.ground >= 0.4 and level.ground <= 0.15, (fc, level)


@pytest.mark.parametrize('seed', [0, 1])
def test_a_repetitive_face_has_no_single_peak(seed):
    """Bars a few pixels apart match at several disparities: no single clear range, not
    confirmed (measured: NCC 0.87 at the true range and at a rival 8 px away)."""
    left, right = _scene(seed, 2.5, 'bars', face_contrast=4.0)
    fc = check_face(left, right, CAM, METRIC, 2.55, 0.5, 1.0)
    assert fc is not None
    assert fc.off_peak > fc.score - 0.15, fc
    assert not fc.confirmed(0.25, 0.15), fc


def test_a_region_out_of_the_image_gives_none():
    """A near edge behind the camera's view (0.2 m ahead, below the image) is no check."""
    left, right = _scene(0, 2.5)
    assert check_face(left, right, CAM, METRIC, 0.2, 0.5, 1.0) is None


def _faint_wall_frames(n: int = 20):
    """The simulator's dark wall (albedo 45: its texture a few grey levels) appearing
    2.4 m ahead of the paper's rig standing still at 0.8 s: (camera, frames)."""
    from asmonc_vision.sim import RigSettings, StereoRenderer, simulate_frame
    from asmonc_vision.sim.motion import Leg, Trajectory
    from asmonc_vision.sim.scenarios import Scenario, random_pavement
    from asmonc_vision.sim.world import Ground, World, wall

    rig = RigSettings()
    rng = np.random.default_rng(3)
    w = wall(2.4, -6.0, 2.4, 6.0, appear=0.8, albedo=45.0)
    world = World(Ground(pavement=random_pavement(rng)), [w], seed=3)
    traj = Trajectory([Leg(2.0, 0.0)], rig, world, rng=np.random.default_rng(4))
    scene = Scenario('faint_wall', 'a faint wall appears', 3, 2.0, rig, world, traj)
    ren = StereoRenderer(rig)
    return rig.camera(), [simulate_frame(scene, k, ren) for k in range(n)]


def test_the_detector_reports_a_faint_wall_as_an_obstacle_not_unknown_ground():
    """The dark wall 2.4 m ahead: GPOD's edges miss it, the unseen ground finds the
    ground hidden from its foot, and the face check makes that an obstacle at the
    wall's range (face_height_m tall) in place of unknown ground; with the check off
    (face_min_ncc 0) the same frames give unknown ground."""
    cam, frames = _faint_wall_frames()
    counts = {}
    for ncc in (0.25, 0.0):
        det = GpodDetector(override(GpodConfig(), {'unseen.face_min_ncc': ncc}))
        face = unknown = 0
        for f in frames:
            r = det.process(f.left, f.right, cam, stamp_ns=int(f.time * 1e9))
            if f.time < 1.0:
                continue
            ahead = [o for o in r.obstacles if abs(o.range * math.sin(o.bearing)) <= 0.5
                     and abs(o.range - 2.4) <= 0.3 and o.confidence >= 0.3]
            face += any(not is_unknown(o.height) and o.height >= 0.5 for o in ahead)
            unknown += any(is_unknown(o.height) for o in ahead)
        counts[ncc] = (face, unknown)
    assert counts[0.25][0] >= 8 and counts[0.25][1] <= 2, counts    # of 10 frames
    assert counts[0.0][0] <= 1 and counts[0.0][1] >= 8, counts


def _confirmed_face(range_m: float):
    left, right = _scene(0, 2.5)
    fc = check_face(left, right, CAM, METRIC, 2.55, 0.5, 1.0)
    assert fc is not None and fc.confirmed(0.25, 0.15)
    import dataclasses
    return dataclasses.replace(fc, range=range_m)


def test_a_remembered_face_is_carried_to_the_band_it_hides():
    """A face confirmed 4 m ahead, walked towards 0.1 m a pair: the band found 2.6-3.5 m
    ahead in the pairs after (no peak of its own) is that face, at its carried range;
    a pair or two without a band is bridged, three are not; a band far from it, or a pair
    whose travel is unknown, forgets it."""
    from asmonc_vision.core.plain_face import FaceMemory
    mem = FaceMemory(max_gap=2)
    assert mem.explains(3.0) is None                 # nothing remembered
    mem.confirmed(_confirmed_face(4.0))
    for k in range(1, 6):
        mem.carry(0.1)
        got = mem.explains(4.0 - 0.1 * k + 0.2)       # the band's edge a little beyond
        assert got is not None and got.range == pytest.approx(4.0 - 0.1 * k), (k, got)
    for _ in range(2):                                # two pairs without the band
        mem.carry(0.1)
        assert mem.explains(None) is None
    mem.carry(0.0)
    assert mem.explains(3.2) is not None              # bridged: the face at 3.3 m
    for _ in range(3):
        mem.explains(None)
    assert mem.face is None                           # three: forgotten
    mem.confirmed(_confirmed_face(4.0))
    assert mem.explains(2.0) is None and mem.face is None    # a band elsewhere
    mem.confirmed(_confirmed_face(4.0))
    mem.carry(None)
    assert mem.face is None                           # travel unknown
