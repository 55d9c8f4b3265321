"""rosbag2 (MCAP) access with rosbags: the Jazzy typestore plus asmonc_vision_msgs.

No rclpy here, so the simulator, the evaluation and the tests can read and write bags
without a ROS middleware. Image messages convert to numpy arrays once, here.
"""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

import numpy as np

MSG_PACKAGE = 'asmonc_vision_msgs'

#: The topic contract. Names and types are stable: evaluations rely on them.
TOPICS = {
    'left_image': ('/stereo/left/image_rect', 'sensor_msgs/msg/Image'),
    'right_image': ('/stereo/right/image_rect', 'sensor_msgs/msg/Image'),
    'left_info': ('/stereo/left/camera_info', 'sensor_msgs/msg/CameraInfo'),
    'right_info': ('/stereo/right/camera_info', 'sensor_msgs/msg/CameraInfo'),
    'imu': ('/inclinometer/imu', 'sensor_msgs/msg/Imu'),
    'ground_plane': ('/ground_plane', f'{MSG_PACKAGE}/msg/GroundPlane'),
    'obstacles': ('/obstacles', f'{MSG_PACKAGE}/msg/ObstacleArray'),
    'markers': ('/obstacles/markers', 'visualization_msgs/msg/MarkerArray'),
    'debug_image': ('/detector/debug_image', 'sensor_msgs/msg/Image'),
    'alarms': ('/alarms', f'{MSG_PACKAGE}/msg/Alarm'),
    'diagnostics': ('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray'),
    'gt_obstacles': ('/ground_truth/obstacles', f'{MSG_PACKAGE}/msg/ObstacleArray'),
    'gt_camera_pose': ('/ground_truth/camera_pose', 'geometry_msgs/msg/PoseStamped'),
    'gt_ground_plane': ('/ground_truth/ground_plane', f'{MSG_PACKAGE}/msg/GroundPlane'),
    'gait_state': ('/gait/state', f'{MSG_PACKAGE}/msg/GaitState'),
    'gait_motion': ('/gait/predicted_motion', 'geometry_msgs/msg/TransformStamped'),
    'egomotion': ('/egomotion', 'geometry_msgs/msg/TransformStamped'),
    'egomotion_odometry': ('/egomotion/odometry', 'nav_msgs/msg/Odometry'),
}


def msg_definition_dirs() -> list[Path]:
    """Where the .msg files of asmonc_vision_msgs may be, most specific first."""
    dirs: list[Path] = []
    env = os.environ.get('ASMONC_MSG_DIR')
    if env:
        dirs.append(Path(env))
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / 'share' / MSG_PACKAGE / 'msg')
    dirs.append(Path(sys.prefix) / 'share' / MSG_PACKAGE / 'msg')
    # Source checkout: <repo>/msg/msg next to <repo>/asmonc_vision.
    dirs.append(Path(__file__).resolve().parent.parent / 'msg' / 'msg')
    return dirs


@functools.lru_cache(maxsize=1)
def typestore():
    """The rosbags typestore for ROS 2 Jazzy with asmonc_vision_msgs registered.

    Raises:
        FileNotFoundError: when no directory holds the message definitions.
    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    for d in msg_definition_dirs():
        files = sorted(d.glob('*.msg')) if d.is_dir() else []
        if files:
            types = {}
            for f in files:
                types.update(get_types_from_msg(f.read_text(), f'{MSG_PACKAGE}/msg/{f.stem}'))
            store.register(types)
            return store
    raise FileNotFoundError(
        f'no {MSG_PACKAGE} .msg definitions found in any of: '
        + ', '.join(str(d) for d in msg_definition_dirs()))


def msg_class(msgtype: str):
    """rosbags dataclass for a message type name such as 'sensor_msgs/msg/Image'."""
    return typestore().types[msgtype]


# --- images -------------------------------------------------------------------------

#: encodings accepted on the image topics, with (channels, dtype)
IMAGE_ENCODINGS = {'mono8': (1, np.uint8), 'rgb8': (3, np.uint8), 'bgr8': (3, np.uint8),
                   # as cv_bridge reads them: 8UC1 is mono8, 8UC3 is bgr8; rgba8 / bgra8
                   # (e.g. ZED cameras) lose their alpha
                   '8UC1': (1, np.uint8), '8UC3': (3, np.uint8),
                   'rgba8': (4, np.uint8), 'bgra8': (4, np.uint8)}
#: OpenCV conversion to grey of each multi-channel encoding
_TO_GRAY = {'rgb8': 'COLOR_RGB2GRAY', 'bgr8': 'COLOR_BGR2GRAY', '8UC3': 'COLOR_BGR2GRAY',
            'rgba8': 'COLOR_RGBA2GRAY', 'bgra8': 'COLOR_BGRA2GRAY'}


class ImageFormatError(ValueError):
    """An image message that cannot be used (encoding, size or step wrong)."""


def image_to_gray(encoding: str, height: int, width: int, step: int, data) -> np.ndarray:
    """Convert raw image fields (any message representation) to a mono8 array.

    Args:
        encoding: one of `IMAGE_ENCODINGS` ('mono8'; 'rgb8', 'bgr8', 'rgba8', 'bgra8'
            converted to grey; '8UC1', '8UC3' read as mono8, bgr8).
        height, width, step: as in sensor_msgs/Image.
        data: bytes-like or uint8 array of length >= height * step.
    Returns:
        (height, width) uint8 array (a copy, safe to keep).
    Raises:
        ImageFormatError: wrong encoding, or data shorter than the header says.
    """
    if encoding not in IMAGE_ENCODINGS:
        raise ImageFormatError(
            f"unsupported image encoding '{encoding}'; expected one of "
            f"{', '.join(IMAGE_ENCODINGS)}")
    ch, _ = IMAGE_ENCODINGS[encoding]
    if height <= 0 or width <= 0 or step < width * ch:
        raise ImageFormatError(f'bad image geometry {width}x{height} step {step} ({encoding})')
    buf = np.frombuffer(memoryview(data), dtype=np.uint8) if not isinstance(
        data, np.ndarray) else data.reshape(-1).view(np.uint8)
    if buf.size < height * step:
        raise ImageFormatError(
            f'image data has {buf.size} bytes, header says {height}x{step} = {height * step}')
    img = buf[:height * step].reshape(height, step)[:, :width * ch]
    if ch == 1:
        return img.copy()
    import cv2

    img = img.reshape(height, width, ch)
    return cv2.cvtColor(np.ascontiguousarray(img), getattr(cv2, _TO_GRAY[encoding]))


def decode_compressed(fmt: str, data) -> np.ndarray:
    """Decode a sensor_msgs/CompressedImage payload (PNG, JPEG) to mono8."""
    import cv2

    buf = np.frombuffer(memoryview(data), dtype=np.uint8) if not isinstance(
        data, np.ndarray) else data.reshape(-1).view(np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ImageFormatError(f"cannot decode compressed image (format '{fmt}')")
    return img


# --- bags -----------------------------------------------------------------------------

class BagError(RuntimeError):
    """A bag that cannot be read: missing, truncated, empty or not a rosbag2 bag."""


def open_reader(path):
    """Open a rosbag2 bag (a directory with metadata.yaml, or one .mcap file) for reading.

    Returns an open `rosbags.rosbag2.Reader` (use as a context manager or close it).
    Raises:
        BagError: with a message naming the path and what is wrong.
    """
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    p = Path(path)
    if not p.exists():
        raise BagError(f"bag '{p}' does not exist")
    try:
        reader = Reader(p)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError, *bagplay_read_errors()) as exc:
        # (a damaged length field once asked for exabytes: MemoryError)
        raise BagError(f"bag '{p}' cannot be read ({type(exc).__name__}: {exc}); "
                       'is it a complete rosbag2 (MCAP or sqlite3) bag?') from exc
    return reader


def _damaged_source(path, problem: BagError):
    """A damaged or truncated MCAP bag that rosbags cannot open, scanned as a stream
    (`asmonc_vision.io.bagplay.BagSource`: the messages before the damage). Raises
    ``problem`` when not even that can be read."""
    from asmonc_vision.io import bagplay

    try:
        return bagplay.BagSource(path)
    except bagplay.BagError as exc:
        raise problem from exc


def bag_summary(path) -> tuple[dict[str, tuple[str, int]], str | None]:
    """(`bag_topics`, `bag_damage`) of a bag, opening (or, when damaged, scanning) it
    once. Raises BagError when nothing can be read."""
    try:
        reader = open_reader(path)
    except BagError as exc:
        src = _damaged_source(path, exc)
        return ({t.name: (t.msgtype, t.count) for t in src.info.topics.values()},
                src.info.truncated or str(exc))
    try:
        out: dict[str, tuple[str, int]] = {}
        for c in reader.connections:
            t, n = out.get(c.topic, (c.msgtype, 0))
            out[c.topic] = (t, n + c.msgcount)
        return out, None
    finally:
        reader.close()


def bag_damage(path) -> str | None:
    """Why a bag cannot be read to its end (a truncated or damaged MCAP file whose
    messages before the damage can still be read), or None for an intact bag.
    Raises BagError when nothing can be read."""
    return bag_summary(path)[1]


def bag_topics(path) -> dict[str, tuple[str, int]]:
    """topic -> (message type, message count) of a bag; of a truncated or damaged MCAP
    bag, those of the messages before the damage (`bag_damage` says why). Raises
    BagError."""
    return bag_summary(path)[0]


def read_messages(path, topics):
    """Yield (topic, bag_time_ns, deserialized rosbags message) for the given topics.

    Raises:
        BagError: unreadable bag, or a truncated one (after yielding what was readable).
    """
    from rosbags.rosbag2.errors import ReaderError

    store = typestore()
    try:
        reader = open_reader(path)
    except BagError as exc:
        # A truncated or damaged MCAP file: the messages before the damage, then the error.
        from asmonc_vision.io import bagplay

        src = _damaged_source(path, exc)
        wanted = {t.name: t.msgtype for t in src.info.topics.values() if t.name in set(topics)}
        try:
            for m in src.messages(wanted):
                yield m.topic, m.timestamp, _deserialize(store, path, m.topic, m.data,
                                                         m.msgtype)
        except bagplay.BagError as cut:
            raise BagError(str(cut)) from cut
        if src.info.truncated:
            raise BagError(src.info.truncated) from exc
        return
    try:
        conns = [c for c in reader.connections if c.topic in set(topics)]
        if not conns:
            return                  # rosbags reads every connection when given none
        try:
            for conn, t, raw in reader.messages(connections=conns):
                yield conn.topic, t, _deserialize(store, path, conn.topic, raw, conn.msgtype)
        except BagError:
            raise
        except (ReaderError, OSError, ValueError, EOFError,
                *bagplay_read_errors()) as exc:
            raise BagError(f"bag '{path}' is truncated or corrupt: {exc}") from exc
    finally:
        reader.close()


def header_stamps(path, topics) -> dict[str, list[int]] | None:
    """Per topic of ``topics`` (also read as ``TOPIC/compressed``, counted under
    ``TOPIC``), the header stamps (ns) of its messages in the order the bag holds them
    (its log time), each stamp once. The stamp is read from the CDR bytes (a header
    comes first), nothing is deserialized. None for a bag that cannot be read to its end."""
    import struct

    from rosbags.rosbag2.errors import ReaderError

    names = {t: t for t in topics}
    names.update({t + '/compressed': t for t in topics})
    found: dict[str, dict[int, None]] = {t: {} for t in topics}   # a dict keeps the order
    try:
        reader = open_reader(path)
    except BagError:
        return None
    try:
        conns = [c for c in reader.connections if c.topic in names]
        for conn, _, raw in reader.messages(connections=conns):
            # the encapsulation's second byte: 1 little-endian CDR, 0 big-endian
            sec, nsec = struct.unpack_from('<iI' if raw[1] & 1 else '>iI', raw, 4)
            found[names[conn.topic]].setdefault(sec * 1_000_000_000 + nsec, None)
    except (ReaderError, OSError, ValueError, EOFError, struct.error,
            *bagplay_read_errors()):
        return None
    finally:
        reader.close()
    return {t: list(stamps) for t, stamps in found.items()}


def pair_stamps(path) -> list[int] | None:
    """Header stamps (ns) that both the left and the right image topic hold (raw or
    ``/compressed``): the stereo pairs a replay of the bag plays, in the order the bag
    holds their left images (`header_stamps`). None for a bag that cannot be read to
    its end."""
    stamps = header_stamps(path, (TOPICS['left_image'][0], TOPICS['right_image'][0]))
    return None if stamps is None else whole_pairs(stamps)


def whole_pairs(stamps: dict[str, list[int]]) -> list[int]:
    """The stamps of ``stamps`` (`header_stamps` of the left and right image topics, at
    least) on both image topics, in the left topic's order."""
    rights = set(stamps[TOPICS['right_image'][0]])
    return [s for s in stamps[TOPICS['left_image'][0]] if s in rights]


def _deserialize(store, path, topic: str, raw, msgtype: str):
    """One message from its CDR bytes; BagError when they are damaged."""
    try:
        return store.deserialize_cdr(raw, msgtype)
    except (*bagplay_read_errors(), TypeError) as exc:
        raise BagError(f"bag '{path}' is corrupt: a {msgtype} message on {topic} cannot be "
                       f'decoded ({type(exc).__name__}: {exc})') from exc


def bagplay_read_errors() -> tuple:
    """What decoding a damaged bag may raise (`asmonc_vision.io.bagplay`'s list)."""
    from asmonc_vision.io.bagplay import read_errors
    return read_errors()


def header_stamp_ns(msg) -> int:
    """Integer ns of a rosbags message's header stamp."""
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def imu_to_rpy_var(msg) -> tuple[np.ndarray, np.ndarray | None]:
    """(roll, pitch, yaw) rad and the diagonal variances (rad^2, None if not given) of a
    sensor_msgs/Imu (an rclpy or a rosbags message).

    Raises:
        ValueError: no orientation (covariance[0] = -1) or a degenerate quaternion.
    """
    from asmonc_vision.core.rotations import quaternion_to_rpy

    cov = np.asarray(msg.orientation_covariance, float)
    if cov.size and cov[0] == -1.0:
        raise ValueError('Imu has no orientation (orientation_covariance[0] = -1)')
    q = msg.orientation
    rpy = quaternion_to_rpy(np.array([q.x, q.y, q.z, q.w], float))
    var = cov[[0, 4, 8]] if cov.size == 9 else None
    if var is not None and not np.all(np.isfinite(var) & (var > 0)):
        var = None
    return rpy, var


# --- compressed images --------------------------------------------------------------

def compressed_to_image_cdr(data: bytes) -> bytes:
    """CDR sensor_msgs/CompressedImage (PNG or JPEG) -> CDR mono8 sensor_msgs/Image.

    The header (stamp, frame) is kept.

    Raises:
        ImageFormatError: the payload cannot be decoded.
        ValueError: the bytes are not a CompressedImage.
    """
    store = typestore()
    msg = store.deserialize_cdr(data, 'sensor_msgs/msg/CompressedImage')
    img = decode_compressed(msg.format, msg.data)
    image_cls = store.types['sensor_msgs/msg/Image']
    h, w = img.shape[:2]
    out = image_cls(header=msg.header, height=h, width=w, encoding='mono8', is_bigendian=0,
                    step=w, data=np.ascontiguousarray(img, dtype=np.uint8).reshape(-1))
    return bytes(store.serialize_cdr(out, 'sensor_msgs/msg/Image'))


def has_header(msgtype: str) -> bool:
    """Whether a message type starts with a std_msgs/Header (its stamp then sits at CDR
    offset 4, right after the encapsulation header); False for unknown types."""
    try:
        fields = typestore().fielddefs[msgtype][1]
    except (KeyError, FileNotFoundError):
        return False
    return bool(fields) and fields[0][1][1] == 'std_msgs/msg/Header'
