"""Scoring detections against ground truth, frame by frame (pure numpy).

Positions are compared *on the ground*: each obstacle's place is the point
``range * (cos bearing, sin bearing)`` in the ground plane, from the point below the
camera (x forward, y left). That is where the wearer must not step, and it does not
depend on whether the obstacle's top is in view (a 2 m post's top is not).

A true obstacle counts as *detected* in a frame when a detection lies within
`match_radius` metres of it on the ground. A detection is *false* when it explains no
true obstacle: it is neither within `match_radius` of one, nor inside one's image
region (so a detection on the far end of a wall is not false, though the wall's true
position is its nearest visible part).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class FrameObstacles:
    """Obstacles of one frame, as arrays.

    Attributes:
        stamp_ns: the image pair's stamp.
        ids: (N,) int; track or ground-truth ids.
        position: (N, 3) float, metres, left optical frame (the obstacle's top).
        height: (N,) metres above the ground (negative for a drop).
        range: (N,) metres along the ground.
        bearing: (N,) radians, positive left.
        roi: (N, 4) int (x, y, w, h) in the left image.
    """

    stamp_ns: int
    ids: np.ndarray
    position: np.ndarray
    height: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    roi: np.ndarray

    @classmethod
    def empty(cls, stamp_ns: int) -> 'FrameObstacles':
        z = np.zeros(0)
        return cls(stamp_ns, z.astype(int), np.zeros((0, 3)), z, z, z, np.zeros((0, 4), int))

    def __len__(self) -> int:
        return len(self.ids)

    def ground_xy(self) -> np.ndarray:
        """(N, 2) metres: position on the ground, x forward, y left, from the camera's foot."""
        return np.stack([self.range * np.cos(self.bearing),
                         self.range * np.sin(self.bearing)], axis=1)


@dataclass
class ObstacleRecord:
    """How one true obstacle fared over the frames it was eligible in."""

    id: int
    height: float
    min_range: float
    frames_eligible: int = 0
    frames_detected: int = 0

    @property
    def detected(self) -> bool:
        """Detected in at least half of the frames it was eligible in."""
        return self.frames_eligible > 0 and self.frames_detected * 2 >= self.frames_eligible


@dataclass
class DetectionScore:
    """Totals over a sequence (see `score_sequence`)."""

    frames: int = 0
    eligible: int = 0
    detected: int = 0
    false_obstacles: int = 0
    frames_with_false: int = 0
    range_errors: list = field(default_factory=list)
    bearing_errors: list = field(default_factory=list)
    obstacles: dict = field(default_factory=dict)

    @property
    def recall(self) -> float:
        """Fraction of (frame, eligible true obstacle) pairs detected; nan if none."""
        return self.detected / self.eligible if self.eligible else float('nan')

    @property
    def false_per_frame(self) -> float:
        return self.false_obstacles / self.frames if self.frames else float('nan')

    def as_dict(self) -> dict:
        """Plain dict for JSON output."""
        obs = {str(k): {'height_m': round(v.height, 3), 'min_range_m': round(v.min_range, 2),
                        'frames_eligible': v.frames_eligible,
                        'frames_detected': v.frames_detected, 'detected': v.detected}
               for k, v in sorted(self.obstacles.items())}
        re = np.asarray(self.range_errors, float)
        be = np.asarray(self.bearing_errors, float)
        return {
            'frames': self.frames, 'eligible': self.eligible, 'detected': self.detected,
            'recall': self.recall, 'false_obstacles': self.false_obstacles,
            'false_per_frame': self.false_per_frame,
            'frames_with_false': self.frames_with_false,
            'range_error_median_m': float(np.median(np.abs(re))) if re.size else None,
            'bearing_error_median_deg': float(np.degrees(np.median(np.abs(be))))
            if be.size else None,
            'obstacles': obs,
        }


def _inside_roi(roi: np.ndarray, pts_uv: np.ndarray, margin: float) -> np.ndarray:
    """(M, N) bool: detection n's image point inside true roi m (inflated by margin px)."""
    x, y, w, h = (roi[:, i][:, None].astype(float) for i in range(4))
    u, v = pts_uv[:, 0][None, :], pts_uv[:, 1][None, :]
    return (u >= x - margin) & (u <= x + w + margin) & (v >= y - margin) & (v <= y + h + margin)


def score_frame(det: FrameObstacles, truth: FrameObstacles, score: DetectionScore, *,
                match_radius: float = 0.3, min_height: float = 0.10,
                max_range: float = 5.0, roi_margin: float = 4.0) -> None:
    """Add one frame's outcome to `score` (in place).

    Eligible true obstacles: |height| >= min_height and range <= max_range.
    Each eligible one is detected if an unused detection lies within match_radius of
    it on the ground (greedy, nearest true obstacle first). Range and bearing errors
    are taken from those matches.
    """
    score.frames += 1
    m, n = len(truth), len(det)
    dist = (np.linalg.norm(truth.ground_xy()[:, None, :] - det.ground_xy()[None, :, :], axis=2)
            if m and n else np.zeros((m, n)))
    eligible = (np.abs(truth.height) >= min_height) & (truth.range <= max_range)
    used = np.zeros(n, bool)
    order = np.argsort(truth.range) if m else np.zeros(0, int)
    for i in order:
        tid = int(truth.ids[i])
        rec = score.obstacles.get(tid)
        if rec is None:
            rec = score.obstacles[tid] = ObstacleRecord(tid, float(truth.height[i]),
                                                        float(truth.range[i]))
        rec.min_range = min(rec.min_range, float(truth.range[i]))
        if not eligible[i]:
            continue
        rec.frames_eligible += 1
        score.eligible += 1
        if n == 0:
            continue
        d = np.where(used, np.inf, dist[i])
        j = int(np.argmin(d))
        if d[j] <= match_radius:
            used[j] = True
            score.detected += 1
            rec.frames_detected += 1
            score.range_errors.append(float(det.range[j] - truth.range[i]))
            db = (det.bearing[j] - truth.bearing[i] + np.pi) % (2 * np.pi) - np.pi
            score.bearing_errors.append(float(db))
    if n:
        near_any = (dist <= match_radius).any(axis=0) if m else np.zeros(n, bool)
        det_uv = np.stack([det.roi[:, 0] + det.roi[:, 2] / 2.0,
                           det.roi[:, 1] + det.roi[:, 3] / 2.0], axis=1)
        in_roi = (_inside_roi(truth.roi, det_uv, roi_margin).any(axis=0)
                  if m else np.zeros(n, bool))
        false = ~(used | near_any | in_roi)
        nf = int(false.sum())
        score.false_obstacles += nf
        score.frames_with_false += int(nf > 0)


def score_sequence(detections: dict[int, FrameObstacles], truth: dict[int, FrameObstacles],
                   **kwargs) -> tuple[DetectionScore, list[int]]:
    """Score every ground-truth frame; frames with no detection message are *missing*.

    Args:
        detections: stamp_ns -> detections of that frame (absent: the frame was dropped).
        truth: stamp_ns -> true obstacles of that frame.
        **kwargs: passed to `score_frame`.
    Returns:
        (score over the frames that have detections, stamps of the missing frames).
    """
    score = DetectionScore()
    missing = []
    for stamp in sorted(truth):
        det = detections.get(stamp)
        if det is None:
            missing.append(stamp)
            continue
        score_frame(det, truth[stamp], score, **kwargs)
    return score, missing
