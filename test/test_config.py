"""Settings dataclasses: validation messages, and config/*.yaml equal to the defaults."""
import importlib
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from asmonc_vision.core.config import (check_fields, flat_fields, flat_values, group, override,
                                       param, to_dict)

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


@dataclass(frozen=True)
class _Outer:
    level: float = param(0.5, 'a level', range=(0.0, 1.0))
    demo: _Demo = group(_Demo, 'a stage')

    def __post_init__(self):
        check_fields(self)


def test_a_group_is_named_by_dotted_paths_and_overridden_by_them():
    assert [n for n, _ in flat_fields(_Outer)] == ['level', 'demo.gain', 'demo.mode', 'demo.on']
    assert [n for n, _ in flat_fields(_Outer, 'x.')][1] == 'x.demo.gain'
    assert flat_values(_Outer()) == {'level': 0.5, 'demo.gain': 1.0, 'demo.mode': 'a',
                                     'demo.on': True}
    assert to_dict(_Outer()) == {'level': 0.5, 'demo': {'gain': 1.0, 'mode': 'a', 'on': True}}
    o = override(_Outer(), {'demo.gain': 1.5, 'level': 0.25})
    assert o == _Outer(level=0.25, demo=_Demo(gain=1.5)) and _Outer().demo.gain == 1.0
    # a group's own check, named by its path in the outer settings
    with pytest.raises(ValueError, match=r'^_Outer\.demo\.gain = 3\.0 is out of range'):
        override(_Outer(), {'demo.gain': 3.0})
    for bad in ('gain', 'demo', 'demo.nope', 'level.x'):
        with pytest.raises(ValueError, match=f"_Outer has no setting '{bad}'"):
            override(_Outer(), {bad: 1.0})
    with pytest.raises(TypeError, match=r'_Outer\.demo must be a _Demo, got dict'):
        _Outer(demo={'gain': 1.0})


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
        for name, v in flat_values(_load(spec)()).items():
            expected[prefix + name] = list(v) if isinstance(v, tuple) else v

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
