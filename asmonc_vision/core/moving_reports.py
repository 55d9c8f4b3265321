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

`TallReports.passing` says which of a pair's detector reports pass the map (and
`ChainedReports.passing` which go out after the map was cleared, until it confirms again:
chained over ``unmapped_frames`` pairs):

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

from asmonc_vision.core.camera import columns

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
        xy = columns(r * np.cos(b), r * np.sin(b))[kind]
        chain = _chain(xy, self._xy, self._chain, self._stamp_s, stamp_s,
                       self.moving_gate_m, self.moving_max_speed_mps)
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


class ChainedReports:
    """Which detector reports go out after the evidence map was cleared (it had
    confirmed, then lost the camera's motion while walking) until it has placed
    ``EvidenceMapConfig.min_placed_pairs`` pairs in a row again: those that end a chain
    of ``frames`` pairs (as `TallReports`', of any height; raised reports chain with
    raised ones, drops with drops), so that one pair's ghost (a refit pitched a few
    degrees off for a pair, a mismatch) does not reach the wearer. Unknown ground ahead
    (NaN height) always goes out. (At a start, `core.perception.Perception` publishes the
    detector's reports as they are.)

    A wide drop is not held back (``drop_frames`` 1): its lower ground is hidden behind
    its edge, and the detector finds it in a pair here and there (on tuning walk
    step_down 1011, chest rig, a 21 cm step down in one pair only, 3.6 m ahead, 3.9 m
    wide: held back, it was never warned). A drop narrower than ``drop_min_width_m``
    chains as a raised report does (``frames``): a drop the wearer can step off is wide,
    as the map's ``min_drop_cells`` says; one pair's narrow patch below the plane is a
    refit off for a pair (held-out kerb_ramp 900017, chest rig: 35 cm deep, 0.55 m wide,
    4.5 m ahead, in the pair whose plane rose 9 cm).

    Args:
        frames: pairs in a row a raised report's chain must span (1: every one goes
            out).
        drop_frames: the same for a drop at least ``drop_min_width_m`` wide.
        gate_m, max_speed_mps: as `TallReports`' ``moving_gate_m`` and
            ``moving_max_speed_mps``.
        drop_min_width_m: a narrower drop chains over ``frames`` pairs, m (0: every
            drop over ``drop_frames``).
    """

    def __init__(self, frames: int, drop_frames: int, gate_m: float,
                 max_speed_mps: float, drop_min_width_m: float = 0.0) -> None:
        self.frames = int(frames)
        self.drop_frames = int(drop_frames)
        self.drop_min_width_m = float(drop_min_width_m)
        self.gate_m = float(gate_m)
        self.max_speed_mps = float(max_speed_mps)
        self.reset()

    def reset(self) -> None:
        """Forget the previous pair."""
        self._stamp_s: float | None = None
        #: the previous pair's raised (0) and drop (1) reports' feet and chain lengths
        self._xy: dict[int, np.ndarray] = {k: np.zeros((0, 2)) for k in (0, 1)}
        self._chain: dict[int, np.ndarray] = {k: np.zeros(0, np.int64) for k in (0, 1)}

    def passing(self, stamp_s: float, height: np.ndarray, range_m: np.ndarray,
                bearing: np.ndarray, width: np.ndarray | None = None) -> np.ndarray:
        """Which of a pair's reports go out (arguments as `TallReports.passing`;
        ``width`` (N,) m across the line of sight, None: every drop wide); call once per
        pair, in stamp order, whether or not the map confirms. (N,) bool."""
        h = np.asarray(height, float).reshape(-1)
        r = np.asarray(range_m, float).reshape(-1)
        b = np.asarray(bearing, float).reshape(-1)
        w = np.full(len(h), np.inf) if width is None else np.asarray(width, float).reshape(-1)
        known = np.isfinite(h)
        xy = columns(r * np.cos(b), r * np.sin(b))
        out = ~known
        chains = {}
        for k, sel in enumerate((known & (h >= 0), known & (h < 0))):   # raised, drops
            chains[k] = _chain(xy[sel], self._xy[k], self._chain[k], self._stamp_s,
                               stamp_s, self.gate_m, self.max_speed_mps)
            self._xy[k] = xy[sel]
            need = (self.frames if k == 0 else
                    np.where(w[sel] >= self.drop_min_width_m, self.drop_frames, self.frames))
            out[sel] = chains[k] >= need
        self._chain = chains
        self._stamp_s = float(stamp_s)
        return out

    @classmethod
    def from_config(cls, c) -> 'ChainedReports':
        """From an `EvidenceMapConfig`."""
        return cls(c.unmapped_frames, c.unmapped_drop_frames, c.moving_gate_m,
                   c.moving_max_speed_mps, c.unmapped_drop_min_width_m)


def _chain(xy: np.ndarray, prev_xy: np.ndarray, prev_chain: np.ndarray,
           prev_stamp_s: float | None, stamp_s: float, gate_m: float,
           max_speed_mps: float) -> np.ndarray:
    """(n,) int64 chain lengths of the reports at ``xy`` (n, 2) m: 1 + the longest chain
    among the previous pair's reports ``prev_xy`` (m, 2) (chains ``prev_chain`` (m,))
    within ``gate_m`` + ``max_speed_mps`` times the time between the pairs; 1 with none
    or over a gap of more than MAX_GAP_S."""
    chain = np.ones(len(xy), np.int64)
    dt = math.inf if prev_stamp_s is None else stamp_s - prev_stamp_s
    if len(xy) and len(prev_xy) and 0.0 <= dt <= MAX_GAP_S:
        gate = gate_m + max_speed_mps * dt
        d = np.linalg.norm(xy[:, None, :] - prev_xy[None, :, :], axis=2)    # (n, m)
        prev = np.where(d <= gate, prev_chain[None, :], 0).max(axis=1)
        chain = 1 + prev
    return chain


def report_arrays(obstacles: Sequence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(height, range, bearing), each (N,) float64, of reports with those attributes."""
    return (np.array([o.height for o in obstacles], float),
            np.array([o.range for o in obstacles], float),
            np.array([o.bearing for o in obstacles], float))
