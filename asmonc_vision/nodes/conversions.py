"""Message <-> numpy conversions, done once at the node boundary.

Everything past these functions is plain numpy and the core's dataclasses.
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import CameraInfo, Image

from asmonc_vision.io.bagio import ImageFormatError, image_to_gray
from asmonc_vision.core.camera import StereoCamera

__all__ = ['ImageFormatError', 'image_msg_to_gray', 'array_to_image_msg',
           'stereo_camera_from_infos', 'stamp_to_ns', 'ns_to_stamp']


def image_msg_to_gray(msg: Image) -> np.ndarray:
    """sensor_msgs/Image (mono8, or another encoding `bagio.image_to_gray` converts) to
    a (H, W) uint8 array.

    Raises:
        ImageFormatError: unsupported encoding or inconsistent size/step/data.
    """
    return image_to_gray(msg.encoding, msg.height, msg.width, msg.step, msg.data)


def array_to_image_msg(img: np.ndarray, header=None) -> Image:
    """(H, W) uint8 -> mono8 Image, (H, W, 3) uint8 BGR -> bgr8 Image."""
    img = np.ascontiguousarray(img, dtype=np.uint8)
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(img.shape[0]), int(img.shape[1])
    if img.ndim == 2:
        msg.encoding, msg.step = 'mono8', msg.width
    elif img.ndim == 3 and img.shape[2] == 3:
        msg.encoding, msg.step = 'bgr8', msg.width * 3
    else:
        raise ValueError(f'cannot make an Image from an array of shape {img.shape}')
    msg.data = img.tobytes()
    return msg


def stereo_camera_from_infos(left: CameraInfo, right: CameraInfo) -> StereoCamera:
    """The rectified stereo model from the two CameraInfo messages on the wire.

    Uses the projection matrices P (the right camera's P[0,3] holds -f*B).

    Raises:
        ValueError: the infos do not describe a rectified pair (sizes differ, f or the
            principal point differ, or the baseline is not positive).
    """
    if (left.width, left.height) != (right.width, right.height):
        raise ValueError(f'left camera_info is {left.width}x{left.height} but right is '
                         f'{right.width}x{right.height}')
    pl = np.asarray(left.p, float).reshape(3, 4)
    pr = np.asarray(right.p, float).reshape(3, 4)
    if pl[0, 0] <= 0:
        raise ValueError(f'left camera_info has P[0,0] = {pl[0, 0]}; not a rectified camera')
    if abs(pl[0, 0] - pr[0, 0]) > 1e-3 * pl[0, 0] or abs(pl[1, 2] - pr[1, 2]) > 0.5:
        raise ValueError('left and right camera_info P differ in f or cy: not rectified')
    return StereoCamera.from_projection(pl, pr, left.width, left.height)


def stamp_to_ns(stamp: Time) -> int:
    """builtin_interfaces/Time to integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Integer nanoseconds to builtin_interfaces/Time."""
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))
