"""Ground Plane Obstacle Detection (GPOD), after Molton, Se, Brady et al. (1998), Sec. 2.

Per stereo pair:

1. Vertical edges in both images and edge strings (:mod:`.edges`).
2. Row-wise PMF matching of the edges (:mod:`.matching`): features (u_left, u_right, v, d).
3. The ground plane ``d = a*u + b*v + c`` (cyclopean, :mod:`.ground_plane`): calibrated
   from the features of the first ``init_frames`` frames (assumed obstacle-free, as in
   the paper, but fitted robustly anyway; from the last frame alone when the frames'
   planes disagree: a walk from the first frame), then either kept fixed (``'fixed'``,
   the paper's GPOD) or refitted every frame (``'refit'``, so that a walking wearer
   keeps a plane): a coarse robust fit on the nearer half of the features within
   ``refit_gate_px`` of the predicted plane, then a fine fit on the features within
   ``refit_gate_m`` of the coarse plane (when that took another surface: of the
   current plane; standing still: of the plane the rig had when it stopped), accepted
   if it moved the plane plausibly little and smoothed by a Kalman filter on (a, b, c).
   The filter's prediction is the paper's dynamic recalibration: with the camera's
   motion given (`process`'s ``motion``; /egomotion in the node graph) the plane is
   carried through it (`ground_plane.predict_plane`), the refits are gated closer to
   the prediction (``motion_gate_m``) and limited to a small change from it
   (``motion_max_*``), the plane the rig stopped with stays the gate while the wearer
   shifts on the spot (``still_anchor_travel_m``), and frames too poor in ground
   features to refit are bridged by the motion (``motion_coast_frames``); without a
   motion, a constant-plane model with the walking process noise (a refit that finds
   no ground then tries once more within ``refit_retry_gate_px``, and a walking rig's
   plane is carried unrefitted only while the near features agree with it). The RANSAC
   fits weigh features by disparity cubed: of two surfaces, the near one -- the ground
   the wearer stands on -- wins.
4. The obstacle threshold: ``threshold_mode='fixed'``: ``threshold_px`` (1.7 px in the
   paper); ``'sigma'`` (default): ``threshold_k`` times the robust (MAD) spread sigma of
   the disparity residuals of the initial plane fit -- the paper's reasoning from its
   Fig. 4 -- within ``threshold_floor_px`` .. ``threshold_ceiling_px`` (the paper's 1.7);
   with ``sigma_per_edge``, sigma is taken per edge pixel from the initial fit's
   residuals in bins of the precision of its edges' sub-pixel positions (gradient
   curvature: sharp, contrasted edges are located better) and bands of image rows.
5. Obstacles: the disparity excess (measured minus plane disparity) of every matched edge
   pixel is averaged over ``string_window`` neighbouring pixels of its matched run and,
   while the rig stands still (most edges stay in place from frame to frame), over
   about ``temporal_frames`` frames; a pixel above its threshold is an obstacle pixel if
   it lies in a disparity-consistent matched run of its edge string of at least
   ``min_matched_run`` pixels, longer for a larger excess (``obstacle_run_fraction``;
   figural continuity: isolated and short mismatches never make obstacles). An edge
   string is an obstacle if it has at least ``min_obstacle_pixels`` of them (1 is the
   paper's rule "any pixel"; weak edges count less, ``obstacle_min_strength``), comes
   down to the ground (``max_floating_height_m``) and is not a repetitive pattern
   matched a period off (``ambiguity_fraction``; nor is a run of it that hangs in the
   air over another depth of its own string, `hanging_runs`). Pixels below the plane by more than the
   threshold (a disparity deficit where the ground should be) make drop-offs: hazards
   with negative height. Obstacle strings are clustered by the proximity of their feet
   on the ground, and each cluster is reported with its top, height, range and bearing
   of its nearest point, width, disparity excess, confidence and image region; a
   cluster joined from parts farther apart than ``part_radius_m`` is also reported part
   by part. A drop-off is placed at its nearest visible lower ground, for a straight
   brink at the foot of the perpendicular from the camera (`_brink_bearings`).
6. The nearest point of an obstacle (range and bearing of one point): each obstacle
   string's matched run is followed down to where it meets the ground (its excess falls
   to the noise), giving one ground foot per string. A foot nearer than the outermost
   two (in bearing) is the near corner. Otherwise the near corner may have no vertical
   edge (two faces of one shade): if the outermost feet L and R are corners of a
   rectangular footprint, the corner N between them sees them at a right angle, so N
   lies on the circle with diameter LR (Thales); of the candidates on its near arc, those
   whose triangle L-N-R contains visible ground (ground features: free space) are
   impossible, and the one whose contact polyline L-N-R follows the image's intensity
   edges best is taken -- unless it hardly bulges from the chord LR (a frontal face),
   when the feet's probably nearest point is reported (their mean weighted by the
   probability of being the nearest: the middle of a frontal face), as it is when the
   corner would lie beyond the feet. A face running out of the view, or seen as two
   obstacles with a blank middle, is placed at its nearest point (`view_edge_points`,
   `face_gap_points`), unless the ground is seen through its line. A low obstacle seen
   by one silhouette edge only (a frontal box whose other end is matched at the
   ground's disparity) is placed along the face beside that edge which the image shows
   as two parallel intensity edges, its contact line and its top outline
   (`lone_face_points`), when that brings its nearest point nearer.

Status per frame: ``'initialising'`` (not enough calibration frames yet), ``'tracking'``
(a plane is valid for this frame, refitted or carried over for up to
``max_coast_frames``) or ``'lost'`` (no plane could be fitted or carried over). A frame
without a plane is a return value, never an exception.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from typing import Callable, NamedTuple
from dataclasses import dataclass

import cv2
import numpy as np

from .alignment import AlignmentConfig, VerticalAlignment, brightness_gain_offset
from .camera import MetricPlane, StereoCamera, ground_range_bearing, plane_disparity
from .config import param
from .edges import (EdgeMap, chain_roots, detect_vertical_edges, gradient_noise_gain,
                    image_noise_sigma, textured_edge_threshold)
from .edges import warm_up as edges_warm_up
from .motion.geometry import so3_log
from .obstacle_tracks import ObstacleTracker
from .unseen_ground import UNKNOWN_HEIGHT, UnseenGroundMonitor
from .ground_surface import GroundSurface, GroundSurfaceConfig, fit_ground_surface
from .ground_plane import (PlaneFit, PlausiblePlaneConfig, fit_ground_plane, lsq_plane,
                           plane_is_plausible, predict_plane)
from .ground_plane import _median
from .jit import jit as _jit
from .jit import nb_pairwise_sum as _nb_pairwise_sum
from .jit import warmed as _warmed
from .matching import Candidates, Matches, pmf_match
from .matching import warm_up as matching_warm_up

#: ``[True]``, to prefix run-start masks (``np.concatenate``: ``np.r_`` costs ~20 us a call).
_TRUE = np.ones(1, bool)

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
#: A drop's brink taken for a straight line (`_brink_bearings`): at least this many edge
#: strings' nearest lower ground, spanning this many metres, within this orthogonal RMS.
_BRINK_MIN_POINTS = 4
_BRINK_MIN_SPAN_M = 0.5
_BRINK_MAX_RMS_M = 0.1
#: ... with at least this fraction of the points left after dropping those more than
#: _BRINK_MAX_RMS_M behind the line (strings that start on the lower ground).
_BRINK_MIN_KEPT = 0.5

#: An obstacle string's foot is where its matched run, followed down the image from its
#: lowest obstacle pixel, comes within this many noise sigmas of the ground plane.
_FOOT_SIGMAS = 1.0
#: Least uncertainty of a foot's image row, rows (the row is found to a pixel).
_FOOT_MIN_ROWS = 0.5
#: Candidate positions of a hidden near corner on the Thales arc (`hidden_corner`).
_CORNER_ARC_POINTS = 33
#: A hidden corner must bulge beyond the chord between its neighbours by more than this
#: many range sigmas of their feet (else the straight face explains the image as well).
_CORNER_SIGMAS = 2.0
#: Edge strings within this many pixels of the left or right image border may be the
#: view's edge rather than an obstacle's silhouette.
_BORDER_PX = 3.0
#: How far the wearer may walk per second while the camera motion is unknown, m/s: the
#: uncertainty added to an obstacle remembered below the view that is held in place
#: (`GpodDetector._track`).
_UNKNOWN_WALK_MPS = 1.5
#: A ground feature must lie this far (metres) inside a hypothesised footprint to rule
#: it out (features on its sides are its own contact edges; feet and ground features are
#: located to a few centimetres).
_FREE_SPACE_MARGIN_M = 0.05

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
_FACE_BEHIND_MIN = 5
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
#: wide (metres: a gap one could walk through, `GpodConfig.part_radius_m`'s default).
_FACE_GAP_SEEN_M = 0.35
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
_LONE_STEP_M = 0.02
_LONE_MAX_M = 0.7
_LONE_MIN_M = 0.1
_LONE_BAR = 2.0
_LONE_FLOOR_SIGMAS = 4.0
_LONE_MIN_SEP_PX = 2.5
_LONE_MIN_SEP_FRACTION = 0.8
_LONE_MIN_GAIN_M = 0.05
#: The directions searched (radians from the ground's x axis towards y) and the steps
#: along each (metres from the foot).
_LONE_PHI = np.arange(_LONE_DIRECTIONS) * (2.0 * np.pi / _LONE_DIRECTIONS)
_LONE_STEPS = np.arange(1, int(round(_LONE_MAX_M / _LONE_STEP_M)) + 1) * _LONE_STEP_M
#: The standard deviation of the unblurred Sobel gradient per grey level of pixel noise.
_SOBEL_NOISE_GAIN = gradient_noise_gain(0.0)
#: `soft_nearest` averages the nearest foot with the feet as near as it only over one
#: body: not with a foot more than _BODY_GAP_SPAN_M away from it when at least
#: _FACE_BEHIND_MIN ground features lie between the two, _BODY_GAP_BAND_M[0] to [1]
#: metres behind the line joining them and _BODY_GAP_END_M clear of either foot. Behind
#: a face (a box's front, its side) the body and its shadow hide that strip; between two
#: obstacles side by side the ground is seen there.
_BODY_GAP_SPAN_M = 0.2
_BODY_GAP_BAND_M = (0.05, 0.3)
_BODY_GAP_END_M = 0.1

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
_WEAK_HEIGHT_RATIO = 2.0
#: A candidate silhouette is no side of an obstacle when at least this many ground
#: features are seen where the body between it and the obstacle's feet would hide them
#: (`_face_hides_kernel`).
_FACE_HIDDEN_MIN = 2

#: A whole obstacle placed at one part's nearest point takes that part's height and
#: confidence when the part is lower than this fraction of the whole's height (another
#: body, `described_by_part`; the factor 2 of ``_WEAK_HEIGHT_RATIO``).
_OTHER_BODY_HEIGHT_FRACTION = 1.0 / _WEAK_HEIGHT_RATIO

#: `cluster_points_2d` links up to this many (thinned) points by testing all pairs, more
#: on a grid.
_PAIRWISE_POINTS = 256
#: ... and, compiled (`_link_groups_kernel`), up to this many.
_JIT_PAIRWISE_POINTS = 4096
#: The compiled thinning (`_thin_kernel`) counts cells up to this many columns plus rows.
_THIN_MAX_CELLS = 1 << 16

#: The residual spread sigma of the initial fit is taken over the calibration features
#: within this many ``plane_inlier_px`` of the fitted plane.
_SIGMA_GATE = 3.0
#: The initial plane is fitted to the calibration window's frames together only if each
#: frame's residual spread about it is at most this many times that about the frame's
#: own plane (a standing rig: 1.00-1.03; a wearer already walking: 1.2-10).
_WINDOW_SIGMA_RATIO = 1.15

#: `GpodDetector._stillness` compares the strong edges when there are this many, else
#: all edges.
_STILL_MIN_EDGES = 100
#: Largest camera translation (m) and rotation (rad) between two frames of a rig seen
#: standing still (its edges within a pixel) that is taken as a real motion
_STILL_MAX_TRANSLATION_M = 0.02
_STILL_MAX_ROTATION_RAD = math.radians(1.0)

#: The left image's pixel noise is estimated (`edges.image_noise_sigma`, 0.2 ms at
#: 320 x 240) on the first frame and then every this many frames.
_NOISE_EVERY = 8

#: Detector statuses (GroundPlane.msg: INITIALISING = 0, TRACKING = 1, LOST = 2).
STATUSES = ('initialising', 'tracking', 'lost')


@dataclass(frozen=True)
class GpodConfig(PlausiblePlaneConfig):
    """Settings of the GPOD detector (validated on construction)."""

    # --- detection ---------------------------------------------------------------
    threshold_px: float = param(
        1.7, 'Disparity excess over the ground plane above which an edge pixel is an '
        'obstacle, pixels (Molton et al. 1998 use 1.7)', range=(0.05, 50.0))
    threshold_mode: str = param(
        'sigma', "'fixed': an edge pixel is an obstacle pixel when its disparity excess is "
        "above threshold_px (the paper's rule); 'sigma': above threshold_k times the robust "
        '(MAD) spread sigma of the disparity residuals of the initial ground-plane fit (the '
        "paper's Fig. 4 reasoning), kept within threshold_floor_px .. threshold_ceiling_px",
        choices=('fixed', 'sigma'))
    threshold_k: float = param(
        3.5, "'sigma': the obstacle threshold in units of the residual spread sigma",
        range=(0.5, 50.0))
    threshold_floor_px: float = param(
        0.5, "'sigma': least obstacle threshold, pixels", range=(0.05, 50.0))
    threshold_ceiling_px: float = param(
        1.7, "'sigma': largest obstacle threshold, pixels (or the disparity excess of "
        'threshold_ceiling_height_m at threshold_ceiling_depth_m, if larger)',
        range=(0.05, 50.0))
    threshold_ceiling_height_m: float = param(
        0.1, "'sigma': the largest obstacle threshold is at least the disparity excess "
        'f*B*h/(H*z) of an obstacle this high (h, metres) at threshold_ceiling_depth_m (z) '
        'for the camera height H of the calibrated plane: on a rig with a longer baseline '
        'or focal length than the paper\'s, the ground\'s unevenness spreads over more '
        'pixels, and so does the obstacle the ceiling keeps in view; 0 = '
        'threshold_ceiling_px alone', range=(0.0, 1.0))
    threshold_ceiling_depth_m: float = param(
        5.0, "'sigma': the depth of threshold_ceiling_height_m, metres", range=(0.5, 100.0))
    sigma_per_edge: bool = param(
        True, "'sigma': take sigma per edge pixel rather than one for all: the residual "
        'spread of the initial fit in bins of the precision of the edges (gradient '
        'curvature at the maximum: contrast and sharpness; blurred or faint edges are '
        'located less well), times a factor per band of image rows (the far ground '
        'matches less well)')
    obstacle_min_strength: float = param(
        8.0, 'Edge strength (mean |dI/du| of the left and right edge, grey levels per pixel) '
        'from which an obstacle or drop pixel counts fully towards min_obstacle_pixels and '
        'min_drop_pixels; a weaker one counts as (strength / this)^2 of a pixel (weak edges '
        'are often mismatched)', range=(0.0, 255.0))
    obstacle_min_edge_snr: float = param(
        5.0, "The same in units of the image's gradient noise (the deviation of |dI/du| "
        "that the left image's pixel noise gives, estimated every few frames): the larger "
        'of obstacle_min_strength and this times the gradient noise applies, so that on a '
        'noisy camera edges made by the noise count less (0 = off)', range=(0.0, 1000.0))
    temporal_frames: int = param(
        5, 'While the rig stands still, the disparity excess of each edge pixel is averaged '
        'over about this many consecutive frames (exponentially weighted) before the '
        'threshold test; 1 = no averaging. Any motion restarts the average',
        range=(1, 1000))
    still_overlap: float = param(
        0.8, 'The rig counts as still when at least this fraction of the left edge pixels '
        'lie within one column of an edge pixel of the previous frame on the same row (the '
        'edges as strong as obstacle evidence needs, when there are enough of them)',
        range=(0.0, 1.0))
    temporal_gate_px: float = param(
        1.0, 'An edge pixel joins the running average of the pixel at its place in the '
        'previous frame only if its excess is within this of that average, pixels (else the '
        'average restarts there)', range=(0.01, 100.0))
    temporal_gate_thr: float = param(
        0.75, 'The running average also restarts where the excess moved by more than this '
        "times the pixel's obstacle threshold (a change as large as an obstacle makes: a "
        'small obstacle that appears is not averaged with the ground it stands on); the '
        'smaller of this and temporal_gate_px applies (0 = temporal_gate_px alone)',
        range=(0.0, 100.0))
    ambiguity_fraction: float = param(
        0.8, 'An obstacle string whose excess is above 3 px is dropped when at least this '
        'fraction of its obstacle pixels also had a candidate match on the ground plane (a '
        'repetitive pattern, e.g. paving joints matched one tile off); 0 = off',
        range=(0.0, 1.0))
    min_range_m: float = param(
        1.0, 'Nearest depth searched by the matcher, metres along the optical axis '
        '(largest disparity f*B/min_range)', range=(0.05, 100.0))
    max_range_m: float = param(
        10.0, 'Obstacles whose foot is farther than this along the ground are not reported, '
        'metres', range=(0.1, 1000.0))
    search_max_range_m: float = param(
        1000.0, 'Farthest depth searched by the matcher, metres (smallest disparity '
        'f*B/this); keep it far beyond max_range_m so that distant features find their '
        'true match rather than a wrong one inside the range', range=(0.1, 1.0e6))
    # --- ground plane ------------------------------------------------------------
    init_frames: int = param(
        3, 'Frames, assumed obstacle-free, whose features calibrate the initial ground '
        'plane (accumulated, fitted robustly)', range=(1, 1000))
    init_min_inlier_fraction: float = param(
        0.1, 'The initial ground plane is taken only if at least this fraction of the '
        'calibration features lie on it (the ground is a large part of any view the rig '
        'starts in; a plane through a few per cent of them is a chance consensus of '
        'mismatches, as on ground with no clear edges); 0 = any', range=(0.0, 1.0))
    plane_update: str = param(
        'refit', "'fixed': keep the calibrated plane (the paper's GPOD); 'refit': robust "
        'refit every frame from features near the predicted plane, smoothed',
        choices=('fixed', 'refit'))
    refit_gate_px: float = param(
        8.0, 'Features within this disparity of the predicted plane take part in the '
        'coarse per-frame refit (wide enough for the walking motion between frames), '
        'pixels', range=(0.1, 100.0))
    refit_retry_gate_px: float = param(
        16.0, 'With no camera motion to predict the plane (or a plane carried over a frame '
        'that had none), a coarse refit that finds no ground within refit_gate_px is tried '
        'once more with this wider gate: a vigorous walker sways the ground by more than '
        'refit_gate_px between frames, pixels; 0 = no second try', range=(0.0, 100.0))
    refit_gate_m: float = param(
        0.1, 'Features within this height of the coarse plane take part in the fine '
        'per-frame refit, metres (keeps the ground beyond a step or on a kerb out)',
        range=(0.001, 100.0))
    refit_process_noise_px: float = param(
        1.0, "'refit': expected change of the ground disparity from one frame to the next "
        '(walking motion), pixels; the per-frame refits are smoothed by a Kalman filter '
        'that weighs this against the fit covariance (small = smooth, large = follow the '
        'fit)', range=(0.001, 100.0))
    plane_method: str = param(
        'ransac', 'Robust plane fit: RANSAC then least squares on the inliers, or '
        'iteratively trimmed least squares', choices=('ransac', 'trimmed'))
    plane_inlier_px: float = param(
        1.0, 'Inlier bound of the robust plane fit, pixels of disparity', range=(0.05, 20.0))
    plane_min_spread_px: float = param(
        3.0, 'A plane fit is taken only if its inliers spread at least this far across '
        'their main direction in the image (standard deviation along the minor axis), '
        'pixels: features along one line, such as the only joint of smooth slabs, leave '
        'the plane free to turn about it; 0 = any', range=(0.0, 1000.0))
    ransac_iterations: int = param(
        1000, 'Most RANSAC hypotheses per plane fit (it stops earlier once 99% sure)',
        range=(1, 100000))
    min_plane_features: int = param(
        30, 'Least number of inlier features for a valid plane fit', range=(3, 1000000))
    max_coast_frames: int = param(
        2, "'refit': frames the last plane may be carried over when a refit fails "
        '(status tracking, plane not updated) before the status becomes lost',
        range=(0, 100000))
    refit_max_height_change_m: float = param(
        0.1, "'refit': a refit that moves the camera height by more than this from the "
        'current plane is rejected (another surface, e.g. the ground beyond a step), metres',
        range=(0.001, 100.0))
    refit_max_angle_change_deg: float = param(
        8.0, "'refit': a refit that turns the plane normal by more than this from the "
        'current plane is rejected, degrees', range=(0.01, 90.0))
    recover_height_tolerance: float = param(
        0.3, "'refit': when lost (gated refits failed for longer than max_coast_frames), "
        'an ungated refit is accepted if its camera height is within this fraction of the '
        'calibrated one',
        range=(0.0, 10.0))
    recover_max_angle_deg: float = param(
        25.0, "'refit': ... and its normal within this angle of the calibrated normal, "
        'degrees', range=(0.0, 90.0))
    # with the camera's motion known (`process`'s motion: /egomotion in the node graph)
    # the plane is predicted through it (the paper's dynamic recalibration)
    motion_process_noise_px: float = param(
        0.2, "'refit', the camera's motion known: expected change of the ground disparity "
        'from one frame to the next that the motion does not explain (uneven ground, '
        'motion error), pixels; the Kalman process noise in place of '
        'refit_process_noise_px', range=(0.001, 100.0))
    motion_gate_m: float = param(
        0.05, "'refit', the camera's motion known: features within this height of the "
        'plane predicted through the motion (or of the coarse refit) take part in the fine '
        'refit, metres, in place of refit_gate_m (the prediction is good to millimetres: '
        'the ground beyond a kerb down leaks in less)', range=(0.001, 100.0))
    motion_max_height_change_m: float = param(
        0.05, "'refit', the camera's motion known: a refit that moves the camera height by "
        'more than this from the plane predicted through the motion is rejected, metres '
        '(in place of refit_max_height_change_m)', range=(0.001, 100.0))
    motion_max_angle_change_deg: float = param(
        2.0, "'refit', the camera's motion known: a refit that turns the plane normal by "
        'more than this from the plane predicted through the motion is rejected, degrees '
        '(in place of refit_max_angle_change_deg)', range=(0.01, 90.0))
    motion_coast_frames: int = param(
        10, "'refit', the camera's motion known: frames the plane is carried through the "
        'motion alone while refits fail (in place of max_coast_frames; refits rejected by '
        'the motion_max_* limits max_coast_frames times in a row lift those limits '
        'instead: the motion may be wrong)', range=(0, 100000))
    still_anchor_travel_m: float = param(
        0.3, "'refit', the camera's motion known: the plane the rig had when it came to "
        'stand still stays the refit gate, carried through the motion, until the camera '
        'has travelled this far (a wearer who shifts or turns on the spot stands on the '
        'same ground), metres', range=(0.0, 100.0))
    # --- edges ---------------------------------------------------------------------
    edge_threshold: float = param(
        4.0, 'Least horizontal intensity gradient of a vertical edge, grey levels per pixel',
        range=(0.0, 255.0))
    edge_rel_threshold: float = param(
        0.0, 'Least horizontal gradient as a multiple of the mean |dI/du| of the image '
        '(0 = off); the larger of the two thresholds applies', range=(0.0, 100.0))
    edge_max_angle_deg: float = param(
        70.0, 'Largest angle of an edge from the vertical, degrees', range=(1.0, 90.0))
    edge_blur_sigma: float = param(
        0.0, 'Gaussian pre-blur of the images before the Sobel operator, pixels (0 = none)',
        range=(0.0, 10.0))
    edge_min_density: float = param(
        8.0, 'Weakly textured ground: where the lower half of the left image (the near '
        'ground) has fewer vertical-edge candidates at edge_threshold than this many times '
        '120 (this many per row of the paper\'s 320 x 240 image, whatever the image size: a '
        'ground plane needs as many edges, not as dense), the threshold of both images is '
        'lowered for that pair to keep edge_target_density times 120 of them, but not below '
        'edge_noise_floor_snr times the gradient noise (asphalt, plain concrete and large '
        'flags otherwise give too few edges for a ground plane, or a plane through chance '
        'matches); 0 = never lower', range=(0.0, 1000.0))
    edge_target_density: float = param(
        24.0, 'Vertical-edge candidates (times 120, as edge_min_density) in the lower half '
        'of the left image that a threshold lowered by edge_min_density keeps (at least '
        'edge_min_density)', range=(0.0, 1000.0))
    edge_noise_floor_snr: float = param(
        2.5, 'The least edge threshold that edge_min_density may lower to, in units of the '
        "image's gradient noise (the deviation of |dI/du| that the left image's estimated "
        'pixel noise gives)', range=(0.0, 100.0))
    min_string_length: int = param(
        3, 'Edge strings shorter than this many pixels are dropped', range=(1, 100000))
    # --- matching ------------------------------------------------------------------
    match_min_strength_ratio: float = param(
        0.5, 'Least ratio of the weaker to the stronger edge strength of a match',
        range=(0.0, 1.0))
    right_gain_frames: int = param(
        5, 'The right camera\'s gain relative to the left\'s (the ratio of the images\' '
        'grey-level spreads) is the median over this many latest pairs, and the matching\'s '
        'strength test compares edges on the left\'s scale: two cameras with their own '
        'exposure or gain otherwise fail it on true matches and pass it on wrong ones '
        '(0: the cameras are taken as alike)', range=(0, 100))
    match_max_orientation_diff_deg: float = param(
        30.0, 'Largest difference of gradient directions of a match, degrees',
        range=(0.0, 180.0))
    pmf_support_radius_px: float = param(
        3.0, 'PMF support neighbourhood radius in the cyclopean image, pixels',
        range=(1.0, 30.0))
    pmf_disparity_gradient_limit: float = param(
        1.0, 'PMF disparity-gradient limit (1.0 in PMF)', range=(0.05, 1.95))
    pmf_iterations: int = param(
        2, 'PMF winner-take-all rounds: accept the matches with the highest support for '
        'both their edges, remove their competitors, recompute the support (1 = one pass)',
        range=(1, 50))
    pmf_min_support: float = param(
        0.5, 'Least PMF support of an accepted match (sum of 1/distance)', range=(0.0, 1000.0))
    # --- obstacles -----------------------------------------------------------------
    min_matched_run: int = param(
        3, 'An obstacle or drop pixel counts only within a run of at least this many '
        'consecutive matched pixels of its edge string whose disparities agree (figural '
        'continuity; isolated mismatches never make obstacles)', range=(1, 100000))
    obstacle_run_fraction: float = param(
        0.25, 'A pixel with a disparity excess E counts only within a matched run of at '
        'least this fraction of E / |b| pixels (b: the plane disparity change per image '
        'row; an edge standing on the ground needs about E / |b| rows to rise E above the '
        'plane), at least min_matched_run and at most max_required_run: a short run with a '
        'large excess is a mismatch, not a tall obstacle', range=(0.0, 10.0))
    max_required_run: int = param(
        10, 'Longest matched run that obstacle_run_fraction asks for, pixels',
        range=(1, 100000))
    string_disparity_tolerance_px: float = param(
        1.0, 'Largest disparity difference between consecutive pixels of one matched run, '
        'pixels', range=(0.01, 100.0))
    string_window: int = param(
        3, 'The disparity excess of each matched edge pixel is averaged over a window of '
        'this many consecutive pixels of its matched run (centred; 1 = no averaging) '
        'before the threshold test: an obstacle raises its edges coherently, noise does '
        'not', range=(1, 99))
    min_obstacle_pixels: int = param(
        2, 'Obstacle pixels an edge string needs to be an obstacle; 1 is the rule of '
        'Molton et al. (any pixel), 2 rejects single-pixel excursions of far ground',
        range=(1, 100000))
    min_obstacle_pixels_focal_px: float = param(
        300.0, 'The focal length min_obstacle_pixels is for, pixels (the paper\'s rig): a '
        'camera with a longer one needs as many more pixels, the same angle (KITTI\'s '
        'f = 719 px: 5); 0 = min_obstacle_pixels on any camera', range=(0.0, 100000.0))
    max_floating_height_m: float = param(
        0.5, 'An obstacle edge string must come down to within this height above the ground '
        '(its lowest reliably matched pixel); obstacles stand on the ground, a string '
        'floating higher is a mismatch (e.g. a distant pole matched to the wrong edge), '
        'metres', range=(0.0, 100.0))
    detect_drops: bool = param(
        True, 'Report drop-offs (disparity below the ground plane) as negative obstacles')
    min_drop_pixels: int = param(
        3, 'Pixels below the plane by more than the threshold that an edge string needs '
        'to be a drop-off', range=(1, 100000))
    min_drop_cluster_pixels: int = param(
        15, 'Drop pixels a drop-off needs in all (a drop is a region, not a lone string)',
        range=(1, 1000000))
    drop_cluster_radius_m: float = param(
        1.0, 'Drop strings whose feet are closer than this join one drop-off, metres',
        range=(0.01, 100.0))
    max_drop_depth_m: float = param(
        1.5, 'Pixels more than this far below the plane are ignored (mismatches), metres',
        range=(0.01, 100.0))
    max_obstacle_height_m: float = param(
        2.5, 'Pixels higher than this above the plane are ignored (overhead, no hazard), '
        'metres', range=(0.05, 100.0))
    cluster_radius_m: float = param(
        0.7, 'Obstacle strings whose feet on the ground are closer than this join one '
        'obstacle (a gap narrower than this cannot be walked through), metres',
        range=(0.01, 10.0))
    part_radius_m: float = param(
        0.35, 'An obstacle joined by cluster_radius_m from parts whose feet are farther '
        'apart than this (a bollard beside a box) is also reported part by part, each part '
        'at its own nearest point when that is farther than this from the whole\'s; metres, '
        'at most cluster_radius_m (0 = off)', range=(0.0, 10.0))
    coarse_min_width: int = param(
        480, 'Images at least this wide (pixels) are searched a second time binned 2 x 2 '
        '(half the size: a faint texture, such as a plain wall, gives twice the gradient '
        'per pixel at half the noise), and the binned pass\'s obstacles that no full-size '
        'obstacle explains (no foot within part_radius_m) and the full-size matches do not '
        'contradict join the frame\'s; 0 = off',
        range=(0, 100000))
    coarse_min_height_m: float = param(
        0.3, 'The binned pass adds only obstacles at least this high (drop-offs at least '
        'this deep), metres: its disparity is half as fine, and low obstacles are the '
        'full-size pass\'s', range=(0.0, 100.0))
    unseen_max_ratio: float = param(
        0.15, 'Unseen ground (a wall with no edges, `core.unseen_ground`): the walking '
        'corridor\'s ground from some range out to its far end, where at most this fraction '
        'of the matched edge pixels the same cells showed in earlier frames are seen, is '
        'hidden by something, reported as an obstacle at its near edge; 0 = off',
        range=(0.0, 0.95))
    unseen_min_expected: float = param(
        30.0, 'Unseen ground: least number of edge pixels the hidden band must have been '
        'expected to show (fewer: too little evidence either way)', range=(1.0, 1.0e6))
    unseen_frames: int = param(
        2, 'Unseen ground: pairs in a row a band must be found hidden before it is reported',
        range=(1, 1000))
    unseen_range_m: float = param(
        5.0, 'Unseen ground: far end of the watched corridor, metres along the ground',
        range=(0.5, 100.0))
    unseen_half_width_m: float = param(
        0.5, 'Unseen ground: half width of the watched corridor, metres',
        range=(0.05, 10.0))
    unseen_explain_min_confidence: float = param(
        0.3, 'Unseen ground: only a detected obstacle or drop-off at least this confident '
        'explains the missing ground (a weak report that no alarm would announce must not '
        'silence the unseen ground behind it; the alarm node\'s min_confidence), 0..1',
        range=(0.0, 1.0))
    disparity_sigma_px: float = param(
        1.0, 'Standard deviation of the disparity excess of ground features, pixels (the '
        "paper's sigma = 1), for the confidence", range=(0.01, 20.0))
    confidence_full_pixels: int = param(
        20, 'Obstacle pixels at which the confidence is no longer reduced for small '
        'evidence (confidence = P(any pixel truly beyond the threshold) * '
        'min(1, pixels / this), a weak edge pixel counted as in obstacle_min_strength)',
        range=(1, 100000))
    track_confidence_frames: int = param(
        3, 'Obstacle tracks: a tracked obstacle\'s confidence combines its detections in up '
        'to this many of its latest views, 1 - prod(1 - confidence) (evidence accumulated '
        'over frames; the frames of a rig standing still are one view, at its best '
        'detection; 1 = the latest view\'s alone)', range=(1, 100))
    track_coast_s: float = param(
        1.0, 'Obstacle tracks (DGPR): an obstacle detected before is still reported for up to '
        'this long after its last detection, at its tracked place (moved by the camera '
        'motion, or still while the rig stands still), unless the frame shows ground where '
        'it stood; 0 = report detections only, s',
        range=(0.0, 60.0))
    track_gate_chi2: float = param(
        11.34, 'Obstacle tracks: a detection updates a track when their squared Mahalanobis '
        'distance (3 dof) is below this (11.34: chi-square 99 %)', range=(0.1, 1000.0))
    track_process_noise_m: float = param(
        0.05, 'Obstacle tracks: random-walk noise of a tracked foot, m per sqrt(s)',
        range=(0.0, 10.0))
    track_confirm_hits: int = param(
        1, 'Obstacle tracks: frames in which a track must have been detected before it is '
        'reported in frames where it is not', range=(1, 1000))
    track_min_hit_fraction: float = param(
        0.5, 'Obstacle tracks: a track is carried through frames without a detection only '
        'while it was detected in at least this fraction of the frames since it began (M of '
        'N: an obstacle is seen in most frames, ground texture that sometimes passes the '
        'threshold is not)', range=(0.0, 1.0))
    track_sure_hits: int = param(
        3, 'Obstacle tracks: a track detected in at least this many frames is carried '
        'through frames without a detection whatever its hit fraction, for up to '
        'track_coast_s, unless the frame shows ground where it stood (0 = off)',
        range=(0, 100000))
    track_unseen_coast_s: float = param(
        5.0, 'Obstacle tracks: a track detected in at least track_sure_hits frames whose '
        'foot has left the bottom of the image (an obstacle walked up to, nearer than the '
        'ground the camera sees) is still reported, carried by the camera motion, for up '
        'to this long after its last detection, unless a part of its image region still in '
        'view shows ground; it ends once passed (behind the camera, or out to the side), s',
        range=(0.0, 600.0))
    track_motion_hold_frames: int = param(
        2, 'Obstacle tracks: a pair that comes without a motion while the rig moves carries '
        'the tracks by the previous given motion, scaled to the time between the pairs, '
        'its translation uncertain by half its length, for at most this many pairs in a '
        'row (a missed /egomotion must not make the obstacles walked up to forget); '
        '0 = such a pair ends all tracks', range=(0, 100))
    track_position_sigma_m: float = param(
        0.05, 'Obstacle tracks: placement uncertainty of a detected foot added to its '
        'triangulation noise (which corner of the obstacle is nearest), metres',
        range=(0.001, 10.0))
    track_pixel_sigma_px: float = param(
        1.0, 'Obstacle tracks: image position uncertainty of a detected foot, pixels',
        range=(0.01, 100.0))
    track_free_min_features: int = param(
        5, 'Obstacle tracks: a track not detected in a frame ends when its image region '
        'holds at least this many reliably matched edge pixels on the ground plane, where '
        'the obstacle would have stood out above it, and three times as many as above it '
        '(the obstacle went away)', range=(1, 100000))
    track_frame_period_s: float = param(
        0.1, 'Time between frames assumed when process() is given no stamp, s',
        range=(1e-4, 10.0))
    # --- the ground surface ahead (core/ground_surface.py) -------------------------
    surface_enabled: bool = param(
        True, 'Judge obstacles against the ground surface ahead -- the plane continued by '
        'a piecewise-linear height profile along the walking direction, where features '
        'support it (a slope, ramp or crest ahead is ground; a step is not) -- rather than '
        'against the plane alone')
    surface_near_m: float = param(
        2.0, 'surface: the plane alone is the ground up to this distance along the ground, '
        'metres', range=(0.0, 50.0))
    surface_far_m: float = param(
        10.0, 'surface: the profile is fitted out to this distance along the ground, metres',
        range=(0.5, 100.0))
    surface_knot_spacing_m: float = param(
        1.0, 'surface: distance between the knots of the profile, metres',
        range=(0.1, 20.0))
    surface_max_grade_change: float = param(
        0.12, 'surface: largest change of the grade (rise per metre) from one segment to '
        'the next', range=(0.0, 2.0))
    surface_max_step_m: float = param(
        0.04, "surface: largest difference of the median residuals of a segment's near "
        'and far halves, metres (a step inside a segment is not a slope)',
        range=(0.001, 1.0))
    surface_min_width_m: float = param(
        0.8, "surface: least width across the path of a segment's features, metres",
        range=(0.0, 50.0))
    align_vertical: bool = param(
        True, 'Measure the vertical misalignment of the rectified pair from corners matched '
        'between its images (core.alignment) and, where it reaches align_apply_px, resample '
        'the right image onto the left\'s rows before matching: a rig turned off its '
        'calibration by a tenth of a degree parts the rows by half a pixel, which raises '
        'the ground\'s disparity noise and the obstacle threshold')
    align_every_frames: int = param(
        10, 'Once the misalignment is known, measure it in one pair of this many (in every '
        'pair until then)', range=(1, 1000))
    align_apply_px: float = param(
        0.2, 'Resample the right image when the measured misalignment reaches this at an '
        'image side (and is sure), pixels; it stops below half of this',
        range=(0.01, 100.0))
    seed: int = param(0, 'Seed of the random generator of the robust plane fit',
                      range=(0, 2 ** 31 - 1))

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.min_range_m >= self.search_max_range_m:
            raise ValueError(f'GpodConfig.min_range_m = {self.min_range_m} must be less than '
                             f'search_max_range_m = {self.search_max_range_m}')
        if self.part_radius_m > self.cluster_radius_m:
            raise ValueError(f'GpodConfig.part_radius_m = {self.part_radius_m} must not exceed '
                             f'cluster_radius_m = {self.cluster_radius_m}')
        if self.max_range_m > self.search_max_range_m:
            raise ValueError(f'GpodConfig.max_range_m = {self.max_range_m} must not exceed '
                             f'search_max_range_m = {self.search_max_range_m}')
        if self.surface_near_m >= self.surface_far_m:
            raise ValueError(f'GpodConfig.surface_near_m = {self.surface_near_m} must be less '
                             f'than surface_far_m = {self.surface_far_m}')
        if self.threshold_floor_px > self.threshold_ceiling_px:
            raise ValueError(
                f'GpodConfig.threshold_floor_px = {self.threshold_floor_px} must not exceed '
                f'threshold_ceiling_px = {self.threshold_ceiling_px}')
        if self.edge_target_density < self.edge_min_density:
            raise ValueError(
                f'GpodConfig.edge_target_density = {self.edge_target_density} must be at '
                f'least edge_min_density = {self.edge_min_density}')


def surface_config(c: 'GpodConfig') -> GroundSurfaceConfig:
    """The ground surface settings of a GpodConfig (its ``surface_*`` fields)."""
    return GroundSurfaceConfig(enabled=c.surface_enabled, near_m=c.surface_near_m,
                               far_m=c.surface_far_m, knot_spacing_m=c.surface_knot_spacing_m,
                               max_grade_change=c.surface_max_grade_change,
                               max_step_m=c.surface_max_step_m,
                               min_width_m=c.surface_min_width_m)


@dataclass(frozen=True)
class GpodObstacle:
    """One obstacle (or drop-off, with negative height) found in a stereo pair.

    Attributes:
        position: (3,) float64 the obstacle's top (for a drop: the lowest point seen),
            above its nearest foot, metres, left optical frame.
        height: metres above the ground plane (negative for a drop-off).
        range: metres along the ground from the point below the left camera to the foot.
        bearing: radians in the ground plane from the walking direction, positive left.
        width: metres, lateral extent of the feet seen (0 for a single edge string).
        disparity_excess: pixels, measured minus plane disparity, largest in magnitude
            over the obstacle's pixels (negative for a drop-off).
        confidence: 0..1. A detection's: P(any of its pixels truly beyond the threshold)
            * min(1, pixels / ``confidence_full_pixels``), a pixel weaker than
            ``obstacle_min_strength`` counted as (strength / that)^2 of one (as the
            edge-string rule counts it). A reported (tracked) obstacle's:
            1 - prod(1 - c) over its track's latest ``track_confidence_frames`` views, c
            the largest detection confidence in a view (the frames while the rig stands
            still are one view).
        roi: (x, y, w, h) ints, region in the left image (from the top of the obstacle
            down to its foot on the ground).
        num_edge_pixels: matched edge pixels beyond the threshold in the obstacle.
        string_ids: (k,) int32 ids of its edge strings (left EdgeMap); empty when coasted.
        track_id: id of its obstacle track (> 0), 0 if untracked.
        age_s: seconds since it was last detected: 0 when detected in this frame, > 0
            when the track is coasted (reported at its tracked place, see
            ``GpodConfig.track_coast_s``).
    """

    position: np.ndarray
    height: float
    range: float
    bearing: float
    width: float
    disparity_excess: float
    confidence: float
    roi: tuple[int, int, int, int]
    num_edge_pixels: int
    string_ids: np.ndarray
    track_id: int = 0
    age_s: float = 0.0

    @property
    def is_drop(self) -> bool:
        """True for a drop-off (a step down), i.e. negative height."""
        return self.height < 0


@dataclass(frozen=True)
class GpodFeatures:
    """Matched edge features of one frame, for drawing and diagnostics.

    Attributes:
        u_left: (K,) float32 sub-pixel column in the left image, pixels.
        u_right: (K,) float32 sub-pixel column in the right image, pixels.
        v: (K,) int32 row, pixels.
        d: (K,) float32 disparity, pixels.
        excess: (K,) float32 disparity minus plane disparity, pixels (NaN without plane).
        is_obstacle: (K,) bool, pixel beyond the obstacle threshold (counted).
        is_drop: (K,) bool, pixel below the plane by more than the threshold (counted).
        string_class: (K,) int8 class of the pixel's edge string: 1 obstacle, -1 drop,
            0 ground / unclassified.
        string_id: (K,) int32 edge-string id (left EdgeMap).
        strength: (K,) float32 edge strength, grey levels per pixel (None if unknown).
        excess_mean: (K,) float32 the excess averaged over the frames the rig stood still
            (= excess when it moved), pixels, which the threshold test uses (None if
            unknown).
        threshold: (K,) float32 the obstacle threshold of each pixel, pixels (None if
            unknown).
    """

    u_left: np.ndarray
    u_right: np.ndarray
    v: np.ndarray
    d: np.ndarray
    excess: np.ndarray
    is_obstacle: np.ndarray
    is_drop: np.ndarray
    string_class: np.ndarray
    string_id: np.ndarray
    strength: np.ndarray | None = None
    excess_mean: np.ndarray | None = None
    threshold: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.v.shape[0])


@dataclass(frozen=True)
class GpodPlane:
    """The ground plane of one frame, ``d = a*u + b*v + c`` (cyclopean pixels).

    Attributes:
        abc: (3,) float64 (a, b, c).
        cov: (3, 3) float64 covariance of (a, b, c).
        num_features: features used by the last plane fit.
        residual_rms: RMS disparity residual of the last plane fit, pixels.
        metric: the plane in the left optical frame.
        updated: True when the plane was (re)fitted on this frame.
    """

    abc: np.ndarray
    cov: np.ndarray
    num_features: int
    residual_rms: float
    metric: MetricPlane
    updated: bool


@dataclass(frozen=True)
class GpodResult:
    """Everything GPOD found in one stereo pair.

    Attributes:
        status: 'initialising' | 'tracking' | 'lost'.
        frame_index: frames processed since the last reset, counting this one (1-based).
        plane_abc: (3,) float64 plane (a, b, c) used for this frame, or None.
        plane_cov: (3, 3) float64 covariance of plane_abc, or None.
        plane_num_features: features used by the last plane fit (0 if none).
        plane_residual_rms: RMS residual of the last plane fit, pixels (NaN if none).
        plane_updated: True when the plane was (re)fitted on this frame.
        metric_plane: the plane in the left optical frame, or None.
        obstacles: obstacles and drop-offs, nearest first: this frame's detections (their
            feet filtered by their tracks) and the tracks coasted through this frame
            (``age_s`` > 0).
        features: the matched edge features.
        threshold_px: the obstacle threshold used, pixels ('sigma' mode: threshold_k
            times sigma_px within the floor and ceiling; with ``sigma_per_edge`` each
            pixel has its own, see ``features.threshold``).
        num_edges: (left, right) numbers of edge pixels.
        timings_ms: stage -> milliseconds ('edges', 'matching', 'plane', 'obstacles',
            'total'; on images at least ``coarse_min_width`` wide, 'coarse': the binned
            pass).
        sigma_px: robust (MAD) spread of the disparity residuals of the initial ground
            plane fit, pixels (NaN before it).
        still: True when the rig stood still since the previous frame (the excess is
            being averaged over frames).
        detections: this frame's own obstacles and drop-offs, before tracking, nearest
            first (per-frame detection rates are measured on these).
        misalignment_px: the rig's measured vertical misalignment, the largest over the
            image, pixels (NaN before the first measurement; core.alignment).
        misalignment_corrected: True when the right image was resampled to remove it.
        edge_threshold: the edge threshold used for this pair, grey levels per pixel
            (``edge_threshold``, or lower on weakly textured ground: ``edge_min_density``).
        surface: the ground surface ahead the obstacles were judged against
            (``surface_enabled``; its ``known_until_m``: how far the ground is known),
            or None.
    """

    status: str
    frame_index: int
    plane_abc: np.ndarray | None
    plane_cov: np.ndarray | None
    plane_num_features: int
    plane_residual_rms: float
    plane_updated: bool
    metric_plane: MetricPlane | None
    obstacles: tuple[GpodObstacle, ...]
    features: GpodFeatures
    threshold_px: float
    num_edges: tuple[int, int]
    timings_ms: dict[str, float]
    sigma_px: float = float('nan')
    still: bool = False
    detections: tuple[GpodObstacle, ...] = ()
    misalignment_px: float = float('nan')
    misalignment_corrected: bool = False
    edge_threshold: float = float('nan')
    surface: GroundSurface | None = None

    @property
    def plane(self) -> GpodPlane | None:
        """The plane fields as one object, or None when the frame has no plane."""
        if self.plane_abc is None or self.metric_plane is None:
            return None
        return GpodPlane(abc=self.plane_abc, cov=self.plane_cov,
                         num_features=self.plane_num_features,
                         residual_rms=self.plane_residual_rms, metric=self.metric_plane,
                         updated=self.plane_updated)

    @property
    def timings(self) -> dict[str, float]:
        """Alias of ``timings_ms`` (stage -> milliseconds)."""
        return self.timings_ms


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross(a, b)`` of two (3,) float64 vectors, with its arithmetic
    (a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0), without its overhead."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _normal_cdf(x: np.ndarray) -> np.ndarray:
    """Standard normal CDF (Abramowitz & Stegun 7.1.26 erf, |error| < 1.5e-7)."""
    z = np.abs(np.asarray(x, np.float64)) / math.sqrt(2.0)
    t = 1.0 / (1.0 + 0.3275911 * z)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
                                                       + t * (-1.453152027 + t * 1.061405429))))
    erf = 1.0 - poly * np.exp(-z * z)
    return 0.5 * (1.0 + np.sign(x) * erf)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of an undirected graph with n nodes and edges (a, b).

    Returns:
        (n,) int64 label of each node, 0..C-1 in order of first node.
    """
    if a.size <= _PAIRWISE_POINTS:
        # Few edges: union-find in Python (labels as below: by each component's first node).
        parent = list(range(n))

        def root(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for x, y in zip(a.tolist(), b.tolist()):
            rx, ry = root(x), root(y)
            if rx != ry:
                parent[max(rx, ry)] = min(rx, ry)
        out, names = [], {}
        for x in range(n):
            out.append(names.setdefault(root(x), len(names)))
        return np.array(out, np.int64)
    label = np.arange(n, dtype=np.int64)
    if a.size:
        while True:
            la, lb = label[a], label[b]
            m = np.minimum(la, lb)
            new = label.copy()
            np.minimum.at(new, la, m)
            np.minimum.at(new, lb, m)
            while True:                       # pointer jumping to the roots
                nxt = new[new]
                if np.array_equal(nxt, new):
                    break
                new = nxt
            if np.array_equal(new, label):
                break
            label = new
    _, comp = np.unique(label, return_inverse=True)
    return comp.astype(np.int64)


def cluster_points_2d(points: np.ndarray, group: np.ndarray, radius: float) -> np.ndarray:
    """Single-linkage clustering of groups of 2-D points.

    Two groups join when any of their points are within ``radius`` of each other (to
    within ``radius / 4``: points of one group are thinned to one per square of side
    ``radius / 4`` first); the points of one group always stay together.

    Args:
        points: (N, 2) float64 coordinates, metres.
        group: (N,) int group id of each point (e.g. edge string), >= 0.
        radius: linking distance, metres (> 0).
    Returns:
        (N,) int64 cluster label of each point, 0..C-1.
    """
    n = points.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    if _nb_link_groups is not None and _nb_thin is not None:
        # The same groups, thinning and links, compiled (the labels do not depend on the
        # order of the thinned points).
        g, pts, gr, n_g = _nb_thin(np.ascontiguousarray(points, np.float64),
                                   np.asarray(group, np.int64), float(radius) / 4.0)
        if n_g > 0 and pts.shape[0] <= _JIT_PAIRWISE_POINTS:
            return _nb_link_groups(pts, gr, n_g, float(radius) * float(radius))[g]
    _, g = np.unique(group, return_inverse=True)
    g = g.astype(np.int64)
    n_g = int(g.max()) + 1
    # Thin: one point per (group, fine cell).
    fine = np.floor((points - points.min(axis=0)) / (radius / 4.0)).astype(np.int64)
    fkey = (g * (int(fine[:, 0].max()) + 1) + fine[:, 0]) * (int(fine[:, 1].max()) + 1) + fine[:, 1]
    _, rep = np.unique(fkey, return_index=True)
    pts, gr = points[rep], g[rep]
    nr = pts.shape[0]
    if _nb_link_groups is not None and nr <= _JIT_PAIRWISE_POINTS:
        # All pairs, union-find, compiled: the same links and labels as below.
        return _nb_link_groups(pts, gr, n_g, float(radius) * float(radius))[g]
    if nr <= _PAIRWISE_POINTS:
        # Few points: all pairs at once (the same links as the grid search below).
        pi, pj = np.nonzero(gr[:, None] != gr[None, :])
        diff = pts[pi] - pts[pj]
        close = np.einsum('ij,ij->i', diff, diff) <= radius * radius
        a, b = gr[pi[close]], gr[pj[close]]
        if a.size:
            pair = np.unique(a * n_g + b)
            a, b = pair // n_g, pair % n_g
        return _components(n_g, a, b)[g]
    cell = np.floor((pts - pts.min(axis=0)) / radius).astype(np.int64) + 1
    span = int(cell[:, 1].max()) + 3
    key = cell[:, 0] * span + cell[:, 1]
    order = np.argsort(key, kind='stable')
    skey = key[order]
    src, dst = [], []
    for ox, oz in ((0, 0), (1, -1), (1, 0), (1, 1), (0, 1)):
        target = skey + ox * span + oz
        lo = np.searchsorted(skey, target, side='left')
        hi = np.searchsorted(skey, target, side='right')
        cnt = hi - lo
        tot = int(cnt.sum())
        if tot == 0:
            continue
        i = np.repeat(np.arange(nr), cnt)
        j = np.arange(tot) + np.repeat(lo - (np.cumsum(cnt) - cnt), cnt)
        pi, pj = order[i], order[j]
        ok = gr[pi] != gr[pj]
        pi, pj = pi[ok], pj[ok]
        diff = pts[pi] - pts[pj]
        close = np.einsum('ij,ij->i', diff, diff) <= radius * radius
        src.append(gr[pi[close]])
        dst.append(gr[pj[close]])
    a = np.concatenate(src) if src else np.zeros(0, np.int64)
    b = np.concatenate(dst) if dst else np.zeros(0, np.int64)
    if a.size:
        pair = np.unique(a * n_g + b)
        a, b = pair // n_g, pair % n_g
    return _components(n_g, a, b)[g]


def _thin_kernel(points, group, cell):
    """The groups and thinning of :func:`cluster_points_2d` (for numba): (N,) int64 the
    rank of each point's group among the distinct groups, the thinned points (nr, 2) and
    their groups (nr,) -- the first point of each (group, cell), cells of side ``cell``
    from the points' minimum, in the order of the cell keys (counting sorts by group,
    column and row) -- and the number of groups (-1, nothing thinned, when the points
    span more than ``_THIN_MAX_CELLS`` cells across: the numpy path thins them)."""
    n = points.shape[0]
    g_lo, g_hi = group[0], group[0]
    for i in range(n):
        g_lo, g_hi = min(g_lo, group[i]), max(g_hi, group[i])
    gk = np.empty(n, np.int64)
    for i in range(n):
        gk[i] = group[i] - g_lo
    order = _nb_stable_order(gk, np.arange(n), g_hi - g_lo + 1)
    g = np.empty(n, np.int64)
    n_g = 0
    for t in range(n):
        i = order[t]
        if t > 0 and group[i] != group[order[t - 1]]:
            n_g += 1
        g[i] = n_g
    n_g += 1
    lo0, lo1 = points[0, 0], points[0, 1]
    for i in range(1, n):
        lo0, lo1 = min(lo0, points[i, 0]), min(lo1, points[i, 1])
    f0 = np.empty(n, np.int64)
    f1 = np.empty(n, np.int64)
    m0, m1 = 0, 0
    for i in range(n):
        f0[i] = np.int64(math.floor((points[i, 0] - lo0) / cell))
        f1[i] = np.int64(math.floor((points[i, 1] - lo1) / cell))
        m0, m1 = max(m0, f0[i]), max(m1, f1[i])
    if m0 + m1 > _THIN_MAX_CELLS:           # points too far apart to count cells: numpy
        return g, np.empty((0, 2)), np.empty(0, np.int64), -1
    key = np.empty(n, np.int64)
    for i in range(n):
        key[i] = (g[i] * (m0 + 1) + f0[i]) * (m1 + 1) + f1[i]
    # stably by the key, i.e. by (group, f0, f1): the first of equal keys first
    ko = _nb_stable_order(g, _nb_stable_order(f0, _nb_stable_order(f1, np.arange(n), m1 + 1),
                                              m0 + 1), n_g)
    nr = 0
    for t in range(n):
        if t == 0 or key[ko[t]] != key[ko[t - 1]]:
            nr += 1
    pts = np.empty((nr, 2))
    gr = np.empty(nr, np.int64)
    nr = 0
    for t in range(n):
        i = ko[t]
        if t == 0 or key[i] != key[ko[t - 1]]:
            pts[nr, 0], pts[nr, 1] = points[i, 0], points[i, 1]
            gr[nr] = g[i]
            nr += 1
    return g, pts, gr, n_g


_nb_thin = _jit(_thin_kernel)


def _link_groups_kernel(pts, gr, n_g, r2):
    """The links and components of :func:`cluster_points_2d` (for numba), all pairs of
    the thinned points ``pts`` (nr, 2) of groups ``gr`` (nr,): (n_g,) int64 label of
    each group, 0..C-1 in order of each component's first group (as `_components`)."""
    parent = np.arange(n_g)
    nr = pts.shape[0]
    for i in range(nr):
        gi = gr[i]
        for j in range(i + 1, nr):
            gj = gr[j]
            if gj == gi:
                continue
            dx = pts[i, 0] - pts[j, 0]
            dy = pts[i, 1] - pts[j, 1]
            if dx * dx + dy * dy <= r2:
                x = gi
                while parent[x] != x:
                    parent[x] = parent[parent[x]]
                    x = parent[x]
                y = gj
                while parent[y] != y:
                    parent[y] = parent[parent[y]]
                    y = parent[y]
                if x != y:
                    if x < y:
                        parent[y] = x
                    else:
                        parent[x] = y
    label = np.empty(n_g, np.int64)
    name = np.full(n_g, -1, np.int64)
    n_c = 0
    for x in range(n_g):
        r = x
        while parent[r] != r:
            r = parent[r]
        if name[r] < 0:
            name[r] = n_c
            n_c += 1
        label[x] = name[r]
    return label


_nb_link_groups = _jit(_link_groups_kernel)


def run_links(edges: EdgeMap, m: Matches, tolerance_px: float) -> np.ndarray:
    """The previous match in the same matched run of each match.

    A run is a maximal chain of matches on consecutive pixels of one edge string (rows
    v, v+1, ...) whose disparities differ by at most ``tolerance_px`` from one pixel to
    the next.

    Args:
        edges: the left EdgeMap the matches index (for ``string_prev``).
        m: the matches.
        tolerance_px: largest disparity step within a run, pixels.
    Returns:
        (K,) int64 index of the match one row up in the same run, -1 at a run's top.
    """
    k = len(m)
    if k == 0:
        return np.zeros(0, np.int64)
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    prev_edge = edges.string_prev[m.left_index]
    prev = np.where(prev_edge >= 0, feat_of_edge[np.maximum(prev_edge, 0)], -1)
    d = m.d
    link = (prev >= 0) & (np.abs(d - d[np.maximum(prev, 0)]) <= tolerance_px)
    return np.where(link, prev, -1)


def _runs_kernel(string_prev, left_index, d, n_edges, tol, window, x):
    """`run_links`, `matched_run_length` and `smooth_along_runs` of the matches (for
    numba), with their tests and order of summation.

    Args:
        string_prev: (E,) int32 the left EdgeMap's ``string_prev``; left_index (K,) int32,
            d (K,) float32 the matches' left edges and disparities; n_edges: E.
        tol: float32 largest disparity step within a run, pixels.
        window: smoothing window, pixels; x (K,) float64 the values smoothed.
    Returns:
        prev (K,) int64 the match one row up in the same run (-1 at a run's top); run
        (K,) int64 its run's length; smooth (K,) float64 the mean of x over up to
        ``window // 2`` pixels of the run on either side (in the order: itself, up, down);
        nxt (K,) int64 the match one row down (-1 at a run's bottom).
    """
    k = left_index.shape[0]
    feat_of_edge = np.full(n_edges, -1, np.int64)
    for i in range(k):
        feat_of_edge[left_index[i]] = i
    prev = np.full(k, -1, np.int64)
    for i in range(k):
        pe = string_prev[left_index[i]]
        if pe >= 0:
            p = feat_of_edge[pe]
            if p >= 0 and abs(d[i] - d[p]) <= tol:
                prev[i] = p
    nxt = np.full(k, -1, np.int64)
    for i in range(k):
        if prev[i] >= 0:
            nxt[prev[i]] = i
    # run lengths: the matches per run top
    root = np.empty(k, np.int64)
    for i in range(k):
        p = prev[i]
        if p < 0:
            root[i] = i
        elif p < i:
            root[i] = root[p]
        else:
            r = p
            while prev[r] >= 0:
                r = prev[r]
            root[i] = r
    size = np.zeros(k, np.int64)
    for i in range(k):
        size[root[i]] += 1
    run = np.empty(k, np.int64)
    for i in range(k):
        run[i] = size[root[i]]
    half = max(window, 1) // 2
    smooth = x.copy()
    if half > 0:
        for i in range(k):
            total, count = x[i], 1.0
            c = i
            for _ in range(half):
                c = prev[c] if c >= 0 else -1
                total += x[c] if c >= 0 else 0.0
                count += 1.0 if c >= 0 else 0.0
            c = i
            for _ in range(half):
                c = nxt[c] if c >= 0 else -1
                total += x[c] if c >= 0 else 0.0
                count += 1.0 if c >= 0 else 0.0
            smooth[i] = total / count
    return prev, run, smooth, nxt


_nb_runs = _jit(_runs_kernel)


def occluded_matches(right: EdgeMap, m: Matches, gradient_limit: float,
                     trusted: np.ndarray | None = None, neighbours: int = 16) -> np.ndarray:
    """Matches hidden in the right image behind a nearer surface (half-occlusion).

    A right edge string is one continuous curve in the right image. When it is matched,
    at nearby rows, to left edges whose disparities differ more than a continuous
    surface allows (disparity gradient ``|dd| / cyclopean distance`` above
    ``gradient_limit``, PMF's limit), the two cannot both be right: the nearer surface
    (larger disparity) is what the right camera sees along that edge, and the farther
    match is a left-image edge whose true partner is hidden behind it (typically the
    ground just left of a post, matched to the post's silhouette in the right image).
    The test is scale-free (a disparity gradient), so it holds at any focal length.
    Only a trusted nearer match (e.g. one in a matched run: figural continuity) hides
    another; an isolated mismatch of large disparity hides nothing.

    Args:
        right: the right EdgeMap the matches index (for ``string_id``).
        m: the matches.
        gradient_limit: largest disparity gradient along one surface.
        trusted: (K,) bool, the matches that may hide others (default all).
        neighbours: matches of the same right string compared on either side (in row
            order).
    Returns:
        (K,) bool, True for a match of the farther surface of such a pair.
    """
    k = len(m)
    occ = np.zeros(k, bool)
    if k < 2:
        return occ
    tr = np.ones(k, bool) if trusted is None else np.asarray(trusted, bool)
    if _nb_occluded_all is not None:
        # The same selection, order and pair tests, compiled (one pass).
        return _nb_occluded_all(right.string_id, m.right_index, np.ascontiguousarray(tr),
                                m.v, m.d, m.u_left, m.u_right, float(gradient_limit),
                                int(neighbours))
    rs = right.string_id[m.right_index].astype(np.int64)
    if not tr.any():
        return occ
    # only the right strings with a trusted match can hide anything
    has = np.zeros(int(rs.max()) + 1, bool)
    has[rs[tr]] = True
    sub = np.nonzero(has[rs])[0]
    order = sub[np.lexsort((m.v[sub], rs[sub]))]
    n = order.size
    rs_o = rs[order]
    tr_o = tr[order]
    d_o = m.d[order].astype(np.float64)
    u_o = 0.5 * (m.u_left[order].astype(np.float64) + m.u_right[order])
    v_o = m.v[order].astype(np.float64)
    if _nb_occluded is not None:
        occ[order[_nb_occluded(rs_o, tr_o, d_o, u_o, v_o, float(gradient_limit),
                               min(neighbours, n - 1))]] = True
        return occ
    for s in range(1, min(neighbours, n - 1) + 1):
        same = rs_o[s:] == rs_o[:-s]
        dd = d_o[s:] - d_o[:-s]
        dist = np.hypot(u_o[s:] - u_o[:-s], v_o[s:] - v_o[:-s])
        # the nearer of the pair (larger disparity) must be trusted
        near_ok = np.where(dd > 0, tr_o[s:], tr_o[:-s])
        bad = same & near_ok & (np.abs(dd) > gradient_limit * np.maximum(dist, 1.0))
        if not bad.any():
            continue
        i = np.nonzero(bad)[0]
        far = np.where(dd[i] > 0, i, i + s)       # the smaller disparity of the pair
        occ[order[far]] = True
    return occ


def _occluded_kernel(rs_o, tr_o, d_o, u_o, v_o, gradient_limit, neighbours):
    """The pair loop of :func:`occluded_matches` (for numba), same tests: (n,) bool,
    the farther match of each offending pair, in the sorted order."""
    n = rs_o.shape[0]
    far = np.zeros(n, np.bool_)
    for s in range(1, neighbours + 1):
        for i in range(n - s):
            j = i + s
            if rs_o[j] != rs_o[i]:
                continue
            dd = d_o[j] - d_o[i]
            if not (tr_o[j] if dd > 0 else tr_o[i]):
                continue
            if gradient_limit > 0 and abs(dd) <= gradient_limit:
                continue        # within limit * max(dist, 1) >= limit, whatever dist
            dist = math.hypot(u_o[j] - u_o[i], v_o[j] - v_o[i])
            if abs(dd) > gradient_limit * max(dist, 1.0):
                far[i if dd > 0 else j] = True
    return far


def _stable_order(key, rows, n_keys):
    """``rows[np.argsort(key[rows], kind='stable')]`` for int keys 0..n_keys-1 (for
    numba): a counting sort."""
    count = np.zeros(n_keys + 1, np.int64)
    for r in rows:
        count[key[r] + 1] += 1
    for q in range(n_keys):
        count[q + 1] += count[q]
    out = np.empty(rows.shape[0], np.int64)
    for r in rows:
        out[count[key[r]]] = r
        count[key[r]] += 1
    return out


def _occluded_all_kernel(r_string, right_index, tr, v, d, u_left, u_right, gradient_limit,
                         neighbours):
    """`occluded_matches` (for numba): the matches of the right strings with a trusted
    match, in the order of ``np.lexsort((v, right string))``, the same coordinates
    (float64 d, cyclopean u, v) and `_occluded_kernel`'s pair tests; (K,) bool."""
    k = right_index.shape[0]
    occ = np.zeros(k, np.bool_)
    if k < 2:
        return occ
    rs = np.empty(k, np.int64)
    n_rs, n_v, any_tr = 0, 0, False
    for i in range(k):
        rs[i] = r_string[right_index[i]]
        n_rs = max(n_rs, rs[i] + 1)
        n_v = max(n_v, np.int64(v[i]) + 1)
        any_tr = any_tr or tr[i]
    if not any_tr:
        return occ
    has = np.zeros(n_rs, np.bool_)
    for i in range(k):
        if tr[i]:
            has[rs[i]] = True
    n = 0
    for i in range(k):
        n += has[rs[i]]
    sub = np.empty(n, np.int64)
    n = 0
    for i in range(k):
        if has[rs[i]]:
            sub[n] = i
            n += 1
    vk = np.empty(k, np.int64)
    for i in range(k):
        vk[i] = v[i]
    order = _nb_stable_order(rs, _nb_stable_order(vk, sub, n_v), n_rs)
    rs_o = np.empty(n, np.int64)
    tr_o = np.empty(n, np.bool_)
    d_o = np.empty(n)
    u_o = np.empty(n)
    v_o = np.empty(n)
    for t in range(n):
        i = order[t]
        rs_o[t], tr_o[t], d_o[t] = rs[i], tr[i], np.float64(d[i])
        u_o[t] = 0.5 * (np.float64(u_left[i]) + np.float64(u_right[i]))
        v_o[t] = np.float64(v[i])
    far = _nb_occluded(rs_o, tr_o, d_o, u_o, v_o, gradient_limit, min(neighbours, n - 1))
    for t in range(n):
        if far[t]:
            occ[order[t]] = True
    return occ


_nb_occluded = _jit(_occluded_kernel)
_nb_stable_order = _jit(_stable_order)
_nb_occluded_all = _jit(_occluded_all_kernel)
_warm = False


def _warm_up() -> None:
    """Compile the numba kernels once per process (see `matching.warm_up`), before the
    first frame; falls back to the numpy paths if numba is missing or fails."""
    global _warm, _nb_occluded, _nb_hanging, _nb_link_groups, _nb_corner_free, _nb_contact, \
        _nb_walk_down, _nb_extremes, _nb_soft_args, _nb_arcs, _nb_contact_bounds, _nb_owners, \
        _nb_group_quantile, _nb_extent, _nb_runs, _nb_occluded_all, _nb_hanging_all, \
        _nb_on_ground, _nb_still, _nb_temporal, _nb_thin, _nb_outline
    if _warm:
        return
    _warm = True
    edges_warm_up()
    if not matching_warm_up() or _nb_occluded is None:
        _nb_occluded = _nb_hanging = _nb_link_groups = _nb_corner_free = _nb_contact = None
        _nb_walk_down = _nb_extremes = _nb_soft_args = _nb_arcs = _nb_contact_bounds = None
        _nb_owners = _nb_group_quantile = _nb_extent = _nb_runs = _nb_occluded_all = None
        _nb_hanging_all = _nb_on_ground = _nb_still = _nb_temporal = _nb_thin = None
        _nb_outline = None
        return
    f2, f1, i1 = np.zeros((1, 2)), np.zeros(1), np.zeros(1, np.int64)
    _nb_corner_free = _warmed(_nb_corner_free, f2, f2, f2, f2, f1 + 1.0, np.zeros((1, 1, 2)),
                               0.05)
    _nb_contact = _warmed(_nb_contact, f1, f1, f1, f1, f2[:, :1], f2[:, :1],
                          np.ones((1, 1), bool), i1, i1 + 1, i1, i1 + 1, 0, 0,
                          np.zeros((1, 1), np.float32), np.zeros((1, 1), np.float32))
    _nb_walk_down = _warmed(_nb_walk_down, i1, i1 - 1, f1, f1, 2.0, 1)
    _nb_arcs = _warmed(_nb_arcs, f2, f2, f1)
    _nb_group_quantile = _warmed(_nb_group_quantile, i1, f1, 0.5, 1)
    v1, u1 = np.zeros(1, np.int32), np.zeros(1, np.float32)
    _nb_still = _warmed(_nb_still, np.zeros((1, 3), bool), True, v1, v1, 1, 1)
    _nb_temporal = _warmed(_nb_temporal, v1, u1, f1, f1, True, 0.5, 0.75, 0.8, True,
                           np.zeros((1, 1), np.float32), np.ones((1, 1), np.float32), 1, 1)
    _nb_on_ground = _warmed(_nb_on_ground, i1, i1, f1, np.zeros(1, np.float32),
                            np.zeros(1, np.int32), np.zeros(1, np.float32), np.zeros(3), 1.0, 1)
    _nb_runs = _warmed(_nb_runs, np.full(1, -1, np.int32), np.zeros(1, np.int32),
                       np.zeros(1, np.float32), 1, np.float32(1.0), 5, f1)
    _nb_extent = _warmed(_nb_extent, i1, 1, f2, f1, f1, f1 + 1.0, f1,
                         np.zeros(1, np.float32), np.zeros(1, np.int32), np.zeros(1, np.int32),
                         True)
    _nb_owners = _warmed(_nb_owners, f2, f1, np.zeros((2, 2)), np.zeros(2, np.int64), f1 + 1.0,
                         0.5, 1.2, f1, np.zeros(2), f1, np.zeros(2), f2)
    _nb_contact_bounds = _warmed(_nb_contact_bounds, f1, f1, f1, f1, f2[:, :1], f2[:, :1],
                                 np.ones((1, 1), bool), 2, 2)
    _nb_link_groups = _warmed(_nb_link_groups, np.zeros((2, 2)), np.arange(2), 2, 1.0)
    _nb_thin = _warmed(_nb_thin, np.zeros((2, 2)), np.arange(2), 0.1)
    g32 = np.zeros((2, 2), np.float32)
    _nb_outline = _warmed(_nb_outline, np.ones((1, 2, 2)), np.zeros(3), np.zeros(3),
                          np.zeros(3), np.zeros(3), 0.1, 300.0, 1.0, 1.0, g32, g32, 0, 0,
                          2, 2)
    z, i = np.zeros(2), np.zeros(1, np.int64)
    _nb_occluded = _warmed(_nb_occluded, np.zeros(2, np.int64), np.ones(2, bool), z, z, z,
                           1.0, 1)
    i32, f32 = np.zeros(2, np.int32), np.zeros(2, np.float32)
    _nb_occluded_all = (None if _nb_occluded is None else _warmed(
        _nb_occluded_all, i32, i32, np.ones(2, bool), i32, f32, f32, f32, 1.0, 16))
    _nb_hanging = _warmed(_nb_hanging, i, i, np.zeros(1), i - 1, i, i - 1, 1, 2, 1.0, 0.1,
                          np.ones(1, bool))
    _nb_hanging_all = (None if _nb_hanging is None else _warmed(
        _nb_hanging_all, np.full(1, -1, np.int32), np.zeros(1, np.int32),
        np.zeros(1, np.int32), np.zeros(1, np.float32), i - 1, np.ones(1), 0.5, True,
        np.ones(1, bool), 32, 1.0, 0.1, np.ones(1, bool)))
    # The soft nearest points (four kernels, one switch) and the per-obstacle extremes.
    one = np.ones(1, bool)
    soft = _warmed(_nb_soft_args, f2, f1 + 1.0, i1, one, 1, 2.0)
    if soft is not None:
        idx, start, near, arg = soft(f2, f1 + 1.0, i1, one, 1, 2.0)
        ok = (_warmed(_nb_soft_far, f2, idx, start, near, f1 + 1.0) is not None
              and _warmed(_nb_soft_finish, f2, idx, start, near, f1 + 1.0, one, f2)
              is not None)
        soft = soft if ok else None
    _nb_soft_args = soft
    _nb_extremes = _warmed(_nb_extremes, i1, 1, f1, f1) if soft is not None else None


def matched_run_length(edges: EdgeMap, m: Matches, tolerance_px: float,
                       prev: np.ndarray | None = None) -> np.ndarray:
    """Length of the disparity-consistent matched run (see :func:`run_links`) that each
    match belongs to.

    Args:
        edges: the left EdgeMap the matches index (for ``string_prev``).
        m: the matches.
        tolerance_px: largest disparity step within a run, pixels.
        prev: :func:`run_links` of the matches, if already known.
    Returns:
        (K,) int64 run length (>= 1) of each match.
    """
    k = len(m)
    if k == 0:
        return np.zeros(0, np.int64)
    if prev is None:
        prev = run_links(edges, m, tolerance_px)
    root = chain_roots(prev)
    return np.bincount(root, minlength=k)[root]


#: Along an edge string, this many successive matched pixels on the ground (within the
#: threshold) separate its obstacle pixels into pieces, each judged on its own
#: (`string_pieces`).
_GROUND_BREAK_PX = 5


def string_pieces(sid: np.ndarray, v: np.ndarray, ground: np.ndarray,
                  min_break: int = _GROUND_BREAK_PX) -> np.ndarray:
    """Cut edge strings where they run along the ground.

    An edge string can pass from an obstacle onto the ground and on (a post's edge in
    line with a tile joint below it): pixels of it that stand out far below the obstacle,
    beyond a stretch of matched pixels on the ground, belong to something else (often a
    single noisy pixel), not to the obstacle whose string it is. Each string (pixels in
    row order) is cut at every run of at least ``min_break`` successive ``ground`` pixels.

    Args:
        sid: (N,) int edge-string id of each matched pixel.
        v: (N,) int image row of each pixel.
        ground: (N,) bool, the pixel is reliably matched on the ground plane.
        min_break: shortest run of ground pixels that cuts a string.
    Returns:
        (N,) int64 piece index of each pixel (pieces never span two strings).
    """
    n = sid.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort((v, sid))
    s_o, g_o = sid[order], ground[order]
    new_string = np.concatenate((_TRUE, s_o[1:] != s_o[:-1]))
    change = new_string | np.concatenate((_TRUE, g_o[1:] != g_o[:-1]))
    run_id = np.cumsum(change) - 1
    long_ground = g_o & (np.bincount(run_id)[run_id] >= min_break)
    piece_o = np.cumsum(new_string | (long_ground & change)) - 1
    piece = np.empty(n, np.int64)
    piece[order] = piece_o
    return piece


def hanging_runs(edges: EdgeMap, m: Matches, prev: np.ndarray, h: np.ndarray,
                 max_height: float, tolerance_px: float, slope: float,
                 only: np.ndarray | None = None, max_gap: int = 32,
                 solid: np.ndarray | None = None) -> np.ndarray:
    """Matches in runs that hang in the air over another depth: the run's lowest pixel is
    more than ``max_height`` metres above the ground, and the same edge string goes on
    below it (matched pixels within ``max_gap`` rows) but never at the run's disparity
    (within ``tolerance_px`` + ``slope`` px per row of the gap). On a
    repetitive texture a stretch of an edge matched a period off is such a run: a
    wall's vertical streaks 8 m away, matched 43 px off for 12 rows, made an obstacle
    "1.9 m away" out of a string whose other runs stand on the wall's foot. An edge of a
    real obstacle broken by a texture change goes on below at its own depth.

    Args:
        edges: the left EdgeMap the matches index; m: the matches.
        prev: :func:`run_links` of the matches.
        h: (K,) height of each match above the ground plane, metres.
        max_height: metres (``GpodConfig.max_floating_height_m``).
        tolerance_px: largest disparity step within a run, pixels.
        slope: |b| of the plane, pixels of disparity per row.
        only: (K,) bool, or None: only the runs of edge strings with such a match are
            tested (the obstacle pixels: the rest cannot matter).
        max_gap: rows searched below a run's bottom.
        solid: (K,) bool, or None (every match): the matches that can hold a run up. A
            stray match or two at the run's depth below it is as likely a mismatch the
            same period off as the run: only a matched run of its own (figural
            continuity, ``min_matched_run``) holds it up. A wall's streak matched 7 px off
            for 11 rows, 5 m away, was held up by two pixels matched alike 25 rows below.
    Returns:
        (K,) bool.
    """
    k = len(m)
    out = np.zeros(k, bool)
    if k == 0:
        return out
    solid = np.ones(k, bool) if solid is None else np.asarray(solid, bool)
    if _nb_hanging_all is not None:
        # The same run bottoms and walk, compiled (one pass).
        return _nb_hanging_all(edges.string_prev, m.left_index, m.string_id, m.d,
                               np.asarray(prev, np.int64), np.asarray(h, np.float64),
                               float(max_height), only is not None,
                               np.zeros(k, bool) if only is None else np.asarray(only, bool),
                               int(max_gap), float(tolerance_px), float(slope), solid)
    is_prev = np.zeros(k, bool)
    is_prev[prev[prev >= 0]] = True
    cand = ~is_prev & (h > max_height)                        # floating run bottoms
    if only is not None:
        # ... of edge strings with a match of ``only``.
        sid = m.string_id
        has = np.zeros(int(sid.max()) + 1 if k else 0, bool)
        has[sid[only]] = True
        cand &= has[sid]
    bottom = np.flatnonzero(cand)
    if bottom.size == 0:
        return out
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    below = np.full(len(edges), -1, np.int64)
    has = edges.string_prev >= 0
    below[edges.string_prev[has]] = np.flatnonzero(has)
    if _nb_hanging is not None:
        return _nb_hanging(bottom, m.left_index.astype(np.int64), m.d.astype(np.float64),
                           below, feat_of_edge, prev.astype(np.int64), k, int(max_gap),
                           float(tolerance_px), float(slope), solid)
    d0 = m.d[bottom].astype(np.float64)
    # A run held up only by a run that hangs itself hangs too (two stretches matched
    # the same period off, one above the other, or a chain of them down an edge that
    # alternates between two matches): repeat until nothing changes. Each pass can only
    # add runs, so at most one pass per run bottom (and one to see no change).
    for _ in range(bottom.size + 1):
        e = m.left_index[bottom].astype(np.int64)
        seen = np.zeros(bottom.size, bool)      # a matched pixel below
        held = np.zeros(bottom.size, bool)      # ... at the run's depth, not hanging
        for r in range(1, max_gap + 1):
            live = ~held & (e >= 0)
            if not live.any():
                break
            e = np.where(live, below[np.maximum(e, 0)], -1)
            f = np.where(e >= 0, feat_of_edge[np.maximum(e, 0)], -1)
            hit = f >= 0
            seen |= hit
            fh = f[hit]
            held[hit] |= ((np.abs(m.d[fh] - d0[hit]) <= tolerance_px + slope * r)
                          & solid[fh] & ~out[fh])
        hang = seen & ~held
        new = np.zeros(k, bool)
        cur = bottom[hang]                      # whole runs, from the bottom up
        while cur.size:
            new[cur] = True
            cur = prev[cur]
            cur = cur[cur >= 0]
        if np.array_equal(new, out):
            break
        out = new
    return out


def _robust_row_slope(u: np.ndarray, v: np.ndarray, d: np.ndarray) -> float:
    """The slope b of ``d = a u + b v + c`` (pixels of disparity per image row) fitted to
    features (u, v, d: (N,) pixels, N >= 3) by least squares trimmed twice to the
    residuals within 2.5 robust sigmas (at least 0.5 px): the mismatches among a
    frame's features (any disparity, anywhere) flatten a plain least-squares slope."""
    a = np.column_stack((u, v, np.ones_like(u)))
    coef = np.linalg.lstsq(a, d, rcond=None)[0]
    for _ in range(2):
        r = d - a @ coef
        dev = np.abs(r - _median(r))
        keep = dev <= max(2.5 * 1.4826 * _median(dev), 0.5)
        if keep.sum() < 3:
            break
        coef = np.linalg.lstsq(a[keep], d[keep], rcond=None)[0]
    return float(coef[1])


def floating_bottom_runs(sid: np.ndarray, v: np.ndarray, prev: np.ndarray, h: np.ndarray,
                         ok: np.ndarray, max_height: float, only: np.ndarray) -> np.ndarray:
    """Matches in the lowest matched run of their edge string when that run floats: its
    lowest usable pixel more than ``max_height`` metres above the ground, while the
    string stands on the ground elsewhere (a usable pixel within ``max_height``). The
    string-wide test (`GpodConfig.max_floating_height_m`) let such a run through: a
    stretch of a far wall's streak matched 58 px off for 10 rows, at the bottom of a
    string whose upper pixels lie on the wall 9 m away, made an obstacle "1.5 metres
    ahead" floating 1 m high. Nothing of its string below it holds it up (that is
    `hanging_runs`'s case), and what stands on the ground lies above it in the image:
    farther, another surface.

    Args:
        sid: (K,) edge string of each match; v: (K,) its image row.
        prev: :func:`run_links` of the matches (the next pixel up the run, -1 at a top).
        h: (K,) height above the ground plane, metres.
        ok: (K,) bool, the usable matches (reliably matched, in range).
        max_height: metres.
        only: (K,) bool: only strings with such a match are tested (obstacle pixels).
    Returns:
        (K,) bool.
    """
    k = sid.shape[0]
    out = np.zeros(k, bool)
    cand = only & (h > max_height)
    if not cand.any():
        return out
    # the strings with a floating tested match, and their matches (runs stay within a
    # string, so the run links stay within the selection)
    has = np.zeros(int(sid.max()) + 1, bool)
    has[sid[cand]] = True
    sel = np.flatnonzero(has[sid])
    pos = np.full(k, -1, np.int64)
    pos[sel] = np.arange(sel.size)
    p = prev[sel]
    # run label: the top pixel of each run (pointer jumping up the prev links)
    lab = np.where(p >= 0, pos[np.maximum(p, 0)], np.arange(sel.size))
    while True:
        nxt = lab[lab]
        if np.array_equal(nxt, lab):
            break
        lab = nxt
    s_sid, s_v, s_h, s_ok = sid[sel], v[sel], h[sel], ok[sel]
    idx = np.flatnonzero(s_ok)
    if idx.size == 0:
        return out
    # each string's lowest usable pixel (largest row) and the run it is in
    order = idx[np.lexsort((-s_v[idx], s_sid[idx]))]
    first = np.concatenate((_TRUE, s_sid[order][1:] != s_sid[order][:-1]))
    bottom_run = np.full(has.size, -1, np.int64)
    bottom_run[s_sid[order][first]] = lab[order][first]
    run_low = np.full(sel.size, np.inf)
    np.minimum.at(run_low, lab[idx], s_h[idx])
    grounded = np.zeros(has.size, bool)
    grounded[s_sid[idx][s_h[idx] <= max_height]] = True
    out[sel] = ((lab == bottom_run[s_sid]) & (run_low[lab] > max_height)
                & grounded[s_sid])
    return out


def continuation_alternatives(edges: EdgeMap, m: Matches, prev: np.ndarray,
                              cand: Candidates, select: np.ndarray, lower: np.ndarray,
                              plane_d: np.ndarray, tolerance_px: float, slope: float,
                              min_support: int, max_gap: int = 32) -> np.ndarray:
    """Matches of ``select`` in runs that hang over nothing at their depth, whose own
    edge string goes on on lower ground (a match of ``lower``: below the run, or above it
    where the run ends the string), and whose left edge also had a candidate match on
    that lower ground.

    An obstacle stands on the ground: below the foot of its edge the image shows nearer
    ground, never a lower ground farther away on the same edge line. A run of a string
    seen in front of its own continuation on the lower ground beyond a drop, that could
    equally have been matched on that lower ground, is a stretch of a repetitive pattern
    matched one period off: the paving joints beyond a kerb down, matched one joint
    spacing off for 10 rows, 43-54 px above the plane (an obstacle "0.9 m" away). The
    ambiguity test's ground-plane alternative cannot see it: the true depth is below the
    plane.

    Args:
        edges: the left EdgeMap the matches index; m: the matches; cand: the frame's
            candidate matches (of the same left EdgeMap).
        prev: :func:`run_links` of the matches.
        select: (K,) bool: the matches tested (the rest are False).
        lower: (K,) bool: matches on lower ground (below the plane by more than the
            threshold, within the deepest drop looked for).
        plane_d: (K,) float: the plane's disparity at each match, pixels.
        tolerance_px: largest disparity step within a run, pixels.
        slope: |b| of the plane, pixels of disparity per row.
        min_support: the lower ground must be seen: at least this many ``lower``
            matches lie on it (within ``tolerance_px``). Beyond a kerb down they are
            15-70 % of a frame's matches; scattered mismatches of obstacles' textures
            that look like a ground 0.7-1.2 m down, at most 1.4 % (`_LOWER_GROUND_FRACTION`).
        max_gap: rows searched below a run's bottom.
    Returns:
        (K,) bool. The run must hang: no matched pixel of its string within ``max_gap``
        rows below its bottom is at its depth (within ``tolerance_px + slope * r``, r
        rows down; an edge of a real obstacle broken by a mismatch goes on below at its
        own depth). The continuation is the string's first ``lower`` match there, or,
        where it has none there, its nearest ``lower`` match within ``max_gap`` rows
        above the run (a run that ends its string at a kerb's brink). The lower ground
        is taken parallel to the plane (its disparity a fixed fraction,
        the continuation's d / plane_d, of the plane's), and a match of the run has the
        alternative when one of its candidates lies within ``tolerance_px`` of that
        ground's disparity at it.
    """
    k = len(m)
    out = np.zeros(k, bool)
    sel = np.flatnonzero(select)
    if sel.size == 0 or len(cand) == 0 or np.count_nonzero(lower) < min_support:
        return out
    # The bottom of each match's run.
    nxt = np.full(k, -1, np.int64)
    has = prev >= 0
    nxt[prev[has]] = np.flatnonzero(has)
    jump = chain_roots(nxt)
    bottoms, b_of = np.unique(jump[sel], return_inverse=True)
    feat_of_edge = np.full(len(edges), -1, np.int64)
    feat_of_edge[m.left_index] = np.arange(k)
    below = np.full(len(edges), -1, np.int64)
    has_e = edges.string_prev >= 0
    below[edges.string_prev[has_e]] = np.flatnonzero(has_e)
    # The matched pixels of each bottom's string in the max_gap rows below it.
    nb = bottoms.size
    under = np.full((max_gap, nb), -1, np.int64)
    e = m.left_index[bottoms].astype(np.int64)
    for r in range(max_gap):
        e = np.where(e >= 0, below[np.maximum(e, 0)], -1)
        if not (e >= 0).any():
            under = under[:r]
            break
        under[r] = np.where(e >= 0, feat_of_edge[np.maximum(e, 0)], -1)
    d = m.d.astype(np.float64)
    pd = np.asarray(plane_d, np.float64)
    d0 = d[bottoms]
    # The continuation: the first lower match below. (It is farther than the bottom
    # wherever the run hangs: a lower match nearer than the bottom is within the slope
    # allowance of its depth, below, and holds the run up.) Where the string has none
    # below (the run ends it, at a kerb's brink), the nearest lower match above the run.
    is_low = (under >= 0) & lower[np.maximum(under, 0)]
    ok = is_low.any(axis=0)
    found = np.full(nb, -1, np.int64)
    if ok.any():
        found[ok] = under[np.argmax(is_low[:, ok], axis=0), np.flatnonzero(ok)]
    if not ok.all():
        top = chain_roots(prev)                 # each run's top
        miss = np.flatnonzero(~ok)
        e = m.left_index[top[bottoms[miss]]].astype(np.int64)
        for _ in range(max_gap):
            live = (found[miss] < 0) & (e >= 0)
            if not live.any():
                break
            e = np.where(live, edges.string_prev[np.maximum(e, 0)], -1)
            f = np.where(e >= 0, feat_of_edge[np.maximum(e, 0)], -1)
            hit = (f >= 0) & lower[np.maximum(f, 0)]
            found[miss[hit]] = f[hit]
        ok = found >= 0
    ok[ok] = pd[found[ok]] > 0
    # The lower ground, taken parallel to the plane: its disparity the continuation's
    # fraction d / plane_d of the plane's. It must itself be seen: min_support lower
    # matches on it.
    ratio = np.full(nb, np.nan)
    q = np.flatnonzero(ok)
    ratio[q] = d[found[q]] / pd[found[q]]
    lo = np.flatnonzero(lower)
    n_on = (np.abs(d[lo][None, :] - ratio[q, None] * pd[lo][None, :])
            <= tolerance_px).sum(axis=1)
    ok[q] = n_on >= min_support
    if not ok.any():
        return out
    # Which matches of such runs had a candidate on that lower ground.
    mine = sel[ok[b_of]]
    n_edges = len(edges)
    t_d = np.full(n_edges, np.nan)
    le = m.left_index[mine]
    t_d[le] = ratio[b_of[ok[b_of]]] * pd[mine]
    cl = cand.left
    with np.errstate(invalid='ignore'):
        alt = np.abs(cand.d - t_d[cl]) <= tolerance_px
    hit_edge = np.zeros(n_edges, bool)
    hit_edge[cl[alt]] = True
    has_alt = np.zeros(k, bool)
    has_alt[mine] = hit_edge[le]
    # The run must hang: no pixel below at its depth, other than such pixels themselves
    # (two stretches matched the same period off, one above the other).
    rows = np.arange(1, under.shape[0] + 1, dtype=np.float64)[:, None]
    near = (under >= 0) & (np.abs(d[np.maximum(under, 0)] - d0[None, :])
                           <= tolerance_px + slope * rows)
    for _ in range(under.shape[1] + 1):     # until nothing changes (runs only join)
        held = (near & ~out[np.maximum(under, 0)]).any(axis=0)
        new = np.zeros(k, bool)
        new[sel] = has_alt[sel] & ~held[b_of]
        if np.array_equal(new, out):
            break
        out = new
    return out


def _hanging_kernel(bottom, left_index, d, below, feat_of_edge, prev, k, max_gap, tol,
                    slope, solid):
    """:func:`hanging_runs` after its candidate run bottoms, as loops (for numba): the
    same walk, tests and passes."""
    out = np.zeros(k, np.bool_)
    new = np.zeros(k, np.bool_)
    for _ in range(bottom.shape[0] + 1):
        new[:] = False
        for i in range(bottom.shape[0]):
            b = bottom[i]
            e = left_index[b]
            seen = False
            held = False
            for r in range(1, max_gap + 1):
                e = below[e]
                if e < 0:
                    break
                f = feat_of_edge[e]
                if f < 0:
                    continue
                seen = True
                if abs(d[f] - d[b]) <= tol + slope * r and solid[f] and not out[f]:
                    held = True
                    break
            if seen and not held:
                c = b
                while c >= 0:
                    new[c] = True
                    c = prev[c]
        same = True
        for j in range(k):
            if new[j] != out[j]:
                same = False
                out[j] = new[j]
        if same:
            break
    return out


def _hanging_all_kernel(string_prev, left_index, string_id, d, prev, h, max_height, use_only,
                        only, max_gap, tol, slope, solid):
    """`hanging_runs` (for numba): its candidate run bottoms (no match below in the run,
    higher than ``max_height``; of strings with an ``only`` match when ``use_only``), the
    edges below each edge and `_hanging_kernel`'s walk; (K,) bool."""
    k = left_index.shape[0]
    is_prev = np.zeros(k, np.bool_)
    for i in range(k):
        if prev[i] >= 0:
            is_prev[prev[i]] = True
    n_s = 0
    for i in range(k):
        n_s = max(n_s, np.int64(string_id[i]) + 1)
    has = np.zeros(n_s, np.bool_)
    for i in range(k):
        if only[i]:
            has[string_id[i]] = True
    n_b = 0
    cand = np.zeros(k, np.bool_)
    for i in range(k):
        cand[i] = (not is_prev[i] and h[i] > max_height
                   and (has[string_id[i]] if use_only else True))
        n_b += cand[i]
    if n_b == 0:
        return np.zeros(k, np.bool_)
    bottom = np.empty(n_b, np.int64)
    n_b = 0
    for i in range(k):
        if cand[i]:
            bottom[n_b] = i
            n_b += 1
    n_e = string_prev.shape[0]
    feat_of_edge = np.full(n_e, -1, np.int64)
    li = np.empty(k, np.int64)
    d64 = np.empty(k)
    for i in range(k):
        feat_of_edge[left_index[i]] = i
        li[i] = left_index[i]
        d64[i] = d[i]
    below = np.full(n_e, -1, np.int64)
    for e in range(n_e):
        if string_prev[e] >= 0:
            below[string_prev[e]] = e
    return _nb_hanging(bottom, li, d64, below, feat_of_edge, prev, k, max_gap, tol, slope,
                       solid)


_nb_hanging = _jit(_hanging_kernel)
_nb_hanging_all = _jit(_hanging_all_kernel)


def smooth_along_runs(x: np.ndarray, prev: np.ndarray, window: int) -> np.ndarray:
    """Mean of x over a window of up to ``window`` consecutive pixels of each pixel's
    matched run, centred on it (shortened at the run's ends).

    Args:
        x: (K,) values per match.
        prev: (K,) :func:`run_links` of the matches.
        window: pixels (odd; 1 = no smoothing).
    Returns:
        (K,) float64.
    """
    x = np.asarray(x, np.float64)
    k = x.shape[0]
    half = max(int(window), 1) // 2
    if half == 0 or k == 0:
        return x.copy()
    nxt = np.full(k, -1, np.int64)
    has = prev >= 0
    nxt[prev[has]] = np.flatnonzero(has)
    total, count = x.copy(), np.ones(k)
    for step in (prev, nxt):
        cur = np.arange(k)
        for _ in range(half):
            ok = cur >= 0
            cur = np.where(ok, step[np.maximum(cur, 0)], -1)
            ok = cur >= 0
            total += np.where(ok, x[np.maximum(cur, 0)], 0.0)
            count += ok
    return total / count


class _FrameContext:
    """What describing one frame's obstacles needs: the matches' smoothed excess, noise
    and run links, the plane, the visible ground and the left image (internal).

    Ground coordinates (``xy``): metres on the ground plane from the point below the left
    camera, x along the walking direction (the optical axis projected on the plane), y to
    the left, as range and bearing (`core.camera.ground_range_bearing`) measure them.
    """

    def __init__(self, cam: StereoCamera, metric: MetricPlane, abc: np.ndarray, u, v, pd,
                 excess_mean, sigma, prev, ground_points, left, u_left, usable,
                 nxt: np.ndarray | None = None) -> None:
        self.cam, self.metric, self.abc = cam, metric, abc
        self._nxt = nxt
        self.u, self.v, self.pd = u, v, pd
        # the matches' left-image columns and whether each is reliably matched in range
        self.u_left, self.usable = u_left, usable
        self.excess_mean, self.sigma, self.prev = excess_mean, sigma, prev
        n = metric.normal_up
        fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
        self.fwd = fwd / np.linalg.norm(fwd)
        self.lft = _cross3(n, self.fwd)
        self.origin = -metric.height * n
        self._ground_points = ground_points
        # Placement-only silhouette candidates (`silhouette_owners`): the lowest
        # candidate pixel of each and the height of its top, metres.
        self.weak_start = np.zeros(0, np.int64)
        self.weak_top = np.zeros(0)
        self._ground_xy: np.ndarray | None = None
        self._left = left

    @property
    def nxt(self) -> np.ndarray:
        """(K,) int64 the match one row down in the same matched run of each match (-1
        at a run's bottom): the inverse of ``prev``."""
        if self._nxt is None:
            k = self.prev.shape[0]
            nxt = np.full(k, -1, np.int64)
            has = self.prev >= 0
            nxt[self.prev[has]] = np.flatnonzero(has)
            self._nxt = nxt
        return self._nxt

    def to_xy(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) ground coordinates of the feet (projections on the plane) of (N, 3)
        points of the left optical frame."""
        n = self.metric.normal_up
        g = points - self.metric.signed_height(points)[:, None] * n[None, :] - self.origin
        return np.stack([g @ self.fwd, g @ self.lft], axis=1)

    def to_image(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Left-image (u, v) of ground points (N, 2)."""
        p = (self.origin[None, :] + xy[:, :1] * self.fwd[None, :]
             + xy[:, 1:2] * self.lft[None, :])
        p[:, 2] = np.maximum(p[:, 2], 1e-6)
        return self.cam.project_left(p)

    @property
    def ground_xy(self) -> np.ndarray:
        """(G, 2) ground coordinates of the frame's ground features (visible ground)."""
        if self._ground_xy is None:
            self._ground_xy = self.to_xy(self._ground_points)
        return self._ground_xy

    def outline_evidence(self, foot: np.ndarray, height: float, phi: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The image's evidence for a face of ``height`` (m) starting at the ground point
        ``foot`` (2,) in each direction ``phi`` (D,) on the ground (radians from the
        ground's x axis towards y).

        Returns:
            points: (D, S, 2) ground coordinates of the samples (`_LONE_STEPS` metres
                from the foot), metres;
            evidence: (D, S) the weaker of the image gradients across the contact line
                (the samples) and across the top outline (the samples raised by
                ``height``), grey levels per pixel (the largest within one pixel across
                the line; 0 outside the image);
            separation: (D, S) the distance between the two lines across their
                direction, pixels;
            shift: (D, S) the distance between each sample and its raised copy in the
                image, pixels (the separation is its part across the line).
        """
        img_h, img_w = self._left.shape
        dirs = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        points = foot[None, None, :] + _LONE_STEPS[None, :, None] * dirs[:, None, :]
        # The gradient on the patch that holds every sample (the lines' ends and the
        # foot bound them, raised or not), two pixels wider than the samples one pixel
        # across the lines reach: the full image's values there.
        ends = np.concatenate((foot[None], points[:, -1]))
        e3 = self.origin[None, :] + ends[:, :1] * self.fwd + ends[:, 1:] * self.lft
        e3 = np.concatenate((e3, e3 + height * self.metric.normal_up))
        e3[:, 2] = np.maximum(e3[:, 2], 1e-6)
        ue, ve = self.cam.project_left(e3)
        x0 = int(np.clip(np.floor(ue.min()) - 3, 0, img_w - 1))
        x1 = int(np.clip(np.ceil(ue.max()) + 4, x0 + 1, img_w))
        y0 = int(np.clip(np.floor(ve.min()) - 3, 0, img_h - 1))
        y1 = int(np.clip(np.ceil(ve.max()) + 4, y0 + 1, img_h))
        patch = self._left[y0:y1, x0:x1].astype(np.float32)
        gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        if _nb_outline is not None:
            ev, sep, shift = _nb_outline(points, self.origin, self.fwd, self.lft,
                                         self.metric.normal_up, float(height),
                                         float(self.cam.f), float(self.cam.cx),
                                         float(self.cam.cy), gx, gy, x0, y0, img_w, img_h)
            return points, ev, sep, shift
        p3 = (self.origin[None, None, :] + points[..., :1] * self.fwd
              + points[..., 1:] * self.lft)
        lines = []
        for lift in (0.0, height):
            q = (p3 + lift * self.metric.normal_up).reshape(-1, 3)
            q[:, 2] = np.maximum(q[:, 2], 1e-6)
            u, v = self.cam.project_left(q)
            u, v = u.reshape(points.shape[:2]), v.reshape(points.shape[:2])
            # a line on the ground (or parallel to it) is a line in the image: one
            # normal per direction, from its ends
            du, dv = u[:, -1:] - u[:, :1], v[:, -1:] - v[:, :1]
            length = np.maximum(np.hypot(du, dv), 1e-9)
            nu, nv = -dv / length, du / length
            best = np.zeros(u.shape)
            for off in (-1.0, 0.0, 1.0):
                ui = np.clip(np.rint(u + off * nu), 0, img_w - 1).astype(np.int64) - x0
                vi = np.clip(np.rint(v + off * nv), 0, img_h - 1).astype(np.int64) - y0
                best = np.maximum(best, np.abs(gx[vi, ui] * nu + gy[vi, ui] * nv))
            inside = (u >= 0) & (u <= img_w - 1) & (v >= 0) & (v <= img_h - 1)
            lines.append((np.where(inside, best, 0.0), u, v, nu, nv))
        (g_c, uc, vc, nuc, nvc), (g_t, ut, vt, _, _) = lines
        separation = np.abs((ut - uc) * nuc + (vt - vc) * nvc)
        return points, np.minimum(g_c, g_t), separation, np.hypot(ut - uc, vt - vc)

    def contact_edge_score(self, a: np.ndarray, n: np.ndarray, b: np.ndarray) -> np.ndarray:
        """How well the left image's intensity edges follow the ground polylines
        a -> n[k] -> b (a, b (2,), n (M, 2) ground points): the mean over each polyline of
        the image gradient across it (the largest within one pixel), grey levels per
        pixel, (M,). An obstacle standing on the ground meets it along such an edge (its
        silhouette edges show that it contrasts with the ground)."""
        return self.contact_edge_scores(a[None], n[None], b[None],
                                        np.ones((1, n.shape[0]), bool))[0]

    def contact_edge_scores(self, a: np.ndarray, n: np.ndarray, b: np.ndarray,
                            ok: np.ndarray) -> np.ndarray:
        """`contact_edge_score` of several searches at once: a, b (T, 2), n (T, M, 2);
        only the candidates ``ok`` (T, M) are scored (-inf elsewhere), (T, M).

        Each search samples the image gradient in the frame of its own patch (the
        bounding box of its points and candidates, 3-4 pixels wider), as one search alone
        would; the gradient is computed once on the union of the patches (a sample lies
        at least two pixels inside its patch, or on the image border: the same values).
        """
        t_n, m = ok.shape
        img_h, img_w = self._left.shape
        if _nb_contact is not None and _nb_contact_bounds is not None:
            # One projection of all the points (elementwise: the same pixels), the
            # patches' bounds compiled (the same arithmetic).
            uu, vv = self.to_image(np.concatenate((a, b, n.reshape(-1, 2))))
            ua, ub, un = uu[:t_n], uu[t_n:2 * t_n], uu[2 * t_n:].reshape(t_n, m)
            va, vb, vn = vv[:t_n], vv[t_n:2 * t_n], vv[2 * t_n:].reshape(t_n, m)
            okc = np.ascontiguousarray(ok)
            x0, x1, y0, y1 = _nb_contact_bounds(ua, va, ub, vb, un, vn, okc, img_w, img_h)
            gx0, gx1, gy0, gy1 = int(x0.min()), int(x1.max()), int(y0.min()), int(y1.max())
            patch = self._left[gy0:gy1, gx0:gx1].astype(np.float32)
            gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
            return _nb_contact(ua, va, ub, vb, un, vn, okc, x0, x1, y0, y1, gx0, gy0, gx, gy)
        ua, va = self.to_image(a)
        ub, vb = self.to_image(b)
        un, vn = self.to_image(n.reshape(-1, 2))
        un, vn = un.reshape(t_n, m), vn.reshape(t_n, m)
        inf = np.inf
        u_lo = np.minimum(np.minimum(ua, ub), np.where(ok, un, inf).min(axis=1))
        u_hi = np.maximum(np.maximum(ua, ub), np.where(ok, un, -inf).max(axis=1))
        v_lo = np.minimum(np.minimum(va, vb), np.where(ok, vn, inf).min(axis=1))
        v_hi = np.maximum(np.maximum(va, vb), np.where(ok, vn, -inf).max(axis=1))
        x0 = np.clip(np.floor(u_lo).astype(np.int64) - 3, 0, img_w - 1)
        x1 = np.minimum(np.maximum(np.ceil(u_hi).astype(np.int64) + 4, x0 + 1), img_w)
        y0 = np.clip(np.floor(v_lo).astype(np.int64) - 3, 0, img_h - 1)
        y1 = np.minimum(np.maximum(np.ceil(v_hi).astype(np.int64) + 4, y0 + 1), img_h)
        gx0, gx1, gy0, gy1 = int(x0.min()), int(x1.max()), int(y0.min()), int(y1.max())
        patch = self._left[gy0:gy1, gx0:gx1].astype(np.float32)
        gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        if _nb_contact is not None:
            return _nb_contact(ua, va, ub, vb, np.ascontiguousarray(un),
                               np.ascontiguousarray(vn), np.ascontiguousarray(ok), x0, x1,
                               y0, y1, gx0, gy0, gx, gy)
        # Segments (T, 2, M): a -> n and b -> n, in each search's patch coordinates.
        fx, fy = x0.astype(np.float64)[:, None, None], y0.astype(np.float64)[:, None, None]
        u0 = np.stack([ua, ub], axis=1)[:, :, None] - fx
        v0 = np.stack([va, vb], axis=1)[:, :, None] - fy
        u1 = un[:, None, :] - fx
        v1 = vn[:, None, :] - fy
        du, dv = u1 - u0, v1 - v0
        length = np.hypot(du, dv)
        nu = (-dv / np.maximum(length, 1e-9))[..., None]
        nv = (du / np.maximum(length, 1e-9))[..., None]
        t = (np.arange(16) + 0.5) / 16.0
        uu = u0[..., None] + t * du[..., None]
        vv = v0[..., None] + t * dv[..., None]
        # Clipping to each patch, then the offset into the union patch (flat index).
        pw = gx.shape[1]
        w_max = (x1 - x0 - 1)[:, None, None, None]
        h_max = (y1 - y0 - 1)[:, None, None, None]
        ox = (x0 - gx0)[:, None, None, None]
        oy = (y0 - gy0)[:, None, None, None]
        gxf, gyf = gx.ravel(), gy.ravel()
        best = None
        for off in (-1.0, 0.0, 1.0):
            ui = np.rint(uu + off * nu).astype(np.int64)
            vi = np.rint(vv + off * nv).astype(np.int64)
            np.maximum(ui, 0, out=ui)
            np.minimum(ui, w_max, out=ui)
            np.maximum(vi, 0, out=vi)
            np.minimum(vi, h_max, out=vi)
            flat = (vi + oy) * pw + (ui + ox)
            val = np.abs(gxf[flat] * nu + gyf[flat] * nv)
            best = val if best is None else np.maximum(best, val)
        total = best.mean(axis=-1) * length
        score = (total[:, 0] + total[:, 1]) / np.maximum(length[:, 0] + length[:, 1], 1e-9)
        return np.where(ok, score, -inf)


def _outline_kernel(points, origin, fwd, lft, nup, height, f, cx, cy, gx, gy, x0, y0,
                    img_w, img_h):
    """`_FrameContext.outline_evidence` after the sample points (for numba): the same
    arithmetic in the same order; gx, gy the gradient patch at (x0, y0) of the img_w x
    img_h image; returns (evidence, separation, shift), (D, S) each."""
    n_d, n_s = points.shape[0], points.shape[1]
    grad = np.zeros((2, n_d, n_s))
    uu = np.empty((2, n_d, n_s))
    vv = np.empty((2, n_d, n_s))
    nus = np.empty((2, n_d))
    nvs = np.empty((2, n_d))
    for line in range(2):
        lift = 0.0 if line == 0 else height
        for d in range(n_d):
            for k in range(n_s):
                px, py = points[d, k, 0], points[d, k, 1]
                q0 = origin[0] + px * fwd[0] + py * lft[0] + lift * nup[0]
                q1 = origin[1] + px * fwd[1] + py * lft[1] + lift * nup[1]
                q2 = max(origin[2] + px * fwd[2] + py * lft[2] + lift * nup[2], 1e-6)
                uu[line, d, k] = f * q0 / q2 + cx
                vv[line, d, k] = f * q1 / q2 + cy
            du = uu[line, d, n_s - 1] - uu[line, d, 0]
            dv = vv[line, d, n_s - 1] - vv[line, d, 0]
            length = max(math.hypot(du, dv), 1e-9)
            nu, nv = -dv / length, du / length
            nus[line, d], nvs[line, d] = nu, nv
            for k in range(n_s):
                u, v = uu[line, d, k], vv[line, d, k]
                if not (u >= 0 and u <= img_w - 1 and v >= 0 and v <= img_h - 1):
                    continue
                best = 0.0
                for off in (-1.0, 0.0, 1.0):
                    ui = int(min(max(np.rint(u + off * nu), 0.0), img_w - 1.0))
                    vi = int(min(max(np.rint(v + off * nv), 0.0), img_h - 1.0))
                    val = abs(np.float64(gx[vi - y0, ui - x0]) * nu
                              + np.float64(gy[vi - y0, ui - x0]) * nv)
                    best = max(best, val)
                grad[line, d, k] = best
    ev = np.empty((n_d, n_s))
    sep = np.empty((n_d, n_s))
    shift = np.empty((n_d, n_s))
    for d in range(n_d):
        for k in range(n_s):
            ev[d, k] = min(grad[0, d, k], grad[1, d, k])
            sep[d, k] = abs((uu[1, d, k] - uu[0, d, k]) * nus[0, d]
                            + (vv[1, d, k] - vv[0, d, k]) * nvs[0, d])
            shift[d, k] = math.hypot(uu[1, d, k] - uu[0, d, k], vv[1, d, k] - vv[0, d, k])
    return ev, sep, shift


_nb_outline = _jit(_outline_kernel)


def _contact_bounds_kernel(ua, va, ub, vb, un, vn, ok, img_w, img_h):
    """The patch of each search of `_FrameContext.contact_edge_scores` (for numba): the
    bounding box of its feet (ua, va), (ub, vb) (T,) and candidates ``ok`` (un, vn)
    (T, M), pixels, widened by 3 (4 past the far side), within the image: (T,) int64
    x0, x1, y0, y1 each (x1, y1 exclusive), as numpy's floor, ceil and clipping give."""
    t_n, m = ok.shape
    x0 = np.empty(t_n, np.int64)
    x1 = np.empty(t_n, np.int64)
    y0 = np.empty(t_n, np.int64)
    y1 = np.empty(t_n, np.int64)
    for t in range(t_n):
        u_lo, u_hi = min(ua[t], ub[t]), max(ua[t], ub[t])
        v_lo, v_hi = min(va[t], vb[t]), max(va[t], vb[t])
        for k in range(m):
            if ok[t, k]:
                u_lo, u_hi = min(u_lo, un[t, k]), max(u_hi, un[t, k])
                v_lo, v_hi = min(v_lo, vn[t, k]), max(v_hi, vn[t, k])
        x0[t] = min(max(np.int64(math.floor(u_lo)) - 3, 0), img_w - 1)
        x1[t] = min(max(np.int64(math.ceil(u_hi)) + 4, x0[t] + 1), img_w)
        y0[t] = min(max(np.int64(math.floor(v_lo)) - 3, 0), img_h - 1)
        y1[t] = min(max(np.int64(math.ceil(v_hi)) + 4, y0[t] + 1), img_h)
    return x0, x1, y0, y1


_nb_contact_bounds = _jit(_contact_bounds_kernel)


def _contact_kernel(ua, va, ub, vb, un, vn, ok, x0, x1, y0, y1, gx0, gy0, gx, gy):
    """The sampling of `_FrameContext.contact_edge_scores` (for numba): the same samples,
    clipping and arithmetic, the mean of 16 samples as numpy's pairwise sum; (T, M)."""
    t_n, m = ok.shape
    out = np.full((t_n, m), -np.inf)
    best = np.empty(16)
    for t in range(t_n):
        fx, fy = np.float64(x0[t]), np.float64(y0[t])
        w_max, h_max = x1[t] - x0[t] - 1, y1[t] - y0[t] - 1
        ox, oy = x0[t] - gx0, y0[t] - gy0
        for k in range(m):
            if not ok[t, k]:
                continue
            u1, v1 = un[t, k] - fx, vn[t, k] - fy
            tot = 0.0
            lsum = 0.0
            for s in range(2):
                u0 = (ua[t] if s == 0 else ub[t]) - fx
                v0 = (va[t] if s == 0 else vb[t]) - fy
                du, dv = u1 - u0, v1 - v0
                length = math.hypot(du, dv)
                nu = -dv / max(length, 1e-9)
                nv = du / max(length, 1e-9)
                for i in range(16):
                    ti = (i + 0.5) / 16.0
                    uu, vv = u0 + ti * du, v0 + ti * dv
                    bi = 0.0
                    for o in range(3):
                        off = o - 1.0
                        ui = min(max(np.int64(np.rint(uu + off * nu)), 0), w_max)
                        vi = min(max(np.int64(np.rint(vv + off * nv)), 0), h_max)
                        val = abs(np.float64(gx[vi + oy, ui + ox]) * nu
                                  + np.float64(gy[vi + oy, ui + ox]) * nv)
                        bi = val if o == 0 else max(bi, val)
                    best[i] = bi
                # numpy's pairwise sum of 16: eight partial sums, then a tree
                r0, r1 = best[0] + best[8], best[1] + best[9]
                r2, r3 = best[2] + best[10], best[3] + best[11]
                r4, r5 = best[4] + best[12], best[5] + best[13]
                r6, r7 = best[6] + best[14], best[7] + best[15]
                mean = (((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))) / 16.0
                tot += mean * length
                lsum += length
            out[t, k] = tot / max(lsum, 1e-9)
    return out


_nb_contact = _jit(_contact_kernel)


def _walk_down_kernel(start, nxt, exm, sig, k, steps):
    """The walk of `string_feet` down each matched run (for numba): from each start,
    follow ``nxt`` while there is a next pixel and the excess is above ``k`` sigmas, at
    most ``steps`` times; (S,) int64 the pixels reached."""
    out = start.copy()
    for s in range(out.shape[0]):
        c = out[s]
        for _ in range(steps):
            n = nxt[c]
            if n < 0 or not exm[c] > k * sig[c]:
                break
            c = n
        out[s] = c
    return out


_nb_walk_down = _jit(_walk_down_kernel)


def string_feet(ctx: _FrameContext, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ground foot of edge strings, from their lowest obstacle pixels ``start``.

    Each string's matched run is followed down the image (one row at a time, only while
    the disparity stays consistent, :func:`run_links`) from its start until its smoothed
    disparity excess is within ``_FOOT_SIGMAS`` noise sigmas of the plane: there the edge
    meets the ground (an edge standing on the ground loses |b| px of excess per row).
    The foot is the projection on the plane of that pixel's point (its disparity the
    plane's plus the remaining excess; on the plane when the run ended on it). Its range
    uncertainty: the range spanned by one image row there, times the row's uncertainty
    (noise sigma / |b|, at least ``_FOOT_MIN_ROWS``).

    Returns:
        ((S, 2) ground coordinates of the feet, (S,) range sigma, metres).
    """
    nxt = ctx.nxt
    cur = np.asarray(start, np.int64)
    exm, sig = ctx.excess_mean, ctx.sigma
    if _nb_walk_down is not None:
        cur = _nb_walk_down(cur, nxt, exm, sig, _FOOT_SIGMAS, int(ctx.cam.height))
    else:
        for _ in range(int(ctx.cam.height)):
            n = nxt[cur]
            go = (n >= 0) & (exm[cur] > _FOOT_SIGMAS * sig[cur])
            if not go.any():
                break
            cur = np.where(go, n, cur)
    u, v = ctx.u[cur], ctx.v[cur]
    p = ctx.cam.triangulate(u, v, ctx.pd[cur] + np.maximum(exm[cur], 0.0))
    xy = ctx.to_xy(p)
    slope = max(abs(float(ctx.abc[1])), 1e-3)

    def ground_range(dv: float) -> np.ndarray:
        d = np.maximum(plane_disparity(ctx.abc, u, v + dv), 1e-3)
        g = ctx.to_xy(ctx.cam.triangulate(u, v + dv, d))
        return np.hypot(g[:, 0], g[:, 1])

    rows = np.maximum(sig[cur] / slope, _FOOT_MIN_ROWS)
    return xy, np.abs(ground_range(0.5) - ground_range(-0.5)) * rows


def soft_nearest(xy: np.ndarray, sr: np.ndarray, ground_xy=None) -> np.ndarray:
    """The expected nearest of points with uncertain ranges: their mean weighted by
    ``exp(-dr^2 / 2(s_i^2 + s_0^2))``, dr the range beyond the nearest point's (whose
    sigma is s_0). Points as near as the nearest to within their noise share the weight
    (a frontal face: its middle), clearly farther ones do not count.

    Args:
        xy: (S, 2) ground coordinates of the feet, metres; sr: (S,) their range sigmas.
        ground_xy: (G, 2) visible ground, or a callable returning it, or None. Given,
            a foot that visible ground separates from the nearest one (`_body_gap`: two
            obstacles side by side, not one face) does not share the weight.
    Returns:
        (2,) ground coordinates, metres.
    """
    r = np.hypot(xy[:, 0], xy[:, 1])
    j = int(np.argmin(r))
    w = np.exp(-0.5 * (r - r[j]) ** 2 / np.maximum(sr ** 2 + sr[j] ** 2, 1e-12))
    if ground_xy is not None:
        far = np.flatnonzero((w > 0.01) & (np.hypot(*(xy - xy[j]).T) > _BODY_GAP_SPAN_M))
        if far.size:
            g = ground_xy() if callable(ground_xy) else ground_xy
            for i in far.tolist():
                if _body_gap(g, xy[j], xy[i]):
                    w[i] = 0.0
    return (w[:, None] * xy).sum(axis=0) / w.sum()


def _body_gap(ground: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether visible ground (G, 2) separates the feet a and b ((2,), metres, ground
    coordinates from the camera): at least ``_FACE_BEHIND_MIN`` features in the strip
    ``_BODY_GAP_BAND_M`` behind the segment a-b (away from the camera), more than
    ``_BODY_GAP_END_M`` from its ends along it."""
    e = b - a
    length = float(np.hypot(*e))
    if ground.shape[0] == 0 or length <= 2.0 * _BODY_GAP_END_M:
        return False
    t = e / length
    nrm = np.array([-t[1], t[0]])
    if nrm @ (0.5 * (a + b)) < 0.0:         # pointing away from the camera
        nrm = -nrm
    rel = ground - a
    along, behind = rel @ t, rel @ nrm
    lo, hi = _BODY_GAP_BAND_M
    inside = ((along > _BODY_GAP_END_M) & (along < length - _BODY_GAP_END_M)
              & (behind > lo) & (behind < hi))
    return int(np.count_nonzero(inside)) >= _FACE_BEHIND_MIN


#: Relative rounding slack of the compiled `_body_gap` test (`_body_gap_kernel`): its
#: sums of products may differ from numpy's BLAS products (fused multiply-adds) in the
#: last bits; ground points this close to the strip's sides leave the decision to numpy.
_GAP_SLACK = 1e-12


def _body_gap_kernel(g, ax, ay, bx, by):
    """`_body_gap` (for numba) of the feet (ax, ay), (bx, by) and ground g (G, 2): 1 when
    it is sure to be True, 0 when sure to be False, -1 when a ground point (or the
    camera's side of the segment) lies within rounding distance of the strip's sides
    (``_GAP_SLACK`` times the size of the products): then only `_body_gap` decides.

    The same quantities as `_body_gap`: e = b - a, t = e / |e|, nrm = (-t_y, t_x) turned
    towards the camera's far side (nrm . (a + b) / 2 >= 0), and for each ground point
    p - a its coordinates along t and along nrm."""
    ex, ey = bx - ax, by - ay
    length = math.hypot(ex, ey)
    if g.shape[0] == 0 or length <= 2.0 * _BODY_GAP_END_M:
        return 0
    tx, ty = ex / length, ey / length
    nx, ny = -ty, tx
    mx, my = 0.5 * (ax + bx), 0.5 * (ay + by)
    p0, p1 = nx * mx, ny * my
    side = p0 + p1
    if abs(side) <= _GAP_SLACK * (abs(p0) + abs(p1)):
        return -1
    if side < 0.0:                     # pointing away from the camera
        nx, ny = -nx, -ny
    lo, hi = _BODY_GAP_BAND_M
    end0, end1 = _BODY_GAP_END_M, length - _BODY_GAP_END_M
    sure, maybe = 0, 0
    for p in range(g.shape[0]):
        rx, ry = g[p, 0] - ax, g[p, 1] - ay
        q0, q1 = rx * tx, ry * ty
        along = q0 + q1
        ta = _GAP_SLACK * (abs(q0) + abs(q1))
        q0, q1 = rx * nx, ry * ny
        behind = q0 + q1
        tb = _GAP_SLACK * (abs(q0) + abs(q1))
        if (along > end0 - ta and along < end1 + ta and behind > lo - tb
                and behind < hi + tb):
            maybe += 1
            if (along > end0 + ta and along < end1 - ta and behind > lo + tb
                    and behind < hi - tb):
                sure += 1
                if sure >= _FACE_BEHIND_MIN:
                    return 1
    return 0 if maybe < _FACE_BEHIND_MIN else -1


def _first_min(x, k, best):
    """Whether x[k] replaces x[best] as ``np.argmin``'s answer scanning in order: smaller,
    or the first NaN (which numpy returns)."""
    return not math.isnan(x[best]) and (math.isnan(x[k]) or x[k] < x[best])


def _soft_args_kernel(xy, sr, group, want, n_groups, two):
    """The per-foot exponents of `soft_nearest` for the feet of the groups ``want``
    (n_groups,) bool (for numba). ``two`` is 2.0, passed at run time: the nearest
    foot's sigma squared is ``pow(s_near, 2)`` as numpy squares a scalar (libm's pow,
    which the compiler would otherwise turn into s * s).

    Returns:
        idx (P,) int64 the feet by group, ascending within each (as ``np.argsort(group,
        kind='stable')``); start (n_groups + 1,) int64 each group's first row in idx;
        near (n_groups,) int64 each group's nearest foot (``np.argmin`` of the range,
        first of equals), -1 for none; arg (P,) float64
        ``-0.5 (r - r_near)^2 / max(s^2 + s_near^2, 1e-12)`` (numpy's operations).
    """
    s_n = group.shape[0]
    start = np.zeros(n_groups + 1, np.int64)
    for i in range(s_n):
        if want[group[i]]:
            start[group[i] + 1] += 1
    for k in range(n_groups):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    idx = np.empty(start[n_groups], np.int64)
    r = np.empty(s_n)
    for i in range(s_n):
        k = group[i]
        if want[k]:
            idx[fill[k]] = i
            fill[k] += 1
            r[i] = math.hypot(xy[i, 0], xy[i, 1])
    near = np.full(n_groups, -1, np.int64)
    arg = np.empty(idx.shape[0])
    for k in range(n_groups):
        if start[k] == start[k + 1]:
            continue
        j = idx[start[k]]
        for p in range(start[k] + 1, start[k + 1]):
            if _nb_first_min(r, idx[p], j):
                j = idx[p]
        near[k] = j
        rj, sj2 = r[j], math.pow(sr[j], two)
        for p in range(start[k], start[k + 1]):
            i = idx[p]
            dr = r[i] - rj
            den = sr[i] * sr[i] + sj2
            if not (den >= 1e-12 or math.isnan(den)):     # np.maximum(den, 1e-12)
                den = 1e-12
            arg[p] = -0.5 * (dr * dr) / den
    return idx, start, near, arg


def _soft_far_kernel(xy, idx, start, near, w):
    """(P,) bool: the feet of `_soft_args_kernel`'s rows that `soft_nearest` tests for a
    body gap: weight above 0.01 and more than ``_BODY_GAP_SPAN_M`` from the nearest foot
    (for numba)."""
    far = np.zeros(idx.shape[0], np.bool_)
    for k in range(near.shape[0]):
        j = near[k]
        for p in range(start[k], start[k + 1]):
            i = idx[p]
            far[p] = (w[p] > 0.01 and math.hypot(xy[i, 0] - xy[j, 0], xy[i, 1] - xy[j, 1])
                      > _BODY_GAP_SPAN_M)
    return far


def _soft_finish_kernel(xy, idx, start, near, w, far, g):
    """The weighted means of `soft_nearest` (for numba): per group, the weights w (P,)
    with those of the ``far`` feet that visible ground g (G, 2) separates from the
    nearest foot set to 0 (`_body_gap_kernel`), then sum(w xy) / sum(w) in numpy's order
    (the products' column sums in order, the weights' pairwise).

    Returns:
        ((n_groups, 2) float64 the points, NaN for groups without feet; (n_groups,) bool,
        the groups left to numpy (a body-gap test too close to call, or more than 128
        feet), their point not computed).
    """
    n_g = near.shape[0]
    out = np.full((n_g, 2), np.nan)
    undecided = np.zeros(n_g, np.bool_)
    ww = w.copy()
    for k in range(n_g):
        j = near[k]
        if j < 0:
            continue
        if start[k + 1] - start[k] > 128:       # numpy sums more values by halves
            undecided[k] = True
            continue
        for p in range(start[k], start[k + 1]):
            if not far[p]:
                continue
            i = idx[p]
            gap = _nb_body_gap(g, xy[j, 0], xy[j, 1], xy[i, 0], xy[i, 1])
            if gap < 0:
                undecided[k] = True
                break
            if gap == 1:
                ww[p] = 0.0
        if undecided[k]:
            continue
        sx, sy = 0.0, 0.0
        for p in range(start[k], start[k + 1]):
            i = idx[p]
            sx += ww[p] * xy[i, 0]
            sy += ww[p] * xy[i, 1]
        den = _nb_pairwise_sum(ww, start[k], start[k + 1])
        out[k, 0] = sx / den
        out[k, 1] = sy / den
    return out, undecided


def _soft_nearest_groups(xy: np.ndarray, sr: np.ndarray, group: np.ndarray, n_groups: int,
                         want: np.ndarray, ground_xy=None) -> np.ndarray:
    """`soft_nearest` of the feet of each group ``want`` at once.

    Args:
        xy: (S, 2) ground coordinates of the feet, metres; sr: (S,) their range sigmas.
        group: (S,) int64 group of each foot, 0..n_groups-1.
        want: (n_groups,) bool, the groups to compute (each with at least one foot).
        ground_xy: as `soft_nearest`'s (an array, a callable returning one, or None).
    Returns:
        (n_groups, 2) float64, NaN for the groups not wanted.
    """
    out = np.full((n_groups, 2), np.nan)
    if not want.any():
        return out
    if _nb_soft_args is None:
        order = np.argsort(group, kind='stable')
        first = np.searchsorted(group[order], np.arange(n_groups), side='left')
        last = np.searchsorted(group[order], np.arange(n_groups), side='right')
        for k in np.flatnonzero(want).tolist():
            sel = order[first[k]:last[k]]
            out[k] = soft_nearest(xy[sel], sr[sel], ground_xy)
        return out
    xy = np.ascontiguousarray(xy, np.float64)
    idx, start, near, arg = _nb_soft_args(xy, np.ascontiguousarray(sr, np.float64),
                                          np.asarray(group, np.int64), want, n_groups, 2.0)
    w = np.exp(arg)                  # numpy's exp (the compiled one differs in last bits)
    if ground_xy is None:
        far = np.zeros(idx.shape[0], bool)
        g = np.zeros((0, 2))
    else:
        far = _nb_soft_far(xy, idx, start, near, w)
        g = np.zeros((0, 2))
        if far.any():
            g = ground_xy() if callable(ground_xy) else ground_xy
            g = np.ascontiguousarray(g, np.float64)
    q, undecided = _nb_soft_finish(xy, idx, start, near, w, far, g)
    out[want] = q[want]
    for k in np.flatnonzero(undecided).tolist():       # left to numpy
        sel = idx[start[k]:start[k + 1]]
        out[k] = soft_nearest(xy[sel], sr[sel], g)
    return out


_nb_first_min = _jit(_first_min)
_nb_body_gap = _jit(_body_gap_kernel)
_nb_soft_args = _jit(_soft_args_kernel)
_nb_soft_far = _jit(_soft_far_kernel)
_nb_soft_finish = _jit(_soft_finish_kernel)


def _ground_inside(g: np.ndarray, a: np.ndarray, n: np.ndarray, b: np.ndarray,
                   margin: float, job: np.ndarray | None = None) -> np.ndarray:
    """(T, M) bool: whether any of the ground points g (P, 2) of search ``job[p]`` lies
    inside the triangle a[t]-n[t, k]-b[t] by more than ``margin`` from each side (never
    for a degenerate triangle); a, b (T, 2), n (T, M, 2), job (P,) (None: all points
    belong to every search)."""
    t_n, m = n.shape[:2]
    out = np.zeros((t_n, m), bool)
    if g.shape[0] == 0:
        return out
    if job is None:
        job = np.repeat(np.arange(t_n), g.shape[0])
        g = np.tile(g, (t_n, 1))
    gx, gy = g[:, None, 0], g[:, None, 1]

    def side(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """(P, M) signed distance of each point from the line p0 -> p1 of its search
        (left positive); p0, p1 (T, M, 2)."""
        e = p1 - p0
        length = np.maximum(np.hypot(e[..., 0], e[..., 1]), 1e-12)[job]
        ex, ey = e[job, :, 0], e[job, :, 1]
        return (ex * (gy - p0[job, :, 1]) - ey * (gx - p0[job, :, 0])) / length

    aa = np.broadcast_to(a[:, None, :], n.shape)
    bb = np.broadcast_to(b[:, None, :], n.shape)
    area2 = ((n[..., 0] - a[:, None, 0]) * (b[:, None, 1] - a[:, None, 1])
             - (n[..., 1] - a[:, None, 1]) * (b[:, None, 0] - a[:, None, 0]))
    sgn = np.where(area2 > 0, 1.0, -1.0)[job]
    inside = ((sgn * side(aa, n) > margin) & (sgn * side(n, bb) > margin)
              & (sgn * side(bb, aa) > margin))
    np.logical_or.at(out, job, inside)
    return out & (np.abs(area2) > 1e-12)


def _inside_by_kernel(ax, ay, nx, ny, bx, by, gx, gy, sgn, margin):
    """Whether the point g lies more than ``margin`` inside the triangle a-n-b of
    orientation ``sgn`` (+1 counter-clockwise), metres (for numba): each side's signed
    distance side(p0, p1) from the line p0 -> p1 (left positive) times sgn exceeds it
    (`_ground_inside`'s arithmetic)."""
    e0x, e0y = nx - ax, ny - ay                             # a -> n
    l0 = max(math.hypot(e0x, e0y), 1e-12)
    if not sgn * ((e0x * (gy - ay) - e0y * (gx - ax)) / l0) > margin:
        return False
    e1x, e1y = bx - nx, by - ny                             # n -> b
    l1 = max(math.hypot(e1x, e1y), 1e-12)
    if not sgn * ((e1x * (gy - ny) - e1y * (gx - nx)) / l1) > margin:
        return False
    e2x, e2y = ax - bx, ay - by                             # b -> a
    l2 = max(math.hypot(e2x, e2y), 1e-12)
    return sgn * ((e2x * (gy - by) - e2y * (gx - bx)) / l2) > margin


_nb_inside_by = _jit(_inside_by_kernel)


def _corner_free_kernel(g, a, b, c, r, n, margin):
    """The free-space test of `hidden_corners` (for numba): (T, M) bool, whether no ground
    point g (G, 2) lies inside the triangle a[t]-n[t, k]-b[t] by more than ``margin``
    (c, r (T, 2), (T,): the searches' circles). The same prefilters and arithmetic as
    the numpy path (bounding box of all circles, off the chord and inside the circle,
    then `_ground_inside`)."""
    t_n, m = n.shape[0], n.shape[1]
    ok = np.ones((t_n, m), np.bool_)
    lo0, lo1, hi0, hi1 = np.inf, np.inf, -np.inf, -np.inf
    for t in range(t_n):
        lo0 = min(lo0, c[t, 0] - r[t])
        lo1 = min(lo1, c[t, 1] - r[t])
        hi0 = max(hi0, c[t, 0] + r[t])
        hi1 = max(hi1, c[t, 1] + r[t])
    lo0 -= margin
    lo1 -= margin
    hi0 += margin
    hi1 += margin
    area2 = np.empty(m)
    for t in range(t_n):
        ax, ay, bx, by = a[t, 0], a[t, 1], b[t, 0], b[t, 1]
        ex, ey = ax - bx, ay - by
        chord = max(math.hypot(ex, ey), 1e-12)
        rr = (r[t] * 1.001) ** 2
        for k in range(m):
            area2[k] = ((n[t, k, 0] - ax) * (by - ay) - (n[t, k, 1] - ay) * (bx - ax))
        for p in range(g.shape[0]):
            gx, gy = g[p, 0], g[p, 1]
            if not (gx >= lo0 and gx <= hi0 and gy >= lo1 and gy <= hi1):
                continue
            off = abs(ex * (gy - by) - ey * (gx - bx))
            dx, dy = gx - c[t, 0], gy - c[t, 1]
            if not (off > (margin * 0.999) * chord and dx * dx + dy * dy < rr):
                continue
            for k in range(m):
                if not ok[t, k] or not abs(area2[k]) > 1e-12:
                    continue
                sgn = 1.0 if area2[k] > 0 else -1.0
                if _nb_inside_by(ax, ay, n[t, k, 0], n[t, k, 1], bx, by, gx, gy, sgn,
                                 margin):
                    ok[t, k] = False
    return ok


_nb_corner_free = _jit(_corner_free_kernel)


#: The candidates' positions along the Thales arc, 0..1 (`hidden_corners`).
_ARC_LIN = np.linspace(0.0, 1.0, _CORNER_ARC_POINTS)


def _arcs_kernel(a, b, sigma):
    """The circles and near arcs of `hidden_corners`' searches (for numba), with its
    arithmetic (libm's hypot and atan2, Python's float modulo).

    Args:
        a, b: (T, 2) silhouette feet, metres; sigma: (T,) their range sigmas.
    Returns:
        ok (T,) bool, the searches whose corner could bulge enough (rho > 2 sigma) and
        whose circle leaves out the camera's foot; c (T, 2) the circles' centres
        (a + b) / 2, rho (T,) their radii |b - a| / 2; a0 (T,) the angle of a from c,
        span (T,) the near arc from a to b, radians (negative: clockwise).
    """
    t_n = a.shape[0]
    ok = np.zeros(t_n, np.bool_)
    c = np.empty((t_n, 2))
    rho = np.empty(t_n)
    a0 = np.empty(t_n)
    span = np.empty(t_n)
    two_pi = 2 * math.pi
    for t in range(t_n):
        cx, cy = 0.5 * (a[t, 0] + b[t, 0]), 0.5 * (a[t, 1] + b[t, 1])
        c[t, 0], c[t, 1] = cx, cy
        r = 0.5 * math.hypot(b[t, 0] - a[t, 0], b[t, 1] - a[t, 1])
        rho[t] = r
        if r <= _CORNER_SIGMAS * sigma[t] or math.hypot(cx, cy) <= r:
            continue
        ang0 = math.atan2(a[t, 1] - cy, a[t, 0] - cx)
        sp = (math.atan2(b[t, 1] - cy, b[t, 0] - cx) - ang0) % two_pi      # a -> b, ccw
        if (math.atan2(-cy, -cx) - ang0) % two_pi > sp:                    # near half cw
            sp -= two_pi
        ok[t] = True
        a0[t] = ang0
        span[t] = sp
    return ok, c, rho, a0, span


_nb_arcs = _jit(_arcs_kernel)


def hidden_corners(a: np.ndarray, b: np.ndarray, sigma: np.ndarray, ground_xy,
                   score) -> np.ndarray:
    """`hidden_corner` of several pairs of silhouette feet at once.

    Args:
        a, b: (T, 2) ground coordinates of the silhouette feet of each search.
        sigma: (T,) their range sigmas, metres.
        ground_xy: (G, 2) visible ground, or a callable returning it (only called when
            a search gets that far).
        score: ``score(a (T', 2), n (T', M, 2), b (T', 2), ok (T', M)) -> (T', M)``, the
            contact-edge score of the candidates ``ok`` (others -inf)
            (`_FrameContext.contact_edge_scores`).
    Returns:
        (T, 2) the hidden corner of each search, NaN where there is none.
    """
    t_n = a.shape[0]
    out = np.full((t_n, 2), np.nan)
    if _nb_arcs is not None:
        # The same circles and arcs, compiled (one pass over the searches).
        ok_t, c_all, rho_all, a0_all, span_all = _nb_arcs(
            np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64),
            np.ascontiguousarray(sigma, np.float64))
        jobs = np.flatnonzero(ok_t)
        if not jobs.size:
            return out
        cj, rj, a0j, spanj = c_all[jobs], rho_all[jobs], a0_all[jobs], span_all[jobs]
    else:
        jobs, cs, rhos, a0s, spans = [], [], [], [], []
        for t in range(t_n):
            at, bt = a[t], b[t]
            c = 0.5 * (at + bt)
            rho = 0.5 * float(np.hypot(*(bt - at)))
            cn = float(np.hypot(*c))
            if rho <= _CORNER_SIGMAS * sigma[t] or cn <= rho:   # no corner could bulge enough
                continue
            a0 = math.atan2(at[1] - c[1], at[0] - c[0])
            span = (math.atan2(bt[1] - c[1], bt[0] - c[0]) - a0) % (2 * math.pi)  # a -> b, ccw
            if (math.atan2(-c[1], -c[0]) - a0) % (2 * math.pi) > span:   # the near half is cw
                span -= 2 * math.pi
            jobs.append(t)
            cs.append(c)
            rhos.append(rho)
            a0s.append(a0)
            spans.append(span)
        if not jobs:
            return out
        jobs = np.array(jobs)
        cj, rj, a0j, spanj = np.array(cs), np.array(rhos), np.array(a0s), np.array(spans)
    aj, bj = a[jobs], b[jobs]
    ang = a0j[:, None] + _ARC_LIN * spanj[:, None]
    n = cj[:, None, :] + rj[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], axis=2)
    margin = _FREE_SPACE_MARGIN_M
    g = ground_xy() if callable(ground_xy) else ground_xy
    if g.size and _nb_corner_free is not None:      # the same tests, compiled
        ok = _nb_corner_free(np.ascontiguousarray(g, np.float64), aj, bj, cj, rj, n, margin)
    elif g.size:
        # Only ground inside a search's circle (its triangles are inscribed) and off its
        # chord by more than the margin can be inside one of its triangles (a cheap test
        # of every ground point, the exact one of the few left).
        # Ground within the bounding box of all the circles first (one cheap pass).
        lo = (cj - rj[:, None]).min(axis=0) - margin
        hi = (cj + rj[:, None]).max(axis=0) + margin
        g = g[(g[:, 0] >= lo[0]) & (g[:, 0] <= hi[0]) & (g[:, 1] >= lo[1]) & (g[:, 1] <= hi[1])]
        ex, ey = (aj - bj)[:, 0:1], (aj - bj)[:, 1:2]
        chord = np.maximum(np.hypot(ex, ey), 1e-12)
        off = np.abs(ex * (g[None, :, 1] - bj[:, 1:2]) - ey * (g[None, :, 0] - bj[:, 0:1]))
        dx, dy = g[None, :, 0] - cj[:, 0:1], g[None, :, 1] - cj[:, 1:2]
        near = ((off > (margin * 0.999) * chord)
                & (dx * dx + dy * dy < (rj[:, None] * 1.001) ** 2))
        job, gi = np.nonzero(near)
        ok = ~_ground_inside(g[gi], aj, n, bj, margin, job)
    else:
        ok = np.ones(n.shape[:2], bool)
    live = ok.any(axis=1)
    if not live.any():
        return out
    jobs, aj, bj, n, ok = jobs[live], aj[live], bj[live], n[live], ok[live]
    best = np.argmax(score(aj, n, bj, ok), axis=1)
    q = n[np.arange(jobs.size), best]
    e = bj - aj
    rho = rj[live]
    bulge = np.abs(e[:, 0] * (q[:, 1] - aj[:, 1]) - e[:, 1] * (q[:, 0] - aj[:, 0])) / (2.0 * rho)
    keep = bulge > _CORNER_SIGMAS * sigma[jobs]
    out[jobs[keep]] = q[keep]
    return out


def _single_score(score):
    """A batched score (`hidden_corners`) from a single one ``score(a, n, b) -> (M,)``."""
    def batched(a, n, b, ok):
        out = np.full(ok.shape, -np.inf)
        for t in range(ok.shape[0]):
            out[t, ok[t]] = score(a[t], n[t][ok[t]], b[t])
        return out
    return batched


def hidden_corner(a: np.ndarray, b: np.ndarray, sigma: float, ground_xy: np.ndarray,
                  score) -> np.ndarray | None:
    """The near corner hidden between the silhouette feet a and b (ground, (2,) each).

    If a and b are corners of a rectangular footprint whose corner n between them has no
    vertical edge, the angle a-n-b is right: n lies on the near half of the circle with
    diameter ab (Thales). Of ``_CORNER_ARC_POINTS`` candidates on that arc, those whose
    triangle a-n-b holds visible ground (a ground feature more than
    ``_FREE_SPACE_MARGIN_M`` inside: free space seen through it) are impossible; of the
    others the one whose contact polyline a-n-b the image's edges follow best
    (``score(a, n, b) -> (M,)``) is taken. None when the camera's foot is inside the
    circle, no candidate is possible, or the best one lies within ``_CORNER_SIGMAS``
    ``sigma`` (the feet's range sigma) of the chord ab: the straight face ab explains the
    image as well (a frontal face, no hidden corner). See `hidden_corners` (batched).
    """
    q = hidden_corners(np.asarray(a, np.float64)[None], np.asarray(b, np.float64)[None],
                       np.array([float(sigma)]), ground_xy, _single_score(score))[0]
    return None if np.isnan(q[0]) else q


def nearest_points(xy: np.ndarray, sr: np.ndarray, group: np.ndarray, n_groups: int,
                   ground_xy, score=None, at_border: np.ndarray | None = None
                   ) -> np.ndarray:
    """`nearest_point` of the feet of several obstacles at once (their hidden-corner
    searches batched, `hidden_corners`).

    Args:
        xy: (S, 2) ground coordinates of the feet, sr (S,) their range sigmas.
        group: (S,) obstacle of each foot, 0..n_groups-1.
        ground_xy: (G, 2) visible ground, or a callable returning it (called only when a
            search or `soft_nearest` needs it).
        score: batched contact-edge score (`hidden_corners`), or None (no search).
        at_border: (S,) bool, feet of strings at the image's left or right border.
    Returns:
        (n_groups, 2) ground coordinates of each obstacle's nearest point (NaN without
        feet).
    """
    out = np.full((n_groups, 2), np.nan)
    if xy.shape[0] == 0:
        return out
    if _nb_extremes is not None and _nb_soft_args is not None:
        return _nearest_points_compiled(xy, sr, group, n_groups, ground_xy, score,
                                        at_border)
    order = np.argsort(group, kind='stable')
    g_s = group[order]
    first = np.searchsorted(g_s, np.arange(n_groups), side='left')
    last = np.searchsorted(g_s, np.arange(n_groups), side='right')
    brg_all = np.arctan2(xy[:, 1], xy[:, 0])
    r_all = np.hypot(xy[:, 0], xy[:, 1])
    search, pair, soft = [], [], []

    for k in range(n_groups):
        sel = order[first[k]:last[k]]
        if sel.size == 0:
            continue
        if sel.size == 1:
            out[k] = xy[sel[0]]
            continue
        brg, r, s = brg_all[sel], r_all[sel], sr[sel]
        i, j = int(np.argmax(brg)), int(np.argmin(brg))
        kk = int(np.argmin(r))
        # A foot between the outermost ones and clearly nearer than both is the near
        # corner (a foot on a frontal face, e.g. of a texture stripe, is not clearly nearer).
        seen = kk not in (i, j) and (min(r[i], r[j]) - r[kk]
                                     > _CORNER_SIGMAS * math.hypot(s[kk], max(s[i], s[j])))
        border = at_border is not None and bool(at_border[sel[i]] or at_border[sel[j]])
        if score is not None and not seen and not border and i != j:
            search.append(k)
            pair.append((sel[i], sel[j], float(max(s[i], s[j]))))
        else:
            soft.append(k)
    if search:
        ii, jj, sg = (np.array(x) for x in zip(*pair))
        q = hidden_corners(xy[ii], xy[jj], sg, ground_xy, score)
        for k, qk in zip(search, q):
            if np.isnan(qk[0]):
                soft.append(k)
                continue
            # A corner beyond the nearest foot is not the nearest point (two bodies
            # in one cluster: the corner of the far one, the near one's foot nearer).
            sel = order[first[k]:last[k]]
            qs = soft_nearest(xy[sel], sr[sel], ground_xy)
            out[k] = qk if np.hypot(*qk) <= np.hypot(*qs) else qs
    for k in soft:
        sel = order[first[k]:last[k]]
        out[k] = soft_nearest(xy[sel], sr[sel], ground_xy)
    return out


def _extremes_kernel(group, n_groups, brg, r):
    """Per group of feet (for numba): the number of feet, and the feet of largest and
    smallest bearing and of smallest range, (n_groups,) int64 each (-1 for none): the
    first of equals, or the first NaN, as ``np.argmax`` / ``np.argmin`` over the group's
    feet in order."""
    count = np.zeros(n_groups, np.int64)
    i_max = np.full(n_groups, -1, np.int64)
    i_min = np.full(n_groups, -1, np.int64)
    i_near = np.full(n_groups, -1, np.int64)
    for p in range(group.shape[0]):
        k = group[p]
        if count[k] == 0:
            i_max[k] = i_min[k] = i_near[k] = p
        else:
            b, bm = brg[p], brg[i_max[k]]
            if not math.isnan(bm) and (math.isnan(b) or b > bm):
                i_max[k] = p
            if _nb_first_min(brg, p, i_min[k]):
                i_min[k] = p
            if _nb_first_min(r, p, i_near[k]):
                i_near[k] = p
        count[k] += 1
    return count, i_max, i_min, i_near


_nb_extremes = _jit(_extremes_kernel)


def _nearest_points_compiled(xy: np.ndarray, sr: np.ndarray, group: np.ndarray,
                             n_groups: int, ground_xy, score,
                             at_border: np.ndarray | None) -> np.ndarray:
    """`nearest_points` with its per-obstacle loop compiled (`_extremes_kernel`) and the
    soft nearest points of all obstacles at once (`_soft_nearest_groups`): the same
    tests and arithmetic, so the same points (S >= 1 feet)."""
    out = np.full((n_groups, 2), np.nan)
    group = np.asarray(group, np.int64)
    brg_all = np.arctan2(xy[:, 1], xy[:, 0])
    r_all = np.hypot(xy[:, 0], xy[:, 1])
    count, i, j, kk = _nb_extremes(group, n_groups, brg_all, r_all)
    single = count == 1
    out[single] = xy[i[single]]
    multi = count > 1
    # A foot between the outermost ones and clearly nearer than both is the near corner
    # (a foot on a frontal face, e.g. of a texture stripe, is not clearly nearer).
    seen = np.zeros(n_groups, bool)
    for k in np.flatnonzero(multi & (kk != i) & (kk != j)).tolist():
        ri, rj, rk = r_all[i[k]], r_all[j[k]], r_all[kk[k]]
        si, sj, sk = sr[i[k]], sr[j[k]], sr[kk[k]]
        seen[k] = min(ri, rj) - rk > _CORNER_SIGMAS * math.hypot(sk, max(si, sj))
    search = multi & ~seen & (i != j)
    if at_border is not None:
        search &= ~(at_border[np.maximum(i, 0)] | at_border[np.maximum(j, 0)])
    if score is None:
        search[:] = False
    soft = multi & ~search
    found = np.zeros(n_groups, bool)
    ks = np.flatnonzero(search)
    if ks.size:
        ii, jj = i[ks], j[ks]
        si, sj = sr[ii], sr[jj]
        q = hidden_corners(xy[ii], xy[jj], np.where(sj > si, sj, si).astype(np.float64),
                           ground_xy, score)
        hit = ~np.isnan(q[:, 0])
        soft[ks[~hit]] = True
        found[ks[hit]] = True
        qk = np.full((n_groups, 2), np.nan)
        qk[ks[hit]] = q[hit]
    qs = _soft_nearest_groups(xy, sr, group, n_groups, soft | found, ground_xy)
    out[soft] = qs[soft]
    if found.any():
        # A corner beyond the nearest foot is not the nearest point (two bodies in one
        # cluster: the corner of the far one, the near one's foot nearer).
        f = np.flatnonzero(found)
        nearer = np.hypot(qk[f, 0], qk[f, 1]) <= np.hypot(qs[f, 0], qs[f, 1])
        out[f] = np.where(nearer[:, None], qk[f], qs[f])
    return out


def nearest_point(xy: np.ndarray, sr: np.ndarray, ground_xy: np.ndarray,
                  score=None, at_border: np.ndarray | None = None) -> np.ndarray:
    """The nearest point on the ground of an obstacle from the feet of its edge strings.

    Args:
        xy: (S, 2) ground coordinates of the feet (`string_feet`), S >= 1.
        sr: (S,) their range sigmas, metres.
        ground_xy: (G, 2) visible ground (ground features).
        score: the contact-edge score ``score(a, n, b) -> (M,)``
            (`_FrameContext.contact_edge_score`), or None to skip the hidden-corner search.
        at_border: (S,) bool, feet of strings at the image's left or right border (the
            view's edge, not the obstacle's silhouette: no hidden corner next to them).
    Returns:
        (2,) ground coordinates: the nearest foot when it lies between the outermost
        feet in bearing and is clearly (``_CORNER_SIGMAS``) nearer than both (the near
        corner is seen; `soft_nearest`); else the hidden corner between the outermost
        feet, if there is one (`hidden_corner`); else `soft_nearest` of the feet.
        See `nearest_points` (batched).
    """
    return nearest_points(xy, sr, np.zeros(xy.shape[0], np.int64), 1, ground_xy,
                          None if score is None else _single_score(score), at_border)[0]


def _fit_line(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Total least squares line through ground points p (N, 2), metres: (centroid (2,),
    unit direction (2,), (N,) coordinates along it from the centroid, orthogonal RMS
    residual)."""
    c = p.mean(axis=0)
    _, sv, vt = np.linalg.svd(p - c, full_matrices=False)
    d = vt[0]
    return c, d, (p - c) @ d, float(sv[1]) / math.sqrt(p.shape[0])


def _ground_across_line(ground: np.ndarray, c: np.ndarray, d: np.ndarray, a: np.ndarray,
                        b: np.ndarray) -> tuple[int, int, int, int, int, float, float]:
    """Visible ground on either side of the ground line through ``c`` along unit ``d``,
    within the bearings of its points ``a`` and ``b`` ((2,) each, metres): the numbers of
    ground features (G, 2) more than ``_FACE_BEHIND_M`` in front of it (the camera's side)
    and behind it, of all features within those bearings, and of those in front and
    behind within ``_FACE_BAND_M`` of the line; then the last two again, each feature
    weighted by its range (so that
    evenly seen ground counts the same near and far: within a wedge of bearings, clear
    pavement gives 0.71-0.86 times as many features per band 1 m behind a line 2.5-5.5 m
    ahead as 1 m in front of it, and 0.98-1.03 times the range-weighted sum)."""
    b0, b1 = math.atan2(a[1], a[0]), math.atan2(b[1], b[0])
    bg = np.arctan2(ground[:, 1], ground[:, 0])
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
    front) are separate objects in a row, not a face. The point is given unless visible ground lies behind
    the extended line within that wedge of bearings (``_FACE_BEHIND_MIN`` and ``_FACE_BEHIND_FRACTION``
    of its ground features beyond the line by ``_FACE_BEHIND_M``: then the face ends
    inside the view).

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
    for k in np.flatnonzero(counts >= _FACE_MIN_FEET):
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
        t = np.linspace(0.0, span, 65)[1:]
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
            fine = pts[j - 1][None] + np.linspace(0.0, 1.0, 33)[:, None] * (pts[j] - pts[j - 1])
            uf, vf = to_image(fine)
            inside = (uf >= 0.0) & (uf <= width - 1) & (vf <= height - 1)
            q = fine[max(int(np.argmin(inside)) - 1, 0)]
        if np.hypot(*q) >= np.hypot(*e) - 1e-6:
            continue
        if ground is None:
            ground = ground_xy() if callable(ground_xy) else ground_xy
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
        if any(_seen_through(*_ground_across_line(ground, c, d, a, b)[3:]) for a, b in spans):
            continue
        # Visible ground behind the extension shows the face ends before the view's edge.
        _, n_behind, n_wedge, *_ = _ground_across_line(ground, c, d, e, q)
        if _ground_behind(n_behind, n_wedge):
            continue
        out[k] = q
    return out


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
        radius: metres along the ground (``part_radius_m``).
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
        mine = np.flatnonzero(owner == k)
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
    hides = _nb_face_hides if _nb_face_hides is not None else _face_hides_kernel
    for k in range(n_groups):
        mine = group == k
        h = float(height[k])
        if not (0.0 < h <= _LONE_MAX_HEIGHT_M) or not mine.any() or at_border[mine].any():
            continue
        f = xy[mine]
        if np.ptp(f[:, 0]) > _LONE_SPREAD_M or np.ptp(f[:, 1]) > _LONE_SPREAD_M:
            continue        # more than one silhouette: the corner searches place it
        foot = q[k]
        if np.min(np.hypot(f[:, 0] - foot[0], f[:, 1] - foot[1])) > _LONE_SPREAD_M:
            continue        # placed elsewhere already (a face out of the view, a gap)
        # Only a face that runs towards the camera's side can bring the point nearer.
        phi = _LONE_PHI[np.cos(_LONE_PHI) * foot[0] + np.sin(_LONE_PHI) * foot[1] < 0.0]
        if phi.size == 0:
            continue
        points, ev, sep, shift = ctx.outline_evidence(foot, h, phi)
        bar = max(_LONE_BAR * float(np.median(ev.mean(axis=1))), noise_floor)
        gain = np.cumsum(ev - bar, axis=1)
        end = np.argmax(gain, axis=1)
        rows = np.arange(ev.shape[0])
        support = gain[rows, end]
        ok = ((support > 0.0) & ((end + 1) * _LONE_STEP_M >= _LONE_MIN_M)
              & (np.median(sep, axis=1) >= _LONE_MIN_SEP_PX)
              & (np.median(sep / np.maximum(shift, 1e-9), axis=1)
                 >= _LONE_MIN_SEP_FRACTION))
        # each face's nearest point to the camera (the foot, its end, or between)
        ends = points[rows, end]
        d = ends - foot
        t = np.clip(-(d @ foot) / np.maximum(np.einsum('ij,ij->i', d, d), 1e-12), 0.0, 1.0)
        near = foot + t[:, None] * d
        ok &= np.hypot(near[:, 0], near[:, 1]) <= math.hypot(*foot) - _LONE_MIN_GAIN_M
        best = None
        for j in np.flatnonzero(ok)[np.argsort(-support[ok], kind='stable')]:
            if g_all is None:
                g_all = np.ascontiguousarray(ctx.ground_xy, np.float64).reshape(-1, 2)
            if not hides(float(ends[j, 0]), float(ends[j, 1]), 0.0,
                         np.ascontiguousarray(foot[None]), np.zeros(1), g_all, h / cam_h,
                         _FREE_SPACE_MARGIN_M, _FACE_HIDDEN_MIN):
                best = near[j]                  # the best supported face that hides no
                break                           # visible ground
        if best is not None:
            out[k] = best
    return out


def face_gap_points(xy: np.ndarray, group: np.ndarray, n_groups: int, q: np.ndarray,
                    ground_xy) -> np.ndarray:
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
    for t in np.flatnonzero(ok):
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
        if ground.shape[0] == 0:
            continue
        n_front, n_behind, n_wedge, *band = _ground_across_line(
            ground, ct, d, ct + lo_t * d, ct + hi_t * d)
        # Near the line, the ground behind the gap seen about as densely as in front of
        # it: two objects with a way between them (a bollard and a wall 3.6 m apart once
        # made a "face" 6 m away), not one face.
        if (n_front < _FACE_BEHIND_MIN or _ground_behind(n_behind, n_wedge)
                or _seen_through(*band)):
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
        radius: metres (``GpodConfig.cluster_radius_m``).
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
    if _nb_owners is not None:
        # The same tests, compiled (numpy's bearings: its atan2 differs in last bits).
        xw = np.ascontiguousarray(xw, np.float64)
        xy = np.ascontiguousarray(xy, np.float64)
        return _nb_owners(xw, np.asarray(top, np.float64), xy, np.asarray(g_lab, np.int64),
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
        mine = np.flatnonzero(lab == k)
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


def _owners_kernel(xw, top, xy, g_lab, height, radius, cam_h, sw, sf, bw, bf, g_all):
    """`silhouette_owners` (for numba), with its tests and arithmetic; ``bw``, ``bf``
    (W,), (S,) the bearings of the candidates and feet (numpy's arctan2), ``g_all``
    (G, 2) the visible ground.

    Returns:
        (W,) int64 obstacle of each candidate, -1 for none.
    """
    w_n, s_n = xw.shape[0], xy.shape[0]
    m_ = _FREE_SPACE_MARGIN_M
    lab = np.full(w_n, -1, np.int64)
    for w in range(w_n):
        best, j = np.inf, 0
        tp = top[w]
        for q in range(s_n):
            hk = height[g_lab[q]]
            d = math.hypot(xw[w, 0] - xy[q, 0], xw[w, 1] - xy[q, 1])
            if (d <= radius and tp * _WEAK_HEIGHT_RATIO >= hk and tp <= _WEAK_HEIGHT_RATIO * hk
                    and d < best):
                best, j = d, q
        if best < np.inf:
            lab[w] = g_lab[j]
    out = np.full(w_n, -1, np.int64)
    n_k = 0
    for w in range(w_n):
        n_k = max(n_k, lab[w] + 1)
    for k in range(n_k):
        # its feet, their bearings' extremes, its candidates
        n_f = 0
        b_hi, b_lo = -np.inf, np.inf
        for q in range(s_n):
            if g_lab[q] == k:
                n_f += 1
                b_hi = max(b_hi, bf[q])
                b_lo = min(b_lo, bf[q])
        if n_f == 0:
            continue
        f = np.empty((n_f, 2))
        sf_k = np.empty(n_f)
        n_f = 0
        for q in range(s_n):
            if g_lab[q] == k:
                f[n_f, 0], f[n_f, 1] = xy[q, 0], xy[q, 1]
                sf_k[n_f] = sf[q]
                n_f += 1
        for sgn in (1.0, -1.0):
            # the candidates beyond the feet on this side, outermost first (stable)
            side = np.empty(w_n, np.int64)
            n_side = 0
            for w in range(w_n):
                if lab[w] != k:
                    continue
                tol = m_ / max(math.hypot(xw[w, 0], xw[w, 1]), 1e-9)
                if (bw[w] > b_hi + tol) if sgn > 0 else (bw[w] < b_lo - tol):
                    side[n_side] = w
                    n_side += 1
            # outermost first: by -sgn * bearing, stably (insertion sort; a few each)
            for t in range(1, n_side):
                w, kw = side[t], -sgn * bw[side[t]]
                q = t
                while q > 0 and -sgn * bw[side[q - 1]] > kw:
                    side[q] = side[q - 1]
                    q -= 1
                side[q] = w
            for t in range(n_side):
                w = side[t]
                if n_f >= 2 and _nb_separated(xw[w, 0], xw[w, 1], f, g_all, m_):
                    continue
                if _nb_face_hides(xw[w, 0], xw[w, 1], sw[w], f, sf_k, g_all,
                                  height[k] / cam_h, m_, _FACE_HIDDEN_MIN):
                    continue
                out[w] = k
                break
    return out


def _face_hides_kernel(wx, wy, sw, f, sf, g_all, h_ratio, margin, need):
    """Whether ``need`` or more ground points of g_all (G, 2) would be hidden by a body
    standing on the segments from w = (wx, wy) to the points f (F, 2), of height
    ``h_ratio`` times the camera's (for numba; ground coordinates from the point below
    the camera, metres; ``sw``, ``sf`` (F,) the range sigmas of w and f).

    The camera's ray to a ground point g at range r passes below the height h at
    horizontal distances beyond r (1 - h / H). A vertical face on a segment w-p that the
    ray crosses there, between r (1 - h / H) + ``margin`` and r - ``margin`` - sigma
    (the larger range sigma of w and p: where the face is) and more than ``margin`` from
    both of the segment's ends, hides g. A body whose footprint holds w and p (convex:
    its silhouette edge at w) holds the segment.
    """
    if g_all.shape[0] == 0 or f.shape[0] == 0 or not h_ratio > 0.0:
        return False
    # bearing and range window of the points that can be behind a segment
    b_lo = b_hi = math.atan2(wy, wx)
    r_lo = r_hi = math.hypot(wx, wy)
    for i in range(f.shape[0]):
        b = math.atan2(f[i, 1], f[i, 0])
        r = math.hypot(f[i, 0], f[i, 1])
        b_lo, b_hi = min(b_lo, b), max(b_hi, b)
        r_lo, r_hi = min(r_lo, r), max(r_hi, r)
    r_hi = r_hi / max(1.0 - h_ratio, 1e-6)
    count = 0
    for p in range(g_all.shape[0]):
        gx, gy = g_all[p, 0], g_all[p, 1]
        rg = math.hypot(gx, gy)
        if not (rg > r_lo and rg < r_hi + margin):      # rg > r_lo >= 0
            continue
        bg = math.atan2(gy, gx)
        if not (bg > b_lo and bg < b_hi):
            continue
        ux, uy = gx / rg, gy / rg
        s_lo = rg * (1.0 - h_ratio) + margin
        for i in range(f.shape[0]):
            s_hi = rg - margin - max(sw, sf[i])
            if not s_lo < s_hi:
                continue
            ex, ey = f[i, 0] - wx, f[i, 1] - wy
            den = ux * ey - uy * ex                 # cross(u, e)
            le = math.hypot(ex, ey)
            if abs(den) < 1e-12 or le <= 2.0 * margin:
                continue
            s_c = (wx * ey - wy * ex) / den         # cross(w, e) / cross(u, e)
            t_c = (wx * uy - wy * ux) / den         # cross(w, u) / cross(u, e)
            if (s_c > s_lo and s_c < s_hi and t_c * le > margin
                    and (1.0 - t_c) * le > margin):
                count += 1
                break
        if count >= need:
            return True
    return False


_nb_face_hides = _jit(_face_hides_kernel)


def _separated_kernel(wx, wy, f, g_all, margin):
    """`_separated` (for numba): whether a ground point of g_all (G, 2) lies more than
    ``margin`` inside a triangle w-p-q, p, q two of the points f (F, 2) (`_ground_inside`'s
    arithmetic, triangles a = p, n = w, b = q)."""
    if g_all.shape[0] == 0:
        return False
    lo0, lo1, hi0, hi1 = wx, wy, wx, wy
    for i in range(f.shape[0]):
        lo0, hi0 = min(lo0, f[i, 0]), max(hi0, f[i, 0])
        lo1, hi1 = min(lo1, f[i, 1]), max(hi1, f[i, 1])
    lo0, lo1, hi0, hi1 = lo0 - margin, lo1 - margin, hi0 + margin, hi1 + margin
    for p in range(g_all.shape[0]):
        gx, gy = g_all[p, 0], g_all[p, 1]
        if not (gx >= lo0 and gx <= hi0 and gy >= lo1 and gy <= hi1):
            continue
        for i in range(f.shape[0]):
            ax, ay = f[i, 0], f[i, 1]
            for j in range(i + 1, f.shape[0]):
                bx, by = f[j, 0], f[j, 1]
                area2 = (wx - ax) * (by - ay) - (wy - ay) * (bx - ax)
                if not abs(area2) > 1e-12:
                    continue
                sgn = 1.0 if area2 > 0 else -1.0
                if _nb_inside_by(ax, ay, wx, wy, bx, by, gx, gy, sgn, margin):
                    return True
    return False


_nb_separated = _jit(_separated_kernel)
_nb_owners = (_jit(_owners_kernel) if _nb_separated is not None and _nb_face_hides is not None
              else None)


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


class _Pass(NamedTuple):
    """One detector pass over a pair (`GpodDetector._frame_pass`)."""

    status: str
    updated: bool
    metric: MetricPlane | None
    features: GpodFeatures
    detections: tuple[GpodObstacle, ...]
    threshold: float
    el: EdgeMap
    er: EdgeMap
    still: bool
    timings: dict[str, float]
    #: the camera's motion since the previous pair as `GpodDetector.process` takes it
    #: (a callable resolved once the plane was calibrated), or None
    motion: tuple | None = None


def _state_metric(cam: StereoCamera, abc: np.ndarray) -> MetricPlane | None:
    """The metric plane of a plane state (a, b, c): any plane below the camera, however
    high or tilted (None: not below the camera, or not finite)."""
    return plane_is_plausible(cam, abc, min_height_m=0.0, max_height_m=float('inf'),
                              max_tilt_deg=90.0)


def _still_motion(motion: tuple) -> bool:
    """Whether a camera motion (R (3, 3), t (3,) m, ...) is small enough for a rig seen
    standing still: |t| <= 2 cm and a rotation of at most 1 degree."""
    return (float(np.linalg.norm(np.asarray(motion[1], float))) <= _STILL_MAX_TRANSLATION_M
            and float(np.linalg.norm(so3_log(motion[0]))) <= _STILL_MAX_ROTATION_RAD)


def bin_pair(left: np.ndarray, right: np.ndarray, cam: StereoCamera
             ) -> tuple[np.ndarray, np.ndarray, StereoCamera]:
    """A rectified pair binned 2 x 2, and its camera.

    Each binned pixel is the mean of a 2 x 2 block (an odd last row or column is dropped),
    so a faint texture's gradient per pixel doubles while the pixel noise halves. The
    binned pixel (i, j) is centred on the full-size point (2 i + 0.5, 2 j + 0.5): f
    halves and the principal point moves to ((cx - 0.5) / 2, (cy - 0.5) / 2), so points
    triangulated in the binned pair lie in the same left optical frame, metres.

    Args:
        left, right: (H, W) uint8 rectified images, H, W >= 2.
        cam: their camera.
    Returns:
        (left, right) (H // 2, W // 2) uint8, and the binned camera.
    """
    h, w = cam.height // 2, cam.width // 2
    if h < 1 or w < 1:
        raise ValueError(f'cannot bin a {cam.width}x{cam.height} pair 2 x 2')
    out = tuple(cv2.resize(np.ascontiguousarray(img[:2 * h, :2 * w]), (w, h),
                           interpolation=cv2.INTER_AREA) for img in (left, right))
    cam_b = dataclasses.replace(cam, f=cam.f / 2.0, cx=(cam.cx - 0.5) / 2.0,
                                cy=(cam.cy - 0.5) / 2.0, width=w, height=h)
    return out[0], out[1], cam_b


#: The binned pass: a full-size matched pixel within this of twice a binned pixel's
#: disparity agrees with it, pixels (`_coarse_consistent`).
_COARSE_AGREE_PX = 2.0


def _disparity_image(f: GpodFeatures, cam: StereoCamera) -> np.ndarray:
    """(H, W) float32 disparity of the matched left edge pixels at their rounded column,
    NaN elsewhere, pixels."""
    out = np.full((cam.height, cam.width), np.nan, np.float32)
    col = np.clip(np.rint(f.u_left).astype(np.int64), 0, cam.width - 1)
    out[f.v.astype(np.int64), col] = f.d
    return out


def _coarse_consistent(ob: GpodObstacle, coarse: GpodFeatures, fine_d: np.ndarray) -> bool:
    """Whether the full-size matches do not contradict a binned-pass obstacle.

    Each of the obstacle's binned pixels (u, v, d) (those beyond the threshold on its
    edge strings) is looked up in the full-size pair at rows 2v, 2v + 1 and columns
    within 2 of 2u + 0.5. It agrees when there are full-size matches there and all have
    a disparity within ``_COARSE_AGREE_PX`` of 2d; it is contradicted when one does not
    (the full-size pass, with finer neighbours to tell them apart, matched the edge
    elsewhere, or the place is ambiguous: a door's edge matched both to itself and to a
    pole a period off). A faint surface leaves most of its pixels unmatched at full
    size: neither.

    Args:
        ob: a detection of the binned pass; coarse: that pass's features.
        fine_d: (H, W) the full-size pass's `_disparity_image`.
    Returns:
        False when more of its pixels are contradicted than agree.
    """
    sel = np.isin(coarse.string_id, ob.string_ids) & (coarse.is_obstacle | coarse.is_drop)
    if not sel.any():
        return True
    h, w = fine_d.shape
    u = np.rint(2.0 * coarse.u_left[sel] + 0.5).astype(np.int64)
    v = 2 * coarse.v[sel].astype(np.int64)
    d = 2.0 * coarse.d[sel].astype(np.float64)
    rows = np.clip(v[:, None] + np.array([0, 1])[None, :], 0, h - 1)[:, :, None]   # (k, 2, 1)
    cols = np.clip(u[:, None] + np.arange(-2, 3)[None, :], 0, w - 1)[:, None, :]   # (k, 1, 5)
    vals = fine_d[rows, cols].reshape(len(d), -1)                                 # (k, 10)
    seen = np.isfinite(vals)
    with np.errstate(invalid='ignore'):
        bad = (seen & ~(np.abs(vals - d[:, None]) <= _COARSE_AGREE_PX)).any(axis=1)
    agree = seen.any(axis=1) & ~bad
    return int(bad.sum()) <= int(agree.sum())


class GpodDetector:
    """The GPOD obstacle detector with ground-plane calibration and per-frame refit.

    Call :meth:`process` on every rectified stereo pair, in order. The detector keeps
    the ground plane between frames; it resets itself when the camera changes, and
    :meth:`reset` starts a new calibration.
    """

    def __init__(self, config: GpodConfig | None = None) -> None:
        self.config = config if config is not None else GpodConfig()
        _warm_up()
        c = self.config
        #: the rig's vertical misalignment (a property of the cameras: kept over resets
        #: of the detector, restarted by a new camera)
        self.alignment = VerticalAlignment(AlignmentConfig(
            enabled=c.align_vertical, every_frames=c.align_every_frames,
            apply_min_px=c.align_apply_px))
        self.reset()

    def reset(self) -> None:
        """Forget the ground plane and the calibration frames (status 'initialising')."""
        self._cam: StereoCamera | None = None
        self._rng = np.random.default_rng(self.config.seed)
        self._init_window: deque = deque(maxlen=self.config.init_frames)
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
        #: the plane before this frame's motion (None: no motion this frame)
        self._unmoved: MetricPlane | None = None
        #: residual spread of the initial fit: global, and per edge strength (bin
        #: strengths, bin sigmas), pixels
        self._sigma = float('nan')
        self._sigma_bins: tuple[np.ndarray, np.ndarray] | None = None
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
        self._noise_gain = gradient_noise_gain(self.config.edge_blur_sigma)
        #: obstacle_min_strength in force (raised on a noisy camera)
        self._min_strength = self.config.obstacle_min_strength
        #: the current left image and the current frame's context for describing obstacles
        self._left: np.ndarray | None = None
        self._ctx: _FrameContext | None = None
        #: the ground surface ahead of the latest pair (surface_enabled), or None
        self._surface: GroundSurface | None = None
        c = self.config
        self._tracker = ObstacleTracker(coast_s=c.track_coast_s, gate_chi2=c.track_gate_chi2,
                                        process_noise_m=c.track_process_noise_m,
                                        confirm_hits=c.track_confirm_hits,
                                        min_hit_fraction=c.track_min_hit_fraction,
                                        sure_hits=c.track_sure_hits,
                                        unseen_coast_s=c.track_unseen_coast_s)
        #: track id -> (the detection confidences of its latest track_confidence_frames
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
        self._log_gains: deque = deque(maxlen=max(self.config.right_gain_frames, 1))
        #: the detector of the binned pass (`_with_coarse`), made on its first pair
        self._coarse: GpodDetector | None = None
        #: the corridor's ground edge pixels expected, and its bands gone unseen
        self._unseen = (UnseenGroundMonitor(c.unseen_max_ratio, c.unseen_min_expected,
                                            c.unseen_frames, c.unseen_range_m,
                                            c.unseen_half_width_m)
                        if c.unseen_max_ratio > 0 else None)

    @property
    def calibrated_plane(self) -> PlaneFit | None:
        """The plane fitted on the calibration frames, or None while initialising."""
        return self._calib

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

    def _fit(self, u, v, d, cam: StereoCamera, min_support: float = 0.0) -> PlaneFit | None:
        """Robust, plausibility-checked plane fit of features (u, v, d) with the settings
        (``min_support``: least fraction of the features on a RANSAC hypothesis)."""
        c = self.config
        # Weighted by disparity cubed: of two competing surfaces (the ground here and the
        # ground beyond a step), the nearer one is the one the wearer stands on; far
        # features, least flat and least well measured, count little.
        return fit_ground_plane(
            u, v, d, cam=cam, method=c.plane_method, inlier_threshold_px=c.plane_inlier_px,
            iterations=c.ransac_iterations, weights=np.maximum(d, 0.0) ** 3,
            min_features=c.min_plane_features, min_spread_px=c.plane_min_spread_px,
            min_support_fraction=min_support, rng=self._rng, **c.plausibility())

    def _near_calibration(self, fit: PlaneFit) -> bool:
        """Whether an ungated refit is close enough to the calibrated plane to trust."""
        c = self.config
        cal = self._calib.metric if self._calib is not None else None
        if cal is None or fit.metric is None:
            return False
        if abs(fit.metric.height - cal.height) > c.recover_height_tolerance * cal.height:
            return False
        cosang = float(np.clip(np.dot(fit.metric.normal_up, cal.normal_up), -1.0, 1.0))
        return math.degrees(math.acos(cosang)) <= c.recover_max_angle_deg

    def _predict_plane(self, cam: StereoCamera, motion: tuple) -> bool:
        """Carry the plane state (and the plane the rig stopped with) through the camera's
        motion (R, t, ...) since the previous frame: x = f(x), P = F P F^T
        (`ground_plane.predict_plane`); the plane before it is kept as ``_unmoved``.
        False, with nothing changed, when it cannot."""
        r = predict_plane(cam, self._abc, motion[0], motion[1])
        if r is None:
            return False
        R, t = np.asarray(motion[0], float), np.asarray(motion[1], float)
        self._unmoved = _state_metric(cam, self._abc)
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
            max_h, max_a = c.motion_max_height_change_m, c.motion_max_angle_change_deg
        else:
            max_h, max_a = c.refit_max_height_change_m, c.refit_max_angle_change_deg
        if cur is None:
            cur = _state_metric(cam, self._abc)
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
        cosang = float(np.clip(np.dot(plane.normal_up, ref.normal_up), -1.0, 1.0))
        return math.degrees(math.acos(cosang)) <= max_a

    @property
    def sigma_px(self) -> float:
        """Robust (MAD) spread of the disparity residuals of the initial ground-plane fit,
        pixels (NaN while initialising)."""
        return self._sigma

    def _window_shares_plane(self, joint: PlaneFit, cam: StereoCamera) -> bool:
        """Whether the calibration window's frames all lie on the plane ``joint`` fitted
        to them together: each frame's own plane (least squares from ``joint``, refitted
        on its features within ``plane_inlier_px``, weighted as `_fit` weights them)
        differs from it by at most ``plane_inlier_px`` over the image's lower half, and
        the frame's residual spread about ``joint`` (robust sigma within ``_SIGMA_GATE *
        plane_inlier_px``) is at most ``_WINDOW_SIGMA_RATIO`` times that about its own.
        Deterministic (draws nothing from the detector's random generator). A frame
        whose own plane cannot be fitted counts as not sharing it."""
        tol = self.config.plane_inlier_px
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
        return res, np.abs(res) <= _SIGMA_GATE * self.config.plane_inlier_px

    def _calibrate_sigma(self, u, v, d, s) -> None:
        """Residual spread of the calibration features about the calibrated plane.

        ``sigma_px``: one robust sigma (1.4826 * MAD) over the features within
        ``_SIGMA_GATE * plane_inlier_px`` of the plane. For ``sigma_per_edge``: sigmas in
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
        if c.threshold_mode == 'fixed' or not np.isfinite(self._sigma):
            return np.full(k, c.threshold_px), c.threshold_px
        ceiling = self.threshold_ceiling()
        glob = float(np.clip(c.threshold_k * self._sigma, c.threshold_floor_px, ceiling))
        if not c.sigma_per_edge or self._sigma_bins is None:
            return np.full(k, glob), glob
        log_s, sig_b, v_b, f_b = self._sigma_bins
        log_p = np.log(np.maximum(precision.astype(np.float64), 1e-3))
        sig = np.interp(log_p, log_s, sig_b)
        # Below the least precise bin, sigma grows as 1 / precision.
        sig *= np.exp(np.maximum(log_s[0] - log_p, 0.0))
        if v is not None:
            sig = sig * np.interp(v, v_b, f_b)
        thr = np.clip(c.threshold_k * sig, c.threshold_floor_px, ceiling)
        return thr, glob

    def min_obstacle_pixels(self, cam: StereoCamera) -> float:
        """Obstacle pixels an edge string needs on this camera: ``min_obstacle_pixels``
        times f / ``min_obstacle_pixels_focal_px`` (rounded), at least
        ``min_obstacle_pixels``: the same angle of evidence on any rig."""
        c = self.config
        if c.min_obstacle_pixels_focal_px <= 0.0:
            return float(c.min_obstacle_pixels)
        return float(max(c.min_obstacle_pixels,
                         round(c.min_obstacle_pixels * cam.f / c.min_obstacle_pixels_focal_px)))

    def threshold_ceiling(self) -> float:
        """The largest obstacle threshold of the 'sigma' mode, pixels: the larger of
        ``threshold_ceiling_px`` and the disparity excess ``f*B*h/(H*z)`` of an obstacle
        ``threshold_ceiling_height_m`` high at depth ``threshold_ceiling_depth_m`` for the
        calibrated camera height H (the paper's rig: 1.7 px and 1.68 px; the KITTI car's:
        4.7 px). ``threshold_ceiling_px`` alone before the calibration."""
        c = self.config
        cal = self._calib.metric if self._calib is not None else None
        if (c.threshold_ceiling_height_m <= 0.0 or cal is None or self._cam is None
                or not cal.height > 0.0):
            return c.threshold_ceiling_px
        excess = (self._cam.fb * c.threshold_ceiling_height_m
                  / (cal.height * c.threshold_ceiling_depth_m))
        return max(c.threshold_ceiling_px, float(excess))

    def _update_plane(self, u, v, d, s, cam: StereoCamera, still: bool = False,
                      motion: tuple | None = None) -> tuple[str, bool]:
        """Advance the plane state with this frame's features (s: their
        :func:`_noise_key`, for the residual spread; ``still``: the rig stood still since
        the previous frame; ``motion``: the camera's (R, t, ...) since the previous frame,
        as `process` takes it, or None). Returns (status, updated)."""
        c = self.config
        if self._calib is None:
            self._init_window.append((u, v, d, s))
            if len(self._init_window) < c.init_frames:
                return 'initialising', False
            uu, vv, dd, ss = (np.concatenate(x) for x in zip(*self._init_window))
            # No plane is known yet: the ground must hold init_min_inlier_fraction of the
            # features to be a candidate at all (not only the winner checked below), so
            # that the disparity weighting cannot crown a few wrong matches at large
            # disparity, which a long baseline searched from min_range_m gives.
            support = c.init_min_inlier_fraction
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
                # from the joint plane does not.
                last = self._fit(u, v, d, cam, support)
                if last is not None and (
                        not _planes_agree(fit.abc, last.abc, cam, c.plane_inlier_px)
                        or not self._window_shares_plane(fit, cam)):
                    fit, uu, vv, dd, ss = last, u, v, d, s
            if fit.num_features < c.init_min_inlier_fraction * uu.shape[0]:
                return 'initialising', False
            self._calib = self._last_fit = fit
            self._abc, self._cov = fit.abc.copy(), fit.cov.copy()
            self._calibrate_sigma(uu, vv, dd, ss.astype(np.float64))
            self._init_window.clear()
            return 'tracking', True
        enough = u.shape[0] >= c.min_plane_features
        if c.plane_update == 'fixed':
            # The plane is known, but a frame with too few features cannot vouch that
            # nothing stands on it: lost, as in 'refit' mode.
            return ('tracking', False) if enough else ('lost', False)
        fit = None
        # Kalman predict: through the camera's motion when it is known (the paper's
        # dynamic recalibration), else the constant-plane model below. While the rig
        # stands still (its edges stayed in place) a motion larger than a standing
        # wearer's sway can only be an error: the identity instead (a wrong one carried
        # the plane the rig stopped with off the ground for as long as the wearer stood).
        self._unmoved = None
        if motion is not None and still and not _still_motion(motion):
            motion = (np.eye(3), np.zeros(3))
        predicted = motion is not None and self._predict_plane(cam, motion)
        current = _state_metric(cam, self._abc)
        # moving: the plane the rig stopped with is kept, carried through the motion,
        # while the camera is still near where it stopped (on the same ground)
        if not still and not (predicted and self._still_plane is not None
                              and self._still_travel <= c.still_anchor_travel_m):
            self._still_plane = None
        elif self._still_plane is None:
            self._still_plane = current             # the plane when the rig stopped
            self._still_travel = 0.0
        anchored = self._still_plane is not None
        # Refits near the prediction through the motion: a narrower gate and tighter
        # change limits, unless refits were rejected by those limits max_coast_frames
        # times in a row (the motion may be wrong: then as without one, around the
        # predicted plane). With a motion the plane is carried through frames with too
        # few ground features to refit for up to motion_coast_frames.
        # A plane carried unrefitted over a frame whose motion was missing has not moved
        # with the camera over that frame: its prediction through the later motions is
        # off by that frame's motion (a vigorous walker's sway: 10 px of disparity). It
        # gets neither the narrow gate nor the long coast until a refit has found the
        # ground again (it coasted at most max_coast_frames, then recovers).
        tight = predicted and not self._stale and self._rejected < c.max_coast_frames
        gate_m = c.motion_gate_m if tight else c.refit_gate_m
        coast_frames = (c.motion_coast_frames if predicted and not self._stale
                        else c.max_coast_frames)
        rejected = False

        def coarse_then_fine(gate_px: float = c.refit_gate_px) -> PlaneFit | None:
            # Coarse refit from the nearer half of the features near the predicted plane
            # in disparity (a gate wide enough for walking motion), then a fine refit
            # from all features near the coarse plane in disparity *and* metric height,
            # so that another surface (the ground beyond a step, a kerb top) cannot
            # take over.
            nonlocal rejected
            gate = np.abs(d - plane_disparity(self._abc, u, v)) <= gate_px
            if gate.any():      # the coarse fit sees only the nearer half: the ground here
                gate &= d >= _median(d[gate])      # (np.median's arithmetic, finite d)
            coarse = self._fit(u[gate], v[gate], d[gate], cam)
            out = None
            if coarse is not None:
                height = coarse.metric.signed_height(cam.triangulate(u, v, d))
                gate = ((np.abs(d - plane_disparity(coarse.abc, u, v)) <= gate_px)
                        & (np.abs(height) <= gate_m))
                out = self._fit(u[gate], v[gate], d[gate], cam)
            if out is not None and not self._close_to_current(out, cam, current, tight):
                out, rejected = None, True
            return out

        if enough and current is not None and not anchored:
            fit = coarse_then_fine()
        if enough and current is not None and fit is None:
            # Standing still the current plane is where the ground is: refit from the
            # features within refit_gate_m of it. So too when the coarse fit took another
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
            fit = self._fit(u[gate], v[gate], d[gate], cam)
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
                and self._coast < coast_frames and c.refit_retry_gate_px > c.refit_gate_px):
            # Nothing predicted where the ground went: a vigorous walker (the paper's
            # extreme motion: 5 degrees of sway) moves the ground by 10 px of disparity
            # between frames, and a frame whose /egomotion is missing then kept the
            # previous frame's plane, 10 px off, and reported the whole ground as a drop.
            # (Not once lost: the plane to widen the gate around is then stale.)
            fit = coarse_then_fine(c.refit_retry_gate_px)
        if fit is None and enough and self._coast >= coast_frames:
            # Lost: recover from the nearer half of the features (the ground the wearer
            # stands on, rather than the ground beyond a step) if the result is near the
            # calibration.
            near = d >= np.median(d)
            ungated = self._fit(u[near], v[near], d[near], cam)
            if ungated is not None and self._near_calibration(ungated):
                fit = ungated
        noise = c.motion_process_noise_px if predicted else c.refit_process_noise_px
        sq = noise ** 2
        q = np.diag([sq / (0.5 * cam.width) ** 2, sq / (0.5 * cam.height) ** 2, sq])
        if fit is None:
            self._rejected = self._rejected + 1 if rejected else 0
            self._stale = self._stale or not predicted
            if self._coast < coast_frames and enough and (
                    predicted or still or self._near_ground_agrees(u, v, d)):
                self._coast += 1
                if predicted:
                    self._cov = self._cov + q
                return 'tracking', False
            # stay lost until a refit succeeds
            self._coast = max(c.max_coast_frames, c.motion_coast_frames)
            return 'lost', False
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
        self._coast = self._rejected = 0
        self._stale = False
        return 'tracking', True

    def _near_ground_agrees(self, u: np.ndarray, v: np.ndarray, d: np.ndarray) -> bool:
        """Whether the current plane may be carried, unconfirmed by a refit, over a frame
        of a walk with no motion to carry it by (u, v, d: (N,) the frame's features,
        pixels; "near": the half with d at least the median).

        It may if it still lies on the near features (their median disparity residual
        within ``plane_inlier_px``), or if they stand above it as a surface that is not
        the ground (an obstacle filling the near view: their disparity does not grow
        down the image as the plane's does), or if there are fewer than twice
        ``min_plane_features`` of them (a plain wall filling the view leaves a few
        mismatches). Not if they lie below it (the near view is the ground the wearer
        stands on, or an obstacle on it: never lower; the plane is off and every
        feature a drop) or above it as a ground (the plane is too low: every feature an
        obstacle)."""
        near = d >= _median(d)
        un, vn, dn = u[near], v[near], d[near]
        if un.shape[0] < 2 * self.config.min_plane_features:
            return True
        res = dn - plane_disparity(self._abc, un, vn)
        med = _median(res)
        if abs(med) <= self.config.plane_inlier_px:
            return True
        if med < 0:
            return False
        return bool(_robust_row_slope(un, vn, dn) < 0.5 * float(self._abc[1]))

    # ------------------------------------------------------------------ main
    def process(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                stamp_ns: int | None = None,
                motion: tuple | Callable[[], tuple | None] | None = None) -> GpodResult:
        """Detect obstacles in one rectified stereo pair.

        Args:
            left, right: (H, W) uint8 rectified grey images, H = cam.height, W = cam.width.
            cam: the rectified stereo camera. A camera different from the previous
                call's resets the detector.
            stamp_ns: the pair's time, ns (for the obstacle tracks' coasting time); None:
                frames ``track_frame_period_s`` apart.
            motion: the left camera's motion from the previous pair to this one, the
                obstacle tracks' input: (R (3, 3), t (3,)) or (R, t, cov (3, 3) of t, m²),
                ``X_prev = R X_curr + t`` (metres, left optical frames; `/egomotion`'s
                convention). None: the identity while the rig stands still (its edges
                stay in place), unknown otherwise (the tracks end). A callable returning
                one of these is called after the detection, before the tracks are updated
                (so a node can wait for the motion while the detector works).
        Returns:
            The GpodResult (status 'initialising', 'tracking' or 'lost').
        Raises:
            ValueError: images that are not 2-D uint8 arrays of the camera's size.
        """
        t_start = time.perf_counter()
        self._begin(left, right, cam)
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
            stamp_s = (self._frame * c.track_frame_period_s if stamp_ns is None
                       else stamp_ns * 1e-9)
            if callable(motion):            # the frame that completed the calibration
                motion = motion()
            obstacles = self._track(detections, stamp_s, p.still, cam, metric, motion)
            unseen = self._unseen_ground(p.features, p.threshold, cam, metric,
                                         detections + obstacles)
            if unseen:
                detections = tuple(sorted(detections + unseen, key=lambda o: o.range))
                obstacles = tuple(sorted(obstacles + unseen, key=lambda o: o.range))
        else:
            self._tracker.reset()
            self._last_motion = None
            if self._unseen is not None:
                self._unseen.reset()
        t4 = time.perf_counter()
        timings['obstacles'] = timings.get('obstacles', 0.0) + (t4 - t3) * 1e3
        timings['total'] = (t4 - t_start) * 1e3
        have_plane = status == 'tracking'
        al = self.alignment
        fit = self._last_fit
        return GpodResult(
            status=status, frame_index=self._frame,
            plane_abc=self._abc.copy() if have_plane else None,
            plane_cov=self._cov.copy() if have_plane else None,
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
        edge_kw = dict(abs_threshold=self._edge_threshold(left),
                       rel_threshold=c.edge_rel_threshold,
                       max_angle_deg=c.edge_max_angle_deg, min_string_length=c.min_string_length,
                       blur_sigma=c.edge_blur_sigma)
        el = detect_vertical_edges(left, **edge_kw)
        er = detect_vertical_edges(right, **edge_kw)
        t1 = time.perf_counter()
        timings['edges'] = (t1 - t0) * 1e3

        d_min, d_max = self.disparity_range(cam)
        m, cand, _ = pmf_match(el, er, d_min, d_max,
                               min_strength_ratio=c.match_min_strength_ratio,
                               max_orientation_diff_deg=c.match_max_orientation_diff_deg,
                               support_radius=c.pmf_support_radius_px,
                               disparity_gradient_limit=c.pmf_disparity_gradient_limit,
                               iterations=c.pmf_iterations, min_support=c.pmf_min_support,
                               right_gain=self._right_gain(left, right))
        t2 = time.perf_counter()
        timings['matching'] = (t2 - t1) * 1e3

        u = m.u
        v = m.v.astype(np.float64)
        d = m.d.astype(np.float64)
        still = self._stillness(el)
        if callable(motion) and self._calib is not None:     # not while calibrating
            motion = motion()
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
            metric = _state_metric(cam, self._abc)
        threshold = self.pixel_thresholds(np.zeros(0))[1]
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
                       metric: MetricPlane, known: tuple[GpodObstacle, ...]
                       ) -> tuple[GpodObstacle, ...]:
        """The frame's band of unseen corridor ground (`core.unseen_ground`), unless an
        obstacle or drop-off in ``known`` at least ``unseen_explain_min_confidence``
        confident explains it, as unknown ground straight ahead: an untracked entry
        (``track_id`` 0) whose ``height`` is ``UNKNOWN_HEIGHT`` (NaN: ground that cannot
        be seen is not a thing; ``disparity_excess`` 0, ``num_edge_pixels`` 0;
        ``confidence`` 1 - seen / expected). Empty when there is none or
        ``unseen_max_ratio`` is 0."""
        if self._unseen is None:
            return ()
        # the known feet on the ground: (forward, left) from their range and bearing; a
        # weak report (a 4 cm blip at 0.08) would hide a wall from the wearer
        known = tuple(o for o in known
                      if o.confidence >= self.config.unseen_explain_min_confidence)
        explained = _ground_points(known) if known else None
        thr = features.threshold if features.threshold is not None else threshold
        r = self._unseen.update(cam, metric, features.u_left, features.v, features.excess,
                                thr, explained, left=self._left)
        if r is None:
            return ()
        u, v = cam.project_left(np.stack([r.position, r.position - r.height
                                          * metric.normal_up]))
        x0 = int(np.clip(np.floor(min(u)), 0, cam.width - 1))
        y0 = int(np.clip(np.floor(min(v)), 0, cam.height - 1))
        x1 = int(np.clip(np.ceil(max(u)), x0 + 1, cam.width))
        y1 = int(np.clip(np.ceil(max(v)), y0 + 1, cam.height))
        return (GpodObstacle(
            position=r.position, height=UNKNOWN_HEIGHT, range=r.range, bearing=0.0,
            width=r.width, disparity_excess=0.0,
            confidence=float(np.clip(1.0 - r.seen / r.expected, 0.0, 1.0)),
            roi=(x0, y0, x1 - x0, y1 - y0), num_edge_pixels=0,
            string_ids=np.zeros(0, np.int32)),)

    # ------------------------------------------------------------ binned pass
    def _coarse_wanted(self, cam: StereoCamera) -> bool:
        """Whether this camera's images are also searched binned 2 x 2
        (``coarse_min_width``)."""
        w = self.config.coarse_min_width
        return w > 0 and cam.width >= w and cam.height >= 2

    def _with_coarse(self, detections: tuple[GpodObstacle, ...], features: GpodFeatures,
                     left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                     metric: MetricPlane | None, motion: tuple | None = None
                     ) -> tuple[GpodObstacle, ...]:
        """The frame's detections joined by those of the binned pass that no full-size
        detection explains.

        The binned pass is a second detector (its own plane, threshold and noise
        estimates, no tracks) on the pair binned 2 x 2 (`bin_pair`). Its obstacles at least
        ``coarse_min_height_m`` high (drop-offs as deep) whose foot lies farther than
        ``part_radius_m`` from every full-size detection's foot join, their image regions
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
            self._coarse = GpodDetector(dataclasses.replace(c, coarse_min_width=0))
        lb, rb, cam_b = bin_pair(left, right, cam)
        self._coarse._begin(lb, rb, cam_b)
        p = self._coarse._frame_pass(lb, rb, cam_b, motion)
        if metric is None or not p.detections:
            return detections
        n = metric.normal_up
        feet = np.array([o.position - o.height * n for o in detections]).reshape(-1, 3)
        fine_d = None
        added = []
        for ob in p.detections:
            if abs(ob.height) < c.coarse_min_height_m:
                continue
            if fine_d is None:
                fine_d = _disparity_image(features, cam)
            if not _coarse_consistent(ob, p.features, fine_d):
                continue
            foot = ob.position - ob.height * n
            if len(feet):
                gap = feet - foot
                gap -= np.outer(gap @ n, n)            # along the ground
                if float(np.min(np.linalg.norm(gap, axis=1))) <= c.part_radius_m:
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
        median over the latest ``right_gain_frames`` pairs of the ratio of their grey-level
        spreads (`alignment.brightness_gain_offset`), within [1/4, 4]; 1 when disabled or
        before a pair with contrast."""
        if self.config.right_gain_frames == 0:
            return 1.0
        go = brightness_gain_offset(left, right)
        if go is not None:
            self._log_gains.append(math.log(min(max(go[0], 0.25), 4.0)))
        if not self._log_gains:
            return 1.0
        return math.exp(float(np.median(np.asarray(self._log_gains))))

    @property
    def image_noise_sigma(self) -> float:
        """The left image's pixel noise as last estimated (:func:`edges.image_noise_sigma`),
        grey levels (NaN before the first frame)."""
        return self._image_noise

    def _estimate_noise(self, left: np.ndarray) -> None:
        """Estimate the left image's pixel noise on the first frame and every
        ``_NOISE_EVERY`` frames after, and set the obstacle edge strength in force from it
        (``obstacle_min_edge_snr``)."""
        if (self._frame - 1) % _NOISE_EVERY:
            return
        c = self.config
        self._image_noise = image_noise_sigma(left)
        self._min_strength = max(c.obstacle_min_strength, c.obstacle_min_edge_snr
                                 * self._noise_gain * self._image_noise)

    def _edge_threshold(self, left: np.ndarray) -> float:
        """The edge threshold of this pair, grey levels per pixel: ``edge_threshold``,
        lowered on weakly textured ground (`edges.textured_edge_threshold`:
        ``edge_min_density``, ``edge_target_density``) to no less than
        ``edge_noise_floor_snr`` times the gradient noise; unchanged while the pixel noise
        is unknown."""
        c = self.config
        if not c.edge_min_density > 0 or not math.isfinite(self._image_noise):
            return c.edge_threshold
        floor = c.edge_noise_floor_snr * self._noise_gain * self._image_noise
        return textured_edge_threshold(left, c.edge_threshold, min_density=c.edge_min_density,
                                       target_density=c.edge_target_density, floor=floor,
                                       blur_sigma=c.edge_blur_sigma)

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
        if _nb_still is not None:
            # The same image and hits, compiled.
            use = prev is not None and prev.shape == (h, w + 2) and n > 0
            img, hits = _nb_still(prev if use else np.zeros((1, 1), bool), use, v, u_int,
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
        if _nb_temporal is not None:
            # The same neighbours, gate and sums, compiled.
            use = bool(still and self._acc is not None and lam > 0 and k)
            ps, pw = self._acc if use else (np.zeros((1, 1), np.float32),) * 2
            gate_thr = thr is not None and c.temporal_gate_thr > 0
            s_new, w_new, acc_s, acc_w = _nb_temporal(
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
                gate = c.temporal_gate_px
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

    def disparity_range(self, cam: StereoCamera) -> tuple[float, float]:
        """Disparity search range (d_min, d_max) of the matcher, pixels, from
        ``search_max_range_m`` and ``min_range_m`` (d_max at most the image width - 1)."""
        d_min = cam.fb / self.config.search_max_range_m
        d_max = min(cam.fb / self.config.min_range_m, float(cam.width - 1))
        return d_min, max(d_max, d_min)

    # ------------------------------------------------------------------ obstacles
    def _detect(self, m: Matches, u, v, d, cam: StereoCamera, metric: MetricPlane,
                d_min: float, d_max: float, el: EdgeMap, er: EdgeMap, cand: Candidates,
                still: bool) -> tuple[GpodFeatures, tuple[GpodObstacle, ...]]:
        c = self.config
        pd = plane_disparity(self._abc, u, v)
        pts = cam.triangulate(u, v, d)
        h = metric.signed_height(pts)
        self._surface = None
        if c.surface_enabled:
            # The reference of the obstacle test: the plane continued by the profile
            # ahead where features support it (core/ground_surface.py).
            surf = fit_ground_surface(pts, metric, surface_config(c))
            self._surface = surf
            if surf.bends:
                pd_surf = surf.disparity(cam, u, v)
                pd = np.where(np.isfinite(pd_surf), pd_surf, pd)
                h = surf.height_above(pts)
        excess = d - pd
        feet = pts - h[:, None] * metric.normal_up[None, :]
        ground_range = np.linalg.norm(feet + metric.height * metric.normal_up[None, :], axis=1)
        tol = c.string_disparity_tolerance_px
        nxt = None
        if _nb_runs is not None and type(tol) in (float, int) and len(m):
            # run_links, matched_run_length and smooth_along_runs in one compiled pass
            # (the same links, lengths and sums; the tolerance compared in single
            # precision, as numpy compares the float32 disparities with it).
            prev, run, smooth, nxt = _nb_runs(el.string_prev, m.left_index, m.d, len(el),
                                              np.float32(tol), int(c.string_window), excess)
        else:
            prev = run_links(el, m, tol)
            run = matched_run_length(el, m, tol, prev)
            smooth = smooth_along_runs(excess, prev, c.string_window)
        in_range = ground_range <= c.max_range_m
        thr, thr_global = self.pixel_thresholds(_noise_key(m), v)
        ex_mean = self._temporal_excess(m, smooth, still, el.shape, thr)
        # Figural continuity: a run of min_matched_run pixels at least, and longer for a
        # larger excess -- an edge standing on the ground rises by |b| px of excess per
        # row, so an excess E needs about E / |b| rows of it (a fraction of them, up to
        # max_required_run, must be matched in one run).
        slope = max(abs(float(self._abc[1])), 1e-3)
        need = np.clip(np.ceil(c.obstacle_run_fraction * np.abs(ex_mean) / slope),
                       c.min_matched_run, max(c.max_required_run, c.min_matched_run))
        reliable = run >= need
        usable = reliable & in_range
        obst = (ex_mean > thr) & (h <= c.max_obstacle_height_m) & usable
        below = (ex_mean < -thr) & (h >= -c.max_drop_depth_m)
        if obst.any():
            obst &= ~hanging_runs(el, m, prev, h, c.max_floating_height_m,
                                  c.string_disparity_tolerance_px, slope, obst,
                                  solid=run >= c.min_matched_run)
            obst &= ~floating_bottom_runs(m.string_id, m.v, prev, h, reliable & in_range,
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
        drop = np.zeros_like(obst)
        if c.detect_drops:
            # Below the plane where the plane itself is within the detection range.
            pd_far = cam.fb / c.max_range_m
            drop = below & (pd >= pd_far) & (pd <= d_max) & usable
        sid = m.string_id
        n_s = max(el.num_strings, int(sid.max()) + 1 if sid.size else 0)
        weight = self._evidence_weight(m.strength)
        min_px = self.min_obstacle_pixels(cam)
        if obst.any():
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
        n_obst = np.bincount(sid[obst], weights=weight[obst], minlength=n_s) + 1e-9
        n_drop = np.bincount(sid[drop], weights=weight[drop], minlength=n_s) + 1e-9
        obst_string = n_obst >= min_px
        if obst_string.any():
            # Obstacles stand on the ground: a string whose matched pixels all float
            # higher than max_floating_height_m above it is a mismatch (a distant pole
            # matched to the wrong edge), not an obstacle.
            low = np.full(n_s, np.inf)
            ok = reliable & in_range
            np.minimum.at(low, sid[ok], h[ok])
            obst_string &= low <= c.max_floating_height_m
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
        drop_string = ~obst_string & (n_drop >= c.min_drop_pixels)
        obst &= obst_string[sid]
        drop &= drop_string[sid]
        sclass = np.where(obst_string[sid], 1, np.where(drop_string[sid], -1, 0)).astype(np.int8)
        features = _features(m, excess.astype(np.float32), obst, drop, sclass,
                             ex_mean.astype(np.float32), thr.astype(np.float32))
        self._frame_thr = thr
        # Ground features: reliably matched edge pixels on the plane (free space).
        ground = (np.abs(ex_mean) <= thr) & usable & ~obst_string[sid]
        self._ctx = _FrameContext(cam=cam, metric=metric, abc=self._abc.copy(), u=u, v=v,
                                  pd=pd, excess_mean=ex_mean, sigma=thr / c.threshold_k,
                                  prev=prev, ground_points=pts[ground], left=self._left,
                                  u_left=m.u_left, usable=usable, nxt=nxt)
        if obst_string.any():
            # Candidate silhouette edges for placing detected obstacles (never obstacles):
            # strings neither obstacle, drop nor rejected as one (mismatch, repetitive
            # pattern, half-occlusion), consistently above the plane near the threshold:
            # reliably matched pixels above _WEAK_FRACTION of it, at least
            # _WEAK_MIN_PIXELS, whose mean excess is _WEAK_SIGMAS standard errors above
            # the plane (sum of z > K sqrt(n _WEAK_CORR)).
            weak = (usable & (ex_mean > _WEAK_FRACTION * thr) & (h <= c.max_obstacle_height_m)
                    & ~(obst_string | drop_string | (n_obst >= min_px))[sid])
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
                self._ctx.weak_start, self._ctx.weak_top = wi[head], top
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

        def is_free(ob: GpodObstacle, foot: np.ndarray) -> bool:
            roi = _moved_roi(ob, foot, n, cam, require_in_view=True) if moved else ob.roi
            return self._track_is_free(ob, foot, roi)
        # While the view stands still an obstacle's nearest visible point is one fixed
        # point, so a detection of the same obstacle placed elsewhere (its far corner when
        # one silhouette edge dips) keeps its track seen; in motion the nearest visible
        # part of a large obstacle moves with the view, and it does not. The detection
        # must not lie more than cluster_radius_m farther than the track: a nearer one
        # (boxes reported as one obstacle at the nearest) or a far corner may be the
        # same obstacle, but an obstacle seen metres beyond a track shows the track's
        # placement was wrong (a pole's foot once followed down a paving joint).
        radius = self.config.cluster_radius_m
        tracks = self._tracker.update(
            feet, cov, obst, is_free,
            (lambda a, b: _same_object(a, b, radius)) if still else None,
            lambda ob, foot: _below_view(cam, foot))
        out = list(drops)
        feet_t = np.array([tr.foot for tr in tracks]).reshape(-1, 3)
        rngs, brgs = ground_range_bearing(metric, feet_t)
        confs = self._track_confidences(tracks, still)
        for tr, rng_k, brg_k, conf in zip(tracks, rngs.tolist(), brgs.tolist(), confs):
            ob = tr.payload
            seen = tr.index >= 0
            roi = ob.roi if (seen or not moved) else _moved_roi(ob, tr.foot, n, cam)
            out.append(dataclasses.replace(
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
        (|t| / 2)² I, for at most ``track_motion_hold_frames`` pairs in a row; else None
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
        if self._motion_held >= self.config.track_motion_hold_frames:
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
        ``track_confidence_frames`` views, this frame's included when it was detected.
        A view is one frame, or a run of frames while the rig stands still (``still``:
        this frame saw what the previous one saw), which counts once, at its largest
        confidence: each view's evidence is taken as independent of the others', but a
        still view's frames repeat the same matches, their errors as well (a mismatch
        made by the scene repeats in every frame), and their noise is already averaged
        in the detection (``temporal_frames``). Forgets the tracks that ended."""
        k = self.config.track_confidence_frames
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
        pixel (``track_pixel_sigma_px`` in u and v, the ground's disparity noise) plus
        ``track_position_sigma_m``² (which point of the obstacle is nearest)."""
        c = self.config
        k = feet.shape[0]
        z = np.maximum(feet[:, 2], 1e-3)
        d = cam.fb / z
        sig_d = self._sigma if np.isfinite(self._sigma) else c.disparity_sigma_px
        # X = (u - cx) B / d + B / 2, Y = (v - cy) B / d, Z = f B / d (cyclopean u):
        # J = d(X, Y, Z)/d(u, v, d)
        J = np.zeros((k, 3, 3))
        J[:, 0, 0] = z / cam.f
        J[:, 1, 1] = z / cam.f
        J[:, 0, 2] = -(feet[:, 0] - cam.baseline / 2.0) / d
        J[:, 1, 2] = -feet[:, 1] / d
        J[:, 2, 2] = -z / d
        S = np.diag([c.track_pixel_sigma_px ** 2, c.track_pixel_sigma_px ** 2, sig_d ** 2])
        return (np.einsum('nij,jk,nlk->nil', J, S, J)
                + (c.track_position_sigma_m ** 2) * np.eye(3)[None])

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
            ``track_free_min_features`` reliably matched edge pixels on the ground plane
            (within half their threshold) where the obstacle would have stood out (the
            foot's disparity at least the threshold above the plane's), and three times
            as many as above it. A foot below the image (an obstacle walked up to) is
            free only by that evidence, from the part of its region still in view.
        """
        cam, ctx = self._cam, self._ctx
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
        return on_ground >= self.config.track_free_min_features and on_ground >= 3 * above

    def _ambiguous_strings(self, m: Matches, excess: np.ndarray, obst: np.ndarray,
                           cand: Candidates, el: EdgeMap, er: EdgeMap, threshold: float,
                           n_s: int) -> np.ndarray:
        """(n_s,) bool: edge strings whose obstacle pixels are well above the plane
        (> ``_AMBIGUOUS_EXCESS_PX``) but, for at least ``ambiguity_fraction`` of them,
        the left edge also had a candidate match on the ground (|excess| <= threshold):
        a repetitive pattern matched one period off."""
        on_ground = _ground_candidates(cand, el, er, self._abc, threshold)
        alt = obst & (excess > _AMBIGUOUS_EXCESS_PX) & on_ground[m.left_index]
        n_alt = np.bincount(m.string_id[alt], minlength=n_s)
        n_obst = np.bincount(m.string_id[obst], minlength=n_s)
        return n_alt >= self.config.ambiguity_fraction * np.maximum(n_obst, 1)

    def _clusters(self, idx: np.ndarray, sign: float, radius: float, min_pixels: int,
                  m: Matches, pts: np.ndarray, h: np.ndarray, excess: np.ndarray,
                  cam: StereoCamera, metric: MetricPlane) -> list[GpodObstacle]:
        """Cluster the selected pixels (by string, feet proximity) into obstacles; drop
        clusters of fewer than ``min_pixels`` pixels."""
        n_up = metric.normal_up
        p = pts[idx]
        hh = h[idx]
        feet = p - hh[:, None] * n_up[None, :]
        fwd = np.array([0.0, 0.0, 1.0]) - n_up[2] * n_up
        fwd /= np.linalg.norm(fwd)
        lft = _cross3(n_up, fwd)
        origin = -metric.height * n_up
        g = feet - origin[None, :]
        g2 = np.stack([g @ fwd, g @ lft], axis=1)
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
        ctx = self._ctx
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
        ctx = self._ctx
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
            # A drop is placed at the nearest visible part of the lower ground (just
            # beyond the brink, which hides the lower ground for a shadow's length):
            # each pixel's viewing ray, continued from where it meets the plane down to
            # the cluster's depth D (the median height), lands at r_ray (H + D) / H,
            # H the camera's height -- its row places it, not its noisy disparity. The
            # nearest: the pixel of rank _DROP_RANK.
            ctx = self._ctx
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
        if _nb_extent is not None and count.min() > 0:
            # The same extremes and string lists, compiled (one pass).
            lo_lat, hi_lat, exc, x0, x1, y0, y1, sid_u, sid_start = _nb_extent(
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


def _extent_kernel(label, n_c, g2, mx, my, norm, ex, ul, vv, sid, high):
    """The per-obstacle extremes of `GpodDetector._describe` (for numba), every group
    0..n_c-1 non-empty.

    Args:
        label: (N,) int64 obstacle of each pixel; g2 (N, 2) its foot on the ground, m;
            mx, my, norm (n_c,): each obstacle's median foot and its distance (>= 1e-9).
        ex: (N,) float64 disparity excess; ul (N,) float32 column, vv (N,) int32 row,
            sid (N,) int32 edge string of each pixel; high: obstacles (the largest
            excess), else drops (the smallest).
    Returns:
        lo_lat, hi_lat (n_c,) the extremes of the feet's lateral offset
        ``(y mx - x my) / norm``; exc (n_c,) the excess extreme; x0, x1 (n_c,) int64 the
        floor / ceil of the columns' extremes; y0, y1 (n_c,) int64 the rows' extremes;
        sid_u (U,) int32 each obstacle's strings, ascending, from sid_start (n_c + 1,).
    """
    lo_lat = np.full(n_c, np.inf)
    hi_lat = np.full(n_c, -np.inf)
    exc = np.empty(n_c)
    u_lo = np.empty(n_c, np.float32)
    u_hi = np.empty(n_c, np.float32)
    y0 = np.empty(n_c, np.int64)
    y1 = np.empty(n_c, np.int64)
    seen = np.zeros(n_c, np.bool_)
    for i in range(label.shape[0]):
        k = label[i]
        lat = (g2[i, 1] * mx[k] - g2[i, 0] * my[k]) / norm[k]
        if not seen[k]:
            seen[k] = True
            lo_lat[k] = hi_lat[k] = lat
            exc[k] = ex[i]
            u_lo[k] = u_hi[k] = ul[i]
            y0[k] = y1[k] = vv[i]
            continue
        lo_lat[k] = min(lo_lat[k], lat)
        hi_lat[k] = max(hi_lat[k], lat)
        exc[k] = max(exc[k], ex[i]) if high else min(exc[k], ex[i])
        u_lo[k] = min(u_lo[k], ul[i])
        u_hi[k] = max(u_hi[k], ul[i])
        y0[k] = min(y0[k], np.int64(vv[i]))
        y1[k] = max(y1[k], np.int64(vv[i]))
    x0 = np.empty(n_c, np.int64)
    x1 = np.empty(n_c, np.int64)
    for k in range(n_c):
        x0[k] = np.int64(math.floor(u_lo[k]))
        x1[k] = np.int64(math.ceil(u_hi[k]))
    # the distinct strings of each obstacle, ascending: the pixels by (obstacle, string)
    n_p = label.shape[0]
    sk = np.empty(n_p, np.int64)
    n_s = 0
    for i in range(n_p):
        sk[i] = sid[i]
        n_s = max(n_s, sk[i] + 1)
    by = _nb_stable_order(label, _nb_stable_order(sk, np.arange(n_p), n_s), n_c)
    sid_u = np.empty(n_p, np.int32)
    sid_start = np.zeros(n_c + 1, np.int64)
    n = 0
    for t in range(n_p):
        i = by[t]
        if t == 0 or label[i] != label[by[t - 1]] or sid[i] != sid[by[t - 1]]:
            sid_u[n] = sid[i]
            n += 1
            sid_start[label[i] + 1] = n
    for k in range(n_c):                  # (every obstacle has pixels)
        sid_start[k + 1] = max(sid_start[k + 1], sid_start[k])
    return lo_lat, hi_lat, exc, x0, x1, y0, y1, sid_u[:n].copy(), sid_start


_nb_extent = _jit(_extent_kernel)


def _ground_candidates(cand: Candidates, el: EdgeMap, er: EdgeMap, abc: np.ndarray,
                       threshold: float) -> np.ndarray:
    """(N_left,) bool: the left edges with a candidate match on the ground plane ``abc``
    (its disparity within ``threshold`` pixels of the plane's at the candidate's
    cyclopean position)."""
    if _nb_on_ground is not None and type(threshold) in (float, int):
        return _nb_on_ground(cand.left, cand.right, cand.d, el.u, el.v, er.u,
                             np.asarray(abc, np.float64), float(threshold), len(el))
    uc = 0.5 * (el.u[cand.left].astype(np.float64) + er.u[cand.right])
    exc_c = cand.d - plane_disparity(abc, uc, el.v[cand.left].astype(np.float64))
    on_ground = np.zeros(len(el), bool)
    on_ground[cand.left[np.abs(exc_c) <= threshold]] = True
    return on_ground


def _on_ground_kernel(c_left, c_right, c_d, u_l, v_l, u_r, abc, threshold, n_left):
    """`GpodDetector._ambiguous_strings`' left edges with a candidate match on the ground
    (for numba): (n_left,) bool, some candidate's disparity within ``threshold`` pixels
    of the plane ``abc`` at its cyclopean position (``(a u + b v) + c``, as
    `plane_disparity`)."""
    out = np.zeros(n_left, np.bool_)
    a, b, c = abc[0], abc[1], abc[2]
    for q in range(c_left.shape[0]):
        e = c_left[q]
        uc = 0.5 * (np.float64(u_l[e]) + np.float64(u_r[c_right[q]]))
        if abs(c_d[q] - (a * uc + b * np.float64(v_l[e]) + c)) <= threshold:
            out[e] = True
    return out


_nb_on_ground = _jit(_on_ground_kernel)


def _still_kernel(prev, use, v, u_int, h, w):
    """`GpodDetector._stillness` (for numba): the (h, w + 2) bool image of the edge
    pixels (rows ``v``, columns ``u_int`` + 1), and, when ``use``, how many of them were
    within one column of an edge pixel of ``prev`` (the previous frame's image)."""
    img = np.zeros((h, w + 2), np.bool_)
    hits = 0
    for i in range(v.shape[0]):
        r, c = v[i], u_int[i]
        img[r, c + 1] = True
        if use and (prev[r, c] or prev[r, c + 1] or prev[r, c + 2]):
            hits += 1
    return img, hits


def _temporal_kernel(v, u_left, excess, thr, gate_thr, gate_px, thr_factor, lam, use, ps,
                     pw, h, w):
    """`GpodDetector._temporal_excess` (for numba), with its arithmetic.

    Args:
        v: (K,) int32 rows, u_left (K,) float32 columns of the matches; excess (K,)
            float64 their (smoothed) excess, pixels.
        thr: (K,) float64 their thresholds, used when ``gate_thr``: the gate is
            ``min(gate_px, thr_factor * thr)``, else ``gate_px``.
        lam: the running average's decay; use: average with the previous sums ps, pw
            (h, w) float32 (the rig stood still).
    Returns:
        (K,) float64 sums and weights (the averaged excess is their ratio), and the new
        (h, w) float32 running sums and weights at the matches' pixels.
    """
    k = v.shape[0]
    s_new = excess.copy()
    w_new = np.ones(k)
    uu = np.empty(k, np.int64)
    for i in range(k):
        uu[i] = min(max(np.int64(np.rint(u_left[i])), 0), w - 1)
    if use:
        for i in range(k):
            r = v[i]
            # the largest previous weight at the column, left, right (the first of equals)
            best = min(max(uu[i], 0), w - 1)
            wb = pw[r, best]
            for dc in (-1, 1):
                col = min(max(uu[i] + dc, 0), w - 1)
                if not math.isnan(wb) and (math.isnan(pw[r, col]) or pw[r, col] > wb):
                    best, wb = col, pw[r, col]
            w0 = np.float64(wb)
            s0 = np.float64(ps[r, best])
            gate = gate_px
            if gate_thr:
                g = thr_factor * thr[i]
                if g < gate or math.isnan(g):
                    gate = g
            if w0 > 0 and abs(excess[i] - s0 / w0) <= gate:
                s_new[i] = s_new[i] + lam * s0
                w_new[i] = w_new[i] + lam * w0
    acc_s = np.zeros((h, w), np.float32)
    acc_w = np.zeros((h, w), np.float32)
    for i in range(k):
        acc_s[v[i], uu[i]] = np.float32(s_new[i])
        acc_w[v[i], uu[i]] = np.float32(w_new[i])
    return s_new, w_new, acc_s, acc_w


_nb_still = _jit(_still_kernel)
_nb_temporal = _jit(_temporal_kernel)


def _planes_agree(abc0: np.ndarray, abc1: np.ndarray, cam: StereoCamera,
                  tol_px: float) -> bool:
    """Whether two planes ``d = a*u + b*v + c`` ((3,) each) differ by at most ``tol_px``
    pixels of disparity over the image's lower half (where the ground is seen): at its
    four corners, the largest difference of a linear function."""
    uu = np.array([0.0, cam.width - 1.0, 0.0, cam.width - 1.0])
    vv = np.array([cam.cy, cam.cy, cam.height - 1.0, cam.height - 1.0])
    dd = np.asarray(abc0, float) - np.asarray(abc1, float)
    return bool(np.max(np.abs(dd[0] * uu + dd[1] * vv + dd[2])) <= tol_px)


def _brink_bearings(xy: np.ndarray, group: np.ndarray, bearing: np.ndarray) -> np.ndarray:
    """The bearing of the nearest point of each drop's brink, where it is a straight
    line: a kerb down is seen along its whole width at nearly one range, and the
    nearest visible lower ground lies at the foot of the perpendicular from the camera's
    foot to the line (or at the line's seen end nearer to it).

    Args:
        xy: (S, 2) ground points, metres: the nearest lower ground of each of the
            drops' edge strings near their nearest range.
        group: (S,) drop of each point, 0..len(bearing)-1.
        bearing: (G,) radians, the drops' bearings so far (kept where the points are
            fewer than ``_BRINK_MIN_POINTS``, span less than ``_BRINK_MIN_SPAN_M`` or
            lie off one line by more than ``_BRINK_MAX_RMS_M``).
    Returns:
        (G,) radians.
    """
    out = bearing.copy()
    counts = np.bincount(group, minlength=bearing.shape[0])
    for k in np.flatnonzero(counts >= _BRINK_MIN_POINTS):
        p = xy[group == k]
        n_all = p.shape[0]
        # The brink is the near boundary of the lower ground: a string that starts
        # beyond it (texture on the lower ground) is dropped and the line refitted
        # (most of the strings must stay: a scatter has no brink).
        for _ in range(3):
            c, d, _, rms = _fit_line(p)
            n_fit = p.shape[0]
            nrm = np.array([-d[1], d[0]])
            behind = math.copysign(1.0, float(nrm @ c)) * ((p - c) @ nrm)
            keep = behind <= _BRINK_MAX_RMS_M
            if keep.all() or np.count_nonzero(keep) < _BRINK_MIN_POINTS:
                break
            p = p[keep]
        # (after three trimmings the last fit's line with the points it kept)
        along = (p - c) @ d
        rms *= math.sqrt(n_fit / p.shape[0])
        if (keep.sum() < max(_BRINK_MIN_POINTS, _BRINK_MIN_KEPT * n_all)
                or float(along.max() - along.min()) < _BRINK_MIN_SPAN_M
                or rms > _BRINK_MAX_RMS_M):
            continue
        t = float(np.clip(-(c @ d), along.min(), along.max()))
        q = c + t * d
        out[k] = math.atan2(q[1], q[0])
    return out


def _same_object(a: GpodObstacle, b: GpodObstacle, radius: float = math.inf) -> bool:
    """Whether detection ``b`` may be track ``a``'s obstacle reported at another point:
    their image regions overlap by at least half the smaller one, and ``b`` lies no more
    than ``radius`` metres farther than ``a``."""
    if b.range - a.range > radius:
        return False
    ax, ay, aw, ah = a.roi
    bx, by, bw, bh = b.roi
    ix = min(ax + aw, bx + bw) - max(ax, bx)
    iy = min(ay + ah, by + bh) - max(ay, by)
    if ix <= 0 or iy <= 0:
        return False
    return ix * iy >= 0.5 * min(aw * ah, bw * bh)


def _below_view(cam: StereoCamera, foot: np.ndarray) -> bool:
    """Whether a foot ((3,) metres, left optical frame) is in front of the camera but
    projects below the left image's bottom row: ground nearer than the camera sees, where
    an obstacle the wearer walks up to goes (from about 1.4 m on the paper's rig)."""
    if foot[2] <= 1e-3:
        return False
    return float(cam.project_left(np.asarray(foot, float))[1][0]) > cam.height - 1


def _moved_roi(ob: GpodObstacle, foot: np.ndarray, normal_up: np.ndarray,
               cam: StereoCamera, require_in_view: bool = False
               ) -> tuple[int, int, int, int] | None:
    """The left-image region (x, y, w, h) of obstacle ``ob`` moved to stand on ``foot``
    ((3,) metres, left optical frame; ``normal_up`` the plane's unit normal): its region
    carried with its foot's image point and scaled about it by the change of depth, so
    that it keeps its place beside and above the foot (a foot placed off the obstacle's
    edges -- a wall's nearest point, the near one of two boxes -- must not drag the
    region off them); clipped to the image (at least 1 x 1). With ``require_in_view``,
    None when the moved region lies wholly outside the image (an obstacle walked up to,
    below the view)."""
    old_foot = ob.position - ob.height * normal_up
    ends = np.stack([old_foot, foot]).astype(float)
    ends[:, 2] = np.maximum(ends[:, 2], 1e-3)
    (u0, u1), (v0, v1) = cam.project_left(ends)
    scale = ends[0, 2] / ends[1, 2]
    x, y, w, h = ob.roi
    xa, xb = u1 + (x - u0) * scale, u1 + (x + w - 1 - u0) * scale
    ya, yb = v1 + (y - v0) * scale, v1 + (y + h - 1 - v0) * scale
    if require_in_view and (xb < 0 or xa > cam.width - 1 or yb < 0 or ya > cam.height - 1):
        return None
    x0 = int(np.clip(np.floor(xa), 0, cam.width - 1))
    x1 = int(np.clip(np.ceil(xb), 0, cam.width - 1))
    y0 = int(np.clip(np.floor(ya), 0, cam.height - 1))
    y1 = int(np.clip(np.ceil(yb), 0, cam.height - 1))
    return (x0, y0, max(x1 - x0 + 1, 1), max(y1 - y0 + 1, 1))


def _group_quantile(group: np.ndarray, x: np.ndarray, q: float, n_groups: int) -> np.ndarray:
    """``np.quantile(x[group == k], q)`` (linear interpolation) for k = 0..n_groups-1
    (NaN for an empty group)."""
    out = np.full(n_groups, np.nan)
    if x.size == 0:
        return out
    if _nb_group_quantile is not None:
        return _nb_group_quantile(np.asarray(group, np.int64), np.asarray(x, np.float64),
                                  float(q), n_groups)
    order = np.lexsort((x, group))
    g, xs = group[order], x[order]
    count = np.bincount(g, minlength=n_groups)
    start = np.cumsum(count) - count
    has = count > 0
    pos = q * (count[has] - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, count[has] - 1)
    frac = pos - lo
    s = start[has]
    out[has] = xs[s + lo] + (xs[s + hi] - xs[s + lo]) * frac
    return out


def _by_group(group, n_groups):
    """The rows of each group (for numba): (N,) int64 row indices by group, ascending
    within each (a stable counting sort), and (n_groups + 1,) int64 group starts."""
    start = np.zeros(n_groups + 1, np.int64)
    for g in group:
        start[g + 1] += 1
    for k in range(n_groups):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    rows = np.empty(group.shape[0], np.int64)
    for i in range(group.shape[0]):
        g = group[i]
        rows[fill[g]] = i
        fill[g] += 1
    return rows, start


def _group_quantile_kernel(group, x, q, n_groups):
    """`_group_quantile` (for numba): each group's values sorted, then numpy's linear
    interpolation between the order statistics at ``q * (count - 1)``."""
    out = np.full(n_groups, np.nan)
    rows, start = _nb_by_group(group, n_groups)
    for k in range(n_groups):
        c = start[k + 1] - start[k]
        if c == 0:
            continue
        xs = _nb_sorted(x[rows[start[k]:start[k + 1]]])
        pos = q * np.float64(c - 1)
        lo = np.int64(math.floor(pos))
        hi = min(lo + 1, c - 1)
        out[k] = xs[lo] + (xs[hi] - xs[lo]) * (pos - np.float64(lo))
    return out


def _sorted(x):
    """``np.sort(x)`` (for numba; one compiled sort that the kernels share)."""
    return np.sort(x)


_nb_by_group = _jit(_by_group)
_nb_sorted = _jit(_sorted)
_nb_group_quantile = _jit(_group_quantile_kernel) if _nb_by_group is not None else None


def _features(m: Matches, excess: np.ndarray, obst: np.ndarray | None = None,
              drop: np.ndarray | None = None, sclass: np.ndarray | None = None,
              excess_mean: np.ndarray | None = None,
              threshold: np.ndarray | None = None) -> GpodFeatures:
    """GpodFeatures of the matches (no pixel flagged when the flags are None)."""
    k = len(m)
    z = np.zeros(k, bool)
    return GpodFeatures(u_left=m.u_left, u_right=m.u_right, v=m.v, d=m.d, excess=excess,
                        is_obstacle=z if obst is None else obst,
                        is_drop=z.copy() if drop is None else drop,
                        string_class=np.zeros(k, np.int8) if sclass is None else sclass,
                        string_id=m.string_id, strength=m.strength,
                        excess_mean=excess if excess_mean is None else excess_mean,
                        threshold=threshold)


def _noise_key(m: Matches) -> np.ndarray:
    """What the disparity noise of a match is binned by for ``sigma_per_edge``: the
    precision of its edges' sub-pixel positions (their gradient curvature,
    ``Matches.precision``), or the edge strength when that is unknown."""
    return m.precision if m.precision is not None else m.strength


def _mad_sigma(x: np.ndarray) -> float:
    """Robust standard deviation, 1.4826 * median absolute deviation (NaN if empty)."""
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return float('nan')
    return float(1.4826 * np.median(np.abs(x - np.median(x))))
