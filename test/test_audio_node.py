"""audio_node and the alarm node's /alarms/contact over real topics, in-process."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import CameraInfo  # noqa: E402

from asmonc_vision.core.audio import read_wav  # noqa: E402
from asmonc_vision.nodes.alarm_node import AlarmNode, contact_from_msg  # noqa: E402
from asmonc_vision.nodes.audio_node import AudioNode  # noqa: E402
from asmonc_vision.nodes.common import ALARM_QOS, RESULT_QOS  # noqa: E402
from asmonc_vision_msgs.msg import Alarm, GroundPlane, Obstacle, ObstacleArray  # noqa: E402

ROS_DOMAIN_OFFSET = 67
DEADLINE = 15.0
T0 = 1_700_000_000 * 10 ** 9          # the camera time of the first pair
RATE = 16000


def _stamp(msg, ns):
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10 ** 9, ns % 10 ** 9
    return msg


def _onsets(x, thresh=0.02, gap=0.03):
    loud = np.flatnonzero(np.max(np.abs(x), axis=1) > thresh)
    starts = [loud[0]] + [b for a, b in zip(loud[:-1], loud[1:]) if b - a > gap * RATE]
    return [s / RATE for s in starts]


def test_audio_node_plays_silently_without_a_device_and_writes_the_wav(ros, tmp_path):
    wav = tmp_path / 'heard.wav'
    probe = ros.add(Node('audio_probe', context=ros.ctx))
    diags = ros.diagnostics(probe, 'audio_node')
    info_pub = probe.create_publisher(CameraInfo, '/stereo/left/camera_info', RESULT_QOS)
    alarm_pub = probe.create_publisher(Alarm, '/alarms', ALARM_QOS)
    node = ros.add(AudioNode(context=ros.ctx, parameter_overrides=[
        Parameter('wav_path', value=str(wav)), Parameter('t0_ns', value=T0),
        Parameter('verbosity', value='tones'),
        Parameter('latency_path', value=str(tmp_path / 'lat.json'))]))
    # no PortAudio / no device here: the node says so and keeps going
    ros.spin_until(lambda: any(d.message.startswith('silent output') for d in diags),
                   'the silent-output diagnostic')
    assert diags[-1].level == bytes([1])
    assert {kv.key: kv.value for kv in diags[-1].values}['output'] == 'none (silent)'
    ros.spin_until(lambda: info_pub.get_subscription_count() > 0
                   and alarm_pub.get_subscription_count() > 0, 'the node to subscribe')

    def pair(k):                         # 10 Hz pairs from T0
        info_pub.publish(_stamp(CameraInfo(), T0 + k * 100_000_000))

    def alarm(k, level, text, bearing=0.0, rng=0.0, oid=0):
        a = _stamp(Alarm(), T0 + k * 100_000_000)
        a.level, a.text, a.bearing, a.range, a.obstacle_id = level, text, bearing, rng, oid
        alarm_pub.publish(a)

    pair(0)
    ros.spin_for(0.05)
    alarm(0, Alarm.CLEAR, 'all clear')
    decisions = {7: (Alarm.WARNING, 'obstacle, 2 metres, left', math.radians(40), 2.0, 1),
                 25: (Alarm.STOP, 'stop, obstacle, 1 metre, ahead', 0.0, 1.0, 1)}
    diag_pub = probe.create_publisher(DiagnosticArray, '/diagnostics', 10)
    for k in range(1, 30):
        pair(k)
        ros.spin_for(0.02)
        if k in decisions:
            alarm(k, *decisions[k])
        if k == 15:                       # the walk model: the inclinometer went silent
            d = DiagnosticArray()
            d.status = [DiagnosticStatus(name='gait_filter_node', level=bytes([1]),
                                         message='inclinometer silent (0.6 s)')]
            diag_pub.publish(d)
        ros.spin_for(0.08)
    node.close()
    x, rate = read_wav(wav)
    assert rate == RATE and x.shape[1] == 2 and len(x) / RATE >= 2.8
    found = _onsets(x)
    for k in decisions:                  # onsets at the decisions' stamps, bag time
        assert min(abs(f - k * 0.1) for f in found) < 0.05, (k, found)
    assert not [f for f in found if f < 0.65]          # CLEAR is silent
    a, b = int(0.7 * RATE), int(0.8 * RATE)            # the WARNING cue: 40 deg left
    assert np.abs(x[a:b, 0]).max() > 1.5 * np.abs(x[a:b, 1]).max()
    cues = json.loads(wav.with_suffix('.cues.json').read_text())
    assert cues['t0_ns'] == T0 and [e for e in cues['events'] if e['what'] == 'stop']
    degraded = [e['t'] for e in cues['events'] if e['what'] == 'degraded']
    assert len(degraded) == 1 and 1.45 < degraded[0] < 1.8
    lat = json.loads((tmp_path / 'lat.json').read_text())['latency_s']
    assert lat and all(0 <= v < 5.0 for v in lat)


def test_alarm_node_publishes_the_contact_by_time_to_contact(ros):
    from geometry_msgs.msg import TransformStamped

    probe = ros.add(Node('contact_probe', context=ros.ctx))
    contacts, alarms = [], []
    probe.create_subscription(DiagnosticArray, '/alarms/contact',
                              lambda m: contacts.append(contact_from_msg(m)), RESULT_QOS)
    probe.create_subscription(Alarm, '/alarms', alarms.append, ALARM_QOS)
    obs_pub = probe.create_publisher(ObstacleArray, '/obstacles', RESULT_QOS)
    plane_pub = probe.create_publisher(GroundPlane, '/ground_plane', RESULT_QOS)
    ego_pub = probe.create_publisher(TransformStamped, '/egomotion', RESULT_QOS)
    ros.add(AlarmNode(context=ros.ctx, parameter_overrides=[
        Parameter('timeout', value=5.0), Parameter('startup_grace', value=60.0)]))
    ros.spin_until(lambda: obs_pub.get_subscription_count() > 0
                   and ego_pub.get_subscription_count() > 0, 'the node to subscribe')
    plane_pub.publish(_stamp(GroundPlane(status=GroundPlane.TRACKING), T0))
    ros.spin_for(0.1)
    for k in range(1, 8):                # walking at 1.4 m/s straight on, 10 Hz
        ns = T0 + k * 100_000_000
        ego = _stamp(TransformStamped(), ns)
        ego.transform.translation.z = 0.14
        ego.transform.rotation.w = 1.0
        ego_pub.publish(ego)
        ros.spin_for(0.02)
        arr = _stamp(ObstacleArray(), ns)
        arr.obstacles = [Obstacle(id=3, range=4.0, bearing=0.0, height=0.3, confidence=0.9)]
        obs_pub.publish(arr)
        ros.spin_for(0.08)
    ros.spin_until(lambda: len(contacts) >= 7, 'the contacts')
    last = contacts[-1]
    assert last['moving'] and last['speed'] == pytest.approx(1.4, rel=0.05)
    assert last['time_to_contact'] == pytest.approx(4.0 / 1.4, rel=0.05)
    assert last['level'] == Alarm.WARNING and not last['drop']
    assert any(a.level == Alarm.WARNING for a in alarms)   # 4 m: CAUTION by range alone
