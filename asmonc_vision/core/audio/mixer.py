"""Mixing and ducking of cues and phrases on one time line, and WAV output (no ROS).

A ``Soundtrack`` is a stereo sample buffer whose sample 0 is time 0 of the caller's
time line (for a replay: the stamp of the bag's first stereo pair). Tones and phrases
are added at their onset times on two layers; ``duck(t)`` cuts whatever phrase is
sounding at t (a short fade, then silence to the phrase's end): an urgent cue cuts an
older phrase, and a new phrase cuts an older one. ``read`` gives the mix of both layers
(clipped to [-1, 1]) for a live output; ``trim`` drops what has been played.
"""
from __future__ import annotations

import wave
from pathlib import Path

import numpy as np


class Soundtrack:
    """Stereo float32 time line at ``rate`` Hz, tones and speech on separate layers."""

    def __init__(self, rate: int):
        self.rate = int(rate)
        self._base = 0                          # sample index of the buffers' first row
        self._tones: np.ndarray = np.zeros((0, 2), np.float32)
        self._speech: np.ndarray = np.zeros((0, 2), np.float32)
        #: (start, end) sample indices of the phrases placed (absolute)
        self._phrases: list[tuple[int, int]] = []
        #: (onset sample, kind) of every event placed, for inspection and timelines
        self.events: list[tuple[float, str]] = []

    # -- sizes
    @property
    def end(self) -> int:
        """One past the last sample holding sound (absolute index)."""
        return self._base + len(self._tones)

    def _grow(self, end: int) -> None:
        need = end - self._base - len(self._tones)
        if need > 0:
            extra = max(need, self.rate)        # grow by at least a second
            z = np.zeros((extra, 2), np.float32)
            self._tones = np.concatenate([self._tones, z])
            self._speech = np.concatenate([self._speech, z])

    def _index(self, t: float) -> int:
        return max(int(round(t * self.rate)), self._base)

    # -- placing sound
    def add_tone(self, t: float, samples: np.ndarray, label: str = 'tone') -> int:
        """Add a stereo cue (n, 2) with its onset at time t (s). Returns the onset sample."""
        i = self._index(t)
        self._grow(i + len(samples))
        j = i - self._base
        self._tones[j:j + len(samples)] += samples
        self.events.append((i / self.rate, label))
        return i

    def add_phrase(self, t: float, samples: np.ndarray, label: str = 'phrase',
                   fade: float = 0.01) -> int:
        """Add a phrase (mono (n,) or stereo (n, 2)) at time t (s), cutting any older
        phrase still sounding then. Returns the onset sample."""
        self.duck(t, fade)
        if samples.ndim == 1:
            samples = np.stack([samples, samples], axis=1)
        i = self._index(t)
        self._grow(i + len(samples))
        j = i - self._base
        self._speech[j:j + len(samples)] += samples.astype(np.float32)
        self._phrases.append((i, i + len(samples)))
        self.events.append((i / self.rate, label))
        return i

    def duck(self, t: float, fade: float = 0.01) -> bool:
        """Cut the phrases sounding at time t (s): a linear fade of ``fade`` s, then
        silence to their end. Returns whether a phrase was cut."""
        i = self._index(t)
        cut = False
        for start, end in self._phrases:
            if start <= i < end:
                a, b = i - self._base, end - self._base
                k = min(b - a, max(1, int(fade * self.rate)))
                self._speech[a:a + k] *= np.linspace(1.0, 0.0, k, dtype=np.float32)[:, None]
                self._speech[a + k:b] = 0.0
                cut = True
        self._phrases = [(s, min(e, i + max(1, int(fade * self.rate))) if s <= i < e else e)
                         for s, e in self._phrases]
        return cut

    # -- reading
    def read(self, start: int, n: int) -> np.ndarray:
        """The mix of samples [start, start + n) (absolute), zeros where none, (n, 2)."""
        out = np.zeros((n, 2), np.float32)
        a, b = max(start, self._base), min(start + n, self.end)
        if b > a:
            out[a - start:b - start] = (self._tones[a - self._base:b - self._base]
                                        + self._speech[a - self._base:b - self._base])
        return np.clip(out, -1.0, 1.0)

    def mix(self, duration: float | None = None) -> np.ndarray:
        """The whole time line from the first sample kept, (n, 2) float32 in [-1, 1];
        ``duration`` (s) pads with silence (or cuts) to that length from time 0."""
        n = (self.end - self._base if duration is None
             else int(round(duration * self.rate)) - self._base)
        return self.read(self._base, max(n, 0))

    def trim(self, before: int) -> None:
        """Forget the samples before absolute index ``before`` (already played)."""
        k = min(max(before - self._base, 0), len(self._tones))
        if k:
            self._tones = self._tones[k:]
            self._speech = self._speech[k:]
            self._base += k
            self._phrases = [(s, e) for s, e in self._phrases if e > self._base]


def write_wav(path: str | Path, samples: np.ndarray, rate: int) -> None:
    """Write stereo float samples (n, 2) in [-1, 1] as a 16-bit PCM WAV at ``rate`` Hz."""
    pcm = (np.clip(samples, -1.0, 1.0) * 32767.0).round().astype('<i2')
    with wave.open(str(path), 'wb') as w:
        w.setnchannels(2)
        w.setsampwidth(2)
        w.setframerate(int(rate))
        w.writeframes(pcm.tobytes())


def read_wav(path: str | Path) -> tuple[np.ndarray, int]:
    """A 16-bit PCM WAV as float32 (n, channels) in [-1, 1], and its rate (Hz)."""
    with wave.open(str(path), 'rb') as w:
        rate, ch = w.getframerate(), w.getnchannels()
        pcm = np.frombuffer(w.readframes(w.getnframes()), dtype='<i2')
    return (pcm.reshape(-1, ch).astype(np.float32) / 32768.0), rate
