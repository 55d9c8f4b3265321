"""A soak: the whole node graph fed by a bag played in a loop for a long time, watched for
growth of each process's memory (RSS) and open file descriptors.

`soak` starts every node of the graph that the bag's inputs call for (the audio node too,
silent and writing no WAV), then the bag player with ``loop`` and ``loop_restamp`` (the
stamps keep increasing from pass to pass, as from a sensor that never stops) paced by the
detector's /obstacles like `asmonc run`. Every ``period`` seconds it reads each node
process's RSS and number of open file descriptors from /proc. At the end it prints, per
process, the values at the end of the warm-up and at the end, their growth, and the
memory's growth rate (a least-squares line through the samples after the warm-up), with
the count of stereo pairs played and of results (/obstacles) received.

The pieces that do not need ROS (`ProcSample`, `read_proc`, `growth`, `format_table`) are
tested on their own; `asmonc soak` (cli/soak.py) is the command.
"""
from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ['ProcSample', 'read_proc', 'growth', 'format_table', 'SoakCounts', 'soak']


@dataclass(frozen=True)
class ProcSample:
    """One reading of a process: seconds since the soak started, RSS (KiB), open fds."""

    t: float
    rss_kb: int
    fds: int


def read_proc(pid: int, t: float, proc: Path = Path('/proc')) -> ProcSample | None:
    """The RSS (VmRSS) and open file descriptor count of process ``pid`` now (None if it
    is gone)."""
    try:
        status = (proc / str(pid) / 'status').read_text()
        fds = len(os.listdir(proc / str(pid) / 'fd'))
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None
    rss = next((int(line.split()[1]) for line in status.splitlines()
                if line.startswith('VmRSS:')), 0)
    return ProcSample(t, rss, fds)


def growth(samples: list[ProcSample], warmup: float) -> dict | None:
    """What changed after the warm-up: the first sample at or after ``warmup`` s against
    the last one.

    Returns:
        {'rss_start_mb', 'rss_end_mb', 'rss_growth_mb', 'rss_slope_mb_per_h',
        'fds_start', 'fds_end', 'fds_growth', 'samples', 'span_s'}; None with fewer than
        two samples after the warm-up. The slope is the least-squares line through the
        samples after the warm-up (MiB per hour).
    """
    after = [s for s in samples if s.t >= warmup]
    if len(after) < 2:
        return None
    a, b = after[0], after[-1]
    t = np.array([s.t for s in after])
    rss = np.array([s.rss_kb for s in after]) / 1024.0
    slope = float(np.polyfit(t, rss, 1)[0]) * 3600.0 if np.ptp(t) > 0 else 0.0
    return {'rss_start_mb': a.rss_kb / 1024.0, 'rss_end_mb': b.rss_kb / 1024.0,
            'rss_growth_mb': (b.rss_kb - a.rss_kb) / 1024.0, 'rss_slope_mb_per_h': slope,
            'fds_start': a.fds, 'fds_end': b.fds, 'fds_growth': b.fds - a.fds,
            'samples': len(after), 'span_s': b.t - a.t}


def format_table(per_process: dict[str, dict | None]) -> list[str]:
    """Lines of the growth table (one row per process; 'too short' without samples)."""
    head = (f"{'process':<10} {'RSS start':>10} {'RSS end':>9} {'growth':>8} {'MiB/h':>7} "
            f"{'fds start':>9} {'fds end':>7} {'growth':>6}")
    lines = [head, '-' * len(head)]
    for name, g in per_process.items():
        if g is None:
            lines.append(f'{name:<10} (too short: fewer than two samples after the warm-up)')
            continue
        lines.append(f"{name:<10} {g['rss_start_mb']:8.1f}MB {g['rss_end_mb']:7.1f}MB "
                     f"{g['rss_growth_mb']:+7.1f}M {g['rss_slope_mb_per_h']:+7.1f} "
                     f"{g['fds_start']:9d} {g['fds_end']:7d} {g['fds_growth']:+6d}")
    return lines


@dataclass
class SoakCounts:
    """Messages counted by the soak's own node."""

    pairs_in: int = 0        # left camera_info played (one per stereo pair)
    results_out: int = 0     # /obstacles
    alarms: int = 0          # /alarms
    gait_states: int = 0     # /gait/state


class _Counter:
    """An rclpy node in this process that counts the graph's inputs and outputs."""

    def __init__(self, context):
        from rclpy.node import Node
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CameraInfo

        from asmonc_vision.io import bagio
        from asmonc_vision.nodes.common import ALARM_QOS, RESULT_QOS
        from asmonc_vision_msgs.msg import Alarm, GaitState, ObstacleArray

        self.node = Node('asmonc_soak_counter', context=context)
        self.counts = SoakCounts()
        self.lock = threading.Lock()

        def counter(field: str):
            def cb(_msg) -> None:
                with self.lock:
                    setattr(self.counts, field, getattr(self.counts, field) + 1)
            return cb

        self.node.create_subscription(CameraInfo, bagio.TOPICS['left_info'][0],
                                      counter('pairs_in'), qos_profile_sensor_data)
        self.node.create_subscription(ObstacleArray, '/obstacles', counter('results_out'),
                                      RESULT_QOS)
        self.node.create_subscription(Alarm, '/alarms', counter('alarms'), ALARM_QOS)
        self.node.create_subscription(GaitState, '/gait/state', counter('gait_states'),
                                      RESULT_QOS)

    def snapshot(self) -> SoakCounts:
        with self.lock:
            return SoakCounts(**vars(self.counts))


def _player_cmd(bag: Path, rate: float, nodes: dict, topics: dict) -> list[str]:
    from asmonc_vision.io import bagio
    from asmonc_vision.replay.children import wait_topics
    from asmonc_vision.replay.params import PACE_LEAD
    cmd = [sys.executable, '-m', 'asmonc_vision.nodes.player_node', '--ros-args',
           '-p', f'bag:={bag.resolve()}', '-p', f'rate:={float(rate)}',
           '-p', 'loop:=true', '-p', 'loop_restamp:=true', '-p', 'exit_when_done:=false',
           '-p', f'wait_topics:={json.dumps(wait_topics(nodes, topics))}']
    if 'detector' in nodes:
        cmd += ['-p', 'pace_topic:=/obstacles',
                '-p', 'pace_type:=asmonc_vision_msgs/msg/ObstacleArray',
                '-p', f"pace_image_topic:={bagio.TOPICS['left_image'][0]}",
                '-p', f'pace_lead:={PACE_LEAD}']
    return cmd


def _start_nodes(nodes: dict, counter: _Counter, log_dir: Path, echo, env: dict) -> dict:
    """Start the graph's nodes (late ones after the others are connected)."""
    from asmonc_vision.replay.children import Child, connected
    children = {}
    early = [n for n, s in nodes.items() if not s.start_late]
    for group in [early] + [[n] for n, s in nodes.items() if s.start_late]:
        for name in group:
            cmd = [sys.executable, '-m', nodes[name].module, '--ros-args',
                   *nodes[name].ros_args()]
            if name == 'audio':
                cmd += ['-p', 'output:=none']
            children[name] = Child(name, cmd, log_dir, echo, env, echo_warnings=False)
        deadline = time.monotonic() + 90.0
        def produced(name: str) -> frozenset[str]:
            return frozenset(t for m in children if m != name for t in nodes[m].outputs)

        while not all(connected(counter.node, nodes[n], False, children[n], produced(n))
                      for n in group):
            dead = [n for n in group if not children[n].alive()]
            if dead or time.monotonic() > deadline:
                for c in children.values():
                    c.stop()
                why = f'{dead[0]} node exited at start' if dead else 'nodes did not connect'
                raise RuntimeError(f'{why}; logs in {log_dir}')
            time.sleep(0.1)
    return children


def soak(bag: Path, minutes: float, rate: float = 1.0, warmup: float = 60.0,
         period: float = 10.0, echo=print) -> dict:
    """Loop ``bag`` through the node graph for ``minutes`` and measure each process.

    Args:
        bag: a rosbag2 bag following the topic contract.
        minutes: how long the bag is played (after the nodes are up).
        rate: replay speed factor.
        warmup: seconds after the start of playing before growth is counted.
        period: seconds between two samples of each process.
        echo: where the lines go (a node's errors, the table).
    Returns:
        {'growth': {process: growth(...) or None}, 'counts': SoakCounts as a dict,
        'died': [processes that exited], 'minutes', 'rate', 'warmup', 'period',
        'samples': {process: [[t s, RSS KiB, fds], ...]}}.
    Raises:
        RuntimeError: the nodes did not start; asmonc_vision.io.bagio.BagError: bad bag.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from asmonc_vision import graph
    from asmonc_vision.io import bagio
    from asmonc_vision.replay.children import Child
    from asmonc_vision.replay.spin import SpinThread
    from asmonc_vision.replay.domain import claim_domain

    topics, _ = bagio.bag_summary(bag)
    inputs = {k for k, key in (('images', 'left_image'), ('imu', 'imu'))
              if topics.get(bagio.TOPICS[key][0], ('', 0))[1]}
    nodes = {s.name: s for s in graph.nodes_for(inputs, requested={'audio'})}
    if not nodes:
        raise RuntimeError(f"bag '{bag}' has neither stereo images nor inclinometer data")
    domain, lock = claim_domain(int(os.environ.get('ROS_DOMAIN_ID', '0') or 0))
    if domain is None:
        raise RuntimeError('no free ROS domain')
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env = dict(os.environ)
    log_dir = Path(tempfile.mkdtemp(prefix='asmonc-soak-'))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    counter = _Counter(ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(counter.node)
    spinner = SpinThread(ex, 'soak-counter')
    children: dict = {}
    samples: dict[str, list[ProcSample]] = {}
    died: list[str] = []
    try:
        children = _start_nodes(nodes, counter, log_dir, echo, env)
        children['player'] = Child('player', _player_cmd(bag, rate, nodes, topics),
                                    log_dir, echo, env, echo_warnings=False)
        echo(f"soak: {bag} looped at rate {rate:g} for {minutes:g} min through "
             f"{', '.join(children)}; sampling every {period:g} s, warm-up {warmup:g} s")
        samples = _sample(children, minutes * 60.0, period, died, echo, counter)
    finally:
        for name in ['player', 'alarm', *children]:
            if name in children:
                children[name].stop()
        if spinner.stop():  # destroying a node its thread still waits on would race it
            counter.node.destroy_node()
            rclpy.try_shutdown(context=ctx)
        lock.close()
    shutil.rmtree(log_dir, ignore_errors=True)
    return {'growth': {n: growth(s, warmup) for n, s in samples.items()},
            'counts': vars(counter.snapshot()), 'died': died, 'minutes': minutes,
            'rate': rate, 'warmup': warmup, 'period': period,
            'samples': {n: [[round(x.t, 1), x.rss_kb, x.fds] for x in s]
                        for n, s in samples.items()}}


def _sample(children: dict, duration: float, period: float, died: list[str], echo,
            counter: _Counter) -> dict[str, list[ProcSample]]:
    """Read every child process each ``period`` s for ``duration`` s."""
    samples: dict[str, list[ProcSample]] = {n: [] for n in children}
    start = time.monotonic()
    next_at = start
    shown = 0
    while True:
        now = time.monotonic()
        for name, child in children.items():
            s = read_proc(child.proc.pid, now - start) if child.alive() else None
            if s is not None:
                samples[name].append(s)
            elif name not in died:
                died.append(name)
                echo(f'soak: the {name} node exited ({child.proc.poll()}) after '
                     f'{now - start:.0f} s; see {child.log_path}')
        if now - start >= duration:
            return samples
        c = counter.snapshot()
        if now - start >= 60.0 * (shown + 1):
            shown = int((now - start) // 60)
            echo(f'soak: {(now - start) / 60:5.1f} min, {c.pairs_in} pairs in, '
                 f'{c.results_out} results out')
        next_at += period
        time.sleep(max(0.0, min(next_at, start + duration) - time.monotonic()))
