"""rule_ground_step: a step of the ground across the walking corridor is map evidence.

GPOD (Molton et al. 1998) finds an obstacle pixel by pixel: an edge pixel whose disparity
stands more than the threshold above the ground plane's. A kerb across the path is a
poor subject for that test on a short baseline. Its edges run along the image rows,
which stereo matching along the rows hardly measures, and what is matched of it stands
little above the ground: a 10 cm kerb 3.6 m ahead of a chest rig (12 cm baseline, camera
1.4 m up) stands about 1.5 px above the ground's disparity, under the 1.7 px threshold.
No pixel of it counts, the map (`core.evidence_map`) gets no raised evidence, and the
wearer walks into the kerb with "all clear" in force.

The ground surface ahead (`core.ground_surface`) sees such a kerb all the same, from
many pixels at once: the segment that contains it is a line plus a step, and the known
surface ends before it (``rule_step``; a step down is often refused first for the fall
of its grade, ``rule_grade``). The segment's check records the step's height and place
(`SegmentCheck.step_m`, ``step_at_m``). This module turns that step into evidence for
the map (`ground_step`, then `step_evidence`):

* heights are taken over the ground at the step's foot: the known surface, offset by
  the median height over it of the features within ``band_m`` before the step and
  ``gate_m`` of the surface (when there are ``min_features`` of them; a plane tilted
  towards the raised ground beyond a kerb puts the kerb's foot below the surface);
* its support is the features beyond it, within ``band_m`` and ``support_half_width_m``
  of the walking line, that stand over the ground at its foot on its side (up for a
  kerb, down for a drop) by at most the step plus ``gate_m``; their median is the far
  side's level, and those within ``level_share`` of it are the support (the stepped
  ground, not a thing standing on it): at least ``min_features`` of them, spread at
  least ``min_width_m`` across the path (the foot of a post or a box is narrow),
  ``min_corridor_features`` of them within ``half_width_m`` of the walking line (the
  kerbs either side of a kerb ramp step, the ramp between them does not), their median
  at least ``min_step_m`` over (or under) the foot: the step's height, its standard
  deviation from the spreads of both sides; a step up lies where its support begins
  (the segment can end short of a kerb), a step down where the segment ends (its lower
  side begins beyond the edge, hidden behind it);
* the evidence is the step itself: points on the ground from the step to ``depth_m``
  beyond it, one per map cell across the walking corridor (``half_width_m`` either
  side), raised (a step up) or drop (a step down), at the step's height. A kerb across
  the path crosses the corridor whether or not every cell of it shows a feature;
* the support's features are not ground seen free (`core.perception.Perception.evidence`):
  they are ground, but not the ground the plane is, and would clear the step's cells.

Each pixel of the far side is under the threshold; together they are not. The map
confirms the step as it confirms anything else: in the world, from two viewpoints, over
pairs; a step found in the ground's noise wanders with the viewpoint and does not stay
in one cell.

Frames: points in the left optical frame (REP 103: x right, y down, z forward),
metres; the surface's (s, l, h): along the ground ahead, to the left, up. No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .ground_plane import fast_median
from .ground_surface import GroundSurface
from .map_evidence import DROP, RAISED, PairEvidence
from .map_settings import GroundStepConfig


@dataclass(frozen=True)
class GroundStep:
    """A step of the ground ahead taken as evidence (`ground_step`).

    Attributes:
        at_m: where the ground steps, metres along the ground from the point below the
            camera (the surface's s): a step up where its support begins (the
            ``RAISED_SIDE_PERCENTILE`` of its distances, when beyond the segment's place
            of the step), a step down where the segment put it.
        height_m: the step's height, metres (negative: a step down): the median height
            of its support over the ground at its foot.
        sigma_m: its standard deviation, metres: from the robust spreads of the support's
            heights and of the foot's, each over the square root of its number.
        far: (N,) bool over the points given: the far side's features on its level
            within ``band_m`` of the step (its support: ground, but not at the level of
            the ground before the step).
    """

    at_m: float
    height_m: float
    sigma_m: float
    far: np.ndarray


#: A step up lies where its support begins: this percentile of their distances along
#: the ground (a few features of the far side may be matched short of it). A step
#: down's lower side begins beyond its edge, hidden behind it: the segment's place stands.
RAISED_SIDE_PERCENTILE = 5.0

#: The rules whose refusal of a segment leaves its step measured (`SegmentCheck.step_m`):
#: a step down across the path is often refused first for the fall of its grade.
_STEPPED = ('rule_grade', 'rule_step', 'rule_spread')


def may_step(surface: GroundSurface | None, config: GroundStepConfig) -> bool:
    """Whether the known ``surface`` ends at a measured step (``rule_step``,
    ``rule_grade`` or ``rule_spread`` refused the segment beyond it, whose check has a
    step and its place) and the rule is on: `ground_step` may find one."""
    if not config.enabled or surface is None or not surface.checks:
        return False
    check = surface.checks[-1]
    return (check.refused_by in _STEPPED and math.isfinite(check.step_m)
            and check.step_m != 0.0 and math.isfinite(check.step_at_m))


def ground_step(surface: GroundSurface | None, points: np.ndarray,
                config: GroundStepConfig) -> GroundStep | None:
    """The step of the ground ahead where the known surface ends at a measured step
    (`may_step`), as the module doc tells, or None (no such surface, fewer than
    ``min_features`` features on its far side's level within ``band_m``, a step under
    ``min_step_m``, a far side narrower than ``min_width_m`` or with fewer than
    ``min_corridor_features`` in the corridor).

    Args:
        surface: the pair's ground surface ahead (`core.ground_surface`), or None.
        points: (N, 3) float the pair's matched features, left optical frame, metres.
        config: the rule's settings.
    Returns:
        The GroundStep, or None.
    """
    if not may_step(surface, config):
        return None
    assert surface is not None
    check = surface.checks[-1]
    step, at = float(check.step_m), float(check.step_at_m)
    s, lat, h = surface.coordinates(np.asarray(points, float).reshape(-1, 3))
    # heights over the ground just before the step: the known surface (continued
    # beyond it at its tail grade) and the median offset from it of the ground pixels
    # within band_m before the step (a kerb is a step from the ground at its foot; a
    # plane tilted towards the ground beyond it puts that foot below the surface)
    over = h - surface.profile(s)
    wide = np.abs(lat) <= config.support_half_width_m
    with np.errstate(invalid='ignore'):
        near = wide & (s >= at - config.band_m) & (s < at) & (np.abs(over) <= config.gate_m)
    n_near = int(np.count_nonzero(near))
    base = fast_median(over[near]) if n_near >= config.min_features else 0.0
    rel = over - base
    with np.errstate(invalid='ignore'):
        band = (wide & (s >= at) & (s <= at + config.band_m)
                & (np.abs(rel) <= abs(step) + config.gate_m) & (rel * step > 0.0))
    if np.count_nonzero(band) < config.min_features:
        return None
    # the far side's level: the band's median height (the segment's own fit of a step
    # near its end leans on few features beyond it, and finds it low), then the median
    # of the band's features on it
    level = fast_median(rel[band])
    far = band & (np.abs(rel - level) <= config.level_share * abs(level))
    n = int(np.count_nonzero(far))
    if n < config.min_features:
        return None
    lv = rel[far]
    height = fast_median(lv)
    if not abs(height) >= config.min_step_m:
        return None
    if float(np.subtract(*np.percentile(lat[far], [90, 10]))) < config.min_width_m:
        return None     # narrow: the foot of a thing, not the ground beyond a step
    if np.count_nonzero(np.abs(lat[far]) <= config.half_width_m) < config.min_corridor_features:
        return None     # not seen crossing the corridor (kerbs either side of a ramp)
    if height > 0:
        # a step up is where its raised side begins: the segment's place of the step can
        # lie short of it (a level chest rig sees little ground before a kerb), and
        # evidence short of a kerb falls in other cells as the wearer comes nearer
        at = max(at, float(np.percentile(s[far], RAISED_SIDE_PERCENTILE)))
    var = (1.4826 * fast_median(np.abs(lv - height))) ** 2 / n
    if n_near >= config.min_features:
        ln = over[near]
        var += (1.4826 * fast_median(np.abs(ln - base))) ** 2 / n_near
    return GroundStep(at_m=at, height_m=height, sigma_m=max(math.sqrt(var), 1e-3), far=far)


def step_evidence(step: GroundStep, config: GroundStepConfig, cell_m: float,
                  per_cell: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The map evidence of a step: points on the ground just beyond it, across the
    walking corridor.

    Args:
        step: the step (`ground_step`).
        config: the rule's settings (``half_width_m``: the corridor's half width;
            ``depth_m``: how far beyond the step).
        cell_m: the map's cell side, metres.
        per_cell: points at each place (>= 1).
    Returns:
        xy: (K, 2) float64 points in the pair's ground frame G (x forward along the
            ground, y left, metres): every ``cell_m`` from ``cell_m / 2`` to
            ``depth_m`` beyond the step, and from ``-half_width_m`` to
            ``half_width_m`` across, ``per_cell`` at each;
        height: (K,) float64 the step's height there, metres;
        sigma_h: (K,) float64 its standard deviation, metres.
    """
    y = np.arange(-config.half_width_m, config.half_width_m + 1e-9, cell_m)
    x = step.at_m + np.arange(0.5 * cell_m, max(config.depth_m, 0.5 * cell_m) + 1e-9, cell_m)
    xx, yy = np.meshgrid(x, y, indexing='ij')
    xy = np.repeat(np.stack([xx.ravel(), yy.ravel()], axis=1), max(int(per_cell), 1), axis=0)
    k = xy.shape[0]
    return xy, np.full(k, step.height_m), np.full(k, step.sigma_m)


def with_step(ev: PairEvidence, step: GroundStep, config: GroundStepConfig, cell_m: float,
              min_drop_pixels: int) -> PairEvidence:
    """A pair's evidence with the step's appended (`step_evidence`): raised points for a
    step up, drop points for a step down (``min_drop_pixels`` at each place, as many as
    the map asks of one pair's drop pixels in a cell), each counting fully.

    Args:
        ev: the pair's evidence (`core.map_evidence.pair_evidence`, ground frame G).
        step: the step (`ground_step`).
        config: the rule's settings.
        cell_m: the map's cell side, metres.
        min_drop_pixels: the map's ``min_drop_pixels``.
    Returns:
        A new PairEvidence: ``ev``'s points, then the step's.
    """
    up = step.height_m > 0
    xy, height, sigma_h = step_evidence(step, config, cell_m, 1 if up else min_drop_pixels)
    n = height.shape[0]
    return PairEvidence(
        xy=np.concatenate([ev.xy, xy]), height=np.concatenate([ev.height, height]),
        sigma_h=np.concatenate([ev.sigma_h, sigma_h]),
        kind=np.concatenate([ev.kind, np.full(n, RAISED if up else DROP, np.int8)]),
        weight=None if ev.weight is None else np.concatenate([ev.weight, np.ones(n)]))
