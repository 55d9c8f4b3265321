"""The nodes of a replay as processes: start, watch, stop, restart, inject faults."""
from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import threading
import time
from pathlib import Path

from asmonc_vision.faults import PROCESS_KINDS
from asmonc_vision.graph import GraphNode
from asmonc_vision.io import bagio
from asmonc_vision.replay.monitor import Console, Monitor

#: the bag player's log line once it has published the whole bag (`nodes.player_node`)
PLAYED_MARK = ']: published '
#: a node's log line once its subscription of a topic has matched a publisher
#: (`nodes.common.LINKED_LINE`)
LINKED_RE = re.compile(r'\]: input (\S+): \d+ publisher\(s\) matched')


class Child:
    """A node in its own process; its log goes to a file, warnings and errors to stderr."""

    def __init__(self, name: str, cmd: list[str], log_dir: Path, echo, env: dict,
                 echo_warnings: bool = True, done_mark: str | None = None,
                 log_name: str | None = None):
        self.name = name
        self._marks = ('[ERROR]', '[FATAL]', 'Traceback') + (('[WARN]',) if echo_warnings else ())
        #: set when a log line contains ``done_mark`` (the player's end-of-bag line)
        self._done_mark = done_mark
        self.done = threading.Event()
        #: the log lines that contained ``done_mark``
        self.done_lines: list[str] = []
        #: the inputs whose subscription has matched a publisher, as the node logged them
        self.linked: set[str] = set()
        #: halted by `freeze`
        self.frozen = False
        self.log_path = log_dir / f'{log_name or name}.log'
        self._log = self.log_path.open('w')
        self._echo = echo
        # a process group of its own (signalled as a group, no terminal Ctrl-C), in this
        # session: the kernel's autogroup scheduling shares a CPU between sessions first,
        # so a session per node would void the nodes' nice values (GraphNode.nice)
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     env=env, text=True, bufsize=1, process_group=0)
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self._log.write(line)
            self._log.flush()
            if self._done_mark is not None and self._done_mark in line:
                self.done_lines.append(line.rstrip())
                self.done.set()
            if (m := LINKED_RE.search(line)) is not None:
                self.linked.add(m.group(1))
            if any(m in line for m in self._marks):
                self._echo(f'[{self.name}] {line.rstrip()}')
        self._log.flush()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def freeze(self) -> None:
        """Stop the process at once (SIGSTOP: the kernel halts it before its next
        instruction, however loaded the machine), so it publishes nothing more until
        `stop` ends it."""
        if self.alive():
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGSTOP)
                self.frozen = True

    def stop(self, timeout: float = 5.0) -> int:
        if self.alive():
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
                # a halted process (`freeze`, or `replay.end_watch`) acts on the SIGINT
                # once it runs again; a running one ignores SIGCONT
                os.killpg(self.proc.pid, signal.SIGCONT)
                self.proc.wait(timeout=timeout)
            except (subprocess.TimeoutExpired, ProcessLookupError):
                self.proc.kill()
                self.proc.wait()
        self._thread.join(timeout=2.0)
        self._log.close()
        return self.proc.returncode


class GaitStopper(threading.Thread):
    """Stops the gait node once the bag has been played and its last states are out.

    After the whole bag is played the inclinometer goes quiet for good, and the gait
    node would report the end of the replay as a silent sensor ``timeout`` s after its
    last sample. Its last /gait/state follows that sample at once, so the node is stopped
    ``quiet`` s after the newest state (or the end of the replay, if later) -- however late
    the player's end is seen -- or as soon as every inclinometer reading has its state:
    halted (`Child.freeze`), and shut down with the other halted nodes at the end.
    Runs on its own thread, so that stopping other nodes cannot delay it. The fallback of
    `replay.end_watch`, which halts the node on its state for the bag's last reading from
    a process of its own (cancelled then); this thread shares its process with the
    recorder and was seen to act more than 0.75 s late."""

    def __init__(self, child: 'Child', player: 'Child', monitor: 'Monitor', n_imu: int,
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
                # halted at once (a SIGINT may take longer than the node's timeout to act
                # on a loaded machine); `Replay.stop_all` shuts it down last
                self.stopping.set()
                self.child.freeze()
                return

    def cancel(self) -> None:
        self._cancel.set()


class FaultSchedule:
    """The process faults of ``--inject`` (`asmonc_vision.faults`): SIGKILL a node when
    the replay reaches the fault's bag time (the newest camera_info played, counted from
    ``t0``, the bag's first image stamp). Each fault done is kept in ``done`` with the wall
    time (ns) it was done at."""

    def __init__(self, faults, children: dict, monitor: 'Monitor', console: 'Console',
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


def wait_topics(nodes: dict[str, GraphNode], topics: dict) -> list[str]:
    """The player's ``wait_topics``: each bag input topic with its number of readers
    among ``nodes`` ('topic=N'); every stereo node reads both images and both
    camera_infos."""
    stereo = sum(bagio.TOPICS['left_image'][0] in spec.inputs for spec in nodes.values())
    want = {bagio.TOPICS[k][0]: stereo
            for k in ('left_image', 'right_image', 'left_info', 'right_info')}
    if stereo:
        want[bagio.TOPICS['left_info'][0]] += 1      # `Monitor` counts the frames played
    imu = bagio.TOPICS['imu'][0]
    want[imu] = sum(imu in spec.inputs for spec in nodes.values())
    return [f'{t}={n}' for t, n in want.items() if n > 0 and t in topics]


def connected(node, spec: GraphNode, recording: bool, child: Child | None = None,
              produced: frozenset[str] = frozenset()) -> bool:
    """True once `spec`'s node publishes its outputs and subscribes its inputs (and the
    recorder, when recording, subscribes its outputs), and, of its inputs in `produced`
    (the outputs of the graph's other running nodes), `child` has logged each as matched
    to a publisher: seen in the graph is not yet linked between two processes."""
    if child is not None and not {t for t in spec.inputs if t in produced} <= child.linked:
        return False
    for topic in spec.outputs:
        if spec.ros_name not in {i.node_name for i in node.get_publishers_info_by_topic(topic)}:
            return False
        if recording and 'bag_recorder_node' not in {
                i.node_name for i in node.get_subscriptions_info_by_topic(topic)}:
            return False
    return all(spec.ros_name in {i.node_name for i in node.get_subscriptions_info_by_topic(t)}
               for t in spec.inputs)


def pacing(player: 'Child | None', paced: bool) -> dict:
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
