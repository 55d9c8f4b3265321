"""stereo_capture_node over real topics, in-process: folder -> node -> /stereo/*."""
from __future__ import annotations

import os
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import diagnostic_statuses

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402

from asmonc_vision.nodes.capture_node import StereoCaptureNode  # noqa: E402
from asmonc_vision.nodes.common import IMAGE_QOS  # noqa: E402
from asmonc_vision.nodes.conversions import (image_msg_to_gray,  # noqa: E402
                                             stamp_to_ns, stereo_camera_from_infos)

#: the KITTI sequence's rectified cameras 2 and 3 (shared/data/kitti_road_seq/calib.txt)
KITTI_F = 718.856
KITTI_CX, KITTI_CY = 607.1928, 185.2157
KITTI_P2_TX, KITTI_P3_TX = 45.38225, -337.2877   # P[0,3], pixel-metres relative to camera 0
KITTI_B = (KITTI_P2_TX - KITTI_P3_TX) / KITTI_F   # 0.5323 m


def _kitti_calib_text() -> str:
    def row(name, tx):
        vals = [KITTI_F, 0, KITTI_CX, tx, 0, KITTI_F, KITTI_CY, 0, 0, 0, 1, 0]
        return f'{name}: ' + ' '.join(f'{v:.12e}' for v in vals)
    return '\n'.join([row('P0', 0.0), row('P1', -386.1448), row('P2', KITTI_P2_TX),
                      row('P3', KITTI_P3_TX)]) + '\n'

#: a generous bound so a broken node fails the test instead of hanging it (not a speed test)
DEADLINE = 20.0
ERROR = b'\x02'


def _domain_id(offset: int) -> int:
    return 1 + (os.getpid() * 3 + offset) % 100


@pytest.fixture
def ros(request):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=_domain_id(len(request.node.name)))
    ex = SingleThreadedExecutor(context=ctx)
    nodes = []

    def add(node):
        nodes.append(node)
        ex.add_node(node)
        return node

    def spin_until(pred, what):
        end = time.monotonic() + DEADLINE
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.02)
            if pred():
                return
        raise AssertionError(f'timed out waiting for {what}')

    yield ctx, add, spin_until
    for n in nodes:
        ex.remove_node(n)
        n.destroy_node()
    ex.shutdown()
    rclpy.try_shutdown(context=ctx)


def _kitti_like_folder(root: Path, n: int = 3, right_size=(48, 64)) -> list:
    """A KITTI-style sequence: image_2/, image_3/, calib.txt; returns the left images."""
    rng = np.random.default_rng(0)
    (root / 'image_2').mkdir()
    (root / 'image_3').mkdir()
    lefts = []
    for k in range(n):
        left = rng.integers(0, 255, (48, 64), dtype=np.uint8)
        right = np.roll(left, -5, axis=1)[:right_size[0], :right_size[1]]
        cv2.imwrite(str(root / 'image_2' / f'{k:06d}.png'), left)
        cv2.imwrite(str(root / 'image_3' / f'{k:06d}.png'), right)
        lefts.append(left)
    (root / 'calib.txt').write_text(_kitti_calib_text())
    return lefts


def test_folder_source_publishes_synchronised_rectified_pairs(ros, tmp_path):
    ctx, add, spin_until = ros
    lefts = _kitti_like_folder(tmp_path)
    probe = add(Node('capture_probe', context=ctx))
    got: dict[str, list] = {k: [] for k in ('li', 'ri', 'lc', 'rc')}
    for key, topic, typ in (('li', '/stereo/left/image_rect', Image),
                            ('ri', '/stereo/right/image_rect', Image),
                            ('lc', '/stereo/left/camera_info', CameraInfo),
                            ('rc', '/stereo/right/camera_info', CameraInfo)):
        probe.create_subscription(typ, topic, got[key].append, IMAGE_QOS)

    add(StereoCaptureNode(context=ctx, parameter_overrides=[
        Parameter('source', value='folder'), Parameter('folder', value=str(tmp_path)),
        Parameter('loop', value=True), Parameter('fps', value=30.0)]))

    def complete_pairs():
        stamps = [set(stamp_to_ns(m.header.stamp) for m in got[k]) for k in got]
        return set.intersection(*stamps)

    spin_until(lambda: len(complete_pairs()) >= 4, 'four complete stereo pairs')
    # (no spinning below: the received lists do not change while they are checked)

    by_stamp = {k: {stamp_to_ns(m.header.stamp): m for m in got[k]} for k in got}
    for stamp in sorted(complete_pairs()):
        li, ri = by_stamp['li'][stamp], by_stamp['ri'][stamp]
        lc, rc = by_stamp['lc'][stamp], by_stamp['rc'][stamp]
        assert li.encoding == ri.encoding == 'mono8'
        assert li.header.frame_id == lc.header.frame_id == 'stereo_left_optical_frame'
        assert ri.header.frame_id == rc.header.frame_id == 'stereo_right_optical_frame'
        assert (lc.width, lc.height) == (li.width, li.height) == (64, 48)
        left = image_msg_to_gray(li)
        right = image_msg_to_gray(ri)
        assert any(np.array_equal(left, ref) for ref in lefts)  # left is the left image
        assert not np.array_equal(left, right)
        cam = stereo_camera_from_infos(lc, rc)
        assert cam.f == pytest.approx(KITTI_F)
        assert cam.baseline == pytest.approx(KITTI_B, rel=1e-6)
        assert rc.p[3] == pytest.approx(-KITTI_F * KITTI_B)
        assert lc.p[3] == 0.0
        assert list(lc.k) == pytest.approx([lc.p[0], 0, lc.p[2], 0, lc.p[5], lc.p[6], 0, 0, 1])
        assert list(lc.d) == [0.0] * 5
    # every left image has its right image with the identical stamp
    assert len(complete_pairs()) >= 4
    # pairs are in grab order, one stamp per pair
    stamps = [stamp_to_ns(m.header.stamp) for m in got['li']]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)


def test_missing_device_gives_an_error_diagnostic_not_a_crash(ros):
    ctx, add, spin_until = ros
    probe = add(Node('capture_probe', context=ctx))
    diags = diagnostic_statuses(probe, 'stereo_capture_node')
    node = add(StereoCaptureNode(context=ctx, parameter_overrides=[
        Parameter('source', value='devices'),
        Parameter('left_device', value='/nonexistent/left_camera.avi'),
        Parameter('right_device', value='/nonexistent/right_camera.avi'),
        Parameter('retry_period', value=0.2)]))
    spin_until(lambda: any(d.level == ERROR for d in diags), 'an ERROR diagnostic')
    err = next(d for d in diags if d.level == ERROR)
    assert '/nonexistent/left_camera.avi' in err.message
    assert 'cannot open left camera' in err.message
    time.sleep(0.5)  # a few retries happen meanwhile
    assert node._thread.is_alive()  # still retrying, not crashed
    assert node.published == 0


def test_left_and_right_of_different_sizes_are_skipped(ros, tmp_path):
    ctx, add, spin_until = ros
    _kitti_like_folder(tmp_path, n=2, right_size=(40, 60))
    probe = add(Node('capture_probe', context=ctx))
    diags = diagnostic_statuses(probe, 'stereo_capture_node')
    node = add(StereoCaptureNode(context=ctx, parameter_overrides=[
        Parameter('source', value='folder'), Parameter('folder', value=str(tmp_path)),
        Parameter('loop', value=True), Parameter('fps', value=30.0)]))
    spin_until(lambda: any(d.level == ERROR and 'skipped' in d.message for d in diags),
               'an ERROR diagnostic for the skipped pair')
    assert node.skipped >= 1 and node.published == 0
    assert node._thread.is_alive()
