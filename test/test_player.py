"""The bag player node: in-process replay (content, order, timing, compressed images,
start offset, unknown types, /clock, exit) and the process's exit codes."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_bagplay_helpers as h  # noqa: E402

from asmonc_vision.io.bagio import typestore  # noqa: E402
from asmonc_vision.io.bagplay import BagError, PlayerConfig  # noqa: E402

TYPES = {h.LEFT: 'sensor_msgs/msg/Image', h.LEFT_INFO: 'sensor_msgs/msg/CameraInfo',
         h.IMU: 'sensor_msgs/msg/Imu', h.OBSTACLES: 'asmonc_vision_msgs/msg/ObstacleArray'}


def _player(ctx, **settings):
    from asmonc_vision.nodes.player_node import BagPlayerNode

    settings.setdefault('exit_when_done', False)
    return BagPlayerNode(PlayerConfig(**settings), context=ctx, start=False)


def _play(ctx, player, collector, expected: int, timeout: float = 10.0) -> None:
    """Spin both, wait for discovery, play, wait for `expected` messages."""
    spinner = h.Spinner(ctx, player, collector.node)
    try:
        assert player.wait_for_subscribers(1, 10.0, topics=[p.out_topic for p in player.plan])
        # both ends matched: the first message does not come late
        assert collector.wait_matched([p.out_topic for p in player.plan])
        player.start()
        assert player.play_done.wait(timeout)
        assert h.wait_for(lambda: collector.count() >= expected, 5.0), collector.count()
        time.sleep(0.05)  # nothing more must come
    finally:
        spinner.stop()


@pytest.mark.parametrize('rate', [1.0, 5.0])
def test_plays_everything_in_order_with_bag_timing(tmp_path, ros_context, rate):
    msgs = h.sample_messages(11)  # 1.0 s of bag time
    bag = h.write_bag(tmp_path / 'bag', msgs)
    player = _player(ros_context, bag=str(bag), rate=rate)
    collector = h.RawCollector(ros_context, TYPES)
    _play(ros_context, player, collector, len(msgs))

    expected = h.by_topic(msgs)
    for topic in TYPES:
        assert collector.data(topic) == expected[topic], topic  # same bytes, same order
    assert player.published_counts == {t: 11 for t in TYPES}
    assert player.error is None and player.passes == 1

    # loose bounds: the replay keeps the bag's pace, scaled by the rate
    span = collector.times()[-1] - collector.times()[0]
    wanted = 1.0 / rate
    if rate == 1.0:
        assert 0.8 * wanted <= span <= wanted + 1.0
    else:
        assert 0.5 * wanted <= span <= wanted + 0.25

    # the bytes are the real messages: rclpy reads them
    from rclpy.serialization import deserialize_message

    from asmonc_vision_msgs.msg import ObstacleArray
    last = deserialize_message(collector.data(h.OBSTACLES)[-1], ObstacleArray)
    assert len(last.obstacles) == 10 % 3 and last.obstacles[0].id == 11
    assert last.header.stamp.sec == (h.T0 + 10 * h.STEP) // 10**9


def test_compressed_images_published_as_mono8(tmp_path, ros_context):
    T = typestore().types
    msgs, frames = [], []
    for i in range(3):
        ns = h.T0 + i * h.STEP
        px = h.image_pixels(i)
        frames.append(px)
        for side, ext in (('left', '.png'), ('right', '.jpg')):
            ok, enc = cv2.imencode(ext, px if ext == '.png' else np.full_like(px, 60 * i))
            assert ok
            m = T['sensor_msgs/msg/CompressedImage'](header=h.header(ns, side), format=ext[1:],
                                                     data=enc.reshape(-1))
            msgs.append((f'/stereo/{side}/image_rect/compressed',
                         'sensor_msgs/msg/CompressedImage', ns + (side == 'right'),
                         h.cdr(m, 'sensor_msgs/msg/CompressedImage')))
    bag = h.write_bag(tmp_path / 'cbag', msgs)
    player = _player(ros_context, bag=str(bag), rate=5.0)
    assert sorted(player.image_topics) == ['/stereo/left/image_rect', '/stereo/right/image_rect']
    collector = h.RawCollector(ros_context, {'/stereo/left/image_rect': 'sensor_msgs/msg/Image',
                                             '/stereo/right/image_rect': 'sensor_msgs/msg/Image'})
    _play(ros_context, player, collector, 6)

    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image
    left = [deserialize_message(d, Image) for d in collector.data('/stereo/left/image_rect')]
    right = [deserialize_message(d, Image) for d in collector.data('/stereo/right/image_rect')]
    assert len(left) == len(right) == 3
    for i, m in enumerate(left):
        assert (m.encoding, m.height, m.width, m.step, m.header.frame_id) == (
            'mono8', 24, 32, 32, 'left')
        assert m.header.stamp.nanosec == (h.T0 + i * h.STEP) % 10**9
        assert np.array_equal(np.frombuffer(bytes(m.data), np.uint8).reshape(24, 32), frames[i])
    for i, m in enumerate(right):  # JPEG: lossy, a flat grey survives
        img = np.frombuffer(bytes(m.data), np.uint8)
        assert m.encoding == 'mono8' and abs(int(img.mean()) - 60 * i) <= 2


def test_start_offset_and_topic_filters(tmp_path, ros_context):
    msgs = h.sample_messages(6)
    bag = h.write_bag(tmp_path / 'bag', msgs)
    # start 0.25 s in: frames at 0.3, 0.4, 0.5 s remain; /inclinometer/imu excluded
    player = _player(ros_context, bag=str(bag), rate=5.0, start_offset=0.25,
                     exclude_topics=('inclinometer/imu',))
    assert [p.out_topic for p in player.plan] == sorted([h.LEFT_INFO, h.LEFT, h.OBSTACLES])
    collector = h.RawCollector(ros_context, TYPES)
    _play(ros_context, player, collector, 9)
    expected = h.by_topic(msgs)
    assert collector.data(h.LEFT) == expected[h.LEFT][3:]
    assert collector.data(h.OBSTACLES) == expected[h.OBSTACLES][3:]
    assert collector.data(h.IMU) == []

    with pytest.raises(BagError, match='past the end'):
        _player(ros_context, bag=str(bag), start_offset=2.0)


def test_unknown_type_is_skipped_rest_plays(tmp_path, ros_context):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(typestore().fielddefs)
    store.register(get_types_from_msg('int32 value', 'no_such_pkg/msg/Thing'))
    thing = store.types['no_such_pkg/msg/Thing'](value=3)
    msgs = h.sample_messages(2) + [('/thing', 'no_such_pkg/msg/Thing', h.T0 + 50,
                                    bytes(store.serialize_cdr(thing, 'no_such_pkg/msg/Thing')))]
    bag = h.write_bag(tmp_path / 'bag', sorted(msgs, key=lambda m: m[2]), store=store)
    player = _player(ros_context, bag=str(bag), rate=5.0)
    assert '/thing' not in [p.bag_topic for p in player.plan]
    collector = h.RawCollector(ros_context, TYPES)
    _play(ros_context, player, collector, 8)
    assert player.published_counts == {t: 2 for t in TYPES}


def test_clock_and_exit_when_done(tmp_path, ros_context):
    """exit_when_done shuts the player's context down once the last message is delivered."""
    import rclpy

    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(4))
    player = _player(ros_context, bag=str(bag), rate=2.0, publish_clock=True,
                     exit_when_done=True)
    # the subscriber lives in another context (as in another process) on the same domain
    other = rclpy.Context()
    rclpy.init(context=other, domain_id=ros_context.get_domain_id())
    try:
        collector = h.RawCollector(other, {'/clock': 'rosgraph_msgs/msg/Clock',
                                           h.LEFT: 'sensor_msgs/msg/Image'})
        spinner = h.Spinner(other, collector.node)
        try:
            assert player.wait_for_subscribers(1, 10.0, topics=[h.LEFT])
            assert h.wait_for(lambda: player._clock_pub.get_subscription_count() >= 1, 10.0)
            assert collector.wait_matched()
            player.start()
            assert player.play_done.wait(10.0)
            # the context is shut down, so rclpy.spin in main() returns
            assert h.wait_for(lambda: not ros_context.ok(), 2.0)
            # every frame was acknowledged before that: none is lost
            assert h.wait_for(lambda: len(collector.data(h.LEFT)) == 4, 5.0)
        finally:
            spinner.stop()
    finally:
        other.try_shutdown()
    from rclpy.serialization import deserialize_message
    from rosgraph_msgs.msg import Clock
    clocks = [deserialize_message(d, Clock).clock for d in collector.data('/clock')]
    ns = [c.sec * 10**9 + c.nanosec for c in clocks]
    assert len(ns) >= 4 and ns == sorted(ns)
    assert h.T0 <= ns[0] and ns[-1] <= h.T0 + 3 * h.STEP + 3000


def test_a_player_started_paused_plays_nothing_until_resumed(tmp_path, ros_context):
    """start_paused holds the first message until ~/resume (std_srvs/Trigger) is called,
    as `ros2 bag play --start-paused`; a second call says it is already playing."""
    from std_srvs.srv import Trigger

    msgs = h.sample_messages(4)
    bag = h.write_bag(tmp_path / 'bag', msgs)
    player = _player(ros_context, bag=str(bag), rate=5.0, start_paused=True)
    collector = h.RawCollector(ros_context, TYPES)
    client = collector.node.create_client(Trigger, '/bag_player_node/resume')
    spinner = h.Spinner(ros_context, player, collector.node)
    try:
        assert collector.wait_matched([p.out_topic for p in player.plan])
        player.start()
        time.sleep(1.0)                     # 4 messages at rate 5 would take 0.6 s
        assert collector.count() == 0 and not player.play_done.is_set()
        assert client.wait_for_service(timeout_sec=5.0)
        answers = []
        for _ in range(2):
            future = client.call_async(Trigger.Request())
            assert h.wait_for(future.done, 5.0)
            answers.append((future.result().success, future.result().message))
            if len(answers) == 1:
                assert player.play_done.wait(10.0)
        assert answers == [(True, 'playing'), (False, 'already playing')]
        assert h.wait_for(lambda: collector.count() >= len(msgs), 5.0), collector.count()
    finally:
        spinner.stop()


def test_waits_for_image_and_camera_info_subscribers(tmp_path, ros_context):
    """With wait_for_subscribers, a subscriber that comes late still gets every frame and
    every camera_info: the player waits for both (a stereo node needs both; on a loaded
    machine the camera_info subscription once matched 2 s after the images', and the
    frames before it were lost)."""
    from asmonc_vision.nodes.player_node import BagPlayerNode

    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(3))
    player = BagPlayerNode(PlayerConfig(bag=str(bag), rate=5.0, wait_for_subscribers=1,
                                        exit_when_done=False), context=ros_context)
    assert sorted(player.camera_topics) == sorted([h.LEFT, h.LEFT_INFO])
    time.sleep(0.4)
    assert not player.play_done.is_set() and sum(player.published_counts.values()) == 0
    images = h.RawCollector(ros_context, {h.LEFT: 'sensor_msgs/msg/Image'})
    spinner = h.Spinner(ros_context, player, images.node)
    try:
        time.sleep(0.6)     # the image subscriber alone does not start the replay
        assert sum(player.published_counts.values()) == 0
        infos = h.RawCollector(ros_context, {h.LEFT_INFO: 'sensor_msgs/msg/CameraInfo'},
                               name='infos')
        spinner.add(infos.node)
        assert player.play_done.wait(10.0)
        assert h.wait_for(lambda: images.count() >= 3 and infos.count() >= 3, 5.0)
    finally:
        spinner.stop()
        player.destroy_node()
    sent = h.by_topic(h.sample_messages(3))
    assert images.data(h.LEFT) == sent[h.LEFT]
    assert infos.data(h.LEFT_INFO) == sent[h.LEFT_INFO]


class _Answerer:
    """A node that receives the left images and answers each, on /answers, only when the
    test says so (`answer(i)`: the i-th image received)."""

    def __init__(self, ctx):
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Image

        from asmonc_vision_msgs.msg import ObstacleArray

        self.node = Node('answerer', context=ctx)
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.images = []
        self.sub = self.node.create_subscription(Image, h.LEFT, self.images.append, qos)
        self.pub = self.node.create_publisher(ObstacleArray, '/answers', qos)
        self._cls = ObstacleArray

    def answer(self, i: int) -> None:
        self.pub.publish(self._cls(header=self.images[i].header))


def _paced_player(ctx, bag, **settings):
    settings = dict(dict(bag=str(bag), rate=5.0, pace_topic='/answers',
                         pace_type='asmonc_vision_msgs/msg/ObstacleArray',
                         pace_image_topic=h.LEFT, pace_lead=2, pace_timeout=30.0,
                         topics=(h.LEFT,)), **settings)
    return _player(ctx, **settings)


def test_a_paced_replay_waits_for_the_answers_and_skipped_images_cost_no_wait(
        tmp_path, ros_context):
    """Paced by a node's answers (`asmonc run` paces by /obstacles): at most pace_lead
    images go unanswered; an answer also settles the images sent before it (pairs the
    node skipped), so they cost no wait; every image is played in the end."""
    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(11))
    player = _paced_player(ros_context, bag)
    node = _Answerer(ros_context)
    spinner = h.Spinner(ros_context, player, node.node)
    try:
        assert player.wait_for_subscribers(1, 10.0, topics=[h.LEFT])
        assert h.wait_for(lambda: node.sub.get_publisher_count() >= 1
                          and node.pub.get_subscription_count() >= 1)
        player.start()
        # 11 frames at rate 5 take 0.2 s: without answers, lead + 1 images go out and stop
        assert h.wait_for(lambda: len(node.images) == 3)
        time.sleep(0.6)
        assert len(node.images) == 3 and player.published_counts[h.LEFT] == 3
        node.answer(0)                          # one answered: one more goes
        assert h.wait_for(lambda: len(node.images) == 4)
        time.sleep(0.3)
        assert len(node.images) == 4
        node.answer(3)                          # settles 1 and 2 as well (skipped by it)
        assert h.wait_for(lambda: len(node.images) == 7)
        time.sleep(0.3)
        assert len(node.images) == 7
        for i in range(7, 11):                  # from here on every image is answered
            node.answer(i - 1)
            assert h.wait_for(lambda i=i: len(node.images) >= i + 1)
        assert player.play_done.wait(10.0)
    finally:
        spinner.stop()
    assert player.published_counts[h.LEFT] == 11 and player.pace_given_up == 0
    assert player.pace_holds >= 3 and player.pace_held_s > 1.0


def test_a_paced_replay_whose_node_never_answers_waits_once_then_plays_on(
        tmp_path, ros_context, capfd):
    """A node that answers nothing (it refuses every pair, or has died) costs one
    pace_timeout, not one per image: the replay then keeps the bag's rate."""
    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(11))
    player = _paced_player(ros_context, bag, pace_timeout=0.5)
    collector = h.RawCollector(ros_context, {h.LEFT: 'sensor_msgs/msg/Image'})
    spinner = h.Spinner(ros_context, player, collector.node)
    try:
        assert player.wait_for_subscribers(1, 10.0, topics=[h.LEFT])
        assert collector.wait_matched()
        start = time.monotonic()
        player.start()
        assert player.play_done.wait(10.0)
        took = time.monotonic() - start
        assert h.wait_for(lambda: collector.count() == 11, 5.0)
    finally:
        spinner.stop()
    assert player.pace_holds == 1 and player.pace_given_up == 3
    assert took < 5 * 0.5                       # one hold, not one per image
    assert 'no answer on /answers within 0.5 s for 3 image(s)' in capfd.readouterr().err


def test_pacing_needs_a_message_type():
    with pytest.raises(ValueError, match='pace_type'):
        PlayerConfig(bag='x', pace_topic='/obstacles')


# --- the process ----------------------------------------------------------------------

def _run_player(bag, timeout: float = 60.0, *params: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, '-m', 'asmonc_vision.nodes.player_node', '--ros-args',
           '-p', f'bag:={bag}', *[a for p in params for a in ('-p', p)]]
    return subprocess.run(cmd, env=h.subprocess_env(h.next_domain_id()), capture_output=True,
                          text=True, timeout=timeout)


def _start_player(bag, *params: str) -> subprocess.Popen:
    cmd = [sys.executable, '-m', 'asmonc_vision.nodes.player_node', '--ros-args',
           '-p', f'bag:={bag}', *[a for p in params for a in ('-p', p)]]
    return subprocess.Popen(cmd, env=h.subprocess_env(h.next_domain_id()),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_process_exit_codes_and_error_lines(tmp_path):
    good = h.write_bag(tmp_path / 'good', h.sample_messages(3))
    big, _ = h.big_bag(tmp_path)  # two MCAP chunks
    data = (big / 'big.mcap').read_bytes()
    half = tmp_path / 'half.mcap'
    half.write_bytes(data[:int(len(data) * 0.75)])
    early = tmp_path / 'early.mcap'
    early.write_bytes(data[:100])
    missing = tmp_path / 'missing_bag'
    # all four processes at once: each pays the ROS start-up only in parallel
    procs = {name: _start_player(path, 'rate:=10.0') for name, path in
             [('good', good), ('half', half), ('early', early), ('missing', missing)]}
    out = {}
    for name, p in procs.items():
        try:
            stdout, stderr = p.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            stdout, stderr = p.communicate()
        out[name] = (p.returncode, stdout + stderr)

    rc, log = out['good']
    assert rc == 0, log
    assert 'published 12 messages' in log

    rc, log = out['missing']
    assert rc == 2, log
    assert '[ERROR]' in log and f"bag '{missing}' does not exist" in log

    rc, log = out['early']
    assert rc == 2, log
    assert '[ERROR]' in log and 'early.mcap' in log and 'truncated or corrupt' in log

    rc, log = out['half']
    assert rc == 2, log
    played = [ln for ln in log.splitlines() if 'published' in ln]
    assert played and 'published 0 messages' not in played[0], log
    errors = [ln for ln in log.splitlines() if '[ERROR]' in ln]
    assert any('half.mcap' in ln and 'truncated' in ln for ln in errors), log


def test_loop_until_stopped_and_wait_timeout(tmp_path, ros_context):
    from asmonc_vision.nodes.player_node import BagPlayerNode

    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(2))  # 0.1 s long
    # nobody subscribes: after wait_timeout it plays anyway, and loops until stopped
    player = BagPlayerNode(PlayerConfig(bag=str(bag), rate=10.0, loop=True,
                                        wait_for_subscribers=1, wait_timeout=0.2,
                                        exit_when_done=True), context=ros_context)
    try:
        assert h.wait_for(lambda: player.passes >= 3, 10.0)
        assert not player.play_done.is_set()
    finally:
        player.destroy_node()  # stops the thread
    assert player.play_done.is_set()
    assert player.published_counts[h.LEFT] >= 6
    assert ros_context.ok()  # a stop is not "done": the context stays up
