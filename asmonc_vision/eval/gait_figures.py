"""The paper's Figs. 13-15 redrawn from the walk model's runs (`asmonc gait figs`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from asmonc_vision.core.gait import GaitConfig, GaitTracker
from asmonc_vision.eval.gait_real import REAL_SIGMA, load_real, real_config
from asmonc_vision.eval.gait_walks import DEFAULT_DATA, HORIZON, make_case, run_tracker


def draw_figures(out: Path, data: Path = DEFAULT_DATA) -> list[Path]:
    """The paper's Figs. 13-15 redrawn (PNG): 13 roll during walking, sensor output and
    filtered; 14 pitch during straight walking, measured and predicted 0.5 s earlier;
    15 yaw in a complex walk (turns, speed changes), measured and predicted 0.5 s
    earlier. Simulated walker, and the real lower-back recordings where present."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = GaitConfig()
    return [_fig13(plt, out, cfg), _fig14(plt, out, cfg, data), _fig15(plt, out, cfg, data)]


def _save(plt, fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _real_recording(data: Path, test: str, name: str):
    """The named real recording, or None when the data or the recording is missing."""
    try:
        recs = [r for r in load_real(data, tests=(test,)) if r.name == name]
    except FileNotFoundError:
        return None
    return recs[0] if recs else None


def _fig13(plt, out: Path, cfg: GaitConfig) -> Path:
    """Fig. 13: roll during walking, sensor output and filtered (simulated compass)."""
    deg = np.degrees
    case = make_case('walk', 0)
    from asmonc_vision.core.gait.prefilter import Prefilter

    tr = GaitTracker(cfg)
    pf = Prefilter(cfg.sample_rate, cfg.prefilter_cutoff, cfg.prefilter_order)
    filt, att = [], []
    for t, z in zip(case.imu_times, case.imu_rpy):
        est = tr.add_inclinometer(t, z, np.full(3, case.imu_variance))
        filt.append(pf(z))
        att.append(est.attitude)
    filt, att = np.array(filt), np.array(att)
    t = case.imu_times
    _, truth = case.walker.states(t)
    sel = (t > 8) & (t < 16)
    fig, ax = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    ax[0].plot(t[sel], deg(case.imu_rpy[sel, 0]), 'k.-', lw=0.8, ms=3)
    ax[0].set_ylabel('roll, deg')
    ax[0].set_title('(a) sensor output (16 Hz compass: 0.3 deg noise, 0.1 deg steps, '
                    '80 ms lag)', fontsize=9)
    ax[1].plot(t[sel], deg(filt[sel, 0]), 'k-', lw=1.2, label='Butterworth prefilter '
               f'({cfg.prefilter_order}nd order, {cfg.prefilter_cutoff:g} Hz)')
    ax[1].plot(t[sel], deg(att[sel, 0]), 'r--', lw=1.2,
               label='walk model (lags compensated)')
    ax[1].plot(t[sel], deg(truth[sel, 0]), color='0.6', lw=3, alpha=0.5, zorder=0,
               label='true roll')
    ax[1].set_ylabel('roll, deg')
    ax[1].set_xlabel('time, s')
    ax[1].set_title('(b) filtered', fontsize=9)
    ax[1].legend(fontsize=7, loc='upper right')
    fig.suptitle('Fig. 13. Roll during walking (simulated walker)', fontsize=10)
    return _save(plt, fig, out / 'gait_fig13.png')


def _fig14(plt, out: Path, cfg: GaitConfig, data: Path) -> Path:
    """Fig. 14: pitch during straight walking, measured and predicted 0.5 s earlier."""
    deg = np.degrees
    case = make_case('walk', 0)
    run = run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, cfg)
    real = _real_recording(data, 'Test5', 'HA/001 Test5 Trial1')
    rows = 3 if real is not None else 2
    fig, ax = plt.subplots(rows, 1, figsize=(8, 2.6 * rows))
    sel = (run.times > 8) & (run.times < 14)
    ax[0].plot(run.times[sel], deg(case.imu_rpy[sel, 1]), 'k.-', lw=0.8, ms=3)
    ax[0].set_title('(a) measured (simulated 16 Hz compass)', fontsize=9)
    ax[1].plot(run.times[sel] + HORIZON, deg(run.predicted[sel, 1]), 'r.-', lw=0.8, ms=3,
               label='predicted 0.5 s earlier')
    _, tp = case.walker.states(run.times[sel] + HORIZON)
    ax[1].plot(run.times[sel] + HORIZON, deg(tp[:, 1]), color='0.6', lw=3, alpha=0.5,
               zorder=0, label='true pitch')
    ax[1].set_xlim(ax[0].get_xlim())
    ax[1].set_title('(b) predicted half a second earlier', fontsize=9)
    ax[1].legend(fontsize=7, loc='upper right')
    if real is not None:
        rr = run_tracker(real.times, real.rpy, REAL_SIGMA ** 2, real_config(cfg))
        s, e = real.bouts[0]
        m = (rr.times > s - 1.0) & (rr.times < e + 1.0)
        ax[2].plot(rr.times[m], deg(real.rpy[m, 1]), 'k.-', lw=0.8, ms=3, label='measured')
        ax[2].plot(rr.times[m] + HORIZON, deg(rr.predicted[m, 1]), 'r.-', lw=0.8, ms=3,
                   label='predicted 0.5 s earlier')
        ax[2].axvspan(s, e, color='g', alpha=0.08, label='reference walking bout')
        ax[2].set_title(f'(c) real: Mobilise-D lower-back IMU, {real.name}', fontsize=9)
        ax[2].legend(fontsize=7, loc='upper left')
    for a in ax:
        a.set_ylabel('pitch, deg')
    ax[-1].set_xlabel('time, s')
    fig.suptitle('Fig. 14. Pitch during walking', fontsize=10)
    return _save(plt, fig, out / 'gait_fig14.png')


def _fig15(plt, out: Path, cfg: GaitConfig, data: Path) -> Path:
    """Fig. 15: yaw in a complex walk (turns, speed changes)."""
    deg = np.degrees
    case = make_case('turn', 0)
    run = run_tracker(case.imu_times, case.imu_rpy, case.imu_variance, cfg)
    real11 = _real_recording(data, 'Test11', 'MS/001 Test11 Trial1')
    rows = 2 if real11 is not None else 1
    fig, ax = plt.subplots(rows, 1, figsize=(8, 3.0 * rows), squeeze=False)
    ax = ax[:, 0]
    yaw_m = np.unwrap(case.imu_rpy[:, 2])
    ax[0].plot(run.times, deg(yaw_m), 'k-', lw=1.0, label='measured')
    ax[0].plot(run.times + HORIZON, deg(run.predicted[:, 2]), 'r:', lw=1.4,
               label='predicted 0.5 s earlier')
    ax[0].set_title('(a) simulated: walk, 90 deg turn, speed change, 60 deg turn back',
                    fontsize=9)
    if real11 is not None:
        rr = run_tracker(real11.times, real11.rpy, REAL_SIGMA ** 2, real_config(cfg))
        s, e = real11.bouts[3] if len(real11.bouts) > 3 else real11.bouts[0]
        m = (rr.times > s - 2) & (rr.times < e + 2)
        ax[1].plot(rr.times[m], deg(real11.rpy[m, 2]), 'k-', lw=1.0, label='measured')
        ax[1].plot(rr.times[m] + HORIZON, deg(rr.predicted[m, 2]), 'r:', lw=1.4,
                   label='predicted 0.5 s earlier')
        ax[1].axvspan(s, e, color='g', alpha=0.08, label='reference walking bout')
        ax[1].set_title(f'(b) real: {real11.name} (daily-living walk with turns)',
                        fontsize=9)
    for a in ax:
        a.set_ylabel('yaw, deg')
        a.legend(fontsize=7, loc='best')
    ax[-1].set_xlabel('time, s')
    fig.suptitle('Fig. 15. Yaw during a complex walk', fontsize=10)
    return _save(plt, fig, out / 'gait_fig15.png')


def figures_command(out: Path, data: Path = DEFAULT_DATA) -> int:
    """`asmonc gait figs`: draw the figures into ``out``, print their paths."""
    for path in draw_figures(out, data):
        print(f'figure: {path}')
    return 0
