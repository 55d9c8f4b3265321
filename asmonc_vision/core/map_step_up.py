"""rule_step_up: raised ground the wearer has walked onto is the ground they stand on.

The evidence map's heights are heights above each pair's ground plane
(`core.evidence_map`). Walking up to a kerb, the raised footway beyond it is confirmed as
a thing 10-20 cm high, and rightly: the wearer is told of the kerb. Once the wearer has
stepped up, the pairs' planes are the footway, and the footway the camera sees is ground
again: it clears the cells in view. The cells nearer than the view (a chest camera sees
the ground from about 2 m on, the paper's rig from about 1.4 m) are seen by no pair
before they are underfoot, and the map would report them from memory as an obstacle at
the wearer's feet: "stop, obstacle, half a metre" for a second or two after every kerb
climbed (tuning kerb_cross 1003, both rigs).

No pair measures the level the wearer stands on well enough to carry the heights over
(the height of one pair's ground over the previous pair's varies by 4-8 cm at the 95th
percentile on level walks, and jumps by 22-45 cm at a kerb, often half or all of it
back the next pair). What does tell is where the wearer has walked: a body cannot
pass through a thing standing on its path. Confirmed raised cells on the wearer's path
just behind the wearer (from ``behind_m`` to ``behind_m + depth_m`` back, within
``half_width_m`` of the path), at least ``min_cells`` of them, whose median height is a
step (at most ``max_height_m``; a wall or a person is never walked onto, and cells of
one behind the wearer are the map's pose error, not ground), were stepped onto or over.
Every confirmed raised cell at or below that level (at most ``level_tol_m`` above the
median) nearer than the ground in view plus ``margin_m``, and joined to the cells walked
over through such cells (8-connected, as the map's regions), is let go: the footway under
and before the wearer, seen from below the kerb, and the kerb's own face, measured lower
(what stood less than a step above the old ground is below the new one). A thing
standing on the footway stands its own height above that level, and stays; so does a
low thing apart from it (walking past a low box at the path's edge does not let go
another one ahead).

Standing before a kerb, its cells lie ahead of the wearer: the map's pose drifts by
centimetres while the wearer stands, and the kerb is let go only once the wearer has
walked ``behind_m`` onto it. No ROS here.

Frames: the pair's ground frame G (`core.map_evidence`: x forward along the optical
axis laid on the plane, y left, origin below the left camera), metres.
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core.map_settings import StepUpConfig


def stepped_onto(xy: np.ndarray, height: np.ndarray, view_m: float, config: StepUpConfig
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The confirmed raised cells the wearer has stepped up onto (module docstring).

    Args:
        xy: (K, 2) float64 the confirmed raised cells' evidence points in this pair's G,
            m.
        height: (K,) float the cells' heights above the ground they were measured on, m.
        view_m: G's x of the nearest ground the pair's image shows, m (inf: none).
    Returns:
        ((K,) bool the cells at or below the level walked onto and nearer than the
        reach, (K,) bool the cells walked over); both all False when the wearer has
        walked onto no step. The caller lets go those of the first connected to the
        second (a low thing apart from the footway is not its ground).
    """
    none = np.zeros(len(xy), bool)
    c = config
    if not c.enabled or not len(xy):
        return none, none
    x, y = xy[:, 0], xy[:, 1]
    walked = ((x <= -c.behind_m) & (x >= -(c.behind_m + c.depth_m))
              & (np.abs(y) <= c.half_width_m))
    if int(walked.sum()) < c.min_cells:
        return none, none
    level = float(np.median(height[walked]))
    if not 0.0 < level <= c.max_height_m:
        return none, none
    reach = view_m + c.margin_m
    return (height <= level + c.level_tol_m) & (x < reach), walked
