"""Does the walk model earn its place? Its 0.5 s-ahead pitch prediction against holding the
last measurement, without and with the fallback rule (core/gait/fallback.py).

    python -m asmonc_vision.eval.gait_fallback [--seeds 41 42] [--data DIR] [--json F]

Simulated walks (``asmonc gait sim``'s *stop* and *turn* scenarios, seeds not used to
tune the model: 41 and 42 by default), scored against the simulator's true attitude
0.5 s later, after the first second; and the real lower-back walking recordings
(Mobilise-D, ``../shared/data/gait_lowback``: the straight walks Test5 and the
daily-living walks with stops and turns Test11, pooled over the participants), scored
against the measured attitude 0.5 s later within the reference walking bouts, as
``asmonc gait real`` does. Prints one row per case: pitch RMS error (deg) of the model
(fallback off), of holding, and of the model with the fallback rule.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from asmonc_vision.core.gait import GaitConfig
from asmonc_vision.core.gait import scoring

HORIZON = 0.5
SIM_SCENARIOS = ('stop', 'turn')
HELD_OUT_SEEDS = (41, 42)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e))) if e.size else float('nan')


def _pitch_rms(pred, truth, mask) -> float:
    return _rms(scoring.angle_errors_deg(pred, truth)[mask, 1])


def sim_rows(seeds=HELD_OUT_SEEDS, scenarios=SIM_SCENARIOS,
             config: GaitConfig | None = None) -> list[dict]:
    """Pitch RMS 0.5 s ahead on simulated walks: model, hold, with fallback."""
    from asmonc_vision.eval.gait_walks import make_case, run_tracker
    cfg = config if config is not None else GaitConfig()
    rows = []
    for seed in seeds:
        for name in scenarios:
            case = make_case(name, seed)
            runs = {on: run_tracker(case.imu_times, case.imu_rpy, case.imu_variance,
                                    dataclasses.replace(cfg, fallback=on))
                    for on in (False, True)}
            t = runs[False].times
            _, truth = case.walker.states(t + HORIZON)
            hold = case.imu_rpy[np.searchsorted(case.imu_times, t)]
            inside = (t >= 1.0) & (t + HORIZON <= case.duration)
            rows.append({'case': f'sim {name} seed {seed}', 'samples': int(inside.sum()),
                         'model': _pitch_rms(runs[False].predicted, truth, inside),
                         'hold': _pitch_rms(hold, truth, inside),
                         'fallback': _pitch_rms(runs[True].predicted, truth, inside)})
    return rows


def real_rows(data: Path, config: GaitConfig | None = None,
              tests=('Test5', 'Test11')) -> list[dict]:
    """Pitch RMS 0.5 s ahead within the reference bouts of the real recordings, pooled
    per test: model, hold, with fallback."""
    from asmonc_vision.eval.gait_real import REAL_SIGMA, load_real, real_config
    from asmonc_vision.eval.gait_walks import run_tracker
    cfg = real_config(config)
    errs: dict[str, dict[str, list]] = {t: {'model': [], 'hold': [], 'fallback': []}
                                        for t in tests}
    for rec in load_real(data, tests):
        test = rec.name.split()[1]
        runs = {on: run_tracker(rec.times, rec.rpy, REAL_SIGMA ** 2,
                                dataclasses.replace(cfg, fallback=on)) for on in (False, True)}
        t = runs[False].times
        later = np.column_stack([np.interp(t + HORIZON, rec.times, rec.rpy[:, a])
                                 for a in range(3)])
        in_bout = np.zeros(t.size, bool)
        for s, e in rec.bouts:
            in_bout |= (t >= s) & (t + HORIZON <= e)
        for key, pred in (('model', runs[False].predicted), ('hold', rec.rpy[:t.size]),
                          ('fallback', runs[True].predicted)):
            errs[test][key].append(scoring.angle_errors_deg(pred, later)[in_bout, 1])
    rows = []
    for test, e in errs.items():
        if not e['model']:
            continue
        cat = {k: np.concatenate(v) for k, v in e.items()}
        rows.append({'case': f'real {test} (all participants)',
                     'samples': int(cat['model'].size),
                     **{k: _rms(v) for k, v in cat.items()}})
    return rows


def print_table(rows: list[dict], file=sys.stdout) -> None:
    print('pitch RMS error of the 0.5 s-ahead prediction, deg', file=file)
    print(f"{'case':<34} {'samples':>7} {'model':>7} {'hold':>7} {'fallback':>9}", file=file)
    for r in rows:
        print(f"{r['case']:<34} {r['samples']:7d} {r['model']:7.2f} {r['hold']:7.2f} "
              f"{r['fallback']:9.2f}", file=file)


def main(argv: list[str] | None = None) -> int:
    from asmonc_vision.eval.gait_walks import DEFAULT_DATA
    p = argparse.ArgumentParser(prog='python -m asmonc_vision.eval.gait_fallback',
                                description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--seeds', type=int, nargs='+', default=list(HELD_OUT_SEEDS))
    p.add_argument('--data', type=Path, default=DEFAULT_DATA,
                   help='the gait_lowback folder of the real walking data')
    p.add_argument('--json', type=Path, default=None)
    args = p.parse_args(argv)
    rows = sim_rows(args.seeds)
    try:
        rows += real_rows(args.data)
    except FileNotFoundError as exc:
        print(f'real walking data not found, simulated walks only: {exc}', file=sys.stderr)
    print_table(rows)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
