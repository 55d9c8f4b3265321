"""Kalman tracks of obstacles over frames (the obstacle half of the paper's DGPR).

Molton et al. (1998), Section 4: obstacles found by GPOD are tracked from frame to frame
as 3-D points (X, Y, Z) with a Kalman filter, associated to new detections by nearest
neighbour within a Mahalanobis gate, born from unassociated detections and deleted when
they are no longer seen; the camera's motion between frames is the filter's input.

Here each track is the *foot* of an obstacle's nearest point: where its nearest part
meets the ground, metres, in the current left optical frame (x right, y down, z forward).
All tracks are one batch of 3-state filters (arrays of x and P), with

    predict:  x = F x + u,  F = R_cᵀ, u = -R_cᵀ t_c      (camera motion as input)
              P = F P Fᵀ + Q,  Q = q² dt I + F Σ_t Fᵀ    (random walk; motion uncertainty)
    update:   y = z - H x,  H = I
              S = H P Hᵀ + R
              K = P Hᵀ S⁻¹
              x = x + K y
              P = (I - K H) P (I - K H)ᵀ + K R Kᵀ         (Joseph form)

where (R_c, t_c) is the motion ``T_prev_curr`` of the left camera (``X_prev = R_c X_curr +
t_c``, as `/egomotion` gives it). With no motion known (``motion=None``) tracks cannot be
carried into the new frame and are ended -- all but the sure ones the caller's ``hold``
test keeps (obstacles remembered below the view, which no frame could find again): those
stay where they were, more uncertain; the detector passes the identity while the rig
stands still.

Association: the squared Mahalanobis distance d² = yᵀ S⁻¹ y of every (track, detection)
pair; pairs within the gate (χ² with 3 degrees of freedom, ``gate_chi2``) are taken
greedily by increasing d² (global nearest neighbour, each track and detection at most
once). A detection left over starts a track. A track left over is *coasted*: reported at
its predicted place, flagged with the time since its last detection, for up to
``coast_s`` seconds -- unless the caller's free-space test says its region now shows
ground (the obstacle went away) or its foot is out of view. Coasting bridges the frames
in which a small obstacle's evidence dips under the threshold: an obstacle does not
vanish because one frame's disparities were noisy.

A track whose place the caller's ``unseen`` test says the camera cannot see (an
obstacle the wearer walks up to leaves the bottom of the image about 1.4 m ahead on the
paper's rig, nearer than the alarm's stop range) is not detected because it cannot be,
not because it went away: a *sure* track (``sure_hits``) is then remembered, carried by
the motion, for up to ``unseen_coast_s`` (the free-space test still ends it when a part
of its region in view shows ground); a track not sure ends, as before.

A detection outside a track's gate that the caller's ``same_object`` test says shows
the same obstacle (another point of it reported as its nearest, e.g. a box's far corner
when one silhouette edge dips) keeps the track seen without moving it.

A missed measurement of a track is ``z = None`` in textbook terms: the track is
predicted and not updated.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from .npfast import flat_nonzero

#: χ²(3) 0.99 quantile: the default association gate.
CHI2_3_99 = 11.344866730144373


@dataclass
class TrackOutput:
    """One track's report for the current frame.

    Attributes:
        track_id: positive id, stable over the track's life.
        index: index into the frame's detections of the detection it was updated with,
            or -1 when coasted (no detection this frame).
        foot: (3,) float64 the filtered foot, metres, current left optical frame.
        foot_cov: (3, 3) float64 its covariance, m².
        age_s: seconds since the track was last detected (0 when detected this frame).
        hits: number of frames in which it was detected.
        payload: the object of its latest detection (passed in by the caller).
    """

    track_id: int
    index: int
    foot: np.ndarray
    foot_cov: np.ndarray
    age_s: float
    hits: int
    payload: object = None


class ObstacleTracker:
    """A batch of constant-position Kalman tracks of obstacle feet; see the module
    docstring.

    Args:
        coast_s: longest time a track is reported without a detection, s (0: tracks are
            reported only in frames where they are detected).
        gate_chi2: association gate on the squared Mahalanobis distance (3 dof).
        process_noise_m: random-walk noise of a foot, m/√s (a static obstacle's estimate
            may drift this much: ground-plane refits, sway).
        confirm_hits: detections a track needs before it is coasted.
        min_hit_fraction: a track is coasted only while it was detected in at least this
            fraction of the frames since its birth (M of N: an obstacle is seen in most
            frames, a texture that sometimes passes the threshold is not).
        sure_hits: a track detected in at least this many frames is coasted whatever its
            hit fraction (0: off): an obstacle seen that often is not a texture passing
            the threshold by chance, and it does not go away because its evidence dips
            for longer than it was seen. It still ends after ``coast_s`` without a
            detection, or when the free-space test sees ground in its place.
        unseen_coast_s: longest time a sure track is reported without a detection while
            its place is out of the camera's view (the ``unseen`` test of ``update``), s;
            None: ``coast_s``.
    Raises:
        ValueError: a setting out of its range (the message names it).
    """

    def __init__(self, coast_s: float = 1.0, gate_chi2: float = CHI2_3_99,
                 process_noise_m: float = 0.05, confirm_hits: int = 1,
                 min_hit_fraction: float = 0.5, sure_hits: int = 0,
                 unseen_coast_s: float | None = None) -> None:
        self.coast_s, self.gate_chi2 = float(coast_s), float(gate_chi2)
        self.unseen_coast_s = float(coast_s if unseen_coast_s is None else unseen_coast_s)
        self.process_noise_m, self.confirm_hits = float(process_noise_m), int(confirm_hits)
        self.min_hit_fraction = float(min_hit_fraction)
        self.sure_hits = int(sure_hits)
        for name, lo, hi in (('coast_s', 0.0, 3600.0), ('gate_chi2', 0.01, 1e6),
                             ('process_noise_m', 0.0, 100.0), ('confirm_hits', 1, 1000),
                             ('min_hit_fraction', 0.0, 1.0), ('sure_hits', 0, 100000),
                             ('unseen_coast_s', 0.0, 3600.0)):
            val = getattr(self, name)
            if not lo <= val <= hi:
                raise ValueError(f'ObstacleTracker.{name} = {val} is out of range '
                                 f'[{lo}, {hi}]')
        #: x (T, 3) feet, P (T, 3, 3) covariances, ids, hits, stamps last detected
        self._x: np.ndarray = np.zeros((0, 3))
        self._P: np.ndarray = np.zeros((0, 3, 3))
        self._id: np.ndarray = np.zeros(0, np.int64)
        self._hits: np.ndarray = np.zeros(0, np.int64)
        self._frames: np.ndarray = np.zeros(0, np.int64)
        self._last_seen = np.zeros(0)
        self._payload: list = []
        self._stamp: float | None = None
        self._next_id = 1

    def __len__(self) -> int:
        return int(self._x.shape[0])

    def reset(self) -> None:
        """End every track (ids keep counting up)."""
        self._keep(np.zeros(len(self), bool))
        self._stamp = None

    def _keep(self, keep: np.ndarray) -> None:
        self._x, self._P = self._x[keep], self._P[keep]
        self._id, self._hits = self._id[keep], self._hits[keep]
        self._frames = self._frames[keep]
        self._last_seen = self._last_seen[keep]
        self._payload = [p for p, k in zip(self._payload, keep) if k]

    def _sure(self, i: int) -> bool:
        """Track i has been detected in at least ``sure_hits`` (> 0) frames, and is
        confirmed."""
        return bool(0 < self.sure_hits <= self._hits[i] and self._hits[i] >= self.confirm_hits)

    def predict(self, stamp_s: float,
                motion: tuple[np.ndarray, np.ndarray] | None,
                motion_cov: np.ndarray | None = None,
                hold: Callable[[object, np.ndarray], bool] | None = None) -> None:
        """Carry the tracks to the frame at ``stamp_s`` (seconds).

        Args:
            stamp_s: the new frame's time, s. A time going backwards ends all tracks.
            motion: (R (3, 3), t (3,)) the left camera's motion from the previous frame
                to this one, ``X_prev = R X_curr + t`` (metres, left optical frames), or
                None when unknown: all tracks end, except the sure ones (``sure_hits``)
                that ``hold`` keeps.
            motion_cov: (3, 3) covariance of t, m² (default 0); with ``motion`` None,
                the uncertainty added to the held tracks.
            hold: ``hold(payload, foot) -> bool``, used when ``motion`` is None: True for
                a track that must not be forgotten because the motion is unknown (an
                obstacle walked up to, out of view below the image, where no frame can
                find it again). A sure track held stays where it is (the identity
                motion, ``P = P + Q + motion_cov``); ``update`` then ends it as usual
                (``unseen_coast_s`` after its last detection, or ground in its place).
        """
        dt = 0.0 if self._stamp is None else stamp_s - self._stamp
        self._stamp = stamp_s
        if len(self) == 0:
            return
        if motion is None or dt < 0:
            keep: np.ndarray = np.zeros(len(self), bool)
            if motion is None and dt >= 0 and hold is not None:
                keep = np.array([self._sure(i) and bool(hold(self._payload[i],
                                                             self._x[i].copy()))
                                 for i in range(len(self))], bool)
            if not keep.any():
                self.reset()
                self._stamp = stamp_s
                return
            self._keep(keep)
            # x = x ; P = P + Q (+ the unknown motion's uncertainty)
            Q = (self.process_noise_m ** 2) * dt * np.eye(3)
            if motion_cov is not None:
                Q = Q + np.asarray(motion_cov, float).reshape(3, 3)
            self._P = self._P + Q[None]
            return
        Rc = np.asarray(motion[0], float).reshape(3, 3)
        tc = np.asarray(motion[1], float).reshape(3)
        F = Rc.T
        u = -F @ tc
        # x = F x + u
        self._x = self._x @ F.T + u[None, :]
        # P = F P Fᵀ + Q
        Q = (self.process_noise_m ** 2) * dt * np.eye(3)
        if motion_cov is not None:
            Q = Q + F @ np.asarray(motion_cov, float).reshape(3, 3) @ F.T
        self._P = np.einsum('ij,njk,lk->nil', F, self._P, F) + Q[None]

    def update(self, feet: np.ndarray, feet_cov: np.ndarray, payloads: Sequence[object],
               is_free: Callable[[object, np.ndarray], bool] | None = None,
               same_object: Callable[[object, object], bool] | None = None,
               unseen: Callable[[object, np.ndarray], bool] | None = None
               ) -> list[TrackOutput]:
        """Associate this frame's detections with the (predicted) tracks and update.

        Call :meth:`predict` first, once per frame.

        Args:
            feet: (N, 3) float64 detected feet, metres, current left optical frame.
            feet_cov: (N, 3, 3) their covariances R, m².
            payloads: N objects kept with the track (e.g. the detection).
            is_free: ``is_free(payload, foot) -> bool`` for an undetected track: True when
                the frame shows its place free (or out of view), which ends it.
            same_object: ``same_object(track_payload, detection_payload) -> bool``: a
                detection that is not the track's (outside its gate: another point of
                the obstacle measured as its nearest, e.g. a far corner) but shows the
                same obstacle. It keeps the track seen (its coasting time and hit count
                go on as if detected) without moving it.
            unseen: ``unseen(payload, foot) -> bool`` for an undetected track: True when
                its place is out of the camera's view where no frame can show it or its
                absence (below the image). A sure track (``sure_hits``) is then reported
                for up to ``unseen_coast_s`` after its last detection, whatever its hit
                fraction, unless ``is_free`` sees ground in its place; a track not sure
                ends.
        Returns:
            The tracks reported this frame: every detection's (in detection order), then
            the coasted ones.
        """
        z = np.asarray(feet, float).reshape(-1, 3)
        Rz = np.asarray(feet_cov, float).reshape(-1, 3, 3)
        n, t = z.shape[0], len(self)
        if len(payloads) != n or Rz.shape[0] != n:
            raise ValueError(f'feet ({n}), feet_cov ({Rz.shape[0]}) and payloads '
                             f'({len(payloads)}) must be as many')
        stamp = 0.0 if self._stamp is None else self._stamp
        det_track = self._associate(z, Rz)
        self._correct(det_track, z, Rz, payloads, stamp)
        # Tracks not detected: coast or end.
        seen = np.zeros(t, bool)
        seen[det_track[det_track >= 0]] = True
        self._frames += 1
        keep = self._survivors(seen, payloads, stamp, is_free, same_object, unseen)
        # Births: detections left over.
        new = flat_nonzero(det_track < 0)
        ids = np.arange(self._next_id, self._next_id + new.size, dtype=np.int64)
        self._next_id += int(new.size)
        index_of = np.full(t + new.size, -1, np.int64)
        index_of[det_track[det_track >= 0]] = flat_nonzero(det_track >= 0)
        index_of[t:] = new
        self._x = np.concatenate([self._x, z[new]])
        self._P = np.concatenate([self._P, Rz[new]])
        self._id = np.concatenate([self._id, ids])
        self._hits = np.concatenate([self._hits, np.ones(new.size, np.int64)])
        self._frames = np.concatenate([self._frames, np.ones(new.size, np.int64)])
        self._last_seen = np.concatenate([self._last_seen, np.full(new.size, stamp)])
        self._payload.extend(payloads[j] for j in new.tolist())
        keep = np.concatenate([keep, np.ones(new.size, bool)])
        index_of = index_of[keep]
        self._keep(keep)
        out = [TrackOutput(track_id=int(self._id[i]), index=int(index_of[i]),
                           foot=self._x[i].copy(), foot_cov=self._P[i].copy(),
                           age_s=float(stamp - self._last_seen[i]), hits=int(self._hits[i]),
                           payload=self._payload[i]) for i in range(len(self))]
        out.sort(key=lambda o: (o.index < 0, o.index))
        return out

    def _associate(self, z: np.ndarray, Rz: np.ndarray) -> np.ndarray:
        """The track index of each detection (-1: none): nearest pairs first by
        Mahalanobis distance, within the gate, one detection per track."""
        n, t = z.shape[0], len(self)
        det_track = np.full(n, -1, np.int64)
        if not (n and t):
            return det_track
        # y = z - H x ; S = H P Hᵀ + R ; d² = yᵀ S⁻¹ y, all (track, detection) pairs
        y = z[None, :, :] - self._x[:, None, :]
        S = self._P[:, None] + Rz[None, :]
        d2 = np.einsum('tni,tni->tn', y, np.linalg.solve(S, y[..., None])[..., 0])
        order = np.argsort(d2, axis=None)
        used_t = np.zeros(t, bool)
        for flat in order:
            i, j = divmod(int(flat), n)
            if d2[i, j] > self.gate_chi2:
                break
            if used_t[i] or det_track[j] >= 0:
                continue
            used_t[i] = True
            det_track[j] = i
        return det_track

    def _correct(self, det_track: np.ndarray, z: np.ndarray, Rz: np.ndarray,
                 payloads: Sequence[object], stamp: float) -> None:
        """The Kalman update of the detected tracks with their detections."""
        ti = det_track[det_track >= 0]
        dj = flat_nonzero(det_track >= 0)
        if not ti.size:
            return
        P = self._P[ti]
        S = P + Rz[dj]
        # K = P Hᵀ S⁻¹ (P, S symmetric: K = (S⁻¹ P)ᵀ)
        K = np.swapaxes(np.linalg.solve(S, P), 1, 2)
        # x = x + K y
        self._x[ti] = self._x[ti] + np.einsum('nij,nj->ni', K, z[dj] - self._x[ti])
        # P = (I - K) P (I - K)ᵀ + K R Kᵀ
        IK = np.eye(3)[None] - K
        self._P[ti] = (np.einsum('nij,njk,nlk->nil', IK, P, IK)
                       + np.einsum('nij,njk,nlk->nil', K, Rz[dj], K))
        self._hits[ti] += 1
        self._last_seen[ti] = stamp
        for i, j in zip(ti.tolist(), dj.tolist()):
            self._payload[i] = payloads[j]

    def _survivors(self, seen: np.ndarray, payloads: Sequence[object], stamp: float,
                   is_free, same_object, unseen) -> np.ndarray:
        """Which tracks live on (the undetected ones coast or end; `update`'s rules)."""
        keep = np.ones(len(seen), bool)
        n = len(payloads)
        for i in flat_nonzero(~seen).tolist():
            if same_object is not None and any(same_object(self._payload[i], payloads[j])
                                               for j in range(n)):
                self._hits[i] += 1
                self._last_seen[i] = stamp
                continue
            sure = self._sure(i)
            age = stamp - self._last_seen[i]
            if unseen is not None and unseen(self._payload[i], self._x[i].copy()):
                # Out of view: no evidence either way. Only a sure track is remembered.
                alive = sure and age <= self.unseen_coast_s + 1e-9
            else:
                alive = (self._hits[i] >= self.confirm_hits
                         and (sure or self._hits[i] >= self.min_hit_fraction * self._frames[i])
                         and age <= self.coast_s + 1e-9)
            if alive and is_free is not None:
                alive = not is_free(self._payload[i], self._x[i].copy())
            keep[i] = alive
        return keep
