"""The detector's state between frames (`DetectorState.reset`): the plane, its
calibration and filter, the threshold's sigma, the temporal averages, the tracks.
"""
from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..alignment import VerticalAlignment
from ..camera import MetricPlane, StereoCamera
from ..edges import gradient_noise_gain
from ..ground_plane import PlaneFit
from ..ground_surface import GroundSurface
from ..surface_tracking import SurfaceTracker
from ..obstacle_tracks import ObstacleTracker
from ..plain_face import FaceMemory
from ..unseen_ground import UnseenGroundMonitor
from .footing import _FrameContext
from .settings import GpodConfig

if TYPE_CHECKING:
    from .detector import GpodDetector


class DetectorState:
    """The detector state kept between frames (see `reset`)."""

    config: GpodConfig
    alignment: VerticalAlignment
    #: the surface carried's motion source (`GpodDetector.__init__`)
    surface_motion: Callable[[bool], tuple | None] | None

    def reset(self) -> None:
        """Forget the ground plane and the calibration frames (status 'initialising')."""
        self._cam: StereoCamera | None = None
        self._rng = np.random.default_rng(self.config.plane.seed)
        #: the world's up direction in the left optical frame for the pair (None: unknown)
        self._up: np.ndarray | None = None
        self._init_window: deque = deque(maxlen=self.config.plane.init_frames)
        self._frame = 0
        self._calib: PlaneFit | None = None
        self._abc: np.ndarray | None = None
        self._cov: np.ndarray | None = None
        self._last_fit: PlaneFit | None = None
        self._coast = 0
        #: the plane when the rig last came to stand still (None: moving, or no plane)
        self._still_plane: MetricPlane | None = None
        #: how far the camera has travelled (m, by the motions given) since then
        self._still_travel = 0.0
        #: refits rejected in a row by the change limits around a motion's prediction
        self._rejected = 0
        #: the plane was carried over a frame without a motion and without a refit: it
        #: is not where the camera's later motions would carry it (until a refit)
        self._stale = False
        #: the calibrated camera height and the free heights of the latest refits taken
        #: (cyclopean, metres): the anchor of ``plane.refit_hold_height``
        self._heights: deque = deque(maxlen=self.config.plane.height_anchor_frames + 1)
        #: the free height of this frame's refit (NaN: none)
        self._free_height = math.nan
        #: the plane before this frame's motion (None: no motion this frame)
        self._unmoved: MetricPlane | None = None
        #: residual spread of the initial fit: global, and per edge strength (bin
        #: strengths, bin sigmas), pixels
        self._sigma = float('nan')
        self._sigma_bins: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        #: the residual spread is to be taken again (the right image's correction changed)
        self._sigma_stale = False
        #: the previous frame's left edge pixels (H, W+2) bool, and the running sums of
        #: the excess (S, W) at the matched edge pixels, (H, W) float32 each
        self._prev_edges: np.ndarray | None = None
        self._acc: tuple[np.ndarray, np.ndarray] | None = None
        self._frame_thr = np.zeros(0)
        #: the left image's pixel noise, grey levels (NaN until estimated)
        self._image_noise = float('nan')
        #: the deviation of |dI/du| per grey level of pixel noise, after the edges' blur
        self._noise_gain = gradient_noise_gain(self.config.edges.blur_sigma)
        #: detection.min_strength in force (raised on a noisy camera)
        self._min_strength = self.config.detection.min_strength
        #: the current left image and the current frame's context for describing obstacles
        self._left: np.ndarray | None = None
        self._ctx: _FrameContext | None = None
        #: the ground surface ahead of the latest pair (surface.enabled), or None
        self._surface: GroundSurface | None = None
        #: the ground surface carried through the motion (surface_tracking.enabled)
        self._surface_tracker = SurfaceTracker(self.config.surface_tracking)
        #: the motion given with the current pair (None: none, or not yet known)
        self._pair_motion: tuple | None = None
        c = self.config
        self._tracker = ObstacleTracker(coast_s=c.tracks.coast_s, gate_chi2=c.tracks.gate_chi2,
                                        process_noise_m=c.tracks.process_noise_m,
                                        confirm_hits=c.tracks.confirm_hits,
                                        min_hit_fraction=c.tracks.min_hit_fraction,
                                        sure_hits=c.tracks.sure_hits,
                                        unseen_coast_s=c.tracks.unseen_coast_s)
        #: track id -> (the detection confidences of its latest tracks.confidence_frames
        #: views, the view of the latest); a view: the frames from one that moved to the
        #: next that moves (a still rig's frames see one view)
        self._track_conf: dict[int, tuple[deque, int]] = {}
        self._view = 0
        #: the last given motion (R, t, dt s), the pairs carried by it since, the stamp
        #: of the last tracked pair (s)
        self._last_motion: tuple | None = None
        self._motion_held = 0
        self._track_stamp: float | None = None
        #: log of the right camera's gain relative to the left's, latest pairs
        self._log_gains: deque = deque(maxlen=max(self.config.image.right_gain_frames, 1))
        #: the detector of the binned pass (`_with_coarse`), made on its first pair
        self._coarse: GpodDetector | None = None
        #: the corridor's ground edge pixels expected, and its bands gone unseen
        self._unseen = (UnseenGroundMonitor(c.unseen.max_ratio, c.unseen.min_expected,
                                            c.unseen.frames, c.unseen.range_m,
                                            c.unseen.half_width_m,
                                            c.unseen.follow_travel_m)
                        if c.unseen.max_ratio > 0 else None)
        #: the last plain face confirmed in an unseen band, carried by the travel
        self._face_memory = FaceMemory(c.unseen.frames)

