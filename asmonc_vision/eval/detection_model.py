"""The obstacle detection model of Molton, Se, Brady et al. (1998), Sec. 2.2-2.3 (Fig. 5).

Pure numpy/scipy. Units: metres for lengths, pixels (px) for image quantities and
disparities, radians unless a name ends in ``_deg``.

The paper's chain, with the geometry made exact for a pitched rig:

1. **Eq. 1** -- the disparity excess of an obstacle's top over the ground behind it.
   A point A at height S on an obstacle whose foot is at range Y is seen along the same
   ray as the ground point B behind it; GPOD compares A's measured disparity with the
   ground plane's disparity at A's pixel, i.e. B's disparity::

       excess = f I / Y - f I / (Y + dY),  dY / Y = S / (H - S)   =>   excess = f I S / (Y H)

   (f focal length px, I baseline m, H camera height m). This assumes a *level* camera
   (the optical axis parallel to the ground, so depth = range). For a camera pitched
   down by theta the same two projections give (:func:`exact_disparity_excess`, which
   projects A and B with :class:`.camera.StereoCamera`)::

       excess = f I S / (H z_A),   z_A = Y cos(theta) + (H - S) sin(theta)

   where z_A is A's depth along the optical axis. The ground plane's disparity at A's
   pixel is A's disparity times (H - S) / H, so the excess is the fraction S / H of
   A's disparity, whatever the pitch; at theta = 0 this is Eq. 1 exactly.

2. **Eq. 2** -- a pixel's measured excess is the true excess plus Gaussian noise of
   standard deviation sigma, so the probability that it exceeds the threshold T is::

       p = integral_T^inf N(x; excess, sigma^2) dx = 1 - Phi((T - excess) / sigma)

   (the paper's printed integrand lacks the ``exp``; this is the integral it means).

3. **The edge string** -- a vertical edge string of n pixels is an obstacle when at
   least one pixel is (``1 - prod(1 - p_i)``; :func:`string_detection_probability`
   generalises it to "at least m pixels", the detector's ``min_obstacle_pixels``).

4. **The excess along the edge** (derived, :func:`edge_pixel_excesses`). A point of the
   obstacle's vertical edge at height h has depth z(h) = Y cos(theta) + (H - h) sin(theta)
   and image row v with (v - cy) / f = cot(theta) - Y / (z sin(theta)), so its inverse
   depth ``1 / z = (cos(theta) - sin(theta) (v - cy) / f) / Y`` is affine in v. The
   point's disparity f I / z and the ground plane's disparity at its row,
   ``(I / H) ((v - cy) cos(theta) + f sin(theta))``, are therefore both affine in v, and
   so is their difference, the excess. It is 0 at the foot (h = 0, where the edge meets
   the ground) and the Eq. 1 value at the top, so it grows linearly with the number of
   rows above the foot, at a rate that does not depend on the obstacle's height::

       g = d(excess) / d(rows above the foot) = I (cos(theta) / H + sin(theta) / Y)   px/row

   (I / H = 0.28 px/row for the paper's level rig). The edge spans excess_top / g rows
   (f S / Y for a level camera). Pixel centres sample it at ``phase + k`` rows above the
   foot, k = 0, 1, ..., where the phase (0..1) is where the foot falls between two pixel
   centres; the model averages over it (uniformly), so the curves are smooth in S.

Consequences for a level rig: the excess of the k-th pixel above the foot does not
depend on the range, and the edge's length in pixels is f S / Y, so the detection
probability depends on S / Y alone: the 90% height grows in proportion to the range
(the paper: 6 cm at 2.5 m, 12 cm at 5 m).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from asmonc_vision.core.camera import StereoCamera

#: Threshold and noise of the paper (Sec. 2.2-2.3), pixels.
PAPER_THRESHOLD_PX = 1.7
PAPER_SIGMA_PX = 1.0
#: Default number of sub-pixel phases of the foot averaged over.
DEFAULT_PHASES = 32


@dataclass(frozen=True)
class ModelRig:
    """The rig geometry the model needs.

    Attributes:
        f_px: focal length, pixels.
        baseline_m: interocular distance I, metres.
        height_m: camera (baseline midpoint) height H above the ground, metres.
        pitch_deg: downward tilt of the optical axes, degrees; None = not known, use the
            paper's level-camera Eq. 1. With a pitch (0 included) the exact geometry is
            used; at pitch 0 it equals Eq. 1.
    """

    f_px: float = 300.0
    baseline_m: float = 0.35
    height_m: float = 1.25
    pitch_deg: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.f_px) and self.f_px > 0):
            raise ValueError(f'ModelRig.f_px must be > 0 pixels, got {self.f_px}')
        if not (math.isfinite(self.baseline_m) and self.baseline_m > 0):
            raise ValueError(f'ModelRig.baseline_m must be > 0 metres, got {self.baseline_m}')
        if not (math.isfinite(self.height_m) and self.height_m > 0):
            raise ValueError(f'ModelRig.height_m must be > 0 metres, got {self.height_m}')
        if self.pitch_deg is not None and not (-80.0 < self.pitch_deg < 89.0):
            raise ValueError(f'ModelRig.pitch_deg must be in (-80, 89) degrees or None, '
                             f'got {self.pitch_deg}')

    @property
    def pitch_rad(self) -> float:
        """Pitch in radians (0 when unknown)."""
        return math.radians(self.pitch_deg) if self.pitch_deg is not None else 0.0

    def describe(self) -> str:
        """One line: f, I, H and the pitch (or 'level, Eq. 1')."""
        pitch = ('level camera, Eq. 1' if self.pitch_deg is None
                 else f'pitch {self.pitch_deg:g} deg, exact geometry')
        return (f'f = {self.f_px:g} px, I = {self.baseline_m:g} m, H = {self.height_m:g} m, '
                f'{pitch}')


#: The rig of Molton et al. (1998) as their Eq. 1 sees it (level camera).
PAPER_RIG = ModelRig()


# --------------------------------------------------------------------------- geometry


def disparity_excess(f_px, baseline_m, height_m, obstacle_height_m, range_m) -> np.ndarray:
    """Eq. 1: disparity excess f I S / (Y H) of an obstacle's top over the ground, px.

    Assumes a *level* camera (optical axis parallel to the ground, so the depth of the
    obstacle equals its range); see :func:`exact_disparity_excess` for a pitched rig.

    Args:
        f_px: focal length f, pixels.
        baseline_m: interocular distance I, metres.
        height_m: camera height H above the ground, metres.
        obstacle_height_m: obstacle height S, metres (0 <= S < H).
        range_m: range Y to the obstacle, metres.
    Returns:
        Excess in pixels, broadcast over the array arguments.
    """
    s = np.asarray(obstacle_height_m, float)
    y = np.asarray(range_m, float)
    return f_px * baseline_m * s / (y * height_m)


def _depth_of(height_m, pitch_rad, obstacle_height_m, range_m) -> np.ndarray:
    """Depth z (m, optical axis) of a point h above the ground at range Y."""
    return (np.asarray(range_m, float) * math.cos(pitch_rad)
            + (height_m - np.asarray(obstacle_height_m, float)) * math.sin(pitch_rad))


def exact_disparity_excess(f_px, baseline_m, height_m, obstacle_height_m, range_m,
                           pitch_rad: float = 0.0) -> np.ndarray:
    """Exact disparity excess (px) of a point S above the ground at range Y, pitched rig.

    The paper's construction with :mod:`.camera`: the obstacle's top A and the ground
    point B behind it on the same (cyclopean) ray are both projected with
    :meth:`.camera.StereoCamera.project`, and the excess is d(A) - d(B), the disparity
    A has beyond the ground plane at its pixel. The rig stands H above flat ground, its
    optical axes pitched down by ``pitch_rad``, no roll. Equals
    ``f I S / (H (Y cos(theta) + (H - S) sin(theta)))`` and, for ``pitch_rad = 0``, Eq. 1.

    Args:
        f_px, baseline_m, height_m: f (px), I (m), H (m: the cyclopean centre's height).
        obstacle_height_m: S, metres above the ground (0 <= S < H).
        range_m: Y, metres along the ground from the point below the camera.
        pitch_rad: downward tilt of the optical axis, radians.
    Returns:
        Excess in pixels, broadcast over obstacle_height_m and range_m.
    """
    s, y = np.broadcast_arrays(np.asarray(obstacle_height_m, float),
                               np.asarray(range_m, float))
    c, sn = math.cos(pitch_rad), math.sin(pitch_rad)
    cam = StereoCamera(f=float(f_px), cx=0.0, cy=0.0, baseline=float(baseline_m),
                       width=1, height=1)
    # World forward F and up U in the optical frame (x right, y down, z forward):
    # F = (0, -sin, cos), U = (0, -cos, -sin); the ground is U . X + H = 0 (cyclopean).
    up = np.array([0.0, -c, -sn])
    fwd = np.array([0.0, -sn, c])
    a_cyc = y.reshape(-1, 1) * fwd + (s.reshape(-1, 1) - height_m) * up
    b_cyc = a_cyc * (-height_m / (a_cyc @ up))[:, None]      # the ray through A hits B
    shift = np.array([baseline_m / 2.0, 0.0, 0.0])           # cyclopean -> left frame
    _, _, d_a = cam.project(a_cyc + shift)
    _, _, d_b = cam.project(b_cyc + shift)
    return (d_a - d_b).reshape(s.shape)


def excess_row_gradient(rig: ModelRig, range_m) -> np.ndarray:
    """Growth of the excess along a vertical edge: px of excess per image row above the
    foot, ``I (cos(theta) / H + sin(theta) / Y)`` (I / H for a level camera)."""
    th = rig.pitch_rad
    return rig.baseline_m * (math.cos(th) / rig.height_m
                             + math.sin(th) / np.asarray(range_m, float))


def top_excess(rig: ModelRig, obstacle_height_m, range_m) -> np.ndarray:
    """Excess (px) of the obstacle's top: Eq. 1 when the pitch is unknown, else exact."""
    if rig.pitch_deg is None:
        return disparity_excess(rig.f_px, rig.baseline_m, rig.height_m, obstacle_height_m,
                                range_m)
    s = np.asarray(obstacle_height_m, float)
    return (rig.f_px * rig.baseline_m * s
            / (rig.height_m * _depth_of(rig.height_m, rig.pitch_rad, s, range_m)))


def edge_span_rows(rig: ModelRig, obstacle_height_m, range_m) -> np.ndarray:
    """Image rows from the foot to the top of a vertical edge of height S at range Y
    (f S / Y for a level camera)."""
    return top_excess(rig, obstacle_height_m, range_m) / excess_row_gradient(rig, range_m)


def edge_pixel_excesses(rig: ModelRig, obstacle_height_m: float, range_m: float,
                        phase: float = 0.0) -> np.ndarray:
    """True disparity excess (px) of each pixel of an obstacle's vertical edge.

    The pixel centres lie ``phase + k`` rows above the foot (k = 0, 1, ...) up to the top;
    each one's excess is ``g (phase + k)`` with g = :func:`excess_row_gradient` (linear,
    0 at the foot, the top's excess at the top; see the module doc).

    Args:
        rig: the rig.
        obstacle_height_m: S, metres; range_m: Y, metres (scalars).
        phase: where the lowest pixel centre lies above the foot, rows, in [0, 1).
    Returns:
        (n,) float64, from the foot up; empty when the edge is shorter than ``phase``.
    """
    if not 0.0 <= phase < 1.0:
        raise ValueError(f'phase must be in [0, 1), got {phase}')
    g = float(excess_row_gradient(rig, range_m))
    span = float(edge_span_rows(rig, obstacle_height_m, range_m))
    n = int(math.floor(span - phase + 1e-12)) + 1 if span >= phase else 0
    return g * (phase + np.arange(n, dtype=float))


# --------------------------------------------------------------------------- probability


def pixel_detection_probability(excess_px, threshold_px=PAPER_THRESHOLD_PX,
                                sigma_px=PAPER_SIGMA_PX) -> np.ndarray:
    """Eq. 2: P(measured excess > threshold) = 1 - Phi((threshold - excess) / sigma).

    Args:
        excess_px: true disparity excess, pixels (array).
        threshold_px: the detector's threshold T, pixels.
        sigma_px: standard deviation of the measured excess, pixels (> 0).
    Returns:
        Probabilities in [0, 1], shape of excess_px.
    """
    if not sigma_px > 0:
        raise ValueError(f'sigma_px must be > 0, got {sigma_px}')
    return ndtr((np.asarray(excess_px, float) - threshold_px) / sigma_px)


def string_detection_probability(p_i, min_pixels: int = 1) -> np.ndarray:
    """Probability that an edge string is an obstacle: at least ``min_pixels`` of its
    pixels are, the pixels independent with probabilities ``p_i`` (last axis).

    ``min_pixels = 1`` is the paper's rule, ``1 - prod(1 - p_i)``; larger values use the
    Poisson-binomial distribution (the detector's ``min_obstacle_pixels``).

    Args:
        p_i: (..., n) per-pixel probabilities.
        min_pixels: m >= 1.
    Returns:
        (...) probabilities (0 where n < m).
    """
    p = np.asarray(p_i, float)
    if min_pixels < 1:
        raise ValueError(f'min_pixels must be >= 1, got {min_pixels}')
    if min_pixels == 1:
        return 1.0 - np.prod(1.0 - p, axis=-1)
    # dist[..., j] = P(j successes so far), j = 0 .. m-1 (m or more are absorbed).
    dist = np.zeros(p.shape[:-1] + (min_pixels,))
    dist[..., 0] = 1.0
    for k in range(p.shape[-1]):
        pk = p[..., k, None]
        shifted = np.concatenate([np.zeros_like(dist[..., :1]), dist[..., :-1]], axis=-1)
        dist = dist * (1.0 - pk) + shifted * pk
    return np.clip(1.0 - dist.sum(axis=-1), 0.0, 1.0)


def obstacle_detection_probability(rig: ModelRig, obstacle_height_m, range_m,
                                   threshold_px: float = PAPER_THRESHOLD_PX,
                                   sigma_px: float = PAPER_SIGMA_PX, min_pixels: int = 1,
                                   phases: int = DEFAULT_PHASES) -> np.ndarray:
    """Probability that one vertical edge of an obstacle of height S at range Y is
    detected (Sec. 2.3), averaged over the foot's sub-pixel phase.

    Args:
        rig: the rig (pitch None = Eq. 1).
        obstacle_height_m, range_m: S and Y, metres (broadcast together).
        threshold_px, sigma_px: Eq. 2's threshold and noise, pixels.
        min_pixels: obstacle pixels the string needs (1 = the paper).
        phases: sub-pixel phases averaged (1 = the foot on a pixel centre).
    Returns:
        Probabilities, the broadcast shape of S and Y.
    """
    s, y = np.broadcast_arrays(np.asarray(obstacle_height_m, float),
                               np.asarray(range_m, float))
    if phases < 1:
        raise ValueError(f'phases must be >= 1, got {phases}')
    phi = (np.arange(phases) + 0.5) / phases if phases > 1 else np.zeros(1)
    g = excess_row_gradient(rig, y)
    span = edge_span_rows(rig, s, y)
    n_max = int(math.floor(float(np.max(span, initial=0.0)))) + 1
    k = np.arange(n_max, dtype=float)
    # rows above the foot of each pixel: (..., phases, n_max)
    rows = phi[:, None] + k[None, :]
    rows = np.broadcast_to(rows, s.shape + rows.shape)
    inside = rows <= span[..., None, None] + 1e-12
    p = pixel_detection_probability(g[..., None, None] * rows, threshold_px, sigma_px)
    p = np.where(inside, p, 0.0)
    return string_detection_probability(p, min_pixels).mean(axis=-1)


def fig5_curves(rig: ModelRig, heights_m, ranges_m, threshold_px: float = PAPER_THRESHOLD_PX,
                sigma_px: float = PAPER_SIGMA_PX, min_pixels: int = 1,
                phases: int = DEFAULT_PHASES) -> np.ndarray:
    """The grid of the paper's Fig. 5: detection probability per height and range.

    Args:
        rig: the rig (pitch None = the paper's Eq. 1).
        heights_m: (H,) obstacle heights S, metres.
        ranges_m: (R,) ranges Y, metres.
        threshold_px, sigma_px, min_pixels, phases: see
            :func:`obstacle_detection_probability`.
    Returns:
        (H, R) float64 probabilities; row i = heights_m[i], column j = ranges_m[j].
    """
    h = np.asarray(heights_m, float).reshape(-1, 1)
    r = np.asarray(ranges_m, float).reshape(1, -1)
    return obstacle_detection_probability(rig, h, r, threshold_px, sigma_px, min_pixels,
                                          phases)


def min_height_for(prob: float = 0.9, range_m=5.0, rig: ModelRig = PAPER_RIG,
                   threshold_px: float = PAPER_THRESHOLD_PX, sigma_px: float = PAPER_SIGMA_PX,
                   min_pixels: int = 1, phases: int = DEFAULT_PHASES,
                   tol_m: float = 1e-5) -> np.ndarray | float:
    """Smallest obstacle height detected with probability ``prob`` at each range.

    The probability never decreases with the height (a taller edge only adds pixels at
    its top), so bisection finds it.

    Args:
        prob: the detection probability, in (0, 1).
        range_m: Y, metres (scalar or array).
        rig, threshold_px, sigma_px, min_pixels, phases: as :func:`fig5_curves`.
        tol_m: bisection tolerance, metres.
    Returns:
        Heights in metres (float for a scalar range); ``inf`` where even an obstacle
        reaching 0.99 H is not detected with that probability.
    """
    if not 0.0 < prob < 1.0:
        raise ValueError(f'prob must be in (0, 1), got {prob}')
    y = np.asarray(range_m, float)
    flat = y.ravel()

    def p_of(s: np.ndarray) -> np.ndarray:
        return obstacle_detection_probability(rig, s, flat, threshold_px, sigma_px,
                                              min_pixels, phases)

    lo = np.zeros_like(flat)
    hi = np.full_like(flat, 0.99 * rig.height_m)
    ok = p_of(hi) >= prob
    while np.max(hi - lo, initial=0.0) > tol_m:
        mid = 0.5 * (lo + hi)
        above = p_of(mid) >= prob
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    out = np.where(ok, hi, np.inf).reshape(y.shape)
    return float(out) if out.ndim == 0 else out
