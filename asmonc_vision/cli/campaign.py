"""A campaign of random simulated walks, scored for the wearer's safety: ours and the peer.

    asmonc campaign [--minutes 20] [--workers 2] [--blind | --tuning]
                    [--classes CLASS ...] [--rigs backpack chest narrow] [--duration 20]
                    [--walk CLASS:SEED:RIG ... [--trace T0 T1]] [--events]
                    [--methods gpod gpod_ego gpod_map gpod_map_lag gpod_map_wait sgbm]
                    [--cache DIR]
                    [--json FILE]
                    [--markdown FILE] [--no-progress]

Picks walks (scene class, seed, rig) from `sim.scenes` until the minutes are covered,
cycling through the classes with the rigs alternating (`plan_walks`), seeds counting up
from the start of their range, so the same arguments give the same walks. The rigs by
default are the backpack and the chest rig (`DEFAULT_RIGS`: the sets docs/evaluation.md
reports); `--rigs narrow` runs the narrow-baseline module camera, reported apart.
Each walk is rendered once into a cache outside the repository (default
~/.cache/asmonc_vision/campaign/<key>, the key a hash of the scene class, seed, rig,
duration and the simulator's source code) as a rosbag2 bag with the pixels that see
each obstacle in both images beside it
(`truth.json`), and reused when present. On every walk, offline (no ROS), our detector
(``gpod``: GPOD alone, the evidence map off and no motion input), the same given each pair's
motion from the egomotion estimator (``gpod_ego``), our detector with the evidence map
(``gpod_map``: the map on, with each pair's motion at once, as a graph that waits for it),
the map as the detector node runs it (``gpod_map_lag``: the detector with no motion, the
map's motion predicted by `core.map_motion.MotionPredictor` from the motions of the pairs
``eval.bench.MAP_MOTION_LAG`` (1) or more before, as the graph has them without waiting), the map
given each pair's own motion with the detector given none (``gpod_map_wait``: as a graph
whose map, not its detector, would wait for the pair's motion) and the SGBM
peer (`core.baseline`, as `asmonc eval --method sgbm`)
each run over the stereo pairs in order, the alarm node's logic (`core.alarm`,
default settings) is replayed over their outputs in bag time (`eval.alarm_replay`), and
the safety score is taken (`eval.safety`, the definitions of docs/evaluation.md).

Seeds: TUNING walks use seeds 1000-1999, BLIND walks 900000-900999. Tune only on the
tuning seeds and quote the blind ones, which no tuning has looked at. By default both
sets are run, half the minutes each, and reported apart; --blind or --tuning runs one.
`--walk CLASS:SEED:RIG` (repeatable) runs the walks named instead of a plan (each in the
set its seed belongs to): to look again at one walk a table showed.

`--events` prints, under each walk's line, what lies behind its numbers: each false
alarm event (its time in the walk, level, range and bearing, and how far the nearest true
obstacle was), each obstacle on the path that was not warned in time (late, never, or
under FAULT) or was warned by an alarm about something farther off, and how many of the
walk's frames with a hazard on the path had "all clear" in force, per method.

Prints per set a table per scene class and per rig, ours and the peer side by side:
warned in time (warned/on the path), cued (at least 3 s before contact, or as they came
into the corridor; /on the path), false alarm events per 10 minutes of walking, false
reports per frame, recall; then the set's totals, the obstacles warned by an alarm
about something farther off, and the frames with a hazard on the path and "all clear" in
force; and the time per walk-minute
(rendering, each detector). `--trace T0 T1` (with `--walk`) prints under each walk, per
method, every pair from T0 to T1 s into it: the ground status, the alarm in force, each
report, and how far the ground surface was known with the rule that ended it.
`--markdown FILE` writes the tables as Markdown (a results table a document can
include). A progress bar goes to stderr. `--workers N` runs N walks
at once (one process each, one OpenCV thread each). Exit status 0; 2 on bad arguments.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from asmonc_vision.eval.bench import MAP_MOTION_LAG

#: seed ranges (inclusive start, exclusive end)
TUNING_SEEDS = (1000, 2000)
BLIND_SEEDS = (900000, 901000)
#: The rigs a campaign runs unless --rigs says otherwise: those docs/evaluation.md reports
#: its sets on (the narrow-baseline module is run and reported apart).
DEFAULT_RIGS: tuple[str, ...] = ('backpack', 'chest')
METHOD_NAMES = {'gpod': 'ours (GPOD)', 'gpod_ego': 'ours (GPOD + motion)',
                'gpod_map': 'ours (GPOD + map)', 'gpod_map_lag': 'ours (GPOD + map, no wait)',
                'gpod_map_wait': 'ours (GPOD + map, map waits)',
                'sgbm': 'peer (SGBM)'}


def default_cache() -> Path:
    return Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')) / \
        'asmonc_vision' / 'campaign'


def add_arguments(p) -> None:
    from asmonc_vision.sim.scenes import ALL_CLASSES, EXTRA_CLASSES, RIGS, SCENE_CLASSES

    p.add_argument('--minutes', type=float, default=20.0,
                   help='minutes of walks in all (default 20; split evenly between the '
                        'tuning and the blind seeds unless --blind or --tuning)')
    p.add_argument('--workers', type=int, default=1, help='walks processed at once (default 1)')
    which = p.add_mutually_exclusive_group()
    which.add_argument('--blind', action='store_true',
                       help=f'only the BLIND seeds {BLIND_SEEDS[0]}-{BLIND_SEEDS[1] - 1} '
                            '(never tuned on)')
    which.add_argument('--tuning', action='store_true',
                       help=f'only the TUNING seeds {TUNING_SEEDS[0]}-{TUNING_SEEDS[1] - 1}')
    p.add_argument('--classes', nargs='+', choices=ALL_CLASSES,
                   default=list(SCENE_CLASSES),
                   help=f'scene classes (default all but {" ".join(EXTRA_CLASSES)})')
    p.add_argument('--rigs', nargs='+', choices=RIGS, default=list(DEFAULT_RIGS),
                   help=f'rigs (default {" ".join(DEFAULT_RIGS)}; narrow: a 7.5 cm '
                        'baseline module, reported apart)')
    p.add_argument('--duration', type=float, default=20.0, help='seconds per walk (default 20)')
    p.add_argument('--walk', action='append', default=None, metavar='CLASS:SEED:RIG',
                   help='run this walk (repeatable) instead of the plan: a scene class, a '
                        'seed of the tuning or the blind range, a rig; e.g. '
                        'kerb_ramp:1003:chest')
    p.add_argument('--events', action='store_true',
                   help='under each walk, its false alarm events (time, level, range, '
                        'bearing, the nearest true obstacle), the obstacles on the path '
                        'not warned in time, and its frames with a hazard on the path and '
                        '"all clear" in force, per method')
    p.add_argument('--trace', nargs=2, type=float, default=None, metavar=('T0', 'T1'),
                   help='with --walk: under each walk, per method, every pair from T0 to T1 '
                        's into the walk: the ground status, the alarm in force and each '
                        'report (id, height, range, bearing)')
    p.add_argument('--methods', nargs='+', choices=tuple(METHOD_NAMES),
                   default=['gpod_map_lag', 'sgbm'],
                   help='detectors to run: gpod (no map, no motion), gpod_ego (no map, '
                        'each pair\'s motion from the egomotion estimator), gpod_map (the '
                        'evidence map, with each pair\'s motion), gpod_map_lag (the map, its '
                        'motion predicted from the pairs 2 or more before, as the node '
                        'graph runs it: the system), gpod_map_wait (the map given each '
                        'pair\'s own motion, the detector none), sgbm (the peer); default '
                        'gpod_map_lag '
                        'and sgbm')
    p.add_argument('--cache', type=Path, default=None,
                   help='rendered walks are kept here (default ~/.cache/asmonc_vision/campaign)')
    p.add_argument('--json', type=Path, default=None, help='write every number here as JSON')
    p.add_argument('--markdown', type=Path, default=None,
                   help='write the tables here as Markdown')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.set_defaults(func=run)


# --- walks and the cache ------------------------------------------------------------------

@dataclass(frozen=True)
class Walk:
    """One walk of a campaign."""

    seed_set: str
    scene_class: str
    seed: int
    rig: str
    duration: float


def plan_walks(seed_set: str, minutes: float, classes: list[str], rigs: list[str],
               duration: float) -> list[Walk]:
    """Walks covering ``minutes``: the i-th has class i mod C, rig (i mod C + i div C) mod
    R (so the rigs alternate along the classes, and each class meets every rig within
    C x R walks) and seed start + i of the set's range."""
    start, stop = TUNING_SEEDS if seed_set == 'tuning' else BLIND_SEEDS
    n = max(1, math.ceil(minutes * 60.0 / duration - 1e-9))
    if n > stop - start:
        raise ValueError(f'{n} walks exceed the {stop - start} seeds of the {seed_set} set')
    nc = len(classes)
    return [Walk(seed_set, classes[i % nc], start + i, rigs[(i % nc + i // nc) % len(rigs)],
                 float(duration)) for i in range(n)]


def parse_walk(text: str, duration: float) -> Walk:
    """The walk ``CLASS:SEED:RIG`` of `--walk`; its seed set is the range its seed lies
    in. Raises ValueError naming what is wrong."""
    from asmonc_vision.sim.scenes import ALL_CLASSES, RIGS

    parts = text.split(':')
    if len(parts) != 3:
        raise ValueError(f'--walk {text!r}: expected CLASS:SEED:RIG')
    cls, seed_s, rig = parts
    if cls not in ALL_CLASSES:
        raise ValueError(f'--walk {text!r}: scene class {cls!r} is not one of '
                         f'{", ".join(ALL_CLASSES)}')
    if rig not in RIGS:
        raise ValueError(f'--walk {text!r}: rig {rig!r} is not one of {", ".join(RIGS)}')
    try:
        seed = int(seed_s)
    except ValueError:
        raise ValueError(f'--walk {text!r}: seed {seed_s!r} is not an integer') from None
    for name, (lo, hi) in (('tuning', TUNING_SEEDS), ('blind', BLIND_SEEDS)):
        if lo <= seed < hi:
            return Walk(name, cls, seed, rig, float(duration))
    raise ValueError(f'--walk {text!r}: seed {seed} is in neither the tuning seeds '
                     f'{TUNING_SEEDS[0]}-{TUNING_SEEDS[1] - 1} nor the blind seeds '
                     f'{BLIND_SEEDS[0]}-{BLIND_SEEDS[1] - 1}')


def sim_code_version() -> str:
    """A hash of the simulator's source files (the cache is invalid when they change)."""
    import asmonc_vision.sim as sim

    h = hashlib.sha1()
    for p in sorted(Path(sim.__file__).parent.glob('*.py')):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:12]


def cache_key(w: Walk, version: str) -> str:
    doc = json.dumps({'class': w.scene_class, 'seed': w.seed, 'rig': w.rig,
                      'duration': w.duration, 'sim': version}, sort_keys=True)
    return hashlib.sha1(doc.encode()).hexdigest()[:16]


def render_walk(w: Walk, entry: Path) -> tuple[float, float]:
    """Render ``w`` into the cache directory ``entry`` (bag/ and truth.json) unless it is
    there; returns the wall and CPU seconds spent rendering (0 when cached). Written to a temporary
    directory and renamed, so parallel or interrupted runs never see half an entry."""
    from asmonc_vision.eval.truth import visible_pixels
    from asmonc_vision.sim.bagwriter import stamp_ns, write_bag
    from asmonc_vision.sim.scenes import make_scene

    if (entry / 'truth.json').is_file():
        return 0.0, 0.0
    t0, c0 = time.perf_counter(), time.process_time()
    sc = make_scene(w.scene_class, w.seed, duration=w.duration, rig=w.rig)
    fb = sc.rig.camera().fb
    tmp = entry.with_name(f'{entry.name}.tmp{os.getpid()}')
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    visible: dict[int, dict] = {}

    def keep(frame) -> None:
        visible[stamp_ns(frame.time)] = visible_pixels(frame.labels, frame.depth, fb)

    write_bag(sc, tmp / 'bag', on_frame=keep)
    doc = {'walk': {'class': w.scene_class, 'seed': w.seed, 'rig': w.rig,
                    'duration': w.duration}, 'visible': {str(k): v for k, v in visible.items()}}
    (tmp / 'truth.json').write_text(json.dumps(doc))
    try:
        tmp.rename(entry)
    except OSError:                 # another process finished it first
        shutil.rmtree(tmp, ignore_errors=True)
    return time.perf_counter() - t0, time.process_time() - c0


def score_walk(w: Walk, cache: Path, methods: list[str], version: str,
               trace: tuple[float, float] | None = None) -> dict:
    """Render (or reuse) a walk, run each method with the alarm logic, score it.

    Args:
        trace: (t0, t1) s into the walk: also the pairs between, per method
            (`trace_lines`).
    Returns:
        {'walk': Walk, 'render_s', 'render_cpu_s': wall and CPU seconds of rendering (0
         when cached), 'frames': int, 'scores': {method: SafetyScore},
         'detect_s', 'detect_cpu_s': {method: wall and CPU seconds},
         'trace': {method: [str]} (empty without `trace`)}.
    """
    from asmonc_vision.eval.bench import run_method
    from asmonc_vision.io.frames import load_frames
    from asmonc_vision.eval.alarm_replay import replay_alarms
    from asmonc_vision.eval.safety import score_safety
    from asmonc_vision.eval.truth import truth_from_bag

    entry = cache / cache_key(w, version)
    render_s, render_cpu_s = render_walk(w, entry)
    frames = load_frames(entry / 'bag')
    vis = json.loads((entry / 'truth.json').read_text())['visible']
    truth = truth_from_bag(entry / 'bag', frames, {int(k): v for k, v in vis.items()})
    scores, detect_s, detect_cpu_s, traced = {}, {}, {}, {}
    for m in methods:
        t0, c0 = time.perf_counter(), time.process_time()
        runs = (run_method(frames, 'gpod', map_enabled=m.startswith('gpod_map'),
                           egomotion=m != 'gpod',
                           motion_lag=MAP_MOTION_LAG if m == 'gpod_map_lag' else 0,
                           map_waits=m == 'gpod_map_wait')
                if m.startswith('gpod') else run_method(frames, m, egomotion=True))
        detect_s[m] = time.perf_counter() - t0
        detect_cpu_s[m] = time.process_time() - c0
        alarms = replay_alarms([(r.stamp_ns, r.status, r.obstacles) for r in runs],
                               motions=[r.ego_t for r in runs])
        scores[m] = score_safety(truth, alarms, {r.stamp_ns: r.obstacles for r in runs})
        if trace is not None:
            traced[m] = trace_lines(runs, alarms, trace)
    return {'walk': w, 'render_s': render_s, 'render_cpu_s': render_cpu_s,
            'frames': len(frames), 'scores': scores, 'detect_s': detect_s,
            'detect_cpu_s': detect_cpu_s, 'trace': traced}


def _score_walk_job(args):
    return score_walk(*args)


def trace_lines(runs, alarms: list[dict], window: tuple[float, float]) -> list[str]:
    """`--trace`: per pair whose time into the walk (from the first pair) lies in
    `window` (s): the time, the ground status, the alarm in force
    (`eval.evaluation.alarm_in_force`) and each report: id, height (cm; a drop negative,
    '?' for ground that cannot be seen), range (m), bearing (degrees, left +); for GPOD
    also how far the ground surface ahead is known (m along the ground) and the rule
    that ended it (`GroundSurface.ended_by`)."""
    from asmonc_vision.core.alarm import AlarmLevel
    from asmonc_vision.eval.evaluation import alarm_in_force

    if not runs:
        return []
    t_first = runs[0].stamp_ns
    in_force = alarm_in_force([r.stamp_ns for r in runs], alarms)
    out = []
    for r, k in zip(runs, in_force):
        t = (r.stamp_ns - t_first) / 1e9
        if not window[0] <= t <= window[1]:
            continue
        now = alarms[k] if k >= 0 else None
        said = ('-' if now is None else f"{AlarmLevel(int(now['level'])).name} "
                f"\"{now['text']}\"")
        o = r.obstacles
        reports = ('no answer' if o is None else '; '.join(
            f'id {int(o.ids[i])} '
            + ('?' if not math.isfinite(o.height[i]) else f'{o.height[i] * 100:+.0f} cm')
            + f' {o.range[i]:.2f} m {math.degrees(o.bearing[i]):+.0f} deg'
            for i in range(len(o.ids))) or 'none')
        ground = ('' if r.ground is None else f'  |  ground known to {r.ground[0]:.1f} m'
                  + (f', then {r.ground[1]}' if r.ground[1] else ''))
        out.append(f'{t:6.2f} s  {r.status or "-":12s} {said}  |  {reports}{ground}')
    return out


# --- report -------------------------------------------------------------------------------

def _cell(s) -> list[str]:
    """warned x/y; cued x/y (cued at least `cue_lead_s` before contact, or as they came
    into the corridor: `eval.safety`); false alarm events per 10 min walking; false
    reports per frame; recall; the share of walking time with FAULT in force."""
    fa = (f'{len(s.false_alarm_events) / s.walking_s * 600:.1f}' if s.walking_s > 0 else '-')
    fr = f'{s.false_reports_per_frame:.3f}' if s.false_reports_per_frame is not None else '-'
    rc = f'{s.recall:.0%}' if s.recall is not None else '-'
    fs = f'{s.fault_share_walking:.1%}' if s.fault_share_walking is not None else '-'
    return [f'{s.warned}/{s.on_path}', f'{s.cued_ahead + s.cued_at_entry}/{s.on_path}', fa, fr,
            rc, fs]


def table(results: list[dict], methods: list[str], title: str) -> list[str]:
    """The printed table of one seed set: per class, per rig, totals."""
    from asmonc_vision.eval.safety import SafetyScore

    heads = ['warned', 'cued', 'FA/10min', 'FR/frame', 'recall', 'FAULT']
    w0 = 22
    line1 = f'{"":{w0}s} {"walks":>5s} {"min":>5s} ' + ''.join(
        f'| {METHOD_NAMES[m]:<56s}' for m in methods)
    line2 = f'{"":{w0}s} {"":5s} {"":5s} ' + ''.join(
        '| ' + ''.join(f'{h:>9s}' for h in heads) + '  ' for _ in methods)
    out = [f'=== {title} ===', line1, line2]

    def row(label: str, rs: list[dict]) -> str:
        walk_min = sum(r['walk'].duration for r in rs) / 60.0
        cells = ''
        for m in methods:
            s = SafetyScore.merge([r['scores'][m] for r in rs])
            cells += '| ' + ''.join(f'{c:>9s}' for c in _cell(s)) + '  '
        return f'{label:<{w0}s} {len(rs):5d} {walk_min:5.1f} {cells}'

    for key, name in (('scene_class', 'class'), ('rig', 'rig')):
        for v in sorted({getattr(r['walk'], key) for r in results}):
            out.append(row(f'{name} {v}', [r for r in results if getattr(r['walk'], key) == v]))
    out.append(row('all', results))
    totals = [SafetyScore.merge([r['scores'][m] for r in results]) for m in methods]
    out.append('of the obstacles warned, warned by an alarm about something farther off '
               '(the obstacle itself unseen then): '
               + ', '.join(f'{METHOD_NAMES[m]} {s.warned_by_farther}/{s.warned}'
                           for m, s in zip(methods, totals)))
    out.append('frames on the path with "all clear" in force (a hazard there, the wearer '
               'told the way is clear): '
               + ', '.join(f'{METHOD_NAMES[m]} {s.frames_on_path_clear}/{s.frames_on_path}'
                           for m, s in zip(methods, totals)))
    return out


def markdown_table(results: list[dict], methods: list[str], title: str) -> list[str]:
    """The table of one seed set as Markdown: per class, per rig, totals; per method
    warned x/y, cued x/y, false alarm events per 10 minutes of walking, false reports per
    frame."""
    from asmonc_vision.eval.safety import SafetyScore

    head = ['', 'walks', 'min'] + [f'{METHOD_NAMES[m]} {h}' for m in methods
                                   for h in ('warned', 'cued', 'FA/10 min', 'FR/frame')]
    out = [f'**{title}**', '', '| ' + ' | '.join(head) + ' |',
           '|' + '---|' * len(head)]

    def row(label: str, rs: list[dict]) -> str:
        cells = [label, str(len(rs)), f"{sum(r['walk'].duration for r in rs) / 60.0:.1f}"]
        for m in methods:
            cells += _cell(SafetyScore.merge([r['scores'][m] for r in rs]))[:4]
        return '| ' + ' | '.join(cells) + ' |'

    for key, name in (('scene_class', 'class'), ('rig', 'rig')):
        for v in sorted({getattr(r['walk'], key) for r in results}):
            out.append(row(f'{name} {v}', [r for r in results if getattr(r['walk'], key) == v]))
    out.append(row('**all**', results))
    return out


def summary_json(results: list[dict], methods: list[str]) -> dict:
    from asmonc_vision.eval.safety import SafetyScore

    def merged(rs):
        return {m: SafetyScore.merge([r['scores'][m] for r in rs]).as_dict() for m in methods}

    doc = {'walks': [{'seed_set': r['walk'].seed_set, 'class': r['walk'].scene_class,
                      'seed': r['walk'].seed, 'rig': r['walk'].rig,
                      'duration_s': r['walk'].duration, 'frames': r['frames'],
                      'render_s': r['render_s'], 'render_cpu_s': r['render_cpu_s'],
                      'detect_s': r['detect_s'], 'detect_cpu_s': r['detect_cpu_s'],
                      'safety': {m: r['scores'][m].as_dict() for m in methods}}
                     for r in results]}
    for seed_set in sorted({r['walk'].seed_set for r in results}):
        rs = [r for r in results if r['walk'].seed_set == seed_set]
        doc[seed_set] = {'all': merged(rs)}
        for key in ('scene_class', 'rig'):
            for v in sorted({getattr(r['walk'], key) for r in rs}):
                doc[seed_set][f'{key}={v}'] = merged(
                    [r for r in rs if getattr(r['walk'], key) == v])
    return doc


def timing_lines(results: list[dict], methods: list[str]) -> list[str]:
    """Seconds per walk-minute, wall clock / CPU: rendering (walks rendered in this run)
    and each detector (with its alarm logic and scoring, which take little)."""
    out = ['time per walk-minute, wall / CPU seconds (per worker; wall includes waiting for a '
           'shared core):']
    for rig in sorted({r['walk'].rig for r in results}):
        rs = [r for r in results if r['walk'].rig == rig]
        rendered = [r for r in rs if r['render_s'] > 0]
        parts = []
        if rendered:
            mins = sum(r['walk'].duration for r in rendered) / 60.0
            parts.append(f"render {sum(r['render_s'] for r in rendered) / mins:.0f} / "
                         f"{sum(r['render_cpu_s'] for r in rendered) / mins:.0f} s")
        else:
            parts.append('render - (all cached)')
        minutes = sum(r['walk'].duration for r in rs) / 60.0
        for m in methods:
            parts.append(f"{m} {sum(r['detect_s'][m] for r in rs) / minutes:.0f} / "
                         f"{sum(r['detect_cpu_s'][m] for r in rs) / minutes:.0f} s")
        out.append(f'  {rig}: ' + ', '.join(parts))
    return out


def walk_line(r: dict, methods: list[str]) -> str:
    """One line per finished walk: its scores per method."""
    w = r['walk']
    cells = '; '.join(f"{m} " + ' '.join(_cell(r['scores'][m])) for m in methods)
    return (f"  {w.seed_set:6s} {w.scene_class:15s} {w.seed:6d} {w.rig:8s}: {cells}  "
            f"(render {r['render_s']:.0f} s, detect "
            + ' + '.join(f"{r['detect_s'][m]:.0f}" for m in methods) + ' s)')


def event_lines(r: dict, methods: list[str]) -> list[str]:
    """`--events`: per method, the walk's false alarm events and its obstacles on the
    path not warned in time (`eval.safety.format_events`), and how many of its frames
    with a hazard on the path had "all clear" in force."""
    from asmonc_vision.eval.safety import format_events

    out = []
    for m in methods:
        s = r['scores'][m]
        out += [f'      {m}: {line.strip()}' for line in format_events(s.as_dict())]
        if s.frames_on_path_clear:
            out.append(f'      {m}: "all clear" in force in {s.frames_on_path_clear} of the '
                       f'{s.frames_on_path} frames with a hazard on the path')
    return out


class _Bar:
    """Progress on stderr: a bar redrawn in place on a terminal, else a line per walk."""

    def __init__(self, total: int, on: bool):
        self.total, self.on, self.t0 = total, on, time.monotonic()
        self.tty = sys.stderr.isatty()

    def show(self, done: int, note: str = '') -> None:
        if not self.on:
            return
        w = 30
        k = int(w * done / max(self.total, 1))
        el = time.monotonic() - self.t0
        eta = el / done * (self.total - done) if done else 0.0
        sys.stderr.write(f'{chr(13) if self.tty else ""}  walks [{"#" * k}{"." * (w - k)}] '
                         f'{done}/{self.total} {el / 60:5.1f} min, ~{eta / 60:.1f} min left '
                         f'{note[:30]:30s}' + ('' if self.tty else '\n'))
        sys.stderr.flush()

    def clear(self) -> None:
        if self.on and self.tty:
            sys.stderr.write('\r' + ' ' * 100 + '\r')
            sys.stderr.flush()

    def end(self) -> None:
        if self.on and self.tty:
            sys.stderr.write('\n')
            sys.stderr.flush()


def run(args) -> int:
    err = lambda s: print(f'asmonc campaign: {s}', file=sys.stderr)  # noqa: E731
    if not args.minutes > 0 or args.workers < 1 or not 1.0 <= args.duration <= 600.0:
        err('--minutes must be > 0, --workers >= 1, --duration in [1, 600] s')
        return 2
    if args.trace is not None and (not args.walk or args.trace[0] > args.trace[1]):
        err('--trace T0 T1 needs --walk and T0 <= T1')
        return 2
    sets = ['blind'] if args.blind else ['tuning'] if args.tuning else ['tuning', 'blind']
    try:
        if args.walk:
            walks = list(dict.fromkeys(parse_walk(t, args.duration) for t in args.walk))
            sets = [s for s in ('tuning', 'blind') if any(w.seed_set == s for w in walks)]
        else:
            walks = [w for s in sets for w in plan_walks(s, args.minutes / len(sets),
                                                          args.classes, args.rigs,
                                                          args.duration)]
    except ValueError as exc:
        err(str(exc))
        return 2
    cache = args.cache or default_cache()
    cache.mkdir(parents=True, exist_ok=True)
    version = sim_code_version()
    chosen = (', '.join(f'{w.scene_class}:{w.seed}:{w.rig}' for w in walks) if args.walk
              else f'classes {", ".join(args.classes)}, rigs {", ".join(args.rigs)}')
    print(f'asmonc campaign: {len(walks)} walks of {args.duration:g} s ({", ".join(sets)} '
          f'seeds), {chosen}; {args.workers} worker(s); cache {cache} (simulator {version})',
          flush=True)
    bar = _Bar(len(walks), not args.no_progress)
    bar.show(0)
    results = []
    trace = tuple(args.trace) if args.trace is not None else None
    jobs = [(w, cache, list(args.methods), version, trace) for w in walks]
    t0 = time.monotonic()
    print('per walk: warned, cued, false alarm events per 10 min walking, false reports per '
          'frame, recall', flush=True)

    def done(r: dict) -> None:
        results.append(r)
        w = r['walk']
        bar.clear()
        print(walk_line(r, list(args.methods)), flush=True)
        if args.events:
            for line in event_lines(r, list(args.methods)):
                print(line, flush=True)
        for m, lines in r['trace'].items():
            print(f'      {m}: pairs from {args.trace[0]:g} to {args.trace[1]:g} s', flush=True)
            for line in lines:
                print(f'        {line}', flush=True)
        bar.show(len(results), f'{w.scene_class} {w.seed} {w.rig}')

    if args.workers == 1:
        for j in jobs:
            done(score_walk(*j))
    else:
        with ProcessPoolExecutor(max_workers=args.workers) as ex:
            futs = [ex.submit(_score_walk_job, j) for j in jobs]
            for f in as_completed(futs):
                done(f.result())
    bar.end()
    order = {w: i for i, w in enumerate(walks)}
    results.sort(key=lambda r: order[r['walk']])
    print('warned = obstacles on the path warned in time / on the path; cued = cued 3 s '
          'before contact, standing or as they came into the corridor / on the path; '
          'FA/10min = false alarm events per 10 minutes of walking; FR/frame = false '
          'reports per frame; recall = (obstacle, frame) pairs found (EVALUATION.md); '
          'FAULT = share of walking time with FAULT in force ("cannot see the way ahead", '
          'a lost ground, a sensor fault)')
    for s in sets:
        rs = [r for r in results if r['walk'].seed_set == s]
        lo, hi = TUNING_SEEDS if s == 'tuning' else BLIND_SEEDS
        print()
        print('\n'.join(table(rs, list(args.methods),
                              f'{s.upper()} seeds {lo}-{hi - 1}: {len(rs)} walks')))
    print()
    print('\n'.join(timing_lines(results, list(args.methods))))
    print(f'campaign wall time {(time.monotonic() - t0) / 60:.1f} min')
    if args.markdown is not None:
        md = []
        for s in sets:
            rs = [r for r in results if r['walk'].seed_set == s]
            lo, hi = TUNING_SEEDS if s == 'tuning' else BLIND_SEEDS
            md += markdown_table(rs, list(args.methods),
                                 f'{s.upper()} seeds {lo}-{hi - 1}: {len(rs)} walks of '
                                 f'{args.duration:g} s') + ['']
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text('\n'.join(md))
        print(f'markdown: {args.markdown}')
    if args.json is not None:
        from asmonc_vision.eval.evaluation import json_ready
        doc = summary_json(results, list(args.methods))
        doc['arguments'] = {'minutes': args.minutes, 'workers': args.workers, 'sets': sets,
                            'classes': args.classes, 'rigs': args.rigs,
                            'duration': args.duration, 'methods': args.methods,
                            'simulator': version}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(json_ready(doc), indent=1, allow_nan=False) + '\n')
        print(f'json: {args.json}')
    return 0
