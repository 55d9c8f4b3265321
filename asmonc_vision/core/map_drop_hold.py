"""rule_drop_hold: a confirmed drop whose edge has left the view is held until it is reached.

The evidence map's heights are heights above each pair's ground plane
(`core.evidence_map`), and that plane is fitted to the ground the pair sees. A level
chest camera sees the ground from about 2.4 m on. Walking up to a step down, once its
edge leaves the bottom of the view all the ground in view is the lower ground beyond
it, and the plane found there (`core.gpod.plane_tracking`: lost and recovered, or walked
onto it by refits) is that lower ground. Against such a plane the lower ground where the
map confirmed the drop is ground seen free, and it clears the drop within a few pairs:
the wearer is told "all clear" a metre or two before the edge.

A drop's edge that has left the bottom of the view cannot be seen again before the
wearer reaches it, so nothing this pair sees of its lower ground can tell whether it is
still there. The rule holds such a drop: the cells of a confirmed drop region whose
nearest point lies ahead of the wearer and at most ``margin_m`` beyond the nearest
ground in view keep their drop log-odds through the pair (no ground seen free, no miss,
no decay takes from them) until the wearer has passed that point. A drop the map has
confirmed is then reported from memory up to its edge, as a thing walked up to is.
Once the wearer has passed it (stepped down), its cells nearer than the reach are let
go: the lower ground the wearer now stands on, which no pair sees before it is
underfoot, would otherwise be remembered as a drop at the wearer's feet. So are the
other confirmed drop cells at its level (within ``level_tol_m`` of its median height),
and none of those is held again: the map reports the part of a region in view and the
part below the view as two regions, and the lower ground still in view as the wearer
steps down, not yet cleared, slips below the view as a region of its own, which would
be held as a new drop up to the wearer's feet (tuning kerb_cross 1002, backpack rig: a
false "stop, drop, half a metre" for 1.3 s after stepping down). A second step further
down stands a step's height below that level, and is not let go.

Only a region some of whose cells were confirmed while its nearest point lay beyond
that reach is held: a drop confirmed while the ground before its edge was in view,
against a plane fitted there. Lower ground first confirmed once its edge was already at
the bottom of the view was judged against a plane fitted to little of the ground before
it: the far side of a crest, measured against the rising ground before the brow, stands
30 cm below it and is confirmed as a drop for a pair or two (tuning crest 1055, chest
rig); held, that one pair's CAUTION became a WARNING and a STOP.

What it costs: a drop confirmed wrongly from afar that is still confirmed when it
reaches the bottom of the view is held to the wearer's feet (it was being reported
anyway). No ROS here.

Frames: the pair's ground frame G (`core.map_evidence`: x forward along the optical
axis laid on the plane, y left, origin below the left camera), metres.
"""
from __future__ import annotations

import math

import numpy as np

from asmonc_vision.core.camera import MetricPlane, StereoCamera, ground_axes
from asmonc_vision.core.map_settings import DropHoldConfig

_NONE = np.zeros(0, np.int64)


def nearest_ground_in_view(cam: StereoCamera, plane: MetricPlane) -> float:
    """Range along the ground of the nearest ground the left image shows.

    Args:
        cam: the rectified stereo camera.
        plane: the pair's ground plane, left optical frame.
    Returns:
        m, G's x of the point where the sight line of the bottom row's centre pixel meets
        the plane; inf when that sight line does not meet it ahead (it looks level or up).
    """
    ray = np.array([0.0, (cam.height - 1 - cam.cy) / cam.f, 1.0])
    n = np.asarray(plane.normal_up, float)
    down = -float(ray @ n)                 # how fast the sight line sinks towards the plane
    if down <= 1e-9:
        return math.inf
    origin, fwd, _ = ground_axes(plane)
    p = ray * (float(plane.height) / down)
    return float((p - origin) @ fwd)


class DropHold:
    """Which confirmed drop cells to hold through a pair, and which to let go (module
    docstring). Keeps, for each region held, the nearest point of its cells seen while
    held (in the map's world frame W), and the ids of the regions let go (walked past:
    not held again); the map keeps which cells were confirmed in a region whose nearest
    point lay beyond the reach (``before``: only regions with such cells are held)."""

    def __init__(self, config: DropHoldConfig) -> None:
        self.config = config
        self._edge: dict[int, np.ndarray] = {}
        self._passed: set[int] = set()

    def reset(self) -> None:
        """Forget the regions held and passed (the map was cleared)."""
        self._edge = {}
        self._passed = set()

    def cells(self, cells: np.ndarray, region: np.ndarray, cell_w: np.ndarray,
              to_ground, cam: StereoCamera | None, plane: MetricPlane | None,
              before: np.ndarray, heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The confirmed drop cells to hold through this pair, and those to let go.

        Args:
            cells: (K,) int64 flat indices of the confirmed drop cells.
            region: (K,) int32 the id of the region each belonged to when last reported
                (0: none; not held).
            cell_w: (K, 2) float64 their evidence points in W, m.
            to_ground: callable (N, 2) points of W -> (N, 2) in this pair's G, m.
            cam: the stereo camera (None: nothing is held).
            plane: this pair's ground plane (None: nothing is held).
            before: (n * n,) bool per map cell, set here (in place) for the cells of a
                region whose nearest point lies beyond the reach: a drop confirmed while
                the ground before its edge was in view, against a plane fitted there. A
                region confirmed only once its edge had reached the bottom of the view
                (the far side of a crest, confirmed against a plane fitted to the rising
                ground before the brow) is not held.
        Returns:
            ((H,) int64 the cells held: those of each region whose nearest point lies
            ahead within ``margin_m`` of the nearest ground in view and some of whose
            cells were confirmed farther; (G,) int64 the cells
            let go: once the wearer has passed the nearest point a held region showed,
            its cells and every confirmed drop cell within ``level_tol_m`` of its
            median height, nearer than the reach (the lower ground the wearer stepped
            down onto, which no pair sees before it is underfoot); the cells at its
            level are not held again).
        """
        keep = region > 0
        # a region id once gone from the map does not come back: forget it
        self._passed &= set(region[keep].tolist())
        if not self.config.enabled or cam is None or plane is None or not keep.any():
            self._edge = {}
            return _NONE, _NONE
        cells, region, cell_w, h = cells[keep], region[keep], cell_w[keep], heights[keep]
        x = to_ground(cell_w)[:, 0]
        view = nearest_ground_in_view(cam, plane)
        reach = view + self.config.margin_m
        held = np.zeros(cells.size, bool)
        gone = np.zeros(cells.size, bool)
        edges: dict[int, np.ndarray] = {}
        nearest: dict[int, tuple[float, np.ndarray, np.ndarray]] = {}
        for oid in np.unique(region).tolist():
            if oid in self._passed:
                continue
            mine = np.flatnonzero(region == oid)
            j = mine[np.argmin(x[mine])]
            near, near_w = float(x[j]), cell_w[j]
            edge = self._edge.get(oid)
            if edge is not None:
                at = float(to_ground(edge[None])[0, 0])
                if at < near:                   # the nearer point seen while held stands
                    near, near_w = at, edge
                if near <= 0.0:                 # walked past: the wearer stepped down
                    self._passed.add(oid)
                    # onto its lower ground, which the map may hold in other regions
                    # too (the part in view and the part below it are reported apart):
                    # every confirmed drop cell at its level is that ground
                    level = float(np.median(h[mine]))
                    same = np.abs(h - level) <= self.config.level_tol_m
                    same[mine] = True
                    gone |= same & (x < reach)
                    before[cells[same]] = False
                    continue
            nearest[oid] = (near, near_w, mine)
        for oid, (near, near_w, mine) in nearest.items():
            if near > reach:
                before[cells[mine]] = True
            elif near > 0.0 and before[cells[mine]].any():
                held[mine] = True
                edges[oid] = near_w
        held &= ~gone
        self._edge = edges
        return cells[held], cells[gone]
