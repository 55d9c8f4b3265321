"""Write a simulated scenario to a rosbag2 (MCAP, zstd chunk compression) with rosbags.

Per camera frame, at one stamp and in this order: left and right CameraInfo, left and
right Image (mono8), then /ground_truth/obstacles, /ground_truth/camera_pose and
/ground_truth/ground_plane. Inclinometer samples (sensor_msgs/Imu on their own 16 Hz
clock) are interleaved by time. Bag timestamps equal header stamps, which start at
``EPOCH_NS`` (a realistic wall-clock time). Topic names and types come from
``bagio.TOPICS``; frame ids from ``sim.rig``. The bag's metadata ``custom_data`` records
the scenario, seed, duration, rig, gait and the obstacles' footprints (`sim.footprints`).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from asmonc_vision.io import bagio
from asmonc_vision.core.camera import plane_from_metric
from asmonc_vision.sim.footprints import world_footprints
from asmonc_vision.sim.geometry import matrix_to_quaternion, quaternion_from_rpy
from asmonc_vision.sim.inclinometer import simulate_inclinometer
from asmonc_vision.sim.render import StereoRenderer
from asmonc_vision.sim.rig import IMU_FRAME, LEFT_FRAME, RIGHT_FRAME, WORLD_FRAME, RigSettings
from asmonc_vision.sim.scenarios import Scenario, SimFrame, simulate

#: Header stamp (ns) of the first camera frame: 2023-11-14T22:13:20Z.
EPOCH_NS = 1_700_000_000 * 10**9

#: Order of the per-frame topics (keys of bagio.TOPICS).
FRAME_TOPICS = ('left_info', 'right_info', 'left_image', 'right_image',
                'gt_obstacles', 'gt_camera_pose', 'gt_ground_plane')


@dataclass(frozen=True)
class BagSummary:
    """What ``write_bag`` wrote.

    Attributes:
        path: the rosbag2 directory.
        frames: camera frames (stereo pairs); imu: inclinometer samples.
        duration: seconds from the first to the last camera frame.
        size_bytes: total size of the bag directory.
        counts: messages per topic name.
    """

    path: Path
    frames: int
    imu: int
    duration: float
    size_bytes: int
    counts: dict


def stamp_ns(t: float) -> int:
    """Header/bag stamp (ns) of simulation time t (s)."""
    return EPOCH_NS + int(round(t * 1e9))


class _Msgs:
    """Builds the rosbags message objects."""

    def __init__(self, rig: RigSettings) -> None:
        self.ts = bagio.typestore()
        self.t = self.ts.types
        self.rig = rig
        self.cam = rig.camera()
        k, pl, pr = rig.matrices()
        self.k, self.pl, self.pr = k.ravel(), pl.ravel(), pr.ravel()

    def header(self, ns: int, frame: str):
        time = self.t['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9)
        return self.t['std_msgs/msg/Header'](stamp=time, frame_id=frame)

    def roi(self, x: int = 0, y: int = 0, w: int = 0, h: int = 0):
        return self.t['sensor_msgs/msg/RegionOfInterest'](x_offset=x, y_offset=y, height=h,
                                                          width=w, do_rectify=False)

    def camera_info(self, ns: int, right: bool):
        return self.t['sensor_msgs/msg/CameraInfo'](
            header=self.header(ns, RIGHT_FRAME if right else LEFT_FRAME),
            height=self.rig.height, width=self.rig.width, distortion_model='plumb_bob',
            d=np.zeros(5), k=self.k.copy(), r=np.eye(3).ravel(),
            p=(self.pr if right else self.pl).copy(), binning_x=0, binning_y=0, roi=self.roi())

    def image(self, ns: int, img: np.ndarray, right: bool):
        return self.t['sensor_msgs/msg/Image'](
            header=self.header(ns, RIGHT_FRAME if right else LEFT_FRAME),
            height=img.shape[0], width=img.shape[1], encoding='mono8', is_bigendian=0,
            step=img.shape[1], data=np.ascontiguousarray(img, np.uint8).ravel())

    def vector3(self, v):
        return self.t['geometry_msgs/msg/Vector3'](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quaternion(self, q):
        return self.t['geometry_msgs/msg/Quaternion'](x=float(q[0]), y=float(q[1]),
                                                      z=float(q[2]), w=float(q[3]))

    def point(self, p):
        return self.t['geometry_msgs/msg/Point'](x=float(p[0]), y=float(p[1]), z=float(p[2]))

    def obstacles(self, ns: int, frame: SimFrame):
        cls = self.t[f'{bagio.MSG_PACKAGE}/msg/Obstacle']
        obs = [cls(id=o.id, position=self.point(o.position), height=o.height, range=o.range,
                   bearing=o.bearing, width=o.width, disparity_excess=o.disparity_excess,
                   confidence=1.0, roi=self.roi(*o.roi)) for o in frame.obstacles]
        return self.t[f'{bagio.MSG_PACKAGE}/msg/ObstacleArray'](
            header=self.header(ns, LEFT_FRAME), obstacles=obs)

    def camera_pose(self, ns: int, frame: SimFrame):
        pose = self.t['geometry_msgs/msg/Pose'](
            position=self.point(frame.left_pose.centre),
            orientation=self.quaternion(matrix_to_quaternion(frame.left_pose.rotation)))
        return self.t['geometry_msgs/msg/PoseStamped'](header=self.header(ns, WORLD_FRAME),
                                                       pose=pose)

    def ground_plane(self, ns: int, frame: SimFrame):
        cls = self.t[f'{bagio.MSG_PACKAGE}/msg/GroundPlane']
        a, b, c = plane_from_metric(self.cam, frame.plane)
        return cls(header=self.header(ns, LEFT_FRAME), a=float(a), b=float(b), c=float(c),
                   covariance=np.zeros(9), num_features=0, residual_rms=0.0,
                   status=cls.TRACKING, normal=self.vector3(frame.plane.normal_up),
                   height=float(frame.plane.height))

    def imu(self, ns: int, rpy, variance: float):
        cov = np.zeros(9)
        cov[[0, 4, 8]] = variance
        absent = np.zeros(9)
        absent[0] = -1.0
        return self.t['sensor_msgs/msg/Imu'](
            header=self.header(ns, IMU_FRAME),
            orientation=self.quaternion(quaternion_from_rpy(*rpy)),
            orientation_covariance=cov, angular_velocity=self.vector3((0, 0, 0)),
            angular_velocity_covariance=absent.copy(),
            linear_acceleration=self.vector3((0, 0, 0)),
            linear_acceleration_covariance=absent.copy())


def writer_qos():
    """The offered QoS recorded with every topic of a written bag (reliable, depth 10)."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    zero = QosTime(sec=0, nsec=0)
    return [Qos(history=QosHistory.KEEP_LAST, depth=10, reliability=QosReliability.RELIABLE,
                durability=QosDurability.VOLATILE, deadline=zero, lifespan=zero,
                liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=zero,
                avoid_ros_namespace_conventions=False)]


def dir_size(path: Path) -> int:
    """Bytes in the files under ``path``."""
    return sum(p.stat().st_size for p in path.rglob('*') if p.is_file())


def write_bag(scenario: Scenario, out_dir: str | Path,
              progress: Callable[[int, int], None] | None = None,
              on_frame: Callable[[SimFrame], None] | None = None) -> BagSummary:
    """Simulate ``scenario`` and write it as a rosbag2 directory.

    Args:
        scenario: what to simulate.
        out_dir: the bag directory to create (must not exist; rosbags creates it).
        progress: optional callback(frame_index, n_frames) after each frame.
        on_frame: optional callback(SimFrame) after each frame is written (e.g. to keep
            truth the messages do not carry).
    Returns:
        BagSummary.
    Raises:
        rosbags.rosbag2.WriterError: out_dir exists.
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    out = Path(out_dir)
    msgs = _Msgs(scenario.rig)
    ts = msgs.ts
    imu = simulate_inclinometer(scenario.trajectory, scenario.duration, scenario.inclinometer,
                                rng=np.random.default_rng([scenario.seed, 0x1AC1]))
    counts = {bagio.TOPICS[k][0]: 0 for k in FRAME_TOPICS + ('imu',)}
    writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        meta = {'scenario': scenario.name, 'description': scenario.description,
                'seed': scenario.seed, 'duration': scenario.duration,
                'rig': dataclasses.asdict(scenario.rig),
                'gait': dataclasses.asdict(scenario.trajectory.gait),
                'inclinometer': dataclasses.asdict(scenario.inclinometer),
                'epoch_ns': EPOCH_NS, 'generator': 'asmonc_vision.sim',
                'footprints': world_footprints(scenario.world)}
        writer.set_custom_data('asmonc_vision.sim', json.dumps(meta, sort_keys=True))
        conns = {}
        for key in FRAME_TOPICS + ('imu',):
            topic, msgtype = bagio.TOPICS[key]
            conns[key] = writer.add_connection(topic, msgtype, typestore=ts,
                                               offered_qos_profiles=writer_qos())

        def put(key: str, ns: int, msg) -> None:
            topic, msgtype = bagio.TOPICS[key]
            writer.write(conns[key], ns, ts.serialize_cdr(msg, msgtype))
            counts[topic] += 1

        j = 0
        n = scenario.n_frames
        renderer = StereoRenderer(scenario.rig)
        for frame in simulate(scenario, renderer):
            ns = stamp_ns(frame.time)
            while j < imu.times.size and stamp_ns(imu.times[j]) <= ns:
                put('imu', stamp_ns(imu.times[j]), msgs.imu(stamp_ns(imu.times[j]),
                                                             imu.rpy[j], imu.variance))
                j += 1
            put('left_info', ns, msgs.camera_info(ns, right=False))
            put('right_info', ns, msgs.camera_info(ns, right=True))
            put('left_image', ns, msgs.image(ns, frame.left, right=False))
            put('right_image', ns, msgs.image(ns, frame.right, right=True))
            put('gt_obstacles', ns, msgs.obstacles(ns, frame))
            put('gt_camera_pose', ns, msgs.camera_pose(ns, frame))
            put('gt_ground_plane', ns, msgs.ground_plane(ns, frame))
            if on_frame is not None:
                on_frame(frame)
            if progress is not None:
                progress(frame.index, n)
        while j < imu.times.size:
            put('imu', stamp_ns(imu.times[j]), msgs.imu(stamp_ns(imu.times[j]), imu.rpy[j],
                                                         imu.variance))
            j += 1
    return BagSummary(path=out, frames=scenario.n_frames, imu=int(imu.times.size),
                      duration=scenario.frame_time(scenario.n_frames - 1),
                      size_bytes=dir_size(out), counts=counts)
