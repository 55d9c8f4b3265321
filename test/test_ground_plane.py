"""Robust ground-plane fit in disparity space (core.ground_plane)."""
import numpy as np
import pytest

from asmonc_vision.core.camera import MetricPlane, StereoCamera, plane_from_metric
from asmonc_vision.core.rotations import rotvec_to_matrix
from asmonc_vision.core.ground_plane import (PlaneFit, fast_median, fast_percentile,
                                             fit_ground_plane, lsq_plane,
                                             plane_is_plausible, predict_plane)

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)


def _ground(pitch_deg=20.0, height=1.25, roll_deg=0.0):
    t, r = np.radians(pitch_deg), np.radians(roll_deg)
    down = np.array([0.0, np.cos(t), np.sin(t)])
    cr, sr = np.cos(r), np.sin(r)
    down = np.array([cr * down[0] - sr * down[1], sr * down[0] + cr * down[1], down[2]])
    plane = MetricPlane(normal_up=-down, height=height)
    return plane, plane_from_metric(CAM, plane)


def _noisy_points(abc, n=600, noise=0.3, outlier_frac=0.2, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 319, n)
    v = rng.uniform(60, 239, n)
    d = abc[0] * u + abc[1] * v + abc[2] + rng.normal(0, noise, n)
    out = rng.random(n) < outlier_frac
    d[out] += rng.uniform(3, 40, out.sum()) * rng.choice([-1.0, 1.0], out.sum())
    return u, v, d, out


@pytest.mark.parametrize('method', ['ransac', 'trimmed'])
def test_recovers_plane_with_20_percent_outliers(method):
    plane, abc = _ground(pitch_deg=20, roll_deg=3)
    u, v, d, out = _noisy_points(abc)
    fit = fit_ground_plane(u, v, d, cam=CAM, method=method, rng=0)
    assert isinstance(fit, PlaneFit)
    sigma = np.sqrt(np.diag(fit.cov))
    assert np.all(np.abs(fit.abc - abc) < 5 * sigma)
    assert np.all(sigma < [2e-3, 3e-3, 0.3])
    # Disparity error over the image well below the noise.
    uu, vv = np.meshgrid(np.arange(0, 320, 20), np.arange(60, 240, 20))
    err = (fit.abc[0] - abc[0]) * uu + (fit.abc[1] - abc[1]) * vv + (fit.abc[2] - abc[2])
    assert np.abs(err).max() < 0.15
    assert np.mean(fit.inliers == ~out) > 0.97
    assert fit.num_features == int(fit.inliers.sum())
    assert 0.2 < fit.residual_rms < 0.4
    assert 0.2 < fit.residual_sigma < 0.4        # robust spread of the inlier residuals
    assert fit.metric is not None
    assert abs(fit.metric.height - plane.height) < 0.03
    assert np.degrees(np.arccos(np.clip(fit.metric.normal_up @ plane.normal_up, -1, 1))) < 1.0


def test_ransac_with_outlier_majority():
    """The road is a minority of the features (as on KITTI): RANSAC with the
    plausibility check still finds it; plain least squares would not."""
    _, abc = _ground()
    u, v, d, out = _noisy_points(abc, n=1000, outlier_frac=0.7, seed=4)
    fit = fit_ground_plane(u, v, d, cam=CAM, rng=1)
    assert fit is not None
    assert np.all(np.abs(fit.abc - abc) < [3e-3, 3e-3, 0.3])
    assert np.mean(fit.inliers[~out]) > 0.9


def test_seeded_fits_are_reproducible():
    _, abc = _ground()
    u, v, d, _ = _noisy_points(abc, seed=2)
    f1 = fit_ground_plane(u, v, d, rng=7)
    f2 = fit_ground_plane(u, v, d, rng=np.random.default_rng(7))
    np.testing.assert_array_equal(f1.abc, f2.abc)
    np.testing.assert_array_equal(f1.inliers, f2.inliers)
    assert f1.metric is None                                  # no camera given


def test_failures_return_none():
    _, abc = _ground()
    u, v, d, _ = _noisy_points(abc, outlier_frac=0.0)
    assert fit_ground_plane(u[:2], v[:2], d[:2]) is None                      # too few
    assert fit_ground_plane(u[:20], v[:20], d[:20], min_features=30) is None  # too few
    assert fit_ground_plane([], [], []) is None
    assert fit_ground_plane(u, np.full_like(v, 150.0), d) is None             # one row
    assert fit_ground_plane(np.full_like(u, 100.0), v, d) is None             # one column
    nan = np.full_like(d, np.nan)
    assert fit_ground_plane(u, v, nan) is None
    # A plane above the cameras (disparity growing upwards) is not a ground.
    assert fit_ground_plane(u, 240.0 - v, d, cam=CAM) is None
    # A fronto-parallel wall is not a ground.
    assert fit_ground_plane(u, v, np.full_like(d, 20.0), cam=CAM) is None
    # Camera too high for the bounds.
    assert fit_ground_plane(u, v, d, cam=CAM, max_height_m=1.0) is None


def test_nans_are_ignored_and_masked_out():
    _, abc = _ground()
    u, v, d, _ = _noisy_points(abc, outlier_frac=0.0, seed=3)
    d[::10] = np.nan
    fit = fit_ground_plane(u, v, d, cam=CAM, rng=0)
    assert fit is not None and not fit.inliers[::10].any()
    assert np.all(np.abs(fit.abc - abc) < [2e-3, 2e-3, 0.2])


def test_bad_arguments_raise():
    with pytest.raises(ValueError):
        fit_ground_plane([1, 2, 3], [1, 2, 3], [1, 2, 3], method='hough')
    with pytest.raises(ValueError):
        fit_ground_plane([1, 2, 3], [1, 2, 3], [1, 2], rng=0)
    with pytest.raises(ValueError):
        fit_ground_plane([1, 2, 3], [1, 2, 3], [1, 2, 3], inlier_threshold_px=0.0)


def test_lsq_plane_exact_and_covariance():
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 300, 400)
    v = rng.uniform(0, 200, 400)
    d = 0.02 * u + 0.3 * v - 7.0 + rng.normal(0, 0.5, 400)
    abc, cov, rms = lsq_plane(u, v, d)
    assert np.all(np.abs(abc - [0.02, 0.3, -7.0]) < [2e-3, 2e-3, 0.3])
    a_mat = np.stack([u, v, np.ones_like(u)], 1)
    ref = np.linalg.lstsq(a_mat, d, rcond=None)[0]
    np.testing.assert_allclose(abc, ref, rtol=1e-9, atol=1e-9)
    res = d - a_mat @ ref
    np.testing.assert_allclose(cov, res @ res / (400 - 3) * np.linalg.inv(a_mat.T @ a_mat),
                               rtol=1e-6)
    assert abs(rms - 0.5) < 0.05


def test_plausibility_check():
    plane, abc = _ground(pitch_deg=30, height=1.4)
    m = plane_is_plausible(CAM, abc)
    assert m is not None and abs(m.height - 1.4) < 1e-9
    assert plane_is_plausible(CAM, abc, max_height_m=1.0) is None
    assert plane_is_plausible(CAM, abc, max_tilt_deg=20.0) is None
    assert plane_is_plausible(CAM, np.zeros(3)) is None
    assert plane_is_plausible(CAM, np.array([np.nan, 0.1, 1.0])) is None


def test_weights_prefer_the_near_surface():
    """Ground here (large disparity) and a larger area of lower ground beyond a step:
    weighting by disparity cubed picks the near one; unweighted RANSAC the bigger one."""
    _, near_abc = _ground(height=1.25)
    _, far_abc = _ground(height=1.40)
    rng = np.random.default_rng(6)
    un, vn = rng.uniform(0, 319, 150), rng.uniform(190, 239, 150)
    uf, vf = rng.uniform(0, 319, 600), rng.uniform(40, 170, 600)
    u, v = np.r_[un, uf], np.r_[vn, vf]
    d = np.r_[near_abc[0] * un + near_abc[1] * vn + near_abc[2],
              far_abc[0] * uf + far_abc[1] * vf + far_abc[2]] + rng.normal(0, 0.2, 750)
    plain = fit_ground_plane(u, v, d, cam=CAM, rng=0)
    near = fit_ground_plane(u, v, d, cam=CAM, weights=np.maximum(d, 0) ** 3, rng=0)
    assert abs(plain.metric.height - 1.40) < 0.03
    assert abs(near.metric.height - 1.25) < 0.03
    assert near.inliers[:150].mean() > 0.95
    with pytest.raises(ValueError):
        fit_ground_plane(u, v, d, weights=np.ones(3))


@pytest.mark.parametrize('n', [1, 2, 3, 10, 101, 1000])
def test_median_is_numpy_median(n):
    x = np.random.default_rng(n).normal(0.0, 1.0, n)
    assert fast_median(x) == float(np.median(x))


@pytest.mark.parametrize('n', [1, 2, 3, 7, 10, 101, 1000, 2345])
def test_percentile_is_numpy_percentile(n):
    x = np.random.default_rng(n).normal(0.0, 3.0, n)
    for q in (0.0, 5.0, 10.0, 37.5, 50.0, 90.0, 95.0, 100.0):
        assert (np.float64(fast_percentile(x, q)).tobytes()
                == np.float64(np.percentile(x, q)).tobytes())


@pytest.mark.parametrize('seed', range(5))
def test_predict_plane_is_the_plane_seen_after_the_motion(seed):
    """The plane carried through a motion X_prev = R X + t (left optical frames) is the
    plane the moved camera sees, n' = R^T n, h' = h + n.t, and F is its Jacobian."""
    rng = np.random.default_rng(seed)
    cam = CAM
    plane, _ = _ground(rng.uniform(10, 30), rng.uniform(0.8, 1.6), rng.uniform(-5, 5))
    n = plane.normal_up
    R, t = rotvec_to_matrix(rng.normal(0, 0.05, 3)), rng.normal(0, 0.1, 3)
    abc = plane_from_metric(cam, plane)
    pred, F = predict_plane(cam, abc, R, t)
    seen = plane_from_metric(cam, MetricPlane(normal_up=R.T @ n, height=plane.height + n @ t))
    np.testing.assert_allclose(pred, seen, rtol=1e-9, atol=1e-9)
    eps = 1e-6
    F_num = np.column_stack([(predict_plane(cam, abc + e, R, t)[0]
                              - predict_plane(cam, abc - e, R, t)[0]) / (2 * eps)
                             for e in np.eye(3) * eps])
    np.testing.assert_allclose(F, F_num, rtol=1e-5, atol=1e-7)
    # no motion: the same plane, F = I
    same, F0 = predict_plane(cam, abc, np.eye(3), np.zeros(3))
    np.testing.assert_allclose(same, abc, atol=1e-12)
    np.testing.assert_allclose(F0, np.eye(3), atol=1e-12)


def test_predict_plane_none_when_the_camera_goes_below_the_plane():
    cam = CAM
    plane, abc = _ground(20.0, 1.2)
    n = plane.normal_up
    assert predict_plane(cam, abc, np.eye(3), -1.5 * n) is None     # 1.5 m down
    assert predict_plane(cam, abc, np.eye(3), np.array([np.nan, 0, 0])) is None
    assert predict_plane(cam, abc, np.eye(3), -1.0 * n) is not None  # still 0.2 m up


def test_inliers_along_one_slanted_line_are_refused_with_a_least_spread():
    """Points along one slanted image line (a single grout joint, both of its edges 2 px
    apart) fit many planes exactly -- any turned about the line -- so the fit's residuals
    cannot tell it is wrong; with ``min_spread_px`` it is refused, and points spread over
    the image are still fitted."""
    from asmonc_vision.core.ground_plane import _minor_spread
    _, abc = _ground()
    rng = np.random.default_rng(3)
    t = rng.uniform(0.0, 1.0, 200)
    u = 250.0 - 40.0 * t + rng.choice([0.0, 2.0], 200)     # a line from (250, 60) down-left
    v = 60.0 + 180.0 * t
    d = abc[0] * u + abc[1] * v + abc[2] + rng.normal(0.0, 0.1, 200)
    assert _minor_spread(u, v) < 1.5
    assert fit_ground_plane(u, v, d, rng=0) is not None                   # 0: any spread
    assert fit_ground_plane(u, v, d, min_spread_px=3.0, rng=0) is None
    u2, v2, d2, _ = _noisy_points(abc, outlier_frac=0.0)
    assert _minor_spread(u2, v2) > 30.0
    fit = fit_ground_plane(u2, v2, d2, min_spread_px=3.0, rng=0)
    assert fit is not None and np.allclose(fit.abc, abc, atol=0.05)
    with pytest.raises(ValueError, match='min_spread_px'):
        fit_ground_plane(u2, v2, d2, min_spread_px=-1.0)


def test_lsq_plane_at_height_keeps_the_height_and_fits_the_orientation():
    """A band of noisy ground rows: the free fit trades height against pitch; the fit at
    the true height recovers the plane, and at a wrong height keeps that height."""
    from asmonc_vision.core.ground_plane import cyclopean_height, lsq_plane_at_height
    n = np.array([0.0, np.cos(np.radians(3.0)), np.sin(np.radians(3.0))])
    true = plane_from_metric(CAM, MetricPlane(normal_up=-n, height=1.3))
    rng = np.random.default_rng(4)
    u = rng.uniform(0, 319, 400)
    v = rng.uniform(200, 239, 400)
    d = true[0] * u + true[1] * v + true[2] + rng.normal(0.0, 0.3, 400)
    h_true = cyclopean_height(CAM, true)
    held = lsq_plane_at_height(CAM, u, v, d, h_true)
    assert cyclopean_height(CAM, held) == pytest.approx(h_true, abs=1e-9)
    assert held == pytest.approx(true, abs=0.02 * abs(true[2]))
    wrong = lsq_plane_at_height(CAM, u, v, d, 1.5)
    assert cyclopean_height(CAM, wrong) == pytest.approx(1.5, abs=1e-9)
    assert lsq_plane_at_height(CAM, u[:1], v[:1], d[:1], 1.3) is None


def test_the_compiled_ransac_residuals_give_numpys(monkeypatch):
    """`ground_plane.residuals_kernel` (the RANSAC hypotheses' truncated squared
    residuals and inlier shares) gives numpy's values bit for bit, NaN included, and a
    fit through either draws and returns the same."""
    from asmonc_vision.core import ground_plane as gp
    gp.warm_up()
    if gp.nb_residuals is None:
        pytest.skip('numba is not available')
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0, 320, 700), rng.uniform(120, 240, 700)
    d = 0.1 * v - 8.0 + rng.normal(0, 0.6, 700)
    a, b, c = rng.normal(0, 0.01, 16), 0.1 + rng.normal(0, 0.01, 16), rng.normal(-8, 1, 16)
    a[3] = np.nan
    fast = gp._residuals(a, b, c, u, v, d, 1.0)
    kernel = gp.nb_residuals
    monkeypatch.setattr(gp, 'nb_residuals', None)
    slow = gp._residuals(a, b, c, u, v, d, 1.0)
    for x, y in zip(fast, slow):
        assert x.dtype == y.dtype and x.shape == y.shape
        np.testing.assert_array_equal(x, y)
    fits = []
    for k in (kernel, None):
        monkeypatch.setattr(gp, 'nb_residuals', k)
        fits.append(gp.fit_ground_plane(u, v, d, weights=np.maximum(d, 0.0) ** 3,
                                        rng=np.random.default_rng(5)))
    assert fits[0] is not None and fits[1] is not None
    np.testing.assert_array_equal(fits[0].abc, fits[1].abc)
    np.testing.assert_array_equal(fits[0].inliers, fits[1].inliers)
