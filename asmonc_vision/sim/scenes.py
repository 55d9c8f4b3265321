"""Scene classes for campaigns of random walks: a scene class, a seed and a rig make a walk.

    SCENE_CLASSES: tuple[str, ...]; RIGS: tuple[str, ...]
    make_scene(scene_class, seed, *, duration=20.0, rig='backpack', realism=None) -> Scenario

The classes are the simulator's walking scenarios (`sim.scenarios`): walk_obstacles,
clear_walk, walk_stop_turn, slope, step_down (each lays out its course for the requested
duration). The rigs:

* ``backpack``: the paper's rig, `RigSettings()` (320x240, f 300 px, baseline 0.35 m,
  1.25 m high, 20 deg down);
* ``chest``: a chest-worn camera pair: 640x480, f 520 px, baseline 0.12 m, 1.3 m high,
  5 deg down.

``realism`` selects a rendering model where the simulator has several; this one has one
(None and False give it; True is refused).
"""
from __future__ import annotations

import dataclasses

from asmonc_vision.sim.rig import RigSettings
from asmonc_vision.sim.scenarios import Scenario, make_scenario

SCENE_CLASSES: tuple[str, ...] = ('walk_obstacles', 'clear_walk', 'walk_stop_turn', 'slope',
                                  'step_down')
RIGS: tuple[str, ...] = ('backpack', 'chest')

#: RigSettings changes per rig name
RIG_SETTINGS = {
    'backpack': {},
    'chest': {'width': 640, 'height': 480, 'focal': 520.0, 'baseline': 0.12,
              'camera_height': 1.3, 'camera_pitch_deg': 5.0},
}


def rig_settings(rig: str) -> RigSettings:
    """The RigSettings of a rig name (see the module doc).

    Raises:
        KeyError: unknown rig (the message lists the known ones).
    """
    if rig not in RIG_SETTINGS:
        raise KeyError(f"unknown rig '{rig}'; known: {', '.join(RIGS)}")
    return dataclasses.replace(RigSettings(), **RIG_SETTINGS[rig])


def make_scene(scene_class: str, seed: int, *, duration: float = 20.0, rig: str = 'backpack',
               realism: bool | None = None) -> Scenario:
    """A walk of ``scene_class`` drawn from ``seed`` (the same arguments, the same walk).

    Args:
        scene_class: one of SCENE_CLASSES.
        seed: any int.
        duration: seconds of walk (camera frames at the rig's 10 Hz).
        rig: one of RIGS.
        realism: None or False (this simulator has a single rendering model).
    Raises:
        KeyError: unknown scene class or rig; ValueError: realism=True.
    """
    if scene_class not in SCENE_CLASSES:
        raise KeyError(f"unknown scene class '{scene_class}'; known: {', '.join(SCENE_CLASSES)}")
    if realism:
        raise ValueError('this simulator has a single rendering model: realism must be '
                         'None or False')
    return make_scenario(scene_class, seed=int(seed), duration=float(duration),
                         rig=rig_settings(rig))
