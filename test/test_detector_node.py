"""detector_node over real topics, in-process: frames from the committed static bag."""
import contextlib
import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image

from asmonc_vision.core.surface_kernels import RULES
from asmonc_vision.nodes.common import IMAGE_QOS, RESULT_QOS
from asmonc_vision.nodes.detector_node import DetectorNode
from asmonc_vision.nodes.stereo_input import StereoPairer
from asmonc_vision_msgs.msg import GroundPlane, ObstacleArray
from conftest import BAGS, read_messages, spin_until, stereo_sender, stereo_types

TYPES = stereo_types()


def load_frames(bag, indices):
    """[(left, right, left_info, right_info)] rclpy messages of the given frame indices."""
    per_topic = read_messages(bag, TYPES)
    return [tuple(per_topic[t][i] for t in TYPES) for i in indices]


@pytest.fixture
def graph(ros_context):
    # (debug image scaled down to 160 px wide: the scaling path is exercised at 320x240)
    with detector_graph(ros_context, [Parameter('publish_debug_image', value=True),
                                      Parameter('debug_image_max_width', value=160)]) as g:
        yield g


@pytest.fixture
def graph_ego(ros_context):
    """The detector with the motion input on (``use_egomotion``; off by default)."""
    with detector_graph(ros_context, [Parameter('use_egomotion', value=True)]) as g:
        yield g


@contextlib.contextmanager
def detector_graph(ctx, overrides):
    """(detector, executor, send, received) with the detector's parameters
    ``overrides``, torn down on leaving the ``with``."""
    det = DetectorNode(context=ctx, parameter_overrides=overrides)
    probe = Node('probe', context=ctx)
    got = {'obstacles': [], 'plane': [], 'debug': []}
    probe.create_subscription(ObstacleArray, '/obstacles', got['obstacles'].append, RESULT_QOS)
    probe.create_subscription(GroundPlane, '/ground_plane', got['plane'].append, RESULT_QOS)
    probe.create_subscription(Image, '/detector/debug_image', got['debug'].append, IMAGE_QOS)
    pubs, send = stereo_sender(probe)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(det)
    ex.add_node(probe)
    assert spin_until(ex, lambda: all(p.get_subscription_count() >= 1 for p in pubs.values())
                      and probe.count_publishers('/obstacles') >= 1)
    try:
        yield det, ex, send, got
    finally:
        ex.shutdown()
        det.destroy_node()
        probe.destroy_node()


def test_one_result_per_pair_and_obstacles_found(graph):
    det, ex, send, got = graph
    frames = load_frames(BAGS / 'static_obstacles', [0, 1, 2, 3, 45, 46, 47])
    for i, f in enumerate(frames):
        send(*f)
        assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
    stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in got['obstacles']]
    assert stamps == [(f[0].header.stamp.sec, f[0].header.stamp.nanosec) for f in frames]
    assert all(m.header.frame_id == 'stereo_left_optical_frame' for m in got['obstacles'])
    assert spin_until(ex, lambda: len(got['plane']) == len(frames))
    assert got['plane'][0].status == GroundPlane.INITIALISING
    assert got['plane'][-1].status == GroundPlane.TRACKING
    # the paper's rig: cameras 1.25 m above the ground
    assert got['plane'][-1].height == pytest.approx(1.25, abs=0.05)
    assert got['obstacles'][0].obstacles == []  # initialising: nothing reported
    assert len(got['obstacles'][-1].obstacles) >= 3  # boxes, post and bollard are up
    assert spin_until(ex, lambda: len(got['debug']) >= 1)
    assert got['debug'][-1].encoding == 'bgr8'
    assert (got['debug'][-1].width, got['debug'][-1].height) == (160, 120)
    assert got['debug'][-1].step == 3 * 160 and len(got['debug'][-1].data) == 3 * 160 * 120


def test_a_rig_off_its_calibration_is_corrected_and_reported(ros_context):
    """Right images 1.5 px below the left's rows (a rig knocked off its calibration):
    the detector measures it, resamples the right image, still finds the obstacles, and
    reports the misalignment in /diagnostics as a WARN."""
    import cv2
    import numpy as np

    from asmonc_vision.nodes.conversions import array_to_image_msg
    from conftest import diagnostic_statuses

    def shifted(img):
        a = np.frombuffer(bytes(img.data), np.uint8).reshape(img.height, img.width)
        m = np.float32([[1, 0, 0], [0, 1, 1.5]])
        return array_to_image_msg(cv2.warpAffine(a, m, (img.width, img.height),
                                                 flags=cv2.INTER_LINEAR,
                                                 borderMode=cv2.BORDER_REPLICATE),
                                  img.header)

    with detector_graph(ros_context, []) as (det, ex, send, got):
        probe = Node('diag_probe', context=ros_context)
        ex.add_node(probe)
        diags = diagnostic_statuses(probe, 'asmonc_vision: detector')
        frames = load_frames(BAGS / 'static_obstacles', list(range(0, 8)) + [45, 46, 47])
        for i, (left, right, li, ri) in enumerate(frames):
            send(left, shifted(right), li, ri)
            assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
        assert spin_until(ex, lambda: any('misaligned' in d.message for d in diags),
                          timeout=5)
        last = [d for d in diags if 'misaligned' in d.message][-1]
        assert last.level == bytes([1])
        values = {kv.key: kv.value for kv in last.values}
        assert float(values['misalignment_px']) == pytest.approx(1.5, abs=0.3)
        assert values['misalignment_corrected'] == 'True'
        # the tiled pavement shows its edges: the edge threshold is not lowered
        assert float(values['edge_threshold']) == pytest.approx(4.0)
        # how far the ground surface ahead is known, and what ended it
        assert float(values['ground_known_m']) >= 2.0
        ended = values['ground_ended_by']
        assert ended == '' or ended.split()[0] in (*RULES, 'rule_anchor'), ended
        assert len(got['obstacles'][-1].obstacles) >= 3
        ex.remove_node(probe)
        probe.destroy_node()



def test_a_right_camera_with_its_own_principal_point_is_aligned(graph):
    """Pairs rectified without CALIB_ZERO_DISPARITY: the right camera_info's principal
    point 6 px left of the left one's (P[0,2]), its image content with it. The detector
    moves the right image back (`core.camera.align_right_image`): the same ground
    (1.25 m) and obstacles as from the pair as recorded; taken as it stands, each
    disparity would be 6 px off."""
    import copy

    import numpy as np

    from asmonc_vision.nodes.conversions import array_to_image_msg

    from asmonc_vision.core.gpod import GpodDetector
    from asmonc_vision.nodes.conversions import image_msg_to_gray, stereo_camera_from_infos

    det, ex, send, got = graph
    frames = load_frames(BAGS / 'static_obstacles', [0, 1, 2, 3, 45, 46, 47])
    ref = GpodDetector()          # the pairs as recorded
    for left, right, li, ri in frames:
        r = ref.process(image_msg_to_gray(left), image_msg_to_gray(right),
                        stereo_camera_from_infos(li, ri))
    for i, (left, right, li, ri) in enumerate(frames):
        a = np.frombuffer(bytes(right.data), np.uint8).reshape(right.height, right.width)
        moved = array_to_image_msg(np.ascontiguousarray(
            np.concatenate([a[:, 6:], a[:, -1:].repeat(6, 1)], 1)), right.header)
        ri = copy.deepcopy(ri)
        ri.p[2] -= 6.0
        send(left, moved, li, ri)
        assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
    assert spin_until(ex, lambda: len(got['plane']) == len(frames))
    assert got['plane'][-1].status == GroundPlane.TRACKING
    last = got['plane'][-1]
    assert last.height == pytest.approx(1.25, abs=0.05)
    # (a disparity offset alone would be taken into the plane's c, and every range off)
    np.testing.assert_allclose([last.a, last.b, last.c], r.plane_abc, atol=0.05)
    assert len(got['obstacles'][-1].obstacles) >= 3

def test_walking_tracks_take_egomotion_as_their_motion_input(graph_ego):
    """Walking: with the pair's /egomotion (here from the core estimator on the same
    frames) the node's obstacle tracks are carried from frame to frame and keep their
    ids; the detector uses one motion per pair after the first."""
    from geometry_msgs.msg import TransformStamped

    from asmonc_vision.core.motion import EgomotionEstimator
    from asmonc_vision.core.rotations import matrix_to_quaternion
    from asmonc_vision.nodes.conversions import image_msg_to_gray, stereo_camera_from_infos

    det, ex, send, got = graph_ego
    probe = Node('ego_probe', context=det.context)
    pub = probe.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
    ex.add_node(probe)
    assert spin_until(ex, lambda: pub.get_subscription_count() >= 1)
    frames = load_frames(BAGS / 'walk_obstacles', range(16, 32))   # walking
    est = EgomotionEstimator()
    motions = []
    for left, right, li, ri in frames:
        cam = stereo_camera_from_infos(li, ri)
        stamp = left.header.stamp.sec * 10 ** 9 + left.header.stamp.nanosec
        r = est.process(image_msg_to_gray(left), image_msg_to_gray(right), cam, stamp)
        motions.append(r.motion if r.ok else None)
    assert sum(m is not None for m in motions) >= 11
    for i, f in enumerate(frames):
        send(*f)
        if motions[i] is not None:
            msg = TransformStamped()
            msg.header = f[0].header
            msg.child_frame_id = f[0].header.frame_id
            q = matrix_to_quaternion(motions[i].R)
            msg.transform.rotation.x, msg.transform.rotation.y = float(q[0]), float(q[1])
            msg.transform.rotation.z, msg.transform.rotation.w = float(q[2]), float(q[3])
            t = motions[i].t
            msg.transform.translation.x, msg.transform.translation.y = float(t[0]), float(t[1])
            msg.transform.translation.z = float(t[2])
            pub.publish(msg)
        assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
    # a motion is taken for every pair with a ground plane (none while initialising)
    assert spin_until(ex, lambda: len(got['plane']) == len(frames))
    tracking = [p.status == GroundPlane.TRACKING for p in got['plane']]
    assert det.motions_used == sum(m is not None and tr for m, tr in zip(motions[1:],
                                                                         tracking[1:]))
    # the same obstacle keeps its track id from frame to frame while walking
    ids = [{o.id for o in m.obstacles} for m in got['obstacles'][3:]]
    carried = sum(len(a & b) for a, b in zip(ids, ids[1:]))
    assert carried >= 10 and all(i > 0 for s_ in ids for i in s_)
    probe.destroy_node()


def test_a_silent_egomotion_publisher_never_stalls_detection(graph_ego, capfd):
    """Someone publishes /egomotion but no usable motion comes (one malformed message):
    every pair is still detected and published (each waits at most egomotion_wait, none
    while others are queued)."""
    from geometry_msgs.msg import TransformStamped

    det, ex, send, got = graph_ego
    probe = Node('silent_ego', context=det.context)
    pub = probe.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
    ex.add_node(probe)
    assert spin_until(ex, lambda: pub.get_subscription_count() >= 1)
    frames = load_frames(BAGS / 'static_obstacles', [0, 1, 2, 3, 45, 46, 47, 48])
    bad = TransformStamped()                 # a zero quaternion: warned about, ignored
    bad.header = frames[4][0].header
    bad.transform.rotation.w = 0.0
    pub.publish(bad)
    for f in frames:
        send(*f)
    assert spin_until(ex, lambda: len(got['obstacles']) == len(frames), timeout=20)
    assert det.frames_dropped == 0 and det.motions_used == 0
    assert '/egomotion with an invalid rotation or translation ignored' in capfd.readouterr().err
    assert len(got['obstacles'][-1].obstacles) >= 3    # still-rig tracks and detections
    probe.destroy_node()


def test_bad_inputs_are_logged_skipped_and_the_node_keeps_going(graph, capfd):
    det, ex, send, got = graph
    good = load_frames(BAGS / 'static_obstacles', [0, 1, 2, 15])  # 15: 1.5 s later

    # 1. a wrong encoding
    left, right, li, ri = load_frames(BAGS / 'static_obstacles', [0])[0]
    left.encoding = right.encoding = '16UC1'
    send(left, right, li, ri)
    assert spin_until(ex, lambda: det.frames_bad >= 1, timeout=10)
    # 2. left and right of different sizes
    left, right, li, ri = load_frames(BAGS / 'static_obstacles', [0])[0]
    right.height, right.data = right.height // 2, bytes(right.data)[:len(right.data) // 2]
    right.header.stamp.nanosec += 1  # a new stamp, so it is a new pair
    left.header.stamp.nanosec += 1
    send(left, right, li, ri)
    assert spin_until(ex, lambda: det.frames_bad >= 2, timeout=10)
    # 3. a pair whose stamps do not match: never paired, dropped when it expires
    left, right, li, ri = load_frames(BAGS / 'static_obstacles', [0])[0]
    left.header.stamp.nanosec += 2
    right.header.stamp.nanosec += 50_000_002
    send(left, right, li, ri)
    assert got['obstacles'] == []
    # the node still works on good pairs (which also push the mismatched ones out)
    for f in good:
        send(*f)
    assert spin_until(ex, lambda: len(got['obstacles']) == len(good), timeout=15)
    assert spin_until(ex, lambda: det.frames_bad >= 3, timeout=10)
    err = capfd.readouterr().err
    assert "unsupported image encoding '16UC1'" in err
    assert 'left image is 320x240 but right is 320x120' in err
    assert 'has no partner with the same stamp' in err


def test_a_pair_waits_for_a_camera_info_that_comes_late(ros_context):
    """A camera_info sent before the detector saw its publisher comes again only at the
    publisher's next DDS heartbeat (3 s in Fast DDS): the first pair waits for it
    (info_wait 8 s) instead of being skipped."""
    with detector_graph(ros_context, []) as (det, ex, send, got):
        frames = load_frames(BAGS / 'static_obstacles', [0, 1])
        # the images alone, then the camera_infos 3.5 s later
        send(*frames[0][:2])
        end = time.monotonic() + 3.5
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        assert got['obstacles'] == [] and det.frames_bad == 0
        send(*frames[1])              # its infos (and the next pair)
        assert spin_until(ex, lambda: len(got['obstacles']) == 2, timeout=15)
        assert det.frames_bad == 0


def test_without_camera_info_pairs_are_skipped_at_once_after_the_first_wait(ros_context, capfd):
    """No camera_info at all: the first pair waits info_wait, later ones are skipped at
    once (not one per info_wait, which would overflow the queue), and the first
    camera_info ends it."""
    with detector_graph(ros_context, [Parameter('info_wait', value=2.0)]) as \
            (det, ex, send, got):
        frames = load_frames(BAGS / 'static_obstacles', [0, 1, 2, 3, 4, 5])
        send(*frames[0][:2])
        assert spin_until(ex, lambda: det.frames_bad == 1, timeout=10)
        for f in frames[1:5]:
            send(*f[:2])
        # one info_wait for each would take 8 s
        assert spin_until(ex, lambda: det.frames_bad == 5, timeout=3)
        assert det.frames_dropped == 0 and got['obstacles'] == []
        assert 'no camera_info on /stereo/{left,right}/camera_info; pair skipped' in \
            capfd.readouterr().err
        send(*frames[5])
        assert spin_until(ex, lambda: len(got['obstacles']) == 1, timeout=15)


def test_pairer_pairs_by_stamp_and_expires_orphans():
    p = StereoPairer(max_skew_ns=0, timeout_ns=1_000_000_000)
    assert p.add('left', 100, 'L1') is None
    assert p.add('right', 200, 'R2') is None
    assert p.add('right', 100, 'R1') == ('L1', 'R1')
    assert p.add('left', 200, 'L2') == ('L2', 'R2')
    assert p.add('left', 300, 'L3') is None
    assert p.expire() == []
    assert p.add('left', 2_000_000_000, 'L4') is None
    assert p.expire() == [('left', 300)]


def test_parameter_out_of_range_is_a_clear_error_and_exit_2():
    import os
    import subprocess
    import sys
    res = subprocess.run(
        [sys.executable, '-m', 'asmonc_vision.nodes.detector_node', '--ros-args',
         '-p', 'gpod.threshold.px:=-1.0'],
        env=dict(os.environ), capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert 'invalid settings' in res.stderr and 'gpod.threshold.px' in res.stderr


def test_a_setting_that_does_not_exist_is_a_clear_error_and_exit_2():
    """A detector setting under a name it does not have (misspelt, or from before the
    settings were grouped by stage) stops the node rather than running the default."""
    import os
    import subprocess
    import sys
    res = subprocess.run(
        [sys.executable, '-m', 'asmonc_vision.nodes.detector_node', '--ros-args',
         '-p', 'gpod.threshold_k:=3.0', '-p', 'gpod.threshold.k:=3.0'],
        env=dict(os.environ), capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert 'no such setting: gpod.threshold_k ' in res.stderr, res.stderr[-2000:]


def test_the_map_takes_odometry_and_never_waits(ros_context):
    """With the evidence map on, the detector never waits for /egomotion (a silent
    publisher of it is there, with a 2 s wait configured): each pair's map motion is
    predicted from the /egomotion/odometry received by then (here each pair's pose
    arrives only after the next pair is sent), so the map is placed on every walking
    pair with a plane instead of being cleared for want of a motion."""
    import numpy as np
    from geometry_msgs.msg import TransformStamped
    from nav_msgs.msg import Odometry

    from asmonc_vision.core.motion import EgomotionEstimator, compose
    from asmonc_vision.core.rotations import matrix_to_quaternion
    from asmonc_vision.nodes.conversions import image_msg_to_gray, stereo_camera_from_infos

    frames = load_frames(BAGS / 'walk_obstacles', range(16, 30))   # walking
    est = EgomotionEstimator()
    poses, R, t = [], np.eye(3), np.zeros(3)
    for left, right, li, ri in frames:
        cam = stereo_camera_from_infos(li, ri)
        stamp = left.header.stamp.sec * 10 ** 9 + left.header.stamp.nanosec
        r = est.process(image_msg_to_gray(left), image_msg_to_gray(right), cam, stamp)
        if r.ok:
            R, t = compose(R, t, r.motion.R, r.motion.t)
        poses.append((R, t) if r.ok or not poses else None)
    assert sum(p is not None for p in poses) >= 12
    with detector_graph(ros_context, [Parameter('map.enabled', value=True),
                                      Parameter('egomotion_wait', value=2.0),
                                      Parameter('publish_debug_image', value=False)]) as g:
        det, ex, send, got = g
        probe = Node('odom_probe', context=det.context)
        silent = probe.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
        odom = probe.create_publisher(Odometry, '/egomotion/odometry', RESULT_QOS)
        ex.add_node(probe)
        try:
            assert spin_until(ex, lambda: odom.get_subscription_count() >= 1)
            assert silent.get_subscription_count() == 0   # nobody waits for /egomotion
            took = []
            for i, f in enumerate(frames):
                t0 = time.monotonic()
                send(*f)
                assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
                took.append(time.monotonic() - t0)
                if poses[i] is not None:       # pair i's pose, known once pair i is done
                    msg = Odometry()
                    msg.header = f[0].header
                    q = matrix_to_quaternion(poses[i][0])
                    o = msg.pose.pose.orientation
                    o.x, o.y, o.z, o.w = (float(v) for v in q)
                    p = msg.pose.pose.position
                    p.x, p.y, p.z = (float(v) for v in poses[i][1])
                    odom.publish(msg)
                    n = det.motion_predictor._odom
                    assert spin_until(ex, lambda n=n: det.motion_predictor._odom is not n,
                                      timeout=5)
            assert spin_until(ex, lambda: len(got['plane']) == len(frames))
        finally:
            ex.remove_node(probe)
            probe.destroy_node()
    assert max(took) < 1.9
    pred = det.motion_predictor
    assert pred.predictions >= len(frames) - 3 and pred.measured == 0   # all extrapolated
    # from the pose of the pair before (~0.1 s), as /diagnostics says
    assert pred.ahead_ns is not None and 0.05e9 < pred.ahead_ns < 0.25e9, pred.ahead_ns
    assert 50 <= int(det._motion_ahead_ms()) <= 250
    # never cleared while walking: every pair with a ground plane is placed
    tracking = sum(p.status == GroundPlane.TRACKING for p in got['plane'])
    assert tracking >= len(frames) - 3
    assert det.perception.map.placed_pairs == tracking


def test_a_motion_over_a_pair_the_detector_processed_is_not_taken_as_its_own(graph_ego):
    """The egomotion node, on a busy CPU, skips pairs: its motion for pair 4 is then from
    pair 2 (the /egomotion before it). The detector, which processed pair 3, must not take
    it as pair 3 -> 4; the next motion (4 -> 5) is its own again."""
    from geometry_msgs.msg import TransformStamped

    det, ex, send, got = graph_ego
    probe = Node('skipping_ego', context=det.context)
    pub = probe.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
    ex.add_node(probe)
    assert spin_until(ex, lambda: pub.get_subscription_count() >= 1)
    frames = load_frames(BAGS / 'static_obstacles', range(8))      # a still rig
    published = [1, 2, 4, 5, 6, 7]                                  # pair 3 skipped
    for i, f in enumerate(frames):
        if i in published:
            msg = TransformStamped()                                # no motion: identity
            msg.header = f[0].header
            msg.child_frame_id = f[0].header.frame_id
            msg.transform.rotation.w = 1.0
            pub.publish(msg)
            assert spin_until(ex, lambda: pub.get_subscription_count() >= 1)
        send(*f)
        assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
    assert spin_until(ex, lambda: len(got['plane']) == len(frames))
    tracking = [p.status == GroundPlane.TRACKING for p in got['plane']]
    assert tracking[4], 'the test needs a plane at pair 4 to tell the motions apart'
    assert det.motions_used == sum(tracking[i] for i in (1, 2, 5, 6, 7))
    probe.destroy_node()


def test_the_inclinometer_gives_each_pair_its_up_direction(graph):
    """The latest /inclinometer/imu orientation is the up direction of a pair stamped
    within gravity_prior_max_age_s of it; an older sample gives none."""
    import math

    import numpy as np
    from sensor_msgs.msg import Imu

    from asmonc_vision.core.rotations import rpy_to_quaternion

    det, ex, send, got = graph
    frames = load_frames(BAGS / 'clear_static', range(0, 2))
    probe = Node('imu_probe', context=det.context)
    pub = probe.create_publisher(Imu, '/inclinometer/imu', RESULT_QOS)
    ex.add_node(probe)
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1)
        pitch = math.radians(10.0)
        for i, (f, age_s) in enumerate(zip(frames, (0.05, 1.0))):
            msg = Imu()
            stamp_ns = (f[0].header.stamp.sec * 10 ** 9 + f[0].header.stamp.nanosec
                        - int(age_s * 1e9))
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10 ** 9)
            o = msg.orientation
            o.x, o.y, o.z, o.w = (float(v) for v in rpy_to_quaternion([0.0, pitch, 0.0]))
            pub.publish(msg)
            assert spin_until(ex, lambda s=stamp_ns: det._imu is not None
                              and det._imu[0] == s)
            send(*f)
            assert spin_until(ex, lambda i=i: len(got['obstacles']) == i + 1, timeout=15)
            up = det.detector._up
            if age_s < det.gpod_config.plane.gravity_prior_max_age_s:
                assert np.allclose(up, [0.0, -math.cos(pitch), -math.sin(pitch)])
            else:
                assert up is None
    finally:
        ex.remove_node(probe)
        probe.destroy_node()
