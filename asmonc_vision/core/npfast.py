"""numpy's small functions without their Python-level wrappers, for the per-frame paths.

numpy's convenience functions (``np.flatnonzero``, ...) are Python functions that call
one or two more (``np.ravel``, ``np.nonzero``'s dispatch) before the C method that does
the work: a few microseconds a call in a frame's code, which calls them dozens of times
(with cold caches, more than a micro-benchmark shows). The functions here give the same
arrays through the C methods directly. No ROS here.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt


def flat_nonzero(a: npt.ArrayLike) -> np.ndarray:
    """``np.flatnonzero(a)``: (K,) intp indices of the non-zero entries of ``a`` (an
    array of any shape and dtype, raveled in C order, or a numpy scalar or sequence),
    the same array (values and dtype) through ``ndarray.nonzero`` without
    np.flatnonzero's, np.ravel's and np.nonzero's wrappers."""
    return np.asarray(a).ravel().nonzero()[0]


def linspace(start: float, stop: float, num: int) -> np.ndarray:
    """``np.linspace(start, stop, num)`` of two real scalars (int or float) and num >= 2:
    (num,) float64, numpy's arithmetic written out (``arange(num) * step + start``, step
    ``(stop - start) / (num - 1)``, or ``/ (num - 1) * delta`` when the step is zero; the
    last value ``stop`` itself), the same values without its argument conversions (some
    twenty microseconds a call)."""
    div = num - 1
    delta = np.float64(float(stop) - float(start))
    y = np.arange(num, dtype=np.float64)
    step = delta / div
    if step == 0:
        y /= div
        y *= delta
    else:
        y *= step
    y += float(start)
    y[-1] = float(stop)
    return y


def unique_counts(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(x, return_counts=True)`` of a 1-D integer array: its distinct values
    ascending and how often each occurs ((K,) x's dtype, (K,) int64), without
    np.unique's overhead."""
    if x.size == 0:
        return x[:0], np.zeros(0, np.int64)
    if x.min() == x.max():                  # one value (a map region's cells mostly are)
        return x[:1], np.array([x.size], np.int64)
    s = np.sort(x)
    head = flat_nonzero(np.concatenate((_HEAD, s[1:] != s[:-1])))
    return s[head], np.diff(np.append(head, s.size))


_HEAD = np.ones(1, bool)
