"""The alarm node's logic over a detector's outputs, offline, in bag time.

`replay_alarms` feeds `core.alarm.AlarmLogic` as `nodes.alarm_node` does, with the bag's
stamps as its clock: the logic starts (FAULT "starting up") just before the first pair;
for each pair the detector answered, its obstacle list (`update`) and then its ground
status (`ground_status`), in the order the detector node publishes them (/obstacles,
then /ground_plane); and the node's timer (`check_timeout`, every `CHECK_PERIOD_S`) between
pairs, so a run of pairs without an answer gives the FAULT the node would give. Alarms about a pair
carry its stamp (as the node's do); timer alarms carry the tick's bag time.

Given the pairs' egomotion (``/egomotion``'s translations, as `eval.bench.run_method`
keeps them), each is turned into the walking speed and direction by
`core.walking.WalkingSpeed` and given to the logic (``walk_motion``) before the pair's
obstacle list, as the node does with each /egomotion message: the levels by time to
contact and the corridor along the walking direction are then those of the live graph.
The walk model's walking/standing state (``/gait/state``) is not replayed: the logic
then knows a walker by the speed alone.
"""
from __future__ import annotations

import math
from typing import Sequence

from asmonc_vision.core.alarm import (CHECK_PERIOD_S, AlarmConfig, AlarmLogic, Decision,
                                      GroundStatus, ObstacleInfo)
from asmonc_vision.core.walking import WalkingSpeed
from asmonc_vision.eval.evaluation import FrameObstacles

#: the detector's status words -> GroundPlane status values
STATUS_VALUES = {'initialising': GroundStatus.INITIALISING, 'tracking': GroundStatus.TRACKING,
                 'lost': GroundStatus.LOST}
#: the alarm node's timer period, seconds
TIMER_PERIOD_S = CHECK_PERIOD_S


def obstacle_infos(fo: FrameObstacles) -> list[ObstacleInfo]:
    """The alarm logic's view of one frame's reports (confidence 1 when not known)."""
    conf = fo.confidence if fo.confidence is not None else [1.0] * len(fo)
    return [ObstacleInfo(int(fo.ids[k]), float(fo.range[k]), float(fo.bearing[k]),
                         float(fo.height[k]), float(conf[k])) for k in range(len(fo))]


def _alarm(d: Decision, stamp_ns: int) -> dict:
    return {'stamp_ns': int(stamp_ns), 'level': int(d.level), 'text': d.text,
            'obstacle_id': int(d.obstacle_id), 'range': float(d.range),
            'bearing': float(d.bearing)}


def replay_alarms(outputs: Sequence[tuple[int, str | None, FrameObstacles | None]],
                  config: AlarmConfig | None = None,
                  motions: Sequence | None = None) -> list[dict]:
    """The alarms the alarm node would give for a detector's outputs.

    Args:
        outputs: per stereo pair in stamp order, (stamp_ns, ground status word
            'initialising' | 'tracking' | 'lost' or None for no /ground_plane, the
            reports or None when the detector gave no answer for that pair).
        config: the alarm settings (default `AlarmConfig()`, the node's defaults).
        motions: per pair, the /egomotion translation published for it ((3,) m, the
            left camera's from the pair before, its optical frame) or None; None: no
            egomotion (levels by range only, as a graph without /egomotion).
    Returns:
        the alarms in announced order: dicts ``stamp_ns``, ``level``, ``text``,
        ``obstacle_id``, ``range`` (m), ``bearing`` (rad), as `asmonc run` logs /alarms.
    """
    if not outputs:
        return []
    s0 = int(outputs[0][0])
    logic = AlarmLogic(config or AlarmConfig(), t0=0.0)
    alarms = [_alarm(logic.current, s0 - 1)]
    t_tick = 0.0
    walk, prev_motion_ns = WalkingSpeed(), None
    if motions is not None and len(motions) != len(outputs):
        raise ValueError(f'motions: {len(motions)} for {len(outputs)} pairs')

    def sec(ns: int) -> float:
        return (int(ns) - s0) / 1e9

    for i, (stamp, status, fo) in enumerate(outputs):
        t = sec(stamp)
        while t_tick + TIMER_PERIOD_S <= t:
            t_tick += TIMER_PERIOD_S
            d = logic.check_timeout(t_tick)
            if d is not None:
                alarms.append(_alarm(d, s0 + int(round(t_tick * 1e9))))
        tr = motions[i] if motions is not None else None
        if tr is not None:
            # as nodes.alarm_node._on_egomotion: the interval from the last motion
            prev_motion_ns, prev = int(stamp), prev_motion_ns
            if prev is not None and 0 < int(stamp) - prev < 1e9:
                speed = walk.update(t, tuple(float(v) for v in tr), (int(stamp) - prev) * 1e-9)
                if speed is not None and math.isfinite(speed):
                    logic.walk_motion(t, speed, walk.heading)
        if fo is None:
            continue
        d = logic.update(t, obstacle_infos(fo))
        if d is not None:
            alarms.append(_alarm(d, stamp))
        if status is not None:
            d = logic.ground_status(t, STATUS_VALUES.get(status, GroundStatus.LOST))
            if d is not None:
                alarms.append(_alarm(d, stamp))
    return alarms
