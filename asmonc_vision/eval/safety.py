"""The wearer's safety score: one implementation of the definitions in docs/evaluation.md.

Inputs (all in bag time, nanosecond stamps):

* the truth (`SafetyTruth`): every true obstacle of the world with its footprint on
  the ground (world x, y, metres; z up; a moving one's, e.g. a walking person's, where
  it is at each frame's stamp), its height (negative for a drop) and when it exists;
  and per camera frame the true pose of the left optical frame in the world and which
  obstacles are in view (with the pixels that see them in both images, if known);
* the alarms given (dicts ``stamp_ns``, ``level``, ``obstacle_id``, ``range`` m,
  ``bearing`` rad, as /alarms carries them), in the order they were announced;
* the obstacles reported per frame (``eval.evaluation.FrameObstacles``: ``height``,
  ``range``, ``bearing`` are used).

Geometry. At each frame the wearer's *ground frame* is the point on the ground below the
left camera (the pose's x, y) and the *heading*, the left camera's optical axis laid on
the ground (REP 103: x forward, y left). A range and bearing (as in the topic contract)
are put on the ground in the world through it. Distances are horizontal (world x, y).

Definitions (`SafetyCriteria` holds every number):

* **Corridor**: the strip 0..``corridor_length`` ahead, +-``corridor_half_width`` to the
  sides of the heading. An obstacle is *in the corridor* when its footprint meets it.
* **On the path**: present, |height| >= ``min_height``, in the corridor, and the nearest
  point of its footprint's part inside the corridor within ``on_path_range`` of the
  ground point below the camera. Obstacles out of view count where they are.
* **Alarm in force** at a frame: the last alarm stamped at or before the frame's stamp
  (`eval.evaluation.alarm_levels_at`, which also places alarms stamped by a node's own
  clock, far outside the bag's span, right after the alarm before them).
* **Warned in time**: per obstacle, at its first frame on the path the alarm in force is
  CAUTION, WARNING or STOP: *warned*. FAULT there: *under FAULT* (apart). Otherwise
  (CLEAR, or nothing said yet): *late* when a warning is in force at a later frame on
  the path, else *never*. Also counted: frames with an obstacle on the path with CLEAR
  (or nothing) in force, and with FAULT. Beside the definition, what the warning of a
  warned obstacle was about (``warned_by``): put on the ground with the true pose of its
  stamp, it lies within the false alarm tolerance (below) of the obstacle's own
  footprint (*itself*), or else nearer to the wearer than the obstacle (*nearer*: a
  nearer hazard outranks it) or not (*farther*: something farther off was the nearest
  thing the alarm knew of, so the obstacle itself was not seen then; warned by the
  definition, by chance).
* **False alarm**: a CAUTION, WARNING or STOP whose range and bearing, put on the ground
  with the true pose of its stamp (the frame at or before it), lie farther than
  max(``alarm_tolerance_m``, ``alarm_tolerance_frac`` x range) from the footprint of
  every obstacle present. One *event* each time such an alarm starts: its level or its
  obstacle id differs from the previous alarm's. Per minute of *walking*: frames whose
  camera moved faster than ``walking_speed`` over a centred window of
  ``walking_window_s``, each counted for its frame interval.
* **False report**: a reported obstacle (not an unknown-ahead entry, whose height is
  NaN: it says the ground there cannot be seen, `core.unseen_ground`) whose ground
  point lies farther than max(``report_tolerance_m``, ``report_tolerance_frac`` x its
  range) from the footprint of every obstacle present; a drop is matched only by a
  report of negative height. Per frame scored (frames with a report list).
* **Recall**: (obstacle, frame) pairs of obstacles in view with at least
  ``recall_min_pixels`` pixels seen in both images (all listed ones when the counts are
  unknown), matched one to one to reports, nearest pair first, within the same
  tolerance (and the drop rule); binned by |height| and range (the nearest point of the
  footprint). The headline adds the subset >= ``min_height`` within ``corridor_length``.
* **FAULT while walking** (beside the definitions, not one of them): the share of walking
  time with FAULT in force ("cannot see the way ahead", a lost ground, a sensor fault),
  each walking frame counted for its frame interval: the fault cue a wearer hears on a
  path that may be clear.

A terrace (raised or lowered ground, ``ground_region``) the wearer stands on is ground,
not an obstacle, while the point below the camera is inside it.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from asmonc_vision.core.alarm import AlarmLevel
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.eval.evaluation import (HEIGHT_BINS_M, RANGE_BINS_M, WARNING_LEVELS,
                                           FrameObstacles, alarm_in_force, json_ready,
                                           levels_in_force)


@dataclass(frozen=True)
class SafetyCriteria:
    """The numbers of the safety score's definitions (docs/evaluation.md)."""

    corridor_half_width: float = param(0.5, 'walking corridor half width, metres',
                                       range=(0.05, 5.0))
    corridor_length: float = param(5.0, 'walking corridor length ahead, metres',
                                   range=(0.5, 50.0))
    on_path_range: float = param(2.5, 'an obstacle in the corridor is on the path when its '
                                 'nearest point there is this near, metres', range=(0.1, 50.0))
    min_height: float = param(0.10, 'least |height| of an obstacle (depth of a drop) on the '
                              'path, metres', range=(0.0, 5.0))
    alarm_tolerance_m: float = param(0.5, 'an alarm this near a true footprint is not false, '
                                     'metres', range=(0.0, 10.0))
    alarm_tolerance_frac: float = param(0.15, '... or this fraction of its range',
                                        range=(0.0, 1.0))
    report_tolerance_m: float = param(0.3, 'a report this near a true footprint is not '
                                      'false (and finds it), metres', range=(0.0, 10.0))
    report_tolerance_frac: float = param(0.10, '... or this fraction of its range',
                                         range=(0.0, 1.0))
    recall_min_pixels: int = param(20, 'obstacles seen by fewer pixels in both images do '
                                   'not count in the recall', range=(0, 100000))
    walking_speed: float = param(0.2, 'the camera moves faster than this: walking, m/s',
                                 range=(0.0, 10.0))
    walking_window_s: float = param(1.0, 'window of the walking speed, centred, seconds',
                                    range=(0.0, 10.0))
    cue_lead_s: float = param(3.0, 'an obstacle on the path is cued ahead when CAUTION or '
                              'higher was in force while it lay in the corridor at least '
                              'this long before contact at the walking speed, seconds',
                              range=(0.0, 60.0))
    entry_slack_s: float = param(0.2, 'an obstacle that came into the corridor less than '
                                 'cue_lead_s before contact (the wearer turned towards it) is '
                                 'cued at entry when the cue led by at least its lead at entry '
                                 'less this, seconds (about two pairs at walking pace)',
                                 range=(0.0, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TrueObstacle:
    """One true obstacle, fixed in the world or moving on it (``track``).

    Attributes:
        id: ground-truth id.
        height: metres above the ground; negative for a drop (its depth).
        footprint: (M, 2) float64 world x, y, metres: a convex polygon (M >= 3, either
            orientation), or with ``points`` a set of points (M >= 1) on it.
        points: the footprint is a point set, not a polygon (known only where seen).
        appear_ns, vanish_ns: it exists for appear_ns <= stamp < vanish_ns (None: always).
        ground_region: a terrace (kerb up, step down): ground, not an obstacle, while the
            point below the camera is inside its footprint.
        kind: free text ('box', 'drop', ...).
        track: a moving obstacle's footprints: (stamps_ns (K,) int, increasing; K
            footprints, each as ``footprint``); at a stamp it is the one at or before it
            (the first before them all), `placed`. None: fixed at ``footprint``.
    """

    id: int
    height: float
    footprint: np.ndarray
    points: bool = False
    appear_ns: int | None = None
    vanish_ns: int | None = None
    ground_region: bool = False
    kind: str = ''
    track: tuple | None = None

    def placed(self, stamp_ns: int) -> 'TrueObstacle':
        """The obstacle where it is at ``stamp_ns``: itself unless it moves."""
        if self.track is None:
            return self
        stamps, feet = self.track
        i = int(np.searchsorted(np.asarray(stamps, np.int64), int(stamp_ns), side='right'))
        return dataclasses.replace(self, footprint=np.asarray(feet[max(i - 1, 0)], float),
                                   track=None)


@dataclass
class TruthFrame:
    """What is true at one camera frame.

    Attributes:
        stamp_ns: the stereo pair's stamp.
        R, t: pose of the left optical frame in the world, ``X_world = R X + t``
            (R (3, 3), t (3,) metres; world z up).
        visible: id -> pixels that see it in both images (None: unknown, counts as
            enough) for the obstacles in view.
    """

    stamp_ns: int
    R: np.ndarray
    t: np.ndarray
    visible: dict = field(default_factory=dict)

    @property
    def foot(self) -> np.ndarray:
        """(2,) world x, y of the point on the ground below the left camera."""
        return np.asarray(self.t, float)[:2]

    @property
    def heading(self) -> np.ndarray:
        """(2,) unit world x, y of the optical axis laid on the ground."""
        f = np.asarray(self.R, float)[:2, 2]
        n = float(np.hypot(*f))
        return f / n if n > 1e-9 else np.array([1.0, 0.0])

    def to_world(self, rng: np.ndarray, bearing: np.ndarray) -> np.ndarray:
        """(N, 2) world x, y of ground points at range (N,) m and bearing (N,) rad
        (positive left) from this frame's ground frame."""
        f = self.heading
        lft = np.array([-f[1], f[0]])
        r = np.asarray(rng, float).reshape(-1, 1)
        b = np.asarray(bearing, float).reshape(-1, 1)
        return self.foot[None] + r * (np.cos(b) * f[None] + np.sin(b) * lft[None])

    def to_ground(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) (forward, left) metres of world points xy (N, 2) in this ground frame."""
        f = self.heading
        d = np.asarray(xy, float).reshape(-1, 2) - self.foot[None]
        return np.stack([d @ f, d @ np.array([-f[1], f[0]])], axis=1)


@dataclass
class SafetyTruth:
    """The world's obstacles and the frames, in stamp order."""

    obstacles: list[TrueObstacle]
    frames: list[TruthFrame]

    def __post_init__(self) -> None:
        self.frames = sorted(self.frames, key=lambda f: f.stamp_ns)
        self._stamps = np.array([f.stamp_ns for f in self.frames], np.int64)

    def frame_at(self, stamp_ns: int) -> TruthFrame | None:
        """The frame at or before ``stamp_ns`` (the first frame before them all)."""
        if not self.frames:
            return None
        i = int(np.searchsorted(self._stamps, int(stamp_ns), side='right')) - 1
        return self.frames[max(i, 0)]

    def present(self, frame: TruthFrame) -> list[TrueObstacle]:
        """The obstacles that exist at the frame and are not ground under the wearer, a
        moving one where it is at the frame's stamp."""
        out = []
        for ob in self.obstacles:
            if ob.appear_ns is not None and frame.stamp_ns < ob.appear_ns:
                continue
            if ob.vanish_ns is not None and frame.stamp_ns >= ob.vanish_ns:
                continue
            ob = ob.placed(frame.stamp_ns)
            if ob.ground_region and not ob.points and polygon_distance(
                    ob.footprint, frame.foot) == 0.0:
                continue
            out.append(ob)
        return out


# --- geometry --------------------------------------------------------------------------

def polygon_distance(poly: np.ndarray, q: np.ndarray) -> float:
    """Distance (m) from point q (2,) to a convex polygon (M, 2) (0 inside or on it)."""
    p = np.asarray(poly, float).reshape(-1, 2)
    q = np.asarray(q, float).reshape(2)
    if len(p) == 1:
        return float(np.hypot(*(p[0] - q)))
    a, e = p, np.roll(p, -1, axis=0) - p
    cross = e[:, 0] * (q[1] - a[:, 1]) - e[:, 1] * (q[0] - a[:, 0])
    if len(p) >= 3 and (np.all(cross >= -1e-12) or np.all(cross <= 1e-12)):
        return 0.0
    s = np.clip(np.einsum('ij,ij->i', q[None] - a, e) / np.maximum(
        np.einsum('ij,ij->i', e, e), 1e-18), 0.0, 1.0)
    return float(np.min(np.hypot(*(a + s[:, None] * e - q[None]).T)))


def footprint_distance(ob: TrueObstacle, q: np.ndarray) -> float:
    """Distance (m) on the ground from world point q (2,) to an obstacle's footprint."""
    if ob.points:
        d = np.asarray(ob.footprint, float).reshape(-1, 2) - np.asarray(q, float)[None]
        return float(np.min(np.hypot(d[:, 0], d[:, 1])))
    return polygon_distance(ob.footprint, q)


def _clip(poly: np.ndarray, axis: int, bound: float, keep_below: bool) -> np.ndarray:
    """Sutherland-Hodgman: the part of polygon (M, 2) with x[axis] <= bound (or >=)."""
    if not len(poly):
        return poly
    out = []
    sgn = 1.0 if keep_below else -1.0
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        da, db = sgn * (bound - a[axis]), sgn * (bound - b[axis])
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (b - a) * (da / (da - db)))
    return np.array(out).reshape(-1, 2)


def corridor_range(ob: TrueObstacle, frame: TruthFrame, half_width: float,
                   length: float) -> float | None:
    """Distance (m) from the point below the camera to the nearest point of the obstacle's
    footprint inside the corridor (0..length ahead, +-half_width), or None when the
    footprint does not meet the corridor."""
    g = frame.to_ground(ob.footprint)
    if ob.points or len(g) < 3:
        k = (g[:, 0] >= 0) & (g[:, 0] <= length) & (np.abs(g[:, 1]) <= half_width)
        return float(np.min(np.hypot(g[k, 0], g[k, 1]))) if k.any() else None
    for axis, bound, below in ((0, 0.0, False), (0, length, True),
                               (1, -half_width, False), (1, half_width, True)):
        g = _clip(g, axis, bound, below)
    if len(g) == 0:
        return None
    return polygon_distance(g, np.zeros(2))


# --- the score ---------------------------------------------------------------------------

@dataclass
class SafetyScore:
    """Totals of `score_safety`; additive over walks (`merge`)."""

    criteria: dict = field(default_factory=dict)
    on_path: int = 0
    warned: int = 0
    late: int = 0
    never: int = 0
    under_fault: int = 0
    warned_by_farther: int = 0
    cued_ahead: int = 0
    cued_at_entry: int = 0
    frames: int = 0
    frames_on_path: int = 0
    frames_on_path_clear: int = 0
    frames_on_path_fault: int = 0
    duration_s: float = 0.0
    walking_s: float = 0.0
    walking_fault_s: float = 0.0
    false_alarm_events: list = field(default_factory=list)
    alarms_false: int = 0
    alarms_warning: int = 0
    frames_scored: int = 0
    frames_missing: int = 0
    reports: int = 0
    false_reports: int = 0
    recall_eligible: int = 0
    recall_found: int = 0
    headline_eligible: int = 0
    headline_found: int = 0
    bin_eligible: np.ndarray = field(default_factory=lambda: np.zeros(
        (len(HEIGHT_BINS_M) - 1, len(RANGE_BINS_M) - 1), int))
    bin_found: np.ndarray = field(default_factory=lambda: np.zeros(
        (len(HEIGHT_BINS_M) - 1, len(RANGE_BINS_M) - 1), int))
    path_obstacles: list = field(default_factory=list)

    @property
    def false_alarms_per_minute(self) -> float | None:
        """False alarm events per minute of walking (None: no walking)."""
        return (len(self.false_alarm_events) / (self.walking_s / 60.0)
                if self.walking_s > 0 else None)

    @property
    def fault_share_walking(self) -> float | None:
        """The share of walking time with FAULT in force (None: no walking)."""
        return self.walking_fault_s / self.walking_s if self.walking_s > 0 else None

    @property
    def false_reports_per_frame(self) -> float | None:
        return self.false_reports / self.frames_scored if self.frames_scored else None

    @property
    def recall(self) -> float | None:
        return self.recall_found / self.recall_eligible if self.recall_eligible else None

    @property
    def headline_recall(self) -> float | None:
        return self.headline_found / self.headline_eligible if self.headline_eligible else None

    @classmethod
    def merge(cls, scores: Sequence['SafetyScore']) -> 'SafetyScore':
        """The totals of several walks (events and obstacles listed together)."""
        out = cls(criteria=scores[0].criteria if scores else {})
        for s in scores:
            for k in ('on_path', 'warned', 'late', 'never', 'under_fault',
                      'warned_by_farther', 'cued_ahead',
                      'cued_at_entry',
                      'frames',
                      'frames_on_path', 'frames_on_path_clear', 'frames_on_path_fault',
                      'duration_s', 'walking_s', 'walking_fault_s', 'alarms_false',
                      'alarms_warning',
                      'frames_scored', 'frames_missing', 'reports', 'false_reports',
                      'recall_eligible', 'recall_found', 'headline_eligible',
                      'headline_found'):
                setattr(out, k, getattr(out, k) + getattr(s, k))
            out.false_alarm_events += s.false_alarm_events
            out.path_obstacles += s.path_obstacles
            out.bin_eligible = out.bin_eligible + s.bin_eligible
            out.bin_found = out.bin_found + s.bin_found
        return out

    def as_dict(self) -> dict:
        """JSON-ready dict (the `safety` key of summaries)."""
        with np.errstate(invalid='ignore', divide='ignore'):
            rb = np.where(self.bin_eligible > 0, self.bin_found / np.maximum(
                self.bin_eligible, 1), np.nan)
        return json_ready({
            'criteria': self.criteria,
            'warned_in_time': {'on_path': self.on_path, 'warned': self.warned,
                               'late': self.late, 'never': self.never,
                               'under_fault': self.under_fault,
                               'warned_by_farther': self.warned_by_farther,
                               'cued_ahead': self.cued_ahead,
                               'cued_at_entry': self.cued_at_entry,
                               'obstacles': self.path_obstacles},
            'frames': self.frames, 'duration_s': self.duration_s,
            'walking_s': self.walking_s,
            'walking_fault_s': self.walking_fault_s,
            'fault_share_walking': self.fault_share_walking,
            'frames_on_path': self.frames_on_path,
            'frames_on_path_clear': self.frames_on_path_clear,
            'frames_on_path_fault': self.frames_on_path_fault,
            'false_alarms': {'events': len(self.false_alarm_events),
                             'per_minute_walking': self.false_alarms_per_minute,
                             'false_alarm_messages': self.alarms_false,
                             'warning_messages': self.alarms_warning,
                             'event_list': self.false_alarm_events},
            'false_reports': {'total': self.false_reports, 'reports': self.reports,
                              'frames_scored': self.frames_scored,
                              'frames_missing': self.frames_missing,
                              'per_frame': self.false_reports_per_frame},
            'recall': {'eligible': self.recall_eligible, 'found': self.recall_found,
                       'recall': self.recall,
                       'headline_eligible': self.headline_eligible,
                       'headline_found': self.headline_found,
                       'headline_recall': self.headline_recall,
                       'height_edges_m': list(HEIGHT_BINS_M),
                       'range_edges_m': list(RANGE_BINS_M),
                       'bin_eligible': self.bin_eligible, 'bin_found': self.bin_found,
                       'bin_recall': rb},
        })


def walking_mask(truth: SafetyTruth, speed: float, window_s: float) -> tuple[np.ndarray,
                                                                                np.ndarray]:
    """(walking (F,) bool, frame interval (F,) s): a frame is walking when the point below
    the camera moved faster than ``speed`` m/s between the frames at the ends of a
    ``window_s`` window centred on it (clipped to the sequence); its interval is the time
    to the next frame (the median interval for the last)."""
    v, interval = walking_speed(truth, window_s)
    return v > speed, interval


def walking_speed(truth: SafetyTruth, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(speed (F,) m/s, frame interval (F,) s): the speed of the point below the camera
    between the frames at the ends of a ``window_s`` window centred on each frame
    (clipped to the sequence), and the time to the next frame (`walking_mask`)."""
    st = np.array([f.stamp_ns for f in truth.frames], np.int64)
    n = st.size
    if n < 2:
        return np.zeros(n), np.zeros(n)
    xy = np.array([f.foot for f in truth.frames])
    ts = (st - st[0]) / 1e9
    dt = np.diff(ts)
    interval = np.r_[dt, np.median(dt)]
    lo = np.searchsorted(ts, ts - window_s / 2.0, side='left')
    hi = np.clip(np.searchsorted(ts, ts + window_s / 2.0, side='right') - 1, 0, n - 1)
    span = ts[hi] - ts[lo]
    dist = np.hypot(*(xy[hi] - xy[lo]).T)
    with np.errstate(invalid='ignore', divide='ignore'):
        v = np.where(span > 0, dist / np.where(span > 0, span, 1.0), 0.0)
    return v, interval


def _report_tolerance(c: SafetyCriteria, rng: float) -> float:
    return max(c.report_tolerance_m, c.report_tolerance_frac * float(rng))


def _alarm_tolerance(c: SafetyCriteria, rng: float) -> float:
    return max(c.alarm_tolerance_m, c.alarm_tolerance_frac * float(rng))


def _matchable(ob: TrueObstacle, report_height: float) -> bool:
    """A drop is matched only by a report of negative height."""
    return not (ob.height < 0 and report_height >= 0)


def score_safety(truth: SafetyTruth, alarms: Sequence[dict],
                 reports: dict[int, FrameObstacles] | None = None,
                 criteria: SafetyCriteria | None = None) -> SafetyScore:
    """The safety score of one walk (see the module doc).

    Args:
        truth: the world's obstacles and the frames with their true poses.
        alarms: the alarms in announced order: dicts with ``stamp_ns`` (int ns),
            ``level`` (AlarmLevel value), ``obstacle_id``, ``range`` (m), ``bearing``
            (rad, positive left); the last three may be absent for FAULT and CLEAR.
        reports: stamp_ns -> obstacles reported for that frame (None: no reports to
            score; a frame absent from the dict counts as missing).
        criteria: the definitions' numbers (default `SafetyCriteria()`).
    Returns:
        SafetyScore.
    """
    c = criteria or SafetyCriteria()
    out = SafetyScore(criteria={k: getattr(c, k) for k in c.__dataclass_fields__})
    frames = truth.frames
    if not frames:
        return out
    stamps = [f.stamp_ns for f in frames]
    walking, interval = walking_mask(truth, c.walking_speed, c.walking_window_s)
    out.frames = len(frames)
    out.duration_s = float(interval.sum())
    out.walking_s = float(interval[walking].sum())
    in_force = alarm_in_force(stamps, alarms)
    levels = levels_in_force(in_force, alarms)
    out.walking_fault_s = float(interval[walking & (levels == AlarmLevel.FAULT)].sum())
    present = [truth.present(f) for f in frames]

    _score_warnings(c, truth, alarms, in_force, levels, stamps, present, out)
    _score_false_alarms(c, truth, alarms, stamps, present, out)

    # -- false reports and recall
    if reports is not None:
        for f, obs in zip(frames, present):
            det = reports.get(f.stamp_ns)
            if det is None:
                out.frames_missing += 1
                continue
            out.frames_scored += 1
            _score_reports(c, f, obs, det, out)
    return out


def _score_warnings(c: SafetyCriteria, truth: SafetyTruth, alarms: Sequence[dict],
                    in_force: np.ndarray, levels: np.ndarray, stamps: list[int],
                    present: list, out: SafetyScore) -> None:
    """Warned in time: per obstacle on the path, the alarm in force at its first pair on
    the path (warned, under FAULT, late or never; a warning: what it was about,
    `_warned_by`), the pairs on the path by level, and the cue's lead: the range in
    the corridor where CAUTION or higher was first in force over the walking speed then
    (infinite for a standing wearer); into ``out``. ``in_force``: (F,) the index into
    ``alarms`` of the alarm in force at each frame (`alarm_in_force`), ``levels`` its
    level (`levels_in_force`)."""
    frames = truth.frames
    speed, _ = walking_speed(truth, c.walking_window_s)
    track: dict[int, dict] = {}
    cued: dict[int, float] = {}                 # obstacle id -> lead of its first cue, s
    entry: dict[int, float] = {}                # id -> lead at its first pair in the corridor
    for k, (f, level, obs, v) in enumerate(zip(frames, levels, present, speed)):
        on = []
        for ob in obs:
            if abs(ob.height) < c.min_height:
                continue
            r = corridor_range(ob, f, c.corridor_half_width, c.corridor_length)
            lead = None if r is None else r / v if v > c.walking_speed else math.inf
            if lead is not None and ob.id not in entry:
                entry[ob.id] = lead
            if lead is not None and level in WARNING_LEVELS and ob.id not in cued:
                cued[ob.id] = lead
            if r is not None and r <= c.on_path_range:
                on.append((ob, r))
        if not on:
            continue
        out.frames_on_path += 1
        if level == AlarmLevel.FAULT:
            out.frames_on_path_fault += 1
        elif level not in WARNING_LEVELS:
            out.frames_on_path_clear += 1
        for ob, r in on:
            o = track.get(ob.id)
            if o is None:
                o = track[ob.id] = dict(id=ob.id, height_m=ob.height, kind=ob.kind,
                                        first_t_s=(f.stamp_ns - stamps[0]) / 1e9,
                                        first_range_m=r, first_level=int(level),
                                        warned_later_at_m=None, nearest_m=r,
                                        warned_by=None)
                if level in WARNING_LEVELS and in_force[k] >= 0:
                    o['warned_by'] = _warned_by(c, truth, alarms[in_force[k]], ob, f)
            o['nearest_m'] = min(o['nearest_m'], r)
            if (o['first_level'] not in WARNING_LEVELS and o['warned_later_at_m'] is None
                    and level in WARNING_LEVELS):
                o['warned_later_at_m'] = r
    for o in track.values():
        lead = cued.get(o['id'])
        # (None: never cued in the corridor; cued while the wearer stood: no contact time)
        o['cue_lead_s'] = float(lead) if lead is not None and math.isfinite(lead) else None
        o['cued_standing'] = bool(lead == math.inf)
        # the most any cue in the corridor could lead by: from the pair it came into it
        most = entry.get(o['id'])
        o['corridor_lead_s'] = float(most) if most is not None and math.isfinite(most) else None
        out.cued_ahead += int(lead is not None and lead >= c.cue_lead_s)
        out.cued_at_entry += int(lead is not None and lead < c.cue_lead_s
                                 and lead >= most - c.entry_slack_s)
        if o['first_level'] in WARNING_LEVELS:
            o['outcome'] = 'warned'
            out.warned_by_farther += int(o['warned_by'] == 'farther')
        elif o['first_level'] == AlarmLevel.FAULT:
            o['outcome'] = 'under_fault'
        elif o['warned_later_at_m'] is not None:
            o['outcome'] = 'late'
        else:
            o['outcome'] = 'never'
        setattr(out, o['outcome'], getattr(out, o['outcome']) + 1)
    out.on_path = len(track)
    out.path_obstacles = [track[k] for k in sorted(track)]


def _warned_by(c: SafetyCriteria, truth: SafetyTruth, alarm: dict, ob: TrueObstacle,
               frame: TruthFrame) -> str:
    """What ``alarm`` (a CAUTION, WARNING or STOP in force at ``frame``, ``ob``'s first
    pair on the path) was about: put on the ground with the true pose of its stamp
    (``frame``'s when the stamp lies outside the walk: a node's own clock), 'itself' when
    within the false alarm tolerance of ``ob``'s footprint (as present at ``frame``), else
    'nearer' when nearer to the point below the camera at ``frame`` than that footprint,
    else 'farther'."""
    t = int(alarm['stamp_ns'])
    inside = truth.frames[0].stamp_ns <= t <= truth.frames[-1].stamp_ns
    f = truth.frame_at(t) if inside else frame
    rng, brg = float(alarm.get('range', 0.0)), float(alarm.get('bearing', 0.0))
    q = f.to_world(np.array([rng]), np.array([brg]))[0]
    if footprint_distance(ob, q) <= _alarm_tolerance(c, rng):
        return 'itself'
    here = frame.foot
    return ('nearer' if float(np.hypot(*(q - here))) < footprint_distance(ob, here)
            else 'farther')


def _score_false_alarms(c: SafetyCriteria, truth: SafetyTruth, alarms: Sequence[dict],
                        stamps: list[int], present: list, out: SafetyScore) -> None:
    """False alarms: CAUTION/WARNING/STOP placed on the ground farther than the tolerance
    from every obstacle present; an event where such an alarm starts; into ``out``."""
    index = {s: i for i, s in enumerate(stamps)}
    prev = None
    for a in alarms:
        level = int(a['level'])
        key = (level, int(a.get('obstacle_id', 0)))
        if level in WARNING_LEVELS:
            out.alarms_warning += 1
            f = truth.frame_at(int(a['stamp_ns']))
            i = index[f.stamp_ns]
            rng, brg = float(a.get('range', 0.0)), float(a.get('bearing', 0.0))
            q = f.to_world(np.array([rng]), np.array([brg]))[0]
            near = min((footprint_distance(ob, q) for ob in present[i]), default=math.inf)
            if near > _alarm_tolerance(c, rng):
                out.alarms_false += 1
                if key != prev:
                    out.false_alarm_events.append(dict(
                        t_s=(int(a['stamp_ns']) - stamps[0]) / 1e9, level=level,
                        level_name=AlarmLevel(level).name, obstacle_id=key[1],
                        range_m=rng, bearing_deg=math.degrees(brg),
                        nearest_true_m=near if math.isfinite(near) else None))
        prev = key


def obstacle_reports(det: FrameObstacles) -> FrameObstacles:
    """The frame's reports without its unknown-ahead entries (height NaN: ground that
    cannot be seen, `core.unseen_ground`), which report no obstacle."""
    keep = ~np.isnan(np.asarray(det.height, float))
    if keep.all():
        return det
    return dataclasses.replace(
        det, ids=det.ids[keep], position=det.position[keep], height=det.height[keep],
        range=det.range[keep], bearing=det.bearing[keep], roi=det.roi[keep],
        confidence=None if det.confidence is None else det.confidence[keep])


def _score_reports(c: SafetyCriteria, f: TruthFrame, obs: list[TrueObstacle],
                   det: FrameObstacles, out: SafetyScore) -> None:
    """False reports and recall of one frame, added to ``out``."""
    det = obstacle_reports(det)
    n = len(det)
    pts = f.to_world(det.range, det.bearing) if n else np.zeros((0, 2))
    tol = np.array([_report_tolerance(c, r) for r in det.range]) if n else np.zeros(0)
    dist = np.array([[footprint_distance(ob, pts[j]) if _matchable(ob, det.height[j])
                      else math.inf for j in range(n)] for ob in obs]).reshape(len(obs), n)
    ok = dist <= tol[None, :]
    out.reports += n
    out.false_reports += int((~ok.any(axis=0)).sum()) if n else 0
    # recall: obstacles in view with enough pixels, one-to-one, nearest pair first
    elig = [i for i, ob in enumerate(obs) if ob.id in f.visible
            and (f.visible[ob.id] is None or f.visible[ob.id] >= c.recall_min_pixels)]
    found = set()
    if elig and n:
        pairs = sorted((dist[i, j], i, j) for i in elig for j in range(n) if ok[i, j])
        used_i, used_j = set(), set()
        for _, i, j in pairs:
            if i in used_i or j in used_j:
                continue
            used_i.add(i)
            used_j.add(j)
            found.add(i)
    for i in elig:
        ob = obs[i]
        r = footprint_range(ob, f)
        hit = i in found
        out.recall_eligible += 1
        out.recall_found += int(hit)
        if abs(ob.height) >= c.min_height and r <= c.corridor_length:
            out.headline_eligible += 1
            out.headline_found += int(hit)
        hb = int(np.digitize(abs(ob.height) + 1e-6, HEIGHT_BINS_M)) - 1
        rb = int(np.digitize(r, RANGE_BINS_M)) - 1
        if 0 <= hb < out.bin_eligible.shape[0] and 0 <= rb < out.bin_eligible.shape[1]:
            out.bin_eligible[hb, rb] += 1
            out.bin_found[hb, rb] += int(hit)


def footprint_range(ob: TrueObstacle, frame: TruthFrame) -> float:
    """Distance (m) from the point below the camera to the obstacle's footprint."""
    return footprint_distance(ob, frame.foot)


def format_safety(s: dict, indent: str = '') -> list[str]:
    """Printed lines of a `SafetyScore.as_dict()`."""
    w, fa, fr, rc = s['warned_in_time'], s['false_alarms'], s['false_reports'], s['recall']
    pm = fa['per_minute_walking']
    lines = [
        f"warned in time: {w['warned']}/{w['on_path']} obstacles on the path (late "
        f"{w['late']}, never {w['never']}, under FAULT {w['under_fault']}); frames on the "
        f"path {s['frames_on_path']}, CLEAR in force in {s['frames_on_path_clear']}, FAULT in "
        f"{s['frames_on_path_fault']}"
        + (f"; warned by an alarm about something farther off (the obstacle unseen) "
           f"{w['warned_by_farther']}/{w['warned']}" if 'warned_by_farther' in w else '')
        + (f"; cued at least {s['criteria']['cue_lead_s']:g} s before contact "
           f"{w['cued_ahead']}/{w['on_path']}" if 'cued_ahead' in w else '')
        + (f" (and {w['cued_at_entry']} that came into the corridor later, cued as they "
           f"came)" if w.get('cued_at_entry') else ''),
        f"false alarm events: {fa['events']} in {s['walking_s'] / 60:.2f} min of walking = "
        + (f'{pm:.2f} per minute' if pm is not None else '- per minute')
        + f" ({fa['false_alarm_messages']} of {fa['warning_messages']} CAUTION/WARNING/STOP "
        'messages false)',
        f"false reports: {fr['total']} of {fr['reports']} in {fr['frames_scored']} frames = "
        + (f"{fr['per_frame']:.3f} per frame" if fr['per_frame'] is not None else '-')
        + (f" ({fr['frames_missing']} frames missing)" if fr['frames_missing'] else ''),
        'recall: ' + (f"{rc['found']}/{rc['eligible']} = {rc['recall']:.1%}"
                      if rc['eligible'] else 'nothing in view')
        + (f"; >= {s['criteria']['min_height'] * 100:g} cm within "
           f"{s['criteria']['corridor_length']:g} m: {rc['headline_found']}/"
           f"{rc['headline_eligible']} = {rc['headline_recall']:.1%}"
           if rc['headline_eligible'] else '')]
    return [indent + ln for ln in lines + format_events(s)]


def format_events(s: dict) -> list[str]:
    """Printed lines, indented by two spaces, of what lies behind a `SafetyScore.as_dict()`'s
    numbers: its false alarm events (the first 20) and its obstacles on the path not warned
    in time."""
    w, fa = s['warned_in_time'], s['false_alarms']
    lines = []
    for e in fa['event_list'][:20]:
        near = (f"{e['nearest_true_m']:.1f} m" if e['nearest_true_m'] is not None
                else 'no obstacle')
        lines.append(f"  false {e['level_name']:<8s} at {e['t_s']:6.1f} s: range "
                     f"{e['range_m']:.1f} m, bearing {e['bearing_deg']:+.0f} deg, nearest "
                     f"true obstacle {near}")
    if len(fa['event_list']) > 20:
        lines.append(f"  ... {len(fa['event_list']) - 20} more")
    for o in w['obstacles']:
        if o['outcome'] != 'warned':
            what = o['outcome'].replace('_', ' ')
        elif o.get('warned_by') == 'farther':
            what = 'warned by an alarm about something farther off'
        else:
            continue
        lines.append(f"  obstacle {o['id']} ({o['kind'] or 'obstacle'}, "
                     f"{o['height_m'] * 100:.0f} cm): {what}, "
                     f"on the path at {o['first_t_s']:.1f} s from {o['first_range_m']:.1f} m")
    return lines
