"""Moving obstacles: people walking on the pavement.

A ``Person`` is an upright box (shoulder width across its walking direction, body depth
along it, 1.5-1.9 m tall) that follows a track of timed waypoints at walking speed,
turned to face where it is going. ``World.active(t)`` hands the renderer and the ground
truth the person *as it is at time t* (``Person.at``), so every frame, and every
sub-exposure of a motion-blurred frame, sees it at its true place; its earlier places
are empty. Its clothes: ``albedo`` above ``waist`` of its height, ``lower_albedo`` below.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from asmonc_vision.sim.world import Box, Hits, World

_F = np.float32


@dataclass(frozen=True, kw_only=True)
class Person(Box):
    """A walking person (kind 'person').

    Attributes:
        track: ((t, x, y), ...) waypoints: seconds (increasing), world metres; linear in
            between, standing still before the first and after the last.
        lower_albedo: grey level of the legs (below ``waist`` of the height).
        waist: share of the height where the clothes change.
        (x, y, yaw_deg are those at the first waypoint; ``at`` moves them.)
    """

    track: tuple[tuple[float, float, float], ...]
    lower_albedo: float = 60.0
    waist: float = 0.5
    kind: str = 'person'

    def __post_init__(self) -> None:
        super().__post_init__()
        t = [p[0] for p in self.track]
        if len(t) < 1 or any(b <= a for a, b in zip(t, t[1:])):
            raise ValueError('Person.track needs increasing waypoint times')

    def place(self, t: float) -> tuple[float, float, float]:
        """(x, y, yaw_deg) at time t (s): the track position, facing its direction."""
        tr = np.asarray(self.track, float)
        x = float(np.interp(t, tr[:, 0], tr[:, 1]))
        y = float(np.interp(t, tr[:, 0], tr[:, 2]))
        if len(tr) < 2:
            return x, y, self.yaw_deg
        k = int(np.clip(np.searchsorted(tr[:, 0], t, side='right') - 1, 0, len(tr) - 2))
        d = tr[k + 1, 1:] - tr[k, 1:]
        yaw = math.degrees(math.atan2(d[1], d[0])) if np.hypot(*d) > 1e-9 else self.yaw_deg
        return x, y, yaw

    def speed(self, t: float) -> float:
        """Walking speed (m/s) at time t (s)."""
        tr = np.asarray(self.track, float)
        k = int(np.searchsorted(tr[:, 0], t, side='right') - 1)
        if k < 0 or k >= len(tr) - 1:
            return 0.0
        return float(np.hypot(*(tr[k + 1, 1:] - tr[k, 1:])) / (tr[k + 1, 0] - tr[k, 0]))

    def at(self, t: float, world: World) -> 'Person':
        """The person at time t: moved along its track, standing on the ground there."""
        x, y, yaw = self.place(t)
        return dataclasses.replace(self, x=x, y=y, yaw_deg=yaw,
                                   base_z=float(world.ground_height(x, y, t)))

    def surface_albedo(self, world: World, h: Hits) -> np.ndarray:
        """Box texture; the legs (below the waist) in ``lower_albedo``."""
        out = super().surface_albedo(world, h)
        legs = (h.face < 4) & (h.pz < _F(float(self.base_z) + self.waist * self.height))
        out[legs] *= _F(self.lower_albedo / self.albedo)
        return out


def walker(track, *, height: float = 1.75, width: float = 0.45, depth: float = 0.28,
           albedo: float = 90.0, lower_albedo: float = 60.0, **kw) -> Person:
    """A person following ``track`` ((t, x, y), ...), ``width`` m across its walking
    direction, ``depth`` m along it, ``height`` m tall."""
    t0, x0, y0 = track[0]
    yaw = 0.0
    if len(track) > 1:
        yaw = math.degrees(math.atan2(track[1][2] - y0, track[1][1] - x0))
    return Person(x=x0, y=y0, length=depth, width=width, height=height, yaw_deg=yaw,
                  track=tuple(tuple(float(v) for v in p) for p in track), albedo=albedo,
                  lower_albedo=lower_albedo, name=f'person {height * 100:.0f} cm', **kw)
