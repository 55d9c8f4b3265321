"""Evidence over time in the world: an egocentric 2.5-D map of raised, dropped and free ground.

A detection in one stereo pair can be a mismatch: a repetitive pattern (a drainage grate,
paving joints, a painted line) matched one period off stands above or below the ground
plane in that pair. What tells it from an obstacle is that it is not *where* an obstacle
would be: as the viewpoint moves, a mismatch moves in the world (its false depth follows
the pattern's period in the image, not a surface), while a real obstacle stays where it
is. This module keeps the matched evidence in a grid fixed in the world and reports only
what stays.

Frames (REP 103):

* the ground frame G of a pair: origin on the ground plane below the left camera, x the
  walking direction (the optical axis projected onto the plane), y left, z up along the
  plane's normal (`core.camera.ground_axes`);
* the map frame W: a horizontal frame fixed in the world (the first ground frame, moved
  by the camera motion since). The grid's axes are W's; the wearer's pose in W is an
  SE(2) pose (x, y, yaw) of the current G. The grid is re-centred on the wearer by whole
  cells (the evidence does not blur).

Each pair, `EvidenceMap.update`:

1. moves the wearer: the camera motion ``T_prev_curr`` (``X_prev = R X_curr + t``,
   left optical frames, `/egomotion`'s convention) gives ``T_Gprev_Gcurr =
   T_Gprev_cam · T_prev_curr · T_cam_Gcurr``, whose horizontal part (x, y, yaw) is
   composed onto the pose. With no motion the identity is used while the rig stands
   still; while it moves with no motion for more than ``motion_gap_frames`` pairs the
   map is cleared (its evidence can no longer be placed).
2. decays every cell's log-odds towards the prior: ``L = L exp(-dt / decay_s)``.
3. places each matched edge pixel of the pair (`core.map_evidence`, the measurement
   model): its 3-D point from (u, v, d), its height above the plane h and that height's
   standard deviation from the pixel's disparity noise, ``σ_h = |h(d + σ_d) - h(d)|``,
   σ_d the detector's per-pixel threshold over ``threshold_k``; a pixel the detector
   counted as an obstacle is *raised* evidence at the cell below it, one counted as a
   drop is *drop* evidence, a reliably matched pixel on the plane is *ground* evidence
   (free space) at its cell.
4. updates the cells: raised evidence in a cell adds ``hit_logodds`` to its raised
   log-odds ``L_r`` (once per pair: the pixels of one pair share their errors; from
   ``max(L_r, 0)``, a thing may step in, when the pair has ``appear_min_pixels`` there
   or the pair before had raised evidence near it), drop evidence likewise to the drop log-odds
   ``L_d`` (from ``L_d`` itself with ``drop_weighs_ground``: lower ground does not step
   in), ground evidence with no raised evidence there subtracts ``free_logodds`` from
   ``L_r`` and, where its height is known to ``drop_clear_max_sigma_m``, from ``L_d`` (a
   thing said to be there is cleared by the ground seen where it stood); a confirmed
   cell in plain view with no evidence of the pair near it loses
   ``miss_logodds`` (`_unseen`: a passer-by who walked on is not seen again); log-odds
   stay within [``min_logodds``, ``max_logodds``]; a confirmed drop whose nearest
   point has come within ``hold.margin_m`` of the nearest ground in view, confirmed
   farther, keeps its drop log-odds through the pair until the wearer passes it
   (`core.map_drop_hold`, rule_drop_hold: its edge is out of view, and the pair's
   plane may be the lower ground beyond it). The top of a raised
   cell is a scalar Kalman filter per cell (batched):

       predict:  x = F x,          F = 1 (a thing stays as tall as it is)
                 P = F P Fᵀ + Q,   Q = q² dt
       update:   y = z - H x,      H = 1, z the pair's highest raised point in the cell
                 S = H P Hᵀ + R,   R = σ_h² of that point
                 K = P Hᵀ S⁻¹
                 x = x + K y
                 P = (1 - K H) P

5. counts viewpoints: a cell remembers where the wearer was when its evidence began;
   it has *two views* once it is seen raised (or dropped) again from at least
   ``min_baseline_m`` away, or while the rig stands still in ``still_min_frames``
   pairs (a still rig has no parallax; its frames are separate looks only in time).
6. reports: cells with ``L ≥ report_logodds`` and two views are *confirmed*. A raised
   one in the image (in plain view or hidden behind a nearer thing) that the pair saw
   nothing at is not reported once its last evidence is older than ``unseen_report_s``;
   nor, as old and wherever it is (out of the image too), one whose raised evidence
   began where the ground was seen at most ``moved_in_s`` before and that stands at
   least ``moved_in_min_height_m`` high (a thing that moved in, a passer-by, may have
   moved on; a thing walked up to covers its ground; the raised side of a kerb is
   ground seen as ground before the kerb is measured, and is lower). Connected
   regions of them (8-connected, gaps of ``join_cells`` bridged) are obstacles
   (drop regions of at least ``min_drop_cells``: drop-offs, which are wide) with the
   nearest point to the wearer, the top height, the width across the line of sight,
   a confidence (the largest P of its cells) and an id kept from the region of the
   previous pair it overlaps most (published as the detector's reports by
   `core.map_reports.objects_to_obstacles`).

A cleared cell (``L_r ≤ 0`` and ``L_d ≤ 0``) forgets its height and its views, so a
passer-by's cells, cleared by the ground seen behind them, leave no trail.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core import map_grid, map_kernels, map_sight
from asmonc_vision.core.camera import MetricPlane, StereoCamera, columns, sub_rows
from asmonc_vision.core.map_drop_hold import DropHold, nearest_ground_in_view
from asmonc_vision.core.map_evidence import (DROP, GROUND, RAISED, PairEvidence, ground_frame,
                                             ground_motion)
from asmonc_vision.core.map_settings import EvidenceMapConfig
from asmonc_vision.core.map_step_up import stepped_onto
from .npfast import flat_nonzero, unique_counts


@dataclass(frozen=True)
class MapObject:
    """A connected region of confirmed cells, as seen from the current pair.

    Attributes:
        object_id: stable id (> 0) of the region, kept while it overlaps its previous cells.
        is_drop: True for a drop-off region.
        nearest_xy: (2,) float64 nearest point of the region to the wearer, m, ground frame G
            of the current pair (x forward, y left).
        far_xy: (2,) float64 the region's cells' points, (k, 2) in G, m.
        height: m, the highest cell top (drop: the lowest, negative).
        width: m, extent across the line of sight to the nearest point.
        confidence: 0..1, the largest P(raised) (drop: P(drop)) of its cells.
        cells: number of confirmed cells.
        fresh_pixels: matched edge pixels of this pair that fell in the region's cells.
        age_s: s since a cell of the region last had evidence of its kind.
    """

    object_id: int
    is_drop: bool
    nearest_xy: np.ndarray
    far_xy: np.ndarray
    height: float
    width: float
    confidence: float
    cells: int
    fresh_pixels: int
    age_s: float


def _compose(pose: np.ndarray, dx: float, dy: float, dyaw: float) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * dx - s * dy, pose[1] + s * dx + c * dy,
                     math.atan2(math.sin(pose[2] + dyaw), math.cos(pose[2] + dyaw))])


class EvidenceMap:
    """The egocentric evidence map; see the module docstring.

    Arrays are (n, n) indexed [iy, ix] (row along W's y, column along W's x, as
    nav_msgs/OccupancyGrid lays them out), cell (iy, ix) covering
    ``origin + cell * ([ix, ix + 1), [iy, iy + 1))`` in W.
    """

    def __init__(self, config: EvidenceMapConfig | None = None) -> None:
        self.config = config or EvidenceMapConfig()
        c = self.config
        self.n = int(math.ceil(2 * c.radius_m / c.cell_m))
        self._next_id = 1
        self._hold = DropHold(c.hold)
        map_kernels.warm_up()
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget all evidence and the wearer's pose."""
        n = self.n
        self.L_r = np.zeros((n, n), np.float32)        # log-odds raised
        self.L_d = np.zeros((n, n), np.float32)        # log-odds drop
        self.h_x = np.zeros((n, n), np.float32)        # height estimate x, m
        self.h_P = np.full((n, n), np.inf, np.float32)  # its variance P, m² (inf: none)
        self.pt_xy = np.zeros((n, n, 2), np.float32)   # mean evidence point in W, m
        self.first_xy = np.full((n, n, 2), np.nan, np.float32)  # wearer when evidence began
        self.still_hits = np.zeros((n, n), np.int16)
        self.two_views = np.zeros((n, n), bool)
        self.last_hit_s = np.full((n, n), -np.inf)
        self.raised_s = np.full((n, n), -np.inf)      # raised evidence last entered, s
        self.free_s = np.full((n, n), -np.inf)        # ground last seen there, finely
        self.moved_in = np.zeros((n, n), bool)        # raised where ground was just seen
        self.drop_before = np.zeros((n, n), bool)     # drop confirmed beyond the hold's reach
        self.ids = np.zeros((n, n), np.int32)          # region id of the previous pair
        self.pose = np.zeros(3)                        # G in W: x, y, yaw
        self.origin = np.array([-self.config.radius_m, -self.config.radius_m])
        self._plane: MetricPlane | None = None
        self._hold.reset()
        self._stamp_s: float | None = None
        self._entered_s = -np.inf                      # the last pair entered, s
        self._gap = 0
        #: pairs entered since the last reset (the map's evidence is continuous over them)
        self.placed_pairs = 0
        self._pair_count: np.ndarray | None = None
        #: the cells with raised or drop pixels of the pair (flat indices)
        self._pair_cells = np.zeros(0, np.int64)
        self._counts = map_kernels.PixelCounts(n * n)
        #: (n * n,) bool: the confirmed cells in plain view this pair saw nothing at
        self._missed = np.zeros(n * n, bool)
        self.objects: tuple[MapObject, ...] = ()

    @property
    def has_pose(self) -> bool:
        """True once a pair with a ground plane has placed the wearer."""
        return self._plane is not None

    def _scroll(self) -> None:
        """Re-centre the grid on the wearer by whole cells, once it is ``recentre_m`` off."""
        c = self.config
        centre = self.origin + c.radius_m
        off = self.pose[:2] - centre
        if np.max(np.abs(off)) < c.recentre_m:
            return
        k = np.round(off / c.cell_m).astype(int)      # cells to shift, (x, y)
        self.origin = self.origin + k * c.cell_m
        fills = ((self.L_r, 0), (self.L_d, 0), (self.h_x, 0), (self.h_P, np.inf),
                 (self.pt_xy, 0), (self.first_xy, np.nan), (self.still_hits, 0),
                 (self.two_views, False), (self.last_hit_s, -np.inf), (self.ids, 0),
                 (self.raised_s, -np.inf),
                 (self.free_s, -np.inf), (self.moved_in, False), (self.drop_before, False))
        for a, fill in fills:
            map_grid.shift(a, int(k[1]), int(k[0]), fill)

    # ------------------------------------------------------------------ update
    def update(self, stamp_s: float, plane: MetricPlane | None, ev: PairEvidence | None,
               motion: tuple | None, still: bool, cam: StereoCamera | None = None
               ) -> tuple[MapObject, ...]:
        """Enter one pair and return the map's objects (see the module docstring).

        Args:
            stamp_s: the pair's time, s.
            plane: the pair's ground plane (None: no plane; nothing is entered).
            ev: the pair's evidence (`pair_evidence`, in this pair's G), or None.
            motion: camera motion from the previous pair, (R (3, 3), t (3,)[, cov]),
                ``X_prev = R X_curr + t``, left optical frames, m; None if unknown.
            still: the rig stood still since the previous pair.
            cam: the stereo camera; given, a region's cells in the image and those out of
                it (walked past, below or beside the view) are reported apart, each at
                its own nearest point (the part in view is what can be seen now).
        Returns:
            The confirmed objects, nearest first (also kept as ``self.objects``).
        """
        c = self.config
        dt = 0.0 if self._stamp_s is None else max(stamp_s - self._stamp_s, 0.0)
        self._stamp_s = stamp_s
        moved = self._move(plane, motion, still)
        if moved is None:
            return self.objects
        self.placed_pairs += 1
        # rule_drop_hold: a confirmed drop whose edge has left the view keeps its log-odds
        drops = self._confirmed_cells(drop=True)
        held, let_go = self._hold.cells(drops, self.ids.reshape(-1)[drops],
                                        self.pt_xy.reshape(-1, 2)[drops].astype(np.float64),
                                        self.to_ground, cam, plane,
                                        self.drop_before.reshape(-1),
                                        self.h_x.reshape(-1)[drops].astype(np.float64))
        held_L = self.L_d.reshape(-1)[held]
        # in place: still, or a step shorter than stationary_step_m (turning on the spot);
        # no parallax, so only separate frames can count as separate looks
        still = still or moved < c.stationary_step_m
        # decay towards the prior: L = L exp(-dt / τ)
        if dt > 0:
            k = np.float32(math.exp(-dt / c.decay_s))
            self.L_r *= k
            self.L_d *= k
            # height predict: x = x, P = P + q² dt
            self.h_P += np.float32(c.height_process_noise ** 2 * dt)
        self._pair_count = None
        self._missed[:] = False
        if ev is not None and ev.xy.shape[0]:
            self._enter(stamp_s, ev, still)
            if cam is not None:
                self._unseen(ev, cam)
        if cam is not None and plane is not None:
            self._step_up(cam, plane)
        Ld = self.L_d.reshape(-1)
        Ld[held] = np.maximum(Ld[held], held_L)
        Ld[let_go] = np.minimum(Ld[let_go], 0.0)
        self._forget(let_go)
        self.objects = self._regions(stamp_s, cam)
        return self.objects

    def _move(self, plane: MetricPlane | None, motion, still: bool) -> float | None:
        """Carry the wearer's pose by the motion; the step's length (m; inf when unknown),
        or None when the pair cannot be entered (no plane)."""
        c = self.config
        if plane is None:
            # no plane: nothing entered; the pose is carried by the motion over the
            # previous plane (the ground taken as unchanged)
            if self._plane is not None and motion is not None:
                self._gap = 0
                dx, dy, dyaw = ground_motion(self._plane, self._plane, motion[0], motion[1])
                self.pose = _compose(self.pose, dx, dy, dyaw)
                self._scroll()
            elif not still:
                self._gap += 1
                if self._gap > c.motion_gap_frames:
                    self.reset()
            self.objects = ()
            return None
        step = math.inf
        if self._plane is not None:
            if motion is None and still:
                motion = (np.eye(3), np.zeros(3))
            if motion is None:
                self._gap += 1
                if self._gap > c.motion_gap_frames:
                    self.reset()
                # else the previous pose is held: the evidence stays where it was
                self._plane = plane
                return step
            self._gap = 0
            dx, dy, dyaw = ground_motion(self._plane, plane, motion[0], motion[1])
            self.pose = _compose(self.pose, dx, dy, dyaw)
            step = math.hypot(dx, dy)
            self._scroll()
        self._plane = plane
        return step

    def _step_up(self, cam: StereoCamera, plane: MetricPlane) -> None:
        """rule_step_up (`core.map_step_up`): let go the confirmed raised cells of the
        ground the wearer has walked onto."""
        c = self.config
        if not c.step_up.enabled:
            return
        # the cells walked over lie within behind_m + depth_m of the wearer: none
        # confirmed there (most pairs), nothing to do
        r = c.step_up.behind_m + c.step_up.depth_m + c.cell_m
        x, y = (float(self.pose[k] - self.origin[k]) / c.cell_m for k in (0, 1))
        k = r / c.cell_m
        win = (slice(max(int(y - k), 0), max(int(y + k) + 1, 0)),
               slice(max(int(x - k), 0), max(int(x + k) + 1, 0)))
        if np.count_nonzero((self.L_r[win] >= c.report_logodds)
                            & self.two_views[win]) < c.step_up.min_cells:
            return
        cells = self._confirmed_cells()
        level, walked = stepped_onto(self._cell_xy(cells), self.h_x.reshape(-1)[cells],
                                     nearest_ground_in_view(cam, plane), self.config.step_up)
        if not walked.any():
            return
        at = cells[level | walked]
        go = [r for r in self._label(self._grid_of(at) > 0, at)
              if np.isin(r, cells[walked]).any()]
        if not go:
            return
        go = np.concatenate(go)
        Lr = self.L_r.reshape(-1)
        Lr[go] = np.minimum(Lr[go], 0.0)
        self._forget(go[self.L_d.reshape(-1)[go] <= 0])

    def _surest(self, ev: PairEvidence, inside: np.ndarray, sel: np.ndarray,
                flat: np.ndarray, cells: np.ndarray) -> np.ndarray | float:
        """How much a pair's evidence counts in each of ``cells`` (K,): the weight of the
        surest of its pixels there (``sel`` (M,) bool over the pixels ``inside`` the grid,
        (M,) indices of ev's, ``flat`` (S,) the cells of the selected ones), with
        ``weigh_by_rivals``; else 1.
        The pixels of one pair share their errors (a grate's bars are all a period off
        alike): the cell's evidence is as sure as its surest match."""
        if ev.weight is None or not self.config.weigh_by_rivals:
            return 1.0
        if map_kernels.nb_surest is not None:
            return map_kernels.nb_surest(np.asarray(flat, np.int64),
                                         np.asarray(ev.weight[inside][sel], np.float64),
                                         np.asarray(cells, np.int64))
        best = np.zeros(self.n * self.n)
        np.maximum.at(best, flat, ev.weight[inside][sel])
        return best[cells]

    def _cell_xy(self, cells: np.ndarray) -> np.ndarray:
        """(K, 2) evidence points of ``cells`` (flat indices) in the current G, m."""
        return self.to_ground(self.pt_xy.reshape(-1, 2)[cells].astype(np.float64))

    def to_world(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) points of the current G to W, m."""
        cy, sy = math.cos(self.pose[2]), math.sin(self.pose[2])
        x, y = xy[:, 0], xy[:, 1]
        return columns(self.pose[0] + cy * x - sy * y, self.pose[1] + sy * x + cy * y)

    def to_ground(self, w: np.ndarray) -> np.ndarray:
        """(N, 2) points of W to the current G, m."""
        cy, sy = math.cos(self.pose[2]), math.sin(self.pose[2])
        x, y = w[:, 0] - self.pose[0], w[:, 1] - self.pose[1]
        return columns(cy * x + sy * y, -sy * x + cy * y)

    def _cells(self, w: np.ndarray, dx: int = 0, dy: int = 0
               ) -> tuple[np.ndarray, np.ndarray]:
        """Flat cell index of W points (N, 2) (or of the cell ``dx``, ``dy`` cells from
        each) and a mask of those inside the grid (the index of the others is clipped
        into it)."""
        ij = np.floor(sub_rows(w, self.origin) / self.config.cell_m).astype(np.int64)
        ix, iy = ij[:, 0] + dx, ij[:, 1] + dy
        inside = (ix >= 0) & (iy >= 0) & (ix < self.n) & (iy < self.n)
        ix, iy = ix.clip(0, self.n - 1), iy.clip(0, self.n - 1)
        return iy * self.n + ix, inside

    def _enter(self, stamp_s: float, ev: PairEvidence, still: bool) -> None:
        """Enter one pair's evidence into the cells (module docstring, step 4).

        The cells' arithmetic touches only the cells this pair has evidence in (the
        indices of the kinds' cells, sorted): the log-odds of every other cell are
        within [min_logodds, max_logodds] already (the decay towards 0 keeps them so).
        """
        c = self.config
        w = self.to_world(ev.xy)
        flat, inside = self._cells(w)
        inside = flat_nonzero(inside)         # (one selection for the arrays below)
        flat, w, kind = flat[inside], w[inside], ev.kind[inside]
        h, sh = ev.height[inside], ev.sigma_h[inside]
        hit = c.hit_logodds * (c.still_hit_factor if still else 1.0)
        f_r, f_d = flat[kind == RAISED], flat[kind == DROP]
        # pixels per cell of each kind (n_sure: ground of a finely known height), and the
        # cells of each kind, ascending
        sure = (kind == GROUND) & (sh <= c.drop_clear_max_sigma_m)
        n_r, n_d, n_g, n_sure, u_r, u_d, u_g = self._count(flat, kind, sure)
        self._pair_cells = np.concatenate((u_r, u_d))
        Lr, Ld = self.L_r.reshape(-1), self.L_d.reshape(-1)
        # a cell seen through by this pair's sight lines takes none of its raised evidence
        seen_through = self._rays(ev.xy[ev.kind == GROUND], n_r)
        n_r[seen_through] = 0
        raised = u_r[n_r[u_r] != 0]
        dropc = u_d[(n_d[u_d] >= c.min_drop_pixels) & (n_r[u_d] == 0)]
        # (ground in a cell with no more raised and drop pixels: in u_g)
        free_g = (n_g[u_g] >= c.min_ground_pixels) & (n_g[u_g] > n_r[u_g] + n_d[u_g])
        if c.clear_guard_cells > 0:
            # ground seen beside a thing seen in this pair (its foot, the ground in front
            # of its face in the same cell) does not clear it
            free_g &= ~self._near(np.concatenate((raised, u_d)), u_g, c.clear_guard_cells)
        free = u_g[free_g]
        # ground that can rule a drop out: pixels of height known to drop_clear_max_sigma_m
        free_d = free
        if c.drop_clear_max_sigma_m > 0:
            free_d = free[n_sure[free] >= c.min_ground_pixels]
        if c.moved_in_s > 0:
            self._moved_in(stamp_s, raised[Lr[raised] <= 0], free_d)
        # a thing that appears (a face: appear_min_pixels; or seen in the pair before
        # too) is not held back by the ground seen there: L = max(L, 0) + hit; a pixel
        # or two once, a mismatch that comes and goes, and lower ground (terrain,
        # drop_weighs_ground) add to it: L = L + hit
        hit_r = hit * self._surest(ev, inside, kind == RAISED, f_r, raised)
        hit_d = hit * self._surest(ev, inside, kind == DROP, f_d, dropc)
        rs = self.raised_s.reshape(-1)
        restart = np.ones(raised.size, bool)
        if c.appear_min_pixels > 1:
            before = flat_nonzero(rs >= self._entered_s)   # raised in the pair before
            restart = ((n_r[raised] >= c.appear_min_pixels)
                       | self._near(before, raised, c.miss_guard_cells))
        Lr[raised] = np.where(restart, np.maximum(Lr[raised], 0.0), Lr[raised]) + hit_r
        rs[raised] = stamp_s
        self._entered_s = stamp_s
        Ld[dropc] = (Ld[dropc] if c.drop_weighs_ground else np.maximum(Ld[dropc], 0.0)) + hit_d
        Lr[free] -= c.free_logodds
        Ld[free_d] -= c.free_logodds
        for L, cells in ((Lr, np.concatenate((raised, free))),
                         (Ld, np.concatenate((dropc, free_d)))):
            L[cells] = L[cells].clip(c.min_logodds, c.max_logodds)
        if seen_through.size:
            Lr[seen_through] -= c.ray_logodds
            Lr[seen_through] = Lr[seen_through].clip(c.min_logodds, c.max_logodds)
            free = np.union1d(free, seen_through)
        # cells whose evidence is gone forget their height and views
        gone = free[(Lr[free] <= 0) & (Ld[free] <= 0)]
        self._forget(gone)
        # height: per cell, the pair's highest raised point (drop: lowest) is z, R = σ_h²
        # (a Kalman update); the cells' evidence points and last hits
        map_kernels.enter_heights(flat, kind, h, sh, w, raised, dropc, self.h_x.reshape(-1),
                                  self.h_P.reshape(-1), self.pt_xy.reshape(-1, 2),
                                  self.last_hit_s.reshape(-1), stamp_s)
        self._views(np.concatenate((raised, dropc)), still)

    def _count(self, flat: np.ndarray, kind: np.ndarray, sure: np.ndarray,
               use_kernel: bool = True) -> tuple[np.ndarray, ...]:
        """A pair's pixels per cell (`map_kernels.PixelCounts.count`); also kept:
        ``_pair_count`` = n_r + n_d, (n * n,) int64."""
        out = self._counts.count(flat, kind, sure, use_kernel)
        self._pair_count = self._counts.pair
        return out

    def _near(self, marked: np.ndarray, cells: np.ndarray, radius: int) -> np.ndarray:
        """(C,) bool: whether any of the ``marked`` cells ((K,) int64 flat indices) lies
        within ``radius`` cells in x and in y of each of ``cells`` ((C,) int64 flat
        indices): the grid of the marked cells dilated by that square
        (`map_grid.dilate`), read at the cells (`map_kernels.near_kernel` where it
        compiled: the same booleans)."""
        if map_kernels.nb_near is not None:
            return map_kernels.nb_near(np.asarray(marked, np.int64), self.n,
                                       np.asarray(cells, np.int64), int(radius))
        return map_grid.dilate(self._grid_of(marked), radius).reshape(-1)[cells] > 0

    def _grid_of(self, *cells: np.ndarray) -> np.ndarray:
        """(n, n) uint8: 1 at the given flat cell indices, else 0."""
        g = np.zeros(self.n * self.n, np.uint8)
        for cs in cells:
            g[cs] = 1
        return g.reshape(self.n, self.n)

    def _moved_in(self, stamp_s: float, begins: np.ndarray, free: np.ndarray) -> None:
        """Raised evidence begins in cells ``begins`` (flat indices) where ground was seen
        finely at most ``moved_in_s`` before: a thing that moved in (a passer-by), not
        one the wearer walks up to (it covers its ground). ``free``: the cells whose
        ground this pair saw finely."""
        fs = self.free_s.reshape(-1)
        self.moved_in.reshape(-1)[begins] = stamp_s - fs[begins] <= self.config.moved_in_s
        fs[free] = stamp_s

    def _views(self, seen: np.ndarray, still: bool) -> None:
        """Viewpoints of the cells ``seen`` (flat indices) raised or dropped in this pair:
        where their evidence began, and two views once seen again from min_baseline_m
        away (or in still_min_frames pairs of a still rig)."""
        if not seen.size:
            return
        c = self.config
        fx = self.first_xy.reshape(-1, 2)
        began = ~np.isfinite(fx[seen, 0])
        fx[seen[began]] = self.pose[:2]
        moved = np.hypot(fx[seen, 0] - self.pose[0], fx[seen, 1] - self.pose[1])
        tv = self.two_views.reshape(-1)
        sh_ = self.still_hits.reshape(-1)
        if still:
            sh_[seen] = np.minimum(sh_[seen] + 1, 30000)
        tv[seen] |= (moved >= c.min_baseline_m) | (sh_[seen] >= c.still_min_frames)

    def _rays(self, ground_xy: np.ndarray, n_r: np.ndarray, use_kernel: bool = True
              ) -> np.ndarray:
        """Flat indices of raised cells seen through by this pair's ground matches
        (`map_sight.seen_through`: sight lines passing below a cell's top, within
        ``ray_lateral_m`` of its evidence point, on both sides); the cells with positive
        raised log-odds and a height, against the plane's camera height."""
        c = self.config
        none = np.zeros(0, np.int64)
        if c.ray_logodds <= 0 or ground_xy.shape[0] == 0 or self._plane is None:
            return none
        Lr, hx, hP = self.L_r.reshape(-1), self.h_x.reshape(-1), self.h_P.reshape(-1)
        cells = flat_nonzero((Lr > 0) & np.isfinite(hP))
        if not cells.size:
            return none
        top = hx[cells] - np.maximum(c.ray_margin_m, 2.0 * np.sqrt(hP[cells]))
        through = map_sight.seen_through(self._cell_xy(cells), top, ground_xy,
                                         float(self._plane.height), n_r[cells], c,
                                         use_kernel)
        return cells[through]

    def _label(self, mask: np.ndarray, cells: np.ndarray | None = None) -> list[np.ndarray]:
        """Flat cell indices of each region of ``mask`` (8-connected, gaps of
        ``join_cells`` bridged; `map_grid.label_regions`; ``cells``: the mask's cells,
        ascending, when known)."""
        return map_grid.label_regions(mask, self.config.join_cells, cells=cells)

    def _unseen(self, ev: PairEvidence, cam: StereoCamera) -> None:
        """Confirmed cells in plain view that this pair saw nothing at are fading.

        A confirmed cell in plain view, with none of this pair's raised or drop evidence
        within ``miss_guard_cells`` of it, loses ``miss_logodds``: a thing that stays
        where it is is seen again; a passer-by who walked on, or a mismatch, is not. In
        plain view: the foot of its evidence point is in both images
        (``miss_margin_px`` inside their borders), or for a raised cell the point at
        ``_SEEN_SHARE`` of its height (a level chest camera sees the upper part of a tall
        thing near the wearer, not its foot), the pair matched ground or a thing
        at its bearing beyond it (the sight line passed it), and no raised evidence
        nearer at its bearing (nothing in front hides it)."""
        c = self.config
        if (c.miss_logodds <= 0 and c.unseen_report_s <= 0) or self._pair_count is None:
            return
        # the confirmed cells, raised and drop (ascending),
        # and which of the two each is
        cells, conf_r, conf_d = self._confirmed_both()
        if not cells.size:
            return
        kept = flat_nonzero(~self._near(self._pair_cells, cells, c.miss_guard_cells))
        cells, conf_r, conf_d = cells[kept], conf_r[kept], conf_d[kept]
        if not cells.size:
            return
        g, feet, up = self._cell_feet(cells)
        view = map_sight.in_both_images(feet, cam, c.miss_margin_px)
        # a raised thing near a level camera shows its upper part, not its foot: the
        # point at _SEEN_SHARE of its height in view is in plain view too
        raised_cell = conf_r
        if raised_cell.any():
            seen_at = _SEEN_SHARE * np.maximum(self.h_x.reshape(-1)[cells], 0.0)   # (M,) m
            view |= raised_cell & map_sight.in_both_images(
                feet + seen_at[:, None] * up[None, :], cam, c.miss_margin_px)
        # in plain view: this pair saw something at the cell's bearing beyond it, and
        # no raised evidence nearer (`map_sight.passed_unhidden`)
        passed, unhidden = map_sight.passed_unhidden(g, ev.xy, ev.kind, c.cell_m)
        unhidden &= view
        # not reported once stale (unseen_report_s): in the image, hidden or not (a
        # passer-by's cells behind them; the ground beyond need not have been matched;
        # what hides a thing is nearer and reported itself)
        self._missed[cells[view]] = True
        fading = unhidden & passed
        self.L_r.reshape(-1)[cells[fading & conf_r]] -= c.miss_logodds
        self.L_d.reshape(-1)[cells[fading & conf_d]] -= c.miss_logodds
        self.L_r.clip(c.min_logodds, c.max_logodds, out=self.L_r)
        self.L_d.clip(c.min_logodds, c.max_logodds, out=self.L_d)

    def _cell_feet(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The evidence points of ``cells`` (flat indices): (M, 2) on the ground (wearer
        frame, x ahead, y left, m), (M, 3) in the current left optical frame (their feet
        on the plane, m), and (3,) the plane's up normal in that frame."""
        assert self._plane is not None                 # after an update
        Rcg, o = ground_frame(self._plane)
        g = self._cell_xy(cells)
        return g, g @ Rcg[:, :2].T + o[None, :], Rcg[:, 2]

    def _forget(self, cells: np.ndarray) -> None:
        if not cells.size:
            return
        self.h_P.reshape(-1)[cells] = np.inf
        self.first_xy.reshape(-1, 2)[cells] = np.nan
        self.still_hits.reshape(-1)[cells] = 0
        self.two_views.reshape(-1)[cells] = False
        self.moved_in.reshape(-1)[cells] = False
        self.drop_before.reshape(-1)[cells] = False

    def ground_seen_around(self, xy: np.ndarray, stamp_s: float, within_s: float
                           ) -> np.ndarray:
        """(N,) bool for points (N, 2) of the current G (m): the point's cell and the
        eight around it are in the grid and had their ground seen finely (to
        ``drop_clear_max_sigma_m``) at most ``within_s`` s before ``stamp_s``, and the
        eight hold no raised evidence (log-odds raised ≤ 0; the point's own cell may
        hold the latest pair's, which is what is being judged)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        out = np.full(len(xy), len(xy) > 0 and within_s > 0)
        if not out.any():
            return out
        w = self.to_world(xy)
        free_s, L_r = self.free_s.reshape(-1), self.L_r.reshape(-1)
        # the nine cells of each point at once, (N, 9) (`_cells` of each offset)
        ij = np.floor((w - self.origin[None, :]) / self.config.cell_m).astype(np.int64)
        ix, iy = ij[:, 0:1] + _AROUND_DX, ij[:, 1:2] + _AROUND_DY
        n = self.n
        inside = (ix >= 0) & (iy >= 0) & (ix < n) & (iy < n)
        flat = iy.clip(0, n - 1) * n + ix.clip(0, n - 1)
        ok = inside & (stamp_s - free_s[flat] <= within_s)
        ok[:, _AROUND_RING] &= L_r[flat[:, _AROUND_RING]] <= 0
        return out & ok.all(axis=1)

    # ------------------------------------------------------------------ objects
    def confirmed(self, drop: bool = False) -> np.ndarray:
        """(n, n) bool: the cells reported (log-odds ≥ ``report_logodds``, two views;
        `_confirmed_cells` on the grid)."""
        return self._grid_of(self._confirmed_cells(drop)) > 0

    def _confirmed_both(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The confirmed cells, raised or drop ((K,) int64 flat indices, ascending: from
        the cells with two views alone, those whose log-odds of a kind reach
        ``report_logodds`` and are not below the other kind's) and (K,) bool each,
        whether each is a raised one and whether a drop one (both where the two log-odds
        are equal)."""
        tv = flat_nonzero(self.two_views)
        lr, ld = self.L_r.reshape(-1)[tv], self.L_d.reshape(-1)[tv]
        rep = self.config.report_logodds
        is_r = (lr >= rep) & (lr >= ld)
        is_d = (ld >= rep) & (ld >= lr)
        sel = flat_nonzero(is_r | is_d)
        return tv[sel], is_r[sel], is_d[sel]

    def _confirmed_cells(self, drop: bool = False) -> np.ndarray:
        """(K,) int64 the flat indices of the cells `confirmed` reports, ascending (the
        raised or the drop ones of `_confirmed_both`)."""
        cells, is_r, is_d = self._confirmed_both()
        return cells[is_d if drop else is_r]

    def probability(self) -> np.ndarray:
        """(n, n) float32 P(raised) = 1 / (1 + exp(-L_r)) of every cell."""
        return 1.0 / (1.0 + np.exp(-self.L_r))

    def in_view(self, cells: np.ndarray, cam: StereoCamera) -> tuple[np.ndarray, np.ndarray]:
        """((k,) bool, (k,) bool): cells (flat indices) whose evidence point, at the
        ground or at its height, projects into the left image of the current pair; and
        those out of it below the image (in front of the wearer, walked up to)."""
        g, feet, up = self._cell_feet(cells)
        tops = feet + self.h_x.reshape(-1)[cells, None] * up[None, :]
        vis = np.zeros(cells.size, bool)
        below = np.zeros(cells.size, bool)
        for p in (feet, tops):
            z = p[:, 2]
            ok = z > 0.1
            zz = np.where(ok, z, 1.0)
            u = cam.f * p[:, 0] / zz + cam.cx
            v = cam.f * p[:, 1] / zz + cam.cy
            across = ok & (u >= 0) & (u <= cam.width - 1)
            vis |= across & (v >= 0) & (v <= cam.height - 1)
            below |= across & (v > cam.height - 1)
        # below the view: ahead of the wearer within the image's columns (as the
        # detector's tracks remember obstacles walked up to); beside it: passed
        below |= (g[:, 0] > 0) & (np.abs(g[:, 1]) * cam.f
                                  <= (0.5 * cam.width) * np.maximum(g[:, 0], 1e-3))
        return vis, below & ~vis

    def _regions(self, stamp_s: float, cam: StereoCamera | None = None
                 ) -> tuple[MapObject, ...]:
        c = self.config
        out: list[MapObject] = []
        new_ids = np.zeros_like(self.ids)
        used: set[int] = set()
        masks = []                     # (drop, the cells of a mask, flat indices)
        both, conf_r, conf_d = self._confirmed_both()
        for drop in (False, True):
            cells = both[conf_d if drop else conf_r]
            if not cells.size:
                continue
            if cam is None:
                masks.append((drop, cells))
                continue
            vis, below = self.in_view(cells, cam)
            if c.unseen_report_s > 0 and not drop:
                # in plain view, a raised thing is seen again or is gone (a passer-by
                # walked on); a drop's evidence is intermittent (its lower ground is
                # hidden by its edge), so a drop is reported from memory
                stale = stamp_s - self.last_hit_s.reshape(-1)[cells] > c.unseen_report_s
                vis &= ~(self._missed[cells] & stale)
                # a thing that moved in is not remembered where it is no longer seen
                # (hidden, or out of the image): it may have moved on. Not one lower
                # than a body: the raised side of a kerb is ground, seen as ground (under
                # the pixel threshold) before the kerb is measured, and stays put
                gone = (self.moved_in.reshape(-1)[cells] & stale
                        & (self.h_x.reshape(-1)[cells] >= c.moved_in_min_height_m))
                vis &= ~gone
                below &= ~gone
            masks.extend([(drop, cells[vis]), (drop, cells[below])])
        h_x = self.h_x.reshape(-1)
        ids, last_hit = self.ids.reshape(-1), self.last_hit_s.reshape(-1)
        for drop, cells in masks:
            if not cells.size:
                continue
            L = (self.L_d if drop else self.L_r).reshape(-1)
            # the cells' points in G, all at once (elementwise: each region's the same)
            g_cells = self._cell_xy(cells)
            for cs in self._label(self._grid_of(cells) > 0, cells):
                if cs.size < (c.min_drop_cells if drop else c.min_region_cells):
                    continue
                g = g_cells[np.searchsorted(cells, cs)]
                ahead = g[:, 0] > 0
                if not ahead.any():
                    continue            # passed: behind the wearer
                r = np.hypot(g[:, 0], g[:, 1])
                r[~ahead] = np.inf
                # the nearest point: of the cells within near_tolerance_m of the nearest
                # range, the one at their median bearing (a face square to the line of
                # sight is nearest where the sight line meets it, not at its noisiest cell)
                near_set = flat_nonzero(r <= float(r.min()) + c.near_tolerance_m)
                b = np.arctan2(g[near_set, 1], g[near_set, 0])
                b_med = float(b[np.argsort(b)[(near_set.size - 1) // 2]])
                r0 = float(r.min())
                near = r0 * np.array([math.cos(b_med), math.sin(b_med)])
                across = np.array([-near[1], near[0]]) / max(r0, 1e-6)
                lat = g @ across
                hx = h_x[cs]
                height = float(hx.min()) if drop else float(hx.max())
                # the id of the previous pair's region most of its cells had (the
                # smallest of equal counts), of those not taken by a nearer region
                prev = ids[cs]
                vals, cnt = unique_counts(prev[prev > 0])
                if used and vals.size:
                    free = np.array([int(x) not in used for x in vals.tolist()], bool)
                    vals, cnt = vals[free], cnt[free]
                if vals.size:
                    oid = int(vals[np.argmax(cnt)])
                else:
                    oid = self._next_id
                    self._next_id += 1
                used.add(oid)
                new_ids.reshape(-1)[cs] = oid
                conf = float(1.0 / (1.0 + math.exp(-float(L[cs].max()))))
                last = float(last_hit[cs].max())
                out.append(MapObject(
                    object_id=oid, is_drop=drop, nearest_xy=near, far_xy=g,
                    height=height, width=float(lat.max() - lat.min()) + c.cell_m,
                    confidence=conf, cells=int(cs.size),
                    fresh_pixels=(int(self._pair_count[cs].sum())
                                  if self._pair_count is not None else 0),
                    age_s=max(stamp_s - last, 0.0)))
        self.ids = new_ids
        out.sort(key=lambda o: float(np.hypot(*o.nearest_xy)))
        return tuple(out)

    # ------------------------------------------------------------------ views
    def occupancy(self) -> np.ndarray:
        """(n, n) int8 occupancy of the cells, [iy, ix]: P(raised) in percent (0-100),
        -1 where the cell holds no evidence (|L_r| and |L_d| below 0.05)."""
        p = np.rint(100.0 * self.probability()).astype(np.int8)
        unknown = (np.abs(self.L_r) < 0.05) & (np.abs(self.L_d) < 0.05)
        p[unknown] = -1
        return p

    def grid_in_camera(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The grid's placement in the current left optical frame: (R (3, 3), p (3,)),
        the rotation of W's axes and the position of the grid's corner (cell (0, 0)'s
        outer corner), m; None before a pair with a plane."""
        if self._plane is None:
            return None
        Rcg, o = ground_frame(self._plane)
        cy, sy = math.cos(self.pose[2]), math.sin(self.pose[2])
        Rgw = np.array([[cy, sy, 0.0], [-sy, cy, 0.0], [0.0, 0.0, 1.0]])   # W to G
        R = Rcg @ Rgw
        corner_g = Rgw @ np.array([self.origin[0] - self.pose[0],
                                   self.origin[1] - self.pose[1], 0.0])
        return R, Rcg @ corner_g + o


#: `EvidenceMap.ground_seen_around`: the offsets (x, y) of a cell and the eight around
#: it, and which of them are the eight
_AROUND_DX = np.repeat(np.arange(-1, 2), 3)[None, :]
_AROUND_DY = np.tile(np.arange(-1, 2), 3)[None, :]
_AROUND_RING = flat_nonzero((_AROUND_DX[0] != 0) | (_AROUND_DY[0] != 0))
#: `EvidenceMap._unseen`: a raised cell is in plain view when the point at this share of
#: its height is (the part of a tall thing a level camera sees near the wearer, below
#: its top, whose edge may be level and unmatched)
_SEEN_SHARE = 0.75

