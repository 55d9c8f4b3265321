"""`GpodDetector`: the wiring of the stages per stereo pair (`process`): images checked,
edges and matches, the plane, the detection, the binned pass, the unseen-ground rule
and the tracks.
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Callable, cast

import numpy as np

from ..alignment import AlignmentConfig, VerticalAlignment, brightness_gain_offset
from ..camera import MetricPlane, StereoCamera, ground_axes
from ..config import override
from ..edges import detect_vertical_edges, image_noise_sigma, textured_edge_threshold
from ..ground_plane import fast_median
from ..matching import pmf_match
from ..plain_face import FaceCheck, check_face
from ..unseen_ground import UNKNOWN_HEIGHT
from . import kernels as kn
from .coarse import _coarse_consistent, _disparity_image, bin_pair
from .faces import _ground_points
from .results import GpodFeatures, GpodObstacle, GpodResult
from .settings import GpodConfig
from .support import _features, _noise_key, _Pass, _state_metric
from .tracking import Tracking

#: The left image's pixel noise is estimated (`edges.image_noise_sigma`, 0.2 ms at
#: 320 x 240) on the first frame and then every this many frames.
_NOISE_EVERY = 8


class GpodDetector(Tracking):
    """The GPOD obstacle detector with ground-plane calibration and per-frame refit.

    Call :meth:`process` on every rectified stereo pair, in order. The detector keeps
    the ground plane between frames; it resets itself when the camera changes, and
    :meth:`reset` starts a new calibration.
    """

    def __init__(self, config: GpodConfig | None = None) -> None:
        self.config = config if config is not None else GpodConfig()
        kn.warm_up()
        c = self.config
        #: the rig's vertical misalignment (a property of the cameras: kept over resets
        #: of the detector, restarted by a new camera)
        self.alignment = VerticalAlignment(AlignmentConfig(
            enabled=c.image.align_vertical, every_frames=c.image.align_every_frames,
            apply_min_px=c.image.align_apply_px))
        #: a callable of the pair's stillness giving the camera's motion since the
        #: previous pair for the surface carried (None: the identity while still only;
        #: set by a caller such as `core.perception.Perception`, kept over resets)
        self.surface_motion: Callable[[bool], tuple | None] | None = None
        self.reset()

    # ------------------------------------------------------------------ helpers
    def _check_images(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera) -> None:
        """Raise ValueError unless both images are 2-D uint8 of the camera's size."""
        for name, img in (('left', left), ('right', right)):
            if not isinstance(img, np.ndarray):
                raise ValueError(f'{name} image must be a numpy array, got {type(img).__name__}')
            if img.dtype != np.uint8 or img.ndim != 2:
                raise ValueError(f'{name} image must be a 2-D uint8 array (H, W), got '
                                 f'{img.dtype} with shape {img.shape}')
            if img.shape != (cam.height, cam.width):
                raise ValueError(f'{name} image shape {img.shape} differs from the camera '
                                 f'size (height {cam.height}, width {cam.width})')

    # ------------------------------------------------------------------ main
    def process(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                stamp_ns: int | None = None,
                motion: tuple | Callable[[], tuple | None] | None = None,
                up: np.ndarray | None = None) -> GpodResult:
        """Detect obstacles in one rectified stereo pair.

        Args:
            left, right: (H, W) uint8 rectified grey images, H = cam.height, W = cam.width.
            cam: the rectified stereo camera. A camera different from the previous
                call's resets the detector.
            stamp_ns: the pair's time, ns (for the obstacle tracks' coasting time); None:
                frames ``tracks.frame_period_s`` apart.
            motion: the left camera's motion from the previous pair to this one, the
                obstacle tracks' input: (R (3, 3), t (3,)) or (R, t, cov (3, 3) of t, m²),
                ``X_prev = R X_curr + t`` (metres, left optical frames; `/egomotion`'s
                convention). None: the identity while the rig stands still (its edges
                stay in place), unknown otherwise (the tracks end). A callable returning
                one of these is called after the detection, before the tracks are updated
                (so a node can wait for the motion while the detector works).
            up: (3,) the world's up direction in the left optical frame at the pair's
                time (`core.rotations.up_for_pair`: the inclinometer's), or None
                (unknown): the prior of ``plane.gravity_prior_deg`` on the ground's
                orientation.
        Returns:
            The GpodResult (status 'initialising', 'tracking' or 'lost').
        Raises:
            ValueError: images that are not 2-D uint8 arrays of the camera's size.
        """
        t_start = time.perf_counter()
        self._begin(left, right, cam)
        self._up = None if up is None else np.asarray(up, np.float64).reshape(3)
        c = self.config
        corrected = self.alignment.applied
        right = self.alignment.process(left, right, cam.f, cam.cx, cam.cy)
        if self.alignment.applied != corrected:
            if self._calib is None:
                # the calibration frames must all be seen alike (their residual spread
                # sets the obstacle threshold)
                self._init_window.clear()
            else:
                self._sigma_stale = True
        p = self._frame_pass(left, right, cam, motion)
        motion = p.motion
        status, metric, timings = p.status, p.metric, p.timings
        detections = p.detections
        if self._coarse_wanted(cam):
            t0 = time.perf_counter()
            detections = self._with_coarse(detections, p.features, left, right, cam, metric,
                                           None if callable(motion) else motion)
            timings['coarse'] = (time.perf_counter() - t0) * 1e3
        t3 = time.perf_counter()
        obstacles: tuple[GpodObstacle, ...] = ()
        if status == 'tracking':
            stamp_s = (self._frame * c.tracks.frame_period_s if stamp_ns is None
                       else stamp_ns * 1e-9)
            if callable(motion):            # the frame that completed the calibration
                motion = motion()
            metric = cast(MetricPlane, metric)   # (a pass stays 'tracking' only with one)
            obstacles = self._track(detections, stamp_s, p.still, cam, metric, motion)
            unseen = self._unseen_ground(p.features, p.threshold, cam, metric,
                                         detections + obstacles, p.still, right)
            if unseen:
                detections = tuple(sorted(detections + unseen, key=lambda o: o.range))
                obstacles = tuple(sorted(obstacles + unseen, key=lambda o: o.range))
        else:
            self._tracker.reset()
            self._surface_tracker.reset()
            self._last_motion = None
            self._face_memory.forget()      # (carried by no travel over this pair)
            if self._unseen is not None and status == 'initialising':
                # a new calibration; a pair whose plane is lost is no observation of
                # the ground the wearer walks on: the expectation and the band's pairs
                # in a row stay as they were
                self._unseen.reset()
        t4 = time.perf_counter()
        timings['obstacles'] = timings.get('obstacles', 0.0) + (t4 - t3) * 1e3
        timings['total'] = (t4 - t_start) * 1e3
        have_plane = status == 'tracking'
        al = self.alignment
        fit = self._last_fit
        return GpodResult(
            status=status, frame_index=self._frame,
            # (a tracking status has a plane)
            plane_abc=cast(np.ndarray, self._abc).copy() if have_plane else None,
            plane_cov=cast(np.ndarray, self._cov).copy() if have_plane else None,
            plane_num_features=fit.num_features if (fit is not None and have_plane) else 0,
            plane_residual_rms=(fit.residual_rms if (fit is not None and have_plane)
                                else float('nan')),
            plane_updated=p.updated and have_plane, metric_plane=metric if have_plane else None,
            obstacles=obstacles, features=p.features, threshold_px=p.threshold,
            num_edges=(len(p.el), len(p.er)), timings_ms=timings, sigma_px=self._sigma,
            still=p.still, detections=detections,
            misalignment_px=al.max_px if al.measurements else float('nan'),
            misalignment_corrected=al.applied, edge_threshold=p.el.threshold,
            surface=self._surface if have_plane else None)

    def _begin(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera) -> None:
        """Check a pair against its camera (ValueError, `_check_images`); a camera
        different from the previous pair's resets the detector."""
        self._check_images(left, right, cam)
        if self._cam is not None and cam != self._cam:
            self.reset()
        self._cam = cam

    def _frame_pass(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                    motion: tuple | Callable[[], tuple | None] | None = None) -> '_Pass':
        """One pair's edges, matches, plane and detections (no tracking): the images
        already checked against ``cam``, the camera already this detector's; ``motion``
        as `process` takes it (a callable is called once the pair is matched, before
        the plane is updated; not while the plane is being calibrated)."""
        self._left = left
        self._frame += 1
        c = self.config
        timings: dict[str, float] = {}

        t0 = time.perf_counter()
        self._estimate_noise(left)
        edge_kw: dict[str, Any] = dict(abs_threshold=self._edge_threshold(left),
                       rel_threshold=c.edges.rel_threshold,
                       max_angle_deg=c.edges.max_angle_deg,
                       min_string_length=c.edges.min_string_length,
                       blur_sigma=c.edges.blur_sigma)
        el = detect_vertical_edges(left, **edge_kw)
        er = detect_vertical_edges(right, **edge_kw)
        t1 = time.perf_counter()
        timings['edges'] = (t1 - t0) * 1e3

        d_min, d_max = self.disparity_range(cam)
        m, cand, _ = pmf_match(el, er, d_min, d_max,
                               min_strength_ratio=c.matching.min_strength_ratio,
                               max_orientation_diff_deg=c.matching.max_orientation_diff_deg,
                               support_radius=c.matching.pmf_support_radius_px,
                               disparity_gradient_limit=c.matching.pmf_disparity_gradient_limit,
                               iterations=c.matching.pmf_iterations,
                               min_support=c.matching.pmf_min_support,
                               right_gain=self._right_gain(left, right))
        t2 = time.perf_counter()
        timings['matching'] = (t2 - t1) * 1e3

        u = m.u
        v = m.v.astype(np.float64)
        d = m.d.astype(np.float64)
        still = self._stillness(el)
        if callable(motion) and self._calib is not None:     # not while calibrating
            motion = motion()
        self._pair_motion = None if callable(motion) else motion
        s = _noise_key(m)
        status, updated = self._update_plane(u, v, d, s, cam, still,
                                             None if callable(motion) else motion)
        if self._sigma_stale and status == 'tracking' and updated:
            # the images changed since the calibration (the right one is now resampled,
            # or no longer): the residual spread is taken again, about this frame's plane
            self._calibrate_sigma(u, v, d, s.astype(np.float64))
            self._sigma_stale = False
        t3 = time.perf_counter()
        timings['plane'] = (t3 - t2) * 1e3

        metric = None
        detections: tuple[GpodObstacle, ...] = ()
        if status == 'tracking':
            metric = _state_metric(cam, cast(np.ndarray, self._abc))   # (tracking: a plane)
        threshold = self.global_threshold()
        if status == 'tracking' and metric is not None:
            features, detections = self._detect(m, u, v, d, cam, metric, d_min, d_max, el,
                                                er, cand, still)
        else:
            if status == 'tracking':          # smoothing made an implausible plane
                status = 'lost'
            self._acc = None
            features = _features(m, np.full(len(m), np.nan, np.float32))
        timings['obstacles'] = (time.perf_counter() - t3) * 1e3
        return _Pass(status, bool(updated), metric, features, detections, threshold, el, er,
                     still, timings, motion)

    def _unseen_ground(self, features: GpodFeatures, threshold: float, cam: StereoCamera,
                       metric: MetricPlane, known: tuple[GpodObstacle, ...],
                       still: bool = False, right: np.ndarray | None = None
                       ) -> tuple[GpodObstacle, ...]:
        """The frame's band of unseen corridor ground (`core.unseen_ground`), unless an
        obstacle or drop-off in ``known`` at least ``unseen.explain_min_confidence``
        confident explains it, as unknown ground straight ahead: an untracked entry
        (``track_id`` 0) whose ``height`` is ``UNKNOWN_HEIGHT`` (NaN: ground that cannot
        be seen is not a thing; ``disparity_excess`` 0, ``num_edge_pixels`` 0;
        ``confidence`` 1 - seen / expected). Empty when there is none or
        ``unseen.max_ratio`` is 0. The wearer's travel since the previous pair, for a
        band that keeps to the wearer, is the camera's motion (`_ground_motion`, as the
        ground surface is carried; ``still``: the rig stood still) along the plane's
        forward axis. With the right image given and ``unseen.face_min_ncc`` > 0, a
        band in which a plain face stands (`core.plain_face`, swept from the band's near
        edge to its far end) is that face instead: an untracked obstacle
        ``unseen.face_height_m`` tall (or as high as the image shows it) at the face's
        range, straight ahead, the corridor's width, with the band's confidence (its
        seen edge pixels against at least ``unseen.min_expected``); so is a band found
        near the face confirmed in the pairs before, carried by the travel
        (`core.plain_face.FaceMemory`)."""
        if self._unseen is None:
            return ()
        # the known feet on the ground: (forward, left) from their range and bearing; a
        # weak report (a 4 cm blip at 0.08) would hide a wall from the wearer
        known = tuple(o for o in known
                      if o.confidence >= self.config.unseen.explain_min_confidence)
        explained = _ground_points(known) if known else None
        thr = features.threshold if features.threshold is not None else threshold
        us = self.config.unseen
        left = self._left
        faces = us.face_min_ncc > 0.0 and right is not None and left is not None
        travel = None
        if self._unseen.follow_travel_m > 0.0 or faces:
            motion = self._ground_motion(still)
            if motion is not None:
                # X_prev = R X_curr + t: t is the camera's position now, in the previous
                # pair's frame; its forward part along the ground is the travel
                travel = float(np.asarray(motion[1], float).reshape(3) @ ground_axes(metric)[1])
        memory = self._face_memory
        memory.carry(travel)
        checks: dict[tuple[float, float], FaceCheck | None] = {}

        def face_at(range_m: float, far_m: float) -> FaceCheck | None:
            """The plain-face check of a band from its near edge to its far end (once
            per band), if it confirms a face."""
            if left is None or right is None:
                return None
            if (range_m, far_m) not in checks:
                fc = check_face(left, right, cam, metric, range_m, us.half_width_m,
                                us.face_height_m, far_m)
                checks[range_m, far_m] = (fc if fc is not None and fc.confirmed(
                    us.face_min_ncc, us.face_margin) else None)
            return checks[range_m, far_m]

        r = self._unseen.update(cam, metric, features.u_left, features.v, features.excess,
                                thr, explained, left=left, travel_m=travel,
                                face=(lambda x, far: _face_range(face_at(x, far)))
                                if faces else None)
        if r is None:
            memory.explains(None)
            return ()
        # (a band kept for its face alone may have had less expected of it)
        confidence = float(np.clip(1.0 - r.seen / max(r.expected, us.min_expected), 0.0, 1.0))
        face = face_at(r.range, r.far_range) if faces else None
        if face is not None:
            memory.confirmed(face)
        else:
            # the face confirmed in the pairs before, carried, if this band is the one
            # it hides (near, its single peak can be lost)
            face = memory.explains(r.range)
        if face is not None:
            return (_face_obstacle(face, cam, metric, r.width, confidence),)
        u, v = cam.project_left(np.stack([r.position, r.position - r.height
                                          * metric.normal_up]))
        x0 = int(np.clip(np.floor(min(u)), 0, cam.width - 1))
        y0 = int(np.clip(np.floor(min(v)), 0, cam.height - 1))
        x1 = int(np.clip(np.ceil(max(u)), x0 + 1, cam.width))
        y1 = int(np.clip(np.ceil(max(v)), y0 + 1, cam.height))
        return (GpodObstacle(
            position=r.position, height=UNKNOWN_HEIGHT, range=r.range, bearing=0.0,
            width=r.width, disparity_excess=0.0,
            confidence=confidence,
            roi=(x0, y0, x1 - x0, y1 - y0), num_edge_pixels=0,
            string_ids=np.zeros(0, np.int32)),)

    # ------------------------------------------------------------ binned pass
    def _coarse_wanted(self, cam: StereoCamera) -> bool:
        """Whether this camera's images are also searched binned 2 x 2
        (``coarse.min_width``)."""
        w = self.config.coarse.min_width
        return w > 0 and cam.width >= w and cam.height >= 2

    def _with_coarse(self, detections: tuple[GpodObstacle, ...], features: GpodFeatures,
                     left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                     metric: MetricPlane | None, motion: tuple | None = None
                     ) -> tuple[GpodObstacle, ...]:
        """The frame's detections joined by those of the binned pass that no full-size
        detection explains.

        The binned pass is a second detector (its own plane, threshold and noise
        estimates, no tracks) on the pair binned 2 x 2 (`bin_pair`). Its obstacles at least
        ``coarse.min_height_m`` high (drop-offs as deep) whose foot lies farther than
        ``detection.part_radius_m`` from every full-size detection's foot join, their image regions
        scaled to the full image. It runs on every pair, so that its plane calibrates
        along with this one's; while this detector has no plane its detections are not
        used.

        Args:
            detections, features: the full-size detections and matched features of the
                pair.
            left, right: (H, W) uint8 full-size rectified images.
            cam: the full-size camera; metric: this frame's plane (None: none).
        Returns:
            the detections, the binned pass's added, nearest first.
        """
        c = self.config
        if self._coarse is None:
            self._coarse = GpodDetector(override(c, {'coarse.min_width': 0}))
        lb, rb, cam_b = bin_pair(left, right, cam)
        self._coarse._begin(lb, rb, cam_b)
        self._coarse._up = self._up
        p = self._coarse._frame_pass(lb, rb, cam_b, motion)
        if metric is None or not p.detections:
            return detections
        n = metric.normal_up
        feet = np.array([o.position - o.height * n for o in detections]).reshape(-1, 3)
        fine_d = None
        added = []
        for ob in p.detections:
            if abs(ob.height) < c.coarse.min_height_m:
                continue
            if fine_d is None:
                fine_d = _disparity_image(features, cam)
            if not _coarse_consistent(ob, p.features, fine_d):
                continue
            foot = ob.position - ob.height * n
            if len(feet):
                gap = feet - foot
                gap -= np.outer(gap @ n, n)            # along the ground
                if float(np.min(np.linalg.norm(gap, axis=1))) <= c.detection.part_radius_m:
                    continue
            x, y, w, h = ob.roi
            x0, y0 = 2 * x, 2 * y
            roi = (x0, y0, min(2 * w, cam.width - x0), min(2 * h, cam.height - y0))
            added.append(dataclasses.replace(ob, roi=roi, string_ids=np.zeros(0, np.int32)))
        if not added:
            return detections
        return tuple(sorted(detections + tuple(added), key=lambda o: o.range))

    def _right_gain(self, left: np.ndarray, right: np.ndarray) -> float:
        """The factor that puts the right image's grey levels on the left's scale: the
        median over the latest ``image.right_gain_frames`` pairs of the ratio of their grey-level
        spreads (`alignment.brightness_gain_offset`), within [1/4, 4]; 1 when disabled or
        before a pair with contrast."""
        if self.config.image.right_gain_frames == 0:
            return 1.0
        go = brightness_gain_offset(left, right)
        if go is not None:
            self._log_gains.append(math.log(min(max(go[0], 0.25), 4.0)))
        if not self._log_gains:
            return 1.0
        logs = np.asarray(self._log_gains)
        if not np.isfinite(logs).all():
            return math.exp(float(np.median(logs)))
        return math.exp(fast_median(logs))       # (np.median's arithmetic)

    @property
    def image_noise_sigma(self) -> float:
        """The left image's pixel noise as last estimated (:func:`edges.image_noise_sigma`),
        grey levels (NaN before the first frame)."""
        return self._image_noise

    def _estimate_noise(self, left: np.ndarray) -> None:
        """Estimate the left image's pixel noise on the first frame and every
        ``_NOISE_EVERY`` frames after, and set the obstacle edge strength in force from it
        (``detection.min_edge_snr``)."""
        if (self._frame - 1) % _NOISE_EVERY:
            return
        c = self.config
        self._image_noise = image_noise_sigma(left)
        self._min_strength = max(c.detection.min_strength, c.detection.min_edge_snr
                                 * self._noise_gain * self._image_noise)

    def _edge_threshold(self, left: np.ndarray) -> float:
        """The edge threshold of this pair, grey levels per pixel: ``edges.threshold``,
        lowered on weakly textured ground (`edges.textured_edge_threshold`:
        ``edges.min_density``, ``edges.target_density``) to no less than
        ``edges.noise_floor_snr`` times the gradient noise; unchanged while the pixel noise
        is unknown."""
        c = self.config
        if not c.edges.min_density > 0 or not math.isfinite(self._image_noise):
            return c.edges.threshold
        floor = c.edges.noise_floor_snr * self._noise_gain * self._image_noise
        return textured_edge_threshold(left, c.edges.threshold, min_density=c.edges.min_density,
                                       target_density=c.edges.target_density, floor=floor,
                                       blur_sigma=c.edges.blur_sigma)


def _face_range(face: FaceCheck | None) -> float | None:
    """The range of a confirmed face, metres, or None."""
    return None if face is None else face.range


def _face_obstacle(face: FaceCheck, cam: StereoCamera, metric: MetricPlane, width: float,
                   confidence: float) -> GpodObstacle:
    """A confirmed plain face (`core.plain_face`) as an untracked obstacle straight
    ahead: its top ``face.height`` above its foot at ``face.range``, ``width`` metres
    wide; its region in the left image from the tested region's top down to the foot."""
    origin, fwd, _ = ground_axes(metric)
    foot = origin + face.range * fwd
    x, y, w, h = face.roi
    foot_v = cam.project_left(foot[None])[1][0]
    y1 = int(np.clip(np.ceil(foot_v), y + h, cam.height))
    return GpodObstacle(
        position=foot + face.height * np.asarray(metric.normal_up, float),
        height=face.height, range=face.range, bearing=0.0, width=width,
        disparity_excess=face.excess, confidence=confidence, roi=(x, y, w, y1 - y),
        num_edge_pixels=0, string_ids=np.zeros(0, np.int32))
