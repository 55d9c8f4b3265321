"""The fail-safe, heard: the detector is killed mid-replay and the FAULT cue's onset is
read from the audio node's WAV (player, detector, alarm and audio nodes in their own
processes, as `asmonc run` starts them)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np

from asmonc_vision.io import bagio
from asmonc_vision.core.alarm import AlarmConfig
from asmonc_vision.core.audio import read_wav
from conftest import BAGS

BAG = BAGS / 'static_obstacles'
#: the bag's time of the kill: the pavement is still clear (CLEAR, silence) until 2 s
KILL_AT = 1.0
#: the target: FAULT heard at most this long after perception stops (s, bag time)
FAULT_WITHIN = 0.5
#: a generous bound so a broken graph fails the test instead of hanging it
DEADLINE = 180.0


def _start(module, params, env, log):
    cmd = [sys.executable, '-m', module, '--ros-args']
    for k, v in params.items():
        cmd += ['-p', f'{k}:={v}']
    return subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)


def _stop(proc, sig=signal.SIGINT, timeout=20.0):
    if proc.poll() is None:
        os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def _linked(log, topic):
    """Whether the node's log says its subscription of `topic` has a publisher."""
    from asmonc_vision.replay.children import LINKED_RE
    return any(m.group(1) == topic for m in LINKED_RE.finditer(log.read_text()))


def _perception_stopped(obstacles, info, t0):
    """When perception stopped, on the cameras' time line (s from `t0`): the arrival of
    its last /obstacles, placed as the audio node places an alarm of the alarm node's own
    clock -- the newest camera_info that arrived before it, plus the time between the two
    arrivals (the replay runs at rate 1). The detector's share of a frame's latency (the
    camera's stamp to its result) comes before this and is not the fail-safe's."""
    last_ns, last_at = obstacles[-1]
    before = [(ns, at) for ns, at in info if at <= last_at]
    assert before, 'no camera_info arrived before the last /obstacles'
    ns, at = max(before, key=lambda p: p[1])
    return (ns - t0) * 1e-9 + (last_at - at)


def test_killing_the_detector_is_heard_as_fault_within_half_a_second(tmp_path):
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo

    from asmonc_vision.nodes.common import ALARM_QOS, RESULT_QOS, SENSOR_QOS
    from asmonc_vision_msgs.msg import Alarm, ObstacleArray

    domain = 1 + (os.getpid() * 3 + 79) % 100
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    t0 = next(bagio.header_stamp_ns(m) for _, _, m in
              bagio.read_messages(BAG, [bagio.TOPICS['left_image'][0]]))
    wav = tmp_path / 'heard.wav'
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    from rclpy.executors import SingleThreadedExecutor
    probe = Node('failsafe_probe', context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(probe)
    seen = {'obstacles': [], 'info': [], 'alarms': []}
    # (camera stamp ns, arrival on this process's steady clock s)
    probe.create_subscription(ObstacleArray, '/obstacles',
                              lambda m: seen['obstacles'].append(
                                  (bagio.header_stamp_ns(m), time.monotonic())),
                              RESULT_QOS)
    probe.create_subscription(CameraInfo, '/stereo/left/camera_info',
                              lambda m: seen['info'].append(
                                  (bagio.header_stamp_ns(m), time.monotonic())),
                              SENSOR_QOS)
    probe.create_subscription(Alarm, '/alarms', seen['alarms'].append, ALARM_QOS)
    procs = {}
    logs = {n: (tmp_path / f'{n}.log').open('w') for n in ('detector', 'alarm', 'audio',
                                                            'player')}

    def spin_until(pred, what):
        end = time.monotonic() + DEADLINE
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
            if pred():
                return
            dead = [n for n, p in procs.items() if p.poll() is not None and n != 'detector']
            assert not dead, f'{dead} exited: see {tmp_path}'
        raise AssertionError(f'timed out waiting for {what}')

    def subscribed(node, topic):
        return node in {i.node_name for i in probe.get_subscriptions_info_by_topic(topic)}

    try:
        procs['detector'] = _start('asmonc_vision.nodes.detector_node',
                                   {'use_egomotion': 'false'}, env, logs['detector'])
        procs['audio'] = _start('asmonc_vision.nodes.audio_node',
                                {'wav_path': wav, 't0_ns': t0, 'verbosity': 'tones'},
                                env, logs['audio'])
        spin_until(lambda: subscribed('detector_node', '/stereo/right/image_rect')
                   and subscribed('audio_node', '/alarms'), 'the detector and audio nodes')
        procs['alarm'] = _start('asmonc_vision.nodes.alarm_node', {}, env, logs['alarm'])
        # seen in the graph is not yet linked between two processes: wait for the nodes'
        # own word that the detector's results and the alarms reach them
        spin_until(lambda: subscribed('alarm_node', '/obstacles')
                   and _linked(tmp_path / 'alarm.log', '/obstacles')
                   and _linked(tmp_path / 'audio.log', '/alarms'), 'the alarm node')
        procs['player'] = _start('asmonc_vision.nodes.player_node', {
            'bag': BAG.resolve(), 'rate': 1.0, 'exit_when_done': 'true',
            'wait_topics': json.dumps(['/stereo/left/image_rect=1', '/stereo/right/image_rect=1',
                                       '/stereo/left/camera_info=3',
                                       '/stereo/right/camera_info=1'])}, env, logs['player'])
        spin_until(lambda: seen['obstacles']
                   and seen['obstacles'][-1][0] >= t0 + KILL_AT * 1e9,
                   'the replay to reach the kill')
        _stop(procs['detector'], signal.SIGKILL)
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
    finally:
        for name in ('player', 'alarm', 'detector', 'audio'):
            if name in procs:
                _stop(procs[name])
        executor.remove_node(probe)
        probe.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=ctx)
        for f in logs.values():
            f.close()

    faults = [a for a in seen['alarms'] if a.level == Alarm.FAULT
              and a.text != 'starting up, hold still']
    assert faults, 'no FAULT was announced after the kill'
    x, rate = read_wav(wav)
    stop_t = _perception_stopped(seen['obstacles'], seen['info'], t0)
    # the first sound after perception stopped: quiet before (the path was clear), then FAULT
    env_ = np.max(np.abs(x), axis=1)
    after = np.flatnonzero(env_[int((stop_t - 0.2) * rate):] > 0.02)
    assert len(after), f'no sound after perception stopped at {stop_t:.2f} s'
    onset = (after[0] + int((stop_t - 0.2) * rate)) / rate
    print(f'perception stopped at {stop_t:.3f} s bag time; FAULT cue onset {onset:.3f} s '
          f'(+{onset - stop_t:.3f} s)')
    # (the audio node's and this process's views of the camera time differ by their
    # callbacks' delays: up to about a frame on a loaded machine)
    assert stop_t - 0.1 <= onset <= stop_t + FAULT_WITHIN, (stop_t, onset)
    # and it is the FAULT cue: a low dyad, its energy below 800 Hz
    seg = x[int(onset * rate):int((onset + 0.09) * rate)].mean(axis=1)
    spec = np.abs(np.fft.rfft(seg, 4096)) ** 2
    f = np.fft.rfftfreq(4096, 1 / rate)
    assert spec[f < 800].sum() > 0.8 * spec.sum()
    # and the default timeout leaves room for it
    from asmonc_vision.nodes.alarm_node import CHECK_PERIOD
    assert AlarmConfig().timeout + CHECK_PERIOD <= FAULT_WITHIN
