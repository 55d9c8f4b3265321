"""GPOD's named rules (stages 6-10): the special cases of the obstacle and drop-off test,
each a function of one frame's evidence, run in the order `GpodConfig.rules` lists them
(as nav2 runs the costmap layers its YAML lists).

The test itself is the paper's: a pixel is obstacle evidence when its excess over the
ground is above the threshold in a long enough matched run, drop evidence when it is as
far below, and a string is an obstacle (drop-off) when it holds enough such pixels. The
rules take out evidence that a known failure gives (a periodic pattern matched a period
off, a run hanging over its own string, ground bending away beyond a brow, ...) or add
what the test misses (a region of lower ground), or place an obstacle better than its
own feet do (a face running out of the view). There are four lists:

* ``pixels``: on the obstacle and drop pixels (``FrameEvidence.obst``, ``.drop``);
* ``strings``: on the obstacle strings (``.obst_string``; ``.n_drop`` too);
* ``drops``: on the drop-off strings (``.drop_string``);
* ``placement``: on each obstacle's nearest point (stages 9-10: `Placement`).

A rule left out of its list is off; `docs/gpod.md` says what each costs and gains. No
ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..camera import MetricPlane
from ..edges import EdgeMap
from ..ground_surface import GroundSurface, fall_limit
from ..matching import Candidates, Matches
from . import kernels as kn
from .faces import face_gap_points, lone_face_points, silhouette_owners, view_edge_points
from .footing import _FrameContext, ground_coords
from .grouping import cluster_points_2d
from .nearest import nearest_points
from .runs import (
    continuation_alternatives,
    hanging_runs,
    occluded_matches,
    string_pieces,
)
from .settings import GpodConfig
from ..npfast import flat_nonzero

#: Obstacle pixels this far above the plane (pixels) or more are checked for a match on
#: the lower ground beyond a drop (rule ``lower_ground_continuation``): a repetitive
#: pattern matched one period off; genuine small obstacles are never this far above it.
AMBIGUOUS_EXCESS_PX = 3.0

#: A run hanging over lower ground (rule ``lower_ground_continuation``) is checked only
#: when that ground is seen: at least this fraction of the frame's matches lie on it
#: (beyond a kerb down, 15-70 %; scattered mismatches of obstacle texture that look like
#: a lower ground, at most 1.4 % on the simulator's walks).
LOWER_GROUND_FRACTION = 0.05

#: Rule ``ground_bend``: ground bending away beyond a brow or a dip starts where the
#: ground is; a cluster whose line lies this far off the ground at its near end is a drop
#: or an obstacle whatever its grade (the least step the wearer must be told of, m).
BEND_MAX_START_M = 0.10
#: Rule ``ground_bend``, a line farther off at its near end (`bending_ground`): its own
#: strings lead up to it with at least this many pixels in the last BEND_LEAD_M (m)
#: before it, the last at most BEND_LEAD_GAP_M (m) before it, their median at most
#: BEND_LEAD_TOL_M (m) off the ground bent there (a kerb 10 cm down hides 0.3 m beyond
#: its edge at 4 m on a chest camera, and its lower ground is level: 10 cm off).
BEND_LEAD_MIN = 3
BEND_LEAD_M = 0.5
BEND_LEAD_GAP_M = 0.25
BEND_LEAD_TOL_M = 0.04


@dataclass
class FrameEvidence:
    """One frame's evidence as the rules read and change it: K matches of n_s edge
    strings. Heights in metres above the ground reference, disparities in pixels."""

    m: Matches
    el: EdgeMap                 # left edges (the matches' strings)
    er: EdgeMap                 # right edges
    cand: Candidates            # every candidate match of the left edges
    metric: MetricPlane
    pd: np.ndarray              # (K,) the ground reference's disparity at each match
    pts: np.ndarray             # (K, 3) each match in the camera frame, m
    h: np.ndarray               # (K,) height above the ground reference, m
    excess: np.ndarray          # (K,) disparity excess over the ground
    ex_mean: np.ndarray         # (K,) the excess averaged along runs (and over frames)
    thr: np.ndarray             # (K,) obstacle threshold per match, px
    prev: np.ndarray            # (K,) run links (`run_links`)
    run: np.ndarray             # (K,) matched run length
    usable: np.ndarray          # (K,) bool: reliably matched (long enough run), in range
    below: np.ndarray           # (K,) bool: below the lowest ground the surface allows
    slope: float                # |b| of the plane, px of disparity per row
    weight: np.ndarray          # (K,) evidence weight per match (edge strength)
    min_px: float               # the (weighted) obstacle pixels a string needs
    n_s: int                    # edge strings
    obst: np.ndarray            # (K,) bool: obstacle pixels (rules ``pixels``)
    drop: np.ndarray            # (K,) bool: drop pixels (rules ``pixels``)
    obst_string: np.ndarray | None = None   # (n_s,) bool (rules ``strings``)
    n_drop: np.ndarray | None = None        # (n_s,) weighted drop pixels per string
    drop_string: np.ndarray | None = None   # (n_s,) bool (rules ``drops``)
    surface: GroundSurface | None = None    # the ground surface ahead (None: the plane)
    #: the plane's grade against gravity along the walking direction (rise per metre;
    #: `ground_surface.level_grade`), None: unknown (no inclinometer)
    level: float | None = None
    #: clusterings of pixels by (sign, radius): (pixel indices, feet, labels)
    #: (`bending_ground`'s, for `Detection._clusters` to reuse on the same pixels)
    clustered: dict = field(default_factory=dict)

    @property
    def sid(self) -> np.ndarray:
        """(K,) the edge string of each match."""
        return self.m.string_id

    @property
    def on_ground(self) -> np.ndarray:
        """(K,) bool: the reliable matches that are neither obstacle nor drop pixels
        (what may lead up to a bend, `bending_ground`)."""
        return self.usable & ~self.drop & ~self.obst


Rule = Callable[[GpodConfig, FrameEvidence], None]


# --- pixel rules ---------------------------------------------------------------------

def periodic_matches(c: GpodConfig, m: Matches, pd: np.ndarray, thr: np.ndarray
                     ) -> np.ndarray:
    """(K,) bool: the matches of a periodic pattern: at least
    ``detection.periodic_min_rivals`` rivals (`match_rivals`) with
    ``detection.ambiguous_match_ratio`` of the match's first-round support or more, one of
    them on the ground (within the pixel's threshold ``thr`` (K,) of the ground disparity
    ``pd`` (K,)). The bars of a grate support candidates a period apart alike, and the
    one a period nearer stands above the ground by the period over the baseline times the
    height of the ray (a 3.5 cm period: 10 cm on the paper's rig) wherever the walker is:
    a world-fixed false obstacle that the map would confirm. A kerb's face has at most
    one strong rival on the ground (the ground around it supports the ground's
    disparity), an obstacle's texture few."""
    k = len(m)
    out = np.zeros(k, bool)
    r = c.detection.ambiguous_match_ratio
    n_min = c.detection.periodic_min_rivals
    if (n_min <= 0 or r <= 0 or m.rival_match is None or m.rival_d is None
            or m.rival_ratio is None or k == 0):
        return out
    strong = m.rival_ratio >= r
    if kn.nb_rivals_on_ground is not None:
        # The same counts and tests, compiled (one pass over the rivals).
        n_strong, ground, _ = kn.nb_rivals_on_ground(
            m.rival_match, strong, m.rival_d, np.asarray(pd, np.float64),
            np.asarray(thr, np.float64), m.d, k)
        return (n_strong >= n_min) & ground
    j = m.rival_match[strong]
    n_strong = np.bincount(j, minlength=k)
    on_ground = np.abs(m.rival_d[strong].astype(np.float64) - pd[j]) <= thr[j]
    ground = np.zeros(k, bool)
    ground[j[on_ground]] = True
    return (n_strong >= n_min) & ground


def ambiguous_drops(c: GpodConfig, m: Matches, pd: np.ndarray, thr: np.ndarray
                    ) -> np.ndarray:
    """(K,) bool: the matches that are no evidence of a drop-off: a rival of the match
    (`match_rivals`) with at least ``detection.ambiguous_match_ratio`` of its first-round
    support lies on the ground (within the pixel's threshold ``thr`` (K,) of the ground
    disparity ``pd`` (K,)) and nearer than the match: the edge may as well be ground
    matched a period off (a grate's bars). Obstacle evidence is not judged so: the face
    of a 10 cm kerb has ground rivals as strong as its match, and a kerb must not be
    lost to a grate's false reports."""
    k = len(m)
    no_drop = np.zeros(k, bool)
    r = c.detection.ambiguous_match_ratio
    if (r <= 0 or m.rival_match is None or m.rival_d is None or m.rival_ratio is None
            or k == 0):
        return no_drop
    if kn.nb_rivals_on_ground is not None:
        # The same tests, compiled (one pass over the rivals).
        return kn.nb_rivals_on_ground(m.rival_match, m.rival_ratio >= r, m.rival_d,
                                      np.asarray(pd, np.float64),
                                      np.asarray(thr, np.float64), m.d, k)[2]
    j = m.rival_match
    rd = m.rival_d.astype(np.float64)
    sel = flat_nonzero((m.rival_ratio >= r) & (np.abs(rd - pd[j]) <= thr[j]))
    if sel.size:
        nearer = rd[sel] > m.d[j[sel]]
        no_drop[j[sel[nearer]]] = True
    return no_drop


def _periodic_pattern(c: GpodConfig, ev: FrameEvidence) -> None:
    """A periodic pattern matched a period off is no evidence either way."""
    periodic = periodic_matches(c, ev.m, ev.pd, ev.thr)
    ev.obst &= ~periodic
    ev.drop &= ~periodic


def _ambiguous_drop(c: GpodConfig, ev: FrameEvidence) -> None:
    """A drop pixel with a strong nearer rival on the ground is no drop evidence."""
    ev.drop &= ~ambiguous_drops(c, ev.m, ev.pd, ev.thr)


def _hanging_run(c: GpodConfig, ev: FrameEvidence) -> None:
    """Runs that hang over another depth of their own string (`hanging_runs`)."""
    if ev.obst.any():
        ev.obst &= ~hanging_runs(ev.el, ev.m, ev.prev, ev.h, c.detection.max_floating_height_m,
                                 c.detection.string_disparity_tolerance_px, ev.slope, ev.obst,
                                 solid=ev.run >= c.detection.min_matched_run)


def _lower_ground_continuation(c: GpodConfig, ev: FrameEvidence) -> None:
    """A run, at any height, that hangs over its own string's continuation on the lower
    ground beyond a drop and could have been matched there: the paving beyond a kerb down
    matched one period off (`continuation_alternatives`). Every stretch of these strings
    well above the plane is tested (one matched the same period off may hold up
    another)."""
    high = ev.obst & (ev.excess > AMBIGUOUS_EXCESS_PX)
    if not high.any():
        return
    m = ev.m
    in_s = np.zeros(int(m.string_id.max()) + 1, bool)
    in_s[m.string_id[high]] = True
    high = (ev.excess > AMBIGUOUS_EXCESS_PX) & in_s[m.string_id]
    support = max(c.drops.min_cluster_pixels, math.ceil(LOWER_GROUND_FRACTION * len(m)))
    ev.obst &= ~continuation_alternatives(
        ev.el, m, ev.prev, ev.cand, high, ev.below & (ev.run >= c.detection.min_matched_run),
        ev.pd, c.detection.string_disparity_tolerance_px, ev.slope, support)


def _string_pieces(c: GpodConfig, ev: FrameEvidence) -> None:
    """The edge-string rule per piece of a string between stretches of it on the ground
    (`string_pieces`): obstacle pixels of pieces with fewer than ``min_px`` (weighted)
    of them are dropped -- a noisy pixel far below a post, on the post's edge continued
    by a tile joint, is no part of the post (its foot would be taken there)."""
    if not ev.obst.any():
        return
    sid = ev.sid
    has = np.zeros(ev.n_s, bool)
    has[sid[ev.obst]] = True
    sel = flat_nonzero(has[sid])
    piece = string_pieces(sid[sel], ev.m.v[sel],
                          (np.abs(ev.ex_mean[sel]) <= ev.thr[sel]) & ev.usable[sel])
    o_sel = ev.obst[sel]
    n_piece = np.bincount(piece[o_sel], weights=ev.weight[sel][o_sel],
                          minlength=int(piece.max()) + 1)
    ev.obst[sel] &= n_piece[piece] + 1e-9 >= ev.min_px


# --- string rules --------------------------------------------------------------------

def bending_ground(c: GpodConfig, px: np.ndarray, pts: np.ndarray, h: np.ndarray,
                   metric: MetricPlane, n_s: int, sid: np.ndarray, radius: float,
                   sign: float, memo: dict | None = None, lead: np.ndarray | None = None,
                   max_grade: float = math.inf) -> np.ndarray:
    """(n_s,) bool: the strings that are ground bending away from the ground reference:
    in a cluster of their pixels (``px`` (K,) bool; feet clustered at ``radius`` m) of at
    least 8 pixels spread over ``bend.min_span_m`` or more along the walking direction
    whose heights ``h`` (K,) (m above the ground reference; ``sign`` -1: drop pixels,
    below it) fit a line leaving it at ``bend.min_grade`` or more from less than
    `BEND_MAX_START_M` off it at its near end. Beyond a brow the ground goes on falling,
    beyond a dip rising, from where the ground is: the farther its points the farther
    off; the lower ground beyond a drop and the top of a kerb are level, as far off near
    as far, and start a step away.

    A line's near end is as far off as the threshold lets a pixel first count, which
    grows with range (12-20 cm at 4.5 m on the chest rig). So with ``lead`` (K,) bool
    (the other reliable pixels of the strings), a line whose near end is farther off
    still bends from the ground when its own strings lead up to it without a gap: at
    least `BEND_LEAD_MIN` of their pixels in the `BEND_LEAD_M` before its nearest pixel,
    the last within `BEND_LEAD_GAP_M` of it, lie on the ground bent there (the level
    ground, then the line; median off it at most `BEND_LEAD_TOL_M`), at a grade of at
    most ``max_grade`` (ground a pedestrian walks; steeper is a flight of steps). The
    lower ground beyond a drop is hidden from the drop's edge for as far as the drop is
    deep, times the range over the camera's height: no pixels lead up to it.

    ``memo`` (a dict, or None): the clustering is kept
    in it under ``(sign, radius)`` as (pixel indices (P,) int64, their feet (P, 2), their
    cluster labels (P,) int64), for a later clustering of the same pixels
    (`Detection._clusters`)."""
    out = np.zeros(n_s, bool)
    idx = flat_nonzero(px)
    if idx.size < 8 or c.bend.min_grade <= 0:
        return out
    h_i, sid_i = h[idx], sid[idx]
    g2 = ground_coords(pts[idx], h_i, metric)
    label = cluster_points_2d(g2, sid_i, radius)
    if memo is not None:
        memo[(sign, radius)] = (idx, g2, label)
    # (clusters of fewer than 8 pixels are none)
    for k in flat_nonzero(np.bincount(label) >= 8).tolist():
        sel = label == k
        s_k, h_k = g2[sel, 0], sign * h_i[sel]
        if float(s_k.max() - s_k.min()) < c.bend.min_span_m:
            continue
        grade, at0 = (float(x) for x in np.polyfit(s_k, h_k, 1))
        near = grade * float(s_k.min()) + at0
        if grade < c.bend.min_grade:
            continue
        if near < BEND_MAX_START_M or (
                lead is not None and grade <= max_grade
                and _leads_up(lead, sid, sid_i[sel], pts, h, metric, sign, grade, at0,
                              float(s_k.min()))):
            out[sid_i[sel]] = True
    return out


def _leads_up(lead: np.ndarray, sid: np.ndarray, strings: np.ndarray, pts: np.ndarray,
              h: np.ndarray, metric: MetricPlane, sign: float, grade: float, at0: float,
              s_min: float) -> bool:
    """Whether the ``lead`` pixels (K,) bool of ``strings`` lead up to a line
    ``sign * h = grade * s + at0`` whose nearest pixel is at ``s_min`` m along the ground
    without a gap, lying on the ground bent there (`bending_ground`)."""
    near = flat_nonzero(lead & np.isin(sid, strings))
    if near.size < BEND_LEAD_MIN:
        return False
    s = ground_coords(pts[near], h[near], metric)[:, 0]
    keep = (s >= s_min - BEND_LEAD_M) & (s < s_min)
    if np.count_nonzero(keep) < BEND_LEAD_MIN or float(s[keep].max()) < s_min - BEND_LEAD_GAP_M:
        return False
    bent = np.maximum(grade * s[keep] + at0, 0.0)
    return float(np.median(np.abs(sign * h[near][keep] - bent))) <= BEND_LEAD_TOL_M


def _floating_string(c: GpodConfig, ev: FrameEvidence) -> None:
    """A string whose reliably matched pixels all float higher than
    ``detection.max_floating_height_m`` above the ground is a mismatch (a distant pole
    matched to the wrong edge)."""
    s = ev.obst_string
    assert s is not None
    if s.any():
        low = np.full(ev.n_s, np.inf)
        np.minimum.at(low, ev.sid[ev.usable], ev.h[ev.usable])
        s &= low <= c.detection.max_floating_height_m


def _risen_ground(c: GpodConfig, ev: FrameEvidence) -> None:
    """A string beyond the known ground whose reliable pixels all lie more than
    ``risen.min_height_m`` above the surface (higher than a kerb or a step; nothing of it
    comes down to the ground) and no higher than the ground may have risen since the known
    ground (``surface.max_grade_rise`` per metre beyond ``known_until_m``) is the ground
    risen ahead, seen where it has texture (a manhole cover on a rise the surface could not
    follow for want of features), not an obstacle: an obstacle stands on the ground, and
    its edges come down to it."""
    s = ev.obst_string
    assert s is not None
    surf = ev.surface
    if surf is None or not s.any() or c.risen.min_height_m <= 0.0:
        return
    sel = flat_nonzero(s[ev.sid] & ev.usable)
    if not sel.size:
        return
    dist = surf.coordinates(ev.pts[sel])[0]
    beyond = dist - surf.known_until_m
    h = ev.h[sel]
    sid = ev.sid[sel]
    # per string: its lowest height, and how far its pixels rise above the highest
    # ground the surface allows where they are (the surface itself on the known ground)
    low = np.full(ev.n_s, np.inf)
    np.minimum.at(low, sid, h)
    over = np.full(ev.n_s, -np.inf)
    np.maximum.at(over, sid, h - c.surface.max_grade_rise * np.maximum(beyond, 0.0))
    risen = (low > c.risen.min_height_m) & (over <= 0.0)
    s &= ~risen


def _ground_bend_up(c: GpodConfig, ev: FrameEvidence) -> None:
    """Strings whose obstacle pixels are ground rising beyond a dip (`bending_ground`)."""
    s = ev.obst_string
    assert s is not None
    if s.any():
        s &= ~bending_ground(c, ev.obst & s[ev.sid], ev.pts, ev.h, ev.metric, ev.n_s, ev.sid,
                             c.detection.cluster_radius_m, 1.0, ev.clustered,
                             lead=ev.on_ground,
                             max_grade=c.surface.max_grade_rise)


def _half_occlusion(c: GpodConfig, ev: FrameEvidence) -> None:
    """A left edge matched to the silhouette of an obstacle (a nearer surface) in the
    right image is hidden there (`occluded_matches`): a string that is an obstacle or a
    drop only through such pixels is none (strings with enough other evidence are kept
    whole)."""
    s = ev.obst_string
    assert s is not None
    if not s.any():
        return
    sid = ev.sid
    occluded = occluded_matches(ev.er, ev.m, c.matching.pmf_disparity_gradient_limit,
                                trusted=s[sid] & (ev.run >= c.detection.min_matched_run))
    if occluded.any():
        seen = ev.obst & ~occluded
        n_seen = np.bincount(sid[seen], weights=ev.weight[seen], minlength=ev.n_s)
        s &= n_seen + 1e-9 >= ev.min_px
        seen = ev.drop & ~occluded
        ev.n_drop = np.bincount(sid[seen], weights=ev.weight[seen], minlength=ev.n_s) + 1e-9


# --- drop-off rules ------------------------------------------------------------------

def drop_regions(c: GpodConfig, drop: np.ndarray, weight: np.ndarray, pts: np.ndarray,
                 h: np.ndarray, metric: MetricPlane, n_s: int, sid: np.ndarray
                 ) -> np.ndarray:
    """(n_s,) bool: the strings whose drop pixels (``drop`` (K,) bool) belong to a region
    of lower ground: their feet clustered at ``drops.cluster_radius_m``, of at least
    ``drops.region_min_strings`` strings, whose drop pixels weigh (``weight`` (K,)) at
    least ``drops.region_pixels`` times ``drops.min_pixels`` in all and lie at one depth
    below the plane (``h`` (K,): the median absolute deviation of their heights at most
    ``drops.region_max_spread`` times their median)."""
    out = np.zeros(n_s, bool)
    idx = flat_nonzero(drop)
    if idx.size == 0 or c.drops.region_pixels <= 0.0:
        return out
    g2 = ground_coords(pts[idx], h[idx], metric)
    label = cluster_points_2d(g2, sid[idx], c.drops.cluster_radius_m)
    total = np.bincount(label, weights=weight[idx])
    for k in flat_nonzero(total >= c.drops.region_pixels * c.drops.min_pixels):
        sel = idx[label == k]
        if np.unique(sid[sel]).size < c.drops.region_min_strings:
            continue
        depth = h[sel]
        med = float(np.median(depth))
        if float(np.median(np.abs(depth - med))) <= c.drops.region_max_spread * abs(med):
            out[sid[sel]] = True
    return out


def _drop_region(c: GpodConfig, ev: FrameEvidence) -> None:
    """A string with a little drop evidence in a region of lower ground is a drop-off
    (`drop_regions`); not an obstacle string."""
    s, n_drop, obst_string = ev.drop_string, ev.n_drop, ev.obst_string
    assert s is not None and n_drop is not None and obst_string is not None
    s |= drop_regions(c, ev.drop & (n_drop[ev.sid] > 1e-6), ev.weight, ev.pts, ev.h,
                      ev.metric, ev.n_s, ev.sid) & ~obst_string


def _ground_bend_down(c: GpodConfig, ev: FrameEvidence) -> None:
    """Drop strings that are ground falling away beyond a brow (`bending_ground`)."""
    s = ev.drop_string
    assert s is not None
    if s.any():
        tail = ev.surface.tail_grade if ev.surface is not None else 0.0
        s &= ~bending_ground(c, ev.drop & s[ev.sid], ev.pts, ev.h, ev.metric, ev.n_s,
                             ev.sid, c.drops.cluster_radius_m, -1.0, ev.clustered,
                             lead=ev.on_ground,
                             max_grade=fall_limit(tail, ev.level, c.surface.max_grade_fall))


# --- placement rules -----------------------------------------------------------------

@dataclass
class Placement:
    """What the placement rules read of one frame's obstacle clusters: one foot per
    (cluster, edge string), on the ground (forward, left) from below the camera, metres."""

    ctx: _FrameContext
    xy: np.ndarray              # (F, 2) the feet of the obstacles' own strings
    sr: np.ndarray              # (F,) each foot's standard error along its ray, m
    group: np.ndarray           # (F,) the cluster of each foot (0 .. n-1)
    n: int                      # clusters
    height: np.ndarray          # (n,) each cluster's height, m
    at_border: np.ndarray       # (F,) bool: the string lies at the image's left or right edge
    #: the candidate silhouette strings (near the threshold, no obstacle), or None:
    #: (feet (W, 2), standard errors (W,), top heights (W,), at the border (W,))
    weak: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None
    lone_floor: float           # the lone-face search's least edge evidence
    #: the first cluster of a second set (None: one set): clusters 0 .. split-1 and
    #: split .. n-1 are placed as each set would be on its own (the rules that weigh
    #: clusters against each other, ``silhouettes`` and ``face_gap``, do so within a set)
    split: int | None = None

    def sets(self) -> tuple[tuple[int, int], ...]:
        """The sets of clusters as (first, end) ranges: (0, n), or (0, split) and
        (split, n)."""
        if self.split is None:
            return ((0, self.n),)
        return ((0, self.split), (self.split, self.n))


PlacementRule = Callable[[GpodConfig, Placement, np.ndarray], np.ndarray]


def _nearer(q: np.ndarray, new: np.ndarray, only_nearer: bool) -> np.ndarray:
    """(n, 2) ``q`` with the rows of ``new`` that are set (not NaN) and, with
    ``only_nearer``, nearer to the wearer."""
    take = ~np.isnan(new[:, 0])
    if only_nearer and take.any():
        take &= np.hypot(new[:, 0], new[:, 1]) < np.hypot(q[:, 0], q[:, 1])
    if not take.any():
        return q
    q = q.copy()
    q[take] = new[take]
    return q


def _silhouettes(c: GpodConfig, pl: Placement, q: np.ndarray) -> np.ndarray:
    """Edge strings just under the thresholds that `silhouette_owners` gives to an
    obstacle add their feet to its nearest-point search; the result is kept only where
    nearer (a silhouette can reveal a hidden near corner, never move an obstacle away)."""
    if pl.weak is None:
        return q
    xw, sw, top, bd = pl.weak
    ctx = pl.ctx
    if pl.split is None:
        lw = silhouette_owners(xw, top, pl.xy, pl.group, pl.height,
                               c.detection.cluster_radius_m, lambda: ctx.ground_xy,
                               ctx.metric.height, sw, pl.sr)
        keep = lw >= 0
        if not keep.any():
            return q
        xy_w, sr_w, lab_w, bd_w = xw[keep], sw[keep], lw[keep], bd[keep]
    else:
        # each set's owners among its own clusters: a candidate may be one of each
        got = []
        for lo, hi in pl.sets():
            own = (pl.group >= lo) & (pl.group < hi)
            lw = silhouette_owners(xw, top, pl.xy[own], pl.group[own] - lo, pl.height[lo:hi],
                                   c.detection.cluster_radius_m, lambda: ctx.ground_xy,
                                   ctx.metric.height, sw, pl.sr[own])
            keep = lw >= 0
            got.append((xw[keep], sw[keep], lw[keep] + lo, bd[keep]))
        if not any(g[2].size for g in got):
            return q
        xy_w, sr_w, lab_w, bd_w = (np.concatenate([g[i] for g in got]) for i in range(4))
    # only the obstacles with candidates are searched again
    ks = np.unique(lab_w)
    sub = np.full(pl.n, -1, np.int64)
    sub[ks] = np.arange(ks.size)
    mine = sub[pl.group] >= 0
    qw = nearest_points(np.concatenate([pl.xy[mine], xy_w]), np.concatenate([pl.sr[mine], sr_w]),
                        np.concatenate([sub[pl.group[mine]], sub[lab_w]]), ks.size,
                        lambda: ctx.ground_xy, ctx.contact_edge_scores,
                        np.concatenate([pl.at_border[mine], bd_w]))
    new = np.full_like(q, np.nan)
    new[ks] = qw
    return _nearer(q, new, True)


def _view_edge(c: GpodConfig, pl: Placement, q: np.ndarray) -> np.ndarray:
    """A face going out of the view (a wall beside the path): its nearest visible point
    is where it leaves the image (`view_edge_points`), when nearer."""
    ctx = pl.ctx
    return _nearer(q, view_edge_points(pl.xy, pl.group, pl.n, ctx.to_image, ctx.cam.width,
                                       ctx.cam.height, lambda: ctx.ground_xy), True)


def _face_gap(c: GpodConfig, pl: Placement, q: np.ndarray) -> np.ndarray:
    """A face seen as two obstacles (its middle has no edges): its nearest point
    (`face_gap_points`)."""
    return _nearer(q, face_gap_points(pl.xy, pl.group, pl.n, q, lambda: pl.ctx.ground_xy,
                                      pl.split), False)


def _lone_face(c: GpodConfig, pl: Placement, q: np.ndarray) -> np.ndarray:
    """A low obstacle seen by one silhouette edge: the face the image shows beside it
    (`lone_face_points`)."""
    return _nearer(q, lone_face_points(pl.ctx, pl.xy, pl.group, pl.n, q, pl.height,
                                       pl.at_border, pl.lone_floor), False)


#: Every rule by list and name (`GpodConfig.rules` names them in the order they run).
PIXEL_RULES: dict[str, Rule] = {
    'periodic_pattern': _periodic_pattern,
    'ambiguous_drop': _ambiguous_drop,
    'hanging_run': _hanging_run,
    'lower_ground_continuation': _lower_ground_continuation,
    'string_pieces': _string_pieces,
}
STRING_RULES: dict[str, Rule] = {
    'floating_string': _floating_string,
    'risen_ground': _risen_ground,
    'ground_bend': _ground_bend_up,
    'half_occlusion': _half_occlusion,
}
DROP_RULES: dict[str, Rule] = {
    'drop_region': _drop_region,
    'ground_bend': _ground_bend_down,
}
PLACEMENT_RULES: dict[str, PlacementRule] = {
    'silhouettes': _silhouettes,
    'view_edge': _view_edge,
    'face_gap': _face_gap,
    'lone_face': _lone_face,
}


def run_rules(c: GpodConfig, names: tuple[str, ...], table: dict[str, Rule],
              ev: FrameEvidence) -> None:
    """Run the rules ``names`` of ``table`` on ``ev`` in that order."""
    for name in names:
        table[name](c, ev)
