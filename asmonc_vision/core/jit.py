"""Optional numba compilation of the core's inner loops.

Every kernel compiled here has a numpy path beside it with the same tests and the same
arithmetic; numba is used when it is installed and compiles, and the numpy path
otherwise (the tests check that both give identical results).
"""
from __future__ import annotations

try:                        # optional: JIT-compiled loops (same results as numpy's)
    import numba as _numba
except ImportError:         # pragma: no cover
    _numba = None


def jit(fn):
    """``numba.njit(fn)``, cached on disk when a cache directory is writable; None
    without numba (the numpy path is used then)."""
    if _numba is None:
        return None
    try:
        return _numba.njit(cache=True, nogil=True)(fn)
    except Exception:       # no writable cache location: compile at every start
        return _numba.njit(cache=False, nogil=True)(fn)


def warmed(kernel, *args):
    """``kernel`` once it has been called on ``args`` (tiny inputs of the real argument
    types: compiled, or loaded from numba's disk cache, before the first frame); None if
    ``kernel`` is None or that call fails (a broken numba/llvmlite install: the numpy
    path is used then)."""
    if kernel is None:
        return None
    try:
        kernel(*args)
    except Exception:       # pragma: no cover - a broken numba/llvmlite install
        return None
    return kernel
