"""alarm_node: /obstacles + /ground_plane in, /alarms (what the wearer is told) out.

Subscribes:
    /obstacles (asmonc_vision_msgs/ObstacleArray, RELIABLE)
    /ground_plane (asmonc_vision_msgs/GroundPlane, RELIABLE)
    /egomotion (geometry_msgs/TransformStamped, best effort): the walking speed and
        direction (``core.walking.WalkingSpeed``), for the levels by time to contact
    /gait/state (asmonc_vision_msgs/GaitState, best effort): walking or standing
Publishes:
    /alarms (asmonc_vision_msgs/Alarm, RELIABLE + TRANSIENT_LOCAL: a late subscriber
        hears the current state at once)
    /alarms/contact (diagnostic_msgs/DiagnosticArray, RELIABLE): per obstacle list, the
        most urgent obstacle, what the sound cue tracks between announcements; header =
        the list's header, one status named ``contact`` with the values ``level``
        (0..3), ``obstacle_id``, ``range`` (m), ``bearing`` (rad from the cameras'
        axis, positive left, as on /alarms and /obstacles), ``time_to_contact`` (s,
        ``inf`` while standing or unknown), ``drop`` and ``moving``
        (``true``/``false``), ``speed`` (m/s, ``nan`` unknown). Level 0: no obstacle
        on the path. Published after any /alarms message for the same list: it is the
        node's whole answer to that list.
    /diagnostics

An /obstacles entry whose height is NaN is ground the detector cannot see from its
range on (``core.unseen_ground``), not an obstacle: it is said as FAULT "cannot see the
way ahead" in place of "all clear" (``core.alarm``).

The decisions are made by ``core.alarm.AlarmLogic`` on the node's *steady* clock (time
of arrival), never on message stamps or sim time, so a stalled pipeline gives FAULT
even when /clock stops too. The silence check runs on a thread of its own, not on the
executor: a publish can block the executor for a while (0.3 s seen on /diagnostics on a
loaded machine, and a 1 s stall once a node was killed), and the FAULT that says
detection has stopped must not wait for it; /diagnostics and the contact are published
outside the lock the check takes. A FAULT "starting up" is published at start: silence
is never "all clear". Parameters: the fields of ``core.alarm.AlarmConfig`` (changeable at
run time).
"""
from __future__ import annotations

import threading

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Header

from asmonc_vision.core.alarm import (CHECK_PERIOD_S, AlarmConfig, AlarmLevel, AlarmLogic, Contact,
                                      Decision, ObstacleInfo)
from asmonc_vision.core.walking import WalkingSpeed
from asmonc_vision.nodes.common import (ALARM_QOS, RESULT_QOS, SENSOR_QOS, Diagnostics,
                                        declare_config, run_node, watch_input_links)
from asmonc_vision.nodes.conversions import stamp_to_ns
from asmonc_vision_msgs.msg import Alarm, GaitState, GroundPlane, ObstacleArray

#: frame id of alarms made before any obstacle list was seen
DEFAULT_FRAME = 'stereo_left_optical_frame'
#: period of the timeout check on the steady clock, seconds
CHECK_PERIOD = CHECK_PERIOD_S
#: a stamp this much older than the last one is a restarted replay, not a late
#: message: it is accepted (and the order check starts again), seconds
CLOCK_RESET_JUMP = 5.0


#: time constant of the walking speed's smoothing, seconds
SPEED_TAU = 0.5
#: topic of the per-list contact (see module doc)
CONTACT_TOPIC = '/alarms/contact'


def contact_msg(c: Contact, header: Header, speed: float | None) -> DiagnosticArray:
    """The /alarms/contact message of a contact (see module doc)."""
    msg = DiagnosticArray()
    msg.header = header
    ob = c.target
    values = dict(level=int(c.level), obstacle_id=ob.id if ob else 0,
                  range=f'{ob.range:.3f}' if ob else 'nan',
                  bearing=(f'{math.remainder(ob.bearing + c.heading, math.tau):.4f}'
                           if ob else 'nan'),
                  time_to_contact=f'{c.time_to_contact:.3f}',
                  drop=str(bool(ob and ob.is_drop)).lower(), moving=str(c.moving).lower(),
                  speed='nan' if speed is None else f'{speed:.3f}')
    msg.status = [DiagnosticStatus(name='contact', message=AlarmLevel(c.level).name,
                                   values=[KeyValue(key=k, value=str(v))
                                           for k, v in values.items()])]
    return msg


def contact_from_msg(msg: DiagnosticArray) -> dict | None:
    """The values of an /alarms/contact message as numbers and booleans, or None."""
    for st in msg.status:
        if st.name == 'contact':
            v = {kv.key: kv.value for kv in st.values}
            try:
                return dict(level=int(v['level']), obstacle_id=int(v['obstacle_id']),
                            range=float(v['range']), bearing=float(v['bearing']),
                            time_to_contact=float(v['time_to_contact']),
                            drop=v['drop'] == 'true', moving=v['moving'] == 'true',
                            speed=float(v['speed']))
            except (KeyError, ValueError):
                return None
    return None


def obstacles_from_msg(msg: ObstacleArray) -> list[ObstacleInfo]:
    """The alarm's view of an ObstacleArray."""
    return [ObstacleInfo(id=int(o.id), range=float(o.range), bearing=float(o.bearing),
                         height=float(o.height), confidence=float(o.confidence))
            for o in msg.obstacles]


class _StampOrder:
    """Rejects stamps older than the last accepted one (a big jump back resets)."""

    def __init__(self) -> None:
        self.last_ns: int | None = None
        self.rejected = 0

    def accept(self, ns: int) -> tuple[bool, bool]:
        """(accepted, was_reset)."""
        if self.last_ns is None or ns >= self.last_ns:
            self.last_ns = ns
            return True, False
        if self.last_ns - ns > CLOCK_RESET_JUMP * 1e9:
            self.last_ns = ns
            return True, True
        self.rejected += 1
        return False, False


class AlarmNode(Node):
    """Turns obstacle lists into spoken alarms (see module doc)."""

    def __init__(self, **kwargs):
        super().__init__('alarm_node', **kwargs)
        self._lock = threading.Lock()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.config: AlarmConfig = declare_config(self, AlarmConfig, on_change=self._on_config)
        self._logic = AlarmLogic(self.config, t0=self._now())
        self._frame_id = DEFAULT_FRAME
        self._obstacle_order = _StampOrder()
        self._ground_order = _StampOrder()
        self._messages = 0
        self._walk = WalkingSpeed(SPEED_TAU)
        self._ego_prev_ns: int | None = None

        self._pub = self.create_publisher(Alarm, '/alarms', ALARM_QOS)
        self._contact_pub = self.create_publisher(DiagnosticArray, CONTACT_TOPIC, RESULT_QOS)
        self._diag = Diagnostics(self, 'alarm_node')
        self.create_subscription(ObstacleArray, '/obstacles', self._on_obstacles, RESULT_QOS)
        self.create_subscription(GroundPlane, '/ground_plane', self._on_ground, RESULT_QOS)
        self.create_subscription(TransformStamped, '/egomotion', self._on_egomotion, SENSOR_QOS)
        self.create_subscription(GaitState, '/gait/state', self._on_gait, SENSOR_QOS)
        self._stop = threading.Event()
        self._watchdog = threading.Thread(target=self._watch_silence, name='alarm_watchdog',
                                          daemon=True)
        watch_input_links(self, ('/obstacles',))

        # Silence at start must not mean "all clear".
        self._publish(self._logic.current, None)
        self._update_diagnostics(self._diagnostic_status())
        self.get_logger().info(
            f'alarm node up: corridor +-{self.config.corridor_half_width} m, STOP <= '
            f'{self.config.stop_range} m, WARNING <= {self.config.warning_range} m, CAUTION '
            f'<= {self.config.caution_range} m, FAULT after {self.config.timeout} s of silence')
        self._watchdog.start()

    def destroy_node(self) -> None:
        self._stop.set()
        if self._watchdog.is_alive() and self._watchdog is not threading.current_thread():
            self._watchdog.join(timeout=2.0)
        super().destroy_node()

    # -- helpers
    def _now(self) -> float:
        return self._steady.now().nanoseconds * 1e-9

    def _on_config(self, cfg: AlarmConfig) -> None:
        with self._lock:
            self.config = cfg
            self._logic.set_config(cfg)
        self.get_logger().info(f'alarm settings changed: {cfg}')

    def _publish(self, d: Decision, header: Header | None) -> None:
        msg = Alarm()
        if header is not None:
            msg.header.stamp = header.stamp
            msg.header.frame_id = header.frame_id or self._frame_id
        else:
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = self._frame_id
        msg.level = int(d.level)
        msg.obstacle_id = int(d.obstacle_id) & 0xFFFFFFFF
        msg.range = float(d.range)
        msg.bearing = float(d.bearing)
        msg.text = d.text
        self._pub.publish(msg)
        log = self.get_logger()
        line = f'alarm {AlarmLevel(d.level).name}: "{d.text}"'
        if d.repeat:
            log.debug(line)
        elif d.level == AlarmLevel.FAULT:
            log.warning(line)
        else:
            log.info(line)

    def _diagnostic_status(self) -> tuple[int, str, dict]:
        """(level, message, values) of the node's /diagnostics status now; taken under
        the lock, published after it (`_update_diagnostics`): a /diagnostics publish
        that blocks must not hold the silence check."""
        cur = self._logic.current
        age = self._logic.last_obstacles_age(self._now())
        values = dict(alarm_level=AlarmLevel(cur.level).name, alarm_text=cur.text,
                      obstacle_lists=self._messages,
                      last_obstacles_age_s='never' if age is None else f'{age:.2f}',
                      out_of_order=self._obstacle_order.rejected + self._ground_order.rejected)
        fault = self._logic.fault
        if fault is None:
            return Diagnostics.OK, f'alarm {AlarmLevel(cur.level).name}', values
        level, message = {
            'starting': (Diagnostics.WARN, 'starting up: no trusted obstacle data yet'),
            'no_data': (Diagnostics.ERROR, 'no /obstacles within the timeout'),
            'unknown_ahead': (Diagnostics.WARN, 'cannot see the way ahead'),
            'not_started': (Diagnostics.ERROR, 'no /obstacles since the start'),
        }.get(fault, (Diagnostics.ERROR, 'ground plane lost'))
        return level, message, values

    def _update_diagnostics(self, status: tuple[int, str, dict]) -> None:
        level, message, values = status
        self._diag.update(level, message, **values)

    # -- callbacks
    def _on_obstacles(self, msg: ObstacleArray) -> None:
        ok, reset = self._obstacle_order.accept(stamp_to_ns(msg.header.stamp))
        if not ok:
            self.get_logger().warning(
                '/obstacles stamp older than the last one: message ignored '
                f'({self._obstacle_order.rejected} so far)', throttle_duration_sec=2.0)
            return
        if reset:
            self.get_logger().info('/obstacles stamps jumped back (replay restarted?): '
                                   'accepting the new time line')
        obstacles = obstacles_from_msg(msg)
        with self._lock:
            self._messages += 1
            if msg.header.frame_id:
                self._frame_id = msg.header.frame_id
            d = self._logic.update(self._now(), obstacles)
            if d is not None:
                self._publish(d, msg.header)
            status = self._diagnostic_status() if d is not None else None
            contact = contact_msg(self._logic.contact, msg.header, self._walk.speed)
        # published outside the lock: the silence check never waits for these publishes;
        # last, the contact: the list's answer is complete once it is out
        if status is not None:
            self._update_diagnostics(status)
        self._contact_pub.publish(contact)

    def _on_egomotion(self, msg: TransformStamped) -> None:
        ns = stamp_to_ns(msg.header.stamp)
        prev, self._ego_prev_ns = self._ego_prev_ns, ns
        if prev is None or not 0 < ns - prev < 1e9:
            return                      # the first motion, or a gap: no interval to use
        tr = msg.transform.translation
        with self._lock:
            speed = self._walk.update(self._now(), (tr.x, tr.y, tr.z), (ns - prev) * 1e-9)
            if speed is not None and math.isfinite(speed):
                self._logic.walk_motion(self._now(), speed, self._walk.heading)

    def _on_gait(self, msg: GaitState) -> None:
        with self._lock:
            self._logic.gait(self._now(), bool(msg.walking))

    def _on_ground(self, msg: GroundPlane) -> None:
        ok, _ = self._ground_order.accept(stamp_to_ns(msg.header.stamp))
        if not ok:
            self.get_logger().warning('/ground_plane stamp older than the last one: ignored',
                                      throttle_duration_sec=2.0)
            return
        if msg.status > 2:
            self.get_logger().warning(
                f'/ground_plane has unknown status {msg.status}: ignored',
                throttle_duration_sec=2.0)
            return
        with self._lock:
            d = self._logic.ground_status(self._now(), msg.status)
            if d is not None:
                self._publish(d, msg.header)
            status = self._diagnostic_status() if d is not None else None
        if status is not None:
            self._update_diagnostics(status)

    def _watch_silence(self) -> None:
        """Every `CHECK_PERIOD` on the steady clock, until the node is destroyed or its
        context shut down: the timeout check (`_check_silence`)."""
        log = self.get_logger()
        while not self._stop.wait(CHECK_PERIOD) and self.context.ok():
            try:
                self._check_silence()
            except Exception as exc:  # noqa: BLE001 (the check must go on; said, not hidden)
                if not self.context.ok():
                    return
                log.error(f'silence check failed: {exc!r}', throttle_duration_sec=5.0)

    def _check_silence(self) -> None:
        """FAULT when the obstacle lists stopped or the ground is lost; the status's
        values refreshed for the periodic /diagnostics."""
        with self._lock:
            d = self._logic.check_timeout(self._now())
            if d is not None:
                self._publish(d, None)
            status = self._diagnostic_status()
        self._update_diagnostics(status)


def main(args=None):
    run_node(AlarmNode, args, name='alarm_node')


if __name__ == '__main__':
    main()
