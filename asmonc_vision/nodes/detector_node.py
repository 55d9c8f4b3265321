"""GPOD obstacle detector node.

Subscribes to the rectified stereo pair and its camera infos, pairs left and right by
stamp, and runs the core detector (`core.gpod.GpodDetector`) on a worker thread so the
callbacks that receive images stay fast. Publishes, per processed pair:

* `/obstacles` (asmonc_vision_msgs/ObstacleArray): stamp of the pair, left optical frame.
  Published for every good pair, empty when nothing stands above the ground.
* `/ground_plane` (asmonc_vision_msgs/GroundPlane)
* `/obstacles/markers` (visualization_msgs/MarkerArray), `/detector/debug_image` (bgr8)
* `/diagnostics`

Focal length, principal point and baseline come from the CameraInfo on the wire, the
ground plane from the images: the node works on any rectified rig and image size.
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import Point
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from asmonc_vision_msgs.msg import GroundPlane, Obstacle, ObstacleArray

from asmonc_vision.core.camera import StereoCamera, metric_from_plane
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.draw import draw_debug
from asmonc_vision.core.gpod import GpodConfig, GpodDetector, GpodResult
from asmonc_vision.nodes.common import (IMAGE_QOS, RESULT_QOS, Diagnostics, declare_config,
                                        run_node)
from asmonc_vision.nodes.conversions import (ImageFormatError, array_to_image_msg,
                                             image_msg_to_gray, stamp_to_ns,
                                             stereo_camera_from_infos)

_STATUS = {'initialising': GroundPlane.INITIALISING, 'tracking': GroundPlane.TRACKING,
           'lost': GroundPlane.LOST}


@dataclass(frozen=True)
class DetectorNodeConfig:
    """Settings of the node around the core detector (the detector's own: GpodConfig)."""

    max_stamp_skew: float = param(
        0.0, 'largest left/right stamp difference still paired, s (0: stamps must be equal)',
        range=(0.0, 0.1))
    max_pending_pairs: int = param(
        30, 'pairs waiting for the detector before the oldest is dropped (with a warning)',
        range=(1, 1000))
    unpaired_timeout: float = param(
        1.0, 'an image with no partner this long (s of stamp time) is dropped with a warning',
        range=(0.05, 10.0))
    publish_debug_image: bool = param(True, 'publish /detector/debug_image')
    publish_markers: bool = param(True, 'publish /obstacles/markers')
    time_jump_reset: float = param(
        1.0, 'stamps going back by more than this (s) restart the detector (bag loop)',
        range=(0.0, 1e6))
    info_wait: float = param(
        1.0, 'how long a pair waits for its first camera_info before it is skipped, s',
        range=(0.0, 10.0))
    input_timeout: float = param(
        2.0, 'no image pair for this long (s) is reported in /diagnostics', range=(0.1, 60.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass
class _Pair:
    stamp_ns: int
    left: Image
    right: Image
    left_info: CameraInfo | None
    right_info: CameraInfo | None


class StereoPairer:
    """Pairs left and right images by stamp (pure bookkeeping, no ROS calls).

    `add(side, stamp_ns, item)` returns the (left, right) items when a partner with a
    stamp within `max_skew_ns` exists, else None. Items older than `timeout_ns` than the
    newest stamp seen, still unpaired, are returned by `expire()` for reporting.
    """

    def __init__(self, max_skew_ns: int, timeout_ns: int, capacity: int = 64):
        self.max_skew_ns = max_skew_ns
        self.timeout_ns = timeout_ns
        self._waiting = {'left': collections.OrderedDict(), 'right': collections.OrderedDict()}
        self._capacity = capacity
        self._newest = 0

    def add(self, side: str, stamp_ns: int, item):
        other = 'right' if side == 'left' else 'left'
        self._newest = max(self._newest, stamp_ns)
        best, best_dt = None, None
        for s in self._waiting[other]:
            dt = abs(s - stamp_ns)
            if dt <= self.max_skew_ns and (best_dt is None or dt < best_dt):
                best, best_dt = s, dt
        if best is not None:
            partner = self._waiting[other].pop(best)
            return (item, partner) if side == 'left' else (partner, item)
        waiting = self._waiting[side]
        waiting[stamp_ns] = item
        while len(waiting) > self._capacity:
            waiting.popitem(last=False)
        return None

    def expire(self) -> list[tuple[str, int]]:
        """Drop and return (side, stamp_ns) of images that will never find a partner."""
        gone = []
        for side, waiting in self._waiting.items():
            for s in [s for s in waiting if self._newest - s > self.timeout_ns]:
                waiting.pop(s)
                gone.append((side, s))
        return gone

    def clear(self) -> None:
        for w in self._waiting.values():
            w.clear()
        self._newest = 0


class DetectorNode(Node):
    """GPOD detection on the rectified stereo pair; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__('detector_node', **kwargs)
        self.node_config = declare_config(self, DetectorNodeConfig)
        self.gpod_config = declare_config(self, GpodConfig, prefix='gpod.')
        self.detector = GpodDetector(self.gpod_config)
        cfg = self.node_config

        self.pub_obstacles = self.create_publisher(ObstacleArray, '/obstacles', RESULT_QOS)
        self.pub_plane = self.create_publisher(GroundPlane, '/ground_plane', RESULT_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, '/obstacles/markers', RESULT_QOS)
        self.pub_debug = self.create_publisher(Image, '/detector/debug_image', IMAGE_QOS)
        self.diag = Diagnostics(self, 'asmonc_vision: detector')

        self._lock = threading.Lock()
        self._info = {'left': None, 'right': None}
        self._pairer = StereoPairer(int(cfg.max_stamp_skew * 1e9),
                                    int(cfg.unpaired_timeout * 1e9))
        self._pending = collections.deque()
        self._cv = threading.Condition()
        self._last_stamp_ns: int | None = None
        self._camera: StereoCamera | None = None
        self._camera_key = None
        self._last_pair_wall = time.monotonic()
        self.frames_in = 0
        self.frames_done = 0
        self.frames_dropped = 0
        self.frames_bad = 0
        self._stop = False

        self.create_subscription(Image, '/stereo/left/image_rect',
                                 lambda m: self._on_image('left', m), IMAGE_QOS)
        self.create_subscription(Image, '/stereo/right/image_rect',
                                 lambda m: self._on_image('right', m), IMAGE_QOS)
        self.create_subscription(CameraInfo, '/stereo/left/camera_info',
                                 lambda m: self._on_info('left', m), IMAGE_QOS)
        self.create_subscription(CameraInfo, '/stereo/right/camera_info',
                                 lambda m: self._on_info('right', m), IMAGE_QOS)
        self.create_timer(0.5, self._check_input)
        self._worker = threading.Thread(target=self._work, name='gpod-worker', daemon=True)
        self._worker.start()
        self.get_logger().info('detector ready: waiting for /stereo/{left,right}/image_rect')

    # --- callbacks: cheap bookkeeping only --------------------------------------------
    def _on_info(self, side: str, msg: CameraInfo) -> None:
        with self._lock:
            self._info[side] = msg

    def _on_image(self, side: str, msg: Image) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        with self._lock:
            pair = self._pairer.add(side, stamp, msg)
            expired = self._pairer.expire()
            infos = (self._info['left'], self._info['right'])
        for s, t in expired:
            self.frames_bad += 1
            self.get_logger().warn(
                f'{s} image at stamp {t / 1e9:.3f} s has no partner with the same stamp; '
                'dropped (left and right must share one stamp)', throttle_duration_sec=2.0)
        if pair is None:
            return
        self.frames_in += 1
        with self._cv:
            self._pending.append(_Pair(stamp, pair[0], pair[1], *infos))
            while len(self._pending) > self.node_config.max_pending_pairs:
                old = self._pending.popleft()
                self.frames_dropped += 1
                self.get_logger().warn(
                    f'detector falling behind: dropped the pair at {old.stamp_ns / 1e9:.3f} s '
                    f'({self.frames_dropped} dropped so far)', throttle_duration_sec=2.0)
            self._cv.notify()

    def _check_input(self) -> None:
        idle = time.monotonic() - self._last_pair_wall
        if idle > self.node_config.input_timeout:
            self.diag.update(Diagnostics.WARN, f'no stereo pair for {idle:.1f} s',
                             frames_in=self.frames_in, frames_done=self.frames_done)

    # --- worker --------------------------------------------------------------------
    def _work(self) -> None:
        while True:
            with self._cv:
                while not self._pending and not self._stop:
                    self._cv.wait(timeout=0.5)
                if self._stop:
                    return
                pair = self._pending.popleft()
            try:
                self._process(pair)
            except Exception as exc:  # a bug must not silence the detector for good
                self.frames_bad += 1
                self.get_logger().error(f'detector failed on pair {pair.stamp_ns / 1e9:.3f} s: '
                                        f'{type(exc).__name__}: {exc}',
                                        throttle_duration_sec=1.0)
                self.diag.update(Diagnostics.ERROR, f'internal error: {exc}')

    def _camera_for(self, pair: _Pair) -> StereoCamera | None:
        # The infos travel on their own topics and may arrive just after the images.
        deadline = time.monotonic() + self.node_config.info_wait
        while pair.left_info is None or pair.right_info is None:
            with self._lock:
                pair.left_info = pair.left_info or self._info['left']
                pair.right_info = pair.right_info or self._info['right']
            if pair.left_info is not None and pair.right_info is not None:
                break
            if time.monotonic() > deadline or self._stop:
                self.get_logger().warn(
                    'no camera_info on /stereo/{left,right}/camera_info; pair skipped',
                    throttle_duration_sec=2.0)
                return None
            time.sleep(0.01)
        key = (tuple(pair.left_info.p), tuple(pair.right_info.p),
               pair.left_info.width, pair.left_info.height)
        if key != self._camera_key:
            try:
                cam = stereo_camera_from_infos(pair.left_info, pair.right_info)
            except ValueError as exc:
                self.get_logger().error(f'bad camera_info: {exc}', throttle_duration_sec=2.0)
                return None
            if self._camera is not None:
                self.get_logger().info(f'camera changed to {cam}; re-initialising the plane')
                self.detector.reset()
            self._camera, self._camera_key = cam, key
            self.get_logger().info(
                f'camera: {cam.width}x{cam.height}, f={cam.f:.1f} px, B={cam.baseline:.3f} m')
        return self._camera

    def _process(self, pair: _Pair) -> None:
        self._last_pair_wall = time.monotonic()
        if self._last_stamp_ns is not None and pair.stamp_ns <= self._last_stamp_ns:
            back = (self._last_stamp_ns - pair.stamp_ns) / 1e9
            if back > self.node_config.time_jump_reset:
                self.get_logger().info(f'time went back {back:.1f} s: restarting the detector')
                self.detector.reset()
            else:
                self.frames_bad += 1
                self.get_logger().warn(
                    f'pair at {pair.stamp_ns / 1e9:.3f} s is not newer than the last one '
                    f'({self._last_stamp_ns / 1e9:.3f} s); skipped', throttle_duration_sec=2.0)
                return
        try:
            left = image_msg_to_gray(pair.left)
            right = image_msg_to_gray(pair.right)
        except ImageFormatError as exc:
            self.frames_bad += 1
            self.get_logger().error(f'bad image: {exc}; pair skipped', throttle_duration_sec=2.0)
            self.diag.update(Diagnostics.ERROR, f'bad image: {exc}')
            return
        if left.shape != right.shape:
            self.frames_bad += 1
            self.get_logger().error(
                f'left image is {left.shape[1]}x{left.shape[0]} but right is '
                f'{right.shape[1]}x{right.shape[0]}; pair skipped', throttle_duration_sec=2.0)
            self.diag.update(Diagnostics.ERROR, 'left and right images differ in size')
            return
        cam = self._camera_for(pair)
        if cam is None:
            self.frames_bad += 1
            return
        if (cam.height, cam.width) != left.shape:
            self.frames_bad += 1
            self.get_logger().error(
                f'images are {left.shape[1]}x{left.shape[0]} but camera_info says '
                f'{cam.width}x{cam.height}; pair skipped', throttle_duration_sec=2.0)
            return
        result = self.detector.process(left, right, cam)
        self._last_stamp_ns = pair.stamp_ns
        self._publish(pair, cam, left, result)
        self.frames_done += 1

    # --- output --------------------------------------------------------------------
    def _publish(self, pair: _Pair, cam: StereoCamera, left: np.ndarray,
                 result: GpodResult) -> None:
        header = pair.left.header
        self.pub_obstacles.publish(obstacles_to_msg(result, header))
        self.pub_plane.publish(plane_to_msg(result, cam, header))
        if self.node_config.publish_markers:
            self.pub_markers.publish(markers_msg(result, header))
        if self.node_config.publish_debug_image and self.pub_debug.get_subscription_count() > 0:
            self.pub_debug.publish(array_to_image_msg(draw_debug(left, result), header))
        level = Diagnostics.OK if result.status == 'tracking' else Diagnostics.WARN
        self.diag.update(level, f'{result.status}: {len(result.obstacles)} obstacles',
                         frames_in=self.frames_in, frames_done=self.frames_done,
                         frames_dropped=self.frames_dropped, frames_bad=self.frames_bad,
                         total_ms=f"{result.timings.get('total', float('nan')):.1f}")

    def destroy_node(self):
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._worker.join(timeout=2.0)
        return super().destroy_node()


def obstacles_to_msg(result: GpodResult, header) -> ObstacleArray:
    """GpodResult obstacles to an ObstacleArray with the pair's header."""
    out = ObstacleArray(header=header)
    for ob in result.obstacles:
        m = Obstacle()
        m.id = int(getattr(ob, 'id', 0))
        m.position = Point(x=float(ob.position[0]), y=float(ob.position[1]),
                           z=float(ob.position[2]))
        m.height = float(ob.height)
        m.range = float(ob.range)
        m.bearing = float(ob.bearing)
        m.width = float(ob.width)
        m.disparity_excess = float(ob.disparity_excess)
        m.confidence = float(ob.confidence)
        x, y, w, h = (int(v) for v in ob.roi)
        m.roi.x_offset, m.roi.y_offset, m.roi.width, m.roi.height = (
            max(x, 0), max(y, 0), max(w, 0), max(h, 0))
        out.obstacles.append(m)
    return out


def plane_to_msg(result: GpodResult, cam: StereoCamera, header) -> GroundPlane:
    """The frame's ground plane (or its absence) as a GroundPlane message."""
    msg = GroundPlane(header=header, status=_STATUS.get(result.status, GroundPlane.LOST))
    plane = result.plane
    if plane is not None:
        msg.a, msg.b, msg.c = (float(v) for v in plane.abc)
        msg.covariance = [float(v) for v in np.asarray(plane.cov, float).reshape(9)]
        msg.num_features = int(plane.num_features)
        msg.residual_rms = float(plane.residual_rms)
        metric = metric_from_plane(cam, plane.abc)
        if metric is not None:
            n = metric.normal_up
            msg.normal.x, msg.normal.y, msg.normal.z = float(n[0]), float(n[1]), float(n[2])
            msg.height = float(metric.height)
    return msg


def markers_msg(result: GpodResult, header) -> MarkerArray:
    """A sphere at each obstacle's top and a label with its height and range."""
    out = MarkerArray()
    out.markers.append(Marker(header=header, ns='obstacles', action=Marker.DELETEALL))
    for i, ob in enumerate(result.obstacles):
        p = Point(x=float(ob.position[0]), y=float(ob.position[1]), z=float(ob.position[2]))
        sphere = Marker(header=header, ns='obstacles', id=2 * i, type=Marker.SPHERE,
                        action=Marker.ADD)
        sphere.pose.position = p
        sphere.pose.orientation.w = 1.0
        sphere.scale.x = sphere.scale.y = sphere.scale.z = 0.15
        sphere.color = ColorRGBA(r=1.0, g=0.2, b=0.1, a=0.9)
        label = Marker(header=header, ns='obstacles', id=2 * i + 1,
                       type=Marker.TEXT_VIEW_FACING, action=Marker.ADD)
        label.pose.position = Point(x=p.x, y=p.y - 0.2, z=p.z)
        label.pose.orientation.w = 1.0
        label.scale.z = 0.12
        label.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        label.text = f'{ob.height * 100:.0f} cm @ {ob.range:.1f} m'
        out.markers.extend([sphere, label])
    return out


def main(args=None):
    run_node(DetectorNode, args, name='detector_node')


if __name__ == '__main__':
    main()
