"""Tall things that move: the detector's reports that pass the evidence map unconfirmed.

The evidence map (`core.evidence_map`) reports what stays where it is while the view
moves: a mismatched pattern moves in the world, a thing does not. A person walking
towards the wearer moves too. It is in new cells every pair, each seen once, so the map
seldom confirms it, while the detector finds it in pair after pair (tuning walk
people_towards 1022: from 5.4 m on, each pair; the map confirmed it at 1.8 m). What
tells a passer-by from a mismatch is its height and that it goes somewhere. A ground
pattern matched wrongly stands a few centimetres up, rarely half a metre, and comes and
goes from pair to pair. A person's matched legs stand 0.6-0.9 m up, in every pair, along a path a
walker can take.

`TallReports.passing` says which of a pair's detector reports pass the map:

* a report at least ``pass_height_m`` tall (a thing that tall is no ground mismatch)
  passes once it is the last of a *chain* of ``pass_frames`` pairs (one pair's ghost, a
  far wall's texture matched 6 m too near, 2 m tall, in one pair, is not one);
* a report at least ``moving_min_height_m`` tall, no farther than
  ``moving_max_range_m``, passes once it is the last of a chain of ``moving_frames``
  pairs.

A chain is a report of either kind in each of the latest pairs, each no farther from one
in the pair before than ``moving_gate_m`` plus ``moving_max_speed_mps`` times the time
between the two (how far a thing and the wearer can move apart in that time; the
positions are the reports' feet in each pair's ground frame, so no camera motion is
needed). Chains break over a gap of more than ``MAX_GAP_S`` between pairs.

Nothing here is remembered beyond the previous pair: a passer-by who walked on leaves
no report behind. Frames: the ground frame of the pair (x ahead along the walking
direction, y left, metres; `core.camera.ground_range_bearing`'s range and bearing).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Chains end when the pairs are this far apart in time, seconds.
MAX_GAP_S = 0.5


class TallReports:
    """Which detector reports pass the evidence map unconfirmed (see the module doc).

    Args:
        pass_height_m: a report at least this tall passes once chained over
            ``pass_frames`` pairs (0: none does).
        pass_frames: pairs in a row a chain of a pass_height_m report must span (1: at
            once).
        moving_min_height_m: a chained report must be at least this tall (0: no chains).
        moving_frames: pairs in a row a chain must span (1: any tall-enough report).
        moving_gate_m: placement tolerance between chained reports, metres.
        moving_max_speed_mps: fastest the report's foot may move between pairs in the
            wearer's ground frame (the thing's speed and the wearer's together), m/s.
        moving_max_range_m: chained reports farther than this along the ground do not
            count, metres.
    """

    def __init__(self, pass_height_m: float, pass_frames: int, moving_min_height_m: float,
                 moving_frames: int, moving_gate_m: float, moving_max_speed_mps: float,
                 moving_max_range_m: float) -> None:
        self.pass_height_m = float(pass_height_m)
        self.pass_frames = int(pass_frames)
        self.moving_min_height_m = float(moving_min_height_m)
        self.moving_frames = int(moving_frames)
        self.moving_gate_m = float(moving_gate_m)
        self.moving_max_speed_mps = float(moving_max_speed_mps)
        self.moving_max_range_m = float(moving_max_range_m)
        self.reset()

    def reset(self) -> None:
        """Forget the previous pair."""
        self._stamp_s: float | None = None
        self._xy: np.ndarray = np.zeros((0, 2))
        self._chain: np.ndarray = np.zeros(0, np.int64)

    def passing(self, stamp_s: float, height: np.ndarray, range_m: np.ndarray,
                bearing: np.ndarray) -> np.ndarray:
        """Which of a pair's reports pass; call once per pair, in stamp order.

        Args:
            stamp_s: the pair's time, seconds.
            height: (N,) float64 metres above the ground (negative: a drop; NaN: unknown
                ground ahead, which never counts here).
            range_m: (N,) float64 metres along the ground to each report's foot.
            bearing: (N,) float64 radians from the walking direction, positive left.
        Returns:
            (N,) bool.
        """
        h = np.asarray(height, float).reshape(-1)
        r = np.asarray(range_m, float).reshape(-1)
        b = np.asarray(bearing, float).reshape(-1)
        with np.errstate(invalid='ignore'):
            tall = (self.pass_height_m > 0) & (h >= self.pass_height_m)
            moving = ((self.moving_min_height_m > 0) & (h >= self.moving_min_height_m)
                      & (r <= self.moving_max_range_m))
        kind = tall | moving
        xy = np.stack([r * np.cos(b), r * np.sin(b)], axis=1)[kind]
        chain = np.ones(len(xy), np.int64)
        dt = math.inf if self._stamp_s is None else stamp_s - self._stamp_s
        if len(xy) and len(self._xy) and 0.0 <= dt <= MAX_GAP_S:
            gate = self.moving_gate_m + self.moving_max_speed_mps * dt
            d = np.linalg.norm(xy[:, None, :] - self._xy[None, :, :], axis=2)    # (n, m)
            near = d <= gate
            prev = np.where(near, self._chain[None, :], 0).max(axis=1)
            chain = 1 + prev
        self._stamp_s = float(stamp_s)
        self._xy, self._chain = xy, chain
        out = np.zeros(len(h), bool)
        out[kind] = ((tall[kind] & (chain >= self.pass_frames))
                     | (moving[kind] & (chain >= self.moving_frames)))
        return out

    @classmethod
    def from_config(cls, c) -> 'TallReports':
        """From an `EvidenceMapConfig`."""
        return cls(c.pass_height_m, c.pass_frames, c.moving_min_height_m, c.moving_frames,
                   c.moving_gate_m, c.moving_max_speed_mps, c.moving_max_range_m)


def report_arrays(obstacles: Sequence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(height, range, bearing), each (N,) float64, of reports with those attributes."""
    return (np.array([o.height for o in obstacles], float),
            np.array([o.range for o in obstacles], float),
            np.array([o.bearing for o in obstacles], float))
