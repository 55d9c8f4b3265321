"""The rectified stereo pair as input: what the detector and egomotion nodes share.

`StereoInputNode` subscribes to `/stereo/{left,right}/image_rect` and their camera
infos, pairs left and right by stamp (`StereoPairer`), queues pairs (bounded: the oldest
is dropped, with a warning, when the work falls behind) and hands each good pair to
`process_pair` on a worker thread, so the callbacks that receive images stay fast.
Bad input is logged (throttled), counted and reported in /diagnostics, and the pair is
skipped: a wrong encoding, left and right of different sizes, images that do not match
their camera_info, stamps that do not pair or go backwards; so are pairs that never
came (a stamp step well beyond the usual one). A pair uses the camera_infos stamped like
it when they have come (each side's newest otherwise). A jump back in time (a replayed
bag that loops) or a new camera calls `restart`.
"""
from __future__ import annotations

import collections
import itertools
import threading
import time
from dataclasses import dataclass

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from asmonc_vision.core.camera import StereoCamera, align_right_image, principal_offset_px
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.nodes.common import IMAGE_QOS, Diagnostics, watch_input_links
from asmonc_vision.nodes.conversions import (ImageFormatError, image_msg_to_gray, stamp_to_ns,
                                             stereo_camera_from_infos)


#: camera_infos kept per side to find the one stamped like a pair
INFO_HISTORY = 32
#: a stamp step this many times the usual one means pairs are missing
GAP_FACTOR = 1.8
#: stamp steps kept to judge the usual one
GAP_HISTORY = 20


@dataclass(frozen=True)
class StereoInputConfig:
    """Settings of the stereo input every `StereoInputNode` shares (pairing, queue,
    time-outs); a node's own settings class derives from it and may override a default by
    declaring the field again."""

    max_stamp_skew: float = param(
        0.0, 'largest left/right stamp difference still paired, s (0: stamps must be equal)',
        range=(0.0, 0.1))
    max_pending_pairs: int = param(
        10, 'pairs waiting for processing before the oldest is dropped (with a warning)',
        range=(1, 1000))
    unpaired_timeout: float = param(
        1.0, 'an image with no partner this long (s of stamp time) is dropped with a warning',
        range=(0.05, 10.0))
    info_wait: float = param(
        8.0, 'how long a pair waits for the first camera_info before it is skipped, s (once '
        'this wait has run out, later pairs are skipped at once until a camera_info comes; '
        'a camera_info sent before this node saw its publisher comes again at the '
        "publisher's next DDS heartbeat, every 3 s in Fast DDS)",
        range=(0.0, 10.0))
    input_timeout: float = param(
        2.0, 'no image pair for this long (s) is reported in /diagnostics', range=(0.1, 60.0))
    time_jump_reset: float = param(
        1.0, 'stamps going back by more than this (s) restart the node\'s processing and its '
        'state: the detector\'s plane, the estimator\'s odometry (bag loop)',
        range=(0.0, 1e6))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass
class StereoPair:
    """One received pair: messages as they came, and a sequence number (0, 1, ...)."""

    seq: int
    stamp_ns: int
    left: Image
    right: Image
    left_info: CameraInfo | None
    right_info: CameraInfo | None


class StereoPairer:
    """Pairs left and right images by stamp (pure bookkeeping, no ROS calls).

    `add(side, stamp_ns, item)` returns the (left, right) items when a partner with a
    stamp within `max_skew_ns` exists, else None. Items older than `timeout_ns` than the
    newest stamp seen, still unpaired, are returned by `expire()` for reporting.
    """

    def __init__(self, max_skew_ns: int, timeout_ns: int, capacity: int = 64):
        self.max_skew_ns = max_skew_ns
        self.timeout_ns = timeout_ns
        self._waiting = {'left': collections.OrderedDict(), 'right': collections.OrderedDict()}
        self._capacity = capacity
        self._newest = 0

    def add(self, side: str, stamp_ns: int, item):
        other = 'right' if side == 'left' else 'left'
        self._newest = max(self._newest, stamp_ns)
        best, best_dt = None, None
        for s in self._waiting[other]:
            dt = abs(s - stamp_ns)
            if dt <= self.max_skew_ns and (best_dt is None or dt < best_dt):
                best, best_dt = s, dt
        if best is not None:
            partner = self._waiting[other].pop(best)
            return (item, partner) if side == 'left' else (partner, item)
        waiting = self._waiting[side]
        waiting[stamp_ns] = item
        while len(waiting) > self._capacity:
            waiting.popitem(last=False)
        return None

    def expire(self) -> list[tuple[str, int]]:
        """Drop and return (side, stamp_ns) of images that will never find a partner."""
        gone = []
        for side, waiting in self._waiting.items():
            for s in [s for s in waiting if self._newest - s > self.timeout_ns]:
                waiting.pop(s)
                gone.append((side, s))
        return gone

    def clear(self) -> None:
        for w in self._waiting.values():
            w.clear()
        self._newest = 0


class StereoInputNode(Node):
    """Base of nodes that work on the rectified stereo pair (see the module docstring).

    A subclass declares its settings (which must have the fields `max_stamp_skew`,
    `max_pending_pairs`, `unpaired_timeout`, `info_wait`, `input_timeout` and
    `time_jump_reset`), then calls `start_stereo_input(settings)`, and implements
    `process_pair(pair, left, right, cam)` (on the worker thread; left/right are
    (H, W) uint8) and `restart()`.
    """

    def __init__(self, node_name: str, label: str, **kwargs):
        super().__init__(node_name, **kwargs)
        self.label = label
        self.diag = Diagnostics(self, f'asmonc_vision: {label}')
        self.frames_in = 0
        self.frames_done = 0
        self.frames_dropped = 0
        self.frames_bad = 0
        #: pairs that never came, judged by the gaps in the stamps (`_check_gap`)
        self.frames_missing = 0
        self._last_seen_ns: int | None = None
        self._steps: collections.deque[float] = collections.deque(maxlen=GAP_HISTORY)
        self._lock = threading.Lock()
        self._info = {'left': None, 'right': None}
        #: the newest camera_infos by stamp (ns), per side
        self._info_by_stamp = {'left': collections.OrderedDict(),
                               'right': collections.OrderedDict()}
        self._seq = itertools.count()
        self._pending: collections.deque[StereoPair] = collections.deque()
        self._cv = threading.Condition()
        self._stop = False
        self._camera: StereoCamera | None = None
        #: cx_left - cx_right of the camera_infos, px (`core.camera.principal_offset_px`)
        self._right_offset = 0.0
        self._camera_key = None
        #: set when a pair waited `info_wait` for a camera_info in vain (cleared by one)
        self._info_missing = False
        self._last_stamp_ns: int | None = None
        self._last_pair_wall = time.monotonic()
        self._worker: threading.Thread | None = None

    # --- subclass interface ----------------------------------------------------------
    def process_pair(self, pair: StereoPair, left: np.ndarray, right: np.ndarray,
                     cam: StereoCamera) -> None:
        """Work on one good pair (worker thread)."""
        raise NotImplementedError

    def restart(self) -> None:
        """Forget the past: time went back (a looping replay) or the camera changed."""

    def pending_pairs(self) -> int:
        """Pairs received and waiting for the worker."""
        with self._cv:
            return len(self._pending)

    def skip_pair(self, pair: StereoPair, level: int, why: str) -> None:
        """A pair could not be used: count it and report why in /diagnostics."""
        self.frames_bad += 1
        self.diag.update(level, why, frames_in=self.frames_in, frames_done=self.frames_done,
                         frames_bad=self.frames_bad)

    def start_stereo_input(self, settings: StereoInputConfig) -> None:
        """Subscribe and start the worker; call at the end of the subclass's __init__."""
        self._settings = settings
        self._pairer = StereoPairer(int(settings.max_stamp_skew * 1e9),
                                    int(settings.unpaired_timeout * 1e9))
        self.create_subscription(Image, '/stereo/left/image_rect',
                                 lambda m: self._on_image('left', m), IMAGE_QOS)
        self.create_subscription(Image, '/stereo/right/image_rect',
                                 lambda m: self._on_image('right', m), IMAGE_QOS)
        self.create_subscription(CameraInfo, '/stereo/left/camera_info',
                                 lambda m: self._on_info('left', m), IMAGE_QOS)
        self.create_subscription(CameraInfo, '/stereo/right/camera_info',
                                 lambda m: self._on_info('right', m), IMAGE_QOS)
        watch_input_links(self, ('/stereo/left/image_rect', '/stereo/right/image_rect'))
        self.create_timer(0.5, self._check_input)
        self._worker = threading.Thread(target=self._work, name=f'{self.label}-worker',
                                        daemon=True)
        self._worker.start()

    # --- callbacks: cheap bookkeeping only --------------------------------------------
    def _on_info(self, side: str, msg: CameraInfo) -> None:
        with self._lock:
            self._info[side] = msg
            self._info_missing = False
            recent = self._info_by_stamp[side]
            recent[stamp_to_ns(msg.header.stamp)] = msg
            while len(recent) > INFO_HISTORY:
                recent.popitem(last=False)

    def _infos_for(self, stamp_ns: int) -> tuple[CameraInfo | None, CameraInfo | None]:
        """The camera_infos stamped like a pair (each side's newest if none is): the infos
        travel on their own topics, so the newest may already be the next frame's, or the
        one before, whatever its content (a bad one would spoil a good pair)."""
        with self._lock:
            return tuple(self._info_by_stamp[side].get(stamp_ns, self._info[side])
                         for side in ('left', 'right'))

    def _on_image(self, side: str, msg: Image) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        with self._lock:
            pair = self._pairer.add(side, stamp, msg)
            expired = self._pairer.expire()
        infos = self._infos_for(stamp)
        for s, t in expired:
            self.frames_bad += 1
            self.diag.update(Diagnostics.WARN, 'images without a partner (stamps differ)',
                             frames_in=self.frames_in, frames_done=self.frames_done,
                             frames_bad=self.frames_bad)
            self.get_logger().warn(
                f'{s} image at stamp {t / 1e9:.3f} s has no partner with the same stamp; '
                'dropped (left and right must share one stamp, or differ by at most the '
                f'max_stamp_skew parameter, now {self._settings.max_stamp_skew:g} s)',
                throttle_duration_sec=2.0)
        if pair is None:
            return
        self.frames_in += 1
        with self._cv:
            self._pending.append(StereoPair(next(self._seq), stamp, pair[0], pair[1], *infos))
            while len(self._pending) > self._settings.max_pending_pairs:
                old = self._pending.popleft()
                self.frames_dropped += 1
                if self._settings.max_pending_pairs == 1:
                    continue            # a queue of one keeps to the newest pair by design
                self.get_logger().warn(
                    f'{self.label} falling behind: dropped the pair at '
                    f'{old.stamp_ns / 1e9:.3f} s ({self.frames_dropped} dropped so far)',
                    throttle_duration_sec=2.0)
            self._cv.notify()

    def _check_input(self) -> None:
        idle = time.monotonic() - self._last_pair_wall
        if idle > self._settings.input_timeout:
            self.diag.update(Diagnostics.WARN, f'no stereo pair for {idle:.1f} s',
                             frames_in=self.frames_in, frames_done=self.frames_done)

    # --- worker --------------------------------------------------------------------
    def _work(self) -> None:
        while True:
            with self._cv:
                while not self._pending and not self._stop:
                    self._cv.wait(timeout=0.5)
                if self._stop:
                    return
                pair = self._pending.popleft()
            try:
                self._process(pair)
            except Exception as exc:  # a bug must not silence the node for good
                self.frames_bad += 1
                self.get_logger().error(f'{self.label} failed on pair {pair.stamp_ns / 1e9:.3f} s: '
                                        f'{type(exc).__name__}: {exc}', throttle_duration_sec=1.0)
                self.diag.update(Diagnostics.ERROR, f'internal error: {exc}')

    def _camera_for(self, pair: StereoPair) -> StereoCamera | None:
        # The infos travel on their own topics and may arrive after the first images (one
        # sent before this node saw its publisher comes again only at the publisher's next
        # DDS heartbeat, 3 s later in Fast DDS): the first pair waits up to `info_wait`
        # for them, the pairs behind it queue. Once that wait has run out, pairs are
        # skipped at once (no pair-per-`info_wait` crawl that would overflow the queue)
        # until a camera_info arrives.
        began = time.monotonic()
        deadline = began + self._settings.info_wait
        matched = self._infos_for(pair.stamp_ns)   # those stamped like it may be in by now
        pair.left_info = matched[0] or pair.left_info
        pair.right_info = matched[1] or pair.right_info
        while pair.left_info is None or pair.right_info is None:
            with self._lock:
                pair.left_info = pair.left_info or self._info['left']
                pair.right_info = pair.right_info or self._info['right']
                missing = self._info_missing
            if pair.left_info is not None and pair.right_info is not None:
                break
            if missing or time.monotonic() > deadline or self._stop:
                with self._lock:
                    self._info_missing = (self._info['left'] is None
                                          or self._info['right'] is None)
                self.get_logger().warn(
                    'no camera_info on /stereo/{left,right}/camera_info; pair skipped',
                    throttle_duration_sec=2.0)
                return None
            time.sleep(0.01)
        waited = time.monotonic() - began
        if waited > 0.1:
            self.get_logger().info(f'the camera_info for the pair at {pair.stamp_ns / 1e9:.3f} s '
                                   f'came {waited:.2f} s after it')
        key = (tuple(pair.left_info.p), tuple(pair.right_info.p),
               pair.left_info.width, pair.left_info.height)
        if key != self._camera_key:
            try:
                cam = stereo_camera_from_infos(pair.left_info, pair.right_info)
                offset = principal_offset_px(pair.left_info.p, pair.right_info.p, cam.width)
            except ValueError as exc:
                self.get_logger().error(f'bad camera_info: {exc}', throttle_duration_sec=2.0)
                return None
            if self._camera is not None:
                self.get_logger().info(f'camera changed to {cam}; restarting the {self.label}')
                self.restart()
            self._camera, self._camera_key, self._right_offset = cam, key, offset
            self.get_logger().info(
                f'camera: {cam.width}x{cam.height}, f={cam.f:.1f} px, B={cam.baseline:.3f} m'
                + (f'; right image moved {offset:+.2f} px to the left principal point'
                   if offset else ''))
        return self._camera

    def _check_gap(self, stamp_ns: int) -> None:
        """Report pairs that never came (dropped on the way, a stalled camera): a stamp
        step more than `GAP_FACTOR` times the usual one (the median of the recent
        steps) is logged (throttled), counted in ``frames_missing`` and said in
        /diagnostics."""
        last = self._last_seen_ns
        if last is not None and stamp_ns <= last:
            if (last - stamp_ns) / 1e9 > self._settings.time_jump_reset:
                self._last_seen_ns = stamp_ns    # time went back (a bag loop)
            return                               # else a stamp out of order: skipped
        self._last_seen_ns = stamp_ns
        if last is None:
            return
        dt = (stamp_ns - last) / 1e9
        if len(self._steps) >= 3:
            usual = float(np.median(self._steps))
            if dt > GAP_FACTOR * usual:
                missing = max(1, int(round(dt / usual)) - 1)
                self.frames_missing += missing
                self.get_logger().warn(
                    f'{missing} stereo pair(s) missing before {stamp_ns / 1e9:.3f} s: '
                    f'{dt:.2f} s since the last pair (usually {usual:.3f} s; '
                    f'{self.frames_missing} missing so far)', throttle_duration_sec=2.0)
                self.diag.update(Diagnostics.WARN, f'{missing} stereo pair(s) missing',
                                 frames_in=self.frames_in, frames_done=self.frames_done,
                                 frames_missing=self.frames_missing)
                return              # a gap is not a usual step
        self._steps.append(dt)

    def _process(self, pair: StereoPair) -> None:
        self._last_pair_wall = time.monotonic()
        log = self.get_logger()
        self._check_gap(pair.stamp_ns)
        if self._last_stamp_ns is not None and pair.stamp_ns <= self._last_stamp_ns:
            back = (self._last_stamp_ns - pair.stamp_ns) / 1e9
            if back > self._settings.time_jump_reset:
                log.info(f'time went back {back:.1f} s: restarting the {self.label}')
                self.restart()
            else:
                log.warn(f'pair at {pair.stamp_ns / 1e9:.3f} s is not newer than the last one '
                         f'({self._last_stamp_ns / 1e9:.3f} s); skipped', throttle_duration_sec=2.0)
                self.skip_pair(pair, Diagnostics.WARN, 'stamps not increasing')
                return
        try:
            left = image_msg_to_gray(pair.left)
            right = image_msg_to_gray(pair.right)
        except ImageFormatError as exc:
            log.error(f'bad image: {exc}; pair skipped', throttle_duration_sec=2.0)
            self.skip_pair(pair, Diagnostics.ERROR, f'bad image: {exc}')
            return
        if left.shape != right.shape:
            log.error(f'left image is {left.shape[1]}x{left.shape[0]} but right is '
                      f'{right.shape[1]}x{right.shape[0]}; pair skipped', throttle_duration_sec=2.0)
            self.skip_pair(pair, Diagnostics.ERROR, 'left and right images differ in size')
            return
        cam = self._camera_for(pair)
        if cam is None:
            self.skip_pair(pair, Diagnostics.WARN, 'no usable camera_info')
            return
        if (cam.height, cam.width) != left.shape:
            log.error(f'images are {left.shape[1]}x{left.shape[0]} but camera_info says '
                      f'{cam.width}x{cam.height}; pair skipped', throttle_duration_sec=2.0)
            self.skip_pair(pair, Diagnostics.ERROR, 'image size differs from camera_info')
            return
        right = align_right_image(right, self._right_offset)
        self.process_pair(pair, left, right, cam)
        self._last_stamp_ns = pair.stamp_ns
        self.frames_done += 1

    def destroy_node(self):
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        if self._worker is not None:
            self._worker.join(timeout=2.0)
        return super().destroy_node()
