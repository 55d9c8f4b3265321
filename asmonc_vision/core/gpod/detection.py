"""Obstacles in one frame (`Detection._detect`): the disparity excess over the ground
(averaged along runs and, standing still, over frames), the obstacle pixels and
strings, their clusters, and each cluster's description (feet, nearest point, height,
extent, confidence).
"""
from __future__ import annotations

import math
from typing import cast

import numpy as np

from ..camera import MetricPlane, StereoCamera, plane_disparity
from ..edges import EdgeMap, gradient_noise_gain
from ..ground_surface import depth_noise, fit_ground_surface
from ..matching import Candidates, Matches
from . import kernels as kn
from .faces import (
    _ground_points,
    described_by_part,
    face_gap_points,
    lone_face_points,
    silhouette_owners,
    view_edge_points,
)
from .footing import _cross3, _FrameContext, string_feet
from .grouping import _brink_bearings, _group_quantile, _normal_cdf, cluster_points_2d
from .nearest import nearest_points
from .plane_tracking import PlaneTracking
from .results import GpodFeatures, GpodObstacle
from .runs import (
    _TRUE,
    continuation_alternatives,
    floating_bottom_runs,
    hanging_runs,
    matched_run_length,
    occluded_matches,
    run_links,
    smooth_along_runs,
    string_pieces,
)
from .settings import surface_config
from .support import _features, _ground_candidates, _noise_key, contrary_rival_share

#: Obstacle pixels this far above the plane (pixels) or more are checked for a ground
#: alternative (``GpodConfig.ambiguity_fraction``): a repetitive pattern matched one
#: period off; genuine small obstacles are never this far above the plane.
_AMBIGUOUS_EXCESS_PX = 3.0

#: A run hanging over lower ground (`continuation_alternatives`) is checked only when that
#: ground is seen: at least this fraction of the frame's matches lie on it (beyond a kerb
#: down, 15-70 %; scattered mismatches of obstacle texture that look like a lower ground,
#: at most 1.4 % on the simulator's walks).
_LOWER_GROUND_FRACTION = 0.05

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
        least as strong as an obstacle's evidence needs (``obstacle_min_strength``, or
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
            return use and bool(hits / n >= self.config.still_overlap)
        img = np.zeros((h, w + 2), bool)
        img[v, u_int + 1] = True
        self._prev_edges = img
        if prev is None or prev.shape != img.shape or n == 0:
            return False
        hit = prev[v, u_int] | prev[v, u_int + 1] | prev[v, u_int + 2]
        return bool(hit.mean() >= self.config.still_overlap)

    def _temporal_excess(self, m: Matches, excess: np.ndarray, still: bool,
                         shape: tuple[int, int], thr: np.ndarray | None = None) -> np.ndarray:
        """The excess of each match averaged (exponentially, over about
        ``temporal_frames`` frames) with the running average found at its place (same
        row, within one column) in the previous frame, when the rig stood still and the
        two agree to within ``temporal_gate_px`` and ``temporal_gate_thr`` times the
        pixel's threshold ``thr`` (K,) px, if given. Updates the running sums."""
        c = self.config
        h, w = shape
        k = len(m)
        lam = 1.0 - 1.0 / c.temporal_frames
        if kn.nb_temporal is not None:
            # The same neighbours, gate and sums, compiled.
            use = bool(still and self._acc is not None and lam > 0 and k)
            ps, pw = (self._acc if use and self._acc is not None     # (use: it is set)
                      else (np.zeros((1, 1), np.float32),) * 2)
            gate_thr = thr is not None and c.temporal_gate_thr > 0
            s_new, w_new, acc_s, acc_w = kn.nb_temporal(
                m.v, m.u_left, np.asarray(excess, np.float64),
                np.asarray(thr if gate_thr else np.zeros(0), np.float64), gate_thr,
                float(c.temporal_gate_px), float(c.temporal_gate_thr), float(lam), use, ps,
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
                gate: float | np.ndarray = c.temporal_gate_px
                if thr is not None and c.temporal_gate_thr > 0:
                    gate = np.minimum(gate, c.temporal_gate_thr * thr)
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
        thr, thr_global = self.pixel_thresholds(_noise_key(m), v)
        pd, pts, h, low = self._ground_reference(u, v, d, cam, metric, thr / c.threshold_k)
        excess = d - pd
        feet = pts - h[:, None] * metric.normal_up[None, :]
        ground_range = np.linalg.norm(feet + metric.height * metric.normal_up[None, :], axis=1)
        prev, run, smooth, nxt = self._runs(m, el, excess)
        in_range = ground_range <= c.max_range_m
        ex_mean = self._temporal_excess(m, smooth, still, el.shape, thr)
        # Figural continuity: a run of min_matched_run pixels at least, and longer for a
        # larger excess -- an edge standing on the ground rises by |b| px of excess per
        # row, so an excess E needs about E / |b| rows of it (a fraction of them, up to
        # max_required_run, must be matched in one run).
        slope = max(abs(float(cast(np.ndarray, self._abc)[1])), 1e-3)   # (tracking: set)
        need = np.clip(np.ceil(c.obstacle_run_fraction * np.abs(ex_mean) / slope),
                       c.min_matched_run, max(c.max_required_run, c.min_matched_run))
        reliable = run >= need
        usable = reliable & in_range
        amb_drop = self._ambiguous_drops(m, pd, thr)
        # a periodic pattern matched a period off is no evidence either way
        periodic = self._periodic_matches(m, pd, thr)
        obst = (ex_mean > thr) & (h <= c.max_obstacle_height_m) & usable & ~periodic
        # below the lowest ground the surface allows (``low`` px under its disparity)
        below = (ex_mean < -thr - low) & (h >= -c.max_drop_depth_m)
        if obst.any():
            self._rejected_runs(el, m, cand, prev, run, reliable & in_range, h, excess, pd,
                                below, slope, obst)
        drop = np.zeros_like(obst)
        if c.detect_drops:
            # Below the plane where the plane itself is within the detection range.
            pd_far = cam.fb / c.max_range_m
            drop = below & (pd >= pd_far) & (pd <= d_max) & usable & ~amb_drop & ~periodic
        sid = m.string_id
        n_s = max(el.num_strings, int(sid.max()) + 1 if sid.size else 0)
        weight = self._evidence_weight(m.strength)
        min_px = self.min_obstacle_pixels(cam)
        if obst.any():
            self._piece_rule(m, ex_mean, thr, usable, weight, min_px, n_s, obst)
        n_obst = np.bincount(sid[obst], weights=weight[obst], minlength=n_s) + 1e-9
        n_drop = np.bincount(sid[drop], weights=weight[drop], minlength=n_s) + 1e-9
        obst_string = self._obstacle_strings(n_obst >= min_px, obst, reliable & in_range,
                                             pts, h, metric, n_s, sid)
        if c.ambiguity_fraction > 0 and obst_string.any():
            obst_string &= ~self._ambiguous_strings(m, excess, obst, cand, el, er, thr_global,
                                                    n_s)
        if obst_string.any():
            # Half-occlusion: a left edge matched to the silhouette of an obstacle (a
            # nearer surface) in the right image is hidden there. A string that is an
            # obstacle or a drop only through such pixels is none (strings with enough
            # other evidence are kept whole).
            occluded = occluded_matches(er, m, c.pmf_disparity_gradient_limit,
                                        trusted=obst_string[sid] & (run >= c.min_matched_run))
            if occluded.any():
                seen = obst & ~occluded
                n_seen = np.bincount(sid[seen], weights=weight[seen], minlength=n_s)
                obst_string &= n_seen + 1e-9 >= min_px
                seen = drop & ~occluded
                n_drop = np.bincount(sid[seen], weights=weight[seen], minlength=n_s) + 1e-9
        drop_string = self._drop_strings(drop, n_drop, weight, pts, h, metric, n_s, sid,
                                         obst_string)
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
                                  pd=pd, excess_mean=ex_mean, sigma=thr / c.threshold_k,
                                  prev=prev, ground_points=pts[ground], left=self._left,
                                  u_left=m.u_left, usable=usable, nxt=nxt)
        if obst_string.any():
            weak = self._weak_silhouettes(m, ex_mean, thr, h, usable,
                                          obst_string | drop_string | (n_obst >= min_px))
            if weak is not None:
                self._ctx.weak_start, self._ctx.weak_top = weak
        found: list[GpodObstacle] = []
        for sel, sign, radius, min_px in (
                (obst, 1.0, c.cluster_radius_m, 1),
                (drop, -1.0, c.drop_cluster_radius_m, c.min_drop_cluster_pixels)):
            idx = np.flatnonzero(sel)
            if idx.size:
                found.extend(self._clusters(idx, sign, radius, min_px, m, pts, h, excess,
                                            cam, metric))
        found.sort(key=lambda o: o.range)
        return features, tuple(found)

    def _drop_strings(self, drop: np.ndarray, n_drop: np.ndarray, weight: np.ndarray,
                      pts: np.ndarray, h: np.ndarray, metric: MetricPlane, n_s: int,
                      sid: np.ndarray, obst_string: np.ndarray) -> np.ndarray:
        """(n_s,) bool: the drop strings: ``min_drop_pixels`` of drop evidence (``n_drop``
        (n_s,)), or, with ``drop_region_pixels``, a string in a region of lower ground
        (`_drop_regions`); not an obstacle string (``obst_string`` (n_s,)), nor, with
        ``ground_bend_min_grade``, ground falling away beyond a brow (`_bending_ground`)."""
        c = self.config
        out = n_drop >= c.min_drop_pixels
        if c.drop_region_pixels > 0.0:
            out |= self._drop_regions(drop & (n_drop[sid] > 1e-6), weight, pts, h, metric,
                                      n_s, sid)
        out &= ~obst_string
        if c.ground_bend_min_grade > 0 and out.any():
            out &= ~self._bending_ground(drop & out[sid], pts, h, metric, n_s, sid,
                                         c.drop_cluster_radius_m, -1.0)
        return out

    def _obstacle_strings(self, strings: np.ndarray, obst: np.ndarray, ok: np.ndarray,
                          pts: np.ndarray, h: np.ndarray, metric: MetricPlane, n_s: int,
                          sid: np.ndarray) -> np.ndarray:
        """(n_s,) bool: of the candidate obstacle strings ``strings`` (n_s,), those that
        stand on the ground: a string whose reliably matched pixels (``ok`` (K,)) all
        float higher than max_floating_height_m above it is a mismatch (a distant pole
        matched to the wrong edge); strings whose obstacle pixels (``obst`` (K,)) are
        ground rising beyond a dip (`_bending_ground`) are none."""
        c = self.config
        if strings.any():
            low = np.full(n_s, np.inf)
            np.minimum.at(low, sid[ok], h[ok])
            strings = strings & (low <= c.max_floating_height_m)
        if c.ground_bend_min_grade > 0 and strings.any():
            strings = strings & ~self._bending_ground(obst & strings[sid], pts, h, metric,
                                                      n_s, sid, c.cluster_radius_m, 1.0)
        return strings

    def _bending_ground(self, px: np.ndarray, pts: np.ndarray, h: np.ndarray,
                        metric: MetricPlane, n_s: int, sid: np.ndarray, radius: float,
                        sign: float) -> np.ndarray:
        """(n_s,) bool: the strings that are ground bending away from the ground
        reference: in a cluster of their pixels (``px`` (K,) bool; feet clustered at
        ``radius`` m) of at least 8 pixels spread over ``ground_bend_min_span_m`` or
        more along the walking direction whose heights ``h`` (K,) (m above the ground
        reference; ``sign`` -1: drop pixels, below it) fit a line leaving it at
        ``ground_bend_min_grade`` or more from less than ``_BEND_MAX_START_M`` off it at
        its near end. Beyond a brow the ground goes on falling, beyond a dip rising,
        from where the ground is: the farther its points the farther off; the lower
        ground beyond a drop and the top of a kerb are level, as far off near as far,
        and start a step away."""
        c = self.config
        out = np.zeros(n_s, bool)
        idx = np.flatnonzero(px)
        if idx.size < 8:
            return out
        g2 = _ground_coords(pts[idx], h[idx], metric)
        label = cluster_points_2d(g2, sid[idx], radius)
        for k in range(int(label.max()) + 1):
            sel = label == k
            s_k, h_k = g2[sel, 0], sign * h[idx][sel]
            if sel.sum() < 8 or float(s_k.max() - s_k.min()) < c.ground_bend_min_span_m:
                continue
            grade, at0 = (float(x) for x in np.polyfit(s_k, h_k, 1))
            near = grade * float(s_k.min()) + at0
            if grade >= c.ground_bend_min_grade and near < _BEND_MAX_START_M:
                out[sid[idx][sel]] = True
        return out

    def _drop_regions(self, drop: np.ndarray, weight: np.ndarray, pts: np.ndarray,
                      h: np.ndarray, metric: MetricPlane, n_s: int, sid: np.ndarray
                      ) -> np.ndarray:
        """(n_s,) bool: the strings whose drop pixels (``drop`` (K,) bool) belong to a
        region of lower ground: their feet clustered at ``drop_cluster_radius_m``, of at
        least ``drop_region_min_strings`` strings, whose drop pixels weigh (``weight``
        (K,)) at least ``drop_region_pixels`` times ``min_drop_pixels`` in all and lie
        at one depth below the plane (``h`` (K,): the median absolute deviation of
        their heights at most ``drop_region_max_spread`` times their median)."""
        c = self.config
        out = np.zeros(n_s, bool)
        idx = np.flatnonzero(drop)
        if idx.size == 0:
            return out
        g2 = _ground_coords(pts[idx], h[idx], metric)
        label = cluster_points_2d(g2, sid[idx], c.drop_cluster_radius_m)
        total = np.bincount(label, weights=weight[idx])
        for k in np.flatnonzero(total >= c.drop_region_pixels * c.min_drop_pixels):
            sel = idx[label == k]
            if np.unique(sid[sel]).size < c.drop_region_min_strings:
                continue
            depth = h[sel]
            med = float(np.median(depth))
            if float(np.median(np.abs(depth - med))) <= c.drop_region_max_spread * abs(med):
                out[sid[sel]] = True
        return out

    def _ground_reference(self, u, v, d, cam: StereoCamera, metric: MetricPlane,
                          sigma_px: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | float]:
        """The ground the features are judged against: (its disparity at each feature,
        the features' 3-D points, their heights above it, how far (px, >= 0; 0.0 where
        the surface does not rise beyond the known ground) the disparity of the lowest
        ground it allows lies below its own there). The plane,
        or with ``surface_enabled`` the ground surface ahead where it bends (kept in
        ``self._surface``), fitted knowing each feature's disparity noise ``sigma_px``
        (K,) px (the obstacle threshold over ``threshold_k``) as a depth noise. Beyond
        the known ground a rise seen to go on is the obstacle test's ground, but it may
        end there (`GroundSurface.lowest`): a drop is below the level ground too."""
        c = self.config
        pd = plane_disparity(self._abc, u, v)
        pts = cam.triangulate(u, v, d)
        h = metric.signed_height(pts)
        low: np.ndarray | float = 0.0
        self._surface = None
        if c.surface_enabled:
            # The reference of the obstacle test: the plane continued by the profile
            # ahead where features support it (core/ground_surface.py).
            surf = fit_ground_surface(pts, metric, surface_config(c),
                                      depth_noise(cam, d, sigma_px))
            self._surface = surf
            if surf.bends:
                pd_surf = surf.disparity(cam, u, v)
                pd = np.where(np.isfinite(pd_surf), pd_surf, pd)
                h = surf.height_above(pts)
                if surf.tail_grade > 0.0:
                    pd_low = surf.lowest().disparity(cam, u, v)
                    low = np.where(np.isfinite(pd_low), np.maximum(pd - pd_low, 0.0), 0.0)
        return pd, pts, h, low

    def _runs(self, m: Matches, el: EdgeMap, excess: np.ndarray) -> tuple:
        """The matched runs: (`run_links`, `matched_run_length`, the excess smoothed along
        the runs, the links downwards or None)."""
        c = self.config
        tol = c.string_disparity_tolerance_px
        nxt = None
        if kn.nb_runs is not None and type(tol) in (float, int) and len(m):
            # run_links, matched_run_length and smooth_along_runs in one compiled pass
            # (the same links, lengths and sums; the tolerance compared in single
            # precision, as numpy compares the float32 disparities with it).
            prev, run, smooth, nxt = kn.nb_runs(el.string_prev, m.left_index, m.d, len(el),
                                                np.float32(tol), int(c.string_window), excess)
        else:
            prev = run_links(el, m, tol)
            run = matched_run_length(el, m, tol, prev)
            smooth = smooth_along_runs(excess, prev, c.string_window)
        return prev, run, smooth, nxt

    def _rejected_runs(self, el: EdgeMap, m: Matches, cand: Candidates, prev, run, reliable,
                       h, excess, pd, below, slope: float, obst: np.ndarray) -> None:
        """Obstacle pixels ``obst`` (changed in place) that are no evidence: runs that
        hang over another depth of their own string or float above the ground, and runs
        that hang over their string's continuation on the lower ground beyond a drop
        (``reliable``: reliably matched and in range)."""
        c = self.config
        obst &= ~hanging_runs(el, m, prev, h, c.max_floating_height_m,
                              c.string_disparity_tolerance_px, slope, obst,
                              solid=run >= c.min_matched_run)
        obst &= ~floating_bottom_runs(m.string_id, m.v, prev, h, reliable,
                                      c.max_floating_height_m, obst)
        high = obst & (excess > _AMBIGUOUS_EXCESS_PX)
        if high.any():
            # A run, at any height, that hangs over its own string's continuation on
            # the lower ground beyond a drop and could have been matched there: the
            # paving beyond a kerb down matched one period off. Every stretch of
            # these strings well above the plane is tested (one matched the same
            # period off may hold up another).
            in_s = np.zeros(int(m.string_id.max()) + 1, bool)
            in_s[m.string_id[high]] = True
            high = (excess > _AMBIGUOUS_EXCESS_PX) & in_s[m.string_id]
            support = max(c.min_drop_cluster_pixels,
                          math.ceil(_LOWER_GROUND_FRACTION * len(m)))
            obst &= ~continuation_alternatives(
                el, m, prev, cand, high, below & (run >= c.min_matched_run), pd,
                c.string_disparity_tolerance_px, slope, support)

    @staticmethod
    def _piece_rule(m: Matches, ex_mean, thr, usable, weight, min_px: float, n_s: int,
                    obst: np.ndarray) -> None:
        """The edge-string rule per piece of a string: obstacle pixels ``obst`` (changed in
        place) of pieces with fewer than ``min_px`` (weighted) of them are dropped."""
        sid = m.string_id
        # The edge-string rule holds for each piece of a string between stretches of
        # it on the ground (`string_pieces`): a noisy pixel far below a post, on the
        # post's edge continued by a tile joint, is no part of the post (its foot
        # would be taken there).
        has = np.zeros(n_s, bool)
        has[sid[obst]] = True
        sel = np.flatnonzero(has[sid])
        piece = string_pieces(sid[sel], m.v[sel], (np.abs(ex_mean[sel]) <= thr[sel])
                              & usable[sel])
        o_sel = obst[sel]
        n_piece = np.bincount(piece[o_sel], weights=weight[sel][o_sel],
                              minlength=int(piece.max()) + 1)
        obst[sel] &= n_piece[piece] + 1e-9 >= min_px

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
        weak = (usable & (ex_mean > _WEAK_FRACTION * thr) & (h <= c.max_obstacle_height_m)
                & ~taken[sid])
        wi = np.flatnonzero(weak)
        if wi.size:
            z = ex_mean[wi] * (c.threshold_k / thr[wi])
            n_w = np.bincount(sid[wi], minlength=n_s)
            z_sum = np.bincount(sid[wi], weights=z, minlength=n_s)
            ok_s = (n_w >= _WEAK_MIN_PIXELS) & (
                z_sum > _WEAK_SIGMAS * np.sqrt(np.maximum(n_w, 1) * _WEAK_CORR))
            wi = wi[ok_s[sid[wi]]]
        if wi.size:
            o = np.lexsort((-m.v[wi], sid[wi]))
            wi = wi[o]
            head = np.concatenate((_TRUE, sid[wi][1:] != sid[wi][:-1]))
            top = np.maximum.reduceat(h[wi], np.flatnonzero(head))
            return wi[head], top
        return None

    def _ambiguous_drops(self, m: Matches, pd: np.ndarray, thr: np.ndarray) -> np.ndarray:
        """(K,) bool: the matches that are no evidence of a drop-off: a rival of the match
        (`match_rivals`) with at least ``ambiguous_match_ratio`` of its first-round support
        lies on the ground (within the pixel's threshold ``thr`` (K,) of the ground
        disparity ``pd`` (K,)) and nearer than the match: the edge may as well be ground
        matched a period off (a grate's bars). Obstacle evidence is not judged so: the face
        of a 10 cm kerb has ground rivals as strong as its match, and a kerb must not be
        lost to a grate's false reports."""
        k = len(m)
        no_drop = np.zeros(k, bool)
        r = self.config.ambiguous_match_ratio
        if (r <= 0 or m.rival_match is None or m.rival_d is None or m.rival_ratio is None
                or k == 0):
            return no_drop
        j = m.rival_match
        rd = m.rival_d.astype(np.float64)
        sel = np.flatnonzero((m.rival_ratio >= r) & (np.abs(rd - pd[j]) <= thr[j]))
        if sel.size:
            nearer = rd[sel] > m.d[j[sel]]
            no_drop[j[sel[nearer]]] = True
        return no_drop

    def _periodic_matches(self, m: Matches, pd: np.ndarray, thr: np.ndarray) -> np.ndarray:
        """(K,) bool: the matches of a periodic pattern: at least ``periodic_min_rivals``
        rivals (`match_rivals`) with ``ambiguous_match_ratio`` of the match's first-round
        support or more, one of them on the ground (within the pixel's threshold ``thr``
        (K,) of the ground disparity ``pd`` (K,)). The bars of a grate support candidates
        a period apart alike, and the one a period nearer stands above the ground by the
        period over the baseline times the height of the ray (a 3.5 cm period: 10 cm on
        the paper's rig) wherever the walker is: a world-fixed false obstacle that the map
        would confirm. A kerb's face has at most one strong rival on the ground (the
        ground around it supports the ground's disparity), an obstacle's texture few."""
        k = len(m)
        out = np.zeros(k, bool)
        r = self.config.ambiguous_match_ratio
        n_min = self.config.periodic_min_rivals
        if (n_min <= 0 or r <= 0 or m.rival_match is None or m.rival_d is None
                or m.rival_ratio is None or k == 0):
            return out
        strong = m.rival_ratio >= r
        j = m.rival_match[strong]
        n_strong = np.bincount(j, minlength=k)
        on_ground = np.abs(m.rival_d[strong].astype(np.float64) - pd[j]) <= thr[j]
        ground = np.zeros(k, bool)
        ground[j[on_ground]] = True
        return (n_strong >= n_min) & ground

    def _ambiguous_strings(self, m: Matches, excess: np.ndarray, obst: np.ndarray,
                           cand: Candidates, el: EdgeMap, er: EdgeMap, threshold: float,
                           n_s: int) -> np.ndarray:
        """(n_s,) bool: edge strings whose obstacle pixels are well above the plane
        (> ``_AMBIGUOUS_EXCESS_PX``) but, for at least ``ambiguity_fraction`` of them,
        the left edge also had a candidate match on the ground (|excess| <= threshold):
        a repetitive pattern matched one period off."""
        on_ground = _ground_candidates(cand, el, er, cast(np.ndarray, self._abc), threshold)
        alt = obst & (excess > _AMBIGUOUS_EXCESS_PX) & on_ground[m.left_index]
        n_alt = np.bincount(m.string_id[alt], minlength=n_s)
        n_obst = np.bincount(m.string_id[obst], minlength=n_s)
        return n_alt >= self.config.ambiguity_fraction * np.maximum(n_obst, 1)

    def _clusters(self, idx: np.ndarray, sign: float, radius: float, min_pixels: int,
                  m: Matches, pts: np.ndarray, h: np.ndarray, excess: np.ndarray,
                  cam: StereoCamera, metric: MetricPlane) -> list[GpodObstacle]:
        """Cluster the selected pixels (by string, feet proximity) into obstacles; drop
        clusters of fewer than ``min_pixels`` pixels."""
        hh = h[idx]
        g2, fwd, lft = _ground_coords(pts[idx], hh, metric, axes=True)
        label = cluster_points_2d(g2, m.string_id[idx], radius)
        out = self._describe(idx, label, sign, min_pixels, hh, g2, m, excess, cam, metric,
                             fwd, lft)
        pr = self.config.part_radius_m
        if sign > 0 and 0.0 < pr < radius and out:
            out, parts = self._parts(out, idx, label, pr, sign, min_pixels, hh, g2, m,
                                     excess, cam, metric, fwd, lft)
            out.extend(parts)
        return out

    def _parts(self, whole: list[GpodObstacle], idx, label, radius: float, sign: float,
               min_pixels: int, hh, g2, m: Matches, excess, cam, metric, fwd, lft
               ) -> tuple[list[GpodObstacle], list[GpodObstacle]]:
        """The whole obstacles as their parts describe them (`described_by_part`), and
        the parts (clustered at ``radius``) of the obstacles made of several, as
        obstacles of their own: those whose nearest point lies more than ``radius`` from
        every whole obstacle's (the nearest part is the whole's report already)."""
        fine = cluster_points_2d(g2, m.string_id[idx], radius)
        pairs = np.unique(label * (int(fine.max()) + 1) + fine)
        n_parts = np.bincount(pairs // (int(fine.max()) + 1), minlength=int(label.max()) + 1)
        sel = n_parts[label] > 1
        if not sel.any():
            return whole, []
        _, part = np.unique(fine[sel], return_inverse=True)
        parts = self._describe(idx[sel], part.astype(np.int64), sign, min_pixels, hh[sel],
                               g2[sel], m, excess, cam, metric, fwd, lft)
        owner = np.zeros(len(parts), np.int64)
        owner[part] = label[sel]
        ctx = cast(_FrameContext, self._ctx)          # (set by this frame's _detect)
        whole = described_by_part(whole, parts, owner, radius, metric.normal_up,
                                  lambda: ctx.ground_xy)
        at, p_at = _ground_points(whole), _ground_points(parts)
        far = np.hypot(p_at[:, None, 0] - at[None, :, 0],
                       p_at[:, None, 1] - at[None, :, 1]).min(axis=1) > radius
        return whole, [p for p, f in zip(parts, far.tolist()) if f]

    def _obstacle_feet(self, idx: np.ndarray, label: np.ndarray, sid: np.ndarray, n_c: int,
                       m: Matches, height: np.ndarray
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
        xy_w = None
        if n_w:
            lw = silhouette_owners(xw, ctx.weak_top, xy, g_lab, height,
                                   self.config.cluster_radius_m, lambda: ctx.ground_xy,
                                   ctx.metric.height, sw, sr)
            keep = lw >= 0
            if keep.any():
                uw = m.u_left[ctx.weak_start[keep]]
                xy_w, sr_w, lab_w = xw[keep], sw[keep], lw[keep]
                bd_w = (uw < _BORDER_PX) | (uw > ctx.cam.width - 1 - _BORDER_PX)
        q = q0 = nearest_points(xy, sr, g_lab, n_c, lambda: ctx.ground_xy,
                                ctx.contact_edge_scores, at_border)
        if xy_w is not None:
            # The candidate silhouettes can only reveal a nearer point (a hidden near
            # corner), never move an obstacle away.
            # (Only the obstacles with candidates are searched again.)
            ks = np.unique(lab_w)
            sub = np.full(n_c, -1, np.int64)
            sub[ks] = np.arange(ks.size)
            mine = sub[g_lab] >= 0
            qw = nearest_points(np.concatenate([xy[mine], xy_w]),
                                np.concatenate([sr[mine], sr_w]),
                                np.concatenate([sub[g_lab[mine]], sub[lab_w]]), ks.size,
                                lambda: ctx.ground_xy, ctx.contact_edge_scores,
                                np.concatenate([at_border[mine], bd_w]))
            nearer = np.hypot(qw[:, 0], qw[:, 1]) < np.hypot(q[ks, 0], q[ks, 1])
            q = q.copy()
            q[ks[nearer]] = qw[nearer]
        # A face going out of the view (a wall beside the path): its nearest visible
        # point is where it leaves the image.
        qe = view_edge_points(xy, g_lab, n_c, ctx.to_image, ctx.cam.width, ctx.cam.height,
                              lambda: ctx.ground_xy)
        ext = ~np.isnan(qe[:, 0])
        if ext.any():
            ext &= np.hypot(qe[:, 0], qe[:, 1]) < np.hypot(q[:, 0], q[:, 1])
            q = q.copy()
            q[ext] = qe[ext]
        # A face seen as two obstacles (its middle has no edges): its nearest point.
        qg = face_gap_points(xy, g_lab, n_c, q, lambda: ctx.ground_xy)
        gap = ~np.isnan(qg[:, 0])
        if gap.any():
            q = q.copy()
            q[gap] = qg[gap]
        # A low obstacle seen by one silhouette edge: the face the image shows beside it.
        ql = lone_face_points(ctx, xy, g_lab, n_c, q, height, at_border,
                              _LONE_FLOOR_SIGMAS * _SOBEL_NOISE_GAIN * self._image_noise
                              if math.isfinite(self._image_noise) else 0.0)
        lone = ~np.isnan(ql[:, 0])
        if lone.any():
            q = q.copy()
            q[lone] = ql[lone]
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
                  metric, fwd, lft) -> list[GpodObstacle]:
        """GpodObstacles of the clusters ``label`` (0..C-1) of the pixels ``idx``, all at
        once (per-cluster quantiles from one sort by (cluster, value)).

        Height: the 90th percentile of the pixels' heights (10th for a drop). Foot of an
        obstacle: its nearest point on the ground estimated from the ground feet of its
        edge strings (:meth:`_obstacle_feet`); range and bearing are those of that one
        point. Foot of a drop: the nearest visible lower ground (each pixel's viewing
        ray continued down to the drop's depth; the second nearest), in the median
        direction of the nearest feet of its edge strings (one vote per string) within
        ``max(_NEAR_ZONE_M, _NEAR_ZONE_FRACTION * range)`` of that range.
        """
        c = self.config
        n_c = int(label.max()) + 1
        count = np.bincount(label, minlength=n_c)
        height = _group_quantile(label, hh, 0.9 if sign > 0 else 0.1, n_c)
        sid_all = m.string_id[idx]
        if sign > 0:
            r_near, bearing, q_roi = self._obstacle_feet(idx, label, sid_all, n_c, m,
                                                              height)
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
        if kn.nb_extent is not None and count.min() > 0:
            # The same extremes and string lists, compiled (one pass).
            lo_lat, hi_lat, exc, x0, x1, y0, y1, sid_u, sid_start = kn.nb_extent(
                np.asarray(label, np.int64), n_c, np.ascontiguousarray(g2, np.float64),
                mx, my, norm, np.ascontiguousarray(ex, np.float64), m.u_left[idx],
                m.v[idx], m.string_id[idx], sign > 0)
        else:
            lat = (g2[:, 1] * mx[label] - g2[:, 0] * my[label]) / norm[label]
            order = np.argsort(label, kind='stable')
            starts = np.flatnonzero(np.concatenate((_TRUE, np.diff(label[order]) != 0)))
            lo_lat = np.minimum.reduceat(lat[order], starts)
            hi_lat = np.maximum.reduceat(lat[order], starts)
            ex_o = ex[order]
            exc = (np.maximum.reduceat(ex_o, starts) if sign > 0
                   else np.minimum.reduceat(ex_o, starts))
            ul = m.u_left[idx][order]
            vv = m.v[idx][order]
            x0 = np.floor(np.minimum.reduceat(ul, starts)).astype(np.int64)
            x1 = np.ceil(np.maximum.reduceat(ul, starts)).astype(np.int64)
            y0 = np.minimum.reduceat(vv, starts).astype(np.int64)
            y1 = np.maximum.reduceat(vv, starts).astype(np.int64)
            sid = m.string_id[idx][order]
            lab_o = label[order]
            srt = np.lexsort((sid, lab_o))
            sid_s, lab_s = sid[srt], lab_o[srt]
            uniq = np.concatenate((_TRUE, (sid_s[1:] != sid_s[:-1]) | (lab_s[1:] != lab_s[:-1])))
            sid_u, lab_u = sid_s[uniq], lab_s[uniq]
            sid_start = np.searchsorted(lab_u, np.arange(n_c + 1))
        z = (np.abs(ex) - self._frame_thr[idx]) / c.disparity_sigma_px
        p_i = np.clip(_normal_cdf(z), 0.0, 1.0 - 1e-12)
        p_any = 1.0 - np.exp(np.bincount(label, weights=np.log1p(-p_i), minlength=n_c))
        # Small evidence lowers the confidence: the pixels counted as the edge-string rule
        # counts them, a weak edge as (strength / obstacle_min_strength)^2 of a pixel.
        n_ev = np.bincount(label, weights=self._evidence_weight(m.strength[idx]),
                           minlength=n_c)
        conf = np.clip(p_any * np.minimum(1.0, n_ev / c.confidence_full_pixels), 0.0, 1.0)
        out = []
        for k in range(n_c):
            if count[k] < min_pixels:
                continue
            yk1 = int(y1[k])
            fk = foot_roi[k]
            if sign > 0 and fk[2] > 1e-6:    # extend down to where the obstacle meets the ground
                v_foot = cam.f * fk[1] / fk[2] + cam.cy
                if np.isfinite(v_foot):
                    yk1 = max(yk1, int(round(min(v_foot, cam.height - 1))))
            xk0, yk0 = max(int(x0[k]), 0), max(int(y0[k]), 0)
            xk1, yk1 = min(int(x1[k]), cam.width - 1), min(yk1, cam.height - 1)
            roi = (xk0, yk0, max(xk1 - xk0 + 1, 1), max(yk1 - yk0 + 1, 1))
            out.append(GpodObstacle(
                position=position[k].astype(np.float64), height=float(height[k]),
                range=float(r_near[k]), bearing=float(bearing[k]),
                width=float(hi_lat[k] - lo_lat[k]), disparity_excess=float(exc[k]),
                confidence=float(conf[k]), roi=roi, num_edge_pixels=int(count[k]),
                string_ids=sid_u[sid_start[k]:sid_start[k + 1]].astype(np.int32)))
        return out


#: `_bending_ground`: ground bending away beyond a brow or a dip starts where the ground
#: is; a cluster whose line lies this far off the ground at its near end is a drop or an
#: obstacle whatever its grade (the least step the wearer must be told of, m)
_BEND_MAX_START_M = 0.10


def _ground_coords(p: np.ndarray, hh: np.ndarray, metric: MetricPlane, axes: bool = False):
    """The feet of points ``p`` (K, 3) (heights ``hh`` (K,) above the plane) on the ground:
    (K, 2) (forward, left) from the point below the camera, metres; with ``axes`` also
    the forward and left unit vectors (3,)."""
    n_up = metric.normal_up
    feet = p - hh[:, None] * n_up[None, :]
    fwd = np.array([0.0, 0.0, 1.0]) - n_up[2] * n_up
    fwd /= np.linalg.norm(fwd)
    lft = _cross3(n_up, fwd)
    g = feet + metric.height * n_up[None, :]
    g2 = np.stack([g @ fwd, g @ lft], axis=1)
    return (g2, fwd, lft) if axes else g2
