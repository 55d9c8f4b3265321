"""The walk model on real walking: the Mobilise-D lower-back IMU recordings in
../shared/data/gait_lowback (five straight walks, Test5, with reference walking bouts and
cadence from INDIP or stereophotogrammetry). A fast check of what `asmonc gait real`
measures at length; the data must be there (it ships beside the project)."""
import numpy as np
import pytest

from asmonc_vision.eval import gait_real as gait
from asmonc_vision.core.gait import scoring


@pytest.fixture(scope='module')
def runs():
    assert (gait.DEFAULT_DATA / 'data_csv').is_dir(), \
        f'the real walking recordings are missing: {gait.DEFAULT_DATA}'
    recs = gait.load_real(gait.DEFAULT_DATA, tests=('Test5',))
    assert len(recs) == 6
    cfg = gait.real_config()
    return [(rec, gait.run_tracker(rec.times, rec.rpy, gait.REAL_SIGMA ** 2, cfg))
            for rec in recs if rec.bouts]


def _in_bout(rec, t, horizon=0.0):
    m = np.zeros(t.size, bool)
    for s, e in rec.bouts:
        m |= (t >= s) & (t + horizon <= e)
    return m


def test_walking_is_detected_inside_the_reference_bouts(runs):
    assert len(runs) == 5
    inside = np.concatenate([run.walking[_in_bout(rec, run.times)] for rec, run in runs])
    # measured: walking in 0.86 of the samples inside the reference bouts (0.73-1.0 per
    # walk; the change detector needs about a stride to lock on)
    assert inside.mean() >= 0.8, inside.mean()


def test_the_tracked_cadence_follows_the_reference(runs):
    errs = []
    for rec, run in runs:
        m = _in_bout(rec, run.times) & run.walking
        assert m.any(), rec.name
        # the walk model tracks the pitch frequency (one per step); the reference
        # cadence is in steps per second
        errs.append(abs(float(np.median(run.frequency[m])) - rec.cadence[0]))
    # measured: 0.05, 0.06, 0.25, 0.12, 0.08 Hz
    assert sorted(errs)[3] < 0.15, errs
    assert max(errs) < 0.3, errs


def test_pitch_half_a_second_ahead_beats_holding(runs):
    pred, held = [], []
    for rec, run in runs:
        t = run.times
        later = np.column_stack([np.interp(t + gait.HORIZON, rec.times, rec.rpy[:, a])
                                 for a in range(3)])
        m = _in_bout(rec, t, gait.HORIZON)
        pred.append(scoring.angle_errors_deg(run.predicted, later)[m])
        held.append(scoring.angle_errors_deg(rec.rpy[:t.size], later)[m])
    p, h = scoring.rms(np.concatenate(pred)), scoring.rms(np.concatenate(held))
    # measured: pitch 2.09 deg RMS against 2.62 for holding (20 % better); roll 1.71
    # against 2.34
    assert p[1] < 0.85 * h[1], (p, h)
    assert p[0] < h[0], (p, h)


#: HA/001's first straight walk (Test5 Trial1), its reference walking bout (INDIP, s) and
#: cadence (steps/s), as `gait.load_real` reads them from data.mat
ONE_WALK = ('HA', '001', 'TimeMeasure1_Test5_Trial1.csv')
ONE_BOUT = (5.05, 9.88)
ONE_CADENCE = 1.675


def test_one_real_walk_quickly():
    """One recording without its reference file (about a second): the attitude as
    `gait.load_real` makes it (complementary filter, 16 Hz), through the walk model."""
    from asmonc_vision.core.gait.attitude import (MOBILISE_TO_BODY, complementary_filter,
                                                  decimate_to)

    f = gait.DEFAULT_DATA.joinpath('data_csv', *ONE_WALK)
    assert f.is_file(), f'the real walking recordings are missing: {f}'
    a = np.loadtxt(f, delimiter=',', skiprows=1)
    rpy = complementary_filter(a[:, 1:4] @ MOBILISE_TO_BODY.T,
                               np.radians(a[:, 4:7]) @ MOBILISE_TO_BODY.T,
                               gait.REAL_RATE, gait.REAL_ATTITUDE_TIME_CONSTANT)
    t16, rpy16 = decimate_to(rpy, gait.REAL_RATE, 16.0)
    run = gait.run_tracker(t16, rpy16, gait.REAL_SIGMA ** 2, gait.real_config())
    bout = (run.times >= ONE_BOUT[0]) & (run.times <= ONE_BOUT[1])
    # measured: walking in 0.79 of the bout's samples; tracked step frequency 1.72 Hz
    # (median while walking in the bout) against the reference 1.675 steps/s
    assert run.walking[bout].mean() >= 0.75, run.walking[bout].mean()
    freq = float(np.median(run.frequency[bout & run.walking]))
    assert abs(freq - ONE_CADENCE) < 0.1, freq
