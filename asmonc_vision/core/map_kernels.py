"""The evidence map's sight-line test compiled by numba (``core.jit``):
`EvidenceMap._rays` (`asmonc_vision.core.evidence_map`) runs it when it compiled, else
its numpy path, which builds the (cells x sight lines) arrays of the same arithmetic
(the same operations in the same order, in float64: both give the same counts; test_
evidence_map compares them). Only the large temporaries and numpy's call overhead are
gone: most sight lines pass far beside a cell and are dropped at the first test.
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.jit import jit, warmed


def rays_kernel(p, top, gh, R, height, lateral_m, stop_m):
    """Sight lines passing through raised cells, counted on each side of them.

    Args:
        p: (M, 2) float64 the cells' evidence points on the ground (x ahead, y left, m).
        top: (M,) float64 the height a sight line must pass below at each cell, m.
        gh: (N, 2) float64 the sight lines' unit directions on the ground.
        R: (N,) float64 the ranges of their ground points, m.
        height: the camera's height above the ground, m.
        lateral_m: a sight line within this of a cell's point passes through it, m.
        stop_m: the sight lines end this short of their ground point, m.
    Returns:
        (left, right): (M,) int64 each, the sight lines through each cell with the cell
        on their left (lateral offset > 0) and on their right (<= 0): those within
        ``lateral_m`` of it, that reach it (along the line: beyond 0.3 m, before
        ``R - stop_m``) and pass lower than ``top`` there (``height (1 - along / R)``).
    """
    m, n = p.shape[0], gh.shape[0]
    left = np.zeros(m, np.int64)
    right = np.zeros(m, np.int64)
    for i in range(m):
        px, py, ti = p[i, 0], p[i, 1], top[i]
        for j in range(n):
            gx, gy = gh[j, 0], gh[j, 1]
            lateral = gx * py - gy * px
            if not abs(lateral) <= lateral_m:
                continue
            along = px * gx + py * gy
            if not (along > 0.3 and along < R[j] - stop_m):
                continue
            if height * (1.0 - along / R[j]) < ti:
                if lateral > 0:
                    left[i] += 1
                else:
                    right[i] += 1
    return left, right


#: ``rays_kernel`` compiled (None without numba; `warm_up` sets it to None when it fails)
nb_rays = jit(rays_kernel)
_warm = False


def warm_up() -> None:
    """Compile the kernels once per process (or load them from numba's disk cache), before
    the first pair: an `EvidenceMap` calls this when it is made."""
    global _warm, nb_rays
    if _warm:
        return
    _warm = True
    nb_rays = warmed(nb_rays, np.zeros((1, 2)), np.zeros(1), np.ones((1, 2)), np.ones(1),
                     1.0, 0.03, 0.2)
