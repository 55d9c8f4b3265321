"""Bag replay without rclpy: reading rosbag2 bags, choosing topics, timing the replay.

The player node (`nodes.player_node`) is a thin shell around these pieces, so they are
tested without a ROS middleware:

* `BagSource` opens a rosbag2 directory or a single ``.mcap`` file with rosbags and
  yields the serialized (CDR) messages. When rosbags cannot open an MCAP file (a bag cut
  short has no summary and no footer), it falls back to streaming the records with the
  ``mcap`` library's non-seeking reader, which reads until the cut; the messages before
  the cut are played and the truncation is reported as a `BagError` at the end.
* `plan_topics` decides what is published where (topic filters; image_transport
  ``<topic>/compressed`` streams become mono8 ``sensor_msgs/Image`` on ``<topic>``).
* `ReplaySchedule` maps bag time to wall-clock time for a replay rate.
* `read_errors` lists what reading a damaged bag may raise.
* `PlayerConfig` holds the player's settings (the node's ROS parameters).
"""
from __future__ import annotations

import dataclasses
import importlib
import struct
import zlib
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import NamedTuple

from asmonc_vision.core.config import check_fields, param

__all__ = ['PlayerConfig', 'BagError', 'BagTopic', 'BagInfo', 'BagMessage', 'BagSource',
           'PlayTopic', 'plan_topics', 'normalize_topic', 'ReplaySchedule',
           'IMAGE_TYPE', 'COMPRESSED_TYPE', 'read_errors',
           'restamp_cdr', 'loop_period_ns', 'LOOP_GAP']

IMAGE_TYPE = 'sensor_msgs/msg/Image'
CAMERA_INFO_TYPE = 'sensor_msgs/msg/CameraInfo'
COMPRESSED_TYPE = 'sensor_msgs/msg/CompressedImage'
COMPRESSED_SUFFIX = '/compressed'
#: seconds between the last message of a pass and the first of the next, restamped
LOOP_GAP = 0.1
#: topics published latched (TRANSIENT_LOCAL) even when the bag does not record QoS
LATCHED_TOPICS = frozenset({'/alarms', '/tf_static'})


@dataclasses.dataclass(frozen=True)
class PlayerConfig:
    """Settings of the bag player (`bag_player_node` parameters)."""

    bag: str = param('', 'path of the rosbag2 directory or single .mcap file to play')
    rate: float = param(1.0, 'replay speed factor: 2.0 plays twice as fast',
                        range=(0.01, 100.0))
    loop: bool = param(False, 'play the bag again and again')
    loop_restamp: bool = param(
        False, 'when looping, shift every header stamp (and /clock) of pass k by k times '
               "the bag's length plus LOOP_GAP, so stamps keep increasing from pass to pass")
    start_offset: float = param(0.0, 'seconds from the start of the bag to begin playing at',
                                range=(0.0, 1.0e6))
    topics: tuple = param((), 'topics to play (bag names, or the image topic of a '
                              '<topic>/compressed stream); empty: all')
    exclude_topics: tuple = param((), 'topics not to play')
    wait_for_subscribers: int = param(
        0, 'before the first message, wait until every image and camera_info topic has '
           'at least this many subscribers (0: do not wait)', range=(0, 1000))
    wait_topics: tuple = param(
        (), "topics that need subscribers before the first message, each 'topic' "
            "(wait_for_subscribers of them) or 'topic=N'; empty: every image and "
            'camera_info topic')
    wait_timeout: float = param(10.0, 'longest wait for subscribers in seconds, then play '
                                      'anyway with a warning (0: wait without limit)',
                                range=(0.0, 3600.0))
    start_paused: bool = param(
        False, "hold the first message until the ~/resume service (std_srvs/Trigger) is "
               "called, as 'ros2 bag play --start-paused', then wait for subscribers: a "
               "starter that sees the readers' own side of each link (a best-effort reader "
               'drops what comes before it has matched) releases it')
    publish_clock: bool = param(False, 'publish /clock from the bag time (for use_sim_time)')
    exit_when_done: bool = param(True, 'when the bag has been played (and not looping), '
                                       'shut down the node\'s context so the process exits')
    pace_topic: str = param(
        '', "pace the replay by a node's answers, one per image (e.g. /obstacles): an image "
            'is held back (and the whole replay with it) while more than pace_lead of the '
            "images published on pace_image_topic are unanswered; '' = bag timing only")
    pace_type: str = param('', "message type of pace_topic, 'pkg/msg/Name'")
    pace_image_topic: str = param(
        '', "the image topic whose messages are answered on pace_topic ('' = the first "
            'image topic played)')
    pace_lead: int = param(3, 'images that may be published ahead of their answers on '
                              'pace_topic', range=(1, 1000))
    pace_timeout: float = param(
        5.0, 'longest hold for pace_topic (s); then the unanswered images are given up, '
             'with a warning, and the replay keeps the bag\'s rate until the next answer '
             '(an answer settles every image sent before it: skipped pairs cost no wait)',
        range=(0.1, 600.0))

    faults: str = param(
        '', "faults injected at bag times, 'KIND[=ARG]@START[+DURATION]; ...' "
            "(asmonc_vision/faults.py); '' = none")

    def __post_init__(self) -> None:
        check_fields(self)
        self.wait_targets(())
        if self.faults:
            from asmonc_vision.faults import parse_faults
            try:
                parse_faults(self.faults)
            except ValueError as exc:
                raise ValueError(f'PlayerConfig.faults: {exc}') from None
        if self.pace_topic and not self.pace_type:
            raise ValueError("PlayerConfig.pace_type: needed with pace_topic "
                             f"'{self.pace_topic}' ('pkg/msg/Name')")

    def wait_targets(self, camera_topics) -> dict[str, int]:
        """{topic: subscribers needed} before the first message: ``wait_topics``, or
        ``wait_for_subscribers`` on each of ``camera_topics`` (empty when not waiting).

        Raises:
            ValueError: a ``wait_topics`` entry that is not 'topic' or 'topic=N', N >= 0.
        """
        out: dict[str, int] = {}
        for item in self.wait_topics:
            topic, sep, n = str(item).partition('=')
            try:
                count = int(n) if sep else self.wait_for_subscribers
            except ValueError:
                count = -1
            if not topic.strip() or count < 0:
                raise ValueError(f"PlayerConfig.wait_topics: '{item}' is not 'topic' or "
                                 "'topic=N' with N >= 0")
            if count > 0:
                out[normalize_topic(topic.strip())] = count
        if not self.wait_topics and self.wait_for_subscribers > 0:
            out = {t: self.wait_for_subscribers for t in camera_topics}
        return out


class BagError(RuntimeError):
    """A bag that cannot be (fully) played: missing, unreadable, truncated or empty.

    The message names the file and the problem.
    """


@dataclasses.dataclass
class BagTopic:
    """One topic of a bag.

    Attributes:
        name: topic name in the bag.
        msgtype: ROS type name, e.g. 'sensor_msgs/msg/Image'.
        count: messages of this topic (of that type) in the bag, or that could be read.
        latched: every recorded publisher offered TRANSIENT_LOCAL durability.
        other_types: further types recorded on the same name (not played).
    """

    name: str
    msgtype: str
    count: int = 0
    latched: bool = False
    other_types: tuple = ()


@dataclasses.dataclass
class BagInfo:
    """What a bag holds.

    Attributes:
        path: the path given (directory or file).
        files: the storage files read.
        storage: 'rosbag2' (read with rosbags) or 'mcap-stream' (read record by record).
        topics: by bag topic name.
        start_ns, end_ns: receive time of the first and the last message (ns).
        message_count: messages in the bag (or that could be read).
        truncated: why the end of the bag cannot be read, or None.
    """

    path: Path
    files: list
    storage: str
    topics: dict
    start_ns: int
    end_ns: int
    message_count: int
    truncated: str | None = None

    @property
    def duration_s(self) -> float:
        """Seconds between the first and the last message."""
        return max(0, self.end_ns - self.start_ns) * 1e-9


class BagMessage(NamedTuple):
    """One serialized message of a bag."""

    topic: str
    msgtype: str
    timestamp: int  # receive (log) time, ns
    data: bytes     # CDR, as on the wire


def normalize_topic(name: str) -> str:
    """'stereo/left' -> '/stereo/left' (topics in bags are absolute)."""
    name = name.strip()
    return name if name.startswith('/') else '/' + name


def _latched(qos_profiles) -> bool:
    """True when every recorded publisher offered TRANSIENT_LOCAL (rosbags Qos list)."""
    if not qos_profiles:
        return False
    from rosbags.interfaces import QosDurability

    return all(getattr(q, 'durability', None) == QosDurability.TRANSIENT_LOCAL
               for q in qos_profiles)


# --- reading ------------------------------------------------------------------------

#: what can go wrong while decoding a damaged MCAP file, besides rosbags' ReaderError
#: (TypeError, OverflowError, MemoryError: rosbags on a damaged length or an early end)
_READ_ERRORS = (OSError, EOFError, ValueError, KeyError, IndexError, struct.error,
                zlib.error, MemoryError, RuntimeError, OverflowError, TypeError)


def read_errors() -> tuple:
    errors: list = list(_READ_ERRORS)
    from mcap.exceptions import McapError
    from rosbags.rosbag2 import ReaderError

    from rosbags.serde import SerdeError
    errors += [McapError, ReaderError, SerdeError]
    # zstd chunks: rosbags decompresses with backports.zstd (compression.zstd on
    # Python >= 3.14), mcap with zstandard; their errors derive from Exception only
    for module in ('zstandard', 'backports.zstd', 'compression.zstd'):
        try:
            errors.append(importlib.import_module(module).ZstdError)
        except (ImportError, AttributeError):
            pass
    return tuple(errors)


class _StreamScan(NamedTuple):
    topics: dict
    start_ns: int
    end_ns: int
    count: int
    error: str | None


def _stream_mcap(path: Path, selected: dict | None = None, start_ns: int | None = None,
                 scan: dict | None = None) -> Iterator[BagMessage]:
    """Messages of an MCAP file in file order, read record by record until the end or a cut.

    Args:
        path: the .mcap file.
        selected: {topic: msgtype} to yield; None: every CDR channel.
        start_ns: skip messages received before this time.
        scan: if given, filled with 'error' (str or None) when the generator ends.
    Raises:
        BagError: the file ends in the middle of a record or is corrupt (after the
            messages before the damage have been yielded).
    """
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    n = 0
    if scan is not None:
        scan['error'] = None
    try:
        with open(path, 'rb') as f:
            for rec in StreamReader(f, record_size_limit=2**32).records:
                if isinstance(rec, Message):
                    ch = channels.get(rec.channel_id)
                    if ch is None:
                        continue
                    if selected is not None and selected.get(ch[0]) != ch[1]:
                        continue
                    if start_ns is not None and rec.log_time < start_ns:
                        continue
                    n += 1
                    yield BagMessage(ch[0], ch[1], rec.log_time, rec.data)
                elif isinstance(rec, Schema):
                    schemas[rec.id] = rec.name
                elif isinstance(rec, Channel):
                    if rec.message_encoding == 'cdr' and rec.schema_id in schemas:
                        channels[rec.id] = (rec.topic, schemas[rec.schema_id])
                        if scan is not None:
                            scan.setdefault('channels', {})[rec.id] = (
                                rec.topic, schemas[rec.schema_id],
                                rec.metadata.get('offered_qos_profiles', ''))
                    elif scan is not None:
                        scan.setdefault('non_cdr', set()).add(
                            f'{rec.topic} ({rec.message_encoding})')
    except read_errors() as exc:
        detail = f'{type(exc).__name__}: {exc}' if str(exc) else type(exc).__name__
        msg = (f"bag file '{path}' is truncated or corrupt: reading stopped after "
               f'{n} message(s) ({detail})' if n else
               f"bag file '{path}' is truncated or corrupt: no message can be read "
               f'({detail})')
        if scan is not None:
            scan['error'] = msg
        raise BagError(msg) from exc


def _scan_stream(path: Path) -> _StreamScan:
    """Read a whole MCAP file record by record to learn its topics, counts and times."""
    from rosbags.rosbag2.metadata import parse_qos

    scan: dict = {}
    topics: dict[str, BagTopic] = {}
    start, end, count = 2**63 - 1, 0, 0
    try:
        for m in _stream_mcap(path, scan=scan):
            t = topics.get(m.topic)
            if t is None:
                t = topics[m.topic] = BagTopic(m.topic, m.msgtype)
            elif t.msgtype != m.msgtype:
                if m.msgtype not in t.other_types:
                    t.other_types += (m.msgtype,)
                continue
            t.count += 1
            count += 1
            start, end = min(start, m.timestamp), max(end, m.timestamp)
    except BagError:
        pass
    for topic, msgtype, qos in scan.get('channels', {}).values():
        t = topics.get(topic)
        if t is not None and t.msgtype == msgtype and qos:
            try:
                t.latched = _latched(parse_qos(qos))
            except Exception:  # noqa: BLE001 - QoS metadata is only a hint
                pass
    return _StreamScan(topics, start, end, count, scan.get('error'))


class BagSource:
    """A rosbag2 bag (directory with metadata.yaml, or a single .mcap / .db3 file).

    Opening reads the bag's index (or, for a damaged MCAP file, scans it) so `info` is
    complete; `messages` can then be iterated any number of times (once per loop).

    Raises (from the constructor):
        BagError: the path does not exist, is not a bag, cannot be read at all, or holds
            no message. The message names the file and the problem.
    """

    def __init__(self, path: str | Path):
        if not str(path).strip():
            raise BagError('no bag given (parameter bag is empty)')
        p = self.path = Path(path).expanduser()
        if not p.exists():
            raise BagError(f"bag '{p}' does not exist")
        self._stream_files: list[Path] = []
        self._rosbags_path: Path | None = None
        if p.is_dir():
            meta = p / 'metadata.yaml'
            if meta.exists():
                self.info = self._open_rosbags(p, fallback=self._dir_mcap_files(p, meta))
            else:
                files = sorted(p.glob('*.mcap'))
                if not files:
                    raise BagError(f"'{p}' is not a rosbag2 bag: it has no metadata.yaml "
                                   'and no .mcap file')
                self.info = self._open_stream(files, reason='no metadata.yaml')
        elif p.suffix == '.mcap':
            self.info = self._open_rosbags(p, fallback=[p])
        elif p.suffix == '.db3':
            self.info = self._open_rosbags(p, fallback=[])
        else:
            raise BagError(f"'{p}' is not a bag: expected a rosbag2 directory or a .mcap "
                           'file')
        if self.info.message_count == 0:
            why = f' ({self.info.truncated})' if self.info.truncated else ''
            raise BagError(f"bag '{p}' contains no message that can be read{why}")

    @staticmethod
    def _dir_mcap_files(p: Path, meta: Path) -> list[Path]:
        """The MCAP files a rosbag2 directory lists (or holds), for the stream fallback."""
        try:
            from ruamel.yaml import YAML

            info = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']
            if info.get('compression_mode', '') in ('file', 'FILE'):
                return []
            if info.get('storage_identifier') != 'mcap':
                return []
            files = [p / Path(f).name for f in info['relative_file_paths']]
            return [f for f in files if f.exists()]
        except Exception:  # noqa: BLE001 - a broken metadata.yaml: use the files present
            return sorted(p.glob('*.mcap'))

    def _open_rosbags(self, p: Path, fallback: list[Path]) -> BagInfo:
        from rosbags.rosbag2 import Reader

        try:
            reader = Reader(p)
            reader.open()
        except Exception as exc:  # noqa: BLE001 - any failure: try the fallback, else report
            problem = f'{type(exc).__name__}: {exc}'
            if fallback:
                return self._open_stream(fallback, reason=problem)
            raise BagError(f"cannot read bag '{p}': {problem}") from exc
        try:
            topics: dict[str, BagTopic] = {}
            for c in reader.connections:
                t = topics.get(c.topic)
                qos = getattr(c.ext, 'offered_qos_profiles', [])
                if t is None:
                    topics[c.topic] = BagTopic(c.topic, c.msgtype, c.msgcount, _latched(qos))
                elif t.msgtype == c.msgtype:
                    t.count += c.msgcount
                    t.latched = t.latched and _latched(qos)
                elif c.msgtype not in t.other_types:
                    t.other_types += (c.msgtype,)
            count = reader.message_count
            start, end = reader.start_time, max(reader.start_time, reader.end_time - 1)
            files = [Path(s.path) for s in getattr(reader.storage, 'storages', [])] or [p]
        finally:
            reader.close()
        self._rosbags_path = p
        return BagInfo(p, files, 'rosbag2', topics, start if count else 0,
                       end if count else 0, count)

    def _open_stream(self, files: list[Path], reason: str) -> BagInfo:
        topics: dict[str, BagTopic] = {}
        start, end, count, error = 2**63 - 1, 0, 0, None
        readable: list[Path] = []
        for f in files:
            s = _scan_stream(f)
            readable.append(f)
            for name, t in s.topics.items():
                if name not in topics:
                    topics[name] = t
                elif topics[name].msgtype == t.msgtype:
                    topics[name].count += t.count
            start, end, count = min(start, s.start_ns), max(end, s.end_ns), count + s.count
            if s.error:
                error = s.error
                break  # stop at the first damage: later files would play after a gap
        if count == 0:
            raise BagError(error or f"cannot read bag '{self.path}': {reason}")
        self._stream_files = readable
        return BagInfo(self.path, list(readable), 'mcap-stream', topics, start, end, count,
                       truncated=error)

    def messages(self, selected: dict[str, str] | None = None,
                 start_ns: int | None = None) -> Iterator[BagMessage]:
        """Serialized messages in bag order (rosbags: receive-time order; stream: file order).

        Args:
            selected: {bag topic: msgtype} to read; None: every topic's main type.
            start_ns: skip messages received before this time (ns).
        Raises:
            BagError: reading stopped at a cut or damage in the file, after the messages
                before it have been yielded.
        """
        if selected is None:
            selected = {t.name: t.msgtype for t in self.info.topics.values()}
        if self._rosbags_path is not None:
            yield from self._rosbags_messages(selected, start_ns)
            return
        for f in self._stream_files:
            yield from _stream_mcap(f, selected, start_ns)

    def messages_before_damage(self, selected: dict[str, str] | None = None
                               ) -> Iterator[BagMessage]:
        """`messages`, ending quietly at a cut or damage in the file."""
        try:
            yield from self.messages(selected)
        except BagError:
            return

    def _rosbags_messages(self, selected: dict[str, str],
                          start_ns: int | None) -> Iterator[BagMessage]:
        from rosbags.rosbag2 import Reader

        n = 0
        try:
            with Reader(self._rosbags_path) as reader:
                conns = [c for c in reader.connections if selected.get(c.topic) == c.msgtype]
                if not conns:
                    return
                for conn, ts, data in reader.messages(conns, start=start_ns):
                    n += 1
                    yield BagMessage(conn.topic, conn.msgtype, ts, bytes(data))
        except read_errors() as exc:
            raise BagError(f"bag '{self.path}' is corrupt: reading stopped after {n} "
                           f'message(s) ({type(exc).__name__}: {exc})') from exc


# --- what to publish where ----------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class PlayTopic:
    """One published stream.

    Attributes:
        bag_topic, bag_type: as recorded.
        out_topic, out_type: as published (differ for decompressed images).
        count: messages in the bag.
        latched: publish TRANSIENT_LOCAL.
        decompress: CompressedImage in the bag, mono8 Image on the wire.
    """

    bag_topic: str
    bag_type: str
    out_topic: str
    out_type: str
    count: int
    latched: bool = False
    decompress: bool = False

    @property
    def is_image(self) -> bool:
        """Published as sensor_msgs/Image."""
        return self.out_type == IMAGE_TYPE

    @property
    def is_camera(self) -> bool:
        """Published as sensor_msgs/Image or CameraInfo (the topics
        `wait_for_subscribers` is about: a stereo node needs both)."""
        return self.out_type in (IMAGE_TYPE, CAMERA_INFO_TYPE)


def plan_topics(topics: dict[str, BagTopic], include: Collection[str] = (),
                exclude: Collection[str] = ()) -> list[PlayTopic]:
    """Decide which bag topics are published, on which topic and with which type.

    A ``<topic>/compressed`` stream of sensor_msgs/CompressedImage is published decoded
    as a mono8 sensor_msgs/Image on ``<topic>``, unless the bag also holds ``<topic>``
    itself (then it is published unchanged). `include` / `exclude` match either name.

    Args:
        topics: the bag's topics (`BagInfo.topics`).
        include: names to play; empty: all.
        exclude: names not to play.
    Returns:
        The streams, sorted by published topic.
    """
    inc = {normalize_topic(t) for t in include if t.strip()}
    exc = {normalize_topic(t) for t in exclude if t.strip()}
    plan = []
    for t in topics.values():
        out_topic, out_type, decompress = t.name, t.msgtype, False
        if (t.msgtype == COMPRESSED_TYPE and t.name.endswith(COMPRESSED_SUFFIX)
                and len(t.name) > len(COMPRESSED_SUFFIX)):
            base = t.name[:-len(COMPRESSED_SUFFIX)]
            if base not in topics:
                out_topic, out_type, decompress = base, IMAGE_TYPE, True
        names = {t.name, out_topic}
        if inc and not names & inc:
            continue
        if names & exc:
            continue
        plan.append(PlayTopic(t.name, t.msgtype, out_topic, out_type, t.count,
                              t.latched or out_topic in LATCHED_TOPICS, decompress))
    return sorted(plan, key=lambda p: p.out_topic)


# --- timing -------------------------------------------------------------------------

class ReplaySchedule:
    """When a message of bag time t is due, for one pass through the bag.

    Wall time is absolute (from a monotonic clock), so sleeping errors do not add up:
    due(t) = wall_start + (t - bag_start) / rate. A message stamped before `bag_start`
    or before an earlier message (out-of-order bag) is due at once: the player never
    sleeps a negative time and publishes in bag order.
    """

    def __init__(self, bag_start_ns: int, wall_start: float, rate: float):
        if not rate > 0:
            raise ValueError(f'replay rate must be positive, got {rate}')
        self.bag_start_ns = int(bag_start_ns)
        self.wall_start = float(wall_start)
        self.rate = float(rate)

    def due(self, t_ns: int) -> float:
        """Wall time (same clock as `wall_start`) at which bag time `t_ns` is published."""
        return self.wall_start + max(0, t_ns - self.bag_start_ns) * 1e-9 / self.rate

    def delay(self, t_ns: int, now: float) -> float:
        """Seconds to wait at wall time `now` before publishing bag time `t_ns` (>= 0)."""
        return max(0.0, self.due(t_ns) - now)

    def bag_time(self, now: float) -> int:
        """Bag time (ns) that corresponds to wall time `now` (for /clock)."""
        return self.bag_start_ns + int(max(0.0, now - self.wall_start) * self.rate * 1e9)


# --- looping -----------------------------------------------------------------------



def restamp_cdr(data: bytes, offset_ns: int) -> bytes:
    """A CDR message that starts with a std_msgs/Header, its stamp moved by ``offset_ns``."""
    if not offset_ns:
        return data
    end = '<' if len(data) > 1 and data[1] == 1 else '>'   # CDR_LE or CDR_BE
    sec, nsec = struct.unpack_from(end + 'iI', data, 4)
    t = sec * 1_000_000_000 + nsec + int(offset_ns)
    out = bytearray(data)
    struct.pack_into(end + 'iI', out, 4, t // 1_000_000_000, t % 1_000_000_000)
    return bytes(out)


def loop_period_ns(info: 'BagInfo', start_ns: int) -> int:
    """How far (ns) each restamped pass is shifted from the one before: the played span
    of the bag (from ``start_ns``) plus `LOOP_GAP`."""
    return max(0, info.end_ns - start_ns) + int(LOOP_GAP * 1e9)
