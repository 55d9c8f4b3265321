"""Replay a bag through the node graph and tell what the wearer would have heard.

Starts the detector and alarm nodes as separate processes, then the bag player; prints
each alarm as it is given, with a progress bar; records every output topic to a rosbag2
MCAP bag with --out; ends with a summary against the bag's ground truth, if it has any:
true obstacles detected or missed, false obstacles, alarms given.

The bag may be any rosbag2 bag that follows the topic contract (README), not only the
simulator's. Exit status: 0 done; 1 frames dropped, a node failed or the bag ended in
error; 2 the bag or the arguments are unusable.
"""
from __future__ import annotations

from pathlib import Path

from asmonc_vision.replay.params import DEFAULT_BAG_NAME, PACE_LEAD


def add_arguments(p) -> None:
    p.add_argument('bag', nargs='?', type=Path, default=None,
                   help=f'rosbag2 bag directory or .mcap file (default: bags/{DEFAULT_BAG_NAME})')
    p.add_argument('--out', type=Path, default=None,
                   help='record every output topic to a rosbag2 MCAP bag in this new directory, '
                        'with summary.json and the nodes\' logs beside it')
    p.add_argument('--rate', type=float, default=1.0, help='replay speed factor (default 1)')
    p.add_argument('--realtime', action='store_true',
                   help='replay strictly at the bag\'s rate: a machine too slow for it drops '
                        'pairs, as with a live camera (default: the replay waits while the '
                        f'detector is more than {PACE_LEAD} pairs behind, so every pair is '
                        'processed; the summary says how long it waited)')
    p.add_argument('--params-file', type=Path, action='append', default=[],
                   help='a ros__parameters YAML passed to the nodes (repeatable)')
    p.add_argument('--settle', type=float, default=5.0,
                   help='seconds to wait for the last outputs after the bag ends (default 5)')
    p.add_argument('--match-radius', type=float, default=0.3,
                   help='a detection within this distance (m) of a true obstacle\'s top finds it')
    p.add_argument('--min-height', type=float, default=0.10,
                   help='true obstacles at least this high (m) count in the recall (default 0.10)')
    p.add_argument('--max-range', type=float, default=5.0,
                   help='true obstacles within this range (m) count in the recall (default 5)')
    p.add_argument('--max-restarts', type=int, default=3,
                   help='a node that dies is restarted at most this many times (default 3)')
    p.add_argument('--inject', default='',
                   help='faults at chosen bag times, e.g. "kill=detector@2;stall@3+1.5" '
                        '(docs/robustness.md lists the classes)')
    p.add_argument('--audio', type=Path, default=None, metavar='FILE.wav',
                   help='also run the audio node and write what the wearer would have heard '
                        'to this WAV (stereo, t = 0 the first stereo pair\'s stamp, bag time '
                        'at any --rate), its cue log FILE.cues.json and a PNG timeline '
                        'FILE.png (cues, alarm levels, true obstacles on the path)')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--quiet', action='store_true', help='print only the summary')
    p.set_defaults(func=run)


def run(args) -> int:
    from asmonc_vision.replay.session import replay
    return replay(args)
