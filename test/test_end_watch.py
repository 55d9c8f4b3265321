"""`replay.end_watch`: a node is halted once it has answered the last input the bag plays
it, not before, from a process of its own."""
import os
import subprocess
import sys
import time

from conftest import REPO, next_domain_id


def _state(pid: int) -> str:
    """The process's state letter from /proc (T: stopped)."""
    with open(f'/proc/{pid}/stat') as f:
        return f.read().rsplit(')', 1)[1].split()[0]


def _stamped(msg, stamp_ns: int):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    return msg


def _stand_in() -> subprocess.Popen:
    """A stand-in for a node: a process group of its own, as `asmonc run` starts it."""
    return subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'],
                            process_group=0)


def test_each_node_is_halted_after_its_last_input_is_answered():
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray

    from asmonc_vision.nodes.common import RESULT_QOS
    from asmonc_vision.replay.end_watch import HALTED_MARK
    from asmonc_vision_msgs.msg import GaitState

    domain = next_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               PYTHONPATH=str(REPO))
    alarm, gait = _stand_in(), _stand_in()
    last_pair, last_imu = 1_700_000_003_000_000_000, 1_700_000_003_050_000_000
    watch = subprocess.Popen([sys.executable, '-m', 'asmonc_vision.replay.end_watch',
                              '--watch', '/alarms/contact', str(last_pair), str(alarm.pid),
                              '--watch', '/gait/state', str(last_imu), str(gait.pid),
                              '--grace', '0.05'], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        node = rclpy.create_node('answer_probe', context=ctx)
        contact = node.create_publisher(DiagnosticArray, '/alarms/contact', RESULT_QOS)
        state = node.create_publisher(GaitState, '/gait/state', RESULT_QOS)
        deadline = time.monotonic() + 30.0
        while (contact.get_subscription_count() == 0 or state.get_subscription_count() == 0
               ) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert contact.get_subscription_count() == state.get_subscription_count() == 1
        time.sleep(0.3)                    # its side of the links too
        # the inputs before the last: one with a newer stamp (a clock that jumped back)
        for stamp in (last_pair - 2_000_000_000, last_pair + 5_000_000_000,
                      last_pair - 100_000_000):
            contact.publish(_stamped(DiagnosticArray(), stamp))
        state.publish(_stamped(GaitState(), last_pair))        # another topic's last
        time.sleep(0.5)
        assert _state(alarm.pid) != 'T' and _state(gait.pid) != 'T' and watch.poll() is None
        contact.publish(_stamped(DiagnosticArray(), last_pair))
        time.sleep(0.5)
        assert _state(alarm.pid) == 'T' and _state(gait.pid) != 'T' and watch.poll() is None
        state.publish(_stamped(GaitState(), last_imu))
        out, _ = watch.communicate(timeout=10.0)
        assert watch.returncode == 0, out
        assert f'{HALTED_MARK} /alarms/contact' in out and f'{HALTED_MARK} /gait/state' in out
        assert _state(gait.pid) == 'T'
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
        if watch.poll() is None:
            watch.kill()
        for p in (alarm, gait):
            p.kill()
            p.wait()


def test_bad_arguments_are_refused():
    for args, said in ((['--watch', '/alarms/contact', '5', '1'], 'PGID must be > 1'),
                       (['--watch', '/obstacles', '5', '99'], 'unknown or given twice'),
                       (['--watch', '/gait/state', 'x', '99'], 'must be integers'),
                       ([], '--watch')):
        res = subprocess.run([sys.executable, '-m', 'asmonc_vision.replay.end_watch', *args],
                             capture_output=True, text=True,
                             env=dict(os.environ, PYTHONPATH=str(REPO)))
        assert res.returncode == 2 and said in res.stderr, (args, res.stderr)
