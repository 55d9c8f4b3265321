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


def pairwise_sum_kernel(a, lo, hi):
    """``a[lo:hi].sum()`` of a contiguous float64 array as numpy adds it, for up to 128
    values (for numba): its pairwise summation, which is in order below 8 values, else
    8 partial sums over blocks of 8, combined pairwise, then the rest in order."""
    n = hi - lo
    if n < 8:
        res = 0.0
        for i in range(lo, hi):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    m = lo + n - n % 8
    for i in range(lo + 8, m, 8):
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(m, hi):
        res += a[i]
    return res


#: ``pairwise_sum_kernel`` compiled (None without numba), for other kernels to call
nb_pairwise_sum = jit(pairwise_sum_kernel)
