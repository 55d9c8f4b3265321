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
