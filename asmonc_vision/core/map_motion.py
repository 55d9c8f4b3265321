"""The camera motion of a pair from the motions measured before it: the evidence map's input.

The evidence map (`core.evidence_map`) places each pair's evidence by the camera motion
since the previous pair. The visual egomotion of a pair is found while the detector works
on that pair (the egomotion node runs beside the detector), so waiting for it puts the
egomotion's time on every pair's latency. `MotionPredictor` gives the map a motion for
pair k at once, from what has been measured by then:

* measured motions (``add_motion``: from a reference pair to a later one, ``X_ref = R
  X_curr + t``, left optical frames, m) or cumulative poses (``add_pose``: the
  egomotion's odometry, ``X_odom = R X_cam + t``) are chained into a trajectory of the
  left camera, one pose per measured stamp; a step whose reference pose is unknown (the
  chain broken, a motion missing) starts from the pose extrapolated to that reference;
* the pose at a stamp is the trajectory's there, interpolated between measured stamps, or
  extrapolated from the newest one at constant velocity (the newest measured motion's,
  rotation vector and translation scaled by the time), up to ``max_extrapolation_s``
  past the newest measurement (beyond it: unknown);
* ``predict(stamp)`` returns the motion from the pose the map was given for the previous
  predicted pair to the best estimate of this pair's pose, and remembers that estimate
  as this pair's: an error in an earlier prediction, once the measurement is in, is
  corrected in the next motion, so the map's pose follows the measured trajectory and
  the prediction errors do not add up (the evidence already entered stays where it was
  placed: off by the extrapolation's error, a few centimetres at a walking pace).
  While the rig stands still (the detector's edges stayed in place) the motion is the
  identity.

A measured step faster than ``max_speed_mps`` or ``max_rate_dps`` (an odometry restarted
from the origin, a wrong motion) breaks the chain: the trajectory starts again there.
Thread-safe: measurements may arrive on one thread while another predicts.
"""
from __future__ import annotations

import bisect
import math
import threading

import numpy as np

from asmonc_vision.core.motion.geometry import compose, invert, so3_exp, so3_log

Pose = tuple[np.ndarray, np.ndarray]


def scale_motion(R: np.ndarray, t: np.ndarray, a: float) -> Pose:
    """The motion ``(R, t)`` scaled by ``a`` (rotation vector and translation times a): the
    same velocity over ``a`` times the interval."""
    return so3_exp(so3_log(np.asarray(R, float)) * a), np.asarray(t, float) * a


def relative(a: Pose, b: Pose) -> Pose:
    """``T_a_b = T_a^-1 T_b`` of two poses in one frame: the motion ``X_a = R X_b + t``."""
    ri, ti = invert(a[0], a[1])
    return compose(ri, ti, b[0], b[1])


class MotionPredictor:
    """The camera motion of each pair from measurements made before it; see the module
    docstring.

    Args:
        max_extrapolation_s: a pose is extrapolated at most this far past the newest
            measurement; beyond, the motion is unknown (None).
        max_speed_mps, max_rate_dps: a measured step faster than these breaks the chain.
        history: measured poses and predictions kept.
    """

    def __init__(self, max_extrapolation_s: float = 0.5, max_speed_mps: float = 4.0,
                 max_rate_dps: float = 360.0, history: int = 64) -> None:
        if not (max_extrapolation_s >= 0 and max_speed_mps > 0 and max_rate_dps > 0
                and history >= 2):
            raise ValueError('MotionPredictor: max_extrapolation_s >= 0, max_speed_mps > 0, '
                             'max_rate_dps > 0 and history >= 2 expected')
        self.max_extrapolation_ns = int(max_extrapolation_s * 1e9)
        self.max_speed_mps = float(max_speed_mps)
        self.max_rate = math.radians(max_rate_dps)
        self.history = int(history)
        self._lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        """Forget the measurements and the predictions."""
        with self._lock:
            self._stamps: list[int] = []                 # measured stamps, ascending
            self._poses: dict[int, Pose] = {}            # measured trajectory
            self._velocity: tuple[np.ndarray, np.ndarray, int] | None = None  # R, t, dt ns
            self._odom: tuple[int, Pose] | None = None   # the newest add_pose
            self._given: tuple[int, Pose | None] | None = None  # the previous pair's
            #: predictions made, and those whose pose was measured (not extrapolated)
            self.predictions = 0
            self.measured = 0
            #: how far past the newest measured pose the latest prediction reached, ns
            #: (0: measured or interpolated; None: no prediction yet)
            self.ahead_ns: int | None = None

    # ------------------------------------------------------------------ measurements
    def add_motion(self, ref_stamp_ns: int, stamp_ns: int, R, t) -> bool:
        """A measured motion from the pair at ``ref_stamp_ns`` to the one at ``stamp_ns``
        (``X_ref = R X_curr + t``); False when it is ignored (not forward in time, not
        finite) or breaks the chain (too fast: the trajectory starts again)."""
        with self._lock:
            return self._add_motion(int(ref_stamp_ns), int(stamp_ns),
                                    np.asarray(R, float), np.asarray(t, float))

    def add_pose(self, stamp_ns: int, R, t) -> bool:
        """A cumulative pose (odometry, ``X_odom = R X_cam + t``): the motion from the
        previous pose given is measured (`add_motion`); False for the first pose (or
        one not after the previous)."""
        pose = (np.asarray(R, float), np.asarray(t, float))
        with self._lock:
            prev = self._odom
            if prev is not None and int(stamp_ns) <= prev[0]:
                return False
            self._odom = (int(stamp_ns), pose)
            if prev is None:
                return False
            mR, mt = relative(prev[1], pose)
            return self._add_motion(prev[0], int(stamp_ns), mR, mt)

    def _add_motion(self, ref_stamp_ns: int, stamp_ns: int, R: np.ndarray,
                    t: np.ndarray) -> bool:
        dt = stamp_ns - ref_stamp_ns
        if dt <= 0 or not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            return False
        if self._too_fast(R, t, dt):
            self._restart_at(stamp_ns)
            return False
        base = self._poses.get(ref_stamp_ns)
        if base is None:
            base = self._estimate(ref_stamp_ns)
        if base is None:                     # the first measurement: the origin is its start
            base = (np.eye(3), np.zeros(3))
        self._insert(stamp_ns, compose(base[0], base[1], R, t))
        self._velocity = (R, t, dt)
        return True

    def _too_fast(self, R: np.ndarray, t: np.ndarray, dt_ns: int) -> bool:
        dt = dt_ns * 1e-9
        return bool(np.linalg.norm(t) > self.max_speed_mps * dt
                    or np.linalg.norm(so3_log(R)) > self.max_rate * dt)

    def _restart_at(self, stamp_ns: int) -> None:
        """The chain broken at ``stamp_ns``: the trajectory starts again from there."""
        self._stamps, self._poses, self._velocity = [], {}, None
        self._given = None
        self._insert(stamp_ns, (np.eye(3), np.zeros(3)))

    def _insert(self, stamp_ns: int, pose: Pose) -> None:
        if stamp_ns not in self._poses:
            bisect.insort(self._stamps, stamp_ns)
        self._poses[stamp_ns] = pose
        while len(self._stamps) > self.history:
            del self._poses[self._stamps.pop(0)]

    # ------------------------------------------------------------------ prediction
    def _estimate(self, stamp_ns: int) -> Pose | None:
        """The trajectory's pose at ``stamp_ns``: measured, interpolated or extrapolated
        (None: nothing measured before it, or the newest measurement too old)."""
        if stamp_ns in self._poses:
            return self._poses[stamp_ns]
        i = bisect.bisect_left(self._stamps, stamp_ns)
        if i == 0:
            return None
        s0 = self._stamps[i - 1]
        p0 = self._poses[s0]
        if i < len(self._stamps):                     # between two measured poses
            s1 = self._stamps[i]
            step = scale_motion(*relative(p0, self._poses[s1]), (stamp_ns - s0) / (s1 - s0))
        else:
            if self._velocity is None or stamp_ns - s0 > self.max_extrapolation_ns:
                return None
            R, t, dt = self._velocity
            step = scale_motion(R, t, (stamp_ns - s0) / dt)
        return compose(p0[0], p0[1], step[0], step[1])

    def predict(self, stamp_ns: int, still: bool = False) -> tuple | None:
        """The motion ``(R, t)`` from the previous predicted pair to the pair at
        ``stamp_ns`` (``X_prev = R X_curr + t``): from the pose the previous pair was
        given to the best estimate of this one's (the identity while ``still``); None
        for the first pair, or when the pose cannot be estimated (no measurement, or
        the newest too old)."""
        stamp_ns = int(stamp_ns)
        with self._lock:
            prev = self._given
            if prev is not None and stamp_ns <= prev[0]:
                return None
            est = self._estimate(stamp_ns)
            base = None
            if prev is not None:
                base = prev[1] if prev[1] is not None else self._estimate(prev[0])
            if base is not None and est is not None and still:
                est = base
            self._given = (stamp_ns, est)
            if base is None or est is None:
                return None
            self.predictions += 1
            self.measured += int(stamp_ns in self._poses)
            self.ahead_ns = max(stamp_ns - self._stamps[-1], 0) if self._stamps else None
            return relative(base, est)
