"""The ground surface's compiled segment test gives what its numpy path gives, exactly:
the same sums in the same order, the same order statistics and interpolation."""
import dataclasses
import math

import numpy as np
import pytest

from asmonc_vision.core import ground_surface as gs
from asmonc_vision.core import surface_kernels as sk

sk.warm_up()
needs_numba = pytest.mark.skipif(sk.nb_segment is None, reason='numba not available')


@needs_numba
@pytest.mark.parametrize('n', [1, 7, 8, 9, 127, 128, 129, 200, 1000, 4097])
def test_the_compiled_sum_adds_as_numpy_does(n):
    rng = np.random.default_rng(n)
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-4, 4, size=n)
    assert sk.nb_pairwise_sum(x, 0, n) == np.sum(x)
    assert sk.nb_pairwise_sum(x, 3, n) == np.sum(x[3:])


@needs_numba
@pytest.mark.parametrize('q', [0.0, 0.1, 0.5, 0.9, 1.0])
def test_the_compiled_percentile_is_numpys(q):
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 10, 11, 101):
        x = rng.normal(size=n)
        assert sk.nb_percentile(x, q) == np.percentile(x, 100 * q)


@needs_numba
def test_the_compiled_median_is_numpys():
    rng = np.random.default_rng(8)
    for n in range(1, 60):
        x = rng.normal(size=n)
        assert sk.nb_median(x) == np.median(x)


@needs_numba
def test_the_compiled_median_by_selection_is_the_sorts():
    """`surface_kernels._median` (np.partition and a scan) gives the full sort's median
    byte for byte: ties, -0.0 beside 0.0, infinities and NaNs among the values."""
    rng = np.random.default_rng(9)
    for n in range(1, 120):
        for _ in range(10):
            x = rng.normal(size=n)
            if rng.random() < 0.3:
                x = np.round(x, 1)
            if rng.random() < 0.3:
                x[rng.random(n) < 0.3] = rng.choice([0.0, -0.0, np.inf, -np.inf, np.nan])
            a, b = sk.nb_median(x), sk.nb_sorted_median(x)
            assert np.float64(a).tobytes() == np.float64(b).tobytes()


def _same(a, b):
    return a == b or (isinstance(a, float) and isinstance(b, float)
                      and math.isnan(a) and math.isnan(b))


def _features(rng, kind, n):
    s, lat = rng.uniform(2.0, 9.0, n), rng.uniform(-1.5, 1.5, n)
    h = rng.normal(0.0, rng.uniform(0.005, 0.05), n)
    if kind == 'slope':
        h += 0.05 * np.clip(s - 3.0, 0.0, None)
    elif kind == 'step':
        h += np.where((s > 3.7) & (np.abs(lat) < rng.uniform(0.3, 2.0)),
                      rng.choice([-0.12, 0.12]), 0.0)
    elif kind == 'clutter':
        h += np.where(rng.random(n) < 0.2, rng.uniform(0.05, 0.5, n), 0.0)
    elif kind == 'kerb_ramp':          # kerbs beside a ramp: the corridor's own step
        half = rng.uniform(0.6, 1.3)
        h += np.where(np.abs(lat) > half, np.where(s > 3.7, 0.13, 0.0),
                      0.1 * np.clip(s - 3.7, 0.0, None))
    elif kind == 'brow':               # a sharp brow, seen whole or nearly grazed
        h = (rng.normal(0.0, rng.uniform(0.003, 0.02), n)
             - rng.uniform(0.1, 0.3) * np.clip(s - 3.7, 0.0, None))
        e_s = rng.uniform(0.0, 0.2, n)
        return s, lat, h, e_s, -e_s * rng.uniform(1.0, 2.0) / s     # along the rays
    return s, lat, h, rng.uniform(0.0, 0.2, n), rng.uniform(0.0, 0.05, n)


@needs_numba
@pytest.mark.parametrize('kind', ['flat', 'slope', 'step', 'clutter', 'kerb_ramp', 'brow'])
def test_the_compiled_segment_test_is_the_numpy_one(kind):
    rng = np.random.default_rng(
        ['flat', 'slope', 'step', 'clutter', 'kerb_ramp', 'brow'].index(kind))
    c = gs.GroundSurfaceConfig()
    verdicts = set()
    for _ in range(150):
        feats = _features(rng, kind, int(rng.integers(0, 600)))
        s_a = float(rng.choice([2.0, 3.0, 3.5, 8.5]))
        z_a, grade = float(rng.normal(0.0, 0.03)), float(rng.normal(0.0, 0.03))
        a = gs._segment(feats, s_a, z_a, grade, c)
        b = gs._segment_numpy(feats, s_a, z_a, grade, c)
        assert all(_same(x, y) for x, y in zip(dataclasses.astuple(a[0]),
                                               dataclasses.astuple(b[0]))), (a, b)
        assert a[1] == b[1] and a[2] == b[2]
        verdicts.add(a[0].refused_by)
    # the cases reach the rules, not only the support test
    assert len(verdicts) >= 2, verdicts


@needs_numba
@pytest.mark.parametrize('kind', ['flat', 'slope', 'step', 'clutter'])
def test_the_compiled_knot_sums_give_numpys_knot_sd(monkeypatch, kind):
    """`ground_surface.knot_sd` with `knot_sums_kernel` and with its numpy path: the same
    values, bit for bit (including a segment without features: NaN from there on)."""
    c = gs.GroundSurfaceConfig()
    for seed in range(30):
        rng = np.random.default_rng(seed)
        s, _, h, _, _ = _features(rng, kind, int(rng.integers(5, 1500)))
        n_k = int(rng.integers(2, 9))
        ks = 2.0 + np.cumsum(np.concatenate([[0.0], rng.uniform(0.3, 1.2, n_k - 1)]))
        kz = np.concatenate([[0.0], rng.normal(0.0, 0.03, n_k - 1)])
        if seed % 5 == 4:
            ks[-1] = 20.0                   # a segment beyond every feature
        checks = [gs.SegmentCheck('', 10, 1.0, 0.0, 0.0, float(x))
                  for x in rng.uniform(0.0, 0.05, n_k - 1)]
        compiled = gs.knot_sd(s, h, ks, kz, checks, c)
        monkeypatch.setattr(sk, 'nb_knot_sums', None)
        plain = gs.knot_sd(s, h, ks, kz, checks, c)
        monkeypatch.undo()
        assert compiled.tobytes() == plain.tobytes(), (seed, compiled, plain)
