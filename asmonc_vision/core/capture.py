"""Stereo capture: calibration files, rectification, and frame sources (no ROS here).

The backpack carries two USB cameras (or one side-by-side stereo camera). This module
turns their frames into a *rectified* mono8 pair plus the rectified projection matrices
that the node publishes as camera_info (see docs/CONVENTIONS.md and core/camera.py):

* Left camera = the reference; rectified ``P_left = [[f,0,cx,0],[0,f,cy,0],[0,0,1,0]]``,
  ``P_right`` equal except ``P_right[0,3] = -f*B`` (B the baseline in metres, > 0).
* Rows agree after rectification; disparity ``d = u_left - u_right > 0``.

Calibration files (``load_calibration``), detected by content:

1. **OpenCV stereo calibration** (``cv2.FileStorage`` YAML/XML/JSON, e.g. written by a
   ``cv2.stereoCalibrate`` script), or the same keys in plain YAML (numbers as flat or
   nested lists)::

       %YAML:1.0
       ---
       image_width: 640          # pixels (or image_size: [640, 480])
       image_height: 480
       K1: !!opencv-matrix {rows: 3, cols: 3, dt: d, data: [...]}   # left intrinsics
       D1: !!opencv-matrix {rows: 1, cols: 5, dt: d, data: [...]}   # left distortion
       K2: ...                   # right intrinsics
       D2: ...                   # right distortion (plumb_bob k1 k2 p1 p2 k3, 4..14 values)
       R: ...                    # 3x3 rotation  } as from cv2.stereoCalibrate:
       T: ...                    # 3x1, METRES   } X_right = R @ X_left + T, T ~ (-B, 0, 0)

   Rectification: ``cv2.stereoRectify`` (CALIB_ZERO_DISPARITY, ``alpha``) then
   ``cv2.initUndistortRectifyMap``, computed once.
2. **ROS camera_info YAML pair** (``camera_calibration``'s left.yaml and right.yaml):
   ``image_width, image_height, camera_matrix, distortion_coefficients,
   rectification_matrix, projection_matrix`` (each ``{rows, cols, data}``); give the
   right file separately. Maps from ``initUndistortRectifyMap(K, D, R, P)``.
3. **KITTI ``calib.txt``** (lines ``P0: ..`` to ``P3: ..``, 12 numbers each): images are
   already rectified; the pair of P rows is chosen by the image folders (image_2/image_3
   -> P2/P3). No maps; image size comes from the frames.
"""
from __future__ import annotations

import glob
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import check_fields, param

#: A clock returning integer nanoseconds (the node passes its ROS clock).
ClockNs = Callable[[], int]


class CalibrationError(ValueError):
    """A calibration file that is missing, unreadable or not a horizontal stereo pair."""


class SourceError(RuntimeError):
    """A frame source that cannot be opened or did not deliver a frame."""


class SourceEnded(Exception):
    """A finite source (image folder, video files without loop) has no more frames."""


class FrameSizeError(ValueError):
    """A pair whose images differ in size, or do not match the calibration."""


# --- settings ------------------------------------------------------------------------

@dataclass(frozen=True)
class CaptureConfig:
    """Settings of the stereo capture node (ROS parameters, fixed at start-up)."""

    source: str = param(
        'devices', 'frame source: "devices" (two cameras or video files), "side_by_side" '
        '(one camera delivering left|right in one frame) or "folder" (image folders)',
        choices=('devices', 'side_by_side', 'folder'))
    left_device: str = param(
        '0', 'source "devices": left camera, a device index ("0"), a device path '
        '("/dev/video0") or a video file')
    right_device: str = param('1', 'source "devices": right camera (as left_device)')
    stereo_device: str = param(
        '0', 'source "side_by_side": the stereo camera (index, device path or video file); '
        'the left half of each frame is the left image')
    folder: str = param(
        '', 'source "folder": directory holding the left and right image folders '
        '(and, for KITTI, calib.txt)')
    left_subdir: str = param(
        '', 'source "folder": left image folder inside `folder`; empty: "left", else '
        '"image_2", else "image_0"')
    right_subdir: str = param(
        '', 'source "folder": right image folder; empty: "right", "image_3" or "image_1"')
    pattern: str = param('*.png', 'source "folder": file name pattern; left and right '
                         'files are paired by name, in sorted order')
    loop: bool = param(False, 'start again at the end of an image folder or video files')
    calibration_file: str = param(
        '', 'stereo calibration: OpenCV stereo YAML (K1 D1 K2 D2 R T), a ROS camera_info '
        'YAML of the left camera (with right_calibration_file) or a KITTI calib.txt; empty '
        'for source "folder": `folder`/calib.txt')
    right_calibration_file: str = param(
        '', 'ROS camera_info YAML of the right camera (only with a left camera_info YAML)')
    rectify_alpha: float = param(
        0.0, 'stereoRectify free scaling: 0 keeps only valid pixels, 1 keeps all source '
        'pixels (black borders)', range=(0.0, 1.0))
    fps: float = param(
        15.0, 'frames per second: requested from cameras; playback rate of folders and '
        'video files', range=(0.5, 120.0))
    width: int = param(0, 'requested camera frame width, pixels (whole side-by-side frame); '
                       '0 keeps the camera default', range=(0, 8192))
    height: int = param(0, 'requested camera frame height, pixels; 0 keeps the default',
                        range=(0, 8192))
    left_frame_id: str = param('stereo_left_optical_frame', 'frame id of the left images')
    right_frame_id: str = param('stereo_right_optical_frame', 'frame id of the right images')
    retry_period: float = param(
        2.0, 'a camera that cannot be opened, or has delivered nothing for this long, is '
        '(re)opened this often, seconds', range=(0.1, 60.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.source == 'folder' and not self.folder:
            raise ValueError('CaptureConfig.folder must be set when source is "folder" '
                             '(directory holding the left and right image folders)')


# --- images --------------------------------------------------------------------------

def to_gray(img: np.ndarray) -> np.ndarray:
    """(H, W) mono8, (H, W, 3) BGR or (H, W, 4) BGRA uint8 -> (H, W) uint8."""
    import cv2

    img = np.asarray(img)
    if img.dtype != np.uint8:
        raise FrameSizeError(f'expected 8-bit images, got {img.dtype}')
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    raise FrameSizeError(f'cannot use an image of shape {img.shape}')


def split_side_by_side(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split one side-by-side stereo frame (left image | right image) into two views.

    Raises:
        FrameSizeError: the width is odd (not two equal halves).
    """
    w = frame.shape[1]
    if w % 2:
        raise FrameSizeError(f'a side-by-side frame must have an even width, got {w}')
    half = w // 2
    return frame[:, :half], frame[:, half:]


# --- calibration -----------------------------------------------------------------------

@dataclass(frozen=True)
class StereoCalibration:
    """An unrectified stereo pair as cv2.stereoCalibrate gives it.

    Attributes:
        k1, k2: 3x3 intrinsics of the left and right cameras, pixels.
        d1, d2: distortion coefficients (OpenCV order k1 k2 p1 p2 [k3 ...]).
        r, t: rotation (3x3) and translation (3,) metres with X_right = r @ X_left + t.
        width, height: image size, pixels.
    """

    k1: np.ndarray
    d1: np.ndarray
    k2: np.ndarray
    d2: np.ndarray
    r: np.ndarray
    t: np.ndarray
    width: int
    height: int


@dataclass(frozen=True)
class CameraCalibration:
    """One camera as in a ROS camera_info YAML: K (3x3), D, R (3x3), P (3x4), size."""

    k: np.ndarray
    d: np.ndarray
    r: np.ndarray
    p: np.ndarray
    width: int
    height: int


def _rectified_projections(f: float, cx: float, cy: float, baseline: float):
    p_left = np.array([[f, 0.0, cx, 0.0], [0.0, f, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
    p_right = p_left.copy()
    p_right[0, 3] = -f * baseline
    return p_left, p_right


def _check_pair(p_left: np.ndarray, p_right: np.ndarray, what: str):
    """(f, cx, cy, baseline) of a horizontal rectified pair, or CalibrationError."""
    f = float(p_left[0, 0])
    if not (np.isfinite(f) and f > 0):
        raise CalibrationError(f'{what}: focal length P[0,0] = {f} is not > 0')
    if abs(p_right[0, 0] - f) > 1e-3 * f or abs(p_right[1, 2] - p_left[1, 2]) > 0.5:
        raise CalibrationError(f'{what}: left and right rectified cameras differ in f or '
                               'cy; not a rectified pair')
    tx = (p_right[0, 3] - p_left[0, 3]) / f
    ty = (p_right[1, 3] - p_left[1, 3]) / f
    if abs(ty) > abs(tx):
        raise CalibrationError(f'{what}: the cameras are one above the other (vertical '
                               'stereo); a side-by-side pair is needed')
    baseline = -tx
    if baseline <= 0:
        raise CalibrationError(f'{what}: the right camera is to the LEFT of the left '
                               f'camera (baseline {baseline:.3f} m): left and right swapped?')
    if baseline >= 10:
        raise CalibrationError(f'{what}: baseline {baseline:.1f} is not a plausible '
                               'length in metres (T given in millimetres?)')
    return f, float(p_left[0, 2]), float(p_left[1, 2]), float(baseline)


class StereoRectifier:
    """Rectifies stereo pairs and gives the rectified cameras' projection matrices.

    Build with ``from_stereo_calibration``, ``from_camera_calibrations`` or
    ``from_projections`` (already rectified images), or with ``load_calibration``.

    Attributes:
        p_left, p_right: 3x4 rectified projection matrices (ROS convention:
            p_right[0, 3] = -f * baseline).
        width, height: image size in pixels the maps were made for; None when the
            images are already rectified (any size is accepted).
    """

    def __init__(self, p_left, p_right, width: int | None = None, height: int | None = None,
                 maps_left=None, maps_right=None, source: str = ''):
        self.source = source
        f, cx, cy, b = _check_pair(np.asarray(p_left, float).reshape(3, 4),
                                   np.asarray(p_right, float).reshape(3, 4),
                                   source or 'calibration')
        self.p_left, self.p_right = _rectified_projections(f, cx, cy, b)
        self.width = None if width is None else int(width)
        self.height = None if height is None else int(height)
        self._maps_left = maps_left
        self._maps_right = maps_right
        #: rectifying rotations (3x3) of the raw cameras, when known (stereoRectify's R1, R2)
        self.r_left: np.ndarray | None = None
        self.r_right: np.ndarray | None = None

    # -- construction
    @classmethod
    def from_stereo_calibration(cls, cal: StereoCalibration, alpha: float = 0.0,
                                source: str = '') -> 'StereoRectifier':
        """Rectification of a raw pair with cv2.stereoRectify (zero disparity at infinity)."""
        import cv2

        size = (int(cal.width), int(cal.height))
        r1, r2, p1, p2, _q, _roi1, _roi2 = cv2.stereoRectify(
            np.asarray(cal.k1, float), np.asarray(cal.d1, float),
            np.asarray(cal.k2, float), np.asarray(cal.d2, float), size,
            np.asarray(cal.r, float), np.asarray(cal.t, float).reshape(3, 1),
            flags=cv2.CALIB_ZERO_DISPARITY, alpha=float(alpha))
        _check_pair(p1, p2, source or 'stereo calibration')
        ml = cv2.initUndistortRectifyMap(np.asarray(cal.k1, float), np.asarray(cal.d1, float),
                                         r1, p1, size, cv2.CV_16SC2)
        mr = cv2.initUndistortRectifyMap(np.asarray(cal.k2, float), np.asarray(cal.d2, float),
                                         r2, p2, size, cv2.CV_16SC2)
        out = cls(p1, p2, cal.width, cal.height, ml, mr, source)
        out.r_left, out.r_right = r1, r2
        return out

    @classmethod
    def from_camera_calibrations(cls, left: CameraCalibration, right: CameraCalibration,
                                 source: str = '') -> 'StereoRectifier':
        """Rectification given by a ROS camera_info pair (K, D, R, P of each camera)."""
        import cv2

        if (left.width, left.height) != (right.width, right.height):
            raise CalibrationError(f'{source}: left calibration is {left.width}x{left.height}'
                                   f' but right is {right.width}x{right.height}')
        size = (int(left.width), int(left.height))
        maps = []
        for cam in (left, right):
            identity = (np.allclose(cam.r, np.eye(3)) and not np.any(cam.d)
                        and np.allclose(cam.k, cam.p[:, :3]))
            maps.append(None if identity else cv2.initUndistortRectifyMap(
                cam.k, cam.d, cam.r, cam.p, size, cv2.CV_16SC2))
        if (maps[0] is None) != (maps[1] is None):
            maps = [m if m is not None else cv2.initUndistortRectifyMap(
                c.k, c.d, c.r, c.p, size, cv2.CV_16SC2) for m, c in zip(maps, (left, right))]
        return cls(left.p, right.p, left.width, left.height, maps[0], maps[1], source)

    @classmethod
    def from_projections(cls, p_left, p_right, source: str = '') -> 'StereoRectifier':
        """Already rectified images (e.g. KITTI): no remapping, only the projections."""
        return cls(p_left, p_right, source=source)

    # -- properties
    @property
    def f(self) -> float:
        """Rectified focal length, pixels."""
        return float(self.p_left[0, 0])

    @property
    def baseline(self) -> float:
        """Distance between the optical centres, metres."""
        return float(-self.p_right[0, 3] / self.p_right[0, 0])

    @property
    def k(self) -> np.ndarray:
        """3x3 intrinsics of the rectified cameras (both the same)."""
        return self.p_left[:, :3].copy()

    @property
    def remaps(self) -> bool:
        """True when rectify() resamples the images (raw cameras)."""
        return self._maps_left is not None

    def camera(self, width: int | None = None, height: int | None = None) -> StereoCamera:
        """The rectified pair as a core StereoCamera (size from the maps or given)."""
        w, h = width or self.width, height or self.height
        if w is None or h is None:
            raise ValueError('the image size is unknown: give width and height')
        return StereoCamera.from_projection(self.p_left, self.p_right, w, h)

    # -- work
    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify one pair.

        Args:
            left, right: raw images, mono8, BGR or BGRA uint8, the same size.
        Returns:
            (left_rect, right_rect): (H, W) uint8, rows aligned.
        Raises:
            FrameSizeError: the images differ in size or do not match the calibration.
        """
        import cv2

        if left.shape[:2] != right.shape[:2]:
            raise FrameSizeError(f'left image is {left.shape[1]}x{left.shape[0]} but right '
                                 f'is {right.shape[1]}x{right.shape[0]}: pair skipped')
        gl, gr = to_gray(left), to_gray(right)
        if self._maps_left is None:
            return np.ascontiguousarray(gl), np.ascontiguousarray(gr)
        h, w = gl.shape
        if (w, h) != (self.width, self.height):
            raise FrameSizeError(f'images are {w}x{h} but the calibration is for '
                                 f'{self.width}x{self.height}: pair skipped')
        out_l = cv2.remap(gl, self._maps_left[0], self._maps_left[1], cv2.INTER_LINEAR)
        out_r = cv2.remap(gr, self._maps_right[0], self._maps_right[1], cv2.INTER_LINEAR)
        return out_l, out_r


# --- calibration files ---------------------------------------------------------------

def load_kitti_projections(path: str | os.PathLike, left: str = 'P2', right: str = 'P3'
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The two 3x4 projection matrices named `left` and `right` in a KITTI calib.txt.

    KITTI's P rows are relative to camera 0; the returned pair is re-expressed in the
    left camera's frame (P_left[:, 3] = 0, P_right[0, 3] = -f*B).
    """
    rows: dict[str, np.ndarray] = {}
    for line in Path(path).read_text().splitlines():
        m = re.match(r'\s*(\w+)\s*:\s*(.*)$', line)
        if not m:
            continue
        try:
            vals = np.array([float(x) for x in m.group(2).split()])
        except ValueError:
            continue
        if vals.size == 12:
            rows[m.group(1)] = vals.reshape(3, 4)
    for name in (left, right):
        if name not in rows:
            raise CalibrationError(f'{path}: no {name} row (3x4 projection) in the KITTI '
                                   f'calibration; found {sorted(rows)}')
    pl, pr = rows[left], rows[right]
    f, cx, cy, _ = _check_pair(pl, pr, str(path))
    baseline = (pl[0, 3] - pr[0, 3]) / f
    return _rectified_projections(f, cx, cy, baseline)


def _mat(value, rows: int, cols: int | None, name: str, path) -> np.ndarray:
    """A matrix from an OpenCV FileNode, a plain list, nested lists or a ROS {data: ...}."""
    if isinstance(value, dict):
        value = value.get('data')
    arr = np.asarray(value, float)
    if cols is None:
        return arr.reshape(-1)
    if arr.size != rows * cols:
        raise CalibrationError(f'{path}: {name} has {arr.size} values, expected {rows}x{cols}')
    return arr.reshape(rows, cols)


def _load_opencv(path: Path) -> dict:
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        out: dict[str, object] = {}
        for key in ('K1', 'D1', 'K2', 'D2', 'R', 'T', 'image_width', 'image_height',
                    'image_size'):
            node = fs.getNode(key)
            if node.empty() or node.isNone():
                continue
            if node.isSeq():
                out[key] = [node.at(i).real() for i in range(node.size())]
            elif node.isMap():
                out[key] = node.mat()
            else:
                out[key] = node.real()
        return out
    finally:
        fs.release()


def _stereo_calibration(data: dict, path) -> StereoCalibration:
    missing = [k for k in ('K1', 'D1', 'K2', 'D2', 'R', 'T') if k not in data]
    if missing:
        raise CalibrationError(f'{path}: missing {", ".join(missing)} (an OpenCV stereo '
                               'calibration needs K1 D1 K2 D2 R T and the image size)')
    if 'image_size' in data:
        w, h = (int(v) for v in np.asarray(data['image_size']).reshape(-1)[:2])
    elif 'image_width' in data and 'image_height' in data:
        w, h = int(data['image_width']), int(data['image_height'])
    else:
        raise CalibrationError(f'{path}: missing the image size (image_width and '
                               'image_height, or image_size: [width, height])')
    return StereoCalibration(
        k1=_mat(data['K1'], 3, 3, 'K1', path), d1=_mat(data['D1'], 0, None, 'D1', path),
        k2=_mat(data['K2'], 3, 3, 'K2', path), d2=_mat(data['D2'], 0, None, 'D2', path),
        r=_mat(data['R'], 3, 3, 'R', path), t=_mat(data['T'], 3, 1, 'T', path).reshape(3),
        width=w, height=h)


def _camera_info_yaml(path: Path) -> CameraCalibration:
    import yaml

    try:
        data = yaml.safe_load(path.read_text())
        return CameraCalibration(
            k=_mat(data['camera_matrix'], 3, 3, 'camera_matrix', path),
            d=_mat(data.get('distortion_coefficients', {'data': []}), 0, None,
                   'distortion_coefficients', path),
            r=_mat(data.get('rectification_matrix', {'data': np.eye(3).ravel().tolist()}),
                   3, 3, 'rectification_matrix', path),
            p=_mat(data['projection_matrix'], 3, 4, 'projection_matrix', path),
            width=int(data['image_width']), height=int(data['image_height']))
    except (KeyError, TypeError, AttributeError) as exc:
        raise CalibrationError(f'{path}: not a ROS camera_info YAML (needs image_width, '
                               f'image_height, camera_matrix, projection_matrix): {exc}') from exc


def load_calibration(path: str | os.PathLike, right_path: str | os.PathLike = '',
                     alpha: float = 0.0, kitti_cameras: tuple[str, str] = ('P2', 'P3')
                     ) -> StereoRectifier:
    """Load a stereo calibration file (format detected, see the module doc).

    Args:
        path: OpenCV stereo calibration, left ROS camera_info YAML, or KITTI calib.txt.
        right_path: the right ROS camera_info YAML (with a left camera_info YAML only).
        alpha: stereoRectify free scaling (0 valid pixels only .. 1 all pixels).
        kitti_cameras: the P rows of the left and right cameras in a KITTI file.
    Raises:
        CalibrationError: missing/unreadable file or not a usable stereo pair.
    """
    import yaml

    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f'calibration file {str(p)!r} does not exist')
    text = p.read_text(errors='replace')
    head = text.lstrip()[:200]
    if re.search(r'^\s*P[0-9]\s*:', text, re.M) and 'K1' not in text:
        pl, pr = load_kitti_projections(p, *kitti_cameras)
        return StereoRectifier.from_projections(pl, pr, source=str(p))
    if right_path or 'camera_matrix' in text:
        if not right_path:
            raise CalibrationError(f'{p}: a ROS camera_info YAML describes one camera; set '
                                   'right_calibration_file to the right camera\'s YAML')
        rp = Path(right_path)
        if not rp.is_file():
            raise CalibrationError(f'right calibration file {str(rp)!r} does not exist')
        return StereoRectifier.from_camera_calibrations(
            _camera_info_yaml(p), _camera_info_yaml(rp), source=str(p))
    if head.startswith('%YAML:') or '!!opencv-matrix' in text or head.startswith('<?xml') \
            or p.suffix.lower() in ('.xml', '.json'):
        try:
            data = _load_opencv(p)
        except Exception as exc:  # cv2.error
            raise CalibrationError(f'{p}: OpenCV cannot read it: {exc}') from exc
    else:
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise CalibrationError(f'{p}: not valid YAML: {exc}') from exc
        if not isinstance(data, dict):
            raise CalibrationError(f'{p}: not a stereo calibration (expected a mapping)')
    return StereoRectifier.from_stereo_calibration(_stereo_calibration(data, p), alpha,
                                                   source=str(p))


def write_opencv_calibration(path: str | os.PathLike, cal: StereoCalibration) -> None:
    """Write a StereoCalibration in the OpenCV FileStorage format load_calibration reads."""
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    try:
        fs.write('image_width', int(cal.width))
        fs.write('image_height', int(cal.height))
        for key, val in (('K1', cal.k1), ('D1', cal.d1), ('K2', cal.k2), ('D2', cal.d2),
                         ('R', cal.r), ('T', cal.t)):
            arr = np.asarray(val, float)
            fs.write(key, arr.reshape(1, -1) if key.startswith('D') else
                     arr.reshape(3, 1) if key == 'T' else arr)
    finally:
        fs.release()


# --- frame sources ---------------------------------------------------------------------

class StereoFrame(NamedTuple):
    """One raw pair: left and right images (mono8/BGR) and the grab time (ns)."""

    left: np.ndarray
    right: np.ndarray
    stamp_ns: int


class FrameSource:
    """A source of stereo pairs. ``open`` then ``read`` repeatedly, ``close`` at the end.

    ``read`` raises SourceError when no frame came (a camera gone quiet: try again or
    reopen) and SourceEnded at the end of a finite source. ``live`` sources (cameras)
    pace themselves; others are paced by the caller.
    """

    live = True

    def open(self) -> None:
        raise NotImplementedError

    def read(self) -> StereoFrame:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def describe(self) -> str:
        return type(self).__name__


def _is_index(dev: str) -> bool:
    return dev.strip().isdigit()


def _open_capture(dev: str, side: str, width: int, height: int, fps: float):
    import cv2

    dev = str(dev).strip()
    if not dev:
        raise SourceError(f'no {side} camera given (empty device)')
    if not _is_index(dev) and not os.path.exists(dev):
        raise SourceError(f'cannot open {side} camera {dev!r}: no such device or file')
    cap = cv2.VideoCapture(int(dev) if _is_index(dev) else dev)
    if not cap.isOpened():
        cap.release()
        raise SourceError(f'cannot open {side} camera {dev!r} (unplugged, busy, or no '
                          'permission?)')
    if _is_index(dev) or dev.startswith('/dev/'):
        if width:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
        if height:
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        if fps:
            cap.set(cv2.CAP_PROP_FPS, fps)
        cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # newest frame, not a backlog (if supported)
    return cap


def _is_file(dev: str) -> bool:
    dev = str(dev).strip()
    return not _is_index(dev) and not dev.startswith('/dev/')


class DevicePairSource(FrameSource):
    """Two cameras (device indexes or paths) or two video files.

    Pairing: ``grab()`` on both first (fast, latches the frames), the stamp taken right
    after, then ``retrieve()`` (slow decode) on both: the skew between the two images is
    that of two grab calls, not of two decodes.
    """

    def __init__(self, left: str, right: str, width: int = 0, height: int = 0,
                 fps: float = 0.0, loop: bool = False, clock: ClockNs = time.time_ns):
        self.devices = (str(left), str(right))
        self.width, self.height, self.fps, self.loop = width, height, fps, loop
        self.clock = clock
        self.live = not (_is_file(left) and _is_file(right))
        self._caps: tuple | None = None

    def describe(self) -> str:
        return f'cameras {self.devices[0]!r} (left) and {self.devices[1]!r} (right)'

    def open(self) -> None:
        self.close()
        left = _open_capture(self.devices[0], 'left', self.width, self.height, self.fps)
        try:
            right = _open_capture(self.devices[1], 'right', self.width, self.height, self.fps)
        except SourceError:
            left.release()
            raise
        self._caps = (left, right)

    def _rewind(self) -> None:
        import cv2

        for cap in self._caps or ():
            cap.set(cv2.CAP_PROP_POS_FRAMES, 0)

    def read(self) -> StereoFrame:
        if self._caps is None:
            raise SourceError('source is not open')
        left, right = self._caps
        ok_l, ok_r = left.grab(), right.grab()
        if not (ok_l and ok_r) and not self.live:
            if not self.loop:
                raise SourceEnded(f'end of video files {self.devices}')
            self._rewind()
            ok_l, ok_r = left.grab(), right.grab()
        stamp = int(self.clock())
        if not ok_l or not ok_r:
            which = ' and '.join(s for s, ok in (('left', ok_l), ('right', ok_r)) if not ok)
            raise SourceError(f'{which} camera delivered no frame')
        ok_l, img_l = left.retrieve()
        ok_r, img_r = right.retrieve()
        if not ok_l or img_l is None or not ok_r or img_r is None:
            raise SourceError('could not decode a frame (retrieve failed)')
        return StereoFrame(img_l, img_r, stamp)

    def close(self) -> None:
        if self._caps is not None:
            for cap in self._caps:
                cap.release()
            self._caps = None


class SideBySideSource(FrameSource):
    """One stereo camera (or video file) delivering left|right side by side."""

    def __init__(self, device: str, width: int = 0, height: int = 0, fps: float = 0.0,
                 loop: bool = False, clock: ClockNs = time.time_ns):
        self.device = str(device)
        self.width, self.height, self.fps, self.loop = width, height, fps, loop
        self.clock = clock
        self.live = not _is_file(device)
        self._cap = None

    def describe(self) -> str:
        return f'side-by-side camera {self.device!r}'

    def open(self) -> None:
        self.close()
        self._cap = _open_capture(self.device, 'stereo', self.width, self.height, self.fps)

    def read(self) -> StereoFrame:
        import cv2

        if self._cap is None:
            raise SourceError('source is not open')
        ok = self._cap.grab()
        if not ok and not self.live:
            if not self.loop:
                raise SourceEnded(f'end of video file {self.device!r}')
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok = self._cap.grab()
        stamp = int(self.clock())
        if not ok:
            raise SourceError('stereo camera delivered no frame')
        ok, img = self._cap.retrieve()
        if not ok or img is None:
            raise SourceError('could not decode a frame (retrieve failed)')
        left, right = split_side_by_side(img)
        return StereoFrame(left, right, stamp)

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


#: (left, right) folder names tried when none are given
FOLDER_LAYOUTS = (('left', 'right'), ('image_2', 'image_3'), ('image_0', 'image_1'))


class FolderSource(FrameSource):
    """Image pairs from two folders, paired by file name (sorted).

    E.g. ``folder/left/*.png`` + ``folder/right/*.png``, or a KITTI sequence
    ``image_2/`` + ``image_3/`` (already rectified; calib.txt beside them).
    """

    live = False

    def __init__(self, folder: str, left_subdir: str = '', right_subdir: str = '',
                 pattern: str = '*.png', loop: bool = False, clock: ClockNs = time.time_ns):
        self.folder = Path(folder)
        self.subdirs = (left_subdir, right_subdir)
        self.pattern = pattern
        self.loop = loop
        self.clock = clock
        self.pairs: list[tuple[Path, Path]] = []
        self.unpaired = 0
        self._index = 0

    def describe(self) -> str:
        return f'image folder {str(self.folder)!r}'

    def resolve_subdirs(self) -> tuple[str, str]:
        """The (left, right) folder names used (given, or the first layout found)."""
        if self.subdirs[0] and self.subdirs[1]:
            return self.subdirs
        for pair in FOLDER_LAYOUTS:
            if all((self.folder / d).is_dir() for d in pair):
                return pair
        raise SourceError(f'{self.folder}: no left/right image folders (tried '
                          + ', '.join('/'.join(p) for p in FOLDER_LAYOUTS) + ')')

    def kitti_cameras(self) -> tuple[str, str]:
        """P rows of a KITTI calib.txt matching the folders (image_2 -> P2), else P2/P3."""
        try:
            left, right = self.resolve_subdirs()
        except SourceError:
            return ('P2', 'P3')
        ml, mr = re.fullmatch(r'image_(\d)', left), re.fullmatch(r'image_(\d)', right)
        if ml and mr:
            return (f'P{ml.group(1)}', f'P{mr.group(1)}')
        return ('P2', 'P3')

    def open(self) -> None:
        if not self.folder.is_dir():
            raise SourceError(f'image folder {str(self.folder)!r} does not exist')
        left_dir, right_dir = (self.folder / d for d in self.resolve_subdirs())
        for d in (left_dir, right_dir):
            if not d.is_dir():
                raise SourceError(f'image folder {str(d)!r} does not exist')
        lefts = {Path(p).name: Path(p) for p in glob.glob(str(left_dir / self.pattern))}
        rights = {Path(p).name: Path(p) for p in glob.glob(str(right_dir / self.pattern))}
        names = sorted(set(lefts) & set(rights))
        if not names:
            raise SourceError(f'no image pairs matching {self.pattern!r} with the same names '
                              f'in {left_dir} and {right_dir}')
        self.unpaired = len(set(lefts) ^ set(rights))
        self.pairs = [(lefts[n], rights[n]) for n in names]
        self._index = 0

    def read(self) -> StereoFrame:
        import cv2

        if not self.pairs:
            raise SourceError('source is not open')
        if self._index >= len(self.pairs):
            if not self.loop:
                raise SourceEnded(f'end of {self.folder} ({len(self.pairs)} pairs)')
            self._index = 0
        lp, rp = self.pairs[self._index]
        self._index += 1
        left = cv2.imread(str(lp), cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(str(rp), cv2.IMREAD_GRAYSCALE)
        stamp = int(self.clock())
        if left is None or right is None:
            raise SourceError(f'cannot read image {lp if left is None else rp}')
        return StereoFrame(left, right, stamp)


def make_source(cfg: CaptureConfig, clock: ClockNs = time.time_ns) -> FrameSource:
    """The frame source the settings ask for (not yet opened)."""
    if cfg.source == 'devices':
        return DevicePairSource(cfg.left_device, cfg.right_device, cfg.width, cfg.height,
                                cfg.fps, cfg.loop, clock)
    if cfg.source == 'side_by_side':
        return SideBySideSource(cfg.stereo_device, cfg.width, cfg.height, cfg.fps, cfg.loop,
                                clock)
    return FolderSource(cfg.folder, cfg.left_subdir, cfg.right_subdir, cfg.pattern,
                        cfg.loop, clock)


def make_rectifier(cfg: CaptureConfig, source: FrameSource | None = None) -> StereoRectifier:
    """The rectifier the settings ask for.

    Uses ``calibration_file`` (and ``right_calibration_file``); with an image folder and
    no file, ``folder/calib.txt`` (KITTI). Raises CalibrationError otherwise.
    """
    kitti = source.kitti_cameras() if isinstance(source, FolderSource) else ('P2', 'P3')
    if cfg.calibration_file:
        return load_calibration(cfg.calibration_file, cfg.right_calibration_file,
                                cfg.rectify_alpha, kitti)
    if cfg.source == 'folder':
        calib = Path(cfg.folder) / 'calib.txt'
        if calib.is_file():
            return load_calibration(calib, '', cfg.rectify_alpha, kitti)
        raise CalibrationError(f'no calibration_file set and no {calib}: the camera_info '
                               'of the pair cannot be given')
    raise CalibrationError('no calibration_file set: the stereo cameras must be calibrated '
                           '(OpenCV stereo YAML with K1 D1 K2 D2 R T, or a ROS camera_info '
                           'YAML pair)')
