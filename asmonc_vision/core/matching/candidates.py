"""Candidate pairs of edges on the same row (PMF step 1), and the disparity-gradient
geometry the support uses."""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.edges import EdgeMap
from asmonc_vision.core.matching import kernels
from asmonc_vision.core.matching.types import Candidates
from ..npfast import flat_nonzero


def expand_ranges(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand index ranges [lo_i, hi_i) to (owner i, index) pairs, vectorised.

    Returns:
        (owner, index): int64 arrays of length sum(hi - lo), grouped by owner and
        ascending within each owner.
    """
    counts = np.maximum(hi - lo, 0)
    total = int(counts.sum())
    if total == 0:
        z = np.zeros(0, np.int64)
        return z, z
    owner = np.repeat(np.arange(lo.shape[0]), counts)
    idx = np.arange(total) + np.repeat(lo - (np.cumsum(counts) - counts), counts)
    return owner, idx


def candidate_matches(left: EdgeMap, right: EdgeMap, d_min: float, d_max: float, *,
                      min_strength_ratio: float = 0.5,
                      max_orientation_diff_deg: float = 30.0,
                      right_gain: float = 1.0) -> Candidates:
    """All admissible (left edge, right edge) pairs on the same row.

    Args:
        left, right: edge maps of the rectified left and right images (same shape).
        d_min, d_max: disparity search range, pixels (``d_min <= d <= d_max``).
        min_strength_ratio: least ratio of the weaker to the stronger edge, 0..1.
        max_orientation_diff_deg: largest difference of gradient directions, degrees.
        right_gain: > 0, the factor that puts the right image's grey levels on the
            left's scale (two cameras with their own gain): the strength test compares
            each left strength with the right one times this.
    Returns:
        Candidates grouped by left edge.
    """
    if left.shape != right.shape:
        raise ValueError(f'left and right edge maps differ in shape: {left.shape} vs {right.shape}')
    if len(left) == 0 or len(right) == 0 or d_max < d_min:
        z = np.zeros(0, np.intp)
        return Candidates(z, z, np.zeros(0))
    if not right_gain > 0:
        raise ValueError(f'right_gain must be > 0, got {right_gain}')
    right_strength = (right.strength if right_gain == 1.0
                      else right.strength * np.float32(right_gain))
    if (kernels.nb_candidates is not None and type(min_strength_ratio) in (float, int)
            and type(max_orientation_diff_deg) in (float, int)):
        # The same keys, ranges and tests, compiled (one pass, no temporaries).
        li, rj, d = kernels.nb_candidates(
            left.polarity, left.v, left.u, left.strength, left.orientation,
            right.polarity, right.v, right.u, right_strength, right.orientation,
            int(left.shape[0]), float(left.shape[1]), float(d_min), float(d_max),
            np.float32(min_strength_ratio), float(np.deg2rad(max_orientation_diff_deg)))
        return Candidates(left=li, right=rj, d=d)
    # Right edges of the same polarity and row, within the disparity range: one
    # contiguous range of the right edges sorted by (polarity, row, column).
    h = left.shape[0]
    span = float(left.shape[1]) + abs(float(d_max)) + abs(float(d_min)) + 4.0
    plane_r = (right.polarity < 0).astype(np.int64)
    order_r = np.r_[flat_nonzero(plane_r == 0), flat_nonzero(plane_r == 1)]
    key_r = ((plane_r * h + right.v) * span + right.u)[order_r]
    plane_l = (left.polarity < 0).astype(np.int64)
    order_l = np.r_[flat_nonzero(plane_l == 0), flat_nonzero(plane_l == 1)]
    key_l = (((plane_l * h + left.v) * span + left.u)[order_l])
    # Queries in ascending order (numpy's binary search is much faster on sorted keys).
    lo = np.empty(len(left), np.intp)
    hi = np.empty(len(left), np.intp)
    lo[order_l] = np.searchsorted(key_r, key_l - d_max, side='left')
    hi[order_l] = np.searchsorted(key_r, key_l - d_min, side='right')
    li, pos = expand_ranges(lo, hi)
    rj = order_r[pos]
    sl = left.strength[li]
    sr = right_strength[rj]
    ok = np.minimum(sl, sr) >= min_strength_ratio * np.maximum(sl, sr)
    dori = np.abs(left.orientation[li] - right.orientation[rj])
    dori = np.minimum(dori, 2.0 * np.pi - dori)
    ok &= dori <= np.deg2rad(max_orientation_diff_deg)
    keep = flat_nonzero(ok)
    li, rj = li[keep], rj[keep]
    return Candidates(left=li, right=rj, d=left.u[li].astype(np.float64) - right.u[rj])


def disc_offsets(radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Integer pixel offsets (du, dv) with ``0 < du^2 + dv^2 <= radius^2``.

    Returns:
        (du, dv): int64 arrays, ordered by dv then du.
    """
    rad = int(np.floor(radius))
    dv, du = np.mgrid[-rad:rad + 1, -rad:rad + 1]
    keep = (du * du + dv * dv <= radius * radius) & ((du != 0) | (dv != 0))
    return du[keep].astype(np.int64), dv[keep].astype(np.int64)


def disparity_gradient_interval(du_left, dv, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """Disparity differences allowed by the disparity-gradient limit.

    For two matches whose left edges are ``(du_left, dv)`` apart, the disparity gradient
    ``|x| / |(du_left - x/2, dv)|`` (x the disparity difference; cyclopean separation, as
    ``u_c = u_left - d/2``) is at most ``limit`` exactly when x lies in the returned
    closed interval.

    Args:
        du_left: (N,) left-image column differences (neighbour minus centre), pixels.
        dv: (N,) or scalar row differences, pixels.
        limit: disparity-gradient limit, 0 < limit < 2.
    Returns:
        (lo, hi): (N,) float64 bounds on ``d_neighbour - d_centre``, pixels.
    """
    a = np.asarray(du_left, np.float64)
    l2 = float(limit) ** 2
    # x^2 <= l2 ((a - x/2)^2 + dv^2)  <=>  qa x^2 + qb x + qc <= 0, qa > 0 for limit < 2.
    qa = 1.0 - 0.25 * l2
    qb = l2 * a
    qc = -l2 * (a * a + np.asarray(dv, np.float64) ** 2)
    root = np.sqrt(qb * qb - 4.0 * qa * qc)
    return (-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)


#: Relative slack of the single-precision disparity pre-filter of :func:`support_links`.
