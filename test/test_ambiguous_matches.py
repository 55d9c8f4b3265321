"""Ambiguous matches: each match's strongest rivals (core.matching.match_rivals) and
GPOD's rule that a match whose nearly as well supported rival lies on the ground is no
evidence of a drop-off (obstacle evidence is not judged by it)."""
import dataclasses

import cv2
import numpy as np
import pytest

from asmonc_vision.core.config import override
from asmonc_vision.core.edges import detect_vertical_edges
from asmonc_vision.core.gpod import GpodConfig, GpodDetector, rules
from asmonc_vision.core.matching import Candidates, Matches, match_rivals, pmf_match


def test_the_rivals_are_the_other_candidates_of_the_left_and_right_edge():
    # candidates: (left, right, d); 0 is a match; 1, 2 share its left edge, 4 its
    # right edge; 3 shares neither
    cand = Candidates(left=np.array([0, 0, 0, 1, 2]), right=np.array([5, 3, 7, 3, 5]),
                      d=np.array([10.0, 12.0, 7.0, 4.0, 8.5]))
    support = np.array([2.0, 1.0, 1.5, 9.0, 1.8])
    match, d, ratio = match_rivals(cand, support, np.array([3, 0]))
    assert match.dtype == np.int32 and d.dtype == np.float32 and ratio.dtype == np.float32
    # match 0 (candidate 3): alone on its left edge; its right edge's other candidate, 1
    # match 1 (candidate 0): candidates 1 and 2 (its left edge) and 4 (its right edge)
    np.testing.assert_array_equal(match, [0, 1, 1, 1])
    got = sorted(zip(match.tolist(), d.tolist(), ratio.tolist()))
    np.testing.assert_allclose(got, [(0, 12.0, 1.0 / 9.0), (1, 7.0, 0.75), (1, 8.5, 0.9),
                                     (1, 12.0, 0.5)], rtol=1e-6)
    match, d, ratio = match_rivals(cand, support, np.zeros(0, np.intp))
    assert match.shape == d.shape == ratio.shape == (0,)


def _pair(period, shift, h=120, w=200, seed=3):
    """Rows of a faint random texture, with vertical bars of ``period`` px (or none),
    the right image shifted by ``shift`` px."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.normal(0.0, 1.0, (h, w + 60)).astype(np.float32), (0, 0), 1.5)
    tex = 128.0 + t / t.std() * 10.0
    if period:
        bars = (np.cos(2.0 * np.pi * np.arange(w + 60) / period) > 0)[None, :]
        tex = cv2.GaussianBlur((tex + 60.0 * bars).astype(np.float32), (0, 0), 1.0)
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    right = cv2.remap(tex.astype(np.float32), uu + shift, vv, cv2.INTER_CUBIC)
    out = [np.clip(img + rng.normal(0.0, 1.0, img.shape), 0, 255).astype(np.uint8)
           for img in (tex[:, :w], right)]
    return [detect_vertical_edges(img, min_string_length=3) for img in out]


def _strongest(m):
    """(K,) the strongest rival's support ratio and disparity of each match (0, NaN if
    none)."""
    ratio = np.zeros(len(m))
    d = np.full(len(m), np.nan)
    order = np.lexsort((m.rival_ratio, m.rival_match))
    last = np.r_[m.rival_match[order][1:] != m.rival_match[order][:-1], True]
    best = order[last]
    ratio[m.rival_match[best]] = m.rival_ratio[best]
    d[m.rival_match[best]] = m.rival_d[best]
    return ratio, d


def test_a_periodic_pattern_gives_rivals_a_period_off_as_strong_as_the_match():
    period, shift = 9.0, 12.3
    m = pmf_match(*_pair(period, shift), 1.0, 40.0)[0]
    assert np.all(np.diff(m.rival_match) >= 0) and m.rival_match.max() < len(m)
    # bars a period apart are supported alike: the matcher picks a period off on most
    assert np.mean(np.abs(m.d - shift) > 1.0) > 0.5
    ratio, d = _strongest(m)
    assert np.mean(ratio >= 0.9) > 0.95
    off = (d - m.d) / period
    assert np.mean(np.abs(off - np.rint(off)) * period < 1.0) > 0.9
    assert np.mean(np.abs(np.rint(off)) >= 1) > 0.9
    # the true disparity is among the rivals of nearly every match a period off
    wrong = np.flatnonzero(np.abs(m.d - shift) > 1.0)
    true = (np.abs(m.rival_d - shift) < 1.0) & (m.rival_ratio >= 0.6)
    assert np.isin(wrong, m.rival_match[true]).mean() > 0.9
    # without the bars, a nearly as strong rival is much rarer
    m0 = pmf_match(*_pair(0.0, shift), 1.0, 40.0)[0]
    assert np.mean(np.abs(m0.d - shift) > 1.0) < 0.05
    assert np.mean(_strongest(m0)[0] >= 0.9) < 0.35


def _matches(d, rivals):
    """Matches of disparities ``d`` with rivals (match, disparity, support ratio)."""
    k = len(d)
    z = np.zeros(k, np.float32)
    r = np.asarray(rivals, np.float64).reshape(-1, 3)
    return Matches(u_left=z + 50, u_right=z + 50 - d, v=np.arange(k, dtype=np.int32),
                   d=np.asarray(d, np.float32), strength=z + 20, string_id=np.zeros(k, np.int32),
                   left_index=np.arange(k, dtype=np.int32),
                   right_index=np.arange(k, dtype=np.int32),
                   support=z + 1, rival_match=r[:, 0].astype(np.int32),
                   rival_d=r[:, 1].astype(np.float32), rival_ratio=r[:, 2].astype(np.float32))


@pytest.mark.parametrize('ratio', [0.6, 0.0])
def test_a_rival_on_the_ground_takes_the_evidence_away(ratio):
    det = GpodDetector(override(GpodConfig(), {'detection.ambiguous_match_ratio': ratio}))
    pd = np.full(6, 10.0)                 # the ground's disparity at every match
    thr = np.full(6, 0.8)
    m = _matches([15.5, 15.5, 15.5, 4.6, 4.6, 4.6],
                 [(0, 10.4, 0.7), (0, 4.5, 1.0),        # one on the ground, one beyond
                  (1, 10.0, 0.5),                       # too weak
                  (2, 12.0, 0.9), (2, 8.0, 0.9),        # beside the ground, not on it
                  (3, 21.0, 1.0), (3, 9.5, 0.95),       # one on the ground, one above
                  (4, 13.0, 0.95),                      # above the ground
                  (5, 10.0, 0.2), (5, 3.0, 0.8)])       # on the ground too weak
    no_drop = rules.ambiguous_drops(det.config, m, pd, thr)
    if ratio == 0.0:                      # off
        assert not no_drop.any()
        return
    # a rival on the ground nearly as strong and nearer than a drop's match: no evidence
    # of a drop (an obstacle's match with a farther rival on the ground is kept)
    np.testing.assert_array_equal(no_drop, [False, False, False, True, False, False])
    # a rival marks the side it lies on only (here, matches on the ground themselves)
    m = _matches([15.5, 4.6], [(0, 16.0, 1.0), (1, 4.0, 1.0)])
    no_drop = rules.ambiguous_drops(det.config, m, np.array([15.3, 4.4]), thr[:2])
    np.testing.assert_array_equal(no_drop, [True, False])
    # matches made without rivals (other matchers) are never ambiguous
    plain = dataclasses.replace(_matches([15.5], []), rival_match=None, rival_d=None,
                                rival_ratio=None)
    assert not rules.ambiguous_drops(det.config, plain, pd[:1], thr[:1]).any()


@pytest.mark.parametrize('n_min', [2, 0])
def test_a_periodic_match_is_no_evidence(n_min):
    det = GpodDetector(override(GpodConfig(), {'detection.periodic_min_rivals': n_min}))
    pd = np.full(5, 10.0)                 # the ground's disparity at every match
    thr = np.full(5, 0.8)
    m = _matches([13.4, 13.4, 13.4, 13.4, 13.4],
                 [(0, 10.2, 0.9), (0, 16.8, 1.1),       # a period either side: periodic
                  (1, 10.1, 1.0),                       # one ground rival (a kerb face)
                  (2, 16.8, 0.9), (2, 20.2, 0.95),      # two strong, none on the ground
                  (3, 10.0, 0.9), (3, 16.8, 0.5),       # the second too weak
                  (4, 6.6, 0.85), (4, 9.5, 0.8)])       # a period below and the ground
    periodic = rules.periodic_matches(det.config, m, pd, thr)
    if n_min == 0:                        # off
        assert not periodic.any()
        return
    np.testing.assert_array_equal(periodic, [True, False, False, False, True])
    plain = dataclasses.replace(_matches([15.5], []), rival_match=None, rival_d=None,
                                rival_ratio=None)
    assert not rules.periodic_matches(det.config, plain, pd[:1], thr[:1]).any()


def test_bars_matched_a_period_off_are_periodic_and_texture_is_not():
    period, shift = 9.0, 12.3
    det = GpodDetector()
    m = pmf_match(*_pair(period, shift), 1.0, 40.0)[0]
    pd = np.full(len(m), shift)           # the true disparity plays the ground's
    periodic = rules.periodic_matches(det.config, m, pd, np.full(len(m), 0.8))
    off = np.abs(m.d - shift) > 1.0       # matched a period (or more) off
    assert off.sum() > 20 and periodic[off].mean() > 0.8
    m0 = pmf_match(*_pair(0.0, shift), 1.0, 40.0)[0]
    p0 = rules.periodic_matches(det.config, m0, np.full(len(m0), shift), np.full(len(m0), 0.8))
    assert p0.mean() < 0.1


def test_a_pixels_contrary_rivals_are_those_on_the_other_side_of_the_ground():
    """`GpodFeatures.contrary_rival_share`: per match, the support of its rivals that say
    otherwise (for a raised pixel: on or below the ground, for a drop: on or above it)
    over that of the match and all its rivals; the map weighs its evidence 1 - that."""
    from asmonc_vision.core.gpod.support import contrary_rival_share

    class Rivalled:
        # match 0 (raised, 30 px on ground of 20 +- 1): a rival on the ground (0.9), one
        # below it (0.2), one raised too (0.5); match 1 (a drop, 15 px on ground of 20):
        # a rival on the ground (1.0) and one deeper still (0.4); match 2: no rival
        rival_match = np.array([0, 0, 0, 1, 1], np.int32)
        rival_d = np.array([20.5, 12.0, 35.0, 19.2, 10.0], np.float32)
        rival_ratio = np.array([0.9, 0.2, 0.5, 1.0, 0.4], np.float32)

        def __len__(self):
            return 3

    pd = np.array([20.0, 20.0, 20.0])
    thr = np.ones(3)
    raised = np.array([True, False, False])
    c = contrary_rival_share(Rivalled(), pd, thr, raised)
    assert c.dtype == np.float32
    assert c == pytest.approx([1.1 / 2.6, 1.0 / 2.4, 0.0], rel=1e-6)
    # a wall's texture matched elsewhere on the wall says nothing against it
    Rivalled.rival_d = np.array([40.0, 45.0, 35.0, 5.0, 10.0], np.float32)
    assert contrary_rival_share(Rivalled(), pd, thr, raised) == pytest.approx([0.0, 0.0, 0.0])
    Rivalled.rival_match = None
    assert contrary_rival_share(Rivalled(), pd, thr, raised) is None


def test_the_compiled_rival_tests_give_the_numpy_paths_results(monkeypatch):
    """The rival tests compiled (`kernels.nb_rivals_on_ground`, `nb_rival_share`) give
    the numpy paths' results bit for bit: periodic matches, ambiguous drops and the
    contrary rivals' share, on random rivals with ties at the support ratio (in single
    precision) and on the ground's bounds, and NaN ground."""
    from asmonc_vision.core.gpod import kernels as kn
    from asmonc_vision.core.gpod.support import contrary_rival_share
    kn.warm_up()
    if kn.nb_rival_share is None or kn.nb_rivals_on_ground is None:
        pytest.skip('numba not installed')
    rng = np.random.default_rng(7)
    k, n_r = 400, 3000
    pd = rng.uniform(5.0, 30.0, k)
    pd[::37] = np.nan
    thr = rng.uniform(0.3, 1.5, k)
    d = (pd + rng.normal(0.0, 3.0, k)).astype(np.float32)
    j = np.sort(rng.integers(0, k, n_r)).astype(np.int32)
    rd = (pd[j] + rng.normal(0.0, 2.0, n_r)).astype(np.float32)
    rd[::5] = (pd[j] + thr[j])[::5]                        # on the ground's bounds
    rd[1::5] = (pd[j] - thr[j])[1::5]
    ratio = rng.uniform(0.0, 1.2, n_r).astype(np.float32)
    config = GpodConfig()
    r = config.detection.ambiguous_match_ratio
    ratio[::7] = np.float32(r)                               # ties, in single precision
    ratio[3::7] = np.nextafter(np.float32(r), np.float32(0.0))
    m = Matches(u_left=np.zeros(k, np.float32), u_right=np.zeros(k, np.float32),
                v=np.zeros(k, np.int32), d=d, strength=np.ones(k, np.float32),
                string_id=np.zeros(k, np.int32), left_index=np.arange(k, dtype=np.int32),
                right_index=np.arange(k, dtype=np.int32), support=np.ones(k, np.float32),
                rival_match=j, rival_d=rd, rival_ratio=ratio)
    raised = rng.random(k) < 0.5

    def run():
        return [rules.periodic_matches(override(config, {'detection.periodic_min_rivals': n}),
                                       m, pd, thr) for n in (1, 2, 3)] + [
            rules.ambiguous_drops(config, m, pd, thr), contrary_rival_share(m, pd, thr, raised)]

    fast = run()
    monkeypatch.setattr(kn, 'nb_rival_share', None)
    monkeypatch.setattr(kn, 'nb_rivals_on_ground', None)
    slow = run()
    for x, y in zip(fast, slow):
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)
    assert all(x.any() for x in fast)                        # the tests were exercised
