"""The replay's spinning threads stop before their nodes are destroyed (replay.spin)."""
import threading
import time

import pytest

from asmonc_vision.replay.spin import SpinThread


@pytest.mark.parametrize('multi', [False, True], ids=['single', 'multi'])
def test_stop_waits_for_the_thread_and_the_callback_in_flight(ros_context, multi):
    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

    node = rclpy.create_node('spin_test', context=ros_context)
    started, finished = threading.Event(), threading.Event()

    def slow() -> None:
        if started.is_set():
            return
        started.set()
        time.sleep(0.3)
        finished.set()

    node.create_timer(0.01, slow)
    ex = (MultiThreadedExecutor(num_threads=2, context=ros_context) if multi
          else SingleThreadedExecutor(context=ros_context))
    ex.add_node(node)
    spin = SpinThread(ex, 'spin-test')
    assert started.wait(5.0)
    assert spin.stop(timeout_s=5.0)
    # the callback that was running when stop() was called has finished, and no thread
    # of the executor is left to touch the node
    assert finished.is_set()
    assert not any(t.name == 'spin-test' for t in threading.enumerate())
    node.destroy_node()


def test_stop_after_the_context_was_shut_down(ros_context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    node = rclpy.create_node('spin_test_ctx', context=ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    spin = SpinThread(ex, 'spin-test-ctx')
    time.sleep(0.1)
    rclpy.try_shutdown(context=ros_context)  # as on a signal: the thread ends by itself
    assert spin.stop(timeout_s=5.0)
    node.destroy_node()
