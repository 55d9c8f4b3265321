"""Visual egomotion node: the stereo rig's motion from pair to pair.

Subscribes to the rectified pair and its camera infos (``bagio.TOPICS``), pairs left
and right by stamp (``detector_node.StereoPairer``), and runs the core estimator
(``core.motion.EgomotionEstimator``) on a worker thread, so the image callbacks only
queue messages. Publishes, per pair:

* ``/egomotion`` (geometry_msgs/TransformStamped): the left camera's motion from the
  previous pair to this one, ``T_prev_curr``: it maps points given in the current left
  optical frame into the previous one, ``X_prev = R X_curr + t``; so ``translation`` is
  where the left camera is now, in metres in the previous left optical frame (x right,
  y down, z forward), and ``rotation`` is the current frame's orientation in the
  previous one. ``header.stamp`` = the pair's stamp; ``header.frame_id`` =
  ``child_frame_id`` = the left image's frame id (``stereo_left_optical_frame``). It is a
  relative motion, not a tf frame (never broadcast on /tf). Published only when the
  motion is from the pair received just before this one (no pair dropped, failed or
  skipped in between).
* ``/egomotion/odometry`` (nav_msgs/Odometry): the chained motions, the left optical
  frame's pose in ``odom_frame`` (the left optical frame of the first pair: x right, y
  down, z forward), with its covariance (6x6, x y z then rotation about x y z, in
  ``odom_frame`` axes; first-order propagation of each motion's covariance); ``twist``
  the last motion over its time interval, in the left optical frame, with covariance.
  ``child_frame_id`` = the left optical frame. Published for every pair with a motion
  (also after a gap, from the last pair that had one).
* ``/diagnostics``: OK while tracking; WARN with the reason when a pair gives no motion:
  too few features (a blank wall, darkness, a covered lens), too few matches, no
  consistent motion, an implausible motion; ERROR for bad input.

When a pair gives no motion nothing is published for it: no motion is better than a
wrong one. A pair with too few features keeps the previous textured pair as the
reference, so the next good pair is matched against it; if a pair has features but no
motion can be found the chain is broken: the odometry carries the last pose over and
adds ``lost_position_variance`` / ``lost_rotation_variance`` to its covariance.
"""
from __future__ import annotations

import collections
import itertools
import threading
import time
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.motion import (FIRST, TOO_FEW_FEATURES, EgomotionConfig,
                                       EgomotionEstimator, EgomotionResult)
from asmonc_vision.core.motion.geometry import (adjoint, compose, invert, matrix_to_quaternion,
                                                so3_log)
from asmonc_vision.core.motion.pipeline import use_one_core
from asmonc_vision.nodes.common import (IMAGE_QOS, RESULT_QOS, Diagnostics, declare_config,
                                        run_node)
from asmonc_vision.nodes.conversions import (ImageFormatError, image_msg_to_gray, stamp_to_ns,
                                             stereo_camera_from_infos)
from asmonc_vision.nodes.detector_node import StereoPairer

DEFAULT_LEFT_FRAME = 'stereo_left_optical_frame'


@dataclass(frozen=True)
class EgomotionNodeConfig:
    """Settings of the node around the core estimator (the estimator's own:
    core.motion.EgomotionConfig, under ``motion.``)."""

    max_stamp_skew: float = param(
        0.0, 'largest left/right stamp difference still paired, s (0: stamps must be equal)',
        range=(0.0, 0.1))
    max_pending_pairs: int = param(
        10, 'pairs waiting for the estimator before the oldest is dropped (with a warning)',
        range=(1, 1000))
    unpaired_timeout: float = param(
        1.0, 'an image with no partner this long (s of stamp time) is dropped with a warning',
        range=(0.05, 10.0))
    info_wait: float = param(
        1.0, 'how long a pair waits for its first camera_info before it is skipped, s',
        range=(0.0, 10.0))
    input_timeout: float = param(
        2.0, 'no image pair for this long (s) is reported in /diagnostics', range=(0.1, 60.0))
    time_jump_reset: float = param(
        1.0, 'stamps going back by more than this (s) restart the estimator and the odometry '
        '(bag loop)', range=(0.0, 1e6))
    odom_frame: str = param(
        'egomotion_origin', 'frame id of /egomotion/odometry: the left optical frame of the '
        'first pair (x right, y down, z forward)')
    publish_odometry: bool = param(True, 'publish /egomotion/odometry')
    lost_position_variance: float = param(
        1.0, 'added to each position variance of the odometry when the motion chain breaks '
        '(a pair with features but no motion), m^2', range=(0.0, 1e6))
    lost_rotation_variance: float = param(
        0.1, 'added to each rotation variance of the odometry when the motion chain breaks, '
        'rad^2', range=(0.0, 1e6))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass
class _Pair:
    seq: int
    stamp_ns: int
    left: Image
    right: Image
    left_info: CameraInfo | None
    right_info: CameraInfo | None


class EgomotionNode(Node):
    """Stereo visual egomotion; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__('egomotion_node', **kwargs)
        self.node_config = declare_config(self, EgomotionNodeConfig)
        self.motion_config = declare_config(self, EgomotionConfig, prefix='motion.')
        self.estimator = EgomotionEstimator(self.motion_config)
        cfg = self.node_config

        self.pub_motion = self.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
        self.pub_odom = self.create_publisher(Odometry, '/egomotion/odometry', RESULT_QOS)
        self.diag = Diagnostics(self, 'asmonc_vision: egomotion')

        self._lock = threading.Lock()
        self._info = {'left': None, 'right': None}
        self._pairer = StereoPairer(int(cfg.max_stamp_skew * 1e9),
                                    int(cfg.unpaired_timeout * 1e9))
        self._seq = itertools.count()
        self._pending: collections.deque[_Pair] = collections.deque()
        self._cv = threading.Condition()
        self._stop = False
        self._camera: StereoCamera | None = None
        self._camera_key = None
        self._last_pair_wall = time.monotonic()
        self._last_stamp_ns: int | None = None
        self._last_seq: int | None = None       # seq of the last pair given to the estimator
        self._ref_seq: int | None = None        # seq of the estimator's reference pair
        self._reset_odometry()
        self.frames_in = 0
        self.frames_done = 0
        self.frames_dropped = 0
        self.frames_bad = 0
        self.motions = 0
        self.last_result: EgomotionResult | None = None

        self.create_subscription(Image, '/stereo/left/image_rect',
                                 lambda m: self._on_image('left', m), IMAGE_QOS)
        self.create_subscription(Image, '/stereo/right/image_rect',
                                 lambda m: self._on_image('right', m), IMAGE_QOS)
        self.create_subscription(CameraInfo, '/stereo/left/camera_info',
                                 lambda m: self._on_info('left', m), IMAGE_QOS)
        self.create_subscription(CameraInfo, '/stereo/right/camera_info',
                                 lambda m: self._on_info('right', m), IMAGE_QOS)
        self.create_timer(0.5, self._check_input)
        self._worker = threading.Thread(target=self._work, name='egomotion-worker', daemon=True)
        self._worker.start()
        self.get_logger().info(
            f'egomotion ready ({self.motion_config.method}): waiting for '
            '/stereo/{left,right}/image_rect')

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
            self._pending.append(_Pair(next(self._seq), stamp, pair[0], pair[1], *infos))
            while len(self._pending) > self.node_config.max_pending_pairs:
                old = self._pending.popleft()
                self.frames_dropped += 1
                self.get_logger().warn(
                    f'egomotion falling behind: dropped the pair at {old.stamp_ns / 1e9:.3f} s '
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
            except Exception as exc:  # a bug must not silence the node for good
                self.frames_bad += 1
                self.get_logger().error(f'egomotion failed on pair {pair.stamp_ns / 1e9:.3f} s: '
                                        f'{type(exc).__name__}: {exc}',
                                        throttle_duration_sec=1.0)
                self.diag.update(Diagnostics.ERROR, f'internal error: {exc}')

    def _camera_for(self, pair: _Pair) -> StereoCamera | None:
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
                self.diag.update(Diagnostics.WARN, 'waiting for camera_info')
                return None
            time.sleep(0.01)
        key = (tuple(pair.left_info.p), tuple(pair.right_info.p),
               pair.left_info.width, pair.left_info.height)
        if key != self._camera_key:
            try:
                cam = stereo_camera_from_infos(pair.left_info, pair.right_info)
            except ValueError as exc:
                self.get_logger().error(f'bad camera_info: {exc}', throttle_duration_sec=2.0)
                self.diag.update(Diagnostics.ERROR, f'bad camera_info: {exc}')
                return None
            if self._camera is not None:
                self.get_logger().info(f'camera changed to {cam}; restarting the egomotion')
                self._restart()
            self._camera, self._camera_key = cam, key
            self.get_logger().info(
                f'camera: {cam.width}x{cam.height}, f={cam.f:.1f} px, B={cam.baseline:.3f} m')
        return self._camera

    def _restart(self) -> None:
        self.estimator.reset()
        self._ref_seq = None
        self._reset_odometry()

    def _reset_odometry(self) -> None:
        self._odom_r = np.eye(3)
        self._odom_t = np.zeros(3)
        self._odom_cov = np.zeros((6, 6))
        self._odom_started = False

    def _skip(self, pair: _Pair, level: int, why: str) -> None:
        self.frames_bad += 1
        self._last_seq = pair.seq
        self.diag.update(level, why, frames_in=self.frames_in, frames_done=self.frames_done,
                         frames_bad=self.frames_bad)

    def _process(self, pair: _Pair) -> None:
        self._last_pair_wall = time.monotonic()
        if self._last_stamp_ns is not None and pair.stamp_ns <= self._last_stamp_ns:
            back = (self._last_stamp_ns - pair.stamp_ns) / 1e9
            if back > self.node_config.time_jump_reset:
                self.get_logger().info(f'time went back {back:.1f} s: restarting the egomotion')
                self._restart()
            else:
                self.get_logger().warn(
                    f'pair at {pair.stamp_ns / 1e9:.3f} s is not newer than the last one '
                    f'({self._last_stamp_ns / 1e9:.3f} s); skipped', throttle_duration_sec=2.0)
                self._skip(pair, Diagnostics.WARN, 'stamps not increasing')
                return
        try:
            left = image_msg_to_gray(pair.left)
            right = image_msg_to_gray(pair.right)
        except ImageFormatError as exc:
            self.get_logger().error(f'bad image: {exc}; pair skipped', throttle_duration_sec=2.0)
            self._skip(pair, Diagnostics.ERROR, f'bad image: {exc}')
            return
        if left.shape != right.shape:
            self.get_logger().error(
                f'left image is {left.shape[1]}x{left.shape[0]} but right is '
                f'{right.shape[1]}x{right.shape[0]}; pair skipped', throttle_duration_sec=2.0)
            self._skip(pair, Diagnostics.ERROR, 'left and right images differ in size')
            return
        cam = self._camera_for(pair)
        if cam is None:
            self._skip(pair, Diagnostics.WARN, 'no usable camera_info')
            return
        if (cam.height, cam.width) != left.shape:
            self.get_logger().error(
                f'images are {left.shape[1]}x{left.shape[0]} but camera_info says '
                f'{cam.width}x{cam.height}; pair skipped', throttle_duration_sec=2.0)
            self._skip(pair, Diagnostics.ERROR, 'image size differs from camera_info')
            return
        res = self.estimator.process(left, right, cam, pair.stamp_ns)
        self._last_stamp_ns = pair.stamp_ns
        self.last_result = res
        self.frames_done += 1
        consecutive = (self._ref_seq is not None and self._last_seq is not None
                       and self._ref_seq == self._last_seq and pair.seq == self._last_seq + 1)
        self._last_seq = pair.seq
        frame_id = pair.left.header.frame_id or DEFAULT_LEFT_FRAME
        if res.ok:
            self.motions += 1
            if consecutive:
                self.pub_motion.publish(transform_msg(res, pair.left.header, frame_id))
            self._update_odometry(res)
            if self.node_config.publish_odometry:
                dt = (pair.stamp_ns - res.reference_stamp_ns) / 1e9 \
                    if res.reference_stamp_ns is not None else 0.0
                self.pub_odom.publish(self._odometry_msg(res, pair.left.header, frame_id, dt))
            self._ref_seq = pair.seq
        elif res.status == FIRST:
            self._ref_seq = pair.seq
            self._odom_started = True
        elif res.status != TOO_FEW_FEATURES:
            # this pair became the reference: the chain of motions is broken here
            self._ref_seq = pair.seq
            if self._odom_started:
                c = self.node_config
                self._odom_cov = self._odom_cov + np.diag(
                    [c.lost_position_variance] * 3 + [c.lost_rotation_variance] * 3)
            self._odom_started = True
        self._report(res)

    # --- output --------------------------------------------------------------------
    def _update_odometry(self, res: EgomotionResult) -> None:
        m = res.motion
        ad = adjoint(self._odom_r, self._odom_t)
        cov = m.cov if m.cov is not None else np.zeros((6, 6))
        self._odom_cov = self._odom_cov + ad @ cov @ ad.T
        self._odom_r, self._odom_t = compose(self._odom_r, self._odom_t, m.R, m.t)
        self._odom_started = True

    def _odometry_msg(self, res: EgomotionResult, header, frame_id: str, dt: float) -> Odometry:
        msg = Odometry()
        msg.header.stamp = header.stamp
        msg.header.frame_id = self.node_config.odom_frame
        msg.child_frame_id = frame_id
        p = msg.pose.pose
        p.position.x, p.position.y, p.position.z = (float(v) for v in self._odom_t)
        q = matrix_to_quaternion(self._odom_r)
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (float(v) for v in q)
        msg.pose.covariance = [float(v) for v in _symmetric(self._odom_cov).ravel()]
        m = res.motion
        if dt > 0:
            # the motion in the current frame's axes: T_prev_curr = (R, t) moves the camera
            # by R^T t in its own (current) axes; its rotation vector is the same in both
            v = m.R.T @ m.t / dt
            w = so3_log(m.R) / dt
            tw = msg.twist.twist
            tw.linear.x, tw.linear.y, tw.linear.z = (float(x) for x in v)
            tw.angular.x, tw.angular.y, tw.angular.z = (float(x) for x in w)
            if m.cov is not None:
                # left perturbation in the previous frame -> right perturbation (current axes)
                r_cp, t_cp = invert(m.R, m.t)
                ad = adjoint(r_cp, t_cp)
                msg.twist.covariance = [float(x) for x in
                                        _symmetric(ad @ m.cov @ ad.T / (dt * dt)).ravel()]
        return msg

    def _report(self, res: EgomotionResult) -> None:
        values = dict(status=res.status, corners_left=res.n_corners[0],
                      corners_right=res.n_corners[1], stereo_features=res.n_stereo,
                      temporal_matches=res.n_matches, inliers=res.n_inliers,
                      cpu_ms=f"{res.timings_ms.get('cpu', float('nan')):.1f}",
                      frames_in=self.frames_in, frames_done=self.frames_done,
                      motions=self.motions, frames_dropped=self.frames_dropped,
                      frames_bad=self.frames_bad)
        if res.ok or res.status == FIRST:
            self.diag.update(Diagnostics.OK, f'tracking: {res.message}', **values)
            return
        if res.status == TOO_FEW_FEATURES:
            text = (f'{res.message}: blank wall, darkness or a covered lens? '
                    'no motion published')
        else:
            text = f'{res.message}; no motion published'
        self.get_logger().warn(text, throttle_duration_sec=2.0)
        self.diag.update(Diagnostics.WARN, text, **values)

    def destroy_node(self):
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._worker.join(timeout=2.0)
        return super().destroy_node()


def _symmetric(c: np.ndarray) -> np.ndarray:
    return 0.5 * (c + c.T)


def transform_msg(res: EgomotionResult, header, frame_id: str) -> TransformStamped:
    """``T_prev_curr`` of a result as a TransformStamped with the pair's stamp; frame_id
    and child_frame_id both the left optical frame (see the module docstring)."""
    msg = TransformStamped()
    msg.header.stamp = header.stamp
    msg.header.frame_id = frame_id
    msg.child_frame_id = frame_id
    t = res.motion.t
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = (
        float(v) for v in t)
    q = matrix_to_quaternion(res.motion.R)
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in q)
    return msg


def main(args=None):
    # its own process: OpenCV and numpy's BLAS on one thread (the budget is one core;
    # not done in __init__, so that building the node in-process changes nothing global)
    use_one_core()
    run_node(EgomotionNode, args, name='egomotion_node')


if __name__ == '__main__':
    main()
