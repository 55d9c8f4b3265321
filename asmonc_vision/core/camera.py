"""Rectified stereo camera model and the ground plane in disparity space.

Conventions (used by every module of asmonc_vision):

* Images are rectified. Pixel coordinates (u, v): u is the column, v the row, origin at
  the centre of the top-left pixel, u right, v down.
* Disparity ``d = u_left - u_right`` in pixels, positive in front of the rig.
* The cyclopean coordinate of a match is ``u = (u_left + u_right) / 2`` and ``v`` (rows
  agree after rectification).
* Frames follow REP 103 optical frames: x right, y down, z forward, metres.
  The *left* optical frame has its origin at the left camera's centre; the *cyclopean*
  frame is the same frame moved ``baseline / 2`` to the right (the baseline midpoint).
* The ground plane in disparity space is ``d = a*u + b*v + c`` in cyclopean
  coordinates (Molton et al. 1998). With the cyclopean frame it is exact:
  a point X on the plane ``n . X = h`` (n the unit normal pointing *down* to the
  ground, h > 0 the cyclopean centre's height) satisfies
  ``d = (B/h) * (n_x (u - cx) + n_y (v - cy) + n_z f)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StereoCamera:
    """Intrinsics of a rectified stereo pair (both cameras share f, cx, cy).

    Attributes:
        f: focal length, pixels.
        cx, cy: principal point, pixels (same for left and right after rectification).
        baseline: distance between the optical centres, metres (> 0).
        width, height: image size, pixels.
    """

    f: float
    cx: float
    cy: float
    baseline: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not (np.isfinite(self.f) and self.f > 0):
            raise ValueError(f'StereoCamera.f must be a finite value > 0 pixels, got {self.f}')
        if not (np.isfinite(self.baseline) and 0 < self.baseline < 10):
            raise ValueError(
                f'StereoCamera.baseline must be in (0, 10) metres, got {self.baseline}')
        if self.width <= 0 or self.height <= 0:
            raise ValueError(
                f'StereoCamera.width/height must be > 0 pixels, got {self.width}x{self.height}')
        if not (np.isfinite(self.cx) and np.isfinite(self.cy)):
            raise ValueError(f'StereoCamera.cx/cy must be finite, got ({self.cx}, {self.cy})')

    @classmethod
    def from_projection(cls, p_left, p_right, width: int, height: int) -> 'StereoCamera':
        """Build from the 3x4 (or flat 12) projection matrices of a rectified pair.

        The right camera's ``P[0, 3]`` holds ``-f * B`` (ROS CameraInfo convention).
        """
        pl = np.asarray(p_left, float).reshape(3, 4)
        pr = np.asarray(p_right, float).reshape(3, 4)
        f = pl[0, 0]
        if f <= 0:
            raise ValueError(f'left projection matrix has f = P[0,0] = {f}; must be > 0')
        baseline = (pl[0, 3] - pr[0, 3]) / f
        return cls(f=float(f), cx=float(pl[0, 2]), cy=float(pl[1, 2]),
                   baseline=float(baseline), width=int(width), height=int(height))

    @property
    def fb(self) -> float:
        """f * B in pixel-metres: disparity (px) times range along z (m)."""
        return self.f * self.baseline

    def disparity_at_depth(self, z):
        """Disparity (px) of a point at depth z (m, along the optical axis)."""
        return self.fb / np.asarray(z, float)

    def triangulate(self, u, v, d) -> np.ndarray:
        """Cyclopean (u, v, d) in pixels to points in the *left* optical frame.

        Args:
            u, v, d: arrays of equal shape (N,), cyclopean pixel coordinates and
                disparity in pixels (d > 0).
        Returns:
            (N, 3) float64 array of (x, y, z) in metres, left optical frame.
        """
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        d = np.asarray(d, float)
        z = self.fb / d
        # Cyclopean frame origin is at +B/2 along x in the left frame.
        x = (u - self.cx) * z / self.f + self.baseline / 2.0
        y = (v - self.cy) * z / self.f
        return columns(x, y, z)

    def project_left(self, points_left: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Left optical-frame points (N, 3), metres (z > 0), to their left-image (u, v),
        pixels, (N,) each."""
        p = np.asarray(points_left, float).reshape(-1, 3)
        return self.f * p[:, 0] / p[:, 2] + self.cx, self.f * p[:, 1] / p[:, 2] + self.cy

    def project(self, points_left: np.ndarray):
        """Left optical-frame points (N, 3) to cyclopean (u, v, d) pixel arrays."""
        p = np.asarray(points_left, float).reshape(-1, 3)
        xc = p[:, 0] - self.baseline / 2.0
        z = p[:, 2]
        u = self.f * xc / z + self.cx
        v = self.f * p[:, 1] / z + self.cy
        d = self.fb / z
        return u, v, d



def principal_offset_px(p_left, p_right, width: int | None = None) -> float:
    """``cx_left - cx_right`` of a rectified pair's projection matrices (3x4 or flat 12),
    px: the disparity of a point at infinity (Middlebury's ``doffs``). 0 when the two
    principal points agree (``cv2.stereoRectify``'s ``CALIB_ZERO_DISPARITY``, the
    ``StereoCamera`` convention); `align_right_image` makes them agree.

    Raises:
        ValueError: the offset is not finite, or (with ``width``) a quarter of the
            image's width or more: not one rectified pair.
    """
    off = float(np.asarray(p_left, float).reshape(3, 4)[0, 2]
                - np.asarray(p_right, float).reshape(3, 4)[0, 2])
    if not math.isfinite(off) or (width is not None and abs(off) >= 0.25 * width):
        raise ValueError(f'the principal points differ by cx_left - cx_right = {off} px '
                         f'(must be finite and under a quarter of the width {width})')
    return off


def align_right_image(right: np.ndarray, offset_px: float) -> np.ndarray:
    """The right image moved ``offset_px`` columns to the right (``principal_offset_px``),
    so that its principal point is the left's and ``d = u_left - u_right`` is ``f·B/z``.

    Args:
        right: (H, W) uint8 right image, rectified.
        offset_px: cx_left - cx_right, px (fractional: bilinear).
    Returns:
        (H, W) uint8: the moved image (the edge column repeated where the move leaves
        none: a constant along rows adds no vertical edge to match); ``right`` itself
        when the offset is 0.
    """
    if offset_px == 0.0:
        return right
    w = right.shape[1]
    k = math.floor(offset_px)
    a = offset_px - k
    # dst(x) = (1 - a) src(x - k) + a src(x - k - 1), columns clipped into the image
    x = np.arange(w)
    c0 = np.clip(x - k, 0, w - 1)
    c1 = np.clip(x - k - 1, 0, w - 1)
    if a == 0.0:
        return np.ascontiguousarray(right[:, c0])
    out = (1.0 - a) * right[:, c0] + a * right[:, c1]
    return np.rint(out).astype(right.dtype)

@dataclass(frozen=True)
class MetricPlane:
    """A plane in the left optical frame: ``normal_up . X + height = 0`` for X on it.

    ``normal_up`` is the unit normal pointing up (away from the ground, towards the
    camera); ``height`` (m) is the left optical centre's distance above the plane.
    """

    normal_up: np.ndarray
    height: float

    def signed_height(self, points_left: np.ndarray) -> np.ndarray:
        """Height (m) of points (N, 3) above the plane; negative below it."""
        return np.asarray(points_left, float).reshape(-1, 3) @ self.normal_up + self.height


def columns(*cols: np.ndarray) -> np.ndarray:
    """``np.stack(cols, axis=-1)`` of arrays of one shape (S) and dtype: (S + (C,)), the
    same values without np.stack's overhead (arrays of different shapes: np.stack's
    answer)."""
    shape = cols[0].shape
    for c in cols:
        if c.shape != shape:
            return np.stack(cols, axis=-1)
    out = np.empty(shape + (len(cols),), np.result_type(*cols))
    for i, c in enumerate(cols):
        out[..., i] = c
    return out


def sub_rows(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``p - v`` of a float64 (N, C) array and a float64 (C,) vector: the same differences
    worked out column by column, without numpy's broadcast over rows of C values (an
    inner loop a row: a few times slower at thousands of rows). (N, C) float64."""
    out = np.empty(p.shape)
    for j in range(p.shape[1]):
        np.subtract(p[:, j], v[j], out=out[:, j])
    return out


def add_rows(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``p + v`` of a float64 (N, C) array and a float64 (C,) vector, column by column
    (`sub_rows`). (N, C) float64."""
    out = np.empty(p.shape)
    for j in range(p.shape[1]):
        np.add(p[:, j], v[j], out=out[:, j])
    return out


def sub_scaled(p: np.ndarray, s: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``p - s[:, None] * n[None, :]`` of float64 p (N, C), s (N,) and n (C,): each
    product rounded, then the difference, as numpy's broadcast does them, column by
    column (`sub_rows`). (N, C) float64."""
    out = np.empty(p.shape)
    for j in range(p.shape[1]):
        col = out[:, j]
        np.multiply(s, n[j], out=col)
        np.subtract(p[:, j], col, out=col)
    return out


def vector_norm(x: np.ndarray) -> float:
    """``np.linalg.norm`` of a 1-D float64 vector, with its arithmetic (the square root
    of ``x @ x``, x contiguous) without its overhead."""
    x = x.ravel()
    return math.sqrt(x.dot(x))


def row_norms(x: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(x, axis=1)`` of a float64 (N, 3) array, with its arithmetic (the
    square root of the squares added in order along the row) without its overhead:
    (N,) float64."""
    s = x * x
    return np.sqrt(s[:, 0] + s[:, 1] + s[:, 2])


def plane_from_metric(cam: StereoCamera, plane: MetricPlane) -> np.ndarray:
    """Disparity-space plane (a, b, c) of a metric ground plane.

    Returns:
        (3,) float64 array (a, b, c) with ``d = a*u + b*v + c`` (cyclopean pixels).
    """
    n_down = -np.asarray(plane.normal_up, float)
    # Cyclopean origin is at +B/2 along x in the left frame: its height above the plane.
    h_c = plane.height + float(plane.normal_up[0]) * cam.baseline / 2.0
    if h_c <= 0:
        raise ValueError(f'camera is not above the plane (cyclopean height {h_c:.3f} m)')
    k = cam.baseline / h_c
    a = k * n_down[0]
    b = k * n_down[1]
    c = k * (n_down[2] * cam.f - n_down[0] * cam.cx - n_down[1] * cam.cy)
    return np.array([a, b, c])


def metric_from_plane(cam: StereoCamera, abc) -> MetricPlane | None:
    """Metric ground plane in the left optical frame from disparity-space (a, b, c).

    Returns None when (a, b, c) do not describe a plane below the cameras (e.g. all zero).
    """
    a, b, c = (float(x) for x in abc)
    # d = (B/h)(n.(u-cx, v-cy, f))  =>  n/h = (a, b, (c + a cx + b cy)/f) / B
    w = np.array([a, b, (c + a * cam.cx + b * cam.cy) / cam.f]) / cam.baseline
    norm = vector_norm(w)
    if not np.isfinite(norm) or norm <= 1e-12:
        return None
    n_down = w / norm
    h_c = 1.0 / norm
    normal_up = -n_down
    h_left = h_c - float(normal_up[0]) * cam.baseline / 2.0
    return MetricPlane(normal_up=normal_up, height=h_left)


def plane_disparity(abc, u, v) -> np.ndarray:
    """Ground disparity (px) predicted at cyclopean (u, v) by the plane (a, b, c)."""
    a, b, c = abc
    return a * np.asarray(u, float) + b * np.asarray(v, float) + c


#: `ground_axes` of the last few planes, by the bytes of their normal and height (a
#: frame asks for the axes of one or two planes some twenty times)
_AXES: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
_AXES_KEPT = 8


def ground_axes(plane: MetricPlane) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ground's own axes in the left optical frame.

    Returns:
        (origin, fwd, left), (3,) float64 each: the point of the plane below the left
        camera (metres), the walking direction (the optical axis projected onto the
        plane) and the direction to the left (REP 103), unit vectors. The arrays of a
        plane asked for before (the same normal and height) are returned again,
        read-only.
    """
    n = np.asarray(plane.normal_up, float)
    key = n.tobytes() + np.float64(plane.height).tobytes()
    axes = _AXES.get(key)
    if axes is None:
        if len(_AXES) >= _AXES_KEPT:
            _AXES.clear()
        axes = _ground_axes(n, plane.height)
        for a in axes:
            a.setflags(write=False)     # shared between callers: read-only
        _AXES[key] = axes
    return axes


def _ground_axes(n: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`ground_axes` of the plane of up normal ``n`` (3,) and ``height`` (m)."""
    fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
    fwd /= vector_norm(fwd)
    # n x fwd, written out (np.cross costs tens of microseconds per call)
    left = np.array([n[1] * fwd[2] - n[2] * fwd[1], n[2] * fwd[0] - n[0] * fwd[2],
                     n[0] * fwd[1] - n[1] * fwd[0]])
    return -height * n, fwd, left


def ground_range_bearing(plane: MetricPlane, points_left) -> tuple[np.ndarray, np.ndarray]:
    """Range and bearing of points along the ground, as the wearer would be told them.

    The range is measured in the ground plane from the point below the left camera to the
    foot of each point (its orthogonal projection onto the plane). The bearing is the
    angle in the ground plane from the walking direction (the optical axis projected onto
    the plane), positive to the left (REP 103).

    Args:
        plane: the ground plane in the left optical frame.
        points_left: (N, 3) metres, left optical frame.
    Returns:
        (range (N,) metres, bearing (N,) radians).
    """
    p = np.asarray(points_left, float).reshape(-1, 3)
    n = np.asarray(plane.normal_up, float)
    foot = p - (p @ n + plane.height)[:, None] * n[None, :]
    origin_foot, fwd, left = ground_axes(plane)
    g = foot - origin_foot[None, :]
    rng_ = row_norms(g)
    bearing = np.arctan2(g @ left, g @ fwd)
    return rng_, bearing
