"""Obstacles in one frame (`Detection._detect`): the disparity excess over the ground
(averaged along runs and, standing still, over frames), the obstacle pixels and
strings, their clusters, and each cluster's description (feet, nearest point, height,
extent, confidence).
"""
from __future__ import annotations

import math
from typing import cast

import numpy as np

from ..camera import (MetricPlane, StereoCamera, add_rows, ground_axes, plane_disparity,
                      row_norms, sub_scaled)
from ..edges import EdgeMap, gradient_noise_gain
from ..ground_surface import depth_noise, drop_margin, fit_ground_surface, level_grade
from ..matching import Candidates, Matches
from . import kernels as kn
from .faces import (
    _ground_points,
    described_by_part,
)
from .footing import _FrameContext, ground_coords, string_feet
from .grouping import _brink_bearings, _group_quantile, _normal_cdf, cluster_points_2d
from .nearest import nearest_points
from .plane_tracking import PlaneTracking
from .results import GpodFeatures, GpodObstacle, new_obstacle
from .rules import (
    DROP_RULES,
    PIXEL_RULES,
    PLACEMENT_RULES,
    STRING_RULES,
    FrameEvidence,
    Placement,
    run_rules,
)
from .runs import (
    _TRUE,
    matched_run_length,
    run_links,
    smooth_along_runs,
)
from .support import _features, _noise_key, contrary_rival_share
from ..npfast import flat_nonzero

#: A drop-off's reported foot is at its nearest range, in the median direction of the
#: nearest feet of its edge strings (one per string) that lie within this distance
#: (metres) or this fraction of the nearest range, whichever is larger, of it.
_NEAR_ZONE_M = 0.5
_NEAR_ZONE_FRACTION = 0.1
#: A drop's range is that of its pixel of this rank by range (0 = the nearest): a minimum
#: that one stray pixel cannot pull. (Its edge pixels are sparse: a percentile of them
#: lies measurably beyond the nearest visible lower ground.)
_DROP_RANK = 1
#: Edge strings within this many pixels of the left or right image border may be the
#: view's edge rather than an obstacle's silhouette.
_BORDER_PX = 3.0
#: The lone-face search's evidence bar is at least this many gradient-noise sigmas
#: (`faces.lone_face_points`).
_LONE_FLOOR_SIGMAS = 4.0
#: The standard deviation of the unblurred Sobel gradient per grey level of pixel noise.
_SOBEL_NOISE_GAIN = gradient_noise_gain(0.0)

#: Placement-only silhouette feet (`silhouette_owners`): an edge string that is no
#: obstacle may still be the other silhouette edge of a detected one. Its pixels above
#: ``_WEAK_FRACTION`` of the threshold must number ``_WEAK_MIN_PIXELS`` or more and their
#: mean smoothed excess exceed ``_WEAK_SIGMAS`` noise sigmas over sqrt(n / _WEAK_CORR)
#: (neighbouring smoothed pixels are correlated); its top must be at the obstacle's
#: height within the factor ``_WEAK_HEIGHT_RATIO``.
_WEAK_FRACTION = 0.5
_WEAK_MIN_PIXELS = 3
_WEAK_SIGMAS = 4.0
_WEAK_CORR = 2.0

#: `GpodDetector._stillness` compares the strong edges when there are this many, else
#: all edges.
_STILL_MIN_EDGES = 100


class Detection(PlaneTracking):
    """The per-frame obstacle stage of `GpodDetector`."""

    def _evidence_weight(self, strength: np.ndarray) -> np.ndarray:
        """How much of a pixel each matched edge pixel counts as evidence: weak edges are
        often mismatched, so a pixel weaker than obstacle_min_strength (or
        obstacle_min_edge_snr times the gradient noise) counts (strength / that)^2."""
        return np.minimum(strength / max(self._min_strength, 1e-6), 1.0) ** 2

    def _stillness(self, el: EdgeMap) -> bool:
        """Whether the rig stood still since the previous frame: most left edge pixels
        are where an edge pixel was (same row, within one column). Only the edges at
        least as strong as an obstacle's evidence needs (``detection.min_strength``, or
        more on a noisy camera) are compared, when there are ``_STILL_MIN_EDGES`` of
        them: the weak ones come and go with the pixel noise (a camera of noise sigma 4
        standing still kept 0.68 of all its edges in place, 0.93 of the strong ones).
        Remembers the edges compared."""
        h, w = el.shape
        prev = self._prev_edges
        strong = el.strength >= self._min_strength
        if int(np.count_nonzero(strong)) >= _STILL_MIN_EDGES:
            v, u_int = el.v[strong], el.u_int[strong]
        else:
            v, u_int = el.v, el.u_int
        n = v.shape[0]
        if kn.nb_still is not None:
            # The same image and hits, compiled.
            use = prev is not None and prev.shape == (h, w + 2) and n > 0
            img, hits = kn.nb_still(prev if use else np.zeros((1, 1), bool), use, v, u_int,
                                  h, w)
            self._prev_edges = img
            return use and bool(hits / n >= self.config.temporal.still_overlap)
        img = np.zeros((h, w + 2), bool)
        img[v, u_int + 1] = True
        self._prev_edges = img
        if prev is None or prev.shape != img.shape or n == 0:
            return False
        hit = prev[v, u_int] | prev[v, u_int + 1] | prev[v, u_int + 2]
        return bool(hit.mean() >= self.config.temporal.still_overlap)

    def _temporal_excess(self, m: Matches, excess: np.ndarray, still: bool,
                         shape: tuple[int, int], thr: np.ndarray | None = None) -> np.ndarray:
        """The excess of each match averaged (exponentially, over about
        ``temporal.frames`` frames) with the running average found at its place (same
        row, within one column) in the previous frame, when the rig stood still and the
        two agree to within ``temporal.gate_px`` and ``temporal.gate_thr`` times the
        pixel's threshold ``thr`` (K,) px, if given. Updates the running sums."""
        c = self.config
        h, w = shape
        k = len(m)
        lam = 1.0 - 1.0 / c.temporal.frames
        if kn.nb_temporal is not None:
            # The same neighbours, gate and sums, compiled.
            use = bool(still and self._acc is not None and lam > 0 and k)
            ps, pw = (self._acc if use and self._acc is not None     # (use: it is set)
                      else (np.zeros((1, 1), np.float32),) * 2)
            gate_thr = thr is not None and c.temporal.gate_thr > 0
            s_new, w_new, acc_s, acc_w = kn.nb_temporal(
                m.v, m.u_left, np.asarray(excess, np.float64),
                np.asarray(thr if gate_thr else np.zeros(0), np.float64), gate_thr,
                float(c.temporal.gate_px), float(c.temporal.gate_thr), float(lam), use, ps,
                pw, h, w)
            self._acc = (acc_s, acc_w)
            return s_new / w_new
        vv = m.v.astype(np.int64)
        uu = np.clip(np.rint(m.u_left).astype(np.int64), 0, w - 1)
        s_new = excess.astype(np.float64)
        w_new = np.ones(k)
        prev = self._acc
        if still and prev is not None and lam > 0 and k:
            ps, pw = prev
            cols = np.clip(uu[:, None] + np.array([0, -1, 1])[None, :], 0, w - 1)
            wp = pw[vv[:, None], cols]
            j = np.argmax(wp, axis=1)
            w0 = wp[np.arange(k), j].astype(np.float64)
            s0 = ps[vv, cols[np.arange(k), j]].astype(np.float64)
            with np.errstate(divide='ignore', invalid='ignore'):
                gate: float | np.ndarray = c.temporal.gate_px
                if thr is not None and c.temporal.gate_thr > 0:
                    gate = np.minimum(gate, c.temporal.gate_thr * thr)
                ok = (w0 > 0) & (np.abs(excess - s0 / w0) <= gate)
            s_new = np.where(ok, s_new + lam * s0, s_new)
            w_new = np.where(ok, w_new + lam * w0, w_new)
        acc_s = np.zeros((h, w), np.float32)
        acc_w = np.zeros((h, w), np.float32)
        if k:
            acc_s[vv, uu] = s_new
            acc_w[vv, uu] = w_new
        self._acc = (acc_s, acc_w)
        return s_new / w_new

    # ------------------------------------------------------------------ obstacles
    def _detect(self, m: Matches, u, v, d, cam: StereoCamera, metric: MetricPlane,
                d_min: float, d_max: float, el: EdgeMap, er: EdgeMap, cand: Candidates,
                still: bool) -> tuple[GpodFeatures, tuple[GpodObstacle, ...]]:
        """Obstacles and drop-offs of one frame's matches ``m`` (features u, v, d; the
        plane's disparity range d_min .. d_max; ``still``: the rig stood still): (the
        features with their obstacle / drop classes, the detections nearest first)."""
        c = self.config
        thr, _ = self.pixel_thresholds(_noise_key(m), v)
        pd, pts, h, low = self._ground_reference(u, v, d, cam, metric, thr / c.threshold.k,
                                                 still)
        excess = d - pd
        feet = sub_scaled(pts, h, metric.normal_up)            # (pts - h n, by column)
        ground_range = row_norms(add_rows(feet, metric.height * metric.normal_up))
        prev, run, smooth, nxt = self._runs(m, el, excess)
        in_range = ground_range <= c.detection.max_range_m
        ex_mean = self._temporal_excess(m, smooth, still, el.shape, thr)
        # Figural continuity: a run of detection.min_matched_run pixels at least, and longer for a
        # larger excess -- an edge standing on the ground rises by |b| px of excess per
        # row, so an excess E needs about E / |b| rows of it (a fraction of them, up to
        # detection.max_required_run, must be matched in one run).
        slope = max(abs(float(cast(np.ndarray, self._abc)[1])), 1e-3)   # (tracking: set)
        det = c.detection
        need = np.ceil(det.obstacle_run_fraction * np.abs(ex_mean) / slope).clip(
            det.min_matched_run, max(det.max_required_run, det.min_matched_run))
        usable = (run >= need) & in_range
        # The paper's test: obstacle pixels above the threshold, drop pixels as far below
        # the lowest ground the surface allows (``low`` px under its disparity,
        # `drop_margin`) where the plane is within the detection range; then the named
        # rules (rules.py) in order.
        obst = (ex_mean > thr) & (h <= c.detection.max_obstacle_height_m) & usable
        drop = np.zeros_like(obst)
        below = (ex_mean < -thr - low) & (h >= -c.drops.max_depth_m)
        if c.drops.enabled:
            drop = below & (pd >= cam.fb / c.detection.max_range_m) & (pd <= d_max) & usable
        sid = m.string_id
        n_s = max(el.num_strings, int(sid.max()) + 1 if sid.size else 0)
        ev = FrameEvidence(m=m, el=el, er=er, cand=cand, metric=metric, pd=pd, pts=pts, h=h,
                           excess=excess, ex_mean=ex_mean, thr=thr,
                           prev=prev, run=run, usable=usable, below=below, slope=slope,
                           weight=self._evidence_weight(m.strength),
                           min_px=self.min_obstacle_pixels(cam), n_s=n_s, obst=obst, drop=drop,
                           surface=self._surface, level=level_grade(metric, self._up))
        run_rules(c, c.rules.pixels, PIXEL_RULES, ev)
        weight, min_px = ev.weight, ev.min_px
        n_obst = np.bincount(sid[obst], weights=weight[obst], minlength=n_s) + 1e-9
        ev.n_drop = np.bincount(sid[drop], weights=weight[drop], minlength=n_s) + 1e-9
        ev.obst_string = n_obst >= min_px
        run_rules(c, c.rules.strings, STRING_RULES, ev)
        obst_string = ev.obst_string
        ev.drop_string = (ev.n_drop >= c.drops.min_pixels) & ~obst_string
        run_rules(c, c.rules.drops, DROP_RULES, ev)
        drop_string = ev.drop_string
        obst &= obst_string[sid]
        drop &= drop_string[sid]
        sclass = np.where(obst_string[sid], 1, np.where(drop_string[sid], -1, 0)).astype(np.int8)
        features = _features(m, excess.astype(np.float32), obst, drop, sclass,
                             ex_mean.astype(np.float32), thr.astype(np.float32),
                             contrary_rival_share(m, pd, thr, obst))
        self._frame_thr = thr
        # Ground features: reliably matched edge pixels on the plane (free space).
        ground = (np.abs(ex_mean) <= thr) & usable & ~obst_string[sid]
        abc = cast(np.ndarray, self._abc)              # (tracking: the plane is set)
        self._ctx = _FrameContext(cam=cam, metric=metric, abc=abc.copy(), u=u, v=v,
                                  pd=pd, excess_mean=ex_mean, sigma=thr / c.threshold.k,
                                  prev=prev, ground_points=pts[ground], left=self._left,
                                  u_left=m.u_left, usable=usable, nxt=nxt)
        if obst_string.any():
            weak = self._weak_silhouettes(m, ex_mean, thr, h, usable,
                                          obst_string | drop_string | (n_obst >= min_px))
            if weak is not None:
                self._ctx.weak_start, self._ctx.weak_top = weak
        found: list[GpodObstacle] = []
        for sel, sign, radius, min_px in (
                (obst, 1.0, c.detection.cluster_radius_m, 1),
                (drop, -1.0, c.drops.cluster_radius_m, c.drops.min_cluster_pixels)):
            idx = flat_nonzero(sel)
            if idx.size:
                found.extend(self._clusters(idx, sign, radius, min_px, m, pts, h, excess,
                                            cam, metric, ev.clustered))
        found.sort(key=lambda o: o.range)
        return features, tuple(found)

    def _ground_reference(self, u, v, d, cam: StereoCamera, metric: MetricPlane,
                          sigma_px: np.ndarray, still: bool = False
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | float]:
        """The ground the features are judged against: (its disparity at each feature,
        the features' 3-D points, their heights above it, how far (px, >= 0; 0.0 where
        the surface does not bend) the lowest ground it allows lies below its own
        disparity there, `drop_margin`). The plane,
        or with ``surface.enabled`` the ground surface ahead where it bends (kept in
        ``self._surface``), fitted knowing each feature's disparity noise ``sigma_px``
        (K,) px (the obstacle threshold over ``threshold.k``) as a depth noise. Beyond
        the known ground a rise seen to go on is the obstacle test's ground, but it may
        end there (`GroundSurface.lowest`): a drop is below the level ground too. With
        ``surface_tracking.enabled`` the profile is fused with the one carried through
        the camera's motion (`core.surface_tracking`; the motion from
        ``self.surface_motion(still)``, the identity while ``still`` without one)."""
        c = self.config
        pd = plane_disparity(self._abc, u, v)
        pts = cam.triangulate(u, v, d)
        h = metric.signed_height(pts)
        low: np.ndarray | float = 0.0
        self._surface = None
        if c.surface.enabled:
            # The reference of the obstacle test: the plane continued by the profile
            # ahead where features support it (core/ground_surface.py).
            tracking = c.surface_tracking.enabled
            surf = fit_ground_surface(pts, metric, c.surface,
                                      depth_noise(cam, d, sigma_px), flatten=not tracking)
            if tracking:
                surf = self._surface_tracker.update(surf, self._ground_motion(still),
                                                    c.surface.min_bend_m)
            self._surface = surf
            if surf.bends:
                pd_surf = surf.disparity(cam, u, v)
                pd = np.where(np.isfinite(pd_surf), pd_surf, pd)
                h = surf.height_above(pts)
                low = drop_margin(surf, cam, u, v, pd, c.surface.lag_share)
        return pd, pts, h, low

    def _ground_motion(self, still: bool) -> tuple | None:
        """The camera's motion since the previous pair for the surface carried
        (``surface_motion``, a callable of ``still`` a caller such as
        `core.perception.Perception` sets; without one the identity while ``still``,
        else the motion given with the pair, or None)."""
        if self.surface_motion is not None:
            return self.surface_motion(still)
        return (np.eye(3), np.zeros(3)) if still else self._pair_motion

    def _runs(self, m: Matches, el: EdgeMap, excess: np.ndarray) -> tuple:
        """The matched runs: (`run_links`, `matched_run_length`, the excess smoothed along
        the runs, the links downwards or None)."""
        c = self.config
        tol = c.detection.string_disparity_tolerance_px
        nxt = None
        if kn.nb_runs is not None and type(tol) in (float, int) and len(m):
            # run_links, matched_run_length and smooth_along_runs in one compiled pass
            # (the same links, lengths and sums; the tolerance compared in single
            # precision, as numpy compares the float32 disparities with it).
            prev, run, smooth, nxt = kn.nb_runs(el.string_prev, m.left_index, m.d, len(el),
                                                np.float32(tol), int(c.detection.string_window),
                                                excess)
        else:
            prev = run_links(el, m, tol)
            run = matched_run_length(el, m, tol, prev)
            smooth = smooth_along_runs(excess, prev, c.detection.string_window)
        return prev, run, smooth, nxt

    def _weak_silhouettes(self, m: Matches, ex_mean, thr, h, usable, taken: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray] | None:
        """The candidate silhouette strings (``taken``: (n_s,) strings already obstacles,
        drops or rejected): (their lowest pixels, their top heights), or None."""
        c = self.config
        sid = m.string_id
        n_s = taken.shape[0]
        # Candidate silhouette edges for placing detected obstacles (never obstacles):
        # strings neither obstacle, drop nor rejected as one (mismatch, repetitive
        # pattern, half-occlusion), consistently above the plane near the threshold:
        # reliably matched pixels above _WEAK_FRACTION of it, at least
        # _WEAK_MIN_PIXELS, whose mean excess is _WEAK_SIGMAS standard errors above
        # the plane (sum of z > K sqrt(n _WEAK_CORR)).
        weak = (usable & (ex_mean > _WEAK_FRACTION * thr) & (h <= c.detection.max_obstacle_height_m)
                & ~taken[sid])
        wi = flat_nonzero(weak)
        if wi.size:
            z = ex_mean[wi] * (c.threshold.k / thr[wi])
            n_w = np.bincount(sid[wi], minlength=n_s)
            z_sum = np.bincount(sid[wi], weights=z, minlength=n_s)
            ok_s = (n_w >= _WEAK_MIN_PIXELS) & (
                z_sum > _WEAK_SIGMAS * np.sqrt(np.maximum(n_w, 1) * _WEAK_CORR))
            wi = wi[ok_s[sid[wi]]]
        if wi.size:
            o = np.lexsort((-m.v[wi], sid[wi]))
            wi = wi[o]
            head = np.concatenate((_TRUE, sid[wi][1:] != sid[wi][:-1]))
            top = np.maximum.reduceat(h[wi], flat_nonzero(head))
            return wi[head], top
        return None

    def _clusters(self, idx: np.ndarray, sign: float, radius: float, min_pixels: int,
                  m: Matches, pts: np.ndarray, h: np.ndarray, excess: np.ndarray,
                  cam: StereoCamera, metric: MetricPlane, memo: dict | None = None
                  ) -> list[GpodObstacle]:
        """Cluster the selected pixels (by string, feet proximity) into obstacles; drop
        clusters of fewer than ``min_pixels`` pixels. ``memo``: the frame's clusterings
        by (sign, radius) (`FrameEvidence.clustered`), one of the same pixels taken as
        it is."""
        hh = h[idx]
        known = memo.get((sign, radius)) if memo else None
        if known is not None and np.array_equal(known[0], idx):
            g2, label = known[1], known[2]
            _, fwd, lft = ground_axes(metric)
        else:
            g2, fwd, lft = ground_coords(pts[idx], hh, metric, axes=True)
            label = cluster_points_2d(g2, m.string_id[idx], radius)
        pr = self.config.detection.part_radius_m
        if sign > 0 and 0.0 < pr < radius:
            return self._parts(idx, label, pr, sign, min_pixels, hh, g2, m, excess, cam,
                               metric, fwd, lft)
        return self._describe(idx, label, sign, min_pixels, hh, g2, m, excess, cam, metric,
                              fwd, lft)

    def _parts(self, idx, label, radius: float, sign: float, min_pixels: int, hh, g2,
               m: Matches, excess, cam, metric, fwd, lft) -> list[GpodObstacle]:
        """The whole obstacles (the clusters ``label`` of the pixels ``idx``) as their
        parts describe them (`described_by_part`), followed by the parts (clustered at
        ``radius``) of the obstacles made of several, as obstacles of their own: those
        whose nearest point lies more than ``radius`` from every whole obstacle's (the
        nearest part is the whole's report already). None of either when no whole is
        kept (``min_pixels``).

        The wholes and the parts are described in one `_describe` of both pixel sets
        (the parts' pixels again, their clusters numbered after the wholes'): each
        description is its cluster's own, and the placement rules that weigh clusters
        against each other (`Placement.split`) do so within the wholes and within the
        parts only, so both are those of a description of each set on its own."""
        fine = cluster_points_2d(g2, m.string_id[idx], radius)
        n_fine = int(fine.max()) + 1
        n_c = int(label.max()) + 1
        # parts per whole: the distinct (whole, part) pairs, counted without a sort
        pair_seen = np.zeros(n_c * n_fine, bool)
        pair_seen[label * n_fine + fine] = True
        n_parts = np.count_nonzero(pair_seen.reshape(n_c, n_fine), axis=1)
        sel = n_parts[label] > 1
        if not sel.any():
            return self._describe(idx, label, sign, min_pixels, hh, g2, m, excess, cam,
                                  metric, fwd, lft)
        # the parts numbered 0.. in the order of their fine cluster (np.unique's inverse)
        used = np.zeros(n_fine, np.int64)
        used[fine[sel]] = 1
        part = (np.cumsum(used) - 1)[fine[sel]]
        both = self._describe(np.concatenate((idx, idx[sel])),
                              np.concatenate((label, part + n_c)), sign, min_pixels,
                              np.concatenate((hh, hh[sel])), np.concatenate((g2, g2[sel])),
                              m, excess, cam, metric, fwd, lft, split=n_c)
        n_whole = int(np.count_nonzero(np.bincount(label, minlength=n_c) >= min_pixels))
        whole, parts = both[:n_whole], both[n_whole:]
        if not whole:
            return whole
        owner = np.zeros(len(parts), np.int64)
        owner[part] = label[sel]
        ctx = cast(_FrameContext, self._ctx)          # (set by this frame's _detect)
        whole = described_by_part(whole, parts, owner, radius, metric.normal_up,
                                  lambda: ctx.ground_xy)
        at, p_at = _ground_points(whole), _ground_points(parts)
        far = np.hypot(p_at[:, None, 0] - at[None, :, 0],
                       p_at[:, None, 1] - at[None, :, 1]).min(axis=1) > radius
        return whole + [p for p, f in zip(parts, far.tolist()) if f]

    def _obstacle_feet(self, idx: np.ndarray, label: np.ndarray, sid: np.ndarray, n_c: int,
                       m: Matches, height: np.ndarray, split: int | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Range and bearing (n_c,) of the nearest point of each obstacle cluster, and
        (n_c, 2) its ground coordinates from the obstacle's own strings alone (the ROI's
        foot: the placement-only candidates below change range and bearing only).

        Every edge string of a cluster gives one ground foot (`string_feet`): its matched
        run followed down to where it meets the ground. The cluster's nearest point is
        then (`nearest_point`): the near corner when one of the feet is nearer than the
        two outermost ones (in bearing); else, when the outermost feet L and R are the
        silhouette of a body whose near corner has no vertical edge (two faces of one
        shade), the hidden corner on the Thales circle over LR that the image's edges
        and the visible ground support (`hidden_corner`); else the probably nearest foot.

        Placement only: edge strings just under the thresholds (the frame's candidates,
        see `_detect`) that `silhouette_owners` assigns to an obstacle add their feet to
        its search; the result is kept only where it is nearer than without them (a
        silhouette can reveal a hidden near corner, not move the obstacle away). They
        never change which obstacles exist, their pixels, ROI, height or confidence.

        ``split``: the clusters below it and those from it on are two sets placed as each
        would be on its own (`Placement.split`; None: one set).
        """
        ctx = cast(_FrameContext, self._ctx)          # (set by this frame's _detect)
        # The lowest obstacle pixel of each (cluster, string): where its foot search starts.
        vv = m.v[idx].astype(np.int64)
        o = np.lexsort((-vv, sid, label))
        lab_o, sid_o = label[o], sid[o]
        head = np.concatenate((_TRUE, (lab_o[1:] != lab_o[:-1]) | (sid_o[1:] != sid_o[:-1])))
        start = idx[o][head]
        n_w = ctx.weak_start.size
        xy, sr = string_feet(ctx, np.concatenate([start, ctx.weak_start]) if n_w else start)
        if n_w:     # one walk down for the obstacles' strings and the candidates
            xy, xw, sr, sw = xy[:-n_w], xy[-n_w:], sr[:-n_w], sr[-n_w:]
        g_lab = lab_o[head]
        ul = m.u_left[start]
        at_border = (ul < _BORDER_PX) | (ul > ctx.cam.width - 1 - _BORDER_PX)
        q0 = nearest_points(xy, sr, g_lab, n_c, lambda: ctx.ground_xy,
                            ctx.contact_edge_scores, at_border)
        weak = None
        if n_w:
            uw = m.u_left[ctx.weak_start]
            weak = (xw, sw, ctx.weak_top, (uw < _BORDER_PX) | (uw > ctx.cam.width - 1 - _BORDER_PX))
        noise = self._image_noise
        pl = Placement(ctx=ctx, xy=xy, sr=sr, group=g_lab, n=n_c, height=height,
                       at_border=at_border, weak=weak, split=split,
                       lone_floor=(_LONE_FLOOR_SIGMAS * _SOBEL_NOISE_GAIN * noise
                                   if math.isfinite(noise) else 0.0))
        q = q0
        for name in self.config.rules.placement:
            q = PLACEMENT_RULES[name](self.config, pl, q)
        rng = np.array([math.hypot(x, y) for x, y in q.tolist()])
        brg = np.array([math.atan2(y, x) for x, y in q.tolist()])
        return rng, brg, q0

    def _drop_feet(self, idx, label, hh, count, sid_all, cam, metric
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The place of each drop cluster of `_describe`: (range of its nearest visible
        lower ground, its bearing, each pixel's ground point on the lower ground)."""
        n_c = count.shape[0]
        # A drop is placed at the nearest visible part of the lower ground (just
        # beyond the brink, which hides the lower ground for a shadow's length):
        # each pixel's viewing ray, continued from where it meets the plane down to
        # the cluster's depth D (the median height), lands at r_ray (H + D) / H,
        # H the camera's height -- its row places it, not its noisy disparity. The
        # nearest: the pixel of rank _DROP_RANK.
        ctx = cast(_FrameContext, self._ctx)          # (set by this frame's _detect)
        g_ray = ctx.to_xy(cam.triangulate(ctx.u[idx], ctx.v[idx], ctx.pd[idx]))
        depth = np.maximum(-_group_quantile(label, hh, 0.5, n_c), 0.0)
        scale = ((metric.height + depth) / metric.height)[label]
        g2 = g_ray * scale[:, None]
        rng_px = np.hypot(g2[:, 0], g2[:, 1])
        o1 = np.lexsort((rng_px, label))
        first = np.searchsorted(label[o1], np.arange(n_c))
        r_near = rng_px[o1][first + np.minimum(_DROP_RANK, count - 1)]
        o3 = np.lexsort((rng_px, sid_all, label))
        lab3, sid3 = label[o3], sid_all[o3]
        head = np.concatenate((_TRUE, (lab3[1:] != lab3[:-1]) | (sid3[1:] != sid3[:-1])))
        s_lab, s_rng, s_g = lab3[head], rng_px[o3][head], g2[o3][head]
        zone = s_rng <= (r_near + np.maximum(_NEAR_ZONE_M,
                                             _NEAR_ZONE_FRACTION * r_near))[s_lab]
        zx = _group_quantile(s_lab[zone], s_g[zone, 0], 0.5, n_c)
        zy = _group_quantile(s_lab[zone], s_g[zone, 1], 0.5, n_c)
        bearing = np.arctan2(zy, zx)
        bearing = _brink_bearings(s_g[zone], s_lab[zone], bearing)
        return r_near, bearing, g2

    def _describe(self, idx, label, sign, min_pixels, hh, g2, m: Matches, excess, cam,
                  metric, fwd, lft, split: int | None = None) -> list[GpodObstacle]:
        """GpodObstacles of the clusters ``label`` (0..C-1) of the pixels ``idx``, all at
        once (per-cluster quantiles from one sort by (cluster, value)).

        Height: the 90th percentile of the pixels' heights (10th for a drop). Foot of an
        obstacle: its nearest point on the ground estimated from the ground feet of its
        edge strings (:meth:`_obstacle_feet`); range and bearing are those of that one
        point. Foot of a drop: the nearest visible lower ground (each pixel's viewing
        ray continued down to the drop's depth; the second nearest), in the median
        direction of the nearest feet of its edge strings (one vote per string) within
        ``max(_NEAR_ZONE_M, _NEAR_ZONE_FRACTION * range)`` of that range.

        ``split`` (obstacles): the clusters below it and those from it on are two sets
        (`_parts`' wholes and parts) whose obstacles are placed as each set's own would be
        (`_obstacle_feet`); None: one set.
        """
        c = self.config
        n_c = int(label.max()) + 1
        count = np.bincount(label, minlength=n_c)
        height = _group_quantile(label, hh, 0.9 if sign > 0 else 0.1, n_c)
        sid_all = m.string_id[idx]
        if sign > 0:
            r_near, bearing, q_roi = self._obstacle_feet(idx, label, sid_all, n_c, m,
                                                         height, split)
        else:
            r_near, bearing, g2 = self._drop_feet(idx, label, hh, count, sid_all, cam, metric)
        foot = (-metric.height * metric.normal_up[None, :]
                + r_near[:, None] * (np.cos(bearing)[:, None] * fwd[None, :]
                                     + np.sin(bearing)[:, None] * lft[None, :]))
        position = foot + height[:, None] * metric.normal_up[None, :]
        foot_roi = foot
        if sign > 0:
            r0 = np.array([math.hypot(x, y) for x, y in q_roi.tolist()])
            b0 = np.array([math.atan2(y, x) for x, y in q_roi.tolist()])
            foot_roi = (-metric.height * metric.normal_up[None, :]
                        + r0[:, None] * (np.cos(b0)[:, None] * fwd[None, :]
                                         + np.sin(b0)[:, None] * lft[None, :]))
        # Lateral extent of the feet across the line of sight to their median.
        mx = _group_quantile(label, g2[:, 0], 0.5, n_c)
        my = _group_quantile(label, g2[:, 1], 0.5, n_c)
        norm = np.maximum(np.hypot(mx, my), 1e-9)
        ex = excess[idx]
        lo_lat, hi_lat, exc, x0, x1, y0, y1, sid_u, sid_start = _cluster_extents(
            label, n_c, count, g2, mx, my, norm, ex, m.u_left[idx], m.v[idx],
            m.string_id[idx], sign > 0)
        z = (np.abs(ex) - self._frame_thr[idx]) / c.detection.disparity_sigma_px
        p_i = _normal_cdf(z).clip(0.0, 1.0 - 1e-12)
        p_any = 1.0 - np.exp(np.bincount(label, weights=np.log1p(-p_i), minlength=n_c))
        # Small evidence lowers the confidence: the pixels counted as the edge-string rule
        # counts them, a weak edge as (strength / detection.min_strength)^2 of a pixel.
        n_ev = np.bincount(label, weights=self._evidence_weight(m.strength[idx]),
                           minlength=n_c)
        conf = (p_any * np.minimum(1.0, n_ev / c.detection.confidence_full_pixels)).clip(0.0, 1.0)
        # (per obstacle, Python numbers: each value as numpy's scalar would give it)
        x0l, x1l, y0l, y1l = x0.tolist(), x1.tolist(), y0.tolist(), y1.tolist()
        foot_l, height_l, count_l = foot_roi.tolist(), height.tolist(), count.tolist()
        range_l, bearing_l, exc_l = r_near.tolist(), bearing.tolist(), exc.tolist()
        width_l, conf_l, sid_l = (hi_lat - lo_lat).tolist(), conf.tolist(), sid_start.tolist()
        out = []
        for k in flat_nonzero(count >= min_pixels).tolist():
            yk1 = y1l[k]
            fk = foot_l[k]
            if sign > 0 and fk[2] > 1e-6:    # extend down to where the obstacle meets the ground
                v_foot = cam.f * fk[1] / fk[2] + cam.cy
                if math.isfinite(v_foot):
                    yk1 = max(yk1, int(round(min(v_foot, cam.height - 1))))
            xk0, yk0 = max(x0l[k], 0), max(y0l[k], 0)
            xk1, yk1 = min(x1l[k], cam.width - 1), min(yk1, cam.height - 1)
            roi = (xk0, yk0, max(xk1 - xk0 + 1, 1), max(yk1 - yk0 + 1, 1))
            out.append(new_obstacle(
                position=position[k].astype(np.float64), height=height_l[k],
                range=range_l[k], bearing=bearing_l[k], width=width_l[k],
                disparity_excess=exc_l[k], confidence=conf_l[k], roi=roi,
                num_edge_pixels=count_l[k],
                string_ids=sid_u[sid_l[k]:sid_l[k + 1]].astype(np.int32)))
        return out


def _cluster_extents(label: np.ndarray, n_c: int, count: np.ndarray, g2: np.ndarray,
                     mx: np.ndarray, my: np.ndarray, norm: np.ndarray, ex: np.ndarray,
                     u: np.ndarray, v: np.ndarray, sid: np.ndarray, positive: bool) -> tuple:
    """Per cluster of ``label`` ((P,) int, 0..n_c-1; ``count`` (n_c,) its sizes): the
    lowest and highest lateral offset (m) of the feet ``g2`` ((P, 2), plane x forward,
    y left) across the line of sight to the cluster's median foot (``mx``, ``my``, its
    length ``norm``; each (n_c,)), the largest (``positive``) or smallest disparity excess
    ``ex`` (px), the image box (x0, x1, y0, y1 int64 px) of the pixels at (``u``, ``v``),
    and its string ids ``sid`` as one sorted list ``sid_u`` cut at ``sid_start``
    ((n_c + 1,)): cluster k's strings are ``sid_u[sid_start[k]:sid_start[k + 1]]``."""
    if kn.nb_extent is not None and count.min() > 0:
        # The same extremes and string lists, compiled (one pass).
        return kn.nb_extent(
            np.asarray(label, np.int64), n_c, np.ascontiguousarray(g2, np.float64),
            mx, my, norm, np.ascontiguousarray(ex, np.float64), u, v, sid, positive)
    lat = (g2[:, 1] * mx[label] - g2[:, 0] * my[label]) / norm[label]
    order = np.argsort(label, kind='stable')
    starts = flat_nonzero(np.concatenate((_TRUE, np.diff(label[order]) != 0)))
    lo_lat = np.minimum.reduceat(lat[order], starts)
    hi_lat = np.maximum.reduceat(lat[order], starts)
    ex_o = ex[order]
    exc = (np.maximum.reduceat(ex_o, starts) if positive
           else np.minimum.reduceat(ex_o, starts))
    ul = u[order]
    vv = v[order]
    x0 = np.floor(np.minimum.reduceat(ul, starts)).astype(np.int64)
    x1 = np.ceil(np.maximum.reduceat(ul, starts)).astype(np.int64)
    y0 = np.minimum.reduceat(vv, starts).astype(np.int64)
    y1 = np.maximum.reduceat(vv, starts).astype(np.int64)
    sid_o = sid[order]
    lab_o = label[order]
    srt = np.lexsort((sid_o, lab_o))
    sid_s, lab_s = sid_o[srt], lab_o[srt]
    uniq = np.concatenate((_TRUE, (sid_s[1:] != sid_s[:-1]) | (lab_s[1:] != lab_s[:-1])))
    sid_u, lab_u = sid_s[uniq], lab_s[uniq]
    sid_start = np.searchsorted(lab_u, np.arange(n_c + 1))
    return lo_lat, hi_lat, exc, x0, x1, y0, y1, sid_u, sid_start
