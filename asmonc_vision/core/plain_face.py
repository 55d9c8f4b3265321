"""Plain face: whether what hides the corridor's ground is a face standing at its edge.

`core.unseen_ground` finds the walking corridor's ground hidden from a range R on (no
edge pixels where the ground showed them) and cannot tell why: a plain wall across the
path hides it, but so does plain ground (a painted patch, smooth asphalt). Said as "cannot
see the way ahead", a wall walked up to is never announced as the obstacle it is. Yet a
plain face is seldom blank: a painted wall's faint brush marks, stains and grain are too
weak for an edge threshold, but over the whole face they match between the two images at
the face's own disparity.

This stage compares the two explanations of the image above the band's near edge (the
corridor's width, from ``FOOT_CLEARANCE_M`` above the ground at R up to ``height_m``
above it, or the image's top), as a plane sweep (Collins 1996) on the horizontal
gradients of both images smoothed by a Gaussian of ``FACE_BLUR_PX`` (the stereo
signal of a face with faint texture; a horizontal edge such as the wall's foot matches
at every disparity and is left out by the horizontal gradient):
- *the ground goes on*: the right image warped by the ground plane's disparity, row by
  row (the disparity falls towards the horizon), or by that of the ground bent at R by
  one of ``BEND_GRADES`` (beyond a crest's brow the ground falls away: seen at a
  grazing angle, it keeps nearly one disparity up the image, as a face does); the best
  of these is the ground's score;
- *a face stands across the walking direction* at range Rf, for Rf swept in
  ``COARSE_PX`` steps of the region centre's disparity from ``RANGE_TOL_M`` beyond the
  band's far end (or R + ``FAR_SWEEP_M`` if farther; on faint ground the edges end
  short of the wall, anywhere in the band) to R - ``NEAR_SWEEP_M`` (then ``STEP_PX``
  steps around the best): the right image warped, where the pixel's ray meets the
  ground nearer than Rf, by the ground's disparity (the band's edge can lie short of
  the face's foot), and elsewhere by the
  disparity of a vertical plane at Rf facing the wearer (constant up the face: a
  fronto-parallel face's disparity does not fall with the row as the ground's does).
Each is scored by the normalised cross-correlation (NCC) of the left gradients with the
warped right ones over the region. The face is *confirmed* (`FaceCheck.confirmed`) when
its best NCC is at least ``min_ncc``, beats the ground's by ``margin``, beats every face
hypothesis at least ``OFF_PEAK_PX`` of disparity away from it by ``margin`` (one clear
peak: a repetitive pattern, such as a grate's bars, matches at several), and its range
lies in the band, give or take ``max(RANGE_TOL_M, RANGE_TOL_SHARE * R)`` at either end
(where the ground stopped showing, or what hides the band's far end). The best must be
a peak: at the sweep's first or last range the scores may rise on beyond it (the
ground falling away beyond a crest's brow), and that is no face. Pixel noise alone
correlates with nothing (NCC near 0 for every hypothesis): a truly blank face or plain
ground stays unknown.

The detector (`GpodDetector._unseen_ground`) asks this of a band about to be reported,
which a confirmed face replaces by an obstacle; of a band whose image shows texture
(`core.unseen_ground`'s texture comparison would dismiss it as ground), which a
confirmed face keeps; and of a band with too little expected of it to be judged by its
edges (faint pavement), which only a confirmed face makes one. A check takes about 7-10
ms at 320 x 240 (30-40 hypotheses over some 12,000 pixels), on the pairs with such a band
only: none on the bench bags; on faint pavement or a grate, where a faint band is found
in most pairs, the detector takes up to 15 % more CPU a walk (tuning grate 1020,
backpack: about 8 ms a pair). A confirmed face is remembered (`FaceMemory`): carried
by the wearer's travel, it is the face of the band found near it in the pairs after,
whose own check, the face filling the region as the wearer comes near, may find no
single peak.

Frames: the left optical frame (x right, y down, z forward); ranges along the ground
from the point below the left camera, as in `core.unseen_ground`.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .camera import MetricPlane, StereoCamera, ground_axes

#: Standard deviation of the Gaussian smoothing both images before their horizontal
#: gradients, pixels: a faint face's texture is broader than a pixel, its noise is not.
FACE_BLUR_PX = 1.0
#: The tested region starts this far above the ground at the band's near edge, metres
#: (the ground's last texture and the face's foot line stay out of it).
FOOT_CLEARANCE_M = 0.05
#: The face's range is swept from the band's near edge minus this, metres ...
NEAR_SWEEP_M = 0.5
#: ... to the near edge plus this, metres.
FAR_SWEEP_M = 1.0
#: Step of the sweep in the region centre's disparity, pixels: every COARSE_PX, then
#: every STEP_PX within COARSE_PX of the best.
COARSE_PX = 1.0
STEP_PX = 0.25
#: Face hypotheses at least this far in disparity from the best are its rivals, pixels
#: (nearer ones share its peak, broadened by the smoothing).
OFF_PEAK_PX = 3.0
#: The confirmed face lies within the larger of this, metres, ...
RANGE_TOL_M = 0.3
#: ... and this share of the band's range, of the band's near edge.
RANGE_TOL_SHARE = 0.1
#: Fewest pixels of the region a hypothesis must be scored on.
MIN_PIXELS = 200
#: The ground going on may bend at the band's near edge by these grades (rise per
#: metre): the face must beat each (beyond a crest's brow the ground falls away; a
#: surface falling or rising at a grazing angle keeps nearly one disparity up the image,
#: as a face does).
BEND_GRADES = (-0.3, -0.2, -0.1, 0.1, 0.2, 0.3)


@dataclass(frozen=True)
class FaceCheck:
    """The plane sweep's answer for one band.

    Attributes:
        range: metres along the ground to the best face hypothesis.
        near_range: metres along the ground to the band's near edge (the sweep's R).
        far_range: metres along the ground to the band's far end: a face up to the
            range tolerance beyond it stands in the band.
        at_end: the best face lies at the sweep's nearest or farthest range: no peak
            (beyond a crest's brow the scores rise on to the farthest range tried).
        height: metres above the ground of the tested region's top (``height_m``, or
            less where the image ends first).
        score: NCC of the best face hypothesis, -1..1.
        ground: NCC of the ground going on, flat or bent at the band's edge by one of
            ``BEND_GRADES`` (the best), -1..1.
        off_peak: best NCC of the face hypotheses at least ``OFF_PEAK_PX`` from the
            best in disparity (-1 when there is none).
        disparity: pixels, the best face's disparity at the region's centre.
        excess: pixels, that minus the ground's disparity there (the ground's taken as
            0 where the centre's ray does not meet the ground ahead).
        roi: (x, y, w, h) ints, the tested region in the left image.
    """

    range: float
    near_range: float
    far_range: float
    at_end: bool
    height: float
    score: float
    ground: float
    off_peak: float
    disparity: float
    excess: float
    roi: tuple[int, int, int, int]

    def confirmed(self, min_ncc: float, margin: float) -> bool:
        """Whether a face stands at the band's edge (see the module doc)."""
        tol = max(RANGE_TOL_M, RANGE_TOL_SHARE * self.near_range)
        return (not self.at_end and self.score >= min_ncc
                and self.score >= self.ground + margin
                and self.score >= self.off_peak + margin
                and self.near_range - tol <= self.range
                <= max(self.near_range, self.far_range) + tol)


def _gradient(img: np.ndarray) -> np.ndarray:
    """(H, W) float32 horizontal gradient of a grey image smoothed by ``FACE_BLUR_PX``."""
    g = cv2.GaussianBlur(img.astype(np.float32), (0, 0), FACE_BLUR_PX)
    return cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)


def _finite(x: float) -> float:
    """A score for ``max``: NaN (not scored) below every score."""
    return x if math.isfinite(x) else -math.inf


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised cross-correlation of two equal-size float arrays (0 when either is
    flat)."""
    a = a - a.mean()
    b = b - b.mean()
    den = math.sqrt(float((a * a).sum()) * float((b * b).sum()))
    return float((a * b).sum()) / den if den > 0.0 else 0.0


def _region(cam: StereoCamera, metric: MetricPlane, near_m: float, half_width_m: float,
            height_m: float) -> tuple[int, int, int, int, float] | None:
    """The tested region in the left image: the corridor's width at ``near_m``, from
    ``FOOT_CLEARANCE_M`` up to ``height_m`` above the ground (or the image's top). Returns
    (u0, u1, v0, v1, the region's top in metres above the ground), or None when it is
    out of the image or smaller than ``MIN_PIXELS``."""
    origin, fwd, lft = ground_axes(metric)
    up = np.asarray(metric.normal_up, float)
    foot = origin + near_m * fwd
    corners = np.stack([foot + s * half_width_m * lft + h * up
                        for h in (FOOT_CLEARANCE_M, height_m) for s in (-1.0, 1.0)])
    if np.any(corners[:2, 2] <= 0.0):
        return None
    top_ahead = corners[2:, 2].min() > 0    # the top corners in front of the camera
    with np.errstate(divide='ignore', invalid='ignore'):
        u, v = cam.project_left(corners)
    cols = u if top_ahead else u[:2]
    u0 = int(max(0, math.floor(cols.min())))
    u1 = int(min(cam.width, math.ceil(cols.max())))
    v1 = int(min(cam.height, math.floor(v[:2].min())))
    # the face's top: the image's top row where the region's top lies above it
    v0 = int(max(0, math.ceil(v[2:].max()))) if top_ahead else 0
    if v1 - v0 < 4 or u1 - u0 < 8 or (v1 - v0) * (u1 - u0) < MIN_PIXELS:
        return None
    top_h = height_m
    if v0 == 0 and top_ahead and v[2:].max() < 0:
        # the image ends below the region's top: the face tested up to the top row
        ray_top = np.array([0.0, (0.0 - cam.cy) / cam.f, 1.0])
        along = float(fwd @ ray_top)
        zc = (near_m + float(fwd @ origin)) / along if along > 0 else 0
        top_h = float(np.clip((zc * ray_top - origin) @ up, FOOT_CLEARANCE_M, height_m))
    return u0, u1, v0, v1, top_h


class _Warp:
    """The region's left gradients and the right image's, with the NCC of the one with
    the other warped by a disparity field (`score`)."""

    def __init__(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                 u0: int, u1: int, v0: int, v1: int) -> None:
        self.gr = _gradient(right[v0:v1, :])
        uu, vv = np.meshgrid(np.arange(u0, u1, dtype=np.float64),
                             np.arange(v0, v1, dtype=np.float64))
        #: (h, w, 3) the region's pixel rays (z = 1), left optical frame
        self.ray = np.stack([(uu - cam.cx) / cam.f, (vv - cam.cy) / cam.f,
                             np.ones_like(uu)], -1)
        self.target = _gradient(left[v0:v1, :])[:, u0:u1]
        self.t_full = self.target - float(self.target.mean())
        self.t_norm = math.sqrt(float(np.vdot(self.t_full, self.t_full)))
        self.cols = uu.astype(np.float32)
        self.rows = (vv - v0).astype(np.float32)

    def score(self, d: np.ndarray) -> float:
        """NCC of the left gradients with the right ones warped by disparity d (the
        region's shape, pixels; NaN or <= 0: not scored); NaN with fewer than
        ``MIN_PIXELS`` scored."""
        xs = (self.cols - d).astype(np.float32, copy=False)
        with np.errstate(invalid='ignore'):
            ok = (xs >= 0.0) & (d > 0.0)        # NaN compares False; xs < u1 <= width
        n = int(np.count_nonzero(ok))
        if n < MIN_PIXELS:
            return math.nan
        if n == self.target.size:               # the usual case: the whole region
            warped = cv2.remap(self.gr, xs, self.rows, cv2.INTER_LINEAR)
            w = warped - float(warped.mean())
            den = self.t_norm * math.sqrt(float(np.vdot(w, w)))
            return float(np.vdot(self.t_full, w)) / den if den > 0.0 else 0.0
        warped = cv2.remap(self.gr, np.where(ok, xs, 0.0).astype(np.float32), self.rows,
                           cv2.INTER_LINEAR)
        return _ncc(self.target[ok], warped[ok])


def _sweep(face: Callable[[float], float], d_far: float, d_near: float
           ) -> tuple[float, float, float, bool] | None:
    """The best of ``face`` (a score of the region centre's disparity) from d_far to
    d_near: every ``COARSE_PX``, then every ``STEP_PX`` within ``COARSE_PX`` of the
    best. Returns (its disparity, its score, the best score ``OFF_PEAK_PX`` or more
    from it, -1 when none, whether the best of every ``COARSE_PX`` was the sweep's
    first or last: no peak, the scores may rise on beyond it), or None when nothing
    could be scored."""
    dc = np.arange(d_far, d_near + 1e-9, COARSE_PX)
    scores = np.array([face(float(d)) for d in dc])
    if not np.isfinite(scores).any():
        return None
    j = int(np.nanargmax(scores))
    at_end = j == 0 or j == len(dc) - 1
    rivals = scores[np.abs(dc - dc[j]) >= OFF_PEAK_PX]
    rivals = rivals[np.isfinite(rivals)]
    fine = np.arange(dc[j] - COARSE_PX + STEP_PX, dc[j] + COARSE_PX - 1e-9, STEP_PX)
    fine = fine[(fine >= d_far) & (fine <= d_near)]
    dc = np.concatenate([dc[j:j + 1], fine])
    scores = np.concatenate([scores[j:j + 1], [face(float(d)) for d in fine]])
    j = int(np.nanargmax(scores))
    return (float(dc[j]), float(scores[j]), float(rivals.max()) if len(rivals) else -1.0,
            at_end)


def check_face(left: np.ndarray, right: np.ndarray, cam: StereoCamera, metric: MetricPlane,
               near_m: float, half_width_m: float, height_m: float,
               far_m: float | None = None) -> FaceCheck | None:
    """The plane sweep of a face standing across the walking direction at the edge of an
    unseen band (see the module doc).

    Args:
        left, right: (H, W) uint8 rectified grey images of the pair.
        cam: the rectified stereo camera.
        metric: the pair's ground plane (left optical frame).
        near_m: metres along the ground to the band's near edge (> 0).
        half_width_m: metres, the corridor's half width (> 0).
        height_m: metres above the ground up to which the face is tested (> 0).
        far_m: metres along the ground to the band's far end: faces are swept out to
            there, or to ``near_m + FAR_SWEEP_M`` if farther (None: ``near_m``).
    Returns:
        The check, or None when the region is out of the image or too small to score.
    """
    region = _region(cam, metric, near_m, half_width_m, height_m)
    if region is None:
        return None
    u0, u1, v0, v1, top_h = region
    origin, fwd, _ = ground_axes(metric)
    up = np.asarray(metric.normal_up, float)
    warp = _Warp(left, right, cam, u0, u1, v0, v1)
    fb = cam.fb
    # the ground going on: up . X = up . origin on the ray X = Z ray
    a_up, c_up = warp.ray @ up, float(up @ origin)
    with np.errstate(divide='ignore', invalid='ignore'):
        d_ground = fb * a_up / c_up
    d_g = np.where(d_ground > 0.0, d_ground, np.nan).astype(np.float32)
    ground = warp.score(d_g)
    # a face at Rf: fwd . X = Rf + fwd . origin; its disparity is fb (fwd . ray) / that
    fr = warp.ray @ fwd
    centre = fr[(v1 - v0) // 2, (u1 - u0) // 2]
    g_centre = float(d_ground[(v1 - v0) // 2, (u1 - u0) // 2])
    offset = float(fwd @ origin)
    far = near_m if far_m is None else float(far_m)
    # (beyond the far end by the tolerance: a face just at it is a peak too)
    d_far = fb * centre / (max(near_m + FAR_SWEEP_M, far + RANGE_TOL_M) + offset)
    d_near = fb * centre / max(near_m - NEAR_SWEEP_M + offset, 0.3)
    if not (math.isfinite(d_far) and d_far > 0.0 and d_near > d_far):
        return None
    fr32 = fr.astype(np.float32)
    with np.errstate(divide='ignore', invalid='ignore'):
        # each pixel's ray meets the ground this far ahead (inf: above the horizon)
        ahead = np.where(d_ground > 0.0, fb / d_ground * fr - offset, np.inf)
        # the ground going on bent at the band's edge (a crest's brow, a rise): beyond
        # near_m, up . (X - origin) = g (fwd . X - offset - near_m) on X = Z ray
        for g in BEND_GRADES:
            z = (c_up - g * (offset + near_m)) / (a_up - g * fr)
            bent = np.where(ahead > near_m, np.where((z > 0.0) & (z * fr - offset > near_m),
                                                     fb / z, np.nan), d_ground)
            ground = max(ground, warp.score(np.where(bent > 0.0, bent, np.nan)), key=_finite)

    def face(d: float) -> float:
        """The score of the ground up to the face whose disparity at the region's
        centre is d, and the face from there up."""
        rf = fb * centre / d - offset
        return warp.score(np.where(ahead < rf, d_g, fr32 * np.float32(d / centre)))

    best = _sweep(face, d_far, d_near)
    if best is None:
        return None
    d_best, s_best, off_peak, at_end = best
    return FaceCheck(range=float(fb * centre / d_best - offset), near_range=float(near_m),
                     far_range=far, at_end=at_end, height=top_h, score=s_best,
                     ground=float(ground) if math.isfinite(ground) else -1.0,
                     off_peak=off_peak, disparity=d_best,
                     excess=d_best - (g_centre if g_centre > 0.0 else 0.0),
                     roi=(u0, v0, u1 - u0, v1 - v0))


#: `FaceMemory`: a band found this near the carried face (metres, or this share of its
#: range if more) is the band the face hides.
MEMORY_TOL_M = 0.5
MEMORY_TOL_SHARE = 0.15


class FaceMemory:
    """The last confirmed face, carried through the wearer's travel while the band it
    hides goes on being found.

    A face is confirmed 4-5 m ahead and walked up to; nearer, the check at the band's
    edge can lose its single peak (the face fills the tested region: on a level chest
    camera, rival ranges within 0.15 at 2.5-3 m), and the band alone is said as
    unknown ground. What hid the ground there was a face, and it stands where it stood:
    the band found within ``MEMORY_TOL_M`` (or ``MEMORY_TOL_SHARE``) of the face carried
    by the travel is that face. The memory bridges at most ``max_gap`` pairs without
    a band or a confirmation, and is forgotten when the travel is unknown (a pair whose
    plane was lost carried nothing).

    Args:
        max_gap: pairs in a row without the band that the memory outlasts (>= 0).
    """

    def __init__(self, max_gap: int) -> None:
        if max_gap < 0:
            raise ValueError(f'max_gap = {max_gap} must be >= 0')
        self.max_gap = int(max_gap)
        self.forget()

    def forget(self) -> None:
        """No face remembered."""
        self.face: FaceCheck | None = None
        self._gap = 0

    def carry(self, travel_m: float | None) -> None:
        """The wearer walked ``travel_m`` metres forward along the ground since the
        previous pair (None: unknown, and the memory is forgotten)."""
        if self.face is None:
            return
        if travel_m is None or not math.isfinite(travel_m):
            self.forget()
            return
        self.face = dataclasses.replace(self.face, range=self.face.range - float(travel_m))

    def confirmed(self, face: FaceCheck) -> None:
        """A face confirmed this pair: remembered."""
        self.face = face
        self._gap = 0

    def explains(self, band_range: float | None) -> FaceCheck | None:
        """The remembered face, at its carried range, if a band found this pair at
        ``band_range`` metres (None: none) is the one it hides; else None, and the
        memory is forgotten when the band lies elsewhere or ``max_gap`` pairs in a row
        had none. (The face keeps the image region it was tested on.)"""
        face = self.face
        if face is None:
            return None
        if band_range is not None and abs(band_range - face.range) <= max(
                MEMORY_TOL_M, MEMORY_TOL_SHARE * face.range):
            self._gap = 0
            return face
        self._gap += 1
        if self._gap > self.max_gap or band_range is not None:
            self.forget()
        return None
