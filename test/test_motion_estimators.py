"""core.motion: the robust estimators on the paper's synthetic experiment."""
import numpy as np
import pytest

from asmonc_vision.core.motion import METHODS, Correspondences, RansacSettings, estimate_motion
from asmonc_vision.core.motion.estimators import ransac, sample_indices
from asmonc_vision.eval.motion_experiment import (PAPER_TABLES, TrialSettings, default_ransac,
                                                  make_trial, motion_errors, run_level,
                                                  run_minimal_level)

SETTINGS = TrialSettings()
CAM = SETTINGS.camera()


def test_trials_are_what_the_paper_describes():
    for i in range(20):
        tr = make_trial([0, i], SETTINGS, 0.0)
        angle = np.degrees(np.linalg.norm(
            np.array([tr.R[2, 1] - tr.R[1, 2], tr.R[0, 2] - tr.R[2, 0], tr.R[1, 0] - tr.R[0, 1]])))
        assert np.degrees(np.arccos(np.clip((np.trace(tr.R) - 1) / 2, -1, 1))) <= 20.0 + 1e-9
        assert 0.05 <= np.linalg.norm(tr.t) <= 0.5
        assert len(tr.corr) == SETTINGS.n_points and angle >= 0
        for pix in (tr.corr.prev_left, tr.corr.prev_right, tr.corr.curr_left, tr.corr.curr_right):
            assert np.all((pix >= 0) & (pix <= [319, 239]))
    # noise is uniform in [-a, a] on every coordinate; outliers are marked
    a = make_trial([1], SETTINGS, 0.0)
    b = make_trial([1], SETTINGS, 0.5, outlier_fraction=0.3)
    d = b.corr.prev_left - a.corr.prev_left
    assert np.abs(d).max() <= 0.5 and np.abs(d).max() > 0.4
    assert b.outliers.sum() == 30


@pytest.mark.parametrize('method', METHODS)
def test_every_method_is_exact_without_noise(method):
    tr = make_trial([2], SETTINGS, 0.0)
    est = estimate_motion(method, tr.corr, CAM, default_ransac(0.0), rng=0)
    assert est.ok, est.reason
    e = motion_errors(est.R, est.t, tr.R, tr.t)
    assert e[:3].max() < 0.01 and e[3:].max() < 1e-4      # mm, deg
    assert est.num_inliers == len(tr.corr)


@pytest.mark.slow
def test_modern_method_meets_the_targets_and_beats_the_papers():
    """The brief's targets for the best method: at 0.5 px pitch <= 0.1 deg and translation
    <= 10 mm, at 1 px pitch <= 0.2 deg; with 30% wrong matches within 1.5x. 25 trials
    (the full 500 are `asmonc motion tables`)."""
    methods = ('stereo_ba', 'three_point', 'essential')
    for a, pitch_max in ((0.5, 0.1), (1.0, 0.2)):
        clean = run_level(methods, a, 25, 0.0)
        dirty = run_level(['stereo_ba'], a, 25, 0.3)
        best = clean['stereo_ba'].mean
        assert best[4] <= pitch_max and best[:3].max() <= 10.0 * a / 0.5
        worst = dirty['stereo_ba'].mean
        assert worst[4] <= 1.5 * pitch_max and worst[:3].max() <= 1.5 * 10.0 * a / 0.5
        assert dirty['stereo_ba'].failures == 0
        for paper in ('three_point', 'essential'):
            assert np.sum(best[:3]) < np.sum(clean[paper].mean[:3])
            assert np.sum(best[3:]) < np.sum(clean[paper].mean[3:])
        # far below the paper's own tables at this noise level
        assert best[4] < PAPER_TABLES['three_point'][a][4] / 5


def test_wrong_matches_are_rejected():
    tr = make_trial([3], SETTINGS, 0.5, outlier_fraction=0.3)
    est = estimate_motion('stereo_ba', tr.corr, CAM, default_ransac(0.5), rng=0)
    assert est.ok
    # nearly every wrong temporal match is out (a wrong stereo match can look right when
    # the motion hardly shows its depth)
    temporal = np.nonzero(tr.outliers)[0][:15]
    assert est.inliers[temporal].sum() <= 1
    assert est.inliers[~tr.outliers].mean() > 0.95
    cov = est.cov
    assert cov.shape == (6, 6) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_minimal_sets_give_errors_of_the_papers_magnitude():
    res = run_minimal_level(1.0, 60)
    pitch = res['three_point'].mean[4]
    # the paper's Table 2 at 1 px: 1.43 deg pitch; minimal sets land in that range
    assert 0.3 < pitch < 5.0
    assert res['three_point'].mean[4] > 10 * run_level(['stereo_ba'], 1.0, 10)['stereo_ba'].mean[4]


def test_too_few_matches_gives_no_motion():
    tr = make_trial([4], TrialSettings(n_points=10), 0.5)
    est = estimate_motion('stereo_ba', tr.corr, CAM, RansacSettings(min_inliers=12), rng=0)
    assert not est.ok and 'too few' in est.reason
    with pytest.raises(ValueError, match='unknown motion method'):
        estimate_motion('nope', tr.corr, CAM)
    with pytest.raises(ValueError, match='curr_left has 3 rows, expected 10'):
        Correspondences(tr.corr.prev_left, tr.corr.prev_right, tr.corr.curr_left[:3])


def test_sampling_and_ransac_core():
    rng = np.random.default_rng(0)
    s = sample_indices(5, 3, 200, rng)
    assert s.shape == (200, 3) and np.all(np.sort(s, 1)[:, 1:] != np.sort(s, 1)[:, :-1])
    # a 1-D "line through the origin" model: slope from one point
    x = np.linspace(1, 10, 50)
    y = 2.0 * x
    y[:10] += 50.0

    def hyp(idx):
        return (y[idx[:, 0]] / x[idx[:, 0]])[:, None]

    def res(models):
        return (models[:, :1] * x[None] - y[None]) ** 2
    best, inl, drawn = ransac(50, 1, hyp, res, 0.5, rng, RansacSettings(max_iterations=100))
    assert best[0] == pytest.approx(2.0) and inl.sum() == 40 and drawn < 100
