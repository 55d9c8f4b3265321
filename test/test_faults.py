"""The fault injector's spec and its changes to serialized messages (no ROS graph)."""
import math

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image, Imu

from asmonc_vision.io.bagio import ImageFormatError
from asmonc_vision.faults import KINDS, FaultPlan, parse_faults
from asmonc_vision.nodes.conversions import image_msg_to_gray, stereo_camera_from_infos

T0 = 1_700_000_000_000_000_000
L_IMG, R_IMG = '/stereo/left/image_rect', '/stereo/right/image_rect'
L_INFO, R_INFO = '/stereo/left/camera_info', '/stereo/right/camera_info'


def image(t_ns, w=8, h=4):
    m = Image(height=h, width=w, encoding='mono8', step=w,
              data=bytes(range(w * h)))
    m.header.stamp.sec, m.header.stamp.nanosec = t_ns // 10**9, t_ns % 10**9
    return serialize_message(m)


def info(t_ns, right=False, w=8, h=4):
    m = CameraInfo(width=w, height=h)
    m.p = [100.0, 0.0, 4.0, -12.0 if right else 0.0, 0.0, 100.0, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    m.header.stamp.sec, m.header.stamp.nanosec = t_ns // 10**9, t_ns % 10**9
    return serialize_message(m)


def at(s):
    return T0 + int(round(s * 1e9))


def test_parse_spec():
    f = parse_faults('kill=detector@2; stall@3+1.5, skew=0.05@1')
    assert [(x.kind, x.arg, x.start, x.duration) for x in f] == [
        ('kill', 'detector', 2.0, 0.0), ('stall', '', 3.0, 1.5), ('skew', '0.05', 1.0, 0.0)]
    assert str(f[1]) == 'stall@3+1.5'
    assert parse_faults('') == []
    for bad, why in [('stall', '@START'), ('boom@1', 'unknown kind'), ('stall@x', 'numbers'),
                     ('stall@-1', '>= 0'), ('stall@nan', 'finite'), ('kill@1', 'needs the node'),
                     ('skew=abc@1', 'finite number'), ('imu_jump=inf@1', 'finite number')]:
        with pytest.raises(ValueError, match=why):
            parse_faults(bad)
    assert len(KINDS) == 14


def test_window_and_untouched_messages():
    # (compared as the same bytes: CDR alignment padding differs between serializations)
    plan = FaultPlan(parse_faults('stall@1+0.5'), T0)
    a, b = image(at(0.9)), image(at(1.6))
    assert plan.apply(L_IMG, a, at(0.9)) == [a]
    assert plan.apply(L_IMG, image(at(1.0)), at(1.0)) == []
    assert plan.apply(L_INFO, info(at(1.5)), at(1.5)) == []
    assert plan.apply('/inclinometer/imu', b'x', at(1.2)) == [b'x']   # not a camera topic
    assert plan.apply(L_IMG, b, at(1.6)) == [b]
    assert plan.counts == {'stall': 2}
    assert not FaultPlan(parse_faults('kill=detector@1'), T0)     # process faults: none here


def test_drop_every_second_pair_and_dup():
    plan = FaultPlan(parse_faults('drop@0+1'), T0)
    kept = [bool(plan.apply(topic, image(at(0.1 * k)), at(0.1 * k)))
            for k in range(4) for topic in (L_IMG, R_IMG)]
    assert kept == [True, True, False, False, True, True, False, False]
    plan = FaultPlan(parse_faults('dup@0'), T0)
    a = image(T0)
    assert plan.apply(L_IMG, a, T0) == [a] * 2


def test_reorder_and_skew_move_stamps():
    plan = FaultPlan(parse_faults('reorder@0+1'), T0)
    stamps = []
    for k in range(3):
        (m,) = plan.apply(L_IMG, image(at(0.1 * k)), at(0.1 * k))
        s = deserialize_message(m, Image).header.stamp
        stamps.append(s.sec * 10**9 + s.nanosec - T0)
    assert stamps == [0, 100_000_000 - 250_000_000, 200_000_000]   # back past its forerunner
    plan = FaultPlan(parse_faults('skew=0.03@0+1'), T0)
    a = image(T0)
    assert plan.apply(L_IMG, a, T0) == [a]
    (m,) = plan.apply(R_IMG, image(T0), T0)
    assert deserialize_message(m, Image).header.stamp.nanosec == 30_000_000


@pytest.mark.parametrize('kind', ['encoding', 'truncate'])
def test_broken_images_are_refused_by_the_conversion(kind):
    (m,) = FaultPlan(parse_faults(f'{kind}@0'), T0).apply(L_IMG, image(T0), T0)
    with pytest.raises(ImageFormatError):
        image_msg_to_gray(deserialize_message(m, Image))


def test_size_halves_the_width_keeping_a_valid_image():
    (m,) = FaultPlan(parse_faults('size@0'), T0).apply(L_IMG, image(T0), T0)
    img = image_msg_to_gray(deserialize_message(m, Image))
    full = np.arange(32, dtype=np.uint8).reshape(4, 8)
    assert np.array_equal(img, full[:, :4])


@pytest.mark.parametrize('kind,topic', [('nan_info', L_INFO), ('inf_info', L_INFO),
                                        ('zero_baseline', R_INFO)])
def test_broken_camera_infos_are_refused(kind, topic):
    plan = FaultPlan(parse_faults(f'{kind}@0'), T0)
    left = deserialize_message(info(T0), CameraInfo)
    right = deserialize_message(info(T0, right=True), CameraInfo)
    assert stereo_camera_from_infos(left, right).baseline == pytest.approx(0.12)
    (m,) = plan.apply(topic, info(T0, right=topic == R_INFO), T0)
    bad = deserialize_message(m, CameraInfo)
    with pytest.raises(ValueError):
        if topic == L_INFO:
            stereo_camera_from_infos(bad, right)
        else:
            stereo_camera_from_infos(left, bad)


def test_imu_jump_turns_pitch_by_the_angle():
    from asmonc_vision.io.bagio import imu_to_rpy_var
    from asmonc_vision.core.gait.rotations import rpy_to_quaternion
    m = Imu()
    q = rpy_to_quaternion(np.array([0.05, 0.3, 1.0]))   # x, y, z, w
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = map(float, q)
    m.orientation_covariance[0] = 1e-4
    (out,) = FaultPlan(parse_faults('imu_jump=20@0'), T0).apply(
        '/inclinometer/imu', serialize_message(m), T0)
    rpy, _ = imu_to_rpy_var(deserialize_message(out, Imu))
    assert rpy[1] == pytest.approx(0.3 + math.radians(20), abs=0.05)
    assert FaultPlan(parse_faults('imu_silent@0'), T0).apply(
        '/inclinometer/imu', serialize_message(m), T0) == []


def _probe(ctx):
    import threading

    from asmonc_vision.nodes.stereo_input import StereoInputConfig, StereoInputNode

    class Probe(StereoInputNode):
        def __init__(self, **kw):
            super().__init__('stereo_probe', 'probe', **kw)
            self.done = threading.Event()
            self.cams = []
            self.start_stereo_input(StereoInputConfig())

        def process_pair(self, pair, left, right, cam):
            self.cams.append(cam)
            self.done.set()

    return Probe(context=ctx)


def _send_pair(node, t):
    for side, right in (('left', False), ('right', True)):
        node._on_info(side, deserialize_message(info(at(t), right), CameraInfo))
    node._on_image('left', deserialize_message(image(at(t)), Image))
    node._on_image('right', deserialize_message(image(at(t)), Image))


def test_stereo_input_uses_the_camera_info_stamped_like_the_pair(ros_context):
    # camera_infos travel on their own topics: a bad info of the frame before (here a
    # zero baseline) must not spoil a good pair whose own info comes after its images
    node = _probe(ros_context)
    try:
        with node._cv:       # hold the worker until the pair's own infos are in
            bad = deserialize_message(info(at(0.1), right=True), CameraInfo)
            bad.p[3] = 0.0                   # the frame before: a zero baseline
            node._on_info('left', deserialize_message(info(at(0.1)), CameraInfo))
            node._on_info('right', bad)
            node._on_info('left', deserialize_message(info(at(0.2)), CameraInfo))
            node._on_image('left', deserialize_message(image(at(0.2)), Image))
            node._on_image('right', deserialize_message(image(at(0.2)), Image))
            # the pair's right camera_info comes after its images
            node._on_info('right', deserialize_message(info(at(0.2), right=True), CameraInfo))
        assert node.done.wait(5.0)
        assert node.cams[0].baseline == pytest.approx(0.12)
        assert node.frames_bad == 0
    finally:
        node.destroy_node()


def test_stereo_input_reports_missing_pairs(ros_context):
    import time
    node = _probe(ros_context)
    try:
        for k in range(5):
            _send_pair(node, 0.1 * k)
        _send_pair(node, 0.9)            # 0.5 .. 0.8 never came
        deadline = time.monotonic() + 5.0
        while len(node.cams) < 6 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(node.cams) == 6 and node.frames_missing == 4
        assert node.diag.level == 1 and 'missing' in node.diag._status.message
        _send_pair(node, 1.0)            # a usual step again: nothing more missing
        _send_pair(node, 0.85)           # a stamp out of order (skipped) ...
        _send_pair(node, 1.1)            # ... is no gap for the pair after it
        while len(node.cams) < 8 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(node.cams) == 8 and node.frames_missing == 4
    finally:
        node.destroy_node()


def test_the_stamps_a_fault_changes_on_a_topic_and_every_stamp_in_bag_order():
    """`faults.changed_stamps` (what `asmonc run` leaves out of the last input it waits
    for) and `bagio.header_stamps` on a bundled bag: the inclinometer silent for 0.5 s
    changes exactly the readings in that window, and the stamps come in the bag's order,
    each once."""
    from asmonc_vision.faults import changed_stamps
    from asmonc_vision.io import bagio
    from asmonc_vision.io.bagplay import BagSource
    from conftest import BAGS

    bag = BAGS / 'walk_obstacles'
    imu = '/inclinometer/imu'
    stamps = bagio.header_stamps(bag, (imu, L_IMG))
    readings = stamps[imu]
    n = sum(1 for _ in bagio.read_messages(bag, [imu]))
    assert len(readings) == n > 100 and readings == sorted(readings)
    assert stamps[L_IMG] == bagio.pair_stamps(bag)       # every pair whole
    changed = changed_stamps(BagSource(bag), parse_faults('imu_silent@1.5+0.5'), (imu,))[imu]
    window = {s for s in readings if T0 + 1_500_000_000 <= s < T0 + 2_000_000_000}
    assert changed and abs(len(changed) - len(window)) <= 1 and changed <= set(readings)
    assert changed_stamps(BagSource(bag), parse_faults('stall@1.0+0.5'), (imu,)) == {imu: set()}
