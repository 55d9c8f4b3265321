"""alarm_node over real topics, in-process: /obstacles -> node -> /alarms."""
from __future__ import annotations

import os

import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from asmonc_vision.core.alarm import TEXT_CLEAR, TEXT_NO_DATA, TEXT_STARTING  # noqa: E402
from asmonc_vision.nodes.alarm_node import AlarmNode  # noqa: E402
from asmonc_vision.nodes.common import ALARM_QOS, RESULT_QOS  # noqa: E402
from asmonc_vision_msgs.msg import GroundPlane, Alarm, Obstacle, ObstacleArray  # noqa: E402

FRAME = 'stereo_left_optical_frame'
#: a generous bound so a broken node fails the test instead of hanging it (not a speed test)
DEADLINE = 15.0


#: this module's DDS domain id offset (see conftest.ros)
ROS_DOMAIN_OFFSET = 11


def _array(stamp_ns: int, ranges, heights=None) -> ObstacleArray:
    msg = ObstacleArray()
    msg.header.frame_id = FRAME
    msg.header.stamp.sec = stamp_ns // 1_000_000_000
    msg.header.stamp.nanosec = stamp_ns % 1_000_000_000
    for k, r in enumerate(ranges):
        o = Obstacle()
        o.id = k + 1
        o.range = float(r)
        o.bearing = 0.0
        o.height = 0.4 if heights is None else heights[k]
        o.confidence = 0.9
        msg.obstacles.append(o)
    return msg


def test_alarms_follow_obstacles_fault_on_silence_and_latch(ros):
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    probe = add(Node('alarm_probe', context=ctx))
    alarms: list[Alarm] = []
    diags = ros.diagnostics(probe, 'alarm_node')
    probe.create_subscription(Alarm, '/alarms', alarms.append, ALARM_QOS)
    pub = probe.create_publisher(ObstacleArray, '/obstacles', RESULT_QOS)

    node = add(AlarmNode(context=ctx, parameter_overrides=[
        Parameter('timeout', value=0.5), Parameter('hold_time', value=0.0),
        Parameter('startup_grace', value=60.0)]))

    # the node says "starting up" before any data: silence is never "all clear"
    spin_until(lambda: alarms, 'the start-up alarm')
    assert alarms[0].level == Alarm.FAULT and alarms[0].text == TEXT_STARTING
    spin_until(lambda: pub.get_subscription_count() > 0, 'the node to subscribe')
    # the detector reports a tracked ground (without it no list can mean "clear")
    plane_pub = probe.create_publisher(GroundPlane, '/ground_plane', RESULT_QOS)
    spin_until(lambda: plane_pub.get_subscription_count() > 0, 'the ground subscription')
    plane_pub.publish(GroundPlane(status=GroundPlane.TRACKING))
    spin_until(lambda: node._logic._ground is not None, 'the ground status to arrive')

    stamp = [10_000_000_000]

    def send(ranges):
        def each():
            stamp[0] += 50_000_000
            pub.publish(_array(stamp[0], ranges))
        return each

    for r, level, text in [(4.0, Alarm.CAUTION, 'obstacle, 4 metres, ahead'),
                           (2.0, Alarm.WARNING, 'obstacle, 2 metres, ahead'),
                           (1.0, Alarm.STOP, 'stop, obstacle, 1 metre, ahead')]:
        spin_until(lambda level=level: alarms[-1].level == level, f'level {level}',
                   each=send([r]))
        a = alarms[-1]
        assert a.text == text
        assert a.obstacle_id == 1 and a.range == pytest.approx(r)
        assert a.header.frame_id == FRAME
        assert a.header.stamp.sec * 10**9 + a.header.stamp.nanosec <= stamp[0]
        assert a.header.stamp.sec >= 10

    # back to CAUTION (hold_time 0), then an older stamp: it is ignored, so the STOP
    # obstacle it carries must never be announced before the newer WARNING one
    spin_until(lambda: alarms[-1].level == Alarm.CAUTION, 'CAUTION', each=send([4.0]))
    n_before = len(alarms)
    pub.publish(_array(stamp[0] - 1_000_000_000, [0.5]))  # 1 s older: ignored
    spin_until(lambda: node._obstacle_order.rejected == 1, 'the old message to arrive')
    spin_until(lambda: any(a.level == Alarm.WARNING for a in alarms[n_before:]),
               'WARNING after the ignored message', each=send([2.0]))
    assert all(a.level != Alarm.STOP for a in alarms[n_before:])

    # stop publishing: FAULT, with an ERROR diagnostic
    spin_until(lambda: alarms[-1].level == Alarm.FAULT, 'FAULT on silence')
    assert alarms[-1].text == TEXT_NO_DATA
    spin_until(lambda: any(d.level == b'\x02' for d in diags), 'an ERROR diagnostic')

    # data back with the detector's ground status, nothing in the way: all clear
    def send_with_ground():
        plane_pub.publish(GroundPlane(status=GroundPlane.TRACKING))
        send([])()
    spin_until(lambda: alarms[-1].level == Alarm.CLEAR, 'recovery', each=send_with_ground)
    assert alarms[-1].text == TEXT_CLEAR
    assert sum(a.level == Alarm.CLEAR for a in alarms) == 1

    # a late-joining (TRANSIENT_LOCAL) subscriber hears the current alarm at once
    late: list[Alarm] = []
    late_node = add(Node('alarm_late_listener', context=ctx))
    late_node.create_subscription(Alarm, '/alarms', late.append, ALARM_QOS)
    spin_until(lambda: late and late[-1].level == Alarm.CLEAR, 'the latched alarm')
    assert late[-1].text == TEXT_CLEAR


def test_bad_parameter_change_is_refused(ros):
    ctx, add = ros.ctx, ros.add
    node = add(AlarmNode(context=ctx))
    res = node.set_parameters([Parameter('stop_range', value=3.0)])[0]
    assert not res.successful and 'stop_range' in res.reason
    res = node.set_parameters([Parameter('hysteresis', value=0.5)])[0]
    assert res.successful and node.config.hysteresis == 0.5


def test_the_silence_check_does_not_wait_for_the_executor(ros):
    """The FAULT for silence comes from the node's own watchdog thread: with the node's
    executor never spun (as when a publish holds it), a list stopped still gives FAULT
    "detection has stopped" on /alarms within the timeout and a few check periods."""
    import time

    from asmonc_vision.nodes.alarm_node import CHECK_PERIOD
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    probe = add(Node('alarm_probe_unspun', context=ctx))
    alarms: list[tuple[float, Alarm]] = []
    probe.create_subscription(Alarm, '/alarms', lambda m: alarms.append((time.monotonic(), m)),
                              ALARM_QOS)
    node = AlarmNode(context=ctx, parameter_overrides=[
        Parameter('timeout', value=0.4), Parameter('startup_grace', value=60.0)])
    try:
        spin_until(lambda: alarms and alarms[-1][1].text == TEXT_STARTING, 'starting up')
        # one ground status and one list, handed to the callbacks (never spun)
        node._on_ground(GroundPlane(status=GroundPlane.TRACKING))
        node._on_obstacles(_array(10_000_000_000, []))
        t_list = time.monotonic()
        spin_until(lambda: alarms[-1][1].text == TEXT_CLEAR, 'all clear')
        spin_until(lambda: alarms[-1][1].text == TEXT_NO_DATA, 'FAULT on silence')
        t_fault, fault = alarms[-1]
        assert fault.level == Alarm.FAULT
        # a generous bound for a loaded machine; the executor-bound check gave no FAULT
        assert t_fault - t_list <= 0.4 + 10 * CHECK_PERIOD + 0.5
    finally:
        node.destroy_node()
    assert not node._watchdog.is_alive()
