"""The walk model on rendered walking bags, fused with the visual motion of the egomotion
estimator: the paper's "ideal solution" (Section 4) end to end, without ROS.

    asmonc gait bags [BAG ...] [--cache DIR] [--json F]

For each bag: the 16 Hz /inclinometer/imu stream as recorded, the visual motion that the
egomotion node would publish (``core.motion.EgomotionEstimator`` with the defaults of
``config/egomotion.yaml``, run over the bag's stereo pairs in order: every frame-to-frame
rotation with its reference frame's stamp), and the walk model with the defaults of
``config/gait_filter.yaml`` (the node's settings: visual-motion noise 0.5 deg per frame,
1 deg model error) in five modes: the inclinometer alone, visual motion alone (the
inclinometer only detects walking and gives the start attitude), both, and both with
either source silent for 4 s in the middle of the bag. Scored against the bag's
/ground_truth/camera_pose (the rig attitude through the fixed camera mounting; a cubic
spline through the 10 Hz poses, whose interpolation error is ~0.01 deg at gait
frequencies): RMS of the 0.5 s-ahead absolute attitude and of the predicted rotation over
the horizon (what DGPR uses), roll / pitch / yaw in degrees, over steady walking (the
rig moving at >= 0.6 m/s, averaged over 1 s, from 2 s before to the horizon, and the
model walking for 2 s); the dropout rows over their 4 s only.

Without BAG arguments the walking bags are rendered by the simulator first (fixed seeds,
into --cache, reused when present): ``clear_walk`` (30 s: straight, a 5-15 deg bend with
a speed change, straight) and ``walk_stop_turn`` (30 s: walk, stop, turn ~90 deg in
place, walk on), seeds 1-3 each; about 15 s per bag to render, 5 s to run.

Exit status: 0 done; 2 a bag is missing or unreadable, has no inclinometer stream, or has
no ground truth.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmonc_vision.eval.evaluation import json_ready

#: the bags rendered when none are given: (scenario, seconds, seeds)
DEFAULT_SCENARIOS = (('clear_walk', 30.0, (1, 2, 3)), ('walk_stop_turn', 30.0, (1, 2, 3)))
DEFAULT_CACHE = Path('/tmp/asmonc_gait_bags')
#: the dropout window's length, s (centred in the bag)
DROPOUT = 4.0
#: variance of an inclinometer reading that gives none (the gait node's default), rad^2
DEFAULT_VARIANCE = math.radians(0.5) ** 2
MODES = ('inclinometer', 'egomotion', 'fused', 'fused_drop_egomotion',
         'fused_drop_inclinometer')


@dataclass
class BagStreams:
    """What the walk model and its scoring need from one bag (times in s from the first
    camera frame)."""

    name: str
    imu_times: np.ndarray          # (M,) s
    imu_rpy: np.ndarray            # (M, 3) rad (REP 103 roll, pitch, yaw of inclinometer_link)
    imu_var: np.ndarray            # (M, 3) rad^2
    egomotion: list                # [(t_prev, t_cur, R (3, 3) optical)] in time order
    frame_times: np.ndarray        # (F,) s
    truth_rpy: np.ndarray          # (F, 3) rad, rig attitude (yaw and roll unwrapped)
    truth_xyz: np.ndarray          # (F, 3) m, left camera position
    motion_status: dict            # egomotion estimator statuses -> counts


def load_bag(bag: Path) -> BagStreams:
    """Read a bag's inclinometer stream and ground truth, and run the egomotion estimator
    over its stereo pairs.

    Raises:
        bagio.BagError: unreadable bag.
        ValueError: no inclinometer stream, or no ground truth.
    """
    from asmonc_vision.io import bagio
    from asmonc_vision.eval.motion_bags import load_sequence
    from asmonc_vision.core.motion import EgomotionEstimator
    from asmonc_vision.core.rotations import R_BODY_OPTICAL, matrix_to_rpy

    frames = load_sequence(bag)
    if not frames or any(f['pose'] is None for f in frames):
        raise ValueError(f"bag '{bag}' has no /ground_truth/camera_pose for its frames")
    t0 = frames[0]['stamp_ns']
    imu_t, imu_rpy, imu_var = [], [], []
    for _, _, msg in bagio.read_messages(bag, [bagio.TOPICS['imu'][0]]):
        try:
            rpy, var = bagio.imu_to_rpy_var(msg)
        except ValueError:
            continue                        # no orientation in this message
        imu_t.append((bagio.header_stamp_ns(msg) - t0) * 1e-9)
        imu_rpy.append(rpy)
        imu_var.append(var if var is not None else np.full(3, DEFAULT_VARIANCE))
    if not imu_t:
        raise ValueError(f"bag '{bag}' has no /inclinometer/imu")
    order = np.argsort(imu_t, kind='stable')
    est = EgomotionEstimator()
    ego, status = [], {}
    for f in frames:
        res = est.process(f['left'], f['right'], f['cam'], f['stamp_ns'])
        status[res.status] = status.get(res.status, 0) + 1
        if res.ok and res.reference_stamp_ns is not None:
            ego.append(((res.reference_stamp_ns - t0) * 1e-9, (f['stamp_ns'] - t0) * 1e-9,
                        np.asarray(res.motion.R, float)))
    ft = np.array([(f['stamp_ns'] - t0) * 1e-9 for f in frames])
    # the rig (inclinometer_link) attitude: R_world_optical = R_world_body R_BODY_OPTICAL
    rpy = np.array([matrix_to_rpy(f['pose'][0] @ R_BODY_OPTICAL.T) for f in frames])
    rpy[:, 0] = np.unwrap(rpy[:, 0])
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    xyz = np.array([f['pose'][1] for f in frames])
    return BagStreams(Path(bag).name, np.asarray(imu_t)[order], np.asarray(imu_rpy)[order],
                      np.asarray(imu_var)[order], ego, ft, rpy, xyz, status)


def _truth(streams: BagStreams):
    """(attitude(t) -> (N, 3) rad, speed(t) -> (N,) m/s averaged over 1 s): cubic splines
    through the 10 Hz ground truth."""
    from scipy.interpolate import CubicSpline

    att = CubicSpline(streams.frame_times, streams.truth_rpy, axis=0)
    pos = CubicSpline(streams.frame_times, streams.truth_xyz, axis=0)
    lo, hi = streams.frame_times[0], streams.frame_times[-1]

    def speed(t):
        t = np.atleast_1d(np.asarray(t, float))
        # mean speed over [t - 0.5, t + 0.5] (the path length / 1 s, by 20 steps)
        u = np.clip(t[:, None] + np.linspace(-0.5, 0.5, 21)[None, :], lo, hi)
        p = pos(u)
        return np.linalg.norm(np.diff(p, axis=1), axis=2).sum(axis=1)

    return att, speed


def evaluate_bag(streams: BagStreams, config=None, horizon: float = 0.5) -> dict:
    """The five modes on one bag: per mode the attitude and motion errors (deg, (n, 3))
    of the scored samples (module doc)."""
    from asmonc_vision.eval.gait_walks import (STEADY_AFTER, WALK_SPEED, held,
                                               motion_increments,
                                        run_tracker)
    from asmonc_vision.core.gait import GaitConfig, scoring

    cfg = config if config is not None else GaitConfig()
    att, speed = _truth(streams)
    t_end = float(streams.frame_times[-1])
    mid = 0.5 * (streams.imu_times[0] + streams.imu_times[-1])
    window = (mid - DROPOUT / 2, mid + DROPOUT / 2)
    opts = {'inclinometer': dict(ego=False, inc=True),
            'egomotion': dict(ego=True, inc=False),
            'fused': dict(ego=True, inc=True),
            'fused_drop_egomotion': dict(ego=True, inc=True, drop_ego=window),
            'fused_drop_inclinometer': dict(ego=True, inc=True, drop_inc=window)}
    out = {}
    for mode, o in opts.items():
        run = run_tracker(streams.imu_times, streams.imu_rpy, streams.imu_var, cfg,
                          egomotion=streams.egomotion if o['ego'] else None,
                          use_inclinometer=o['inc'], drop_inclinometer=o.get('drop_inc'),
                          drop_egomotion=o.get('drop_ego'))
        t = run.times
        inside = (t >= streams.frame_times[0]) & (t + horizon <= t_end)
        def moving(u):
            return speed(u) >= WALK_SPEED        # (speed clamps u to the recording)

        sel = (inside & moving(t) & moving(t - STEADY_AFTER) & moving(t + horizon)
               & (t - STEADY_AFTER >= streams.frame_times[0])
               & held(t, run.walking, STEADY_AFTER))
        if 'drop_inc' in o or 'drop_ego' in o:
            sel &= (t >= window[0]) & (t <= window[1])
        truth_h, truth_now = att(t + horizon), att(t)     # (only `inside` is scored)
        out[mode] = {
            'attitude_err': scoring.angle_errors_deg(run.predicted, truth_h)[sel],
            'motion_err': scoring.angle_errors_deg(motion_increments(run),
                                                   truth_h - truth_now)[sel],
            'egomotion_used': int(run.egomotion_used)}
    return out


def summarise(per_bag: dict) -> dict:
    """Pool the bags: per mode the RMS (deg) of the attitude and the motion, roll / pitch /
    yaw, and the number of samples."""
    from asmonc_vision.core.gait import scoring

    res = {}
    for mode in MODES:
        a = [b[mode]['attitude_err'] for b in per_bag.values() if b[mode]['attitude_err'].size]
        m = [b[mode]['motion_err'] for b in per_bag.values() if b[mode]['motion_err'].size]
        a = np.concatenate(a) if a else np.zeros((0, 3))
        m = np.concatenate(m) if m else np.zeros((0, 3))
        res[mode] = {'attitude_rms_deg': [float(v) for v in scoring.rms(a)] if a.size else None,
                     'motion_rms_deg': [float(v) for v in scoring.rms(m)] if m.size else None,
                     'samples': int(a.shape[0])}
    return res


def render_default_bags(cache: Path, progress=print) -> list[Path]:
    """Render (or reuse) the default walking bags into `cache`; their paths."""
    cache.mkdir(parents=True, exist_ok=True)
    out = []
    for name, seconds, seeds in DEFAULT_SCENARIOS:
        for seed in seeds:
            path = cache / f'{name}_{seconds:g}s_seed{seed}'
            if not (path / 'metadata.yaml').exists():
                progress(f'rendering {path.name} ...')
                subprocess.run([sys.executable, '-m', 'asmonc_vision.sim', name, str(path),
                                '--seed', str(seed), '--duration', f'{seconds:g}', '--quiet',
                                '--force'], check=True, stdout=subprocess.DEVNULL)
            out.append(path)
    return out


def print_summary(per_bag: dict, summary: dict, file=None) -> None:
    file = sys.stdout if file is None else file
    from asmonc_vision.eval.gait_walks import fmt3

    def _fmt(v):
        return fmt3(v or [None] * 3)

    p = lambda s='': print(s, file=file)  # noqa: E731
    p('walk model on walking bags: the inclinometer as recorded, visual motion from the '
      'egomotion estimator; 0.5 s-ahead RMS in steady walking, degrees, roll / pitch / yaw '
      f'(dropout rows: their {DROPOUT:g} s only)')
    p(f'{"source":26} {"0.5 s-ahead attitude":24} {"rotation over the 0.5 s":24} samples')
    for mode, r in summary.items():
        p(f'{mode:26} {_fmt(r["attitude_rms_deg"]):24} {_fmt(r["motion_rms_deg"]):24} '
          f'{r["samples"]}')
    p()
    p('per bag (fused vs inclinometer alone, attitude): ' + '; '.join(
        f'{name} {_fmt(_rms(b["fused"]["attitude_err"]))} vs '
        f'{_fmt(_rms(b["inclinometer"]["attitude_err"]))}' for name, b in per_bag.items()))


def _rms(e):
    from asmonc_vision.core.gait import scoring
    return [float(v) for v in scoring.rms(e)] if e.size else None


def bags_command(bags, cache: Path, json_path: Path | None = None) -> int:
    """`asmonc gait bags`: the walking ``bags`` (default: rendered into ``cache``) scored
    and printed, the numbers also written to ``json_path``; the exit code."""
    from asmonc_vision.io import bagio

    bags = list(bags) or render_default_bags(cache,
                                                  lambda s: print(s, file=sys.stderr))
    per_bag = {}
    for bag in bags:
        try:
            streams = load_bag(bag)
        except (bagio.BagError, ValueError, OSError) as exc:
            print(f'asmonc gait bags: {exc}', file=sys.stderr)
            return 2
        per_bag[streams.name] = evaluate_bag(streams)
        print(f'  {streams.name}: {len(streams.egomotion)} visual motions '
              f'({streams.motion_status}), {streams.imu_times.size} inclinometer samples',
              file=sys.stderr)
    summary = summarise(per_bag)
    print_summary(per_bag, summary)
    if json_path:
        doc = {'summary': summary, 'bags': {
            n: {m: {'attitude_rms_deg': _rms(b[m]['attitude_err']),
                    'motion_rms_deg': _rms(b[m]['motion_err']),
                    'samples': int(b[m]['attitude_err'].shape[0])} for m in MODES}
            for n, b in per_bag.items()}}
        json_path.write_text(json.dumps(json_ready(doc), indent=1, allow_nan=False))
    return 0


