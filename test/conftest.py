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
