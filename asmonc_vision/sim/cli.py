"""Command line: render a scenario to a rosbag2 directory.

    python -m asmonc_vision.sim SCENARIO OUT_DIR [--seed N] [--duration S] [--fps F]
        [--width W --height H --focal F] [--rig FIELD=VALUE ...]
        [--gait extreme|FIELD=VALUE ...] [--force] [--list]
        [--scene] [--preset backpack|chest|narrow] [--realism on|off]

SCENARIO is a scenario (``scenarios.SCENARIOS``) or a scene class of the campaign
(``scenes.ALL_CLASSES``, drawn from the seed as ``scenes.make_scene``); a name that
is both (clear_walk, step_down) is the scenario unless ``--scene`` is given.

(console script ``asmonc-sim``). Exit status 0 on success, 2 on a usage error (unknown
scenario, existing non-empty OUT_DIR without --force, bad settings).
"""
from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import time
from pathlib import Path

from asmonc_vision.sim.motion import GaitSettings
from asmonc_vision.sim.rig import RigSettings
from asmonc_vision.sim.scenarios import DEFAULT_DURATIONS, SCENARIOS, make_scenario
from asmonc_vision.sim.scenes import (ALL_CLASSES, CLEAR_CLASSES, EXTRA_CLASSES, build_scene,
                                      drawn_rig, scene_description)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='asmonc-sim',
        description='Render a simulated stereo walk (rectified mono8 pairs, inclinometer, '
                    'ground truth) to a rosbag2 (MCAP, zstd) directory.')
    p.add_argument('scenario', nargs='?', help='scenario name (see --list)')
    p.add_argument('out_dir', nargs='?', help='bag directory to create')
    p.add_argument('--list', action='store_true', help='list the scenarios and exit')
    p.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    p.add_argument('--duration', type=float, default=None,
                   help='seconds to simulate (default: the scenario default)')
    p.add_argument('--fps', type=float, default=None, help='camera rate, Hz (default 10)')
    p.add_argument('--width', type=int, default=None, help='image width, px (default 320)')
    p.add_argument('--height', type=int, default=None, help='image height, px (default 240)')
    p.add_argument('--focal', type=float, default=None, help='focal length, px (default 300)')
    p.add_argument('--rig', action='append', default=[], metavar='FIELD=VALUE',
                   help='any other rig setting, e.g. baseline=0.2, camera_height=1.0, '
                        'camera_pitch_deg=30, noise_sigma=5 (repeatable; fields and ranges: '
                        'asmonc_vision.sim.rig.RigSettings)')
    p.add_argument('--gait', action='append', default=[], metavar='extreme|FIELD=VALUE',
                   help="the walker: 'extreme' (the paper's extreme motion: 5 degrees of "
                        'sway, 10 cm bob) and/or any gait setting, e.g. pitch_amp_deg=3.5, '
                        'bob_amp=0.05 (repeatable, applied in order; fields and ranges: '
                        'asmonc_vision.sim.motion.GaitSettings)')
    p.add_argument('--scene', action='store_true',
                   help='SCENARIO names a scene class (scenes.ALL_CLASSES) even where a '
                        'scenario has the same name')
    p.add_argument('--preset', choices=('backpack', 'chest', 'narrow'), default=None,
                   help="scene classes: the rig ('backpack' default, 'chest' or 'narrow'; "
                        'its mounting drawn from the seed); scenarios: that rig instead of '
                        "the paper's; --width etc. and --rig change it further")
    p.add_argument('--realism', choices=('on', 'off'), default=None,
                   help='scene classes: the camera realism effects on or off (default: '
                        'drawn from the seed, on for about 60 %% of seeds)')
    p.add_argument('--force', action='store_true',
                   help='replace OUT_DIR if it is an existing rosbag2 directory')
    p.add_argument('--quiet', action='store_true', help='no progress output')
    return p


def _settings_changes(items: list[str], cls, option: str) -> dict:
    """``FIELD=VALUE`` strings as changes of the settings dataclass ``cls`` (the CLI
    ``option``, for messages), each value converted to its field's type.

    Raises:
        ValueError: not FIELD=VALUE, an unknown field, or a value of the wrong type.
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    out = {}
    for item in items:
        name, sep, text = item.partition('=')
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"{option} expects FIELD=VALUE, got '{item}'")
        if name not in fields:
            raise ValueError(f"{option}: unknown {option[2:]} setting '{name}'; known: "
                             f"{', '.join(fields)}")
        kind = type(getattr(cls(), name))
        try:
            out[name] = kind(text)
        except ValueError:
            raise ValueError(f"{option} {name}: expected a {kind.__name__}, got '{text}'"
                             ) from None
    return out


def _gait(items: list[str]) -> GaitSettings | None:
    """``--gait`` items: ``extreme`` (the paper's extreme walking motion,
    `GaitSettings.extreme`) and/or ``FIELD=VALUE`` changes of GaitSettings, applied in
    order; None when there are none (the default walker)."""
    if not items:
        return None
    gait = GaitSettings()
    for item in items:
        if item.strip() == 'extreme':
            gait = GaitSettings.extreme()
        else:
            gait = dataclasses.replace(gait, **_settings_changes([item], GaitSettings,
                                                                 '--gait'))
    return gait


def _is_bag_dir(path: Path) -> bool:
    """A directory holding only a rosbag2 (metadata.yaml and storage files)."""
    files = [f for f in path.iterdir()]
    return (path / 'metadata.yaml').is_file() and all(
        f.is_file() and f.suffix in ('.yaml', '.mcap', '.db3', '.zstd') for f in files)


def main(argv: list[str] | None = None) -> int:
    """Entry point. Returns the process exit status."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.list:
        for name, fn in SCENARIOS.items():
            doc = ' '.join((fn.__doc__ or '').split())
            print(f'{name:18s} {DEFAULT_DURATIONS[name]:5.1f} s  {doc}')
        print('scene classes (--scene where the name is also a scenario above):')
        for name in ALL_CLASSES:
            clear = (' (clear)' if name in CLEAR_CLASSES
                     else ' (not in the default plans)' if name in EXTRA_CLASSES else '')
            print(f'{name:18s} {20.0:5.1f} s  {scene_description(name)}{clear}')
        return 0
    if not args.scenario or not args.out_dir:
        parser.print_usage(sys.stderr)
        print('asmonc-sim: error: SCENARIO and OUT_DIR are required (or --list)',
              file=sys.stderr)
        return 2
    scene = args.scene or (args.scenario not in SCENARIOS and args.scenario in ALL_CLASSES)
    if scene and args.scenario not in ALL_CLASSES or (
            not scene and args.scenario not in SCENARIOS):
        print(f"asmonc-sim: error: unknown scenario '{args.scenario}'; known: "
              f"{', '.join(SCENARIOS)}; scene classes: {', '.join(ALL_CLASSES)}",
              file=sys.stderr)
        return 2
    out = Path(args.out_dir)
    if out.exists():
        if not out.is_dir():
            print(f'asmonc-sim: error: {out} exists and is not a directory', file=sys.stderr)
            return 2
        if any(out.iterdir()):
            if not args.force:
                print(f'asmonc-sim: error: {out} exists and is not empty '
                      '(use --force to replace a bag)', file=sys.stderr)
                return 2
            if not _is_bag_dir(out):
                print(f'asmonc-sim: error: --force refuses to delete {out}: it is not a '
                      'rosbag2 directory', file=sys.stderr)
                return 2
            shutil.rmtree(out)
        else:
            out.rmdir()
    try:
        changes = _settings_changes(args.rig, RigSettings, '--rig')
        changes.update({k: v for k, v in (('fps', args.fps), ('width', args.width),
                                          ('height', args.height), ('focal', args.focal))
                        if v is not None})
        if args.duration is not None and not args.duration > 0:
            raise ValueError(f'--duration must be > 0 s, got {args.duration}')
        if scene:
            base = drawn_rig(args.scenario, args.seed, args.preset or 'backpack')
            realism = None if args.realism is None else args.realism == 'on'
            scenario = build_scene(args.scenario, args.seed,
                                   args.duration if args.duration is not None else 20.0,
                                   dataclasses.replace(base, **changes), realism,
                                   gait=_gait(args.gait))
        else:
            base = {'chest': RigSettings.chest, 'narrow': RigSettings.narrow}.get(
                args.preset, RigSettings)()
            rig = dataclasses.replace(base, **changes)
            scenario = make_scenario(args.scenario, seed=args.seed, duration=args.duration,
                                     rig=rig, gait=_gait(args.gait))
    except (ValueError, TypeError) as exc:
        print(f'asmonc-sim: error: {exc}', file=sys.stderr)
        return 2
    from asmonc_vision.sim.bagwriter import write_bag

    t0 = time.monotonic()

    def progress(k: int, n: int) -> None:
        if not args.quiet and (k + 1 == n or (k + 1) % 10 == 0):
            print(f'\r  frame {k + 1}/{n}', end='', file=sys.stderr, flush=True)

    summary = write_bag(scenario, out, progress=progress)
    if not args.quiet:
        print(file=sys.stderr)
    wall = time.monotonic() - t0
    rig = scenario.rig
    print(f'wrote {summary.path}: scenario {scenario.name}, seed {scenario.seed}, '
          f'{summary.frames} stereo frames {rig.width}x{rig.height} at {rig.fps:g} Hz '
          f'({scenario.duration:g} s), {summary.imu} inclinometer samples, '
          f'{summary.size_bytes / 1e6:.2f} MB, in {wall:.1f} s '
          f'({wall / max(summary.frames, 1) * 1e3:.0f} ms/frame)')
    for topic, count in summary.counts.items():
        print(f'  {topic:32s} {count:6d}')
    return 0


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
