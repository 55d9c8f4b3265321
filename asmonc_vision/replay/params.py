"""The replay's defaults, and the node parameters it must know (from the params files)."""
from __future__ import annotations

import os
from pathlib import Path

LEVEL_NAMES = {0: 'CLEAR', 1: 'CAUTION', 2: 'WARNING', 3: 'STOP', 4: 'FAULT'}
#: every topic a node of the graph publishes (recorded with --out)
OUTPUT_TOPICS = ('/obstacles', '/ground_plane', '/obstacles/markers', '/detector/debug_image',
                 '/alarms', '/diagnostics', '/egomotion', '/egomotion/odometry', '/gait/state',
                 '/gait/predicted_motion', '/obstacle_map', '/alarms/contact')
DEFAULT_BAG_NAME = 'static_obstacles'
#: pairs the player may publish ahead of the detector's /obstacles (unless --realtime)
PACE_LEAD = 3


def default_bag() -> Path:
    """The bundled static-rig bag ($ASMONC_BAGS or the repository's bags/)."""
    root = Path(os.environ.get('ASMONC_BAGS', Path(__file__).resolve().parents[2] / 'bags'))
    return root / DEFAULT_BAG_NAME


def audio_params(args, t0: int) -> list[str]:
    """The audio node's parameters for --audio: its WAV, t = 0 and the replay rate."""
    wav = args.audio.resolve()
    wav.parent.mkdir(parents=True, exist_ok=True)
    return ['-p', f'wav_path:={wav}', '-p', f't0_ns:={int(t0)}',
            '-p', f'rate:={float(args.rate)}',
            '-p', f'latency_path:={wav.with_suffix(".latency.json")}']


def node_param(params_files: list[Path], node: str, name: str, default: float,
                positive: bool = False) -> float:
    """A node's non-negative (``positive``: positive) number parameter ``name``: the last
    of ``params_files`` that sets it for ``node`` (or ``/**``), else ``default``.
    Unreadable files, and other values, are left to the nodes to report."""
    import yaml

    out = default
    for pf in params_files:
        try:
            data = yaml.safe_load(Path(pf).read_text())
        except (OSError, yaml.YAMLError):
            continue
        if not isinstance(data, dict):
            continue
        for key in ('/**', node, '/' + node):
            params = data.get(key)
            params = params.get('ros__parameters') if isinstance(params, dict) else None
            value = params.get(name) if isinstance(params, dict) else None
            if isinstance(value, (int, float)) and not isinstance(value, bool) \
                    and (value > 0 or (value == 0 and not positive)):
                out = float(value)
    return out


def node_timeout(params_files: list[Path], node: str, default: float) -> float:
    """A node's ``timeout`` parameter (s), as `node_param` finds it."""
    return node_param(params_files, node, 'timeout', default, positive=True)


def alarm_config(params_files: list[Path]):
    """The alarm node's settings that decide which obstacles are on the path
    (`eval.evaluation.path_criteria`), from the params files or its defaults; the defaults
    if the files' values do not make a valid `AlarmConfig` (the node reports that)."""
    from asmonc_vision.core.alarm import AlarmConfig
    d = AlarmConfig()
    values = {k: node_param(params_files, 'alarm_node', k, getattr(d, k))
              for k in ('corridor_half_width', 'min_height', 'stop_range', 'warning_range',
                        'caution_range', 'max_range')}
    try:
        return AlarmConfig(**values)
    except ValueError:
        return d


def alarm_timeout(params_files: list[Path]) -> float:
    """The alarm node's ``timeout`` (s, FAULT after this long without /obstacles)."""
    from asmonc_vision.core.alarm import AlarmConfig
    return node_timeout(params_files, 'alarm_node', AlarmConfig().timeout)


def gait_timeout(params_files: list[Path]) -> float:
    """The gait node's ``timeout`` (s, the inclinometer counts as silent after it)."""
    from asmonc_vision.nodes.gait_node import GaitNodeConfig
    return node_timeout(params_files, 'gait_filter_node', GaitNodeConfig().timeout)
