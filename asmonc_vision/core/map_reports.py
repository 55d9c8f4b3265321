"""The evidence map's confirmed objects as the detector's reports (`/obstacles`).

`objects_to_obstacles` turns the map's objects (`core.evidence_map.MapObject`, in the
current pair's ground frame) and the pair's detector reports into the reports published:
the detector's reports the map confirms, the map's own placements of the regions that
confirm none, a region's part in the walking corridor when none of its reports is
there, and the edge of a drop-off seen on both sides of the corridor where it crosses
it (`drop_spans`, rule_drop_span) (docs/map.md, *Objects*).
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from asmonc_vision.core.camera import (MetricPlane, StereoCamera, ground_range_bearing,
                                       plane_disparity, plane_from_metric)
from asmonc_vision.core.evidence_map import MapObject
from asmonc_vision.core.gpod.results import replaced
from asmonc_vision.core.map_evidence import ground_frame
from asmonc_vision.core.map_settings import DropSpanConfig
from .npfast import flat_nonzero

#: ids of the reports placed by the map itself are region ids offset by this (the
#: detector's track ids of the reports it confirms stay below it)
MAP_ID_BASE = 1_000_000
#: ... and those of a region's part in the walking corridor by this
CORRIDOR_ID_BASE = 2_000_000
#: ... and those of a drop's edge across the corridor (`drop_spans`) by this
SPAN_ID_BASE = 3_000_000


def objects_to_obstacles(objects, cam: StereoCamera, plane: MetricPlane,
                         detections=(), attach_m: float = 0.0,
                         corridor_half_width: float = 0.0,
                         seen_ground: Callable[[np.ndarray], np.ndarray] | None = None,
                         span: DropSpanConfig | None = None) -> list:
    """The map's objects as `core.gpod.GpodObstacle` (the detector's output form), in
    the current left optical frame.

    A detector report (``detections``, GpodObstacle: the pair's detections and tracks)
    whose foot lies within ``attach_m`` of a cell of an object of its kind is confirmed:
    it is reported as the detector placed it (its nearest point from the whole
    silhouette; the map sees only matched edges), with the object's confidence and its
    own track id (the object's id + ``MAP_ID_BASE`` when it has none). An object that
    confirms no report is reported as the map places it, id its region id +
    ``MAP_ID_BASE``: ``position`` the top above the nearest point (for a drop, the lowest
    point), range and bearing along the ground, the image region of the region's feet
    and tops (clipped to the image), disparity excess at the top. Reports on no
    confirmed cell are not reported, nor raised ones whose foot ``seen_ground`` judges
    seen as ground ((M, 2) feet in G, m -> (M,) bool; `EvidenceMap.ground_seen_around`):
    no cell nearby confirms a thing where the map saw ground.

    The part in the walking corridor (``corridor_half_width`` > 0: cells ahead within
    it of the walking direction): an object with cells there none of whose reports
    lies in the corridor (a kerb or a wall beside the path whose nearest point is just
    beside it, while the thing reaches into the path farther on) is reported there too,
    at its nearest cell in the corridor, id its region id + ``CORRIDOR_ID_BASE``: the
    alarm sees one point of each report.

    A drop's edge across the corridor (``span`` enabled, `drop_spans`): reported at its
    crossing, id the nearer side's region id + ``SPAN_ID_BASE``."""
    Rcg, o = ground_frame(plane)
    n = np.asarray(plane.normal_up, float)
    dets = list(detections)
    det_xy = np.array([((d.position - d.height * n) - o) @ Rcg[:, :2] for d in dets]
                      ).reshape(-1, 2)
    det_drop = np.array([d.is_drop for d in dets], bool)
    on_ground = np.zeros(len(dets), bool)
    judge = ~det_drop & np.isfinite(det_xy[:, 0]) & np.isfinite(det_xy[:, 1])
    if seen_ground is not None and attach_m > 0 and judge.any():
        on_ground[judge] = seen_ground(det_xy[judge])
    taken = np.zeros(len(dets), bool)
    out = []
    for ob in objects:
        mine = []
        cand: np.ndarray = np.zeros(0, np.int64)
        if attach_m > 0 and len(dets):
            # (np.linalg.norm's arithmetic over the last axis: the root of the sum of
            # the two squares)
            dx = det_xy[:, None, 0] - ob.far_xy[None, :, 0]
            dy = det_xy[:, None, 1] - ob.far_xy[None, :, 1]
            dist = np.sqrt(dx * dx + dy * dy).min(axis=1)
            cand = flat_nonzero((dist <= attach_m) & (det_drop == ob.is_drop)
                                  & ~on_ground)
        if cand.size:
            for k in cand[~taken[cand]].tolist():
                taken[k] = True
                tid = dets[k].track_id or (int(ob.object_id) + MAP_ID_BASE)
                mine.append(replaced(dets[k], track_id=int(tid),
                                     confidence=float(ob.confidence)))
            reported = det_xy[cand]
        else:
            mine.append(_map_report(ob, ob.nearest_xy, int(ob.object_id) + MAP_ID_BASE,
                                    cam, plane))
            reported = ob.nearest_xy[None, :]
        if corridor_half_width > 0:
            g = ob.far_xy
            inside = (g[:, 0] > 0) & (np.abs(g[:, 1]) <= corridor_half_width)
            if inside.any() and not (np.abs(reported[:, 1]) <= corridor_half_width).any():
                gi = g[inside]
                near = gi[int(np.argmin(np.hypot(gi[:, 0], gi[:, 1])))]
                mine.append(_map_report(ob, near, int(ob.object_id) + CORRIDOR_ID_BASE,
                                        cam, plane))
        out.extend(mine)
    if span is not None and span.enabled and corridor_half_width > 0:
        for ob, xy in drop_spans(objects, span, corridor_half_width, seen_ground):
            out.append(_map_report(ob, xy, int(ob.object_id) + SPAN_ID_BASE, cam, plane))
    out.sort(key=lambda d: d.range)
    return out


def drop_spans(objects, config: DropSpanConfig, corridor_half_width: float,
               seen_ground: Callable[[np.ndarray], np.ndarray] | None = None
               ) -> list[tuple[MapObject, np.ndarray]]:
    """rule_drop_span: the edges of drop-offs that cross the walking corridor unseen.

    A step down or a kerb down is a straight edge across the path. Its lower ground is
    seen only where the ground beyond it shows matched edges; on a plain pavement that
    can be a slab joint on either side of the path and nothing in the middle (step_down
    900011, chest rig: the map confirmed the drop 0.6-1.3 m to each side of the path,
    nothing inside the walking corridor). Two confirmed drop regions (``objects``,
    MapObject in the current ground frame G, x ahead, y left) ahead on either side of
    the walking line and none in the corridor: the line through their nearest points
    crosses the corridor at the edge, reported when
    - the two lie at most ``max_gap_m`` apart across the path and the line is within
      ``max_skew_deg`` of the across direction;
    - neither side's lower ground continues towards the wearer: no confirmed drop cell
      within ``band_m`` of its nearest point across the path lies more than
      ``min_lead_m`` nearer (drops along both sides of a raised walkway are nearest at
      the near edge of the view and go on below it, an edge across the path is nearest
      at the edge);
    - ``seen_ground`` ((M, 2) points in G -> (M,) bool, the map's ground seen finely of
      late) says no ground at the crossing nor ``ground_margin_m`` beyond it (the
      ground of a ramp between two kerbs).

    Returns:
        [(the nearer side's MapObject, (2,) float64 the crossing in G, m)], one per
        left region at most (its best partner: the smallest skew), nearest first.
    """
    drops = [o for o in objects if o.is_drop and o.nearest_xy[0] > 0]
    if len(drops) < 2:
        return []
    cells = np.vstack([o.far_xy for o in drops])
    if ((cells[:, 0] > 0) & (np.abs(cells[:, 1]) <= corridor_half_width)).any():
        return []               # a drop in the corridor is reported as it is

    def edge_end(o: MapObject) -> bool:
        x, y = o.nearest_xy
        beside = np.abs(cells[:, 1] - y) <= config.band_m
        return not (beside & (cells[:, 0] < x - config.min_lead_m)).any()

    left = [o for o in drops if o.nearest_xy[1] > 0 and edge_end(o)]
    right = [o for o in drops if o.nearest_xy[1] < 0 and edge_end(o)]
    tan_skew = math.tan(math.radians(config.max_skew_deg))
    out = []
    for a in left:
        best = None
        for b in right:
            (xa, ya), (xb, yb) = a.nearest_xy, b.nearest_xy
            gap = ya - yb
            skew = abs(xa - xb)
            if gap > config.max_gap_m or skew > tan_skew * gap:
                continue
            if best is None or skew < best[0]:
                best = (skew, b, xa + (xb - xa) * ya / gap)
        if best is None:
            continue
        _, b, x = best
        if seen_ground is not None and seen_ground(
                np.array([[x, 0.0], [x + config.ground_margin_m, 0.0]])).any():
            continue
        near = a if float(np.hypot(*a.nearest_xy)) <= float(np.hypot(*b.nearest_xy)) else b
        out.append((near, np.array([x, 0.0])))
    out.sort(key=lambda p: float(p[1][0]))
    return out


def _map_report(ob: MapObject, near_xy: np.ndarray, track_id: int, cam: StereoCamera,
                plane: MetricPlane):
    """A GpodObstacle of a map object placed by the map at ``near_xy`` (G, m)."""
    from asmonc_vision.core.gpod import GpodObstacle

    Rcg, o = ground_frame(plane)
    n = np.asarray(plane.normal_up, float)
    foot = Rcg @ np.array([near_xy[0], near_xy[1], 0.0]) + o
    top = foot + ob.height * n
    rng_, brg = ground_range_bearing(plane, foot[None, :])
    g = ob.far_xy
    feet = (Rcg @ np.column_stack([g, np.zeros(len(g))]).T).T + o
    allp = np.vstack([feet, feet + max(ob.height, 0.0) * n[None, :], top[None, :]])
    allp = allp[allp[:, 2] > 0.1]
    roi = (0, 0, 0, 0)
    excess = 0.0
    if allp.shape[0]:
        uu, vv = cam.project_left(allp)
        # np.clip of these scalars as Python's min and max (the same ints; NaN raises)
        x0 = int(min(max(np.floor(uu.min()), 0.0), cam.width - 1.0))
        x1 = int(min(max(np.ceil(uu.max()), 0.0), cam.width - 1.0))
        y0 = int(min(max(np.floor(vv.min()), 0.0), cam.height - 1.0))
        y1 = int(min(max(np.ceil(vv.max()), 0.0), cam.height - 1.0))
        roi = (x0, y0, max(x1 - x0, 1), max(y1 - y0, 1))
    if top[2] > 0.1:
        u, v, d = cam.project(top[None, :])
        excess = float(d[0] - plane_disparity(plane_from_metric(cam, plane), u, v)[0])
    return GpodObstacle(
        position=top, height=float(ob.height), range=float(rng_[0]),
        bearing=float(brg[0]), width=float(ob.width), disparity_excess=excess,
        confidence=float(ob.confidence), roi=roi,
        num_edge_pixels=int(ob.fresh_pixels),
        string_ids=np.zeros(0, np.int32), track_id=track_id,
        age_s=float(ob.age_s))
