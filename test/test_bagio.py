"""Messages through a bag and back (rclpy CDR <-> rosbags), and image conversion."""
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from asmonc_vision.io import bagio


def test_custom_messages_round_trip_through_an_mcap_bag(tmp_path):
    from rclpy.serialization import deserialize_message, serialize_message

    from asmonc_vision_msgs.msg import Alarm, GroundPlane, Obstacle, ObstacleArray

    arr = ObstacleArray()
    arr.header.stamp.sec, arr.header.frame_id = 17, 'stereo_left_optical_frame'
    for i in range(3):
        o = Obstacle(id=i + 1, height=0.1 * (i + 1), range=2.0 + i, bearing=-0.1 * i,
                     width=0.3, disparity_excess=2.5, confidence=0.9)
        o.position.x, o.position.y, o.position.z = 0.1 * i, 1.1, 2.0 + i
        o.roi.x_offset, o.roi.width = 10 * i, 5
        arr.obstacles.append(o)
    plane = GroundPlane(a=0.01, b=0.26, c=-2.84, num_features=123, residual_rms=0.4,
                        status=GroundPlane.TRACKING, height=1.25)
    plane.covariance = [float(i) for i in range(9)]
    alarm = Alarm(level=Alarm.WARNING, obstacle_id=2, range=2.0, bearing=0.2,
                  text='obstacle, 2 metres, slightly left')
    msgs = [('/obstacles', 'asmonc_vision_msgs/msg/ObstacleArray', arr),
            ('/ground_plane', 'asmonc_vision_msgs/msg/GroundPlane', plane),
            ('/alarms', 'asmonc_vision_msgs/msg/Alarm', alarm)]
    path = tmp_path / 'bag'
    store = bagio.typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for i, (topic, typ, m) in enumerate(msgs):
            conn = w.add_connection(topic, typ, typestore=store)
            w.write(conn, 1000 + i, serialize_message(m))
    assert bagio.bag_topics(path) == {t: (typ, 1) for t, typ, _ in msgs}
    got = {t: m for t, _, m in bagio.read_messages(path, [t for t, _, _ in msgs])}
    assert got['/obstacles'].obstacles[2].position.z == pytest.approx(4.0)
    assert got['/obstacles'].obstacles[1].roi.x_offset == 10
    assert got['/ground_plane'].status == 1 and list(got['/ground_plane'].covariance)[8] == 8
    assert got['/alarms'].text == 'obstacle, 2 metres, slightly left'
    # back to rclpy from the rosbags serialisation
    raw = bytes(store.serialize_cdr(got['/obstacles'], 'asmonc_vision_msgs/msg/ObstacleArray'))
    again = deserialize_message(raw, ObstacleArray)
    assert again == deserialize_message(serialize_message(arr), ObstacleArray)


def test_missing_and_truncated_bags_raise_bag_error(tmp_path):
    with pytest.raises(bagio.BagError, match='does not exist'):
        bagio.bag_topics(tmp_path / 'nope')
    (tmp_path / 'cut.mcap').write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 50)
    with pytest.raises(bagio.BagError, match='cannot be read'):
        bagio.bag_topics(tmp_path / 'cut.mcap')


def test_image_to_gray_encodings_and_errors():
    rgb = np.zeros((4, 6, 3), np.uint8)
    rgb[..., 0] = 200  # red
    g = bagio.image_to_gray('rgb8', 4, 6, 18, rgb.tobytes())
    b = bagio.image_to_gray('bgr8', 4, 6, 18, rgb.tobytes())
    assert g.shape == (4, 6) and g[0, 0] > b[0, 0]  # red weighs more than blue
    mono = np.arange(24, dtype=np.uint8).reshape(4, 6)
    padded = np.zeros((4, 8), np.uint8)
    padded[:, :6] = mono
    np.testing.assert_array_equal(bagio.image_to_gray('mono8', 4, 6, 8, padded.tobytes()), mono)
    # 8UC1 / 8UC3 as cv_bridge reads them; the 4-channel encodings drop their alpha
    np.testing.assert_array_equal(bagio.image_to_gray('8UC1', 4, 6, 8, padded.tobytes()), mono)
    np.testing.assert_array_equal(bagio.image_to_gray('8UC3', 4, 6, 18, rgb.tobytes()), b)
    rgba = np.concatenate([rgb, np.full((4, 6, 1), 77, np.uint8)], axis=2)
    np.testing.assert_array_equal(bagio.image_to_gray('rgba8', 4, 6, 24, rgba.tobytes()), g)
    np.testing.assert_array_equal(bagio.image_to_gray('bgra8', 4, 6, 24, rgba.tobytes()), b)
    with pytest.raises(bagio.ImageFormatError, match='bad image geometry'):
        bagio.image_to_gray('bgra8', 4, 6, 18, bytes(96))
    with pytest.raises(bagio.ImageFormatError, match="unsupported image encoding '16UC1'"):
        bagio.image_to_gray('16UC1', 4, 6, 12, bytes(48))
    with pytest.raises(bagio.ImageFormatError, match='header says'):
        bagio.image_to_gray('mono8', 4, 6, 6, bytes(10))


def _shift_right_camera(src, dst, shift_px: int, limit: int = 24):
    """Copy the first ``limit`` pairs of bag ``src`` to ``dst`` with the right image's
    content moved ``shift_px`` columns to the left and its principal point with it
    (``P[0,2] = cx - shift_px``): the same pair, rectified without
    CALIB_ZERO_DISPARITY."""
    store = bagio.typestore()
    types = {t: typ for t, (typ, _) in bagio.bag_topics(src).items()}
    topics = ['/stereo/left/image_rect', '/stereo/right/image_rect',
              '/stereo/left/camera_info', '/stereo/right/camera_info']
    stamps: list[int] = []
    with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {t: w.add_connection(t, types[t], typestore=store) for t in topics}
        for topic, t, m in bagio.read_messages(src, topics):
            s = bagio.header_stamp_ns(m)
            if s not in stamps:
                stamps.append(s)
            if len(stamps) > limit:
                break
            if topic == '/stereo/right/image_rect':
                img = np.asarray(m.data, np.uint8).reshape(m.height, m.step)
                moved = np.concatenate([img[:, shift_px:], img[:, -1:].repeat(shift_px, 1)], 1)
                m.data = np.ascontiguousarray(moved).reshape(-1)
            elif topic == '/stereo/right/camera_info':
                m.p = np.asarray(m.p, float).copy()
                m.p[2] -= shift_px
            w.write(conns[topic], t, bytes(store.serialize_cdr(m, types[topic])))


def test_a_right_camera_with_its_own_principal_point_is_moved_to_the_left_one(tmp_path):
    """A rectified pair whose right principal point lies 6 px left of the left one's
    (CameraInfo P[0,2]) loads as the same pair: its right image moved back
    (`core.camera.align_right_image`), the camera, the detector's ground and its
    obstacles unchanged;
    taken as it stands, every disparity would be 6 px off."""
    from pathlib import Path

    from asmonc_vision.core.gpod import GpodDetector
    from asmonc_vision.io.frames import load_frames

    src = Path(__file__).resolve().parents[1] / 'bags' / 'static_obstacles'
    _shift_right_camera(src, tmp_path / 'moved', 6)
    a, b = load_frames(src, 24), load_frames(tmp_path / 'moved', 24)
    assert len(a) == len(b) == 24
    for fa, fb in zip(a, b):
        assert fa.stamp_ns == fb.stamp_ns and fa.cam == fb.cam
        np.testing.assert_array_equal(fb.right[:, 6:], fa.right[:, 6:])
    da, db = GpodDetector(), GpodDetector()
    for fa, fb in zip(a, b):
        ra = da.process(fa.left, fa.right, fa.cam)
        rb = db.process(fb.left, fb.right, fb.cam)
    assert ra.metric_plane is not None and rb.metric_plane is not None
    # (a disparity offset alone would be taken into the plane's c, and every range off)
    np.testing.assert_allclose(rb.plane_abc, ra.plane_abc, atol=0.05)
    assert rb.metric_plane.height == pytest.approx(ra.metric_plane.height, abs=0.005)
    assert len(rb.obstacles) == len(ra.obstacles) > 0
    np.testing.assert_allclose(sorted(o.range for o in rb.obstacles),
                               sorted(o.range for o in ra.obstacles), atol=0.05)
    # the principal points' offset is checked: a quarter of the width is no pair
    _shift_right_camera(src, tmp_path / 'far', 80, limit=1)
    with pytest.raises(bagio.BagError, match='principal points differ'):
        load_frames(tmp_path / 'far', 1)
