"""Scenarios: a world, a walk and a rig, and the frame-by-frame simulation of them.

Each scenario function takes ``seed`` (int), ``duration`` (s) and ``rig``
(``RigSettings``, default the paper's rig) and returns a ``Scenario``. The seed draws the
pavement (tile size 0.3-0.6 m, layout, brightness, orientation), the obstacle sizes and
places, and the walker's gait; the same seed gives identical bags. Obstacles are placed
relative to the walking path for the requested duration, so a longer duration gives a
longer course, not an empty one.

Scenarios (see ``SCENARIOS``): static_obstacles, clear_static, walk_obstacles,
clear_walk, walk_stop_turn, slope, step_down, plain_wall.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np

from asmonc_vision.core.camera import MetricPlane
from asmonc_vision.sim.geometry import CameraPose, RigPose
from asmonc_vision.sim.inclinometer import InclinometerSettings
from asmonc_vision.sim.motion import GaitSettings, Leg, Trajectory
from asmonc_vision.sim.render import StereoRenderer, exposure_gains
from asmonc_vision.sim.rig import RigSettings
from asmonc_vision.sim.truth import ObstacleTruth, ground_plane_truth, obstacle_truth
from asmonc_vision.sim.world import (Box, Ground, Obstacle, PavementSettings, Terrace, World,
                                     bollard, door, kerb_up, post, wall)
from asmonc_vision.sim.world import step_down as drop_terrace


@dataclass(frozen=True)
class Scenario:
    """Everything needed to simulate a run.

    Attributes:
        name, description: for the CLI and the bag metadata.
        seed: the scenario seed (camera noise and inclinometer streams derive from it).
        duration: seconds simulated; frames at k / fps for k = 0 .. n_frames - 1.
        rig: camera settings.
        world: the scene.
        trajectory: the rig's motion.
        inclinometer: the compass/inclinometer model.
    """

    name: str
    description: str
    seed: int
    duration: float
    rig: RigSettings
    world: World
    trajectory: Trajectory
    inclinometer: InclinometerSettings = field(default_factory=InclinometerSettings)

    @property
    def n_frames(self) -> int:
        """Number of camera frames."""
        return int(math.floor(self.duration * self.rig.fps - 1e-9)) + 1

    def frame_time(self, k: int) -> float:
        """Time (s) of camera frame k."""
        return k / self.rig.fps

    def describe(self) -> list[str]:
        """One line per obstacle: id, kind, height (m above the ground under it; the rise
        for kerbs and drops), world position (m) and when it exists."""
        lines = []
        for ob in self.world.obstacles:
            when = '' if ob.appear == -math.inf else f', appears at {ob.appear:g} s'
            if isinstance(ob, Terrace):
                p = np.asarray(ob.polygon)
                lines.append(f'{ob.id} {ob.kind}: {ob.rise * 100:+.0f} cm, edge from '
                             f'({p[0, 0]:.2f}, {p[0, 1]:.2f}) to ({p[3, 0]:.2f}, '
                             f'{p[3, 1]:.2f}){when}' if len(p) == 4 else
                             f'{ob.id} {ob.kind}: {ob.rise * 100:+.0f} cm{when}')
            else:
                lines.append(f'{ob.id} {ob.kind}: {ob.height * 100:.0f} cm at '
                             f'({ob.x:.2f}, {ob.y:.2f}){when}')
        return lines


@dataclass
class SimFrame:
    """One simulated camera frame with its ground truth.

    Attributes:
        index: frame number; time: seconds since the start.
        left, right: (H, W) uint8 mono8 rectified images.
        depth: (H, W) float64 left-pixel depth z (m, left optical frame; inf = sky).
        labels: (H, W) int32 left-pixel labels (0 ground, k obstacle id, -1 sky).
        pose: the rig (inclinometer_link) pose; left_pose/right_pose: optical frames.
        plane: the ground plane under the rig, left optical frame.
        obstacles: visible obstacles (ground truth).
    """

    index: int
    time: float
    left: np.ndarray
    right: np.ndarray
    depth: np.ndarray
    labels: np.ndarray
    pose: RigPose
    left_pose: CameraPose
    right_pose: CameraPose
    plane: MetricPlane
    obstacles: list[ObstacleTruth]


def simulate_frame(scenario: Scenario, k: int, renderer: StereoRenderer | None = None
                   ) -> SimFrame:
    """Render camera frame k of the scenario with its ground truth (deterministic: the
    camera noise of frame k depends only on the seed and k)."""
    r = renderer if renderer is not None else StereoRenderer(scenario.rig)
    t = scenario.frame_time(k)
    pose = scenario.trajectory.pose(t)
    img = r.render(scenario.world, t, pose,
                   rng=np.random.default_rng([scenario.seed, 0xCA3E7A, k]),
                   pose_at=scenario.trajectory.pose,
                   exposure=exposure_gains(scenario.rig, scenario.seed, t))
    under = scenario.world.terrace_at(float(pose.position[0]), float(pose.position[1]), t)
    labels = img.labels
    if under is not None:   # the terrace the rig stands on is its ground
        labels = np.where(labels == under.id, 0, labels).astype(np.int32)
    plane = ground_plane_truth(scenario.world, t, pose, img.left_pose)
    obs = obstacle_truth(scenario.world, t, pose, img.left_pose, scenario.rig.camera(), plane,
                         img.depth, labels, img.faces)
    return SimFrame(index=k, time=t, left=img.left, right=img.right, depth=img.depth,
                    labels=labels, pose=pose, left_pose=img.left_pose,
                    right_pose=img.right_pose, plane=plane, obstacles=obs)


def simulate(scenario: Scenario, renderer: StereoRenderer | None = None
             ) -> Iterator[SimFrame]:
    """Render the scenario frame by frame (deterministic for the scenario's seed).

    Yields:
        SimFrame for k = 0 .. n_frames - 1.
    """
    r = renderer if renderer is not None else StereoRenderer(scenario.rig)
    for k in range(scenario.n_frames):
        yield simulate_frame(scenario, k, r)


# --------------------------------------------------------------------------- helpers


def random_pavement(rng: np.random.Generator) -> PavementSettings:
    """A pavement drawn from the seed: tiles 0.3-0.6 m (square or oblong), grid or
    running bond, aligned with world x or y to within 8 degrees."""
    length = float(rng.uniform(0.3, 0.6))
    width = max(float(length * rng.choice([1.0, 1.0, 0.75, 0.6])), 0.3)
    return PavementSettings(
        tile_length=round(length, 3), tile_width=round(width, 3),
        grout_width=round(float(rng.uniform(0.008, 0.015)), 4),
        pattern=str(rng.choice(['grid', 'running_bond'])),
        yaw_deg=round(float(rng.choice([0.0, 90.0]) + rng.uniform(-8.0, 8.0)), 2),
        brightness=round(float(rng.uniform(110.0, 145.0)), 1),
        grout_brightness=round(float(rng.uniform(45.0, 70.0)), 1))


def _along(path_xy: np.ndarray, heading: float, s: float, lateral: float
           ) -> tuple[float, float]:
    """World point ``s`` m ahead along ``heading`` (rad) from path_xy, ``lateral`` m left."""
    c, sn = math.cos(heading), math.sin(heading)
    return (float(path_xy[0] + c * s - sn * lateral), float(path_xy[1] + sn * s + c * lateral))


def obstacle_albedo(rng: np.random.Generator, ground: float) -> float:
    """An albedo clearly darker or brighter than the ground's."""
    if rng.random() < 0.5:
        return float(rng.uniform(40.0, max(ground - 45.0, 45.0)))
    return float(rng.uniform(min(ground + 45.0, 200.0), 215.0))


def random_box(rng: np.random.Generator, x: float, y: float, height: float, ground: float,
               **kw) -> Box:
    """A box of the given height at (x, y), random size, yaw and contrasting albedo."""
    return Box(x=x, y=y, length=float(rng.uniform(0.2, 0.45)),
               width=float(rng.uniform(0.25, 0.5)), height=height,
               yaw_deg=float(rng.uniform(0.0, 90.0)), albedo=obstacle_albedo(rng, ground),
               name=f'box {height * 100:.0f} cm', **kw)


def _distance(traj: Trajectory, t: float) -> float:
    """Path length walked by time t (m), for straight plans."""
    p0, p1 = traj.path(0.0), traj.path(t)
    return float(np.hypot(*(p1 - p0)))


def _rig(rig: RigSettings | None) -> RigSettings:
    return rig if rig is not None else RigSettings()


def _rngs(name: str, seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """(world generator, walker generator) for a scenario: independent streams from the
    seed and the scenario name, so different scenarios with one seed differ."""
    salt = zlib.crc32(name.encode())
    return (np.random.default_rng([seed, salt, 1]), np.random.default_rng([seed, salt, 2]))


# --------------------------------------------------------------------------- scenarios


def static_obstacles(seed: int = 0, duration: float = 8.0,
                     rig: RigSettings | None = None,
                     gait: GaitSettings | None = None) -> Scenario:
    """Standing still; the first 2 s are obstacle-free (for initialisation), then boxes of
    5, 10, 20 and 30 cm appear at 2 s, a post at 3 s and a bollard at 4 s, at 2-5 m."""
    rig = _rig(rig)
    rng, walker = _rngs('static_obstacles', seed)
    ground = Ground(pavement=random_pavement(rng))
    gb = ground.pavement.brightness
    items = [('box', 0.05), ('box', 0.10), ('box', 0.20), ('box', 0.30),
             ('post', 2.2), ('bollard', 0.9)]
    half_fov = math.atan((rig.width / 2) / rig.focal)
    slots = np.linspace(-0.7, 0.7, len(items)) * half_fov
    order = rng.permutation(len(items))
    obstacles: list[Obstacle] = []
    placed: list[tuple[float, float]] = []
    for (kind, h), k in zip(items, order):
        bearing = float(slots[k] + rng.uniform(-0.04, 0.04))
        # centre range such that the nearest point is 2-5 m away, 0.8 m from the others
        margin = {'box': 0.35, 'post': 0.06, 'bollard': 0.11}[kind]
        for _ in range(100):
            rng_m = float(rng.uniform(2.0 + margin, 5.0))
            x, y = rng_m * math.cos(bearing), rng_m * math.sin(bearing)
            if all(math.hypot(x - px, y - py) > 0.8 for px, py in placed):
                break
        placed.append((x, y))
        if kind == 'box':
            obstacles.append(random_box(rng, x, y, h, gb, appear=2.0))
        elif kind == 'post':
            obstacles.append(post(x, y, height=h, appear=3.0, round_=bool(rng.random() < 0.5),
                                  name='post'))
        else:
            obstacles.append(bollard(x, y, height=h, appear=4.0, name='bollard'))
    world = World(ground, obstacles, seed=seed)
    traj = Trajectory([Leg(duration, 0.0)], rig, world, gait=gait, rng=walker)
    return Scenario('static_obstacles', static_obstacles.__doc__.split('\n')[0].strip(),
                    seed, duration, rig, world, traj)


def clear_static(seed: int = 0, duration: float = 5.0,
                 rig: RigSettings | None = None,
                 gait: GaitSettings | None = None) -> Scenario:
    """Standing still on a clear pavement: nothing above the ground (false alarms)."""
    rig = _rig(rig)
    rng, walker = _rngs('clear_static', seed)
    world = World(Ground(pavement=random_pavement(rng)), [], seed=seed)
    traj = Trajectory([Leg(duration, 0.0)], rig, world, gait=gait, rng=walker)
    return Scenario('clear_static', clear_static.__doc__.split('\n')[0].strip(), seed,
                    duration, rig, world, traj)


def walk_obstacles(seed: int = 0, duration: float = 10.0,
                   rig: RigSettings | None = None,
                   gait: GaitSettings | None = None) -> Scenario:
    """Stand 1.5 s, then walk (~1.2 m/s, speed changes) among boxes of 3-30 cm, posts, a
    bollard, a door opened into the path from a wall, towards a 12 cm kerb up."""
    rig = _rig(rig)
    rng, walker = _rngs('walk_obstacles', seed)
    ground = Ground(pavement=random_pavement(rng))
    gb = ground.pavement.brightness
    stand = min(1.5, 0.15 * duration)
    walk = duration - stand
    legs = [Leg(stand, 0.0), Leg(walk * 0.5, 1.2, ramp=1.0),
            Leg(walk * 0.5, float(rng.uniform(0.9, 1.4)), ramp=1.5)]
    probe = Trajectory(legs, rig, None, rng=0)
    end = _distance(probe, duration)
    kerb = end + float(rng.uniform(5.0, 6.0))
    d = min(max(end * 0.6, 7.0), kerb - 1.5)     # where the door is
    obstacles: list[Obstacle] = []
    # a course of obstacles from 5 m to the kerb (none on the kerb, none in the door swing)
    course = [0.03, 'post', 0.30, 'bollard', 0.08, 0.15, 'post', 0.05, 0.20, 'bollard',
              0.10, 0.25]
    s = 5.0
    k = 0
    while s < kerb - 0.8:
        item = course[k % len(course)]
        if isinstance(item, str):
            lat = float(rng.choice([-1, 1]) * rng.uniform(0.7, 1.4))
        else:
            lat = float(rng.uniform(-1.2, 1.2))
        if abs(s - d) < 1.2:
            lat = abs(lat)
        x, y = _along((0.0, 0.0), 0.0, s, lat)
        if item == 'bollard':
            obstacles.append(bollard(x, y, height=float(rng.uniform(0.8, 1.0)),
                                     name='bollard'))
        elif item == 'post':
            obstacles.append(post(x, y, height=2.2, round_=bool(rng.random() < 0.5),
                                  name='post'))
        else:
            obstacles.append(random_box(rng, x, y, float(item), gb))
        s += float(rng.uniform(1.1, 1.8))
        k += 1
    # a wall on the right with a door opened into the path
    wy = -float(rng.uniform(1.6, 1.9))
    obstacles.append(wall(d - 6.0, wy, d - 0.5, wy, name='wall'))
    obstacles.append(wall(d + 0.5, wy, d + 8.0, wy, name='wall'))
    obstacles.append(door(d - 0.45, wy + 0.12, 0.0, float(rng.uniform(50.0, 70.0)),
                          name='door (open)'))
    obstacles.append(kerb_up(kerb, 0.0, float(rng.uniform(-8.0, 8.0)), rise=0.12,
                             name='kerb up 12 cm'))
    world = World(ground, obstacles, seed=seed)
    traj = Trajectory(legs, rig, world, gait=gait, rng=walker)
    return Scenario('walk_obstacles', walk_obstacles.__doc__.split('\n')[0].strip(), seed,
                    duration, rig, world, traj)


def clear_walk(seed: int = 0, duration: float = 8.0,
               rig: RigSettings | None = None,
               gait: GaitSettings | None = None) -> Scenario:
    """Walking on a clear pavement at ~1.2 m/s with a speed change and a gentle bend."""
    rig = _rig(rig)
    rng, walker = _rngs('clear_walk', seed)
    world = World(Ground(pavement=random_pavement(rng)), [], seed=seed)
    v = float(rng.uniform(1.1, 1.3))
    legs = [Leg(duration * 0.4, v), Leg(duration * 0.3, float(rng.uniform(0.9, 1.4)),
                                        turn_deg=float(rng.choice([-1, 1])
                                                       * rng.uniform(5, 15)), ramp=1.5),
            Leg(duration * 0.3, v, ramp=1.5)]
    traj = Trajectory(legs, rig, world, start_speed=v, gait=gait, rng=walker)
    return Scenario('clear_walk', clear_walk.__doc__.split('\n')[0].strip(), seed,
                    duration, rig, world, traj)


def walk_stop_turn(seed: int = 0, duration: float = 12.0,
                   rig: RigSettings | None = None,
                   gait: GaitSettings | None = None) -> Scenario:
    """Walk towards a wall, stop, turn ~90 degrees left in place, walk on past a few
    obstacles."""
    rig = _rig(rig)
    rng, walker = _rngs('walk_stop_turn', seed)
    ground = Ground(pavement=random_pavement(rng))
    gb = ground.pavement.brightness
    v = float(rng.uniform(1.1, 1.3))
    turn = float(rng.uniform(80.0, 100.0))
    rest = max(duration - 3.8, 1.0)      # walking time; stop, stand, turn, stand: 3.8 s
    legs = [Leg(0.55 * rest, v), Leg(1.0, 0.0, ramp=1.0), Leg(0.5, 0.0),
            Leg(2.0, 0.0, turn_deg=turn), Leg(0.3, 0.0), Leg(0.45 * rest, v, ramp=1.0)]
    probe = Trajectory(legs, rig, None, start_speed=v, rng=0)
    t_stop = 0.55 * rest + 1.0
    stop_xy = probe.path(t_stop)
    heading = math.radians(turn)
    obstacles: list[Obstacle] = []
    # the wall ahead of the stop
    wx = float(stop_xy[0]) + float(rng.uniform(2.8, 3.5))
    obstacles.append(wall(wx, -6.0, wx, 6.0, name='wall ahead'))
    # obstacles along the new direction
    for s, lat, h in ((3.0, float(rng.uniform(-0.6, 0.6)), 0.15),
                      (5.0, float(rng.uniform(-0.8, 0.8)), 0.08)):
        x, y = _along(stop_xy, heading, s, lat)
        obstacles.append(random_box(rng, x, y, h, gb))
    x, y = _along(stop_xy, heading, 6.5, float(rng.choice([-1, 1]) * rng.uniform(0.7, 1.2)))
    obstacles.append(bollard(x, y, name='bollard'))
    world = World(ground, obstacles, seed=seed)
    traj = Trajectory(legs, rig, world, start_speed=v, gait=gait, rng=walker)
    return Scenario('walk_stop_turn', walk_stop_turn.__doc__.split('\n')[0].strip(), seed,
                    duration, rig, world, traj)


def slope(seed: int = 0, duration: float = 6.0, rig: RigSettings | None = None,
          slope_deg: float = 5.0, gait: GaitSettings | None = None) -> Scenario:
    """Walking uphill on a 5 degree slope with a few obstacles ahead."""
    rig = _rig(rig)
    rng, walker = _rngs('slope', seed)
    ground = Ground(slope_deg=slope_deg, slope_yaw_deg=0.0, pavement=random_pavement(rng))
    gb = ground.pavement.brightness
    v = float(rng.uniform(1.0, 1.2))
    legs = [Leg(duration, v)]
    end = v * duration
    obstacles: list[Obstacle] = []
    s, k = 4.0, 0
    heights = [0.10, 0.20, 0.05, 0.15]
    while s < end + 6.0:
        if k % 3 == 2:
            obstacles.append(bollard(s, float(rng.choice([-1, 1]) * rng.uniform(0.7, 1.3)),
                                     name='bollard'))
        else:
            obstacles.append(random_box(rng, s, float(rng.uniform(-1.0, 1.0)),
                                  heights[k % len(heights)], gb))
        s += float(rng.uniform(1.8, 2.6))
        k += 1
    world = World(ground, obstacles, seed=seed)
    traj = Trajectory(legs, rig, world, start_speed=v, gait=gait, rng=walker)
    return Scenario('slope', slope.__doc__.split('\n')[0].strip(), seed, duration, rig,
                    world, traj)


def step_down(seed: int = 0, duration: float = 8.0,
              rig: RigSettings | None = None, drop: float = 0.15,
              gait: GaitSettings | None = None) -> Scenario:
    """Walking towards a 15 cm kerb down (the ground beyond a line drops), stopping ~2 m
    before the edge."""
    rig = _rig(rig)
    rng, walker = _rngs('step_down', seed)
    ground = Ground(pavement=random_pavement(rng))
    v = float(rng.uniform(1.1, 1.3))
    stop_ramp = 1.2
    legs = [Leg(max(duration - 2.5, 0.5), v), Leg(2.5, 0.0, ramp=stop_ramp)]
    probe = Trajectory(legs, rig, None, start_speed=v, rng=0)
    end = _distance(probe, duration)
    edge = end + float(rng.uniform(1.8, 2.4))
    obstacles = [drop_terrace(edge, 0.0, float(rng.uniform(-10, 10)), drop=drop,
                              name=f'kerb down {drop * 100:.0f} cm')]
    world = World(ground, obstacles, seed=seed)
    traj = Trajectory(legs, rig, world, start_speed=v, gait=gait, rng=walker)
    return Scenario('step_down', step_down.__doc__.split('\n')[0].strip(), seed, duration,
                    rig, world, traj)


def plain_wall(seed: int = 0, duration: float = 8.0,
               rig: RigSettings | None = None,
               gait: GaitSettings | None = None) -> Scenario:
    """Walking towards a plain painted wall across the path (no texture on its face, so
    no vertical edges in front), stopping ~1.5 m before it."""
    rig = _rig(rig)
    rng, walker = _rngs('plain_wall', seed)
    ground = Ground(pavement=random_pavement(rng))
    v = float(rng.uniform(1.0, 1.3))
    legs = [Leg(max(duration - 2.5, 0.5), v), Leg(2.5, 0.0, ramp=1.2)]
    probe = Trajectory(legs, rig, None, start_speed=v, rng=0)
    wx = _distance(probe, duration) + float(rng.uniform(1.3, 1.8))
    albedo = obstacle_albedo(rng, ground.pavement.brightness)
    obstacles = [wall(wx, -8.0, wx, 8.0, albedo=albedo, texture=0.0, name='plain wall')]
    world = World(ground, obstacles, seed=seed)
    traj = Trajectory(legs, rig, world, start_speed=v, gait=gait, rng=walker)
    return Scenario('plain_wall', plain_wall.__doc__.split('\n')[0].strip(), seed, duration,
                    rig, world, traj)


#: Scenario name -> function(seed, duration, rig) -> Scenario.
SCENARIOS: dict[str, Callable[..., Scenario]] = {
    'static_obstacles': static_obstacles,
    'clear_static': clear_static,
    'walk_obstacles': walk_obstacles,
    'clear_walk': clear_walk,
    'walk_stop_turn': walk_stop_turn,
    'slope': slope,
    'step_down': step_down,
    'plain_wall': plain_wall,
}

#: Default durations (s) of the scenarios.
DEFAULT_DURATIONS = {'static_obstacles': 8.0, 'clear_static': 5.0, 'walk_obstacles': 10.0,
                     'clear_walk': 8.0, 'walk_stop_turn': 12.0, 'slope': 6.0,
                     'step_down': 8.0, 'plain_wall': 8.0}


def make_scenario(name: str, seed: int = 0, duration: float | None = None,
                  rig: RigSettings | None = None,
                  gait: GaitSettings | None = None) -> Scenario:
    """Build a scenario by name (``duration`` None = its default; ``gait`` None = the
    default walker, `GaitSettings`, whose amplitudes and step frequency still vary per
    seed; e.g. ``GaitSettings.extreme()``, the paper's extreme motion).

    Raises:
        KeyError: unknown scenario name (the message lists the known ones).
    """
    if name not in SCENARIOS:
        raise KeyError(f"unknown scenario '{name}'; known: {', '.join(SCENARIOS)}")
    fn = SCENARIOS[name]
    return fn(seed=seed, duration=duration if duration is not None else DEFAULT_DURATIONS[name],
              rig=rig, gait=gait)
