"""compass_node: a serial compass/inclinometer module -> /inclinometer/imu.

Reads attitude sentences (``$PTNTHPR`` True North / Honeywell, or TCM ``$C..P..R..``;
see ``core.nmea``) from a serial device with pyserial, checks their checksums, converts
them to the REP 103 attitude of ``inclinometer_link`` and publishes

    /inclinometer/imu (sensor_msgs/Imu, RELIABLE depth 10 -- also received by
        best-effort subscribers): orientation = world -> inclinometer_link quaternion
        from roll, pitch, yaw; orientation_covariance diag(sigma^2) (flagged angles:
        flagged_sigma; no heading: yaw variance (2 pi)^2); angular_velocity_covariance[0]
        = linear_acceleration_covariance[0] = -1 (not measured); frame inclinometer_link;
        stamp = arrival time of the sentence's end - latency.
    /diagnostics: OK while sentences arrive; WARN when none came for ``timeout`` s, or
        bad lines were seen since the last report; ERROR while the port cannot be
        opened. Counters: sentences, bad checksums, malformed, unknown, flagged,
        reconnects.

Yaw: with ``yaw_zero = east`` (default, REP 103 / ENU) yaw = 90 deg - heading, i.e.
counter-clockwise from east; with ``north`` yaw = -heading, counter-clockwise from the
heading reference. ``declination_deg`` turns a magnetic heading into a true one.

The port is read by a thread; a lost device (unplugged, read error) is closed and
reopened every ``reconnect_period`` s, never a crash. Malformed lines are counted and
logged (throttled). Parameters: ``core.nmea.CompassConfig`` (fixed at start-up).
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Imu

from asmonc_vision.core.gait.rotations import rpy_to_quaternion
from asmonc_vision.core.nmea import (CompassConfig, LineSplitter, NmeaError, accepts,
                                     parse_sentence, to_rep103)
from asmonc_vision.nodes.common import RESULT_QOS, Diagnostics, declare_config, run_node
from asmonc_vision.nodes.conversions import ns_to_stamp

#: period of the diagnostics check, s
CHECK_PERIOD = 0.25
#: throttle of repeated warnings, s
THROTTLE = 5.0


def imu_message(rpy, var, stamp, frame_id: str) -> Imu:
    """sensor_msgs/Imu with only the orientation: quaternion of REP 103 roll, pitch, yaw
    (rad; world -> frame), diagonal orientation covariance `var` (rad^2)."""
    q = rpy_to_quaternion(np.asarray(rpy, float))
    msg = Imu()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = \
        (float(v) for v in q)
    cov = np.zeros(9)
    cov[[0, 4, 8]] = var
    msg.orientation_covariance = cov.tolist()
    msg.angular_velocity_covariance[0] = -1.0
    msg.linear_acceleration_covariance[0] = -1.0
    return msg


class CompassNode(Node):
    """Serial compass driver (see module doc)."""

    def __init__(self, **kwargs):
        super().__init__('compass_node', **kwargs)
        self.config: CompassConfig = declare_config(self, CompassConfig)
        self._pub = self.create_publisher(Imu, '/inclinometer/imu', RESULT_QOS)
        self._diag = Diagnostics(self, 'compass_node', hardware_id=self.config.port)
        self._lock = threading.Lock()
        self.counts = {'sentences': 0, 'checksum': 0, 'format': 0, 'unknown': 0,
                       'flagged': 0, 'reconnects': 0, 'overflows': 0}
        self._reported = dict(self.counts)
        self._last_good: float | None = None       # monotonic time of the last sentence
        self._started = time.monotonic()
        self._port_open = False
        self._port_error = ''
        self._stop = threading.Event()
        self._splitter = LineSplitter()
        self.get_logger().info(
            f'compass on {self.config.port} at {self.config.baud} baud, protocol '
            f'{self.config.protocol}, yaw from {self.config.yaw_zero}')
        self._thread = threading.Thread(target=self._reader, name='compass_reader',
                                        daemon=True)
        self._thread.start()
        self._timer = self.create_timer(CHECK_PERIOD, self._on_timer)

    # ------------------------------------------------------------------ serial thread
    def _open(self):
        import serial

        return serial.Serial(self.config.port, self.config.baud, timeout=0.1)

    def _reader(self) -> None:
        import serial

        port = None
        while not self._stop.is_set():
            if port is None:
                try:
                    port = self._open()
                    self._splitter.reset()
                    with self._lock:
                        if self._port_error:
                            self.counts['reconnects'] += 1
                        self._port_open, self._port_error = True, ''
                    self.get_logger().info(f'serial port {self.config.port} open')
                except (serial.SerialException, OSError, ValueError) as exc:
                    with self._lock:
                        self._port_open, self._port_error = False, str(exc)
                    self.get_logger().warning(
                        f'cannot open {self.config.port}: {exc}; retrying every '
                        f'{self.config.reconnect_period} s', throttle_duration_sec=THROTTLE)
                    self._stop.wait(self.config.reconnect_period)
                    continue
            try:
                data = port.read(max(1, port.in_waiting))
            except (serial.SerialException, OSError, TypeError, ValueError) as exc:
                with self._lock:
                    self._port_open, self._port_error = False, f'device lost: {exc}'
                self.get_logger().warning(f'{self.config.port} lost ({exc}); reconnecting',
                                          throttle_duration_sec=THROTTLE)
                try:
                    port.close()
                except Exception:  # noqa: BLE001 -- a dead port may fail to close
                    pass
                port = None
                self._stop.wait(self.config.reconnect_period)
                continue
            if data:
                self._handle(data)
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001
                pass

    def _handle(self, data: bytes) -> None:
        lines = self._splitter.feed(data)
        with self._lock:
            self.counts['overflows'] = self._splitter.overflows
        for line in lines:
            now = self.get_clock().now()
            try:
                reading = parse_sentence(line, self.config.require_checksum)
                if not accepts(self.config, reading):
                    raise NmeaError('unknown', f'{reading.kind} sentence but protocol is '
                                    f'{self.config.protocol}')
            except NmeaError as exc:
                with self._lock:
                    self.counts[exc.reason] += 1
                if exc.reason != 'unknown':
                    self.get_logger().warning(f'bad line from {self.config.port} '
                                              f'({exc}): {line[:60]!r}',
                                              throttle_duration_sec=THROTTLE)
                continue
            rpy, var = to_rep103(reading, self.config)
            stamp_ns = now.nanoseconds - int(self.config.latency * 1e9)
            self._pub.publish(imu_message(rpy, var, ns_to_stamp(stamp_ns),
                                          self.config.frame_id))
            with self._lock:
                self.counts['sentences'] += 1
                if any(reading.flags):
                    self.counts['flagged'] += 1
                self._last_good = time.monotonic()
            if any(reading.flags):
                self.get_logger().warning(f'compass flags an angle as not normal '
                                          f'(status {reading.status!r})',
                                          throttle_duration_sec=THROTTLE)

    # ------------------------------------------------------------------ diagnostics
    def _on_timer(self) -> None:
        with self._lock:
            counts = dict(self.counts)
            last, port_open, err = self._last_good, self._port_open, self._port_error
        age = None if last is None else time.monotonic() - last
        bad = {k: counts[k] - self._reported[k] for k in ('checksum', 'format', 'overflows')}
        self._reported = counts
        values = dict(counts, port=self.config.port, port_open=port_open,
                      last_sentence_age_s='never' if age is None else f'{age:.2f}')
        if not port_open:
            self._diag.update(Diagnostics.ERROR, f'port not open: {err}', **values)
        elif age is None or age > self.config.timeout:
            silent = time.monotonic() - self._started if age is None else age
            self._diag.update(Diagnostics.WARN, f'no valid sentence for {silent:.1f} s',
                              **values)
            self.get_logger().warning(f'compass silent for {silent:.1f} s',
                                      throttle_duration_sec=THROTTLE)
        elif any(bad.values()):
            self._diag.update(Diagnostics.WARN, 'bad lines: ' + ', '.join(
                f'{v} {k}' for k, v in bad.items() if v), **values)
        else:
            self._diag.update(Diagnostics.OK, 'receiving', **values)

    def destroy_node(self):
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        return super().destroy_node()


def main(args=None):
    run_node(CompassNode, args, name='compass_node')


if __name__ == '__main__':
    main()
