"""The scene registry of the evaluation campaign: random walks of named classes.

``make_scene(scene_class, seed)`` draws everything from the seed: the rig's mounting
(within its kind), the pavement kind (tiles, asphalt, concrete) and its look, the
markings (paint, zebra stripes, manhole covers, grates, stains, patches, cast shadows),
the ground's shape, the obstacles' sizes and places, the people's tracks, the walker's
plan and gait, and (when ``realism`` is None, for about 60 % of seeds) the camera
realism effects. The wearer walks along world +x from the origin; obstacles are placed
along the planned path, so a longer ``duration`` gives a longer course.

Classes (``SCENE_CLASSES``); the *clear* ones (``CLEAR_CLASSES``) have no true obstacle
in the walking corridor (``CORRIDOR`` m either side of the path) and test false alarms:

* ``pavement_obstacles``: boxes of 5-40 cm on the path (several in the corridor) and
  beside it, posts and bollards beside it.
* ``clear_walk`` (clear): a walk with a gentle bend; markings; things well beside.
* ``slope_ahead`` (clear): the ground's grade changes ahead (a 3-7 degree slope that
  starts or ends a few metres ahead, up or down), possibly rounded.
* ``crest`` (clear): a crest (up then down) or a dip (down then up), 3-7 degrees each
  side, sharp or rounded over up to 3 m.
* ``kerb_ramp`` (clear): a dropped kerb across the path: a 10-15 cm kerb whose middle
  1.6-2.6 m is a ramp (grade 1:10-1:17) that the wearer walks up; the kerb beside the
  ramp is an obstacle beside the path, the ramp and the raised footway are ground.
* ``camber`` (clear): a 2-4 % cross-slope, with up to 2 degrees along the path.
* ``asphalt_markings`` (clear): asphalt with edge and centre lines, a stop line or a
  zebra crossing, manhole covers, stains and patches.
* ``grate`` (clear): drainage grates (and maybe a manhole cover) on the path.
* ``people_crossing``: 2-4 people (1.5-1.9 m) crossing the path 2-6 m ahead at
  0.8-1.5 m/s.
* ``people_towards``: 1-2 people walking towards the wearer in the corridor, stepping
  aside when 1.8-2.6 m away.
* ``kerb_up``, ``step_down``: a kerb up or down (10-20 cm / 10-25 cm) across the path;
  the wearer stops 1.2-2.4 m before it.
* ``stop_turn``: walk towards a wall, stop, turn ~90 degrees, walk on past boxes.

Classes outside the default plans (``EXTRA_CLASSES``; ``asmonc campaign --classes``
names them):

* ``kerb_cross``: a kerb up or down (10-20 cm) across the path 45-60 % of the way along;
  the wearer walks on over it (the camera's height changes at once, by the kerb's) and
  on along the new level: the ground under the wearer changes.
"""
from __future__ import annotations

import dataclasses
import math
import zlib

import numpy as np

from asmonc_vision.sim.motion import GaitSettings, Leg, Trajectory
from asmonc_vision.sim.people import Person, walker
from asmonc_vision.sim.relief import GroundProfile
from asmonc_vision.sim.rig import RigSettings
from asmonc_vision.sim.scenarios import Scenario, obstacle_albedo, random_box, random_pavement
from asmonc_vision.sim.surfaces import Marking
from asmonc_vision.sim.world import (Box, Ground, Obstacle, PavementSettings, Terrace, World,
                                     bollard, kerb_up, post, step_down, wall)

SCENE_CLASSES: tuple[str, ...] = (
    'pavement_obstacles', 'clear_walk', 'slope_ahead', 'crest', 'kerb_ramp', 'camber',
    'asphalt_markings', 'grate', 'people_crossing', 'people_towards', 'kerb_up',
    'step_down', 'stop_turn')
#: Classes with no true obstacle in the walking corridor (false-alarm tests).
CLEAR_CLASSES: tuple[str, ...] = ('clear_walk', 'slope_ahead', 'crest', 'kerb_ramp',
                                  'camber', 'asphalt_markings', 'grate')
#: Classes outside the default plans (named with ``--classes``).
EXTRA_CLASSES: tuple[str, ...] = ('kerb_cross',)
#: Every class a scene can be built of.
ALL_CLASSES: tuple[str, ...] = SCENE_CLASSES + EXTRA_CLASSES
RIGS: tuple[str, ...] = ('backpack', 'chest', 'narrow')
#: Half-width (m) of the walking corridor the clear classes keep free.
CORRIDOR = 0.5
#: Share of seeds with the camera realism effects when ``realism`` is None.
REALISM_SHARE = 0.6


# --------------------------------------------------------------------------- draws


def scene_rig(rig: str, rng: np.random.Generator) -> RigSettings:
    """The rig of a scene: 'backpack' (the paper's, 1.15-1.35 m high, 16-24 degrees
    down), 'chest' (``RigSettings.chest``, 1.2-1.4 m high, 0-10 degrees down) or
    'narrow' (``RigSettings.narrow``, a 7.5 cm baseline module worn anywhere from the
    belt to the head: 1.0-1.6 m high, 8-30 degrees down)."""
    if rig == 'backpack':
        return RigSettings(camera_height=round(float(rng.uniform(1.15, 1.35)), 3),
                           camera_pitch_deg=round(float(rng.uniform(16.0, 24.0)), 2))
    if rig == 'chest':
        return RigSettings.chest(camera_height=round(float(rng.uniform(1.2, 1.4)), 3),
                                 camera_pitch_deg=round(float(rng.uniform(0.0, 10.0)), 2))
    if rig == 'narrow':
        return RigSettings.narrow(camera_height=round(float(rng.uniform(1.0, 1.6)), 3),
                                  camera_pitch_deg=round(float(rng.uniform(8.0, 30.0)), 2))
    raise ValueError(f"unknown rig '{rig}'; known: {', '.join(RIGS)}")


def with_realism(rig: RigSettings, rng: np.random.Generator) -> RigSettings:
    """``rig`` with the camera realism effects at random strengths: exposure 4-16 ms
    (motion blur, 3 sub-exposures), vignetting 0.15-0.35, auto-exposure drift 3-10 %
    over 3-10 s, a rectification residual of 0.1-0.4 px vertical shift and up to
    0.04 degrees of rotation of the right image, noise 2-4 grey levels."""
    sign = float(rng.choice([-1.0, 1.0]))
    return dataclasses.replace(
        rig, exposure_time=round(float(rng.uniform(0.004, 0.016)), 4), exposure_samples=3,
        vignetting=round(float(rng.uniform(0.15, 0.35)), 3),
        gain_drift=round(float(rng.uniform(0.03, 0.10)), 3),
        gain_drift_period=round(float(rng.uniform(3.0, 10.0)), 2),
        right_shift_px=round(sign * float(rng.uniform(0.1, 0.4)), 3),
        right_rotation_deg=round(float(rng.uniform(-0.04, 0.04)), 4),
        noise_sigma=round(float(rng.uniform(2.0, 4.0)), 2))


def scene_pavement(rng: np.random.Generator, kind: str | None = None) -> PavementSettings:
    """A pavement of ``kind`` (None: tiles 40 %, asphalt 30 %, concrete 30 %)."""
    if kind is None:
        kind = str(rng.choice(['tiles', 'asphalt', 'concrete'], p=[0.4, 0.3, 0.3]))
    if kind == 'tiles':
        return random_pavement(rng)
    yaw = round(float(rng.choice([0.0, 90.0]) + rng.uniform(-6.0, 6.0)), 2)
    if kind == 'asphalt':
        return PavementSettings(kind='asphalt', yaw_deg=yaw,
                                brightness=round(float(rng.uniform(70.0, 115.0)), 1),
                                texture_contrast=round(float(rng.uniform(0.25, 0.45)), 3))
    b = float(rng.uniform(135.0, 180.0))
    return PavementSettings(kind='concrete', yaw_deg=yaw, pattern='grid',
                            tile_length=round(float(rng.uniform(1.0, 2.0)), 3),
                            tile_width=round(float(rng.uniform(1.0, 2.0)), 3),
                            grout_width=round(float(rng.uniform(0.006, 0.012)), 4),
                            brightness=round(b, 1),
                            grout_brightness=round(b * float(rng.uniform(0.45, 0.65)), 1),
                            tile_spread=round(float(rng.uniform(0.03, 0.08)), 3),
                            texture_contrast=round(float(rng.uniform(0.15, 0.3)), 3))


class Course:
    """The planned walking path (no gait), to place things along it.

    Args:
        legs: the walk plan; rig: for the Trajectory; start_speed: m/s at t = 0;
        duration: seconds.
    """

    def __init__(self, legs, rig: RigSettings, duration: float, start_speed: float = 0.0):
        self.probe = Trajectory(legs, rig, None, start_speed=start_speed, rng=0)
        self.t = np.linspace(0.0, duration, max(int(duration * 50), 2))
        xy = self.probe.path(self.t)
        self.xy = xy
        self.s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        self.length = float(self.s[-1])

    def point(self, s: float, lateral: float = 0.0) -> tuple[float, float, float]:
        """World (x, y) ``s`` m along the path and ``lateral`` m left of it, and the
        path heading there (rad); straight on beyond the end."""
        t = float(np.interp(min(s, self.length), self.s, self.t))
        psi = float(self.probe.heading(t))
        p = self.probe.path(t)
        extra = max(s - self.length, 0.0)
        c, sn = math.cos(psi), math.sin(psi)
        return (float(p[0] + c * extra - sn * lateral),
                float(p[1] + sn * extra + c * lateral), psi)

    def at_time(self, t: float) -> tuple[float, float, float]:
        """(s along the path (m), x, y) of the walker at time t (s)."""
        p = self.probe.path(t)
        return float(np.interp(t, self.t, self.s)), float(p[0]), float(p[1])


def _walk(rng: np.random.Generator, duration: float, stop: bool = False,
          bend: bool = False) -> list[Leg]:
    """Stand 1-1.5 s (the detector calibrates), then walk at 0.9-1.4 m/s with speed
    changes (and a gentle 5-15 degree bend); ``stop``: stop in the last 2.5 s."""
    stand = min(float(rng.uniform(1.0, 1.5)), 0.15 * duration)
    rest = duration - stand - (2.5 if stop else 0.0)
    legs = [Leg(stand, 0.0)]
    if rest > 0.3:
        parts = rng.dirichlet([3.0, 3.0, 3.0]) * rest
        turn = (float(rng.choice([-1, 1]) * rng.uniform(5, 15)) if bend else 0.0)
        for k, part in enumerate(parts):
            legs.append(Leg(max(float(part), 0.1), float(rng.uniform(0.9, 1.4)),
                            turn_deg=turn if k == 1 else 0.0, ramp=1.0 if k == 0 else 1.5))
    if stop:
        legs.append(Leg(2.5, 0.0, ramp=1.2))
    return legs


def _side(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A lateral offset lo-hi m to a random side."""
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


def _beside(rng: np.random.Generator, course: Course, gb: float, n: int,
            min_lateral: float = 1.2) -> list[Obstacle]:
    """``n`` posts, bollards or boxes well beside the path (>= ``min_lateral`` m)."""
    out: list[Obstacle] = []
    for _ in range(n):
        x, y, _ = course.point(float(rng.uniform(3.0, course.length + 6.0)),
                               _side(rng, min_lateral, min_lateral + 1.0))
        k = rng.integers(3)
        if k == 0:
            out.append(post(x, y, round_=bool(rng.random() < 0.5), name='post'))
        elif k == 1:
            out.append(bollard(x, y, height=float(rng.uniform(0.8, 1.0)), name='bollard'))
        else:
            out.append(random_box(rng, x, y, float(rng.uniform(0.1, 0.4)), gb))
    return out


def _stains(rng: np.random.Generator, course: Course, n: int) -> list[Marking]:
    """``n`` stains or patches (darker or lighter soft blobs) on and beside the path."""
    out = []
    for _ in range(n):
        x, y, psi = course.point(float(rng.uniform(1.5, course.length + 8.0)),
                                 float(rng.uniform(-2.0, 2.0)))
        size = float(rng.uniform(0.3, 1.5))
        dark = rng.random() < 0.7
        out.append(Marking('stain' if dark else 'patch', x, y, float(rng.uniform(0, 180)),
                           size, size * float(rng.uniform(0.4, 1.0)), shape='ellipse',
                           fill='multiply',
                           factor=float(rng.uniform(0.6, 0.85) if dark else
                                        rng.uniform(1.1, 1.25)),
                           wobble=float(rng.uniform(0.1, 0.3)),
                           edge=float(rng.uniform(0.01, 0.05))))
    return out


def _shadows(rng: np.random.Generator, course: Course, n: int) -> list[Marking]:
    """``n`` cast shadows: a pole's (a long thin dark band) or a tree's (a large soft
    blob), across or along the path."""
    out = []
    for _ in range(n):
        x, y, psi = course.point(float(rng.uniform(2.0, course.length + 8.0)),
                                 float(rng.uniform(-1.5, 1.5)))
        if rng.random() < 0.5:
            out.append(Marking('shadow', x, y, float(rng.uniform(0, 180)),
                               float(rng.uniform(2.0, 5.0)), float(rng.uniform(0.08, 0.2)),
                               fill='multiply', factor=float(rng.uniform(0.45, 0.65)),
                               edge=float(rng.uniform(0.02, 0.06))))
        else:
            size = float(rng.uniform(1.5, 4.0))
            out.append(Marking('shadow', x, y, float(rng.uniform(0, 180)), size,
                               size * float(rng.uniform(0.5, 1.0)), shape='ellipse',
                               fill='multiply', factor=float(rng.uniform(0.5, 0.7)),
                               wobble=0.3, edge=0.1))
    return out


def _manhole(rng: np.random.Generator, x: float, y: float) -> Marking:
    d = float(rng.uniform(0.55, 0.7))
    period = float(rng.uniform(0.04, 0.07))
    return Marking('manhole', x, y, float(rng.uniform(0, 90)), d, d, shape='ellipse',
                   fill='manhole', albedo=float(rng.uniform(50.0, 90.0)), period=period,
                   bar=period * 0.35)


def _grate(rng: np.random.Generator, x: float, y: float, psi: float) -> Marking:
    period = float(rng.uniform(0.035, 0.05))
    return Marking('grate', x, y, math.degrees(psi) + float(rng.choice([0.0, 90.0])),
                   float(rng.uniform(0.3, 0.5)), float(rng.uniform(0.5, 1.0)), fill='grate',
                   albedo=float(rng.uniform(60.0, 100.0)), period=period,
                   bar=period * float(rng.uniform(0.45, 0.6)))


def _some_markings(rng: np.random.Generator, course: Course) -> list[Marking]:
    """Markings for any class: 0-3 stains/patches, maybe a shadow, maybe a manhole."""
    out = _stains(rng, course, int(rng.integers(0, 4)))
    if rng.random() < 0.4:
        out += _shadows(rng, course, 1)
    if rng.random() < 0.3:
        x, y, _ = course.point(float(rng.uniform(3.0, course.length + 5.0)),
                               float(rng.uniform(-1.0, 1.0)))
        out.append(_manhole(rng, x, y))
    return out


def _rounded(x0: float, breaks, grades, rounding: float, steps: int = 3) -> GroundProfile:
    """A profile along +x from x0 whose grade changes at ``breaks`` (m), each spread
    over ``rounding`` m in ``steps`` equal steps (0: sharp)."""
    if rounding <= 0:
        return GroundProfile(x0, 0.0, 0.0, tuple(breaks), tuple(grades))
    b, g = [], [grades[0]]
    for k, at in enumerate(breaks):
        g0, g1 = grades[k], grades[k + 1]
        for j in range(steps + 1):
            b.append(at - rounding / 2 + rounding * j / steps)
            g.append(g0 + (g1 - g0) * (j + 1) / (steps + 1))
        g[-1] = g1
    return GroundProfile(x0, 0.0, 0.0, tuple(b), tuple(g))


# --------------------------------------------------------------------------- classes


@dataclasses.dataclass
class _Parts:
    """What a class builder returns."""

    legs: list
    obstacles: list = dataclasses.field(default_factory=list)
    markings: list = dataclasses.field(default_factory=list)
    ground: Ground | None = None
    profile: GroundProfile | None = None
    start_speed: float = 0.0


def _pavement_obstacles(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    gb = ground.pavement.mean_albedo
    obs: list[Obstacle] = []
    s, k = float(rng.uniform(3.0, 4.5)), 0
    while s < course.length + 4.0:
        if k < 2 or rng.random() < 0.45:   # a box in the corridor
            x, y, _ = course.point(s, float(rng.uniform(-0.35, 0.35)))
            obs.append(random_box(rng, x, y, round(float(rng.uniform(0.05, 0.40)), 3), gb))
        elif rng.random() < 0.5:
            x, y, _ = course.point(s, _side(rng, 0.6, 1.5))
            obs.append(random_box(rng, x, y, round(float(rng.uniform(0.05, 0.40)), 3), gb))
        else:
            x, y, _ = course.point(s, _side(rng, 0.7, 1.5))
            obs.append(post(x, y, round_=bool(rng.random() < 0.5), name='post')
                       if rng.random() < 0.5 else
                       bollard(x, y, height=float(rng.uniform(0.8, 1.0)), name='bollard'))
        s += float(rng.uniform(1.3, 2.4))
        k += 1
    return _Parts(legs, obs, _some_markings(rng, course), ground)


def _clear_walk(rng, rig, duration):
    legs = _walk(rng, duration, bend=True)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    obs = _beside(rng, course, ground.pavement.mean_albedo, int(rng.integers(0, 3)))
    return _Parts(legs, obs, _some_markings(rng, course), ground)


def _slope_ahead(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    g = math.tan(math.radians(float(rng.uniform(3.0, 7.0)))) * float(rng.choice([-1, 1]))
    g2 = math.tan(math.radians(float(rng.uniform(2.0, 6.0)))) * float(rng.choice([-1, 1]))
    b1 = float(rng.uniform(4.0, 9.0))
    b2 = b1 + float(rng.uniform(6.0, 12.0))
    grades = (0.0, g, float(rng.choice([0.0, g2]))) if rng.random() < 0.5 else \
        (g, 0.0, float(rng.choice([0.0, g2])))
    profile = _rounded(0.0, (b1, b2), grades, float(rng.choice([0.0, rng.uniform(0.5, 2.0)])))
    obs = _beside(rng, course, ground.pavement.mean_albedo, int(rng.integers(0, 2)))
    return _Parts(legs, obs, _some_markings(rng, course), ground, profile)


def _crest(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    up = math.tan(math.radians(float(rng.uniform(3.0, 7.0))))
    down = -math.tan(math.radians(float(rng.uniform(3.0, 7.0))))
    if rng.random() < 0.4:          # a dip
        up, down = down, up
    b1 = float(rng.uniform(5.0, 10.0))
    b2 = b1 + float(rng.uniform(7.0, 12.0))
    profile = _rounded(0.0, (b1, b2), (up, down, 0.0),
                       float(rng.choice([0.0, rng.uniform(0.5, 3.0)])))
    obs = _beside(rng, course, ground.pavement.mean_albedo, int(rng.integers(0, 2)))
    return _Parts(legs, obs, _some_markings(rng, course), ground, profile)


def _kerb_ramp(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    rise = round(float(rng.uniform(0.10, 0.15)), 3)
    length = rise / float(rng.uniform(0.06, 0.10))
    half = float(rng.uniform(0.8, 1.3))
    s0 = float(rng.uniform(5.0, 9.0))
    profile = GroundProfile(0.0, 0.0, 0.0, (s0, s0 + length), (0.0, rise / length, 0.0))
    albedo = float(rng.uniform(150.0, 185.0))
    far = 30.0
    obs: list[Obstacle] = [
        Terrace(polygon=((s0, half), (s0 + length, half), (s0 + length, far), (s0, far)),
                rise=rise, albedo=albedo, name=f'kerb {rise * 100:.0f} cm left of the ramp'),
        Terrace(polygon=((s0, -far), (s0 + length, -far), (s0 + length, -half), (s0, -half)),
                rise=rise, albedo=albedo, name=f'kerb {rise * 100:.0f} cm right of the ramp')]
    return _Parts(legs, obs, _some_markings(rng, course), ground, profile)


def _camber(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    cross = float(rng.uniform(0.02, 0.04)) * float(rng.choice([-1, 1]))
    along = math.tan(math.radians(float(rng.uniform(-2.0, 2.0))))
    ground = Ground(slope_deg=math.degrees(math.atan(math.hypot(along, cross))),
                    slope_yaw_deg=math.degrees(math.atan2(cross, along)),
                    pavement=scene_pavement(rng))
    obs = _beside(rng, course, ground.pavement.mean_albedo, int(rng.integers(0, 2)))
    return _Parts(legs, obs, _some_markings(rng, course), ground)


def _asphalt_markings(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng, 'asphalt'))
    paint = float(rng.uniform(190.0, 230.0))
    wear = float(rng.uniform(0.0, 0.4))
    end = course.length + 10.0
    marks: list[Marking] = []
    # edge lines along the path, a dashed centre line near it
    for side in (-1.0, 1.0):
        if rng.random() < 0.7:
            lat = side * float(rng.uniform(0.9, 1.8))
            x, y, _ = course.point(end / 2, lat)
            marks.append(Marking('line', x, y, 0.0, end + 4.0, float(rng.uniform(0.1, 0.15)),
                                 albedo=paint, wear=wear))
    lat = float(rng.uniform(-0.3, 0.3))
    dash, gap = float(rng.uniform(1.0, 3.0)), float(rng.uniform(1.5, 4.0))
    s = float(rng.uniform(0.5, 2.0))
    while s < end:
        x, y, psi = course.point(s + dash / 2, lat)
        marks.append(Marking('line', x, y, math.degrees(psi), dash, 0.12, albedo=paint,
                             wear=wear))
        s += dash + gap
    # a stop line or a zebra crossing ahead
    s = float(rng.uniform(4.0, max(course.length * 0.6, 5.0)))
    x, y, psi = course.point(s, 0.0)
    if rng.random() < 0.5:
        marks.append(Marking('line', x, y, math.degrees(psi) + 90.0,
                             float(rng.uniform(3.0, 5.0)), float(rng.uniform(0.3, 0.5)),
                             albedo=paint, wear=wear))
    else:
        n = int(rng.integers(4, 8))
        across = bool(rng.random() < 0.6)    # bars across the walking direction
        marks.append(Marking('zebra', x, y, math.degrees(psi) + (0.0 if across else 90.0),
                             n * 1.0 - 0.5, float(rng.uniform(2.5, 4.0)), fill='stripes',
                             albedo=paint, period=1.0, bar=0.5, wear=wear))
    for _ in range(int(rng.integers(1, 3))):
        x, y, _ = course.point(float(rng.uniform(3.0, course.length + 4.0)),
                               float(rng.uniform(-0.4, 0.4)))
        marks.append(_manhole(rng, x, y))
    marks = _stains(rng, course, int(rng.integers(2, 6))) + marks
    if rng.random() < 0.5:
        marks += _shadows(rng, course, 1)
    return _Parts(legs, [], marks, ground)


def _grate_class(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    marks = _stains(rng, course, int(rng.integers(0, 3)))
    for _ in range(int(rng.integers(1, 4))):
        x, y, psi = course.point(float(rng.uniform(2.5, course.length + 4.0)),
                                 float(rng.uniform(-0.3, 0.3)))
        marks.append(_grate(rng, x, y, psi))
    if rng.random() < 0.5:
        x, y, _ = course.point(float(rng.uniform(3.0, course.length + 4.0)),
                               float(rng.uniform(-0.4, 0.4)))
        marks.append(_manhole(rng, x, y))
    return _Parts(legs, [], marks, ground)


def _person(rng, track, gb):
    return walker(track, height=round(float(rng.uniform(1.5, 1.9)), 3),
                  width=round(float(rng.uniform(0.4, 0.5)), 3),
                  depth=round(float(rng.uniform(0.22, 0.32)), 3),
                  albedo=obstacle_albedo(rng, gb), lower_albedo=float(rng.uniform(35, 120)))


def _people_crossing(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    gb = ground.pavement.mean_albedo
    n = int(rng.integers(2, 5))
    times = np.sort(rng.uniform(2.0, max(duration - 1.0, 2.5), n))
    obs: list[Obstacle] = []
    for tc in times:
        s_w, _, _ = course.at_time(float(tc))
        x, y, psi = course.point(s_w + float(rng.uniform(2.0, 6.0)), 0.0)
        v = float(rng.uniform(0.8, 1.5))
        side = float(rng.choice([-1.0, 1.0]))
        half = 5.0
        c, sn = math.cos(psi), math.sin(psi)
        a = (x - sn * side * half, y + c * side * half)      # start on one side ...
        b = (x + sn * side * half, y - c * side * half)      # ... end on the other
        obs.append(_person(rng, ((tc - half / v, *a), (tc + half / v, *b)), gb))
    return _Parts(legs, obs, _some_markings(rng, course), ground)


def _people_towards(rng, rig, duration):
    legs = _walk(rng, duration)            # straight along +x
    course = Course(legs, rig, duration)
    ground = Ground(pavement=scene_pavement(rng))
    gb = ground.pavement.mean_albedo
    obs: list[Obstacle] = []
    n = int(rng.integers(1, 3))
    starts = np.sort(rng.uniform(1.0, max(duration - 9.0, 1.5), n))
    for ts in starts:
        v = float(rng.uniform(0.8, 1.5))
        s_w, xw, _ = course.at_time(float(ts))
        x0 = xw + float(rng.uniform(10.0, 14.0))
        lat = float(rng.uniform(-0.3, 0.3))
        gap = float(rng.uniform(1.8, 2.6))
        tt = np.linspace(ts, ts + 30.0, 3001)
        xp = x0 - v * (tt - ts)
        xw_t = course.probe.path(tt)[:, 0]
        k = int(np.argmax(xp - xw_t <= gap)) if np.any(xp - xw_t <= gap) else len(tt) - 1
        tv = float(tt[k])
        aside = lat + _side(rng, 0.9, 1.3)
        track = ((ts, x0, lat), (tv, x0 - v * (tv - ts), lat),
                 (tv + 1.0, x0 - v * (tv + 1.0 - ts), aside),
                 (tv + 20.0, x0 - v * (tv + 20.0 - ts), aside))
        obs.append(_person(rng, track, gb))
    return _Parts(legs, obs, _some_markings(rng, course), ground)


def _kerb(rng, rig, duration, up: bool):
    legs = _walk(rng, duration, stop=True)
    course = Course(legs, rig, duration)
    cross = float(rng.uniform(-0.03, 0.03))
    ground = Ground(slope_deg=math.degrees(math.atan(abs(cross))),
                    slope_yaw_deg=90.0 if cross >= 0 else -90.0, pavement=scene_pavement(rng))
    x, y, psi = course.point(course.length + float(rng.uniform(1.2, 2.4)), 0.0)
    yaw = math.degrees(psi) + float(rng.uniform(-10.0, 10.0))
    if up:
        rise = round(float(rng.uniform(0.10, 0.20)), 3)
        edge = kerb_up(x, y, yaw, rise=rise, name=f'kerb up {rise * 100:.0f} cm')
    else:
        drop = round(float(rng.uniform(0.10, 0.25)), 3)
        edge = step_down(x, y, yaw, drop=drop, name=f'kerb down {drop * 100:.0f} cm')
    obs = [edge] + _beside(rng, Course(legs, rig, max(duration - 3.0, 1.0)),
                           ground.pavement.mean_albedo, int(rng.integers(0, 3)), 0.8)
    return _Parts(legs, obs, _some_markings(rng, course), ground)


def _stop_turn(rng, rig, duration):
    ground = Ground(pavement=scene_pavement(rng))
    gb = ground.pavement.mean_albedo
    v = float(rng.uniform(1.0, 1.3))
    turn = float(rng.choice([-1, 1]) * rng.uniform(80.0, 100.0))
    rest = max(duration - 3.8, 1.0)
    legs = [Leg(0.45 * rest, v), Leg(1.0, 0.0, ramp=1.0), Leg(0.5, 0.0),
            Leg(2.0, 0.0, turn_deg=turn), Leg(0.3, 0.0), Leg(0.55 * rest, v, ramp=1.0)]
    probe = Trajectory(legs, rig, None, start_speed=v, rng=0)
    t_stop = 0.45 * rest + 1.0
    stop = probe.path(t_stop)
    wx = float(stop[0]) + float(rng.uniform(1.8, 3.0))
    obs: list[Obstacle] = [wall(wx, -8.0, wx, 8.0, albedo=obstacle_albedo(rng, gb),
                                name='wall ahead')]
    heading = math.radians(turn)
    c, sn = math.cos(heading), math.sin(heading)
    s = 3.0
    while s < 0.55 * rest * v + 4.0:
        lat = float(rng.uniform(-0.4, 0.4)) if rng.random() < 0.5 else _side(rng, 0.7, 1.3)
        x, y = float(stop[0] + c * s - sn * lat), float(stop[1] + sn * s + c * lat)
        obs.append(random_box(rng, x, y, round(float(rng.uniform(0.05, 0.4)), 3), gb))
        s += float(rng.uniform(1.5, 2.5))
    course = Course(legs, rig, duration, start_speed=v)
    return _Parts(legs, obs, _some_markings(rng, course), ground, start_speed=v)


def _kerb_cross(rng, rig, duration):
    legs = _walk(rng, duration)
    course = Course(legs, rig, duration)
    cross = float(rng.uniform(-0.03, 0.03))
    ground = Ground(slope_deg=math.degrees(math.atan(abs(cross))),
                    slope_yaw_deg=90.0 if cross >= 0 else -90.0, pavement=scene_pavement(rng))
    x, y, psi = course.point(course.length * float(rng.uniform(0.45, 0.6)), 0.0)
    yaw = math.degrees(psi) + float(rng.uniform(-10.0, 10.0))
    size = round(float(rng.uniform(0.10, 0.20)), 3)
    if rng.random() < 0.5:
        edge = kerb_up(x, y, yaw, rise=size, depth=course.length + 20.0,
                       name=f'kerb up {size * 100:.0f} cm')
    else:
        edge = step_down(x, y, yaw, drop=size, name=f'kerb down {size * 100:.0f} cm')
    return _Parts(legs, [edge], _some_markings(rng, course), ground)


_BUILDERS = {
    'pavement_obstacles': _pavement_obstacles, 'clear_walk': _clear_walk,
    'slope_ahead': _slope_ahead, 'crest': _crest, 'kerb_ramp': _kerb_ramp,
    'camber': _camber, 'asphalt_markings': _asphalt_markings, 'grate': _grate_class,
    'people_crossing': _people_crossing, 'people_towards': _people_towards,
    'kerb_up': lambda rng, rig, d: _kerb(rng, rig, d, True),
    'step_down': lambda rng, rig, d: _kerb(rng, rig, d, False),
    'stop_turn': _stop_turn, 'kerb_cross': _kerb_cross,
}


def _seated(parts: _Parts) -> list[Obstacle]:
    """The obstacles, boxes seated on a sloping ground: their bottom at the lowest ground
    under their footprint (so no gap shows under the downhill side)."""
    bare = World(parts.ground, [], profile=parts.profile)
    out = []
    for o in parts.obstacles:
        if isinstance(o, Box) and not isinstance(o, Person) and o.base_z is None:
            xy = _footprint(o)
            o = dataclasses.replace(o, base_z=float(np.min(bare.ground_height(xy[:, 0],
                                                                                xy[:, 1]))))
        out.append(o)
    return out


def _footprint(o: Box) -> np.ndarray:
    """(4, 2) world corners of a box's footprint."""
    c, s = math.cos(math.radians(o.yaw_deg)), math.sin(math.radians(o.yaw_deg))
    loc = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [o.length / 2, o.width / 2]
    return loc @ np.array([[c, s], [-s, c]]) + [o.x, o.y]


def scene_description(scene_class: str) -> str:
    """One line describing a scene class (its bullet in this module's doc)."""
    bullets, cur = [], None
    for line in __doc__.splitlines():
        if line.startswith('* '):
            cur = [line[2:]]
            bullets.append(cur)
        elif cur is not None and line.startswith('  '):
            cur.append(line.strip())
        else:
            cur = None
    for b in bullets:
        head, _, text = ' '.join(b).partition(': ')
        if f'``{scene_class}``' in head:
            return text
    return scene_class


def build_scene(scene_class: str, seed: int, duration: float, rig: RigSettings,
                realism: bool | None = None, gait: GaitSettings | None = None) -> Scenario:
    """A scene of ``scene_class`` on an explicit rig (``make_scene`` draws the rig).

    Args:
        scene_class: one of SCENE_CLASSES or EXTRA_CLASSES; seed: everything else is
            drawn from it.
        duration: seconds (> 0); rig: the camera settings (realism is added to them when
        drawn on); realism: True, False, or None (on for ~60 % of seeds);
        gait: the walker (None: the default, varied per seed).
    Raises:
        KeyError: unknown class.
    """
    if scene_class not in _BUILDERS:
        raise KeyError(f"unknown scene class '{scene_class}'; known: "
                       f"{', '.join(ALL_CLASSES)}")
    salt = zlib.crc32(('scene/' + scene_class).encode())
    rng = np.random.default_rng([int(seed), salt, 1])
    walker_rng = np.random.default_rng([int(seed), salt, 2])
    camera_rng = np.random.default_rng([int(seed), salt, 3])
    on = bool(camera_rng.random() < REALISM_SHARE) if realism is None else bool(realism)
    if on:
        rig = with_realism(rig, camera_rng)
    parts = _BUILDERS[scene_class](rng, rig, float(duration))
    world = World(parts.ground, _seated(parts), seed=int(seed), profile=parts.profile,
                  markings=parts.markings)
    traj = Trajectory(parts.legs, rig, world, gait=gait, start_speed=parts.start_speed,
                      rng=walker_rng)
    return Scenario(scene_class, scene_description(scene_class), int(seed), float(duration),
                    rig, world, traj)


def make_scene(scene_class: str, seed: int, *, duration: float = 20.0,
               rig: str = 'backpack', realism: bool | None = None) -> Scenario:
    """A random walk of this class; everything (layout, textures, markings, obstacle
    sizes/places, walker's gait, realism effects when realism is None: on for about 60 %
    of seeds) drawn from seed.

    Args:
        scene_class: one of SCENE_CLASSES or EXTRA_CLASSES.
        seed: the seed.
        duration: seconds simulated (10 Hz frames).
        rig: 'backpack' (320 x 240, f 300, B 0.35 m), 'chest' (640 x 480, B 0.12 m) or
            'narrow' (640 x 400, f 450, B 0.075 m).
        realism: camera realism effects on (True), off (False), or drawn (None).
    Raises:
        KeyError: unknown class; ValueError: unknown rig or bad duration.
    """
    if scene_class not in _BUILDERS:
        raise KeyError(f"unknown scene class '{scene_class}'; known: "
                       f"{', '.join(ALL_CLASSES)}")
    if not duration > 0:
        raise ValueError(f'duration must be > 0 s, got {duration}')
    return build_scene(scene_class, seed, duration, drawn_rig(scene_class, seed, rig),
                       realism)


def drawn_rig(scene_class: str, seed: int, rig: str = 'backpack') -> RigSettings:
    """The rig ``make_scene`` draws for this class and seed, before realism."""
    salt = zlib.crc32(('scene-rig/' + scene_class).encode())
    return scene_rig(rig, np.random.default_rng([int(seed), salt]))
