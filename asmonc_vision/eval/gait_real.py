"""The walk model on the real lower-back walking recordings (`asmonc gait real`): loading
them (`load_real`), the references (a window fit, a Fourier-combiner bound), scoring
(`score_real`, `evaluate_real`) and the print-out. The command's help (`cli.gait`) says
what is reported.
"""
from __future__ import annotations

import dataclasses
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmonc_vision.core.gait import GaitConfig, scoring
from asmonc_vision.eval.gait_walks import (DEFAULT_DATA, HORIZON, TrackerRun, as_floats,
                                           fmt3, run_tracker)


REAL_RATE = 100.0
#: "steady" part of a reference bout: without its first and last second
REAL_TRIM = 1.0
#: time constant of the complementary filter for the real recordings, s: long enough
#: that walking accelerations (0.1-0.3 g at the step) leak little into the tilt (about
#: k / omega = 1 / (tau 2 pi 1.8 Hz), 3 %), short enough for the gyroscope's drift
REAL_ATTITUDE_TIME_CONSTANT = 3.0
#: event tolerances of the walk start/stop precision and recall, s
EVENT_TOLERANCES = (0.5, 1.0)


@dataclass(frozen=True)
class RealRecording:
    """One Mobilise-D lower-back recording, as a 16 Hz compass would give it."""

    name: str                      # e.g. 'HA/001 Test5 Trial1'
    times: np.ndarray              # (M,) s from the recording's start
    rpy: np.ndarray                # (M, 3) rad
    bouts: list                    # reference walking bouts [(start, end)] s
    reference: str                 # 'INDIP', 'Stereophoto' or 'none'
    turns: list                    # reference turns [(start, end, angle_deg)]
    cadence: list = dataclasses.field(default_factory=list)   # per bout, steps/s (or nan)


def _bouts_of(standards) -> tuple[list, str, list, list]:
    for ref in ('INDIP', 'Stereophoto'):
        s = getattr(standards, ref, None)
        if s is None:
            continue
        mw = np.atleast_1d(getattr(s, 'MicroWB', np.array([])))
        items = [m for m in mw if hasattr(m, 'Start')]
        if items:
            bouts = [(float(m.Start), float(m.End)) for m in items]
            cadence = [float(np.nanmean(np.atleast_1d(getattr(m, 'Cadence', np.nan))))
                       / 60.0 for m in items]
            turns = []
            for m in items:
                ts, te, ta = (np.atleast_1d(getattr(m, k, [])).astype(float)
                              for k in ('Turn_Start', 'Turn_End', 'Turn_Angle'))
                turns += list(zip(ts, te, ta))
            return bouts, ref, turns, cadence
    return [], 'none', [], []


def load_real(data: Path, tests=('Test5', 'Test11')) -> list[RealRecording]:
    """The lower-back recordings (CSV: acc in g, gyr in deg/s, 100 Hz) with their
    reference bouts from data.mat; attitude by the complementary filter
    (``REAL_ATTITUDE_TIME_CONSTANT``), decimated to 16 Hz.

    Raises:
        FileNotFoundError: the data directory is missing.
    """
    import scipy.io as sio

    from asmonc_vision.core.gait.attitude import (MOBILISE_TO_BODY, complementary_filter,
                                                  decimate_to)

    csv_root, mat_root = Path(data) / 'data_csv', Path(data) / 'data' / 'lab'
    if not csv_root.is_dir():
        raise FileNotFoundError(f'no gait data at {data} (expected data_csv/ and data/lab/)')
    out = []
    for f in sorted(csv_root.glob('*/*/TimeMeasure1_Test*_Trial*.csv')):
        group, pid = f.parent.parent.name, f.parent.name
        _, test, trial = f.stem.split('_')
        if test not in tests:
            continue
        a = np.loadtxt(f, delimiter=',', skiprows=1)
        acc = a[:, 1:4] @ MOBILISE_TO_BODY.T
        gyr = np.radians(a[:, 4:7]) @ MOBILISE_TO_BODY.T
        rpy100 = complementary_filter(acc, gyr, REAL_RATE, REAL_ATTITUDE_TIME_CONSTANT)
        t16, rpy16 = decimate_to(rpy100, REAL_RATE, 16.0)
        bouts, ref, turns, cadence = [], 'none', [], []
        mat = mat_root / group / pid / 'data.mat'
        if mat.exists():
            d = sio.loadmat(mat, squeeze_me=True, struct_as_record=False)['data']
            tr = getattr(getattr(d.TimeMeasure1, test), trial)
            bouts, ref, turns, cadence = _bouts_of(tr.Standards)
        out.append(RealRecording(f'{group}/{pid} {test} {trial}', t16, rpy16, bouts, ref,
                                 turns, cadence))
    return out


#: the walk model for the real recordings: the attitude comes from a complementary filter
#: decimated without lag (no compass lag to compensate); everything else as default
def real_config(config: GaitConfig | None = None) -> GaitConfig:
    base = config if config is not None else GaitConfig()
    return dataclasses.replace(base, sensor_lag=0.0)


#: nominal noise of the decimated complementary-filter attitude, rad
REAL_SIGMA = math.radians(0.1)


def window_fit_prediction(times, rpy, horizon: float = HORIZON, window: float = 2.0,
                          config: GaitConfig | None = None) -> np.ndarray:
    """A reference predictor: at every sample, fit the walk model's stride harmonics by
    least squares to the last `window` seconds (best step frequency on the grid by the
    lock check's criterion; the trend is fitted but not extrapolated) and evaluate it
    `horizon` ahead. No filtering, no state. NaN where the window is not full."""
    from asmonc_vision.core.gait.detector import LOCK_CRITERION, fit_walk

    cfg = config if config is not None else GaitConfig()
    freqs = np.arange(cfg.min_frequency, cfg.max_frequency + 1e-9, 0.02)
    t = np.asarray(times, float)
    out = np.full((t.size, 3), np.nan)
    for i in range(t.size):
        if t[i] - t[0] < window:
            continue
        m = (t > t[i] - window) & (t <= t[i])
        fit = fit_walk(t[m] - t[i], rpy[m], freqs, cfg.harmonics, *LOCK_CRITERION)
        if fit is None:
            continue
        for a in range(3):
            c = fit.coefficients[a]
            k = np.arange(1, c.size + 1)
            out[i, a] = fit.offset[a] + float(np.sum(np.imag(
                c * np.exp(1j * k * np.pi * fit.frequency * horizon))))
    return out


def _harmonic_design(tau, f_stride: float, ks, trend: bool = False) -> np.ndarray:
    cols = [np.ones_like(tau)] + ([tau] if trend else [])
    for k in ks:
        cols += [np.sin(2 * np.pi * k * f_stride * tau), np.cos(2 * np.pi * k * f_stride * tau)]
    return np.column_stack(cols)


def bout_stride_frequency(t, y, ks=(1, 2)) -> tuple[float, float]:
    """Non-causal: the stride frequency (Hz, 0.6-1.3) whose harmonics ``ks`` (with
    offset and trend) fit the whole bout best, and that fit's rms residual (rad)."""
    tau = np.asarray(t, float) - t[0]
    best = (np.inf, 0.0)
    for f in np.arange(0.6, 1.3, 0.005):
        X = _harmonic_design(tau, f, ks, trend=True)
        r = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        best = min(best, (float(np.sqrt(np.mean(r * r))), float(f)))
    return best[1], best[0]


#: the oracle-aided Fourier-combiner benchmark's settings (the best on these recordings,
#: pooled: optimistic): stride harmonics, random walks of offset and coefficients
#: (deg / sqrt(s)), measurement noise (deg), initial coefficient spread (deg)
FLC_BOUND = {'ks': (1, 2, 3), 'q_offset': 2.0, 'q_coef': 0.25, 'r': 1.0, 'p0': 3.0}


def fourier_combiner_bound(rec: RealRecording, horizon: float = HORIZON, axis: int = 1
                           ) -> np.ndarray:
    """An oracle-aided benchmark (not an upper bound) for a causal walk model on a
    recording: a linear Kalman filter of the stride harmonics (a Fourier linear
    combiner), started at each reference bout's start (known only afterwards) and
    *given* the bout's own stride frequency (found non-causally over the whole bout,
    ``bout_stride_frequency``), predicting ``horizon`` ahead; its noise levels were
    chosen on these recordings. Started 1 s before the reference start it is hardly
    better than holding the last value (docs/gait.md, section 4.3). NaN outside the
    bouts."""
    s = FLC_BOUND
    t = rec.times
    out = np.full(t.size, np.nan)
    d = math.radians
    for b0, b1 in rec.bouts:
        m = (t >= b0) & (t <= b1)
        if m.sum() < 8:
            continue
        f0, _ = bout_stride_frequency(t[m], rec.rpy[m, axis])
        n = 1 + 2 * len(s['ks'])
        idx = np.flatnonzero(m)
        x = np.zeros(n)
        x[0] = rec.rpy[idx[0], axis]
        P = np.eye(n) * d(s['p0']) ** 2
        P[0, 0] = d(1.0) ** 2
        dt = 1.0 / 16.0
        Q = np.diag([d(s['q_offset']) ** 2] + [d(s['q_coef']) ** 2] * (n - 1)) * dt
        for i in idx:
            tau = np.array([t[i] - t[idx[0]]])
            H = _harmonic_design(tau, f0, s['ks'])[0]
            P = P + Q                                      # P = P + Q (random walks)
            S = H @ P @ H + d(s['r']) ** 2                 # S = H P H^T + R
            K = P @ H / S                                  # K = P H^T S^-1
            x = x + K * (rec.rpy[i, axis] - H @ x)         # x = x + K (z - H x)
            P = P - np.outer(K, H @ P)                     # P = (I - K H) P
            out[i] = _harmonic_design(tau + horizon, f0, s['ks'])[0] @ x
    return out


def score_real(rec: RealRecording, run: TrackerRun, horizon: float = HORIZON) -> dict:
    """0.5 s-ahead prediction vs the later measured attitude, and vs holding the last
    value, for samples whose t and t + horizon lie inside a reference bout; reference
    predictors; detected walk starts/stops against the reference bouts; the tracked
    step frequency against the reference cadence."""
    t = run.times
    later = np.column_stack([np.interp(t + horizon, rec.times, rec.rpy[:, a]) for a in range(3)])
    in_bout = np.zeros(t.size, bool)
    steady = np.zeros(t.size, bool)
    for s, e in rec.bouts:
        in_bout |= (t >= s) & (t + horizon <= e)
        steady |= (t >= s + REAL_TRIM) & (t + horizon <= e - REAL_TRIM)
    pe_all = scoring.angle_errors_deg(run.predicted, later)
    he_all = scoring.angle_errors_deg(rec.rpy[:t.size], later)
    sel = np.flatnonzero(in_bout)
    wf = np.full((t.size, 3), np.nan)
    if sel.size:
        lo = max(0, sel[0] - 40)
        wf[lo:sel[-1] + 1] = window_fit_prediction(t[lo:sel[-1] + 1],
                                                   rec.rpy[lo:sel[-1] + 1], horizon)
    fit_err = scoring.angle_errors_deg(wf, later)
    flc = fourier_combiner_bound(rec, horizon)
    flc_err = np.degrees(flc - later[:, 1])
    floor = []
    for s, e in rec.bouts:
        m = (rec.times >= s) & (rec.times <= e)
        if m.sum() >= 8:
            floor.append((int(m.sum()), bout_stride_frequency(rec.times[m], rec.rpy[m, 1])[1]))
    up, down = scoring.transitions(t, run.walking)
    events = {}
    for tol in EVENT_TOLERANCES:
        events[f'start_{tol:g}s'] = scoring.event_precision_recall(
            [b[0] for b in rec.bouts], up, tol)
        events[f'end_{tol:g}s'] = scoring.event_precision_recall(
            [b[1] for b in rec.bouts], down, tol)
    cad = []
    for (s, e), c in zip(rec.bouts, rec.cadence or [np.nan] * len(rec.bouts)):
        m = (t >= s) & (t <= e) & run.walking
        if m.any() and np.isfinite(c):
            cad.append((float(np.median(run.frequency[m])), c))
    detected = scoring.bouts(t, run.walking)
    return {'name': rec.name, 'reference': rec.reference, 'n': int(in_bout.sum()),
            'pred_err': pe_all[in_bout], 'hold_err': he_all[in_bout],
            'pred_err_steady': pe_all[steady], 'hold_err_steady': he_all[steady],
            'fit_err': fit_err[in_bout], 'flc_err': flc_err[in_bout],
            'floor': floor, 'events': events, 'cadence': cad,
            'detected_bouts': len(detected),
            'short_bouts': sum(1 for a, b in detected if b - a < 2.0),
            'bouts': len(rec.bouts),
            'walking_share': float(np.mean(run.walking[in_bout])) if in_bout.any()
            else float('nan')}


def _gain(p, h) -> float:
    return float(100.0 * (1.0 - p / h)) if h > 0 else float('nan')


def evaluate_real(data: Path = DEFAULT_DATA, config: GaitConfig | None = None,
                  recordings=None) -> dict:
    """Run the walk model on every recording; per-recording and pooled results."""
    cfg = real_config(config)
    recs = recordings if recordings is not None else load_real(data)
    rows = []
    for rec in recs:
        run = run_tracker(rec.times, rec.rpy, REAL_SIGMA ** 2, cfg)
        rows.append(score_real(rec, run))
    out = {'recordings': []}
    for r in rows:
        rec = {'name': r['name'], 'reference': r['reference'], 'samples': r['n'],
               'bouts': r['bouts'], 'walking_share_in_bouts': r['walking_share']}
        if r['n']:
            p, h = scoring.rms(r['pred_err']), scoring.rms(r['hold_err'])
            fl = r['flc_err'][np.isfinite(r['flc_err'])]
            rec.update({'pred_rms_deg': as_floats(p), 'hold_rms_deg': as_floats(h),
                        'pitch_gain_pct': _gain(p[1], h[1]),
                        'bound_pitch_gain_pct': _gain(float(np.sqrt(np.mean(fl ** 2))), h[1])
                        if fl.size else None})
        out['recordings'].append(rec)
    for test in ('Test5', 'Test11'):
        sel = [r for r in rows if f' {test} ' in r['name'] and r['n']]
        if not sel:
            continue
        cat = lambda k, sel=sel: np.concatenate([r[k] for r in sel])  # noqa: E731
        p, h = scoring.rms(cat('pred_err')), scoring.rms(cat('hold_err'))
        ps, hs = scoring.rms(cat('pred_err_steady')), scoring.rms(cat('hold_err_steady'))
        fe = cat('fit_err')
        fe = fe[np.all(np.isfinite(fe), 1)]
        fl = cat('flc_err')
        fl = fl[np.isfinite(fl)]
        floor_n = sum(n for r in sel for n, _ in r['floor'])
        floor = math.sqrt(sum(n * v * v for r in sel for n, v in r['floor']) / floor_n)
        ev = {}
        for key in sel[0]['events']:
            m = sum(r['events'][key][0] for r in sel)
            nd = sum(r['events'][key][1] for r in sel)
            nt = sum(r['events'][key][2] for r in sel)
            ev[key] = {'matched': m, 'detected': nd, 'true': nt,
                       'precision': m / nd if nd else float('nan'),
                       'recall': m / nt if nt else float('nan')}
        cad = [c for r in sel for c in r['cadence']]
        out[test] = {
            'samples': int(cat('pred_err').shape[0]), 'bouts': int(sum(r['bouts'] for r in sel)),
            'pred_rms_deg': as_floats(p), 'hold_rms_deg': as_floats(h),
            'improvement_pct': [_gain(a, b) for a, b in zip(p, h)],
            'steady_samples': int(cat('pred_err_steady').shape[0]),
            'steady_pred_rms_deg': as_floats(ps), 'steady_hold_rms_deg': as_floats(hs),
            'steady_improvement_pct': [_gain(a, b) for a, b in zip(ps, hs)],
            'window_fit_rms_deg': as_floats(scoring.rms(fe)) if fe.size else None,
            'bound_pitch_rms_deg': float(np.sqrt(np.mean(fl ** 2))) if fl.size else None,
            'bound_pitch_gain_pct': _gain(float(np.sqrt(np.mean(fl ** 2))), h[1])
            if fl.size else None,
            'floor_pitch_rms_deg': math.degrees(floor),
            'floor_pitch_gain_pct': _gain(math.degrees(floor), h[1]),
            'events': ev,
            'cadence': [{'tracked_hz': a, 'reference_hz': b} for a, b in cad],
            'detected_bouts': int(sum(r['detected_bouts'] for r in sel)),
            'detected_short_bouts': int(sum(r['short_bouts'] for r in sel))}
    return out


def print_real(res: dict, file=sys.stdout) -> None:
    p = lambda s='': print(s, file=file)  # noqa: E731
    p('Mobilise-D lower-back IMU: attitude by complementary filter (tau '
      f'{REAL_ATTITUDE_TIME_CONSTANT:g} s), decimated to 16 Hz; 0.5 s-ahead prediction inside '
      'the reference walking bouts (RMS, degrees, roll / pitch / yaw)')
    p(f'{"recording":22} {"ref":11} {"n":>4}  {"walk model":21} {"hold last":21} '
      f'{"pitch gain":>10} {"oracle":>6} walking')
    for r in res['recordings']:
        if not r['samples']:
            p(f'{r["name"]:22} {r["reference"]:11} {0:4d}  (no reference bout)')
            continue
        b = r['bound_pitch_gain_pct']
        p(f'{r["name"]:22} {r["reference"]:11} {r["samples"]:4d}  '
          f'{fmt3(r["pred_rms_deg"]):21} {fmt3(r["hold_rms_deg"]):21} '
          f'{r["pitch_gain_pct"]:+9.0f}% {b:+5.0f}% {r["walking_share_in_bouts"]:6.2f}')
    for test in ('Test5', 'Test11'):
        if test not in res:
            continue
        x = res[test]
        p()
        p(f'{test}: {x["samples"]} samples in {x["bouts"]} bouts: walk model '
          f'{fmt3(x["pred_rms_deg"])}, hold last {fmt3(x["hold_rms_deg"])}; improvement '
          + ' / '.join(f'{v:+.0f}%' for v in x['improvement_pct']))
        p(f'  bouts without their first and last {REAL_TRIM:.0f} s ({x["steady_samples"]} '
          f'samples): walk model {fmt3(x["steady_pred_rms_deg"])}, hold last '
          f'{fmt3(x["steady_hold_rms_deg"])}; improvement '
          + ' / '.join(f'{v:+.0f}%' for v in x['steady_improvement_pct']))
        if x.get('window_fit_rms_deg'):
            p(f'  reference, causal least-squares fit of the stride harmonics over the last '
              f'2 s: {fmt3(x["window_fit_rms_deg"])}')
        if x.get('bound_pitch_rms_deg') is not None:
            p(f'  pitch references: oracle-aided Fourier combiner (each bout\'s own stride '
              f'frequency and start; not a bound) {x["bound_pitch_rms_deg"]:.2f} deg '
              f'({x["bound_pitch_gain_pct"]:+.0f}%); upper bound of the model family, '
              f'non-causal fit of a whole bout (stride harmonics 1, 2, own frequency, trend), '
              f'leaves {x["floor_pitch_rms_deg"]:.2f} deg ({x["floor_pitch_gain_pct"]:+.0f}%)')
        ev = x['events']
        p('  walk start / end vs reference bouts: ' + '; '.join(
            f'{k.replace("_", " within ")}: precision {v["matched"]}/{v["detected"]}, recall '
            f'{v["matched"]}/{v["true"]}' for k, v in ev.items()))
        p(f'  detected bouts {x["detected_bouts"]} ({x["detected_short_bouts"]} shorter than '
          '2 s; a reference MicroWB has at least 2 strides)')
        if x['cadence']:
            c = np.array([[d['tracked_hz'], d['reference_hz']] for d in x['cadence']])
            e = c[:, 0] / c[:, 1] - 1.0
            p('  tracked step frequency vs reference cadence: median error '
              f'{100 * np.median(e):+.0f}%, '
              f'{int(np.sum(np.abs(e) <= 0.1))}/{e.size} bouts within 10 %')


def real_command(data: Path, json_path: Path | None = None) -> int:
    """`asmonc gait real`: the recordings in ``data`` scored and printed, the numbers also
    written to ``json_path``; the exit status."""
    from asmonc_vision.eval.evaluation import json_ready

    try:
        res = evaluate_real(data)
    except FileNotFoundError as exc:
        print(f'asmonc gait real: {exc}', file=sys.stderr)
        return 2
    print_real(res)
    if json_path:
        json_path.write_text(json.dumps(json_ready(res), indent=1, allow_nan=False))
    return 0
