"""When to sound which cue, and which few words to say (no ROS here).

``CuePlanner`` turns the alarm node's outputs into timed events on the caller's time
line (seconds; for a replay, bag time from its first stereo pair):

* ``alarm``: each ``/alarms`` message (level, text, bearing, range, repeat flag).
* ``contact``: the most urgent obstacle of each obstacle list (``/alarms/contact``): its
  bearing from the walking direction, range, time to contact and whether it is a drop;
  it steers the cue that is already sounding (where it comes from, how fast it repeats).
* ``degraded``: the inclinometer went silent (on) or came back (off).
* ``advance(t)``: the tones due up to t.

The rules, all from the field's experience with audio aids: silence means the path is
clear (CLEAR makes no sound); an obstacle level sounds its cue at once and then repeats
it every ``repeat_interval`` (shorter as the time to contact falls); a STOP level uses the
STOP cue, a drop its own cue; FAULT repeats the FAULT cue every ``fault_interval`` for as
long as it lasts; a standing wearer hears the repetition only ``standing_tones_for``
seconds after an alarm. Speech: a short category phrase on a new alarm (verbosity
'normal'), the alarm's sentence ('verbose') or none ('tones'); at most one phrase starts
per ``speech_min_interval``; a phrase held back by that limit is said when the limit
allows if its alarm still holds, else dropped (the tones have carried it). A phrase
starts just after its alarm's first tone.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from asmonc_vision.core.audio.render import AudioConfig, CueKind, mono_cue, repeat_interval

CLEAR, CAUTION, WARNING, STOP, FAULT = range(5)

#: the category phrases said with verbosity 'normal' (pre-rendered at start-up)
PHRASES = ('stop', 'step down', 'obstacle ahead', 'obstacle left', 'obstacle right',
           'cannot see', 'starting, hold still', 'ready', 'tilt sensor lost')
#: |bearing| beyond this is "left"/"right" in a phrase (degrees)
PHRASE_SIDE_DEG = 15.0


@dataclass(frozen=True)
class Event:
    """A sound to place at time t (s): a cue (kind, bearing in radians, positive left) or
    a phrase (its text)."""

    t: float
    kind: CueKind | None = None
    bearing: float = 0.0
    phrase: str | None = None


def category_phrase(level: int, text: str, bearing: float, is_drop: bool) -> str | None:
    """The short phrase for an alarm (verbosity 'normal'), or None."""
    if level == FAULT:
        return 'starting, hold still' if text.startswith('starting') else 'cannot see'
    if level == CLEAR:
        return None
    if level == STOP:
        return 'stop'
    if is_drop:
        return 'step down'
    deg = math.degrees(bearing)
    side = 'ahead' if abs(deg) <= PHRASE_SIDE_DEG else ('left' if deg > 0 else 'right')
    return f'obstacle {side}'


class CuePlanner:
    """The sound policy (see module doc). Deterministic: events depend only on the
    inputs and their times."""

    def __init__(self, cfg: AudioConfig | None = None):
        self.cfg = cfg or AudioConfig()
        self.level = FAULT                  # silence is never "all clear" at start
        self.fault_text = 'starting up, hold still'
        self.bearing = 0.0
        self.range = math.inf
        self.ttc = math.inf
        self.is_drop = False
        self.moving = False
        self._next_tone: float | None = None
        self._last_tone = -math.inf
        self._tones_until = math.inf
        self._last_phrase_t = -math.inf
        self._pending: tuple[float, str, int] | None = None   # (t, phrase, its level)
        self._degraded = False
        self._next_degraded: float | None = None
        self._tone_len = {k: len(mono_cue(k, self.cfg.sample_rate)) / self.cfg.sample_rate
                          for k in CueKind}
        self.phrases_said = 0

    def set_config(self, cfg: AudioConfig) -> None:
        self.cfg = cfg

    # -- what sounds now
    def cue_kind(self) -> CueKind | None:
        """The cue of the current level (None while CLEAR)."""
        if self.level == FAULT:
            return CueKind.FAULT
        if self.level == CLEAR:
            return None
        if self.level == STOP:
            return CueKind.STOP
        return CueKind.DROP if self.is_drop else CueKind.OBSTACLE

    def interval(self) -> float:
        if self.level == FAULT:
            return self.cfg.fault_interval
        return repeat_interval(self.ttc, self.range, self.cfg)

    # -- inputs
    def alarm(self, t: float, level: int, text: str = '', bearing: float = 0.0,
              range_m: float = 0.0, repeat: bool = False) -> list[Event]:
        """An /alarms message at time t (s). Returns the events due at t."""
        prev, self.level = self.level, int(level)
        out: list[Event] = []
        if self.level == CLEAR:
            self._next_tone = None
            if prev == FAULT:
                out += self._phrase(t, 'ready', t)
            return out
        if self.level == FAULT:
            self.fault_text = text
            self._tones_until = math.inf
        else:
            if range_m > 0:
                self.bearing, self.range = float(bearing), float(range_m)
                if text:
                    self.is_drop = text.startswith('drop') or text.startswith('stop, drop')
            self._tones_until = (math.inf if self.moving
                                 else t + self.cfg.standing_tones_for)
        new = (not repeat or self.level > prev or self._next_tone is None
               or (prev == FAULT) != (self.level == FAULT))
        kind = self.cue_kind()
        if new:
            out.append(Event(t, kind, self._bearing(kind)))
            self._last_tone = t
            self._next_tone = t + self.interval()
            if not repeat or self.level != prev:
                phrase = self._words(text)
                if phrase:
                    tone = self._tone_len[kind] if kind is not None else 0.0
                    out += self._phrase(t + tone + 0.02, phrase, t)
        return out

    def contact(self, t: float, level: int, bearing: float, range_m: float, ttc: float,
                is_drop: bool, moving: bool) -> None:
        """The most urgent obstacle of an obstacle list (level CLEAR: none) at time t."""
        self.moving = bool(moving)
        if level == CLEAR or not math.isfinite(range_m):
            return
        self.bearing, self.range, self.is_drop = float(bearing), float(range_m), bool(is_drop)
        self.ttc = float(ttc)
        if self.moving:
            self._tones_until = math.inf
        if self._next_tone is not None and self.level not in (CLEAR, FAULT):
            # a nearer contact shortens the wait at once
            self._next_tone = min(self._next_tone, self._last_tone + self.interval())

    def degraded(self, t: float, on: bool) -> list[Event]:
        """The inclinometer went silent (on) or came back (off) at time t."""
        if bool(on) == self._degraded:
            return []
        self._degraded = bool(on)
        if not on:
            self._next_degraded = None
            return []
        self._next_degraded = t + self.cfg.degraded_interval
        return [Event(t, CueKind.DEGRADED)] + self._phrase(
            t + self._tone_len[CueKind.DEGRADED] + 0.02, 'tilt sensor lost', t)

    def advance(self, t: float) -> list[Event]:
        """The events due at or before t (s), in time order."""
        out: list[Event] = []
        while self._next_tone is not None and self._next_tone <= t:
            tt = self._next_tone
            if self.level not in (CLEAR, FAULT) and tt > self._tones_until:
                self._next_tone = None          # a standing wearer: enough
                break
            kind = self.cue_kind()
            out.append(Event(tt, kind, self._bearing(kind)))
            self._last_tone = tt
            self._next_tone = tt + self.interval()
        while self._next_degraded is not None and self._next_degraded <= t:
            out.append(Event(self._next_degraded, CueKind.DEGRADED))
            self._next_degraded += self.cfg.degraded_interval
        if self._pending is not None:
            pt, phrase, lvl = self._pending
            due = max(pt, self._last_phrase_t + self.cfg.speech_min_interval)
            if lvl != self.level:
                self._pending = None
            elif due <= t:
                self._pending = None
                out += self._phrase(due, phrase, due)
        out.sort(key=lambda e: e.t)
        return out

    # -- internals
    def _bearing(self, kind: CueKind | None) -> float:
        return self.bearing if kind in (CueKind.OBSTACLE, CueKind.DROP, CueKind.STOP) else 0.0

    def _words(self, text: str) -> str | None:
        v = self.cfg.verbosity
        if v == 'tones':
            return None
        if v == 'verbose':
            return text or None
        return category_phrase(self.level, text, self.bearing, self.is_drop)

    def _phrase(self, t: float, phrase: str, t_alarm: float) -> list[Event]:
        if self.cfg.verbosity == 'tones':
            return []
        if t - self._last_phrase_t < self.cfg.speech_min_interval - 1e-6:
            self._pending = (t, phrase, self.level)     # said later if still true
            return []
        self._last_phrase_t = t
        self._pending = None
        self.phrases_said += 1
        return [Event(t, phrase=phrase)]
