"""The end of a replay, watched from a process of its own: halt a node once it has
answered the last input the bag plays it.

At the end of a replay the input stops, and two nodes would announce that silence to
the wearer as a fault: the alarm node after its timeout (0.4 s), the walk model's node
after its own (1 s: "inclinometer silent"). Each answers every input on a topic stamped
like that input: the alarm node's whole answer to each obstacle list is on
``/alarms/contact`` (after any ``/alarms`` message for the same list), the walk model's
state for each inclinometer reading on ``/gait/state``. The graph keeps the order the
bag plays its messages in (a pair not newer than the last one is refused), so once the
answer to the last input the bag plays has come, nothing can come after it, and the
replay is over for that node.

This process subscribes those topics and halts a node's process group with SIGSTOP
``--grace`` s after the answer stamped like its last input, prints `HALTED_MARK` and
the topic, and exits once every node it watches is halted. It does nothing else, so it
answers within milliseconds however busy `asmonc run`'s own process is (recording and
compressing the debug images there, a watching thread was seen to act 0.3 s late for the
alarm node and more than 0.75 s late for the walk model's node). `asmonc run` shuts
the halted nodes down (SIGINT, SIGCONT) once the recorder has closed its bag.

    python -m asmonc_vision.replay.end_watch --watch TOPIC STAMP_NS PGID [--watch ...]
                                             [--grace 0.05]

Not a node of the wearer's graph: a tool of `asmonc run` (`replay.session`).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

#: the start of the line printed, with the topic, once a node has been halted
#: (`replay.session` reads it)
HALTED_MARK = 'end_watch: halted the node answering on'
#: the answer topics this process can watch, and their message types
ANSWER_TOPICS = {'/alarms/contact': ('diagnostic_msgs.msg', 'DiagnosticArray'),
                 '/gait/state': ('asmonc_vision_msgs.msg', 'GaitState')}


def _parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog='end_watch', description=__doc__.splitlines()[0])
    p.add_argument('--watch', nargs=3, action='append', required=True,
                   metavar=('TOPIC', 'STAMP_NS', 'PGID'),
                   help='halt process group PGID once an answer stamped STAMP_NS (the '
                        f"last input's) comes on TOPIC ({', '.join(ANSWER_TOPICS)})")
    p.add_argument('--grace', type=float, default=0.05,
                   help='seconds between the answer and the halt (default 0.05)')
    args = p.parse_args(argv)
    watches = {}
    for topic, stamp, pgid in args.watch:
        if topic not in ANSWER_TOPICS or topic in watches:
            p.error(f'--watch: topic {topic!r} unknown or given twice '
                    f"(one each of {', '.join(ANSWER_TOPICS)})")
        try:
            watches[topic] = (int(stamp), int(pgid))
        except ValueError:
            p.error(f'--watch {topic}: STAMP_NS and PGID must be integers')
        if watches[topic][1] <= 1:
            p.error(f'--watch {topic}: PGID must be > 1')
    if not args.grace >= 0:
        p.error('--grace must be >= 0')
    args.watches = watches
    return args


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)

    import importlib

    import rclpy
    from rclpy.executors import ExternalShutdownException

    from asmonc_vision.nodes.common import RESULT_QOS, quiet_interrupts, watch_input_links

    interrupted = quiet_interrupts()
    rclpy.init(args=['--ros-args', '--disable-rosout-logs'])
    node = rclpy.create_node('asmonc_run_end_watch')
    pending = set(args.watches)
    lock = threading.Lock()
    all_halted = threading.Event()

    def halt(topic: str) -> None:
        try:
            os.killpg(args.watches[topic][1], signal.SIGSTOP)
        except ProcessLookupError:
            pass                          # the node has ended already
        print(f'{HALTED_MARK} {topic}', flush=True)
        with lock:
            pending.discard(topic)
            if not pending:
                all_halted.set()

    def watcher(topic: str):
        last = args.watches[topic][0]
        done = threading.Event()

        def on_answer(msg) -> None:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if stamp == last and not done.is_set():
                done.set()
                if args.grace > 0:
                    threading.Timer(args.grace, halt, (topic,)).start()
                else:
                    halt(topic)
        return on_answer

    for topic in args.watches:
        module, name = ANSWER_TOPICS[topic]
        msg_type = getattr(importlib.import_module(module), name)
        node.create_subscription(msg_type, topic, watcher(topic), RESULT_QOS)
    watch_input_links(node, tuple(args.watches))
    try:
        while rclpy.ok() and not all_halted.is_set() and not interrupted.is_set():
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
