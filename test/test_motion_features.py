"""core.motion.features: corner localisation, NCC windows, stereo and temporal matching."""
import cv2
import numpy as np
import pytest

from asmonc_vision.eval.motion_experiment import (CORNER_KINDS, corner_localisation,
                                                  render_corner)
from asmonc_vision.core.motion.features import (corner_strength, detect_corners, match_stereo,
                                                match_temporal, patches, shi_tomasi_corners,
                                                subpix_refine, wang_brady_corners)


def _texture(seed=0, h=120, w=200):
    """A mosaic of random grey quadrilaterals (corners like the pavement's tiles),
    area-sampled 4x and blurred by 0.5 px as the simulator's camera; float32."""
    rng = np.random.default_rng(seed)
    s = 4
    big = np.full((h * s, w * s), 128, np.uint8)
    for _ in range(70):
        c = rng.uniform([0, 0], [w * s, h * s])
        quad = c + rng.uniform(-12 * s, 12 * s, size=(4, 2))
        cv2.fillPoly(big, [quad.astype(np.int32)], int(rng.integers(40, 220)))
    img = cv2.resize(big.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(img, (0, 0), 0.5)


def _shift(img, du, dv=0.0):
    m = np.float32([[1, 0, du], [0, 1, dv]])
    return cv2.warpAffine(img, m, (img.shape[1], img.shape[0]), flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REFLECT)


@pytest.mark.parametrize('kind', CORNER_KINDS)
@pytest.mark.slow
def test_subpixel_corners_are_accurate(kind):
    """Shi-Tomasi + the cornerSubPix condition: the measured localisation (docs/motion.md)."""
    r = corner_localisation('shi_tomasi', kind, trials=60)
    assert r['detected'] >= 0.95
    assert r['median'] < 0.3 and r['bias'] < 0.05
    # it beats integer positions and the paper's Wang-Brady detector
    assert r['mean'] < 0.5 * corner_localisation('shi_tomasi_integer', kind, trials=60)['mean']
    assert r['mean'] < corner_localisation('wang_brady', kind, trials=60)['mean']


def test_vectorised_subpix_matches_opencv_corner_subpix():
    errs_ours, errs_cv = [], []
    for i in range(40):
        img, truth = render_corner('X_step', [5, i])
        start = np.rint(truth[:1]) + [[0.7, -0.6]]
        ours = subpix_refine(img, start, 5)
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
        cvp = cv2.cornerSubPix(img, start.astype(np.float32).reshape(-1, 1, 2), (5, 5), (-1, -1),
                               crit).reshape(-1, 2)
        errs_ours.append(np.hypot(*(ours[0] - truth[0])))
        errs_cv.append(np.hypot(*(cvp[0] - truth[0])))
    assert np.mean(errs_ours) < 0.1 and np.mean(errs_ours) < 1.3 * np.mean(errs_cv)


def test_compiled_subpix_agrees_with_the_numpy_path(monkeypatch):
    """The numba kernel (double-precision sums) and the numpy path (single precision) give
    the same corners, strengths and refusals on a textured image, corners started off
    by up to a pixel, some near the border and one on blank ground."""
    from asmonc_vision.core.motion import features
    if features._nb_subpix is None:
        pytest.skip('numba not installed: only the numpy path exists')
    img = _texture(3)
    img[:, 150:] = 100.0                                      # blank: refused
    rng = np.random.default_rng(1)
    pts = shi_tomasi_corners(img, max_corners=200, subpix_half_window=0).astype(float)
    pts = np.vstack([pts + rng.uniform(-1, 1, pts.shape), [[175.0, 60.0], [7.0, 7.0]]])
    fast = subpix_refine(img, pts, 5, return_strength=True, return_ok=True)
    monkeypatch.setattr(features, '_NUMPY_ONLY', [True])
    slow = subpix_refine(img, pts, 5, return_strength=True, return_ok=True)
    assert np.array_equal(fast[2], slow[2]) and not fast[2][-2]
    assert np.abs(fast[0] - slow[0]).max() < 1e-3
    assert np.allclose(fast[1], slow[1], rtol=1e-4, atol=1e-4)


@pytest.mark.slow
def test_wang_brady_finds_corners_and_its_correction_helps():
    img, truth = render_corner('L', [6, 0])
    pts = wang_brady_corners(img, max_corners=5, border=4)
    assert len(pts) >= 1
    corr = corner_localisation('wang_brady', 'L', trials=60)
    raw = corner_localisation('wang_brady_uncorrected', 'L', trials=60)
    assert corr['mean'] < 0.6 < raw['mean']


def test_dark_or_blank_images_give_no_corners():
    rng = np.random.default_rng(0)
    blank = np.full((120, 160), 90, np.uint8)
    assert len(detect_corners(blank, min_strength=1.5)) == 0
    noise = np.clip(90 + rng.normal(0, 2, (120, 160)), 0, 255).astype(np.uint8)
    assert len(detect_corners(noise, min_strength=1.5)) < 5
    assert len(detect_corners(noise, min_strength=0.0)) > 50     # noise "corners"
    tex = _texture().astype(np.uint8)
    c = detect_corners(tex, min_strength=1.5)
    assert len(c) > 50 and np.all(corner_strength(tex, c) >= 1.5 - 1e-6)


def test_ncc_windows_ignore_gain_and_offset():
    img = _texture()
    pts = np.array([[50.3, 40.7], [120.0, 60.2]])
    a, va = patches(img, pts)
    b, vb = patches(1.3 * img + 20, pts)
    assert va.all() and vb.all()
    assert np.allclose(np.sum(a * b, axis=1), 1.0, atol=1e-5)
    _, v = patches(img, np.array([[1.0, 1.0]]), half=4)
    assert not v[0]                                          # window leaves the image


def test_stereo_matching_on_rows_gives_subpixel_disparity():
    left = _texture(1)
    right = _shift(left, -7.35)                  # disparity 7.35 px everywhere
    lu = np.clip(left, 0, 255).astype(np.uint8)
    ru = np.clip(right, 0, 255).astype(np.uint8)
    pl = shi_tomasi_corners(lu, max_corners=200, min_strength=1.5)
    pr = shi_tomasi_corners(ru, max_corners=200, min_strength=1.5)
    dl, vl = patches(left, pl)
    dr, vr = patches(right, pr)
    pl, dl, pr, dr = pl[vl], dl[vl], pr[vr], dr[vr]
    idx = match_stereo(pl, dl, pr, dr, row_tol=1.0, min_disparity=1, max_disparity=40,
                       min_ncc=0.8)
    m = idx >= 0
    assert m.sum() > 0.5 * len(pl)
    d = pl[m, 0] - pr[idx[m], 0]
    assert np.median(np.abs(d - 7.35)) < 0.1
    assert np.all(np.abs(pl[m, 1] - pr[idx[m], 1]) <= 1.0)
    # nothing is matched outside the disparity range
    none = match_stereo(pl, dl, pr, dr, row_tol=1.0, min_disparity=10, max_disparity=40)
    assert np.all(none < 0) or np.mean(none >= 0) < 0.05


def test_temporal_matching_within_the_search_radius():
    prev = _texture(2)
    cur = _shift(prev, 12.0, -5.0)
    pu, cu = (np.clip(x, 0, 255).astype(np.uint8) for x in (prev, cur))
    pp = shi_tomasi_corners(pu, max_corners=150, min_strength=1.5)
    cp = shi_tomasi_corners(cu, max_corners=150, min_strength=1.5)
    dp, vp = patches(prev, pp)
    dc, vc = patches(cur, cp)
    pp, dp, cp, dc = pp[vp], dp[vp], cp[vc], dc[vc]
    near = match_temporal(dp, pp, cp, dc, radius=20.0)        # no prediction
    m = near >= 0
    assert m.sum() > 0.5 * len(pp)
    assert np.median(np.abs(cp[near[m]] - pp[m] - [12.0, -5.0])) < 0.1
    assert np.all(match_temporal(dp, pp, cp, dc, radius=5.0) < 0)    # out of reach
    # a prediction narrows the search to a few pixels
    pred = match_temporal(dp, pp + [11.0, -4.0], cp, dc, radius=3.0)
    assert (pred >= 0).sum() >= 0.9 * m.sum()
