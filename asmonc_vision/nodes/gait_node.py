"""gait_filter_node: the walk model (Molton et al. 1998, Section 5) on ROS topics.

Subscribes:
    /inclinometer/imu (sensor_msgs/Imu, SENSOR_QOS: best effort, so RELIABLE publishers
        are received too): roll, pitch, yaw of inclinometer_link in the world, variances
        from orientation_covariance (a message with orientation_covariance[0] = -1 has no
        orientation and is ignored).
    /egomotion (geometry_msgs/TransformStamped, SENSOR_QOS): the left camera's motion
        from the previous camera frame (header.frame_id) to the current one
        (child_frame_id), stamped with the current frame. Its rotation enters the same
        filter as attitude increments over [previous stamp, stamp] (the optical <-> body
        rotation of docs/CONVENTIONS.md applied); noise gait.egomotion_sigma_deg. An
        interval longer than 1.6 times the usual frame interval (a lost message) cannot
        be placed and is skipped.
Publishes:
    /gait/state (asmonc_vision_msgs/GaitState, RELIABLE): per inclinometer sample --
        stamp = the sample's; walking; step frequency; amplitude, phase, offset per axis;
        predicted roll/pitch/yaw at stamp + horizon with variances.
    /gait/predicted_motion (geometry_msgs/TransformStamped, RELIABLE): the predicted
        rotation of the rig over the horizon: pose of inclinometer_link at stamp +
        horizon (child_frame_id ``predicted_frame_id``) in inclinometer_link at stamp
        (header). Translation is not modelled (zero). A message for DGPR, not for /tf.
    /diagnostics: OK while the inclinometer streams (and for ``startup_grace`` s after
        the start while waiting for its first sample); WARN when it is silent (walking
        false unless visual motion keeps the walk model going) or stamps go backwards;
        WARN "inclinometer jump" while a jump of the attitude is kept out of the walk
        model and for JUMP_WARN s after (core/gait/jump.py: roll or pitch leaping by more
        than gait.jump_deg faster than gait.jump_rate_deg/s; meanwhile /gait/state carries
        the walk model's own estimate).

Stamps older than the last one are ignored (throttled warning); a jump back of more than
5 s (a restarted replay) restarts the filter. Silence is judged on the node's steady
clock. Parameters: ``GaitNodeConfig`` and, under ``gait.``, ``core.gait.GaitConfig``.
"""
from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import TransformStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import Imu

from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.gait import GaitConfig, GaitEstimate, GaitTracker
from asmonc_vision.core.gait.jump import JumpRule
from asmonc_vision.io.bagio import imu_to_rpy_var
from asmonc_vision.core.gait.rotations import (matrix_to_quaternion, quaternion_to_matrix,
                                               wrap_angle)
from asmonc_vision.nodes.common import (RESULT_QOS, SENSOR_QOS, Diagnostics, declare_config,
                                        run_node, watch_input_links)
from asmonc_vision.nodes.conversions import ns_to_stamp, stamp_to_ns
from asmonc_vision_msgs.msg import GaitState

#: a stamp this much older than the last one is a restarted replay: start afresh, s
CLOCK_RESET_JUMP = 5.0
#: period of the silence check on the steady clock, s
CHECK_PERIOD = 0.1
THROTTLE = 5.0
#: an /egomotion interval longer than this times the median interval is skipped
EGO_GAP_FACTOR = 1.6
#: /diagnostics says WARN for this long (s) after the last sample a jump kept out
JUMP_WARN = 5.0


@dataclass(frozen=True)
class GaitNodeConfig:
    """gait_filter_node's own settings (the walk model's are under ``gait.``)."""

    timeout: float = param(1.0, 'no inclinometer sample for this long (steady clock): '
                           'diagnostics WARN and walking false, s', range=(0.05, 60.0))
    startup_grace: float = param(10.0, 'before the first inclinometer sample, the sensor '
                                 'counts as silent only this long after the node started '
                                 '(a driver or a replay starts a moment after the filter), s',
                                 range=(0.0, 300.0))
    use_egomotion: bool = param(True, 'fuse /egomotion rotations into the walk model')
    frame_id: str = param('inclinometer_link', 'frame of /gait/state and of the predicted '
                          "motion's header")
    predicted_frame_id: str = param('inclinometer_link_predicted', 'child frame id of '
                                    '/gait/predicted_motion (the rig at stamp + horizon)')

    def __post_init__(self) -> None:
        check_fields(self)


def gait_state_msg(est: GaitEstimate, stamp, frame_id: str) -> GaitState:
    """GaitState of an estimate (yaw angles wrapped to [-pi, pi))."""
    m = GaitState()
    m.header.stamp = stamp
    m.header.frame_id = frame_id
    m.walking = bool(est.walking)
    m.step_frequency = float(est.step_frequency)
    m.step_frequency_variance = float(est.step_frequency_variance)
    m.amplitude = [float(v) for v in est.amplitude]
    m.phase = [float(v) for v in est.phase]
    off = est.offset.copy()
    off[2] = wrap_angle(float(off[2]))
    m.offset = [float(v) for v in off]
    m.horizon = float(est.horizon)
    pred = est.predicted.copy()
    pred[2] = wrap_angle(float(pred[2]))
    m.predicted = [float(v) for v in pred]
    m.predicted_variance = [float(v) for v in np.diag(est.predicted_covariance)]
    return m


class GaitFilterNode(Node):
    """The walk model on topics (see module doc)."""

    def __init__(self, **kwargs):
        super().__init__('gait_filter_node', **kwargs)
        self.config: GaitNodeConfig = declare_config(self, GaitNodeConfig)
        self.gait_config: GaitConfig = declare_config(self, GaitConfig, prefix='gait.')
        self._lock = threading.Lock()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.tracker = GaitTracker(self.gait_config)
        g = self.gait_config
        self.jump_rule = JumpRule(g.jump_deg, g.jump_rate_deg, g.jump_settle)
        self._last_jump_steady: float | None = None
        self._last_imu_ns: int | None = None
        self._last_imu_steady: float | None = None
        self._started_steady = self._now()
        self._last_ego_steady: float | None = None
        self._ego_prev_ns: int | None = None
        self._ego_intervals: deque = deque(maxlen=15)
        self._last_est: GaitEstimate | None = None
        self._silent_published = -1e9
        self.counts = {'imu': 0, 'out_of_order': 0, 'bad_imu': 0, 'egomotion': 0,
                       'egomotion_skipped': 0, 'resets': 0, 'imu_jumps': 0,
                       'imu_jump_samples': 0}
        self._step_times: deque = deque(maxlen=200)

        self._state_pub = self.create_publisher(GaitState, '/gait/state', RESULT_QOS)
        self._motion_pub = self.create_publisher(TransformStamped, '/gait/predicted_motion',
                                                 RESULT_QOS)
        self._diag = Diagnostics(self, 'gait_filter_node')
        self.create_subscription(Imu, '/inclinometer/imu', self._on_imu, SENSOR_QOS)
        watch_input_links(self, ('/inclinometer/imu',))
        if self.config.use_egomotion:
            self.create_subscription(TransformStamped, '/egomotion', self._on_egomotion,
                                     SENSOR_QOS)
        self._timer = self.create_timer(CHECK_PERIOD, self._on_timer, clock=self._steady)
        self.get_logger().info(
            f'gait filter up: horizon {self.gait_config.horizon} s, prefilter '
            f'{self.gait_config.prefilter_cutoff} Hz, sensor lag '
            f'{self.gait_config.sensor_lag} s, egomotion '
            f'{"on" if self.config.use_egomotion else "off"}')

    def _now(self) -> float:
        return self._steady.now().nanoseconds * 1e-9

    # ------------------------------------------------------------------ callbacks
    def _on_imu(self, msg: Imu) -> None:
        try:
            rpy, var = imu_to_rpy_var(msg)
        except ValueError as exc:
            self.counts['bad_imu'] += 1
            self.get_logger().warning(f'/inclinometer/imu ignored: {exc}',
                                      throttle_duration_sec=THROTTLE)
            return
        ns = stamp_to_ns(msg.header.stamp)
        with self._lock:
            if self._last_imu_ns is not None and ns <= self._last_imu_ns:
                if self._last_imu_ns - ns > CLOCK_RESET_JUMP * 1e9:
                    self.get_logger().info('/inclinometer/imu stamps jumped back (replay '
                                           'restarted?): the walk model starts afresh')
                    self._reset()
                else:
                    self.counts['out_of_order'] += 1
                    self.get_logger().warning(
                        '/inclinometer/imu stamp not later than the last one: ignored '
                        f'({self.counts["out_of_order"]} so far)',
                        throttle_duration_sec=THROTTLE)
                    return
            if not self._jump_checked(ns, rpy, msg.header.stamp):
                return
            t0 = time.perf_counter()
            est = self.tracker.add_inclinometer(ns * 1e-9, rpy, var)
            self._step_times.append(time.perf_counter() - t0)
            if est is None:
                self.counts['out_of_order'] += 1
                return
            if self._last_imu_steady is None:
                self.get_logger().info(f'first inclinometer sample: stamp {ns * 1e-9:.3f} s')
            self._last_imu_ns = ns
            self._last_imu_steady = self._now()
            self.counts['imu'] += 1
            self._publish(est, msg.header.stamp)
            if est.event in ('start', 'stop', 'movement', 'gap'):
                self.get_logger().info(f'walk model: {est.event} at {ns * 1e-9:.2f} s')

    def _jump_checked(self, ns: int, rpy, stamp) -> bool:
        """The jump rule on one sample (core/gait/jump.py): True to pass it to the walk
        model. A rejected sample still counts as a sign of life (the sensor is faulty,
        not silent) and the walk model's own estimate is published for its stamp."""
        verdict = self.jump_rule.check(ns * 1e-9, rpy)
        if verdict == 'ok':
            return True
        if verdict == 'settled':
            self.get_logger().warning(
                'inclinometer: the attitude after the jump has held for '
                f'{self.gait_config.jump_settle:g} s; the walk model restarts from it')
            self._reset()
            self.jump_rule.check(ns * 1e-9, rpy)       # the new attitude is the good one
            return True
        now = self._now()
        self._last_jump_steady = now
        self.counts['imu_jump_samples'] += 1
        if verdict == 'jump':
            self.counts['imu_jumps'] += 1
            self.get_logger().warning(
                f'inclinometer jump at {ns * 1e-9:.2f} s (roll or pitch by more than '
                f'{self.gait_config.jump_deg:g} deg faster than '
                f'{self.gait_config.jump_rate_deg:g} deg/s): a sensor fault, kept out of '
                f'the walk model ({self.counts["imu_jumps"]} so far)',
                throttle_duration_sec=THROTTLE)
        self._last_imu_ns = ns
        self._last_imu_steady = now
        if self.tracker.last_stamp is not None:
            self._publish(self.tracker.estimate(ns * 1e-9), stamp)
        return False

    def _on_egomotion(self, msg: TransformStamped) -> None:
        ns = stamp_to_ns(msg.header.stamp)
        q = msg.transform.rotation
        with self._lock:
            prev = self._ego_prev_ns
            self._ego_prev_ns = ns
            if prev is None or ns <= prev:
                return
            dt = (ns - prev) * 1e-9
            usual = float(np.median(self._ego_intervals)) if self._ego_intervals else dt
            self._ego_intervals.append(dt)
            if dt > EGO_GAP_FACTOR * usual:
                self.counts['egomotion_skipped'] += 1
                return
            try:
                r = quaternion_to_matrix(np.array([q.x, q.y, q.z, q.w], float))
            except ValueError:
                self.counts['egomotion_skipped'] += 1
                return
            if self.tracker.add_egomotion(prev * 1e-9, ns * 1e-9, r):
                self.counts['egomotion'] += 1
                self._last_ego_steady = self._now()
                if self._imu_silent():
                    # the inclinometer is silent: visual motion keeps the model going
                    self._publish(self.tracker.estimate(ns * 1e-9), ns_to_stamp(ns))
            else:
                self.counts['egomotion_skipped'] += 1

    def _on_timer(self) -> None:
        with self._lock:
            now = self._now()
            silent = self._imu_silent()
            ego_alive = (self._last_ego_steady is not None
                         and now - self._last_ego_steady <= self.config.timeout)
            if silent and not ego_alive and self.tracker.walking:
                self.tracker.ekf.stop_walking()
            if (silent and not ego_alive and self._last_est is not None
                    and now - self._silent_published >= self.config.timeout):
                # silence is never "walking": say so, holding the last attitude
                est = self._last_est
                hold = dataclasses.replace(
                    est, walking=False, predicted=est.attitude.copy(), event=None)
                self._publish(hold, self.get_clock().now().to_msg(), remember=False)
                self._silent_published = now
            times = np.array(self._step_times) * 1e3 if self._step_times else np.zeros(1)
            st = self.tracker.stats
            values = dict(self.counts, walking=self.tracker.walking,
                          starts=st.starts, stops=st.stops, relocks=st.relocks,
                          turns=st.turns,
                          egomotion_rejected=st.egomotion_rejected,
                          step_ms_median=f'{np.median(times):.3f}',
                          step_ms_max=f'{times.max():.3f}',
                          last_event=st.last_event)
            age = None if self._last_imu_steady is None else now - self._last_imu_steady
            values['inclinometer_age_s'] = 'never' if age is None else f'{age:.2f}'
        if silent:
            what = ('visual motion only' if ego_alive else 'walking false')
            self._diag.update(Diagnostics.WARN, f'inclinometer silent ({what})', **values)
            # two kinds of line, throttled apart (rclpy throttles per call site): a
            # sensor that never started must not hide the first silence after it did
            if self._last_imu_steady is None:
                self.get_logger().warning(
                    f'/inclinometer/imu silent since the node started: {what}',
                    throttle_duration_sec=THROTTLE)
            else:
                self.get_logger().warning(
                    f'/inclinometer/imu silent for more than {self.config.timeout:.1f} s: '
                    f'{what}', throttle_duration_sec=THROTTLE)
        elif self._last_imu_steady is None:
            self._diag.update(Diagnostics.OK, 'waiting for the inclinometer', **values)
        elif self._jumped_lately(now):
            self._diag.update(Diagnostics.WARN, 'inclinometer jump (sensor fault; samples '
                              'kept out of the walk model)', **values)
        elif self.counts['out_of_order']:
            self._diag.update(Diagnostics.WARN, 'inclinometer stamps out of order',
                              **values)
        else:
            self._diag.update(Diagnostics.OK, 'walking' if values['walking'] else
                              'not walking', **values)

    # ------------------------------------------------------------------ helpers
    def _jumped_lately(self, now: float) -> bool:
        """A jump is being held, or one was within the last JUMP_WARN s."""
        return self.jump_rule.faulty or (self._last_jump_steady is not None
                                         and now - self._last_jump_steady <= JUMP_WARN)

    def _imu_silent(self) -> bool:
        """No inclinometer sample for ``timeout`` s; before the first one, for
        ``startup_grace`` s since the node started."""
        if self._last_imu_steady is None:
            return self._now() - self._started_steady > self.config.startup_grace
        return self._now() - self._last_imu_steady > self.config.timeout

    def _reset(self) -> None:
        self.tracker = GaitTracker(self.gait_config)
        self.jump_rule.reset()
        self._last_imu_ns = None
        self._ego_prev_ns = None
        self._ego_intervals.clear()
        self.counts['resets'] += 1

    def _publish(self, est: GaitEstimate, stamp, remember: bool = True) -> None:
        if remember:
            self._last_est = est
        self._state_pub.publish(gait_state_msg(est, stamp, self.config.frame_id))
        tf = TransformStamped()
        tf.header.stamp = stamp
        tf.header.frame_id = self.config.frame_id
        tf.child_frame_id = self.config.predicted_frame_id
        q = matrix_to_quaternion(est.motion) if est.walking or remember else \
            np.array([0.0, 0.0, 0.0, 1.0])
        tf.transform.rotation.x, tf.transform.rotation.y, tf.transform.rotation.z, \
            tf.transform.rotation.w = (float(v) for v in q)
        self._motion_pub.publish(tf)


def main(args=None):
    run_node(GaitFilterNode, args, name='gait_filter_node')


if __name__ == '__main__':
    main()
