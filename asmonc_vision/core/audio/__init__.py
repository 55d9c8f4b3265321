"""What the wearer hears: spatial tones, a few spoken phrases, mixing (no ROS here).

``render``: the cues (tones under 100 ms placed by bearing with ITD/ILD) and
``AudioConfig``; ``planner``: when to sound which cue and say which phrase;
``mixer``: the time line (mixing, ducking, WAV); ``speech``: offline espeak-ng.
``AudioRenderer`` ties them: inputs in, samples on a ``Soundtrack`` out.
"""
from __future__ import annotations

from asmonc_vision.core.audio.mixer import Soundtrack, read_wav, write_wav
from asmonc_vision.core.audio.planner import PHRASES, CuePlanner, Event
from asmonc_vision.core.audio.render import (URGENT, AudioConfig, CueKind, render_cue,
                                             repeat_interval)
from asmonc_vision.core.audio.speech import SpeechEngine


class AudioRenderer:
    """A ``CuePlanner`` whose events are rendered onto a ``Soundtrack``.

    Args:
        cfg: the settings.
        speech: a ``SpeechEngine`` (None: built from cfg; pass one with engine='none' for
            tones only). Its phrases (``PHRASES``) are pre-rendered here.
    """

    def __init__(self, cfg: AudioConfig | None = None, speech: SpeechEngine | None = None):
        self.cfg = cfg or AudioConfig()
        self.planner = CuePlanner(self.cfg)
        self.track = Soundtrack(self.cfg.sample_rate)
        self.speech = speech if speech is not None else SpeechEngine(
            self.cfg.sample_rate, self.cfg.language, self.cfg.speech_rate_wpm,
            engine='none' if self.cfg.verbosity == 'tones' else 'auto')
        if self.speech.available and self.cfg.verbosity == 'normal':
            self.speech.prerender(PHRASES)
        self._cues: dict = {}
        #: (t, kind name or 'phrase: ...') of every event placed
        self.log: list[tuple[float, str]] = []

    def cue_samples(self, kind: CueKind, bearing: float):
        """The cue's stereo samples (n, 2) at a bearing (radians, positive left), cached
        per milliradian."""
        key = (kind, round(bearing, 3))
        if key not in self._cues:
            if len(self._cues) >= 512:
                self._cues = {}
            self._cues[key] = render_cue(kind, bearing, self.cfg)
        return self._cues[key]

    def place(self, events: list[Event]) -> list[Event]:
        """Render events onto the time line; returns them."""
        for e in events:
            if e.kind is not None:
                samples = self.cue_samples(e.kind, e.bearing)
                if e.kind in URGENT:
                    self.track.duck(e.t, self.cfg.duck_fade)
                self.track.add_tone(e.t, samples, e.kind.value)
                self.log.append((e.t, e.kind.value))
            elif e.phrase:
                samples = self.speech.render(e.phrase)
                if samples is not None:
                    self.track.add_phrase(e.t, samples * self.cfg.speech_volume,
                                          'phrase', self.cfg.duck_fade)
                self.log.append((e.t, f'phrase: {e.phrase}'))
        return events

    def alarm(self, t, level, text='', bearing=0.0, range_m=0.0, repeat=False):
        return self.place(self.planner.alarm(t, level, text, bearing, range_m, repeat))

    def contact(self, t, level, bearing, range_m, ttc, is_drop, moving):
        self.planner.contact(t, level, bearing, range_m, ttc, is_drop, moving)

    def degraded(self, t, on):
        return self.place(self.planner.degraded(t, on))

    def advance(self, t):
        return self.place(self.planner.advance(t))


__all__ = ['AudioConfig', 'AudioRenderer', 'CueKind', 'CuePlanner', 'Event', 'PHRASES',
           'SpeechEngine', 'Soundtrack', 'read_wav', 'render_cue', 'repeat_interval',
           'write_wav']
