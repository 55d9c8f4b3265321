"""gait_filter_node over real topics, in-process: a simulated inclinometer stream (best
effort and reliable publishers) and visual motion in; /gait/state at the inclinometer's
rate, /gait/predicted_motion, out-of-order stamps, a silent sensor."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from geometry_msgs.msg import TransformStamped  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from asmonc_vision.eval import gait_walks as ev  # noqa: E402
from asmonc_vision.core.gait.rotations import (matrix_to_quaternion,  # noqa: E402
                                               quaternion_to_matrix, relative_rotation)
from asmonc_vision.nodes.common import RESULT_QOS, SENSOR_QOS  # noqa: E402
from asmonc_vision.nodes.compass_node import imu_message  # noqa: E402
from asmonc_vision.nodes.conversions import ns_to_stamp, stamp_to_ns  # noqa: E402
from asmonc_vision.nodes.gait_node import GaitFilterNode  # noqa: E402
from asmonc_vision_msgs.msg import GaitState  # noqa: E402

DEADLINE = 20.0
T0_NS = 1_700_000_000_000_000_000


#: this module's DDS domain id offset (see conftest.ros)
ROS_DOMAIN_OFFSET = 53


def _imu(t: float, rpy, var: float) -> Imu:
    return imu_message(rpy, np.full(3, var), ns_to_stamp(T0_NS + int(round(t * 1e9))),
                       'inclinometer_link')


@pytest.mark.parametrize('qos_name', ['best_effort', 'reliable'])
def test_walk_stream_gives_gait_state_and_predicted_motion(ros, qos_name):
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    probe = add(Node('gait_probe', context=ctx))
    states: list[GaitState] = []
    motions: list[TransformStamped] = []
    diags = ros.diagnostics(probe, 'gait_filter_node')
    probe.create_subscription(GaitState, '/gait/state', states.append, RESULT_QOS)
    probe.create_subscription(TransformStamped, '/gait/predicted_motion', motions.append,
                              RESULT_QOS)
    qos = SENSOR_QOS if qos_name == 'best_effort' else RESULT_QOS
    imu_pub = probe.create_publisher(Imu, '/inclinometer/imu', qos)
    ego_pub = probe.create_publisher(TransformStamped, '/egomotion', SENSOR_QOS)
    node = add(GaitFilterNode(context=ctx, parameter_overrides=[
        Parameter('timeout', value=1.0)]))
    spin_until(lambda: imu_pub.get_subscription_count() > 0, 'the node to subscribe')

    case = ev.make_case('walk', 0)
    ego = ev.simulate_egomotion(case.walker, case.duration, 0.2, rng=3)
    n = int(np.searchsorted(case.imu_times, 12.0))
    j = 0
    for i in range(n):
        t = float(case.imu_times[i])
        while j < len(ego) and ego[j][1] <= t:
            _, tc, r = ego[j]
            j += 1
            m = TransformStamped()
            m.header.stamp = ns_to_stamp(T0_NS + int(round(tc * 1e9)))
            m.header.frame_id = 'stereo_left_optical_frame'
            m.child_frame_id = 'stereo_left_optical_frame'
            q = matrix_to_quaternion(r)
            m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, \
                m.transform.rotation.w = (float(v) for v in q)
            ego_pub.publish(m)
        before = len(states)
        imu_pub.publish(_imu(t, case.imu_rpy[i], case.imu_variance))
        # the node's state for it taken before the next sample (a loaded machine must not
        # lose states from this probe's queue); a sample lost on the best-effort link
        # makes none
        end = time.monotonic() + 0.5
        while len(states) == before and time.monotonic() < end:
            ros.executor.spin_once(timeout_sec=0.005)
        if i == n // 2:
            # a stale sample: ignored, counted
            imu_pub.publish(_imu(t - 0.5, case.imu_rpy[i], case.imu_variance))
    # the states of the stream's samples (a silence's "walking false", which a stall of
    # this loaded process can bring about, is stamped by the node's clock, not the stream's)
    end_ns = T0_NS + int(round(float(case.imu_times[n - 1]) * 1e9))

    def of_stream():
        return [s for s in states if stamp_to_ns(s.header.stamp) <= end_ns]

    spin_until(lambda: len(of_stream()) >= n - 5, f'{n} GaitState messages')
    # one state per inclinometer sample (best effort on a local link loses none here)
    assert len(of_stream()) <= n
    assert node.counts['out_of_order'] == 1
    assert node.counts['egomotion'] > 20
    last = of_stream()[-1]
    assert last.walking and last.horizon == pytest.approx(0.5)
    assert 1.7 < last.step_frequency < 2.2
    assert np.all(np.asarray(last.amplitude) > 0.005)
    assert np.all(np.asarray(last.predicted_variance) > 0)
    stamp_s = last.header.stamp.sec + last.header.stamp.nanosec * 1e-9 - T0_NS * 1e-9
    _, truth = case.walker.states(np.array([stamp_s + 0.5]))
    err = np.degrees(np.abs(np.asarray(last.predicted)[:2] - truth[0, :2]))
    assert np.all(err < 1.5), err
    # the predicted motion, at the state's stamp, is the rig's rotation over the horizon:
    # the walk model on the same samples off-line is 0.9 deg off the true rotation at 12 s
    # and at most 2.4 deg over 6-12 s; the rotation itself is 5.4 deg (no motion, a wrong
    # sign or frame would be off by about that or more)
    spin_until(lambda: any(m.header.stamp == last.header.stamp for m in motions),
               "the last state's predicted motion")
    motion = next(m for m in motions if m.header.stamp == last.header.stamp)
    assert motion.header.frame_id == 'inclinometer_link'
    assert motion.child_frame_id == 'inclinometer_link_predicted'
    q = motion.transform.rotation
    r = quaternion_to_matrix(np.array([q.x, q.y, q.z, q.w]))
    _, now = case.walker.states(np.array([stamp_s]))
    off = r.T @ relative_rotation(now[0, :3], truth[0, :3])
    off_deg = np.degrees(np.arccos(np.clip((np.trace(off) - 1) / 2, -1, 1)))
    assert off_deg < 2.5, off_deg
    # diagnostics report the out-of-order stamp
    spin_until(lambda: any('out of order' in s.message for s in diags), 'a WARN')

    # the sensor falls silent: WARN and walking false
    states.clear()
    spin_until(lambda: any(not s.walking for s in states), 'walking false after silence')
    spin_until(lambda: any('silent' in s.message and s.level == b'\x01' for s in diags),
               'a silence WARN')


def test_a_node_waiting_for_its_first_sample_is_not_silent_until_the_grace_ends(ros, capfd):
    """Started before the inclinometer (a replay or a driver comes up a moment later), the
    node reports that it waits, not that the sensor is silent, for ``startup_grace``;
    after that a sensor that never spoke is silent."""
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    probe = add(Node('gait_probe3', context=ctx))
    diags = ros.diagnostics(probe, 'gait_filter_node')
    node = add(GaitFilterNode(context=ctx, parameter_overrides=[
        Parameter('timeout', value=0.2), Parameter('startup_grace', value=4.0)]))
    spin_until(lambda: any('waiting' in s.message for s in diags), 'a waiting status',
               deadline=3.0)
    assert not any('silent' in s.message for s in diags)
    assert all(s.level == b'\x00' for s in diags)
    spin_until(lambda: any('silent' in s.message and s.level == b'\x01' for s in diags),
               'a silence WARN after the grace')
    assert node.counts['imu'] == 0
    # the sensor starts, then falls silent within the log's throttle (5 s) of the
    # start-up line: that silence is logged too, as its own kind of line
    pub = probe.create_publisher(Imu, '/inclinometer/imu', SENSOR_QOS)
    spin_until(lambda: pub.get_subscription_count() >= 1, 'the node subscribed')
    for i in range(10):
        pub.publish(_imu(i * 0.02, (0.0, -0.3, 0.0), 1e-4))
        ros.spin_for(0.02)
    spin_until(lambda: node.counts['imu'] > 0, 'samples taken')
    err = [capfd.readouterr().err]
    spin_until(lambda: err.append(capfd.readouterr().err)
               or 'silent for more than 0.2 s' in ''.join(err),
               'the silence logged after the start-up line', deadline=3.0)
    assert 'silent since the node started' in ''.join(err)


def test_imu_without_orientation_is_ignored(ros):
    ctx, add, spin_until = ros.ctx, ros.add, ros.spin_until
    probe = add(Node('gait_probe2', context=ctx))
    pub = probe.create_publisher(Imu, '/inclinometer/imu', SENSOR_QOS)
    node = add(GaitFilterNode(context=ctx))
    spin_until(lambda: pub.get_subscription_count() > 0, 'the node to subscribe')
    m = Imu()
    m.orientation_covariance[0] = -1.0
    m.header.stamp = ns_to_stamp(T0_NS)
    pub.publish(m)
    spin_until(lambda: node.counts['bad_imu'] == 1, 'the message to be refused')
    assert node.counts['imu'] == 0
