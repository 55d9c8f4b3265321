"""Visual egomotion measured: the paper's synthetic experiment (`run_tables`), the estimator
on bags with ground truth (`run_eval`, `load_sequence`, `evaluate_sequence`,
`score_recorded_egomotion`), corner localisation (`run_corners`). `asmonc motion`'s help
(`cli.motion`) says what each reports.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from asmonc_vision.eval.evaluation import json_ready

DEFAULT_BAGS = ('walk_obstacles', 'walk_stop_turn', 'slope', 'clear_walk')
ANGLES = ('pitch', 'roll', 'yaw')


def motion_command(args) -> int:
    """`asmonc motion` with its parsed arguments (see `cli.motion`); the exit code."""
    cmd = getattr(args, 'motion_command', None)
    if cmd == 'tables':
        return run_tables(args)
    if cmd == 'eval':
        return run_eval(args)
    if cmd == 'corners':
        return run_corners(args)
    print('asmonc motion: give a subcommand: tables, eval or corners', file=sys.stderr)
    return 2


def _one_core() -> None:
    from asmonc_vision.core.motion.pipeline import use_one_core
    use_one_core()


# --- tables -----------------------------------------------------------------------------

LABELS = {
    'essential': 'essential matrix (paper 4.1.1)',
    'three_point': 'three point (paper 4.1.2)',
    'stereo_3d': '3-D/3-D (paper\'s third)',
    'p3p_gn': 'LambdaTwist+LO-RANSAC+GN L/R',
    'stereo_ba': 'stereo_ba (modern, default)',
    'opencv': 'cv2 solvePnPRansac AP3P+LM',
}


def _row(label, vals, ms=None, fails=None) -> str:
    x, y, z, ro, pi, ya = vals
    tail = '' if ms is None else f' {ms:7.2f} {fails:5d}'
    return (f'  {label:34s} {x:8.2f} {y:8.2f} {z:8.2f} {ro:7.3f} {pi:7.3f} {ya:7.3f}{tail}')


def _header(title: str) -> list[str]:
    return [title,
            f"  {'method':34s} {'x mm':>8s} {'y mm':>8s} {'z mm':>8s} {'roll°':>7s} "
            f"{'pitch°':>7s} {'yaw°':>7s} {'ms':>7s} {'fail':>5s}"]


def run_tables(args) -> int:
    from asmonc_vision.core.motion import METHODS
    from asmonc_vision.eval.motion_experiment import (PAPER_TABLES, TrialSettings,
                                                      run_level, run_minimal_level)
    methods = list(args.methods or METHODS)
    bad = [m for m in methods if m not in METHODS]
    if bad or args.trials < 1 or args.points < 8 or not (0.0 <= args.outliers < 0.9):
        print(f"asmonc motion tables: bad arguments (unknown methods {bad}; need --trials >= 1, "
              '--points >= 8, 0 <= --outliers < 0.9)', file=sys.stderr)
        return 2
    _one_core()
    settings = TrialSettings(n_points=args.points)
    out: dict = {'settings': {'trials': args.trials, 'points': args.points,
                              'depth_range_m': list(settings.depth_range),
                              'max_rotation_deg': settings.max_rotation_deg,
                              'translation_range_m': list(settings.translation_range),
                              'seed': args.seed}, 'runs': {}}
    print(f'Paper experiment (Molton et al. 1998, 4.2): {args.trials} trials per level, '
          f'{args.points} points at {settings.depth_range[0]:g}-{settings.depth_range[1]:g} m '
          f'seen by the paper\'s rig (f = 300 px, B = 0.35 m, 320x240); rotation up to '
          f'{settings.max_rotation_deg:g} deg about a random axis, translation '
          f'{settings.translation_range[0]:g}-{settings.translation_range[1]:g} m; uniform noise '
          f'+-a px on every image coordinate. Mean absolute error; ms = CPU per solve.')
    runs = [('clean', 0.0)] + ([('outliers', args.outliers)] if args.outliers > 0 else [])
    for name, frac in runs:
        lines = []
        title = ('All matches correct' if frac == 0 else
                 f'{frac:.0%} wrong matches (half temporal, half stereo)')
        print()
        print('\n'.join(_header(title)))
        res_run = {}
        for a in args.noise:
            t0 = time.monotonic()
            res = run_level(methods, a, args.trials, frac, settings, seed=args.seed)
            print(f'  a = {a:g} px' + (f'   ({time.monotonic() - t0:.0f} s)' if sys.stderr.isatty()
                                       else ''))
            if frac == 0:
                for key, tab in (('three_point', 'paper Table 2 (three point)'),
                                 ('essential', 'paper Table 3 (essential)')):
                    if a in PAPER_TABLES[key]:
                        print(_row(tab, PAPER_TABLES[key][a]))
            for m in methods:
                r = res[m]
                print(_row(LABELS.get(m, m), r.mean, r.ms, r.failures))
            res_run[str(a)] = {m: {'mean': res[m].mean.tolist(), 'median': res[m].median.tolist(),
                                   'failures': res[m].failures, 'ms': res[m].ms}
                               for m in methods}
            lines.append(res_run)
        out['runs'][name] = res_run
    if not args.no_minimal:
        print()
        print('\n'.join(_header("The paper's methods on minimal point sets (3 points; 7 points "
                                '+ their stereo scale), no RANSAC or least squares, the '
                                'solution nearest the truth')))
        mins = {}
        for a in args.noise:
            res = run_minimal_level(a, args.trials, settings, seed=args.seed)
            print(f'  a = {a:g} px')
            for key, tab in (('three_point', 'paper Table 2 (three point)'),
                             ('essential', 'paper Table 3 (essential)')):
                if a in PAPER_TABLES[key]:
                    print(_row(tab, PAPER_TABLES[key][a]))
                print(_row(f'{key} on {3 if key == "three_point" else 7} points', res[key].mean,
                           res[key].ms, res[key].failures))
            mins[str(a)] = {m: {'mean': r.mean.tolist(), 'median': r.median.tolist(),
                                'failures': r.failures} for m, r in res.items()}
        out['runs']['minimal'] = mins
    out['paper'] = {k: {str(a): list(v) for a, v in t.items()} for k, t in PAPER_TABLES.items()}
    if args.json:
        args.json.write_text(json.dumps(json_ready(out), indent=2, allow_nan=False) + '\n')
    return 0


# --- eval -------------------------------------------------------------------------------

def load_sequence(bag: Path, limit: int = 0) -> list[dict]:
    """The stereo pairs of a bag in stamp order: dicts with stamp_ns, left, right (uint8),
    cam (StereoCamera), frame_id, and pose (R (3,3), t (3,)) of the left optical frame in
    the world when the bag has /ground_truth/camera_pose, else None (see
    `io.frames.load_frames`).

    Raises:
        bagio.BagError: unreadable bag.
    """
    from asmonc_vision.io.frames import load_frames

    return [{'stamp_ns': f.stamp_ns, 'left': f.left, 'right': f.right, 'cam': f.cam,
             'frame_id': f.frame_id, 'pose': f.pose} for f in load_frames(bag, limit)]


def config_from_params(path: Path | None, method: str | None = None):
    """EgomotionConfig from an egomotion_node ros__parameters YAML (its ``motion``
    settings, nested or as ``motion.x`` keys) and an optional method override."""
    import dataclasses

    import yaml

    from asmonc_vision.core.motion import EgomotionConfig
    values: dict = {}
    if path is not None:
        doc = yaml.safe_load(Path(path).read_text()) or {}
        params = doc.get('egomotion_node', doc).get('ros__parameters', doc)
        nested = params.get('motion', {}) if isinstance(params.get('motion'), dict) else {}
        values.update(nested)
        values.update({k[len('motion.'):]: v for k, v in params.items()
                       if isinstance(k, str) and k.startswith('motion.')})
        known = {f.name for f in dataclasses.fields(EgomotionConfig)}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f'unknown motion settings in {path}: {sorted(unknown)}')
        from asmonc_vision.nodes.egomotion_node import EgomotionNodeConfig
        node_keys = {f.name for f in dataclasses.fields(EgomotionNodeConfig)} | {
            'motion', 'use_sim_time'}
        # in the node's own section (or a bare ros__parameters), not another node's file
        own = 'egomotion_node' in doc or 'ros__parameters' in doc
        names = [str(k) for k in params] if own else []
        stray = sorted(k for k in names if not k.startswith('motion.') and k not in node_keys)
        if stray:
            hint = (' (estimator settings go under motion.)'
                    if any(k in known for k in stray) else '')
            raise ValueError(f'unknown egomotion_node settings in {path}: {stray}{hint}')
        for f in dataclasses.fields(EgomotionConfig):
            v = values.get(f.name)
            if isinstance(f.default, float) and isinstance(v, int) and not isinstance(v, bool):
                values[f.name] = float(v)
    if method is not None:
        values['method'] = method
    return EgomotionConfig(**values)


def evaluate_sequence(frames: list[dict], config=None) -> dict:
    """Run an EgomotionEstimator over frames (``load_sequence``) and score it.

    Returns:
        {'frames', 'statuses': {status: count}, 'motions', 'has_truth', 'errors': {'pitch', 'roll',
        'yaw' (deg), 'translation' (mm): {'median', 'p90', 'max'}}, 'drift': {'path_m',
        'end_error_m', 'percent'} or None, 'cpu_ms': {'median', 'p90'}, 'wall_ms': {...},
        'stages_cpu_ms': {stage: median}, 'per_frame': [...]}; errors are None without
        ground truth.
    """
    from asmonc_vision.core.motion import EgomotionEstimator
    from asmonc_vision.core.motion.geometry import compose, invert, rotation_error_components

    est = EgomotionEstimator(config)
    poses = {f['stamp_ns']: f['pose'] for f in frames}
    statuses: dict[str, int] = {}
    cpu, wall, stages, per = [], [], {}, []
    errs = []
    acc = (np.eye(3), np.zeros(3))
    path = 0.0
    start_pose = None
    last_pose = None
    for f in frames:
        res = est.process(f['left'], f['right'], f['cam'], f['stamp_ns'])
        statuses[res.status] = statuses.get(res.status, 0) + 1
        cpu.append(res.timings_ms['cpu'])
        wall.append(res.timings_ms['wall'])
        for k in ('detect', 'match', 'solve'):
            if k in res.timings_ms:
                stages.setdefault(k, []).append(res.timings_ms[k])
        row = {'stamp_ns': f['stamp_ns'], 'status': res.status, 'inliers': res.n_inliers,
               'matches': res.n_matches, 'stereo': res.n_stereo, 'cpu_ms': res.timings_ms['cpu']}
        if start_pose is None and f['pose'] is not None and res.status in ('first_frame', 'ok'):
            start_pose = f['pose']
        if res.ok:
            acc = compose(*acc, res.motion.R, res.motion.t)
            ref_pose = poses.get(res.reference_stamp_ns)
            if ref_pose is not None and f['pose'] is not None:
                rt, tt = compose(*invert(*ref_pose), *f['pose'])
                w = np.degrees(np.abs(rotation_error_components(res.motion.R, rt)))
                dt = float(np.linalg.norm(res.motion.t - tt)) * 1e3
                errs.append((w[0], w[2], w[1], dt))
                row.update(pitch_err_deg=float(w[0]), roll_err_deg=float(w[2]),
                           yaw_err_deg=float(w[1]), trans_err_mm=dt)
                path += float(np.linalg.norm(tt))
                last_pose = f['pose']
        per.append(row)

    def stats(v):
        v = np.asarray(v, float)
        return ({'median': float(np.median(v)), 'p90': float(np.percentile(v, 90)),
                 'max': float(np.max(v))} if v.size else None)
    errors = _error_stats(errs)
    drift = None
    if start_pose is not None and last_pose is not None and path > 0 and \
            statuses.get('ok', 0) == len(frames) - 1:
        rt, tt = compose(*invert(*start_pose), *last_pose)
        end = float(np.linalg.norm(acc[1] - tt))
        drift = {'path_m': path, 'end_error_m': end, 'percent': 100.0 * end / path}
    return {'frames': len(frames), 'statuses': statuses, 'motions': statuses.get('ok', 0),
            'has_truth': any(f['pose'] is not None for f in frames),
            'errors': errors, 'drift': drift,
            'cpu_ms': {'median': float(np.median(cpu)), 'p90': float(np.percentile(cpu, 90))},
            'wall_ms': {'median': float(np.median(wall)), 'p90': float(np.percentile(wall, 90))},
            'stages_cpu_ms': {k: float(np.median(v)) for k, v in stages.items()},
            'per_frame': per}


def _error_stats(errs: list) -> dict | None:
    """{'pitch', 'roll', 'yaw' (deg), 'translation' (mm): {'median', 'p90', 'max'}} of
    rows (pitch, roll, yaw, translation); None when empty."""
    if not errs:
        return None
    e = np.asarray(errs, float)
    stats = lambda v: {'median': float(np.median(v)), 'p90': float(np.percentile(v, 90)),  # noqa: E731
                       'max': float(np.max(v))}
    return {'pitch': stats(e[:, 0]), 'roll': stats(e[:, 1]), 'yaw': stats(e[:, 2]),
            'translation': stats(e[:, 3])}


def score_recorded_egomotion(bag: Path, outputs: Path) -> dict | None:
    """Per-frame error of the /egomotion recorded by `asmonc run BAG --out OUTPUTS` against
    BAG's /ground_truth/camera_pose.

    Each /egomotion is the left camera's motion T_prev_curr from the pair of the previous
    /egomotion (the pair the node estimated before; pairs it dropped on a busy CPU lie in
    between), as its subscribers take it; the first from the pair before its stamp.
    Returns None when the outputs hold no /egomotion or the bag has no ground-truth pose;
    else {'motions', 'pairs', 'errors'}.
    """
    from asmonc_vision.io import bagio
    from asmonc_vision.core.motion.geometry import (compose, invert, quaternion_to_matrix,
                                                    rotation_error_components)

    t_ego, t_pose = bagio.TOPICS['egomotion'][0], bagio.TOPICS['gt_camera_pose'][0]
    if t_ego not in bagio.bag_topics(outputs):
        return None
    poses = {}
    for _, _, m in bagio.read_messages(bag, [t_pose]):
        p = m.pose
        poses[bagio.header_stamp_ns(m)] = (
            quaternion_to_matrix([p.orientation.x, p.orientation.y, p.orientation.z,
                                  p.orientation.w]),
            np.array([p.position.x, p.position.y, p.position.z]))
    if not poses:
        return None
    stamps = sorted(poses)
    previous = dict(zip(stamps[1:], stamps[:-1]))
    errs, n, last = [], 0, None
    for _, _, m in bagio.read_messages(outputs, [t_ego]):
        n += 1
        stamp = bagio.header_stamp_ns(m)
        ref = last if last is not None and last in poses and last < stamp \
            else previous.get(stamp)
        last = stamp
        if stamp not in poses or ref is None:
            continue
        q, tr = m.transform.rotation, m.transform.translation
        r_est = quaternion_to_matrix([q.x, q.y, q.z, q.w])
        t_est = np.array([tr.x, tr.y, tr.z])
        rt, tt = compose(*invert(*poses[ref]), *poses[stamp])
        w = np.degrees(np.abs(rotation_error_components(r_est, rt)))
        errs.append((w[0], w[2], w[1], float(np.linalg.norm(t_est - tt)) * 1e3))
    return {'motions': n, 'pairs': len(stamps), 'errors': _error_stats(errs)}


def run_eval(args) -> int:
    from asmonc_vision.io import bagio
    root = Path(__file__).resolve().parents[2] / 'bags'
    bags = args.bags or [root / b for b in DEFAULT_BAGS]
    try:
        config = config_from_params(args.params_file, args.method)
    except (OSError, ValueError, TypeError) as exc:
        print(f'asmonc motion eval: {exc}', file=sys.stderr)
        return 2
    _one_core()
    print(f'asmonc motion eval: method {config.method}, detector {config.detector}; errors of '
          'each frame-to-frame motion against /ground_truth/camera_pose (pitch/roll/yaw about '
          'the left optical x/z/y axes); CPU ms per frame on one core')
    results = {}
    for bag in bags:
        try:
            frames = load_sequence(bag, args.frames)
        except bagio.BagError as exc:
            print(f'asmonc motion eval: {exc}', file=sys.stderr)
            return 2
        if len(frames) < 2:
            print(f'asmonc motion eval: {bag}: {len(frames)} stereo pairs; need at least 2',
                  file=sys.stderr)
            return 2
        r = evaluate_sequence(frames, config)
        results[str(bag)] = r
        _print_eval(Path(bag).name, r, frames[0]['cam'])
    if args.json:
        args.json.write_text(json.dumps(json_ready(results), indent=2, allow_nan=False) + '\n')
    return 0


def _print_eval(name: str, r: dict, cam) -> None:
    st = ', '.join(f'{k} {v}' for k, v in sorted(r['statuses'].items()))
    print(f"{name}: {r['frames']} pairs ({cam.width}x{cam.height}), motions {r['motions']} "
          f"[{st}]")
    e = r['errors']
    if e is None:
        print('  no motion scored' + ('' if r['has_truth'] else
                                      ' (no /ground_truth/camera_pose in the bag)'))
    else:
        print('  per-frame error  median / p90 / max: ' + ', '.join(
            f"{k} {e[k]['median']:.3f} / {e[k]['p90']:.3f} / {e[k]['max']:.3f} deg"
            for k in ANGLES) + f"; translation {e['translation']['median']:.1f} / "
            f"{e['translation']['p90']:.1f} / {e['translation']['max']:.1f} mm")
    if r['drift'] is not None:
        d = r['drift']
        print(f"  drift of the chained motions: {d['end_error_m'] * 100:.1f} cm after "
              f"{d['path_m']:.2f} m ({d['percent']:.2f} %)")
    stages = ', '.join(f'{k} {v:.1f}' for k, v in r['stages_cpu_ms'].items())
    c = r['cpu_ms']
    print(f"  time per frame on one core: median {c['median']:.1f} ms (p90 {c['p90']:.1f}) = "
          f"{1e3 / c['median']:.0f} Hz [{stages}]; wall median {r['wall_ms']['median']:.1f} ms")


# --- corners ----------------------------------------------------------------------------

def run_corners(args) -> int:
    from asmonc_vision.eval.motion_experiment import (CORNER_DETECTORS, CORNER_KINDS,
                                                      corner_localisation)
    if args.trials < 1:
        print('asmonc motion corners: --trials must be >= 1', file=sys.stderr)
        return 2
    print(f'Corner localisation on synthetic corners ({args.trials} per kind; 48x48, 8x8 area '
          'sampling, blur 0.5 px, noise 2 grey levels): error of the detection nearest a true '
          'corner within 3 px, pixels')
    print(f"  {'kind':7s} {'detector':22s} {'found':>6s} {'mean':>6s} {'median':>6s} "
          f"{'p90':>6s} {'rms':>6s} {'bias':>6s}")
    for k in CORNER_KINDS:
        for d in CORNER_DETECTORS:
            r = corner_localisation(d, k, args.trials, args.seed)
            print(f"  {k:7s} {d:22s} {r['detected']:6.0%} {r['mean']:6.3f} {r['median']:6.3f} "
                  f"{r['p90']:6.3f} {r['rms']:6.3f} {r['bias']:6.3f}")
    return 0
