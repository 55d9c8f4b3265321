"""Bag recorder: writes ROS topics to a rosbag2 MCAP bag (stands in for ``ros2 bag record``).

Topics and their types are discovered periodically; each chosen topic is subscribed raw
(serialized CDR bytes, never deserialized) with a QoS that matches what its publishers
offer, and every message is written with its receive time (ns, the node clock) as the
timestamp, like ``ros2 bag record``. The bag is written with rosbags (rosbag2 version 9,
MCAP storage, optional zstd chunk compression), so it plays with ``ros2 bag play``, with
`nodes.player_node` and reads with the ``mcap`` library.

`close()` finalises the bag (MCAP summary + metadata.yaml); it runs on shutdown (also
from `destroy_node`), so a recorder stopped with Ctrl-C (SIGINT) or SIGTERM leaves a
complete bag. For the ``asmonc run`` orchestrator: `BagRecorderNode(RecorderConfig(...),
context=ctx)`, `counts`, `topic_types`, `output`, `close()`.
"""
from __future__ import annotations

import contextlib
import dataclasses
import threading
import time
from pathlib import Path
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from asmonc_vision.io.bagio import typestore
from asmonc_vision.io.bagplay import normalize_topic
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.nodes.common import config_overrides, declare_config, run_node
from asmonc_vision.nodes.player_node import message_class

__all__ = ['BagRecorderNode', 'RecorderConfig', 'RecorderError', 'subscription_qos',
           'rosbags_qos', 'main']

#: subscription history depth (raw callbacks are cheap; deep enough for bursts)
SUB_DEPTH = 100


@dataclasses.dataclass(frozen=True)
class RecorderConfig:
    """Settings of the bag recorder (`bag_recorder_node` parameters)."""

    output: str = param('', 'directory of the rosbag2 bag to write (must not exist or be '
                            'empty); empty: rosbag2_<date>-<time> in the working directory')
    topics: tuple = param((), 'topics to record; empty: all discovered topics')
    exclude_topics: tuple = param(('/rosout', '/parameter_events'), 'topics not to record')
    compression: str = param('none', "MCAP chunk compression: 'none' or 'zstd'",
                             choices=('none', 'zstd'))
    discovery_period: float = param(0.2, 'seconds between two looks for new topics',
                                    range=(0.02, 60.0))

    def __post_init__(self) -> None:
        check_fields(self)


class RecorderError(RuntimeError):
    """The bag cannot be written (output exists and is not empty, not writable, ...)."""


def subscription_qos(publisher_qos: list[QoSProfile], depth: int = SUB_DEPTH) -> QoSProfile:
    """A subscription QoS that receives from all these publishers, like rosbag2 does.

    RELIABLE only if every publisher is reliable (else BEST_EFFORT, which also receives
    from reliable ones); TRANSIENT_LOCAL only if every publisher is transient local (a
    latched message such as the current alarm is then recorded even when it was
    published before the recorder started).
    """
    reliable = bool(publisher_qos) and all(
        q.reliability == ReliabilityPolicy.RELIABLE for q in publisher_qos)
    latched = bool(publisher_qos) and all(
        q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in publisher_qos)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def rosbags_qos(qos: QoSProfile):
    """rclpy QoSProfile (as offered by a publisher) -> rosbags Qos for the bag's metadata."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)

    def enum(cls, value, unknown):
        try:
            return cls(int(value))
        except (ValueError, TypeError):
            return unknown

    def dur(d) -> QosTime:
        ns = int(getattr(d, 'nanoseconds', 0))
        return QosTime(ns // 1_000_000_000, ns % 1_000_000_000)

    return Qos(history=enum(QosHistory, qos.history, QosHistory.UNKNOWN),
               depth=int(qos.depth),
               reliability=enum(QosReliability, qos.reliability, QosReliability.UNKNOWN),
               durability=enum(QosDurability, qos.durability, QosDurability.UNKNOWN),
               deadline=dur(qos.deadline), lifespan=dur(qos.lifespan),
               liveliness=enum(QosLiveliness, qos.liveliness, QosLiveliness.UNKNOWN),
               liveliness_lease_duration=dur(qos.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))


def _hidden(topic: str) -> bool:
    return any(part.startswith('_') for part in topic.split('/'))


class BagRecorderNode(Node):
    """Records topics to a rosbag2 MCAP bag (see the module docstring).

    Args:
        config: settings; None reads them from the ROS parameters (YAML, command line).
        node_name: the node's name.
        **node_kwargs: passed to rclpy's Node (context, parameter_overrides, ...).
    Raises:
        RecorderError: the output exists and is not an empty directory, or cannot be
            created (already logged as an error).
        ValueError, rclpy.exceptions.InvalidParameterValueException: bad settings.

    Attributes:
        config: the `RecorderConfig` in force.
        output: the bag directory (a Path).
        counts: messages written per topic (topics subscribed so far).
        topic_types: {topic: type} of the recorded topics.
        closed: the bag has been finalised.
    """

    def __init__(self, config: RecorderConfig | None = None, *,
                 node_name: str = 'bag_recorder_node', **node_kwargs: Any):
        if config is not None:
            node_kwargs['parameter_overrides'] = (
                list(node_kwargs.get('parameter_overrides') or []) + config_overrides(config))
        super().__init__(node_name, **node_kwargs)
        self.counts: dict[str, int] = {}
        self.topic_types: dict[str, str] = {}
        self._lock = threading.Lock()
        self._writer = None
        self._connections: dict[str, Any] = {}
        self._subs: dict[str, Any] = {}
        self._ignored: set[str] = set()
        self._waiting: set[str] = set()
        self._timer = None
        try:
            self.config: RecorderConfig = declare_config(self, RecorderConfig)
            self.output = self._open_writer()
            cfg = self.config
            self._include = {normalize_topic(t) for t in cfg.topics if t.strip()}
            self._exclude = {normalize_topic(t) for t in cfg.exclude_topics if t.strip()}
            self.get_logger().info(
                f"recording to '{self.output}' (MCAP, compression {cfg.compression}): "
                + (', '.join(sorted(self._include)) if self._include else 'all topics')
                + (f" except {', '.join(sorted(self._exclude))}" if self._exclude else ''))
            self.discover()
            self._timer = self.create_timer(cfg.discovery_period, self.discover)
        except BaseException as exc:
            if isinstance(exc, RecorderError):
                self.get_logger().error(str(exc))
            with contextlib.suppress(Exception):
                self.destroy_node()  # finalises the bag if it was opened
            raise

    @property
    def closed(self) -> bool:
        """True once the bag has been finalised."""
        return self._writer is None

    def _open_writer(self) -> Path:
        from rosbags.rosbag2 import Writer
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

        out = self.config.output.strip()
        path = Path(out).expanduser() if out else Path(
            time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S'))
        if path.exists():
            if not path.is_dir():
                raise RecorderError(f"cannot record to '{path}': it exists and is not a "
                                    'directory')
            if any(path.iterdir()):
                raise RecorderError(f"cannot record to '{path}': the directory exists and is "
                                    'not empty; not overwriting it')
            path.rmdir()  # rosbags creates the directory itself
        try:
            writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
            if self.config.compression == 'zstd':
                writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            writer.open()
        except Exception as exc:  # noqa: BLE001 - rosbags WriterError, OSError
            raise RecorderError(f"cannot record to '{path}': {exc}") from exc
        self._writer = writer
        return path

    # --- discovery ----------------------------------------------------------------------

    def _wanted(self, topic: str) -> bool:
        if topic in self._exclude:
            return False
        if self._include:
            return topic in self._include
        return not _hidden(topic)

    def discover(self) -> None:
        """Subscribe to the chosen topics that have appeared since the last look."""
        if self.closed:
            return
        log = self.get_logger()
        try:
            names_types = self.get_topic_names_and_types()
        except Exception:  # noqa: BLE001 - context going down
            return
        for topic, types in names_types:
            if topic in self._subs or topic in self._ignored or not self._wanted(topic):
                continue
            msgtype = types[0]
            if len(types) > 1:
                log.warning(f"topic {topic} has several types ({', '.join(types)}): "
                            f'recording {msgtype}')
            if msgtype not in typestore().types:
                log.warning(f'not recording {topic}: type {msgtype} is unknown to the bag '
                            'typestore')
                self._ignored.add(topic)
                continue
            try:
                cls = message_class(msgtype)
            except ImportError as exc:
                log.warning(f'not recording {topic}: type {msgtype} cannot be imported ({exc})')
                self._ignored.add(topic)
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                if topic not in self._waiting:
                    self._waiting.add(topic)
                    log.debug(f'{topic}: no publisher yet')
                continue
            self._subscribe(topic, msgtype, cls, [i.qos_profile for i in infos])

    def _subscribe(self, topic: str, msgtype: str, cls: type,
                   offered: list[QoSProfile]) -> None:
        qos = subscription_qos(offered)
        with self._lock:
            if self._writer is None:
                return
            try:
                conn = self._writer.add_connection(
                    topic, msgtype, typestore=typestore(),
                    offered_qos_profiles=[rosbags_qos(q) for q in offered])
            except Exception as exc:  # noqa: BLE001 - e.g. a definition rosbags cannot hash
                self.get_logger().warning(f'not recording {topic}: {exc}')
                self._ignored.add(topic)
                return
            self._connections[topic] = conn
            self.counts[topic] = 0
            self.topic_types[topic] = msgtype
        self._subs[topic] = self.create_subscription(
            cls, topic, lambda data, t=topic: self._on_message(t, data), qos, raw=True)
        self.get_logger().info(
            f'recording {topic} [{msgtype}] ({qos.reliability.name.lower()}, '
            f'{qos.durability.name.lower()})')

    # --- writing ------------------------------------------------------------------------

    def _on_message(self, topic: str, data: bytes) -> None:
        t_ns = self.get_clock().now().nanoseconds
        with self._lock:
            if self._writer is None:
                return
            try:
                self._writer.write(self._connections[topic], t_ns, data)
            except Exception as exc:  # noqa: BLE001 - disk full etc.: keep going, say so
                self.get_logger().error(f'cannot write a message of {topic}: {exc}',
                                        throttle_duration_sec=2.0)
                return
            self.counts[topic] += 1

    def close(self) -> None:
        """Finalise the bag (MCAP summary and metadata.yaml). Idempotent."""
        with self._lock:
            writer, self._writer = self._writer, None
            if writer is None:
                return
            if self._timer is not None:
                self._timer.cancel()
            writer.close()
        total = sum(self.counts.values())
        try:
            log = self.get_logger()
            log.info(f"wrote bag '{self.output}': {total} messages"
                     + (': ' + ', '.join(f'{t} {n}' for t, n in sorted(self.counts.items()))
                        if self.counts else ''))
            if not total:
                log.warning(f"bag '{self.output}' holds no message")
        except Exception:  # noqa: BLE001 - the logger may be gone at shutdown
            pass

    def destroy_node(self) -> None:
        """Finalise the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """`bag_recorder_node`: record until Ctrl-C / SIGTERM, then finalise the bag.

    Exits 0 after a clean stop, 2 when the output cannot be written or the settings are
    invalid.
    """
    run_node(BagRecorderNode, args, name='bag_recorder_node', errors=(RecorderError,))


if __name__ == '__main__':
    main()
