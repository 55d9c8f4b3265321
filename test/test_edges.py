"""Vertical edges and edge strings (core.edges) on synthetic step images."""
import numpy as np
import pytest

from asmonc_vision.core.edges import (DENSITY_ROWS, EdgeMap, detect_vertical_edges,
                                      gradient_noise_gain, horizontal_gradient,
                                      image_noise_sigma, textured_edge_threshold)


def _step_image(h, w, x0, lo=50.0, hi=150.0, slope=0.0):
    """Area-sampled step: pixel u covers [u-0.5, u+0.5]; bright for x > x0 + slope*v."""
    u = np.arange(w, dtype=np.float64)[None, :]
    v = np.arange(h, dtype=np.float64)[:, None]
    edge = x0 + slope * v
    frac = np.clip(u + 0.5 - edge, 0.0, 1.0)
    return (lo + (hi - lo) * frac).astype(np.float32)


@pytest.mark.parametrize('x0', [40.0, 40.25, 40.5, 40.8, 41.1])
def test_subpixel_position_of_a_step(x0):
    e = detect_vertical_edges(_step_image(30, 80, x0))
    assert len(e) == 28                       # one edge per interior row, nothing else
    np.testing.assert_allclose(e.u, x0, atol=0.02)
    assert np.all(e.polarity == 1)
    np.testing.assert_allclose(e.orientation, 0.0, atol=1e-3)


def test_subpixel_position_of_a_blurred_noisy_step():
    import cv2
    rng = np.random.default_rng(3)
    img = cv2.GaussianBlur(_step_image(60, 80, 40.3), (0, 0), 1.0)
    img = img + rng.normal(0.0, 1.0, img.shape).astype(np.float32)
    e = detect_vertical_edges(img)
    rows = e.v[np.abs(e.u - 40.3) < 1.0]
    assert rows.size == 58
    assert np.median(np.abs(e.u[np.abs(e.u - 40.3) < 1.0] - 40.3)) < 0.1


def test_polarity_and_orientation_of_a_falling_step():
    e = detect_vertical_edges(_step_image(20, 60, 30.4, lo=200.0, hi=20.0))
    assert len(e) == 18
    assert np.all(e.polarity == -1)
    np.testing.assert_allclose(np.abs(e.orientation), np.pi, atol=1e-3)
    np.testing.assert_allclose(e.u, 30.4, atol=0.02)
    assert e.strength.dtype == np.float32 and np.all(e.strength > 30)


def test_nms_thin_line_gives_two_edges_of_opposite_polarity():
    img = np.full((12, 40), 100.0, np.float32)
    img[:, 20] = 200.0                         # a one-pixel bright line
    e = detect_vertical_edges(img)
    per_row = np.bincount(e.v, minlength=12)
    assert np.all(per_row[1:-1] == 2) and per_row[0] == 0 and per_row[-1] == 0
    left = e.polarity == 1
    np.testing.assert_allclose(e.u[left], 19.0, atol=1e-6)
    np.testing.assert_allclose(e.u[~left], 21.0, atol=1e-6)
    assert e.num_strings == 2                  # one string per polarity


def test_sorted_by_row_then_column():
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 255, (40, 50)).astype(np.float32)
    e = detect_vertical_edges(img, abs_threshold=5.0)
    key = e.v.astype(np.int64) * 1000 + e.u_int
    assert np.all(np.diff(key) > 0)
    assert np.all(np.abs(e.u - e.u_int) <= 0.5)
    assert e.v.dtype == np.int32 and e.u.dtype == np.float32 and e.polarity.dtype == np.int8


def test_thresholds_absolute_and_relative():
    img = _step_image(20, 60, 20.2, lo=100.0, hi=110.0) + _step_image(20, 60, 40.6, 0.0, 100.0)
    weak_strong = detect_vertical_edges(img, abs_threshold=2.0)
    assert set(np.round(weak_strong.u).astype(int)) == {20, 41}
    only_strong = detect_vertical_edges(img, abs_threshold=20.0)
    assert set(np.round(only_strong.u).astype(int)) == {41}
    # Relative to the image contrast (mean |dI/du|): the weak edge goes.
    rel = detect_vertical_edges(img, abs_threshold=0.0, rel_threshold=5.0)
    assert set(np.round(rel.u).astype(int)) == {41}
    assert rel.threshold > 2.0


def test_horizontal_edges_are_rejected_by_angle():
    img = np.full((30, 30), 50.0, np.float32)
    img[15:, :] = 200.0                        # horizontal edge
    assert len(detect_vertical_edges(img)) == 0
    gx, gy = horizontal_gradient(img)
    assert np.abs(gx).max() < 1e-3 and np.abs(gy).max() > 10


def test_strings_vertical_and_slanted():
    img = _step_image(50, 100, 30.3) + _step_image(50, 100, 60.0, 0.0, 80.0, slope=0.6)
    e = detect_vertical_edges(img)
    assert e.num_strings == 2
    np.testing.assert_array_equal(np.sort(e.string_length), [48, 48])
    for s in range(2):
        rows = e.v[e.string_id == s]
        np.testing.assert_array_equal(rows, np.arange(1, 49))
    # The slanted edge is found at its sub-pixel position on every row.
    slanted = e.string_id == e.string_id[np.argmax(e.u)]
    np.testing.assert_allclose(e.u[slanted], 60.0 + 0.6 * e.v[slanted], atol=0.1)
    # string_prev links each pixel to the one above in its string.
    prev = e.string_prev
    has = prev >= 0
    assert has.sum() == len(e) - 2
    assert np.all(e.v[prev[has]] == e.v[has] - 1)
    assert np.all(e.string_id[prev[has]] == e.string_id[has])
    assert np.all(np.abs(e.u_int[prev[has]] - e.u_int[has]) <= 1)


def test_strings_break_at_gaps_and_min_length_drops_short_ones():
    img = _step_image(40, 60, 30.0)
    img[20:23, :] = 100.0                      # interrupt the edge for three rows
    img[:, 45:] = 100.0
    img[5:8, 45:] = 100.0 + 60.0 * (np.arange(15) >= 5)[None, :]   # a 3-row stub at u=50
    e = detect_vertical_edges(img, abs_threshold=5.0)
    long_ = e.string_length[e.string_id]
    assert e.num_strings >= 3
    e3 = detect_vertical_edges(img, abs_threshold=5.0, min_string_length=6)
    assert np.all(e3.string_length >= 6)
    assert not np.any(np.abs(e3.u - 50) < 1.0)             # the stub has gone
    assert len(e3) == int((long_ >= 6).sum())
    np.testing.assert_array_equal(np.unique(e3.string_id), np.arange(e3.num_strings))
    ok = e3.string_prev >= 0
    assert np.all(e3.string_id[e3.string_prev[ok]] == e3.string_id[ok])


def test_blank_and_tiny_images_give_no_edges():
    assert len(detect_vertical_edges(np.zeros((50, 60), np.uint8))) == 0
    e = detect_vertical_edges(np.zeros((2, 2), np.uint8))
    assert isinstance(e, EdgeMap) and len(e) == 0 and e.num_strings == 0
    with pytest.raises(ValueError):
        detect_vertical_edges(np.zeros((4, 4, 3), np.uint8))


@pytest.mark.parametrize('kw', [dict(), dict(abs_threshold=4.1, max_angle_deg=70.0,
                                             min_string_length=3),
                                dict(abs_threshold=0.0, rel_threshold=1.3),
                                dict(abs_threshold=3.3, rel_threshold=0.7, min_string_length=5)])
def test_uint8_integer_path_equals_the_float_path(kw):
    """A uint8 image (integer Sobel sums) gives exactly the edges of its float copy."""
    rng = np.random.default_rng(7)
    img = _step_image(60, 90, 40.3) + _step_image(60, 90, 60.0, 0.0, 80.0, slope=0.4)
    img = np.clip(img + rng.normal(0.0, 6.0, img.shape), 0, 255).astype(np.uint8)
    a = detect_vertical_edges(img, **kw)
    b = detect_vertical_edges(img.astype(np.float32), **kw)
    assert len(a) > 50 and a.threshold == b.threshold and a.shape == b.shape
    for name in ('v', 'u_int', 'u', 'strength', 'polarity', 'orientation', 'string_id',
                 'string_prev', 'string_length', 'curvature'):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize('kw', [dict(), dict(abs_threshold=4.0, max_angle_deg=70.0,
                                             min_string_length=3),
                                dict(abs_threshold=1.0, max_angle_deg=90.0),
                                dict(abs_threshold=3.3, rel_threshold=0.7, min_string_length=5)])
def test_compiled_edges_equal_the_numpy_path(monkeypatch, kw):
    """The uint8 path's compiled kernel (numba, optional) gives bit-identical edges,
    strings and parents to the numpy path: on a noisy scene of straight and slanted
    steps, on a non-contiguous view, and on a blank image."""
    from asmonc_vision.core import edges as E
    if not E.warm_up():
        pytest.skip('numba not installed')
    rng = np.random.default_rng(11)
    img = (_step_image(80, 120, 30.3) + _step_image(80, 120, 70.0, 0.0, 90.0, slope=0.6)
           + _step_image(80, 120, 95.5, 0.0, -60.0, slope=-1.3))
    img = np.clip(img + rng.normal(0.0, 8.0, img.shape), 0, 255).astype(np.uint8)
    images = [img, rng.integers(0, 256, (60, 90), dtype=np.uint8),
              np.asarray(img[::2, 1::2]), np.zeros((20, 30), np.uint8)]
    fast = [E.detect_vertical_edges(i, **kw) for i in images]
    monkeypatch.setattr(E, '_nb_edges', None)
    slow = [E.detect_vertical_edges(i, **kw) for i in images]
    assert len(slow[0]) > 100 and slow[0].num_strings > 5 and len(slow[3]) == 0
    for a, b in zip(fast, slow):
        assert a.threshold == b.threshold and a.shape == b.shape
        for name in ('v', 'u_int', 'u', 'strength', 'polarity', 'orientation', 'string_id',
                     'string_prev', 'string_length', 'curvature'):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype, name
            np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize('sigma', [1.0, 2.0, 5.0])
def test_image_noise_sigma_measures_the_noise_not_the_scene(sigma):
    rng = np.random.default_rng(11)
    h, w = 240, 320
    flat = np.full((h, w), 120.0)
    # a scene with structure: tiles of different shades (edges), a ramp, a dark slab
    yy, xx = np.mgrid[0:h, 0:w]
    scene = 60.0 + 40.0 * (((yy // 30) + (xx // 40)) % 3) + 0.2 * xx
    scene[150:200, 100:180] = 20.0
    for base in (flat, scene):
        img = base + rng.normal(0.0, sigma, base.shape)
        as_u8 = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        assert image_noise_sigma(img) == pytest.approx(sigma, rel=0.08)
        assert image_noise_sigma(as_u8) == pytest.approx(sigma, rel=0.08)
    clean = np.clip(np.rint(scene), 0, 255).astype(np.uint8)
    assert image_noise_sigma(clean) < 0.3
    with pytest.raises(ValueError, match='at least 3 x 3'):
        image_noise_sigma(np.zeros((2, 10)))


@pytest.mark.parametrize('blur', [0.0, 0.7, 1.5])
def test_gradient_noise_gain_is_the_deviation_of_the_gradient_of_unit_noise(blur):
    noise = np.random.default_rng(5).normal(0.0, 1.0, (300, 300)).astype(np.float32)
    gx, _ = horizontal_gradient(noise, blur)
    assert float(gx[20:-20, 20:-20].std()) == pytest.approx(gradient_noise_gain(blur), rel=0.03)


def _lower_half_density(img, thr):
    """Edge candidates (row maxima of |dI/du| >= thr, before the angle test) in the
    image's lower half, counted with detect_vertical_edges, per row of a 320 x 240 image
    (over DENSITY_ROWS)."""
    h, w = img.shape
    e = detect_vertical_edges(img, abs_threshold=thr, max_angle_deg=90.0)
    return np.count_nonzero(e.v >= h // 2) / DENSITY_ROWS


def test_textured_edge_threshold_lowers_only_where_the_ground_shows_few_edges():
    """Tiles with clear joints keep the usual threshold; a weak smooth texture (asphalt-like:
    gradients of 1-3 grey levels per pixel), too few edges at it, gets the threshold that
    gives the target density of edge candidates in the lower half, never below the floor."""
    rng = np.random.default_rng(3)
    h, w = 240, 320
    yy, xx = np.mgrid[0:h, 0:w]
    tiles = 100.0 + 60.0 * (((xx // 12) + (yy // 20)) % 2)
    tiled = np.clip(np.rint(tiles + rng.normal(0, 2.0, (h, w))), 0, 255).astype(np.uint8)
    assert _lower_half_density(tiled, 4.0) >= 8.0
    assert textured_edge_threshold(tiled, 4.0, min_density=8.0, target_density=24.0,
                                   floor=2.0) == 4.0

    import cv2
    blobs = cv2.GaussianBlur(rng.normal(0.0, 1.0, (h, w)).astype(np.float32), (0, 0), 3.0)
    weak = 120.0 + 6.0 * blobs / blobs.std()
    weak_u8 = np.clip(np.rint(weak + rng.normal(0, 1.0, (h, w))), 0, 255).astype(np.uint8)
    assert _lower_half_density(weak_u8, 4.0) < 8.0
    kw = dict(min_density=8.0, target_density=24.0)
    t = textured_edge_threshold(weak_u8, 4.0, floor=0.5, **kw)
    assert 0.5 < t < 4.0
    # the threshold returned keeps (about) the target density, a higher one would not
    assert _lower_half_density(weak_u8, t) >= 24.0
    assert _lower_half_density(weak_u8, t + 0.2) < 24.0
    # the floor bounds it; 0 density or a floor above the threshold leaves it alone
    assert textured_edge_threshold(weak_u8, 4.0, floor=2.5, **kw) == 2.5
    assert textured_edge_threshold(weak_u8, 4.0, min_density=0.0, target_density=24.0,
                                   floor=0.5) == 4.0
    assert textured_edge_threshold(weak_u8, 4.0, floor=5.0, **kw) == 4.0
    # float images take the float path to the same threshold
    assert textured_edge_threshold(weak_u8.astype(np.float32), 4.0, floor=0.5,
                                   **kw) == pytest.approx(t)
    # the counts do not scale with the image: 640 x 480 tiles seen from the same rig
    # (twice the pixels per tile) have half the edges per 320 px of a row, but as many
    # in all as the 320 x 240 image needs
    yy2, xx2 = np.mgrid[0:2 * h, 0:2 * w]
    big_tiles = 100.0 + 60.0 * (((xx2 // 48) + (yy2 // 40)) % 2)
    big = np.clip(np.rint(big_tiles + rng.normal(0, 2.0, (2 * h, 2 * w))), 0, 255
                  ).astype(np.uint8)
    per_320 = _lower_half_density(big, 4.0) * DENSITY_ROWS / (h * 2.0)
    assert per_320 < 8.0 <= _lower_half_density(big, 4.0)
    assert textured_edge_threshold(big, 4.0, floor=0.5, **kw) == 4.0
    with pytest.raises(ValueError, match='first_row_fraction'):
        textured_edge_threshold(weak_u8, 4.0, floor=0.5, first_row_fraction=1.0, **kw)
    with pytest.raises(ValueError, match='target_density'):
        textured_edge_threshold(weak_u8, 4.0, min_density=8.0, target_density=4.0, floor=0.5)


def test_compiled_textured_edge_threshold_equals_the_numpy_path(monkeypatch):
    """The compiled count of candidates (numba, optional) gives the thresholds the numpy
    path gives: lowered to a candidate's strength, to the floor, or left."""
    import cv2
    from asmonc_vision.core import edges as E
    if not E.warm_up():
        pytest.skip('numba not installed')
    rng = np.random.default_rng(4)
    blobs = cv2.GaussianBlur(rng.normal(0.0, 1.0, (240, 320)).astype(np.float32), (0, 0), 3.0)
    weak = np.clip(np.rint(120.0 + 6.0 * blobs / blobs.std()
                           + rng.normal(0, 1.0, (240, 320))), 0, 255).astype(np.uint8)
    cases = [(weak, 0.5), (weak, 2.6), (np.asarray(weak[::2, 1::2]), 0.5),
             (rng.integers(0, 256, (240, 320), dtype=np.uint8), 0.5),
             (np.zeros((20, 30), np.uint8), 0.5)]
    kw = dict(min_density=8.0, target_density=24.0)
    fast = [E.textured_edge_threshold(i, 4.0, floor=f, **kw) for i, f in cases]
    monkeypatch.setattr(E, '_nb_peak_count', None)
    slow = [E.textured_edge_threshold(i, 4.0, floor=f, **kw) for i, f in cases]
    assert fast == slow
    assert 0.5 < slow[0] < 4.0 and slow[1] == 2.6 and slow[3] == 4.0 and slow[4] == 0.5
