"""`core.npfast`: numpy's small functions without their wrappers give numpy's arrays."""
import numpy as np

from asmonc_vision.core.npfast import flat_nonzero


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
