"""Visual egomotion of the stereo rig (Molton et al. 1998, Section 4), pure numpy/OpenCV.

Modules:
    geometry    rigid motions (so3_exp/log, invert, compose, adjoint), rectified stereo
                projection and triangulation; the frame conventions.
    features    corners with sub-pixel positions (Shi–Tomasi + the cornerSubPix
                condition, or Wang–Brady), NCC windows, stereo and temporal matching.
    solvers     Lambda Twist P3P, Grunert's P3P, Kabsch, seven- and eight-point F,
                essential matrix decomposition (all vectorised over hypotheses).
    refine      pose Gauss–Newton/LM, two-view stereo bundle adjustment, the paper's
                object-space and Sampson refinements, scale from stereo.
    estimators  Correspondences -> MotionEstimate with RANSAC / LO-RANSAC, METHODS.
    pipeline    EgomotionConfig, EgomotionEstimator: images -> frame-to-frame motion.
    experiment  the paper's synthetic experiment (Tables 2 and 3) and the corner
                localisation measurement.

The egomotion is ``T_prev_curr = (R, t)``: ``X_prev = R @ X_curr + t`` in the left optical
frames (x right, y down, z forward, metres); see ``geometry`` and docs/motion.md.
"""
from asmonc_vision.core.motion.estimators import (METHODS, Correspondences, MotionEstimate,
                                                  RansacSettings, estimate_motion)
from asmonc_vision.core.motion.features import DETECTORS, detect_corners
from asmonc_vision.core.motion.geometry import (compose, invert, rotation_error_components,
                                                so3_exp, so3_log)
from asmonc_vision.core.motion.pipeline import (FIRST, IMPLAUSIBLE, NO_MOTION, OK,
                                                TOO_FEW_FEATURES, TOO_FEW_MATCHES,
                                                EgomotionConfig, EgomotionEstimator,
                                                EgomotionResult, StereoFeatures)

__all__ = ['METHODS', 'DETECTORS', 'Correspondences', 'MotionEstimate', 'RansacSettings',
           'estimate_motion', 'detect_corners', 'compose', 'invert', 'rotation_error_components',
           'so3_exp', 'so3_log', 'EgomotionConfig', 'EgomotionEstimator', 'EgomotionResult',
           'StereoFeatures', 'OK', 'FIRST', 'TOO_FEW_FEATURES', 'TOO_FEW_MATCHES', 'NO_MOTION',
           'IMPLAUSIBLE']
