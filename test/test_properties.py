"""Property tests of the core on random valid and invalid inputs (hypothesis): no
exception escapes but the documented ones, and the outputs stay finite and in range.
`asmonc fuzz` runs the NMEA parser and the bag reader for longer."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from asmonc_vision.core.alarm import (TEXT_CLEAR, AlarmConfig, AlarmLevel, AlarmLogic,
                                      GroundStatus, ObstacleInfo)
from asmonc_vision.core.edges import detect_vertical_edges
from asmonc_vision.core.ground_plane import fit_ground_plane, lsq_plane
from asmonc_vision.core.matching import match_edges
from asmonc_vision.core.nmea import (LineSplitter, NmeaError, format_ptnthpr, format_tcm,
                                     parse_sentence)

FAST = settings(max_examples=40, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

images = hnp.arrays(np.uint8, st.tuples(st.integers(1, 24), st.integers(1, 40)))
float_images = hnp.arrays(np.float32, st.tuples(st.integers(3, 16), st.integers(5, 30)),
                          elements=st.floats(-1e3, 1e3, width=32) | st.just(np.nan))


def _check_edges(e, shape):
    h, w = shape
    assert e.shape == shape
    n = len(e)
    for a in (e.v, e.u_int, e.u, e.strength, e.polarity, e.orientation, e.string_id):
        assert a.shape == (n,)
    assert np.all(np.isfinite(e.u)) and np.all(np.isfinite(e.strength))
    assert np.all((e.v >= 1) & (e.v <= h - 2)) and np.all((e.u_int >= 2) & (e.u_int <= w - 3))
    assert np.all(np.abs(e.u - e.u_int) <= 0.5 + 1e-5)
    assert np.all(np.isin(e.polarity, (-1, 1)))
    assert np.all(e.strength >= e.threshold - 1e-4)
    assert int(e.string_length.sum()) == n


@FAST
@given(images, st.floats(0.0, 50.0), st.integers(1, 5))
def test_edges_of_any_uint8_image(img, thr, min_len):
    e = detect_vertical_edges(img, abs_threshold=thr, min_string_length=min_len)
    _check_edges(e, img.shape)


@FAST
@given(float_images)
def test_edges_of_float_images_with_nan_stay_finite(img):
    e = detect_vertical_edges(img, abs_threshold=1.0)
    _check_edges(e, img.shape)


@FAST
@given(hnp.arrays(np.uint8, st.sampled_from([(3,), (2, 3, 4), ()])))
def test_edges_refuse_other_shapes(img):
    with pytest.raises(ValueError, match='2-D'):
        detect_vertical_edges(img)


@FAST
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 10.0), st.floats(1.0, 40.0))
def test_matching_random_pairs(seed, d_min, span):
    rng = np.random.default_rng(seed)
    left = (rng.random((20, 60)) * 255).astype(np.uint8)
    shift = int(rng.integers(0, 12))
    right = np.roll(left, -shift, axis=1)
    el = detect_vertical_edges(left, abs_threshold=8.0)
    er = detect_vertical_edges(right, abs_threshold=8.0)
    d_max = d_min + span
    m = match_edges(el, er, d_min, d_max)
    n = len(m)
    assert all(a.shape == (n,) for a in (m.u_left, m.u_right, m.v, m.d, m.support))
    assert np.all(np.isfinite(m.d)) and np.all(np.isfinite(m.support))
    assert np.all(m.d >= d_min - 1.0) and np.all(m.d <= d_max + 1.0)
    assert np.allclose(m.d, m.u_left - m.u_right, atol=1e-4)
    # one right edge per left edge and vice versa
    assert len(set(m.left_index.tolist())) == n == len(set(m.right_index.tolist()))


finite = st.floats(-1e4, 1e4)
any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)


@FAST
@given(st.integers(0, 60).flatmap(lambda n: st.tuples(
    hnp.arrays(np.float64, n, elements=finite), hnp.arrays(np.float64, n, elements=finite),
    hnp.arrays(np.float64, n, elements=finite),
    st.none() | hnp.arrays(np.float64, n, elements=st.floats(0, 1e3)))))
def test_lsq_plane_is_none_or_finite(uvdw):
    u, v, d, w = uvdw
    out = lsq_plane(u, v, d, w)
    if out is not None:
        abc, cov, rms = out
        assert abc.shape == (3,) and cov.shape == (3, 3)
        assert np.all(np.isfinite(abc)) and np.all(np.isfinite(cov)) and math.isfinite(rms)


@FAST
@given(st.integers(0, 2**32 - 1), st.integers(0, 80), st.floats(0.0, 0.5),
       st.sampled_from(['ransac', 'trimmed']), st.booleans())
def test_fit_ground_plane_recovers_or_declines(seed, n, outliers, method, nan):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(-150, 150, n), rng.uniform(0, 120, n)
    abc = np.array([0.01, 0.25, 2.0])
    d = abc[0] * u + abc[1] * v + abc[2] + rng.normal(0, 0.2, n)
    bad = rng.random(n) < outliers
    d[bad] = rng.uniform(0, 60, int(bad.sum()))
    if nan and n:
        d[rng.integers(0, n)] = np.nan
    fit = fit_ground_plane(u, v, d, method=method, rng=rng)
    if fit is None:
        return            # "no ground" is a return value
    assert np.all(np.isfinite(fit.abc)) and np.all(np.isfinite(fit.cov))
    assert fit.inliers.shape == (n,) and fit.num_features <= n
    if not nan and outliers < 0.3 and n >= 40:
        # the plane under the features is found (at the centre of the image)
        assert abs(fit.abc @ [0, 60, 1] - abc @ [0, 60, 1]) < 0.5


events = st.lists(st.tuples(
    st.floats(0.0, 0.6),          # time step, s
    st.sampled_from(['obstacles', 'ground', 'timer']),
    st.lists(st.tuples(st.floats(-1.0, 12.0) | any_float, st.floats(-3.2, 3.2),
                       st.floats(-1.0, 3.0), st.floats(0, 1)), max_size=4),
    st.sampled_from(list(GroundStatus))), max_size=60)


@settings(max_examples=150, deadline=None)
@given(events)
def test_alarm_policy_invariants(seq):
    cfg = AlarmConfig()
    logic = AlarmLogic(cfg, t0=0.0)
    t, ground, ground_t, stale = 0.0, None, -math.inf, False
    last_list = None
    for dt, kind, obs, status in seq:
        t += dt
        if kind == 'obstacles':
            # a ground status from before a gap in the lists is not trusted
            if (last_list is not None and t - last_list > cfg.timeout
                    and ground_t <= last_list + cfg.timeout):
                stale = True
            last_list = t
            d = logic.update(t, [ObstacleInfo(id=i + 1, range=r, bearing=b, height=h,
                                              confidence=c)
                                 for i, (r, b, h, c) in enumerate(obs)])
        elif kind == 'ground':
            d = logic.ground_status(t, status)
            ground, ground_t, stale = status, t, False
        else:
            d = logic.check_timeout(t)
        cur = logic.current
        assert cur.level in set(AlarmLevel)
        assert math.isfinite(cur.range) and math.isfinite(cur.bearing)
        if d is not None:
            assert d.text
            # never "all clear" without a tracked ground plane seen since the last gap
            if d.level == AlarmLevel.CLEAR:
                assert ground == GroundStatus.TRACKING and not stale and d.text == TEXT_CLEAR
        # silence longer than the timeout is always a FAULT
        if last_list is None or t - last_list > cfg.timeout + 1e-9:
            if kind == 'timer':
                assert cur.level == AlarmLevel.FAULT


angles = st.floats(-720, 720)


@FAST
@given(st.floats(0, 359.9), st.floats(-89, 89), st.floats(-179, 179))
def test_nmea_round_trip(h, p, r):
    for line in (format_ptnthpr(h, p, r), format_tcm(h, p, r)):
        a = parse_sentence(line)
        assert abs(a.pitch_deg - round(p, 1)) < 0.051 and abs(a.roll_deg - round(r, 1)) < 0.051


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=120) | st.from_regex(r'\$(PTNTHPR|C)[-0-9.,NPRTEa-z]*(\*[0-9A-F]{2})?',
                                              fullmatch=True))
@pytest.mark.slow
def test_nmea_parser_raises_only_nmea_errors(line):
    try:
        a = parse_sentence(line)
    except NmeaError as exc:
        assert exc.reason in ('checksum', 'format', 'unknown')
        return
    assert math.isfinite(a.pitch_deg) and math.isfinite(a.roll_deg)
    assert a.heading_deg is None or math.isfinite(a.heading_deg)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=300), max_size=10))
def test_line_splitter_any_bytes(chunks):
    s = LineSplitter()
    for c in chunks:
        for line in s.feed(c):
            assert line and '\n' not in line and '\r' not in line
            assert all(ord(ch) < 128 or ch == '\ufffd' for ch in line)


@pytest.mark.parametrize('target', ['nmea', 'bag'])
@pytest.mark.slow
def test_fuzz_command_runs_clean_for_a_few_seconds(target, tmp_path):
    # the bag reader once ended in MemoryError, OverflowError, TypeError and rosbags'
    # SerdeError on damaged files instead of BagError
    import argparse

    from asmonc_vision.cli import fuzz
    args = argparse.Namespace(target=target, seconds=4.0, engine='hypothesis',
                              crash_dir=tmp_path, seed=0)
    assert fuzz.run(args) == 0
    assert not list(tmp_path.glob('fuzz-*'))
