"""GPOD obstacle detector node.

Subscribes to the rectified stereo pair and its camera infos, pairs left and right by
stamp, and runs the core detector (`core.gpod.GpodDetector`) on a worker thread so the
callbacks that receive images stay fast. Publishes, per processed pair:

* `/obstacles` (asmonc_vision_msgs/ObstacleArray): stamp of the pair, left optical frame.
  Published for every good pair, empty when nothing stands above the ground. ``id`` is
  the obstacle's track id (stable while it is tracked, 0 for drop-offs, which are not
  tracked); an obstacle whose evidence dips for a frame or two is still reported at
  its tracked place (`core.obstacle_tracks`; moved by `/egomotion` when taken, below). An entry
  whose ``height`` is NaN is no obstacle: the walking corridor's ground from its
  ``range`` on cannot be seen (`core.unseen_ground`); the alarm node says so.
* `/ground_plane` (asmonc_vision_msgs/GroundPlane)
* `/obstacles/markers` (visualization_msgs/MarkerArray), `/detector/debug_image` (bgr8)
* `/obstacle_map` (nav_msgs/OccupancyGrid, RELIABLE, depth 1), with the evidence map
  enabled (``map.enabled``) and someone subscribed: the map around the wearer, in the
  pair's left optical frame (the grid's origin pose places its horizontal world-fixed
  axes there), cell value P(raised) in percent, -1 where it holds no evidence
* `/diagnostics`: the pair counts, the image noise and edge threshold, the rows'
  misalignment, the time per pair, and how far the ground surface ahead is known
  (``ground_known_m``, m along the ground) with the rule that ended it
  (``ground_ended_by``, e.g. ``rule_step +7.5 cm``: `GroundSurface.ended_by`)

Subscribes to `/inclinometer/imu` (sensor_msgs/Imu, SENSOR_QOS) and keeps the latest
orientation: a pair stamped within ``gpod.plane.gravity_prior_max_age_s`` of it gets the world's
up direction (`core.rotations.up_for_pair`) as the prior on the ground plane's orientation
(``gpod.gravity_prior_*``); without an inclinometer the plane comes from the images alone.

With ``map.enabled`` the obstacles reported are those the evidence map confirms
(`core.perception.Perception`, `core.evidence_map`): seen from two viewpoints, not
cleared by ground seen where they stood. The map places each pair by the camera motion
since the previous pair processed, and never waits for it: it subscribes to
`/egomotion/odometry` (nav_msgs/Odometry, the egomotion node's chained pose, published
for every pair it processes) and a `core.map_motion.MotionPredictor` gives each pair
the motion from the poses received by then (the pair's own when it is in, else
extrapolated at constant velocity from the newest, the error corrected on the next
pair). With no odometry (no egomotion node, or none for ``max_extrapolation``) the map
holds still while the rig stands still and is cleared while it moves, and the
detector's own reports go out.

With ``use_egomotion`` (off by default), subscribes to `/egomotion`
(geometry_msgs/TransformStamped, the visual egomotion node's motion of the left camera from
the previous pair to this one) as the motion input of the ground plane and the obstacle
tracks: once a pair's edges are matched the worker waits up to ``egomotion_wait`` for that
pair's motion (the egomotion node works on the pair meanwhile); the ground plane is
predicted through the motion (`gpod.plane.motion_*`) and the tracks are carried through it.
The wait puts the egomotion node's time (about 35 ms a pair at 320x240) on the path from
camera to ear, and on the campaign's walks the motion input gave more false reports, not
fewer; so by default the plane is refitted on each pair without a prediction, and the
tracks are carried only while the rig stands still (as with no motion: no egomotion node,
a pair it could not estimate, a pair dropped here).

Focal length, principal point and baseline come from the CameraInfo on the wire, the
ground plane from the images: the node works on any rectified rig and image size.
"""
from __future__ import annotations

import array
import collections
import threading
import time
from dataclasses import dataclass

import cv2
import numpy as np
from geometry_msgs.msg import Point, Pose, TransformStamped
from nav_msgs.msg import MapMetaData, OccupancyGrid, Odometry
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, Imu
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from asmonc_vision_msgs.msg import GroundPlane, Obstacle, ObstacleArray

from asmonc_vision.core.camera import StereoCamera, metric_from_plane
from asmonc_vision.core.config import param
from asmonc_vision.core.draw import draw_debug
from asmonc_vision.core.evidence_map import EvidenceMap, EvidenceMapConfig
from asmonc_vision.core.gpod import GpodConfig, GpodResult
from asmonc_vision.core.map_motion import MotionPredictor
from asmonc_vision.core.perception import Perception
from asmonc_vision.core.rotations import (matrix_to_quaternion, quaternion_to_matrix,
                                          up_for_pair)
from asmonc_vision.nodes.common import (IMAGE_QOS, RESULT_QOS, SENSOR_QOS, Diagnostics,
                                        declare_config, run_node)
from asmonc_vision.nodes.conversions import array_to_image_msg, stamp_to_ns
from asmonc_vision.nodes.stereo_input import StereoInputConfig, StereoInputNode, StereoPair

#: A rectified pair's rows this far apart (pixels) is reported: the rig needs recalibrating.
_MISALIGNMENT_WARN_PX = 1.0
#: /obstacle_map: a large message each pair, only the newest of interest
MAP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
_STATUS = {'initialising': GroundPlane.INITIALISING, 'tracking': GroundPlane.TRACKING,
           'lost': GroundPlane.LOST}


@dataclass(frozen=True)
class DetectorNodeConfig(StereoInputConfig):
    """Settings of the node around the core detector (the detector's own: GpodConfig);
    the stereo input's are `StereoInputConfig`'s."""

    max_pending_pairs: int = param(
        30, 'pairs waiting for the detector before the oldest is dropped (with a warning)',
        range=(1, 1000))
    publish_debug_image: bool = param(True, 'publish /detector/debug_image')
    debug_image_max_width: int = param(
        320, 'the debug image is scaled down to at most this width, px (0: full size; a '
        '640x480 bgr8 image at 10 Hz is 9 MB/s for every subscriber and recorder)',
        range=(0, 10000))
    publish_markers: bool = param(True, 'publish /obstacles/markers')
    use_egomotion: bool = param(
        False, 'take /egomotion (the visual egomotion node) as the motion input of the '
        'ground plane and the obstacle tracks: each pair then waits up to egomotion_wait '
        'for its motion, which adds the egomotion node\'s time to every pair\'s latency. '
        'Off, the plane is refitted on each pair and the tracks are carried only while the '
        'rig stands still (fewer false reports, asmonc campaign --methods gpod gpod_ego). '
        'The evidence map (map.enabled) never waits: it takes /egomotion/odometry')
    egomotion_wait: float = param(
        0.1, 'with the motion input, the longest wait, once a pair is matched, for its '
        '/egomotion message (wall time, s); without it the plane is refitted unpredicted '
        'and the tracks are carried only while the rig stands still',
        range=(0.0, 2.0))
    max_extrapolation: float = param(
        0.5, 'with the evidence map, the camera pose is extrapolated at most this long '
        'past the newest /egomotion/odometry; beyond, the map has no motion (s)',
        range=(0.0, 5.0))


class DetectorNode(StereoInputNode):
    """GPOD detection on the rectified stereo pair; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__('detector_node', 'detector', **kwargs)
        self.node_config = declare_config(self, DetectorNodeConfig)
        self.gpod_config = declare_config(self, GpodConfig, prefix='gpod.')
        self.map_config = declare_config(self, EvidenceMapConfig, prefix='map.')
        #: the evidence map's motion, from /egomotion/odometry (None without the map)
        self.motion_predictor = (MotionPredictor(self.node_config.max_extrapolation)
                                 if self.map_config.enabled else None)
        self.perception = Perception(self.gpod_config, self.map_config, self.motion_predictor)
        self.detector = self.perception.detector
        self.pub_map = self.create_publisher(OccupancyGrid, '/obstacle_map', MAP_QOS)
        self.pub_obstacles = self.create_publisher(ObstacleArray, '/obstacles', RESULT_QOS)
        self.pub_plane = self.create_publisher(GroundPlane, '/ground_plane', RESULT_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, '/obstacles/markers', RESULT_QOS)
        self.pub_debug = self.create_publisher(Image, '/detector/debug_image', IMAGE_QOS)
        #: /egomotion by stamp (ns) -> (R, t, the stamp of the /egomotion before it: the
        #: pair it is from), the newest and the last stamp received, the previous
        #: processed pair's stamp, and how many pairs had a motion
        self._motions: collections.OrderedDict = collections.OrderedDict()
        self._motion_cv = threading.Condition()
        self._newest_motion_ns = -1
        self._last_motion_ns: int | None = None
        self._prev_stamp_ns: int | None = None
        self.motions_used = 0
        #: the detector waits for each pair's /egomotion
        self.use_motion = self.node_config.use_egomotion
        if self.use_motion:
            self.create_subscription(TransformStamped, '/egomotion', self._on_egomotion,
                                     RESULT_QOS)
        if self.motion_predictor is not None:
            self.create_subscription(Odometry, '/egomotion/odometry', self._on_odometry,
                                     RESULT_QOS)
        #: the latest /inclinometer/imu orientation: (stamp ns, (4,) quaternion x, y, z, w)
        self._imu: tuple[int, np.ndarray] | None = None
        self.create_subscription(Imu, '/inclinometer/imu', self._on_imu, SENSOR_QOS)
        # The debug image is drawn and published on its own thread, newest frame only:
        # a slow subscriber of that large RELIABLE image (a recorder compressing it) must
        # never hold back the next /obstacles (at 640x480 it once held the worker for
        # 1.9 s, and the alarm node announced a FAULT).
        self._debug_slot = None
        self._debug_cv = threading.Condition()
        self._debug_stop = False
        self._debug_thread = None
        if self.node_config.publish_debug_image:
            self._debug_thread = threading.Thread(target=self._debug_work,
                                                  name='detector-debug', daemon=True)
            self._debug_thread.start()
        self.start_stereo_input(self.node_config)
        self.get_logger().info('detector ready: waiting for /stereo/{left,right}/image_rect')

    def restart(self) -> None:
        self.perception.reset()
        self._prev_stamp_ns = None
        self._imu = None
        with self._motion_cv:           # (time went back: the motions' stamps are void)
            self._motions.clear()
            self._newest_motion_ns, self._last_motion_ns = -1, None

    def _debug_work(self) -> None:
        while True:
            with self._debug_cv:
                while self._debug_slot is None and not self._debug_stop:
                    self._debug_cv.wait(timeout=0.5)
                if self._debug_stop:
                    return
                left, result, header = self._debug_slot
                self._debug_slot = None
            try:
                img = draw_debug(left, result)
                max_w = self.node_config.debug_image_max_width
                if 0 < max_w < img.shape[1]:
                    h = max(int(round(img.shape[0] * max_w / img.shape[1])), 1)
                    img = cv2.resize(img, (max_w, h), interpolation=cv2.INTER_AREA)
                self.pub_debug.publish(array_to_image_msg(img, header))
            except Exception as exc:  # noqa: BLE001 - the debug view must not stop the node
                self.get_logger().warn(f'debug image not published: {exc}',
                                       throttle_duration_sec=5.0)

    def destroy_node(self):
        with self._debug_cv:
            self._debug_stop = True
            self._debug_cv.notify_all()
        if self._debug_thread is not None:
            self._debug_thread.join(timeout=2.0)
        return super().destroy_node()

    def _pose(self, q, p, topic: str):
        """(R (3, 3), t (3,)) of a quaternion and a translation or position message
        field, or None (logged, throttled) when either is invalid."""
        t = np.array([p.x, p.y, p.z], float)
        try:
            R = quaternion_to_matrix(np.array([q.x, q.y, q.z, q.w], float))
        except ValueError:
            R = None
        if R is None or not np.all(np.isfinite(t)):
            self.get_logger().warn(f'{topic} with an invalid rotation or translation ignored',
                                   throttle_duration_sec=5.0)
            return None
        return R, t

    def _on_egomotion(self, msg: TransformStamped) -> None:
        pose = self._pose(msg.transform.rotation, msg.transform.translation, '/egomotion')
        if pose is None:
            return
        stamp = stamp_to_ns(msg.header.stamp)
        with self._motion_cv:
            # the motion is from the pair of the /egomotion before it (the egomotion node's
            # contract: the pair it estimated before, pairs it dropped lie in between)
            ref, self._last_motion_ns = self._last_motion_ns, stamp
            self._motions[stamp] = (*pose, ref)
            while len(self._motions) > 64:
                self._motions.popitem(last=False)
            self._newest_motion_ns = max(self._newest_motion_ns, stamp)
            self._motion_cv.notify_all()

    def _on_imu(self, msg: Imu) -> None:
        """Keep the latest inclinometer orientation (one without: ignored)."""
        if msg.orientation_covariance[0] == -1.0:
            return
        o = msg.orientation
        q = np.array([o.x, o.y, o.z, o.w], float)
        if np.all(np.isfinite(q)) and np.linalg.norm(q) > 1e-9:
            self._imu = (stamp_to_ns(msg.header.stamp), q)   # (one reference: atomic)

    def _on_odometry(self, msg: Odometry) -> None:
        p = msg.pose.pose
        pose = self._pose(p.orientation, p.position, '/egomotion/odometry')
        if pose is not None:
            self.motion_predictor.add_pose(stamp_to_ns(msg.header.stamp), *pose)

    def _motion_for(self, stamp_ns: int, prev_stamp_ns: int | None):
        """The pair's /egomotion (R, t), waiting up to ``egomotion_wait`` -- not at all
        when further pairs are already waiting (detection must not fall behind a slow
        egomotion node); None when the motion is not from the pair processed before this
        one (``prev_stamp_ns``: a pair dropped here or by the egomotion node between),
        nobody publishes /egomotion, a later motion arrived instead (none will come for
        this pair) or time ran out."""
        if not self.use_motion or prev_stamp_ns is None:
            return None
        if self.count_publishers('/egomotion') == 0:
            return None
        wait = 0.0 if self.pending_pairs() else self.node_config.egomotion_wait
        deadline = time.monotonic() + wait
        with self._motion_cv:
            while True:
                motion = self._motions.pop(stamp_ns, None)
                if motion is not None:
                    if motion[2] != prev_stamp_ns:
                        return None
                    self.motions_used += 1
                    return motion[:2]
                left = deadline - time.monotonic()
                if self._newest_motion_ns > stamp_ns or left <= 0:
                    return None
                self._motion_cv.wait(left)

    def process_pair(self, pair: StereoPair, left: np.ndarray, right: np.ndarray,
                     cam: StereoCamera) -> None:
        prev_stamp = self._prev_stamp_ns
        self._prev_stamp_ns = pair.stamp_ns

        def motion():
            m = self._motion_for(pair.stamp_ns, prev_stamp)
            if m is not None and self.motion_predictor is not None:
                # the pair's own motion, waited for: the map's prediction is exact
                self.motion_predictor.add_motion(prev_stamp, pair.stamp_ns, m[0], m[1])
            return m

        # the up direction: the latest inclinometer sample, if near the pair's time
        up = up_for_pair(self._imu, pair.stamp_ns, self.gpod_config.plane.gravity_prior_max_age_s)
        result = self.perception.process(left, right, cam, stamp_ns=pair.stamp_ns,
                                         motion=motion if self.use_motion else None, up=up)
        header = pair.left.header
        self.pub_obstacles.publish(obstacles_to_msg(result, header))
        emap = self.perception.map
        if emap is not None and self.pub_map.get_subscription_count() > 0:
            grid = map_msg(emap, header)
            if grid is not None:
                self.pub_map.publish(grid)
        self.pub_plane.publish(plane_to_msg(result, cam, header))
        if self.node_config.publish_markers and self.pub_markers.get_subscription_count() > 0:
            self.pub_markers.publish(markers_msg(result, header))
        if self.node_config.publish_debug_image and self.pub_debug.get_subscription_count() > 0:
            with self._debug_cv:
                self._debug_slot = (left, result, header)   # replaces one not yet drawn
                self._debug_cv.notify()
        level = Diagnostics.OK if result.status == 'tracking' else Diagnostics.WARN
        message = f'{result.status}: {len(result.obstacles)} obstacles'
        mis = result.misalignment_px
        if np.isfinite(mis) and mis >= _MISALIGNMENT_WARN_PX:
            level = Diagnostics.WARN
            # (the size is in misalignment_px: a message that changes is republished)
            message += ('; rows misaligned, '
                        + ('corrected' if result.misalignment_corrected else 'not corrected')
                        + ': recalibrate the stereo rig')
            self.get_logger().warn(
                f'left and right rows misaligned by {mis:.1f} px (the stereo rig has moved '
                'off its calibration); '
                + ('the right image is resampled to match, ' if result.misalignment_corrected
                   else '') + 'recalibrate the cameras', throttle_duration_sec=30.0)
        surf = result.surface
        self.diag.update(level, message,
                         frames_in=self.frames_in, frames_done=self.frames_done + 1,
                         frames_dropped=self.frames_dropped, frames_bad=self.frames_bad,
                         motions_used=self.motions_used,
                         map_motions=(self.motion_predictor.predictions
                                      if self.motion_predictor is not None else 0),
                         map_motion_ahead_ms=self._motion_ahead_ms(),
                         image_noise=f'{self.detector.image_noise_sigma:.2f}',
                         edge_threshold=f'{result.edge_threshold:.2f}',
                         misalignment_px=f'{mis:.2f}',
                         misalignment_corrected=result.misalignment_corrected,
                         total_ms=f"{result.timings.get('total', float('nan')):.1f}",
                         ground_known_m=f'{surf.known_until_m:.1f}' if surf is not None else '',
                         ground_ended_by=surf.ended_by() if surf is not None else '')


    def _motion_ahead_ms(self) -> str:
        """How far past the newest /egomotion/odometry pose the map's latest motion was
        extrapolated, ms ('' without a prediction)."""
        p = self.motion_predictor
        if p is None or p.ahead_ns is None:
            return ''
        return f'{p.ahead_ns / 1e6:.0f}'


def obstacles_to_msg(result: GpodResult, header) -> ObstacleArray:
    """GpodResult obstacles to an ObstacleArray with the pair's header."""
    out = ObstacleArray(header=header)
    for ob in result.obstacles:
        m = Obstacle()
        m.id = int(ob.track_id)
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


def map_msg(emap: EvidenceMap, header) -> OccupancyGrid | None:
    """The evidence map as an OccupancyGrid in the pair's frame (None before a pair with
    a ground plane placed the wearer)."""
    placed = emap.grid_in_camera()
    if placed is None:
        return None
    R, corner = placed
    q = matrix_to_quaternion(R)
    origin = Pose()
    origin.position.x, origin.position.y, origin.position.z = (float(v) for v in corner)
    (origin.orientation.x, origin.orientation.y, origin.orientation.z,
     origin.orientation.w) = (float(v) for v in q)
    info = MapMetaData(map_load_time=header.stamp, resolution=float(emap.config.cell_m),
                       width=int(emap.n), height=int(emap.n), origin=origin)
    msg = OccupancyGrid(header=header, info=info)
    msg.data = array.array('b', emap.occupancy().tobytes())
    return msg


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
