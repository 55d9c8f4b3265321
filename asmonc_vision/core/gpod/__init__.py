"""Ground Plane Obstacle Detection (GPOD), after Molton, Se, Brady et al. (1998), Sec. 2.

Per stereo pair, `GpodDetector.process` runs these stages (module in brackets):

1. Vertical edges in both images (:mod:`..edges`) and their row-wise PMF matches
   (:mod:`..matching`): features (u_left, u_right, v, d).
2. The ground plane ``d = a*u + b*v + c``: calibrated on the first frames, then refitted
   or carried through the camera's motion every frame, and the obstacle threshold from
   the residual spread of the calibration (:mod:`.plane_tracking`).
3. Obstacle pixels: the disparity excess over the plane, averaged along matched runs and
   over frames while still, above the threshold, in long enough runs that reach the
   ground (:mod:`.detection`, :mod:`.runs`).
4. Obstacles: obstacle strings clustered by their feet on the ground (:mod:`.grouping`),
   each described by its feet (:mod:`.footing`), its nearest point (:mod:`.nearest`)
   and its faces (:mod:`.faces`); on large images a binned second pass
   (:mod:`.coarse`).
5. Obstacle tracks across frames (:mod:`.tracking`).

Status per frame: 'initialising', 'tracking' or 'lost'; a frame without a plane is a
return value, never an exception. Settings: :class:`GpodConfig` (:mod:`.settings`);
outputs: :class:`GpodResult` (:mod:`.results`). See docs/gpod.md.
"""
from .coarse import bin_pair
from .detector import GpodDetector
from .faces import (
    described_by_part,
    face_gap_points,
    lone_face_points,
    silhouette_owners,
    view_edge_points,
)
from .footing import string_feet
from .grouping import cluster_points_2d
from .nearest import hidden_corner, hidden_corners, nearest_point, nearest_points, soft_nearest
from .results import GpodFeatures, GpodObstacle, GpodPlane, GpodResult
from .runs import (
    continuation_alternatives,
    hanging_runs,
    matched_run_length,
    occluded_matches,
    run_links,
    smooth_along_runs,
    string_pieces,
)
from .settings import STATUSES, GpodConfig

__all__ = [
    'GpodConfig', 'GpodDetector', 'GpodFeatures', 'GpodObstacle', 'GpodPlane', 'GpodResult',
    'STATUSES', 'bin_pair', 'cluster_points_2d', 'continuation_alternatives', 'described_by_part',
    'face_gap_points', 'hanging_runs', 'hidden_corner', 'hidden_corners',
    'lone_face_points', 'matched_run_length', 'nearest_point', 'nearest_points',
    'occluded_matches', 'run_links', 'silhouette_owners', 'smooth_along_runs', 'soft_nearest',
    'string_feet', 'string_pieces', 'view_edge_points',
]
