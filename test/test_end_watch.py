"""`replay.end_watch`: the alarm node is halted once it has answered the last pair the bag
plays, not before, from a process of its own."""
import os
import subprocess
import sys
import time

from conftest import REPO, next_domain_id


def _state(pid: int) -> str:
    """The process's state letter from /proc (T: stopped)."""
    with open(f'/proc/{pid}/stat') as f:
        return f.read().rsplit(')', 1)[1].split()[0]


def _contact(stamp_ns: int):
    from diagnostic_msgs.msg import DiagnosticArray
    msg = DiagnosticArray()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    return msg


def test_the_alarm_node_is_halted_after_the_newest_pair_is_answered():
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray

    from asmonc_vision.nodes.alarm_node import CONTACT_TOPIC
    from asmonc_vision.nodes.common import RESULT_QOS
    from asmonc_vision.replay.end_watch import HALTED_LINE

    domain = next_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               PYTHONPATH=str(REPO))
    # the stand-in for the alarm node: a process group of its own, as `asmonc run` starts it
    alarm = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'],
                             process_group=0)
    last = 1_700_000_003_000_000_000
    watch = subprocess.Popen([sys.executable, '-m', 'asmonc_vision.replay.end_watch',
                              '--last-stamp', str(last), '--pgid', str(alarm.pid),
                              '--grace', '0.05'], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        node = rclpy.create_node('contact_probe', context=ctx)
        pub = node.create_publisher(DiagnosticArray, CONTACT_TOPIC, RESULT_QOS)
        deadline = time.monotonic() + 30.0
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert pub.get_subscription_count() == 1, 'end_watch never subscribed'
        time.sleep(0.3)                    # its side of the link too
        # the pairs before the last: one with a newer stamp (a clock that jumped back)
        for stamp in (last - 2_000_000_000, last + 5_000_000_000, last - 100_000_000):
            pub.publish(_contact(stamp))
        time.sleep(0.5)
        assert _state(alarm.pid) != 'T' and watch.poll() is None   # not yet
        pub.publish(_contact(last))
        t0 = time.monotonic()
        out, _ = watch.communicate(timeout=10.0)
        assert watch.returncode == 0, out
        assert HALTED_LINE in out, out
        assert _state(alarm.pid) == 'T'
        assert time.monotonic() - t0 < 5.0
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
        if watch.poll() is None:
            watch.kill()
        alarm.kill()
        alarm.wait()


def test_bad_arguments_are_refused():
    res = subprocess.run([sys.executable, '-m', 'asmonc_vision.replay.end_watch',
                          '--last-stamp', '5', '--pgid', '1'], capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert res.returncode == 2 and '--pgid' in res.stderr
