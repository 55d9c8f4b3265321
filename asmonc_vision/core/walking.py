"""The wearer's walking speed and direction from the visual egomotion, smoothed: what the
alarm logic (`core.alarm`) turns a range into a time to contact with.

Frames: the left optical frame (REP 103 optical: x right, y down, z forward, metres).
No ROS here.
"""
from __future__ import annotations

import math
from collections.abc import Sequence


class WalkingSpeed:
    """Walking speed and direction from the camera's frame-to-frame motion, smoothed.

    Each ``update`` takes one visual-egomotion step: the left camera's translation from
    the previous pair to this one in the previous left optical frame (metres; x right,
    y down, z forward; ``/egomotion``'s ``translation``) over ``dt`` seconds. The speed is
    the step's length over dt (the walker's vertical bob is small beside the stride); the
    heading is the step's direction from the optical axis about the vertical, positive
    left: atan2(-x, hypot(y, z)). Both are smoothed by a first-order low-pass filter of
    time constant ``tau`` (the heading as a unit vector weighted by the step length, so
    a standing rig's jitter does not swing it).
    """

    def __init__(self, tau: float = 0.5, max_speed: float = 3.0):
        self.tau = float(tau)
        self.max_speed = float(max_speed)
        self.speed: float | None = None
        self._dir = (0.0, 0.0)
        self.t: float | None = None

    @property
    def heading(self) -> float:
        """Smoothed walking direction from the camera's axis, radians, positive left."""
        fx, ly = self._dir
        return math.atan2(ly, fx) if (fx or ly) else 0.0

    def update(self, t: float, translation: Sequence[float], dt: float) -> float | None:
        """One motion step at time t (s): translation (x, y, z) in metres, optical frame,
        over dt > 0 seconds. Returns the smoothed speed (m/s); an implausible step (faster
        than ``max_speed``, not finite, dt <= 0) is ignored."""
        x, y, z = (float(v) for v in translation)
        if not (dt > 0 and all(map(math.isfinite, (x, y, z)))):
            return self.speed
        step = math.sqrt(x * x + y * y + z * z)
        v = step / dt
        if v > self.max_speed:
            return self.speed
        alpha = 1.0 - math.exp(-dt / self.tau) if self.tau > 0 else 1.0
        fwd, left = math.hypot(y, z) / dt, -x / dt          # m/s along and across
        if self.speed is None:
            self.speed, self._dir = v, (fwd, left)
        else:
            self.speed += alpha * (v - self.speed)
            self._dir = (self._dir[0] + alpha * (fwd - self._dir[0]),
                         self._dir[1] + alpha * (left - self._dir[1]))
        self.t = float(t)
        return self.speed
