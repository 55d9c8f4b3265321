"""Scoring detections against ground truth, frame by frame (pure numpy).

Positions are compared *on the ground*: each obstacle's place is the point
``range * (cos bearing, sin bearing)`` in the ground plane, from the point below the
camera (x forward, y left). That is where the wearer must not step, and it does not
depend on whether the obstacle's top is in view (a 2 m post's top is not).

A true obstacle counts as *detected* in a frame when a detection lies within
`match_radius` metres of it on the ground. A detection is *false* when it explains no
true obstacle: it is neither within `match_radius` of one, nor inside one's image
region (so a detection on the far end of a wall is not false, though the wall's true
position is its nearest visible part).

The ground truth lists only obstacles in view. A detector that remembers an obstacle
after it has left the view (walked up to, below the image's bottom edge) reports a
real obstacle the frame's truth does not list. Where the true camera poses are known,
`out_of_view_truth` carries the places where each true obstacle was listed into the
later frames that no longer list it; a detection within `match_radius` of one of those
is counted as *remembered*, neither false nor detected.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from asmonc_vision.core.alarm import AlarmConfig, AlarmLevel, AlarmLogic, ObstacleInfo
from asmonc_vision.core.camera import MetricPlane, ground_range_bearing


@dataclass
class FrameObstacles:
    """Obstacles of one frame, as arrays.

    Attributes:
        stamp_ns: the image pair's stamp.
        ids: (N,) int; track or ground-truth ids.
        position: (N, 3) float, metres, left optical frame (the obstacle's top).
        height: (N,) metres above the ground (negative for a drop).
        range: (N,) metres along the ground.
        bearing: (N,) radians, positive left.
        roi: (N, 4) int (x, y, w, h) in the left image.
        confidence: (N,) float 0..1, or None when not known (taken as 1).
    """

    stamp_ns: int
    ids: np.ndarray
    position: np.ndarray
    height: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    roi: np.ndarray
    confidence: np.ndarray | None = None

    @classmethod
    def empty(cls, stamp_ns: int) -> 'FrameObstacles':
        z = np.zeros(0)
        return cls(stamp_ns, z.astype(int), np.zeros((0, 3)), z, z, z, np.zeros((0, 4), int))

    def __len__(self) -> int:
        return len(self.ids)

    def ground_xy(self) -> np.ndarray:
        """(N, 2) metres: position on the ground, x forward, y left, from the camera's foot."""
        return np.stack([self.range * np.cos(self.bearing),
                         self.range * np.sin(self.bearing)], axis=1)


@dataclass
class ObstacleRecord:
    """How one true obstacle fared over the frames it was eligible in."""

    id: int
    height: float
    min_range: float
    frames_eligible: int = 0
    frames_detected: int = 0

    @property
    def detected(self) -> bool:
        """Detected in at least half of the frames it was eligible in."""
        return self.frames_eligible > 0 and self.frames_detected * 2 >= self.frames_eligible


@dataclass
class DetectionScore:
    """Totals over a sequence (see `score_sequence`)."""

    frames: int = 0
    eligible: int = 0
    detected: int = 0
    false_obstacles: int = 0
    frames_with_false: int = 0
    #: reports that explain only a true obstacle out of view (`out_of_view_truth`)
    remembered: int = 0
    range_errors: list = field(default_factory=list)
    bearing_errors: list = field(default_factory=list)
    obstacles: dict = field(default_factory=dict)

    @property
    def recall(self) -> float:
        """Fraction of (frame, eligible true obstacle) pairs detected; nan if none."""
        return self.detected / self.eligible if self.eligible else float('nan')

    @property
    def false_per_frame(self) -> float:
        return self.false_obstacles / self.frames if self.frames else float('nan')

    def as_dict(self) -> dict:
        """Plain dict for JSON output."""
        obs = {str(k): {'height_m': round(v.height, 3), 'min_range_m': round(v.min_range, 2),
                        'frames_eligible': v.frames_eligible,
                        'frames_detected': v.frames_detected, 'detected': v.detected}
               for k, v in sorted(self.obstacles.items())}
        re = np.asarray(self.range_errors, float)
        be = np.asarray(self.bearing_errors, float)
        return {
            'frames': self.frames, 'eligible': self.eligible, 'detected': self.detected,
            'recall': self.recall, 'false_obstacles': self.false_obstacles,
            'false_per_frame': self.false_per_frame,
            'frames_with_false': self.frames_with_false,
            'remembered_out_of_view': self.remembered,
            'range_error_median_m': float(np.median(np.abs(re))) if re.size else None,
            'bearing_error_median_deg': float(np.degrees(np.median(np.abs(be))))
            if be.size else None,
            'obstacles': obs,
        }


def _inside_roi(roi: np.ndarray, pts_uv: np.ndarray, margin: float) -> np.ndarray:
    """(M, N) bool: detection n's image point inside true roi m (inflated by margin px)."""
    x, y, w, h = (roi[:, i][:, None].astype(float) for i in range(4))
    u, v = pts_uv[:, 0][None, :], pts_uv[:, 1][None, :]
    return (u >= x - margin) & (u <= x + w + margin) & (v >= y - margin) & (v <= y + h + margin)


@dataclass
class FrameMatch:
    """How the detections of one frame pair up with its true obstacles (`match_frame`).

    Attributes:
        truth_det: (M,) int, index of the detection that found true obstacle m, or -1.
        eligible: (M,) bool, true obstacle m counts in the recall (height and range).
        false: (N,) bool, detection n explains no true obstacle.
        remembered: (N,) bool, detection n explains only a true obstacle out of view
            (not false).
    """

    truth_det: np.ndarray
    eligible: np.ndarray
    false: np.ndarray
    remembered: np.ndarray | None = None


def match_frame(det: FrameObstacles, truth: FrameObstacles, *, match_radius: float = 0.3,
                min_height: float = 0.10, max_range: float = 5.0,
                roi_margin: float = 4.0,
                remembered: FrameObstacles | None = None) -> FrameMatch:
    """Pair one frame's detections with its true obstacles, on the ground.

    First the eligible true obstacles (|height| >= min_height, range <= max_range), nearest
    first, each take the nearest unused detection within match_radius of it on the
    ground (greedy); then the other true obstacles, nearest first, take what is left. So
    low or far obstacles never take a detection from an eligible one, and the eligible
    matches are exactly those `score_frame` counts. A detection that would be false but
    lies within match_radius of a ``remembered`` place (true obstacles out of view, from
    `out_of_view_truth`) is marked remembered instead.
    """
    m, n = len(truth), len(det)
    dist = (np.linalg.norm(truth.ground_xy()[:, None, :] - det.ground_xy()[None, :, :], axis=2)
            if m and n else np.zeros((m, n)))
    eligible = (np.abs(truth.height) >= min_height) & (truth.range <= max_range)
    truth_det = np.full(m, -1, int)
    used = np.zeros(n, bool)
    order = np.argsort(truth.range) if m else np.zeros(0, int)
    if n:
        for i in np.r_[order[eligible[order]], order[~eligible[order]]].astype(int):
            d = np.where(used, np.inf, dist[i])
            j = int(np.argmin(d))
            if d[j] <= match_radius:
                used[j] = True
                truth_det[i] = j
    false = np.zeros(n, bool)
    if n:
        near_any = (dist <= match_radius).any(axis=0) if m else np.zeros(n, bool)
        det_uv = np.stack([det.roi[:, 0] + det.roi[:, 2] / 2.0,
                           det.roi[:, 1] + det.roi[:, 3] / 2.0], axis=1)
        in_roi = (_inside_roi(truth.roi, det_uv, roi_margin).any(axis=0)
                  if m else np.zeros(n, bool))
        false = ~(used | near_any | in_roi)
    kept = np.zeros(n, bool)
    if n and remembered is not None and len(remembered):
        dr = np.linalg.norm(remembered.ground_xy()[:, None, :] - det.ground_xy()[None, :, :],
                            axis=2)
        kept = false & (dr <= match_radius).any(axis=0)
        false = false & ~kept
    return FrameMatch(truth_det=truth_det, eligible=eligible, false=false, remembered=kept)


def score_frame(det: FrameObstacles, truth: FrameObstacles, score: DetectionScore, *,
                match_radius: float = 0.3, min_height: float = 0.10,
                max_range: float = 5.0, roi_margin: float = 4.0,
                match: FrameMatch | None = None,
                remembered: FrameObstacles | None = None) -> None:
    """Add one frame's outcome to `score` (in place).

    Eligible true obstacles: |height| >= min_height and range <= max_range.
    Each eligible one is detected if an unused detection lies within match_radius of
    it on the ground (greedy, nearest true obstacle first). Range and bearing errors
    are taken from those matches. `match` (from `match_frame` with the same criteria)
    saves matching twice; ``remembered`` (true obstacles out of view, see `match_frame`)
    is used when it is not given.
    """
    if match is None:
        match = match_frame(det, truth, match_radius=match_radius, min_height=min_height,
                            max_range=max_range, roi_margin=roi_margin,
                            remembered=remembered)
    score.frames += 1
    order = np.argsort(truth.range) if len(truth) else np.zeros(0, int)
    for i in order:
        tid = int(truth.ids[i])
        rec = score.obstacles.get(tid)
        if rec is None:
            rec = score.obstacles[tid] = ObstacleRecord(tid, float(truth.height[i]),
                                                        float(truth.range[i]))
        rec.min_range = min(rec.min_range, float(truth.range[i]))
        if not match.eligible[i]:
            continue
        rec.frames_eligible += 1
        score.eligible += 1
        j = int(match.truth_det[i])
        if j >= 0:
            score.detected += 1
            rec.frames_detected += 1
            score.range_errors.append(float(det.range[j] - truth.range[i]))
            db = (det.bearing[j] - truth.bearing[i] + np.pi) % (2 * np.pi) - np.pi
            score.bearing_errors.append(float(db))
    if len(det):
        nf = int(match.false.sum())
        score.false_obstacles += nf
        score.frames_with_false += int(nf > 0)
        if match.remembered is not None:
            score.remembered += int(match.remembered.sum())


def score_sequence(detections: dict[int, FrameObstacles], truth: dict[int, FrameObstacles],
                   remembered: dict[int, FrameObstacles] | None = None,
                   **kwargs) -> tuple[DetectionScore, list[int]]:
    """Score every ground-truth frame; frames with no detection message are *missing*.

    Args:
        detections: stamp_ns -> detections of that frame (absent: the frame was dropped).
        truth: stamp_ns -> true obstacles of that frame.
        remembered: stamp_ns -> true obstacles out of view (`out_of_view_truth`), or None.
        **kwargs: passed to `score_frame` (its criteria).
    Returns:
        (score over the frames that have detections, stamps of the missing frames).
    """
    score = DetectionScore()
    missing = []
    for stamp in sorted(truth):
        det = detections.get(stamp)
        if det is None:
            missing.append(stamp)
            continue
        score_frame(det, truth[stamp], score,
                    remembered=remembered.get(stamp) if remembered else None, **kwargs)
    return score, missing


def out_of_view_truth(truth: dict[int, FrameObstacles], poses: dict[int, tuple],
                      planes: dict[int, MetricPlane], memory_s: float = 10.0,
                      places_per_obstacle: int = 30) -> dict[int, FrameObstacles]:
    """True obstacles out of view, carried into each frame by the true camera poses.

    An obstacle's listed place is its nearest *visible* part, so when the wearer walks up
    to it and it leaves the bottom of the image it is no longer listed, though it is
    still there. For each frame, every obstacle listed in an earlier frame (within
    ``memory_s``) but not in this one is given by the places where it was listed (its
    latest ``places_per_obstacle`` feet), carried by the poses into this frame.
    Obstacles are taken to stand still in the world (as in the simulator).

    Args:
        truth: stamp_ns -> true obstacles of that frame.
        poses: stamp_ns -> (R (3, 3), t (3,)) pose of the left optical frame in the world
            (``X_world = R X + t``, metres).
        planes: stamp_ns -> the true ground plane of that frame (left optical frame).
        memory_s: how long an obstacle is remembered after it was last listed, s.
        places_per_obstacle: feet kept per obstacle.
    Returns:
        stamp_ns -> FrameObstacles of the remembered places in that frame (ids repeat:
        one row per place; roi zero), for frames with truth, pose and plane; places
        behind the camera are left out.
    """
    feet: dict[int, list] = {}          # id -> [(world foot (3,), height)]
    last: dict[int, int] = {}           # id -> stamp last listed
    out: dict[int, FrameObstacles] = {}
    for stamp in sorted(truth):
        T, pose, plane = truth[stamp], poses.get(stamp), planes.get(stamp)
        if pose is None or plane is None:
            continue
        R, t = (np.asarray(x, float) for x in pose)
        n = np.asarray(plane.normal_up, float)
        listed = set(int(i) for i in T.ids)
        rows = [(i, f, h) for i, pl in feet.items() if i not in listed
                and (stamp - last[i]) / 1e9 <= memory_s for f, h in pl]
        if rows:
            w = np.array([r[1] for r in rows])
            h = np.array([r[2] for r in rows])
            foot = (w - t[None]) @ R                # X = Rᵀ (X_world - t)
            ok = foot[:, 2] > 1e-3
            foot, h, ids = foot[ok], h[ok], np.array([r[0] for r in rows], int)[ok]
            rng, brg = ground_range_bearing(plane, foot)
            out[stamp] = FrameObstacles(stamp, ids, foot + h[:, None] * n[None], h, rng, brg,
                                        np.zeros((len(ids), 4), int))
        else:
            out[stamp] = FrameObstacles.empty(stamp)
        for k in range(len(T)):
            i = int(T.ids[k])
            foot_k = np.asarray(T.position[k], float) - float(T.height[k]) * n
            pl = feet.setdefault(i, [])
            pl.append((R @ foot_k + t, float(T.height[k])))
            del pl[:-places_per_obstacle]
            last[i] = stamp
    return out


# --- warnings in time: was the wearer warned of what lay on the path? -------------------------

#: Alarm levels that warn of an obstacle.
WARNING_LEVELS = (AlarmLevel.CAUTION, AlarmLevel.WARNING, AlarmLevel.STOP)


@dataclass
class PathObstacle:
    """How one true obstacle that lay on the walking path was announced.

    "On the path": inside the alarm's corridor (lateral offset |range·sin(bearing)| at most
    the corridor's half width, ahead of the wearer), |height| at least the alarm's least
    height, and within ``warning_range`` along the ground -- where the alarm node should
    say at least WARNING. Ranges are true ranges along the ground, metres.

    Attributes:
        id: ground-truth id.
        height: metres (negative for a drop).
        frames_on_path: frames in which it was on the path.
        frames_unwarned: of those, frames with no CAUTION, WARNING or STOP in force (CLEAR,
            or nothing said yet); frames under a FAULT count in ``frames_fault`` instead.
        frames_fault: of those, frames with a FAULT in force.
        first_on_path_m: its range in the first frame on the path.
        nearest_m: the nearest it came while on the path.
        warned_at_m: its range in the first frame, from when it first counted for the
            alarm (in the corridor within its max range), with a warning in force; None if
            it never had one.
        nearest_unwarned_m: its range in the nearest unwarned frame on the path, or None.
    """

    id: int
    height: float
    frames_on_path: int
    frames_unwarned: int
    frames_fault: int
    first_on_path_m: float
    nearest_m: float
    warned_at_m: float | None
    nearest_unwarned_m: float | None

    @property
    def warned_in_time(self) -> bool:
        """A warning was in force by the time it came onto the path (its first frame
        within the warning range, or earlier)."""
        return self.warned_at_m is not None and self.warned_at_m >= self.first_on_path_m - 1e-9


def alarm_in_force(stamps: Sequence[int], alarms: Sequence[dict]) -> np.ndarray:
    """The index into `alarms` of the alarm in force at each frame stamp: the last
    announced at or before it (-1 before the first).

    Args:
        stamps: frame stamps, ns, ascending.
        alarms: the alarms in the order they were announced, each a dict with ``stamp_ns``
            (as `asmonc run` logs /alarms). Alarms about a frame carry that frame's stamp;
            those made by the alarm node's own timer (a FAULT for silence) carry its
            clock's time, which need not be the recording's: an alarm stamped more than a
            minute outside the frames' span is placed right after the alarm announced
            before it.
    Returns:
        (len(stamps),) int64 indices.
    """
    st = np.asarray(stamps, np.int64)
    if not len(alarms) or not st.size:
        return np.full(st.shape, -1, np.int64)
    lo, hi = int(st.min()) - 60_000_000_000, int(st.max()) + 60_000_000_000
    eff, prev = [], None
    for a in alarms:
        t = int(a['stamp_ns'])
        if not lo <= t <= hi:
            t = prev if prev is not None else lo
        t = t if prev is None else max(t, prev)
        eff.append(t)
        prev = t
    return np.searchsorted(np.asarray(eff, np.int64), st, side='right') - 1


def alarm_levels_at(stamps: Sequence[int], alarms: Sequence[dict]) -> np.ndarray:
    """The alarm level in force at each frame stamp (`alarm_in_force`; -1 before the
    first alarm), as (len(stamps),) int64 levels."""
    return levels_in_force(alarm_in_force(stamps, alarms), alarms)


def levels_in_force(idx: np.ndarray, alarms: Sequence[dict]) -> np.ndarray:
    """The levels of the alarms at indices ``idx`` ((F,) int64, `alarm_in_force`; -1:
    none, level -1), as (F,) int64."""
    out = np.full(idx.shape, -1, np.int64)
    ok = idx >= 0
    if ok.any():
        out[ok] = np.asarray([int(a['level']) for a in alarms], np.int64)[idx[ok]]
    return out


def path_criteria(config: AlarmConfig) -> dict:
    """The settings of ``config`` that decide which obstacles are on the path (metres)."""
    return {k: getattr(config, k) for k in ('corridor_half_width', 'min_height',
                                            'warning_range', 'max_range')}


def path_warnings(truth: dict[int, FrameObstacles], alarms: Sequence[dict],
                  remembered: dict[int, FrameObstacles] | None = None,
                  config: AlarmConfig | None = None) -> list[PathObstacle]:
    """Whether the wearer was warned of each true obstacle that lay on the walking path.

    The criteria are the alarm's own: an obstacle counts where `AlarmLogic.in_corridor`
    of ``config`` would count it (corridor, ahead, least height, max range), and is on the
    path within its ``warning_range``. An obstacle out of view (walked up to) is taken at
    its remembered places (`out_of_view_truth`), the nearest one that counts. A warning is
    any CAUTION, WARNING or STOP in force (`alarm_levels_at`), whichever obstacle it named:
    the wearer has been told to take care.

    Args:
        truth: stamp_ns -> true obstacles in view.
        alarms: the announced alarms, in order (dicts with ``stamp_ns``, ``level``).
        remembered: stamp_ns -> true obstacles out of view, or None.
        config: the alarm's settings (default `AlarmConfig()`).
    Returns:
        one `PathObstacle` per obstacle that was on the path in some frame, by id.
    """
    logic = AlarmLogic(config)
    warning_range = logic.config.warning_range
    stamps = sorted(truth)
    levels = alarm_levels_at(stamps, alarms)
    track: dict[int, dict] = {}
    for stamp, level in zip(stamps, levels):
        best: dict[int, tuple[float, float]] = {}       # id -> (range, height) that counts
        for fo in (truth[stamp], (remembered or {}).get(stamp)):
            if fo is None:
                continue
            for k in range(len(fo)):
                ob = ObstacleInfo(int(fo.ids[k]), float(fo.range[k]), float(fo.bearing[k]),
                                  float(fo.height[k]))
                if logic.in_corridor(ob) and (ob.id not in best or ob.range < best[ob.id][0]):
                    best[ob.id] = (ob.range, ob.height)
        for i, (r, h) in best.items():
            o = track.setdefault(i, dict(h=h, on=0, unw=0, fault=0, first=None, near=math.inf,
                                         warned=None, near_unw=None))
            if o['warned'] is None and level in WARNING_LEVELS:
                o['warned'] = r
            if r > warning_range:
                continue
            o['on'] += 1
            o['first'] = r if o['first'] is None else o['first']
            o['near'] = min(o['near'], r)
            if level == AlarmLevel.FAULT:
                o['fault'] += 1
            elif level not in WARNING_LEVELS:
                o['unw'] += 1
                o['near_unw'] = r if o['near_unw'] is None else min(o['near_unw'], r)
    return [PathObstacle(i, o['h'], o['on'], o['unw'], o['fault'], o['first'], o['near'],
                         o['warned'], o['near_unw'])
            for i, o in sorted(track.items()) if o['on']]


def path_warnings_summary(obstacles: Sequence[PathObstacle], criteria: dict) -> dict:
    """JSON-ready summary of `path_warnings`: counts and one row per obstacle."""
    return dict(
        criteria=criteria,
        on_path=len(obstacles),
        warned_in_time=sum(o.warned_in_time for o in obstacles),
        warned_late=sum(o.warned_at_m is not None and not o.warned_in_time for o in obstacles),
        never_warned=sum(o.warned_at_m is None for o in obstacles),
        frames_on_path=sum(o.frames_on_path for o in obstacles),
        frames_unwarned=sum(o.frames_unwarned for o in obstacles),
        frames_fault=sum(o.frames_fault for o in obstacles),
        obstacles=[dict(id=o.id, height_m=o.height, frames_on_path=o.frames_on_path,
                        frames_unwarned=o.frames_unwarned, frames_fault=o.frames_fault,
                        first_on_path_m=o.first_on_path_m, nearest_m=o.nearest_m,
                        warned_at_m=o.warned_at_m, nearest_unwarned_m=o.nearest_unwarned_m,
                        warned_in_time=o.warned_in_time) for o in obstacles])


# --- a whole evaluation: recall per bin, errors, ground plane, latency ---------------------

#: Height bins (m, of |height|; the last is open): 0-5, 5-10, 10-20, 20-50, >= 50 cm.
HEIGHT_BINS_M = (0.0, 0.05, 0.10, 0.20, 0.50, math.inf)
#: Range bins (m along the ground): 1-2, 2-3, 3-4, 4-5, 5-8 m.
RANGE_BINS_M = (1.0, 2.0, 3.0, 4.0, 5.0, 8.0)


def frame_from_detections(stamp_ns: int, obstacles) -> FrameObstacles:
    """FrameObstacles from detector obstacles (GpodObstacle, SgbmObstacle, sim ObstacleTruth:
    anything with position, height, range, bearing, roi and optionally id or track_id,
    and confidence)."""
    obs = list(obstacles)
    if not obs:
        return FrameObstacles.empty(int(stamp_ns))
    return FrameObstacles(
        stamp_ns=int(stamp_ns),
        ids=np.array([int(getattr(o, 'id', getattr(o, 'track_id', 0))) for o in obs], int),
        position=np.array([np.asarray(o.position, float).reshape(3) for o in obs]),
        height=np.array([o.height for o in obs], float),
        range=np.array([o.range for o in obs], float),
        bearing=np.array([o.bearing for o in obs], float),
        roi=np.array([tuple(int(x) for x in o.roi) for o in obs], int).reshape(-1, 4),
        confidence=np.array([float(getattr(o, 'confidence', 1.0)) for o in obs], float))


def plane_error(estimate: MetricPlane, truth: MetricPlane) -> tuple[float, float]:
    """(angle between the up normals in degrees, estimate.height - truth.height in metres):
    how far a ground plane is from the true one, both in the left optical frame."""
    n1 = np.asarray(estimate.normal_up, float)
    n2 = np.asarray(truth.normal_up, float)
    c = float(np.dot(n1, n2) / (np.linalg.norm(n1) * np.linalg.norm(n2)))
    return math.degrees(math.acos(min(1.0, max(-1.0, c)))), float(estimate.height - truth.height)


def _bin_label(lo: float, hi: float, unit: str, scale: float) -> str:
    if math.isinf(hi):
        return f'>={lo * scale:g} {unit}'
    return f'{lo * scale:g}-{hi * scale:g} {unit}'


def _median(x) -> float | None:
    x = np.asarray(x, float)
    return float(np.median(x)) if x.size else None


def _pct(x, q: float) -> float | None:
    x = np.asarray(x, float)
    return float(np.percentile(x, q)) if x.size else None


def json_ready(obj):
    """obj with NaN/inf floats replaced by None and numpy scalars by Python ones (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


@dataclass
class SequenceEvaluation:
    """Everything `asmonc eval` reports about one run of a detector over a sequence.

    Feed it frame by frame with `add_frame` (and `add_missing` for frames that got no
    output); `summary()` gives a JSON-ready dict. The headline recall, false obstacles and
    range/bearing errors are those of `score_frame` (the same as `asmonc run`); on top of
    them come the recall per |height| x range bin over *all* true obstacles in the bins,
    the ground-plane error against the true plane, and the per-frame latency.
    """

    match_radius: float = 0.3
    min_height: float = 0.10
    max_range: float = 5.0
    roi_margin: float = 4.0
    height_bins: tuple = HEIGHT_BINS_M
    range_bins: tuple = RANGE_BINS_M
    score: DetectionScore = field(default_factory=DetectionScore)
    bin_eligible: np.ndarray = None  # type: ignore[assignment]  # set in __post_init__
    bin_detected: np.ndarray = None  # type: ignore[assignment]
    #: one row per matched true obstacle: (true range m, range error m, bearing error rad,
    #: true height m, 1 if eligible else 0)
    matches: list = field(default_factory=list)
    stamps: list = field(default_factory=list)
    missing: list = field(default_factory=list)
    plane_angle_deg: list = field(default_factory=list)
    plane_height_m: list = field(default_factory=list)
    frames_without_plane: int = 0
    frames_without_truth_plane: int = 0
    latency_ms: list = field(default_factory=list)
    status_counts: dict = field(default_factory=dict)
    #: for a pooled evaluation: the scored seconds of each part (None: a part had no rate)
    part_durations_s: list | None = None

    def __post_init__(self) -> None:
        shape = (len(self.height_bins) - 1, len(self.range_bins) - 1)
        if self.bin_eligible is None:
            self.bin_eligible = np.zeros(shape, int)
        if self.bin_detected is None:
            self.bin_detected = np.zeros(shape, int)

    @property
    def criteria(self) -> dict:
        return {'match_radius': self.match_radius, 'min_height': self.min_height,
                'max_range': self.max_range, 'roi_margin': self.roi_margin}

    def add_frame(self, det: FrameObstacles, truth: FrameObstacles, *,
                  plane: MetricPlane | None = None, truth_plane: MetricPlane | None = None,
                  latency_ms: float | None = None, status: str | None = None,
                  remembered: FrameObstacles | None = None) -> FrameMatch:
        """Score one frame: its detections against its truth, its ground plane (None: the
        detector had none this frame) against the true one, and its latency.
        ``remembered``: true obstacles out of view in this frame (`out_of_view_truth`)."""
        match = match_frame(det, truth, remembered=remembered, **self.criteria)
        score_frame(det, truth, self.score, match=match, **self.criteria)
        self.stamps.append(int(truth.stamp_ns))
        # (1 um: a 5 cm box stored as 0.0499999... is in the 5-10 cm bin)
        hb = np.digitize(np.abs(truth.height) + 1e-6, self.height_bins) - 1
        rb = np.digitize(truth.range, self.range_bins) - 1
        for i in range(len(truth)):
            j = int(match.truth_det[i])
            if j >= 0:
                db = (det.bearing[j] - truth.bearing[i] + np.pi) % (2 * np.pi) - np.pi
                self.matches.append((float(truth.range[i]), float(det.range[j] - truth.range[i]),
                                     float(db), float(truth.height[i]),
                                     int(match.eligible[i])))
            if 0 <= hb[i] < self.bin_eligible.shape[0] and 0 <= rb[i] < self.bin_eligible.shape[1]:
                self.bin_eligible[hb[i], rb[i]] += 1
                self.bin_detected[hb[i], rb[i]] += int(j >= 0)
        if truth_plane is None:
            self.frames_without_truth_plane += 1
        elif plane is None:
            self.frames_without_plane += 1
        else:
            ang, dh = plane_error(plane, truth_plane)
            self.plane_angle_deg.append(ang)
            self.plane_height_m.append(dh)
        if latency_ms is not None:
            self.latency_ms.append(float(latency_ms))
        if status is not None:
            self.status_counts[status] = self.status_counts.get(status, 0) + 1
        return match

    def add_missing(self, stamp_ns: int) -> None:
        """A frame with ground truth but no detector output (dropped)."""
        self.missing.append(int(stamp_ns))

    @classmethod
    def pooled(cls, evals: list['SequenceEvaluation']) -> 'SequenceEvaluation':
        """One evaluation of several sequences together (same criteria and bins); the
        true obstacles' records are keyed 'part:id' (ids are per sequence)."""
        if not evals:
            return cls()
        e0 = evals[0]
        out = cls(match_radius=e0.match_radius, min_height=e0.min_height,
                  max_range=e0.max_range, roi_margin=e0.roi_margin,
                  height_bins=e0.height_bins, range_bins=e0.range_bins)
        s = out.score
        for i, e in enumerate(evals):
            if (e.criteria, e.height_bins, e.range_bins) != (out.criteria, out.height_bins,
                                                             out.range_bins):
                raise ValueError('cannot pool evaluations with different criteria or bins')
            t = e.score
            s.frames += t.frames
            s.eligible += t.eligible
            s.detected += t.detected
            s.false_obstacles += t.false_obstacles
            s.frames_with_false += t.frames_with_false
            s.remembered += t.remembered
            s.range_errors += t.range_errors
            s.bearing_errors += t.bearing_errors
            for k, rec in t.obstacles.items():      # ids are per sequence: 'part:id'
                s.obstacles[f'{i}:{k}'] = rec
            out.bin_eligible += e.bin_eligible
            out.bin_detected += e.bin_detected
            out.matches += e.matches
            out.missing += e.missing
            out.plane_angle_deg += e.plane_angle_deg
            out.plane_height_m += e.plane_height_m
            out.frames_without_plane += e.frames_without_plane
            out.frames_without_truth_plane += e.frames_without_truth_plane
            out.latency_ms += e.latency_ms
            for k, v in e.status_counts.items():
                out.status_counts[k] = out.status_counts.get(k, 0) + v
        out.part_durations_s = [e.duration_s() for e in evals]
        return out

    def camera_rate_hz(self) -> float | None:
        """Camera rate from the frames' stamps (median interval), or None (also when
        pooled: the parts may differ)."""
        if self.part_durations_s is not None:
            return None
        st = np.unique(np.asarray(self.stamps + self.missing, np.int64))
        if st.size < 2:
            return None
        dt = float(np.median(np.diff(st))) / 1e9
        return 1.0 / dt if dt > 0 else None

    def duration_s(self) -> float | None:
        """Seconds of camera time scored: scored frames / camera rate (None if unknown)."""
        if self.part_durations_s is not None:
            parts = self.part_durations_s
            return None if any(d is None for d in parts) else float(sum(parts))
        rate = self.camera_rate_hz()
        return self.score.frames / rate if rate else None

    def summary(self) -> dict:
        """The whole evaluation as a JSON-ready dict (NaN as None)."""
        s = self.score
        gt = s.as_dict()
        dur = self.duration_s()
        rate = self.camera_rate_hz()
        mt = np.asarray(self.matches, float).reshape(-1, 5)
        elig = mt[mt[:, 4] > 0] if mt.size else mt
        rel = np.abs(elig[:, 1]) / np.maximum(elig[:, 0], 1e-6) * 100 if elig.size else []
        with np.errstate(invalid='ignore', divide='ignore'):
            recall = np.where(self.bin_eligible > 0,
                              self.bin_detected / np.maximum(self.bin_eligible, 1), np.nan)
        hl = [_bin_label(lo, hi, 'cm', 100) for lo, hi in zip(self.height_bins[:-1],
                                                             self.height_bins[1:])]
        rl = [_bin_label(lo, hi, 'm', 1) for lo, hi in zip(self.range_bins[:-1],
                                                          self.range_bins[1:])]
        pa = self.plane_angle_deg
        ph = np.asarray(self.plane_height_m, float) * 1e3
        out = {
            'frames': s.frames, 'missing_frames': len(self.missing),
            'camera_rate_hz': rate, 'duration_s': dur,
            'criteria': {'match_radius_m': self.match_radius, 'min_height_m': self.min_height,
                         'max_range_m': self.max_range, 'roi_margin_px': self.roi_margin},
            'status_counts': dict(self.status_counts),
            'recall': {'eligible': s.eligible, 'detected': s.detected, 'recall': s.recall,
                       'obstacles': gt['obstacles'],
                       'obstacles_detected': sum(1 for o in s.obstacles.values() if o.detected),
                       'obstacles_eligible': sum(1 for o in s.obstacles.values()
                                                 if o.frames_eligible > 0)},
            'recall_bins': {'height_labels': hl, 'range_labels': rl,
                            'height_edges_m': list(self.height_bins),
                            'range_edges_m': list(self.range_bins),
                            'eligible': self.bin_eligible.tolist(),
                            'detected': self.bin_detected.tolist(), 'recall': recall.tolist()},
            'false_obstacles': {'total': s.false_obstacles, 'per_frame': s.false_per_frame,
                                'per_minute': (s.false_obstacles / dur * 60.0) if dur else None,
                                'frames_with_false': s.frames_with_false,
                                'remembered_out_of_view': s.remembered},
            'range_error': {'n': len(s.range_errors),
                            'median_abs_m': gt['range_error_median_m'],
                            'median_m': _median(s.range_errors),
                            'median_abs_pct_of_range': _median(rel)},
            'bearing_error': {'n': len(s.bearing_errors),
                              'median_abs_deg': gt['bearing_error_median_deg'],
                              'median_deg': (math.degrees(float(np.median(s.bearing_errors)))
                                             if s.bearing_errors else None)},
            'ground_plane': {'frames_with_plane': len(pa),
                             'frames_without_plane': self.frames_without_plane,
                             'frames_without_truth': self.frames_without_truth_plane,
                             'angle_median_deg': _median(pa), 'angle_p90_deg': _pct(pa, 90),
                             'height_median_abs_mm': _median(np.abs(ph)),
                             'height_p90_abs_mm': _pct(np.abs(ph), 90),
                             'height_median_mm': _median(ph)},
            'latency_ms': {'n': len(self.latency_ms), 'median': _median(self.latency_ms),
                           'p90': _pct(self.latency_ms, 90)},
        }
        return json_ready(out)
