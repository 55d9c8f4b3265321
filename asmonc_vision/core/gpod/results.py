"""What GPOD returns per stereo pair: the obstacles (`GpodObstacle`), the matched features
(`GpodFeatures`), the ground plane (`GpodPlane`) and the whole result (`GpodResult`).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import cast

import numpy as np

from ..camera import MetricPlane
from ..ground_surface import GroundSurface


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
            * min(1, pixels / ``detection.confidence_full_pixels``), a pixel weaker than
            ``detection.min_strength`` counted as (strength / that)^2 of one (as the
            edge-string rule counts it). A reported (tracked) obstacle's:
            1 - prod(1 - c) over its track's latest ``tracks.confidence_frames`` views, c
            the largest detection confidence in a view (the frames while the rig stands
            still are one view).
        roi: (x, y, w, h) ints, region in the left image (from the top of the obstacle
            down to its foot on the ground).
        num_edge_pixels: matched edge pixels beyond the threshold in the obstacle.
        string_ids: (k,) int32 ids of its edge strings (left EdgeMap); empty when coasted.
        track_id: id of its obstacle track (> 0), 0 if untracked.
        age_s: seconds since it was last detected: 0 when detected in this frame, > 0
            when the track is coasted (reported at its tracked place, see
            ``GpodConfig.tracks.coast_s``).
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


#: the fields of a GpodObstacle (`replaced`)
_OBSTACLE_FIELDS = frozenset(f.name for f in fields(GpodObstacle))


def replaced(ob: GpodObstacle, **changes) -> GpodObstacle:
    """``dataclasses.replace(ob, **changes)``: a GpodObstacle with ``ob``'s fields, the
    ``changes`` new (the same objects), without the frozen dataclass's __init__ (a few
    microseconds a call; the tracks and the map's reports make some fifteen a frame).
    Another type (a subclass) goes through dataclasses.replace."""
    if type(ob) is not GpodObstacle or not _OBSTACLE_FIELDS.issuperset(changes):
        return replace(ob, **changes)
    out = object.__new__(GpodObstacle)
    out.__dict__.update(ob.__dict__)
    out.__dict__.update(changes)
    return out


def new_obstacle(position: np.ndarray, height: float, range: float, bearing: float,
                 width: float, disparity_excess: float, confidence: float,
                 roi: tuple[int, int, int, int], num_edge_pixels: int,
                 string_ids: np.ndarray, track_id: int = 0,
                 age_s: float = 0.0) -> GpodObstacle:
    """``GpodObstacle(...)`` of these fields (as its attributes say), the same object
    (its fields set in their order, the same objects) without the frozen dataclass's
    __init__ (one ``object.__setattr__`` a field: a few microseconds an obstacle)."""
    out = object.__new__(GpodObstacle)
    out.__dict__.update(position=position, height=height, range=range, bearing=bearing,
                        width=width, disparity_excess=disparity_excess,
                        confidence=confidence, roi=roi, num_edge_pixels=num_edge_pixels,
                        string_ids=string_ids, track_id=track_id, age_s=age_s)
    return out


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
        contrary_rival_share: (K,) float32 the first-round PMF support of the other
            candidate matches of the pixel's left or right edge that say otherwise (for
            an obstacle pixel those on the ground or below it, for any other those on
            the ground or above it), over that of its match and all those candidates
            (`core.matching.selection.match_rivals`; 0 for a match with no such rival,
            0.5 for one with one as well supported; None if unknown).
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
    contrary_rival_share: np.ndarray | None = None

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
            times sigma_px within the floor and ceiling; with ``threshold.sigma_per_edge`` each
            pixel has its own, see ``features.threshold``).
        num_edges: (left, right) numbers of edge pixels.
        timings_ms: stage -> milliseconds ('edges', 'matching', 'plane', 'obstacles',
            'total'; on images at least ``coarse.min_width`` wide, 'coarse': the binned
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
            (``edges.threshold``, or lower on weakly textured ground: ``edges.min_density``).
        surface: the ground surface ahead the obstacles were judged against
            (``surface.enabled``; its ``known_until_m``: how far the ground is known),
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
        # (the detector sets plane_cov together with plane_abc)
        return GpodPlane(abc=self.plane_abc, cov=cast(np.ndarray, self.plane_cov),
                         num_features=self.plane_num_features,
                         residual_rms=self.plane_residual_rms, metric=self.metric_plane,
                         updated=self.plane_updated)

    @property
    def timings(self) -> dict[str, float]:
        """Alias of ``timings_ms`` (stage -> milliseconds)."""
        return self.timings_ms

