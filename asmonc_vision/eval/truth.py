"""The truth the safety score needs (`eval.safety.SafetyTruth`), from a bag or a scene.

* Footprints: a simulated bag's metadata lists every obstacle's footprint
  (`sim.footprints`, written by the bag writer). A bag without them (recorded elsewhere,
  or by an older simulator) gets footprints from its /ground_truth/obstacles: each
  obstacle's listed feet (its top lowered along the true ground normal), put into the
  world with /ground_truth/camera_pose, as a set of points, present from the first frame
  that lists it. That only knows the parts of an obstacle that were nearest when seen.
* Frames: the true pose of the left optical frame per stereo pair
  (/ground_truth/camera_pose); the obstacles in view are those /ground_truth/obstacles
  lists, with the pixels that see them in both images when known (`visible_pixels` at
  render time, kept by `asmonc campaign` beside its bags), else unknown (all count).
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from asmonc_vision.eval.safety import SafetyTruth, TrueObstacle, TruthFrame

#: kinds of obstacle that move (their footprint in the metadata is their first place)
MOVING_KINDS = ('person',)


def visible_pixels(labels: np.ndarray, depth: np.ndarray, fb: float, cx_shift: float = 0.0
                   ) -> dict[int, int]:
    """Pixels per obstacle seen in both images of a rendered pair.

    A left pixel of obstacle k counts when its match in the right image, at
    u - f B / z, falls inside the right image (the same width). Occlusion in the right
    image alone is not modelled.

    Args:
        labels: (H, W) int left-pixel labels (k > 0 obstacle id).
        depth: (H, W) float left-pixel depth z, metres.
        fb: focal length x baseline, pixel metres.
        cx_shift: right principal point minus left, pixels (0 for a rectified rig).
    Returns:
        id -> pixel count (ids with no such pixel left out).
    """
    v, u = np.nonzero(labels > 0)
    if not u.size:
        return {}
    z = depth[v, u]
    ur = u - fb / np.maximum(z, 1e-6) + cx_shift
    ok = np.isfinite(ur) & (ur >= -0.5) & (ur <= labels.shape[1] - 0.5)
    ids, counts = np.unique(labels[v[ok], u[ok]], return_counts=True)
    return {int(i): int(n) for i, n in zip(ids, counts)}


def obstacles_from_footprints(footprints: list[dict], epoch_ns: int) -> list[TrueObstacle]:
    """`TrueObstacle`s from `sim.footprints.world_footprints` dicts (times in seconds
    after ``epoch_ns``, the stamp of simulation time 0)."""
    out = []
    for d in footprints:
        out.append(TrueObstacle(
            id=int(d['id']), height=float(d['height']),
            footprint=np.asarray(d['polygon'], float).reshape(-1, 2),
            appear_ns=None if d.get('appear_s') is None
            else epoch_ns + int(round(d['appear_s'] * 1e9)),
            vanish_ns=None if d.get('vanish_s') is None
            else epoch_ns + int(round(d['vanish_s'] * 1e9)),
            ground_region=bool(d.get('ground_region', False)), kind=str(d.get('kind', ''))))
    return out


def sim_metadata(bag: Path) -> dict | None:
    """The simulator's metadata of a rosbag2 directory (`sim.bagwriter`), or None."""
    import yaml

    p = Path(bag) / 'metadata.yaml'
    if not p.is_file():
        return None
    try:
        info = yaml.safe_load(p.read_text())['rosbag2_bagfile_information']
        raw = (info.get('custom_data') or {}).get('asmonc_vision.sim')
        return json.loads(raw) if raw else None
    except (KeyError, TypeError, ValueError, yaml.YAMLError):
        return None


def _listed_feet(truth: dict, poses: dict, planes: dict):
    """(stamp_ns, id, (2,) world x, y of the foot, height m) of every listed obstacle,
    stamps ascending: its top lowered along the true ground normal, put into the world
    with the true pose (arguments as `obstacles_from_listings`)."""
    for stamp in sorted(truth):
        T, pose, plane = truth[stamp], poses.get(stamp), planes.get(stamp)
        if T is None or pose is None or plane is None:
            continue
        R, t = (np.asarray(x, float) for x in pose)
        n = np.asarray(plane.normal_up, float)
        for k in range(len(T)):
            foot = np.asarray(T.position[k], float) - float(T.height[k]) * n
            yield int(stamp), int(T.ids[k]), (R @ foot + t)[:2], float(T.height[k])


def obstacles_from_listings(truth: dict, poses: dict, planes: dict) -> list[TrueObstacle]:
    """Point-set footprints from the listed obstacles (see the module doc).

    Args:
        truth: stamp_ns -> `eval.evaluation.FrameObstacles` (left optical frame).
        poses: stamp_ns -> (R, t) of the left optical frame in the world.
        planes: stamp_ns -> the true ground plane (`core.camera.MetricPlane`).
    """
    feet: dict[int, list] = {}
    heights: dict[int, list] = {}
    first: dict[int, int] = {}
    for stamp, i, foot, height in _listed_feet(truth, poses, planes):
        feet.setdefault(i, []).append(foot)
        heights.setdefault(i, []).append(height)
        first.setdefault(i, stamp)
    return [TrueObstacle(id=i, height=float(np.median(heights[i])),
                         footprint=np.array(feet[i]), points=True, appear_ns=first[i])
            for i in sorted(feet)]


def world_tracks(world, stamps_ns, epoch_ns: int) -> dict[int, tuple]:
    """The footprints of a `sim.world.World`'s moving obstacles at the stamps.

    Args:
        world: the world; stamps_ns: increasing frame stamps; epoch_ns: the stamp of
            simulation time 0.
    Returns:
        id -> (stamps_ns (K,) int64, [(M, 2) world x, y polygon per stamp]) for each
        obstacle whose footprint (`sim.footprints.world_footprints`) changes over them.
    """
    from asmonc_vision.sim.footprints import world_footprints

    stamps = np.asarray(stamps_ns, np.int64)
    polys: dict[int, list] = {int(o.id): [] for o in world.obstacles}
    for ns in stamps:
        t = (int(ns) - int(epoch_ns)) / 1e9
        placed = SimpleNamespace(obstacles=[o.at(t, world) for o in world.obstacles])
        for d in world_footprints(placed):
            polys[int(d['id'])].append(np.asarray(d['polygon'], float).reshape(-1, 2))
    return {i: (stamps, p) for i, p in polys.items()
            if p and any(q.shape != p[0].shape or not np.array_equal(q, p[0]) for q in p)}


def scene_world(meta: dict):
    """The `sim.world.World` of a simulated bag, rebuilt from its metadata (scene class,
    seed, duration, rig: `sim.scenes.build_scene`), or None when that is not possible or
    its footprints differ from the metadata's (a bag from another simulator version)."""
    from asmonc_vision.sim.footprints import world_footprints
    from asmonc_vision.sim.rig import RigSettings
    from asmonc_vision.sim.scenes import SCENE_CLASSES, build_scene

    try:
        if meta.get('scenario') not in SCENE_CLASSES:
            return None
        world = build_scene(meta['scenario'], int(meta['seed']), float(meta['duration']),
                            RigSettings(**meta['rig']), realism=False).world
    except (KeyError, TypeError, ValueError):
        return None
    return world if world_footprints(world) == meta.get('footprints') else None


def listed_tracks(frames, ids) -> dict[int, tuple]:
    """Point footprints of obstacles ``ids`` from the listings: per frame that lists
    one, its top lowered along the true ground normal, put into the world with the true
    pose (as `obstacles_from_listings`). id -> (stamps_ns (K,), [(1, 2) per stamp])."""
    out: dict[int, tuple] = {}
    for stamp, i, foot, _ in _listed_feet({f.stamp_ns: f.truth for f in frames},
                                          {f.stamp_ns: f.pose for f in frames},
                                          {f.stamp_ns: f.truth_plane for f in frames}):
        if i in ids:
            st, feet = out.setdefault(i, ([], []))
            st.append(stamp)
            feet.append(foot[None, :])
    return {i: (np.array(st, np.int64), feet) for i, (st, feet) in out.items()}


def moving_tracks(frames, meta: dict | None) -> tuple[dict, bool]:
    """The tracks of a simulated bag's moving obstacles (module doc): (id -> track as
    `world_tracks`, True when they are point footprints from the listings)."""
    fp = (meta or {}).get('footprints') or []
    ids = {int(d['id']) for d in fp if d.get('kind') in MOVING_KINDS}
    if not ids:
        return {}, False
    stamps = sorted(f.stamp_ns for f in frames if f.pose is not None)
    world = scene_world(meta)
    if world is not None:
        return world_tracks(world, stamps, int(meta.get('epoch_ns', 0))), False
    return listed_tracks(frames, ids), True


def truth_from_frames(frames, footprints: list[dict] | None = None, epoch_ns: int = 0,
                      visible: dict | None = None, tracks: dict | None = None,
                      track_points: bool = False) -> SafetyTruth:
    """SafetyTruth of loaded frames (`io.frames.Frame`: stamp, truth, truth_plane, pose).

    Args:
        frames: the bag's frames; those without a true pose are left out.
        footprints: `sim.footprints` dicts (None: from the listings, see the module doc).
        epoch_ns: the stamp of simulation time 0 (for the footprints' times).
        visible: stamp_ns -> {id: pixels in both images} (None: the listed ids, unknown
            counts).
        tracks: id -> a moving obstacle's footprints (`safety.TrueObstacle.track`).
        track_points: the tracks' footprints are point sets.
    """
    have = [f for f in frames if f.pose is not None]
    if footprints is not None:
        obstacles = obstacles_from_footprints(footprints, epoch_ns)
    else:
        obstacles = obstacles_from_listings(
            {f.stamp_ns: f.truth for f in have if f.truth is not None},
            {f.stamp_ns: f.pose for f in have},
            {f.stamp_ns: f.truth_plane for f in have if f.truth_plane is not None})
    tracks = tracks or {}
    obstacles = [dataclasses.replace(o, track=tracks[o.id], points=o.points or track_points)
                 if o.id in tracks else o for o in obstacles]
    out = []
    for f in have:
        if visible is not None and f.stamp_ns in visible:
            vis = {int(k): v for k, v in visible[f.stamp_ns].items()}
        else:
            vis = ({int(i): None for i in f.truth.ids} if f.truth is not None else {})
        out.append(TruthFrame(f.stamp_ns, np.asarray(f.pose[0], float),
                              np.asarray(f.pose[1], float), vis))
    return SafetyTruth(obstacles, out)


def truth_from_bag(bag: Path, frames=None, visible: dict | None = None) -> SafetyTruth | None:
    """SafetyTruth of a bag with /ground_truth/camera_pose (None without poses).

    Args:
        bag: the bag; frames: its frames if already loaded (`io.frames.load_frames`,
            images not needed); visible: as `truth_from_frames`.
    Raises:
        bagio.BagError: unreadable bag.
    """
    from asmonc_vision.io.frames import load_frames

    if frames is None:
        frames = load_frames(bag, images=False)
    if not any(f.pose is not None for f in frames):
        return None
    meta = sim_metadata(bag)
    fp = meta.get('footprints') if meta else None
    tracks, points = moving_tracks(frames, meta) if fp else ({}, False)
    return truth_from_frames(frames, fp, int(meta.get('epoch_ns', 0)) if meta else 0,
                             visible, tracks, points)


def render_scene(scenario) -> tuple[list, SafetyTruth]:
    """Render a scenario in memory: its frames (`io.frames.Frame`, with images, truth and
    true pose) and its `SafetyTruth` (the world's footprints, pixels seen in both images).

    Args:
        scenario: a `sim.scenarios.Scenario` (e.g. from `sim.scenes.make_scene`).
    """
    from asmonc_vision.io.frames import Frame
    from asmonc_vision.eval.evaluation import frame_from_detections
    from asmonc_vision.sim.bagwriter import EPOCH_NS, stamp_ns
    from asmonc_vision.sim.footprints import world_footprints
    from asmonc_vision.sim.render import StereoRenderer
    from asmonc_vision.sim.scenarios import simulate

    cam = scenario.rig.camera()
    frames, tf = [], []
    for f in simulate(scenario, StereoRenderer(scenario.rig)):
        ns = stamp_ns(f.time)
        pose = (np.asarray(f.left_pose.rotation, float), np.asarray(f.left_pose.centre, float))
        frames.append(Frame(ns, f.left, f.right, cam, frame_from_detections(ns, f.obstacles),
                            f.plane, pose))
        tf.append(TruthFrame(ns, pose[0], pose[1], visible_pixels(f.labels, f.depth, cam.fb)))
    tracks = world_tracks(scenario.world, [f.stamp_ns for f in tf], EPOCH_NS)
    obstacles = [dataclasses.replace(o, track=tracks[o.id]) if o.id in tracks else o
                 for o in obstacles_from_footprints(world_footprints(scenario.world), EPOCH_NS)]
    return frames, SafetyTruth(obstacles, tf)
