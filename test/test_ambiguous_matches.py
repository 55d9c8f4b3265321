"""Ambiguous matches: each match's strongest rivals (core.matching.match_rivals) and
GPOD's rule that a match whose nearly as well supported rival lies on the ground is no
evidence of an obstacle or a drop-off."""
import cv2
import numpy as np
import pytest

from asmonc_vision.core.edges import detect_vertical_edges
from asmonc_vision.core.gpod import GpodConfig, GpodDetector
from asmonc_vision.core.matching import Candidates, Matches, match_rivals, pmf_match


def test_the_strongest_rival_on_each_side_of_the_left_and_right_edge():
    # candidates: (left, right, d); 0 is the match; 1, 2 share its left edge, 4 its
    # right edge; 3 shares neither
    cand = Candidates(left=np.array([0, 0, 0, 1, 2]), right=np.array([5, 3, 7, 3, 5]),
                      d=np.array([10.0, 12.0, 7.0, 4.0, 8.5]))
    support = np.array([2.0, 1.0, 1.5, 9.0, 1.8])
    ratio, d = match_rivals(cand, support, np.array([0]))
    # farther: candidates 2 (d 7, 0.75) and 4 (d 8.5, 0.9): the stronger, 4; nearer: 1
    np.testing.assert_allclose(ratio, [[0.9, 0.5]], rtol=1e-6)
    np.testing.assert_allclose(d, [[8.5, 12.0]])
    assert ratio.dtype == np.float32 and d.dtype == np.float32
    # candidate 3 alone on its left edge; its right edge's other candidate (1) is nearer
    ratio, d = match_rivals(cand, support, np.array([3]))
    np.testing.assert_allclose(ratio, [[0.0, 1.0 / 9.0]], rtol=1e-6)
    assert np.isnan(d[0, 0]) and d[0, 1] == 12.0
    ratio, d = match_rivals(cand, support, np.zeros(0, np.intp))
    assert ratio.shape == (0, 2) and d.shape == (0, 2)


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


def test_a_periodic_pattern_gives_rivals_a_period_off_as_strong_as_the_match():
    period, shift = 9.0, 12.3
    m = pmf_match(*_pair(period, shift), 1.0, 40.0)[0]
    assert m.rival_ratio.shape == (len(m), 2) and m.rival_d.shape == (len(m), 2)
    # bars a period apart are supported alike: the matcher picks a period off on most
    assert np.mean(np.abs(m.d - shift) > 1.0) > 0.5
    best = np.argmax(m.rival_ratio, axis=1)
    k = np.arange(len(m))
    assert np.mean(m.rival_ratio[k, best] >= 0.9) > 0.95
    off = (m.rival_d[k, best] - m.d) / period
    assert np.mean(np.abs(off - np.rint(off)) * period < 1.0) > 0.9
    assert np.mean(np.abs(np.rint(off)) >= 1) > 0.9
    # without the bars, a nearly as strong rival is much rarer
    m0 = pmf_match(*_pair(0.0, shift), 1.0, 40.0)[0]
    assert np.mean(np.abs(m0.d - shift) > 1.0) < 0.05
    assert np.mean(m0.rival_ratio.max(axis=1) >= 0.9) < 0.35


def _matches(d, rival_ratio, rival_d):
    k = len(d)
    z = np.zeros(k, np.float32)
    return Matches(u_left=z + 50, u_right=z + 50 - d, v=np.arange(k, dtype=np.int32),
                   d=np.asarray(d, np.float32), strength=z + 20, string_id=np.zeros(k, np.int32),
                   left_index=np.arange(k, dtype=np.int32), right_index=np.arange(k, dtype=np.int32),
                   support=z + 1, rival_ratio=np.asarray(rival_ratio, np.float32),
                   rival_d=np.asarray(rival_d, np.float32))


@pytest.mark.parametrize('ratio', [0.6, 0.0])
def test_a_rival_on_the_ground_takes_the_evidence_away(ratio):
    det = GpodDetector(GpodConfig(ambiguous_match_ratio=ratio))
    pd = np.full(6, 10.0)                 # the ground's disparity at every match
    thr = np.full(6, 0.8)
    nan = np.nan
    m = _matches([15.5, 15.5, 15.5, 4.6, 4.6, 4.6],
                 # (farther rival, nearer rival): their support over the match's
                 [[0.7, 0.0], [0.5, 0.0], [0.9, 0.0], [0.0, 0.95], [0.0, 0.95], [0.8, 0.2]],
                 [[10.4, nan], [10.0, nan], [12.0, nan], [nan, 9.5], [nan, 13.0],
                  [3.0, 10.0]])
    no_obst, no_drop = det._ambiguous_matches(m, pd, thr)
    if ratio == 0.0:                      # off
        assert not no_obst.any() and not no_drop.any()
        return
    # 0: a farther rival on the ground, nearly as strong: no obstacle evidence;
    # 1: too weak; 2: not on the ground (1 px above it plus the threshold)
    # 3: a nearer rival on the ground: no drop evidence; 4: the nearer rival is above
    # the ground; 5: the one on the ground is too weak, the strong one is farther
    np.testing.assert_array_equal(no_obst, [True, False, False, False, False, False])
    np.testing.assert_array_equal(no_drop, [False, False, False, True, False, False])
    # matches made without rivals (other matchers) are never ambiguous
    plain = _matches([15.5], [[0.0, 0.0]], [[nan, nan]])
    plain = Matches(**{**plain.__dict__, 'rival_ratio': None, 'rival_d': None})
    assert not any(a.any() for a in det._ambiguous_matches(plain, pd[:1], thr[:1]))
