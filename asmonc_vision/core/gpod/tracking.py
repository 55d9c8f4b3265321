"""Obstacle tracks across frames (`Tracking._track`): the detections' feet filtered by
`ObstacleTracker` through the camera's motion, the tracks coasted through missed
frames unless their place is seen free, and the confidences over views.
"""
from __future__ import annotations

import math
from collections import deque
from typing import cast

import cv2
import numpy as np

from ..camera import MetricPlane, StereoCamera, ground_range_bearing
from .detection import Detection
from .footing import _FrameContext
from .grouping import _same_object
from .results import GpodObstacle, replaced
from .support import _below_view, _moved_roi

#: How far the wearer may walk per second while the camera motion is unknown, m/s: the
#: uncertainty added to an obstacle remembered below the view that is held in place
#: (`GpodDetector._track`).
_UNKNOWN_WALK_MPS = 1.5


class Tracking(Detection):
    """The obstacle-track stage of `GpodDetector`."""

    def _track(self, detections: tuple[GpodObstacle, ...], stamp_s: float, still: bool,
               cam: StereoCamera, metric: MetricPlane, motion=None
               ) -> tuple[GpodObstacle, ...]:
        """The frame's reports: its detections with their feet filtered by their obstacle
        tracks, and the tracks coasted through this frame (`core.obstacle_tracks`). The
        tracks' motion input is ``motion`` if given, else the identity while the rig
        stands still; after a motion not given (and not held, `_motion_or_held`) the
        tracks end, except the sure ones below the view, which stay in place. Drop-offs
        are not tracked. A coasted obstacle moved by a given motion has its image region
        re-projected from its new foot and top. While the rig stands still, a track not
        detected is still seen when a detection's image region overlaps its own by half
        (the same obstacle placed at another point)."""
        n = metric.normal_up
        # the time since the previous pair, s (None for the first)
        dt = None if self._track_stamp is None else stamp_s - self._track_stamp
        self._track_stamp = stamp_s
        motion = self._motion_or_held(motion, dt, still)
        moved = motion is not None
        if motion is not None:
            mcov = motion[2] if len(motion) > 2 else None
            self._tracker.predict(stamp_s, (motion[0], motion[1]), mcov)
        elif still:
            self._tracker.predict(stamp_s, (np.eye(3), np.zeros(3)))
        else:
            # The rig moves and the motion is unknown: the tracks end, but an obstacle
            # remembered below the view stays where it was last placed (it is not
            # forgotten for want of a motion; nothing else could find it again), its
            # place as uncertain as the walk since then.
            walk = _UNKNOWN_WALK_MPS * max(dt or 0.0, 0.0)
            self._tracker.predict(stamp_s, None, walk ** 2 * np.eye(3),
                                  hold=lambda ob, foot: _below_view(cam, foot))
            moved = True            # re-project the held tracks' regions from their feet
        obst = [o for o in detections if not o.is_drop]
        drops = [o for o in detections if o.is_drop]
        feet = np.array([o.position - o.height * n for o in obst]).reshape(-1, 3)
        cov = self._foot_covariance(feet, cam)

        def is_free(payload: object, foot: np.ndarray) -> bool:
            ob = cast(GpodObstacle, payload)        # (the tracks' payloads are obst)
            roi = _moved_roi(ob, foot, n, cam, require_in_view=True) if moved else ob.roi
            return self._track_is_free(ob, foot, roi)
        # While the view stands still an obstacle's nearest visible point is one fixed
        # point, so a detection of the same obstacle placed elsewhere (its far corner when
        # one silhouette edge dips) keeps its track seen; in motion the nearest visible
        # part of a large obstacle moves with the view, and it does not. The detection
        # must not lie more than detection.cluster_radius_m farther than the track: a nearer one
        # (boxes reported as one obstacle at the nearest) or a far corner may be the
        # same obstacle, but an obstacle seen metres beyond a track shows the track's
        # placement was wrong (a pole's foot once followed down a paving joint).
        radius = self.config.detection.cluster_radius_m
        tracks = self._tracker.update(
            feet, cov, obst, is_free,
            (lambda a, b: _same_object(cast(GpodObstacle, a), cast(GpodObstacle, b), radius))
            if still else None,
            lambda ob, foot: _below_view(cam, foot))
        out = list(drops)
        feet_t = np.array([tr.foot for tr in tracks]).reshape(-1, 3)
        rngs, brgs = ground_range_bearing(metric, feet_t)
        confs = self._track_confidences(tracks, still)
        for tr, rng_k, brg_k, conf in zip(tracks, rngs.tolist(), brgs.tolist(), confs):
            ob = cast(GpodObstacle, tr.payload)
            seen = tr.index >= 0
            # (without require_in_view _moved_roi always gives a region)
            roi = (ob.roi if (seen or not moved)
                   else cast('tuple[int, int, int, int]', _moved_roi(ob, tr.foot, n, cam)))
            out.append(replaced(
                ob, position=tr.foot + ob.height * n, range=rng_k, roi=roi, confidence=conf,
                bearing=brg_k, track_id=tr.track_id, age_s=tr.age_s,
                string_ids=ob.string_ids if seen else np.zeros(0, np.int32),
                num_edge_pixels=ob.num_edge_pixels if seen else 0))
        out.sort(key=lambda o: o.range)
        return tuple(out)

    def _motion_or_held(self, motion, dt: float | None, still: bool):
        """The tracks' motion input for a pair ``dt`` s after the previous one (None for
        the first): ``motion`` when given (and remembered); else, while the rig moves,
        the last given motion scaled to this pair's time step (rotation vector and
        translation times dt / dt_last, at most 3x), with a translation covariance of
        (|t| / 2)² I, for at most ``tracks.motion_hold_frames`` pairs in a row; else None
        (the identity while standing still, the tracks end otherwise)."""
        if motion is not None:
            self._last_motion = ((np.asarray(motion[0], float), np.asarray(motion[1], float),
                                  dt) if dt is not None and dt > 0 else None)
            self._motion_held = 0
            return motion
        last = self._last_motion
        if still or last is None or dt is None or dt <= 0:
            self._last_motion = None
            return None
        if self._motion_held >= self.config.tracks.motion_hold_frames:
            return None
        R0, t0, dt0 = last
        k = dt / dt0
        if k > 3.0:
            return None
        self._motion_held += 1
        rvec, _ = cv2.Rodrigues(R0)
        R, _ = cv2.Rodrigues(rvec * k)
        t = t0 * k
        # the walker may have changed pace or turned: half the step either way
        return R, t, (0.5 * float(np.linalg.norm(t))) ** 2 * np.eye(3)

    def _track_confidences(self, tracks, still: bool = False) -> list[float]:
        """The confidence of each track (`ObstacleTracker.update`'s outputs) reported this
        frame: 1 - prod(1 - c) over its detection confidences c in its latest
        ``tracks.confidence_frames`` views, this frame's included when it was detected.
        A view is one frame, or a run of frames while the rig stands still (``still``:
        this frame saw what the previous one saw), which counts once, at its largest
        confidence: each view's evidence is taken as independent of the others', but a
        still view's frames repeat the same matches, their errors as well (a mismatch
        made by the scene repeats in every frame), and their noise is already averaged
        in the detection (``temporal.frames``). Forgets the tracks that ended."""
        k = self.config.tracks.confidence_frames
        if not still:
            self._view += 1
        old, self._track_conf = self._track_conf, {}
        out = []
        for tr in tracks:
            hist, view = old.get(tr.track_id) or (deque(maxlen=k), -1)
            if tr.index >= 0:
                c = float(tr.payload.confidence)
                if hist and view == self._view:
                    hist[-1] = max(hist[-1], c)      # the same view seen again
                else:
                    hist.append(c)
                view = self._view
            self._track_conf[tr.track_id] = (hist, view)
            # 1 - prod(1 - c_i)
            q = math.prod(1.0 - c for c in hist) if hist else 1.0 - tr.payload.confidence
            out.append(float(min(max(1.0 - q, 0.0), 1.0)))
        return out

    def _foot_covariance(self, feet: np.ndarray, cam: StereoCamera) -> np.ndarray:
        """(N, 3, 3) covariance of detected feet (N, 3), m²: triangulation of the foot's
        pixel (``tracks.pixel_sigma_px`` in u and v, the ground's disparity noise) plus
        ``tracks.position_sigma_m``² (which point of the obstacle is nearest)."""
        c = self.config
        k = feet.shape[0]
        z = np.maximum(feet[:, 2], 1e-3)
        d = cam.fb / z
        sig_d = self._sigma if np.isfinite(self._sigma) else c.detection.disparity_sigma_px
        # X = (u - cx) B / d + B / 2, Y = (v - cy) B / d, Z = f B / d (cyclopean u):
        # J = d(X, Y, Z)/d(u, v, d)
        J = np.zeros((k, 3, 3))
        J[:, 0, 0] = z / cam.f
        J[:, 1, 1] = z / cam.f
        J[:, 0, 2] = -(feet[:, 0] - cam.baseline / 2.0) / d
        J[:, 1, 2] = -feet[:, 1] / d
        J[:, 2, 2] = -z / d
        S = np.diag([c.tracks.pixel_sigma_px ** 2, c.tracks.pixel_sigma_px ** 2, sig_d ** 2])
        return (np.einsum('nij,jk,nlk->nil', J, S, J)
                + (c.tracks.position_sigma_m ** 2) * np.eye(3)[None])

    def _track_is_free(self, ob: GpodObstacle, foot: np.ndarray,
                       roi: tuple[int, int, int, int] | None) -> bool:
        """Whether this frame shows an undetected track's place free.

        Args:
            ob: the track's latest detection.
            foot: (3,) its predicted foot, metres, left optical frame.
            roi: its image region (x, y, w, h) in this frame, left-image pixels, clipped
                to the image; None when the region lies wholly outside the image.
        Returns:
            True when the foot is behind the camera or out of view to the side or above
            (passed, or gone from view), or when the region holds at least
            ``tracks.free_min_features`` reliably matched edge pixels on the ground plane
            (within half their threshold) where the obstacle would have stood out (the
            foot's disparity at least the threshold above the plane's), and three times
            as many as above it. A foot below the image (an obstacle walked up to) is
            free only by that evidence, from the part of its region still in view.
        """
        # (set by the frame's pass before its tracks are updated)
        cam, ctx = cast(StereoCamera, self._cam), cast(_FrameContext, self._ctx)
        if foot[2] <= 1e-3:
            return True
        uf, vf = (float(w[0]) for w in cam.project_left(foot))
        below = vf > cam.height - 1          # `_below_view`: no evidence, not passed
        if not below and not (0 <= uf <= cam.width - 1 and 0 <= vf):
            return True
        if roi is None:
            return False
        x, y, w, h = roi
        inside = (ctx.usable & (ctx.u_left >= x) & (ctx.u_left <= x + w - 1)
                  & (ctx.v >= y) & (ctx.v <= y + h - 1))
        ex = ctx.excess_mean[inside]
        thr = self._frame_thr[inside]
        # Ground evidence counts only where the obstacle would have shown: a point of its
        # face, at about the foot's disparity, stands above the plane there by
        # d_foot - d_plane >= the threshold (its lowest rows are at the plane's
        # disparity under either hypothesis and say nothing).
        informative = (cam.fb / foot[2] - ctx.pd[inside]) >= thr
        on_ground = int(np.count_nonzero((np.abs(ex) <= 0.5 * thr) & informative))
        above = int(np.count_nonzero(ex > 0.5 * thr))
        return on_ground >= self.config.tracks.free_min_features and on_ground >= 3 * above

