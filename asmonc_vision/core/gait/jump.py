"""The inclinometer jump rule: an attitude that leaps is a sensor fault, not a movement.

A wearer's trunk does not turn its roll or pitch by tens of degrees within one 16 Hz
sample: a change of more than ``jump_deg`` at more than ``jump_rate_deg`` per second
between two samples is a fault of the sensor (a glitch, a bad frame, a knocked mount).
Such samples are kept out of the walk model:

* the sample that jumps is flagged ('jump') and rejected;
* the following samples are rejected ('held') while they stay away from the last good
  attitude;
* a sample back within ``jump_deg`` of the last good attitude ends the fault ('ok': a
  spike that came back; the walk model goes on as if nothing happened);
* if the samples stay at the new attitude for ``jump_settle`` s ('settled'), the new
  attitude is taken as real (the sensor was moved) and the caller restarts the walk
  model from it.

Yaw is not judged: it comes from a compass, whose heading legitimately wraps and swings.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['JumpRule']


class JumpRule:
    """Judges each inclinometer sample (see the module doc).

    Args:
        jump_deg: the smallest change (deg) of roll or pitch that can be a jump.
        rate_deg: the smallest rate (deg/s) of such a change that makes it a jump.
        settle: seconds a new attitude must hold before it is accepted.
    Attributes:
        jumps: jumps flagged so far.
        faulty: a jump is being held (its samples rejected).
    """

    def __init__(self, jump_deg: float = 25.0, rate_deg: float = 400.0,
                 settle: float = 1.0) -> None:
        if not (jump_deg > 0 and rate_deg > 0 and settle > 0):
            raise ValueError('JumpRule: jump_deg, rate_deg and settle must be > 0')
        self.jump = math.radians(jump_deg)
        self.rate = math.radians(rate_deg)
        self.settle = float(settle)
        self.jumps = 0
        self._good: tuple[float, np.ndarray] | None = None   # last accepted (t, rpy)
        self._since: float | None = None                     # when the jump began

    @property
    def faulty(self) -> bool:
        return self._since is not None

    def reset(self) -> None:
        """Forget the last good attitude (a restarted stream)."""
        self._good = None
        self._since = None

    @staticmethod
    def _change(rpy: np.ndarray, good: np.ndarray) -> float:
        d = rpy[:2] - good[:2]
        return float(np.max(np.abs((d + math.pi) % (2.0 * math.pi) - math.pi)))

    def check(self, t: float, rpy) -> str:
        """The verdict on the sample ``rpy`` (roll, pitch, yaw; rad) at ``t`` (s):
        'ok' (use it), 'jump' (a jump: rejected), 'held' (still away after a jump:
        rejected) or 'settled' (the new attitude held for ``settle`` s: restart the
        walk model from this sample)."""
        rpy = np.asarray(rpy, float)
        if self._good is None:
            self._good = (float(t), rpy)
            return 'ok'
        change = self._change(rpy, self._good[1])
        if self._since is not None:
            if change <= self.jump:
                self._since = None
                self._good = (float(t), rpy)
                return 'ok'
            if t - self._since >= self.settle:
                self._since = None
                self._good = (float(t), rpy)
                return 'settled'
            return 'held'
        dt = float(t) - self._good[0]
        if change > self.jump and (dt <= 0 or change / dt > self.rate):
            self.jumps += 1
            self._since = float(t)
            return 'jump'
        self._good = (float(t), rpy)
        return 'ok'
