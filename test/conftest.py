"""Test isolation for ROS: local discovery only, a domain id of this session's own, and
an rclpy Context per test (the `ros_context` fixture)."""
import os
import sys
from pathlib import Path

import pytest

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# One domain per pytest process, so parallel or leftover runs never cross-talk.
os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 80))

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / 'shared'
BAGS = REPO / 'bags'
sys.path.insert(0, str(REPO))


@pytest.fixture
def ros_context():
    """A fresh, initialised rclpy Context, shut down after the test."""
    import rclpy

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def spin_until(executor, predicate, timeout=10.0, step=0.05):
    """Spin `executor` until `predicate()` is true or `timeout` s pass; return predicate()."""
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        executor.spin_once(timeout_sec=step)
    return bool(predicate())



def stereo_types():
    """The stereo input topics of the detector and egomotion nodes and their rclpy types,
    in (left image, right image, left info, right info) order."""
    from sensor_msgs.msg import CameraInfo, Image
    return {'/stereo/left/image_rect': Image, '/stereo/right/image_rect': Image,
            '/stereo/left/camera_info': CameraInfo, '/stereo/right/camera_info': CameraInfo}


def read_messages(bag, types):
    """{topic: [rclpy message, ...]} of a bag, for the topics in ``types`` (topic -> type)."""
    from rclpy.serialization import deserialize_message
    from rosbags.rosbag2 import Reader
    per_topic = {t: [] for t in types}
    with Reader(bag) as r:
        conns = [c for c in r.connections if c.topic in types]
        for c, _, raw in r.messages(connections=conns):
            per_topic[c.topic].append(deserialize_message(bytes(raw), types[c.topic]))
    return per_topic


def stereo_sender(probe):
    """Publishers of the stereo input topics on the ``probe`` node, and
    ``send(left, right, left_info, right_info)`` publishing one pair (infos first; the
    images alone when the infos are None)."""
    from asmonc_vision.nodes.common import IMAGE_QOS
    pubs = {t: probe.create_publisher(typ, t, IMAGE_QOS) for t, typ in stereo_types().items()}

    def send(left, right, linfo=None, rinfo=None):
        if linfo is not None:
            pubs['/stereo/left/camera_info'].publish(linfo)
        if rinfo is not None:
            pubs['/stereo/right/camera_info'].publish(rinfo)
        pubs['/stereo/left/image_rect'].publish(left)
        pubs['/stereo/right/image_rect'].publish(right)
    return pubs, send


def diagnostic_statuses(probe, name: str) -> list:
    """A list that fills with the DiagnosticStatus entries named ``name`` arriving on
    /diagnostics (subscribed on the ``probe`` node)."""
    from diagnostic_msgs.msg import DiagnosticArray

    out: list = []
    probe.create_subscription(
        DiagnosticArray, '/diagnostics',
        lambda m: out.extend(s for s in m.status if s.name == name), 10)
    return out


class RosGraph:
    """An rclpy Context on a domain of its own, a single-threaded executor, and the
    nodes added to it (destroyed at `close`). For node tests over real topics."""

    def __init__(self, domain_id: int, deadline: float = 15.0):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.deadline = deadline
        self.nodes = []

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, pred, what, deadline=None, each=None, period=0.05):
        """Spin until pred(); call each() every `period` s meanwhile; fail after the
        deadline (a generous bound so a broken node fails the test instead of hanging it,
        not a speed test)."""
        import time

        end = time.monotonic() + (self.deadline if deadline is None else deadline)
        nxt = time.monotonic()
        while time.monotonic() < end:
            if each is not None and time.monotonic() >= nxt:
                each()
                nxt = time.monotonic() + period
            self.executor.spin_once(timeout_sec=0.01)
            if pred():
                return
        raise AssertionError(f'timed out waiting for {what}')

    def diagnostics(self, probe, name: str) -> list:
        """`diagnostic_statuses` of ``probe`` named ``name``."""
        return diagnostic_statuses(probe, name)

    def spin_for(self, seconds: float) -> None:
        import time

        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def close(self) -> None:
        import rclpy

        for n in self.nodes:
            self.executor.remove_node(n)
            n.destroy_node()
        self.executor.shutdown()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture
def ros(request):
    """A RosGraph on a domain id of the test module's own (its ROS_DOMAIN_OFFSET) and
    with its DEADLINE (s); 0..101 are safe DDS domain ids on Linux, 0 is avoided."""
    offset = getattr(request.module, 'ROS_DOMAIN_OFFSET', 0)
    graph = RosGraph(1 + (os.getpid() * 3 + offset) % 100,
                     getattr(request.module, 'DEADLINE', 15.0))
    yield graph
    graph.close()
