"""Visual egomotion of the stereo rig from one rectified pair to the next.

``EgomotionEstimator.process(left, right, cam, stamp_ns)`` per pair:

1. corners in both images with sub-pixel positions (``features.detect_corners``);
2. left-right NCC matching on the rows (rectified): the features of this pair with a
   3-D point;
3. NCC matching of the *reference* pair's stereo features (normally the previous pair)
   into the current left corners, within a search radius of where they are expected:
   where the motion prediction (given, or the last motion at constant velocity) puts
   them, else where they were; the current left corner's own stereo match gives its
   current right position;
4. the robust motion (``estimators.estimate_motion``; default the modern ``stereo_ba``),
   a second, wide search without the prediction if that failed; if every search failed,
   the first one's matches solved once more within the wider ``faint_threshold_px``
   (faint texture: correct matches beyond the strict bound);
5. plausibility (rotation and translation per frame, speed over the pairs' interval)
   and the covariance.

A pair with fewer than ``min_features`` stereo features (blank wall, darkness, lens
covered) gives no motion (status ``too_few_features``) and does not replace the
reference, so the next textured pair is matched against the last textured one.

The egomotion is ``T_ref_cur`` (``X_ref = R @ X_cur + t``, left optical frames, metres;
see ``geometry``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from asmonc_vision.core.alignment import VerticalAlignment
from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.motion.estimators import (METHODS, Correspondences, MotionEstimate,
                                                  RansacSettings, estimate_motion)
from asmonc_vision.core.motion.features import (DETECTORS, detect_corners, match_stereo,
                                                match_temporal, patches)
from asmonc_vision.core.motion.geometry import (invert, project, so3_exp, so3_log,
                                                triangulate)

#: result statuses
OK = 'ok'
FIRST = 'first_frame'
TOO_FEW_FEATURES = 'too_few_features'
TOO_FEW_MATCHES = 'too_few_matches'
NO_MOTION = 'no_consistent_motion'
IMPLAUSIBLE = 'implausible_motion'


@dataclass(frozen=True)
class EgomotionConfig:
    """Settings of the visual egomotion (core). Pixels, metres, degrees as named."""

    method: str = param('stereo_ba', 'motion estimator: stereo_ba (modern, default), p3p_gn, '
                        'three_point (paper Table 2), essential (paper Table 3), stereo_3d, '
                        'opencv', choices=METHODS)
    detector: str = param('shi_tomasi', 'corner detector: shi_tomasi (+ cornerSubPix) or '
                          'wang_brady (the paper\'s)', choices=DETECTORS)
    max_corners: int = param(500, 'most corners per image, spread over a 4x4 grid',
                             range=(20, 5000))
    min_corner_distance_px: float = param(5.0, 'least distance between corners, pixels',
                                          range=(1.0, 50.0))
    corner_quality: float = param(0.0005, 'shi_tomasi: least corner strength relative to the '
                                  'strongest (kept low: one high-contrast object, a pole '
                                  'against the sky, must not hide the pavement; '
                                  'min_corner_strength is the absolute bound)',
                                  range=(1e-5, 0.5))
    subpix_half_window: int = param(5, 'shi_tomasi: sub-pixel window half size (the '
                                    'cornerSubPix condition), pixels (0: integer positions)',
                                    range=(0, 15))
    smoothing_sigma_px: float = param(1.5, 'Gaussian smoothing of both images before the '
                                      'corners and NCC windows, sigma in pixels (0: none); '
                                      'on faint texture (smooth pavement, motion blur) the '
                                      'finest-scale corners are camera noise and move from '
                                      'frame to frame', range=(0.0, 5.0))
    min_corner_strength: float = param(0.15, 'least absolute corner strength (smaller '
                                       'structure-tensor eigenvalue of the smoothed image), '
                                       '(grey levels/px)^2; camera noise of 2 grey levels '
                                       'alone gives about 0.05 after a 1.5 px smoothing '
                                       '(about 1 without), so a dark or blank view yields no '
                                       'corners',
                                       range=(0.0, 1000.0))
    patch_half_size: int = param(4, 'NCC window half size (windows are 2n+1 square), pixels',
                                 range=(2, 15))
    min_ncc: float = param(0.7, 'least normalised cross-correlation of a match',
                           range=(0.0, 1.0))
    ncc_margin: float = param(0.0, 'a match must beat the second-best candidate\'s NCC by '
                              'this much (ambiguous repeated texture is refused)',
                              range=(0.0, 1.0))
    stereo_row_tolerance_px: float = param(1.0, 'largest row difference of a left-right '
                                           'match (rectified), pixels', range=(0.0, 10.0))
    align_vertical: bool = param(True, 'measure the vertical misalignment of the rectified '
                                 'pair (core.alignment) and, where it is sure, move the '
                                 "right image's corners onto the left's rows before the "
                                 'stereo matching (a rig turned off its calibration by a '
                                 'fifth of a degree parts the rows by more than '
                                 'stereo_row_tolerance_px)')
    min_disparity_px: float = param(1.0, 'smallest disparity of a stereo match, pixels',
                                    range=(0.1, 100.0))
    min_depth_m: float = param(0.7, 'nearest depth of a stereo match (largest disparity '
                               'f*B/min_depth), metres', range=(0.05, 100.0))
    search_radius_px: float = param(40.0, 'temporal search radius around the previous '
                                    'position without a motion prediction, pixels',
                                    range=(1.0, 500.0))
    wide_search_radius_px: float = param(80.0, 'when the search within search_radius_px '
                                         'finds no consistent motion, a last search within '
                                         'this radius of the previous position (a vigorous '
                                         'walker turns the camera 6-7 degrees, 35 px, between '
                                         'frames), pixels; 0 = none', range=(0.0, 500.0))
    predicted_search_radius_px: float = param(20.0, 'temporal search radius around the '
                                              'predicted position, pixels',
                                              range=(1.0, 500.0))
    use_prediction: bool = param(True, 'predict the motion from the last one (constant '
                                 'velocity) to narrow the temporal search; a wide search '
                                 'follows if it fails')
    threshold_px: float = param(1.5, 'RANSAC inlier bound on the reprojection error, pixels',
                                range=(0.1, 20.0))
    faint_threshold_px: float = param(2.5, 'when no search finds a consistent motion within '
                                      'threshold_px, the first search\'s matches are '
                                      'solved once more with this inlier bound, pixels (0: '
                                      'never)', range=(0.0, 20.0))
    max_iterations: int = param(200, 'most RANSAC samples', range=(10, 100000))
    confidence: float = param(0.999, 'RANSAC stops once this sure of an all-inlier sample',
                              range=(0.5, 0.999999))
    huber_px: float = param(1.0, 'Huber bound of the final least squares, pixels '
                            '(0: plain least squares)', range=(0.0, 20.0))
    refine_iterations: int = param(8, 'Gauss-Newton/LM iterations of the final refinement',
                                   range=(0, 100))
    min_features: int = param(30, 'fewer stereo features in a pair: no motion '
                              '(too_few_features)', range=(3, 10000))
    min_inliers: int = param(20, 'fewer inlier features: no motion', range=(4, 10000))
    max_rotation_deg: float = param(30.0, 'a larger rotation between two pairs is refused '
                                    '(implausible), degrees', range=(0.1, 180.0))
    max_translation_m: float = param(1.5, 'a larger translation between two pairs is '
                                     'refused (implausible), metres', range=(0.001, 100.0))
    max_speed_mps: float = param(3.0, 'a translation faster than this over the time between '
                                 'the two pairs is refused (implausible for a walker; a '
                                 'wrong motion on faint texture), m/s (0: no limit)',
                                 range=(0.0, 100.0))
    seed: int = param(0, 'seed of the RANSAC sampling (repeatable results)',
                      range=(0, 2 ** 31 - 1))

    def __post_init__(self) -> None:
        check_fields(self)

    def ransac_settings(self, threshold_px: float | None = None) -> RansacSettings:
        """The RANSAC settings (inlier bound ``threshold_px``, default the setting's)."""
        bound = self.threshold_px if threshold_px is None else float(threshold_px)
        return RansacSettings(threshold_px=bound, max_iterations=self.max_iterations,
                              confidence=self.confidence, min_inliers=self.min_inliers,
                              huber_px=self.huber_px, refine_iterations=self.refine_iterations)


@dataclass
class StereoFeatures:
    """One pair's features.

    Attributes:
        stamp_ns: the pair's stamp (None if not given).
        left: (N, 2) left corners (with a valid NCC window), pixels.
        desc: (N, D) their NCC windows.
        right: (N, 2) the stereo match of each, NaN rows where none.
        n_right: corners found in the right image.
    """

    stamp_ns: int | None
    left: np.ndarray
    desc: np.ndarray
    right: np.ndarray
    n_right: int

    @property
    def stereo(self) -> np.ndarray:
        """(N,) bool: the features with a stereo match."""
        return np.all(np.isfinite(self.right), axis=1)


@dataclass
class EgomotionResult:
    """The outcome of one pair.

    Attributes:
        status: OK, FIRST, TOO_FEW_FEATURES, TOO_FEW_MATCHES, NO_MOTION or IMPLAUSIBLE.
        motion: the estimate (``R``, ``t`` = ``T_ref_cur``, covariance) when status is
            OK; None otherwise.
        reference_stamp_ns: stamp of the pair the motion is from (None if none).
        n_corners: (left, right) corners found; n_stereo: features with a stereo
            match; n_matches: temporal matches; n_inliers: inliers of the motion.
        predicted: the temporal search used a motion prediction.
        timings_ms: CPU time of this thread per stage ('detect': corners, windows and
            stereo matching; 'match': temporal matching; 'solve': the motion), 'cpu' (the
            whole call) and 'wall' (its wall time), milliseconds. CPU time is what one
            core spends, whatever else the machine runs.
        message: a human-readable line for logs and diagnostics.
    """

    status: str
    motion: MotionEstimate | None = None
    reference_stamp_ns: int | None = None
    n_corners: tuple[int, int] = (0, 0)
    n_stereo: int = 0
    n_matches: int = 0
    n_inliers: int = 0
    predicted: bool = False
    timings_ms: dict = field(default_factory=dict)
    message: str = ''

    @property
    def ok(self) -> bool:
        return self.status == OK


class EgomotionEstimator:
    """Frame-to-frame stereo egomotion; holds the reference pair between calls.

    Args:
        config: EgomotionConfig (defaults if None).
    """

    def __init__(self, config: EgomotionConfig | None = None) -> None:
        self.config = config or EgomotionConfig()
        self._rng = np.random.default_rng(self.config.seed)
        #: the rig's vertical misalignment (kept over resets; a new camera restarts it)
        self.alignment = VerticalAlignment()
        self.reset()

    def reset(self) -> None:
        """Forget the reference pair and the motion history."""
        self.reference: StereoFeatures | None = None
        self._last_motion: tuple[np.ndarray, np.ndarray] | None = None
        self._last_dt: float | None = None

    # --- features --------------------------------------------------------------------
    def features(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                 stamp_ns: int | None = None) -> StereoFeatures:
        """Corners of both images and their stereo matches."""
        c = self.config
        kw: dict[str, Any] = dict(method=c.detector, max_corners=c.max_corners,
                  min_distance=c.min_corner_distance_px,
                  border=max(6, c.patch_half_size + 1), subpix_half_window=c.subpix_half_window,
                  quality=c.corner_quality, min_strength=c.min_corner_strength)
        lf: np.ndarray = left.astype(np.float32)
        rf: np.ndarray = right.astype(np.float32)
        if c.smoothing_sigma_px > 0:
            lf = cv2.GaussianBlur(lf, (0, 0), c.smoothing_sigma_px)
            rf = cv2.GaussianBlur(rf, (0, 0), c.smoothing_sigma_px)
        pl = detect_corners(lf, **kw)
        pr = detect_corners(rf, **kw)
        dl, vl = patches(lf, pl, c.patch_half_size)
        dr, vr = patches(rf, pr, c.patch_half_size)
        pl, dl = pl[vl], dl[vl]
        pr, dr = pr[vr], dr[vr]
        if c.align_vertical:
            self.alignment.update(left, right, cam.f, cam.cx, cam.cy)
            if self.alignment.wanted():
                pr = pr.copy()
                pr[:, 1] -= self.alignment.dv_at(pr[:, 0])
        idx = match_stereo(pl, dl, pr, dr, row_tol=c.stereo_row_tolerance_px,
                           min_disparity=c.min_disparity_px,
                           max_disparity=cam.fb / c.min_depth_m, min_ncc=c.min_ncc,
                           margin=c.ncc_margin)
        right_pts = np.full(pl.shape, np.nan)
        right_pts[idx >= 0] = pr[idx[idx >= 0]]
        return StereoFeatures(stamp_ns, pl, dl, right_pts, len(pr))

    # --- the per-pair step -----------------------------------------------------------------
    def process(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                stamp_ns: int | None = None,
                prediction: tuple[np.ndarray, np.ndarray] | None = None) -> EgomotionResult:
        """Estimate the motion from the reference pair to this one.

        Args:
            left, right: (H, W) uint8 rectified images.
            cam: the rectified stereo camera.
            stamp_ns: the pair's stamp (for the constant-velocity prediction).
            prediction: optional predicted ``T_ref_cur`` (R (3, 3), t (3,)), e.g. from a
                walk model; overrides the constant-velocity prediction.
        Returns:
            EgomotionResult. On OK the reference becomes this pair.
        """
        c = self.config
        w0, c0 = time.perf_counter(), time.thread_time()
        times: dict[str, float] = {}
        feats = self.features(left, right, cam, stamp_ns)
        times['detect'] = (time.thread_time() - c0) * 1e3
        n_stereo = int(feats.stereo.sum())
        base: dict[str, Any] = dict(n_corners=(len(feats.left), feats.n_right), n_stereo=n_stereo)

        def done(res: EgomotionResult) -> EgomotionResult:
            res.timings_ms = dict(times, cpu=(time.thread_time() - c0) * 1e3,
                                  wall=(time.perf_counter() - w0) * 1e3)
            return res
        if n_stereo < c.min_features:
            return done(EgomotionResult(
                TOO_FEW_FEATURES, None, self._ref_stamp(), **base,
                message=f'too few features: {n_stereo} stereo matches of '
                        f'{len(feats.left)}/{feats.n_right} corners (need {c.min_features})'))
        ref = self.reference
        if ref is None:
            self.reference = feats
            return done(EgomotionResult(FIRST, None, None, **base,
                                        message=f'first pair: {n_stereo} stereo features'))
        dt = None
        if stamp_ns is not None and ref.stamp_ns is not None:
            dt = (stamp_ns - ref.stamp_ns) / 1e9
        pred = prediction if prediction is not None else self._constant_velocity(dt)
        # the prediction, then around the previous positions, then wider around them
        attempts = ([(pred, c.predicted_search_radius_px)] if pred is not None else []) + [
            (None, c.search_radius_px)]
        if c.wide_search_radius_px > c.search_radius_px:
            attempts.append((None, c.wide_search_radius_px))
        est, n_matches, used_pred = None, 0, False
        first = None            # the first search's matches, and whether predicted
        t_match = t_solve = 0.0
        for p, radius in attempts:
            t1 = time.thread_time()
            corr = self._correspondences(ref, feats, cam, p, radius)
            t2 = time.thread_time()
            n_matches = len(corr)
            if n_matches >= c.min_inliers:
                est = estimate_motion(c.method, corr, cam, c.ransac_settings(), self._rng)
            t_match += (t2 - t1) * 1e3
            t_solve += (time.thread_time() - t2) * 1e3
            used_pred = p is not None
            if est is not None and est.ok:
                break
            first = first if first is not None else (corr, used_pred)
        if ((est is None or not est.ok) and first is not None
                and c.faint_threshold_px > c.threshold_px and len(first[0]) >= c.min_inliers):
            t2 = time.thread_time()
            est = estimate_motion(c.method, first[0], cam,
                                  c.ransac_settings(c.faint_threshold_px), self._rng)
            t_solve += (time.thread_time() - t2) * 1e3
            n_matches, used_pred = len(first[0]), first[1]
        times['match'] = t_match
        times['solve'] = t_solve
        base.update(n_matches=n_matches, predicted=used_pred)
        if est is None or not est.ok:
            status = TOO_FEW_MATCHES if n_matches < c.min_inliers else NO_MOTION
            why = (f'{n_matches} temporal matches' if est is None else est.reason)
            # this pair has features: it becomes the reference (the chain is broken)
            self.reference = feats
            self._last_motion = None
            return done(EgomotionResult(status, None, ref.stamp_ns, **base,
                                        n_inliers=0 if est is None else est.num_inliers,
                                        message=f'no motion: {why}'))
        angle = math.degrees(float(np.linalg.norm(so3_log(est.R))))
        dist = float(np.linalg.norm(est.t))
        fast = c.max_speed_mps > 0 and dt is not None and dt > 0 and dist > c.max_speed_mps * dt
        if angle > c.max_rotation_deg or dist > c.max_translation_m or fast:
            self.reference = feats
            self._last_motion = None
            return done(EgomotionResult(IMPLAUSIBLE, None, ref.stamp_ns, **base,
                                        n_inliers=est.num_inliers,
                                        message=f'implausible motion refused: {angle:.1f} deg, '
                                                f'{dist:.2f} m'
                                                + (f' in {dt:.2f} s' if fast else '')))
        self.reference = feats
        self._last_motion = (est.R, est.t)
        self._last_dt = dt
        return done(EgomotionResult(OK, est, ref.stamp_ns, **base, n_inliers=est.num_inliers,
                                    message=f'{est.num_inliers} inliers of {n_matches} matches, '
                                            f'{est.rms_px:.2f} px rms'))

    def _ref_stamp(self):
        return None if self.reference is None else self.reference.stamp_ns

    def _constant_velocity(self, dt):
        """The last motion scaled to the interval dt (None when not usable)."""
        if not self.config.use_prediction or self._last_motion is None:
            return None
        r, t = self._last_motion
        if dt is None or self._last_dt is None or self._last_dt <= 0:
            return r, t
        k = dt / self._last_dt
        if not (0.2 <= k <= 5.0):
            return None
        return so3_exp(so3_log(r) * k), t * k

    def _correspondences(self, ref: StereoFeatures, cur: StereoFeatures, cam: StereoCamera,
                         prediction, radius: float) -> Correspondences:
        """Temporal matches of the reference's stereo features: searched within
        ``radius`` px of where ``prediction`` (R, t = T_ref_cur) puts them, or of where
        they were when it is None."""
        c = self.config
        s = ref.stereo
        prev_l, prev_r, prev_d = ref.left[s], ref.right[s], ref.desc[s]
        if prediction is not None:
            r_cr, t_cr = invert(*prediction)
            pts = triangulate(prev_l, prev_r, cam.f, cam.cx, cam.cy, cam.baseline)
            x1 = pts @ r_cr.T + t_cr
            with np.errstate(invalid='ignore', divide='ignore'):
                pred = project(x1, cam.f, cam.cx, cam.cy)
            pred[~(x1[:, 2] > 0.05)] = np.nan
        else:
            pred = prev_l
        idx = match_temporal(prev_d, pred, cur.left, cur.desc, radius, c.min_ncc, c.ncc_margin)
        m = idx >= 0
        return Correspondences(prev_l[m], prev_r[m], cur.left[idx[m]], cur.right[idx[m]])


def use_one_core() -> None:
    """Pin OpenCV and numpy's OpenBLAS to one thread in this process.

    The estimator's matrix products are small: a second BLAS thread only spins and, on a
    busy machine, multiplies the wall time. The node and ``asmonc motion`` call this; the
    per-frame budget (30 Hz at 320x240) is measured on one core. OpenBLAS is found among
    the loaded libraries (numpy's wheel bundles ``scipy_openblas``); nothing happens if
    it is not there.
    """
    import ctypes
    import glob
    import os

    cv2.setNumThreads(1)
    paths: set[str] = set()
    try:
        with open('/proc/self/maps') as fh:
            for line in fh:
                part = line.split()[-1]
                if 'openblas' in os.path.basename(part) and '.so' in part:
                    paths.add(part)
    except OSError:
        pass
    if not paths:
        libs = os.path.join(os.path.dirname(os.path.dirname(np.__file__)), 'numpy.libs')
        paths.update(glob.glob(os.path.join(libs, '*openblas*.so*')))
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ('scipy_openblas_set_num_threads64_', 'scipy_openblas_set_num_threads_64_',
                     'openblas_set_num_threads64_', 'openblas_set_num_threads'):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(ctypes.c_int(1))
                break


__all__ = ['EgomotionConfig', 'EgomotionEstimator', 'EgomotionResult', 'StereoFeatures', 'OK',
           'FIRST', 'TOO_FEW_FEATURES', 'TOO_FEW_MATCHES', 'NO_MOTION', 'IMPLAUSIBLE',
           'use_one_core']
