"""End to end: `asmonc run` replays committed bags through the real node graph
(player, detector and alarm nodes in their own processes), records the outputs, and
the recorded /obstacles are scored against the bag's ground truth here, independently
of the command's own summary."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from asmonc_vision.io import bagio
from asmonc_vision.io.frames import frame_from_obstacle_array
from asmonc_vision.eval.evaluation import score_sequence
from conftest import BAGS, fault_timeline


def asmonc_run(*args, timeout=240, **env_overrides):
    """`asmonc run ARGS` in its own process; on `timeout` its threads' stacks (SIGUSR1,
    `cli.main`) are in the failure's message."""
    env = dict(os.environ, **env_overrides)
    proc = subprocess.Popen([sys.executable, '-m', 'asmonc_vision.cli', 'run', *map(str, args)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(2.0)
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f'asmonc run {args} still running after {timeout} s:\n{out}\n{err}')
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def node_logs(out, lines=15):
    """The last lines of each node's log that `asmonc run --out DIR` kept (DIR/logs),
    for a failure's message."""
    return '\n'.join(f'--- {p.name}\n' + '\n'.join(p.read_text().splitlines()[-lines:])
                     for p in sorted((out / 'logs').glob('*.log')))


def strict_json(path):
    """The JSON file at path, refusing NaN and Infinity (not JSON: other readers fail)."""
    def refuse(name):
        raise ValueError(f'{path} holds {name}, which is not JSON')
    return json.loads(path.read_text(), parse_constant=refuse)


def asmonc_run_refused(capsys, *args) -> str:
    """`asmonc run` in this process, for arguments it must refuse before starting any
    node (exit status 2, checked here): what it said on stderr. (The process's own exit
    status is that of `main`, as the runs above show.)"""
    from asmonc_vision.cli.main import main
    capsys.readouterr()
    assert main(['run', *map(str, args)]) == 2
    return capsys.readouterr().err


def frames(bag, topic):
    return {bagio.header_stamp_ns(m): frame_from_obstacle_array(m)
            for _, _, m in bagio.read_messages(bag, [topic])}


@pytest.fixture(scope='module')
def static_run(tmp_path_factory):
    out = tmp_path_factory.mktemp('static') / 'out'
    res = asmonc_run(BAGS / 'static_obstacles', '--out', out, '--no-progress')
    return res, out


def test_static_bag_every_true_obstacle_is_reported(static_run):
    res, out = static_run
    assert res.returncode == 0, res.stdout + res.stderr
    n_pairs = bagio.bag_topics(BAGS / 'static_obstacles')['/stereo/left/image_rect'][1]
    det = frames(out, '/obstacles')
    truth = frames(BAGS / 'static_obstacles', '/ground_truth/obstacles')
    # an /obstacles message for every input pair: nothing dropped at rate 1
    assert len(det) == n_pairs == len(truth)
    assert set(det) == set(truth)
    score, missing = score_sequence(det, truth, match_radius=0.3, min_height=0.10,
                                    max_range=5.0)
    assert missing == []
    eligible = {k: o for k, o in score.obstacles.items() if o.frames_eligible}
    assert len(eligible) >= 4
    for oid, o in eligible.items():
        # reported within 0.3 m of its true position, in most of the frames it is in view
        assert o.detected, f'obstacle {oid} ({o.height:.2f} m high) missed: ' \
                           f'{o.frames_detected}/{o.frames_eligible} frames'
    assert score.false_per_frame < 0.1
    # the command's own summary agrees
    summary = strict_json(out / 'summary.json')
    assert summary['dropped_frames'] == 0
    # paced by /obstacles (the default): nothing given up
    assert summary['replay']['mode'] == 'paced' and summary['replay']['pairs_given_up'] == 0
    assert summary['ground_truth']['detected'] == score.detected
    assert 'WARNING' in summary['alarms'] or 'STOP' in summary['alarms']
    # every true obstacle that lay on the walking path was warned of before it came
    # within the WARNING range, and no frame with one there was silent
    pw = summary['path_warnings']
    assert pw['on_path'] >= 1 and pw['warned_in_time'] == pw['on_path'], pw
    assert pw['frames_unwarned'] == 0 and pw['criteria']['warning_range'] == 2.5
    assert 'obstacles on the path' in res.stdout
    assert '=== summary ===' in res.stdout and 'DETECTED' in res.stdout
    # the end of the replay is not reported as a silent inclinometer (the gait filter is
    # halted once the bag has been played and its last states are out)
    assert 'silent' not in res.stderr, res.stderr


def test_static_bag_outputs_are_recorded(static_run):
    _, out = static_run
    topics = bagio.bag_topics(out)
    for t in ('/obstacles', '/ground_plane', '/alarms', '/obstacles/markers', '/diagnostics'):
        assert topics.get(t, ('', 0))[1] > 0, f'{t} not recorded: {topics}'
    planes = [m for _, _, m in bagio.read_messages(out, ['/ground_plane'])]
    assert planes[-1].status == 1
    assert planes[-1].height == pytest.approx(1.25, abs=0.05)
    # the nodes' logs are kept beside the bag
    assert (out / 'logs' / 'detector.log').exists()


def test_clear_path_standing_still_gives_no_alarm(tmp_path):
    out = tmp_path / 'out'
    # strictly at the bag's rate, as a live camera (the default paces by the detector)
    res = asmonc_run(BAGS / 'clear_static', '--out', out, '--no-progress', '--realtime')
    assert res.returncode == 0, res.stdout + res.stderr
    summary = strict_json(out / 'summary.json')     # strict: no NaN where nothing is eligible
    assert summary['replay']['mode'] == 'realtime'
    assert summary['ground_truth']['eligible'] == 0 and summary['ground_truth']['recall'] is None
    assert 'pacing' not in (out / 'logs' / 'player.log').read_text()
    alarms = [m for _, _, m in bagio.read_messages(out, ['/alarms'])]
    assert alarms, 'the alarm node said nothing at all'
    obstacle_alarms = [a.text for a in alarms if a.level in (1, 2, 3)]  # CAUTION..STOP
    assert obstacle_alarms == []
    assert any(a.level == 0 for a in alarms)  # "all clear" was said once the ground was seen
    det = frames(out, '/obstacles')
    assert sum(len(f) for f in det.values()) <= 1


def _without_right_images(src, dst, drop):
    """Copy the bag ``src`` to ``dst`` without the right images of indices ``drop``."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    right = bagio.TOPICS['right_image'][0]
    with Reader(src) as reader:
        stamps = [t for c, t, _ in reader.messages() if c.topic == right]
        gone = {stamps[i] for i in drop}
        with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {c.id: writer.add_connection(
                c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest,
                offered_qos_profiles=c.ext.offered_qos_profiles) for c in reader.connections}
            for c, t, raw in reader.messages():
                if not (c.topic == right and t in gone):
                    writer.write(conns[c.id], t, raw)
    return len(gone)


def test_missing_right_images_are_not_announced_as_a_fault(tmp_path):
    """A recording that lost right images (one mid-way, the last one): those pairs give
    no result, the others are processed, and the end of the replay, which leaves the
    results short of the pairs, is not announced to the wearer as a fault (the alarm
    node is stopped once every frame has been played and the results have stopped)."""
    bag = tmp_path / 'lost_right'
    assert _without_right_images(BAGS / 'clear_static', bag, [5, -1]) == 2
    # the pairs the bag plays: the alarm node is halted once it has answered each
    all_pairs = bagio.pair_stamps(BAGS / 'clear_static')      # in the bag's order
    assert len(all_pairs) == 30 and all_pairs == sorted(all_pairs)
    assert bagio.pair_stamps(bag) == all_pairs[:5] + all_pairs[6:-1]
    out = tmp_path / 'out'
    # the two lost pairs never come: a 2 s wait for late results is enough
    res = asmonc_run(bag, '--out', out, '--no-progress', '--settle', 2)
    assert res.returncode == 1, res.stdout + res.stderr       # 1: frames were dropped
    assert '28 of 30 processed, 2 dropped' in res.stdout, res.stdout + node_logs(out)
    summary = strict_json(out / 'summary.json')
    assert summary['dropped_frames'] == 2 and not summary['errors']
    assert summary['processed_frames'] == summary['input_pairs'] - 2
    levels = [m.level for _, _, m in bagio.read_messages(out, ['/alarms'])]
    assert levels[0] == 4 and 0 in levels                    # "starting up", then clear
    assert 4 not in levels[levels.index(0):], (levels, fault_timeline(out))  # no FAULT after


def test_the_alarm_timeout_comes_from_the_params_files(tmp_path):
    """`asmonc run` stops the alarm node after half its timeout of silence at the end:
    the timeout is the alarm node's own (default, or the last params file setting it)."""
    from asmonc_vision.replay.params import alarm_timeout as _alarm_timeout
    from asmonc_vision.core.alarm import AlarmConfig
    assert _alarm_timeout([]) == AlarmConfig().timeout
    a, b, bad = tmp_path / 'a.yaml', tmp_path / 'b.yaml', tmp_path / 'bad.yaml'
    a.write_text('alarm_node:\n  ros__parameters:\n    timeout: 2.5\n'
                 'detector_node:\n  ros__parameters:\n    timeout: 9.0\n')
    b.write_text('/**:\n  ros__parameters:\n    timeout: 0.4\n')
    bad.write_text('alarm_node: [unclosed\n')
    assert _alarm_timeout([a]) == 2.5
    assert _alarm_timeout([a, b]) == 0.4
    assert _alarm_timeout([a, bad, tmp_path / 'missing.yaml']) == 2.5


def test_the_gait_timeout_comes_from_the_params_files(tmp_path):
    from asmonc_vision.replay.params import gait_timeout as _gait_timeout
    from asmonc_vision.nodes.gait_node import GaitNodeConfig
    assert _gait_timeout([]) == GaitNodeConfig().timeout
    a = tmp_path / 'a.yaml'
    a.write_text('gait_filter_node:\n  ros__parameters:\n    timeout: 3.0\n'
                 'alarm_node:\n  ros__parameters:\n    timeout: 9.0\n')
    assert _gait_timeout([a]) == 3.0


class _FakeChild:
    def __init__(self, alive=True):
        import threading
        self.done = threading.Event()
        self._alive = alive
        self.stop_calls = []
        self.freeze_calls = []
        self.frozen = False

    def alive(self):
        return self._alive

    def freeze(self):
        import time
        self.freeze_calls.append(time.monotonic())
        self.frozen = True

    def stop(self):
        import time
        self.stop_calls.append(time.monotonic())
        self._alive = False


class _FakeMonitor:
    def __init__(self):
        import threading
        self.lock = threading.Lock()
        self.gait_states = 0
        self.last_gait_at = None

    def state(self):
        import time
        with self.lock:
            self.gait_states += 1
            self.last_gait_at = time.monotonic()


def test_a_player_that_played_the_bag_but_does_not_exit_does_not_hang_the_run(monkeypatch):
    """The player said it published the whole bag and then never exits, and one pair
    never gives a result: the replay stops the alarm node (before its timeout calls the
    end a fault), goes on without the player after PLAYER_EXIT_GRACE and stops it."""
    import threading
    from types import SimpleNamespace

    from asmonc_vision.replay import session
    monkeypatch.setattr(session, 'PLAYER_EXIT_GRACE', 0.3)
    run = object.__new__(session.Replay)
    player, alarm = _FakeChild(), _FakeChild()
    player.done.set()
    lines = []
    run.monitor = SimpleNamespace(lock=threading.Lock(), frames=5, played=0,
                                  last_result_at=time.monotonic(),
                                  take_new_alarms=lambda: [])
    run.children = {'player': player, 'alarm': alarm}
    run.plan = SimpleNamespace(n_pairs=6, topics={})
    run.args = SimpleNamespace(params_file=[], settle=0.2)
    run.console = SimpleNamespace(bar=lambda n: None,
                                  line=lambda text, err=False: lines.append(text))
    run.injector = SimpleNamespace(poll=lambda: None)
    run.check_nodes = lambda: None
    run.stopped, run.player_hung, run.gait_stopper, run.player_rc = set(), False, None, None
    run.end_watch = None
    t0 = time.monotonic()
    waiting = threading.Thread(target=run.wait_for_results, daemon=True)
    waiting.start()
    waiting.join(timeout=10.0)
    assert not waiting.is_alive(), 'the replay waits for the player for ever'
    assert run.player_hung and any('had not exited' in line for line in lines), lines
    assert alarm.freeze_calls and alarm.freeze_calls[0] < t0 + 0.5   # before its timeout
    run.finish()
    assert player.stop_calls and run.player_rc is None


def test_a_node_is_connected_once_it_logs_that_its_inputs_from_the_graph_are_linked(tmp_path):
    """Seen in the ROS graph is not yet linked between two processes: a node with an input
    that another running node publishes counts as connected only once its log says the
    subscription has matched a publisher (`watch_input_links`)."""
    from types import SimpleNamespace

    from asmonc_vision.graph import GraphNode
    from asmonc_vision.nodes.common import LINKED_LINE
    from asmonc_vision.replay.children import Child, connected

    line = '[INFO] [1.5] [alarm_node]: ' + LINKED_LINE.format(topic='/obstacles', n=2)
    child = Child('alarm', [sys.executable, '-c', f'print({line!r})'], tmp_path,
                  lambda s: None, dict(os.environ))
    assert child.proc.wait(timeout=30) == 0
    child.stop()
    assert child.linked == {'/obstacles'}
    everyone = [SimpleNamespace(node_name='alarm_node')]
    graph = SimpleNamespace(get_publishers_info_by_topic=lambda t: everyone,
                            get_subscriptions_info_by_topic=lambda t: everyone)
    spec = GraphNode('alarm', 'alarm_node', 'm', 'alarm_node', 'images', ('/alarms',),
                     ('/obstacles', '/gait/state'), 'alarm.yaml')
    assert connected(graph, spec, False, child, frozenset({'/obstacles', '/other'}))
    # an input of the graph not yet linked; and one without a producer is not waited for
    assert not connected(graph, spec, False, child, frozenset({'/gait/state'}))
    assert connected(graph, spec, False, child, frozenset())


def test_the_gait_node_is_stopped_after_its_last_state_not_before():
    """The end of a replay: the gait node is stopped once the player is done and no
    state has come for `quiet` s (or every reading has its state), whatever else the
    harness is doing (its own thread)."""
    import time

    from asmonc_vision.replay.children import GaitStopper as _GaitStopper
    gait, player, monitor = _FakeChild(), _FakeChild(), _FakeMonitor()
    stopper = _GaitStopper(gait, player, monitor, n_imu=100, quiet=0.2)
    stopper.start()
    time.sleep(0.4)
    assert not gait.freeze_calls                    # the bag is still being played
    player.done.set()
    # states still coming in (a node catching up): not stopped while they come
    t_end = time.monotonic() + 0.6
    while time.monotonic() < t_end:
        monitor.state()
        time.sleep(0.05)
    last = monitor.last_gait_at
    assert not gait.freeze_calls and not stopper.stopping.is_set()
    stopper.join(timeout=2.0)
    assert len(gait.freeze_calls) == 1 and stopper.stopping.is_set()
    assert 0.2 <= gait.freeze_calls[0] - last < 0.5

    # every reading has its state: stopped at once, without waiting for the quiet time
    gait, player, monitor = _FakeChild(), _FakeChild(), _FakeMonitor()
    stopper = _GaitStopper(gait, player, monitor, n_imu=3, quiet=5.0)
    stopper.start()
    for _ in range(3):
        monitor.state()
    player.done.set()
    t0 = time.monotonic()
    stopper.join(timeout=2.0)
    assert len(gait.freeze_calls) == 1 and gait.freeze_calls[0] - t0 < 0.5

    # a player that dies without saying it is done counts as done; cancel() ends the
    # thread without stopping anything
    gait, player, monitor = _FakeChild(), _FakeChild(alive=False), _FakeMonitor()
    stopper = _GaitStopper(gait, player, monitor, n_imu=3, quiet=0.1)
    stopper.start()
    stopper.join(timeout=2.0)
    assert len(gait.freeze_calls) == 1
    gait, player = _FakeChild(), _FakeChild()
    stopper = _GaitStopper(gait, player, _FakeMonitor(), n_imu=3, quiet=0.1)
    stopper.start()
    stopper.cancel()
    stopper.join(timeout=2.0)
    assert not stopper.is_alive() and not gait.freeze_calls


def test_domain_id_out_of_range_is_a_clear_error(capsys, monkeypatch):
    monkeypatch.setenv('ROS_DOMAIN_ID', '500')
    err = asmonc_run_refused(capsys, BAGS / 'clear_static')
    assert 'ROS_DOMAIN_ID must be in [0, 232]' in err and 'got 500' in err


def test_missing_bag_is_a_clear_error(tmp_path, capsys):
    assert 'does not exist' in asmonc_run_refused(capsys, tmp_path / 'no_such_bag')


def test_truncated_bag_replays_what_can_be_read(tmp_path, capsys):
    """A bag cut short (a recording that crashed): the messages before the cut are
    replayed and scored, the cut is reported, and the exit status says the bag ended in
    error. Cut to nothing readable, it is a clear error."""
    src = next((BAGS / 'static_obstacles').glob('*.mcap'))
    cut = tmp_path / 'cut.mcap'
    data = src.read_bytes()
    cut.write_bytes(data[:len(data) // 2])
    out = tmp_path / 'out'
    res = asmonc_run(cut, '--out', out, '--no-progress')
    assert res.returncode == 1, res.stderr[-2000:]
    assert 'cut.mcap' in res.stderr and 'truncated' in res.stderr
    assert 'replaying the messages before it' in res.stderr
    summary = strict_json(out / 'summary.json')
    assert 10 <= summary['input_pairs'] < 55
    assert summary['processed_frames'] == summary['input_pairs'], node_logs(out)
    assert summary['player_exit_code'] == 2 and summary['errors']
    assert len(frames(out, '/obstacles')) == summary['processed_frames']
    assert summary['ground_truth']                   # the truth before the cut is scored
    (tmp_path / 'none.mcap').write_bytes(data[:200])
    err = asmonc_run_refused(capsys, tmp_path / 'none.mcap')
    assert 'none.mcap' in err and 'cannot be read' in err


def test_bag_with_neither_cameras_nor_inclinometer_is_a_clear_error(tmp_path, capsys):
    from rosbags.rosbag2 import StoragePlugin, Writer
    store = bagio.typestore()
    Imu = store.types['sensor_msgs/msg/Imu']
    with Writer(tmp_path / 'imu_only', version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection('/some/other/imu', 'sensor_msgs/msg/Imu', typestore=store)
        msg = Imu(header=store.types['std_msgs/msg/Header'](
            stamp=store.types['builtin_interfaces/msg/Time'](sec=1, nanosec=0), frame_id='x'),
            orientation=store.types['geometry_msgs/msg/Quaternion'](x=0, y=0, z=0, w=1),
            orientation_covariance=np.zeros(9), angular_velocity=store.types[
                'geometry_msgs/msg/Vector3'](x=0, y=0, z=0),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=store.types['geometry_msgs/msg/Vector3'](x=0, y=0, z=0),
            linear_acceleration_covariance=np.zeros(9))
        w.write(c, 1, store.serialize_cdr(msg, 'sensor_msgs/msg/Imu'))
    err = asmonc_run_refused(capsys, tmp_path / 'imu_only')
    assert 'no /stereo/left/image_rect messages and no /inclinometer/imu messages' in err


def test_inclinometer_only_bag_runs_the_walk_model_alone(tmp_path):
    # An IMU-only recording: the /inclinometer/imu stream of a committed walking bag.
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    bag = tmp_path / 'imu_only'
    with Reader(BAGS / 'walk_stop_turn') as r, \
            Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = [c for c in r.connections if c.topic == '/inclinometer/imu']
        out = w.add_connection('/inclinometer/imu', 'sensor_msgs/msg/Imu',
                               typestore=bagio.typestore())
        n_imu = 0
        for _, t, raw in r.messages(connections=conns):
            w.write(out, t, raw)
            n_imu += 1
    res = asmonc_run(bag, '--out', tmp_path / 'out', '--no-progress')
    assert res.returncode == 0, res.stdout + res.stderr
    assert 'no stereo images in this bag' in res.stdout
    assert res.stdout.count('no stereo images') == 1  # said once, not as an error
    # the end of the replay is not reported as a silent inclinometer: the gait filter is
    # stopped once the bag has been played and its last states are out
    assert 'silent' not in res.stderr, res.stderr
    states = [m for _, _, m in bagio.read_messages(tmp_path / 'out', ['/gait/state'])]
    assert len(states) >= 0.9 * n_imu
    assert any(s.walking for s in states)


def test_a_plain_wall_is_announced_through_the_graph(tmp_path):
    """Camera to alarm, a wall with no texture across the path (simulated, seed 0): it has
    no vertical edges, so only the ground it hides (the unseen-ground cue) shows it. The
    graph must report the ground unknown from its foot on while the walker approaches,
    and the alarm node must say that it cannot see the way ahead (not "all clear", not
    an obstacle of a height nobody measured) while the wall is still more than 3 m away."""
    from asmonc_vision.replay.summary import read_truth
    from asmonc_vision.sim.bagwriter import write_bag
    from asmonc_vision.sim.scenarios import make_scenario
    bag = tmp_path / 'plain_wall'
    write_bag(make_scenario('plain_wall', seed=0), bag)
    res = asmonc_run(bag, '--out', tmp_path / 'out', '--no-progress')
    assert res.returncode == 0, res.stdout + res.stderr
    truth = read_truth(bag)
    out = frames(tmp_path / 'out', '/obstacles')
    window = [st for st, t in truth.items() if len(t.range) and 1.6 <= t.range.min() <= 4.2]
    assert len(window) >= 20
    hits = 0
    for st in window:
        det, wall_range = out[st], truth[st].range.min()
        ahead = np.abs(det.range * np.sin(det.bearing)) <= 0.5
        hits += bool(np.any(ahead & (np.abs(det.range - wall_range) <= 0.3)))
    assert hits >= 0.8 * len(window), (hits, len(window))
    alarms = [(bagio.header_stamp_ns(m), m.level, m.text)
              for _, _, m in bagio.read_messages(tmp_path / 'out', ['/alarms'])]
    far = {st for st, t in truth.items() if len(t.range) and t.range.min() > 3.0}
    assert any(st in far and level == 4 and text.startswith('cannot see the way ahead')
               for st, level, text in alarms), alarms


def test_recorded_egomotion_scores_against_the_true_camera_pose(static_run):
    from asmonc_vision.eval.motion_bags import score_recorded_egomotion
    _, out = static_run
    m = score_recorded_egomotion(BAGS / 'static_obstacles', out)
    # the egomotion node runs at a lower priority and keeps to the newest pair: on a
    # loaded machine it estimates over longer intervals (a third of the pairs with the
    # whole graph on one core); each motion is scored over its own interval
    assert m is not None and m['motions'] >= 0.25 * (m['pairs'] - 1)
    assert m['errors']['pitch']['median'] < 0.3      # degrees (the target on walking bags)
    assert m['errors']['translation']['median'] < 10  # mm


def test_side_by_side_runs_claim_different_domains(tmp_path):
    from asmonc_vision.replay.domain import MAX_DOMAIN_ID, MAX_LINUX_DOMAIN_ID, claim_domain
    d1, f1 = claim_domain(7, tmp_path)
    d2, f2 = claim_domain(7, tmp_path)
    assert (d1, d2) == (7, 8)
    f1.close()                                       # the first run ends: its id is free
    d3, f3 = claim_domain(7, tmp_path)
    assert d3 == 7
    f2.close(), f3.close()
    # an id set beyond the portable range is honoured (up to the Linux limit), not refused
    d4, f4 = claim_domain(MAX_DOMAIN_ID + 20, tmp_path)
    assert d4 == MAX_DOMAIN_ID + 20
    f4.close()
    fs = [claim_domain(MAX_LINUX_DOMAIN_ID, tmp_path)[1]]
    assert claim_domain(MAX_LINUX_DOMAIN_ID, tmp_path) == (None, None)
    fs[0].close()


def test_a_frozen_child_says_nothing_more_and_still_shuts_down_cleanly(tmp_path):
    """`Child.freeze` (the alarm node at the end of a replay) halts the process at once;
    `stop` then ends it through its SIGINT handler, not a kill."""
    from asmonc_vision.replay.children import Child
    code = ('import signal, sys, time\n'
            'signal.signal(signal.SIGINT, lambda *a: (print("bye", flush=True), sys.exit(0)))\n'
            'while True:\n    print("tick", flush=True); time.sleep(0.02)\n')
    child = Child('ticker', [sys.executable, '-c', code], tmp_path, lambda s: None,
                  dict(os.environ))
    time.sleep(1.0)
    child.freeze()
    time.sleep(0.1)                              # a line written before the halt
    n = child.log_path.read_text().count('tick')
    time.sleep(0.5)
    assert n > 0 and child.log_path.read_text().count('tick') == n
    assert child.stop() == 0
    assert child.log_path.read_text().rstrip().endswith('bye')
