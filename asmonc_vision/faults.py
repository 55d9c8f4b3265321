"""Faults injected into a replay at chosen bag times (`asmonc run --inject SPEC`).

A spec is a list of faults separated by ';' (or ','), each ``KIND[=ARG]@START[+DURATION]``
with START and DURATION in seconds from the bag's first message (DURATION 0 by default:
the messages at START only, or the event at START). The kinds:

==============  =========================================================================
kill=NODE       SIGKILL the graph node NODE (e.g. detector) at START (`asmonc run` does it)
drop            every second stereo pair (images and camera_infos) left out
dup             every stereo message published twice
stall           the cameras send nothing (images and camera_infos left out)
reorder         every second pair stamped ARG s (default 0.25) earlier: stamps go back
skew            the right image and camera_info stamped ARG s (default 0.02) later
encoding        the left image's encoding is ARG (default 'yuv422_weird')
size            both images cropped to half their width (camera_info unchanged)
truncate        the left image's data cut to half its length
nan_info        the left camera_info's P[0,0] (f) is NaN
inf_info        the left camera_info's P[0,0] (f) is +inf
zero_baseline   the right camera_info's P[0,3] (-f*B) is 0: a zero baseline
imu_silent      no inclinometer messages
imu_jump        the inclinometer's pitch jumps by ARG degrees (default 90)
==============  =========================================================================

A corrupt or truncated bag is a fault of the bag file itself: replay a damaged copy
(docs/robustness.md). `FaultPlan.apply` works on serialized CDR messages (rclpy's
serialization), so the bag player can call it on the bytes it would publish.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

#: kinds that change the bag's messages (applied by the player)
MESSAGE_KINDS = ('drop', 'dup', 'stall', 'reorder', 'skew', 'encoding', 'size', 'truncate',
                 'nan_info', 'inf_info', 'zero_baseline', 'imu_silent', 'imu_jump')
#: kinds that act on the graph's processes (applied by `asmonc run`)
PROCESS_KINDS = ('kill',)
KINDS = MESSAGE_KINDS + PROCESS_KINDS

LEFT_IMAGE = '/stereo/left/image_rect'
RIGHT_IMAGE = '/stereo/right/image_rect'
LEFT_INFO = '/stereo/left/camera_info'
RIGHT_INFO = '/stereo/right/camera_info'
IMU = '/inclinometer/imu'
STEREO = (LEFT_IMAGE, RIGHT_IMAGE, LEFT_INFO, RIGHT_INFO)


@dataclass(frozen=True)
class Fault:
    """One fault: its kind, argument ('' for the default) and bag-time window (s)."""

    kind: str
    arg: str
    start: float
    duration: float

    def active(self, t: float) -> bool:
        """True at bag time ``t`` (s from the bag's first message)."""
        return self.start - 1e-6 <= t <= self.start + self.duration + 1e-6

    def number(self, default: float) -> float:
        return float(self.arg) if self.arg else default

    def __str__(self) -> str:
        return (f'{self.kind}{"=" + self.arg if self.arg else ""}@{self.start:g}'
                + (f'+{self.duration:g}' if self.duration else ''))


def parse_faults(spec: str) -> list[Fault]:
    """Parse a fault spec (module docstring).

    Raises:
        ValueError: an unknown kind, a missing '@START', a bad number or argument.
    """
    out = []
    for item in spec.replace(',', ';').split(';'):
        item = item.strip()
        if not item:
            continue
        head, at, when = item.partition('@')
        if not at:
            raise ValueError(f"fault '{item}': needs '@START' (seconds into the bag)")
        kind, _, arg = head.strip().partition('=')
        kind = kind.strip()
        if kind not in KINDS:
            raise ValueError(f"fault '{item}': unknown kind '{kind}'; one of {', '.join(KINDS)}")
        start_s, _, dur_s = when.partition('+')
        try:
            start, duration = float(start_s), float(dur_s) if dur_s else 0.0
        except ValueError:
            raise ValueError(f"fault '{item}': START and DURATION must be numbers") from None
        if not (math.isfinite(start) and math.isfinite(duration)) or start < 0 or duration < 0:
            raise ValueError(f"fault '{item}': START and DURATION must be finite and >= 0")
        if kind == 'kill' and not arg:
            raise ValueError(f"fault '{item}': kill needs the node, e.g. kill=detector@2")
        if kind in ('reorder', 'skew', 'imu_jump') and arg:
            try:
                if not math.isfinite(float(arg)):
                    raise ValueError
            except ValueError:
                raise ValueError(f"fault '{item}': the argument must be a finite number") from None
        out.append(Fault(kind, arg.strip(), start, duration))
    return out


class FaultPlan:
    """Applies the message faults of a spec to a replay's serialized messages.

    Args:
        faults: parsed faults (`parse_faults`); process faults are ignored here.
        bag_start_ns: receive time of the bag's first message (bag times count from it).
    """

    def __init__(self, faults: list[Fault], bag_start_ns: int):
        self.faults = [f for f in faults if f.kind in MESSAGE_KINDS]
        self.start_ns = bag_start_ns
        #: messages changed or left out, per fault kind
        self.counts: dict[str, int] = {f.kind: 0 for f in self.faults}
        #: the stamp of the pairs seen in each fault's window, by order (for "every second")
        self._pairs: dict[int, list[int]] = {}

    def __bool__(self) -> bool:
        return bool(self.faults)

    def apply(self, topic: str, data: bytes, t_ns: int) -> list[bytes]:
        """The messages to publish instead of ``data`` (serialized CDR on ``topic``),
        received at bag time ``t_ns``: [] to leave it out, two to duplicate it."""
        t = (t_ns - self.start_ns) / 1e9
        out = [data]
        for i, f in enumerate(self.faults):
            if not f.active(t) or topic not in _TOPICS_OF[f.kind]:
                continue
            out = [m for d in out for m in self._one(i, f, topic, d)]
            self.counts[f.kind] += 1
        return out

    # --- the faults ------------------------------------------------------------------
    def _second_pair(self, i: int, topic: str, data: bytes) -> bool:
        """True for every second stereo pair (by stamp) in fault ``i``'s window."""
        stamp = _stamp_ns(topic, data)
        seen = self._pairs.setdefault(i, [])
        if stamp not in seen:
            seen.append(stamp)
        return seen.index(stamp) % 2 == 1

    def _one(self, i: int, f: Fault, topic: str, data: bytes) -> list[bytes]:
        k = f.kind
        if k in ('stall', 'imu_silent'):
            return []
        if k == 'drop':
            return [] if self._second_pair(i, topic, data) else [data]
        if k == 'dup':
            return [data, data]
        if k == 'reorder':
            if not self._second_pair(i, topic, data):
                return [data]
            return [_edit(topic, data, lambda m: _shift_stamp(m, -f.number(0.25)))]
        if k == 'skew':
            return [_edit(topic, data, lambda m: _shift_stamp(m, f.number(0.02)))]
        if k == 'encoding':
            return [_edit(topic, data, lambda m: setattr(m, 'encoding',
                                                         f.arg or 'yuv422_weird'))]
        if k == 'size':
            return [_edit(topic, data, _half_width)]
        if k == 'truncate':
            return [_edit(topic, data, lambda m: setattr(m, 'data',
                                                         bytes(m.data[:len(m.data) // 2])))]
        if k in ('nan_info', 'inf_info'):
            v = math.nan if k == 'nan_info' else math.inf
            return [_edit(topic, data, lambda m: _set_p(m, 0, v))]
        if k == 'zero_baseline':
            return [_edit(topic, data, lambda m: _set_p(m, 3, 0.0))]
        if k == 'imu_jump':
            return [_edit(topic, data, lambda m: _pitch_by(m, math.radians(f.number(90.0))))]
        raise AssertionError(k)


_TOPICS_OF = {
    'drop': STEREO, 'dup': STEREO, 'stall': STEREO, 'reorder': STEREO,
    'skew': (RIGHT_IMAGE, RIGHT_INFO), 'encoding': (LEFT_IMAGE,),
    'size': (LEFT_IMAGE, RIGHT_IMAGE), 'truncate': (LEFT_IMAGE,),
    'nan_info': (LEFT_INFO,), 'inf_info': (LEFT_INFO,), 'zero_baseline': (RIGHT_INFO,),
    'imu_silent': (IMU,), 'imu_jump': (IMU,),
}


def _msg_class(topic: str):
    if topic == IMU:
        from sensor_msgs.msg import Imu
        return Imu
    if topic.endswith('camera_info'):
        from sensor_msgs.msg import CameraInfo
        return CameraInfo
    from sensor_msgs.msg import Image
    return Image


def _edit(topic: str, data: bytes, change) -> bytes:
    from rclpy.serialization import deserialize_message, serialize_message
    msg = deserialize_message(data, _msg_class(topic))
    change(msg)
    return serialize_message(msg)


def _stamp_ns(topic: str, data: bytes) -> int:
    from rclpy.serialization import deserialize_message
    s = deserialize_message(data, _msg_class(topic)).header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _shift_stamp(msg, seconds: float) -> None:
    ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
    ns = max(0, ns + int(round(seconds * 1e9)))
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000


def _half_width(msg) -> None:
    import numpy as np
    rows = np.frombuffer(bytes(msg.data), np.uint8)[:msg.height * msg.step]
    rows = rows.reshape(msg.height, msg.step)
    bpp = msg.step // max(msg.width, 1)
    w = msg.width // 2
    msg.data = rows[:, :w * bpp].tobytes()
    msg.width, msg.step = w, w * bpp


def _set_p(msg, index: int, value: float) -> None:
    p = list(msg.p)
    p[index] = value
    msg.p = p


def _pitch_by(msg, angle: float) -> None:
    """Turn the orientation by ``angle`` rad about the body y axis (pitch), on the right:
    q' = q * (cos(a/2), 0, sin(a/2), 0)."""
    q = msg.orientation
    c, s = math.cos(angle / 2), math.sin(angle / 2)
    w, x, y, z = q.w, q.x, q.y, q.z
    q.w, q.x, q.y, q.z = (w * c - y * s, x * c - z * s, y * c + w * s, z * c + x * s)


def _scan(src, faults: list[Fault], topics) -> tuple[dict[str, set[int]], dict[str, set[int]]]:
    """(every header stamp, the stamps ``faults`` change or leave out), in ns, per topic
    of ``topics`` that the open bag ``src`` (an `asmonc_vision.io.bagplay.BagSource`)
    holds, in one pass. A damaged bag is read up to the damage."""
    plan = FaultPlan(faults, src.info.start_ns)
    selected = {t: src.info.topics[t].msgtype for t in topics if t in src.info.topics}
    every: dict[str, set[int]] = {t: set() for t in topics}
    out: dict[str, set[int]] = {t: set() for t in topics}
    for m in src.messages_before_damage(selected):
        stamp = _stamp_ns(m.topic, m.data)
        every[m.topic].add(stamp)
        if plan and m.data not in plan.apply(m.topic, m.data, m.timestamp):
            out[m.topic].add(stamp)
    return every, out


def changed_stamps(src, faults: list[Fault], topics) -> dict[str, set[int]]:
    """Per topic of ``topics`` (the fault plan's), the header stamps (ns) of the messages
    of the open bag ``src`` (an `asmonc_vision.io.bagplay.BagSource`) that ``faults``
    change or leave out. A damaged bag is read up to the damage."""
    return _scan(src, faults, topics)[1]


def affected_pairs(src, faults: list[Fault]) -> tuple[set[int], set[int]]:
    """(every left image's header stamp, the stamps of the pairs ``faults`` change or
    leave out), in ns, of the open bag ``src`` (an `asmonc_vision.io.bagplay.BagSource`).
    A pair is affected when any of its images or camera_infos is changed or left out: it
    may go without a result. A duplicated message still reaches the graph unchanged: its
    pair counts as good. A damaged bag is read up to the damage."""
    every, out = _scan(src, faults, STEREO)
    return every[LEFT_IMAGE], set().union(*out.values())
