"""Speech for a few short phrases, from an offline espeak-ng (no ROS here).

The engine is the libespeak-ng shipped inside the pinned PyPI wheel ``espeakng-loader``
(library and voice data in the wheel, used through ctypes), or, failing that, the
system's ``espeak-ng`` program. Neither present is no error: ``SpeechEngine.available``
is False, ``why_unavailable`` says why, and the caller renders tones only.

Phrases are rendered once (``render``) and cached: the few category phrases the wearer
hears ("stop", "step down", "cannot see") are pre-rendered at start-up, so no synthesis
runs on the path from an alarm to its sound. Output: mono float32 in [-1, 1] at the
caller's sample rate (resampled linearly from the engine's 22050 Hz).
"""
from __future__ import annotations

import ctypes
import io
import shutil
import subprocess
import threading
import wave

import numpy as np

#: espeak_AUDIO_OUTPUT: AUDIO_OUTPUT_SYNCHRONOUS (samples handed to the callback)
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_POS_CHARACTER = 1
_ESPEAK_RATE = 1
_ESPEAK_CHARS_UTF8 = 1
_ESPEAK_ENDPAUSE = 0x1000
_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int,
                             ctypes.c_void_p)
#: libespeak-ng is one global engine per process
_LIB_LOCK = threading.Lock()


def resample(x: np.ndarray, rate_in: int, rate_out: int) -> np.ndarray:
    """Linear resampling of a mono signal (1-D float array) from rate_in to rate_out Hz."""
    if rate_in == rate_out or len(x) == 0:
        return np.asarray(x, dtype=np.float32)
    n_out = int(round(len(x) * rate_out / rate_in))
    t_out = np.arange(n_out) * (rate_in / rate_out)
    return np.interp(t_out, np.arange(len(x)), x).astype(np.float32)


class _LibEspeak:
    """libespeak-ng through ctypes (the wheel's copy)."""

    def __init__(self) -> None:
        import espeakng_loader  # the pinned wheel; ImportError if absent
        self._lib = ctypes.CDLL(espeakng_loader.get_library_path())
        data = espeakng_loader.get_data_path().encode()
        lib = self._lib
        lib.espeak_Initialize.restype = ctypes.c_int
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p,
                                          ctypes.c_int]
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_Synth.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint,
                                     ctypes.c_int, ctypes.c_uint, ctypes.c_uint,
                                     ctypes.c_void_p, ctypes.c_void_p]
        self.rate = lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, data, 0)
        if self.rate <= 0:
            raise RuntimeError(f'espeak_Initialize failed ({self.rate})')
        self._chunks: list[np.ndarray] = []

        def _cb(wav, n, _events):
            if n > 0 and wav:
                self._chunks.append(np.ctypeslib.as_array(wav, shape=(n,)).copy())
            return 0
        self._cb = _CALLBACK(_cb)          # kept alive as long as the library uses it
        lib.espeak_SetSynthCallback(self._cb)

    def synth(self, text: str, voice: str, words_per_minute: int) -> tuple[np.ndarray, int]:
        lib = self._lib
        if lib.espeak_SetVoiceByName(voice.encode()) != 0:
            raise ValueError(f'espeak-ng has no voice {voice!r}')
        lib.espeak_SetParameter(_ESPEAK_RATE, int(words_per_minute), 0)
        self._chunks = []
        raw = text.encode('utf-8') + b'\0'
        err = lib.espeak_Synth(raw, len(raw), 0, _POS_CHARACTER, 0,
                               _ESPEAK_CHARS_UTF8 | _ESPEAK_ENDPAUSE, None, None)
        lib.espeak_Synchronize()
        if err != 0:
            raise RuntimeError(f'espeak_Synth failed ({err})')
        pcm = np.concatenate(self._chunks) if self._chunks else np.zeros(0, np.int16)
        return pcm.astype(np.float32) / 32768.0, self.rate


def _synth_program(text: str, voice: str, words_per_minute: int) -> tuple[np.ndarray, int]:
    """The system's espeak-ng program, WAV on stdout."""
    out = subprocess.run(['espeak-ng', '--stdout', '-v', voice, '-s', str(words_per_minute),
                          text], capture_output=True, timeout=10, check=True).stdout
    with wave.open(io.BytesIO(out)) as w:
        rate = w.getframerate()
        pcm = np.frombuffer(w.readframes(w.getnframes()), dtype='<i2')
    return pcm.astype(np.float32) / 32768.0, rate


class SpeechEngine:
    """Offline speech with a cache of rendered phrases.

    Args:
        sample_rate: output rate, Hz.
        language: an espeak-ng voice name ('en', 'en-gb', 'de', 'fr', ...).
        words_per_minute: speaking rate (espeak-ng's default is 175).
        engine: 'auto' (wheel, then program), 'library', 'program' or 'none'.
    """

    def __init__(self, sample_rate: int, language: str = 'en', words_per_minute: int = 190,
                 engine: str = 'auto'):
        self.sample_rate = int(sample_rate)
        self.language = language
        self.words_per_minute = int(words_per_minute)
        self._cache: dict[str, np.ndarray] = {}
        self._synth = None
        self.engine_name = 'none'
        self.why_unavailable = ''
        reasons = []
        if engine in ('auto', 'library'):
            try:
                with _LIB_LOCK:
                    lib = _get_lib()
                self._synth = lib.synth
                self.engine_name = 'libespeak-ng (espeakng-loader wheel)'
            except (ImportError, OSError, RuntimeError) as exc:
                reasons.append(f'espeakng-loader: {exc}')
        if self._synth is None and engine in ('auto', 'program'):
            if shutil.which('espeak-ng'):
                self._synth = _synth_program
                self.engine_name = 'espeak-ng program'
            else:
                reasons.append('no espeak-ng program on PATH')
        if engine == 'none':
            reasons.append('speech turned off')
        if self._synth is None:
            self.why_unavailable = '; '.join(reasons)
        elif language:
            try:                     # a wrong language must show at start, not at a cue
                self.render('ok')
            except (ValueError, RuntimeError, subprocess.SubprocessError, OSError) as exc:
                self._synth = None
                self.engine_name = 'none'
                self.why_unavailable = f'{exc}'

    @property
    def available(self) -> bool:
        return self._synth is not None

    def render(self, text: str) -> np.ndarray | None:
        """The phrase as mono float32 samples at ``sample_rate`` (cached), or None when no
        engine is available. Leading and trailing silence are trimmed."""
        if text in self._cache:
            return self._cache[text]
        if self._synth is None:
            return None
        with _LIB_LOCK:
            pcm, rate = self._synth(text, self.language, self.words_per_minute)
        loud = np.flatnonzero(np.abs(pcm) > 0.01)
        if len(loud):
            pcm = pcm[max(0, loud[0] - 40):loud[-1] + 400]
        out = resample(pcm, rate, self.sample_rate)
        self._cache[text] = out
        return out

    def prerender(self, phrases) -> None:
        """Render (and cache) every phrase now."""
        for p in phrases:
            self.render(p)


_LIB: _LibEspeak | None = None


def _get_lib() -> _LibEspeak:
    global _LIB
    if _LIB is None:
        _LIB = _LibEspeak()
    return _LIB
