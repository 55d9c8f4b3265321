"""The bag recorder node: records what is published (latched alarms, best-effort sensors),
writes a bag that rosbags and the mcap library both read, survives SIGINT, refuses to
overwrite, and a replayed bag records back to the same messages."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_bagplay_helpers as h  # noqa: E402

from asmonc_vision.core.config import to_dict  # noqa: E402
from asmonc_vision.nodes.recorder_node import RecorderConfig  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


def test_recorder_yaml_equals_defaults():
    data = yaml.safe_load((REPO / 'config' / 'bag_recorder.yaml').read_text())
    assert data == {'bag_recorder_node': {'ros__parameters': to_dict(RecorderConfig())}}


def _ros_msgs():
    """rclpy messages of the four recorded types."""
    from geometry_msgs.msg import Point
    from sensor_msgs.msg import Image, Imu

    from asmonc_vision_msgs.msg import Alarm, Obstacle, ObstacleArray

    def image(i):
        m = Image(height=2, width=3, encoding='mono8', step=3, data=bytes([i] * 6))
        m.header.frame_id = 'stereo_left_optical_frame'
        m.header.stamp.sec = 100 + i
        return m

    def imu(i):
        m = Imu()
        m.header.frame_id = 'inclinometer_link'
        m.linear_acceleration.z = 9.81 + i
        return m

    def obstacles(i):
        return ObstacleArray(obstacles=[Obstacle(id=i + 1, range=2.5, position=Point(z=3.0))])

    def alarm(level, text):
        return Alarm(level=level, obstacle_id=3, range=1.5, bearing=-0.25, text=text)

    return image, imu, obstacles, alarm


def _recorder(ctx, name: str = 'bag_recorder_node', **settings):
    from asmonc_vision.nodes.recorder_node import BagRecorderNode

    return BagRecorderNode(RecorderConfig(**settings), context=ctx, node_name=name)


@pytest.mark.parametrize('compression', ['none', 'zstd'])
def test_records_topics_types_counts_contents(tmp_path, ros_context, compression):
    from rclpy.node import Node
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image, Imu

    from asmonc_vision.nodes.common import ALARM_QOS, IMAGE_QOS, RESULT_QOS, SENSOR_QOS
    from asmonc_vision_msgs.msg import Alarm, ObstacleArray

    image, imu, obstacles, alarm = _ros_msgs()
    pub = Node('publisher', context=ros_context)
    pubs = {h.ALARMS: pub.create_publisher(Alarm, h.ALARMS, ALARM_QOS),
            h.LEFT: pub.create_publisher(Image, h.LEFT, IMAGE_QOS),
            h.IMU: pub.create_publisher(Imu, h.IMU, SENSOR_QOS),  # best effort
            h.OBSTACLES: pub.create_publisher(ObstacleArray, h.OBSTACLES, RESULT_QOS)}
    sent = {t: [] for t in pubs}

    def send(topic, msg):
        pubs[topic].publish(msg)
        sent[topic].append(msg)

    send(h.ALARMS, alarm(2, 'obstacle, 2 metres'))  # latched, before the recorder exists
    out = tmp_path / 'rec'
    out.mkdir()  # an existing empty directory is fine
    t_start = time.time_ns()
    rec = _recorder(ros_context, output=str(out), compression=compression)
    spinner = h.Spinner(ros_context, pub, rec)
    try:
        assert h.wait_for(lambda: set(pubs) <= set(rec.topic_types), 10.0), rec.topic_types
        assert h.wait_for(lambda: rec.counts[h.ALARMS] == 1, 10.0)  # the latched alarm
        assert h.wait_for(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values())
                          and rec._subs[h.IMU].get_publisher_count() >= 1, 10.0)
        time.sleep(0.1)  # best effort has no retransmission: let both ends settle
        for i in range(3):
            send(h.LEFT, image(i))
            send(h.IMU, imu(i))
            time.sleep(0.01)
        send(h.OBSTACLES, obstacles(0))
        send(h.OBSTACLES, obstacles(1))
        send(h.ALARMS, alarm(0, ''))
        want = {t: len(v) for t, v in sent.items()}
        assert h.wait_for(lambda: rec.counts == want, 10.0), (rec.counts, want)
    finally:
        spinner.stop()
    t_end = time.time_ns()
    rec.close()
    rec.close()  # idempotent
    assert rec.closed
    rec.destroy_node()

    # rosbags
    got = h.read_bag(out)
    assert {t: ty for t, ty, _, _ in got} == {
        h.ALARMS: 'asmonc_vision_msgs/msg/Alarm', h.LEFT: 'sensor_msgs/msg/Image',
        h.IMU: 'sensor_msgs/msg/Imu', h.OBSTACLES: 'asmonc_vision_msgs/msg/ObstacleArray'}
    # same messages, in order, nothing else (compared as messages: CDR padding bytes are
    # not specified, so a second serialization need not give the same bytes)
    recorded = {t: [deserialize_message(d, type(sent[t][0])) for d in v]
                for t, v in h.by_topic(got).items()}
    assert recorded == sent
    assert all(t_start <= t <= t_end for _, _, t, _ in got)  # receive times, ns
    assert [t for _, _, t, _ in got] == sorted(t for _, _, t, _ in got)

    # metadata.yaml
    meta = yaml.safe_load((out / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['version'] == 9 and meta['storage_identifier'] == 'mcap'
    assert meta['message_count'] == sum(len(v) for v in sent.values())
    topics = {t['topic_metadata']['name']: t for t in meta['topics_with_message_count']}
    assert set(topics) == set(sent)
    assert topics[h.LEFT]['message_count'] == 3
    assert topics[h.ALARMS]['topic_metadata']['offered_qos_profiles'][0]['durability'] == \
        'transient_local'
    assert topics[h.IMU]['topic_metadata']['offered_qos_profiles'][0]['reliability'] == \
        'best_effort'

    # the mcap library (seeking reader with the summary, and the ROS 2 decoder)
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    files = list(out.glob('*.mcap'))
    assert len(files) == 1
    with open(files[0], 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary.statistics.message_count == meta['message_count']
        assert {c.topic for c in summary.channels.values()} == set(sent)
        assert {s.name for s in summary.schemas.values()} >= {'asmonc_vision_msgs/msg/Alarm'}
        assert {c.compression for c in summary.chunk_indexes} == {
            'zstd' if compression == 'zstd' else ''}
        decoded = {}
        for _schema, channel, _message, msg in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, []).append(msg)
    assert [a.text for a in decoded[h.ALARMS]] == ['obstacle, 2 metres', '']
    assert [a.level for a in decoded[h.ALARMS]] == [2, 0]
    assert [o.obstacles[0].id for o in decoded[h.OBSTACLES]] == [1, 2]
    assert [bytes(m.data) for m in decoded[h.LEFT]] == [bytes([i] * 6) for i in range(3)]
    assert decoded[h.IMU][2].linear_acceleration.z == pytest.approx(11.81)


def test_refuses_to_overwrite(tmp_path, ros_context):
    from asmonc_vision.nodes.recorder_node import RecorderError

    out = tmp_path / 'bag'
    out.mkdir()
    (out / 'precious.mcap').write_bytes(b'keep me')
    with pytest.raises(RecorderError, match='not empty') as exc:
        _recorder(ros_context, output=str(out))
    assert str(out) in str(exc.value)
    assert (out / 'precious.mcap').read_bytes() == b'keep me'
    f = tmp_path / 'file'
    f.write_text('x')
    with pytest.raises(RecorderError, match='not a directory'):
        _recorder(ros_context, output=str(f))


def test_topic_selection(tmp_path, ros_context):
    from rclpy.node import Node
    from std_msgs.msg import String

    pub = Node('publisher', context=ros_context)
    a = pub.create_publisher(String, '/a', 10)
    pub.create_publisher(String, '/b', 10)
    pub.create_publisher(String, '/_hidden', 10)
    rec = _recorder(ros_context, output=str(tmp_path / 'r1'), topics=('a', '/b'),
                    exclude_topics=('/b',))
    rec_all = _recorder(ros_context, 'recorder_all', output=str(tmp_path / 'r2'),
                        exclude_topics=())
    spinner = h.Spinner(ros_context, pub, rec, rec_all)
    try:
        assert h.wait_for(lambda: '/a' in rec.topic_types and '/b' in rec_all.topic_types)
        assert h.wait_for(lambda: a.get_subscription_count() >= 2)
        a.publish(String(data='hello'))
        assert h.wait_for(lambda: rec.counts['/a'] == 1 and rec_all.counts['/a'] == 1)
        time.sleep(2 * RecorderConfig().discovery_period)
    finally:
        spinner.stop()
    assert set(rec.topic_types) == {'/a'}
    # everything but hidden topics, including this node's /rosout when not excluded
    assert {'/a', '/b', '/rosout'} <= set(rec_all.topic_types)
    assert '/_hidden' not in rec_all.topic_types
    rec.destroy_node()
    rec_all.destroy_node()
    from rclpy.serialization import deserialize_message
    assert [deserialize_message(d, String).data for _, _, _, d in
            h.read_bag(tmp_path / 'r1')] == ['hello']


def test_sigint_leaves_a_readable_bag(tmp_path, ros_context):
    """`bag_recorder_node` in its own process, stopped with Ctrl-C."""
    import rclpy
    from rclpy.node import Node
    from std_msgs.msg import String

    # the process must share the test context's domain
    domain = ros_context.get_domain_id()
    out = tmp_path / 'sigint_bag'
    cmd = [sys.executable, '-m', 'asmonc_vision.nodes.recorder_node', '--ros-args',
           '-p', f'output:={out}', '-p', "topics:=['/chatter']", '-p', 'compression:=zstd']
    proc = subprocess.Popen(cmd, env=h.subprocess_env(domain), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        pub = Node('talker', context=ros_context)
        chatter = pub.create_publisher(String, '/chatter', 10)
        assert h.wait_for(lambda: chatter.get_subscription_count() >= 1, 20.0)
        for i in range(5):
            chatter.publish(String(data=f'msg {i}'))
        time.sleep(0.5)  # delivered (reliable) before the stop
        proc.send_signal(signal.SIGINT)
        log, _ = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, log
    assert 'wrote bag' in log and '/chatter 5' in log, log
    got = h.read_bag(out)
    assert [d[8:-1].rstrip(b'\x00') for _, _, _, d in got] == [
        f'msg {i}'.encode() for i in range(5)]
    assert rclpy.ok(context=ros_context)


def test_process_refuses_existing_bag(tmp_path):
    out = tmp_path / 'bag'
    out.mkdir()
    (out / 'metadata.yaml').write_text('x')
    cmd = [sys.executable, '-m', 'asmonc_vision.nodes.recorder_node', '--ros-args',
           '-p', f'output:={out}']
    r = subprocess.run(cmd, env=h.subprocess_env(h.next_domain_id()), capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert '[ERROR]' in r.stderr and str(out) in r.stderr and 'not overwriting' in r.stderr


def test_round_trip_play_record(tmp_path, ros_context):
    """Play a bag, record it: the same messages come back (bytes, per-topic order)."""
    from asmonc_vision.io.bagplay import PlayerConfig
    from asmonc_vision.nodes.player_node import BagPlayerNode

    msgs = h.sample_messages(5) + [
        (h.ALARMS, 'asmonc_vision_msgs/msg/Alarm', h.T0 + 250_000_000,
         h.cdr(h.make_alarm(3, h.T0), 'asmonc_vision_msgs/msg/Alarm'))]
    src = h.write_bag(tmp_path / 'src', sorted(msgs, key=lambda m: m[2]))
    player = BagPlayerNode(PlayerConfig(bag=str(src), rate=4.0, exit_when_done=False),
                           context=ros_context, start=False)
    rec = _recorder(ros_context, output=str(tmp_path / 'copy'), compression='zstd')
    spinner = h.Spinner(ros_context, player, rec)
    topics = {t for t, _, _, _ in msgs}
    try:
        assert h.wait_for(lambda: topics <= set(rec.topic_types), 10.0)
        assert player.wait_for_subscribers(1, 10.0, topics=topics)
        assert h.wait_for(lambda: all(rec._subs[t].get_publisher_count() >= 1 for t in topics))
        player.start()
        assert player.play_done.wait(10.0)
        want = {t: len(v) for t, v in h.by_topic(msgs).items()}
        assert h.wait_for(lambda: {t: rec.counts.get(t, 0) for t in want} == want, 10.0)
    finally:
        spinner.stop()
    player.destroy_node()
    rec.destroy_node()
    copy = h.read_bag(tmp_path / 'copy')
    assert h.by_topic(copy) == h.by_topic(msgs)
    assert {t: ty for t, ty, _, _ in copy} == {t: ty for t, ty, _, _ in msgs}
    # the replay kept the bag's pace (4x): 0.4 s of bag time in about 0.1 s
    images = [t for topic, _, t, _ in copy if topic == h.LEFT]
    assert 0.05 <= (images[-1] - images[0]) * 1e-9 <= 0.6
