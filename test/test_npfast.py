"""`core.npfast`: numpy's small functions without their wrappers give numpy's arrays."""
import numpy as np

from asmonc_vision.core.npfast import flat_nonzero, unique_counts


def test_flat_nonzero_is_numpys_flatnonzero_byte_for_byte():
    """Values and dtype of np.flatnonzero for bool, int and float arrays of every shape
    (empty, 0-d, 1-d, 2-d C and F order, strided views), NaN and -0.0 included."""
    rng = np.random.default_rng(0)
    base = rng.random((7, 9))
    cases = [np.zeros(0, bool), np.zeros((0, 3)), np.array(True), np.array(0.0),
             base > 0.5, (base > 0.5).T, np.asfortranarray(base > 0.3),
             (base * 3).astype(np.int64) - 1, base[::2, 1::3] > 0.4,
             np.array([0.0, -0.0, np.nan, 1e-300, -np.inf, 0.0]),
             rng.integers(0, 2, 1000).astype(np.uint8), (base > 2.0)]
    for a in cases:
        want = np.flatnonzero(a)
        got = flat_nonzero(a)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert got.tobytes() == want.tobytes()
    # a read-only array and a list, as np.flatnonzero takes them
    ro = base > 0.5
    ro.flags.writeable = False
    assert flat_nonzero(ro).tobytes() == np.flatnonzero(ro).tobytes()
    assert flat_nonzero([0, 3, 0, 1]).tobytes() == np.flatnonzero([0, 3, 0, 1]).tobytes()


def test_linspace_is_numpys_linspace_byte_for_byte():
    """`npfast.linspace` gives np.linspace's float64 values for int and float ends
    (rising, falling, equal, negative, large; the evidence map's sight-line picks)."""
    from asmonc_vision.core.npfast import linspace
    rng = np.random.default_rng(1)
    cases = [(0, 2999, 600), (0, 600, 600), (0, 601, 600), (0.0, 1.0, 33), (0.0, 0.0, 5),
             (3, 3, 2), (-2.5, 7.25, 17), (7.25, -2.5, 17), (0, -1000, 600),
             (1e300, -1e300, 9), (-0.0, 0.0, 4), (2 ** 60, 2 ** 61 + 1, 7)]
    cases += [(float(a), float(b), int(n)) for a, b, n in
              zip(rng.normal(0, 100, 200), rng.normal(0, 1e4, 200), rng.integers(2, 700, 200))]
    cases += [(0, int(k), 600) for k in rng.integers(600, 20000, 200)]
    for a, b, n in cases:
        want = np.linspace(a, b, n)
        got = linspace(a, b, n)
        assert got.dtype == want.dtype and got.shape == want.shape, (a, b, n)
        assert got.tobytes() == want.tobytes(), (a, b, n)
        if max(abs(a), abs(b)) < 1e15:
            assert got.astype(np.int64).tobytes() == want.astype(np.int64).tobytes()


def test_unique_counts_is_numpys_unique_with_counts():
    """`npfast.unique_counts` gives np.unique(x, return_counts=True): one value, several,
    none."""
    rng = np.random.default_rng(4)
    for x in (np.zeros(0, np.int64), np.full(5, 7, np.int64), np.array([3], np.int64),
              rng.integers(1, 4, 50), rng.integers(1, 1000, 200)):
        vals, cnt = unique_counts(x)
        want_v, want_c = np.unique(x, return_counts=True)
        assert vals.tolist() == want_v.tolist() and cnt.tolist() == want_c.tolist()
        assert vals.dtype == want_v.dtype and cnt.dtype == np.int64
