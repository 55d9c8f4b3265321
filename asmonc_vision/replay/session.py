"""One replay of a bag through the node graph (`asmonc run`): the steps in order.

1. `plan_replay` checks the bag and the arguments and chooses the nodes;
2. `claim_run_domain` takes a ROS domain of its own;
3. `read_truths` reads the bag's ground truth, if any;
4. `Replay` starts the monitor (and the recorder), the nodes and the player, watches
   them until every pair has its result, and stops them in order;
5. `Replay.summary` scores the run; `replay` prints it and writes the outputs.
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from asmonc_vision import graph
from asmonc_vision.eval.evaluation import json_ready
from asmonc_vision.faults import (MESSAGE_KINDS, PROCESS_KINDS, STEREO, affected_pairs,
                                  changed_stamps, parse_faults)
from asmonc_vision.graph import GraphNode
from asmonc_vision.io import bagio
from asmonc_vision.io.bagplay import BagSource
from asmonc_vision.replay.children import (PLAYED_MARK, Child, FaultSchedule, GaitStopper,
                                           connected, pacing, wait_topics)
from asmonc_vision.replay.domain import MAX_DOMAIN_ID, MAX_LINUX_DOMAIN_ID, claim_domain, \
    domain_search_limit
from asmonc_vision.replay.end_watch import HALTED_MARK
from asmonc_vision.replay.monitor import Console, Monitor
from asmonc_vision.replay.params import (LEVEL_NAMES, OUTPUT_TOPICS, PACE_LEAD, alarm_timeout,
                                         audio_params, default_bag, gait_timeout)
from asmonc_vision.replay.summary import (audio_outputs, bag_time, first_image_stamp,
                                          print_summary, read_out_of_view_truth, read_truth,
                                          summarise)


#: seconds the nodes of a replay have to start and connect
CONNECT_TIMEOUT = 120.0
#: seconds between the alarm node's answer to the last pair and its halt (its alarm for
#: that pair was published just before the answer, on another topic): `end_watch --grace`
ANSWER_GRACE = 0.05
#: the topics on which `replay.end_watch` hears a node's answer to its last input, and
#: the node
END_WATCHED = {'/alarms/contact': 'alarm', '/gait/state': 'gait'}
#: seconds the started player waits for every node's side of the links from it
LINK_TIMEOUT = 30.0
#: seconds the player's ~/resume service has to answer
RESUME_TIMEOUT = 10.0
#: an unanswered ~/resume is sent again after this long, seconds
RESUME_RETRY = 1.0
#: seconds after the player's last line (and the last result) within which it exits: it
#: waits at most `player_node.ACK_TIMEOUT` (4 s) for its subscribers' acknowledgements
PLAYER_EXIT_GRACE = 10.0


def _err(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


@dataclass
class ReplayPlan:
    """What a replay will do: the bag, what it holds, the nodes, the faults."""

    bag: Path
    topics: dict
    damage: str | None
    n_pairs: int
    n_imu: int
    nodes: dict[str, GraphNode]
    paced: bool
    faults: list
    #: header stamp (ns) of the last stereo pair the bag plays whole that no injected
    #: fault changes or leaves out: once the alarm node has answered it, nothing is
    #: left to answer (None: not known, as in a damaged bag)
    last_pair: int | None = None
    #: the same for the last inclinometer reading and the walk model's node
    last_imu: int | None = None


def plan_replay(args) -> ReplayPlan | int:
    """The plan of a replay, or exit status 2 (said why on stderr)."""
    bag = Path(args.bag) if args.bag is not None else default_bag()
    if not (0.01 <= args.rate <= 100):
        _err(f'asmonc run: --rate must be in [0.01, 100], got {args.rate}')
        return 2
    try:
        topics, damage = bagio.bag_summary(bag)
    except bagio.BagError as exc:
        _err(f'asmonc run: {exc}')
        return 2
    if damage:
        _err(f'asmonc run: {damage}; replaying the messages before it')
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
        _err(f"asmonc run: bag '{bag}' has no {left_topic} messages and no {imu_topic} "
             f"messages: nothing to do. Topics: {', '.join(sorted(topics)) or 'none'}")
        return 2
    if not nodes:
        _err(f"asmonc run: bag '{bag}' holds only {', '.join(sorted(inputs))}, and no node "
             'for that is installed')
        return 2
    faults = _faults(args, nodes)
    if isinstance(faults, int):
        return faults
    if args.out is not None and args.out.exists() and any(args.out.iterdir()):
        _err(f"asmonc run: --out '{args.out}' exists and is not empty")
        return 2
    last_pair, last_imu = (None, None) if damage else _last_inputs(bag, faults)
    return ReplayPlan(bag, topics, damage, n_pairs, n_imu, nodes, paced, faults,
                      last_pair, last_imu)


def _last_inputs(bag: Path, faults: list) -> tuple[int | None, int | None]:
    """The stamps (ns) of the last stereo pair the bag plays whole (`bagio.whole_pairs`)
    and of its last inclinometer reading, each the last in the bag's order that no
    message fault of ``faults`` changes or leaves out; None where none is known. The
    last played, not the newest stamp: a recording whose clock jumped back holds a
    newer stamp before its end."""
    left, right, imu = (bagio.TOPICS[k][0] for k in ('left_image', 'right_image', 'imu'))
    stamps = bagio.header_stamps(bag, (left, right, imu))         # one read of the bag
    if stamps is None:
        return None, None
    pairs, readings = bagio.whole_pairs(stamps), stamps[imu]
    if any(f.kind in MESSAGE_KINDS for f in faults):
        changed = changed_stamps(BagSource(bag), faults, (*STEREO, imu))
        affected = set().union(*(changed[t] for t in STEREO))
        pairs = [s for s in pairs if s not in affected]
        readings = [s for s in readings if s not in changed[imu]]
    return (pairs[-1] if pairs else None), (readings[-1] if readings else None)


def _faults(args, nodes: dict) -> list | int:
    """The faults of --inject, or exit status 2; also checks --max-restarts."""
    try:
        faults = parse_faults(args.inject)
    except ValueError as exc:
        _err(f'asmonc run: --inject: {exc}')
        return 2
    unknown = [f for f in faults if f.kind in PROCESS_KINDS and f.arg not in nodes]
    if unknown:
        _err(f'asmonc run: --inject: {unknown[0]}: no node {unknown[0].arg!r} in this '
             f"run (nodes: {', '.join(nodes)})")
        return 2
    if args.max_restarts < 0:
        _err('asmonc run: --max-restarts must be >= 0')
        return 2
    return faults


def claim_run_domain():
    """(preferred ROS domain id, claimed id, open lock file) for this run, with
    ROS_DOMAIN_ID set to the claimed one; or exit status 2 (said why on stderr)."""
    try:
        preferred = int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
    except ValueError:
        _err(f"asmonc run: ROS_DOMAIN_ID must be an integer, got "
             f"'{os.environ['ROS_DOMAIN_ID']}'")
        return 2
    if not 0 <= preferred <= MAX_LINUX_DOMAIN_ID:
        _err(f'asmonc run: ROS_DOMAIN_ID must be in [0, {MAX_LINUX_DOMAIN_ID}] '
             f'(0..{MAX_DOMAIN_ID} is portable across DDS vendors), got {preferred}')
        return 2
    domain, domain_lock = claim_domain(preferred)
    if domain is None:
        _err(f'asmonc run: every ROS domain {preferred}..{domain_search_limit(preferred)} '
             'is in use by another asmonc run')
        return 2
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    return preferred, domain, domain_lock


def read_truths(plan: ReplayPlan, console: Console):
    """(first image stamp, true obstacles per stamp, those out of view or None, the
    safety truth or None) of the bag; what a damaged bag allows."""
    t0, truth, out_of_view, safety_truth = 0, {}, None, None
    try:
        t0 = first_image_stamp(plan.bag) or 0
        truth = read_truth(plan.bag) if bagio.TOPICS['gt_obstacles'][0] in plan.topics else {}
        if truth and bagio.TOPICS['gt_camera_pose'][0] in plan.topics:
            out_of_view = read_out_of_view_truth(plan.bag, truth)
            from asmonc_vision.eval.truth import truth_from_bag
            safety_truth = truth_from_bag(plan.bag)
    except bagio.BagError as exc:
        truth = getattr(exc, 'partial', truth)
        if not plan.damage:
            console.line(f'asmonc run: {exc} (continuing with what could be read)', err=True)
    return t0, truth, out_of_view, safety_truth


class Replay:
    """The nodes of one replay as processes, watched from an in-process monitor."""

    def __init__(self, args, plan: ReplayPlan, console: Console, env: dict, t0: int):
        self.args, self.plan, self.console, self.env, self.t0 = args, plan, console, env, t0
        self.nodes = plan.nodes
        self.log_dir = Path(tempfile.mkdtemp(prefix='asmonc-run-'))
        self.ros_params: list[str] = []
        for pf in args.params_file:
            self.ros_params += ['--params-file', str(pf)]
        self.children: dict[str, Child] = {}
        self.restarts: Counter = Counter()
        self.failed: list[str] = []
        if plan.damage:
            self.failed.append(f'bag not read to its end: {plan.damage}')
        self.player_rc = None
        self.gait_stopper: GaitStopper | None = None
        self.injector: FaultSchedule | None = None
        self.stopped: set[str] = set()
        #: the player played the whole bag and then did not exit (`PLAYER_EXIT_GRACE`)
        self.player_hung = False
        #: the process that halts the alarm and gait nodes once each has answered the
        #: last input the bag plays it (`replay.end_watch`; None without one)
        self.end_watch: Child | None = None
        #: the topics it watches, and their nodes
        self.end_watched: dict[str, str] = {}
        #: the monitor's and the recorder's spinning threads (`start_ros`)
        self.spinners: list = []
        self.recorder = None

    # --- ROS side -------------------------------------------------------------------

    def start_ros(self) -> None:
        """The monitor (and, with --out, the recorder) on their own spinning threads."""
        import rclpy
        from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

        from asmonc_vision.replay.spin import SpinThread

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.monitor = Monitor(self.ctx)
        self.recorder = None
        if self.args.out is not None:
            from rclpy.parameter import Parameter

            from asmonc_vision.nodes.recorder_node import BagRecorderNode
            self.recorder = BagRecorderNode(context=self.ctx, parameter_overrides=[
                Parameter('output', value=str(self.args.out)),
                Parameter('topics', value=list(OUTPUT_TOPICS)),
                Parameter('compression', value='zstd')])
        # The monitor spins on its own thread: the recorder's callbacks (compressing debug
        # images) must not delay the count of finished frames, which decides when the alarm
        # node is stopped -- late, it announces the end of the replay as a FAULT.
        monitor_ex = SingleThreadedExecutor(context=self.ctx)
        monitor_ex.add_node(self.monitor.node)
        self.spinners = [SpinThread(monitor_ex, 'monitor')]
        if self.recorder is not None:
            recorder_ex = MultiThreadedExecutor(num_threads=2, context=self.ctx)
            recorder_ex.add_node(self.recorder)
            self.spinners.append(SpinThread(recorder_ex, 'recorder'))

    def stop_ros(self) -> None:
        import rclpy

        # the threads stop before any node is destroyed (`replay.spin`)
        stopped = all([sp.stop() for sp in self.spinners])
        if self.recorder is not None:
            self.recorder.close()  # under the recorder's lock: safe beside a late callback
        if not stopped:
            self.console.line('asmonc run: a spinning thread did not stop; its nodes are '
                              'left to the end of the process', err=True)
            return
        if self.recorder is not None:
            self.recorder.destroy_node()
        self.monitor.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)

    # --- the nodes ------------------------------------------------------------------

    def spawn(self, name: str, log_name: str | None = None) -> Child:
        node = self.nodes[name]
        cmd = [*node.command_prefix(), sys.executable, '-m', node.module, '--ros-args',
               *self.ros_params, *node.ros_args()]
        if name == 'audio':
            cmd += audio_params(self.args, self.t0)
        # the alarm node's warnings are its alarms, which are printed anyway
        return Child(name, cmd, self.log_dir, lambda s: self.console.line(s, err=True),
                     self.env, echo_warnings=(name != 'alarm'), log_name=log_name)

    def start(self, names: list[str], then=None) -> None:
        """Start the nodes `names` and wait until they are connected; `then()`, if given,
        is called once they are spawned, before the wait."""
        for name in names:
            self.children[name] = self.spawn(name)
        if then is not None:
            then()
        # Wait until they are connected, so no frame is lost to discovery: each node
        # publishes its outputs and subscribes its inputs, and the recorder (if any)
        # has subscribed every output.
        # (a first start compiles the numba kernels before subscribing: 20-60 s on a
        # loaded 2-core machine with a cold cache)
        deadline = time.monotonic() + CONNECT_TIMEOUT
        while time.monotonic() < deadline:
            if all(connected(self.monitor.node, self.nodes[n], self.recorder is not None,
                             self.children[n], self._produced(n)) for n in names):
                return
            dead = [n for n, c in self.children.items() if not c.alive()]
            if dead:
                raise RuntimeError(f'{", ".join(dead)} node exited at start; see '
                                   f'{self.children[dead[0]].log_path}')
            time.sleep(0.1)
        raise RuntimeError(f'the nodes did not connect within {CONNECT_TIMEOUT:g} s')

    def _produced(self, name: str) -> frozenset[str]:
        """The topics published by the running nodes other than `name`."""
        return frozenset(t for n in self.children if n != name and n in self.nodes
                         for t in self.nodes[n].outputs)

    def start_nodes(self) -> None:
        """The graph's nodes, the player (paused) and the end watch, all connected.

        The gait and alarm nodes last, in that order: their start-up graces (the alarm's
        FAULT "not started", the gait node's "inclinometer silent since the node
        started") run from their own start, and the detector may take seconds to be
        ready (compiling its kernels on a first run); so may the gait filter (about 15 s
        on a first run, before its own grace starts), which would use up the alarm's if
        the two started together. The player starts paused while the late nodes start,
        and the end watch once they are spawned (it needs their process ids): each
        takes a second or two to start, and neither sends anything before
        `release_player`."""
        self.start([n for n, spec in self.nodes.items() if not spec.start_late])
        late = [n for n, spec in self.nodes.items() if spec.start_late]
        self.spawn_player()
        for i, name in enumerate(late):
            self.start([name], then=self.start_end_watch if i == len(late) - 1 else None)
        if not late:
            self.start_end_watch()

    def spawn_player(self) -> None:
        """The bag player, paused: `start_player` lets it play. It must also see every
        reader of the bag's inputs (images and their camera_info, the inclinometer)
        before the first message: a message sent before its subscriber is matched is
        lost."""
        plan, args = self.plan, self.args
        # It starts paused: `release_player` lets it play once the readers have matched.
        player_cmd = [sys.executable, '-m', 'asmonc_vision.nodes.player_node', '--ros-args',
                      '-p', f'bag:={plan.bag.resolve()}', '-p', f'rate:={float(args.rate)}',
                      '-p', f'wait_topics:={json.dumps(wait_topics(self.nodes, plan.topics))}',
                      '-p', 'start_paused:=true', '-p', 'exit_when_done:=true']
        message_faults = '; '.join(str(f) for f in plan.faults if f.kind in MESSAGE_KINDS)
        if message_faults:
            player_cmd += ['-p', f'faults:={message_faults}']
        if plan.paced:
            # one /obstacles per pair: a slow machine slows the replay, drops nothing
            player_cmd += ['-p', 'pace_topic:=/obstacles',
                           '-p', 'pace_type:=asmonc_vision_msgs/msg/ObstacleArray',
                           '-p', f'pace_image_topic:={bagio.TOPICS["left_image"][0]}',
                           '-p', f'pace_lead:={PACE_LEAD}']
        self.children['player'] = Child('player', player_cmd, self.log_dir,
                                        lambda s: self.console.line(s, err=True), self.env,
                                        done_mark=PLAYED_MARK)

    def start_player(self) -> None:
        """Once every node is connected: the watchers of the replay, then the player
        released (`release_player`)."""
        plan, args = self.plan, self.args
        if 'gait' in self.children:
            self.gait_stopper = GaitStopper(
                self.children['gait'], self.children['player'], self.monitor, plan.n_imu,
                quiet=min(0.25, 0.25 * gait_timeout(args.params_file)))
            self.gait_stopper.start()
        self.injector = FaultSchedule(plan.faults, self.children, self.monitor, self.console,
                                      self.t0)
        self.release_player()

    def _fed(self) -> dict[str, set[str]]:
        """Per running node, its inputs that the bag feeds (none of the graph's nodes
        publishes them, and the bag holds them, as images or compressed)."""
        produced = {t for spec in self.nodes.values() for t in spec.outputs}
        return {n: {t for t in self.nodes[n].inputs if t not in produced
                    and (t in self.plan.topics or t + '/compressed' in self.plan.topics)}
                for n in self.nodes if n in self.children}

    def release_player(self) -> None:
        """Let the paused player play once every node has logged the link of each input
        the bag feeds it (`nodes.common.watch_input_links`). The player's own wait sees
        its side of each link only; a reader's side can match a second or more later on
        a loaded machine, and a best-effort reader (the walk model's inclinometer) drops
        every message sent before. After LINK_TIMEOUT the replay plays anyway, saying
        which links were missing."""
        from std_srvs.srv import Trigger

        player = self.children['player']
        readers = {n: (self.children[n], want) for n, want in self._fed().items()}
        if self.end_watch is not None:
            readers['end_watch'] = (self.end_watch, set(self.end_watched))
        deadline = time.monotonic() + LINK_TIMEOUT
        missing: dict[str, set[str]] = {}
        while time.monotonic() < deadline and player.alive():
            missing = {n: m for n, (child, want) in readers.items()
                       if (m := want - child.linked)}
            if not missing:
                break
            time.sleep(0.05)
        if missing:
            self.console.line('asmonc run: playing before these inputs were linked: '
                              + '; '.join(f'{n} {", ".join(sorted(m))}'
                                          for n, m in sorted(missing.items())), err=True)
        client = self.monitor.node.create_client(Trigger, '/bag_player_node/resume')
        deadline = time.monotonic() + RESUME_TIMEOUT
        future, sent = None, 0.0
        try:
            # the service offered, then answered; a player that dies has said why in its
            # log, and the replay ends. A request sent the moment the service is seen can
            # be served before the player's reply has matched this client, and its answer
            # is then lost: unanswered, it is sent again (a second ~/resume is harmless).
            while future is None or not future.done():
                if not player.alive():
                    return
                if time.monotonic() > deadline:
                    raise RuntimeError('the bag player did not answer ~/resume within '
                                       f'{RESUME_TIMEOUT:g} s')
                if future is not None and time.monotonic() - sent > RESUME_RETRY:
                    client.remove_pending_request(future)
                    future = None
                if future is None and client.wait_for_service(timeout_sec=0.1):
                    future, sent = client.call_async(Trigger.Request()), time.monotonic()
                elif future is not None:
                    time.sleep(0.02)
        finally:
            self.monitor.node.destroy_client(client)

    def show_alarms(self) -> None:
        for a in self.monitor.take_new_alarms():
            self.console.line(f'{bag_time(a["stamp_ns"], self.t0)}  '
                              f'{LEVEL_NAMES.get(a["level"], a["level"]):8s} {a["text"]}')

    def check_nodes(self) -> None:
        """Restart a dead node that may be restarted; RuntimeError for one that may not."""
        if self.gait_stopper is not None and self.gait_stopper.stopping.is_set():
            self.stopped.add('gait')
        for name in self.nodes:
            if name in self.stopped or self.children[name].alive():
                continue
            rc = self.children[name].proc.returncode
            if not self.nodes[name].respawn or self.restarts[name] >= self.args.max_restarts:
                raise RuntimeError(f'{name} node died (exit status {rc}); see '
                                   f'{self.children[name].log_path}')
            # Restart it at once: while it is down the alarm node's timeout says FAULT
            # (or, for the alarm node itself, its successor starts with FAULT).
            self.restarts[name] += 1
            self.failed.append(f'{name} node died (exit status {rc}) and was restarted')
            self.console.line(f'asmonc run: {name} node died (exit status {rc}); restarting '
                              f'it ({self.restarts[name]} of at most {self.args.max_restarts})',
                              err=True)
            self.children[name].stop()
            self.children[name] = self.spawn(name, f'{name}.restart{self.restarts[name]}')
            if name == 'gait' and self.gait_stopper is not None:
                self.gait_stopper.child = self.children[name]
            if name in END_WATCHED.values() and self.end_watch is not None:
                self.end_watch.stop()
                self.start_end_watch()

    def wait_for_results(self) -> None:
        """Until every pair has its result (or, with no cameras, the bag has been played),
        or the player has ended and nothing more has come for --settle seconds."""
        monitor, player, n_pairs = self.monitor, self.children['player'], self.plan.n_pairs
        # Half the alarm node's timeout, counted from the last result this monitor saw
        # (`last_change`: when it arrived, not when this loop noticed it; the loop polls
        # every 20 ms while that stop is pending): the silence the alarm node measures
        # runs from the same /obstacles message, and it must be stopped well before that
        # silence reaches its timeout (stopping it takes a signal and a shutdown).
        # Counted from the end of the replay instead, which comes after the last result
        # when the last pairs give none, too little of the timeout may be left; counted
        # from when the loop noticed the result, a loop late on a cold first run (numba
        # compiling) may stop the alarm node too late.
        alarm_quiet = 0.5 * alarm_timeout(self.args.params_file)
        n_infos = self.plan.topics.get(bagio.TOPICS['left_info'][0], ('', 0))[1]
        last, last_change = monitor.frames, time.monotonic()
        player_end = played_at = None
        while (monitor.frames < n_pairs) if n_pairs else player.alive():
            self.show_alarms()
            self.console.bar(monitor.frames)
            self.injector.poll()
            self.check_nodes()
            self.note_end_watch()
            time.sleep(0.02 if played_at is not None and 'alarm' not in self.stopped else 0.1)
            now = time.monotonic()
            if monitor.frames != last:
                last = monitor.frames
                with monitor.lock:   # when it arrived, not when this loop noticed it
                    last_change = monitor.last_result_at or now
            if player_end is None and not player.alive():
                player_end = now
            if (player_end is None and player.done.is_set() and played_at is not None
                    and now - max(last_change, played_at) > PLAYER_EXIT_GRACE):
                # It said it played every message and has not exited: go on without it
                # (stopped with the others) rather than wait for a process that hangs.
                self.console.line(f'asmonc run: the player played the whole bag but had not '
                                  f'exited {PLAYER_EXIT_GRACE:g} s later; stopping it', err=True)
                self.player_hung = True
                player_end = now
            # Played: the player said so (its last line, before it waits for the
            # subscribers' acknowledgements and exits), or every camera_info has come
            # back, or the player has ended.
            if played_at is None and (player_end is not None or player.done.is_set()
                                      or (n_infos and monitor.played >= n_infos)):
                played_at = now
            if (played_at is not None and 'alarm' in self.children
                    and 'alarm' not in self.stopped and now - last_change > alarm_quiet):
                # Every frame has been played and the results have stopped short of the
                # pairs: some pairs give none (a right image missing from the recording,
                # an image the detector refused). The replay is over: stop the alarm node
                # before its timeout announces the silence as a fault, then wait out
                # --settle for late results (recorded, but no longer alarmed).
                self.show_alarms()
                self.stand_down_alarm()
            if player_end is not None and now - max(last_change, player_end) > self.args.settle:
                break

    def finish(self) -> None:
        """After the last result: the alarm node stopped, the gait node and player ended."""
        time.sleep(0.1)  # the alarm for the last frame (the alarm node has the frame too)
        self.show_alarms()
        # The replay is over: halt the alarm node before it reports the silence as a fault.
        self.stand_down_alarm()
        self.show_alarms()
        if self.gait_stopper is not None:
            self.gait_stopper.join(timeout=30.0)
        if self.player_hung:
            self.children['player'].stop()
            return
        try:
            self.player_rc = self.children['player'].proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.failed.append('the player did not finish within 30 s of the last frame')

    def start_end_watch(self) -> None:
        """Start `replay.end_watch`: it halts the alarm node ANSWER_GRACE s after that node
        has answered the last pair the bag plays whole, and the walk model's node after
        its state for the last inclinometer reading, from a process of its own (the end
        of the replay known, not guessed from a silence, and acted on at once however
        busy this process is). Where that input gives no answer (refused), the guesses
        stay (`wait_for_results`, `GaitStopper`)."""
        last = {'alarm': self.plan.last_pair, 'gait': self.plan.last_imu}
        self.end_watched = {topic: name for topic, name in END_WATCHED.items()
                            if last[name] is not None and name in self.children
                            and name not in self.stopped}
        if not self.end_watched:
            self.end_watch = None
            return
        cmd = [sys.executable, '-m', 'asmonc_vision.replay.end_watch',
               '--grace', str(ANSWER_GRACE)]
        for topic, name in self.end_watched.items():
            cmd += ['--watch', topic, str(last[name]), str(self.children[name].proc.pid)]
        self.end_watch = Child('end_watch', cmd, self.log_dir,
                               lambda s: self.console.line(s, err=True), self.env,
                               done_mark=HALTED_MARK)

    def note_end_watch(self) -> None:
        """Take note of the nodes `replay.end_watch` has halted."""
        if self.end_watch is None or not self.end_watch.done.is_set():
            return
        for line in list(self.end_watch.done_lines):
            name = self.end_watched.get(line.rsplit(' ', 1)[-1])
            if name is not None and name not in self.stopped:
                self.children[name].frozen = True
                self.stopped.add(name)
                if name == 'gait' and self.gait_stopper is not None:
                    self.gait_stopper.cancel()

    def stand_down_alarm(self) -> None:
        """The replay is over: halt the alarm node at once (`Child.freeze`), before its
        timeout announces the end of the input as a fault. A signal to shut down would
        race that timeout: on a loaded 2-core machine a node has been seen to take 0.2 s
        or more to act on SIGINT, half the default timeout. It is shut down in
        `stop_all`, once nothing records or plays what it might still say."""
        self.note_end_watch()
        if 'alarm' in self.children and 'alarm' not in self.stopped:
            self.children['alarm'].freeze()
            self.stopped.add('alarm')

    def stop_all(self) -> None:
        self.console.done()
        if self.end_watch is not None:
            self.end_watch.stop()
            self.note_end_watch()
        if self.gait_stopper is not None:
            self.gait_stopper.cancel()
            self.gait_stopper.join(timeout=10.0)
        # Player, then alarm, then detector: the alarm must not outlive the detector
        # and announce the end of the replay as a fault. Halted nodes (the alarm and gait
        # nodes at the end) go last, after the recorder has closed its bag and the audio
        # node has stopped.
        halted = [c for c in self.children.values() if c.frozen]
        for name in ['player', 'alarm', *self.children]:
            if name in self.children and self.children[name] not in halted:
                self.children[name].stop()
        self.stop_ros()
        for child in halted:
            child.stop()

    def play(self) -> None:
        """The whole replay, from the monitor's start to the last node's stop."""
        self.start_ros()
        try:
            self.start_nodes()
            self.start_player()
            self.wait_for_results()
            self.finish()
        except RuntimeError as exc:
            self.failed.append(str(exc))
        except KeyboardInterrupt:
            self.failed.append('interrupted')
        finally:
            self.stop_all()

    # --- the outcome ----------------------------------------------------------------

    def summary(self, truth: dict, out_of_view, safety_truth) -> tuple[dict, int]:
        """(the summary, the frames dropped among the pairs that should have a result)."""
        plan, monitor = self.plan, self.monitor
        summary = summarise(monitor, truth, plan.n_pairs, self.args, out_of_view,
                            safety_truth)
        if 'audio' in self.nodes:
            summary['audio'] = audio_outputs(self.args, monitor, self.t0, truth, plan.bag,
                                             self.console)
        summary['player_exit_code'] = self.player_rc
        summary['replay'] = pacing(self.children.get('player'), plan.paced)
        summary['errors'] = self.failed
        summary['restarts'] = dict(self.restarts)
        dropped = summary['dropped_frames']
        if plan.faults:
            summary['faults'] = {'spec': [str(f) for f in plan.faults],
                                 'processes': self.injector.done if self.injector else []}
            if any(f.kind in MESSAGE_KINDS for f in plan.faults):
                # pairs the faults changed may go without a result: only good ones count
                every, affected = affected_pairs(BagSource(plan.bag), plan.faults)
                with monitor.lock:
                    lost = sorted((every - affected) - set(monitor.detections))
                dropped = len(lost)
                summary['faults'].update(affected_pairs=len(affected),
                                         good_pairs_without_result=len(lost))
        return summary, dropped


def replay(args) -> int:
    """`asmonc run` with its parsed arguments (see `cli.run`); the exit status: 0 done,
    1 frames dropped, a node failed or the bag ended in error, 2 unusable bag or
    arguments."""
    plan = plan_replay(args)
    if isinstance(plan, int):
        return plan
    claimed = claim_run_domain()
    if isinstance(claimed, int):
        return claimed
    preferred, domain, _domain_lock = claimed   # the lock is held until this returns
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    console = Console(plan.n_pairs or plan.n_imu, not args.no_progress, args.quiet)
    if domain != preferred:
        console.line(f'asmonc run: ROS domain {preferred} is in use by another asmonc run; '
                     f'this one uses domain {domain} (ROS_DOMAIN_ID={domain} to watch it)')
    t0, truth, out_of_view, safety_truth = read_truths(plan, console)
    console.line(f'asmonc run: {plan.bag} — {plan.n_pairs} stereo pairs, {plan.n_imu} '
                 f'inclinometer readings, at rate {args.rate:g}'
                 + (', with ground truth' if truth else ', no ground truth')
                 + f"; nodes: {', '.join(plan.nodes)}")
    if not plan.n_pairs:
        console.line(f"asmonc run: no stereo images in this bag ({bagio.TOPICS['left_image'][0]}"
                     '): running the walk model only')
    run = Replay(args, plan, console, env, t0)
    run.play()
    summary, dropped = run.summary(truth, out_of_view, safety_truth)
    print_summary(summary, console)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'summary.json').write_text(
            json.dumps(json_ready(summary), indent=2, allow_nan=False) + '\n')
        shutil.copytree(run.log_dir, args.out / 'logs', dirs_exist_ok=True)
        console.line(f'outputs recorded in {args.out}')
    shutil.rmtree(run.log_dir, ignore_errors=True)
    if run.failed or dropped or run.player_rc not in (0, None):
        return 1
    return 0
