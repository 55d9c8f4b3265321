"""GPOD's speed: its numba kernels (``core.jit``) are all compiled, or loaded from
numba's disk cache, when the detector is made (none is first compiled on a frame: that
frame would stall, and a live graph calls a silent detector a FAULT); its fast helpers
give numpy's values."""
import sys
from pathlib import Path

import pytest

from asmonc_vision.core.gpod import GpodDetector
from asmonc_vision.io.frames import load_frames

BAGS = Path(__file__).resolve().parents[1] / 'bags'


def _dispatchers() -> dict:
    """name -> numba dispatcher of every module-level kernel of the package."""
    from numba.core.registry import CPUDispatcher
    out = {}
    for name, mod in list(sys.modules.items()):
        if name.startswith('asmonc_vision'):
            for k, v in list(vars(mod).items()):
                if isinstance(v, CPUDispatcher):
                    out[f'{name}.{k}'] = v
    return out


def test_no_kernel_is_first_compiled_on_a_frame():
    pytest.importorskip('numba')
    # the first 25 frames: calibration, then obstacles (a low one seen by one silhouette
    # edge from frame 20 on: the lone-face kernels)
    frames = load_frames(BAGS / 'static_obstacles', 25)
    det = GpodDetector()
    before = {k: len(v.signatures) for k, v in _dispatchers().items()}
    for f in frames:
        det.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
    late = sorted(k for k, v in _dispatchers().items() if len(v.signatures) > before.get(k, 0))
    assert not late, f'compiled on a frame: {late}'


def test_no_map_kernel_is_first_compiled_on_a_frame():
    """The evidence map's kernels (``core.map_kernels``) too are compiled when the map is
    made (the detector with its map, as the node runs it)."""
    pytest.importorskip('numba')
    from asmonc_vision.core.perception import Perception
    frames = load_frames(BAGS / 'static_obstacles', 25)
    per = Perception()
    assert per.map is not None
    before = {k: len(v.signatures) for k, v in _dispatchers().items()}
    for f in frames:
        per.process(f.left, f.right, f.cam, stamp_ns=f.stamp_ns)
    late = sorted(k for k, v in _dispatchers().items() if len(v.signatures) > before.get(k, 0))
    assert not late, f'compiled on a frame: {late}'


def test_row_median_is_numpys():
    """`faces._row_median` (the lone-face rule's medians) gives np.median's values, NaN
    rows and even and odd lengths included."""
    import numpy as np

    from asmonc_vision.core.gpod.faces import _row_median
    rng = np.random.default_rng(0)
    for n in range(1, 10):
        for shape in ((n,), (6, n), (2, 3, n)):
            x = np.round(rng.normal(size=shape), 1)         # ties
            x[rng.random(shape) < 0.05] = np.nan
            got, want = _row_median(x), np.median(x, axis=-1)
            assert np.shape(got) == np.shape(want)
            np.testing.assert_array_equal(got, want)
