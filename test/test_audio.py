"""The audio renderer (core.audio): read back from the samples and the WAV file."""
import math

import numpy as np
import pytest

from asmonc_vision.core.audio import (AudioConfig, AudioRenderer, CueKind, CuePlanner,
                                      SpeechEngine, Soundtrack, read_wav, render_cue,
                                      repeat_interval, write_wav)
from asmonc_vision.core.audio.render import interaural, mono_cue

RATE = 16000
CLEAR, CAUTION, WARNING, STOP, FAULT = range(5)


def renderer(**cfg) -> AudioRenderer:
    c = AudioConfig(**cfg)
    return AudioRenderer(c, SpeechEngine(c.sample_rate, engine='none'))


def onsets(x: np.ndarray, rate: int, thresh: float = 0.02, gap: float = 0.03) -> list[float]:
    """Times (s) where the louder channel's |x| first passes thresh after >= gap s quiet."""
    loud = np.flatnonzero(np.max(np.abs(x), axis=1) > thresh)
    if not len(loud):
        return []
    starts = [loud[0]] + [b for a, b in zip(loud[:-1], loud[1:]) if b - a > gap * rate]
    return [s / rate for s in starts]


def wav_roundtrip(tmp_path, r: AudioRenderer, duration: float) -> np.ndarray:
    path = tmp_path / 'out.wav'
    write_wav(path, r.track.mix(duration), r.cfg.sample_rate)
    x, rate = read_wav(path)
    assert rate == r.cfg.sample_rate >= 16000 and x.shape[1] == 2
    return x


def start_clear(r: AudioRenderer, t: float = -10.0) -> None:
    r.alarm(t, CLEAR, 'all clear')


@pytest.mark.parametrize('deg', [-80, -40, -16, 16, 40, 80])
def test_the_louder_ear_is_on_the_obstacles_side(tmp_path, deg):
    r = renderer()
    start_clear(r)
    r.alarm(0.5, WARNING, 'obstacle, 2 metres, left', math.radians(deg), 2.0)
    x = wav_roundtrip(tmp_path, r, 1.0)
    rms = np.sqrt(np.mean(x ** 2, axis=0))
    left_louder = rms[0] > rms[1] * 1.2
    assert left_louder == (deg > 0) and (rms[1] > rms[0] * 1.2) == (deg < 0)
    # the near ear hears it first (ITD)
    first = [np.flatnonzero(np.abs(x[:, ch]) > 0.01)[0] for ch in (0, 1)]
    assert (first[0] < first[1]) == (deg > 0)


def test_interaural_differences_grow_with_bearing():
    c = AudioConfig()
    itds = [interaural(math.radians(d), c)[0] for d in (0, 15, 45, 90)]
    assert itds[0] == 0 and all(a < b for a, b in zip(itds, itds[1:]))
    assert itds[-1] == pytest.approx(0.656e-3, abs=0.01e-3)
    assert interaural(math.radians(90), c)[1] == pytest.approx(c.max_ild_db)


def test_repetition_rate_orders_by_time_to_contact(tmp_path):
    rates = []
    for ttc in (4.0, 2.0, 1.0):
        r = renderer()
        start_clear(r)
        r.contact(0.9, WARNING, 0.0, 1.4 * ttc, ttc, False, True)
        r.alarm(1.0, WARNING, 'obstacle, 2 metres, ahead', 0.0, 1.4 * ttc)
        for k in range(1, 41):                 # 4 s more, a contact every 0.1 s
            t = 1.0 + 0.1 * k
            r.contact(t, WARNING, 0.0, 1.4 * ttc, ttc, False, True)
            r.advance(t)
        x = wav_roundtrip(tmp_path, r, 5.0)
        n = len(onsets(x[int(1.0 * RATE):], RATE))
        rates.append(n / 4.0)
    assert rates[0] < rates[1] < rates[2], rates
    assert repeat_interval(math.inf, 2.0, AudioConfig()) == pytest.approx(0.5)


def test_onsets_sit_at_the_alarm_decisions(tmp_path):
    r = renderer()
    start_clear(r)
    times = [0.73, 2.41, 4.05]
    for t, lvl in zip(times, (CAUTION, WARNING, STOP)):
        r.advance(t)
        r.alarm(t, lvl, 'obstacle, 3 metres, ahead', 0.0, 3.0)
    r.advance(4.2)
    x = wav_roundtrip(tmp_path, r, 4.5)
    found = onsets(x, RATE)
    for t in times:
        assert min(abs(f - t) for f in found) < 0.05, (t, found)


def test_a_drops_cue_differs_from_an_obstacles():
    def centroid_and_sweep(kind):
        x = mono_cue(kind, RATE)
        spec = np.abs(np.fft.rfft(x, 4096))
        f = np.fft.rfftfreq(4096, 1 / RATE)
        half = len(x) // 2
        zc = [np.mean(np.abs(np.diff(np.sign(p)))) for p in (x[:half], x[half:])]
        return float((spec * f).sum() / spec.sum()), zc
    c_obs, zc_obs = centroid_and_sweep(CueKind.OBSTACLE)
    c_drop, zc_drop = centroid_and_sweep(CueKind.DROP)
    assert abs(c_obs - c_drop) > 150.0
    assert zc_drop[1] < 0.7 * zc_drop[0]            # the drop's pitch falls
    assert zc_obs[1] == pytest.approx(zc_obs[0], rel=0.1)


def test_every_cue_is_short_and_distinct():
    sounds = {k: mono_cue(k, RATE) for k in CueKind}
    assert all(len(x) / RATE < 0.1 for x in sounds.values())
    specs = {k: np.abs(np.fft.rfft(x, 4096)) for k, x in sounds.items()}
    specs = {k: s / np.linalg.norm(s) for k, s in specs.items()}
    kinds = list(CueKind)
    for i, a in enumerate(kinds):
        for b in kinds[i + 1:]:
            assert float(specs[a] @ specs[b]) < 0.8, (a, b)


def test_fault_repeats_while_it_lasts_and_clear_is_silent(tmp_path):
    r = renderer()
    start_clear(r)
    r.advance(2.0)
    r.alarm(2.0, FAULT, 'fault, obstacle detection has stopped, walk with care')
    r.advance(5.05)
    r.alarm(5.05, CLEAR, 'all clear')
    r.advance(8.0)
    x = wav_roundtrip(tmp_path, r, 8.0)
    found = onsets(x, RATE)
    assert found and found[0] == pytest.approx(2.0, abs=0.01)
    assert len([f for f in found if 2.0 <= f < 5.05]) == 4      # every 1 s
    assert not [f for f in found if f > 5.2] and not [f for f in found if f < 1.9]


def test_a_standing_wearer_hears_a_few_tones_then_silence():
    p = CuePlanner(AudioConfig(standing_tones_for=2.0))
    p.alarm(0.0, CLEAR)
    p.contact(1.0, WARNING, 0.0, 2.0, math.inf, False, False)
    ev = p.alarm(1.0, WARNING, 'obstacle, 2 metres, ahead', 0.0, 2.0)
    ev += p.advance(10.0)
    tones = [e.t for e in ev if e.kind is not None]
    assert tones and max(tones) <= 3.0 and len(tones) == 5       # every 0.5 s for 2 s


def test_speech_at_most_one_phrase_per_2_s_and_urgent_cues_cut_it():
    speech = SpeechEngine(RATE)
    if not speech.available:
        pytest.skip(f'no speech engine: {speech.why_unavailable}')
    r = AudioRenderer(AudioConfig(), speech)
    start_clear(r)
    r.alarm(1.0, CAUTION, 'obstacle, 4 metres, slightly left', math.radians(20), 4.0)
    r.alarm(1.5, WARNING, 'obstacle, 2.5 metres, slightly left', math.radians(20), 2.5)
    r.advance(2.0)
    r.alarm(2.0, STOP, 'stop, obstacle, 1 metre, ahead', 0.0, 1.0)
    r.advance(6.0)
    phrases = [(t, s) for t, s in r.log if s.startswith('phrase') and t > 0]
    assert phrases[0][1] == 'phrase: obstacle left'
    gaps = np.diff([t for t, _ in phrases])
    assert np.all(gaps >= 2.0 - 1e-9)
    # the STOP held back by the limit is said as soon as it allows
    assert ('phrase: stop' in [s for _, s in phrases])
    # an urgent cue cuts a long phrase: the gap after the STOP cue is silent
    v = AudioRenderer(AudioConfig(verbosity='verbose'), speech)
    start_clear(v)
    v.alarm(1.0, CAUTION, 'obstacle, 4.5 metres, slightly left, and a long sentence after',
            math.radians(20), 4.5)
    y = v.track.mix(3.0)
    assert np.abs(y[int(1.6 * RATE):int(1.7 * RATE)]).max() > 0.05     # speaking
    v.alarm(1.5, STOP, 'stop, obstacle, 1 metre, ahead', 0.0, 1.0)
    y = v.track.mix(3.0)
    assert np.abs(y[int(1.6 * RATE):int(1.7 * RATE)]).max() == 0.0     # cut
    track = Soundtrack(RATE)
    track.add_phrase(0.0, np.full(RATE, 0.3, np.float32))
    track.duck(0.5, 0.01)
    y = track.mix(1.0)
    assert np.all(y[int(0.52 * RATE):] == 0) and np.all(y[:int(0.49 * RATE)] > 0.29)


def test_speech_engine_renders_and_caches():
    speech = SpeechEngine(RATE)
    if not speech.available:
        pytest.skip(f'no speech engine: {speech.why_unavailable}')
    a = speech.render('step down')
    assert a.dtype == np.float32 and 0.2 < len(a) / RATE < 1.5 and np.abs(a).max() > 0.1
    assert speech.render('step down') is a


def test_no_speech_engine_gives_tones_only():
    s = SpeechEngine(RATE, engine='none')
    assert not s.available and s.why_unavailable and s.render('stop') is None
    r = AudioRenderer(AudioConfig(), s)
    start_clear(r)
    r.alarm(0.2, STOP, 'stop, obstacle, 1 metre, ahead', 0.0, 1.0)
    assert ('stop' in [k for _, k in r.log]) and 'phrase: stop' in [k for _, k in r.log]
    assert np.abs(r.track.mix()).max() > 0.1


def test_rendering_is_deterministic():
    def run():
        r = renderer()
        start_clear(r)
        r.alarm(0.3, WARNING, 'drop ahead, 2 metres', 0.2, 2.0)
        r.advance(2.0)
        return r.track.mix(2.0)
    assert np.array_equal(run(), run())


def test_settings_are_checked():
    with pytest.raises(ValueError, match='min_interval'):
        AudioConfig(min_interval=2.0, max_interval=1.0)
    with pytest.raises(ValueError, match='verbosity'):
        AudioConfig(verbosity='chatty')
    assert render_cue(CueKind.FAULT, 1.0, AudioConfig()).shape[1] == 2


def test_a_phrase_held_back_is_said_when_the_limit_allows():
    p = CuePlanner(AudioConfig(speech_min_interval=2.0))
    p.alarm(0.11, FAULT, 'starting up, hold still')            # a phrase at about 0.2 s
    first = p._last_phrase_t
    p.alarm(0.3, CLEAR, 'all clear')                              # "ready" held back
    ev = p.alarm(2.0, WARNING, 'obstacle, 3.5 metres, ahead', 0.0, 3.5)
    assert not [e for e in ev if e.phrase]
    later = p.advance(first + 2.0 + 0.01)
    assert [e.phrase for e in later if e.phrase] == ['obstacle ahead']
    assert [e.t for e in later if e.phrase][0] == pytest.approx(first + 2.0, abs=0.1)


def test_the_degraded_cue_is_soft_and_slow():
    p = CuePlanner(AudioConfig(degraded_interval=5.0))
    p.alarm(0.0, CLEAR)
    ev = p.degraded(1.0, True) + p.advance(12.0)
    assert [e.t for e in ev if e.kind == CueKind.DEGRADED] == [1.0, 6.0, 11.0]
    assert p.degraded(12.0, False) == [] and not p.advance(30.0)
    assert np.abs(render_cue(CueKind.DEGRADED, 0, AudioConfig())).max() < \
        0.5 * np.abs(render_cue(CueKind.OBSTACLE, 0, AudioConfig())).max()
