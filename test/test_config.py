"""Settings dataclasses: validation messages, and config/*.yaml equal to the defaults."""
import dataclasses
import importlib
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from asmonc_vision.core.config import check_fields, param

CONFIG = Path(__file__).resolve().parent.parent / 'config'

# yaml file -> (node name, [(parameter prefix, 'module:Class'), ...])
NODE_CONFIGS = {
    'detector.yaml': ('detector_node', [
        ('', 'asmonc_vision.nodes.detector_node:DetectorNodeConfig'),
        ('gpod.', 'asmonc_vision.core.gpod:GpodConfig'),
        ('map.', 'asmonc_vision.core.evidence_map:EvidenceMapConfig')]),
    'alarm.yaml': ('alarm_node', [('', 'asmonc_vision.core.alarm:AlarmConfig')]),
    'audio.yaml': ('audio_node', [('', 'asmonc_vision.nodes.audio_node:AudioNodeConfig'),
                                  ('', 'asmonc_vision.core.audio.render:AudioConfig')]),
    'stereo_capture.yaml': ('stereo_capture_node', [
        ('', 'asmonc_vision.core.capture:CaptureConfig')]),
    'bag_player.yaml': ('bag_player_node', [('', 'asmonc_vision.nodes.player_node:PlayerConfig')]),
    'bag_recorder.yaml': ('bag_recorder_node', [
        ('', 'asmonc_vision.nodes.recorder_node:RecorderConfig')]),
    'egomotion.yaml': ('egomotion_node', [
        ('', 'asmonc_vision.nodes.egomotion_node:EgomotionNodeConfig'),
        ('motion.', 'asmonc_vision.core.motion:EgomotionConfig')]),
    'compass.yaml': ('compass_node', [('', 'asmonc_vision.core.nmea:CompassConfig')]),
    'gait_filter.yaml': ('gait_filter_node', [
        ('', 'asmonc_vision.nodes.gait_node:GaitNodeConfig'),
        ('gait.', 'asmonc_vision.core.gait.model:GaitConfig')]),
}


def _load(spec):
    mod, cls = spec.split(':')
    return getattr(importlib.import_module(mod), cls)


@dataclass(frozen=True)
class _Demo:
    gain: float = param(1.0, 'a gain', range=(0.0, 2.0))
    mode: str = param('a', 'a mode', choices=('a', 'b'))
    on: bool = param(True, 'a switch')

    def __post_init__(self):
        check_fields(self)


def test_check_fields_names_field_and_range():
    with pytest.raises(ValueError, match=r'_Demo\.gain = 3\.0 is out of range \[0\.0, 2\.0\]'):
        _Demo(gain=3.0)
    with pytest.raises(ValueError, match=r"_Demo\.mode = 'c' is not one of"):
        _Demo(mode='c')
    with pytest.raises(ValueError, match='not finite'):
        _Demo(gain=float('nan'))
    with pytest.raises(TypeError, match='true or false'):
        _Demo(on=1)
    with pytest.raises(TypeError, match='must be a number'):
        _Demo(gain='x')


def test_every_config_file_is_covered():
    assert {p.name for p in CONFIG.glob('*.yaml')} <= set(NODE_CONFIGS)


@pytest.mark.parametrize('fname', sorted(NODE_CONFIGS))
def test_yaml_equals_dataclass_defaults(fname):
    node, parts = NODE_CONFIGS[fname]
    path = CONFIG / fname
    if not path.exists():
        pytest.fail(f'{path} is missing')
    doc = yaml.safe_load(path.read_text())
    params = doc[node]['ros__parameters']
    expected = {}
    for prefix, spec in parts:
        cls = _load(spec)
        for f in dataclasses.fields(cls):
            v = f.default
            expected[prefix + f.name] = list(v) if isinstance(v, tuple) else v

    def flatten(d, pre=''):
        out = {}
        for k, v in d.items():
            if isinstance(v, dict):
                out.update(flatten(v, f'{pre}{k}.'))
            else:
                out[pre + k] = v
        return out
    assert flatten(params) == expected


def test_int_field_refuses_a_float():
    @dataclass(frozen=True)
    class _Count:
        n: int = param(3, 'a count', range=(1, 10))

        def __post_init__(self):
            check_fields(self)
    with pytest.raises(TypeError, match='whole number'):
        _Count(n=2.5)
