"""Unseen ground: the walking corridor's ground is hidden by something with no edges.

GPOD (Molton et al. 1998) finds an obstacle by the disparity of its vertical edges. A
plain painted wall or a glass door has almost none, and is missed. It does hide the ground
behind it: the edge pixels that the ground showed, in the part of the walking corridor
farther than the wall's foot, are gone. This module watches for that.

The corridor ahead (``|lateral| <= half_width``, range up to ``max_range``) is divided
into cells of ground ``CELL_DEPTH_M`` deep along the walking direction, each the
corridor's whole width (tile joints that run along the walk leave narrower strips
without a single vertical edge for metres). For each cell in view
the monitor counts the frame's matched edge pixels whose ray meets the ground plane
inside the cell and whose disparity is at most the obstacle threshold above the plane's
(ground, or the lower ground beyond a drop: the ground there is *seen*). A pixel standing
higher is not ground seen at that cell but something in front of it: the faint stripes
of a plain wall, matched here and there, project onto the ground behind the wall's foot
and would otherwise count as the ground it hides (a standing thing that is detected
explains the band it hides, below). The monitor keeps a running mean of that count over
the frames the cell was in view and not hidden (``expected``; learnt slowly where the
cell itself looks hidden, and from no more than ``SURGE_RATIO`` times itself, plus
``SLACK``, in one pair: a pair with many times the usual edges, its edge threshold
lowered on weakly textured ground, must not make the usual count look hidden). The
cells are fixed to the wearer (range, lateral), not to the world, so the expectation
describes "the ground the wearer walks on, at that distance" and carries through turns.

The corridor's ground is *unseen from range R on* when, over the trusted cells in view
from R out to the corridor's far end (at least ``MIN_CELLS`` of them):
- at most ``max_ratio`` of the expected edge pixels are seen, plus ``SLACK`` (a few
  stray matches behind a wall's foot), with at least ``min_expected`` expected (the far
  ground of a 320 x 240 image shows only about 15 edge pixels from 3 m to 5 m: its fine
  texture is not matched that far);
- so are the last ``TAIL_CELLS`` (a plain patch of ground ends, a wall hides all behind
  it);
- and so is the ground beyond the corridor's far end that the band would hide: fewer
  than ``BEYOND_MIN`` of the pair's ground pixels lie up to ``BEYOND_M`` past it, on
  sight lines that cross the band's first cell within the corridor's width (seen from
  above, the sight line to a ground point at range x and lateral y crosses range R at
  lateral y R / x: what covers the corridor at R hides a wedge behind it, wider the
  farther; between the dashes of a painted centre line the asphalt shows no edges out
  to the far end, but the next dash shows beyond it, also where the walker has drifted
  off the line; a wall shows none there, or a stray few);
- and, for a band not already being reported, the cells in front of R showed at least
  ``FRONT_RATIO`` of theirs (a poor view everywhere, such as motion blur, is not ground
  hidden from some range on).
- and, when the left image is given, the band does not show the ground's own fine
  texture: a blurred camera or faint far joints give fewer matched edges over ground that
  is still there, while a surface with no edges is plain (`_foot_and_face`). Plain is
  judged twice: against the nearer ground's texture, and, unless the band's matched edges
  stand above the ground as many as its ground's are missing (a raised footway), against
  the texture its own first cells usually show (``energy``: a running mean per cell,
  learnt with ``expected``; a rise learnt at ``ENERGY_RISE`` of the rate, from at most
  ``SURGE_RATIO`` times itself, so that markings passing do not count), both above the
  pixel noise's (`noise_energy`). The ground's texture is finer in the image, and
  fainter, the farther it lies: a darker stain 3 m ahead still shows the texture the
  ground usually shows there, and is not hidden; a wall's face shows the noise alone.
  A wall's face can show texture too, too faint for the edges: when the caller gives a
  ``face`` judge (`update`; the detector's is the stereo plane sweep of
  `core.plain_face`) and it finds a face standing in the band (from its near edge to
  its far end), the band is hidden all the same.
- On faint pavement the ground shows so few matched edges beyond 3 m that no band
  there is expected to show ``min_expected`` of them, and on a level chest camera the
  ground before it may be barely in view: such a band (every condition above but
  ``min_expected`` and the ground in front) is judged by the ``face`` judge alone. A
  face it finds standing in the band makes it hidden (and places it for
  `_keeps_to_wearer`: a wall walked up to comes nearer, however steady the edges'
  reach); no face, no band.
The nearest such R, found in ``frames`` pairs in a row (within a cell of the previous
one; a pair whose band shows the ground's texture breaks the row; a pair without a
ground plane is no observation, and the detector does not call `update` for it: what
was learnt and the row stay), is reported as
*unknown ahead* from R, unless a detected obstacle or drop-off already stands in the
corridor no farther than R + ``EXPLAINED_M`` (what hides the ground is already
reported). Unseen ground is not evidence of a thing: a plain wall hides it, but so do a
painted marking or a grate whose edges the matcher rejects. The detector reports it in
its obstacle list as an entry at R straight ahead whose height is ``UNKNOWN_HEIGHT``
(NaN: nothing was measured there; `is_unknown`); the alarm logic says "cannot see the
way ahead" (`core.alarm`), never "all clear" and never an obstacle's level, and the
safety score does not count it as an obstacle report. R is the last ground edge pixel
seen, moved on to where the ground's fine texture gives way to a plain face
(`_foot_and_face`).

What hides the ground stays where it is while the wearer walks: the band's near edge
comes nearer by the distance walked. The camera's own reach does not: on a smoother
surface than the one the expectation was learnt on, or ground seen ever more obliquely,
the edges thin out from about the same range however far the wearer walks. With the
wearer's forward travel given (`update`'s ``travel_m``, from the pair's camera motion)
and ``follow_travel_m`` > 0, a band found over that much walking (in at least
``FOLLOW_FOUND_SHARE`` of the pairs, with no stretch of more than ``FOLLOW_GAP_SHARE`` of
it without: the camera's reach flickers, bands glimpsed as a turn sweeps the view come
and go) whose near edge came nearer by less than ``FOLLOW_SHARE`` of the distance walked
(the least squares slope of its range against the distance walked), over the whole
trail and over the latest ``FOLLOW_RECENT_SHARE`` of ``follow_travel_m``, *keeps to the
wearer*: it is not reported, and the cells in view learn what they show at the usual
rate, so that the expectation comes to describe the new ground, until the band is no
longer found. Without the travel (motion unknown, or the wearer standing) nothing
changes.

Limits, which no passive stereo cue avoids: ground that itself has no edges for metres (a
smooth floor after a textured one) looks the same as a wall with none, and is reported
until the wearer has walked ``follow_travel_m`` onto it (for as long as the wearer stands,
or the camera's motion is unknown); a wall already in view when the monitor starts has no
expectation behind it, and is not; a plain surface across only part of the corridor is
not reported. On a small image the
ground beyond about 3 m shows too few matched edge pixels to expect anything of it: a
wall is found when its foot is about 2.5-3 m ahead, not at 4-5 m.

Frames: the left optical frame (x right, y down, z forward); ground coordinates as in
`core.camera.ground_range_bearing` (range along the ground from the point below the left
camera, bearing positive to the left).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .camera import MetricPlane, StereoCamera, columns, ground_axes
from .edges import image_noise_sigma
from .npfast import flat_nonzero

#: Depth of a corridor cell along the walking direction, metres.
CELL_DEPTH_M = 0.25
#: Height of an unknown-ahead entry in an obstacle list: not a number (not measured).
UNKNOWN_HEIGHT = float('nan')
#: Weight of a frame's count in a cell's running mean of ground pixels.
EMA_RATE = 0.1
#: The same weight for a cell whose count is below ``max_ratio`` times its mean.
EMA_RATE_HIDDEN = 0.01
#: Frames a cell must have been seen before its expectation is used.
TRUST_FRAMES = 5
#: A trusted cell learns at most SURGE_RATIO times its expectation, plus SLACK, from one
#: pair: a pair whose edge threshold was lowered on weakly textured ground
#: (`core.edges`), or a marking passing through the cell, shows many times the usual
#: edge pixels, and would otherwise lift the expectation so far that the next pairs'
#: usual count looks hidden.
SURGE_RATIO = 2.0
#: A cell's usual texture energy learns a rise at ENERGY_RISE times the rate of a fall: it
#: describes the plain ground between markings, not the markings.
ENERGY_RISE = 0.2
#: A detected obstacle in the corridor (or within 0.1 m of it) no farther than R + this
#: explains the unseen ground.
EXPLAINED_M = 0.5
#: The band's last TAIL_CELLS trusted cells must show at most max_ratio of their expected
#: edge pixels, plus SLACK.
TAIL_CELLS = 2
#: Edge pixels a hidden band (and its tail) may show beyond max_ratio of those expected:
#: stray matches, about one per cell behind a wall's foot, would otherwise fail a band
#: whose expectation is small (the far ground of a small image shows a few edge pixels
#: per cell).
SLACK = 2.0
#: A band starts to be reported only when the cells in front of it showed at least
#: FRONT_RATIO of their expected edge pixels, and FRONT_MIN * min_expected were expected.
FRONT_RATIO = 0.5
FRONT_MIN = 0.5
#: Image margin a cell's corners must keep to count as in view, pixels.
MARGIN_PX = 3.0
#: Foot refinement (`UnseenGroundMonitor._foot_and_face`): search span and step
#: along the ground (metres), the least ratio of the ground's texture energy to the
#: hiding face's, and the samples in a row that must be plain.
FOOT_SEARCH_M = 0.75
FOOT_STEP_M = 0.02
FOOT_CONTRAST = 2.0
#: Rows of ground and of face (samples FOOT_STEP_M apart, half of FOOT_SEARCH_M) it takes
#: to say that the face is not plain (that the band is not hidden by a surface with no
#: edges).
PLAIN_MIN_SAMPLES = int(round(0.5 * FOOT_SEARCH_M / FOOT_STEP_M))
FOOT_RUN = 3
#: Least number of trusted cells in view in a reported band.
MIN_CELLS = 2
#: A band found over ``follow_travel_m`` of walking whose near edge came nearer by less
#: than this share of the distance walked keeps to the wearer, not to the world.
FOLLOW_SHARE = 0.5
#: A band's trail (`_keeps_to_wearer`) goes on over pairs that find no band while none was
#: found over this share of ``follow_travel_m`` of walking, and is judged only when at
#: least FOLLOW_FOUND_SHARE of its pairs found the band: the camera's reach flickers
#: (found in 8 pairs of 10 on a raised footway's finer texture), bands glimpsed as a turn
#: sweeps the view come and go (every other pair).
FOLLOW_GAP_SHARE = 0.35
FOLLOW_FOUND_SHARE = 0.75
#: The band keeps to the wearer only if its near edge came nearer by less than
#: FOLLOW_SHARE of the distance walked over the latest FOLLOW_RECENT_SHARE of
#: ``follow_travel_m`` of walking too (at least 3 pairs that found it): a plain wall
#: beyond the camera's reach leaves the band at the reach until its foot comes within it,
#: and then draws the band's edge nearer at the walking pace.
FOLLOW_RECENT_SHARE = 0.5
#: What hides the ground out to the corridor's far end hides the ground beyond it too: a
#: band is not hidden when at least BEYOND_MIN of the pair's ground pixels lie up to
#: BEYOND_M beyond its far end on sight lines through its first cell within the
#: corridor's width (the next dash of a painted line past a gap of plain asphalt; a
#: plain wall shows none, or a stray few).
BEYOND_M = 7.0
BEYOND_MIN = 10


def is_unknown(height: float) -> bool:
    """Whether an obstacle list's entry of this height is unknown ground ahead (the
    unseen band, ``UNKNOWN_HEIGHT``), not a thing."""
    return math.isnan(height)


@dataclass(frozen=True)
class UnseenReport:
    """The corridor's ground unseen from ``range`` on.

    Attributes:
        position: (3,) float64 the point ``height`` above the ground at the band's near
            edge, in the corridor's middle, metres, left optical frame.
        height: metres: a lower bound of what hides the band: the height at range R of the
            ray that meets the ground at the band's far end (the hidden thing must reach
            at least that high to hide all of the band).
        range: metres along the ground to the band's near edge (straight ahead: bearing 0).
        width: metres, the corridor's width.
        expected: edge pixels expected over the band.
        seen: edge pixels counted over the band in this frame.
        far_range: metres, the band's far end (the farthest cell in view).
    """

    position: np.ndarray
    height: float
    range: float
    width: float
    expected: float
    seen: float
    far_range: float


class UnseenGroundMonitor:
    """Running expectation of the ground's edge pixels in the corridor, and the band of it
    that has gone unseen (see the module doc).

    Args:
        max_ratio: a band is unseen when its edge pixels are at most this fraction of
            those expected (0 < max_ratio < 1).
        min_expected: least number of edge pixels expected over a band for it to count
            (> 0).
        frames: pairs in a row a band must be found unseen before it is reported (>= 1).
        max_range: metres, the far end of the corridor (> CELL_DEPTH_M).
        half_width: metres, the corridor's half width (> 0).
        follow_travel_m: metres of walking over which a band is watched for keeping to
            the wearer (>= 0; 0: off).
    """

    def __init__(self, max_ratio: float, min_expected: float, frames: int, max_range: float,
                 half_width: float, follow_travel_m: float = 0.0) -> None:
        if not 0.0 < max_ratio < 1.0:
            raise ValueError(f'max_ratio = {max_ratio} must be in (0, 1)')
        if not min_expected > 0:
            raise ValueError(f'min_expected = {min_expected} must be > 0')
        if frames < 1:
            raise ValueError(f'frames = {frames} must be >= 1')
        if not max_range > CELL_DEPTH_M:
            raise ValueError(f'max_range = {max_range} must be > {CELL_DEPTH_M}')
        if not half_width > 0:
            raise ValueError(f'half_width = {half_width} must be > 0')
        if not (math.isfinite(follow_travel_m) and follow_travel_m >= 0):
            raise ValueError(f'follow_travel_m = {follow_travel_m} must be >= 0')
        self.follow_travel_m = float(follow_travel_m)
        self.max_ratio = float(max_ratio)
        self.min_expected = float(min_expected)
        self.frames = int(frames)
        self.half_width = float(half_width)
        n_r = int(math.ceil(max_range / CELL_DEPTH_M))
        #: (n_r + 1,) range edges of the cells, metres.
        self.range_edges = np.arange(n_r + 1) * CELL_DEPTH_M
        self.reset()

    def reset(self) -> None:
        """Forget every expectation (a new camera, or a new calibration)."""
        n_r = len(self.range_edges) - 1
        #: (n_r,) running mean of edge pixels per cell.
        self.expected = np.zeros(n_r)
        #: (n_r,) frames each cell was seen in (counted into ``expected``).
        self.seen_frames = np.zeros(n_r, np.int64)
        #: (n_r,) running mean of each cell's fine texture energy (`_cell_energy`; grey
        #: levels per pixel), learnt with ``expected`` from the pairs with a left image
        #: (NaN: never measured)
        self.energy = np.full(n_r, np.nan)
        #: pairs in a row the band was found, and its first cell in the last of them
        self._streak = 0
        self._last_cell = -10
        #: metres walked forward over the pairs with a known travel
        self._travel = 0.0
        #: (distance walked, near edge's range) of the band in the pairs that found one
        self._trail: list[tuple[float, float]] = []
        #: the band keeps to the wearer (`_keeps_to_wearer`), at this range (m)
        self._follows = False
        self._follow_range = math.inf

    # -------------------------------------------------------------- geometry
    def pixel_ground(self, cam: StereoCamera, metric: MetricPlane, u: np.ndarray,
                     v: np.ndarray) -> np.ndarray:
        """(N, 2) ground coordinates (range along the walking direction, lateral to the
        left; metres) where the left-image pixels (u, v) (N,) look at the plane; NaN for
        pixels at or above the horizon."""
        n = np.asarray(metric.normal_up, float)
        a = (np.asarray(u, float) - cam.cx) / cam.f
        b = (np.asarray(v, float) - cam.cy) / cam.f
        one = np.ones(np.shape(u))
        nr = columns(a, b, one) @ n
        with np.errstate(divide='ignore', invalid='ignore'):
            t = np.where(nr < -1e-9, -metric.height / nr, np.nan)
        origin, fwd, lft = ground_axes(metric)
        # r t - origin (r = (a, b, 1)), column by column: the same products and differences
        g = columns(a * t - origin[0], b * t - origin[1], one * t - origin[2])
        return columns(g @ fwd, g @ lft)

    def cells_in_view(self, cam: StereoCamera, metric: MetricPlane) -> np.ndarray:
        """(n_r,) bool: the cell's four ground corners project inside the left image, at
        least ``MARGIN_PX`` from its border."""
        origin, fwd, lft = ground_axes(metric)
        lat = np.array([-self.half_width, self.half_width])
        p = (origin + self.range_edges[None, :, None] * fwd
             + lat[:, None, None] * lft)                             # (2, n_r+1, 3)
        z = p[..., 2]
        ok = z > 1e-3
        zs = np.where(ok, z, 1.0)
        u = cam.f * p[..., 0] / zs + cam.cx
        v = cam.f * p[..., 1] / zs + cam.cy
        inside = (ok & (u >= MARGIN_PX) & (u <= cam.width - 1 - MARGIN_PX)
                  & (v >= MARGIN_PX) & (v <= cam.height - 1 - MARGIN_PX)).all(axis=0)
        return inside[:-1] & inside[1:]

    def _beyond(self, xy: np.ndarray, view: np.ndarray, found: int) -> float:
        """Number of ground points xy (N, 2) from the far end of the last cell in
        ``view`` (n_r,) out to ``BEYOND_M`` past it whose sight lines cross the far end
        of cell ``found`` (the band's first) within the corridor's width: seen from
        above, the line from the camera to (x, y) crosses range R at lateral y R / x, so
        that |y| <= half_width x / R (0 with no cell in view). The first cell's far end:
        what hides the band stands within that cell, and the nearer it stands the wider
        the wedge it hides; the narrowest is taken."""
        cells = flat_nonzero(view)
        if not len(cells):
            return 0.0
        far = float(self.range_edges[cells[-1] + 1])
        near = float(self.range_edges[min(found + 1, len(self.range_edges) - 1)])
        with np.errstate(invalid='ignore'):
            ok = ((np.abs(xy[:, 1]) * near <= self.half_width * xy[:, 0])
                  & (xy[:, 0] > far) & (xy[:, 0] <= far + BEYOND_M))
        return float(np.count_nonzero(ok))

    def _count(self, xy: np.ndarray) -> np.ndarray:
        """(n_r,) number of ground points xy (N, 2) in each cell of the corridor."""
        ok = (np.isfinite(xy[:, 0]) & np.isfinite(xy[:, 1]) & (xy[:, 1] >= -self.half_width)
              & (xy[:, 1] <= self.half_width))
        # np.histogram's counts over the edges (a bin holds its lower edge, the last
        # also its upper one), without its sort
        edges = self.range_edges
        n_r = edges.shape[0] - 1
        x = xy[ok, 0]
        b = np.searchsorted(edges, x, side='right') - 1
        b[x == edges[-1]] = n_r - 1
        return np.bincount(b[(b >= 0) & (b < n_r)], minlength=n_r).astype(float)

    def _row_energy(self, ii: np.ndarray, cam: StereoCamera, metric: MetricPlane,
                    r: np.ndarray) -> np.ndarray:
        """(len(r),) mean fine texture energy of the corridor's image row at each range r
        (metres along the ground), over the corridor's columns, from ``ii`` (H + 1, W + 1)
        float64, the integral image of the texture energy (`_texture_integral`); NaN
        where that row is not in the image (or spans fewer than 2 columns)."""
        origin, fwd, lft = ground_axes(metric)
        h, w = ii.shape[0] - 1, ii.shape[1] - 1
        lat = np.array([-self.half_width, 0.0, self.half_width])
        p = origin + r[:, None, None] * fwd + lat[None, :, None] * lft      # (R, 3, 3)
        z = p[..., 2]
        ok = (z > 1e-3).all(axis=1)
        zs = np.where(z > 1e-3, z, 1.0)
        u = cam.f * p[..., 0] / zs + cam.cx                                 # (R, 3)
        vi = np.rint(cam.f * p[:, 1, 1] / zs[:, 1] + cam.cy)
        u0 = np.clip(np.floor(np.minimum(u[:, 0], u[:, 2])), 0, w)
        u1 = np.clip(np.ceil(np.maximum(u[:, 0], u[:, 2])), 0, w)
        ok &= (u1 - u0 >= 2) & (vi >= 1) & (vi <= h - 2)
        rows = np.where(ok, vi, 0).astype(np.intp)
        a, b = np.where(ok, u0, 0).astype(np.intp), np.where(ok, u1, 1).astype(np.intp)
        mean = ((ii[rows + 1, b] - ii[rows, b] - ii[rows + 1, a] + ii[rows, a])
                / np.maximum(b - a, 1))
        return np.where(ok, mean, np.nan)

    def _cell_of(self, r: np.ndarray) -> np.ndarray:
        """(len(r),) intp the corridor cell of each range r >= 0 (metres; the last cell
        for r at or beyond the corridor's far end)."""
        return np.minimum((r / CELL_DEPTH_M).astype(np.intp), len(self.range_edges) - 2)

    def _cell_energy(self, ii: np.ndarray, cam: StereoCamera,
                     metric: MetricPlane) -> np.ndarray:
        """(n_r,) mean fine texture energy (``ii``, `_row_energy`) of each cell's image
        rows: the corridor's rows sampled every ``FOOT_STEP_M`` along the ground inside
        the cell; NaN for a cell none of whose rows is in the image."""
        r = np.arange(0.5 * FOOT_STEP_M, self.range_edges[-1], FOOT_STEP_M)
        mean = self._row_energy(ii, cam, metric, r)
        ok = np.isfinite(mean)
        cell = self._cell_of(r)
        n_r = len(self.range_edges) - 1
        tot = np.bincount(cell[ok], weights=mean[ok], minlength=n_r)
        cnt = np.bincount(cell[ok], minlength=n_r)
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan)

    def _near_edge(self, xy: np.ndarray, excess: np.ndarray, threshold,
                   found: int) -> float:
        """The band's near edge, metres: the last ground edge pixel seen in its first
        cell ``found`` (xy: (K, 2) the pixels' ground points, excess: (K,) pixels,
        threshold: scalar or (K,) pixels), or the cell's near end."""
        r0 = float(self.range_edges[found])
        thr = np.broadcast_to(np.asarray(threshold, float), excess.shape)
        with np.errstate(invalid='ignore'):
            on = (np.isfinite(excess) & (np.abs(excess) <= thr) & np.isfinite(xy[:, 0])
                  & np.isfinite(xy[:, 1]))
        inside = (on & (xy[:, 1] >= -self.half_width) & (xy[:, 1] < self.half_width)
                  & (xy[:, 0] >= r0) & (xy[:, 0] < r0 + CELL_DEPTH_M))
        return float(np.max(xy[inside, 0])) if inside.any() else r0

    def _foot_and_face(self, ii: np.ndarray, cam: StereoCamera, metric: MetricPlane,
                       r_near: float, far: float,
                       floor: float | None = None) -> tuple[float, bool | None]:
        """The near edge of the unseen band, refined in the image, and whether what hides
        the band has a plain face.

        The last ground edge pixel seen (``r_near``) can lie short of what hides the
        ground: a tile's plain inside shows no edges. The ground's fine texture (``ii``,
        its integral image, `_texture_integral`) usually goes on up to the foot, where
        the hiding surface's plain face begins. Along the corridor, from ``r_near`` out to
        ``FOOT_SEARCH_M`` beyond it, the texture energy of each image row (averaged over
        the corridor's columns) is compared with the ground's (the median of the rows up
        to ``FOOT_SEARCH_M`` nearer) and the hiding face's (the median of the rows of the
        band's last ``FOOT_SEARCH_M``). When the ground's is at least ``FOOT_CONTRAST``
        times the face's, the foot is where the energy first stays below their mean for
        ``FOOT_RUN`` samples. Otherwise ``r_near`` stands. With a ``floor`` (the texture
        energy of the camera's pixel noise alone, `noise_energy`), the texture above it
        in the band's first ``FOOT_SEARCH_M`` (the rows' median) is also compared with
        the texture above it that its cells usually show (``energy``, the mean over
        those cells): when that is less than ``FOOT_CONTRAST`` times it (at least
        ``FOOT_RUN`` rows in the image), the face is not plain.

        Returns:
            (metres along the ground, at least ``r_near``; True when the face is plain --
            the ground's energy at least ``FOOT_CONTRAST`` times the face's --, False when
            it is not -- the band shows the ground's own fine texture, only fewer matched
            edges: a blurred camera, faint far joints, not a surface with no edges --,
            None when too few rows of either are in the image to tell: fewer than
            ``FOOT_RUN``, or fewer than ``PLAIN_MIN_SAMPLES`` to say it is not plain).
        """
        def rows(r: np.ndarray) -> np.ndarray:
            return self._row_energy(ii, cam, metric, r)

        step = FOOT_STEP_M
        ground = rows(np.arange(max(0.0, r_near - FOOT_SEARCH_M), r_near, step))
        face = rows(np.arange(max(r_near, far - FOOT_SEARCH_M), far, step))
        ground, face = ground[np.isfinite(ground)], face[np.isfinite(face)]
        if len(ground) < FOOT_RUN or len(face) < FOOT_RUN:
            return r_near, None
        e_g, e_f = float(np.median(ground)), float(np.median(face))
        if floor is not None:
            # the band's first FOOT_SEARCH_M shows the texture the ground there usually
            # shows (far ground's texture is finer in the image, and fainter, than the
            # nearer ground's: compared with that alone, it looks plain); texture above
            # the pixel noise's (a plain face shows the noise alone)
            span = np.arange(r_near, min(far, r_near + FOOT_SEARCH_M), step)
            just = rows(span)
            just = just[np.isfinite(just)]
            cells = np.unique(self._cell_of(span))
            usual = float(np.mean(self.energy[cells])) - floor
            if len(just) >= FOOT_RUN and math.isfinite(usual):
                above = float(np.median(just)) - floor
                if above > 0.0 and usual < FOOT_CONTRAST * above:
                    return r_near, False
        if e_g < FOOT_CONTRAST * max(e_f, 1e-6):
            # not plain -- if enough of both was seen to tell: a wall walked up to leaves
            # only the image's last rows of ground before it, which may be the wall's
            # foot itself
            told = min(len(ground), len(face)) >= PLAIN_MIN_SAMPLES
            return r_near, (False if told else None)
        thr = 0.5 * (e_g + e_f)
        r = np.arange(r_near, min(far, r_near + FOOT_SEARCH_M) + 1e-9, step)
        e = rows(r)
        low = np.isfinite(e) & (e < thr)
        for j in range(len(r) - FOOT_RUN + 1):
            if low[j:j + FOOT_RUN].all():
                return float(max(r_near, r[j] - 0.5 * step)), True
        return r_near, True

    # ---------------------------------------------------------------- update
    def _band_start(self, trusted: np.ndarray, k_all: np.ndarray,
                    min_expected: float | None = None) -> int | None:
        """The first cell of the nearest band hidden out to the corridor's far end (the
        module doc's first two conditions; ``min_expected``: the least expectation over
        it, None: ``self.min_expected``), or None."""
        n_r = len(trusted)
        least = self.min_expected if min_expected is None else min_expected
        # suffix sums over the trusted cells, from the far end in
        lam = np.where(trusted, self.expected, 0.0)[::-1].cumsum()[::-1]
        k = np.where(trusted, k_all, 0.0)[::-1].cumsum()[::-1]
        cells = trusted[::-1].cumsum()[::-1]
        starts = flat_nonzero(trusted & (cells >= MIN_CELLS) & (lam >= least)
                                & (k <= self.max_ratio * lam + SLACK))
        if not len(starts):
            return None
        i = int(starts[0])
        # the band's far end must be hidden too: a plain patch of ground ends, a wall
        # hides all behind it
        tail = flat_nonzero(trusted & (np.arange(n_r) >= i))[-TAIL_CELLS:]
        if k_all[tail].sum() > self.max_ratio * self.expected[tail].sum() + SLACK:
            return None
        return i

    def update(self, cam: StereoCamera, metric: MetricPlane, u: np.ndarray, v: np.ndarray,
               excess: np.ndarray, threshold: np.ndarray | float,
               explained: np.ndarray | None = None, left: np.ndarray | None = None,
               travel_m: float | None = None,
               face: Callable[[float, float], float | None] | None = None
               ) -> UnseenReport | None:
        """Count one frame's edge pixels, report the unseen band, learn the rest.

        Args:
            cam: the rectified stereo camera.
            metric: this frame's ground plane (left optical frame).
            u, v: (K,) left-image column and row of the frame's matched edge pixels.
            excess: (K,) their disparity minus the plane's, pixels (NaN: unusable).
            threshold: the obstacle threshold, pixels: a scalar or (K,) per pixel; a
                pixel whose excess is above it is not counted as ground seen.
            explained: (M, 2) ground coordinates (range, lateral; metres) of the feet of
                the frame's detected obstacles and drop-offs (None: none).
            left: (H, W) uint8 the left image, to place the band's near edge where the
                ground's fine texture gives way to the hiding surface's
                (`_foot_and_face`); None: at the last ground edge pixel seen.
            travel_m: metres the wearer walked forward along the ground since the
                previous pair (the camera's motion laid on the plane), or None (unknown):
                for a band that keeps to the wearer (`_keeps_to_wearer`).
            face: the range (metres) of a face standing across the corridor in a band
                from its near edge to its far end (the two arguments, metres), or None
                (e.g. `core.plain_face`): a band whose image shows texture is still
                hidden where that texture is such a face, and a band with too little
                expected of it is one where there is such a face (None: never).
        Returns:
            the report, or None.
        """
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        excess = np.asarray(excess, float)
        xy = self.pixel_ground(cam, metric, u, v)
        thr = np.broadcast_to(np.asarray(threshold, float), excess.shape)
        with np.errstate(invalid='ignore'):
            # ground or lower: a pixel standing above the threshold is not ground seen
            ground = np.isfinite(excess) & (excess <= thr)
            raised = np.isfinite(excess) & (excess > thr)
        seen = xy[ground]
        k_all = self._count(seen)
        view = self.cells_in_view(cam, metric)
        ii = _texture_integral(left) if left is not None else None
        cell_e = (self._cell_energy(ii, cam, metric) if ii is not None
                  else np.full(len(view), np.nan))
        trusted = view & (self.seen_frames >= TRUST_FRAMES)
        n_r = len(view)
        found = self._band_start(trusted, k_all)
        if found is not None and self._beyond(seen, view, found) >= BEYOND_MIN:
            found = None        # ground seen beyond the far end is seen past the band
        faced = None
        if found is None and face is not None:
            # too little expected of the band, or too little of the ground before it, to
            # say it is hidden (faint pavement): a face the judge finds standing in it is
            # evidence enough
            weak = self._band_start(trusted, k_all, 0.0)
            if weak is not None and self._beyond(seen, view, weak) < BEYOND_MIN:
                far = float(self.range_edges[flat_nonzero(trusted)[-1] + 1])
                faced = face(self._near_edge(xy, excess, threshold, weak), far)
                found = weak if faced is not None else None
        # (such a band is where its face stands: a wall walked up to comes nearer)
        follows = self._keeps_to_wearer(found, travel_m, faced)
        learn = view.copy()
        report = None
        if found is None or follows:
            # no band, or one that keeps to the wearer: the ground as it looks from here
            self._streak, self._last_cell = 0, -10
        else:
            band = trusted & (np.arange(n_r) >= found)
            learn &= np.arange(n_r) < found                # a hidden band is not learnt
            near = self._streak > 0 and abs(found - self._last_cell) <= 1
            # the ground in front of the band must be seen as usual, or the whole view is
            # poor (motion blur, glare), not hidden from some range on; a band already
            # being reported goes on without it (a wall walked up to)
            front = trusted & (np.arange(n_r) < found)
            lam_f = float(self.expected[front].sum())
            front_ok = (lam_f >= FRONT_MIN * self.min_expected
                        and float(k_all[front].sum()) >= FRONT_RATIO * lam_f)
            if front_ok or near or faced is not None:
                self._streak = self._streak + 1 if near else 1
                self._last_cell = found
                report, textured = self._report(cam, metric, xy, excess, threshold, band,
                                                found, k_all, explained, ii,
                                                float(self._count(xy[raised])[band].sum()),
                                                noise_energy(left) if left is not None else None,
                                                face, faced is not None)
                if textured:
                    # the band showed the ground's own texture: this pair is evidence
                    # against it, and the pairs in a row start again (a turn that sets
                    # the tile joints aslant gives fewer vertical edges over ground still
                    # there; the next pair, too close to tell, must not complete a
                    # streak that this one broke)
                    self._streak, self._last_cell = 0, -10
            else:
                self._streak, self._last_cell = 0, -10
        self._learn(learn, k_all, cell_e, follows)
        return report

    def _learn(self, learn: np.ndarray, k_all: np.ndarray, cell_e: np.ndarray,
               follows: bool) -> None:
        """Learn the cells in ``learn`` (n_r,) bool from this pair's edge pixels
        ``k_all`` (n_r,) and texture energy ``cell_e`` (n_r,; NaN: not measured);
        ``follows``: the band keeps to the wearer."""
        n_r = len(learn)
        # learn: the running mean of each cell in view and not hidden; a cell that looks
        # hidden itself is learnt slowly (a wall creeping into the corridor's far end
        # must not teach that the ground there shows nothing), unless the band keeps to
        # the wearer (nothing in the world hides it)
        e = self.expected
        first = learn & (self.seen_frames == 0)
        e[first] = k_all[first]
        rest = learn & ~first
        rate = (np.full(n_r, EMA_RATE) if follows
                else np.where(k_all < self.max_ratio * e, EMA_RATE_HIDDEN, EMA_RATE))
        # a trusted cell's surge is clipped (SURGE_RATIO); a new cell learns what it sees
        z = np.where(self.seen_frames >= TRUST_FRAMES,
                     np.minimum(k_all, SURGE_RATIO * e + SLACK), k_all)
        e[rest] += rate[rest] * (z[rest] - e[rest])                  # x <- x + a (z - x)
        # each cell's usual texture energy, learnt with its edge pixels; a rise is learnt
        # at ENERGY_RISE of the rate and from at most SURGE_RATIO times itself (a zebra
        # crossing passing through must not make the plain asphalt after it look plain)
        g = self.energy
        ok = learn & np.isfinite(cell_e)
        new_e = ok & ~np.isfinite(g)
        g[new_e] = cell_e[new_e]
        old_e = ok & ~new_e
        z_e = np.minimum(cell_e, SURGE_RATIO * g)
        rate_e = np.where(z_e > g, ENERGY_RISE * rate, rate)
        g[old_e] += rate_e[old_e] * (z_e[old_e] - g[old_e])         # x <- x + a (z - x)
        self.seen_frames[learn] += 1

    def _keeps_to_wearer(self, found: int | None, travel_m: float | None,
                         at: float | None = None) -> bool:
        """Whether the band found this pair (its first cell ``found``, None: none; ``at``:
        its range, metres, None: its first cell's near end) keeps to the wearer. The
        pairs since a band was first found, each at the distance walked so far (a pair
        with an unknown ``travel_m`` adds no distance) with the band's range (NaN: none
        found), are kept over the last 2 ``follow_travel_m`` of
        walking, until no band is found over ``FOLLOW_GAP_SHARE`` of ``follow_travel_m``;
        once they span ``follow_travel_m`` and at least ``FOLLOW_FOUND_SHARE`` of them
        found it, the band keeps to the wearer if its near edge's range fell by less
        than ``FOLLOW_SHARE`` of the distance walked (least squares slope of range
        against distance over the pairs that found it; a wall walked up to: -1), over
        the whole trail and over its latest ``FOLLOW_RECENT_SHARE`` of
        ``follow_travel_m`` (a wall whose foot has just come within the reach). It
        goes on keeping to the wearer until no band is found over ``follow_travel_m`` of
        walking, or one is found more than two cells nearer (a new band: something in
        front of the wearer's reach). Always False with ``follow_travel_m`` 0."""
        if self.follow_travel_m <= 0.0:
            return False
        if travel_m is not None and math.isfinite(travel_m):
            self._travel += float(travel_m)
        trail = self._trail
        if found is None:
            # the trail goes on over a gap of less than FOLLOW_GAP_SHARE of
            # follow_travel_m of walking (the pair kept as a miss, NaN); once the band
            # keeps to the wearer, until none is found over follow_travel_m (the
            # expectation learnt, the band shows in a pair now and then)
            last = next((d for d, r in reversed(trail) if not math.isnan(r)), None)
            gap = (self.follow_travel_m if self._follows
                   else FOLLOW_GAP_SHARE * self.follow_travel_m)
            if last is None or self._travel - last > gap:
                trail.clear()
                self._follows = False
            elif not self._follows:
                trail.append((self._travel, math.nan))
                self._trim(trail)
            return False
        r = float(self.range_edges[found]) if at is None else float(at)
        if self._follows and r < self._follow_range - 2.0 * CELL_DEPTH_M:
            trail.clear()
            self._follows = False
        trail.append((self._travel, r))
        self._trim(trail)
        if self._follows:
            # a wall whose foot comes within the reach draws the band nearer at the
            # walking pace: the band no longer keeps to the wearer
            s, rr = np.asarray(trail).T
            hit = np.isfinite(rr)
            recent = self._recent_slope(s[hit], rr[hit])
            if recent is not None and recent <= -FOLLOW_SHARE:
                self._follows = False
            return self._follows
        if trail[-1][0] - trail[0][0] < self.follow_travel_m:
            return False
        s, rr = np.asarray(trail).T               # distance walked, band's range (m)
        hit = np.isfinite(rr)
        if hit.mean() < FOLLOW_FOUND_SHARE:
            return False
        s, rr = s[hit], rr[hit]
        if s[-1] - s[0] < self.follow_travel_m:
            return False
        # over the whole trail, and over its latest FOLLOW_RECENT_SHARE of
        # follow_travel_m: a wall beyond the reach leaves the band at the reach until
        # the wearer has come near enough for its foot to be the band's edge, from
        # where the band comes nearer at the walking pace
        recent = self._recent_slope(s, rr)
        self._follows = (_slope(s, rr) > -FOLLOW_SHARE
                         and recent is not None and recent > -FOLLOW_SHARE)
        if self._follows:
            self._follow_range = float(np.median(rr))
        return self._follows

    def _recent_slope(self, s: np.ndarray, rr: np.ndarray) -> float | None:
        """The slope of the band's range ``rr`` against the distance walked ``s`` (both
        (n,) metres, the pairs that found it) over the latest ``FOLLOW_RECENT_SHARE`` of
        ``follow_travel_m`` of walking (`_slope`: -inf with no walking among them); None
        with fewer than 3 such pairs."""
        recent = s >= s[-1] - FOLLOW_RECENT_SHARE * self.follow_travel_m
        return _slope(s[recent], rr[recent]) if recent.sum() >= 3 else None

    def _trim(self, trail: list) -> None:
        """Keep the last 2 ``follow_travel_m`` of walking of ``trail`` (and 200 pairs:
        a wearer standing)."""
        while len(trail) > 200 or trail[0][0] < self._travel - 2.0 * self.follow_travel_m:
            trail.pop(0)

    def _report(self, cam: StereoCamera, metric: MetricPlane, xy: np.ndarray,
                excess: np.ndarray, threshold, band: np.ndarray, found: int,
                k_all: np.ndarray, explained: np.ndarray | None,
                ii: np.ndarray | None, raised: float = 0.0,
                floor: float | None = None,
                face: Callable[[float, float], float | None] | None = None, faced: bool = False
                ) -> tuple[UnseenReport | None, bool]:
        """The found band as a report: its near edge placed, unless a known obstacle
        explains it or it has not yet been found ``frames`` pairs in a row. ``ii``: the
        integral image of the pair's texture energy (`_texture_integral`; None: no image);
        ``raised``: the band's matched edge pixels standing above the threshold;
        ``floor``: the pixel noise's texture energy (`noise_energy`; None: unknown);
        ``face``: as `update`'s (a textured band in which a face stands is hidden all
        the same); ``faced``: the band is one only for the face the judge found in it
        (its texture is not judged). Returns (the report or None, whether the band showed
        the ground's own fine texture)."""
        r_near = self._near_edge(xy, excess, threshold, found)
        far = float(self.range_edges[flat_nonzero(band)[-1] + 1])
        if ii is not None and not faced:
            # the texture the ground at the face's range usually shows; unless the band's
            # matched edges stand above the ground, as many as the ground's are missing
            # (a raised footway beyond a kerb: textured, but not the ground)
            lam = float(self.expected[band].sum())
            r_near, plain = self._foot_and_face(
                ii, cam, metric, r_near, far,
                floor if raised <= self.max_ratio * lam + SLACK else None)
            if plain is False and (face is None or face(r_near, far) is None):
                # the band shows the ground's fine texture (not a face's that stands
                # at its edge): nothing plain hides it
                return None, True
        if explained is not None and len(explained):
            ex = np.asarray(explained, float).reshape(-1, 2)
            if np.any((np.abs(ex[:, 1]) <= self.half_width + 0.1)
                      & (ex[:, 0] <= r_near + EXPLAINED_M)):
                return None, False
        if self._streak < self.frames:
            return None, False
        height = metric.height * max(0.0, 1.0 - r_near / far)
        origin, fwd, _ = ground_axes(metric)
        pos = origin + r_near * fwd + height * np.asarray(metric.normal_up, float)
        return UnseenReport(position=pos, height=height, range=r_near,
                            width=2.0 * self.half_width,
                            expected=float(self.expected[band].sum()),
                            seen=float(k_all[band].sum()), far_range=far), False


def _slope(s: np.ndarray, r: np.ndarray) -> float:
    """Least squares slope of r against s (both (n,) float64, metres); -inf when s does
    not vary (nothing to tell by)."""
    ds = s - s.mean()
    den = float(ds @ ds)
    return float(ds @ (r - r.mean())) / den if den > 0.0 else -math.inf


#: Texture energy (`_texture_energy`) of pixel noise alone, per grey level of its
#: standard deviation: the 3 x 3 box and the central difference leave 0.385 / 2 of it per
#: direction, and E|x| = sqrt(2 / pi) sigma of a Gaussian: 2 * 0.19 * 0.80.
NOISE_ENERGY = 0.307


def noise_energy(left: np.ndarray) -> float:
    """The texture energy of a grey image's pixel noise alone: ``NOISE_ENERGY`` times its
    standard deviation, Immerkaer's estimate from the mean absolute response to a
    difference of Laplacians, which cancels smooth shading (`edges.image_noise_sigma`
    with ``robust`` False); texture adds to it, so that textured images give somewhat
    more.

    Args:
        left: (H, W) uint8 grey image, H, W >= 3.
    Returns:
        grey levels per pixel (>= 0).
    """
    return NOISE_ENERGY * image_noise_sigma(left, robust=False)


def _texture_integral(left: np.ndarray) -> np.ndarray:
    """(H + 1, W + 1) float64 integral image (`cv2.integral`) of `_texture_energy`."""
    return cv2.integral(_texture_energy(left), sdepth=cv2.CV_64F)


def _texture_energy(left: np.ndarray) -> np.ndarray:
    """(H, W) float32 fine texture of a grey image: |dI/du| + |dI/dv| (central
    differences, grey levels per pixel) of the image smoothed by a 3 x 3 box, so that
    pixel noise counts less than texture."""
    g = cv2.blur(left.astype(np.float32), (3, 3))
    gx = np.zeros_like(g)
    gy = np.zeros_like(g)
    # in place, the halving last: the same values (halving is exact), a third the time
    np.subtract(g[:, 2:], g[:, :-2], out=gx[:, 1:-1])
    np.subtract(g[2:, :], g[:-2, :], out=gy[1:-1, :])
    np.abs(gx, out=gx)
    np.abs(gy, out=gy)
    np.add(gx, gy, out=gx)
    np.multiply(gx, 0.5, out=gx)
    return gx
