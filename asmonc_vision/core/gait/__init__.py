"""The human walk model (Molton et al. 1998, Section 5): a Kalman-filter model of the
wearer's walking that tracks roll, pitch and yaw of the camera rig from a 16 Hz
compass/inclinometer (and visual motion) and predicts them half a second ahead.

Modules:
    model     -- GaitConfig and the iterated EKF (shared step frequency, per-axis
                 amplitude/phase/offset, yaw rate, pitch harmonic).
    prefilter -- the Butterworth prefilter and the known response it is compensated by.
    detector  -- the change detector (walk start/stop, non-walking movement).
    tracker   -- GaitTracker: the whole pipeline, inclinometer + visual motion in,
                 GaitEstimate (state, prediction at the horizon) out.
    rotations -- REP 103 angles, quaternions, visual motion -> attitude increments.
    attitude  -- complementary filter for 100 Hz IMUs (real walking data), decimation.
    scoring   -- prediction, phase and walk-detection metrics.
"""
from asmonc_vision.core.gait.model import GaitConfig, WalkModelEKF
from asmonc_vision.core.gait.tracker import GaitEstimate, GaitTracker

__all__ = ['GaitConfig', 'WalkModelEKF', 'GaitTracker', 'GaitEstimate']
