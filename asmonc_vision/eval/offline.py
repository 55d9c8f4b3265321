"""Scoring a detector on bags with ground truth, offline (`asmonc eval`): in-process runs
of GPOD or the SGBM baseline, or the recorded outputs of `asmonc run`, scored by
`eval.evaluation.SequenceEvaluation` and `eval.safety`; tables, plots and JSON. The
command's help (`cli.eval`) says what is reported.
"""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from asmonc_vision.io import bagio
from asmonc_vision.eval.bench import make_method, out_of_view_for, run_method, score_runs
from asmonc_vision.io.frames import load_frames, plane_from_msg

STATUS_NAMES = {0: 'initialising', 1: 'tracking', 2: 'lost'}


class _Progress:
    """A one-line bar on stderr, only when stderr is a terminal."""

    def __init__(self, enabled: bool):
        self.on = enabled and sys.stderr.isatty()
        self.shown = False

    def __call__(self, label: str):
        def update(done: int, total: int) -> None:
            if not self.on:
                return
            w = 30
            k = int(w * done / max(total, 1))
            sys.stderr.write(f'\r  {label:32.32s} [{"#" * k}{"." * (w - k)}] {done}/{total}')
            sys.stderr.flush()
            self.shown = True
        return update

    def clear(self) -> None:
        if self.on and self.shown:
            sys.stderr.write('\r' + ' ' * 78 + '\r')
            sys.stderr.flush()
            self.shown = False


# --- scoring recorded outputs ------------------------------------------------------------

def score_outputs(frames, outputs: Path, evaluation) -> dict | None:
    """Add the /obstacles and /ground_plane of a recorded outputs bag to `evaluation`,
    frame by frame against `frames` (from `load_frames`, truth needed); a frame with no
    /obstacles message counts as missing.

    Returns:
        whether the recorded /alarms warned of each true obstacle on the path in time
        (`eval.evaluation.path_warnings_summary`, with the alarm node's default criteria),
        or None when the bag has no /alarms.
    Raises:
        bagio.BagError: unreadable bag, or one without /obstacles.
    """
    from asmonc_vision.io.frames import frame_from_obstacle_array
    from asmonc_vision.core.alarm import AlarmConfig
    from asmonc_vision.eval.evaluation import path_criteria, path_warnings, path_warnings_summary

    t_obs, t_plane = bagio.TOPICS['obstacles'][0], bagio.TOPICS['ground_plane'][0]
    t_alarm = bagio.TOPICS['alarms'][0]
    topics = bagio.bag_topics(outputs)
    if t_obs not in topics:
        raise bagio.BagError(f"bag '{outputs}' has no {t_obs} messages (topics: "
                             f"{', '.join(sorted(topics)) or 'none'})")
    dets, planes, alarms = {}, {}, []
    for topic, _, m in bagio.read_messages(outputs, [t_obs, t_plane, t_alarm]):
        if topic == t_obs:
            f = frame_from_obstacle_array(m)
            dets[f.stamp_ns] = f
        elif topic == t_alarm:
            alarms.append({'stamp_ns': bagio.header_stamp_ns(m), 'level': int(m.level)})
        else:
            planes[bagio.header_stamp_ns(m)] = m
    away = out_of_view_for(frames)
    for f in frames:
        if f.truth is None:
            continue
        det = dets.get(f.stamp_ns)
        if det is None:
            evaluation.add_missing(f.stamp_ns)
            continue
        pm = planes.get(f.stamp_ns)
        evaluation.add_frame(det, f.truth, plane=plane_from_msg(pm, f.cam) if pm else None,
                             truth_plane=f.truth_plane,
                             status=STATUS_NAMES.get(int(pm.status), str(pm.status))
                             if pm else 'no /ground_plane', remembered=away.get(f.stamp_ns))
    if t_alarm not in topics:
        return None
    truth = {f.stamp_ns: f.truth for f in frames if f.truth is not None}
    return path_warnings_summary(path_warnings(truth, alarms, away),
                                 path_criteria(AlarmConfig()))


def read_alarms(outputs: Path) -> list[dict]:
    """The /alarms of a recorded outputs bag, in recorded order (as `asmonc run` logs them)."""
    t_alarm = bagio.TOPICS['alarms'][0]
    if t_alarm not in bagio.bag_topics(outputs):
        return []
    return [{'stamp_ns': bagio.header_stamp_ns(m), 'level': int(m.level),
             'obstacle_id': int(m.obstacle_id), 'range': float(m.range),
             'bearing': float(m.bearing), 'text': m.text}
            for _, _, m in bagio.read_messages(outputs, [t_alarm])]


def outputs_safety(bag: Path, frames, outputs: Path) -> dict | None:
    """The safety score (`eval.safety`) of the /alarms and /obstacles recorded by
    `asmonc run BAG --out DIR`, against BAG's truth; None when BAG has no true poses."""
    from asmonc_vision.io.frames import frame_from_obstacle_array
    from asmonc_vision.eval.safety import score_safety
    from asmonc_vision.eval.truth import truth_from_bag

    truth = truth_from_bag(bag, frames)
    if truth is None:
        return None
    dets = {bagio.header_stamp_ns(m): frame_from_obstacle_array(m) for _, _, m in
            bagio.read_messages(outputs, [bagio.TOPICS['obstacles'][0]])}
    return score_safety(truth, read_alarms(outputs), dets).as_dict()


def method_safety(truth, runs) -> dict | None:
    """The safety score of an offline detector run (`eval.bench.run_method`): the alarm
    node's logic with its default settings replayed over its outputs in bag time
    (`eval.alarm_replay`), scored by `eval.safety`; None without truth."""
    from asmonc_vision.eval.alarm_replay import replay_alarms
    from asmonc_vision.eval.safety import score_safety

    if truth is None:
        return None
    alarms = replay_alarms([(r.stamp_ns, r.status, r.obstacles) for r in runs],
                           motions=[r.ego_t for r in runs])
    return score_safety(truth, alarms, {r.stamp_ns: r.obstacles for r in runs}).as_dict()


def egomotion_scores(bag: Path, outputs: Path | None, frames: int = 0) -> dict | None:
    """Egomotion errors on a bag: the estimator run offline, or the recorded /egomotion."""
    from asmonc_vision.eval import motion_bags as motion

    if outputs is not None:
        return motion.score_recorded_egomotion(bag, outputs)
    return motion.evaluate_sequence(motion.load_sequence(bag, frames))


def format_motion(name: str, m: dict | None) -> list[str]:
    """Printed lines of an egomotion score (see `egomotion_scores`)."""
    if not m or not m.get('errors'):
        return [f'{name} - egomotion: no motion or no ground-truth pose to score', '']
    e = m['errors']
    lines = [f'{name} - egomotion ({m.get("motions", 0)} motions):',
             '  per-frame error, median / p90: '
             f"pitch {e['pitch']['median']:.3f} / {e['pitch']['p90']:.3f} deg, "
             f"roll {e['roll']['median']:.3f} / {e['roll']['p90']:.3f} deg, "
             f"translation {e['translation']['median']:.1f} / {e['translation']['p90']:.1f} mm"]
    if m.get('cpu_ms'):
        lines.append(f"  time per frame (one core): median {m['cpu_ms']['median']:.1f} ms CPU")
    return lines + ['']


# --- report ------------------------------------------------------------------------------

def _f(x, fmt: str, none: str = '-') -> str:
    return none if x is None else format(x, fmt)


def format_summary(title: str, s: dict) -> list[str]:
    """The printed table of one SequenceEvaluation.summary()."""
    lines = [f'=== {title} ===']
    rate = s['camera_rate_hz']
    lines.append(f"frames: {s['frames']} scored, {s['missing_frames']} missing"
                 + (f", camera {rate:.1f} Hz" if rate else '')
                 + (f", {s['duration_s']:.1f} s" if s['duration_s'] else '')
                 + ('; status ' + ', '.join(f'{k} {v}' for k, v in
                                            sorted(s['status_counts'].items()))
                    if s['status_counts'] else ''))
    b = s['recall_bins']
    lines.append('recall per frame by true |height| x range (found/eligible, recall):')
    cw = 15
    lines.append('  ' + 'height \\ range'.ljust(12)
                 + ''.join(r.rjust(cw) for r in b['range_labels']))
    for i, hl in enumerate(b['height_labels']):
        cells = []
        for j in range(len(b['range_labels'])):
            e, d, r = b['eligible'][i][j], b['detected'][i][j], b['recall'][i][j]
            cells.append(('.' if not e else f'{d}/{e} {r * 100:3.0f}%').rjust(cw))
        lines.append('  ' + hl.ljust(12) + ''.join(cells))
    c = s['criteria']
    rc = s['recall']
    head = (f"{rc['detected']}/{rc['eligible']} = {rc['recall']:.1%}" if rc['eligible']
            else 'no eligible obstacles')
    lines.append(f"recall (>= {c['min_height_m'] * 100:g} cm, <= {c['max_range_m']:g} m, "
                 f"within {c['match_radius_m']:g} m): {head}; obstacles found in >= half their "
                 f"frames: {rc['obstacles_detected']} of {rc['obstacles_eligible']}")
    fo = s['false_obstacles']
    lines.append(f"false obstacles: {fo['total']} in {s['frames']} frames = "
                 f"{_f(fo['per_frame'], '.3f')} per frame = {_f(fo['per_minute'], '.1f')} per "
                 f"minute ({fo['frames_with_false']} frames with any); "
                 f"{fo.get('remembered_out_of_view', 0)} more reports of true obstacles "
                 f"out of view (remembered, not false)")
    re_, be = s['range_error'], s['bearing_error']
    lines.append(f"range error: median |e| {_f(re_['median_abs_m'], '.3f')} m = "
                 f"{_f(re_['median_abs_pct_of_range'], '.1f')} % of range (signed median "
                 f"{_f(re_['median_m'], '+.3f')} m, n = {re_['n']}); bearing error: median |e| "
                 f"{_f(be['median_abs_deg'], '.2f')} deg")
    g = s['ground_plane']
    lines.append(f"ground plane: {g['frames_with_plane']} frames with a plane, "
                 f"{g['frames_without_plane']} without; normal angle median "
                 f"{_f(g['angle_median_deg'], '.2f')} deg (p90 {_f(g['angle_p90_deg'], '.2f')}), "
                 f"camera height median |e| {_f(g['height_median_abs_mm'], '.1f')} mm "
                 f"(p90 {_f(g['height_p90_abs_mm'], '.1f')}, signed median "
                 f"{_f(g['height_median_mm'], '+.1f')} mm)")
    lat = s['latency_ms']
    if lat['n']:
        lines.append(f"latency of process(): median {lat['median']:.1f} ms, p90 "
                     f"{lat['p90']:.1f} ms over {lat['n']} frames (one OpenCV thread)")
    else:
        lines.append('latency: not measured (recorded outputs)')
    return lines


def _slug(text: str) -> str:
    return re.sub(r'[^A-Za-z0-9._-]+', '_', text).strip('_')


def write_plots(ev, title: str, stem: str, out_dir: Path) -> list[Path]:
    """eval_recall_<stem>.png (recall heat map per bin, with counts) and
    eval_range_error_<stem>.png (signed range error of the matches vs true range)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    out_dir.mkdir(parents=True, exist_ok=True)
    s = ev.summary()
    b = s['recall_bins']
    elig = np.asarray(b['eligible'])
    det = np.asarray(b['detected'])
    rec = np.where(elig > 0, det / np.maximum(elig, 1), np.nan)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    cmap = plt.get_cmap('RdYlGn').with_extremes(bad='#dddddd')
    im = ax.imshow(np.ma.masked_invalid(rec), cmap=cmap, vmin=0, vmax=1, origin='lower',
                   aspect='auto')
    for i in range(rec.shape[0]):
        for j in range(rec.shape[1]):
            txt = f'{rec[i, j]:.0%}\n{det[i, j]}/{elig[i, j]}' if elig[i, j] else 'none'
            ax.text(j, i, txt, ha='center', va='center', fontsize=8)
    ax.set_xticks(range(len(b['range_labels'])), b['range_labels'])
    ax.set_yticks(range(len(b['height_labels'])), b['height_labels'])
    ax.set_xlabel('true range along the ground')
    ax.set_ylabel('true obstacle |height|')
    ax.set_title(f'recall per frame: {title}', fontsize=10)
    fig.colorbar(im, ax=ax, label='recall')
    fig.tight_layout()
    p1 = out_dir / f'eval_recall_{stem}.png'
    fig.savefig(p1, dpi=100)
    plt.close(fig)

    m = np.asarray(ev.matches, float).reshape(-1, 5)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    if m.size:
        e = m[:, 4] > 0
        ax.scatter(m[~e, 0], m[~e, 1], s=10, c='#aaaaaa',
                   label='other matches (low or far obstacles)')
        ax.scatter(m[e, 0], m[e, 1], s=12, c='tab:blue',
                   label=f'>= {ev.min_height * 100:g} cm, <= {ev.max_range:g} m')
        edges = np.asarray(ev.range_bins)
        mids, meds = [], []
        for lo, hi in zip(edges[:-1], edges[1:]):
            k = (m[:, 0] >= lo) & (m[:, 0] < hi)
            if k.any():
                mids.append((lo + hi) / 2)
                meds.append(np.median(np.abs(m[k, 1])))
        if mids:
            ax.plot(mids, meds, 'o-', c='tab:red', label='median |error| per range bin')
        r = np.linspace(max(edges[0], 0.5), edges[-1], 50)
        ax.plot(r, 0.05 * r, ':', c='k', lw=0.8, label='±5 % of range')
        ax.plot(r, -0.05 * r, ':', c='k', lw=0.8)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, 'no matches', ha='center', va='center', transform=ax.transAxes)
    ax.axhline(0, c='k', lw=0.5)
    ax.set_xlabel('true range (m)')
    ax.set_ylabel('reported - true range (m)')
    ax.set_title(f'range error: {title}', fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    p2 = out_dir / f'eval_range_error_{stem}.png'
    fig.savefig(p2, dpi=100)
    plt.close(fig)
    return [p1, p2]


# --- main ----------------------------------------------------------------------------------

def eval_command(args) -> int:
    """`asmonc eval` with its parsed arguments (see `cli.eval`); the exit status."""
    err = lambda s: print(f'asmonc eval: {s}', file=sys.stderr)  # noqa: E731
    checked = _check_arguments(args, err)
    if isinstance(checked, int):
        return checked
    scored = _score_bags(args, *checked, err)
    if isinstance(scored, int):
        return scored
    runs, groups, motion_results = scored
    pooled = []
    if len(args.bags) > 1:
        from asmonc_vision.eval.evaluation import SequenceEvaluation
        for (method, thr), evs in groups.items():
            pooled.append({'bags': [str(b) for b in args.bags], 'method': method,
                           'threshold_px': thr, 'evaluation': SequenceEvaluation.pooled(evs)})
    _print_runs(runs, pooled)
    if len(runs) > 1:
        _print_overview(runs + pooled)
    for name, m in motion_results.items():
        print('\n'.join(format_motion(name, m)))
    if args.plots is not None:
        written = []
        for r in runs:
            written += write_plots(r['evaluation'], _title(r), _stem(r, args), args.plots)
        for r in pooled:
            written += write_plots(r['evaluation'], _title(r, True), _stem(r, args, True),
                                   args.plots)
        print(f'plots: {len(written)} PNG files in {args.plots}')
    if args.json is not None:
        _write_json(args, runs, pooled, motion_results)
    return 0


def _check_arguments(args, err) -> tuple | int:
    """(thresholds, map_enabled) of valid arguments, or exit status 2."""
    if args.outputs is not None:
        if len(args.outputs) != len(args.bags):
            err(f'give one --outputs per BAG ({len(args.bags)} bags, '
                f'{len(args.outputs)} --outputs)')
            return 2
        if args.threshold_px is not None or args.method != ['gpod']:
            err('--method and --threshold-px do not apply to --outputs (nothing is run)')
            return 2
    if args.motion_lag < 0:
        err('--motion-lag must be >= 0')
        return 2
    if args.frames < 0 or args.match_radius <= 0 or args.max_range <= 0 or args.min_height < 0:
        err('--frames must be >= 0, --match-radius and --max-range > 0, --min-height >= 0')
        return 2
    map_enabled = {'default': None, 'on': True, 'off': False}[args.map]
    thresholds = args.threshold_px or [None]
    for t in thresholds:
        if t is not None and not (0.05 <= t <= 50):
            err(f'--threshold-px must be in [0.05, 50], got {t:g}')
            return 2
    return thresholds, map_enabled


def _score_bags(args, thresholds: list, map_enabled, err) -> tuple | int:
    """(runs, evaluations grouped by (method, threshold), egomotion results per bag), or
    exit status 2 for an unusable bag."""
    from asmonc_vision.eval.evaluation import SequenceEvaluation

    criteria = dict(match_radius=args.match_radius, min_height=args.min_height,
                    max_range=args.max_range)
    progress = _Progress(not args.no_progress)
    runs: list[dict] = []
    groups: dict[tuple, list] = {}
    motion_results: dict[str, dict | None] = {}
    for bi, bag in enumerate(args.bags):
        try:
            frames = load_frames(bag, args.frames, images=args.outputs is None)
        except bagio.BagError as exc:
            progress.clear()
            err(str(exc))
            return 2
        if not frames:
            err(f"bag '{bag}' has no stereo pairs")
            return 2
        if all(f.truth is None for f in frames):
            err(f"bag '{bag}' has no {bagio.TOPICS['gt_obstacles'][0]}: nothing to score against")
            return 2
        name = Path(bag).name.removesuffix('.mcap')
        if args.motion:
            motion_results[name] = egomotion_scores(bag, args.outputs[bi] if args.outputs
                                                    else None, args.frames)
        if args.outputs is not None:
            ev = SequenceEvaluation(**criteria)
            try:
                warned = score_outputs(frames, args.outputs[bi], ev)
            except bagio.BagError as exc:
                err(str(exc))
                return 2
            runs.append({'bag': str(bag), 'name': name, 'method': 'outputs',
                         'source': 'recorded', 'outputs': str(args.outputs[bi]),
                         'threshold_px': None, 'path_warnings': warned,
                         'safety': outputs_safety(bag, frames, args.outputs[bi]),
                         'evaluation': ev})
            groups.setdefault(('outputs', None), []).append(ev)
            continue
        for run in _method_runs(args, bag, name, frames, thresholds, map_enabled, criteria,
                                progress):
            runs.append(run)
            groups.setdefault((run['method'], run['threshold_px']), []).append(
                run['evaluation'])
    return runs, groups, motion_results


def _method_runs(args, bag: Path, name: str, frames, thresholds: list, map_enabled,
                 criteria: dict, progress) -> list[dict]:
    """One in-process run per method and threshold on one bag's frames, scored."""
    from asmonc_vision.core.config import to_dict
    from asmonc_vision.core.gpod import GpodConfig
    from asmonc_vision.eval.truth import truth_from_bag

    truth = truth_from_bag(bag, frames)
    runs = []
    for method in args.method:
        for thr in thresholds:
            label = f'{name} {method}' + (f' {thr:g}px' if thr is not None else '')
            rs = run_method(frames, method, thr, progress=progress(label),
                            map_enabled=map_enabled, egomotion=args.egomotion,
                            motion_lag=args.motion_lag)
            progress.clear()
            ev = score_runs(frames, rs, **criteria)
            det = make_method(method, thr, map_enabled)
            cfg = det.config
            run = {'bag': str(bag), 'name': name, 'method': method,
                   'source': 'in-process',
                   'threshold_px': (cfg.threshold.px if isinstance(cfg, GpodConfig)
                                    else cfg.threshold_px),
                   'config': to_dict(cfg), 'safety': method_safety(truth, rs),
                   'evaluation': ev}
            if method == 'gpod':
                run['map_config'] = to_dict(det.map_config)
                run['egomotion'] = bool(args.egomotion)
                run['motion_lag'] = int(args.motion_lag)
            runs.append(run)
    return runs


def _title(r: dict, pooled_: bool = False) -> str:
    who = {'gpod': 'GPOD (ours)', 'sgbm': 'SGBM baseline',
           'outputs': 'recorded outputs'}[r['method']]
    thr = f", threshold {r['threshold_px']:g} px" if r.get('threshold_px') else ''
    src = f" ({r['outputs']})" if r.get('outputs') else ''
    where = 'all bags' if pooled_ else r['name']
    return f'{where} - {who}{thr}{src}'


def _stem(r: dict, args, pooled_: bool = False) -> str:
    thr = f"_t{r['threshold_px']:g}" if (r.get('threshold_px') and args.threshold_px) else ''
    return _slug(f"{'all' if pooled_ else r['name']}_{r['method']}{thr}")


def _print_runs(runs: list[dict], pooled: list[dict]) -> None:
    from asmonc_vision.eval.safety import format_safety
    from asmonc_vision.replay.summary import path_warning_lines

    for r in runs:
        print('\n'.join(format_summary(_title(r), r['evaluation'].summary())))
        if r['method'] == 'outputs':
            print('\n'.join(f'  {line}' for line in path_warning_lines(r['path_warnings'])
                            or ['no /alarms recorded']))
        if r.get('safety'):
            print('safety (EVALUATION.md; ' + ('the recorded /alarms' if r['method'] == 'outputs'
                                               else 'the alarm logic replayed in bag time')
                  + '):')
            print('\n'.join(format_safety(r['safety'], '  ')))
        print()
    for r in pooled:
        print('\n'.join(format_summary(_title(r, True), r['evaluation'].summary())))
        print()


def _print_overview(rows: list[dict]) -> None:
    print('=== overview ===')
    print(f"  {'bag':20s} {'method':8s} {'thr px':>6s} {'recall':>14s} {'false/frame':>11s} "
          f"{'range |e| m':>11s} {'plane deg':>9s} {'plane mm':>8s} {'median ms':>9s} "
          f"{'warned':>7s} {'FA/min':>6s}")
    for r in rows:
        s = r['evaluation'].summary()
        rc = s['recall']
        rec = (f"{rc['detected']}/{rc['eligible']} {rc['recall']:4.0%}" if rc['eligible']
               else '-')
        print(f"  {r.get('name', 'all bags'):20s} {r['method']:8s} "
              f"{_f(r.get('threshold_px'), 'g'):>6s} {rec:>14s} "
              f"{_f(s['false_obstacles']['per_frame'], '.3f'):>11s} "
              f"{_f(s['range_error']['median_abs_m'], '.3f'):>11s} "
              f"{_f(s['ground_plane']['angle_median_deg'], '.2f'):>9s} "
              f"{_f(s['ground_plane']['height_median_abs_mm'], '.1f'):>8s} "
              f"{_f(s['latency_ms']['median'], '.1f'):>9s} "
              + (f"{sf['warned_in_time']['warned']}/{sf['warned_in_time']['on_path']:<3d} "
                 f"{_f(sf['false_alarms']['per_minute_walking'], '.2f'):>6s}"
                 if (sf := r.get('safety')) else f"{'-':>7s} {'-':>6s}"))


def _write_json(args, runs: list[dict], pooled: list[dict], motion_results: dict) -> None:
    from asmonc_vision.eval.evaluation import json_ready

    doc = {'criteria': {'match_radius_m': args.match_radius, 'min_height_m': args.min_height,
                        'max_range_m': args.max_range, 'frames_limit': args.frames},
           'runs': [{k: v for k, v in r.items() if k != 'evaluation'}
                    | r['evaluation'].summary() for r in runs],
           'pooled': [{k: v for k, v in r.items() if k != 'evaluation'}
                      | r['evaluation'].summary() for r in pooled]}
    if motion_results:
        doc['egomotion'] = {k: ({kk: vv for kk, vv in v.items() if kk != 'per_frame'}
                                if v else None) for k, v in motion_results.items()}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(json_ready(doc), indent=2, allow_nan=False) + '\n')
    print(f'json: {args.json}')
