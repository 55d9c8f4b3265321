"""The replay's own view of the graph: the results it subscribes to, and the console."""
from __future__ import annotations

import sys
import threading
import time

from asmonc_vision.eval.evaluation import FrameObstacles
from asmonc_vision.io import bagio
from asmonc_vision.io.frames import frame_from_obstacle_array


class Monitor:
    """Collects /obstacles and /alarms in this process (an rclpy node in a thread)."""

    def __init__(self, context):
        from rclpy.node import Node

        from asmonc_vision.nodes.common import ALARM_QOS, RESULT_QOS
        from asmonc_vision_msgs.msg import Alarm, GaitState, ObstacleArray

        self.node = Node('asmonc_run_monitor', context=context)
        self.lock = threading.Lock()
        self.detections: dict[int, FrameObstacles] = {}
        #: time.monotonic() of the newest /obstacles (None before the first): when the
        #: alarm node's own silence starts, whatever this process's main loop is doing
        self.last_result_at: float | None = None
        self.alarms: list[dict] = []
        self.new_alarms: list[dict] = []
        self.node.create_subscription(ObstacleArray, '/obstacles', self._on_obstacles, RESULT_QOS)
        self.node.create_subscription(Alarm, '/alarms', self._on_alarm, ALARM_QOS)
        self.gait_states = 0
        self.gait_walking = 0
        #: time.monotonic() of the newest /gait/state (None before the first)
        self.last_gait_at: float | None = None
        self.node.create_subscription(GaitState, '/gait/state', self._on_gait, RESULT_QOS)
        # The left camera_info the player sends with each image: how far the replay is
        # (its own subscription, which the player waits for: `wait_topics`).
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CameraInfo
        self.infos_played = 0
        #: header stamp of the newest left camera_info played (None before the first)
        self.last_info_stamp_ns: int | None = None
        self.node.create_subscription(CameraInfo, bagio.TOPICS['left_info'][0],
                                      self._on_info, qos_profile_sensor_data)

    def _on_info(self, msg) -> None:
        with self.lock:
            self.infos_played += 1
            self.last_info_stamp_ns = bagio.header_stamp_ns(msg)

    def _on_gait(self, msg) -> None:
        with self.lock:
            self.gait_states += 1
            self.last_gait_at = time.monotonic()
            self.gait_walking += int(bool(msg.walking))

    def _on_obstacles(self, msg) -> None:
        frame = frame_from_obstacle_array(msg)
        with self.lock:
            self.detections[frame.stamp_ns] = frame
            self.last_result_at = time.monotonic()

    def _on_alarm(self, msg) -> None:
        a = {'stamp_ns': msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
             'level': int(msg.level), 'text': msg.text, 'range': float(msg.range),
             'bearing': float(msg.bearing), 'obstacle_id': int(msg.obstacle_id),
             'received_ns': time.time_ns()}
        with self.lock:
            self.alarms.append(a)
            self.new_alarms.append(a)

    def take_new_alarms(self) -> list[dict]:
        with self.lock:
            out, self.new_alarms = self.new_alarms, []
        return out

    @property
    def frames(self) -> int:
        with self.lock:
            return len(self.detections)

    @property
    def played(self) -> int:
        """Left camera_info messages received from the player so far."""
        with self.lock:
            return self.infos_played


class Console:
    """Alarm lines on stdout; a progress bar on stderr (only when it is a terminal)."""

    def __init__(self, total: int, progress: bool, quiet: bool):
        self.total = max(total, 1)
        self.progress = progress and sys.stderr.isatty() and not quiet
        self.quiet = quiet
        self._bar_shown = False

    def _clear(self) -> None:
        if self._bar_shown:
            sys.stderr.write('\r\033[K')
            self._bar_shown = False

    def line(self, text: str, err: bool = False) -> None:
        if self.quiet and not err:
            return
        self._clear()
        print(text, file=sys.stderr if err else sys.stdout, flush=True)

    def bar(self, done: int, note: str = '') -> None:
        if not self.progress:
            return
        width = 30
        k = min(width, int(width * done / self.total))
        sys.stderr.write(f'\r[{"#" * k}{"." * (width - k)}] {done}/{self.total} frames {note}')
        sys.stderr.flush()
        self._bar_shown = True

    def done(self) -> None:
        self._clear()
