"""Bag reading, topic planning and replay timing without ROS (asmonc_vision.io.bagplay)."""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_bagplay_helpers as h  # noqa: E402

from asmonc_vision.io.bagio import compressed_to_image_cdr, typestore  # noqa: E402
from asmonc_vision.io.bagplay import (BagError, BagSource, BagTopic, PlayerConfig,  # noqa: E402
                                      ReplaySchedule, plan_topics)
from asmonc_vision.core.config import to_dict  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


def test_player_yaml_equals_defaults():
    data = yaml.safe_load((REPO / 'config' / 'bag_player.yaml').read_text())
    assert data == {'bag_player_node': {'ros__parameters': to_dict(PlayerConfig())}}


def test_player_config_checks_ranges():
    with pytest.raises(ValueError, match='rate'):
        PlayerConfig(rate=0.0)
    with pytest.raises(ValueError, match='start_offset'):
        PlayerConfig(start_offset=-1.0)
    assert dataclasses.replace(PlayerConfig(), rate=5.0).rate == 5.0
    with pytest.raises(ValueError, match="wait_topics: '/imu=two'"):
        PlayerConfig(wait_topics=('/imu=two',))
    with pytest.raises(ValueError, match='wait_topics'):
        PlayerConfig(wait_topics=('=2',))


def test_wait_targets():
    cams = ['/stereo/left/image_rect', '/stereo/left/camera_info']
    assert PlayerConfig().wait_targets(cams) == {}
    assert PlayerConfig(wait_for_subscribers=2).wait_targets(cams) == {t: 2 for t in cams}
    cfg = PlayerConfig(wait_for_subscribers=3, wait_topics=('/imu=1', 'stereo/x', '/y=0'))
    assert cfg.wait_targets(cams) == {'/imu': 1, '/stereo/x': 3}


def test_reads_directory_and_single_file(tmp_path):
    msgs = h.sample_messages(6)
    bag = h.write_bag(tmp_path / 'bag', msgs)
    for path in (bag, bag / 'bag.mcap'):
        src = BagSource(path)
        info = src.info
        assert info.storage == 'rosbag2' and info.truncated is None
        assert info.message_count == len(msgs)
        assert {t: info.topics[t].count for t in info.topics} == {
            h.LEFT: 6, h.LEFT_INFO: 6, h.IMU: 6, h.OBSTACLES: 6}
        assert info.topics[h.OBSTACLES].msgtype == 'asmonc_vision_msgs/msg/ObstacleArray'
        assert info.start_ns == h.T0 and info.end_ns == h.T0 + 5 * h.STEP + 3000
        got = list(src.messages())
        assert [(m.topic, m.timestamp, m.data) for m in got] == [
            (t, ts, d) for t, _, ts, d in msgs]
        # iterable again (looping), and from an offset
        later = list(src.messages(start_ns=h.T0 + 3 * h.STEP))
        assert len(later) == 12 and later[0].timestamp == h.T0 + 3 * h.STEP


def test_selected_topics_only(tmp_path):
    src = BagSource(h.write_bag(tmp_path / 'bag', h.sample_messages(3)))
    got = list(src.messages({h.IMU: 'sensor_msgs/msg/Imu'}))
    assert [m.topic for m in got] == [h.IMU] * 3


#: offered_qos_profiles as rosbag2 (Jazzy) writes them for a latched publisher
LATCHED_QOS_YAML = """- history: keep_last
  depth: 10
  reliability: reliable
  durability: transient_local
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false"""


def _write_mcap_like_rosbag2(path: Path, messages, chunk_size: int = 2048) -> Path:
    """An MCAP file as rosbag2 writes one: zstd chunks, ros2msg schemas, cdr channels."""
    from mcap.writer import CompressionType, Writer

    store = typestore()
    with open(path, 'wb') as f:
        w = Writer(f, compression=CompressionType.ZSTD, chunk_size=chunk_size)
        w.start(profile='ros2', library='libmcap 1.4.0')
        schemas, channels = {}, {}
        for i, (topic, msgtype, t, data) in enumerate(messages):
            if msgtype not in schemas:
                text, _ = store.generate_msgdef(msgtype, ros_version=2)
                schemas[msgtype] = w.register_schema(msgtype, 'ros2msg', text.encode())
            if topic not in channels:
                channels[topic] = w.register_channel(
                    topic, 'cdr', schemas[msgtype],
                    {'offered_qos_profiles': LATCHED_QOS_YAML if topic == h.ALARMS else ''})
            w.add_message(channels[topic], log_time=t, data=data, publish_time=t, sequence=i)
        w.finish()
    return path


def test_reads_zstd_chunked_mcap_like_rosbag2(tmp_path):
    msgs = h.sample_messages(5) + [(h.ALARMS, 'asmonc_vision_msgs/msg/Alarm', h.T0 + 10**9,
                                    h.cdr(h.make_alarm(2, h.T0), 'asmonc_vision_msgs/msg/Alarm'))]
    f = _write_mcap_like_rosbag2(tmp_path / 'rec_0.mcap', msgs)
    src = BagSource(f)
    assert src.info.message_count == len(msgs) and src.info.truncated is None
    assert src.info.storage == 'rosbag2'  # read by rosbags, not the fallback
    assert src.info.topics[h.ALARMS].latched and not src.info.topics[h.LEFT].latched
    assert h.by_topic([(m.topic, 0, 0, m.data) for m in src.messages()]) == h.by_topic(msgs)


def test_reads_rosbag2_directory_with_zstd_chunks(tmp_path):
    """A bag directory as `ros2 bag record -s mcap` (Jazzy) leaves it."""
    msgs = h.sample_messages(4) + [(h.ALARMS, 'asmonc_vision_msgs/msg/Alarm', h.T0 + 10**9,
                                    h.cdr(h.make_alarm(1, h.T0), 'asmonc_vision_msgs/msg/Alarm'))]
    bag = tmp_path / 'rosbag2_2026_01_01-00_00_00'
    bag.mkdir()
    _write_mcap_like_rosbag2(bag / 'rosbag2_2026_01_01-00_00_00_0.mcap', msgs)
    counts = {}
    for topic, msgtype, _, _ in msgs:
        counts[(topic, msgtype)] = counts.get((topic, msgtype), 0) + 1
    latched = yaml.safe_load(LATCHED_QOS_YAML)
    start, end = min(m[2] for m in msgs), max(m[2] for m in msgs)
    meta = {'rosbag2_bagfile_information': {
        'version': 9, 'storage_identifier': 'mcap',
        'duration': {'nanoseconds': end - start},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': len(msgs),
        'topics_with_message_count': [
            {'topic_metadata': {'name': topic, 'type': msgtype, 'serialization_format': 'cdr',
                                'offered_qos_profiles': latched if topic == h.ALARMS else [],
                                'type_description_hash': typestore().hash_rihs01(msgtype)},
             'message_count': n} for (topic, msgtype), n in counts.items()],
        'compression_format': '', 'compression_mode': '',
        'relative_file_paths': ['rosbag2_2026_01_01-00_00_00_0.mcap'],
        'files': [{'path': 'rosbag2_2026_01_01-00_00_00_0.mcap',
                   'starting_time': {'nanoseconds_since_epoch': start},
                   'duration': {'nanoseconds': end - start}, 'message_count': len(msgs)}],
        'custom_data': None, 'ros_distro': 'jazzy'}}
    (bag / 'metadata.yaml').write_text(yaml.safe_dump(meta))
    src = BagSource(bag)
    assert src.info.storage == 'rosbag2' and src.info.message_count == len(msgs)
    assert src.info.topics[h.ALARMS].latched
    assert h.by_topic([(m.topic, 0, 0, m.data) for m in src.messages()]) == h.by_topic(msgs)


def test_directory_without_metadata_plays_its_mcap(tmp_path):
    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(2))
    (bag / 'metadata.yaml').unlink()  # a recorder killed before it could finalise
    src = BagSource(bag)
    assert src.info.message_count == 8 and src.info.storage == 'mcap-stream'
    assert len(list(src.messages())) == 8


def test_truncated_mcap_plays_what_can_be_read(tmp_path):
    bag, msgs = h.big_bag(tmp_path)
    data = (bag / 'big.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:int(len(data) * 0.75)])
    src = BagSource(cut)
    info = src.info
    assert info.storage == 'mcap-stream'
    assert info.truncated and 'cut.mcap' in info.truncated and 'truncated' in info.truncated
    assert 0 < info.message_count < len(msgs)
    got = []
    with pytest.raises(BagError, match='truncated'):
        for m in src.messages():
            got.append(m)
    assert len(got) == info.message_count
    assert [m.data for m in got] == [d for _, _, _, d in msgs[:len(got)]]


def test_truncated_bag_directory_falls_back(tmp_path):
    bag, msgs = h.big_bag(tmp_path)
    f = bag / 'big.mcap'
    f.write_bytes(f.read_bytes()[:int(f.stat().st_size * 0.75)])
    src = BagSource(bag)
    assert src.info.truncated and 0 < src.info.message_count < len(msgs)


@pytest.mark.parametrize('case', ['missing', 'empty_string', 'not_a_bag', 'cut_early',
                                  'zero_bytes', 'no_messages', 'empty_dir'])
def test_unplayable_bags_raise_clear_errors(tmp_path, case):
    if case == 'missing':
        path, match = tmp_path / 'nothere', 'does not exist'
    elif case == 'empty_string':
        path, match = '', 'no bag given'
    elif case == 'not_a_bag':
        path = tmp_path / 'notes.txt'
        path.write_text('hello')
        match = 'not a bag'
    elif case == 'cut_early':
        bag = h.write_bag(tmp_path / 'bag', h.sample_messages(3))
        path = tmp_path / 'cut.mcap'
        path.write_bytes((bag / 'bag.mcap').read_bytes()[:200])
        match = 'truncated or corrupt: no message'
    elif case == 'zero_bytes':
        path = tmp_path / 'zero.mcap'
        path.write_bytes(b'')
        match = 'zero.mcap'
    elif case == 'no_messages':
        from rosbags.rosbag2 import StoragePlugin, Writer

        path = tmp_path / 'empty'
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            w.add_connection(h.LEFT, 'sensor_msgs/msg/Image', typestore=typestore())
        match = 'contains no message'
    else:
        path = tmp_path / 'emptydir'
        path.mkdir()
        match = 'no metadata.yaml'
    with pytest.raises(BagError, match=match) as exc:
        BagSource(path)
    if str(path):
        assert Path(path).name in str(exc.value)


def test_plan_topics_filters_and_decompresses():
    topics = {
        '/cam/image/compressed': BagTopic('/cam/image/compressed',
                                          'sensor_msgs/msg/CompressedImage', 4),
        '/raw/image': BagTopic('/raw/image', 'sensor_msgs/msg/Image', 4),
        '/raw/image/compressed': BagTopic('/raw/image/compressed',
                                          'sensor_msgs/msg/CompressedImage', 4),
        '/alarms': BagTopic('/alarms', 'asmonc_vision_msgs/msg/Alarm', 1),
        '/imu': BagTopic('/imu', 'sensor_msgs/msg/Imu', 9),
    }
    plan = {p.bag_topic: p for p in plan_topics(topics)}
    cam = plan['/cam/image/compressed']
    assert (cam.out_topic, cam.out_type, cam.decompress, cam.is_image) == (
        '/cam/image', 'sensor_msgs/msg/Image', True, True)
    # the raw stream exists: its compressed twin is played unchanged
    twin = plan['/raw/image/compressed']
    assert (twin.out_topic, twin.decompress, twin.is_image) == (
        '/raw/image/compressed', False, False)
    assert plan['/alarms'].latched and not plan['/imu'].latched
    # include / exclude match the bag name or the published name, with or without '/'
    assert [p.bag_topic for p in plan_topics(topics, include=['cam/image'])] == [
        '/cam/image/compressed']
    assert {p.bag_topic for p in plan_topics(topics, exclude=['/cam/image', 'imu'])} == {
        '/raw/image', '/raw/image/compressed', '/alarms'}


def test_schedule_scales_and_never_waits_negative():
    s = ReplaySchedule(bag_start_ns=1_000, wall_start=50.0, rate=2.0)
    assert s.due(1_000) == 50.0
    assert s.due(1_000 + 1_000_000_000) == pytest.approx(50.5)
    assert s.delay(1_000 + 1_000_000_000, now=50.2) == pytest.approx(0.3)
    # out of order: an earlier stamp after a later one is due at once
    assert s.delay(1_000 + 200_000_000, now=50.5) == 0.0
    assert s.delay(0, now=49.0) == 1.0  # before the start: due at the start
    assert s.bag_time(50.25) == 1_000 + 500_000_000
    with pytest.raises(ValueError):
        ReplaySchedule(0, 0.0, 0.0)


@pytest.mark.parametrize('fmt', ['png', 'jpeg'])
def test_compressed_to_image(fmt):
    T = typestore().types
    px = np.tile(np.arange(32, dtype=np.uint8) * 8, (24, 1))
    ok, enc = cv2.imencode('.png' if fmt == 'png' else '.jpg', px)
    assert ok
    msg = T['sensor_msgs/msg/CompressedImage'](header=h.header(h.T0 + 5, 'cam'), format=fmt,
                                               data=enc.reshape(-1))
    out = typestore().deserialize_cdr(
        compressed_to_image_cdr(h.cdr(msg, 'sensor_msgs/msg/CompressedImage')),
        'sensor_msgs/msg/Image')
    assert (out.header.stamp.sec, out.header.stamp.nanosec, out.header.frame_id) == (
        msg.header.stamp.sec, msg.header.stamp.nanosec, 'cam')
    assert (out.encoding, out.height, out.width, out.step) == ('mono8', 24, 32, 32)
    img = np.asarray(out.data).reshape(24, 32)
    if fmt == 'png':
        assert np.array_equal(img, px)
    else:
        assert np.abs(img.astype(int) - px).max() <= 8
