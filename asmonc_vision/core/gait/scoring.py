"""Metrics of the walk model: prediction error, gait-phase error, walk start/stop.

All angles radians in, degrees or percent out where a name says so.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.gait.rotations import wrap_angle


def rms(x, axis=0) -> np.ndarray:
    """Root mean square along `axis` (NaN for an empty selection)."""
    x = np.asarray(x, float)
    if x.shape[axis] == 0:
        return np.full(np.delete(np.array(x.shape), axis), np.nan)
    return np.sqrt(np.mean(x * x, axis=axis))


def angle_errors_deg(estimate, truth) -> np.ndarray:
    """(N, 3) estimate - truth in degrees, yaw (column 2) wrapped."""
    e = np.asarray(estimate, float) - np.asarray(truth, float)
    e[..., 2] = wrap_angle(e[..., 2])
    return np.degrees(e)


def phase_error_percent(phase_est, phase_true) -> np.ndarray:
    """Phase error as a percentage of the cycle, wrapped to [-50, 50)."""
    return wrap_angle(np.asarray(phase_est, float) - np.asarray(phase_true, float)) \
        / (2.0 * np.pi) * 100.0


def bouts(times, flags) -> list[tuple[float, float]]:
    """Walking bouts (start, end) from a boolean series sampled at `times` (s). A bout
    still open at the end ends at the last sample."""
    t = np.asarray(times, float)
    f = np.asarray(flags, bool)
    out, start = [], None
    for ti, fi in zip(t, f):
        if fi and start is None:
            start = ti
        elif not fi and start is not None:
            out.append((start, ti))
            start = None
    if start is not None:
        out.append((start, float(t[-1])))
    return out


def transitions(times, flags) -> tuple[np.ndarray, np.ndarray]:
    """(rising times, falling times) of a boolean series (the sample where it changed)."""
    t = np.asarray(times, float)
    f = np.asarray(flags, bool).astype(int)
    d = np.diff(f)
    return t[1:][d > 0], t[1:][d < 0]


@dataclass(frozen=True)
class EventMatch:
    """Matched events: `delays` (detected - true, s) of the true events found within the
    tolerance, `missed` true events, `false` detections matched to none."""

    delays: np.ndarray
    missed: int
    false: int


def match_events(true_times, detected_times, before: float = 1.0, after: float = 3.0
                 ) -> EventMatch:
    """Match each true event to the first unused detection in [t - before, t + after]."""
    det = list(np.asarray(detected_times, float))
    used = [False] * len(det)
    delays, missed = [], 0
    for t in np.asarray(true_times, float):
        hit = None
        for i, d in enumerate(det):
            if not used[i] and t - before <= d <= t + after:
                hit = i
                break
        if hit is None:
            missed += 1
        else:
            used[hit] = True
            delays.append(det[hit] - t)
    return EventMatch(np.array(delays), missed, int(len(det) - sum(used)))


def match_bouts(reference: list[tuple[float, float]], detected: list[tuple[float, float]],
                min_overlap: float = 0.0) -> list[tuple[tuple[float, float],
                                                        tuple[float, float] | None]]:
    """Pair each reference bout with the detected bout overlapping it most (None if no
    detected bout overlaps it by more than `min_overlap` s)."""
    out = []
    for r in reference:
        best, best_ov = None, min_overlap
        for d in detected:
            ov = min(r[1], d[1]) - max(r[0], d[0])
            if ov > best_ov:
                best, best_ov = d, ov
        out.append((r, best))
    return out


def event_precision_recall(true_times, detected_times, tolerance: float
                           ) -> tuple[int, int, int]:
    """One-to-one matching of detected to true events within +-tolerance (s), closest
    pairs first. Returns (matched, detected, true): precision = matched / detected,
    recall = matched / true."""
    tt = np.asarray(true_times, float)
    dd = np.asarray(detected_times, float)
    if tt.size == 0 or dd.size == 0:
        return 0, int(dd.size), int(tt.size)
    gap = np.abs(dd[:, None] - tt[None, :])
    pairs = sorted((float(gap[i, j]), i, j) for i, j in zip(*np.nonzero(gap <= tolerance)))
    used_d, used_t = set(), set()
    for _, i, j in pairs:
        if i not in used_d and j not in used_t:
            used_d.add(i)
            used_t.add(j)
    return len(used_d), int(dd.size), int(tt.size)
