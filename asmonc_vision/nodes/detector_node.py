"""GPOD obstacle detector node.

Subscribes to the rectified stereo pair and its camera infos, pairs left and right by
stamp, and runs the core detector (`core.gpod.GpodDetector`) on a worker thread so the
callbacks that receive images stay fast. Publishes, per processed pair:

* `/obstacles` (asmonc_vision_msgs/ObstacleArray): stamp of the pair, left optical frame.
  Published for every good pair, empty when nothing stands above the ground. ``id`` is
  the obstacle's track id (stable while it is tracked, 0 for drop-offs, which are not
  tracked); while the rig stands still an obstacle whose evidence dips for a frame or
  two is still reported at its tracked place (`core.obstacle_tracks`).
* `/ground_plane` (asmonc_vision_msgs/GroundPlane)
* `/obstacles/markers` (visualization_msgs/MarkerArray), `/detector/debug_image` (bgr8)
* `/diagnostics`

Focal length, principal point and baseline come from the CameraInfo on the wire, the
ground plane from the images: the node works on any rectified rig and image size.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import Point
from sensor_msgs.msg import Image
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from asmonc_vision_msgs.msg import GroundPlane, Obstacle, ObstacleArray

from asmonc_vision.core.camera import StereoCamera, metric_from_plane
from asmonc_vision.core.config import param
from asmonc_vision.core.draw import draw_debug
from asmonc_vision.core.gpod import GpodConfig, GpodDetector, GpodResult
from asmonc_vision.nodes.common import (IMAGE_QOS, RESULT_QOS, Diagnostics, declare_config,
                                        run_node)
from asmonc_vision.nodes.conversions import array_to_image_msg
from asmonc_vision.nodes.stereo_input import StereoInputConfig, StereoInputNode, StereoPair

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
    publish_markers: bool = param(True, 'publish /obstacles/markers')


class DetectorNode(StereoInputNode):
    """GPOD detection on the rectified stereo pair; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__('detector_node', 'detector', **kwargs)
        self.node_config = declare_config(self, DetectorNodeConfig)
        self.gpod_config = declare_config(self, GpodConfig, prefix='gpod.')
        self.detector = GpodDetector(self.gpod_config)
        self.pub_obstacles = self.create_publisher(ObstacleArray, '/obstacles', RESULT_QOS)
        self.pub_plane = self.create_publisher(GroundPlane, '/ground_plane', RESULT_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, '/obstacles/markers', RESULT_QOS)
        self.pub_debug = self.create_publisher(Image, '/detector/debug_image', IMAGE_QOS)
        self.start_stereo_input(self.node_config)
        self.get_logger().info('detector ready: waiting for /stereo/{left,right}/image_rect')

    def restart(self) -> None:
        self.detector.reset()

    def process_pair(self, pair: StereoPair, left: np.ndarray, right: np.ndarray,
                     cam: StereoCamera) -> None:
        result = self.detector.process(left, right, cam, stamp_ns=pair.stamp_ns)
        header = pair.left.header
        self.pub_obstacles.publish(obstacles_to_msg(result, header))
        self.pub_plane.publish(plane_to_msg(result, cam, header))
        if self.node_config.publish_markers and self.pub_markers.get_subscription_count() > 0:
            self.pub_markers.publish(markers_msg(result, header))
        if self.node_config.publish_debug_image and self.pub_debug.get_subscription_count() > 0:
            self.pub_debug.publish(array_to_image_msg(draw_debug(left, result), header))
        level = Diagnostics.OK if result.status == 'tracking' else Diagnostics.WARN
        self.diag.update(level, f'{result.status}: {len(result.obstacles)} obstacles',
                         frames_in=self.frames_in, frames_done=self.frames_done + 1,
                         frames_dropped=self.frames_dropped, frames_bad=self.frames_bad,
                         total_ms=f"{result.timings.get('total', float('nan')):.1f}")


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
