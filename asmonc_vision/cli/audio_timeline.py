"""The PNG timeline of `asmonc run --audio`: what the wearer heard, against the truth.

Three panels on the bag's time line (t = 0 the first stereo pair): the alarm levels as
the audio node heard them (frame-stamped ones at their frames, the alarm node's
own-clock ones -- start-up, time-outs -- where the audio node placed them), the cues and
phrases of the soundtrack (from the WAV's ``.cues.json``), and the true obstacles on the
walking path (the alarm's own corridor, on the true range and bearing) with their range,
drops apart.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

LEVELS = ('CLEAR', 'CAUTION', 'WARNING', 'STOP', 'FAULT')
CUE_ROWS = {'obstacle': 0, 'drop': 1, 'stop': 2, 'fault': 3, 'degraded': 4}
CUE_COLOURS = {'obstacle': 'tab:blue', 'drop': 'tab:purple', 'stop': 'tab:red',
               'fault': 'black', 'degraded': 'tab:gray'}


def truth_on_path(truth: dict, t0_ns: int, config) -> list[tuple[float, float, bool]]:
    """(bag time s, true range m, is_drop) of every true obstacle in the alarm's corridor
    (``AlarmLogic.in_corridor`` on the true range and bearing, confidence 1)."""
    from asmonc_vision.core.alarm import AlarmLogic, ObstacleInfo

    logic = AlarmLogic(config)
    out = []
    for stamp, fr in sorted(truth.items()):
        for k in range(len(fr.range)):
            ob = ObstacleInfo(int(fr.ids[k]), float(fr.range[k]), float(fr.bearing[k]),
                              float(fr.height[k]), 1.0)
            if logic.in_corridor(ob):
                out.append(((stamp - t0_ns) * 1e-9, ob.range, ob.is_drop))
    return out


def write_timeline(png: Path, cues_json: Path, alarms: list[dict], t0_ns: int,
                   truth: dict, config, title: str = '') -> None:
    """Draw the timeline (see module doc) to ``png``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    log = json.loads(Path(cues_json).read_text()) if Path(cues_json).exists() else {}
    cues = log.get('events', [])
    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True,
                             gridspec_kw={'height_ratios': [1.2, 1.2, 1.6]})
    # levels
    ax = axes[0]
    if log.get('alarms'):     # where the audio node placed them (own-clock ones too)
        pts = sorted((a['t'], a['level']) for a in log['alarms'])
    else:
        pts = sorted(((a['stamp_ns'] - t0_ns) * 1e-9, a['level']) for a in alarms
                     if -60 < (a['stamp_ns'] - t0_ns) * 1e-9 < 86400)
    if pts:
        t, lv = zip(*pts)
        ax.step(t, lv, where='post', color='tab:orange')
        ax.plot(t, lv, 'o', ms=3, color='tab:orange')
    ax.set_yticks(range(5), LEVELS)
    ax.set_ylim(-0.5, 4.5)
    ax.set_title(title or 'what the wearer heard')
    ax.set_ylabel('alarm')
    # cues and phrases
    ax = axes[1]
    for e in cues:
        what = e['what']
        if what.startswith('phrase'):
            ax.plot(e['t'], 5, 'v', color='tab:green', ms=5)
            ax.annotate(what.split(': ', 1)[-1], (e['t'], 5), fontsize=7, rotation=30,
                        xytext=(2, 4), textcoords='offset points')
        else:
            ax.plot(e['t'], CUE_ROWS.get(what, 0), '|', ms=10,
                    color=CUE_COLOURS.get(what, 'k'))
    ax.set_yticks(list(CUE_ROWS.values()) + [5], list(CUE_ROWS) + ['phrase'])
    ax.set_ylim(-0.7, 6.2)
    ax.set_ylabel('cues')
    # truth
    ax = axes[2]
    path = truth_on_path(truth, t0_ns, config) if truth else []
    if path:
        arr = np.array([(t, r) for t, r, _ in path])
        drop = np.array([d for _, _, d in path])
        ax.plot(arr[~drop, 0], arr[~drop, 1], '.', color='tab:blue', ms=4,
                label='obstacle on the path')
        if drop.any():
            ax.plot(arr[drop, 0], arr[drop, 1], '.', color='tab:purple', ms=4,
                    label='drop on the path')
        ax.legend(loc='upper right', fontsize=8)
    else:
        ax.text(0.5, 0.5, 'no true obstacle on the path' if truth else 'no ground truth',
                transform=ax.transAxes, ha='center', va='center', color='gray')
    ax.set_ylabel('true range, m')
    ax.set_xlabel('bag time, s (0 = first stereo pair)')
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
