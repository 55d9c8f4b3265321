"""Unseen ground: the walking corridor's ground is hidden by something with no edges.

GPOD (Molton et al. 1998) finds an obstacle by the disparity of its vertical edges. A
plain painted wall or a glass door has almost none, and is missed. It does hide the ground
behind it: the edge pixels that the ground showed, in the part of the walking corridor
farther than the wall's foot, are gone. This module watches for that.

The corridor ahead (``|lateral| <= half_width``, range up to ``max_range``) is divided
into cells of ground ``CELL_DEPTH_M`` deep along the walking direction (``STRIPS``
strips across it: one, the corridor's whole width; tile joints that run along the walk
leave narrower strips without a single vertical edge for metres). For each cell in view
the monitor counts the frame's matched edge pixels whose ray meets the ground plane
inside the cell, at any disparity (ground, obstacle or the lower ground beyond a drop:
all of them are *seen*), and keeps a running mean of that count over the frames the cell
was in view and not hidden (``expected``; learnt slowly where the cell itself looks
hidden). The cells are fixed to the wearer (range, lateral), not to the world, so the
expectation describes "the ground the wearer walks on, at that distance" and carries
through turns.

The corridor's ground is *unseen from range R on* when, over the trusted cells in view
from R out to the corridor's far end (at least ``MIN_CELLS`` of them):
- at most ``max_ratio`` of the expected edge pixels are seen, with at least
  ``min_expected`` expected;
- so are the last ``TAIL_CELLS`` (a plain patch of ground ends, a wall hides all behind
  it);
- and, for a band not already being reported, the cells in front of R showed at least
  ``FRONT_RATIO`` of theirs (a poor view everywhere, such as motion blur, is not ground
  hidden from some range on).
The nearest such R, found in ``frames`` pairs in a row (within a cell of the previous
one), is reported as an obstacle at R straight ahead, unless a detected obstacle or
drop-off already stands in the corridor no farther than R + ``EXPLAINED_M`` (what hides
the ground is already reported). R is the last ground edge pixel seen, moved on to where
the ground's fine texture gives way to a plain face (`_foot_by_texture`).

Limits, which no passive stereo cue avoids: ground that itself has no edges for metres (a
smooth floor after a textured one) looks the same as a wall with none, and is reported;
a wall already in view when the monitor starts has no expectation behind it, and is not;
a plain surface across only part of the corridor is not reported.

Frames: the left optical frame (x right, y down, z forward); ground coordinates as in
`core.camera.ground_range_bearing` (range along the ground from the point below the left
camera, bearing positive to the left).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .camera import MetricPlane, StereoCamera

#: Depth of a corridor cell along the walking direction, metres.
CELL_DEPTH_M = 0.25
#: Strips across the corridor.
STRIPS = 1
#: Weight of a frame's count in a cell's running mean of ground pixels.
EMA_RATE = 0.1
#: The same weight for a cell whose count is below ``max_ratio`` times its mean.
EMA_RATE_HIDDEN = 0.01
#: Frames a cell must have been seen before its expectation is used.
TRUST_FRAMES = 5
#: A detected obstacle in the strip no farther than R + this explains the unseen ground.
EXPLAINED_M = 0.5
#: The band's last TAIL_CELLS trusted cells must show at most max_ratio of their expected
#: edge pixels, plus TAIL_SLACK.
TAIL_CELLS = 2
TAIL_SLACK = 2.0
#: A band starts to be reported only when the cells in front of it showed at least
#: FRONT_RATIO of their expected edge pixels, and FRONT_MIN * min_expected were expected.
FRONT_RATIO = 0.5
FRONT_MIN = 0.5
#: Image margin a cell's corners must keep to count as in view, pixels.
MARGIN_PX = 3.0
#: Foot refinement (`UnseenGroundMonitor._foot_by_texture`): search span and step
#: along the ground (metres), the least ratio of the ground's texture energy to the
#: hiding face's, and the samples in a row that must be plain.
FOOT_SEARCH_M = 0.75
FOOT_STEP_M = 0.02
FOOT_CONTRAST = 2.0
FOOT_RUN = 3
#: Least number of trusted cells in view in a reported band.
MIN_CELLS = 2


@dataclass(frozen=True)
class UnseenReport:
    """Ground unseen from ``range`` on, in one strip of the corridor.

    Attributes:
        position: (3,) float64 the point ``height`` above the ground at the band's near
            edge, in the strip's middle, metres, left optical frame.
        height: metres: a lower bound of what hides the band: the height at range R of the
            ray that meets the ground at the band's far end (the hidden thing must reach
            at least that high to hide all of the band).
        range: metres along the ground to the band's near edge (the last ground seen).
        bearing: radians, positive to the left, of the strip's middle at that range.
        width: metres, the strip's width.
        strip: index of the strip, 0 = rightmost.
        expected: edge pixels expected over the band.
        seen: edge pixels counted over the band in this frame.
        far_range: metres, the band's far end (the farthest cell in view).
    """

    position: np.ndarray
    height: float
    range: float
    bearing: float
    width: float
    strip: int
    expected: float
    seen: float
    far_range: float


class UnseenGroundMonitor:
    """Running expectation of the ground's edge pixels in the corridor, and the bands of it
    that have gone unseen (see the module doc).

    Args:
        max_ratio: a band is unseen when its ground pixels are at most this fraction of
            those expected (0 < max_ratio < 1).
        min_expected: least number of ground pixels expected over a band for it to count
            (> 0).
        frames: pairs in a row a strip must be found unseen before it is reported (>= 1).
        max_range: metres, the far end of the corridor (> CELL_DEPTH_M).
        half_width: metres, the corridor's half width (> 0).
    """

    def __init__(self, max_ratio: float, min_expected: float, frames: int, max_range: float,
                 half_width: float) -> None:
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
        self.max_ratio = float(max_ratio)
        self.min_expected = float(min_expected)
        self.frames = int(frames)
        self.half_width = float(half_width)
        n_r = int(math.ceil(max_range / CELL_DEPTH_M))
        #: (n_r + 1,) range edges of the cells, metres.
        self.range_edges = np.arange(n_r + 1) * CELL_DEPTH_M
        #: (STRIPS + 1,) lateral edges of the strips, metres (negative = right).
        self.lateral_edges = np.linspace(-half_width, half_width, STRIPS + 1)
        self.reset()

    def reset(self) -> None:
        """Forget every expectation (a new camera, or a lost ground plane)."""
        shape = (STRIPS, len(self.range_edges) - 1)
        #: (STRIPS, n_r) running mean of ground pixels per cell.
        self.expected = np.zeros(shape)
        #: (STRIPS, n_r) frames each cell was seen in (counted into ``expected``).
        self.seen_frames = np.zeros(shape, np.int64)
        self._streak = np.zeros(STRIPS, np.int64)
        self._last_cell = np.full(STRIPS, -10, np.int64)

    # -------------------------------------------------------------- geometry
    @staticmethod
    def _axes(metric: MetricPlane) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(origin, fwd, lft): the point below the left camera and the ground axes."""
        n = np.asarray(metric.normal_up, float)
        fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
        fwd /= np.linalg.norm(fwd)
        lft = np.cross(n, fwd)
        return -metric.height * n, fwd, lft

    def pixel_ground(self, cam: StereoCamera, metric: MetricPlane, u: np.ndarray,
                     v: np.ndarray) -> np.ndarray:
        """(N, 2) ground coordinates (range along the walking direction, lateral to the
        left; metres) where the left-image pixels (u, v) (N,) look at the plane; NaN for
        pixels at or above the horizon."""
        n = np.asarray(metric.normal_up, float)
        r = np.stack([(np.asarray(u, float) - cam.cx) / cam.f,
                      (np.asarray(v, float) - cam.cy) / cam.f,
                      np.ones(np.shape(u))], axis=1)
        nr = r @ n
        with np.errstate(divide='ignore', invalid='ignore'):
            t = np.where(nr < -1e-9, -metric.height / nr, np.nan)
        origin, fwd, lft = self._axes(metric)
        g = r * t[:, None] - origin
        return np.stack([g @ fwd, g @ lft], axis=1)

    def cells_in_view(self, cam: StereoCamera, metric: MetricPlane) -> np.ndarray:
        """(STRIPS, n_r) bool: the cell's four ground corners project inside the left
        image, at least ``MARGIN_PX`` from its border."""
        origin, fwd, lft = self._axes(metric)
        rr, ll = np.meshgrid(self.range_edges, self.lateral_edges)      # (S+1, n_r+1)
        p = origin + rr[..., None] * fwd + ll[..., None] * lft
        z = p[..., 2]
        ok = z > 1e-3
        zs = np.where(ok, z, 1.0)
        u = cam.f * p[..., 0] / zs + cam.cx
        v = cam.f * p[..., 1] / zs + cam.cy
        inside = (ok & (u >= MARGIN_PX) & (u <= cam.width - 1 - MARGIN_PX)
                  & (v >= MARGIN_PX) & (v <= cam.height - 1 - MARGIN_PX))
        return inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]

    def _count(self, xy: np.ndarray) -> np.ndarray:
        """(STRIPS, n_r) number of ground points xy (N, 2) in each cell."""
        ok = np.isfinite(xy).all(axis=1)
        if not ok.any():
            return np.zeros(self.expected.shape)
        h, _, _ = np.histogram2d(xy[ok, 1], xy[ok, 0],
                                 bins=(self.lateral_edges, self.range_edges))
        return h

    def _foot_by_texture(self, energy: np.ndarray, cam: StereoCamera, metric: MetricPlane,
                         s: int, r_near: float, far: float) -> float:
        """The near edge of strip s's unseen band, refined in the image.

        The last ground edge pixel seen (``r_near``) can lie short of what hides the
        ground: a tile's plain inside shows no edges. The ground's fine texture
        (``energy``, `_texture_energy`) usually goes on up to the foot, where the hiding
        surface's plain face begins. Along the strip's middle, from ``r_near`` out to
        ``FOOT_SEARCH_M`` beyond it, the texture energy of each image row (averaged over
        the strip's columns) is compared with the ground's (the median of
        the rows up to ``FOOT_SEARCH_M`` nearer) and the hiding face's (the median of the
        rows of the band's last ``FOOT_SEARCH_M``). When the ground's is at least
        ``FOOT_CONTRAST`` times the face's, the foot is where the energy first stays
        below their mean for ``FOOT_RUN`` samples. Otherwise ``r_near`` stands.

        Returns:
            metres along the ground, at least ``r_near``.
        """
        lo_lat, hi_lat = self.lateral_edges[s], self.lateral_edges[s + 1]
        origin, fwd, lft = self._axes(metric)
        h, w = energy.shape

        def rows(r: np.ndarray) -> np.ndarray:
            """(len(r),) mean energy of the strip's image row at each range r."""
            out = np.full(len(r), np.nan)
            for j, rj in enumerate(r):
                p = origin + rj * fwd + np.outer([lo_lat, 0.5 * (lo_lat + hi_lat), hi_lat], lft)
                if np.any(p[:, 2] <= 1e-3):
                    continue
                u = cam.f * p[:, 0] / p[:, 2] + cam.cx
                v = cam.f * p[1, 1] / p[1, 2] + cam.cy
                u0, u1 = int(max(0, np.floor(min(u[0], u[2])))), int(min(w, np.ceil(max(u[0], u[2]))))
                vi = int(round(v))
                if u1 - u0 < 2 or vi < 1 or vi > h - 2:
                    continue
                out[j] = float(energy[vi, u0:u1].mean())
            return out

        step = FOOT_STEP_M
        ground = rows(np.arange(max(0.0, r_near - FOOT_SEARCH_M), r_near, step))
        face = rows(np.arange(max(r_near, far - FOOT_SEARCH_M), far, step))
        ground, face = ground[np.isfinite(ground)], face[np.isfinite(face)]
        if len(ground) < FOOT_RUN or len(face) < FOOT_RUN:
            return r_near
        e_g, e_f = float(np.median(ground)), float(np.median(face))
        if e_g < FOOT_CONTRAST * max(e_f, 1e-6):
            return r_near
        thr = 0.5 * (e_g + e_f)
        r = np.arange(r_near, min(far, r_near + FOOT_SEARCH_M) + 1e-9, step)
        e = rows(r)
        low = np.isfinite(e) & (e < thr)
        for j in range(len(r) - FOOT_RUN + 1):
            if low[j:j + FOOT_RUN].all():
                return float(max(r_near, r[j] - 0.5 * step))
        return r_near

    # ---------------------------------------------------------------- update
    def update(self, cam: StereoCamera, metric: MetricPlane, u: np.ndarray, v: np.ndarray,
               excess: np.ndarray, threshold: np.ndarray | float,
               explained: np.ndarray | None = None, left: np.ndarray | None = None
               ) -> tuple[UnseenReport, ...]:
        """Count one frame's ground pixels, report the unseen bands, learn the rest.

        Args:
            cam: the rectified stereo camera.
            metric: this frame's ground plane (left optical frame).
            u, v: (K,) left-image column and row of the frame's matched edge pixels.
            excess: (K,) their disparity minus the plane's, pixels (NaN: unusable).
            threshold: the obstacle threshold, pixels: a scalar or (K,) per pixel.
            explained: (M, 2) ground coordinates (range, lateral; metres) of the feet of
                the frame's detected obstacles and drop-offs (None: none).
            left: (H, W) uint8 the left image, to place a band's near edge where the
                ground's fine texture gives way to the hiding surface's
                (`_foot_by_texture`); None: at the last ground edge pixel seen.
        Returns:
            the reports, one per strip at most, nearest first.
        """
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        excess = np.asarray(excess, float)
        thr = np.broadcast_to(np.asarray(threshold, float), excess.shape)
        xy = self.pixel_ground(cam, metric, u, v)
        fin = np.isfinite(excess)
        on = fin & (np.abs(excess) <= thr)
        k_all = self._count(xy[fin])
        view = self.cells_in_view(cam, metric)
        trusted = view & (self.seen_frames >= TRUST_FRAMES)
        learn = view.copy()
        reports = []
        energy = None
        n_r = self.expected.shape[1]
        for s in range(STRIPS):
            lat = 0.5 * (self.lateral_edges[s] + self.lateral_edges[s + 1])
            found = None
            # suffix sums over the trusted cells, from the far end in
            lam = np.where(trusted[s], self.expected[s], 0.0)[::-1].cumsum()[::-1]
            k = np.where(trusted[s], k_all[s], 0.0)[::-1].cumsum()[::-1]
            cells = trusted[s][::-1].cumsum()[::-1]
            for i in range(n_r):
                if not trusted[s, i]:
                    continue
                if (cells[i] >= MIN_CELLS and lam[i] >= self.min_expected
                        and k[i] <= self.max_ratio * lam[i]):
                    found = i
                break_here = found is not None
                if break_here:
                    break
            if found is not None:
                # the band's far end must be hidden too: a plain patch of ground ends,
                # a wall hides all behind it
                tail = np.flatnonzero(trusted[s] & (np.arange(n_r) >= found))[-TAIL_CELLS:]
                if (k_all[s][tail].sum()
                        > self.max_ratio * self.expected[s][tail].sum() + TAIL_SLACK):
                    found = None
            if found is None:
                self._streak[s] = 0
                self._last_cell[s] = -10
                continue
            band = trusted[s] & (np.arange(n_r) >= found)
            learn[s] &= ~(np.arange(n_r) >= found)     # a hidden band is not learnt
            near = (self._streak[s] > 0 and abs(found - self._last_cell[s]) <= 1)
            # the ground in front of the band must be seen as usual, or the whole view is
            # poor (motion blur, glare), not hidden from some range on; a band already
            # being reported goes on without it (a wall walked up to)
            front = trusted[s] & (np.arange(n_r) < found)
            lam_f = float(self.expected[s][front].sum())
            front_ok = (lam_f >= FRONT_MIN * self.min_expected
                        and float(k_all[s][front].sum()) >= FRONT_RATIO * lam_f)
            if not (front_ok or near):
                self._streak[s] = 0
                self._last_cell[s] = -10
                continue
            self._streak[s] = self._streak[s] + 1 if near else 1
            self._last_cell[s] = found
            r0 = float(self.range_edges[found])
            # the last ground seen in the band's first cell moves R to it
            sel = on & np.isfinite(xy).all(axis=1)
            inside = (sel & (xy[:, 1] >= self.lateral_edges[s])
                      & (xy[:, 1] < self.lateral_edges[s + 1])
                      & (xy[:, 0] >= r0) & (xy[:, 0] < r0 + CELL_DEPTH_M))
            r_near = float(np.max(xy[inside, 0])) if inside.any() else r0
            far = float(self.range_edges[np.flatnonzero(band)[-1] + 1])
            if left is not None:
                if energy is None:
                    energy = _texture_energy(left)
                r_near = self._foot_by_texture(energy, cam, metric, s, r_near, far)
            if explained is not None and len(explained):
                ex = np.asarray(explained, float).reshape(-1, 2)
                hit = ((ex[:, 1] >= self.lateral_edges[s] - 0.1)
                       & (ex[:, 1] <= self.lateral_edges[s + 1] + 0.1)
                       & (ex[:, 0] <= r_near + EXPLAINED_M))
                if hit.any():
                    continue
            if self._streak[s] < self.frames:
                continue
            height = metric.height * max(0.0, 1.0 - r_near / far)
            origin, fwd, lft = self._axes(metric)
            n = np.asarray(metric.normal_up, float)
            pos = origin + r_near * fwd + lat * lft + height * n
            reports.append(UnseenReport(
                position=pos, height=height, range=float(math.hypot(r_near, lat)),
                bearing=float(math.atan2(lat, r_near)),
                width=float(self.lateral_edges[s + 1] - self.lateral_edges[s]), strip=s,
                expected=float(self.expected[s][band].sum()),
                seen=float(k_all[s][band].sum()), far_range=far))
        # learn: the running mean of each cell in view and not hidden; a cell that looks
        # hidden itself is learnt slowly (a wall creeping into the corridor's far end
        # must not teach that the ground there shows nothing)
        e = self.expected
        first = learn & (self.seen_frames == 0)
        e[first] = k_all[first]
        rest = learn & ~first
        rate = np.where(k_all < self.max_ratio * e, EMA_RATE_HIDDEN, EMA_RATE)
        e[rest] += rate[rest] * (k_all[rest] - e[rest])              # x <- x + a (z - x)
        self.seen_frames[learn] += 1
        return tuple(sorted(reports, key=lambda r: r.range))


def _texture_energy(left: np.ndarray) -> np.ndarray:
    """(H, W) float32 fine texture of a grey image: |dI/du| + |dI/dv| (central
    differences, grey levels per pixel) of the image smoothed by a 3 x 3 box, so that
    pixel noise counts less than texture."""
    g = cv2.blur(left.astype(np.float32), (3, 3))
    gx = np.zeros_like(g)
    gy = np.zeros_like(g)
    gx[:, 1:-1] = 0.5 * (g[:, 2:] - g[:, :-2])
    gy[1:-1, :] = 0.5 * (g[2:, :] - g[:-2, :])
    return np.abs(gx) + np.abs(gy)
