"""Bag player: replays a rosbag2 bag (MCAP directory or single .mcap file) on ROS topics.

PyPI has no rosbag2, so this node stands in for ``ros2 bag play``: it publishes every
topic of the bag with its recorded type and timing (receive timestamps scaled by
1/rate), passing the serialized CDR bytes through untouched. image_transport
``<topic>/compressed`` streams (PNG/JPEG) are decoded and published as mono8
``sensor_msgs/Image`` on ``<topic>``.

Publishing runs in a dedicated thread (`BagPlayerNode.start`), so the node needs no
spinning to play; spinning serves its parameter services and, when the replay is paced
(``pace_topic``), the subscription that counts a node's answers: an image is then held
back, with the whole replay, while more than ``pace_lead`` images are unanswered, so a
machine slower than the bag's rate slows the replay instead of dropping pairs
(``asmonc run`` paces by /obstacles). Before the end is
reported, the player waits (at most ACK_TIMEOUT) until reliable subscribers have
acknowledged the last messages, so exiting right after does not lose them. With ``start_paused``
the first message waits for the ``~/resume`` service (std_srvs/Trigger), as with
``ros2 bag play --start-paused``, and the wait for subscribers (``wait_topics``,
``wait_timeout``) follows the resume: ``asmonc run`` starts the player while the last nodes
start and calls ~/resume once every node has logged its own side of each link (a
best-effort reader drops what comes before). For the ``asmonc run``
orchestrator the node offers `play_done` (an Event), `published_counts` and `error`.

Errors: a missing, unreadable or empty bag is logged (naming the file) and raises
`BagError` from the constructor; `main` exits with status 2. A bag cut short plays what
can be read, then logs the truncation; `error` is set and `main` exits with status 2.
"""
from __future__ import annotations

import collections
import contextlib
import importlib
import re
import struct
import threading
import time
from collections.abc import Iterable
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from asmonc_vision.io.bagio import compressed_to_image_cdr, has_header
from asmonc_vision.io.bagplay import (BagError, BagSource, PlayerConfig, PlayTopic,
                                      ReplaySchedule, loop_period_ns,
                                      normalize_topic, plan_topics, restamp_cdr)
from asmonc_vision.nodes.common import config_overrides, declare_config, run_node
from asmonc_vision.nodes.conversions import stamp_to_ns

__all__ = ['BagPlayerNode', 'BagError', 'PlayerConfig', 'message_class', 'main']

#: publisher depth of image streams (a reader keeps up; a deep queue only adds latency)
IMAGE_DEPTH = 10
#: publisher depth of small topics (camera_info, imu, results)
SMALL_DEPTH = 100
#: /clock is published at least this often while waiting for the next message
CLOCK_HZ = 25.0
#: at the end, wait at most this long (s) for subscribers to acknowledge the last messages
#: (a reliable writer's periodic heartbeat, which asks for them, comes every 3 s in Fast
#: DDS: with 2 s, half the walking replays warned that the last camera_info was unacked)
ACK_TIMEOUT = 4.0
#: the log line of a paced replay's end (`read_paced_line` reads it back for `asmonc run`)
PACED_LINE = ('paced by {topic}: held back {holds} time(s), {held_s:.2f} s in all; '
              '{given_up} image(s) given up')
_PACED_RE = re.compile(r'paced by \S+: held back (\d+) time\(s\), ([0-9.]+) s in all; '
                       r'(\d+) image\(s\) given up')


def read_paced_line(log: str) -> tuple[int, float, int] | None:
    """(times held back, seconds held back, images given up) from the last `PACED_LINE`
    in a player's log text; None if it has none."""
    found = _PACED_RE.findall(log)
    if not found:
        return None
    holds, held_s, given_up = found[-1]
    return int(holds), float(held_s), int(given_up)


def message_class(msgtype: str):
    """rclpy message class for 'pkg/msg/Name'.

    Raises:
        ImportError: the package is not installed, or the name is not 'pkg/msg/Name'.
    """
    parts = msgtype.split('/')
    if len(parts) != 3 or parts[1] != 'msg':
        raise ImportError(f"'{msgtype}' is not a message type name (pkg/msg/Name)")
    module = importlib.import_module(f'{parts[0]}.msg')
    try:
        return getattr(module, parts[2])
    except AttributeError:
        raise ImportError(f'{parts[0]}.msg has no message {parts[2]}') from None


class BagPlayerNode(Node):
    """Replays a bag on its topics (see the module docstring).

    Args:
        config: settings; None reads them from the ROS parameters (YAML, command line).
        node_name: the node's name.
        start: start playing at once (else call `start()`).
        **node_kwargs: passed to rclpy's Node (context, parameter_overrides, ...).
    Raises:
        BagError: the bag is missing, unreadable or empty, or no topic can be played
            (already logged as an error).
        ValueError, rclpy.exceptions.InvalidParameterValueException: bad settings.

    Attributes:
        config: the `PlayerConfig` in force.
        source: the opened `BagSource` (its `info` describes the bag).
        plan: the published streams (`PlayTopic`).
        published_counts: messages published per published topic (updated while playing).
        play_done: set when playing has ended (bag done and not looping, error, or stop).
        passes: completed passes through the bag.
        error: why the bag could not be played to its end, or None.
    """

    def __init__(self, config: PlayerConfig | None = None, *,
                 node_name: str = 'bag_player_node', start: bool = True, **node_kwargs: Any):
        if config is not None:
            node_kwargs['parameter_overrides'] = (
                list(node_kwargs.get('parameter_overrides') or []) + config_overrides(config))
        super().__init__(node_name, **node_kwargs)
        self.published_counts: dict[str, int] = {}
        self.play_done = threading.Event()
        self.passes = 0
        self.error: str | None = None
        self._stop = threading.Event()
        #: set by ~/resume (or at once without ``start_paused``): playing may begin
        self._resumed = threading.Event()
        self._thread: threading.Thread | None = None
        self._destroyed = False
        #: pacing (``pace_topic``): the stamps of the unanswered images, whether pacing
        #: waits for the next answer after a timeout, images given up (no answer within
        #: ``pace_timeout``), and how often and how long (s) the replay was held back
        self._pace_cv = threading.Condition()
        self._pace_owed: collections.deque[int] = collections.deque()
        self._pace_suspended = False
        self.pace_given_up = 0
        self.pace_holds = 0
        self.pace_held_s = 0.0
        self._pace_topic: str | None = None
        self._has_header: dict[str, bool] = {}
        try:
            self.config: PlayerConfig = declare_config(self, PlayerConfig)
            self._setup()
        except BagError as exc:
            self.get_logger().error(str(exc))
            self.error = str(exc)
            with contextlib.suppress(Exception):
                self.destroy_node()
            raise
        except Exception:
            with contextlib.suppress(Exception):
                self.destroy_node()
            raise
        if start:
            self.start()

    # --- setup --------------------------------------------------------------------------

    def _setup(self) -> None:
        cfg = self.config
        self.source = BagSource(cfg.bag)
        info = self.source.info
        self._start_ns = info.start_ns + int(round(cfg.start_offset * 1e9))
        if self._start_ns > info.end_ns:
            raise BagError(f"bag '{info.path}': start_offset {cfg.start_offset:.3f} s is "
                           f'past the end of the bag ({info.duration_s:.3f} s long)')
        log = self.get_logger()
        for t in info.topics.values():
            if t.other_types:
                log.warning(f"bag topic {t.name} also holds type(s) {', '.join(t.other_types)}"
                            f': playing only {t.msgtype}')
        plan = plan_topics(info.topics, cfg.topics, cfg.exclude_topics)
        self.plan: list[PlayTopic] = []
        self._pubs: dict[str, Any] = {}
        for p in plan:
            try:
                cls = message_class(p.out_type)
            except ImportError as exc:
                log.warning(f'skipping topic {p.bag_topic}: unknown message type '
                            f'{p.bag_type} ({exc})')
                continue
            if p.out_topic in self._pubs:
                log.warning(f'skipping topic {p.bag_topic}: {p.out_topic} is already played')
                continue
            if cfg.publish_clock and p.out_topic == '/clock':
                log.warning('skipping the bag\'s /clock: publish_clock makes a new one')
                continue
            depth = IMAGE_DEPTH if p.out_type.endswith('Image') else SMALL_DEPTH
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=(DurabilityPolicy.TRANSIENT_LOCAL if p.latched
                                         else DurabilityPolicy.VOLATILE))
            self._pubs[p.out_topic] = self.create_publisher(cls, p.out_topic, qos)
            self.published_counts[p.out_topic] = 0
            self.plan.append(p)
        if not self.plan:
            raise BagError(f"bag '{info.path}': no topic to play (bag topics: "
                           f"{', '.join(sorted(info.topics)) or 'none'}; topics="
                           f'{list(cfg.topics)}, exclude_topics={list(cfg.exclude_topics)})')
        self._by_bag_topic = {p.bag_topic: p for p in self.plan}
        from asmonc_vision.faults import FaultPlan, parse_faults
        self._faults = FaultPlan(parse_faults(cfg.faults), info.start_ns)
        self._faults_started: set[int] = set()
        if self._faults:
            log.warning('injecting faults: ' + '; '.join(map(str, self._faults.faults)))
        if cfg.pace_topic:
            self._setup_pacing()
        if cfg.start_paused:
            from std_srvs.srv import Trigger
            self.create_service(Trigger, '~/resume', self._on_resume)
        else:
            self._resumed.set()
        self._clock_pub = None
        if cfg.publish_clock:
            from rosgraph_msgs.msg import Clock
            self._clock_pub = self.create_publisher(
                Clock, '/clock', QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
            self._clock_msg = Clock()
            self._last_clock = 0.0
        note = ''
        if info.truncated:
            note = f' [damaged: playing the {info.message_count} message(s) that can be read]'
        files = ', '.join(f.name for f in info.files)
        log.info(f"bag '{info.path}' ({info.storage}, {files}): "
                 f'{info.duration_s:.3f} s, {info.message_count} messages, '
                 f'{len(info.topics)} topics; rate {cfg.rate:g}'
                 + (f', from {cfg.start_offset:g} s' if cfg.start_offset else '')
                 + (', looping' if cfg.loop else '') + note)
        for p in self.plan:
            how = (f' -> {p.out_topic} [{p.out_type}, decoded mono8]' if p.decompress
                   else '')
            log.info(f'  {p.bag_topic} [{p.bag_type}] {p.count} msgs{how}'
                     + (' (latched)' if p.latched else ''))
        if info.truncated:
            log.warning(info.truncated)

    def _setup_pacing(self) -> None:
        cfg = self.config
        try:
            cls = message_class(cfg.pace_type)
        except ImportError as exc:
            raise ValueError(f"pace_type '{cfg.pace_type}': {exc}") from None
        images = self.image_topics
        topic = normalize_topic(cfg.pace_image_topic) if cfg.pace_image_topic else (
            images[0] if images else None)
        if topic is None or topic not in images:
            self.get_logger().warning(
                f'pace_topic {cfg.pace_topic}: no image topic {topic or ""} played from this '
                'bag; playing at the bag\'s rate')
            return
        self._pace_topic = topic
        self.create_subscription(cls, cfg.pace_topic, self._on_pace_answer,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        self.get_logger().info(f'pacing {topic} by {cfg.pace_topic}: at most {cfg.pace_lead} '
                               'image(s) ahead of their answers')

    def _on_resume(self, request, response):
        """~/resume (std_srvs/Trigger): let a player started paused begin."""
        response.success = not self._resumed.is_set()
        response.message = 'playing' if response.success else 'already playing'
        self._resumed.set()
        return response

    def _on_pace_answer(self, msg) -> None:
        # The node answers in the order it got the images: an answer for stamp s also
        # settles every image sent before s (those will never be answered: pairs it
        # skipped or dropped).
        stamp = stamp_to_ns(msg.header.stamp)
        with self._pace_cv:
            if stamp in self._pace_owed:
                while self._pace_owed.popleft() != stamp:
                    pass
            self._pace_suspended = False
            self._pace_cv.notify_all()

    def _pace(self, sched: ReplaySchedule) -> None:
        """Hold the replay while more than ``pace_lead`` images of the paced topic are
        unanswered, at most ``pace_timeout``; then give them up and stop pacing until the
        next answer (a node that answers nothing costs one timeout, not one per image).
        The schedule is shifted by the hold, so the bag's timing resumes where it stopped."""
        cfg = self.config
        start = time.monotonic()
        deadline = start + cfg.pace_timeout
        waited = False        # a hold is a wait for answers, not the time to take the lock
        with self._pace_cv:
            while (len(self._pace_owed) > cfg.pace_lead and not self._pace_suspended
                   and not self._stop.is_set()):
                waited = True
                left = deadline - time.monotonic()
                if left <= 0:
                    self.pace_given_up += len(self._pace_owed)
                    self.get_logger().warning(
                        f'no answer on {cfg.pace_topic} within {cfg.pace_timeout:g} s for '
                        f'{len(self._pace_owed)} image(s) of {self._pace_topic}; playing on '
                        'at the bag\'s rate until the next answer', throttle_duration_sec=5.0)
                    self._pace_owed.clear()
                    self._pace_suspended = True
                    break
                self._pace_cv.wait(min(left, 0.1))
        held = time.monotonic() - start
        if waited:
            self.pace_holds += 1
            self.pace_held_s += held
            sched.wall_start += held

    def _paced_sent(self, data: bytes) -> None:
        """Note an image of the paced topic as sent, just before it is (its header stamp,
        read from the CDR)."""
        end = '<' if len(data) > 1 and data[1] == 1 else '>'   # CDR_LE or CDR_BE
        sec, nsec = struct.unpack_from(end + 'iI', data, 4)
        with self._pace_cv:
            self._pace_owed.append(sec * 1_000_000_000 + nsec)

    # --- playing ------------------------------------------------------------------------

    def start(self) -> None:
        """Start the playing thread (once)."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name='bag_player', daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop playing and wait for the thread to end."""
        self._stop.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout)

    @property
    def image_topics(self) -> list[str]:
        """Published topics of type sensor_msgs/Image."""
        return [p.out_topic for p in self.plan if p.is_image]

    @property
    def camera_topics(self) -> list[str]:
        """Published topics of type sensor_msgs/Image and CameraInfo."""
        return [p.out_topic for p in self.plan if p.is_camera]

    def wait_for_targets(self, targets: dict[str, int], timeout: float) -> bool:
        """Wait until each published topic of ``targets`` has that many subscribers
        (topics not played are left out, with a warning).

        Args:
            targets: {topic: subscribers needed}.
            timeout: seconds; <= 0 waits without limit (until `stop`).
        Returns:
            True when they are there, False on timeout or stop.
        """
        known = {t: n for t, n in targets.items() if t in self._pubs}
        if len(known) < len(targets):
            self.get_logger().warning(
                'not waiting for subscribers of ' + ', '.join(sorted(set(targets) - set(known)))
                + ': not played from this bag')
        deadline = None if timeout <= 0 else time.monotonic() + timeout
        while not self._stop.is_set():
            missing = {t: (have, n) for t, n in known.items()
                       if (have := self._pubs[t].get_subscription_count()) < n}
            if not missing:
                return True
            if deadline is not None and time.monotonic() > deadline:
                self.get_logger().warning(
                    f'waited {timeout:g} s for subscribers; still missing on '
                    + ', '.join(f'{t} ({have} of {n})' for t, (have, n) in sorted(missing.items()))
                    + ': playing anyway')
                return False
            self._stop.wait(0.02)
        return False

    def wait_for_subscribers(self, count: int, timeout: float,
                             topics: Iterable[str] | None = None) -> bool:
        """Wait until each of `topics` (default: the image and camera_info topics: a
        stereo node needs both, and a message published before its subscriber is
        matched is lost) has `count` subscribers (`wait_for_targets`)."""
        topics = self.camera_topics if topics is None else topics
        return self.wait_for_targets({t: count for t in topics}, timeout)

    def _run(self) -> None:
        cfg = self.config
        log = self.get_logger()
        stopped_early = False
        try:
            # paused, the wait for subscribers runs from the resume (the caller resumes
            # once its readers are there; they may start after the player)
            if cfg.start_paused and not self._resumed.is_set():
                log.info('paused before the first message: waiting for ~/resume')
                while not self._resumed.wait(0.05):
                    if self._stop.is_set() or not self.context.ok():
                        raise _ContextGone
                log.info('resumed')
            targets = cfg.wait_targets(self.camera_topics)
            if targets:
                log.info('waiting for subscribers: ' + ', '.join(
                    f'{t} ({n})' for t, n in sorted(targets.items())))
                self.wait_for_targets(targets, cfg.wait_timeout)
            while not self._stop.is_set():
                self._play_pass()
                if self._stop.is_set():
                    break
                self.passes += 1
                if not cfg.loop:
                    break
        except _ContextGone:
            stopped_early = True
        except Exception as exc:  # noqa: BLE001 - report, never die silently in a thread
            self.error = f"bag '{self.source.info.path}': playing failed: {exc!r}"
            log.error(self.error)
        finally:
            stopped_early = stopped_early or self._stop.is_set()
            total = sum(self.published_counts.values())
            try:
                log.info(f'published {total} messages'
                         + (f' in {self.passes} pass(es)' if cfg.loop else '')
                         + (' (stopped)' if stopped_early else '') + ': '
                         + ', '.join(f'{t} {n}' for t, n in self.published_counts.items()))
                if self._pace_topic is not None:
                    log.info(PACED_LINE.format(topic=cfg.pace_topic, holds=self.pace_holds,
                                               held_s=self.pace_held_s,
                                               given_up=self.pace_given_up))
                if self.error:
                    log.error(f'bag not played to its end: {self.error}')
            except Exception:  # noqa: BLE001 - the logger may be gone at shutdown
                pass
            if not stopped_early:
                self._wait_acked(ACK_TIMEOUT)
            self.play_done.set()
            if cfg.exit_when_done and not stopped_early:
                self.context.try_shutdown()

    def _wait_acked(self, timeout: float) -> bool:
        """Wait until subscribers have acknowledged every message (the last ones too)."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + timeout
        try:
            for topic, pub in self._pubs.items():
                left = max(0.0, deadline - time.monotonic())
                if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                    self.get_logger().warning(
                        f'{topic}: not every message was acknowledged by its subscribers '
                        f'within {timeout:g} s')
                    return False
        except Exception:  # noqa: BLE001 - the context is going down: nothing to wait for
            return False
        return True

    def _play_pass(self) -> None:
        """Publish the bag once, from start_offset, at the configured rate."""
        cfg = self.config
        selected = {p.bag_topic: p.bag_type for p in self.plan}
        sched = ReplaySchedule(self._start_ns, time.monotonic(), cfg.rate)
        # loop_restamp: pass k is shifted by k bag lengths, so its stamps follow the last
        shift = (self.passes * loop_period_ns(self.source.info, self._start_ns)
                 if cfg.loop and cfg.loop_restamp else 0)
        try:
            for msg in self.source.messages(selected, self._start_ns):
                p = self._by_bag_topic[msg.topic]
                data = self._decode(p, msg.data) if p.decompress else msg.data
                if not self._wait_until(sched, msg.timestamp, shift):
                    return
                if shift and data is not None and self._stamped(p):
                    data = restamp_cdr(data, shift)
                for out in self._inject(p, data, msg.timestamp + shift):
                    if p.out_topic == self._pace_topic:
                        self._pace(sched)
                        if self._stop.is_set():
                            return
                        self._paced_sent(out)     # before publishing: its answer may be quick
                    self._publish(p, out, msg.timestamp + shift)
        except BagError as exc:  # a cut or damage: logged once when playing ends
            if self.error is None:
                self.error = str(exc)

    def _stamped(self, p: PlayTopic) -> bool:
        """Whether the messages of ``p`` start with a Header (cached per topic)."""
        known = self._has_header.get(p.out_topic)
        if known is None:
            known = self._has_header[p.out_topic] = has_header(p.out_type)
        return known

    def _inject(self, p: PlayTopic, data: bytes | None, t_ns: int) -> list[bytes]:
        """``data`` as the ``faults`` setting changes it (none, one or more messages)."""
        if data is None:
            return []
        if not self._faults:
            return [data]
        t = (t_ns - self._faults.start_ns) / 1e9
        for i, f in enumerate(self._faults.faults):
            if i not in self._faults_started and f.active(t):
                self._faults_started.add(i)
                self.get_logger().warning(f'fault injected from {t:.2f} s: {f}')
        return self._faults.apply(p.out_topic, data, t_ns)

    def _wait_until(self, sched: ReplaySchedule, t_ns: int, shift: int = 0) -> bool:
        """Sleep until bag time `t_ns` is due, publishing /clock (moved by ``shift`` ns)
        meanwhile; False on stop."""
        while True:
            now = time.monotonic()
            delay = sched.delay(t_ns, now)
            if self._stop.is_set():
                return False
            if delay <= 0.0:
                return True
            if self._clock_pub is not None:
                if now - self._last_clock >= 1.0 / CLOCK_HZ:
                    self._publish_clock(sched.bag_time(now) + shift)
                    self._last_clock = now
                delay = min(delay, 1.0 / CLOCK_HZ)
            self._stop.wait(delay)

    def _publish_clock(self, t_ns: int) -> None:
        self._clock_msg.clock.sec = int(t_ns // 1_000_000_000)
        self._clock_msg.clock.nanosec = int(t_ns % 1_000_000_000)
        self._clock_pub.publish(self._clock_msg)

    def _decode(self, p: PlayTopic, data: bytes) -> bytes | None:
        """CompressedImage CDR -> mono8 Image CDR; None (and a warning) if undecodable."""
        try:
            return compressed_to_image_cdr(data)
        except Exception as exc:  # noqa: BLE001 - a bad frame must not stop the replay
            self.get_logger().warning(
                f'cannot decode a compressed image on {p.bag_topic}: {exc}',
                throttle_duration_sec=2.0)
            return None

    def _publish(self, p: PlayTopic, data: bytes, t_ns: int) -> None:
        if not self.context.ok():
            raise _ContextGone()
        try:
            if self._clock_pub is not None:
                self._publish_clock(t_ns)
                self._last_clock = time.monotonic()
            self._pubs[p.out_topic].publish(data)
        except Exception:
            if not self.context.ok():
                raise _ContextGone() from None
            raise
        self.published_counts[p.out_topic] += 1

    def destroy_node(self) -> None:
        """Stop the playing thread, then destroy the node."""
        if self._destroyed:
            return
        self._destroyed = True
        self.stop()
        super().destroy_node()


class _ContextGone(Exception):
    """The context was shut down under the playing thread."""


def main(args: list[str] | None = None) -> None:
    """`bag_player_node`: play the bag given by the `bag` parameter.

    Exits 0 when the bag has been played (or on Ctrl-C), 2 when the bag is missing,
    unreadable, empty or truncated, or the settings are invalid.
    """
    run_node(BagPlayerNode, args, name='bag_player_node', errors=(BagError,),
             failed=lambda n: bool(n.error))


if __name__ == '__main__':
    main()
