"""Visual egomotion node: the stereo rig's motion from pair to pair.

Subscribes to the rectified pair and its camera infos (``bagio.TOPICS``), pairs left
and right by stamp (``stereo_input.StereoInputNode``), and runs the core estimator
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
  motion is from the pair this node estimated just before, so a subscriber's interval is
  the time since the previous /egomotion (except the first motion after a pair that gave
  none, which is from that pair: the interval a subscriber takes is then too long by
  the pairs without a motion). The node keeps to the newest pair (``max_pending_pairs``
  1): on a CPU too busy for every pair it estimates over a longer interval rather than
  fall behind the camera, and the pairs it had no time for are not in between.
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

from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import param
from asmonc_vision.core.motion import (FIRST, TOO_FEW_FEATURES, EgomotionConfig,
                                       EgomotionEstimator, EgomotionResult)
from asmonc_vision.core.motion.geometry import (adjoint, compose, invert, matrix_to_quaternion,
                                                so3_log)
from asmonc_vision.core.motion.pipeline import use_one_core
from asmonc_vision.nodes.common import (RESULT_QOS, Diagnostics, declare_config,
                                        run_node)
from asmonc_vision.nodes.stereo_input import StereoInputConfig, StereoInputNode, StereoPair

DEFAULT_LEFT_FRAME = 'stereo_left_optical_frame'


@dataclass(frozen=True)
class EgomotionNodeConfig(StereoInputConfig):
    """Settings of the node around the core estimator (the estimator's own:
    core.motion.EgomotionConfig, under ``motion.``); the stereo input's are
    `StereoInputConfig`'s."""

    max_pending_pairs: int = param(
        1, 'pairs waiting for the estimator before the oldest is dropped: 1 keeps to the '
        'newest pair (the motion then spans the pairs dropped; on a busy CPU the motion '
        'stays current instead of falling behind the camera)', range=(1, 1000))
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


class EgomotionNode(StereoInputNode):
    """Stereo visual egomotion; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__('egomotion_node', 'egomotion', **kwargs)
        self.node_config = declare_config(self, EgomotionNodeConfig)
        self.motion_config = declare_config(self, EgomotionConfig, prefix='motion.')
        self.estimator = EgomotionEstimator(self.motion_config)
        self.pub_motion = self.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
        self.pub_odom = self.create_publisher(Odometry, '/egomotion/odometry', RESULT_QOS)
        self._last_seq: int | None = None       # seq of the last pair given to the estimator
        self._ref_seq: int | None = None        # seq of the estimator's reference pair
        self._reset_odometry()
        self.motions = 0
        self.last_result: EgomotionResult | None = None
        self.start_stereo_input(self.node_config)
        self.get_logger().info(
            f'egomotion ready ({self.motion_config.method}): waiting for '
            '/stereo/{left,right}/image_rect')

    def restart(self) -> None:
        self.estimator.reset()
        self._ref_seq = None
        self._reset_odometry()

    def _reset_odometry(self) -> None:
        self._odom_r = np.eye(3)
        self._odom_t = np.zeros(3)
        self._odom_cov = np.zeros((6, 6))
        self._odom_started = False

    def skip_pair(self, pair: StereoPair, level: int, why: str) -> None:
        self._last_seq = pair.seq
        super().skip_pair(pair, level, why)

    def process_pair(self, pair: StereoPair, left: np.ndarray, right: np.ndarray,
                     cam: StereoCamera) -> None:
        res = self.estimator.process(left, right, cam, pair.stamp_ns)
        self.last_result = res
        # from the pair estimated just before: pairs dropped from the queue are not between
        consecutive = self._ref_seq is not None and self._ref_seq == self._last_seq
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
