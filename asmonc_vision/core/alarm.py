"""What to tell the wearer: obstacle lists in, spoken alarms out (no ROS here).

The alarm logic turns the detector's obstacles (one list per stereo pair) into a small
number of plain-speech announcements for a blind pedestrian:

* **Levels** (same numbers as ``asmonc_vision_msgs/Alarm``): CLEAR 0, CAUTION 1,
  WARNING 2, STOP 3, FAULT 4. FAULT means "the system cannot see: do not trust
  silence" and outranks every other level.
* **Walking corridor**: only obstacles with ``|range * sin(bearing)| <= corridor_half_width``,
  ``range * cos(bearing) >= 0`` and ``range <= max_range`` count, and only if
  ``|height| >= min_height`` (a drop, negative height, counts by its depth) and
  ``confidence >= min_confidence``. The nearest such obstacle is the *target*.
* **Level from the target's range** r: STOP if r <= stop_range, WARNING if
  r <= warning_range, CAUTION if r <= caution_range, else CLEAR.
* **Going up is immediate** (a nearer obstacle is announced on the first frame that
  shows it). **Going down is slow**: to keep a level it already holds, the range may
  exceed that level's threshold by ``hysteresis`` metres, and a lower level must then
  persist for ``hold_time`` seconds before the alarm steps down. While the ground plane
  is LOST (but not yet for ``timeout``) the alarm never steps down: an empty obstacle
  list then is not evidence that the path is clear; the time the lower level has
  persisted stops counting then, and goes on once the ground is back.
* **Announcements** (``Decision``) are made when the level changes, when the target
  changes (a different non-zero track id, at most once per ``hold_time``), and every
  ``repeat_period`` seconds while the level is not CLEAR. A repeat describes the target
  as last seen: the current one, or, when a frame shows none (the ground LOST as the
  wearer walks up to a wall, or a held level), the last one seen since the level was
  announced if it is the one announced (never an older range than the newest measured)
  or was seen within ``hold_time``, where it is now (moved by the distance walked since
  it was seen, while the wearer moves); else, or when it has been walked past, it
  repeats the announcement (another target seen once since, longer ago, is no news: a
  passer-by glimpsed nearer has moved on).
* **Faults**: no obstacle list for longer than ``timeout`` seconds (measured on the
  caller's clock, the time messages *arrive*), or the ground plane LOST for longer than
  ``timeout`` (but see *a hazard walked up to*, below), or INITIALISING for longer than
  ``startup_grace``, gives FAULT, repeated every ``repeat_period``. At start, and when
  the detector (re)initialises its ground plane, FAULT "starting up, hold still" is
  announced once. When data return, the real level is announced at once (CLEAR as "all
  clear") -- after a gap in the obstacle lists, only once a ground status has come
  after it (a detector that died and was restarted has no ground plane yet; the status
  from before the gap is stale). A gap that ended before the periodic check said FAULT
  is not announced: the level is held until that status comes, and FAULT follows if it
  has not come within ``timeout``.

* **A hazard walked up to while the ground is LOST** (``lost_hold``): the ground plane
  is often lost just as the wearer reaches a hazard already announced. A level camera
  on the chest sees no ground nearer than about 2.5 m, so 2.5 m before a step down its
  whole view is the lower ground; a wall walked up to fills the view. The hazard has not
  gone: once the ground has been LOST for ``timeout`` (before that the level is held,
  as above), the obstacle or drop announced at CAUTION or higher, last seen at most
  ``lost_hold`` seconds ago, is carried by the distance walked since (at the walking
  speed, along the walking direction, as a repeat describes it) and, while it still lies
  ahead, keeps its level, which rises as it comes nearer (the levels by range
  and time to contact of where it now is), in place of FAULT "cannot see the ground".
  FAULT follows once it has been walked past or was seen ``lost_hold`` ago. Obstacle
  lists that stop, a start and a ground still initialising are FAULT as before.

* **Unknown ahead**: an entry of the obstacle list whose height is NaN is no obstacle
  but ground the detector cannot see from its range on (`core.unseen_ground`: a plain
  face hides it, or a surface whose edges do not match). In the corridor (as an obstacle,
  its height aside), it is said as such: FAULT "cannot see the way ahead, N metres, walk
  with care" (``fault`` 'unknown_ahead'; the Alarm's range and bearing are its), in place
  of "all clear" and never as an obstacle's level. An obstacle's level (CAUTION or
  higher) outranks it and is announced at once; it is repeated every ``repeat_period``
  (not while the wearer stands), and once it is gone, "all clear" waits ``hold_time``.

* **Time to contact** (when the wearer's motion is given; without it the levels are by
  range only, as above). ``walk_motion`` gives the walking speed (m/s, smoothed, e.g.
  ``WalkingSpeed`` over ``/egomotion``) and heading (the walking direction from the
  camera's axis, radians, positive left); ``gait`` the walk model's walking/standing
  verdict. While the wearer *moves* (the gait says walking, or no gait is known, and the
  speed is at least ``min_walking_speed``), a second corridor is laid along the walking
  direction (an obstacle's bearing is taken from it; an alarm's bearing is still the
  cameras', as on /obstacles): an obstacle in either counts (the walking direction is
  measured with a few degrees' noise, and a wearer may step where they face); each
  obstacle's time to contact
  is its distance along that direction over the speed; its level is the higher of the
  level by range (the floor that also holds for a standing wearer) and the level by time
  to contact (STOP <= ``stop_time``, WARNING <= ``warning_time``, the lead time,
  CAUTION <= ``caution_time``; a held level is kept up to its time plus
  ``time_hysteresis``). Priority: the obstacles at the highest level compete; a drop
  comes first, then the least time to contact (the nearest for a standing wearer).
* **A standing wearer is not told again and again**: while the wearer stands, the
  periodic repeat of an unchanged level about the same target is left out
  (``repeat_when_standing``); any change of level or target is still announced.

All times are seconds on one monotonic clock chosen by the caller (the node uses the
steady clock), passed in as ``t``, so the logic is deterministic under test.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Iterable, Sequence

from asmonc_vision.core.alarm_settings import AlarmConfig  # noqa: F401 (its settings, here too)


class AlarmLevel(enum.IntEnum):
    """Alarm levels; the values equal the constants of asmonc_vision_msgs/Alarm."""

    CLEAR = 0
    CAUTION = 1
    WARNING = 2
    STOP = 3
    FAULT = 4


class GroundStatus(enum.IntEnum):
    """Ground-plane status; the values equal the constants of asmonc_vision_msgs/GroundPlane."""

    INITIALISING = 0
    TRACKING = 1
    LOST = 2


#: Plain-speech texts of the faults (FAULT level).
#: period of the alarm node's timeout check (`AlarmLogic.check_timeout`), seconds: with
#: the default timeout (0.4 s) a FAULT is decided at most 0.45 s after the last list
CHECK_PERIOD_S = 0.05
#: `AlarmLogic._fault_reason`'s answer while the level is held unannounced
_HELD = 'held'
TEXT_STARTING = 'starting up, hold still'
TEXT_NO_DATA = 'fault, obstacle detection has stopped, walk with care'
TEXT_NOT_STARTED = 'fault, obstacle detection has not started, walk with care'
TEXT_GROUND_LOST = 'fault, cannot see the ground, walk with care'
TEXT_CLEAR = 'all clear'


def unknown_text(r: float) -> str:
    """The spoken text for ground unknown from r metres ahead."""
    return f'cannot see the way ahead, {range_words(r)}, walk with care'


@dataclass(frozen=True)
class ObstacleInfo:
    """One obstacle as the alarm needs it (from asmonc_vision_msgs/Obstacle).

    Attributes:
        id: track id, 0 if untracked.
        range: metres along the ground from the point below the cameras to the foot.
        bearing: radians in the ground plane from the walking direction, positive left.
        height: metres above the ground; negative for a drop (step down, kerb, hole).
        confidence: 0..1.
    """

    id: int
    range: float
    bearing: float
    height: float
    confidence: float = 1.0

    @property
    def lateral(self) -> float:
        """Offset from the walking line, metres, positive to the left."""
        return self.range * math.sin(self.bearing)

    @property
    def forward(self) -> float:
        """Distance along the walking direction, metres."""
        return self.range * math.cos(self.bearing)

    @property
    def is_drop(self) -> bool:
        return self.height < 0.0

    @property
    def is_unknown(self) -> bool:
        """Ground unknown from this range on (height NaN), not an obstacle."""
        return math.isnan(self.height)


@dataclass(frozen=True)
class Decision:
    """An announcement: publish it as an Alarm and speak its text.

    Attributes:
        level: the alarm level.
        text: plain speech for the wearer.
        obstacle_id: the target's track id (0 if none or untracked).
        range: the target's range, metres (0 if none).
        bearing: the target's bearing from the cameras' axis laid on the ground (as on
            /obstacles), radians, positive left (0 if none); the text speaks from the
            walking direction.
        t: the caller's time of the decision, seconds.
        repeat: True when this re-announces an unchanged state.
        time_to_contact: the target's time to contact at the walking speed, seconds
            (inf when the wearer stands or the motion is unknown, or no target).
    """

    level: AlarmLevel
    text: str
    obstacle_id: int = 0
    range: float = 0.0
    bearing: float = 0.0
    t: float = 0.0
    repeat: bool = False
    time_to_contact: float = math.inf


# --- wording -------------------------------------------------------------------------

def range_words(r: float) -> str:
    """A range in metres as spoken: rounded to 0.5 m, at least "half a metre".

    >>> range_words(1.1), range_words(2.3), range_words(0.2), range_words(1.6)
    ('1 metre', '2.5 metres', 'half a metre', '1.5 metres')
    """
    half = max(1, int(math.floor(max(r, 0.0) * 2.0 + 0.5)))  # in half metres
    if half == 1:
        return 'half a metre'
    if half == 2:
        return '1 metre'
    value = half / 2.0
    return f'{value:g} metres'


def direction_words(bearing: float, ahead_deg: float = 10.0, side_deg: float = 30.0) -> str:
    """A bearing (radians, positive left) as "ahead", "slightly left", "left", ..."""
    deg = math.degrees(bearing)
    if abs(deg) <= ahead_deg:
        return 'ahead'
    side = 'left' if deg > 0 else 'right'
    return f'slightly {side}' if abs(deg) <= side_deg else side


def obstacle_text(level: AlarmLevel, ob: ObstacleInfo, ahead_deg: float = 10.0,
                  side_deg: float = 30.0) -> str:
    """The spoken text for an obstacle alarm.

    Examples: "stop, obstacle, 1 metre, ahead"; "obstacle, 2 metres, slightly left";
    "drop ahead, 3 metres"; "stop, drop slightly right, 1 metre".
    """
    where = direction_words(ob.bearing, ahead_deg, side_deg)
    dist = range_words(ob.range)
    body = f'drop {where}, {dist}' if ob.is_drop else f'obstacle, {dist}, {where}'
    return f'stop, {body}' if level == AlarmLevel.STOP else body


@dataclass(frozen=True)
class Contact:
    """The most urgent obstacle of the latest obstacle list (what a sound cue tracks).

    Attributes:
        t: the caller's time of the list, seconds.
        level: the level that obstacle alone calls for (CLEAR with no target).
        target: the obstacle, its bearing taken from the walking direction; None if none.
        time_to_contact: seconds at the walking speed; inf while standing or unknown.
        moving: whether the wearer was taken to be walking.
        heading: the walking frame's direction from the cameras' axis (radians,
            positive left; 0 while not walking): the target's bearing from the cameras'
            axis is its bearing plus this.
    """

    t: float
    level: AlarmLevel
    target: ObstacleInfo | None
    time_to_contact: float
    moving: bool
    heading: float = 0.0


# --- the logic -----------------------------------------------------------------------

class AlarmLogic:
    """The alarm state machine. Not thread-safe: call it from one thread (or lock).

    Feed it with ``update`` (each obstacle list), ``ground_status`` (each ground-plane
    status) and ``check_timeout`` (periodically, e.g. at 10 Hz). Each returns a
    ``Decision`` to announce, or None. ``current`` is the state last announced.
    """

    def __init__(self, config: AlarmConfig | None = None, t0: float = 0.0):
        """Start in FAULT "starting up, hold still" at time t0 (seconds)."""
        self._cfg = config or AlarmConfig()
        self._t0 = float(t0)
        self._last_obstacles_t: float | None = None
        self._first_obstacles_t: float | None = None
        self._ground: GroundStatus | None = None
        self._ground_since = float(t0)
        #: False from obstacle lists resuming after a gap until the next ground status
        self._ground_fresh = True
        #: arrival time of the first list after the newest such gap
        self._stale_since = -math.inf
        #: arrival time of the newest ground status
        self._ground_t = -math.inf
        self._fault: str | None = 'starting'
        self._below_since: float | None = None
        #: seconds since the previous obstacle list (0 for the first)
        self._list_dt = 0.0
        self._current = Decision(AlarmLevel.FAULT, TEXT_STARTING, t=float(t0))
        self._last_announce_t = float(t0)
        #: the newest target seen while the current (obstacle) level holds, and when
        self._last_target: ObstacleInfo | None = None
        self._last_target_t = -math.inf
        self._speed: float | None = None       # m/s, smoothed, from walk_motion
        self._heading = 0.0                    # rad from the camera's axis, positive left
        self._speed_t: float | None = None
        self._walking: bool | None = None      # the walk model's verdict
        self._gait_t: float | None = None
        self._contact = Contact(float(t0), AlarmLevel.CLEAR, None, math.inf, False)

    # -- accessors
    @property
    def config(self) -> AlarmConfig:
        return self._cfg

    @property
    def current(self) -> Decision:
        """The decision last announced (the initial FAULT before any other)."""
        return self._current

    @property
    def fault(self) -> str | None:
        """None, or why the level is FAULT: 'starting', 'not_started' (no obstacle list
        within ``startup_grace``), 'no_data' (none for ``timeout``), 'ground_lost' or
        'unknown_ahead' (ground ahead that cannot be seen)."""
        return self._fault if self._current.level == AlarmLevel.FAULT else None

    def set_config(self, config: AlarmConfig) -> None:
        """Change the settings, keeping the state (used by parameter updates)."""
        self._cfg = config

    @property
    def contact(self) -> Contact:
        """The most urgent obstacle of the latest obstacle list (see ``Contact``)."""
        return self._contact

    # -- the wearer's motion
    def walk_motion(self, t: float, speed: float, heading: float = 0.0) -> None:
        """The wearer's smoothed walking speed (m/s) and direction (radians from the
        camera's axis, positive left) at time t (s), e.g. from ``WalkingSpeed``."""
        if math.isfinite(speed) and math.isfinite(heading):
            self._speed, self._heading = max(0.0, float(speed)), float(heading)
            self._speed_t = float(t)

    def gait(self, t: float, walking: bool) -> None:
        """The walk model's walking/standing verdict at time t (s)."""
        self._walking, self._gait_t = bool(walking), float(t)

    def _fresh(self, t_in: float | None, t: float) -> bool:
        return t_in is not None and math.isfinite(t) and t - t_in <= self._cfg.motion_timeout

    def moving(self, t: float) -> bool:
        """The wearer is known to walk: a fresh speed of at least ``min_walking_speed``
        and no fresh gait verdict of standing."""
        if self._fresh(self._gait_t, t) and not self._walking:
            return False
        return (self._fresh(self._speed_t, t) and self._speed is not None
                and self._speed >= max(self._cfg.min_walking_speed, 1e-6))

    def standing(self, t: float) -> bool:
        """The wearer is known to stand: the walk model says so, or a fresh speed is
        below ``min_walking_speed``. (Unknown motion is neither moving nor standing.)"""
        if self._fresh(self._gait_t, t) and not self._walking:
            return True
        return (self._fresh(self._speed_t, t) and self._speed is not None
                and self._speed < self._cfg.min_walking_speed)

    def walking_frame(self, t: float, obstacles: Iterable[ObstacleInfo]) -> list[ObstacleInfo]:
        """The obstacles with their bearings taken from the walking direction (while the
        wearer moves and ``follow_walking_direction``), else unchanged."""
        obstacles = list(obstacles)
        h = self.walking_heading(t)
        if h == 0.0:
            return obstacles
        return [dataclasses.replace(o, bearing=math.remainder(o.bearing - h, math.tau))
                for o in obstacles]

    def walking_heading(self, t: float) -> float:
        """The walking frame's direction from the camera's axis (radians, positive left)
        that `walking_frame` takes the bearings from: the walking direction, clipped to
        ``max_heading_deg``, while the wearer moves and ``follow_walking_direction``;
        else 0."""
        if not (self._cfg.follow_walking_direction and self.moving(t)):
            return 0.0
        lim = math.radians(self._cfg.max_heading_deg)
        return min(max(self._heading, -lim), lim)

    def walked(self, t: float, ob: ObstacleInfo, seen_t: float) -> ObstacleInfo:
        """An obstacle seen at time ``seen_t`` (in the walking frame), where it is from
        the wearer at time ``t`` while the wearer moves: its distance along the walking
        direction less the distance walked since at the walking speed (unchanged while
        standing or the motion is unknown)."""
        if not self.moving(t) or self._speed is None:
            return ob
        fwd = ob.forward - self._speed * max(t - seen_t, 0.0)
        lat = ob.lateral
        return dataclasses.replace(ob, range=math.hypot(fwd, lat),
                                   bearing=math.atan2(lat, fwd))

    def time_to_contact(self, t: float, ob: ObstacleInfo | None) -> float:
        """Seconds until the wearer reaches ob at the walking speed (its distance along
        the walking direction over the speed); inf while standing or unknown."""
        if ob is None or not self.moving(t) or self._speed is None:
            return math.inf
        return max(ob.forward, 0.0) / self._speed

    def level_for_time(self, ttc: float, held: AlarmLevel = AlarmLevel.CLEAR) -> AlarmLevel:
        """Level for a time to contact (s), given the level held (see ``level_for``)."""
        c = self._cfg
        held = AlarmLevel.CLEAR if held == AlarmLevel.FAULT else held
        for level, threshold in ((AlarmLevel.STOP, c.stop_time),
                                 (AlarmLevel.WARNING, c.warning_time),
                                 (AlarmLevel.CAUTION, c.caution_time)):
            margin = c.time_hysteresis if held >= level else 0.0
            if ttc <= threshold + margin:
                return level
        return AlarmLevel.CLEAR

    def obstacle_level(self, t: float, ob: ObstacleInfo | None,
                       held: AlarmLevel = AlarmLevel.CLEAR) -> AlarmLevel:
        """The level one obstacle calls for: by range (the floor), raised by its time to
        contact while the wearer moves."""
        if ob is None:
            return AlarmLevel.CLEAR
        return max(self.level_for(ob.range, held),
                   self.level_for_time(self.time_to_contact(t, ob), held))

    def select(self, t: float, obstacles: Iterable[ObstacleInfo],
               held: AlarmLevel = AlarmLevel.CLEAR) -> tuple[ObstacleInfo | None, AlarmLevel]:
        """The target and its level among obstacles already in the walking frame: those
        at the highest level compete, a drop first, then the least time to contact, then
        the nearest."""
        margin = self._cfg.hysteresis if held not in (AlarmLevel.CLEAR, AlarmLevel.FAULT) else 0.0
        best, best_key = None, None
        for ob in obstacles:
            if not self.in_path(t, ob, margin):
                continue
            level = self.obstacle_level(t, ob, held)
            key = (-int(level), not ob.is_drop, self.time_to_contact(t, ob), ob.range)
            if best_key is None or key < best_key:
                best, best_key = ob, key
        return best, (AlarmLevel(-best_key[0]) if best_key is not None else AlarmLevel.CLEAR)

    def last_obstacles_age(self, t: float) -> float | None:
        """Seconds since the last obstacle list, None if none yet."""
        return None if self._last_obstacles_t is None else t - self._last_obstacles_t

    # -- selection
    def in_path(self, t: float, ob: ObstacleInfo, margin: float = 0.0) -> bool:
        """Whether an obstacle (in the walking frame) counts (``in_corridor``) in the
        corridor along the walking direction or in the one along the cameras' axis: the
        walking direction is measured from the egomotion with a few degrees' noise, and
        a wearer may step where they face; an obstacle in either is on the path."""
        h = self.walking_heading(t)
        return self.in_corridor(ob, margin) or (
            h != 0.0 and self.in_corridor(dataclasses.replace(ob, bearing=ob.bearing + h),
                                          margin))

    def in_corridor(self, ob: ObstacleInfo, margin: float = 0.0) -> bool:
        """Whether an obstacle counts: in the corridor, near enough, high/deep enough,
        confident enough. ``margin`` (m) extends max_range (hysteresis)."""
        c = self._cfg
        return (math.isfinite(ob.range) and math.isfinite(ob.bearing)
                and math.isfinite(ob.height) and ob.range >= 0.0
                and abs(ob.lateral) <= c.corridor_half_width
                and ob.forward >= 0.0
                and ob.range <= c.max_range + margin
                and abs(ob.height) >= c.min_height
                and ob.confidence >= c.min_confidence)

    def unknown_ahead(self, unknown: Iterable[ObstacleInfo]) -> ObstacleInfo | None:
        """The nearest unknown-ahead entry (already in the walking frame) that counts as
        an obstacle would (``in_corridor``, its height aside), or None."""
        c = self._cfg
        ok = [u for u in unknown
              if self.in_corridor(dataclasses.replace(u, height=max(c.min_height, 1.0)))]
        return min(ok, key=lambda u: u.range, default=None)

    def target(self, obstacles: Iterable[ObstacleInfo]) -> ObstacleInfo | None:
        """The obstacle that counts (see ``in_corridor``) and calls for the highest level
        (a drop first, then the nearest), judged by range only; or None."""
        return self.select(-math.inf, obstacles, self._current.level)[0]

    def level_for(self, r: float | None, held: AlarmLevel = AlarmLevel.CLEAR) -> AlarmLevel:
        """Level for a target at range r (m; None for no target), given the level held.

        A level at or below ``held`` (FAULT counts as none) is kept up to its threshold
        plus the hysteresis.
        """
        if r is None:
            return AlarmLevel.CLEAR
        c = self._cfg
        held = AlarmLevel.CLEAR if held == AlarmLevel.FAULT else held
        for level, threshold in ((AlarmLevel.STOP, c.stop_range),
                                 (AlarmLevel.WARNING, c.warning_range),
                                 (AlarmLevel.CAUTION, c.caution_range)):
            margin = c.hysteresis if held >= level else 0.0
            if r <= threshold + margin:
                return level
        return AlarmLevel.CLEAR

    # -- inputs
    def update(self, t: float, obstacles: Sequence[ObstacleInfo]) -> Decision | None:
        """A new obstacle list arrived at time t (s). Returns an announcement or None."""
        t = float(t)
        last, timeout = self._last_obstacles_t, self._cfg.timeout
        if last is not None and t - last > timeout and self._ground_t <= last + timeout:
            # Lists are back after a gap: the detector stalled, or died and restarted
            # without its ground plane. The ground status from before the gap (which
            # may arrive just after its frame's list) is stale: no level is announced
            # until one has come after the silence reached the timeout.
            self._ground_fresh = False
            self._stale_since = t
        self._list_dt = t - last if last is not None else 0.0
        self._last_obstacles_t = t
        if self._first_obstacles_t is None:
            self._first_obstacles_t = t
        fault = self._fault_reason(t)
        if fault == _HELD:
            return None
        if fault is not None:
            return self._announce_fault(t, fault)

        cur = self._current
        obstacles = self.walking_frame(t, obstacles)
        unknown = self.unknown_ahead(o for o in obstacles if o.is_unknown)
        obstacles = [o for o in obstacles if not o.is_unknown]
        if cur.level == AlarmLevel.FAULT and self._fault == 'unknown_ahead':
            return self._from_unknown(t, obstacles, unknown)
        if cur.level == AlarmLevel.FAULT:
            # Data are back: announce the real level at once, without memory -- but
            # with the ground LOST an empty path is no evidence: "all clear" waits.
            tgt, level = self.select(t, obstacles)
            self._set_contact(t, tgt, level)
            if tgt is not None:
                self._remember(t, tgt)
            self._below_since = None
            if level == AlarmLevel.CLEAR and self._ground == GroundStatus.LOST:
                return None
            if level == AlarmLevel.CLEAR and unknown is not None:
                return self._announce_unknown(t, unknown)
            return self._announce(self._decide(t, level, tgt))

        tgt, level = self.select(t, obstacles, cur.level)
        seen = tgt is not None
        held = None if seen else self._held_through_lost(t)
        if held is not None:         # (not remembered: it was not seen in this list)
            tgt, level = held, self.obstacle_level(t, held, cur.level)
        self._set_contact(t, tgt, level)
        if seen:
            self._remember(t, tgt)
        if level > cur.level:
            self._below_since = None
            return self._announce(self._decide(t, level, tgt))
        if held is not None:
            # the ground LOST: no evidence either way; the hazard carried by the walk
            self._pause_below()
            return self._maybe_repeat(t, tgt)
        if level < cur.level:
            if self._ground == GroundStatus.LOST:
                self._pause_below()       # no evidence the path is clear: hold
            else:
                if self._below_since is None:
                    self._below_since = t
                if t - self._below_since >= self._cfg.hold_time:
                    self._below_since = None
                    if level == AlarmLevel.CLEAR and unknown is not None:
                        return self._announce_unknown(t, unknown)
                    return self._announce(self._decide(t, level, tgt))
            # Held at the current level: describe the nearest target if there is one.
            return self._maybe_repeat(t, tgt)
        self._below_since = None
        if level == AlarmLevel.CLEAR and unknown is not None:
            return self._announce_unknown(t, unknown)
        if (tgt is not None and level != AlarmLevel.CLEAR and tgt.id != 0
                and cur.obstacle_id != 0 and tgt.id != cur.obstacle_id
                and t - self._last_announce_t >= self._cfg.hold_time):
            return self._announce(self._decide(t, level, tgt))
        return self._maybe_repeat(t, tgt)

    def ground_status(self, t: float, status: int) -> Decision | None:
        """The detector's ground-plane status (GroundStatus value) at time t (s).

        INITIALISING: FAULT "starting up, hold still", said once on entering it (obstacle
        lists then do not lower the level; after ``startup_grace`` it becomes FAULT
        "cannot see the ground", repeated). LOST: the level is held (never lowered); after
        ``timeout`` s FAULT "cannot see the ground". TRACKING: the next obstacle list
        recovers from such a FAULT.
        """
        t = float(t)
        status = GroundStatus(int(status))
        self._ground_fresh = True
        self._ground_t = t
        if status != self._ground:
            self._ground = status
            self._ground_since = t
        fault = self._fault_reason(t)
        if fault is not None:
            return self._announce_fault(t, fault)
        return None

    def check_timeout(self, t: float) -> Decision | None:
        """Call periodically: FAULT when obstacle lists stopped or the ground is lost."""
        t = float(t)
        fault = self._fault_reason(t)
        if fault is not None and fault != _HELD:
            return self._announce_fault(t, fault)
        return None

    # -- internals
    def _fault_reason(self, t: float) -> str | None:
        c = self._cfg
        if self._last_obstacles_t is None:
            return 'starting' if t - self._t0 <= c.startup_grace else 'not_started'
        if t - self._last_obstacles_t > c.timeout:
            return 'no_data'
        if self._ground is None and c.require_ground_plane:
            # The ground plane's grace runs from the first obstacle list (the detector may
            # take long to start, e.g. compiling), not from this node's start.
            first = self._first_obstacles_t
            since = self._t0 if first is None else max(self._t0, first)
            return 'starting' if t - since <= c.startup_grace else 'ground_lost'
        if not self._ground_fresh and c.require_ground_plane:
            # Lists after a gap, no ground status since (`update`). A FAULT said in the
            # gap stands. A gap that ended before the periodic check said it (a list
            # 0.40-0.45 s late) is over: "detection has stopped" would be untrue now, so
            # the level is held unannounced until the ground status comes, for at most
            # ``timeout``.
            said = self._current.level == AlarmLevel.FAULT and self._fault == 'no_data'
            return 'no_data' if said or t - self._stale_since > c.timeout else _HELD
        if self._ground == GroundStatus.INITIALISING:
            return 'starting' if t - self._ground_since <= c.startup_grace else 'ground_lost'
        if self._ground == GroundStatus.LOST and t - self._ground_since > c.timeout:
            return None if self._held_through_lost(t) is not None else 'ground_lost'
        return None

    def _held_through_lost(self, t: float) -> ObstacleInfo | None:
        """The hazard walked up to while the ground has been LOST for longer than
        ``timeout`` (module docstring, ``lost_hold``; before that the level is held as
        it was): the target last seen while the current obstacle level holds,
        where the walk since has brought it (walking frame), if it was seen at most
        ``lost_hold`` ago, is the one announced or was seen within ``hold_time`` (as a
        repeat names it), and still lies ahead within ``max_range``; else None."""
        c, last = self._cfg, self._last_target
        if (c.lost_hold <= 0.0 or last is None or self._ground != GroundStatus.LOST
                or t - self._ground_since <= c.timeout    # (held as before, unmoved)
                or self._current.level not in (AlarmLevel.CAUTION, AlarmLevel.WARNING,
                                               AlarmLevel.STOP)
                or t - self._last_target_t > c.lost_hold
                or not (last.id == self._current.obstacle_id
                        or t - self._last_target_t <= c.hold_time)):
            return None      # (another target glimpsed long ago has moved on)
        moved = self.walked(t, last, self._last_target_t)
        # (not the corridor test again: it was in the path, and the walking direction's
        # sway moves a wide drop's nearest point, beside the walking line, in and out)
        return moved if moved.forward > 0.0 and moved.range <= c.max_range else None

    def _announce_fault(self, t: float, reason: str) -> Decision | None:
        cur = self._current
        if cur.level == AlarmLevel.FAULT and self._fault == reason:
            # "starting up" is said once; real faults are repeated.
            if reason != 'starting' and t - self._last_announce_t >= self._cfg.repeat_period:
                return self._announce(dataclasses.replace(cur, t=t, repeat=True))
            return None
        self._fault = reason
        self._below_since = None
        text = {'starting': TEXT_STARTING, 'no_data': TEXT_NO_DATA,
                'not_started': TEXT_NOT_STARTED, 'ground_lost': TEXT_GROUND_LOST}[reason]
        return self._announce(Decision(AlarmLevel.FAULT, text, t=t))

    def _decide(self, t: float, level: AlarmLevel, tgt: ObstacleInfo | None,
                repeat: bool = False) -> Decision:
        if level == AlarmLevel.CLEAR or tgt is None:
            return Decision(level, TEXT_CLEAR if level == AlarmLevel.CLEAR else
                            self._current.text, t=t, repeat=repeat)
        c = self._cfg
        # the text speaks from the walking direction; the bearing is the cameras' (as
        # on /obstacles)
        return Decision(level, obstacle_text(level, tgt, c.ahead_angle_deg, c.side_angle_deg),
                        obstacle_id=int(tgt.id), range=float(tgt.range),
                        bearing=math.remainder(tgt.bearing + self.walking_heading(t),
                                               math.tau), t=t, repeat=repeat,
                        time_to_contact=self.time_to_contact(t, tgt))

    def _from_unknown(self, t: float, obstacles: list[ObstacleInfo],
                      unknown: ObstacleInfo | None) -> Decision | None:
        """An obstacle list while "cannot see the way ahead" is in force: an obstacle's
        level at once; the unknown ground repeated; "all clear" after ``hold_time``
        without either, counted while the ground is not LOST (`_pause_below`)."""
        tgt, level = self.select(t, obstacles)
        self._set_contact(t, tgt, level)
        if level > AlarmLevel.CLEAR:
            self._below_since = None
            self._remember(t, tgt)
            return self._announce(self._decide(t, level, tgt))
        if unknown is not None:
            self._below_since = None
            if (t - self._last_announce_t < self._cfg.repeat_period
                    or (not self._cfg.repeat_when_standing and self.standing(t))):
                return None
            return self._announce_unknown(t, unknown, repeat=True)
        if self._ground == GroundStatus.LOST:
            self._pause_below()
            return None
        if self._below_since is None:
            self._below_since = t
        if t - self._below_since < self._cfg.hold_time:
            return None
        self._below_since = None
        return self._announce(self._decide(t, AlarmLevel.CLEAR, None))

    def _pause_below(self) -> None:
        """The ground is LOST: the time a lower level has persisted stops counting (its
        start moves on by the time since the previous list) until the ground is back; a
        lower level steps down after ``hold_time`` of lists with the ground seen. An
        empty list without the ground is no evidence that the path is clear; nor does
        it undo the evidence gathered before (a plane lost in a pair now and then held
        a FAULT "cannot see the way ahead" long after the unseen ground had gone)."""
        if self._below_since is not None:
            self._below_since += self._list_dt

    def _announce_unknown(self, t: float, unknown: ObstacleInfo,
                          repeat: bool = False) -> Decision:
        self._below_since = None
        d = self._announce(Decision(AlarmLevel.FAULT, unknown_text(unknown.range),
                                    range=float(unknown.range),
                                    bearing=math.remainder(unknown.bearing
                                                           + self.walking_heading(t),
                                                           math.tau), t=t, repeat=repeat))
        self._fault = 'unknown_ahead'
        return d

    def _set_contact(self, t: float, tgt: ObstacleInfo | None, level: AlarmLevel) -> None:
        self._contact = Contact(t, level, tgt, self.time_to_contact(t, tgt), self.moving(t),
                                self.walking_heading(t))

    def _maybe_repeat(self, t: float, tgt: ObstacleInfo | None) -> Decision | None:
        cur = self._current
        if cur.level == AlarmLevel.CLEAR or t - self._last_announce_t < self._cfg.repeat_period:
            return None
        if not self._cfg.repeat_when_standing and self.standing(t):
            # A standing wearer has been told about this obstacle: not again and again.
            return None
        if tgt is None:
            # the newest seen (nearer than when announced) if it is what was announced,
            # or seen within hold_time; an older other one (a passer-by glimpsed after
            # the announcement, now elsewhere) is no news: the announcement is repeated
            # (where it is now: moved by the walk since it was seen; walked past, it is
            # no news either)
            last = self._last_target
            if last is not None and (last.id == cur.obstacle_id
                                     or t - self._last_target_t <= self._cfg.hold_time):
                moved = self.walked(t, last, self._last_target_t)
                tgt = moved if self.in_path(t, moved, self._cfg.hysteresis) else None
        if tgt is None:
            return self._announce(dataclasses.replace(cur, t=t, repeat=True))
        return self._announce(self._decide(t, cur.level, tgt, repeat=True))

    def _remember(self, t: float, tgt: ObstacleInfo | None) -> None:
        self._last_target, self._last_target_t = tgt, t

    def _announce(self, d: Decision) -> Decision:
        self._current = d
        self._last_announce_t = d.t
        if d.level != AlarmLevel.FAULT:
            self._fault = None
        if d.level in (AlarmLevel.CLEAR, AlarmLevel.FAULT):
            self._last_target = None
        return d
