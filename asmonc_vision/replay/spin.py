"""An executor spun on a background thread, stopped without racing it.

`Executor.shutdown()` called from another thread while `spin()` waits destroys the
executor's guard condition under the wait set that holds it (ros2/rclpy#968); destroying
a node the thread still waits on crashes the same way. Either can end the process with a
segmentation fault after its work is done. Here the thread spins in short slices and is
told to stop between them; `stop()` joins it, lets the callbacks already handed to a
`MultiThreadedExecutor`'s pool finish, and only then shuts the executor down, so the
nodes can be destroyed safely afterwards.
"""
from __future__ import annotations

import threading

#: seconds each spin slice may wait: the thread sees `stop()` within about this long
SLICE_S = 0.05


class SpinThread:
    """Spins `executor` on a daemon thread until `stop()`."""

    def __init__(self, executor, name: str = 'spin') -> None:
        self.executor = executor
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        while not self._stop.is_set() and self.executor.context.ok():
            try:
                self.executor.spin_once(timeout_sec=SLICE_S)
            except ExternalShutdownException:  # the context was shut down under us
                break

    def stop(self, timeout_s: float = 5.0) -> bool:
        """Stop spinning, wait for the thread and the callbacks in flight, shut the
        executor down. Returns False when the thread did not end within `timeout_s`
        (the executor is then left alone: shutting it down would race the thread)."""
        self._stop.set()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            return False
        # a MultiThreadedExecutor's callbacks run on its own pool; nothing else waits
        # for them (Executor.shutdown's wait for work in progress does not, rclpy#968)
        pool = getattr(self.executor, '_executor', None)
        if pool is not None and hasattr(pool, 'shutdown'):
            pool.shutdown(wait=True)
        self.executor.shutdown(timeout_sec=timeout_s)
        return True
