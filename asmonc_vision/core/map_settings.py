"""Settings of the evidence map (`core.evidence_map.EvidenceMap`): one frozen dataclass,
validated on construction; `docs/map.md` says what each does and why, `docs/parameters.md`
lists them with their ranges. No ROS here.
"""
from __future__ import annotations

from dataclasses import dataclass

from asmonc_vision.core.config import check_fields, group, param


@dataclass(frozen=True)
class DropSpanConfig:
    """rule_drop_span (`core.map_reports.drop_spans`): a drop-off seen on both sides of
    the walking corridor, whose edge crosses the corridor where the map has seen no ground
    (``map.span.*``)."""

    enabled: bool = param(
        True, "report the edge of a drop-off (a step down, a kerb) where it crosses the "
        "walking corridor when the map confirms its lower ground on both sides of the "
        "corridor and has seen none of the corridor's ground there: a plain pavement "
        "shows no edge to match in the middle of the path, and the edge of a step down is "
        "straight across it")
    max_gap_m: float = param(
        3.0, 'largest lateral distance between the two sides\' nearest points that the '
        'edge is carried across, m', range=(0.0, 20.0))
    max_skew_deg: float = param(
        30.0, 'largest angle of the line through the two nearest points to the across '
        'direction, degrees: a step down crosses the path; drops along both sides of it '
        '(a raised walkway) are seen nearest at the view\'s near edge, and are told apart '
        'by min_lead_m', range=(0.0, 89.0))
    min_lead_m: float = param(
        0.5, "no confirmed drop cell may lie within band_m of a side's nearest point "
        "across the path and more than this nearer along it: the nearest lower ground of "
        "an edge across the path is at the edge, that of a drop running along the path "
        "continues towards the wearer, m", range=(0.0, 10.0))
    band_m: float = param(
        0.2, "half width across the path of the band along a side's nearest point that "
        "min_lead_m looks in, m", range=(0.0, 5.0))
    ground_margin_m: float = param(
        0.3, 'the map must not have seen ground finely (map.attach_seen_ground_s) at the '
        'crossing or this far beyond it: the ground of a ramp between two kerbs, m',
        range=(0.0, 5.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class DropHoldConfig:
    """rule_drop_hold (`core.map_drop_hold`): a confirmed drop whose edge has left the
    bottom of the view is held until the wearer reaches it (``map.hold.*``)."""

    enabled: bool = param(
        True, "hold a confirmed drop-off whose nearest point has come within margin_m of "
        "the nearest ground the camera sees, and was confirmed farther than that: no "
        "ground seen, no miss and no decay takes from its cells until the wearer has "
        "passed its nearest point (then its cells nearer than the reach are let go). With "
        "its edge out of view the pair's plane can be the lower ground beyond it (a level "
        "chest camera sees the ground from about 2.4 m), against which the drop's lower "
        "ground is ground seen free")
    margin_m: float = param(
        1.0, "a drop is held once its nearest point is at most this beyond the nearest "
        "ground in view, m: the ground an edge hides behind it (about depth times range "
        "over camera height, 0.3 m for 16 cm at 2.4 m from 1.3 m up) and the last of the "
        "ground before it, too little to hold a chest rig's plane (a pair whose plane "
        "was 10 cm low cleared one side of a 16 cm step down 3.5 m ahead, the view's "
        "bottom at 2.6 m: 0.5 kept that side's drop from the map)",
        range=(0.0, 5.0))
    level_tol_m: float = param(
        0.06, "once the wearer has passed a held drop, the confirmed drop cells within "
        "this of its median height are the lower ground stepped onto: let go nearer "
        "than the reach, and not held again, m (the cells of a 20 cm drop lie within "
        "4 cm of each other; a second step down lies a step's height below)",
        range=(0.0, 1.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class StepUpConfig:
    """rule_step_up (`core.map_step_up`): raised ground the wearer has walked onto is the
    ground they stand on (``map.step_up.*``)."""

    enabled: bool = param(
        True, "let go the confirmed raised cells at or below the level of those the "
        "wearer has walked onto (a footway seen from below its kerb, which no pair sees again "
        "before it is underfoot)")
    behind_m: float = param(
        0.15, "the walked-over cells lie at least this far behind the wearer (below the "
        "left camera), m: standing before a kerb, its cells lie ahead", range=(0.0, 2.0))
    depth_m: float = param(
        0.45, "... and at most behind_m plus this, m", range=(0.05, 3.0))
    half_width_m: float = param(
        0.2, "... and within this of the path (the wearer's feet), m", range=(0.05, 2.0))
    min_cells: int = param(
        3, "least confirmed raised cells walked over", range=(1, 1000))
    max_height_m: float = param(
        0.3, "their median height must be a step up, at most this, m: a wall or a "
        "person is never walked onto", range=(0.0, 2.0))
    level_tol_m: float = param(
        0.06, "confirmed raised cells at most this above that median height are at or "
        "below the ground stepped onto, m (a thing standing on it stands its own height "
        "higher)",
        range=(0.0, 1.0))
    margin_m: float = param(
        1.0, "they are let go nearer than the nearest ground in view plus this, m (those "
        "farther are in view, and cleared by the ground seen)", range=(0.0, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GroundStepConfig:
    """Settings of rule_ground_step (`core.map_steps`) (``EvidenceMapConfig.steps``; in ROS
    ``map.steps.*``)."""

    enabled: bool = param(
        True, 'rule_ground_step: where the ground surface ahead ends at a step across '
        'the walking corridor (its segment refused by rule_step, rule_grade or '
        'rule_spread with a step measured), the step enters the map as raised (a kerb '
        'up) or drop (a step down) evidence just beyond it, at its height')
    min_step_m: float = param(
        0.05, 'least height (or depth) of a step taken, metres', range=(0.0, 1.0))
    band_m: float = param(
        0.6, "the features up to this far before the step find its foot, those up to "
        'this far beyond it its level, metres', range=(0.01, 5.0))
    half_width_m: float = param(
        0.6, 'the step is entered across the walking corridor to this distance either '
        'side of the walking line, metres', range=(0.1, 10.0))
    depth_m: float = param(
        0.3, 'the step is entered on the ground from it to this far beyond it, metres',
        range=(0.01, 5.0))
    support_half_width_m: float = param(
        2.0, "the far side's features within this distance of the walking line support "
        'the step (the ground surface\'s own width), metres', range=(0.1, 50.0))
    gate_m: float = param(
        0.1, "the features within band_m before the step and this close to the known "
        "surface find the step's foot (their median height over it); those beyond it "
        "up to this much farther from the foot than the surface's own step (on its "
        "side) find the far side's level, metres", range=(0.0, 1.0))
    level_share: float = param(
        0.5, "the far side's features within this share of its level's height of that "
        'level support the step (the stepped ground, not a thing on it)',
        range=(0.01, 10.0))
    min_features: int = param(
        4, "least number of the far side's features on its level within band_m of the "
        'step', range=(1, 100000))
    min_width_m: float = param(
        0.8, "least width of the far side's features on its level (10th to 90th "
        'percentile across the path), metres: the ground beyond a kerb is wide, the foot '
        'of a post or a box narrow', range=(0.0, 20.0))
    min_corridor_features: int = param(
        6, "least number of the far side's features on its level within half_width_m of "
        'the walking line: the step is seen crossing the corridor (the kerbs either side '
        'of a kerb ramp step, the ramp between them does not)', range=(0, 100000))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class EvidenceMapConfig:
    """Settings of the evidence map (`EvidenceMap`)."""

    enabled: bool = param(
        True, 'report obstacles and drop-offs from the evidence map (a thing confirmed '
        'from two viewpoints, cleared by ground seen where it stood) instead of each '
        "pair's detections and their tracks")
    cell_m: float = param(0.1, 'side of a map cell, m', range=(0.02, 0.5))
    radius_m: float = param(
        9.0, 'half side of the square map around the wearer, m (evidence farther away is '
        'not kept)', range=(1.0, 50.0))
    max_range_m: float = param(8.0, 'evidence farther than this along the ground is not '
                               'entered, m', range=(0.5, 50.0))
    recentre_m: float = param(1.0, 'the grid is re-centred on the wearer (by whole cells) '
                              'once the wearer is this far from its centre, m',
                              range=(0.1, 10.0))
    hit_logodds: float = param(0.85, 'log-odds added to a cell with raised (or drop) '
                               'evidence in a pair', range=(0.01, 10.0))
    weigh_by_rivals: bool = param(
        True, 'raised and drop evidence counts by how sure its match is: hit_logodds times '
        '1 - c of the surest such pixel in the cell, c the first-round support of its '
        'rivals (the other candidate matches of its edges) that say otherwise (on or below '
        'the ground for a raised pixel, on or above it for a drop) over that of the match '
        'and all its rivals: were the supports likelihoods, the chance that it is not the '
        "ground matched wrongly (one such rival as well supported: half). A grate's bars "
        'matched a period off stand about 10 cm up, nearly where they are in the world '
        'from every viewpoint, and texture on the ground matched a few pixels off stays in '
        'place too; their matches have such rivals. Off: every pixel counts fully')
    appear_min_pixels: int = param(
        4, 'raised evidence in a cell starts from 0 over the ground seen there before '
        '(L_r = max(L_r, 0) + hit: a thing that appears, a passer-by stepping in) when '
        'the pair has at least this many raised pixels in the cell (a face) or the pair '
        'before had raised evidence within miss_guard_cells of it (seen again); else it '
        'adds to what the ground said (L_r = L_r + hit: a mismatch over the ground, a '
        'pixel or two that comes and goes). 1: every raised pair starts from 0',
        range=(1, 1000))
    drop_weighs_ground: bool = param(
        True, 'drop evidence in a cell adds to what the ground seen there before said '
        '(L_d = L_d + hit): lower ground is terrain, it does not step in as a passer-by '
        'does, so a cell seen as ground for many pairs and below it in one or two (the '
        'far ground of a bend beyond the known surface, a plane off for a pair) is not '
        'a drop; off: as raised evidence, L_d = max(L_d, 0) + hit')
    drop_clear_max_sigma_m: float = param(
        0.033, 'ground seen in a cell takes log-odds from its drop evidence only from '
        'ground pixels whose height is known to this standard deviation or better, m '
        '(0.033: a 10 cm drop at 3 sigma): far ground, measured coarsely, cannot tell the '
        'lower ground beyond a drop from the ground before it; 0 = any', range=(0.0, 10.0))
    free_logodds: float = param(1.2, 'log-odds taken from a cell where ground is seen and '
                                'no raised evidence (the clearing is faster than the '
                                'filling)', range=(0.0, 10.0))
    still_hit_factor: float = param(
        1.0, 'raised or drop evidence of a pair taken while the rig stands still counts '
        'this much (its frames repeat the same matches and their errors)', range=(0.0, 1.0))
    miss_logodds: float = param(
        0.6, 'log-odds taken from a confirmed cell in plain view (not hidden by a nearer '
        'thing) with none of the evidence of a pair near it (0: off)',
        range=(0.0, 10.0))
    miss_guard_cells: int = param(
        2, 'a confirmed cell with evidence of a pair within this many cells of it is not '
        'missed (the matched points of a thing scatter along the line of sight)',
        range=(0, 10))
    miss_margin_px: float = param(
        5.0, 'a cell is in plain view when the foot of its evidence point (a raised cell: '
        'or the point at 3/4 of its height) lies this far inside both images, px',
        range=(0.0, 100.0))
    min_ground_pixels: int = param(2, 'ground-matched edge pixels in a cell that clear '
                                   'it', range=(1, 1000))
    min_drop_pixels: int = param(
        2, 'drop pixels of one pair in a cell (and no raised pixel there) that make it drop '
        'evidence: a lone pixel below the ground is as often a mismatch (on a marking, on '
        'the far ground of a slope beyond the known surface) as a drop', range=(1, 1000))
    clear_guard_cells: int = param(
        1, 'ground seen within this many cells of raised or drop evidence of the same pair '
        'does not clear (an obstacle is seen with the ground at its foot)', range=(0, 10))
    ray_logodds: float = param(
        1.2, 'log-odds taken from a raised cell seen through: ground seen behind it along '
        'sight lines passing lower than its top (0: off)', range=(0.0, 10.0))
    ray_min_pixels: int = param(3, 'sight lines through a raised cell below its top, on '
                                'each side of its evidence point, that clear it in a pair',
                                range=(1, 10000))
    ray_lateral_m: float = param(0.03, 'a sight line passes through a raised cell when '
                                 'it passes this near its evidence point, m',
                                 range=(0.001, 1.0))
    ray_margin_m: float = param(0.05, 'a sight line must pass this far below a cell top '
                                '(at least 2 standard deviations of it) to count, m',
                                range=(0.0, 2.0))
    ray_stop_m: float = param(0.2, 'sight lines are followed up to this short of their '
                              'ground point, m', range=(0.0, 2.0))
    ray_max_points: int = param(600, 'ground matches of a pair whose sight lines are '
                                'followed (evenly picked when there are more)',
                                range=(1, 100000))
    min_logodds: float = param(-2.0, 'least log-odds of a cell', range=(-20.0, 0.0))
    max_logodds: float = param(3.5, 'largest log-odds of a cell', range=(0.0, 20.0))
    report_logodds: float = param(1.5, 'a cell is reported (with two views) from this '
                                  'log-odds on', range=(0.0, 20.0))
    decay_s: float = param(4.0, 'time constant of the decay of the log-odds towards the '
                           'prior, s (cells out of view are remembered about this long)',
                           range=(0.1, 600.0))
    min_baseline_m: float = param(
        0.3, 'a cell seen raised or dropped again from this far from where its evidence '
        'began has two views, m (a mismatch of a repetitive pattern moves in the world '
        'by a fraction of this)', range=(0.0, 10.0))
    still_min_frames: int = param(
        2, 'pairs with evidence at a cell while the rig stands still that count as two '
        'views (no parallax while still)', range=(1, 1000))
    stationary_step_m: float = param(
        0.03, 'a pair whose camera moved less than this along the ground since the '
        'previous one (turning on the spot) counts as still for still_min_frames, m',
        range=(0.0, 1.0))
    height_process_noise: float = param(
        0.05, 'process noise q of a cell height, m/sqrt(s)', range=(0.0, 10.0))
    join_cells: int = param(2, 'confirmed cells this many cells apart belong to one '
                            'region (0: touching cells only)', range=(0, 20))
    near_tolerance_m: float = param(
        0.15, "a region's nearest point is at its nearest range, at the median bearing of "
        'its cells within this of that range, m', range=(0.0, 2.0))
    corridor_half_width_m: float = param(
        0.5, "a region with cells ahead within this of the walking direction none of "
        "whose reports lies there is reported there too, at its nearest cell there (the "
        "alarm's walking corridor: a thing beside the path that reaches into it farther "
        "on), m (0: off)", range=(0.0, 5.0))
    attach_m: float = param(
        0.5, "a detector report whose foot lies within this of a confirmed cell of its kind "
        "is confirmed and reported as the detector placed it (from the whole silhouette); "
        "a region that confirms none is reported at its own nearest point, m (0: the "
        "map's placement only)", range=(0.0, 5.0))
    attach_seen_ground_s: float = param(
        3.0, "a detector report is not confirmed by a cell within attach_m when the map "
        "saw the ground finely (to drop_clear_max_sigma_m) at its foot and in the cells "
        "around it at most this long before, with no raised evidence there: the map has "
        "seen ground where the report says a thing stands (a pair's misfit of a slope "
        "next to a kerb), s (0: off)", range=(0.0, 60.0))
    pass_height_m: float = param(
        1.0, "a detector report at least this tall is published whether the map confirms "
        "it or not (once chained over pass_frames pairs): a person walking towards the "
        "wearer is in new cells every pair and is seldom confirmed, while a mismatch (a "
        "grate, a marking) is low, m (0: none pass)", range=(0.0, 10.0))
    pass_frames: int = param(
        2, 'a pass_height_m report is published unconfirmed once it is the last of a chain '
        'of such reports over this many pairs in a row (`core.moving_reports`; 1: at once): '
        'one pair\'s ghost is not one', range=(1, 100))
    moving_min_height_m: float = param(
        0.6, "a detector report at least this tall (less than pass_height_m) is published "
        "unconfirmed once it is the last of a chain of such reports, one in each of the "
        "latest moving_frames pairs, each near one of the pair before "
        "(`core.moving_reports`): a passer-by's legs stand 0.6-0.9 m up in every pair, a "
        "ground pattern matched wrongly seldom half a metre and not pair after pair, m "
        "(0: no chains)", range=(0.0, 10.0))
    moving_frames: int = param(
        3, 'pairs in a row a chain of moving_min_height_m reports must span', range=(1, 100))
    moving_gate_m: float = param(
        0.3, 'a chained report lies at most this plus moving_max_speed_mps times the time '
        'between the pairs from one of the pair before (feet in each pair\'s ground frame), m',
        range=(0.0, 5.0))
    moving_max_speed_mps: float = param(
        4.0, 'fastest a chained report may move between pairs in the wearer\'s ground frame '
        '(a passer-by and the wearer walking towards each other), m/s', range=(0.0, 20.0))
    moving_max_range_m: float = param(
        5.0, 'chained reports farther than this along the ground do not count, m (the '
        'ground ahead is less sure farther on; a passer-by closing at 2.5 m/s is chained '
        'by about 4.5 m, 0.8 s before it must be warned of at 2.5 m)', range=(0.0, 50.0))
    min_region_cells: int = param(1, 'least confirmed cells in a reported region',
                                  range=(1, 10000))
    min_drop_cells: int = param(
        3, 'least confirmed cells in a reported drop region: a drop the wearer can step '
        'off (a kerb or a step down across the path) is wide; a cell or two of lower '
        'ground is a brow seen at a grazing angle or noise', range=(1, 10000))
    unseen_report_s: float = param(
        0.35, 'a confirmed raised cell in the image (in plain view or hidden behind a '
        'nearer thing, which is reported itself) that the pair saw nothing at is not '
        'reported once its last evidence is older than this, s: a passer-by\'s cells '
        'behind them fade from the map over several pairs, but the wearer is not warned '
        'of where they were; a thing out of the image (walked up to), and a drop (its '
        'lower side is hidden by its edge), are still reported from memory; 0 = no limit',
        range=(0.0, 60.0))
    moved_in_s: float = param(
        3.0, 'a raised cell whose ground was seen (to drop_clear_max_sigma_m) at most this '
        'long before its raised evidence began holds a thing that moved in (a passer-by): '
        'it is reported only while its evidence is younger than unseen_report_s, in view '
        'or not (a thing the wearer walks up to covers its ground and is remembered); '
        '0 = off', range=(0.0, 60.0))
    moved_in_min_height_m: float = param(
        0.3, 'moved_in_s applies to a cell whose height is at least this, m: a thing that '
        'moves in (a person, a cyclist, a dog) is a body; the raised side of a kerb or a '
        'step is ground, seen as ground (under the pixel threshold) before the step is '
        'measured, and stays put: below the view it is remembered, and the wearer standing '
        'at a kerb is not told "all clear"; 0 = any height', range=(0.0, 10.0))
    carried_plane_evidence: str = param(
        'ground', "what a pair enters into the map when its ground plane was carried over "
        "from the pair before (the refit failed) while the rig moves: the camera has "
        "pitched since by the gait's few degrees a pair, and the ground stands off that "
        "plane by that times the range; 'all' its evidence, 'ground' only its ground seen "
        "free (which clears where a passer-by had been), 'none' nothing (its raised and "
        "drop evidence gave a false drop 3 m ahead of the chest rig, clear_walk 1079)",
        choices=('all', 'ground', 'none'))
    motion_gap_frames: int = param(
        2, 'pairs in a row the rig may move with no motion known (the previous pose held) '
        'before the map is cleared', range=(0, 100))
    min_placed_pairs: int = param(
        5, "until the map has placed this many pairs in a row the detector's reports are "
        "published instead of the map's: at a start as they are (for start_raw_s), after "
        "the map was cleared for want of a motion, or never took over, once chained over "
        "unmapped_frames pairs",
        range=(0, 1000))
    start_raw_s: float = param(
        1.5, "at a start the detector's reports go out as they are for this long after "
        "the first pair with a ground plane (a thing in view from the first pair is said "
        "from the first pairs; the map needs min_placed_pairs pairs, about half a second, "
        "to take over); a map that has not taken over by then lacks the camera's motion "
        "while the rig moves, and the reports go out chained as after a clear "
        "(unmapped_frames), s", range=(0.0, 60.0))
    unmapped_frames: int = param(
        3, "after the map was cleared, until it has placed min_placed_pairs pairs in a "
        "row again, a raised detector report goes out once it ends a chain of this many "
        "pairs (core.moving_reports: one in each pair within moving_gate_m + "
        "moving_max_speed_mps times the time between them, in each pair's ground frame; "
        "unknown ground ahead always goes out): one pair's ghost, a refit pitched a few "
        "degrees off, does not reach the wearer; 1 = every report", range=(1, 100))
    unmapped_drop_frames: int = param(
        1, "the same for a drop report: the detector finds a drop's edge in a pair here "
        "and there (its lower ground hidden), and one held back can be the only warning "
        "(a 21 cm step down on step_down 1011, chest rig)", range=(1, 100))
    unmapped_drop_min_width_m: float = param(
        1.0, "a drop report narrower than this (across the line of sight) chains over "
        "unmapped_frames pairs instead: a drop the wearer can step off is wide (the 21 cm "
        "step down of step_down 1011 was reported 3.9 m wide), one pair's narrow patch "
        "below the plane is a refit off for that pair, m (0: every drop over "
        "unmapped_drop_frames)", range=(0.0, 10.0))
    span: DropSpanConfig = group(
        DropSpanConfig, 'rule_drop_span: a drop-off seen on both sides of the walking '
        'corridor reported where its edge crosses it')
    hold: DropHoldConfig = group(
        DropHoldConfig, 'rule_drop_hold: a confirmed drop whose edge has left the bottom '
        'of the view held until the wearer reaches it')
    step_up: StepUpConfig = group(
        StepUpConfig, 'rule_step_up: raised ground the wearer has walked onto is the '
        'ground they stand on')
    steps: GroundStepConfig = group(
        GroundStepConfig, 'rule_ground_step: a step of the ground across the walking '
        'corridor entered as raised or drop evidence')
    default_sigma_px: float = param(0.4, 'σ_d of a match when the detector gives '
                                    'neither a per-pixel threshold nor a sigma, px',
                                    range=(0.01, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.min_logodds >= self.report_logodds or self.report_logodds > self.max_logodds:
            raise ValueError('EvidenceMapConfig: min_logodds < report_logodds <= max_logodds '
                             f'is required, got {self.min_logodds}, {self.report_logodds}, '
                             f'{self.max_logodds}')
