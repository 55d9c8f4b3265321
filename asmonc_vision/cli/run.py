"""Replay a bag through the node graph and tell what the wearer would have heard.

Starts the detector and alarm nodes as separate processes, then the bag player; prints
each alarm as it is given, with a progress bar; records every output topic to a rosbag2
MCAP bag with --out; ends with a summary against the bag's ground truth, if it has any:
true obstacles detected or missed, false obstacles, alarms given.

The bag may be any rosbag2 bag that follows the topic contract (README), not only the
simulator's. Exit status: 0 done; 1 frames dropped, a node failed or the bag ended in
error; 2 the bag or the arguments are unusable.
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np

from asmonc_vision import bagio, graph
from asmonc_vision.faults import MESSAGE_KINDS, PROCESS_KINDS, affected_pairs, parse_faults
from asmonc_vision.graph import GraphNode
from asmonc_vision.core.evaluation import (FrameObstacles, json_ready, path_criteria,
                                          path_warnings, path_warnings_summary, score_sequence)

LEVEL_NAMES = {0: 'CLEAR', 1: 'CAUTION', 2: 'WARNING', 3: 'STOP', 4: 'FAULT'}
#: every topic a node of the graph publishes (recorded with --out)
OUTPUT_TOPICS = ('/obstacles', '/ground_plane', '/obstacles/markers', '/detector/debug_image',
                 '/alarms', '/diagnostics', '/egomotion', '/egomotion/odometry', '/gait/state',
                 '/gait/predicted_motion', '/obstacle_map', '/alarms/contact')


#: the node graph (`asmonc_vision.graph`); a node entry there is started here too
NodeSpec = GraphNode
DEFAULT_BAG_NAME = 'static_obstacles'
#: pairs the player may publish ahead of the detector's /obstacles (unless --realtime)
PACE_LEAD = 3


def default_bag() -> Path:
    """The bundled static-rig bag ($ASMONC_BAGS or the repository's bags/)."""
    root = Path(os.environ.get('ASMONC_BAGS', Path(__file__).resolve().parents[2] / 'bags'))
    return root / DEFAULT_BAG_NAME


def add_arguments(p) -> None:
    p.add_argument('bag', nargs='?', type=Path, default=None,
                   help=f'rosbag2 bag directory or .mcap file (default: bags/{DEFAULT_BAG_NAME})')
    p.add_argument('--out', type=Path, default=None,
                   help='record every output topic to a rosbag2 MCAP bag in this new directory, '
                        'with summary.json and the nodes\' logs beside it')
    p.add_argument('--rate', type=float, default=1.0, help='replay speed factor (default 1)')
    p.add_argument('--realtime', action='store_true',
                   help='replay strictly at the bag\'s rate: a machine too slow for it drops '
                        'pairs, as with a live camera (default: the replay waits while the '
                        f'detector is more than {PACE_LEAD} pairs behind, so every pair is '
                        'processed; the summary says how long it waited)')
    p.add_argument('--params-file', type=Path, action='append', default=[],
                   help='a ros__parameters YAML passed to the nodes (repeatable)')
    p.add_argument('--settle', type=float, default=5.0,
                   help='seconds to wait for the last outputs after the bag ends (default 5)')
    p.add_argument('--match-radius', type=float, default=0.3,
                   help='a detection within this distance (m) of a true obstacle\'s top finds it')
    p.add_argument('--min-height', type=float, default=0.10,
                   help='true obstacles at least this high (m) count in the recall (default 0.10)')
    p.add_argument('--max-range', type=float, default=5.0,
                   help='true obstacles within this range (m) count in the recall (default 5)')
    p.add_argument('--max-restarts', type=int, default=3,
                   help='a node that dies is restarted at most this many times (default 3)')
    p.add_argument('--inject', default='',
                   help='faults at chosen bag times, e.g. "kill=detector@2;stall@3+1.5" '
                        '(docs/robustness.md lists the classes)')
    p.add_argument('--audio', type=Path, default=None, metavar='FILE.wav',
                   help='also run the audio node and write what the wearer would have heard '
                        'to this WAV (stereo, t = 0 the first stereo pair\'s stamp, bag time '
                        'at any --rate), its cue log FILE.cues.json and a PNG timeline '
                        'FILE.png (cues, alarm levels, true obstacles on the path)')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--quiet', action='store_true', help='print only the summary')
    p.set_defaults(func=run)


# --- in-process monitor ------------------------------------------------------------------

class _Monitor:
    """Collects /obstacles and /alarms in this process (an rclpy node in a thread)."""

    def __init__(self, context):
        from rclpy.node import Node

        from asmonc_vision.nodes.common import ALARM_QOS, RESULT_QOS
        from asmonc_vision_msgs.msg import Alarm, GaitState, ObstacleArray

        self.node = Node('asmonc_run_monitor', context=context)
        self.lock = threading.Lock()
        self.detections: dict[int, FrameObstacles] = {}
        #: time.monotonic() of the newest /obstacles (None before the first): when the
        #: alarm node's own silence starts, whatever this process's main loop is doing
        self.last_result_at: float | None = None
        self.alarms: list[dict] = []
        self.new_alarms: list[dict] = []
        self.node.create_subscription(ObstacleArray, '/obstacles', self._on_obstacles, RESULT_QOS)
        self.node.create_subscription(Alarm, '/alarms', self._on_alarm, ALARM_QOS)
        self.gait_states = 0
        self.gait_walking = 0
        #: time.monotonic() of the newest /gait/state (None before the first)
        self.last_gait_at: float | None = None
        self.node.create_subscription(GaitState, '/gait/state', self._on_gait, RESULT_QOS)
        # The left camera_info the player sends with each image: how far the replay is
        # (its own subscription, which the player waits for: `_wait_topics`).
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CameraInfo
        self.infos_played = 0
        #: header stamp of the newest left camera_info played (None before the first)
        self.last_info_stamp_ns: int | None = None
        self.node.create_subscription(CameraInfo, bagio.TOPICS['left_info'][0],
                                      self._on_info, qos_profile_sensor_data)

    def _on_info(self, msg) -> None:
        with self.lock:
            self.infos_played += 1
            self.last_info_stamp_ns = bagio.header_stamp_ns(msg)

    def _on_gait(self, msg) -> None:
        with self.lock:
            self.gait_states += 1
            self.last_gait_at = time.monotonic()
            self.gait_walking += int(bool(msg.walking))

    def _on_obstacles(self, msg) -> None:
        frame = frame_from_obstacle_array(msg)
        with self.lock:
            self.detections[frame.stamp_ns] = frame
            self.last_result_at = time.monotonic()

    def _on_alarm(self, msg) -> None:
        a = {'stamp_ns': msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
             'level': int(msg.level), 'text': msg.text, 'range': float(msg.range),
             'bearing': float(msg.bearing), 'obstacle_id': int(msg.obstacle_id),
             'received_ns': time.time_ns()}
        with self.lock:
            self.alarms.append(a)
            self.new_alarms.append(a)

    def take_new_alarms(self) -> list[dict]:
        with self.lock:
            out, self.new_alarms = self.new_alarms, []
        return out

    @property
    def frames(self) -> int:
        with self.lock:
            return len(self.detections)

    @property
    def played(self) -> int:
        """Left camera_info messages received from the player so far."""
        with self.lock:
            return self.infos_played


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


# --- child processes ----------------------------------------------------------------------

#: the bag player's log line once it has published the whole bag (`nodes.player_node`)
_PLAYED_MARK = ']: published '


class _Child:
    """A node in its own process; its log goes to a file, warnings and errors to stderr."""

    def __init__(self, name: str, cmd: list[str], log_dir: Path, echo, env: dict,
                 echo_warnings: bool = True, done_mark: str | None = None,
                 log_name: str | None = None):
        self.name = name
        self._marks = ('[ERROR]', '[FATAL]', 'Traceback') + (('[WARN]',) if echo_warnings else ())
        #: set when a log line contains ``done_mark`` (the player's end-of-bag line)
        self._done_mark = done_mark
        self.done = threading.Event()
        self.log_path = log_dir / f'{log_name or name}.log'
        self._log = self.log_path.open('w')
        self._echo = echo
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     env=env, text=True, bufsize=1, start_new_session=True)
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self._log.write(line)
            self._log.flush()
            if self._done_mark is not None and self._done_mark in line:
                self.done.set()
            if any(m in line for m in self._marks):
                self._echo(f'[{self.name}] {line.rstrip()}')
        self._log.flush()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, timeout: float = 5.0) -> int:
        if self.alive():
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
                self.proc.wait(timeout=timeout)
            except (subprocess.TimeoutExpired, ProcessLookupError):
                self.proc.kill()
                self.proc.wait()
        self._thread.join(timeout=2.0)
        self._log.close()
        return self.proc.returncode


class _Console:
    """Alarm lines on stdout; a progress bar on stderr (only when it is a terminal)."""

    def __init__(self, total: int, progress: bool, quiet: bool):
        self.total = max(total, 1)
        self.progress = progress and sys.stderr.isatty() and not quiet
        self.quiet = quiet
        self._bar_shown = False

    def _clear(self) -> None:
        if self._bar_shown:
            sys.stderr.write('\r\033[K')
            self._bar_shown = False

    def line(self, text: str, err: bool = False) -> None:
        if self.quiet and not err:
            return
        self._clear()
        print(text, file=sys.stderr if err else sys.stdout, flush=True)

    def bar(self, done: int, note: str = '') -> None:
        if not self.progress:
            return
        width = 30
        k = min(width, int(width * done / self.total))
        sys.stderr.write(f'\r[{"#" * k}{"." * (width - k)}] {done}/{self.total} frames {note}')
        sys.stderr.flush()
        self._bar_shown = True

    def done(self) -> None:
        self._clear()


# --- ground truth ---------------------------------------------------------------------------

def read_truth(bag: Path) -> dict[int, FrameObstacles]:
    """stamp_ns -> true obstacles, from /ground_truth/obstacles (empty if the bag has none).
    Of a truncated bag, the BagError carries those before the cut as ``partial``."""
    topic = bagio.TOPICS['gt_obstacles'][0]
    out: dict[int, FrameObstacles] = {}
    try:
        for _, _, m in bagio.read_messages(bag, [topic]):
            out[bagio.header_stamp_ns(m)] = frame_from_obstacle_array(m)
    except bagio.BagError as exc:
        exc.partial = out
        raise
    return out


def read_out_of_view_truth(bag: Path, truth: dict[int, FrameObstacles]
                           ) -> dict[int, FrameObstacles] | None:
    """stamp_ns -> true obstacles out of view (`core.evaluation.out_of_view_truth`), from
    the bag's /ground_truth/camera_pose and /ground_truth/ground_plane; None when it has
    no poses."""
    from asmonc_vision.cli.bench import plane_from_msg, pose_from_msg
    from asmonc_vision.core.evaluation import out_of_view_truth

    t_pose, t_plane = bagio.TOPICS['gt_camera_pose'][0], bagio.TOPICS['gt_ground_plane'][0]
    poses, planes = {}, {}
    for topic, _, m in bagio.read_messages(bag, [t_pose, t_plane]):
        stamp = bagio.header_stamp_ns(m)
        if topic == t_pose:
            poses[stamp] = pose_from_msg(m)
        else:
            plane = plane_from_msg(m)
            if plane is not None:
                planes[stamp] = plane
    if not poses:
        return None
    return out_of_view_truth(truth, poses, planes)


def first_image_stamp(bag: Path) -> int | None:
    topic = bagio.TOPICS['left_image'][0]
    for _, _, m in bagio.read_messages(bag, [topic]):
        return bagio.header_stamp_ns(m)
    return None


# --- run ----------------------------------------------------------------------------------------

MAX_DOMAIN_ID = 101   # the highest domain id that is portable across DDS vendors
#: The highest domain id a DDS participant can take on Linux (ROS 2 "The ROS_DOMAIN_ID"):
#: a ROS_DOMAIN_ID set above `MAX_DOMAIN_ID` is honoured up to this.
MAX_LINUX_DOMAIN_ID = 232


def domain_search_limit(preferred: int) -> int:
    """The last domain id `claim_domain` tries from ``preferred``: `MAX_DOMAIN_ID`, or
    `MAX_LINUX_DOMAIN_ID` for a preferred id already above the portable range."""
    return MAX_DOMAIN_ID if preferred <= MAX_DOMAIN_ID else MAX_LINUX_DOMAIN_ID


def claim_domain(preferred: int, lock_dir: Path | None = None):
    """Claim a ROS domain id for one `asmonc run`, so that runs started side by side on one
    machine do not hear each other's topics (each would see the other's /obstacles).

    Tries ``preferred``, then the ids above it up to `domain_search_limit`, taking an exclusive
    ``flock`` on ``<lock_dir>/asmonc-run-domain-<id>.lock`` (the system temp dir by
    default); the lock lasts as long as the returned file object is open, and the OS
    releases it if the process dies. Other ROS programs in the domain are not seen: this
    only keeps asmonc runs apart.

    Returns:
        (domain id, open lock file), or (None, None) when every id is taken.
    """
    import fcntl
    lock_dir = Path(lock_dir or tempfile.gettempdir())
    for domain in range(max(0, preferred), domain_search_limit(preferred) + 1):
        f = open(lock_dir / f'asmonc-run-domain-{domain}.lock', 'a')
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        return domain, f
    return None, None


class FaultSchedule:
    """The process faults of ``--inject`` (`asmonc_vision.faults`): SIGKILL a node when
    the replay reaches the fault's bag time (the newest camera_info played, counted from
    ``t0``, the bag's first image stamp). Each fault done is kept in ``done`` with the wall
    time (ns) it was done at."""

    def __init__(self, faults, children: dict, monitor: '_Monitor', console: '_Console',
                 t0: int):
        self.pending = [f for f in faults if f.kind in PROCESS_KINDS]
        self.children, self.monitor, self.console, self.t0 = children, monitor, console, t0
        self.done: list[dict] = []

    def poll(self) -> None:
        with self.monitor.lock:
            stamp = self.monitor.last_info_stamp_ns
        if stamp is None or not self.pending:
            return
        t = (stamp - self.t0) / 1e9
        for f in [f for f in self.pending if f.start <= t]:
            self.pending.remove(f)
            child = self.children.get(f.arg)
            if child is None or not child.alive():
                self.console.line(f'asmonc run: fault {f}: no running node {f.arg!r}', err=True)
                continue
            os.kill(child.proc.pid, signal.SIGKILL)
            self.done.append({'fault': str(f), 'bag_time_s': t, 'wall_ns': time.time_ns()})
            self.console.line(f'asmonc run: fault injected at {t:.2f} s: {f}', err=True)


def run(args) -> int:
    console_err = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    bag = Path(args.bag) if args.bag is not None else default_bag()
    if not (0.01 <= args.rate <= 100):
        console_err(f'asmonc run: --rate must be in [0.01, 100], got {args.rate}')
        return 2
    try:
        topics, damage = bagio.bag_summary(bag)
    except bagio.BagError as exc:
        console_err(f'asmonc run: {exc}')
        return 2
    if damage:
        console_err(f'asmonc run: {damage}; replaying the messages before it')
    left_topic = bagio.TOPICS['left_image'][0]
    imu_topic = bagio.TOPICS['imu'][0]
    n_pairs = topics.get(left_topic, ('', 0))[1]
    n_imu = topics.get(imu_topic, ('', 0))[1]
    inputs = {'images'} if n_pairs else set()
    inputs |= {'imu'} if n_imu else set()
    nodes = {spec.name: spec for spec in graph.nodes_for(
        inputs, requested={'audio'} if args.audio is not None else set())
             if importlib.util.find_spec(spec.module) is not None}
    # the replay is paced by the detector's /obstacles unless --realtime
    paced = 'detector' in nodes and not args.realtime
    if not inputs:
        console_err(f"asmonc run: bag '{bag}' has no {left_topic} messages and no {imu_topic} "
                    f"messages: nothing to do. Topics: {', '.join(sorted(topics)) or 'none'}")
        return 2
    if not nodes:
        console_err(f"asmonc run: bag '{bag}' holds only {', '.join(sorted(inputs))}, and no node "
                    'for that is installed')
        return 2
    try:
        faults = parse_faults(args.inject)
    except ValueError as exc:
        console_err(f'asmonc run: --inject: {exc}')
        return 2
    unknown = [f for f in faults if f.kind in PROCESS_KINDS and f.arg not in nodes]
    if unknown:
        console_err(f'asmonc run: --inject: {unknown[0]}: no node {unknown[0].arg!r} in this '
                    f"run (nodes: {', '.join(nodes)})")
        return 2
    if args.max_restarts < 0:
        console_err('asmonc run: --max-restarts must be >= 0')
        return 2
    if args.out is not None and args.out.exists() and any(args.out.iterdir()):
        console_err(f"asmonc run: --out '{args.out}' exists and is not empty")
        return 2

    try:
        preferred = int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
    except ValueError:
        console_err(f"asmonc run: ROS_DOMAIN_ID must be an integer, got "
                    f"'{os.environ['ROS_DOMAIN_ID']}'")
        return 2
    if not 0 <= preferred <= MAX_LINUX_DOMAIN_ID:
        console_err(f'asmonc run: ROS_DOMAIN_ID must be in [0, {MAX_LINUX_DOMAIN_ID}] '
                    f'(0..{MAX_DOMAIN_ID} is portable across DDS vendors), got {preferred}')
        return 2
    domain, domain_lock = claim_domain(preferred)   # held until this function returns
    if domain is None:
        console_err(f'asmonc run: every ROS domain {preferred}..{domain_search_limit(preferred)} '
                    'is in use by another asmonc run')
        return 2
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    console = _Console(n_pairs or n_imu, not args.no_progress, args.quiet)
    if domain != preferred:
        console.line(f'asmonc run: ROS domain {preferred} is in use by another asmonc run; '
                     f'this one uses domain {domain} (ROS_DOMAIN_ID={domain} to watch it)')
    t0, truth, out_of_view, safety_truth = 0, {}, None, None
    try:
        t0 = first_image_stamp(bag) or 0
        truth = read_truth(bag) if bagio.TOPICS['gt_obstacles'][0] in topics else {}
        if truth and bagio.TOPICS['gt_camera_pose'][0] in topics:
            out_of_view = read_out_of_view_truth(bag, truth)
            from asmonc_vision.eval.truth import truth_from_bag
            safety_truth = truth_from_bag(bag)
    except bagio.BagError as exc:
        truth = getattr(exc, 'partial', truth)
        if not damage:
            console.line(f'asmonc run: {exc} (continuing with what could be read)', err=True)
    console.line(f'asmonc run: {bag} — {n_pairs} stereo pairs, {n_imu} inclinometer readings, '
                 f'at rate {args.rate:g}'
                 + (', with ground truth' if truth else ', no ground truth')
                 + f"; nodes: {', '.join(nodes)}")
    if not n_pairs:
        console.line(f'asmonc run: no stereo images in this bag ({left_topic}): '
                     'running the walk model only')

    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

    log_dir = Path(tempfile.mkdtemp(prefix='asmonc-run-'))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    monitor = _Monitor(ctx)
    recorder = None
    if args.out is not None:
        from rclpy.parameter import Parameter

        from asmonc_vision.nodes.recorder_node import BagRecorderNode
        recorder = BagRecorderNode(context=ctx, parameter_overrides=[
            Parameter('output', value=str(args.out)),
            Parameter('topics', value=list(OUTPUT_TOPICS)),
            Parameter('compression', value='zstd')])
    # The monitor spins on its own thread: the recorder's callbacks (compressing debug
    # images) must not delay the count of finished frames, which decides when the alarm
    # node is stopped -- late, it announces the end of the replay as a FAULT.
    executors = [SingleThreadedExecutor(context=ctx)]
    executors[0].add_node(monitor.node)
    if recorder is not None:
        executors.append(MultiThreadedExecutor(num_threads=2, context=ctx))
        executors[1].add_node(recorder)
    for ex in executors:
        threading.Thread(target=ex.spin, daemon=True).start()

    ros_params = []
    for pf in args.params_file:
        ros_params += ['--params-file', str(pf)]
    children: dict[str, _Child] = {}
    restarts: Counter = Counter()
    failed: list[str] = []
    if damage:
        failed.append(f'bag not read to its end: {damage}')
    player_rc = None
    gait_stopper: _GaitStopper | None = None
    injector: FaultSchedule | None = None
    try:
        def spawn(name: str, log_name: str | None = None) -> _Child:
            cmd = [sys.executable, '-m', nodes[name].module, '--ros-args', *ros_params,
                   *nodes[name].ros_args()]
            if name == 'audio':
                cmd += _audio_params(args, t0)
            # the alarm node's warnings are its alarms, which are printed anyway
            return _Child(name, cmd, log_dir, lambda s: console.line(s, err=True),
                          env, echo_warnings=(name != 'alarm'), log_name=log_name)

        def start(names: list[str]) -> None:
            for name in names:
                children[name] = spawn(name)
            # Wait until they are connected, so no frame is lost to discovery: each node
            # publishes its outputs and subscribes its inputs, and the recorder (if any)
            # has subscribed every output.
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline:
                if all(_connected(monitor.node, nodes[n], recorder is not None) for n in names):
                    return
                dead = [n for n, c in children.items() if not c.alive()]
                if dead:
                    raise RuntimeError(f'{", ".join(dead)} node exited at start; see '
                                       f'{children[dead[0]].log_path}')
                time.sleep(0.1)
            raise RuntimeError('the nodes did not connect within 60 s')

        # The gait and alarm nodes last, in that order: their start-up graces (the
        # alarm's FAULT "not started", the gait node's "inclinometer silent since the
        # node started") run from their own start, and the detector may take seconds to
        # be ready (compiling its kernels on a first run); so may the gait filter (about
        # 15 s on a first run, before its own grace starts), which would use up the
        # alarm's if the two started together.
        start([n for n, spec in nodes.items() if not spec.start_late])
        for name, spec in nodes.items():
            if spec.start_late:
                start([name])

        # The player itself must also see every reader of the bag's inputs (images and
        # their camera_info, the inclinometer) before the first message: a message sent
        # before its subscriber is matched is lost.
        player_cmd = [sys.executable, '-m', 'asmonc_vision.nodes.player_node', '--ros-args',
                      '-p', f'bag:={bag.resolve()}', '-p', f'rate:={float(args.rate)}',
                      '-p', f'wait_topics:={json.dumps(_wait_topics(nodes, topics))}',
                      '-p', 'exit_when_done:=true']
        message_faults = '; '.join(str(f) for f in faults if f.kind in MESSAGE_KINDS)
        if message_faults:
            player_cmd += ['-p', f'faults:={message_faults}']
        if paced:
            # one /obstacles per pair: a slow machine slows the replay, drops nothing
            player_cmd += ['-p', 'pace_topic:=/obstacles',
                           '-p', 'pace_type:=asmonc_vision_msgs/msg/ObstacleArray',
                           '-p', f'pace_image_topic:={left_topic}',
                           '-p', f'pace_lead:={PACE_LEAD}']
        children['player'] = _Child('player', player_cmd, log_dir,
                                    lambda s: console.line(s, err=True), env,
                                    done_mark=_PLAYED_MARK)

        def show_alarms() -> None:
            for a in monitor.take_new_alarms():
                console.line(f'{_bag_time(a["stamp_ns"], t0)}  '
                             f'{LEVEL_NAMES.get(a["level"], a["level"]):8s} {a["text"]}')

        stopped: set[str] = set()
        if 'gait' in children:
            gait_stopper = _GaitStopper(children['gait'], children['player'], monitor, n_imu,
                                        quiet=min(0.25, 0.25 * _gait_timeout(args.params_file)))
            gait_stopper.start()

        def check_nodes() -> None:
            if gait_stopper is not None and gait_stopper.stopping.is_set():
                stopped.add('gait')
            for name in nodes:
                if name in stopped or children[name].alive():
                    continue
                rc = children[name].proc.returncode
                if not nodes[name].respawn or restarts[name] >= args.max_restarts:
                    raise RuntimeError(f'{name} node died (exit status {rc}); see '
                                       f'{children[name].log_path}')
                # Restart it at once: while it is down the alarm node's timeout says FAULT
                # (or, for the alarm node itself, its successor starts with FAULT).
                restarts[name] += 1
                failed.append(f'{name} node died (exit status {rc}) and was restarted')
                console.line(f'asmonc run: {name} node died (exit status {rc}); restarting '
                             f'it ({restarts[name]} of at most {args.max_restarts})', err=True)
                children[name].stop()
                children[name] = spawn(name, f'{name}.restart{restarts[name]}')
                if name == 'gait' and gait_stopper is not None:
                    gait_stopper.child = children[name]

        injector = FaultSchedule(faults, children, monitor, console, t0)

        # Half the alarm node's timeout, counted from the last result this monitor saw
        # (`last_change`: when it arrived, not when this loop noticed it; the loop polls
        # every 20 ms while that stop is pending): the silence the alarm node measures
        # runs from the same /obstacles message, and it must be stopped well before that
        # silence reaches its timeout (stopping it takes a signal and a shutdown).
        # Counted from the end of the replay instead, which comes after the last result
        # when the last pairs give none, it once left 0.3 s, and a FAULT was announced.
        # Counted from when the loop noticed the result, on cold first runs (numba
        # compiling) the loop noticed it up to 0.4 s late, and the alarm node was once
        # stopped 1.03 s into its silence (session 37, 43 runs, no FAULT seen).
        alarm_quiet = 0.5 * _alarm_timeout(args.params_file)
        n_infos = topics.get(bagio.TOPICS['left_info'][0], ('', 0))[1]
        last, last_change = monitor.frames, time.monotonic()
        player_end = played_at = None
        # Until every pair has its result (or, with no cameras, the bag has been played),
        # or the player has ended and nothing more comes.
        while (monitor.frames < n_pairs) if n_pairs else children['player'].alive():
            show_alarms()
            console.bar(monitor.frames)
            injector.poll()
            check_nodes()
            time.sleep(0.02 if played_at is not None and 'alarm' not in stopped else 0.1)
            now = time.monotonic()
            if monitor.frames != last:
                last = monitor.frames
                with monitor.lock:   # when it arrived, not when this loop noticed it
                    last_change = monitor.last_result_at or now
            if player_end is None and not children['player'].alive():
                player_end = now
            # Played: the player said so (its last line, before it waits for the
            # subscribers' acknowledgements and exits), or every camera_info has come
            # back, or the player has ended.
            if played_at is None and (player_end is not None or children['player'].done.is_set()
                                      or (n_infos and monitor.played >= n_infos)):
                played_at = now
            if (played_at is not None and 'alarm' in children and 'alarm' not in stopped
                    and now - last_change > alarm_quiet):
                # Every frame has been played and the results have stopped short of the
                # pairs: some pairs give none (a right image missing from the recording,
                # an image the detector refused). The replay is over: stop the alarm node
                # before its timeout announces the silence as a fault, then wait out
                # --settle for late results (recorded, but no longer alarmed).
                show_alarms()
                children['alarm'].stop()
                stopped.add('alarm')
            if player_end is not None and now - max(last_change, player_end) > args.settle:
                break
        time.sleep(0.1)  # the alarm for the last frame (the alarm node has the frame too)
        show_alarms()
        # The replay is over: stop the alarm node before it reports the silence as a fault.
        if 'alarm' in children:
            children['alarm'].stop()
        show_alarms()
        if gait_stopper is not None:
            gait_stopper.join(timeout=30.0)
        try:
            player_rc = children['player'].proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            failed.append('the player did not finish within 30 s of the last frame')
    except RuntimeError as exc:
        failed.append(str(exc))
    except KeyboardInterrupt:
        failed.append('interrupted')
    finally:
        console.done()
        if gait_stopper is not None:
            gait_stopper.cancel()
            gait_stopper.join(timeout=10.0)
        # Player, then alarm, then detector: the alarm must not outlive the detector
        # and announce the end of the replay as a fault.
        for name in ['player', 'alarm', *children]:
            if name in children:
                children[name].stop()
        for ex in executors:
            ex.shutdown(timeout_sec=2.0)
        if recorder is not None:
            recorder.close()
            recorder.destroy_node()
        monitor.node.destroy_node()
        rclpy.try_shutdown(context=ctx)

    summary = summarise(monitor, truth, n_pairs, args, out_of_view, safety_truth)
    if 'audio' in nodes:
        summary['audio'] = _audio_outputs(args, monitor, t0, truth, bag, console)
    summary['player_exit_code'] = player_rc
    summary['replay'] = _pacing(children.get('player'), paced)
    summary['errors'] = failed
    summary['restarts'] = dict(restarts)
    dropped = summary['dropped_frames']
    if faults:
        summary['faults'] = {'spec': [str(f) for f in faults],
                             'processes': injector.done if injector is not None else []}
        if any(f.kind in MESSAGE_KINDS for f in faults):
            # pairs the faults changed may go without a result: only good ones count
            every, affected = affected_pairs(bag, faults)
            with monitor.lock:
                lost = sorted((every - affected) - set(monitor.detections))
            dropped = len(lost)
            summary['faults'].update(affected_pairs=len(affected),
                                     good_pairs_without_result=len(lost))
    print_summary(summary, console)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'summary.json').write_text(
            json.dumps(json_ready(summary), indent=2, allow_nan=False) + '\n')
        shutil.copytree(log_dir, args.out / 'logs', dirs_exist_ok=True)
        console.line(f'outputs recorded in {args.out}')
    shutil.rmtree(log_dir, ignore_errors=True)
    if failed or dropped or player_rc not in (0, None):
        return 1
    return 0


def _audio_params(args, t0: int) -> list[str]:
    """The audio node's parameters for --audio: its WAV, t = 0 and the replay rate."""
    wav = args.audio.resolve()
    wav.parent.mkdir(parents=True, exist_ok=True)
    return ['-p', f'wav_path:={wav}', '-p', f't0_ns:={int(t0)}',
            '-p', f'rate:={float(args.rate)}',
            '-p', f'latency_path:={wav.with_suffix(".latency.json")}']


def _audio_outputs(args, monitor: '_Monitor', t0: int, truth: dict, bag: Path,
                   console: '_Console') -> dict:
    """After an --audio run: the PNG timeline, and the files written."""
    from asmonc_vision.cli.audio_timeline import write_timeline
    wav = args.audio.resolve()
    out = {'wav': str(wav), 'cues': str(wav.with_suffix('.cues.json')),
           'png': str(wav.with_suffix('.png'))}
    if not wav.exists():
        console.line(f'asmonc run: the audio node wrote no {wav}', err=True)
        return out
    with monitor.lock:
        alarms = list(monitor.alarms)
    write_timeline(wav.with_suffix('.png'), wav.with_suffix('.cues.json'), alarms, t0, truth,
                   _alarm_config(args.params_file), title=f'{bag.name}: what the wearer heard')
    console.line(f'soundtrack: {wav} (timeline {wav.with_suffix(".png")})')
    return out


def _node_param(params_files: list[Path], node: str, name: str, default: float,
                positive: bool = False) -> float:
    """A node's non-negative (``positive``: positive) number parameter ``name``: the last
    of ``params_files`` that sets it for ``node`` (or ``/**``), else ``default``.
    Unreadable files, and other values, are left to the nodes to report."""
    import yaml

    out = default
    for pf in params_files:
        try:
            data = yaml.safe_load(Path(pf).read_text())
        except (OSError, yaml.YAMLError):
            continue
        if not isinstance(data, dict):
            continue
        for key in ('/**', node, '/' + node):
            params = data.get(key)
            params = params.get('ros__parameters') if isinstance(params, dict) else None
            value = params.get(name) if isinstance(params, dict) else None
            if isinstance(value, (int, float)) and not isinstance(value, bool) \
                    and (value > 0 or (value == 0 and not positive)):
                out = float(value)
    return out


def _node_timeout(params_files: list[Path], node: str, default: float) -> float:
    """A node's ``timeout`` parameter (s), as `_node_param` finds it."""
    return _node_param(params_files, node, 'timeout', default, positive=True)


def _alarm_config(params_files: list[Path]):
    """The alarm node's settings that decide which obstacles are on the path
    (`core.evaluation.path_criteria`), from the params files or its defaults; the defaults
    if the files' values do not make a valid `AlarmConfig` (the node reports that)."""
    from asmonc_vision.core.alarm import AlarmConfig
    d = AlarmConfig()
    values = {k: _node_param(params_files, 'alarm_node', k, getattr(d, k))
              for k in ('corridor_half_width', 'min_height', 'stop_range', 'warning_range',
                        'caution_range', 'max_range')}
    try:
        return AlarmConfig(**values)
    except ValueError:
        return d


def _alarm_timeout(params_files: list[Path]) -> float:
    """The alarm node's ``timeout`` (s, FAULT after this long without /obstacles)."""
    from asmonc_vision.core.alarm import AlarmConfig
    return _node_timeout(params_files, 'alarm_node', AlarmConfig().timeout)


def _gait_timeout(params_files: list[Path]) -> float:
    """The gait node's ``timeout`` (s, the inclinometer counts as silent after it)."""
    from asmonc_vision.nodes.gait_node import GaitNodeConfig
    return _node_timeout(params_files, 'gait_filter_node', GaitNodeConfig().timeout)


class _GaitStopper(threading.Thread):
    """Stops the gait node once the bag has been played and its last states are out.

    After the whole bag is played the inclinometer goes quiet for good, and the gait
    node would report the end of the replay as a silent sensor ``timeout`` s after its
    last sample. Its last /gait/state follows that sample at once, so the node is stopped
    ``quiet`` s after the newest state (or the end of the replay, if later) -- however late
    the player's end is seen -- or as soon as every inclinometer reading has its state.
    Runs on its own thread, so that stopping other nodes cannot delay it."""

    def __init__(self, child: '_Child', player: '_Child', monitor: '_Monitor', n_imu: int,
                 quiet: float):
        super().__init__(daemon=True, name='gait-stopper')
        self.child, self.player, self.monitor = child, player, monitor
        self.n_imu, self.quiet = n_imu, quiet
        #: set just before the node is stopped (its end is then not a failure)
        self.stopping = threading.Event()
        self._cancel = threading.Event()

    def run(self) -> None:
        played_at = None
        while not self._cancel.wait(0.02):
            now = time.monotonic()
            if played_at is None:
                if not (self.player.done.is_set() or not self.player.alive()):
                    continue
                played_at = now
            with self.monitor.lock:
                states, last = self.monitor.gait_states, self.monitor.last_gait_at
            if states >= self.n_imu or now - max(played_at, last or played_at) >= self.quiet:
                self.stopping.set()
                self.child.stop()
                return

    def cancel(self) -> None:
        self._cancel.set()


def _wait_topics(nodes: dict[str, NodeSpec], topics: dict) -> list[str]:
    """The player's ``wait_topics``: each bag input topic with its number of readers
    among ``nodes`` ('topic=N'); every stereo node reads both images and both
    camera_infos."""
    stereo = sum(bagio.TOPICS['left_image'][0] in spec.inputs for spec in nodes.values())
    want = {bagio.TOPICS[k][0]: stereo
            for k in ('left_image', 'right_image', 'left_info', 'right_info')}
    if stereo:
        want[bagio.TOPICS['left_info'][0]] += 1      # `_Monitor` counts the frames played
    imu = bagio.TOPICS['imu'][0]
    want[imu] = sum(imu in spec.inputs for spec in nodes.values())
    return [f'{t}={n}' for t, n in want.items() if n > 0 and t in topics]


def _connected(node, spec: NodeSpec, recording: bool) -> bool:
    """True once `spec`'s node publishes its outputs and subscribes its inputs (and the
    recorder, when recording, subscribes its outputs)."""
    for topic in spec.outputs:
        if spec.ros_name not in {i.node_name for i in node.get_publishers_info_by_topic(topic)}:
            return False
        if recording and 'bag_recorder_node' not in {
                i.node_name for i in node.get_subscriptions_info_by_topic(topic)}:
            return False
    return all(spec.ros_name in {i.node_name for i in node.get_subscriptions_info_by_topic(t)}
               for t in spec.inputs)


def _pacing(player: '_Child | None', paced: bool) -> dict:
    """How the replay was timed: 'paced' (held back while the detector was behind) or
    'realtime', with the player's own count of holds (from its log)."""
    from asmonc_vision.nodes.player_node import read_paced_line

    out = {'mode': 'paced' if paced else 'realtime', 'held_back_times': 0,
           'held_back_s': 0.0, 'pairs_given_up': 0}
    try:
        found = read_paced_line(player.log_path.read_text()) if player is not None else None
    except OSError:
        found = None
    if found:
        out.update(held_back_times=found[0], held_back_s=found[1], pairs_given_up=found[2])
    return out


def _bag_time(stamp_ns: int, t0: int) -> str:
    """Seconds into the bag, or '(live)' for alarms stamped by a node's own clock
    (start-up, timeouts), which are not bag times."""
    t = (stamp_ns - t0) / 1e9
    return f'{t:7.1f} s' if t0 and -60.0 < t < 86400.0 else '   (live)'


def summarise(monitor: _Monitor, truth: dict, n_pairs: int, args,
              out_of_view: dict | None = None, safety_truth=None) -> dict:
    """Counts, alarms and the score against ground truth, as a JSON-ready dict.
    ``out_of_view``: stamp_ns -> true obstacles out of view (`read_out_of_view_truth`):
    reports of them are counted as remembered, not false. ``safety_truth``
    (`eval.truth.truth_from_bag`): the recorded /alarms and /obstacles get the safety
    score of EVALUATION.md (`eval.safety`), key ``safety``."""
    with monitor.lock:
        detections = dict(monitor.detections)
        alarms = list(monitor.alarms)
    levels = Counter(LEVEL_NAMES.get(a['level'], str(a['level'])) for a in alarms)
    out = {'bag': str(args.bag or default_bag()), 'rate': args.rate, 'input_pairs': n_pairs,
           'processed_frames': len(detections), 'dropped_frames': max(0, n_pairs - len(detections)),
           'alarms': dict(levels), 'alarm_log': alarms,
           'obstacle_reports': int(sum(len(d) for d in detections.values())),
           'gait_states': monitor.gait_states, 'gait_walking_states': monitor.gait_walking}
    if truth:
        score, missing = score_sequence(detections, truth, remembered=out_of_view,
                                        match_radius=args.match_radius,
                                        min_height=args.min_height, max_range=args.max_range)
        out['ground_truth'] = score.as_dict()
        out['ground_truth']['criteria'] = {'match_radius_m': args.match_radius,
                                           'min_height_m': args.min_height,
                                           'max_range_m': args.max_range}
        out['dropped_frames'] = max(out['dropped_frames'], len(missing))
        cfg = _alarm_config(args.params_file)
        out['path_warnings'] = path_warnings_summary(
            path_warnings(truth, alarms, out_of_view, cfg), path_criteria(cfg))
    if safety_truth is not None:
        from asmonc_vision.eval.safety import score_safety
        out['safety'] = score_safety(safety_truth, alarms, detections).as_dict()
    return out


def path_warning_lines(pw: dict | None) -> list[str]:
    """The summary's lines on `core.evaluation.path_warnings_summary` ``pw``: the counts,
    then each obstacle not warned in time or with unwarned frames (none if ``pw`` is
    None)."""
    if not pw:
        return []
    c = pw['criteria']
    lines = [f"obstacles on the path (within {c['corridor_half_width']:g} m of it, "
             f"{c['warning_range']:g} m ahead, >= {c['min_height'] * 100:.0f} cm): "
             f"{pw['on_path']}; warned in time {pw['warned_in_time']}, late "
             f"{pw['warned_late']}, never {pw['never_warned']}; frames on the path with no "
             f"warning {pw['frames_unwarned']}/{pw['frames_on_path']} "
             f"(FAULT in {pw['frames_fault']})"]
    for o in pw['obstacles']:
        if o['warned_in_time'] and not o['frames_unwarned']:
            continue
        warned = ('never warned' if o['warned_at_m'] is None
                  else f"warned at {o['warned_at_m']:.1f} m")
        lines.append(f"  obstacle {o['id']:>3}: {o['height_m'] * 100:5.1f} cm, on the path "
                     f"from {o['first_on_path_m']:.1f} m to {o['nearest_m']:.1f} m — {warned}, "
                     f"{o['frames_unwarned']}/{o['frames_on_path']} frames without a warning")
    return lines


def print_summary(s: dict, console: _Console) -> None:
    p = lambda t: console.line(t, err=False) if not console.quiet else print(t)  # noqa: E731
    p('')
    p('=== summary ===')
    if s['input_pairs']:
        p(f"frames: {s['processed_frames']} of {s['input_pairs']} processed, "
          f"{s['dropped_frames']} dropped")
        rp = s.get('replay')
        if rp and rp['mode'] == 'paced' and rp['held_back_times']:
            p(f"replay held back {rp['held_back_times']} time(s), {rp['held_back_s']:.1f} s "
              'in all, while the detector was behind'
              + (f"; {rp['pairs_given_up']} pair(s) given no answer" if rp['pairs_given_up']
                 else ''))
    if s['gait_states']:
        p(f"walk model: {s['gait_states']} /gait/state messages, walking in "
          f"{s['gait_walking_states']}")
    alarms = ', '.join(f'{k} {v}' for k, v in sorted(s['alarms'].items())) or 'none'
    p(f'alarms given: {alarms}')
    gt = s.get('ground_truth')
    if gt:
        c = gt['criteria']
        p(f"true obstacles (>= {c['min_height_m'] * 100:.0f} cm high, within "
          f"{c['max_range_m']:g} m; found = a report within {c['match_radius_m']:g} m of it "
          'on the ground):')
        for oid, o in gt['obstacles'].items():
            if o['frames_eligible'] == 0:
                continue
            verdict = 'DETECTED' if o['detected'] else 'MISSED'
            p(f"  obstacle {oid:>3}: {o['height_m'] * 100:5.1f} cm, "
              f"nearest {o['min_range_m']:4.1f} m"
              f" — {verdict} in {o['frames_detected']}/{o['frames_eligible']} frames")
        recall = gt['recall']
        p(f"recall per frame: {gt['detected']}/{gt['eligible']}"
          + (f' = {recall:.1%}' if gt['eligible'] else ''))
        p(f"false obstacles: {gt['false_obstacles']} in {gt['frames']} frames "
          f"({gt['false_per_frame']:.3f} per frame); "
          f"{gt.get('remembered_out_of_view', 0)} more reports of true obstacles out of view "
          f"(remembered, not false)")
        if gt['range_error_median_m'] is not None:
            p(f"median |range error| {gt['range_error_median_m']:.3f} m, "
              f"median |bearing error| {gt['bearing_error_median_deg']:.2f} deg")
        for line in path_warning_lines(s.get('path_warnings')):
            p(line)
        if s.get('safety'):
            from asmonc_vision.eval.safety import format_safety
            p('safety (EVALUATION.md):')
            for line in format_safety(s['safety'], '  '):
                p(line)
    else:
        p('no ground truth in this bag: no score')
    f = s.get('faults')
    if f:
        p(f"faults injected: {'; '.join(f['spec'])}"
          + (f"; {f['affected_pairs']} pair(s) changed or left out, good pairs without a "
             f"result: {f['good_pairs_without_result']}" if 'affected_pairs' in f else ''))
    for e in s.get('errors', []):
        p(f'error: {e}')
