"""The end of a replay, watched from a process of its own: halt the alarm node once it has
answered the last pair the bag plays.

At the end of a replay the input stops, and the alarm node's timeout (0.4 s) would
announce that silence to the wearer as a fault. The alarm node publishes its whole answer
to each obstacle list on ``/alarms/contact`` (after any ``/alarms`` message for the same
list). The pipeline keeps the order the pairs are played in (a pair not newer than the
last one is refused), so once the answer to the last pair the bag plays whole has come,
nothing can come after it, and the replay is over for the alarm node.

This process subscribes that topic and halts the alarm node's process group with
SIGSTOP ``--grace`` s after the answer stamped ``--last-stamp``, prints
`HALTED_LINE` and exits. It does nothing else, so it answers within milliseconds however
busy `asmonc run`'s own process is (recording and compressing the debug images there, a
watcher thread was seen to act 0.3 s late, when the timeout had already fired). `asmonc
run` shuts the halted node down (SIGINT, SIGCONT) once the recorder has closed its bag.

    python -m asmonc_vision.replay.end_watch --last-stamp NS --pgid PGID [--grace 0.05]

Not a node of the wearer's graph: a tool of `asmonc run` (`replay.session`).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

#: the line printed once the alarm node has been halted (`replay.session` waits for it)
HALTED_LINE = 'end_watch: alarm node halted'


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='end_watch', description=__doc__.splitlines()[0])
    p.add_argument('--last-stamp', type=int, required=True,
                   help='header stamp (ns) of the last pair the bag plays whole')
    p.add_argument('--pgid', type=int, required=True,
                   help="the alarm node's process group id")
    p.add_argument('--grace', type=float, default=0.05,
                   help='seconds between the answer and the halt (default 0.05)')
    args = p.parse_args(argv)
    if args.grace < 0 or args.pgid <= 1:
        p.error('--grace must be >= 0 and --pgid > 1')

    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import ExternalShutdownException

    from asmonc_vision.nodes.alarm_node import CONTACT_TOPIC
    from asmonc_vision.nodes.common import RESULT_QOS, quiet_interrupts, watch_input_links

    interrupted = quiet_interrupts()
    rclpy.init(args=['--ros-args', '--disable-rosout-logs'])
    node = rclpy.create_node('asmonc_run_end_watch')
    halted = threading.Event()

    def halt() -> None:
        try:
            os.killpg(args.pgid, signal.SIGSTOP)
        except ProcessLookupError:
            pass                          # the alarm node has ended already
        print(HALTED_LINE, flush=True)
        halted.set()

    def on_contact(msg) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if stamp == args.last_stamp and not halted.is_set():
            node.destroy_subscription(sub)
            if args.grace > 0:
                threading.Timer(args.grace, halt).start()
            else:
                halt()

    sub = node.create_subscription(DiagnosticArray, CONTACT_TOPIC, on_contact, RESULT_QOS)
    watch_input_links(node, (CONTACT_TOPIC,))
    try:
        while rclpy.ok() and not halted.is_set() and not interrupted.is_set():
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
