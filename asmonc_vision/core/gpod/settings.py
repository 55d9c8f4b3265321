"""GPOD's settings: `GpodConfig`, grouped by stage (frozen, validated on construction;
config/detector.yaml under ``gpod.<group>.`` mirrors its defaults), and the frame statuses.

Each group is the settings of one stage of `docs/gpod.md`'s table (or of one named rule,
as ``bend``); a group's parameters are ``gpod.<group>.<name>`` in ROS.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..config import check_fields, group, param
from ..ground_plane import PlausiblePlaneConfig
from ..ground_surface import GroundSurfaceConfig
from ..surface_tracking import SurfaceTrackingConfig

#: Detector statuses (GroundPlane.msg: INITIALISING = 0, TRACKING = 1, LOST = 2).
STATUSES = ('initialising', 'tracking', 'lost')


@dataclass(frozen=True)
class ImageSettings:
    """GPOD stage 1: the images checked, the right camera's gain, the rig's vertical
    misalignment (``GpodConfig.image``)."""

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
    right_gain_frames: int = param(
        5, 'The right camera\'s gain relative to the left\'s (the ratio of the images\' '
        'grey-level spreads) is the median over this many latest pairs, and the matching\'s '
        'strength test compares edges on the left\'s scale: two cameras with their own '
        'exposure or gain otherwise fail it on true matches and pass it on wrong ones '
        '(0: the cameras are taken as alike)', range=(0, 100))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class EdgeSettings:
    """GPOD stage 2: vertical edges and edge strings (``GpodConfig.edges``)."""

    threshold: float = param(
        4.0, 'Least horizontal intensity gradient of a vertical edge, grey levels per pixel',
        range=(0.0, 255.0))
    rel_threshold: float = param(
        0.0, 'Least horizontal gradient as a multiple of the mean |dI/du| of the image '
        '(0 = off); the larger of the two thresholds applies', range=(0.0, 100.0))
    max_angle_deg: float = param(
        70.0, 'Largest angle of an edge from the vertical, degrees', range=(1.0, 90.0))
    blur_sigma: float = param(
        0.0, 'Gaussian pre-blur of the images before the Sobel operator, pixels (0 = none)',
        range=(0.0, 10.0))
    min_density: float = param(
        8.0, 'Weakly textured ground: where the lower half of the left image (the near '
        'ground) has fewer vertical-edge candidates at threshold than this many times '
        '120 (this many per row of the paper\'s 320 x 240 image, whatever the image size: a '
        'ground plane needs as many edges, not as dense), the threshold of both images is '
        'lowered for that pair to keep target_density times 120 of them, but not below '
        'noise_floor_snr times the gradient noise (asphalt, plain concrete and large '
        'flags otherwise give too few edges for a ground plane, or a plane through chance '
        'matches); 0 = never lower', range=(0.0, 1000.0))
    target_density: float = param(
        24.0, 'Vertical-edge candidates (times 120, as min_density) in the lower half '
        'of the left image that a threshold lowered by min_density keeps (at least '
        'min_density)', range=(0.0, 1000.0))
    noise_floor_snr: float = param(
        2.5, 'The least edge threshold that min_density may lower to, in units of the '
        "image's gradient noise (the deviation of |dI/du| that the left image's estimated "
        'pixel noise gives)', range=(0.0, 100.0))
    min_string_length: int = param(
        3, 'Edge strings shorter than this many pixels are dropped', range=(1, 100000))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.target_density < self.min_density:
            raise ValueError(f'EdgeSettings.target_density = {self.target_density} must be at '
                             f'least min_density = {self.min_density}')


@dataclass(frozen=True)
class MatchSettings:
    """GPOD stage 3: row-wise PMF matching of the edges (``GpodConfig.matching``)."""

    min_strength_ratio: float = param(
        0.5, 'Least ratio of the weaker to the stronger edge strength of a match',
        range=(0.0, 1.0))
    max_orientation_diff_deg: float = param(
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
    min_range_m: float = param(
        1.0, 'Nearest depth searched by the matcher, metres along the optical axis '
        '(largest disparity f*B/min_range)', range=(0.05, 100.0))
    search_max_range_m: float = param(
        1000.0, 'Farthest depth searched by the matcher, metres (smallest disparity '
        'f*B/this); keep it far beyond detection.max_range_m so that distant features find their '
        'true match rather than a wrong one inside the range', range=(0.1, 1.0e6))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.min_range_m >= self.search_max_range_m:
            raise ValueError(f'MatchSettings.min_range_m = {self.min_range_m} must be less '
                             f'than search_max_range_m = {self.search_max_range_m}')


@dataclass(frozen=True)
class PlaneSettings(PlausiblePlaneConfig):
    """GPOD stage 4: the ground plane: calibration, refits, prediction through the motion, the
    Kalman filter, the gravity prior (``GpodConfig.plane``)."""

    init_frames: int = param(
        3, 'Frames, assumed obstacle-free, whose features calibrate the initial ground '
        'plane (accumulated, fitted robustly)', range=(1, 1000))
    init_min_inlier_fraction: float = param(
        0.1, 'The initial ground plane is taken only if at least this fraction of the '
        'calibration features lie on it (the ground is a large part of any view the rig '
        'starts in; a plane through a few per cent of them is a chance consensus of '
        'mismatches, as on ground with no clear edges); 0 = any', range=(0.0, 1.0))
    init_max_step_m: float = param(
        0.3, "When the calibration window's frames disagree, the latest frame's own plane "
        'calibrates (weighted by disparity cubed: of two grounds a kerb or a step apart, the '
        'nearer, the one the wearer stands on), unless it and the joint plane put the '
        'camera more than this far apart in height: no kerb or step lies between such '
        'grounds, one is a wrong consensus (a short line of near mismatches), and the one '
        "holding more of the latest frame's features (each counted once, within inlier_px) "
        "calibrates, metres; 0 = always the frame's own", range=(0.0, 10.0))
    init_near_share: float = param(
        0.15, 'The nearest this share of the calibration features (the largest '
        'disparities on the calibrated plane) must not lie above it on a parallel plane '
        'at most init_max_step_m higher: if they do, the calibrated plane is the lower '
        'ground beyond a drop just ahead, whose features outnumber the strip the wearer '
        'stands on, and that parallel plane calibrates instead; 0 = no test',
        range=(0.0, 0.5))
    init_max_height_sd_m: float = param(
        0.03, 'The initial ground plane is taken only if its features fix the camera '
        'height to this standard deviation (first order, from the fit\'s covariance), '
        'metres: features in one band across the image (the joints of a kerb across a '
        'plain pavement) leave the plane free to turn about them, and a plane through '
        'them is any plane; 0 = any', range=(0.0, 10.0))
    init_max_tilt_deg: float = param(
        20.0, "The initial ground plane is taken only if its upward normal lies within this "
        "angle of the pair's up direction from the inclinometer (when one is given): the "
        'ground a pedestrian starts on is no steeper than a ramp, while a plane through '
        "the edges of a wall or a kerb can lie at any angle (the chest rig's binned pass "
        'took one 76 degrees off the ground), degrees; 0 = no test', range=(0.0, 90.0))
    update: str = param(
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
    method: str = param(
        'ransac', 'Robust plane fit: RANSAC then least squares on the inliers, or '
        'iteratively trimmed least squares', choices=('ransac', 'trimmed'))
    inlier_px: float = param(
        1.0, 'Inlier bound of the robust plane fit, pixels of disparity', range=(0.05, 20.0))
    min_spread_px: float = param(
        3.0, 'A plane fit is taken only if its inliers spread at least this far across '
        'their main direction in the image (standard deviation along the minor axis), '
        'pixels: features along one line, such as the only joint of smooth slabs, leave '
        'the plane free to turn about it; 0 = any', range=(0.0, 1000.0))
    ransac_iterations: int = param(
        1000, 'Most RANSAC hypotheses per plane fit (it stops earlier once 99% sure)',
        range=(1, 100000))
    min_features: int = param(
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
    refit_hold_height: bool = param(
        True, "'refit': each refit keeps the camera height of the anchor (the median of the "
        'calibrated height and the free heights of the latest height_anchor_frames refits) '
        "and fits the plane's orientation alone: the wearer carries the rig at a steady "
        'height while it pitches and rolls with the gait, and a free fit to a narrow band '
        'of far ground (a chest rig looking level sees the ground from 3 m) trades height '
        'against pitch, so that a chain of them walks the plane onto the ground beyond a '
        'drop')
    hold_min_height_sd_m: float = param(
        0.015, "'refit', refit_hold_height: a refit is held at the anchor height only when "
        'its own camera height is this uncertain or more (standard deviation by the fit '
        'covariance, metres): a rig that sees the ground from near its feet fits the '
        'height to millimetres and follows it freely', range=(0.0, 100.0))
    height_anchor_frames: int = param(
        50, "'refit', refit_hold_height: the free heights (least squares on the held "
        "refit's inliers) of this many latest refits taken join the calibrated height in "
        'the anchor', range=(0, 100000))
    recover_max_height_change_m: float = param(
        0.1, "'refit': when lost (gated refits failed for longer than max_coast_frames), "
        'an ungated refit is accepted only if its camera height is within this of the '
        'calibrated height or of the anchor height (the median of the calibrated height '
        'and the free heights of the latest refits): the wearer carries the rig at a '
        'steady height above the ground underfoot, and a plane at another height is the '
        'ground beyond a kerb, a drop or a bend, metres', range=(0.001, 100.0))
    recover_max_angle_deg: float = param(
        25.0, "'refit': ... and its normal within this angle of the calibrated normal, "
        'degrees', range=(0.0, 90.0))
    gravity_prior_deg: float = param(
        3.0, "The angle scale of the prior that the inclinometer's up direction "
        "(`process`'s ``up``) puts on the ground's orientation in the calibration's plane "
        'fit: a plane whose upward normal is this far from it costs as much as '
        'gravity_prior_cost of the features off it (RANSAC score and final least '
        'squares), degrees; 0 = no prior', range=(0.0, 90.0))
    gravity_prior_cost: float = param(
        0.0, 'The cost of a plane gravity_prior_deg from the up direction, a fraction of '
        "the features (by weight): features that leave the ground's tilt free (a plain "
        'floor, obstacle edges filling the view) cannot tilt the plane, well-spread '
        'ground features on a slope outweigh it; 0 = no prior (off: 0.02 halved the false '
        'alarm events of the 90 tuning walks, but on the 60 held-out walks it warned a box '
        'late and added two false alarms, docs/ground.md)', range=(0.0, 100.0))
    gravity_prior_max_age_s: float = param(
        0.25, "An inclinometer sample is a pair's up direction only if stamped at most "
        "this long from the pair's stamp, s", range=(0.0, 10.0))
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
    seed: int = param(0, 'Seed of the random generator of the robust plane fit',
                      range=(0, 2 ** 31 - 1))


@dataclass(frozen=True)
class ThresholdSettings:
    """GPOD stage 4: the obstacle threshold on the disparity excess (``GpodConfig.threshold``)."""

    px: float = param(
        1.7, 'Disparity excess over the ground plane above which an edge pixel is an '
        'obstacle, pixels (Molton et al. 1998 use 1.7)', range=(0.05, 50.0))
    mode: str = param(
        'sigma', "'fixed': an edge pixel is an obstacle pixel when its disparity excess is "
        "above px (the paper's rule); 'sigma': above k times the robust "
        '(MAD) spread sigma of the disparity residuals of the initial ground-plane fit (the '
        "paper's Fig. 4 reasoning), kept within floor_px .. ceiling_px",
        choices=('fixed', 'sigma'))
    k: float = param(
        3.5, "'sigma': the obstacle threshold in units of the residual spread sigma",
        range=(0.5, 50.0))
    floor_px: float = param(
        0.5, "'sigma': least obstacle threshold, pixels", range=(0.05, 50.0))
    ceiling_px: float = param(
        1.7, "'sigma': largest obstacle threshold, pixels (or the disparity excess of "
        'ceiling_height_m at ceiling_depth_m, if larger)',
        range=(0.05, 50.0))
    ceiling_height_m: float = param(
        0.1, "'sigma': the largest obstacle threshold is at least the disparity excess "
        'f*B*h/(H*z) of an obstacle this high (h, metres) at ceiling_depth_m (z) '
        'for the camera height H of the calibrated plane: on a rig with a longer baseline '
        'or focal length than the paper\'s, the ground\'s unevenness spreads over more '
        'pixels, and so does the obstacle the ceiling keeps in view; 0 = '
        'ceiling_px alone', range=(0.0, 1.0))
    ceiling_depth_m: float = param(
        5.0, "'sigma': the depth of ceiling_height_m, metres", range=(0.5, 100.0))
    sigma_per_edge: bool = param(
        True, "'sigma': take sigma per edge pixel rather than one for all: the residual "
        'spread of the initial fit in bins of the precision of the edges (gradient '
        'curvature at the maximum: contrast and sharpness; blurred or faint edges are '
        'located less well), times a factor per band of image rows (the far ground '
        'matches less well)')

    def __post_init__(self) -> None:
        check_fields(self)
        if self.floor_px > self.ceiling_px:
            raise ValueError(f'ThresholdSettings.floor_px = {self.floor_px} must not exceed '
                             f'ceiling_px = {self.ceiling_px}')


@dataclass(frozen=True)
class TemporalSettings:
    """GPOD stage 5: the disparity excess averaged over frames while the rig stands still
    (``GpodConfig.temporal``)."""

    frames: int = param(
        5, 'While the rig stands still, the disparity excess of each edge pixel is averaged '
        'over about this many consecutive frames (exponentially weighted) before the '
        'threshold test; 1 = no averaging. Any motion restarts the average',
        range=(1, 1000))
    still_overlap: float = param(
        0.8, 'The rig counts as still when at least this fraction of the left edge pixels '
        'lie within one column of an edge pixel of the previous frame on the same row (the '
        'edges as strong as obstacle evidence needs, when there are enough of them)',
        range=(0.0, 1.0))
    gate_px: float = param(
        1.0, 'An edge pixel joins the running average of the pixel at its place in the '
        'previous frame only if its excess is within this of that average, pixels (else the '
        'average restarts there)', range=(0.01, 100.0))
    gate_thr: float = param(
        0.75, 'The running average also restarts where the excess moved by more than this '
        "times the pixel's obstacle threshold (a change as large as an obstacle makes: a "
        'small obstacle that appears is not averaged with the ground it stands on); the '
        'smaller of this and gate_px applies (0 = gate_px alone)',
        range=(0.0, 100.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class DetectionSettings:
    """GPOD stages 5-7: obstacle pixels, matched runs, strings and clusters
    (``GpodConfig.detection``)."""

    min_strength: float = param(
        8.0, 'Edge strength (mean |dI/du| of the left and right edge, grey levels per pixel) '
        'from which an obstacle or drop pixel counts fully towards min_obstacle_pixels and '
        'drops.min_pixels; a weaker one counts as (strength / this)^2 of a pixel (weak edges '
        'are often mismatched)', range=(0.0, 255.0))
    min_edge_snr: float = param(
        5.0, "The same in units of the image's gradient noise (the deviation of |dI/du| "
        "that the left image's pixel noise gives, estimated every few frames): the larger "
        'of min_strength and this times the gradient noise applies, so that on a '
        'noisy camera edges made by the noise count less (0 = off)', range=(0.0, 1000.0))
    ambiguous_match_ratio: float = param(
        0.8, 'A matched edge pixel is no evidence of a drop-off when another candidate '
        'match of its left or right edge, at a larger disparity on the ground (within the '
        'threshold), had at least this fraction of its first-round PMF support: an '
        'ambiguous match, perhaps ground matched a period off (a uniqueness ratio; on a '
        'periodic pattern, such as the bars of a grate, the candidates a period apart are '
        'supported alike). Obstacle evidence is not judged so (a kerb face has ground '
        'rivals as strong); 0 = off', range=(0.0, 10.0))
    periodic_min_rivals: int = param(
        2, 'A matched edge pixel is no evidence of an obstacle or a drop-off when at '
        'least this many other candidate matches of its left or right edge had '
        'ambiguous_match_ratio of its first-round PMF support or more, one of them on the '
        'ground (within the threshold): a periodic pattern, such as the bars of a grate, '
        'supports candidates a period apart alike, and one period off stands about 9 % '
        'of the camera height above the ground on the paper\'s rig (a kerb face has at '
        'most one strong rival on the ground); 0 = off', range=(0, 100))
    max_range_m: float = param(
        10.0, 'Obstacles whose foot is farther than this along the ground are not reported, '
        'metres', range=(0.1, 1000.0))
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
    disparity_sigma_px: float = param(
        1.0, 'Standard deviation of the disparity excess of ground features, pixels (the '
        "paper's sigma = 1), for the confidence", range=(0.01, 20.0))
    confidence_full_pixels: int = param(
        20, 'Obstacle pixels at which the confidence is no longer reduced for small '
        'evidence (confidence = P(any pixel truly beyond the threshold) * '
        'min(1, pixels / this), a weak edge pixel counted as in min_strength)',
        range=(1, 100000))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.part_radius_m > self.cluster_radius_m:
            raise ValueError(f'DetectionSettings.part_radius_m = {self.part_radius_m} must not '
                             f'exceed cluster_radius_m = {self.cluster_radius_m}')


@dataclass(frozen=True)
class DropSettings:
    """GPOD stages 6-7: drop-offs (ground below the plane) (``GpodConfig.drops``)."""

    enabled: bool = param(
        True, 'Report drop-offs (disparity below the ground plane) as negative obstacles')
    min_pixels: int = param(
        3, 'Pixels below the plane by more than the threshold that an edge string needs '
        'to be a drop-off', range=(1, 100000))
    region_pixels: float = param(
        3.0, 'An edge string with fewer than min_pixels drop pixels is still a drop '
        'string when the drop pixels of all the strings whose feet lie within '
        'cluster_radius_m of its own (the lower ground it belongs to) count at least '
        'this many times min_pixels (weighted as min_pixels counts them): the '
        'lower ground is many short texture edges, none long alone; 0 = each string '
        'alone', range=(0.0, 100000.0))
    region_min_strings: int = param(
        15, 'region_pixels: the region must hold drop pixels of at least this many '
        'edge strings (the lower ground shows many texture edges; a few strings below the '
        'plane are mismatches)', range=(1, 100000))
    region_max_spread: float = param(
        0.25, 'region_pixels: the drop pixels of the region must lie at one depth '
        'below the plane (a level lower ground): the median absolute deviation of their '
        'heights at most this fraction of their median depth (mismatches scatter in '
        'depth)', range=(0.0, 10.0))
    min_cluster_pixels: int = param(
        15, 'Drop pixels a drop-off needs in all (a drop is a region, not a lone string)',
        range=(1, 1000000))
    cluster_radius_m: float = param(
        1.0, 'Drop strings whose feet are closer than this join one drop-off, metres',
        range=(0.01, 100.0))
    max_depth_m: float = param(
        1.5, 'Pixels more than this far below the plane are ignored (mismatches), metres',
        range=(0.01, 100.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class BendSettings:
    """GPOD stage 7, rule ground_bend: a cluster whose heights grow steadily with distance is
    ground bending away beyond a brow, not a drop or an obstacle (``GpodConfig.bend``)."""

    min_grade: float = param(
        0.05, 'A cluster of drop strings (drops.cluster_radius_m), or of obstacle strings '
        '(detection.cluster_radius_m), whose pixels, spread over at least min_span_m '
        'along the walking direction, lie farther below (above) the ground the farther '
        'they are, at this grade or more (a line fitted to their heights), from less than '
        '10 cm off the ground at its near end or led up to from the ground by the rest of '
        'its strings without a gap (at a grade a pedestrian walks: surface.max_grade_fall '
        'below level, surface.max_grade_rise), is ground bending away beyond a brow (a '
        'dip), not a drop (an obstacle): the lower ground beyond a drop and the top of a '
        'kerb are level, as far off near as far, and start a step away (0.05: 1 in 20, '
        'the least grade of a ramp; the top of a kerb ramp seen from the ramp falls away '
        'at its grade); 0 = off', range=(0.0, 10.0))
    min_span_m: float = param(
        0.5, 'min_grade: the least spread of a cluster\'s pixels along the '
        'walking direction for its line to be judged, metres', range=(0.05, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class RisenSettings:
    """GPOD stage 7, rule risen_ground: beyond the known ground, a string that floats
    within the rise the ground may have made is that ground (``GpodConfig.risen``)."""

    min_height_m: float = param(
        0.2, 'An obstacle string beyond the known ground (ground surface known_until_m) '
        'whose reliable pixels all lie more than this above the surface (higher than a '
        'kerb or a step: none comes down to the ground) and no higher than the ground may '
        'have risen since the known ground (surface.max_grade_rise per metre beyond it) is '
        'the ground risen ahead where it has texture (a manhole cover on a rise the surface '
        'could not follow), not an obstacle, metres; 0 = off', range=(0.0, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class CoarseSettings:
    """GPOD stage 11: the second pass on images binned 2 x 2 (``GpodConfig.coarse``)."""

    min_width: int = param(
        480, 'Images at least this wide (pixels) are searched a second time binned 2 x 2 '
        '(half the size: a faint texture, such as a plain wall, gives twice the gradient '
        'per pixel at half the noise), and the binned pass\'s obstacles that no full-size '
        'obstacle explains (no foot within detection.part_radius_m) and the full-size '
        'matches do not contradict join the frame\'s; 0 = off',
        range=(0, 100000))
    min_height_m: float = param(
        0.3, 'The binned pass adds only obstacles at least this high (drop-offs at least '
        'this deep), metres: its disparity is half as fine, and low obstacles are the '
        'full-size pass\'s', range=(0.0, 100.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class UnseenSettings:
    """GPOD stage 12: a corridor whose ground edges stop showing (core/unseen_ground.py)
    (``GpodConfig.unseen``)."""

    max_ratio: float = param(
        0.15, 'Unseen ground (a wall with no edges, `core.unseen_ground`): the walking '
        'corridor\'s ground from some range out to its far end, where at most this fraction '
        'of the matched edge pixels the same cells showed in earlier frames are seen, is '
        'hidden by something, reported as unknown ground at its near edge (height NaN, '
        'said as "cannot see the way ahead", never as an obstacle); 0 = off',
        range=(0.0, 0.95))
    min_expected: float = param(
        15.0, 'Unseen ground: least number of edge pixels the hidden band must have been '
        'expected to show (fewer: too little evidence either way)', range=(1.0, 1.0e6))
    frames: int = param(
        2, 'Unseen ground: pairs in a row a band must be found hidden before it is reported',
        range=(1, 1000))
    range_m: float = param(
        5.0, 'Unseen ground: far end of the watched corridor, metres along the ground',
        range=(0.5, 100.0))
    half_width_m: float = param(
        0.5, 'Unseen ground: half width of the watched corridor, metres',
        range=(0.05, 10.0))
    explain_min_confidence: float = param(
        0.3, 'Unseen ground: only a detected obstacle or drop-off at least this confident '
        'explains the missing ground (a weak report that no alarm would announce must not '
        'silence the unseen ground behind it; the alarm node\'s min_confidence), 0..1',
        range=(0.0, 1.0))
    follow_travel_m: float = param(
        1.5, 'Unseen ground: a band found while the wearer walked this far whose near edge '
        'came nearer by less than half the distance walked keeps to the wearer, not to the '
        'world (the camera\'s own reach on smoother or more oblique ground, not a thing '
        'hiding it): not reported, and learnt as what the ground shows; metres, 0 = off',
        range=(0.0, 20.0))
    face_min_ncc: float = param(
        0.25, 'Unseen ground, plain face (`core.plain_face`): the image above a band\'s '
        'near edge is swept, out to its far end, for a face standing across the walking '
        'direction; a face whose gradients match between the images at least this well '
        '(normalised cross-correlation), and face_margin better than the ground going on '
        'and than any other face range, is reported as an obstacle face_height_m tall at '
        'its range in place of the unknown ground (also in a band with too little '
        'expected of it to be judged by its edges); 0 = off', range=(0.0, 1.0))
    face_margin: float = param(
        0.15, 'Unseen ground, plain face: least margin of the face\'s correlation over the '
        'ground\'s and over its rival ranges\' (one clear peak), 0..1', range=(0.0, 1.0))
    face_height_m: float = param(
        1.0, 'Unseen ground, plain face: the face is tested up to this height above the '
        'ground (or the image\'s top), and reported this tall: a report at least the map\'s '
        'pass_height_m tall goes out unconfirmed once chained over its pass_frames pairs, '
        'metres',
        range=(0.1, 5.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TrackSettings:
    """GPOD stage 13: obstacle tracks through the motion and missed frames
    (``GpodConfig.tracks``)."""

    confidence_frames: int = param(
        3, 'Obstacle tracks: a tracked obstacle\'s confidence combines its detections in up '
        'to this many of its latest views, 1 - prod(1 - confidence) (evidence accumulated '
        'over frames; the frames of a rig standing still are one view, at its best '
        'detection; 1 = the latest view\'s alone)', range=(1, 100))
    coast_s: float = param(
        1.0, 'Obstacle tracks (DGPR): an obstacle detected before is still reported for up to '
        'this long after its last detection, at its tracked place (moved by the camera '
        'motion, or still while the rig stands still), unless the frame shows ground where '
        'it stood; 0 = report detections only, s',
        range=(0.0, 60.0))
    process_noise_m: float = param(
        0.05, 'Obstacle tracks: random-walk noise of a tracked foot, m per sqrt(s)',
        range=(0.0, 10.0))
    confirm_hits: int = param(
        1, 'Obstacle tracks: frames in which a track must have been detected before it is '
        'reported in frames where it is not', range=(1, 1000))
    min_hit_fraction: float = param(
        0.5, 'Obstacle tracks: a track is carried through frames without a detection only '
        'while it was detected in at least this fraction of the frames since it began (M of '
        'N: an obstacle is seen in most frames, ground texture that sometimes passes the '
        'threshold is not)', range=(0.0, 1.0))
    sure_hits: int = param(
        3, 'Obstacle tracks: a track detected in at least this many frames is carried '
        'through frames without a detection whatever its hit fraction, for up to '
        'coast_s, unless the frame shows ground where it stood (0 = off)',
        range=(0, 100000))
    unseen_coast_s: float = param(
        5.0, 'Obstacle tracks: a track detected in at least sure_hits frames whose '
        'foot has left the bottom of the image (an obstacle walked up to, nearer than the '
        'ground the camera sees) is still reported, carried by the camera motion, for up '
        'to this long after its last detection, unless a part of its image region still in '
        'view shows ground; it ends once passed (behind the camera, or out to the side), s',
        range=(0.0, 600.0))
    motion_hold_frames: int = param(
        2, 'Obstacle tracks: a pair that comes without a motion while the rig moves carries '
        'the tracks by the previous given motion, scaled to the time between the pairs, '
        'its translation uncertain by half its length, for at most this many pairs in a '
        'row (a missed /egomotion must not make the obstacles walked up to forget); '
        '0 = such a pair ends all tracks', range=(0, 100))
    position_sigma_m: float = param(
        0.05, 'Obstacle tracks: placement uncertainty of a detected foot added to its '
        'triangulation noise (which corner of the obstacle is nearest), metres',
        range=(0.001, 10.0))
    pixel_sigma_px: float = param(
        1.0, 'Obstacle tracks: image position uncertainty of a detected foot, pixels',
        range=(0.01, 100.0))
    free_min_features: int = param(
        5, 'Obstacle tracks: a track not detected in a frame ends when its image region '
        'holds at least this many reliably matched edge pixels on the ground plane, where '
        'the obstacle would have stood out above it, and three times as many as above it '
        '(the obstacle went away)', range=(1, 100000))
    gate_chi2: float = param(
        11.34, 'Obstacle tracks: a detection updates a track when their squared Mahalanobis '
        'distance (3 dof) is below this (11.34: chi-square 99 %)', range=(0.1, 1000.0))
    frame_period_s: float = param(
        0.1, 'Time between frames assumed when process() is given no stamp, s',
        range=(1e-4, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)


#: The named rules (core/gpod/rules.py) each list of `RuleSettings` may hold.
PIXEL_RULE_NAMES = ('periodic_pattern', 'ambiguous_drop', 'hanging_run',
                    'lower_ground_continuation', 'string_pieces')
STRING_RULE_NAMES = ('floating_string', 'risen_ground', 'ground_bend', 'half_occlusion')
DROP_RULE_NAMES = ('drop_region', 'ground_bend')
PLACEMENT_RULE_NAMES = ('silhouettes', 'view_edge', 'face_gap', 'lone_face')


@dataclass(frozen=True)
class RuleSettings:
    """GPOD stages 6-10: the named rules of the obstacle and drop-off test and of the
    nearest point, run in the order listed (core/gpod/rules.py; a rule left out is off)
    (``GpodConfig.rules``)."""

    pixels: tuple[str, ...] = param(
        PIXEL_RULE_NAMES, 'Rules on the obstacle and drop pixels, in order: '
        'periodic_pattern (a match with detection.periodic_min_rivals strong rivals, one on '
        'the ground, is no evidence), ambiguous_drop (a drop pixel with a strong nearer '
        'rival on the ground is none), hanging_run (a run hanging over another depth of '
        'its own string), lower_ground_continuation (a run that could be its string matched '
        'on the lower ground beyond a drop), string_pieces (the string rule per piece of '
        'a string between stretches on the ground)')
    strings: tuple[str, ...] = param(
        STRING_RULE_NAMES, 'Rules on the obstacle strings, in order: floating_string (all '
        'its reliable pixels above detection.max_floating_height_m: a mismatch), '
        'risen_ground (beyond the known ground, all of it higher than risen.min_height_m '
        'but within the rise the ground may have made: risen ground), ground_bend '
        '(ground rising beyond a dip, bend.*), half_occlusion (an obstacle only through '
        'edges hidden in the right image)')
    drops: tuple[str, ...] = param(
        DROP_RULE_NAMES, 'Rules on the drop-off strings, in order: drop_region (a string '
        'in a region of lower ground, drops.region_*), ground_bend (ground falling away '
        'beyond a brow, bend.*)')

    placement: tuple[str, ...] = param(
        PLACEMENT_RULE_NAMES, "Rules that move an obstacle's nearest point from that of its "
        'own feet, in order: silhouettes (edges just under the thresholds that are its '
        'silhouette reveal a hidden near corner), view_edge (a face running out of the '
        'image: where it leaves the view), face_gap (a face seen as two obstacles: its '
        'middle), lone_face (a low obstacle seen by one silhouette edge: the face the '
        'image shows beside it)')

    def __post_init__(self) -> None:
        check_fields(self)
        for name, known in (('pixels', PIXEL_RULE_NAMES), ('strings', STRING_RULE_NAMES),
                            ('drops', DROP_RULE_NAMES), ('placement', PLACEMENT_RULE_NAMES)):
            listed = getattr(self, name)
            if not isinstance(listed, tuple):
                raise TypeError(f'RuleSettings.{name} must be a list of rule names, got '
                                f'{listed!r}')
            bad = [r for r in listed if r not in known]
            if bad or len(set(listed)) != len(listed):
                raise ValueError(f'RuleSettings.{name} = {list(listed)}: each of '
                                 f'{list(known)} at most once')


@dataclass(frozen=True)
class GpodConfig:
    """Settings of the GPOD detector, one group per stage (validated on construction)."""

    image: ImageSettings = group(ImageSettings, 'stage 1: the images checked, the right '
                                 "camera's gain, the rig's vertical misalignment")
    edges: EdgeSettings = group(EdgeSettings, 'stage 2: vertical edges and edge strings')
    matching: MatchSettings = group(MatchSettings, 'stage 3: row-wise PMF matching')
    plane: PlaneSettings = group(PlaneSettings, 'stage 4: the ground plane')
    threshold: ThresholdSettings = group(ThresholdSettings, 'stage 4: the obstacle threshold')
    surface: GroundSurfaceConfig = group(GroundSurfaceConfig,
                                         'stage 5: the ground surface ahead')
    surface_tracking: SurfaceTrackingConfig = group(
        SurfaceTrackingConfig, "stage 5: the ground surface carried through the camera's "
        'motion')
    temporal: TemporalSettings = group(TemporalSettings,
                                       'stage 5: the excess averaged while standing still')
    detection: DetectionSettings = group(DetectionSettings,
                                         'stages 5-7: obstacle pixels, runs and clusters')
    drops: DropSettings = group(DropSettings, 'stages 6-7: drop-offs')
    rules: RuleSettings = group(RuleSettings, 'stages 6-10: the named rules, in order')
    bend: BendSettings = group(BendSettings, 'stage 7: rule ground_bend')
    risen: RisenSettings = group(RisenSettings, 'stage 7: rule risen_ground')
    coarse: CoarseSettings = group(CoarseSettings, 'stage 11: the binned second pass')
    unseen: UnseenSettings = group(UnseenSettings, 'stage 12: unseen ground')
    tracks: TrackSettings = group(TrackSettings, 'stage 13: obstacle tracks')

    def __post_init__(self) -> None:
        check_fields(self)
        if self.detection.max_range_m > self.matching.search_max_range_m:
            raise ValueError(
                f'GpodConfig.detection.max_range_m = {self.detection.max_range_m} must not '
                f'exceed matching.search_max_range_m = {self.matching.search_max_range_m}')
