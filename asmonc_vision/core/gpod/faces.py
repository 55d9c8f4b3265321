"""Faces of obstacles beyond their feet: a face running out of the view
(`view_edge_points`), a face seen as two parts with a blank middle (`face_gap_points`),
a low obstacle seen by one silhouette (`lone_face_points`, `silhouette_owners`), and a
whole described by its parts (`described_by_part`).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from . import kernels_geometry as kg
from .footing import _LONE_STEP_M, _FrameContext
from .grouping import _fit_line
from .kernels_geometry import (
    _FACE_BEHIND_MIN,
    _FACE_HIDDEN_MIN,
    _FREE_SPACE_MARGIN_M,
    _WEAK_HEIGHT_RATIO,
    _face_hides_kernel,
)
from .nearest import _body_gap, _ground_inside
from .results import GpodObstacle
from ..npfast import flat_nonzero

#: A straight face of an obstacle (a wall beside the path) whose feet come nearer towards
#: the left or right edge of the view continues out of it: its nearest visible point is
#: where its contact line leaves the image (`view_edge_points`). The face needs this many
#: feet at least, along a line (orthogonal RMS residual at most _FACE_MAX_RMS_M metres)
#: over _FACE_MIN_SPAN_M metres or more; it is extended by at most its own span, and not
#: where ground is seen behind the extension (the face ends before the view's edge).
#: Nor when the line runs within _FACE_MIN_ANGLE_DEG of the line of sight at its near end:
#: feet err along the line of sight (range), so feet at one bearing make such a line out
#: of range errors (the strings of a post, with one string matched a period off 2.9 m
#: farther, made a "face" pointing at the camera that left the view 2.3 m in front of the
#: post).
_FACE_MIN_FEET = 3
_FACE_MIN_ANGLE_DEG = 15.0
_FACE_MAX_RMS_M = 0.06
_FACE_MIN_SPAN_M = 0.3
#: Ground features this far (metres) behind the extended line end the face: at least
#: _FACE_BEHIND_MIN of them and _FACE_BEHIND_FRACTION of the ground features within the
#: extension's bearings (ground seen past a face's end is a region; a few are wall texture
#: matched at the ground's disparity).
_FACE_BEHIND_M = 0.1
_FACE_BEHIND_FRACTION = 0.25
#: Feet on one line are not a face when the ground within _FACE_BAND_M metres behind the
#: line, within the feet's own bearings, is seen at least _FACE_SEEN_THROUGH times as
#: densely as within as far in front (and by _FACE_BEHIND_MIN features): separate objects
#: in a row (a post and a bollard), with the ground between them in view. Behind a wall
#: only texture matched at the ground's disparity is (0.01-0.2 times, on the simulator's
#: walls; 0.7-1.2 for a post and bollard 0.8 m apart).
_FACE_BAND_M = 1.0
_FACE_SEEN_THROUGH = 0.5
#: ... and so within the widest gap between a face's successive feet, if at least this
#: wide (metres: a gap one could walk through, `GpodConfig.detection.part_radius_m`'s default).
_FACE_GAP_SEEN_M = 0.35
#: `view_edge_points` samples the extension at these multiples of span / 64 (as
#: np.linspace(0, span, 65)[1:] does, the last at the span itself), and refines between
#: two samples at these fractions.
_SPAN_STEPS = np.arange(1, 65, dtype=np.float64)
_FINE_STEPS = np.linspace(0.0, 1.0, 33)
#: Least span (metres) of the feet of two obstacles taken for one face (`face_gap_points`).
_GAP_MIN_SPAN_M = 1.0
#: A lone silhouette's face (`lone_face_points`): a low obstacle (at most
#: _LONE_MAX_HEIGHT_M high) seen by one silhouette edge only (the feet of its strings
#: within _LONE_SPREAD_M of each other) may stand with a face that has no vertical edge
#: of its own (a frontal box: its near corner or middle lies beside the one edge seen).
#: Such a face shows in the image as two parallel intensity edges: its contact line on
#: the ground and its top outline, the same line raised by the obstacle's height. From
#: the foot, the directions of _LONE_DIRECTIONS on the ground that run towards the
#: camera's side are followed in steps of _LONE_STEP_M up to _LONE_MAX_M; a face is the
#: extent along a direction over which the weaker of the two edges (the image gradient
#: across each line) exceeds a bar by the largest sum: _LONE_BAR times the median over
#: those directions of the mean evidence (the ground's own texture), at least
#: _LONE_FLOOR_SIGMAS times the gradient noise.
#: It must be _LONE_MIN_M long or more; its two lines at least _LONE_MIN_SEP_PX apart
#: across their direction (a line along the line of sight is its own raised copy), and
#: that separation at least _LONE_MIN_SEP_FRACTION of the raise itself (the image
#: distance between a contact point and the same point raised by the height), so that the
#: line crosses the raise at 53 degrees or more: a line nearer the raise's direction is
#: mostly its own raised copy slid along itself, however long the raise (a paving joint
#: leading from a box's corner towards the camera once passed the pixel bar at 2.7-3.5
#: px, 0.7 of a raise of 4-5 px, where the box's own face gave 0.96-1, and placed the box
#: 0.3 m nearer than it stood); and no visible ground may lie where it would be hidden
#: (`_face_hides_kernel`). Of the faces that bring the obstacle's nearest point nearer by
#: _LONE_MIN_GAIN_M or more, the best supported gives it.
_LONE_MAX_HEIGHT_M = 0.3
_LONE_SPREAD_M = 0.15
_LONE_DIRECTIONS = 72
_LONE_MIN_M = 0.1
_LONE_BAR = 2.0
_LONE_MIN_SEP_PX = 2.5
_LONE_MIN_SEP_FRACTION = 0.8
_LONE_MIN_GAIN_M = 0.05
#: The directions searched (radians from the ground's x axis towards y) and the steps
#: along each (metres from the foot).
_LONE_PHI = np.arange(_LONE_DIRECTIONS) * (2.0 * np.pi / _LONE_DIRECTIONS)
_LONE_COS, _LONE_SIN = np.cos(_LONE_PHI), np.sin(_LONE_PHI)

#: A whole obstacle placed at one part's nearest point takes that part's height and
#: confidence when the part is lower than this fraction of the whole's height (another
#: body, `described_by_part`; the factor 2 of ``_WEAK_HEIGHT_RATIO``).
_OTHER_BODY_HEIGHT_FRACTION = 1.0 / _WEAK_HEIGHT_RATIO


def _ground_across_line(ground: np.ndarray, c: np.ndarray, d: np.ndarray, a: np.ndarray,
                        b: np.ndarray, bearing: np.ndarray | None = None
                        ) -> tuple[int, int, int, int, int, float, float]:
    """Visible ground on either side of the ground line through ``c`` along unit ``d``,
    within the bearings of its points ``a`` and ``b`` ((2,) each, metres): the numbers of
    ground features (G, 2) more than ``_FACE_BEHIND_M`` in front of it (the camera's side)
    and behind it, of all features within those bearings, and of those in front and
    behind within ``_FACE_BAND_M`` of the line; then the last two again, each feature
    weighted by its range (so that
    evenly seen ground counts the same near and far: within a wedge of bearings, clear
    pavement gives 0.71-0.86 times as many features per band 1 m behind a line 2.5-5.5 m
    ahead as 1 m in front of it, and 0.98-1.03 times the range-weighted sum).
    ``bearing``: (G,) the ground features' bearings, ``np.arctan2(ground[:, 1],
    ground[:, 0])`` (radians), when the caller has them (None: worked out here)."""
    b0, b1 = math.atan2(a[1], a[0]), math.atan2(b[1], b[0])
    bg = np.arctan2(ground[:, 1], ground[:, 0]) if bearing is None else bearing
    w = ground[(bg >= min(b0, b1)) & (bg <= max(b0, b1))]
    nrm = np.array([-d[1], d[0]])
    off = math.copysign(1.0, float(nrm @ -c)) * ((w - c) @ nrm)
    front, behind = off > _FACE_BEHIND_M, off < -_FACE_BEHIND_M
    near = np.abs(off) <= _FACE_BAND_M
    rng_w = np.hypot(w[:, 0], w[:, 1])
    band_front, band_behind = front & near, behind & near
    return (int(np.count_nonzero(front)), int(np.count_nonzero(behind)), int(w.shape[0]),
            int(np.count_nonzero(band_front)), int(np.count_nonzero(band_behind)),
            float(rng_w[band_front].sum()), float(rng_w[band_behind].sum()))


def _ground_behind(n_behind: int, n_wedge: int) -> bool:
    """Whether enough ground is seen behind a face line to show the way through: at least
    ``_FACE_BEHIND_MIN`` features and ``_FACE_BEHIND_FRACTION`` of those in its bearings
    (a few are texture on the face matched at the ground's disparity)."""
    return n_behind >= max(_FACE_BEHIND_MIN, _FACE_BEHIND_FRACTION * n_wedge)


def _seen_through(n_front: int, n_behind: int, w_front: float, w_behind: float) -> bool:
    """Whether the ground within ``_FACE_BAND_M`` behind a line is seen at least
    ``_FACE_SEEN_THROUGH`` times as densely as within as far in front of it (by the
    range-weighted feature sums ``w_*`` of `_ground_across_line`), and by
    ``_FACE_BEHIND_MIN`` features (``n_behind``): separate objects in a row, not one face."""
    return n_behind >= _FACE_BEHIND_MIN and w_behind >= _FACE_SEEN_THROUGH * w_front


def view_edge_points(xy: np.ndarray, group: np.ndarray, n_groups: int, to_image,
                     width: int, height: int, ground_xy) -> np.ndarray:
    """Where the straight face of an obstacle leaves the view, for faces that come nearer
    towards the view's left or right edge (a wall beside the path): there is its nearest
    visible point, which its edge strings' feet (inside the view) cannot reach.

    For each obstacle with at least ``_FACE_MIN_FEET`` feet lying along one line (total
    least squares, orthogonal RMS <= ``_FACE_MAX_RMS_M``, spanning >= ``_FACE_MIN_SPAN_M``,
    at least ``_FACE_MIN_ANGLE_DEG`` from the line of sight at its near end)
    whose range falls towards its outermost foot, the line is followed beyond that foot
    (by at most the feet's span) to where it leaves the image (left or right border, or
    the bottom row). Feet with the ground seen through their line (between them, or
    within their widest gap if it is ``_FACE_GAP_SEEN_M`` or wider; within
    ``_FACE_BAND_M``, ``_FACE_SEEN_THROUGH`` times as densely, range-weighted, as in
    front) are separate objects in a row, not a face. The point is given unless visible
    ground lies behind the extended line within that wedge of bearings
    (``_FACE_BEHIND_MIN`` and ``_FACE_BEHIND_FRACTION`` of its ground features beyond the
    line by ``_FACE_BEHIND_M``: then the face ends inside the view).

    Args:
        xy: (S, 2) ground coordinates of the feet, metres (`_FrameContext.to_xy`).
        group: (S,) obstacle of each foot, 0..n_groups-1.
        to_image: ground (N, 2) -> left-image (u, v) pixels (`_FrameContext.to_image`).
        width, height: image size, pixels.
        ground_xy: (G, 2) visible ground, or a callable returning it.
    Returns:
        (n_groups, 2) ground coordinates of the point where each obstacle's face leaves
        the view, NaN where there is none.
    """
    out = np.full((n_groups, 2), np.nan)
    if xy.shape[0] < _FACE_MIN_FEET:
        return out
    counts = np.bincount(group, minlength=n_groups)
    ground = None
    g_brg: np.ndarray | None = None         # the ground's bearings, once it is needed
    for k in flat_nonzero(counts >= _FACE_MIN_FEET):
        c, d, along, rms = _fit_line(xy[group == k])
        span = float(along.max() - along.min())
        if span < _FACE_MIN_SPAN_M or rms > _FACE_MAX_RMS_M:
            continue
        # The end of the face nearer the camera (range falls along the line towards it).
        ends = (c + along.min() * d, c + along.max() * d)
        e, sgn = (ends[0], -1.0) if np.hypot(*ends[0]) < np.hypot(*ends[1]) else (ends[1], 1.0)
        step = sgn * d
        if float(e @ step) >= 0.0:          # the nearest point of the line is in the face
            continue
        if abs(float(e[0] * d[1] - e[1] * d[0])) < (math.sin(math.radians(_FACE_MIN_ANGLE_DEG))
                                                  * float(np.hypot(*e))):
            continue                        # along the line of sight: range errors
        u0, v0 = (w[0] for w in to_image(e[None]))
        if not (0.0 <= u0 <= width - 1 and 0.0 <= v0 <= height - 1):
            continue
        t = _SPAN_STEPS * (span / 64.0)     # np.linspace(0.0, span, 65)[1:] (span > 0)
        t[-1] = span
        pts = e[None] + t[:, None] * step[None]
        # Stay in front of the camera (ground points behind it have no image).
        pts = pts[pts[:, 0] > 0.05]
        if pts.shape[0] == 0:
            continue
        uu, vv = to_image(pts)
        outside = (uu < 0.0) | (uu > width - 1) | (vv > height - 1)
        if not outside.any():
            continue                        # the face would end inside the view
        j = int(np.argmax(outside))
        q = e
        if j > 0:
            # Refine between the last sample inside and the first outside.
            fine = pts[j - 1][None] + _FINE_STEPS[:, None] * (pts[j] - pts[j - 1])
            uf, vf = to_image(fine)
            inside = (uf >= 0.0) & (uf <= width - 1) & (vf <= height - 1)
            q = fine[max(int(np.argmin(inside)) - 1, 0)]
        if np.hypot(*q) >= np.hypot(*e) - 1e-6:
            continue
        if ground is None:
            ground = ground_xy() if callable(ground_xy) else ground_xy
            g_brg = np.arctan2(ground[:, 1], ground[:, 0])     # (one for every line)
        # Ground seen through the line between the feet: separate objects, not a face.
        # Also within the widest gap between successive feet alone: objects in a row hide
        # the ground behind themselves, which dilutes the whole span's share (a post and
        # a box 0.66 m apart, 4-5 m ahead, once made a "face" leaving the view 1.2 m
        # nearer, where the pavement was clear).
        spans = [(ends[1] if e is ends[0] else ends[0], e)]
        t_s = np.sort(along)
        i_gap = int(np.argmax(np.diff(t_s)))
        if t_s[i_gap + 1] - t_s[i_gap] >= _FACE_GAP_SEEN_M:
            spans.append((c + t_s[i_gap] * d, c + t_s[i_gap + 1] * d))
        if any(_seen_through(*_ground_across_line(ground, c, d, a, b, g_brg)[3:])
               for a, b in spans):
            continue
        # Visible ground behind the extension shows the face ends before the view's edge.
        _, n_behind, n_wedge, *_ = _ground_across_line(ground, c, d, e, q, g_brg)
        if _ground_behind(n_behind, n_wedge):
            continue
        out[k] = q
    return out


#: Index pairs (i < j) of n points, by n (`_pairs_of`).
_PAIRS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _ground_points(obstacles) -> np.ndarray:
    """(N, 2) ground coordinates (forward, left), metres, of obstacles' reported points,
    from their range and bearing."""
    return np.array([[o.range * math.cos(o.bearing), o.range * math.sin(o.bearing)]
                     for o in obstacles]).reshape(-1, 2)


def described_by_part(whole: list[GpodObstacle], parts: list[GpodObstacle],
                      owner: np.ndarray, radius: float, normal_up: np.ndarray,
                      ground_xy) -> list[GpodObstacle]:
    """Obstacles joined from parts (`GpodDetector._parts`), each described by the part
    at its place when that part is another body than the one that gives it its height.

    A whole is reported at its nearest point. When that point lies within ``radius`` of
    exactly one of its parts' nearest points, that part is lower than half the whole's
    height, and visible ground separates it from the whole's highest part (`_body_gap`:
    side by side, not one face), the part is another body: a two-pixel blip of the
    ground 0.7 m in front of a box is no 18 cm obstacle with the box's confidence (the
    box is reported as a part of its own). The whole then takes that part's height,
    confidence, image region, excess and pixel count, and keeps its place, width and
    strings. Parts of a like height may be one body (the two silhouette edges of a
    box), whose evidence the whole sums; so may a low part with no ground seen between
    it and the highest (a wall's end at the image's border, seen only near its foot);
    and a whole placed between its parts (a hidden corner) keeps its own.

    Args:
        whole: the C obstacles (heights > 0), each made of one or more parts.
        parts: the P parts of the wholes of more than one.
        owner: (P,) int, the index in ``whole`` of each part's whole.
        radius: metres along the ground (``detection.part_radius_m``).
        normal_up: (3,) the ground's unit normal, left optical frame.
        ground_xy: (G, 2) the frame's ground features, metres along the ground
            (forward, left) from the point below the camera, or a callable returning
            them (asked only when a whole qualifies by height).
    Returns:
        The C obstacles, in order.
    """
    at = _ground_points(parts)
    here_all = _ground_points(whole)
    out = list(whole)
    for k, ob in enumerate(whole):
        mine = flat_nonzero(owner == k)
        if mine.size < 2:
            continue
        dist = np.hypot(*(at[mine] - here_all[k]).T)
        near = dist <= radius
        if near.sum() == 1:
            j = int(mine[np.argmax(near)])
            p = parts[j]
            others = mine[mine != j]
            q = int(others[np.argmax([parts[i].height for i in others])])
            if (p.height < _OTHER_BODY_HEIGHT_FRACTION * ob.height
                    and _body_gap(ground_xy() if callable(ground_xy) else ground_xy,
                                  at[j], at[q])):
                out[k] = dataclasses.replace(
                    ob, position=ob.position + (p.height - ob.height) * normal_up,
                    height=p.height, confidence=p.confidence, roi=p.roi,
                    disparity_excess=p.disparity_excess,
                    num_edge_pixels=p.num_edge_pixels)
    return out


def _row_median(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=-1)`` of a float array with at least one column, the same
    values (the middle of the sorted row, or the mean of the middle two; NaN for a row
    with a NaN) without np.median's overhead on small arrays."""
    s = np.sort(x, axis=-1)
    n = s.shape[-1]
    mid = s[..., n // 2] if n % 2 else (s[..., n // 2 - 1] + s[..., n // 2]) / 2.0
    return np.where(np.isnan(s[..., -1]), np.nan, mid)


def _pairs_of(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, 1)``: (P,) int64 i < j of every pair of 0..n-1, in row-major
    order (cached up to n = 256; read-only)."""
    out = _PAIRS.get(n)
    if out is None:
        ia, ib = np.triu_indices(n, 1)
        ia.flags.writeable = False
        ib.flags.writeable = False
        out = (ia, ib)
        if n <= 256:
            _PAIRS[n] = out
    return out


def lone_face_points(ctx: _FrameContext, xy: np.ndarray, group: np.ndarray, n_groups: int,
                     q: np.ndarray, height: np.ndarray, at_border: np.ndarray,
                     noise_floor: float = 0.0) -> np.ndarray:
    """The nearest point of a low obstacle seen by one silhouette edge, along the face the
    image shows beside it (see `_LONE_MAX_HEIGHT_M` and below it for the rule).

    Args:
        ctx: the frame (its left image, plane, camera and visible ground).
        xy: (S, 2) ground coordinates of the obstacles' string feet, metres;
            ``group`` (S,) the obstacle of each; ``n_groups`` the number of obstacles.
        q: (n_groups, 2) each obstacle's nearest point so far, metres.
        height: (n_groups,) the obstacles' heights, metres.
        at_border: (S,) the string lies at the image's left or right border.
        noise_floor: the least bar of the edge evidence, grey levels per pixel.
    Returns:
        (n_groups, 2): the nearer point, NaN where none is found (or the obstacle is not
        a low one placed at its one silhouette).
    """
    out = np.full((n_groups, 2), np.nan)
    if xy.shape[0] == 0:
        return out
    g_all = None
    cam_h = ctx.metric.height
    hides = kg.nb_face_hides if kg.nb_face_hides is not None else _face_hides_kernel
    # the obstacles to search, all at once: low, with feet none at the image's border,
    # within _LONE_SPREAD_M in x and in y (more than one silhouette: the corner searches
    # place it), one within _LONE_SPREAD_M of the nearest point so far (else it was
    # placed elsewhere already: a face out of the view, a gap)
    group = np.asarray(group, np.int64)
    low = (height > 0.0) & (height <= _LONE_MAX_HEIGHT_M)
    fq = q[group]
    dist = np.hypot(xy[:, 0] - fq[:, 0], xy[:, 1] - fq[:, 1])
    mine = low[group]
    lo_x = np.full(n_groups, np.inf)
    hi_x = np.full(n_groups, -np.inf)
    lo_y, hi_y, closest = lo_x.copy(), hi_x.copy(), lo_x.copy()
    g = group[mine]
    np.minimum.at(lo_x, g, xy[mine, 0])
    np.maximum.at(hi_x, g, xy[mine, 0])
    np.minimum.at(lo_y, g, xy[mine, 1])
    np.maximum.at(hi_y, g, xy[mine, 1])
    np.minimum.at(closest, g, dist[mine])
    border = np.zeros(n_groups, bool)
    border[group[at_border]] = True
    # (NaN spreads and distances search, as np.ptp and np.min of NaN compare false)
    search = (low & ~border & (np.bincount(group, minlength=n_groups) > 0)
              & ~(hi_x - lo_x > _LONE_SPREAD_M) & ~(hi_y - lo_y > _LONE_SPREAD_M)
              & ~(closest > _LONE_SPREAD_M))
    for k in flat_nonzero(search).tolist():
        h = float(height[k])
        foot = q[k]
        # Only a face that runs towards the camera's side can bring the point nearer.
        phi = _LONE_PHI[_LONE_COS * foot[0] + _LONE_SIN * foot[1] < 0.0]
        if phi.size == 0:
            continue
        points, ev, sep, shift = ctx.outline_evidence(foot, h, phi)
        rows = np.arange(ev.shape[0])
        if kg.nb_lone_support is not None:
            # the same bar, sums, ends and tests, compiled
            ok, end, support = kg.nb_lone_support(
                np.ascontiguousarray(ev, np.float64), np.ascontiguousarray(sep, np.float64),
                np.ascontiguousarray(shift, np.float64), _LONE_BAR, float(noise_floor),
                _LONE_STEP_M, _LONE_MIN_M, _LONE_MIN_SEP_PX, _LONE_MIN_SEP_FRACTION)
        else:
            bar = max(_LONE_BAR * float(_row_median(ev.mean(axis=1))), noise_floor)
            gain = np.cumsum(ev - bar, axis=1)
            end = np.argmax(gain, axis=1)
            support = gain[rows, end]
            ok = ((support > 0.0) & ((end + 1) * _LONE_STEP_M >= _LONE_MIN_M)
                  & (_row_median(sep) >= _LONE_MIN_SEP_PX)
                  & (_row_median(sep / np.maximum(shift, 1e-9))
                     >= _LONE_MIN_SEP_FRACTION))
        if not ok.any():
            continue                            # no face passes the image's tests
        # each face's nearest point to the camera (the foot, its end, or between)
        ends = points[rows, end]
        d = ends - foot
        t = (-(d @ foot) / np.maximum(np.einsum('ij,ij->i', d, d), 1e-12)).clip(0.0, 1.0)
        near = foot + t[:, None] * d
        ok &= np.hypot(near[:, 0], near[:, 1]) <= math.hypot(*foot) - _LONE_MIN_GAIN_M
        best = None
        tried = flat_nonzero(ok)
        if tried.size == 0:
            continue
        if g_all is None:
            g_all = np.ascontiguousarray(ctx.ground_xy, np.float64).reshape(-1, 2)
        foot_1, sd_1 = np.ascontiguousarray(foot[None]), np.zeros(1)
        for j in tried[np.argsort(-support[tried], kind='stable')].tolist():
            if not hides(float(ends[j, 0]), float(ends[j, 1]), 0.0, foot_1, sd_1, g_all,
                         h / cam_h, _FREE_SPACE_MARGIN_M, _FACE_HIDDEN_MIN):
                best = near[j]                  # the best supported face that hides no
                break                           # visible ground
        if best is not None:
            out[k] = best
    return out


def face_gap_points(xy: np.ndarray, group: np.ndarray, n_groups: int, q: np.ndarray,
                    ground_xy, split: int | None = None) -> np.ndarray:
    """The nearest point of a straight face seen as two obstacles: a wall across the
    path whose middle has no edges to match (plain paint, a blank door) is found at its
    textured parts on either side, each placed at its own nearest foot, while the face's
    nearest point lies in the gap between them.

    For each pair of obstacles whose feet together (at least ``_FACE_MIN_FEET`` + 1) lie
    along one line (orthogonal RMS <= ``_FACE_MAX_RMS_M``, span >= ``_GAP_MIN_SPAN_M``)
    with the foot of the perpendicular from the camera in the gap between their feet:
    the gap is that face when visible ground lies in front of the line within the gap's
    bearings (``_FACE_BEHIND_MIN`` features at least: the gap is seen) and not behind it
    (fewer than ``_FACE_BEHIND_MIN`` and ``_FACE_BEHIND_FRACTION`` beyond the line by
    ``_FACE_BEHIND_M``: a gap one could walk through shows the ground beyond; nor, within
    ``_FACE_BAND_M`` of the line, ``_FACE_SEEN_THROUGH`` times as densely as in front).
    The nearer obstacle of the pair is then placed at that foot.

    Args:
        xy: (S, 2) ground coordinates of the feet, metres.
        group: (S,) obstacle of each foot, 0..n_groups-1.
        q: (n_groups, 2) each obstacle's nearest point so far.
        ground_xy: (G, 2) visible ground, or a callable returning it.
        split: None, or the first obstacle of a second set: only pairs within a set
            (both below ``split``, or neither) are faces (each set's points as its own
            call would give them).
    Returns:
        (n_groups, 2) the face's nearest point for the obstacles to move there, NaN for
        the others.
    """
    out = np.full((n_groups, 2), np.nan)
    if n_groups < 2 or xy.shape[0] < _FACE_MIN_FEET + 1:
        return out
    counts = np.bincount(group, minlength=n_groups).astype(np.float64)
    r_q = np.hypot(q[:, 0], q[:, 1])
    # Per obstacle: mean and scatter of its feet; per pair, the line through all their
    # feet from those (its normal's variance, the smaller eigenvalue of the 2x2 scatter).
    n1 = np.maximum(counts, 1.0)
    mean = np.stack([np.bincount(group, xy[:, i], n_groups) for i in (0, 1)], 1) / n1[:, None]
    dev = xy - mean[group]
    sxx = np.bincount(group, dev[:, 0] ** 2, n_groups)
    syy = np.bincount(group, dev[:, 1] ** 2, n_groups)
    sxy = np.bincount(group, dev[:, 0] * dev[:, 1], n_groups)
    ia, ib = _pairs_of(n_groups)
    na, nb = counts[ia], counts[ib]
    ok = (na > 0) & (nb > 0) & (na + nb >= _FACE_MIN_FEET + 1) & np.isfinite(r_q[ia]) \
        & np.isfinite(r_q[ib])
    if split is not None:
        ok &= (ia < split) == (ib < split)
    n = np.maximum(na + nb, 1.0)
    c = (na[:, None] * mean[ia] + nb[:, None] * mean[ib]) / n[:, None]
    da, db = mean[ia] - c, mean[ib] - c
    mxx = sxx[ia] + sxx[ib] + na * da[:, 0] ** 2 + nb * db[:, 0] ** 2
    myy = syy[ia] + syy[ib] + na * da[:, 1] ** 2 + nb * db[:, 1] ** 2
    mxy = sxy[ia] + sxy[ib] + na * da[:, 0] * da[:, 1] + nb * db[:, 0] * db[:, 1]
    half_tr = 0.5 * (mxx + myy)
    disc = np.sqrt(np.maximum(half_tr ** 2 - (mxx * myy - mxy ** 2), 0.0))
    ok &= (half_tr - disc) / n <= _FACE_MAX_RMS_M ** 2
    ground = None
    g_brg: np.ndarray | None = None         # the ground's bearings, once it is needed
    for t in flat_nonzero(ok):
        a, b = int(ia[t]), int(ib[t])
        lam = half_tr[t] + disc[t]              # the line's direction: the larger eigenvalue
        d = np.array([mxy[t], lam - mxx[t]]) if abs(mxy[t]) > 1e-12 else (
            np.array([1.0, 0.0]) if mxx[t] >= myy[t] else np.array([0.0, 1.0]))
        d = d / np.linalg.norm(d)
        ct = c[t]
        ta, tb = (xy[group == a] - ct) @ d, (xy[group == b] - ct) @ d
        span = float(max(ta.max(), tb.max()) - min(ta.min(), tb.min()))
        if span < _GAP_MIN_SPAN_M:
            continue
        t_p = -float(ct @ d)
        if ta.max() < t_p < tb.min():
            lo_t, hi_t = float(ta.max()), float(tb.min())
        elif tb.max() < t_p < ta.min():
            lo_t, hi_t = float(tb.max()), float(ta.min())
        else:
            continue                            # the nearest point is within one of them
        if ground is None:
            ground = ground_xy() if callable(ground_xy) else ground_xy
            g_brg = np.arctan2(ground[:, 1], ground[:, 0])     # (one for every pair)
        if ground.shape[0] == 0:
            continue
        n_front, n_behind, n_wedge, b_front, b_behind, w_front, w_behind = _ground_across_line(
            ground, ct, d, ct + lo_t * d, ct + hi_t * d, g_brg)
        # Near the line, the ground behind the gap seen about as densely as in front of
        # it: two objects with a way between them (a bollard and a wall 3.6 m apart once
        # made a "face" 6 m away), not one face.
        if (n_front < _FACE_BEHIND_MIN or _ground_behind(n_behind, n_wedge)
                or _seen_through(b_front, b_behind, w_front, w_behind)):
            continue
        k = a if r_q[a] <= r_q[b] else b
        foot = ct + t_p * d
        if np.hypot(*foot) < r_q[k] and (np.isnan(out[k, 0])
                                         or np.hypot(*foot) < np.hypot(*out[k])):
            out[k] = foot
    return out


def silhouette_owners(xw: np.ndarray, top: np.ndarray, xy: np.ndarray, g_lab: np.ndarray,
                      height: np.ndarray, radius: float, ground_xy,
                      camera_height: float = math.inf, sigma_w: np.ndarray | None = None,
                      sigma: np.ndarray | None = None) -> np.ndarray:
    """The detected obstacle whose silhouette foot each candidate edge may be (-1: none).

    A candidate (an edge string just under the obstacle thresholds, never an obstacle
    itself) with foot ``xw`` and top ``top`` metres above the plane belongs to the
    nearest obstacle that has a string foot within ``radius`` of it, whose height
    (``height[g_lab]``) its top matches within the factor ``_WEAK_HEIGHT_RATIO``, and
    whose footprint stays free of visible ground with it: the obstacle's footprint holds
    the convex hull of its feet, so a ground feature more than ``_FREE_SPACE_MARGIN_M``
    inside a triangle w-p-q (p, q feet of the obstacle) separates w from it. A
    silhouette lies beyond the obstacle's feet in bearing (by more than that margin
    across the line of sight): of the candidates of one obstacle only the outermost on
    either side is kept. Nor may the body between them hide visible ground: with the
    camera ``camera_height`` above the ground, ``_FACE_HIDDEN_MIN`` ground features
    behind a segment w-p (p a foot of the obstacle), where a body of the obstacle's
    height would hide them, separate w from it (`_face_hides_kernel`; a noise string in
    front of a box is no side of it).

    Args:
        xw: (W, 2) ground coordinates of the candidates' feet, ``top`` (W,) their tops.
        xy: (S, 2) the obstacles' string feet, ``g_lab`` (S,) their obstacle.
        height: (C,) the obstacles' heights, metres.
        radius: metres (``GpodConfig.detection.cluster_radius_m``).
        ground_xy: (G, 2) visible ground, or a callable returning it.
        camera_height: metres above the ground (inf: no test of hidden ground).
        sigma_w, sigma: (W,), (S,) range sigmas of the candidates' feet and the
            obstacles' feet, metres (None: 0).
    Returns:
        (W,) int obstacle of each candidate, -1 for none.
    """
    w_n = xw.shape[0]
    if w_n == 0 or xy.shape[0] == 0:
        return np.full(w_n, -1, np.int64)
    sw = np.zeros(w_n) if sigma_w is None else np.asarray(sigma_w, np.float64)
    sf = np.zeros(xy.shape[0]) if sigma is None else np.asarray(sigma, np.float64)
    g_all = np.ascontiguousarray(ground_xy() if callable(ground_xy) else ground_xy,
                                 np.float64).reshape(-1, 2)
    if kg.nb_owners is not None:
        # The same tests, compiled (numpy's bearings: its atan2 differs in last bits).
        xw = np.ascontiguousarray(xw, np.float64)
        xy = np.ascontiguousarray(xy, np.float64)
        return kg.nb_owners(xw, np.asarray(top, np.float64), xy, np.asarray(g_lab, np.int64),
                          np.asarray(height, np.float64), float(radius),
                          float(camera_height), sw, sf, np.arctan2(xw[:, 1], xw[:, 0]),
                          np.arctan2(xy[:, 1], xy[:, 0]), g_all)
    dist = np.hypot(xw[:, None, 0] - xy[None, :, 0], xw[:, None, 1] - xy[None, :, 1])
    tp = np.asarray(top, np.float64)[:, None]
    hk = np.asarray(height, np.float64)[g_lab][None, :]
    ok = (dist <= radius) & (tp * _WEAK_HEIGHT_RATIO >= hk) & (tp <= _WEAK_HEIGHT_RATIO * hk)
    dist = np.where(ok, dist, np.inf)
    j = np.argmin(dist, axis=1)
    lab = np.where(np.isfinite(dist[np.arange(w_n), j]), g_lab[j], -1).astype(np.int64)
    m_ = _FREE_SPACE_MARGIN_M
    # A silhouette widens the obstacle: only the outermost candidate beyond its feet on
    # either side (in bearing, by more than the margin across the line of sight: feet
    # are located to a few centimetres) counts; one between them, or along the line of
    # sight of an outermost foot (the same silhouette), is none.
    bw = np.arctan2(xw[:, 1], xw[:, 0])
    tol = m_ / np.maximum(np.hypot(xw[:, 0], xw[:, 1]), 1e-9)
    bf = np.arctan2(xy[:, 1], xy[:, 0])
    out = np.full(w_n, -1, np.int64)
    for k in np.unique(lab[lab >= 0]):
        mine = flat_nonzero(lab == k)
        f = xy[g_lab == k]
        sf_k = sf[g_lab == k]
        bk = bf[g_lab == k]
        for sgn, side in ((1.0, mine[bw[mine] > bk.max() + tol[mine]]),
                          (-1.0, mine[bw[mine] < bk.min() - tol[mine]])):
            # The outermost candidate on this side that no visible ground separates.
            for w in side[np.argsort(-sgn * bw[side], kind='stable')]:
                if f.shape[0] >= 2 and _separated(xw[w], f, g_all, m_):
                    continue
                if _face_hides_kernel(float(xw[w, 0]), float(xw[w, 1]), float(sw[w]), f,
                                      sf_k, g_all, float(height[k]) / camera_height, m_,
                                      _FACE_HIDDEN_MIN):
                    continue
                out[w] = k
                break
    return out


def _separated(w: np.ndarray, f: np.ndarray, g_all: np.ndarray, margin: float) -> bool:
    """Whether a ground point of g_all (G, 2) lies more than ``margin`` inside one of
    the triangles w-p-q of pairs p, q of the points f (F >= 2, 2)."""
    if g_all.shape[0] == 0:
        return False
    pts = np.vstack([f, w[None, :]])
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    g = g_all[np.all((g_all >= lo) & (g_all <= hi), axis=1)]
    if g.shape[0] == 0:
        return False
    ii, jj = np.triu_indices(f.shape[0], 1)
    n = np.broadcast_to(w[None, None, :], (ii.size, 1, 2))
    return bool(_ground_inside(g, f[ii], n, f[jj], margin).any())

