"""The ground plane over frames: calibration on the first frames, the per-frame refit
or motion-carried prediction with its Kalman filter (`PlaneTracking._update_plane`),
and the obstacle thresholds from the calibration's residual spread.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, cast

import numpy as np

from ..camera import MetricPlane, StereoCamera, plane_disparity, vector_norm
from ..ground_plane import (PlaneFit, cyclopean_height, fast_median, fit_ground_plane,
                            lsq_plane, lsq_plane_at_height, plane_is_plausible, predict_plane)
from .runs import _robust_row_slope
from .state import DetectorState
from .support import _mad_sigma, _planes_agree, _state_metric, _still_motion

#: The residual spread sigma of the initial fit is taken over the calibration features
#: within this many ``plane.inlier_px`` of the fitted plane.
_SIGMA_GATE = 3.0
#: The initial plane is fitted to the calibration window's frames together only if each
#: frame's residual spread about it is at most this many times that about the frame's
#: own plane (a standing rig: 1.00-1.03; a wearer already walking: 1.2-10).
_WINDOW_SIGMA_RATIO = 1.15


class PlaneTracking(DetectorState):
    """The ground-plane stage of `GpodDetector`."""

    @property
    def calibrated_plane(self) -> PlaneFit | None:
        """The plane fitted on the calibration frames, or None while initialising."""
        return self._calib

    def _fit(self, u, v, d, cam: StereoCamera, min_support: float = 0.0,
             prior: bool = True) -> PlaneFit | None:
        """Robust, plausibility-checked plane fit of features (u, v, d) with the settings
        (``min_support``: least fraction of the features on a RANSAC hypothesis;
        ``prior``: the pair's up direction, when known, is a soft prior on the plane's
        orientation, ``plane.gravity_prior_deg`` and ``plane.gravity_prior_cost``)."""
        c = self.config
        up = self._up if prior else None
        # Weighted by disparity cubed: of two competing surfaces (the ground here and the
        # ground beyond a step), the nearer one is the one the wearer stands on; far
        # features, least flat and least well measured, count little.
        return fit_ground_plane(
            u, v, d, cam=cam, method=c.plane.method, inlier_threshold_px=c.plane.inlier_px,
            iterations=c.plane.ransac_iterations, weights=np.maximum(d, 0.0) ** 3,
            min_features=c.plane.min_features, min_spread_px=c.plane.min_spread_px,
            min_support_fraction=min_support, up_prior=up,
            prior_scale_deg=c.plane.gravity_prior_deg, prior_cost=c.plane.gravity_prior_cost,
            rng=self._rng,
            **cast(dict[str, Any], c.plane.plausibility()))

    def _refit(self, u, v, d, cam: StereoCamera) -> PlaneFit | None:
        """A per-frame refit of features (u, v, d): `_fit` without the gravity prior (the
        refits must follow the ground's slope; measured, the prior paid only in the
        calibration), then, with ``plane.refit_hold_height``, `_held` at the anchor height."""
        fit = self._fit(u, v, d, cam, prior=False)
        if fit is None or not self.config.plane.refit_hold_height:
            return fit
        if not _height_sd(cam, fit) > self.config.plane.hold_min_height_sd_m:
            return fit
        return self._held(fit, u, v, d, cam)

    def _held(self, fit: PlaneFit, u, v, d, cam: StereoCamera) -> PlaneFit | None:
        """The plane of the refit ``fit`` of features (u, v, d: (N,) pixels) refitted at
        the anchor height (`_anchor_height`): least squares of its orientation alone on
        its inliers (weighted as `_fit` weighs them), the inliers re-selected within
        ``plane.inlier_px`` of it until they settle (at most 3 rounds). The free least
        squares on the final inliers gives the height this frame adds to the anchor
        (kept in ``_free_height`` until the refit is taken). None when too few inliers
        remain or the plane is not a plausible ground."""
        c = self.config
        height = self._anchor_height()
        if not math.isfinite(height):
            return fit
        w = np.maximum(d, 0.0) ** 3
        inl = fit.inliers
        abc = fit.abc
        for _ in range(3):
            held = lsq_plane_at_height(cam, u[inl], v[inl], d[inl], height, w[inl])
            if held is None:
                return None
            abc = held
            new = np.abs(d - plane_disparity(abc, u, v)) <= c.plane.inlier_px
            if int(new.sum()) < c.plane.min_features:
                return None
            if np.array_equal(new, inl):
                break
            inl = new
        metric = plane_is_plausible(cam, abc, **cast(dict[str, Any], c.plane.plausibility()))
        if metric is None:
            return None
        free = lsq_plane(u[inl], v[inl], d[inl], w[inl])
        self._free_height = cyclopean_height(cam, free[0]) if free is not None else math.nan
        return dataclasses.replace(fit, abc=np.asarray(abc, np.float64), inliers=inl,
                                   num_features=int(inl.sum()), metric=metric)

    def _anchor_height(self) -> float:
        """The cyclopean camera height the refits are held at (``plane.refit_hold_height``):
        the median of the calibrated one and the free heights of the latest
        ``plane.height_anchor_frames`` refits taken, metres (NaN before the calibration)."""
        if not self._heights:
            return math.nan
        return float(np.median(np.asarray(self._heights)))

    def _near_calibration(self, fit: PlaneFit, cam: StereoCamera) -> bool:
        """Whether an ungated refit is close enough to the calibrated plane to trust: its
        camera height within ``plane.recover_max_height_change_m`` of the anchor height
        (`_anchor_height`) or of the calibrated one (either can be off: the anchor with
        refits of another surface, the calibrated one with the calibration), its normal
        within ``plane.recover_max_angle_deg`` of the calibrated one."""
        c = self.config
        cal = self._calib.metric if self._calib is not None else None
        if cal is None or fit.metric is None:
            return False
        max_h = c.plane.recover_max_height_change_m
        if not (abs(cyclopean_height(cam, fit.abc) - self._anchor_height()) <= max_h
                or abs(fit.metric.height - cal.height) <= max_h):
            return False
        return _angle_deg(fit.metric.normal_up, cal.normal_up) <= c.plane.recover_max_angle_deg

    def _upright(self, fit: PlaneFit, max_deg: float) -> bool:
        """Whether the fit's upward normal lies within ``max_deg`` degrees of the pair's
        up direction (``_up``, the inclinometer's, left optical frame); True without an
        up direction, a metric plane or a bound (``max_deg`` 0)."""
        if max_deg <= 0.0 or self._up is None or fit.metric is None:
            return True
        up = self._up / max(vector_norm(self._up), 1e-12)
        return _angle_deg(fit.metric.normal_up, up) <= max_deg

    def _predict_plane(self, cam: StereoCamera, motion: tuple) -> bool:
        """Carry the plane state (and the plane the rig stopped with) through the camera's
        motion (R, t, ...) since the previous frame: x = f(x), P = F P F^T
        (`ground_plane.predict_plane`); the plane before it is kept as ``_unmoved``.
        False, with nothing changed, when it cannot."""
        abc = cast(np.ndarray, self._abc)       # (calibrated: the plane state is set)
        r = predict_plane(cam, abc, motion[0], motion[1])
        if r is None:
            return False
        R, t = np.asarray(motion[0], float), np.asarray(motion[1], float)
        self._unmoved = _state_metric(cam, abc)
        self._abc, F = r
        self._cov = F @ self._cov @ F.T
        if self._still_plane is not None:
            n = self._still_plane.normal_up
            # n . X_prev + h = 0, X_prev = R X + t  =>  (R^T n) . X + (h + n . t) = 0
            self._still_plane = MetricPlane(normal_up=R.T @ n,
                                            height=self._still_plane.height + float(n @ t))
        self._still_travel += float(np.linalg.norm(t))
        return True

    def _close_to_current(self, fit: PlaneFit, cam: StereoCamera,
                          cur: MetricPlane | None = None, tight: bool = False) -> bool:
        """Whether a refit is within the per-frame change limits of the current plane
        (``cur``: its metric plane, if known; ``tight``: the current plane was predicted
        through the camera's motion: the limits ``motion_max_*``, from the prediction or
        from the plane before the motion -- a wrong motion (visual egomotion once 4 cm
        off) must not reject the ground; another surface differs from both)."""
        c = self.config
        if tight:
            max_h, max_a = c.plane.motion_max_height_change_m, c.plane.motion_max_angle_change_deg
        else:
            max_h, max_a = c.plane.refit_max_height_change_m, c.plane.refit_max_angle_change_deg
        if cur is None:
            cur = _state_metric(cam, cast(np.ndarray, self._abc))   # (calibrated)
        if cur is None or fit.metric is None:
            return False
        if tight and self._unmoved is not None and self._within(fit.metric, self._unmoved,
                                                                max_h, max_a):
            return True
        return self._within(fit.metric, cur, max_h, max_a)

    @staticmethod
    def _within(plane: MetricPlane, ref: MetricPlane, max_h: float, max_a: float) -> bool:
        """Whether ``plane`` is within ``max_h`` metres of camera height and ``max_a``
        degrees of normal of ``ref``."""
        if abs(plane.height - ref.height) > max_h:
            return False
        return _angle_deg(plane.normal_up, ref.normal_up) <= max_a

    @property
    def sigma_px(self) -> float:
        """Robust (MAD) spread of the disparity residuals of the initial ground-plane fit,
        pixels (NaN while initialising)."""
        return self._sigma

    def _window_shares_plane(self, joint: PlaneFit, cam: StereoCamera) -> bool:
        """Whether the calibration window's frames all lie on the plane ``joint`` fitted
        to them together: each frame's own plane (least squares from ``joint``, refitted
        on its features within ``plane.inlier_px``, weighted as `_fit` weights them)
        differs from it by at most ``plane.inlier_px`` over the image's lower half, and
        the frame's residual spread about ``joint`` (robust sigma within ``_SIGMA_GATE *
        plane_inlier_px``) is at most ``_WINDOW_SIGMA_RATIO`` times that about its own.
        Deterministic (draws nothing from the detector's random generator). A frame
        whose own plane cannot be fitted counts as not sharing it."""
        tol = self.config.plane.inlier_px
        for u, v, d, _ in self._init_window:
            own = joint.abc
            for it in range(3):
                near = (self._gated_residuals(own, u, v, d)[1] if it == 0
                        else np.abs(d - plane_disparity(own, u, v)) <= tol)
                ls = lsq_plane(u[near], v[near], d[near], np.maximum(d[near], 0.0) ** 3)
                if ls is None:
                    return False
                own = ls[0]
            if not _planes_agree(joint.abc, own, cam, tol):
                return False
            sig = []
            for abc in (own, joint.abc):
                res, near = self._gated_residuals(abc, u, v, d)
                sig.append(_mad_sigma(res[near]) if near.sum() >= 3 else math.nan)
            if not (sig[1] <= _WINDOW_SIGMA_RATIO * sig[0]):      # NaN: not shared
                return False
        return True

    def _gated_residuals(self, abc, u, v, d) -> tuple[np.ndarray, np.ndarray]:
        """Disparity residuals of features (u, v, d: (N,) pixels) about the plane ``abc``
        (N,) px, and (N,) bool: within ``_SIGMA_GATE * plane_inlier_px`` of it (the
        features whose spread is the fit's error; far off it are other surfaces, walls,
        trees)."""
        res = d - plane_disparity(abc, u, v)
        return res, np.abs(res) <= _SIGMA_GATE * self.config.plane.inlier_px

    def _calibrate_sigma(self, u, v, d, s) -> None:
        """Residual spread of the calibration features about the calibrated plane.

        ``sigma_px``: one robust sigma (1.4826 * MAD) over the features within
        ``_SIGMA_GATE * plane_inlier_px`` of the plane. For ``threshold.sigma_per_edge``: sigmas in
        (equal-count) bins of the features' precision s (made non-increasing with it),
        and factors (>= 1) in bands of image rows by which the residuals, divided by their
        bin's sigma, are still spread (the far ground, foreshortened, matches less well).
        """
        res, near = self._gated_residuals(self._abc, u, v, d)
        res, s, v = res[near], s[near], v[near]
        self._sigma = _mad_sigma(res)
        n_bins = int(min(8, res.size // 100))
        self._sigma_bins = None
        if n_bins >= 2:
            order = np.argsort(s, kind='stable')
            parts = np.array_split(order, n_bins)
            s_b = np.array([np.median(s[p]) for p in parts])
            sig_b = np.array([_mad_sigma(res[p]) for p in parts])
            sig_b = np.maximum(np.minimum.accumulate(sig_b), 0.01)
            log_s = np.log(np.maximum(s_b, 1e-3))
            r_n = res / np.interp(np.log(np.maximum(s, 1e-3)), log_s, sig_b)
            order = np.argsort(v, kind='stable')
            parts = np.array_split(order, n_bins)
            v_b = np.array([np.median(v[p]) for p in parts])
            f_b = np.array([max(1.0, _mad_sigma(r_n[p])) for p in parts])
            self._sigma_bins = (log_s, sig_b, v_b, f_b)

    def pixel_thresholds(self, precision: np.ndarray, v: np.ndarray | None = None
                         ) -> tuple[np.ndarray, float]:
        """The obstacle thresholds of edge pixels, and the global one.

        Args:
            precision: (K,) the pixels' ``Matches.precision`` (or edge strengths).
            v: (K,) their image rows (None: no row factor).
        Returns:
            ((K,) float64 per-pixel thresholds, global threshold), pixels.
        """
        c = self.config
        k = precision.shape[0]
        if c.threshold.mode == 'fixed' or not np.isfinite(self._sigma):
            return np.full(k, c.threshold.px), c.threshold.px
        ceiling = self.threshold_ceiling()
        glob = self.global_threshold()
        if not c.threshold.sigma_per_edge or self._sigma_bins is None:
            return np.full(k, glob), glob
        log_s, sig_b, v_b, f_b = self._sigma_bins
        log_p = np.log(np.maximum(precision.astype(np.float64), 1e-3))
        sig = np.interp(log_p, log_s, sig_b)
        # Below the least precise bin, sigma grows as 1 / precision.
        sig *= np.exp(np.maximum(log_s[0] - log_p, 0.0))
        if v is not None:
            sig = sig * np.interp(v, v_b, f_b)
        thr = (c.threshold.k * sig).clip(c.threshold.floor_px, ceiling)
        return thr, glob

    def global_threshold(self) -> float:
        """The global obstacle threshold, pixels: `pixel_thresholds`' second value
        (``threshold.px`` in the 'fixed' mode or before sigma is known, else
        ``threshold.k`` sigma within ``threshold.floor_px`` .. `threshold_ceiling`),
        without the per-pixel thresholds."""
        c = self.config
        if c.threshold.mode == 'fixed' or not np.isfinite(self._sigma):
            return c.threshold.px
        return float(np.clip(c.threshold.k * self._sigma, c.threshold.floor_px,
                             self.threshold_ceiling()))

    def min_obstacle_pixels(self, cam: StereoCamera) -> float:
        """Obstacle pixels an edge string needs on this camera:
        ``detection.min_obstacle_pixels`` times f / ``detection.min_obstacle_pixels_focal_px``
        (rounded), at least ``detection.min_obstacle_pixels``: the same angle of evidence
        on any rig."""
        d = self.config.detection
        if d.min_obstacle_pixels_focal_px <= 0.0:
            return float(d.min_obstacle_pixels)
        return float(max(d.min_obstacle_pixels,
                         round(d.min_obstacle_pixels * cam.f / d.min_obstacle_pixels_focal_px)))

    def threshold_ceiling(self) -> float:
        """The largest obstacle threshold of the 'sigma' mode, pixels: the larger of
        ``threshold.ceiling_px`` and the disparity excess ``f*B*h/(H*z)`` of an obstacle
        ``threshold.ceiling_height_m`` high at depth ``threshold.ceiling_depth_m`` for the
        calibrated camera height H (the paper's rig: 1.7 px and 1.68 px; the KITTI car's:
        4.7 px). ``threshold.ceiling_px`` alone before the calibration."""
        c = self.config
        cal = self._calib.metric if self._calib is not None else None
        if (c.threshold.ceiling_height_m <= 0.0 or cal is None or self._cam is None
                or not cal.height > 0.0):
            return c.threshold.ceiling_px
        excess = (self._cam.fb * c.threshold.ceiling_height_m
                  / (cal.height * c.threshold.ceiling_depth_m))
        return max(c.threshold.ceiling_px, float(excess))

    def _update_plane(self, u, v, d, s, cam: StereoCamera, still: bool = False,
                      motion: tuple | None = None) -> tuple[str, bool]:
        """Advance the plane state with this frame's features.

        Args:
            u, v, d: (N,) float the features' column, row and disparity, pixels.
            s: (N,) their :func:`_noise_key` (for the residual spread).
            cam: the rectified stereo camera.
            still: the rig stood still since the previous frame.
            motion: the camera's (R (3, 3), t (3,) m, ...) since the previous frame, as
                `process` takes it, or None.
        Returns:
            (status: 'initialising' | 'tracking' | 'lost', whether the plane was refitted).
        """
        c = self.config
        self._free_height = math.nan
        if self._calib is None:
            return self._calibrate(u, v, d, s, cam)
        enough = u.shape[0] >= c.plane.min_features
        if c.plane.update == 'fixed':
            # The plane is known, but a frame with too few features cannot vouch that
            # nothing stands on it: lost, as in 'refit' mode.
            return ('tracking', False) if enough else ('lost', False)
        # Kalman predict: through the camera's motion when it is known (the paper's
        # dynamic recalibration), else the constant-plane model below. While the rig
        # stands still (its edges stayed in place) a motion larger than a standing
        # wearer's sway can only be an error: the identity instead (a wrong one carried
        # the plane the rig stopped with off the ground for as long as the wearer stood).
        self._unmoved = None
        if motion is not None and still and not _still_motion(motion):
            motion = (np.eye(3), np.zeros(3))
        predicted = motion is not None and self._predict_plane(cam, motion)
        current = _state_metric(cam, cast(np.ndarray, self._abc))   # (calibrated)
        # moving: the plane the rig stopped with is kept, carried through the motion,
        # while the camera is still near where it stopped (on the same ground)
        if not still and not (predicted and self._still_plane is not None
                              and self._still_travel <= c.plane.still_anchor_travel_m):
            self._still_plane = None
        elif self._still_plane is None:
            self._still_plane = current             # the plane when the rig stopped
            self._still_travel = 0.0
        # Refits near the prediction through the motion: a narrower gate and tighter
        # change limits, unless refits were rejected by those limits plane.max_coast_frames
        # times in a row (the motion may be wrong: then as without one, around the
        # predicted plane). With a motion the plane is carried through frames with too
        # few ground features to refit for up to plane.motion_coast_frames.
        # A plane carried unrefitted over a frame whose motion was missing has not moved
        # with the camera over that frame: its prediction through the later motions is
        # off by that frame's motion (a vigorous walker's sway: 10 px of disparity). It
        # gets neither the narrow gate nor the long coast until a refit has found the
        # ground again (it coasted at most plane.max_coast_frames, then recovers).
        tight = predicted and not self._stale and self._rejected < c.plane.max_coast_frames
        gate_m = c.plane.motion_gate_m if tight else c.plane.refit_gate_m
        coast_frames = (c.plane.motion_coast_frames if predicted and not self._stale
                        else c.plane.max_coast_frames)
        fit, rejected = self._refit_plane(u, v, d, cam, current, enough, predicted, tight,
                                          gate_m, coast_frames)
        noise = c.plane.motion_process_noise_px if predicted else c.plane.refit_process_noise_px
        sq = noise ** 2
        q = np.diag([sq / (0.5 * cam.width) ** 2, sq / (0.5 * cam.height) ** 2, sq])
        if fit is None:
            return self._without_refit(u, v, d, q, rejected, predicted, still, enough,
                                       coast_frames)
        self._kalman_update(fit, q)
        return 'tracking', True

    def _refit_plane(self, u, v, d, cam: StereoCamera, current: MetricPlane | None,
                     enough: bool, predicted: bool, tight: bool, gate_m: float,
                     coast_frames: int) -> tuple[PlaneFit | None, bool]:
        """The refit of `_update_plane`, each way tried while the ones before found
        none: `_coarse_then_fine` (not while the plane the rig stopped with is kept); a
        fit of the features within ``gate_m`` of that plane (else of ``current``), then,
        kept but not predicted, `_coarse_then_fine`; while the prediction is stale or
        missing, `_coarse_then_fine` with the wider ``plane.refit_retry_gate_px``; `_recover`
        once coasted ``coast_frames``.

        Args:
            u, v, d: (N,) float the features' column, row and disparity, pixels.
            cam: the rectified stereo camera.
            current: the plane state's metric plane (left optical frame), or None.
            enough: at least ``plane.min_features`` features.
            predicted: the plane was carried through this frame's motion.
            tight: the change limits around the motion's prediction apply
                (`_close_to_current`).
            gate_m: metres from the plane of the features refitted.
            coast_frames: frames the plane may be carried without a refit.
        Returns:
            (the refit or None, whether a refit was rejected by the change limits).
        """
        c = self.config
        fit = None
        anchored = self._still_plane is not None
        rejected = False

        def coarse_then_fine(gate_px: float = c.plane.refit_gate_px) -> PlaneFit | None:
            nonlocal rejected
            out, no = self._coarse_then_fine(u, v, d, cam, current, tight, gate_m, gate_px)
            rejected = rejected or no
            return out

        if enough and current is not None and not anchored:
            fit = coarse_then_fine()
        if enough and current is not None and fit is None:
            # Standing still the current plane is where the ground is: refit from the
            # features within plane.refit_gate_m of it. So too when the coarse fit took another
            # surface while walking: the ground beyond a step down can fill more of the
            # view than the ground the wearer stands on, even in the nearer half (and a
            # mixture of the two tilts the plane).
            # Standing, the gate stays where the plane was when the rig stopped: the
            # ground has not moved since. Gated around the current plane instead, the
            # ground beyond a kerb down leaked in at 4-10 m (where 15 cm is 1-2 px of
            # disparity, about the gate's 10 cm), each refit tilted the plane towards it
            # and the tilted plane let more of it in: 0.1 -> 3.8 degrees and 12 cm in
            # 0.5 s, and the pavement between the wearer and the kerb stood 20 cm up.
            ref = self._still_plane if self._still_plane is not None else current
            height = ref.signed_height(cam.triangulate(u, v, d))
            gate = np.abs(height) <= gate_m
            fit = self._refit(u[gate], v[gate], d[gate], cam)
            if fit is not None and not self._close_to_current(fit, cam, current, tight):
                fit, rejected = None, True
            if fit is None and anchored and not predicted:
                # "Still" by the edges, with no motion to carry the plane, but no ground
                # where the rig stopped: the edges can stay in place while the camera
                # moves (the only edges of smooth slabs are joints along the walk,
                # which forward motion keeps in place while the body's pitch sway moves
                # the ground by pixels). Refit as when moving.
                fit = coarse_then_fine()
        if (fit is None and enough and current is not None and (self._stale or not predicted)
                and self._coast < coast_frames
                and c.plane.refit_retry_gate_px > c.plane.refit_gate_px):
            # Nothing predicted where the ground went: a vigorous walker (the paper's
            # extreme motion: 5 degrees of sway) moves the ground by 10 px of disparity
            # between frames, and a frame whose /egomotion is missing then kept the
            # previous frame's plane, 10 px off, and reported the whole ground as a drop.
            # (Not once lost: the plane to widen the gate around is then stale.)
            fit = coarse_then_fine(c.plane.refit_retry_gate_px)
        if fit is None and enough and self._coast >= coast_frames:
            fit = self._recover(u, v, d, cam)
        return fit, rejected

    def _calibrate(self, u, v, d, s, cam: StereoCamera) -> tuple[str, bool]:
        """The calibration step of `_update_plane`: this frame's features join the
        calibration window; once it holds ``plane.init_frames`` frames, the plane is fitted
        from them (or from the latest frame alone when the frames' planes disagree).
        Returns (status, updated)."""
        c = self.config
        self._init_window.append((u, v, d, s))
        if len(self._init_window) < c.plane.init_frames:
            return 'initialising', False
        uu, vv, dd, ss = (np.concatenate(x) for x in zip(*self._init_window))
        # No plane is known yet: the ground must hold plane.init_min_inlier_fraction of the
        # features to be a candidate at all (not only the winner checked below), so
        # that the disparity weighting cannot crown a few wrong matches at large
        # disparity, which a long baseline searched from min_range_m gives.
        support = c.plane.init_min_inlier_fraction
        fit = self._fit(uu, vv, dd, cam, support)
        if fit is None:
            return 'initialising', False
        if len(self._init_window) > 1:
            # Frames of different ground planes (a wearer who walks from the first
            # frame sways): their joint plane lies between them, tilted for each
            # (3 degrees: obstacles everywhere), and its residual spread, which sets
            # the obstacle threshold, is theirs plus the sway's. Then this frame
            # alone calibrates. (A car on a flat road moves, but its ground plane
            # does not.)
            # Both tests: the latest frame's own robust fit may find another surface
            # than the joint fit (the near ground before a kerb down, where the joint
            # took the lower ground beyond it), which a least-squares refit started
            # from the joint plane does not. But two planes more than a step apart are
            # not two grounds: then the one holding more of this frame's features
            # calibrates.
            last = self._fit(u, v, d, cam, support)
            if last is not None and self._latest_frame_calibrates(fit, last, u, v, d, cam):
                fit, uu, vv, dd, ss = last, u, v, d, s
        if fit.num_features < c.plane.init_min_inlier_fraction * uu.shape[0]:
            return 'initialising', False
        # The ground is where the wearer stands: a plane with the nearest ground
        # above it is the lower ground beyond a drop just ahead (a wearer starting
        # 1.8 m before a step down, step_down 1076), whose features outnumber the
        # strip before the edge.
        near = self._nearer_ground(fit, uu, vv, dd, cam)
        if near is not None:
            fit = near
        if 0.0 < c.plane.init_max_height_sd_m < _height_sd(cam, fit):
            # features in one band of the image (a kerb's joints across a plain
            # pavement, the only edges at full size) fix no plane: any plane through
            # them fits (the chest rig's took the camera 0.75 m too high, 8 degrees off)
            return 'initialising', False
        if not self._upright(fit, c.plane.init_max_tilt_deg):
            # a plane far from gravity's up is no ground a pedestrian starts on (the
            # chest rig's binned pass took one 76 degrees off through a few edges)
            return 'initialising', False
        self._calib = self._last_fit = fit
        self._heights.clear()
        self._heights.append(cyclopean_height(cam, fit.abc))
        self._abc, self._cov = fit.abc.copy(), fit.cov.copy()
        self._calibrate_sigma(uu, vv, dd, ss.astype(np.float64))
        self._init_window.clear()
        return 'tracking', True

    def _nearer_ground(self, fit: PlaneFit, u, v, d, cam: StereoCamera) -> PlaneFit | None:
        """The ground the wearer stands on when the calibrated plane ``fit`` is the
        lower ground beyond a drop before them: the nearest features (the
        ``plane.init_near_share`` of the calibration features (u, v, d: (N,) pixels)
        with the largest disparity on ``fit``) lying above it on a parallel plane (their
        median residual above ``plane.inlier_px``, and within it of the parallel plane)
        at most ``plane.init_max_step_m`` higher. A level plane at camera height h' has
        the disparities of one at h times h / h', so the parallel plane is ``fit``'s
        (a, b, c) times the median ratio of the near features' disparities to
        ``fit``'s. Returns that plane (its inliers: the features within ``inlier_px``)
        or None: the nearest features lie on ``fit``, on no such plane, or the test is
        off (share 0)."""
        c = self.config
        share = c.plane.init_near_share
        if share <= 0.0 or u.shape[0] < 2 * c.plane.min_features:
            return None
        pd = plane_disparity(fit.abc, u, v)
        near = pd >= np.quantile(pd, 1.0 - share)
        if int(near.sum()) < c.plane.min_features:
            return None
        if fast_median(d[near] - pd[near]) <= c.plane.inlier_px:
            return None
        k = fast_median(d[near] / np.maximum(pd[near], 1e-6))
        if fast_median(np.abs(d[near] - k * pd[near])) > c.plane.inlier_px:
            return None
        h = cyclopean_height(cam, fit.abc)
        if h * (1.0 - 1.0 / k) > c.plane.init_max_step_m:
            return None
        abc = k * fit.abc
        metric = plane_is_plausible(cam, abc, **cast(dict[str, Any], c.plane.plausibility()))
        if metric is None:
            return None
        res = d - k * pd                          # (abc's disparities are k * pd)
        on = np.abs(res) <= c.plane.inlier_px
        res = res[on]
        return PlaneFit(abc=abc, cov=fit.cov * k * k, num_features=int(on.sum()),
                        residual_rms=float(np.sqrt(np.mean(res ** 2))), inliers=on,
                        metric=metric, residual_sigma=_mad_sigma(res))

    def _latest_frame_calibrates(self, joint: PlaneFit, last: PlaneFit, u, v, d,
                                 cam: StereoCamera) -> bool:
        """Whether the latest frame's own plane ``last`` (its features u, v, d) calibrates
        in place of the window's ``joint`` one: the two disagree (`_planes_agree`, or the
        window's frames do not share ``joint``), unless they are more than a step apart
        and ``joint`` holds more of the frame's features."""
        if (_planes_agree(joint.abc, last.abc, cam, self.config.plane.inlier_px)
                and self._window_shares_plane(joint, cam)):
            return False
        return not (self._more_than_a_step_apart(joint, last, cam)
                    and self._on_plane(joint, u, v, d) > self._on_plane(last, u, v, d))

    def _more_than_a_step_apart(self, a: PlaneFit, b: PlaneFit, cam: StereoCamera) -> bool:
        """Whether the planes ``a`` and ``b`` put the camera more than
        ``plane.init_max_step_m`` apart in height: no kerb or step lies between two such
        grounds, so one of them is a wrong consensus (a frame's own fit, weighted by
        disparity cubed, through a short line of near mismatches), not the nearer ground
        the wearer stands on. False when the bound is 0."""
        gap = self.config.plane.init_max_step_m
        return 0.0 < gap < abs(cyclopean_height(cam, a.abc) - cyclopean_height(cam, b.abc))

    def _on_plane(self, fit: PlaneFit, u, v, d) -> int:
        """How many of the features (u, v, d) lie within ``plane.inlier_px`` of ``fit``'s
        plane, each counted once (no disparity weighting)."""
        return int(np.count_nonzero(
            np.abs(d - plane_disparity(fit.abc, u, v)) <= self.config.plane.inlier_px))

    def _coarse_then_fine(self, u, v, d, cam: StereoCamera, current: MetricPlane | None,
                          tight: bool, gate_m: float, gate_px: float
                          ) -> tuple[PlaneFit | None, bool]:
        """The refit of `_update_plane`: a coarse refit from the nearer half of the
        features near the predicted plane in disparity (a gate wide enough for walking
        motion), then a fine refit from all features near the coarse plane in disparity
        *and* metric height, so that another surface (the ground beyond a step, a kerb
        top) cannot take over. Returns (the refit or None, whether a refit was rejected
        by the change limits around ``current``)."""
        gate = np.abs(d - plane_disparity(self._abc, u, v)) <= gate_px
        if gate.any():      # the coarse fit sees only the nearer half: the ground here
            gate &= d >= fast_median(d[gate])      # (np.median's arithmetic, finite d)
        coarse = self._refit(u[gate], v[gate], d[gate], cam)
        out = None
        if coarse is not None:
            # (fitted with a camera: it has a metric plane)
            height = cast(MetricPlane, coarse.metric).signed_height(cam.triangulate(u, v, d))
            gate = ((np.abs(d - plane_disparity(coarse.abc, u, v)) <= gate_px)
                    & (np.abs(height) <= gate_m))
            out = self._refit(u[gate], v[gate], d[gate], cam)
        if out is not None and not self._close_to_current(out, cam, current, tight):
            return None, True
        return out, False

    def _kalman_update(self, fit: PlaneFit, q: np.ndarray) -> None:
        """The Kalman step of `_update_plane` with the refit ``fit`` and the process
        noise ``q``; the refit is the plane's latest fit."""
        # Kalman filter: predict with the process noise Q (the walking motion's, or what
        # the known motion leaves unexplained): P = F P F^T + Q (F P F^T is already in
        # self._cov when predicted through the motion, F = I otherwise); update with the
        # refit z and its covariance R: K = P (P + R)^-1, x = x + K (z - x),
        # P = (I - K) P.
        p_pred = self._cov + q
        gain = p_pred @ np.linalg.inv(p_pred + fit.cov)
        self._abc = self._abc + gain @ (fit.abc - self._abc)
        self._cov = (np.eye(3) - gain) @ p_pred
        self._last_fit = fit
        if math.isfinite(self._free_height):
            self._heights.append(self._free_height)
        self._coast = self._rejected = 0
        self._stale = False

    def _recover(self, u, v, d, cam: StereoCamera) -> PlaneFit | None:
        """Lost: a plane from the nearer half of the features (the ground the wearer
        stands on, rather than the ground beyond a step) if it is near the calibration
        (`_near_calibration`), else None."""
        near = d >= np.median(d)
        ungated = self._refit(u[near], v[near], d[near], cam)
        if ungated is not None and self._near_calibration(ungated, cam):
            return ungated
        return None

    def _without_refit(self, u, v, d, q: np.ndarray, rejected: bool, predicted: bool,
                       still: bool, enough: bool, coast_frames: int) -> tuple[str, bool]:
        """A frame of `_update_plane` without a refit: the plane is carried over it (for
        up to ``coast_frames``; through the motion when ``predicted``, adding the process
        noise ``q``), or the status is lost until a refit succeeds."""
        c = self.config
        self._rejected = self._rejected + 1 if rejected else 0
        self._stale = self._stale or not predicted
        if self._coast < coast_frames and enough and (
                predicted or still or self._near_ground_agrees(u, v, d)):
            self._coast += 1
            if predicted:
                self._cov = self._cov + q
            return 'tracking', False
        # stay lost until a refit succeeds
        self._coast = max(c.plane.max_coast_frames, c.plane.motion_coast_frames)
        return 'lost', False

    def _near_ground_agrees(self, u: np.ndarray, v: np.ndarray, d: np.ndarray) -> bool:
        """Whether the current plane may be carried, unconfirmed by a refit, over a frame
        of a walk with no motion to carry it by (u, v, d: (N,) the frame's features,
        pixels; "near": the half with d at least the median).

        It may if it still lies on the near features (their median disparity residual
        within ``plane.inlier_px``), or if they stand above it as a surface that is not
        the ground (an obstacle filling the near view: their disparity does not grow
        down the image as the plane's does), or if there are fewer than twice
        ``plane.min_features`` of them (a plain wall filling the view leaves a few
        mismatches). Not if they lie below it (the near view is the ground the wearer
        stands on, or an obstacle on it: never lower; the plane is off and every
        feature a drop) or above it as a ground (the plane is too low: every feature an
        obstacle)."""
        near = d >= fast_median(d)
        un, vn, dn = u[near], v[near], d[near]
        if un.shape[0] < 2 * self.config.plane.min_features:
            return True
        res = dn - plane_disparity(self._abc, un, vn)
        med = fast_median(res)
        if abs(med) <= self.config.plane.inlier_px:
            return True
        if med < 0:
            return False
        return bool(_robust_row_slope(un, vn, dn) < 0.5 * float(cast(np.ndarray, self._abc)[1]))

    def disparity_range(self, cam: StereoCamera) -> tuple[float, float]:
        """Disparity search range (d_min, d_max) of the matcher, pixels, from
        ``matching.search_max_range_m`` and ``matching.min_range_m`` (d_max at most the
        image width - 1)."""
        d_min = cam.fb / self.config.matching.search_max_range_m
        d_max = min(cam.fb / self.config.matching.min_range_m, float(cam.width - 1))
        return d_min, max(d_max, d_min)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle between two (3,) unit vectors, degrees (0..180)."""
    return math.degrees(math.acos(float(np.clip(np.dot(a, b), -1.0, 1.0))))


def _height_sd(cam: StereoCamera, fit: PlaneFit) -> float:
    """The standard deviation of the cyclopean camera height above the plane of ``fit``
    by its covariance, metres (first order)."""
    M = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                  [cam.cx / cam.f, cam.cy / cam.f, 1.0 / cam.f]]) / cam.baseline
    x = M @ fit.abc
    n = vector_norm(x)
    if not n > 0.0:
        return math.inf
    grad = -(x @ M) / n ** 3          # d (1 / |M abc|) / d abc
    return math.sqrt(max(float(grad @ fit.cov @ grad), 0.0))
