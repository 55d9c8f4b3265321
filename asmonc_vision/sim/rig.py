"""The simulated stereo rig: intrinsics, mounting and image formation settings.

The default is the rig of Molton et al. (1998): f = 300 px, baseline 0.35 m,
320 x 240 images, principal point at the image centre, cameras 1.25 m above the
ground pitched down 20 degrees (ground visible from ~1.4 m to the horizon), 10 Hz.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.config import check_fields, param

#: Frame ids (CONVENTIONS.md).
WORLD_FRAME = 'world'
LEFT_FRAME = 'stereo_left_optical_frame'
RIGHT_FRAME = 'stereo_right_optical_frame'
IMU_FRAME = 'inclinometer_link'


@dataclass(frozen=True)
class RigSettings:
    """Stereo rig and camera image formation. Frozen; validated on construction."""

    width: int = param(320, 'image width, pixels', range=(16, 4096))
    height: int = param(240, 'image height, pixels', range=(16, 4096))
    focal: float = param(300.0, 'focal length f, pixels (both cameras, rectified)',
                         range=(10.0, 10000.0))
    principal_dx: float = param(0.0, 'principal point offset from the image centre '
                                'along u, pixels', range=(-1000.0, 1000.0))
    principal_dy: float = param(0.0, 'principal point offset from the image centre '
                                'along v, pixels', range=(-1000.0, 1000.0))
    baseline: float = param(0.35, 'distance between the optical centres, metres',
                            range=(0.02, 2.0))
    camera_height: float = param(1.25, 'height of the baseline midpoint above the ground '
                                 'when standing, metres', range=(0.2, 3.0))
    camera_pitch_deg: float = param(20.0, 'nominal downward tilt of the optical axes, '
                                    'degrees (REP 103 pitch of inclinometer_link)',
                                    range=(-10.0, 80.0))
    camera_roll_deg: float = param(0.0, 'mounting roll of the rig (a backpack worn '
                                   'crooked), degrees, REP 103 roll of inclinometer_link '
                                   '(positive = left side up)', range=(-20.0, 20.0))
    right_tilt_deg: float = param(0.0, 'rectification residual: the right camera turned '
                                  'about its optical x axis, degrees (a vertical '
                                  'misalignment of about f * this in radians, pixels; '
                                  'positive = the right image moves down)',
                                  range=(-2.0, 2.0))
    right_roll_deg: float = param(0.0, 'rectification residual: the right camera turned '
                                  'about its optical axis, degrees', range=(-5.0, 5.0))
    fps: float = param(10.0, 'camera frame rate, Hz', range=(0.5, 120.0))
    supersample: int = param(2, 'rays per pixel along each image axis (anti-aliasing)',
                             range=(1, 4))
    noise_sigma: float = param(2.0, 'camera noise standard deviation, grey levels',
                               range=(0.0, 50.0))
    blur_sigma: float = param(0.5, 'optical blur (Gaussian) standard deviation, pixels',
                              range=(0.0, 5.0))
    vignetting: float = param(0.08, 'relative darkening at the image corners',
                              range=(0.0, 0.9))
    left_gain: float = param(1.0, 'left camera gain', range=(0.1, 10.0))
    left_offset: float = param(0.0, 'left camera offset, grey levels', range=(-100.0, 100.0))
    right_gain: float = param(1.05, 'right camera gain (right = gain * radiance + offset)',
                              range=(0.1, 10.0))
    right_offset: float = param(4.0, 'right camera offset, grey levels',
                                range=(-100.0, 100.0))
    # camera realism, all off by default (see docs/sim.md)
    exposure_time: float = param(0.0, 'exposure time, seconds: motion blur from the '
                                 'rig and people moving during it, rendered as the mean '
                                 'of exposure_samples renders spread over it, centred on '
                                 'the frame time (0 = off)', range=(0.0, 0.05))
    exposure_samples: int = param(4, 'sub-exposure renders averaged when exposure_time '
                                  '> 0', range=(2, 16))
    gain_drift: float = param(0.0, 'auto-exposure drift: relative amplitude of a slowly '
                              'varying gain, shared by both cameras with a quarter of it '
                              'independent per camera (0 = off)', range=(0.0, 0.3))
    gain_drift_period: float = param(6.0, 'typical period of the auto-exposure drift, '
                                     'seconds', range=(0.5, 120.0))
    right_shift_px: float = param(0.0, 'rectification residual applied after rendering: '
                                  'the right image moved down by this many pixels '
                                  '(CameraInfo still claims a perfect rectification)',
                                  range=(-3.0, 3.0))
    right_rotation_deg: float = param(0.0, 'rectification residual applied after '
                                      'rendering: the right image turned about its '
                                      'principal point, degrees (counter-clockwise as '
                                      'displayed)', range=(-2.0, 2.0))

    def __post_init__(self) -> None:
        check_fields(self)

    @classmethod
    def chest(cls, **changes) -> 'RigSettings':
        """A level chest rig: 640 x 480, f = 560 px (57 degrees across), baseline 0.12 m,
        cameras 1.3 m high looking 5 degrees down (``changes`` override any field)."""
        base = dict(width=640, height=480, focal=560.0, baseline=0.12, camera_height=1.3,
                    camera_pitch_deg=5.0)
        base.update(changes)
        return cls(**base)

    @classmethod
    def narrow(cls, **changes) -> 'RigSettings':
        """A narrow-baseline module camera, as the common commercial stereo modules are:
        640 x 400, f = 450 px (71 degrees across), baseline 0.075 m, 1.3 m high looking
        15 degrees down (``changes`` override any field). f B is 34 px m against the
        paper's 105 and the chest rig's 67: the same height gives a third of the paper's
        disparity excess."""
        base = dict(width=640, height=400, focal=450.0, baseline=0.075, camera_height=1.3,
                    camera_pitch_deg=15.0)
        base.update(changes)
        return cls(**base)

    @property
    def realism(self) -> bool:
        """Whether any of the camera realism effects is on."""
        return bool(self.exposure_time > 0 or self.gain_drift > 0 or self.right_shift_px
                    or self.right_rotation_deg)

    @property
    def cx(self) -> float:
        """Principal point u, pixels (pixel-centre origin: image centre is (W-1)/2)."""
        return (self.width - 1) / 2.0 + self.principal_dx

    @property
    def cy(self) -> float:
        """Principal point v, pixels."""
        return (self.height - 1) / 2.0 + self.principal_dy

    @property
    def pitch(self) -> float:
        """Nominal camera pitch, radians (positive = looking down)."""
        return math.radians(self.camera_pitch_deg)

    @property
    def right_misalignment(self) -> np.ndarray:
        """(3,) rotation vector, radians, in the right optical frame: the right camera's
        rotation away from the rectified pose (zero for a perfectly rectified pair)."""
        return np.radians([self.right_tilt_deg, 0.0, self.right_roll_deg])

    def camera(self) -> StereoCamera:
        """The rectified stereo camera model of ``core.camera``."""
        return StereoCamera(f=float(self.focal), cx=self.cx, cy=self.cy,
                            baseline=float(self.baseline), width=int(self.width),
                            height=int(self.height))

    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera-info matrices of the rectified pair.

        Returns:
            (K (3, 3), P_left (3, 4), P_right (3, 4)) float64; ``P_right[0, 3] = -f * B``.
        """
        k = np.array([[self.focal, 0.0, self.cx], [0.0, self.focal, self.cy], [0.0, 0.0, 1.0]])
        p_left = np.hstack([k, np.zeros((3, 1))])
        p_right = p_left.copy()
        p_right[0, 3] = -self.focal * self.baseline
        return k, p_left, p_right
