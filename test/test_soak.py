"""The soak's pieces: /proc sampling, growth after the warm-up, the table, the command's
arguments; the player's restamped loop; the audio node's streamed WAV; and one short
soak of the whole graph."""
from __future__ import annotations

import os
import struct
import wave

import numpy as np
import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from asmonc_vision.soak import ProcSample, format_table, growth, read_proc  # noqa: E402
from conftest import BAGS  # noqa: E402


def test_read_proc_reads_this_process_and_none_for_a_gone_one():
    s = read_proc(os.getpid(), 1.5)
    assert s is not None and s.t == 1.5
    assert s.rss_kb > 1000 and s.fds >= 3
    fd = os.open(os.devnull, os.O_RDONLY)
    try:
        assert read_proc(os.getpid(), 2.0).fds == s.fds + 1
    finally:
        os.close(fd)
    assert read_proc(2 ** 22 + 12345, 0.0) is None


def test_growth_counts_from_the_end_of_the_warm_up():
    # 100 MiB, +1 MiB per minute after a warm-up in which it jumped by 50 MiB
    samples = [ProcSample(0.0, 50 * 1024, 10), ProcSample(30.0, 100 * 1024, 12)]
    samples += [ProcSample(60.0 + 60.0 * i, (100 + i) * 1024, 12 + (i == 5)) for i in range(6)]
    g = growth(samples, warmup=60.0)
    assert g['rss_start_mb'] == 100.0 and g['rss_end_mb'] == 105.0
    assert g['rss_growth_mb'] == pytest.approx(5.0)
    assert g['rss_slope_mb_per_h'] == pytest.approx(60.0)
    assert (g['fds_start'], g['fds_end'], g['fds_growth']) == (12, 13, 1)
    assert g['samples'] == 6 and g['span_s'] == 300.0
    assert growth(samples[:3], warmup=60.0) is None          # one sample after warm-up
    lines = format_table({'detector': g, 'alarm': None})
    assert 'detector' in lines[2] and '+5.0M' in lines[2] and '+60.0' in lines[2]
    assert 'too short' in lines[3]


def test_the_soak_command_refuses_bad_arguments(capsys):
    from asmonc_vision.cli.main import main
    assert main(['soak', str(BAGS / 'walk_obstacles'), '--minutes', '1',
                 '--warmup', '55', '--period', '10']) == 2
    assert 'two samples' in capsys.readouterr().err
    assert main(['soak', str(BAGS / 'walk_obstacles'), '--rate', '0']) == 2


def test_restamp_moves_a_header_stamp_and_only_header_types_have_one():
    from asmonc_vision.io.bagio import has_header
    from asmonc_vision.io.bagplay import LOOP_GAP, loop_period_ns, restamp_cdr
    for end, enc in (('<', 1), ('>', 0)):
        data = bytes([0, enc, 0, 0]) + struct.pack(end + 'iI', 7, 900_000_000) + b'rest'
        out = restamp_cdr(data, 250_000_000)
        assert struct.unpack_from(end + 'iI', out, 4) == (8, 150_000_000)
        assert out[12:] == b'rest' and restamp_cdr(data, 0) == data
    assert has_header('sensor_msgs/msg/Imu') and has_header('sensor_msgs/msg/CameraInfo')
    assert not has_header('std_msgs/msg/String') and not has_header('nope/msg/Nope')

    class Info:
        end_ns = 10_000_000_000
    assert loop_period_ns(Info, 2_000_000_000) == 8_000_000_000 + int(LOOP_GAP * 1e9)


def test_a_restamped_loop_keeps_stamps_increasing(tmp_path, ros_context):
    import test_bagplay_helpers as h
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo

    from asmonc_vision.io.bagplay import PlayerConfig
    from asmonc_vision.nodes.player_node import BagPlayerNode

    bag = h.write_bag(tmp_path / 'bag', h.sample_messages(3))
    probe = Node('restamp_probe', context=ros_context)
    stamps: list[int] = []
    topic = h.LEFT_INFO
    probe.create_subscription(CameraInfo, topic, lambda m: stamps.append(
        m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec), qos_profile_sensor_data)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(probe)
    player = BagPlayerNode(PlayerConfig(bag=str(bag), rate=5.0, loop=True, loop_restamp=True,
                                        wait_topics=(f'{topic}=1',), wait_timeout=5.0),
                           context=ros_context)
    try:
        assert h.wait_for(lambda: (ex.spin_once(timeout_sec=0.01), player.passes >= 3)[1],
                          20.0)
        for _ in range(20):
            ex.spin_once(timeout_sec=0.01)
    finally:
        player.destroy_node()
        probe.destroy_node()
    assert len(stamps) >= 6
    assert all(b > a for a, b in zip(stamps, stamps[1:])), stamps
    # a pass is shifted by the bag's span plus the loop gap
    first = stamps[:3]
    assert stamps[3] - first[0] == player.source.info.end_ns - player.source.info.start_ns \
        + 100_000_000


def test_the_streamed_wav_equals_the_whole_mix(tmp_path):
    from asmonc_vision.core.audio import Soundtrack, read_wav, write_wav
    from asmonc_vision.nodes.audio_node import WavStream

    rate = 8000
    track, whole = Soundtrack(rate), Soundtrack(rate)
    rng = np.random.default_rng(0)
    stream = WavStream(str(tmp_path / 'stream.wav'), rate)
    for i in range(30):                   # a tone every 0.4 s; the past trimmed as it goes
        tone = (0.3 * rng.standard_normal((800, 2))).astype(np.float32)
        track.add_tone(0.4 * i, tone)
        whole.add_tone(0.4 * i, tone)
        cut = int((0.4 * i - 1.0) * rate)
        if cut > 0:
            stream.write_until(track, cut)
            track.trim(cut)
    end = int(13.0 * rate)
    stream.finish(track, end)
    write_wav(tmp_path / 'whole.wav', whole.mix(13.0), rate)
    a, _ = read_wav(tmp_path / 'stream.wav')
    b, _ = read_wav(tmp_path / 'whole.wav')
    assert a.shape == b.shape == (end, 2)
    assert np.array_equal(a, b)
    assert len(track._tones) < 3 * rate       # only the recent sound was kept
    with wave.open(str(tmp_path / 'stream.wav')) as w:
        assert w.getnframes() == end


@pytest.mark.e2e          # (its processes are started by the command, out of conftest's sight)
def test_a_short_soak_of_the_whole_graph(capsys):
    """18 s of the walking bag looped at twice its rate through every node (the replay
    paced by the detector, as at rate 1): no process dies, every pair played gets its
    result, and each node is sampled."""
    from asmonc_vision.cli.main import main
    rc = main(['soak', str(BAGS / 'walk_obstacles'), '--minutes', '0.3', '--rate', '2',
               '--warmup', '3', '--period', '4'])
    out = capsys.readouterr().out
    assert rc == 0, out
    for name in ('detector', 'egomotion', 'gait', 'alarm', 'audio', 'player'):
        assert any(ln.startswith(name) and 'MB' in ln for ln in out.splitlines()), out
    line = next(ln for ln in out.splitlines() if ln.startswith('stereo pairs in'))
    pairs, results = int(line.split()[3].rstrip(',')), int(line.split()[6].rstrip(','))
    assert pairs > 75                     # more than one pass of the 7.5 s bag
    assert results >= pairs - 5
