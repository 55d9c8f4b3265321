"""The fallback rule: the walk model's prediction is published only while it earns its
place.

The prediction ``horizon`` s ahead (the skill-weighted one, `GaitTracker.estimate`) and
"hold the last measurement" are both scored against the measurement that comes
``horizon`` s later (interpolated between the two samples around it), per axis, over the
last ``fallback_window`` s of scored samples. Where the model's RMS error exceeds
holding's by more than the factor ``1 + fallback_margin`` the axis falls back to holding
the last measurement; it returns to the model once the model's RMS error is below
holding's again (the margin is a hysteresis: near-equal errors do not toggle it).
Nothing is decided before ``FALLBACK_MIN_SCORED`` s of predictions have been scored.

The short skill weighting of the tracker (``skill_memory``, half a second) follows the
model's fit within a stride; this rule watches a longer record, so a model that is worse
than holding over many strides (an irregular daily-living walk, frequent stops and
turns) is not published.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from asmonc_vision.core.gait.rotations import wrap_angle

__all__ = ['FALLBACK_MIN_SCORED', 'PredictionFallback']

#: seconds of scored predictions needed before the rule decides anything
FALLBACK_MIN_SCORED = 2.0


class PredictionFallback:
    """Scores the model's prediction against holding, and says which axes fall back.

    Args:
        horizon: the prediction horizon, s.
        window: seconds of scored predictions the errors are taken over.
        margin: relative margin: fall back when RMS(model) > (1 + margin) RMS(hold).
    Attributes:
        holding: (3,) bool, the axes (roll, pitch, yaw) that fall back now.
        switches: how often an axis changed between model and holding.
    """

    def __init__(self, horizon: float, window: float, margin: float) -> None:
        if not (horizon > 0 and window > 0 and margin >= 0):
            raise ValueError(f'PredictionFallback: horizon {horizon} and window {window} '
                             f'must be > 0, margin {margin} >= 0')
        self.horizon = float(horizon)
        self.window = float(window)
        self.margin = float(margin)
        self.holding: np.ndarray = np.zeros(3, bool)
        self.switches = 0
        self._pending: deque = deque()    # (t, predicted (3,), held (3,)) not yet scored
        self._scored: deque = deque()     # (target t, model e^2 (3,), hold e^2 (3,))
        self._sum_m = np.zeros(3)
        self._sum_h = np.zeros(3)
        self._prev: tuple[float, np.ndarray] | None = None   # the last measurement

    def reset(self) -> None:
        """Forget everything (a restart of the filter)."""
        self.__init__(self.horizon, self.window, self.margin)  # type: ignore[misc]  # final here

    def mean_squares(self) -> tuple[np.ndarray, np.ndarray, int]:
        """(model MSE (3,), hold MSE (3,), scored samples) over the window."""
        n = len(self._scored)
        if n == 0:
            return np.zeros(3), np.zeros(3), 0
        return self._sum_m / n, self._sum_h / n, n

    def score(self, t: float, z) -> None:
        """Score the pending predictions due by ``t`` against the measurement ``z`` (3,)
        at ``t`` (yaw continuous), then update `holding`."""
        z = np.asarray(z, float)
        t0, z0 = self._prev if self._prev is not None else (t, z)
        while self._pending and self._pending[0][0] + self.horizon <= t + 1e-9:
            ti, pred, held = self._pending.popleft()
            target = ti + self.horizon
            u = 1.0 if t <= t0 else min(max((target - t0) / (t - t0), 0.0), 1.0)
            d = z - z0
            d[2] = wrap_angle(float(d[2]))
            truth = z0 + u * d
            em, eh = pred - truth, held - truth
            em[2], eh[2] = wrap_angle(float(em[2])), wrap_angle(float(eh[2]))
            self._scored.append((target, em * em, eh * eh))
            self._sum_m += em * em
            self._sum_h += eh * eh
        while self._scored and self._scored[0][0] < t - self.window:
            _, m2, h2 = self._scored.popleft()
            self._sum_m -= m2
            self._sum_h -= h2
        self._prev = (t, z)
        self._decide()

    def _decide(self) -> None:
        if not self._scored or self._scored[-1][0] - self._scored[0][0] < FALLBACK_MIN_SCORED:
            return
        m2, h2, _ = self.mean_squares()
        worse = m2 > (1.0 + self.margin) ** 2 * h2
        better = m2 < h2
        new = np.where(self.holding, ~better, worse)
        self.switches += int(np.count_nonzero(new != self.holding))
        self.holding = new

    def push(self, t: float, predicted, held) -> None:
        """Remember the prediction made at ``t`` (for ``t + horizon``) and the
        measurement held at ``t`` (3,) each, to be scored when their time comes."""
        self._pending.append((float(t), np.array(predicted, float), np.array(held, float)))

    def apply(self, predicted, held) -> np.ndarray:
        """``predicted`` (3,) with the falling-back axes replaced by ``held``."""
        return np.where(self.holding, np.asarray(held, float), np.asarray(predicted, float))
