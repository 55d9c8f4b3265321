"""Shared helpers of the bag player / recorder tests (no tests here).

Test bags are written with rosbags from the project typestore; ROS tests get their own
rclpy Context on their own DDS domain, with discovery limited to this machine.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from asmonc_vision.io.bagio import TOPICS, typestore  # noqa: E402
from conftest import next_domain_id  # noqa: E402,F401 - re-exported for the tests

LEFT = TOPICS['left_image'][0]
LEFT_INFO = TOPICS['left_info'][0]
IMU = TOPICS['imu'][0]
OBSTACLES = TOPICS['obstacles'][0]
ALARMS = TOPICS['alarms'][0]
T0 = 1_700_000_000_000_000_000  # bag start, ns
STEP = 100_000_000              # 100 ms between frames

def stamp(ns: int):
    t = typestore().types['builtin_interfaces/msg/Time']
    return t(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ns: int, frame: str = 'stereo_left_optical_frame'):
    return typestore().types['std_msgs/msg/Header'](stamp=stamp(ns), frame_id=frame)


def image_pixels(i: int, h: int = 24, w: int = 32) -> np.ndarray:
    """A small mono8 test pattern that differs per frame."""
    rng = np.random.default_rng(i)
    return rng.integers(0, 256, size=(h, w), dtype=np.uint8)


def make_image(i: int, ns: int, h: int = 24, w: int = 32):
    T = typestore().types
    px = image_pixels(i, h, w)
    return T['sensor_msgs/msg/Image'](header=header(ns), height=h, width=w, encoding='mono8',
                                      is_bigendian=0, step=w, data=px.reshape(-1))


def make_info(ns: int):
    T = typestore().types
    roi = T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                do_rectify=False)
    p = np.array([100.0, 0, 16, 0, 0, 100.0, 12, 0, 0, 0, 1, 0])
    return T['sensor_msgs/msg/CameraInfo'](
        header=header(ns), height=24, width=32, distortion_model='plumb_bob',
        d=np.zeros(5), k=np.array([100.0, 0, 16, 0, 100.0, 12, 0, 0, 1]), r=np.eye(3).ravel(),
        p=p, binning_x=0, binning_y=0, roi=roi)


def make_imu(i: int, ns: int):
    T = typestore().types
    v3 = T['geometry_msgs/msg/Vector3']
    q = T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.01 * i, z=0.0, w=1.0)
    return T['sensor_msgs/msg/Imu'](
        header=header(ns, 'inclinometer_link'), orientation=q,
        orientation_covariance=np.zeros(9), angular_velocity=v3(x=0.0, y=0.0, z=0.0),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=v3(x=0.0, y=0.0, z=9.81), linear_acceleration_covariance=np.zeros(9))


def make_obstacles(i: int, ns: int):
    T = typestore().types
    roi = T['sensor_msgs/msg/RegionOfInterest'](x_offset=i, y_offset=2, height=5, width=6,
                                                do_rectify=False)
    ob = T['asmonc_vision_msgs/msg/Obstacle'](
        id=i + 1, position=T['geometry_msgs/msg/Point'](x=0.1 * i, y=1.2, z=3.0),
        height=0.5, range=3.0 - 0.1 * i, bearing=0.05, width=0.4, disparity_excess=2.0,
        confidence=0.9, roi=roi)
    return T['asmonc_vision_msgs/msg/ObstacleArray'](header=header(ns), obstacles=[ob] * (i % 3))


def make_alarm(level: int, ns: int, text: str = 'obstacle, 2 metres'):
    T = typestore().types
    return T['asmonc_vision_msgs/msg/Alarm'](header=header(ns), level=level, obstacle_id=7,
                                             range=2.0, bearing=0.1, text=text)


def cdr(msg, msgtype: str) -> bytes:
    return bytes(typestore().serialize_cdr(msg, msgtype))


def sample_messages(n: int = 6) -> list[tuple[str, str, int, bytes]]:
    """(topic, type, receive time, CDR) of n frames 100 ms apart, in time order."""
    out = []
    for i in range(n):
        ns = T0 + i * STEP
        out += [(LEFT, 'sensor_msgs/msg/Image', ns,
                 cdr(make_image(i, ns), 'sensor_msgs/msg/Image')),
                (LEFT_INFO, 'sensor_msgs/msg/CameraInfo', ns + 1000,
                 cdr(make_info(ns), 'sensor_msgs/msg/CameraInfo')),
                (IMU, 'sensor_msgs/msg/Imu', ns + 2000,
                 cdr(make_imu(i, ns), 'sensor_msgs/msg/Imu')),
                (OBSTACLES, 'asmonc_vision_msgs/msg/ObstacleArray', ns + 3000,
                 cdr(make_obstacles(i, ns), 'asmonc_vision_msgs/msg/ObstacleArray'))]
    return out


def write_bag(path: Path, messages, compression: bool = False, store=None) -> Path:
    """Write (topic, type, t, cdr) messages to a rosbag2 MCAP bag directory with rosbags."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    store = store or typestore()
    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if compression:
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    conns = {}
    with w:
        for topic, msgtype, _, _ in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store)
        for topic, _, t, data in messages:
            w.write(conns[topic], t, data)
    return path


def read_bag(path: Path) -> list[tuple[str, str, int, bytes]]:
    """All messages of a bag with rosbags: (topic, type, t, cdr) in time order."""
    from rosbags.rosbag2 import Reader

    with Reader(path) as r:
        return [(c.topic, c.msgtype, t, bytes(d)) for c, t, d in r.messages()]


def by_topic(messages) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    for topic, _, _, data in messages:
        out.setdefault(topic, []).append(data)
    return out


def big_bag(tmp_path: Path, n: int = 40) -> tuple[Path, list]:
    """A bag of n 200x200 images: about 1.6 MB, so rosbags writes two chunks."""
    T = typestore().types
    msgs = []
    for i in range(n):
        ns = T0 + i * STEP
        px = np.full((200, 200), i, np.uint8)
        m = T['sensor_msgs/msg/Image'](header=header(ns), height=200, width=200,
                                       encoding='mono8', is_bigendian=0, step=200,
                                       data=px.reshape(-1))
        msgs.append((LEFT, 'sensor_msgs/msg/Image', ns, cdr(m, 'sensor_msgs/msg/Image')))
    return write_bag(tmp_path / 'big', msgs), msgs


# --- ROS ----------------------------------------------------------------------------

class Spinner:
    """Spins an executor (of the test's context) in a background thread."""

    def __init__(self, context, *nodes):
        from rclpy.executors import SingleThreadedExecutor

        from asmonc_vision.replay.spin import SpinThread

        self.executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            self.executor.add_node(n)
        self._spin = SpinThread(self.executor, 'test-spinner')

    def add(self, node) -> None:
        self.executor.add_node(node)

    def stop(self) -> None:
        self._spin.stop()


def wait_for(cond, timeout: float = 10.0, period: float = 0.01) -> bool:
    """Poll `cond()` until true or timeout; returns its last value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(period)
    return bool(cond())


class RawCollector:
    """A node that subscribes raw (RELIABLE, depth 100) and keeps (bytes, monotonic time)."""

    def __init__(self, context, topics: dict[str, str], name: str = 'collector', qos=None):
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from asmonc_vision.nodes.player_node import message_class

        self.node = Node(name, context=context)
        self.received: dict[str, list[tuple[bytes, float]]] = {t: [] for t in topics}
        self.subs = {}
        q = qos or QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        for topic, msgtype in topics.items():
            self.subs[topic] = self.node.create_subscription(
                message_class(msgtype), topic,
                lambda data, t=topic: self.received[t].append((data, time.monotonic())),
                q, raw=True)

    def count(self) -> int:
        return sum(len(v) for v in self.received.values())

    def wait_matched(self, topics=None, timeout: float = 10.0) -> bool:
        """Wait until the subscriptions (default: all) have matched a publisher."""
        subs = [s for t, s in self.subs.items() if topics is None or t in topics]
        return wait_for(lambda: all(s.get_publisher_count() >= 1 for s in subs), timeout)

    def data(self, topic: str) -> list[bytes]:
        return [d for d, _ in self.received[topic]]

    def times(self) -> list[float]:
        return sorted(t for v in self.received.values() for _, t in v)


def subprocess_env(domain_id: int) -> dict:
    """The whole environment (the ROS wheels need it) plus this test's domain."""
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env['RCUTILS_COLORIZED_OUTPUT'] = '0'
    return env
