"""Walking motion of the rig in 6 DoF (Molton et al. 1998, Section 5; Lee's gait data).

The walker follows a plan of ``Leg``s (speed changes with smooth ramps, stops, starts,
turns as smooth heading ramps). On top of the path, the rig oscillates:

* pitch, vertical bob and forward surge at the step frequency (~1.8-2 Hz),
* roll, yaw and lateral sway at half of it (the stride frequency),

each a sine of its own amplitude and phase (small second harmonic on pitch and bob, a
slowly varying yaw amplitude as in the paper's Fig. 13), scaled by the walking speed so
the motion dies out when the walker stops. A standing walker keeps a small postural
sway. Amplitudes, frequency and phases vary per walker (drawn from the seed). Walking
uphill leans the trunk (and the rig) slightly forward.

Angles in the settings are degrees; all outputs are radians and metres, world frame
(z up); the rig pose is that of the body frame ``inclinometer_link`` (x forward, y
left, z up, origin at the baseline midpoint; nominal pitch = the camera tilt).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from asmonc_vision.core.config import check_fields, param
from asmonc_vision.sim.geometry import RigPose
from asmonc_vision.sim.rig import RigSettings


@dataclass(frozen=True)
class GaitSettings:
    """Gait model of the walker. Amplitudes are at the nominal speed (0-peak)."""

    nominal_speed: float = param(1.2, 'walking speed at which the amplitudes below '
                                 'apply, m/s', range=(0.2, 3.0))
    step_freq: float = param(1.9, 'step frequency at the nominal speed, Hz (pitch, bob, '
                             'surge; roll, yaw, sway at half of it)', range=(0.5, 4.0))
    cadence_exponent: float = param(0.3, 'step frequency ~ (speed / nominal_speed) ^ this',
                                    range=(0.0, 1.0))
    pitch_amp_deg: float = param(2.0, 'pitch amplitude, degrees', range=(0.0, 10.0))
    roll_amp_deg: float = param(2.0, 'roll amplitude, degrees', range=(0.0, 10.0))
    yaw_amp_deg: float = param(2.5, 'yaw amplitude, degrees', range=(0.0, 10.0))
    bob_amp: float = param(0.03, 'vertical bob amplitude, metres', range=(0.0, 0.3))
    sway_amp: float = param(0.03, 'lateral sway amplitude, metres', range=(0.0, 0.3))
    surge_amp: float = param(0.015, 'forward surge amplitude, metres', range=(0.0, 0.3))
    harmonic: float = param(0.12, 'second-harmonic share of pitch and bob',
                            range=(0.0, 0.5))
    yaw_modulation: float = param(0.3, 'relative slow variation of the yaw amplitude',
                                  range=(0.0, 0.9))
    walker_variation: float = param(0.2, 'per-walker relative spread (+/-) of the '
                                    'amplitudes, drawn from the seed', range=(0.0, 0.6))
    freq_variation: float = param(0.04, 'per-walker relative spread (+/-) of the step '
                                  'frequency', range=(0.0, 0.3))
    stand_sway_deg: float = param(0.15, 'postural sway (always present), degrees in '
                                  'roll and pitch', range=(0.0, 3.0))
    stand_sway: float = param(0.003, 'postural sway, metres', range=(0.0, 0.05))
    slope_lean: float = param(0.4, 'extra forward pitch per unit of uphill slope angle',
                              range=(0.0, 1.0))

    def __post_init__(self) -> None:
        check_fields(self)

    @classmethod
    def extreme(cls) -> 'GaitSettings':
        """The paper's extreme motion (~5 degrees, 20 cm translations, Section 3.3)."""
        return cls(pitch_amp_deg=5.0, roll_amp_deg=5.0, yaw_amp_deg=5.0, bob_amp=0.1,
                   sway_amp=0.1, surge_amp=0.05)


@dataclass(frozen=True)
class Leg:
    """One part of a walk plan.

    Attributes:
        duration: seconds (> 0).
        speed: target walking speed, m/s (0 = stand), reached ``ramp`` s into the leg.
        turn_deg: heading change over the leg, degrees (positive = left), smooth.
        ramp: seconds for the speed change (smooth acceleration / deceleration).
    """

    duration: float
    speed: float
    turn_deg: float = 0.0
    ramp: float = 1.0

    def __post_init__(self) -> None:
        if not (self.duration > 0 and self.speed >= 0 and self.ramp > 0):
            raise ValueError(f'Leg needs duration > 0, speed >= 0, ramp > 0: {self}')


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


class Trajectory:
    """The rig's pose over time for a walk plan. Deterministic for a seed.

    Args:
        legs: the plan; after its end the walker keeps the final speed and heading.
        rig: camera height and nominal pitch.
        world: for the ground height and slope (anything with ``ground_height(x, y)``
            and ``ground_gradient(x, y)`` or ``ground.gradient``); None = flat ground at
            z = 0.
        gait: gait settings.
        start: (x, y) world position at t = 0, metres.
        heading_deg: initial walking direction, degrees from world x (left positive).
        start_speed: speed at t = 0, m/s.
        rng: seed or numpy Generator for the per-walker variation.
        dt: integration step, seconds.
    """

    def __init__(self, legs: Sequence[Leg], rig: RigSettings, world=None,
                 gait: GaitSettings | None = None, start: tuple[float, float] = (0.0, 0.0),
                 heading_deg: float = 0.0, start_speed: float = 0.0,
                 rng: int | np.random.Generator | None = 0, dt: float = 0.002) -> None:
        self.legs = tuple(legs)
        self.rig = rig
        self.world = world
        self.gait = gait if gait is not None else GaitSettings()
        rng = np.random.default_rng(rng)
        g = self.gait
        var = g.walker_variation
        self.step_freq = g.step_freq * (1.0 + rng.uniform(-g.freq_variation, g.freq_variation))
        names = ('pitch', 'roll', 'yaw', 'bob', 'sway', 'surge')
        base = (math.radians(g.pitch_amp_deg), math.radians(g.roll_amp_deg),
                math.radians(g.yaw_amp_deg), g.bob_amp, g.sway_amp, g.surge_amp)
        self.amplitude = {n: a * (1.0 + rng.uniform(-var, var)) for n, a in zip(names, base)}
        self.phase = {n: rng.uniform(0, 2 * np.pi) for n in names + ('pitch2', 'bob2')}
        self._yaw_mod = (rng.uniform(0.1, 0.3), rng.uniform(0, 2 * np.pi))
        # postural sway: three incommensurate low frequencies per channel (roll, pitch, x, y)
        self._sway = rng.uniform(0.08, 0.5, (4, 3)), rng.uniform(0, 2 * np.pi, (4, 3))
        self.duration = float(sum(leg.duration for leg in self.legs))
        n = int(math.ceil(max(self.duration, dt) / dt)) + 1
        t = np.arange(n) * dt
        speed = np.empty(n)
        heading = np.full(n, math.radians(heading_deg))
        t0, v_prev, h_prev = 0.0, float(start_speed), math.radians(heading_deg)
        for leg in self.legs:
            m = t >= t0 - 1e-12
            tau = t[m] - t0
            speed[m] = v_prev + (leg.speed - v_prev) * _smoothstep(tau / leg.ramp)
            turn = math.radians(leg.turn_deg)
            heading[m] = h_prev + turn * _smoothstep(tau / leg.duration)
            t0 += leg.duration
            v_prev, h_prev = leg.speed, h_prev + turn
        if not self.legs:
            speed[:] = start_speed
        # path by trapezoidal integration
        vx, vy = speed * np.cos(heading), speed * np.sin(heading)
        x = start[0] + np.concatenate([[0.0], np.cumsum((vx[1:] + vx[:-1]) * dt / 2)])
        y = start[1] + np.concatenate([[0.0], np.cumsum((vy[1:] + vy[:-1]) * dt / 2)])
        f = self.step_freq * np.power(np.maximum(speed, 1e-3) / g.nominal_speed,
                                      g.cadence_exponent)
        phase = 2 * np.pi * np.concatenate([[0.0], np.cumsum((f[1:] + f[:-1]) * dt / 2)])
        self._t, self._speed, self._heading = t, speed, heading
        self._x, self._y, self._gait_phase = x, y, phase

    # ------------------------------------------------------------------ queries

    def _interp(self, t, arr):
        return np.interp(np.asarray(t, float), self._t, arr)

    def speed(self, t) -> np.ndarray:
        """Walking speed (m/s) at times t (s, scalar or (N,))."""
        return self._interp(t, self._speed)

    def heading(self, t) -> np.ndarray:
        """Walking direction (rad, world, unwrapped) at times t (s)."""
        return self._interp(t, self._heading)

    def path(self, t) -> np.ndarray:
        """(*, 2) walking path position (no gait motion), world metres, at times t (s)."""
        return np.stack([self._interp(t, self._x), self._interp(t, self._y)], axis=-1)

    def envelope(self, t) -> np.ndarray:
        """Gait amplitude factor (speed / nominal speed, clipped to [0, 1.5]) at t (s)."""
        return np.clip(self.speed(t) / self.gait.nominal_speed, 0.0, 1.5)

    def states(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Rig poses at times t.

        Args:
            t: (N,) seconds (clamped to the plan: beyond its end the walker keeps the
               final state of the integration grid).
        Returns:
            (positions (N, 3) world metres of the baseline midpoint, rpy (N, 3) radians,
            REP 103 roll, pitch, yaw of inclinometer_link; yaw is unwrapped).
        """
        t = np.atleast_1d(np.asarray(t, float))
        g, amp, ph = self.gait, self.amplitude, self.phase
        env = self.envelope(t)
        phi = self._interp(t, self._gait_phase)
        psi = self.heading(t)
        xy = self.path(t)
        half = phi / 2.0
        pitch_o = amp['pitch'] * (np.sin(phi + ph['pitch'])
                                  + g.harmonic * np.sin(2 * phi + ph['pitch2']))
        bob = amp['bob'] * (np.sin(phi + ph['bob']) + g.harmonic * np.sin(2 * phi + ph['bob2']))
        surge = amp['surge'] * np.sin(phi + ph['surge'])
        roll_o = amp['roll'] * np.sin(half + ph['roll'])
        fm, pm = self._yaw_mod
        yaw_o = amp['yaw'] * (1.0 + g.yaw_modulation * np.sin(2 * np.pi * fm * t + pm)) * \
            np.sin(half + ph['yaw'])
        sway = amp['sway'] * np.sin(half + ph['sway'])
        freqs, phases = self._sway
        post = [np.sum(np.sin(2 * np.pi * freqs[k][None, :] * t[:, None] + phases[k][None, :]),
                       axis=1) / 2.0 for k in range(4)]
        sway_ang = math.radians(g.stand_sway_deg)
        c, s = np.cos(psi), np.sin(psi)
        fwd = env * surge + g.stand_sway * post[2]
        lat = env * sway + g.stand_sway * post[3]
        px = xy[:, 0] + c * fwd - s * lat
        py = xy[:, 1] + s * fwd + c * lat
        if self.world is not None:
            ground = np.asarray(self.world.ground_height(px, py), float)
            if hasattr(self.world, 'ground_gradient'):   # the local slope
                gx, gy = self.world.ground_gradient(px, py)
            else:
                gx, gy = (float(v) for v in self.world.ground.gradient)
        else:
            ground = np.zeros_like(px)
            gx = gy = 0.0
        uphill = np.arctan(gx * c + gy * s)        # slope angle along the heading
        pz = ground + self.rig.camera_height + env * bob
        roll = math.radians(self.rig.camera_roll_deg) + env * roll_o + sway_ang * post[0]
        pitch = self.rig.pitch + g.slope_lean * uphill + env * pitch_o + sway_ang * post[1]
        yaw = psi + env * yaw_o
        return np.column_stack([px, py, pz]), np.column_stack([roll, pitch, yaw])

    def pose(self, t: float) -> RigPose:
        """The rig pose at time t (s)."""
        p, rpy = self.states(np.array([t]))
        return RigPose(position=p[0], rpy=rpy[0])
