"""egomotion_node over real topics, in-process: frames from the committed walking bag."""
import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from asmonc_vision.core.motion.geometry import (compose, invert, quaternion_to_matrix,
                                                rotation_error_components)
from asmonc_vision.nodes.common import RESULT_QOS
from asmonc_vision.nodes.egomotion_node import EgomotionNode
from conftest import BAGS, read_messages, spin_until, stereo_sender, stereo_types

TYPES = stereo_types()
POSE = '/ground_truth/camera_pose'
BAG = BAGS / 'walk_obstacles'


def load_frames(indices):
    """[(left, right, left_info, right_info)] rclpy messages and {stamp_ns: (R, t)} of the
    left optical frame in the world, for the given frame indices of the walking bag."""
    from geometry_msgs.msg import PoseStamped
    per_topic = read_messages(BAG, {**TYPES, POSE: PoseStamped})
    poses = per_topic[POSE]
    frames = [tuple(per_topic[t][i] for t in TYPES) for i in indices]
    truth = {}
    for i in indices:
        p = poses[i]
        q = p.pose.orientation
        truth[_ns(p.header.stamp)] = (quaternion_to_matrix([q.x, q.y, q.z, q.w]),
                                      np.array([p.pose.position.x, p.pose.position.y,
                                                p.pose.position.z]))
    return frames, truth


def _ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _rt(transform):
    q = transform.rotation
    return (quaternion_to_matrix([q.x, q.y, q.z, q.w]),
            np.array([transform.translation.x, transform.translation.y, transform.translation.z]))


@pytest.fixture
def graph(ros_context):
    ctx = ros_context
    node = EgomotionNode(context=ctx)
    probe = Node('probe', context=ctx)
    got = {'motion': [], 'odom': [], 'diag': []}
    probe.create_subscription(TransformStamped, '/egomotion', got['motion'].append, RESULT_QOS)
    probe.create_subscription(Odometry, '/egomotion/odometry', got['odom'].append, RESULT_QOS)
    probe.create_subscription(DiagnosticArray, '/diagnostics', got['diag'].append, 10)
    pubs, send = stereo_sender(probe)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    assert spin_until(ex, lambda: all(p.get_subscription_count() >= 1 for p in pubs.values())
                      and probe.count_publishers('/egomotion') >= 1)
    yield node, ex, send, got
    ex.shutdown()
    node.destroy_node()
    probe.destroy_node()


def test_one_motion_per_pair_matching_ground_truth(graph):
    node, ex, send, got = graph
    idx = list(range(20, 27))
    frames, truth = load_frames(idx)
    for i, f in enumerate(frames):
        send(*f)
        assert spin_until(ex, lambda i=i: node.frames_done == i + 1, timeout=15)
    assert spin_until(ex, lambda: len(got['motion']) == len(frames) - 1 and
                      len(got['odom']) == len(frames) - 1, timeout=5)
    stamps = [_ns(f[0].header.stamp) for f in frames]
    assert [_ns(m.header.stamp) for m in got['motion']] == stamps[1:]
    for m in got['motion']:
        assert m.header.frame_id == m.child_frame_id == 'stereo_left_optical_frame'
    # each /egomotion is T_prev_curr: X_prev = R X_curr + t, against the ground truth
    for m, s0, s1 in zip(got['motion'], stamps[:-1], stamps[1:]):
        r, t = _rt(m.transform)
        rt, tt = compose(*invert(*truth[s0]), *truth[s1])
        assert np.linalg.norm(t - tt) < 0.01                  # metres
        assert np.degrees(np.abs(rotation_error_components(r, rt))).max() < 0.15
        assert 0.05 < np.linalg.norm(tt) < 0.3                 # walking: the test means something
    # odometry: the chained pose from the first pair, with a growing covariance
    o = got['odom'][-1]
    assert o.header.frame_id == 'egomotion_origin'
    assert o.child_frame_id == 'stereo_left_optical_frame'
    p = o.pose.pose
    r = quaternion_to_matrix([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])
    t = np.array([p.position.x, p.position.y, p.position.z])
    rt, tt = compose(*invert(*truth[stamps[0]]), *truth[stamps[-1]])
    assert np.linalg.norm(t - tt) < 0.02
    assert np.degrees(np.abs(rotation_error_components(r, rt))).max() < 0.3
    cov = np.array(o.pose.covariance).reshape(6, 6)
    cov0 = np.array(got['odom'][0].pose.covariance).reshape(6, 6)
    assert np.all(np.diag(cov) > 0) and np.trace(cov) > np.trace(cov0)
    assert np.allclose(cov, cov.T)
    # the walker moves forward (optical z) at ~1.2 m/s
    assert 0.5 < o.twist.twist.linear.z < 2.0


def test_blank_pair_publishes_nothing_and_says_why(graph):
    node, ex, send, got = graph
    frames, truth = load_frames([30, 31, 32, 33, 34])
    stamps = [_ns(f[0].header.stamp) for f in frames]
    blank = list(frames[2])
    for img in blank[:2]:                       # a covered lens: both images black
        img.data = bytes(len(img.data))
    sequence = [frames[0], frames[1], tuple(blank), frames[3], frames[4]]
    for i, f in enumerate(sequence):
        send(*f)
        assert spin_until(ex, lambda i=i: node.frames_done == i + 1, timeout=15)
    assert spin_until(ex, lambda: len(got['odom']) == 3, timeout=5)
    # /egomotion only from a pair to the one just before it: 31 (from 30) and 34 (from 33);
    # not for the blank pair, nor for 33, whose motion is from 31 across the blank one
    assert [_ns(m.header.stamp) for m in got['motion']] == [stamps[1], stamps[4]]
    # the odometry bridges the gap: 31, 33 (from 31) and 34
    assert [_ns(o.header.stamp) for o in got['odom']] == [stamps[1], stamps[3], stamps[4]]
    p = got['odom'][1].pose.pose
    r = quaternion_to_matrix([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])
    t = np.array([p.position.x, p.position.y, p.position.z])
    rt, tt = compose(*invert(*truth[stamps[0]]), *truth[stamps[3]])
    assert np.linalg.norm(t - tt) < 0.02
    assert np.degrees(np.abs(rotation_error_components(r, rt))).max() < 0.3
    warn = [s for a in got['diag'] for s in a.status
            if s.name == 'asmonc_vision: egomotion' and s.level == b'\x01']
    assert any('too few features' in s.message and 'no motion published' in s.message
               for s in warn)
    assert spin_until(ex, lambda: any(s.level == b'\x00' for a in got['diag'] for s in a.status
                                      if s.name == 'asmonc_vision: egomotion'), timeout=3)


def test_values_given_for_no_parameter_are_named(ros_context):
    """A value in a params file or on the command line under a name the node does not
    have is named in a warning (run_node), not run as if it were a setting."""
    from rclpy.parameter import Parameter

    from asmonc_vision.nodes.common import undeclared_overrides
    from asmonc_vision.nodes.egomotion_node import EgomotionNode
    node = EgomotionNode(context=ros_context, parameter_overrides=[
        Parameter('min_inliers', value=12), Parameter('motion.min_inliers', value=12)])
    try:
        assert undeclared_overrides(node) == ['min_inliers']
        assert node.motion_config.min_inliers == 12
    finally:
        node.destroy_node()

