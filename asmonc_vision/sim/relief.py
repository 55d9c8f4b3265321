"""A ground that is not one plane: a height profile along one direction.

``GroundProfile`` adds to the base plane (``world.Ground``) a continuous, piecewise
linear height ``P(s)`` along a horizontal direction (``yaw_deg``) through a point
(``x0``, ``y0``), constant across it: a slope that starts or ends ahead, a crest, a dip,
the ramp of a dropped kerb. The base plane may itself slope across the walking direction
(a camber / cross-slope), so every piece of the ground is a plane over a strip
``lo <= s < hi`` and rays are intersected with each piece exactly (``intersect``).

Everything here is ground: it is never an obstacle in the ground truth. Units: metres,
world frame (z up), grades are dz/ds (tan of the slope angle).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_EPS_T = 1e-6


@dataclass(frozen=True)
class GroundProfile:
    """Height ``P(s)`` (m) added to the base plane, ``s`` metres along ``yaw_deg`` from
    (x0, y0). ``P(breaks[0]) = 0``; segment k has grade ``grades[k]`` and spans
    ``breaks[k-1] <= s < breaks[k]`` (the first and last segments are unbounded).

    Attributes:
        x0, y0: world point where s = 0, metres.
        yaw_deg: world direction of increasing s, degrees from world x.
        breaks: (n,) increasing s (m) where the grade changes (n >= 1).
        grades: (n + 1,) dz/ds of the segments (|grade| <= 0.5).
    """

    x0: float
    y0: float
    yaw_deg: float
    breaks: tuple[float, ...]
    grades: tuple[float, ...]

    def __post_init__(self) -> None:
        b = np.asarray(self.breaks, float)
        if b.size < 1 or len(self.grades) != b.size + 1:
            raise ValueError('GroundProfile needs n >= 1 breaks and n + 1 grades')
        if np.any(np.diff(b) <= 0):
            raise ValueError('GroundProfile.breaks must increase')
        if max(abs(g) for g in self.grades) > 0.5:
            raise ValueError('GroundProfile.grades must be within +/-0.5')
        if b.size + 1 > 60:
            raise ValueError('GroundProfile supports at most 59 breaks')

    @property
    def direction(self) -> tuple[float, float]:
        """(cos, sin) of the profile direction."""
        a = math.radians(self.yaw_deg)
        return math.cos(a), math.sin(a)

    def s(self, x, y) -> np.ndarray:
        """Profile coordinate s (m) of world x, y (arrays)."""
        c, sn = self.direction
        return (np.asarray(x) - self.x0) * c + (np.asarray(y) - self.y0) * sn

    def _knots(self) -> tuple[np.ndarray, np.ndarray]:
        """(segment start s (n+1,), P at that start (n+1,)); the first start is -inf and
        its P is given at breaks[0] instead."""
        b = np.asarray(self.breaks, float)
        g = np.asarray(self.grades, float)
        p = np.concatenate([[0.0], np.cumsum(g[1:-1] * np.diff(b))]) if b.size > 1 else \
            np.zeros(1)
        starts = np.concatenate([[-np.inf], b])
        return starts, np.concatenate([[0.0], p])

    def segment(self, s) -> np.ndarray:
        """Segment index (int) of profile coordinates s."""
        return np.searchsorted(np.asarray(self.breaks, float), np.asarray(s), side='right')

    def offset(self, x, y) -> np.ndarray:
        """P(s) (m) at world x, y (arrays; float64)."""
        s = self.s(x, y)
        k = self.segment(s)
        starts, p = self._knots()
        g = np.asarray(self.grades, float)[k]
        ref = np.where(k == 0, self.breaks[0], starts[k])
        return p[k] + g * (s - ref)

    def pieces(self, base_gradient, base_z0: float
               ) -> list[tuple[np.ndarray, float, float, float]]:
        """The ground as planes over strips, with the base plane
        ``z = base_z0 + gx x + gy y`` added.

        Returns:
            per segment k: (unit up normal N (3,), offset with N . X = offset, lo, hi)
            where the piece spans lo <= s < hi.
        """
        gx, gy = (float(v) for v in base_gradient)
        c, sn = self.direction
        starts, p = self._knots()
        ends = np.concatenate([np.asarray(self.breaks, float), [np.inf]])
        out = []
        for k, g in enumerate(self.grades):
            ref = self.breaks[0] if k == 0 else starts[k]
            # z = base_z0 + gx x + gy y + p_k + g (s - ref),  s = (x - x0) c + (y - y0) sn
            ax, ay = gx + g * c, gy + g * sn
            z0 = base_z0 + p[k] - g * (ref + self.x0 * c + self.y0 * sn)
            n = np.array([-ax, -ay, 1.0])
            norm = float(np.linalg.norm(n))
            out.append((n / norm, z0 / norm, float(starts[k]), float(ends[k])))
        return out

    def gradient(self, x, y, base_gradient) -> tuple[np.ndarray, np.ndarray]:
        """(dz/dx, dz/dy) of the ground at world x, y (arrays), base plane included."""
        c, sn = self.direction
        g = np.asarray(self.grades, float)[self.segment(self.s(x, y))]
        return float(base_gradient[0]) + g * c, float(base_gradient[1]) + g * sn

    def intersect(self, base_gradient, base_z0: float, o, rx, ry, rz
                  ) -> tuple[np.ndarray, np.ndarray]:
        """First hit of rays ``o + t r`` on the profiled ground.

        Args:
            base_gradient: (2,) the base plane's dz/dx, dz/dy; base_z0: its z at the
                world origin (m).
            o: (3,) ray origin (world); rx, ry, rz: ray directions, arrays of one shape.
        Returns:
            (t, same shape and dtype as rx, inf where missed; piece index (int32)).
        """
        c, sn = self.direction
        ox, oy, oz = (float(v) for v in o)
        t_best = np.full(rx.shape, np.inf, rx.dtype)
        piece = np.zeros(rx.shape, np.int32)
        so = (ox - self.x0) * c + (oy - self.y0) * sn
        rs = rx * c + ry * sn
        for k, (n, off, lo, hi) in enumerate(self.pieces(base_gradient, base_z0)):
            nx, ny, nz = (float(v) for v in n)
            with np.errstate(divide='ignore', invalid='ignore'):
                t = (float(off) - (ox * nx + oy * ny + oz * nz)) / (rx * nx + ry * ny + rz * nz)
            s = so + t * rs
            ok = (t > _EPS_T) & np.isfinite(t) & (s >= lo) & (s < hi) & (t < t_best)
            t_best[ok] = t[ok]
            piece[ok] = k
        return t_best, piece

    def normals(self, base_gradient) -> np.ndarray:
        """(n + 1, 3) unit up normals of the pieces."""
        return np.array([p[0] for p in self.pieces(base_gradient, 0.0)])


def slope_change(x0: float, y0: float, yaw_deg: float, at: float, before_deg: float,
                 after_deg: float, rounding: float = 0.0, steps: int = 4) -> GroundProfile:
    """A grade change ``at`` metres along ``yaw_deg`` from (x0, y0): ``before_deg`` then
    ``after_deg`` (degrees, positive rising). ``rounding`` > 0 spreads the change over
    that length (m) in ``steps`` equal grade steps (a rounded crest or dip)."""
    g0, g1 = math.tan(math.radians(before_deg)), math.tan(math.radians(after_deg))
    if rounding <= 0:
        return GroundProfile(x0, y0, yaw_deg, (at,), (g0, g1))
    b = tuple(at - rounding / 2 + rounding * k / steps for k in range(steps + 1))
    g = tuple(g0 + (g1 - g0) * k / (steps + 1) for k in range(steps + 2))
    return GroundProfile(x0, y0, yaw_deg, b, g)
