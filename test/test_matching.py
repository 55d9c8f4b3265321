"""Row-wise PMF edge matching (core.matching) on synthetic warped texture pairs."""
import cv2
import numpy as np
import pytest

from asmonc_vision.core.edges import detect_vertical_edges
from asmonc_vision.core.matching import (Candidates, candidate_matches,
                                         disparity_gradient_interval, match_edges,
                                         match_rivals, pmf_match, pmf_support, select_matches,
                                         support_links)


def _texture(rng, h, w, blur=1.5, contrast=40.0):
    t = rng.normal(0.0, 1.0, (h, w)).astype(np.float32)
    t = cv2.GaussianBlur(t, (0, 0), blur)
    return 128.0 + t / t.std() * contrast


def _warped_pair(abc, h=240, w=320, seed=0, noise=1.0, blur=1.5):
    """Left = texture; right sampled so that the disparity is ``d = a*u + b*v + c`` in
    cyclopean coordinates (u = (uL + uR)/2): d = (a*uR + b*v + c) / (1 - a/2)."""
    rng = np.random.default_rng(seed)
    a, b, c = abc
    tex = _texture(rng, h, w + 140, blur)
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    d_right = (a * uu + b * vv + c) / (1.0 - a / 2.0)
    right = cv2.remap(tex, (uu + d_right).astype(np.float32), vv, cv2.INTER_CUBIC)
    left = tex[:, :w]
    left = left + rng.normal(0.0, noise, left.shape)
    right = right + rng.normal(0.0, noise, right.shape)
    return (np.clip(left, 0, 255).astype(np.uint8), np.clip(right, 0, 255).astype(np.uint8))


@pytest.fixture(scope='module')
def plane_pair():
    abc = (0.01, 0.12, 2.0)                   # disparity 2 .. 33 px across the image
    left, right = _warped_pair(abc)
    el = detect_vertical_edges(left, min_string_length=3)
    er = detect_vertical_edges(right, min_string_length=3)
    return abc, el, er


@pytest.mark.parametrize('radius, max_wrong', [(3.0, 0.03), (5.0, 0.01)])
def test_recovers_a_ground_plane_disparity_field(plane_pair, radius, max_wrong):
    abc, el, er = plane_pair
    m = match_edges(el, er, 0.5, 80.0, support_radius=radius, iterations=3, min_support=0.5)
    err = m.d - (abc[0] * m.u + abc[1] * m.v + abc[2])
    assert len(m) > 0.7 * len(el)                      # most edges matched
    assert np.mean(np.abs(err) < 0.2) > 0.85           # sub-pixel accurate
    assert np.median(np.abs(err)) < 0.08
    # Few wrong matches on this dense random texture; fewer with a larger PMF
    # neighbourhood (more neighbours to disambiguate).
    assert np.mean(np.abs(err) > 1.0) < max_wrong
    # Dtypes and shapes of the output.
    for name in ('u_left', 'u_right', 'd', 'strength', 'support'):
        assert getattr(m, name).dtype == np.float32 and getattr(m, name).shape == (len(m),)
    for name in ('v', 'string_id', 'left_index', 'right_index'):
        assert getattr(m, name).dtype == np.int32
    np.testing.assert_allclose(m.d, m.u_left - m.u_right, atol=1e-4)
    np.testing.assert_array_equal(m.string_id, el.string_id[m.left_index])


def test_uniqueness_in_both_images(plane_pair):
    _, el, er = plane_pair
    m = match_edges(el, er, 0.5, 80.0)
    assert np.unique(m.left_index).size == len(m)
    assert np.unique(m.right_index).size == len(m)
    np.testing.assert_array_equal(el.v[m.left_index], er.v[m.right_index])


def test_disparity_range_is_respected(plane_pair):
    _, el, er = plane_pair
    m = match_edges(el, er, 10.0, 20.0)
    assert len(m) > 0
    assert m.d.min() >= 10.0 - 1e-4 and m.d.max() <= 20.0 + 1e-4


def test_constant_shift_with_gain_difference():
    rng = np.random.default_rng(5)
    tex = _texture(rng, 120, 260)
    shift = 17.35
    uu, vv = np.meshgrid(np.arange(200, dtype=np.float32), np.arange(120, dtype=np.float32))
    left = tex[:, :200]
    right = cv2.remap(tex, uu + shift, vv, cv2.INTER_CUBIC) * 1.05 + 4.0   # gain, offset
    left = np.clip(left + rng.normal(0, 2.0, left.shape), 0, 255).astype(np.uint8)
    right = np.clip(right + rng.normal(0, 2.0, right.shape), 0, 255).astype(np.uint8)
    el = detect_vertical_edges(left, min_string_length=3)
    er = detect_vertical_edges(right, min_string_length=3)
    m = match_edges(el, er, 1.0, 60.0)
    assert len(m) > 0.6 * len(el)
    assert np.median(np.abs(m.d - shift)) < 0.1        # sub-pixel disparities
    assert abs(np.median(m.d - shift)) < 0.03          # unbiased
    assert np.mean(np.abs(m.d - shift) > 1.0) < 0.03



@pytest.mark.parametrize('gain', [1.6, 0.6])
def test_a_right_camera_with_its_own_gain_is_compared_on_the_lefts_scale(gain):
    """The strength test with the right camera's gain: the raw strengths of a true match
    differ by the gain, so at 1.6 or 0.6 (with ratio 0.7) the raw test rejects many
    true matches (about 40 % here); told the gain, it keeps them, and what it keeps obeys
    the test on the left's scale. The matches' strengths stay the edges' own."""
    rng = np.random.default_rng(7)
    tex = _texture(rng, 120, 260)
    shift = 12.4
    uu, vv = np.meshgrid(np.arange(200, dtype=np.float32), np.arange(120, dtype=np.float32))
    left = np.clip(tex[:, :200] + rng.normal(0, 1.0, (120, 200)), 0, 255).astype(np.uint8)
    right = cv2.remap(tex, uu + shift, vv, cv2.INTER_CUBIC) * gain + 30.0 * (1 - gain)
    right = np.clip(right + rng.normal(0, 1.0, right.shape), 0, 255).astype(np.uint8)
    el = detect_vertical_edges(left, min_string_length=3)
    er = detect_vertical_edges(right, min_string_length=3)
    true = {}
    for told in (1.0, 1.0 / gain):
        c = candidate_matches(el, er, 1.0, 40.0, min_strength_ratio=0.7, right_gain=told)
        s1, s2 = el.strength[c.left], er.strength[c.right] * np.float32(told)
        assert np.all(np.minimum(s1, s2) >= 0.7 * np.maximum(s1, s2) - 1e-4)
        true[told] = int(np.sum(np.abs(c.d - shift) < 0.5))
    assert true[1.0 / gain] > 1.4 * true[1.0], true
    m = pmf_match(el, er, 1.0, 40.0, right_gain=1.0 / gain)[0]
    np.testing.assert_allclose(
        m.strength, 0.5 * (el.strength[m.left_index] + er.strength[m.right_index]), rtol=1e-6)
    with pytest.raises(ValueError, match='right_gain'):
        candidate_matches(el, er, 1.0, 40.0, right_gain=0.0)

def test_candidates_obey_polarity_strength_and_range(plane_pair):
    _, el, er = plane_pair
    c = candidate_matches(el, er, 5.0, 40.0, min_strength_ratio=0.6, max_orientation_diff_deg=25.0)
    assert len(c) > 0
    np.testing.assert_array_equal(el.polarity[c.left], er.polarity[c.right])
    np.testing.assert_array_equal(el.v[c.left], er.v[c.right])
    assert np.all((c.d >= 5.0) & (c.d <= 40.0))
    s1, s2 = el.strength[c.left], er.strength[c.right]
    assert np.all(np.minimum(s1, s2) >= 0.6 * np.maximum(s1, s2) - 1e-6)
    dori = np.abs(el.orientation[c.left] - er.orientation[c.right])
    assert np.all(np.minimum(dori, 2 * np.pi - dori) <= np.deg2rad(25.0) + 1e-6)
    assert np.all(np.diff(c.left) >= 0)


def test_disparity_gradient_interval_matches_brute_force():
    rng = np.random.default_rng(1)
    du = rng.uniform(-5, 5, 200)
    dv = rng.integers(-5, 6, 200).astype(float)
    for limit in (0.5, 1.0, 1.5):
        lo, hi = disparity_gradient_interval(du, dv, limit)
        x = np.linspace(-40, 40, 16001)[None, :]
        sep = np.hypot(du[:, None] - x / 2.0, dv[:, None])
        ok = np.abs(x) <= limit * sep
        ok_lo = np.where(ok.any(1), x[0, np.argmax(ok, 1)], np.nan)
        ok_hi = np.where(ok.any(1), x[0, ok.shape[1] - 1 - np.argmax(ok[:, ::-1], 1)], np.nan)
        np.testing.assert_allclose(lo, ok_lo, atol=0.01)
        np.testing.assert_allclose(hi, ok_hi, atol=0.01)


def _brute_force_support(el, er, c, radius, limit, alive=None):
    """PMF support straight from its definition (Pollard, Mayhew & Frisby 1985): for each
    candidate, the sum over the other left edges of the largest 1 / (cyclopean
    distance) among their (alive) candidates within the radius in the cyclopean image
    that satisfy the disparity-gradient limit with it."""
    uc = 0.5 * (el.u[c.left].astype(float) + er.u[c.right])
    vc = el.v[c.left].astype(float)
    alive = np.ones(len(c), bool) if alive is None else alive
    out = np.zeros(len(c))
    for i in range(len(c)):
        sep = np.hypot(uc - uc[i], vc - vc[i])
        ok = (alive & (c.left != c.left[i]) & (sep <= radius) & (sep > 0)
              & (np.abs(c.d - c.d[i]) <= limit * sep))
        best = {}
        for j in np.flatnonzero(ok):
            best[c.left[j]] = max(best.get(c.left[j], 0.0), 1.0 / sep[j])
        out[i] = sum(best.values())
    return out


@pytest.mark.parametrize('radius, limit', [(3.0, 1.0), (4.5, 0.5), (2.0, 1.5)])
def test_support_is_pmf_as_published(radius, limit):
    """Cyclopean neighbourhood, disparity-gradient limit, 1/distance, and each
    neighbouring edge counting only its best compatible match, against brute force."""
    rng = np.random.default_rng(3)
    left, right = _warped_pair((0.02, 0.1, 5.0), h=40, w=90, seed=4)
    el = detect_vertical_edges(left, min_string_length=2)
    er = detect_vertical_edges(right, min_string_length=2)
    c = candidate_matches(el, er, 0.5, 40.0, min_strength_ratio=0.2,
                          max_orientation_diff_deg=60.0)
    assert len(c) > 200 and np.bincount(c.left).max() >= 3      # real ambiguity
    links = support_links(el, er, c, 0.5, 40.0, support_radius=radius,
                          disparity_gradient_limit=limit)
    np.testing.assert_allclose(pmf_support(links),
                               _brute_force_support(el, er, c, radius, limit), atol=1e-6)
    # After accepting some matches: competitors of accepted ones no longer support.
    acc = rng.random(len(c)) < 0.1
    acc &= ~np.r_[False, c.left[1:] == c.left[:-1]]             # one per left edge
    _, first = np.unique(c.right[acc], return_index=True)       # and per right edge
    acc[np.flatnonzero(acc)[np.setdiff1d(np.arange(acc.sum()), first)]] = False
    taken = np.zeros(len(er), bool)
    taken[c.right[acc]] = True
    left_match = np.full(len(el), -1)
    left_match[c.left[acc]] = c.right[acc]
    alive = acc | ~((left_match[c.left] >= 0) | taken[c.right])
    np.testing.assert_allclose(pmf_support(links, taken, left_match),
                               _brute_force_support(el, er, c, radius, limit, alive),
                               atol=1e-6)


def test_support_with_candidates_in_any_order_of_right_edge():
    """The links are right when the disparities of a left edge's candidates are not
    monotonic (candidates not sorted by right edge): every sibling may share a link."""
    left, right = _warped_pair((0.02, 0.1, 5.0), h=40, w=90, seed=4)
    el = detect_vertical_edges(left, min_string_length=2)
    er = detect_vertical_edges(right, min_string_length=2)
    c = candidate_matches(el, er, 0.5, 40.0, min_strength_ratio=0.2,
                          max_orientation_diff_deg=60.0)
    rng = np.random.default_rng(2)
    o = np.lexsort((rng.random(len(c)), c.left))          # shuffled within each left edge
    c2 = Candidates(c.left[o], c.right[o], c.d[o])
    links = support_links(el, er, c2, 0.5, 40.0, support_radius=3.0)
    assert links.num_single < len(links)                   # some links are grouped
    np.testing.assert_allclose(pmf_support(links),
                               _brute_force_support(el, er, c2, 3.0, 1.0), atol=1e-6)
    acc, _ = select_matches(c2, links, el, er, iterations=2)
    acc0, _ = select_matches(c, support_links(el, er, c, 0.5, 40.0), el, er, iterations=2)
    np.testing.assert_array_equal(np.sort(c2.left[acc] * 10000 + c2.right[acc]),
                                  np.sort(c.left[acc0] * 10000 + c.right[acc0]))


def test_pmf_match_returns_the_candidates_and_their_support(plane_pair):
    _, el, er = plane_pair
    m, cand, support = pmf_match(el, er, 0.5, 80.0, iterations=2)
    assert support.shape == (len(cand),) and cand.left.dtype == np.intp
    assert np.all(np.diff(cand.left) >= 0)
    key = cand.left * 100000 + cand.right
    assert np.all(np.diff(key) > 0)                          # sorted by (left, right)
    np.testing.assert_array_equal(m.d, (el.u[m.left_index] - er.u[m.right_index])
                                  .astype(np.float32))


def test_support_prefers_true_matches(plane_pair):
    abc, el, er = plane_pair
    c = candidate_matches(el, er, 0.5, 80.0)
    links = support_links(el, er, c, 0.5, 80.0, support_radius=3.0)
    s = pmf_support(links)
    uc = el.u[c.left] - c.d / 2.0
    true = np.abs(c.d - (abc[0] * uc + abc[1] * el.v[c.left] + abc[2])) < 0.5
    assert np.median(s[true]) > 2.0 * max(np.median(s[~true]), 0.1)


def test_empty_inputs():
    blank = detect_vertical_edges(np.zeros((40, 50), np.uint8))
    m = match_edges(blank, blank, 1.0, 30.0)
    assert len(m) == 0 and m.d.dtype == np.float32
    rng = np.random.default_rng(0)
    tex = detect_vertical_edges(_texture(rng, 40, 50))
    assert len(match_edges(tex, blank, 1.0, 30.0)) == 0
    assert len(match_edges(blank, tex, 1.0, 30.0)) == 0
    with pytest.raises(ValueError):
        support_links(tex, tex, candidate_matches(tex, tex, 0.0, 5.0), 0.0, 5.0,
                      disparity_gradient_limit=2.5)


@pytest.mark.parametrize('shuffle', [False, True])
def test_numba_kernels_equal_the_numpy_path(plane_pair, monkeypatch, shuffle):
    """The JIT-compiled loops (numba, optional) give bit-identical links, support and
    selection to the numpy path."""
    from asmonc_vision.core import matching as mt
    if not mt.warm_up():
        pytest.skip('numba not installed')
    _, el, er = plane_pair
    c = candidate_matches(el, er, 0.5, 80.0)
    if shuffle:                                   # non-monotonic siblings: grouped links
        o = np.lexsort((np.random.default_rng(1).random(len(c)), c.left))
        c = Candidates(c.left[o], c.right[o], c.d[o])
    fast_links = support_links(el, er, c, 0.5, 80.0, support_radius=3.0)
    fast = select_matches(c, fast_links, el, er, iterations=3)
    k = np.flatnonzero(fast[0])
    first = pmf_support(fast_links)
    fast_rivals = match_rivals(c, first, k)
    for name in ('nb_pairs', 'nb_group', 'nb_select', 'nb_rivals'):
        monkeypatch.setattr(mt.kernels, name, None)
    rivals = match_rivals(c, first, k)
    assert len(rivals[0]) > 0
    for a, b in zip(fast_rivals, rivals):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    links = support_links(el, er, c, 0.5, 80.0, support_radius=3.0)
    for f in ('cand', 'start', 'pair_link', 'pair_cand', 'pair_edge', 'pair_right', 'weight'):
        np.testing.assert_array_equal(getattr(fast_links, f), getattr(links, f))
    assert fast_links.num_single == links.num_single
    slow = select_matches(c, links, el, er, iterations=3)
    np.testing.assert_array_equal(fast[0], slow[0])
    np.testing.assert_array_equal(fast[1], slow[1])


def test_the_candidates_sort_is_numpys_argsort():
    """`support._argsort` gives np.argsort's permutation: distinct keys nearly in order
    (as a frame's candidates), and keys with ties, -0.0 and 0.0, or NaN."""
    from asmonc_vision.core.matching.support import _argsort
    rng = np.random.default_rng(2)
    cases = []
    for n in (0, 1, 2, 9, 1000, 20000):
        k = np.sort(rng.uniform(0.0, 1e5, n)) + rng.normal(0.0, 30.0, n)
        cases.append(k)
        if n >= 2:
            tie = k.copy()
            tie[rng.integers(0, n, max(n // 10, 1))] = k[0]
            zeros = k.copy()
            zeros[:2] = (-0.0, 0.0)
            nan = k.copy()
            nan[n // 2] = np.nan
            cases += [tie, zeros, nan, np.round(k)]
    for k in cases:
        assert _argsort(k).tobytes() == np.argsort(k).tobytes()
