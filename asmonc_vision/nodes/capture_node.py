"""stereo_capture_node: cameras (or image folders) in, the rectified stereo topics out.

Publishes (nodes.common.IMAGE_QOS):
    /stereo/left/image_rect, /stereo/right/image_rect (sensor_msgs/Image mono8; one
        identical stamp per pair = the time of the grab, ROS clock)
    /stereo/left/camera_info, /stereo/right/camera_info (rectified: K = P[:, :3],
        D = 0, R = I, right P[0, 3] = -f*B; same stamps as the images)
    /diagnostics

A worker thread grabs, rectifies and publishes, so the executor is never blocked. A
camera that cannot be opened gives an ERROR (log + diagnostics) and is retried every
``retry_period``; a camera that goes quiet gives throttled warnings and is reopened
after ``retry_period``; the node never exits on camera trouble. Parameters: the fields
of ``core.capture.CaptureConfig`` (fixed at start-up).
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from asmonc_vision.core.capture import (CalibrationError, CaptureConfig, FrameSizeError,
                                        FrameSource, SourceEnded, SourceError,
                                        StereoRectifier, make_rectifier, make_source)
from asmonc_vision.nodes.common import IMAGE_QOS, Diagnostics, declare_config, run_node
from asmonc_vision.nodes.conversions import array_to_image_msg, ns_to_stamp


def camera_info_msg(p: np.ndarray, width: int, height: int, header: Header) -> CameraInfo:
    """CameraInfo of a rectified camera from its 3x4 projection matrix."""
    msg = CameraInfo()
    msg.header = header
    msg.width, msg.height = int(width), int(height)
    msg.distortion_model = 'plumb_bob'
    msg.d = [0.0] * 5
    msg.k = [float(x) for x in np.asarray(p, float)[:, :3].reshape(-1)]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [float(x) for x in np.asarray(p, float).reshape(-1)]
    return msg


class StereoCaptureNode(Node):
    """Grabs stereo pairs in a worker thread and publishes them rectified."""

    def __init__(self, **kwargs):
        super().__init__('stereo_capture_node', **kwargs)
        self.config: CaptureConfig = declare_config(self, CaptureConfig)
        cfg = self.config
        self._pub_left = self.create_publisher(Image, '/stereo/left/image_rect', IMAGE_QOS)
        self._pub_right = self.create_publisher(Image, '/stereo/right/image_rect', IMAGE_QOS)
        self._pub_left_info = self.create_publisher(CameraInfo, '/stereo/left/camera_info',
                                                    IMAGE_QOS)
        self._pub_right_info = self.create_publisher(CameraInfo, '/stereo/right/camera_info',
                                                     IMAGE_QOS)
        self._diag = Diagnostics(self, 'stereo_capture_node', hardware_id=self._hardware_id())
        self._stop = threading.Event()
        self._source: FrameSource | None = None
        self._rectifier: StereoRectifier | None = None
        self.published = 0
        self.skipped = 0
        self.get_logger().info(f'stereo capture from source "{cfg.source}" at {cfg.fps} fps')
        self._thread = threading.Thread(target=self._run, name='stereo_capture', daemon=True)
        self._thread.start()

    def _hardware_id(self) -> str:
        c = self.config
        return {'devices': f'{c.left_device},{c.right_device}',
                'side_by_side': c.stereo_device, 'folder': c.folder}[c.source]

    def _clock_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    # -- worker --------------------------------------------------------------------------
    def _open(self) -> bool:
        """Open the source and load the calibration; False (logged) on failure."""
        cfg = self.config
        source = make_source(cfg, self._clock_ns)
        try:
            source.open()
            rectifier = make_rectifier(cfg, source)
        except (SourceError, CalibrationError) as exc:
            source.close()
            kind = 'calibration' if isinstance(exc, CalibrationError) else 'camera'
            self.get_logger().error(f'{kind} error: {exc}; retrying every '
                                    f'{cfg.retry_period} s',
                                    throttle_duration_sec=max(cfg.retry_period, 10.0))
            self._diag.update(Diagnostics.ERROR, f'{kind} error: {exc}', source=cfg.source)
            return False
        self._source, self._rectifier = source, rectifier
        self.get_logger().info(
            f'opened {source.describe()}; f = {rectifier.f:.2f} px, baseline = '
            f'{rectifier.baseline:.4f} m, '
            f'{"rectifying" if rectifier.remaps else "images already rectified"}')
        self._diag.update(Diagnostics.OK, 'capturing', source=cfg.source)
        return True

    def _close(self) -> None:
        if self._source is not None:
            self._source.close()
        self._source = None

    def _run(self) -> None:
        cfg = self.config
        period = 1.0 / cfg.fps
        next_due = time.monotonic()
        failing_since: float | None = None
        while not self._stop.is_set():
            if self._source is None:
                if not self._open():
                    self._stop.wait(cfg.retry_period)
                    continue
                failing_since = None
                next_due = time.monotonic()
            try:
                frame = self._source.read()
            except SourceEnded as exc:
                self.get_logger().info(f'{exc}: no more frames (set loop to repeat)')
                self._diag.update(Diagnostics.WARN, 'source ended: no more frames',
                                  published=self.published)
                self._close()
                self._stop.wait()
                break
            except SourceError as exc:
                now = time.monotonic()
                failing_since = failing_since or now
                self.get_logger().warning(f'{self._source.describe()}: {exc}',
                                          throttle_duration_sec=2.0)
                if now - failing_since > cfg.retry_period:
                    self.get_logger().error(
                        f'no frames for {now - failing_since:.1f} s: reopening '
                        f'{self._source.describe()}', throttle_duration_sec=10.0)
                    self._diag.update(Diagnostics.ERROR, f'no frames: {exc}',
                                      published=self.published)
                    self._close()
                else:
                    self._diag.update(Diagnostics.WARN, f'frame grab failed: {exc}',
                                      published=self.published)
                self._stop.wait(0.05)
                continue
            failing_since = None
            try:
                left, right = self._rectifier.rectify(frame.left, frame.right)
            except FrameSizeError as exc:
                self.skipped += 1
                self.get_logger().error(str(exc), throttle_duration_sec=5.0)
                self._diag.update(Diagnostics.ERROR, f'pair skipped: {exc}',
                                  skipped=self.skipped)
                continue
            self._publish(left, right, frame.stamp_ns)
            self._diag.update(Diagnostics.OK, 'capturing', published=self.published,
                              skipped=self.skipped)
            if not self._source.live:  # files: play at fps
                next_due += period
                delay = next_due - time.monotonic()
                if delay < -period:
                    next_due = time.monotonic()
                elif delay > 0:
                    self._stop.wait(delay)
        self._close()

    def _publish(self, left: np.ndarray, right: np.ndarray, stamp_ns: int) -> None:
        cfg = self.config
        h, w = left.shape
        stamp = ns_to_stamp(stamp_ns)
        hl = Header(stamp=stamp, frame_id=cfg.left_frame_id)
        hr = Header(stamp=stamp, frame_id=cfg.right_frame_id)
        r = self._rectifier
        self._pub_left_info.publish(camera_info_msg(r.p_left, w, h, hl))
        self._pub_right_info.publish(camera_info_msg(r.p_right, w, h, hr))
        self._pub_left.publish(array_to_image_msg(left, hl))
        self._pub_right.publish(array_to_image_msg(right, hr))
        self.published += 1

    def destroy_node(self):
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        return super().destroy_node()


def main(args=None):
    run_node(StereoCaptureNode, args, name='stereo_capture_node')


if __name__ == '__main__':
    main()
