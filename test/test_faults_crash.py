"""Crash and restart: `asmonc run` restarts a node killed with SIGKILL mid-replay; the
wearer hears FAULT while the detector is down, and normal alarms once it is back."""
import json
import os
import subprocess
import sys

from asmonc_vision.io import bagio
from asmonc_vision.core.alarm import TEXT_NO_DATA, TEXT_STARTING
from conftest import BAGS

FAULT, CLEAR = 4, 0
#: the alarm node's timeout in this test (the wearer's target: FAULT within 0.5 s)
TIMEOUT = 0.5
#: seconds `asmonc run` waits for late results once the bag is played and the results
#: have stopped short of the pairs (the pairs lost at the kill never come)
SETTLE = 3.0


def test_detector_killed_mid_replay_fault_then_recovery(tmp_path):
    params = tmp_path / 'alarm.yaml'
    params.write_text(f'alarm_node:\n  ros__parameters:\n    timeout: {TIMEOUT}\n')
    out = tmp_path / 'out'
    bag = BAGS / 'static_obstacles'
    res = subprocess.run([sys.executable, '-m', 'asmonc_vision.cli', 'run', str(bag),
                          '--out', str(out), '--no-progress', '--params-file', str(params),
                          '--inject', 'kill=detector@1.5', '--settle', str(SETTLE)],
                         env=dict(os.environ), capture_output=True, text=True, timeout=300)
    log = res.stdout + res.stderr
    # a node died: exit status 1, said in the summary, but the run went on
    assert res.returncode == 1, log
    assert 'detector node died (exit status -9); restarting it' in res.stderr, log
    s = json.loads((out / 'summary.json').read_text())
    assert s['restarts'] == {'detector': 1}
    kill = s['faults']['processes']
    assert [k['fault'] for k in kill] == ['kill=detector@1.5']
    k_ns = kill[0]['wall_ns']
    after = [a for a in s['alarm_log'] if a['received_ns'] > k_ns]
    # FAULT "detection has stopped" within the timeout (+ the last frame's age and the
    # alarm node's 0.1 s check period)
    first = after[0]
    assert first['level'] == FAULT and first['text'] == TEXT_NO_DATA, after
    fault_s = (first['received_ns'] - k_ns) / 1e9
    # (a FAULT's stamp is the alarm node's clock when it decided: a late decision is
    # the alarm node's, a late receipt the delivery's)
    decided_s = (first['stamp_ns'] - k_ns) / 1e9
    assert fault_s <= TIMEOUT + 0.3, (fault_s, decided_s, after[:3])
    # back to a normal alarm within 20 s, and never "all clear" before the restarted
    # detector's ground plane: a CLEAR followed by "starting up" would be one
    normal = [a for a in after if a['level'] != FAULT]
    assert normal, after
    assert (normal[0]['received_ns'] - k_ns) / 1e9 <= 20.0
    for a, b in zip(after, after[1:]):
        assert not (a['level'] == CLEAR and b['text'] == TEXT_STARTING), after
    # the restarted detector processed the rest of the bag: only the pairs in flight at
    # the kill (at most the player's lead and the detector's queue) are lost
    n = bagio.bag_topics(bag)['/stereo/left/image_rect'][1]
    last_pair = max(bagio.header_stamp_ns(m) for _, _, m in
                    bagio.read_messages(bag, ['/stereo/left/image_rect']))
    got = {bagio.header_stamp_ns(m) for _, _, m in bagio.read_messages(out, ['/obstacles'])}
    assert last_pair in got
    assert len(got) >= n - 6, (len(got), n)
    assert (out / 'logs' / 'detector.restart1.log').is_file()
