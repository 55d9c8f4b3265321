"""The ground surface ahead carried through the camera's motion (DGPR for the profile).

Each pair's profile (`core.ground_surface`) is fitted to that pair's features alone, and
how far it reaches changes from pair to pair: a segment with too few features, or
features in too narrow a band, ends the known ground (``rule_support``), and on a
kerb-ramp walk a pair's known ground is often a metre or more shorter than the pair
before's. Beyond it the obstacle test's ground goes on at the last grade, and the top of
a ramp or a slope seen a moment ago stands above it. The paper carries its ground plane
through the wearer's motion with a Kalman filter (DGPR, Molton et al. 1998, section 3);
this carries the profile the same way.

The state is the profile's known knots in the previous pair's ground frame G (x ahead
along the ground, y left, heights above that pair's plane: `core.map_evidence`), each
with the variance of its height: ``(s_j, z_j)`` m, ``P_j`` m². Heights above the ground
do not change with the camera's rotation (the gait's pitch and roll are the planes'),
so only the ground frame's horizontal motion carries them, as it carries the evidence
map. Per pair:

* predict: each knot is moved by G's horizontal motion from the previous pair
  (`map_evidence.ground_motion` of the camera's motion and the two planes),
  ``(s_j, 0) <- Rot(-dyaw) ((s_j, 0) - (dx, dy))`` and ``z_j`` kept (F: the motion),
  ``P_j <- P_j + Q``, ``Q = q_pair^2 + (q_per_m * travel)^2`` (the ground carried is
  trusted less the farther the wearer went);
* re-level (`SurfaceTracker._relevelled`): both profiles start on their own plane at
  the first knot, and a plane that tilted between the pairs shows as a difference
  growing along the ground; its grade, fitted to the knots both know, corrects the
  carried heights (and raises their variances by its own); with no knot both know,
  nothing is carried into the pair;
* update, at each of the new profile's knots that its features support: the carried
  height interpolated there, ``x^-`` with ``P^-``, and the measured knot ``z`` with
  ``R = knot_sd^2`` (`ground_surface.knot_sd`), ``H = 1``:
  ``y = z - H x^-``, ``S = H P^- H^T + R``, ``K = P^- H^T S^-1``, ``x = x^- + K y``,
  ``P = (1 - K H) P^-``; an innovation beyond ``gate_sigmas`` (``y^2 > g^2 S``) takes
  the measurement alone (the ground is not what was carried: a knot that lagged a bend,
  a plane that moved);
* the knots the pair could not support are taken from the carried ones, while their
  standard deviation is at most ``max_carry_sd_m``, when the pair's profile ended for
  want of features (``rule_support``): the ground known a moment ago is known still.
  A segment refused for what its features show (a step, a bend, a scatter) is not
  overruled: the ground there is unknown.

A pair without a motion (unknown while the rig moves), or whose profile was refused
whole (``rule_anchor``), restarts the filter from the pair's own profile. Each knot is
its own scalar filter (their covariances are not kept), batched in numpy.

Frames: the left optical frame (REP 103), metres. No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .camera import MetricPlane
from .config import check_fields, param
from .ground_surface import GroundSurface, flattened, tail_grade
from .map_evidence import ground_motion


@dataclass(frozen=True)
class SurfaceTrackingConfig:
    """Settings of the ground surface carried through the motion
    (``GpodConfig.surface_tracking``; in ROS ``gpod.surface_tracking.*``)."""

    enabled: bool = param(
        True, "Carry the ground surface ahead through the camera's motion and fuse it "
              "with each pair's profile (a Kalman filter per knot); needs the camera's "
              "motion (the map's), else each pair's profile alone")
    q_pair_m: float = param(
        0.005, "Process noise of a carried knot's height per pair, metres (Q's part that "
               "does not depend on the motion)", range=(0.0, 1.0))
    q_per_m: float = param(
        0.02, "Process noise of a carried knot's height per metre the camera moved, "
              "metres (Q's part from the motion)", range=(0.0, 10.0))
    gate_sigmas: float = param(
        3.0, "A measured knot further from the carried one than this many standard "
             "deviations of their difference replaces it", range=(0.5, 100.0))
    max_carry_sd_m: float = param(
        0.03, "A carried knot extends the pair's known ground while its standard "
              "deviation is at most this, metres", range=(0.0, 1.0))
    min_gap_m: float = param(
        0.25, "A carried knot extends the pair's known ground from this far beyond its "
              "last known knot on, metres (no segment shorter)", range=(0.01, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)


class SurfaceTracker:
    """The profile's knots carried from pair to pair (see the module doc)."""

    def __init__(self, config: SurfaceTrackingConfig | None = None) -> None:
        self.config = config or SurfaceTrackingConfig()
        #: the known knots (K, 2) (s, z) m in the previous pair's ground frame, the
        #: variances of their heights (K,) m², and that pair's plane; None: nothing
        self._state: tuple[np.ndarray, np.ndarray, MetricPlane] | None = None

    def reset(self) -> None:
        """Forget the carried surface."""
        self._state = None

    def update(self, surface: GroundSurface, motion: tuple | None,
               min_bend_m: float) -> GroundSurface:
        """Fuse a pair's profile with the one carried from the pair before.

        Args:
            surface: the pair's profile as fitted (not flattened; with ``knots_sd``).
            motion: (R (3, 3), t (3,), ...) the camera's motion from the previous pair,
                ``X_prev = R X_curr + t`` (metres, left optical frames), or None
                (unknown: the filter restarts from this pair).
            min_bend_m: the fused profile within this of the plane is the plane itself
                (`ground_surface.flattened`), metres.
        Returns:
            The fused surface (the pair's own when nothing is carried), flattened.
        """
        c = self.config
        ks, kz = surface.knots_s, surface.knots_z.copy()
        sd = (surface.knots_sd if surface.knots_sd is not None
              else np.full(ks.size, np.nan))
        known = (ks <= surface.known_until_m + 1e-9) & np.isfinite(sd)
        known[0] = True
        R_meas = np.where(known, sd * sd, np.nan)
        R_meas[0] = 0.0                               # the first knot: the plane
        P_out = R_meas.copy()
        ext_s: np.ndarray = np.zeros(0)
        ext_z: np.ndarray = np.zeros(0)
        ext_P: np.ndarray = np.zeros(0)
        carried = (self._predict(self._state, surface, motion)
                   if motion is not None and self._state is not None else None)
        if carried is not None:
            carried = self._relevelled(carried, ks, kz, R_meas, known)
        if carried is not None:
            cs, ch, cP = carried
            # H = 1: the carried height interpolated at each measured knot
            inside = (ks >= cs[0] - 1e-9) & (ks <= cs[-1] + 1e-9)
            x_pred = np.interp(ks, cs, ch)
            P_pred = np.interp(ks, cs, cP)
            both = known & inside
            both[0] = False
            y = kz - x_pred                                   # y = z - H x^-
            S = P_pred + R_meas                               # S = H P^- H^T + R
            K = np.where(both, P_pred / np.maximum(S, 1e-12), 0.0)   # K = P^- H^T S^-1
            fuse = both & (y * y <= c.gate_sigmas ** 2 * S)
            kz = np.where(fuse, x_pred + K * y, kz)           # x = x^- + K y
            P_out = np.where(fuse, (1.0 - K) * P_pred, P_out)  # P = (1 - K H) P^-
            # beyond the pair's known ground, when it ended for want of features: the
            # carried knots at their own places, while they are sure enough
            if surface.checks and surface.checks[-1].refused_by == 'rule_support':
                last = float(ks[known][-1])
                beyond = cs >= last + c.min_gap_m
                sure = cP[beyond] <= c.max_carry_sd_m ** 2
                n = int(np.argmin(sure)) if not sure.all() else int(sure.size)
                ext_s, ext_z, ext_P = cs[beyond][:n], ch[beyond][:n], cP[beyond][:n]
        m_s, m_z, m_P = ks[known], kz[known], P_out[known]
        known_until = float(ext_s[-1]) if ext_s.size else float(m_s[-1])
        known_s = np.concatenate([m_s, ext_s])
        known_z = np.concatenate([m_z, ext_z])
        known_P = np.concatenate([m_P, ext_P])
        self._store(surface, known_s, known_z, known_P)
        rest = ks[ks > known_until + 1e-9]
        new_s = np.concatenate([known_s, rest])
        new_z = np.concatenate([known_z, np.zeros(rest.size)])
        new_P = np.concatenate([known_P, np.full(rest.size, np.nan)])
        fused = replace(surface, knots_s=new_s, knots_z=new_z, known_until_m=known_until,
                        knots_sd=np.sqrt(new_P),
                        tail_grade=tail_grade(new_s, new_z, known_until))
        return flattened(fused, min_bend_m)

    @staticmethod
    def _relevelled(carried: tuple, ks: np.ndarray, kz: np.ndarray, R_meas: np.ndarray,
                    known: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The carried knots (s, z, P) re-read against this pair's plane: both profiles
        start on their own plane at the first knot s0, and a plane that tilted between
        the pairs (its refit's noise, the wearer's sway) shows as a difference growing
        along the ground, ``z_meas - z_carried = b (s - s0)`` (a few cm at 8 m for a
        fraction of a degree). b is fitted by weighted least squares to the knots both
        know, ``b = sum w u d / sum w u^2``, ``var b = 1 / sum w u^2`` (u = s - s0,
        d the difference, w = 1 / (P + R)), and the carried heights corrected by it,
        their variances raised by ``u^2 var b``. With no knot both know, None: the
        carried ground cannot be placed on this pair's plane."""
        cs, ch, cP = carried
        s0 = float(ks[0])
        inside = known & (ks >= cs[0] - 1e-9) & (ks <= cs[-1] + 1e-9)
        inside[0] = False
        if not inside.any():
            return None
        u = ks[inside] - s0
        d = kz[inside] - np.interp(ks[inside], cs, ch)
        w = 1.0 / np.maximum(np.interp(ks[inside], cs, cP) + R_meas[inside], 1e-12)
        suu = float(np.sum(w * u * u))
        b = float(np.sum(w * u * d)) / suu
        uc = cs - s0
        return cs, ch + b * uc, cP + uc * uc / suu

    def _predict(self, state: tuple, surface: GroundSurface, motion: tuple
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The carried knots moved into this pair's ground frame by its horizontal
        motion: (s, z, P) (K,) each, by s, m and m²; None with fewer than two."""
        c = self.config
        x, P, plane = state
        dx, dy, dyaw = ground_motion(plane, surface.plane, motion[0], motion[1])
        cy, sy = math.cos(dyaw), math.sin(dyaw)
        # (s, 0) in G_prev -> G_curr: Rot(-dyaw) ((s, 0) - (dx, dy)), its x; z kept (F)
        s = cy * (x[:, 0] - dx) - sy * dy
        h = x[:, 1]
        P = P + c.q_pair_m ** 2 + (c.q_per_m * math.hypot(dx, dy)) ** 2   # P + Q
        order = np.argsort(s)
        if s.size < 2:
            return None
        return s[order], h[order], P[order]

    def _store(self, surface: GroundSurface, ks: np.ndarray, kz: np.ndarray,
               P: np.ndarray) -> None:
        """Keep the known knots (s, z) in this pair's ground frame."""
        if ks.size < 2:
            self.reset()
            return
        self._state = (np.stack([ks, kz], axis=1).astype(float), P.astype(float),
                       surface.plane)
