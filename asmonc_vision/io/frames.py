"""Stereo pairs and their ground truth out of a bag of the topic contract.

* `Frame`: one stereo pair with its camera, true obstacles, true ground plane and pose.
* `load_frames` / `load_pairs`: a bag's pairs in stamp order.
* `frame_from_obstacle_array`, `plane_from_msg`, `pose_from_msg`: messages (rosbags or
  rclpy) to the evaluation's types.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmonc_vision.eval.evaluation import FrameObstacles
from asmonc_vision.io import bagio


@dataclass
class Frame:
    """One stereo pair with what is known about it.

    Attributes:
        stamp_ns: the pair's header stamp.
        left, right: (H, W) uint8 rectified images (None when loaded without images).
        cam: the rectified stereo camera from the pair's CameraInfos.
        truth: true obstacles (eval.evaluation.FrameObstacles), or None.
        truth_plane: the true ground plane (core.camera.MetricPlane), or None.
        pose: the true pose (R (3, 3), t (3,)) of the left optical frame in the world,
            from /ground_truth/camera_pose, or None.
        frame_id: the left image's frame id.
        inclinometer: (stamp_ns, (4,) quaternion x, y, z, w) of the latest
            `/inclinometer/imu` orientation stamped at or before the pair (world ->
            inclinometer_link), or None (no inclinometer in the bag, or none yet).
    """

    stamp_ns: int
    left: np.ndarray | None
    right: np.ndarray | None
    cam: object
    truth: object = None
    truth_plane: object = None
    pose: tuple | None = None
    frame_id: str = ''
    inclinometer: tuple[int, np.ndarray] | None = None


def pose_from_msg(msg) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), t (3,)) of a PoseStamped (rosbags or rclpy): ``X_world = R X + t``."""
    from asmonc_vision.core.rotations import quaternion_to_matrix

    p = msg.pose
    return (quaternion_to_matrix([p.orientation.x, p.orientation.y, p.orientation.z,
                                  p.orientation.w]),
            np.array([p.position.x, p.position.y, p.position.z]))


def plane_from_msg(msg, cam=None):
    """MetricPlane of a GroundPlane message (rosbags or rclpy), or None when its status is
    not TRACKING. Uses its `normal`/`height`; when the normal is unset (zero) and a camera
    is given, converts (a, b, c) with core.camera.metric_from_plane."""
    from asmonc_vision.core.camera import MetricPlane, metric_from_plane

    if int(msg.status) != 1:          # GroundPlane.TRACKING
        return None
    n = np.array([msg.normal.x, msg.normal.y, msg.normal.z], float)
    norm = float(np.linalg.norm(n))
    if np.isfinite(norm) and abs(norm - 1.0) < 1e-3 and np.isfinite(msg.height):
        return MetricPlane(normal_up=n / norm, height=float(msg.height))
    if cam is not None:
        return metric_from_plane(cam, (msg.a, msg.b, msg.c))
    return None


def load_frames(bag: Path, limit: int = 0, images: bool = True) -> list[Frame]:
    """The stereo pairs of a bag in stamp order, with ground truth where the bag has it.

    Args:
        bag: rosbag2 directory or .mcap file following the topic contract.
        limit: at most this many pairs (0: all).
        images: False skips the images (for scoring recorded outputs: stamps, cameras
            and truth only); a pair is then any stamp with both CameraInfos.

    A right camera whose principal point differs from the left's (``cx`` in the
    CameraInfos' P) has its image moved to the left's (`core.camera.align_right_image`),
    as the nodes do.

    Raises:
        bagio.BagError: unreadable bag, or camera_infos that are not one rectified pair.
    """
    from asmonc_vision.core.camera import StereoCamera, align_right_image, principal_offset_px

    T = {k: bagio.TOPICS[k][0] for k in ('left_image', 'right_image', 'left_info', 'right_info',
                                         'gt_obstacles', 'gt_ground_plane', 'gt_camera_pose')}
    need = ['left_info', 'right_info'] + (['left_image', 'right_image'] if images else [])
    need_topics = {T[k] for k in need}
    imu_topic = bagio.TOPICS['imu'][0]
    topics = [T[k] for k in need] + [T['gt_obstacles'], T['gt_ground_plane'],
                                     T['gt_camera_pose'], imu_topic]
    by_stamp: dict[int, dict] = {}
    imu: list[tuple[int, np.ndarray]] = []
    complete = 0
    for topic, _, m in bagio.read_messages(bag, topics):
        if topic == imu_topic:
            sample = _imu_sample(m)
            if sample is not None:
                imu.append(sample)
            continue
        s = by_stamp.setdefault(bagio.header_stamp_ns(m), {})
        s[topic] = m
        if topic in need_topics and need_topics <= s.keys():
            complete += 1
            # messages come in time order: a pair beyond the limit means all are in
            if limit and complete > limit:
                break
    imu.sort(key=lambda sample: sample[0])
    frames: list[Frame] = []
    for stamp in sorted(by_stamp):
        s = by_stamp[stamp]
        if any(T[k] not in s for k in need):
            continue
        li, ri = s[T['left_info']], s[T['right_info']]
        cam = StereoCamera.from_projection(li.p, ri.p, li.width, li.height)
        try:
            offset = principal_offset_px(li.p, ri.p, li.width)
        except ValueError as exc:
            raise bagio.BagError(f'{bag}: camera_info of the pair at {stamp / 1e9:.3f} s: '
                                 f'{exc}') from exc
        left = right = None
        if images:
            lm, rm = s[T['left_image']], s[T['right_image']]
            left = bagio.image_to_gray(lm.encoding, lm.height, lm.width, lm.step, lm.data)
            right = align_right_image(
                bagio.image_to_gray(rm.encoding, rm.height, rm.width, rm.step, rm.data), offset)
        truth = (frame_from_obstacle_array(s[T['gt_obstacles']])
                 if T['gt_obstacles'] in s else None)
        tplane = (plane_from_msg(s[T['gt_ground_plane']], cam)
                  if T['gt_ground_plane'] in s else None)
        pose = pose_from_msg(s[T['gt_camera_pose']]) if T['gt_camera_pose'] in s else None
        frame_id = s[T['left_image']].header.frame_id if images else ''
        frames.append(Frame(stamp, left, right, cam, truth, tplane, pose, frame_id,
                            _latest_at(imu, stamp)))
        if limit and len(frames) >= limit:
            break
    return frames


def _imu_sample(msg) -> tuple[int, np.ndarray] | None:
    """(stamp_ns, (4,) quaternion x, y, z, w) of an Imu message with an orientation,
    else None."""
    cov = np.asarray(msg.orientation_covariance, float)
    if cov.size and cov[0] == -1.0:
        return None
    o = msg.orientation
    q = np.array([o.x, o.y, o.z, o.w], float)
    if not (np.all(np.isfinite(q)) and np.linalg.norm(q) > 1e-9):
        return None
    return bagio.header_stamp_ns(msg), q


def _latest_at(samples: list[tuple[int, np.ndarray]], stamp_ns: int
               ) -> tuple[int, np.ndarray] | None:
    """The sample of ``samples`` (sorted by stamp) with the latest stamp at or before
    ``stamp_ns``, or None."""
    i = bisect.bisect_right(samples, stamp_ns, key=lambda sample: sample[0])
    return samples[i - 1] if i > 0 else None


def load_pairs(bag: Path, limit: int = 0):
    """[(left (H,W) uint8, right, StereoCamera)] from a bag, in stamp order."""
    return [(f.left, f.right, f.cam) for f in load_frames(bag, limit)]


def frame_from_obstacle_array(msg) -> FrameObstacles:
    """An ObstacleArray (rclpy or rosbags message) to FrameObstacles."""
    obs = list(msg.obstacles)
    stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
    if not obs:
        return FrameObstacles.empty(stamp)
    return FrameObstacles(
        stamp_ns=stamp,
        ids=np.array([o.id for o in obs], int),
        position=np.array([[o.position.x, o.position.y, o.position.z] for o in obs], float),
        height=np.array([o.height for o in obs], float),
        range=np.array([o.range for o in obs], float),
        bearing=np.array([o.bearing for o in obs], float),
        roi=np.array([[o.roi.x_offset, o.roi.y_offset, o.roi.width, o.roi.height]
                      for o in obs], int),
        confidence=np.array([o.confidence for o in obs], float))
