"""Short spatial tones: the cues the wearer hears (no ROS here).

Every cue is under 100 ms, so that it is heard and understood before a phrase could be.
Four kinds, each with its own sound, so that they are told apart without words:

* ``OBSTACLE``: a 1 kHz tone (with a weak second harmonic), 60 ms.
* ``DROP`` (a kerb or step down): a falling sweep 1.3 kHz -> 450 Hz, 85 ms -- its
  spectrum sits lower and spreads wider than the obstacle's, and it "goes down".
* ``STOP``: two 30 ms bursts of a bright 2 kHz tone with odd harmonics, 15 ms apart.
* ``FAULT``: a rough low dyad (330 Hz + 415 Hz, a dissonant major third), 90 ms,
  always in the middle of the head.
* ``DEGRADED`` (a softer cue: the inclinometer went silent): 600 Hz, 50 ms, quiet.

Direction is carried by where the sound comes from: interaural time and level
differences (ITD, ILD) of a spherical head. For a bearing theta (radians, positive left,
REP 103; clipped to +-90 deg) the far ear hears the tone later by Woodworth's
ITD = (a / c) (|theta| + sin|theta|) (a the head's radius, c the speed of sound; 0.66 ms
at 90 deg) and quieter by ILD = ``max_ild_db`` sin|theta| dB. Output samples are
float32 in [-1, 1], shape (n, 2), columns (left, right).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.config import check_fields, param

#: speed of sound, m/s
SPEED_OF_SOUND = 343.0


class CueKind(enum.Enum):
    OBSTACLE = 'obstacle'
    DROP = 'drop'
    STOP = 'stop'
    FAULT = 'fault'
    DEGRADED = 'degraded'


#: cues that cut a phrase being spoken (ducking)
URGENT = frozenset({CueKind.STOP, CueKind.FAULT, CueKind.DROP})
#: cues placed by bearing (the others sound in the middle of the head)
SPATIAL = frozenset({CueKind.OBSTACLE, CueKind.DROP, CueKind.STOP})


@dataclass(frozen=True)
class AudioConfig:
    """Settings of the sound the wearer hears (ROS parameters of the audio node)."""

    sample_rate: int = param(16000, 'output sample rate, Hz', range=(16000, 48000))
    volume: float = param(0.5, 'peak level of a tone, 0..1 of full scale', range=(0.0, 1.0))
    speech_volume: float = param(0.6, 'peak level of speech, 0..1 of full scale',
                                 range=(0.0, 1.0))
    max_ild_db: float = param(
        12.0, 'level difference between the ears for a sound at 90 deg, dB',
        range=(0.0, 40.0))
    head_radius: float = param(0.0875, 'radius of the spherical head of the ITD, metres',
                               range=(0.05, 0.15))
    interval_per_second: float = param(
        0.25, 'a cue repeats every time_to_contact * this seconds (rate rising as the '
        'time to contact falls)', range=(0.01, 2.0))
    min_interval: float = param(0.15, 'fastest repetition of a cue, seconds',
                                range=(0.1, 5.0))
    max_interval: float = param(1.2, 'slowest repetition of a cue, seconds',
                                range=(0.1, 10.0))
    standing_speed: float = param(
        1.0, 'for a standing wearer the repetition follows range / this speed, m/s',
        range=(0.1, 5.0))
    standing_tones_for: float = param(
        2.0, 'a standing wearer hears the repeating tones this long after an alarm, '
        'then silence until the next alarm, seconds', range=(0.0, 60.0))
    fault_interval: float = param(1.0, 'the FAULT cue repeats this often, seconds',
                                  range=(0.2, 10.0))
    degraded_interval: float = param(
        5.0, 'the degraded-mode cue repeats this often while it lasts, seconds',
        range=(0.5, 60.0))
    verbosity: str = param(
        'normal', "speech: 'tones' (none), 'normal' (a few category phrases: 'stop', "
        "'step down', 'obstacle left', 'cannot see'), 'verbose' (the alarm's whole "
        "sentence)", choices=('tones', 'normal', 'verbose'))
    language: str = param('en', "speech language (an espeak-ng voice: 'en', 'en-gb', 'de', "
                          "'fr', ...)")
    speech_rate_wpm: int = param(190, 'speaking rate, words per minute', range=(80, 450))
    speech_min_interval: float = param(
        2.0, 'at most one phrase starts per this many seconds; tones carry the rest',
        range=(0.0, 30.0))
    duck_fade: float = param(0.01, 'a phrase cut by an urgent cue fades out in this long, '
                             'seconds', range=(0.001, 0.2))

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.min_interval <= self.max_interval:
            raise ValueError(f'AudioConfig.min_interval = {self.min_interval} must not exceed '
                             f'max_interval = {self.max_interval} (seconds)')


def _envelope(n: int, rate: int, edge: float = 0.005) -> np.ndarray:
    """Raised-cosine attack and release of ``edge`` seconds (no clicks)."""
    e = np.ones(n)
    k = max(1, min(n // 2, int(edge * rate)))
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(k) / k)
    e[:k] = ramp
    e[n - k:] = ramp[::-1]
    return e


def _tone(freqs_amps, duration: float, rate: int) -> np.ndarray:
    t = np.arange(int(round(duration * rate))) / rate
    x = sum(a * np.sin(2 * np.pi * f * t) for f, a in freqs_amps)
    return x * _envelope(len(t), rate)


def mono_cue(kind: CueKind, rate: int) -> np.ndarray:
    """The cue's sound, mono float64 peaking at 1, at ``rate`` Hz (under 100 ms)."""
    if kind == CueKind.OBSTACLE:
        x = _tone([(1000.0, 1.0), (2000.0, 0.25)], 0.060, rate)
    elif kind == CueKind.DROP:
        dur = 0.085
        t = np.arange(int(round(dur * rate))) / rate
        f0, f1 = 1300.0, 450.0                     # exponential sweep down
        k = math.log(f1 / f0) / dur
        x = np.sin(2 * np.pi * f0 * (np.exp(k * t) - 1.0) / k) * _envelope(len(t), rate)
    elif kind == CueKind.STOP:
        burst = _tone([(2000.0, 1.0), (6000.0, 0.3)], 0.030, rate)
        x = np.concatenate([burst, np.zeros(int(0.015 * rate)), burst])
    elif kind == CueKind.FAULT:
        x = _tone([(330.0, 1.0), (415.0, 1.0), (660.0, 0.3)], 0.090, rate)
        t = np.arange(len(x)) / rate
        x = x * (0.75 + 0.25 * np.sin(2 * np.pi * 40.0 * t))   # roughness
    elif kind == CueKind.DEGRADED:
        x = 0.4 * _tone([(600.0, 1.0)], 0.050, rate)
        return x
    else:
        raise ValueError(f'unknown cue kind {kind!r}')
    return x / np.max(np.abs(x))


def interaural(bearing: float, cfg: AudioConfig) -> tuple[float, float, float, float]:
    """(itd_s, ild_db, gain_left, gain_right) for a source at ``bearing`` (radians,
    positive left; clipped to +-pi/2). ITD and ILD are >= 0, the far ear's lag and loss."""
    th = min(abs(float(bearing)), math.pi / 2)
    itd = cfg.head_radius / SPEED_OF_SOUND * (th + math.sin(th))
    ild = cfg.max_ild_db * math.sin(th)
    far = 10.0 ** (-ild / 20.0)
    left_near = bearing >= 0
    return itd, ild, (1.0 if left_near else far), (far if left_near else 1.0)


def spatialise(mono: np.ndarray, bearing: float, cfg: AudioConfig) -> np.ndarray:
    """A mono signal placed at ``bearing`` (radians, positive left) by ITD and ILD.

    Returns float32 (n + max ITD in samples, 2), (left, right); the far ear's copy is
    delayed by the ITD (fractional, by linear interpolation) and attenuated by the ILD.
    """
    itd, _, gl, gr = interaural(bearing, cfg)
    rate = cfg.sample_rate
    pad = int(math.ceil(cfg.head_radius / SPEED_OF_SOUND * (math.pi / 2 + 1) * rate)) + 1
    n = len(mono)
    src = np.concatenate([mono, np.zeros(pad)])
    idx = np.arange(n + pad, dtype=np.float64)
    delayed = np.interp(idx - itd * rate, idx, src, left=0.0, right=0.0)
    near, far = (src, delayed)
    if bearing >= 0:
        out = np.stack([near * gl, far * gr], axis=1)
    else:
        out = np.stack([far * gl, near * gr], axis=1)
    return out.astype(np.float32)


def render_cue(kind: CueKind, bearing: float, cfg: AudioConfig) -> np.ndarray:
    """One cue as stereo float32 (n, 2) at ``cfg.sample_rate``: spatial cues placed at
    ``bearing`` (radians, positive left), FAULT and DEGRADED in the middle; peak
    ``cfg.volume``."""
    mono = mono_cue(kind, cfg.sample_rate) * cfg.volume
    return spatialise(mono, bearing if kind in SPATIAL else 0.0, cfg)


def repeat_interval(time_to_contact: float, range_m: float, cfg: AudioConfig) -> float:
    """Seconds between repetitions of an obstacle's cue: ``interval_per_second`` times
    the time to contact (for a standing wearer, inf, range / ``standing_speed``),
    within [min_interval, max_interval]. Shorter as contact nears."""
    ttc = time_to_contact if math.isfinite(time_to_contact) else range_m / cfg.standing_speed
    if not math.isfinite(ttc):
        return cfg.max_interval
    return float(min(max(ttc * cfg.interval_per_second, cfg.min_interval), cfg.max_interval))
