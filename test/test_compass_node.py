"""compass_node over a pseudo-terminal pair: a simulated device stream with bad checksums
and garbage in, /inclinometer/imu and /diagnostics out; silence and device loss."""
from __future__ import annotations

import math
import os
import tempfile

import numpy as np
import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from asmonc_vision.core.gait.rotations import quaternion_to_rpy  # noqa: E402
from asmonc_vision.core.nmea import format_ptnthpr, format_tcm  # noqa: E402
from asmonc_vision.nodes.common import SENSOR_QOS  # noqa: E402
from asmonc_vision.nodes.compass_node import CompassNode  # noqa: E402

DEADLINE = 15.0


#: this module's DDS domain id offset (see conftest.ros)
ROS_DOMAIN_OFFSET = 41


class Device:
    """A pseudo-terminal standing in for the serial compass, reachable through a
    symlink so that it can be 'unplugged' and replaced by a new one."""

    def __init__(self, link: str) -> None:
        self.link = link
        self.master = None
        self.plug()

    def plug(self) -> None:
        self.master, slave = os.openpty()
        tmp = self.link + '.new'
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.link)
        os.close(slave)

    def unplug(self) -> None:
        os.close(self.master)
        self.master = None

    def send(self, text: str | bytes) -> None:
        os.write(self.master, text.encode() if isinstance(text, str) else text)


def test_stream_with_bad_lines_silence_and_reconnect(ros):
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    with tempfile.TemporaryDirectory() as d:
        dev = Device(os.path.join(d, 'compass'))
        probe = add(Node('compass_probe', context=ctx))
        imus: list[Imu] = []
        diags = ros.diagnostics(probe, 'compass_node')
        probe.create_subscription(Imu, '/inclinometer/imu', imus.append, SENSOR_QOS)
        node = add(CompassNode(context=ctx, parameter_overrides=[
            Parameter('port', value=dev.link), Parameter('timeout', value=0.4),
            Parameter('reconnect_period', value=0.2), Parameter('sigma_deg', value=0.4)]))
        spin_until(lambda: node._port_open, 'the port to open')

        # a device stream: good HPR and TCM sentences mixed with a bad checksum,
        # garbage, a cut line, binary noise, an unknown sentence, a flagged heading
        k = [0]

        def each():
            i = k[0]
            k[0] += 1
            heading = 30.0 + i
            dev.send(format_ptnthpr(heading, 20.0, -3.0))
            if i % 3 == 0:
                dev.send(format_ptnthpr(heading, 20.0, -3.0, checksum_override=0x00))
            if i % 4 == 1:
                dev.send(b'\x00\xff\xfegarbage without a dollar\r\n$PTNTHPR,12.0,N,')
                dev.send(b'\r\n')
            if i % 5 == 2:
                dev.send(format_tcm(heading, 20.0, -3.0))
                dev.send('$HCHDG,101.1,,,7.1,W*3C\r\n')
            if i % 7 == 3:
                dev.send(format_ptnthpr(heading, 20.0, -3.0, status='ONN'))

        spin_until(lambda: len(imus) >= 25, '25 Imu messages', each=each)
        c = node.counts
        assert c['checksum'] >= 5 and c['format'] >= 5, c
        assert c['unknown'] >= 1 and c['flagged'] >= 1, c

        m = imus[-1]
        assert m.header.frame_id == 'inclinometer_link'
        assert m.angular_velocity_covariance[0] == -1.0
        assert m.linear_acceleration_covariance[0] == -1.0
        rpy = quaternion_to_rpy(np.array([m.orientation.x, m.orientation.y,
                                          m.orientation.z, m.orientation.w]))
        # device: pitch 20 nose up, roll -3 (left side down); REP 103: pitch nose down,
        # yaw counter-clockwise from east = 90 deg - heading
        assert math.degrees(rpy[1]) == pytest.approx(-20.0, abs=0.05)
        assert math.degrees(rpy[0]) == pytest.approx(-3.0, abs=0.05)
        cov = np.asarray(m.orientation_covariance).reshape(3, 3)
        sig = math.radians(0.4) ** 2
        assert cov[0, 0] == pytest.approx(sig) and cov[1, 1] == pytest.approx(sig)
        assert np.all(cov[~np.eye(3, dtype=bool)] == 0.0)
        yaws = [math.degrees(quaternion_to_rpy(np.array(
            [x.orientation.x, x.orientation.y, x.orientation.z, x.orientation.w]))[2])
            for x in imus]
        assert any(abs(((90.0 - (30.0 + i)) - y + 180) % 360 - 180) < 0.05
                   for y in yaws for i in range(k[0]))
        # a flagged heading got the large yaw variance
        assert any(x.orientation_covariance[8] == pytest.approx(math.radians(5.0) ** 2)
                   for x in imus)
        # bad lines are reported
        spin_until(lambda: any(s.level == b'\x01' and 'bad lines' in s.message
                               for s in diags), 'a WARN about bad lines')

        # a silent device: WARN, never a crash
        diags.clear()
        spin_until(lambda: any(s.level == b'\x01' and 'no valid sentence' in s.message
                               for s in diags), 'a silence WARN')

        # the device is lost (unplugged): ERROR, then it comes back on a new pty
        n_before = len(imus)
        dev.unplug()
        spin_until(lambda: not node._port_open, 'the node to notice the loss')
        spin_until(lambda: any(s.level == b'\x02' for s in diags), 'an ERROR status')
        dev.plug()
        spin_until(lambda: node._port_open, 'the reconnect')
        assert node.counts['reconnects'] >= 1
        spin_until(lambda: len(imus) > n_before + 3, 'data after the reconnect',
                   each=lambda: dev.send(format_ptnthpr(45.0, 10.0, 0.0)))
        spin_until(lambda: diags and diags[-1].level == b'\x00', 'OK again',
                   each=lambda: dev.send(format_ptnthpr(45.0, 10.0, 0.0)))
        dev.unplug()


def test_missing_port_is_an_error_not_a_crash(ros):
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    probe = add(Node('compass_probe2', context=ctx))
    diags = ros.diagnostics(probe, 'compass_node')
    add(CompassNode(context=ctx, parameter_overrides=[
        Parameter('port', value='/nonexistent/compass'),
        Parameter('reconnect_period', value=0.1)]))
    spin_until(lambda: any(s.level == b'\x02' and 'port not open' in s.message
                           for s in diags), 'ERROR: port not open')
