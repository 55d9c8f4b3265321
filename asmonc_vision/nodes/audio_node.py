"""audio_node: what the wearer hears. /alarms in, sound out (a device, a WAV file, both).

Subscribes:
    /alarms (asmonc_vision_msgs/Alarm, RELIABLE + TRANSIENT_LOCAL)
    /alarms/contact (diagnostic_msgs/DiagnosticArray, RELIABLE): the most urgent obstacle
        of each obstacle list (see ``nodes.alarm_node``): it steers the sounding cue
    /stereo/left/camera_info (sensor_msgs/CameraInfo, best effort): one per stereo
        pair; its stamps tie this node's clock to the camera's time line
    /diagnostics: the walk model's "inclinometer silent" gives the degraded-mode cue
    /obstacles (only their stamps and arrival: the latency's detector share)
Publishes:
    /diagnostics: the output (a device, or silent), the speech engine, cues and
        phrases given, and the camera-stamp-to-onset latency (p50, p99)

Everything that makes samples is ``core.audio`` (deterministic). The node keeps a *time
line* in the cameras' time: t = 0 is ``t0_ns`` (for a replay, the stamp of the bag's first
stereo pair; 0: the first camera_info's stamp). An alarm made for a frame (its stamp is
the frame's) is placed at that stamp; one made by the alarm node's own clock (start-up,
a time-out; its stamp is system time) at the newest camera_info's stamp plus the system
time from that pair's arrival to the alarm's stamp, times ``rate`` (the replay's rate) --
so the WAV is in bag time whatever the replay rate.

Live output: the default sound device through ``sounddevice`` (PortAudio) when
``output`` is 'auto' and one exists. Without PortAudio or a device the node says so in
its log and in /diagnostics (WARN "silent output") and keeps working: the WAV (if
``wav_path`` is set) is written all the same, at shutdown.
"""
from __future__ import annotations

import math

import json
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo

from asmonc_vision.core.audio import AudioConfig, AudioRenderer, Soundtrack
from asmonc_vision.core.audio.render import URGENT
from asmonc_vision.core.config import check_fields, param
from asmonc_vision.nodes.alarm_node import CONTACT_TOPIC, contact_from_msg
from asmonc_vision.nodes.common import (ALARM_QOS, RESULT_QOS, SENSOR_QOS, Diagnostics,
                                        declare_config, run_node, watch_input_links)
from asmonc_vision.nodes.conversions import stamp_to_ns
from asmonc_vision_msgs.msg import Alarm, ObstacleArray

#: period of the cue clock (a thread on the steady clock), seconds
TICK = 0.01
#: a stamp further than this from the camera time line is the alarm node's own clock
LIVE_STAMP_GAP = 60.0
#: seconds of the time line kept in memory behind its present (a cue may be placed a
#: little in the past); older sound is dropped, or streamed to the WAV first
KEEP_S = 10.0
#: latencies kept for the diagnostics' percentiles (all of them with ``latency_path``)
LATENCY_KEEP = 1000
#: the time line is trimmed at most this often, seconds of steady time
TRIM_PERIOD = 1.0
#: the walk model's diagnostic status and the message that means "inclinometer silent"
GAIT_STATUS, GAIT_SILENT = 'gait_filter_node', 'inclinometer silent'


@dataclass(frozen=True)
class AudioNodeConfig:
    """Where the sound goes (ROS parameters of the audio node, beside AudioConfig's)."""

    output: str = param('auto', "'auto': the sound device if one exists (else silent, "
                        "reported); 'none': no live output", choices=('auto', 'none'))
    device: str = param('', 'sounddevice output device (name or index); empty: the default')
    wav_path: str = param('', 'write what the wearer would have heard to this WAV file at '
                          'shutdown (stereo, 16-bit; empty: none)')
    t0_ns: int = param(0, 'camera time (ns) of t = 0 in the WAV: the stamp of the first '
                       'stereo pair; 0: the first camera_info seen', range=(0, 2 ** 63 - 1))
    rate: float = param(1.0, 'replay rate of the camera time line (1 live)',
                        range=(0.01, 100.0))
    wav_tail: float = param(
        1.0, 'the WAV ends this long after the newest camera_info\'s stamp (a replay\'s '
        'end: no sound of the shutdown), seconds; without camera_info it runs to shutdown',
        range=(0.0, 3600.0))
    latency_path: str = param('', 'write the per-cue stamp-to-onset latencies (JSON) here '
                              'at shutdown (empty: none)')

    def __post_init__(self) -> None:
        check_fields(self)


class LiveOutput:
    """The sound device, or nothing. ``available`` False: ``why`` says why."""

    def __init__(self, rate: int, output: str, device: str):
        self.rate = rate
        self.available = False
        self.why = ''
        self.latency = 0.0              # s, the device's output latency
        self.track = Soundtrack(rate)
        self._pos = 0                   # next sample the device plays
        self._lock = threading.Lock()
        self._stream = None
        if output == 'none':
            self.why = 'live output turned off (output: none)'
            return
        try:
            import sounddevice as sd    # PortAudio: OSError when the library is missing
            dev = int(device) if device.strip().isdigit() else (device or None)
            self._stream = sd.OutputStream(samplerate=rate, channels=2, dtype='float32',
                                           device=dev, callback=self._callback)
            self._stream.start()
            self.latency = float(self._stream.latency)
            self.available = True
        except (ImportError, OSError) as exc:
            self.why = f'no sound library: {exc}'
        except Exception as exc:  # noqa: BLE001 -- PortAudioError and friends: no device
            self.why = f'no sound device: {exc}'

    def _callback(self, outdata, frames, _time, _status) -> None:
        with self._lock:
            outdata[:] = self.track.read(self._pos, frames)
            self._pos += frames
            self.track.trim(self._pos - self.rate)

    def play(self, samples: np.ndarray, phrase: bool, urgent: bool, fade: float) -> None:
        """Play samples (n, 2) or (n,) as soon as possible."""
        if not self.available:
            return
        with self._lock:
            t = self._pos / self.rate
            if urgent:
                self.track.duck(t, fade)
            if phrase:
                self.track.add_phrase(t, samples, fade=fade)
            else:
                self.track.add_tone(t, samples)

    def close(self) -> None:
        if self._stream is not None:
            self._stream.stop()
            self._stream.close()


class WavStream:
    """A WAV file written as the time line goes (16-bit stereo): the samples before an
    index are written once they are final, so memory holds only the recent sound."""

    def __init__(self, path: str, rate: int):
        import wave
        self.path = path
        self.rate = int(rate)
        self.written = 0              # samples written (absolute index of the next one)
        self._w = wave.open(str(path), 'wb')
        self._w.setnchannels(2)
        self._w.setsampwidth(2)
        self._w.setframerate(self.rate)

    def write_until(self, track: Soundtrack, end: int) -> None:
        """Write the mix of ``track`` up to absolute sample ``end`` (exclusive)."""
        if end > self.written:
            pcm = (track.read(self.written, end - self.written) * 32767.0).round()
            self._w.writeframes(pcm.astype('<i2').tobytes())
            self.written = end

    def finish(self, track: Soundtrack, end: int) -> None:
        """Write up to ``end`` and close the file."""
        self.write_until(track, end)
        self._w.close()


class AudioNode(Node):
    """Turns alarms into sound (see module doc)."""

    def __init__(self, **kwargs):
        super().__init__('audio_node', **kwargs)
        self._lock = threading.Lock()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.node_config: AudioNodeConfig = declare_config(self, AudioNodeConfig)
        self.config: AudioConfig = declare_config(self, AudioConfig)
        log = self.get_logger()
        self.renderer = AudioRenderer(self.config)
        self.live = LiveOutput(self.config.sample_rate, self.node_config.output,
                               self.node_config.device)
        self._t0_ns = self.node_config.t0_ns or None
        self._anchor: tuple[int, float] | None = None   # (camera stamp ns, steady s)
        self._anchor_wall_ns: int | None = None          # its arrival on the system clock
        self._arrivals: deque = deque(maxlen=512)       # (stamp ns, steady s) of pairs
        #: seconds from a pair's arrival to the onset of a cue it decided (+ the device's
        #: output latency), and to the arrival of its /alarms/contact (when a cue could
        #: start for any pair)
        keep = None if self.node_config.latency_path else LATENCY_KEEP
        self.latencies: deque[float] = deque(maxlen=keep)
        self.contact_latencies: deque[float] = deque(maxlen=keep)
        #: the pairs' times on the time line (s), beside the two above
        self.latency_times: deque[float] = deque(maxlen=keep)
        self.contact_times: deque[float] = deque(maxlen=keep)
        #: the contact latency split: pair -> its /obstacles here (detector), and
        #: /obstacles -> /alarms/contact (alarm node)
        self.detector_latencies: deque[float] = deque(maxlen=keep)
        self.alarm_latencies: deque[float] = deque(maxlen=keep)
        self._obstacle_arrivals: deque = deque(maxlen=512)
        self._closed = False
        self._last_alarm: tuple | None = None
        #: every alarm heard, where it was placed on the time line (with a WAV; else the
        #: last `KEEP_S` seconds of them)
        self.alarm_log: list[dict] = []
        #: cues and phrases given that are no longer in the renderer's log (trimmed)
        self._dropped_cues = self._dropped_phrases = 0
        self._last_trim = -math.inf
        self._wav = WavStream(self.node_config.wav_path, self.config.sample_rate) \
            if self.node_config.wav_path else None

        self._diag = Diagnostics(self, 'audio_node')
        self.create_subscription(Alarm, '/alarms', self._on_alarm, ALARM_QOS)
        self.create_subscription(DiagnosticArray, CONTACT_TOPIC, self._on_contact, RESULT_QOS)
        self.create_subscription(CameraInfo, '/stereo/left/camera_info', self._on_info,
                                 SENSOR_QOS)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.create_subscription(ObstacleArray, '/obstacles', self._on_obstacles, RESULT_QOS)
        watch_input_links(self, ('/alarms', '/stereo/left/camera_info'))
        # the cue clock is a plain thread, not an rclpy timer: a hundred executor wake-ups
        # a second cost about a tenth of a core on a small CPU, which the detector needs
        self._tick_stop = threading.Event()
        self._tick_thread = threading.Thread(target=self._tick_loop, name='audio_cue_clock',
                                             daemon=True)
        self._tick_thread.start()

        sp = self.renderer.speech
        if self.config.verbosity != 'tones' and not sp.available:
            log.warning(f'no speech engine ({sp.why_unavailable}): tones only')
        if self.live.available:
            log.info(f'audio node up: playing to the sound device, latency '
                     f'{self.live.latency * 1e3:.0f} ms; speech: {sp.engine_name}')
        else:
            log.warning(f'audio node up: plays to NO sound device, silent output '
                        f'({self.live.why}); speech: {sp.engine_name}'
                        + (f'; writing {self.node_config.wav_path}'
                           if self.node_config.wav_path else ''))
        self._update_diagnostics()

    # -- the camera time line
    def _now(self) -> float:
        return self._steady.now().nanoseconds * 1e-9

    def timeline_now(self) -> float | None:
        """Camera time now, seconds after t0 (None before the first camera_info)."""
        if self._anchor is None or self._t0_ns is None:
            return None
        ns, at = self._anchor
        return (ns - self._t0_ns) * 1e-9 + (self._now() - at) * self.node_config.rate

    def _stamp_time(self, ns: int) -> float | None:
        """A stamp on the time line (s), or None for a stamp of another clock."""
        if self._t0_ns is None:
            return None
        t = (ns - self._t0_ns) * 1e-9
        now = self.timeline_now()
        if now is not None and abs(t - now) > LIVE_STAMP_GAP:
            return None
        if now is None and not -LIVE_STAMP_GAP < t < 86400.0:
            return None
        return t

    def _wall_stamp_time(self, wall_ns: int) -> float | None:
        """An alarm stamped by the alarm node's own (system) clock on the time line: the
        newest pair's camera time plus the system time since it arrived, at ``rate`` (not
        the arrival here: the transport's delay is not the alarm's); None before the
        first pair."""
        if self._anchor is None or self._t0_ns is None:
            return None
        since = (wall_ns - self._anchor_wall_ns) * 1e-9
        if not -1.0 < since < LIVE_STAMP_GAP:       # another clock after all: arrival time
            return self.timeline_now()
        return (self._anchor[0] - self._t0_ns) * 1e-9 + since * self.node_config.rate

    # -- callbacks
    def _on_info(self, msg: CameraInfo) -> None:
        ns = stamp_to_ns(msg.header.stamp)
        with self._lock:
            if self._t0_ns is None:
                self._t0_ns = ns
            self._anchor = (ns, self._now())
            self._anchor_wall_ns = time.time_ns()
            self._arrivals.append((ns, self._now()))

    def _on_obstacles(self, msg: ObstacleArray) -> None:
        with self._lock:
            self._obstacle_arrivals.append((stamp_to_ns(msg.header.stamp), self._now()))

    def _on_alarm(self, msg: Alarm) -> None:
        ns = stamp_to_ns(msg.header.stamp)
        with self._lock:
            t = self._stamp_time(ns)
            stamped = t is not None
            if t is None:
                t = self._wall_stamp_time(ns)
            if t is None:
                t = 0.0                  # before the first pair: the start of the WAV
            # the same level about the same obstacle (or the same fault) again: a repeat
            key = (int(msg.level), int(msg.obstacle_id),
                   msg.text if msg.level == Alarm.FAULT else '')
            repeat, self._last_alarm = key == self._last_alarm, key
            events = self.renderer.alarm(t, int(msg.level), msg.text, float(msg.bearing),
                                         float(msg.range), repeat=repeat)
            self.alarm_log.append({'t': round(t, 4), 'level': int(msg.level),
                                   'text': msg.text, 'frame_stamped': stamped})
            self._emit(events, ns if stamped else None)

    def _on_contact(self, msg: DiagnosticArray) -> None:
        c = contact_from_msg(msg)
        if c is None:
            return
        with self._lock:
            ns = stamp_to_ns(msg.header.stamp)
            arrived = self._arrival(ns)
            now = self._now()
            if arrived is not None:
                self.contact_latencies.append(now - arrived + self.live.latency)
                self.contact_times.append(self._stamp_time(ns) or 0.0)
            ob = next((a for s, a in reversed(self._obstacle_arrivals) if s == ns), None)
            if ob is not None:
                self.alarm_latencies.append(now - ob)
                if arrived is not None:
                    self.detector_latencies.append(ob - arrived)
            t = self._stamp_time(ns)
            self.renderer.contact(t or 0.0, c['level'], c['bearing'], c['range'],
                                  c['time_to_contact'], c['drop'], c['moving'])

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name != GAIT_STATUS:
                continue
            silent = st.message.startswith(GAIT_SILENT)
            with self._lock:
                t = self.timeline_now()
                if t is not None:
                    self._emit(self.renderer.degraded(t, silent), None)

    def _tick_loop(self) -> None:
        """Every TICK seconds: the repeats that are due (`_on_tick`), until `close`."""
        due = time.monotonic()
        while True:
            due = max(due + TICK, time.monotonic())
            if self._tick_stop.wait(due - time.monotonic()):
                return
            try:
                self._on_tick()
            except Exception as exc:  # noqa: BLE001 - the cue clock must keep running
                if self._tick_stop.is_set():
                    return
                self.get_logger().error(f'cue clock: {exc!r}', throttle_duration_sec=5.0)

    def _on_tick(self) -> None:
        with self._lock:
            t = self.timeline_now()
            if t is not None:
                self._emit(self.renderer.advance(t), None)
                if self._now() - self._last_trim >= TRIM_PERIOD:
                    self._last_trim = self._now()
                    # never past the newest pair: the WAV ends by it (wav_tail)
                    newest = (self._anchor[0] - self._t0_ns) * 1e-9
                    self._trim(min(t, newest) - KEEP_S)

    def _trim(self, before: float) -> None:
        """Forget the time line before ``before`` (s): its sound (streamed to the WAV
        first, when one is written) and, without a WAV, its cue and alarm logs (the
        diagnostics keep their counts)."""
        track = self.renderer.track
        idx = int(before * self.config.sample_rate)
        if idx <= 0:
            return
        if self._wav is not None:
            self._wav.write_until(track, idx)
        track.trim(idx)
        track.events = [e for e in track.events if e[0] >= before]
        if self._wav is None:
            log = self.renderer.log
            old = [k for t, k in log if t < before]
            self._dropped_phrases += sum(1 for k in old if k.startswith('phrase'))
            self._dropped_cues += len(old) - sum(1 for k in old if k.startswith('phrase'))
            self.renderer.log = [e for e in log if e[0] >= before]
            self.alarm_log = [a for a in self.alarm_log if a['t'] >= before]

    # -- output
    def _emit(self, events, stamp_ns: int | None) -> None:
        if not events:
            return
        cfg = self.config
        for e in events:
            if e.kind is not None:
                self.live.play(self.renderer.cue_samples(e.kind, e.bearing), False,
                               e.kind in URGENT, cfg.duck_fade)
            elif e.phrase:
                s = self.renderer.speech.render(e.phrase)
                if s is not None:
                    self.live.play(s * cfg.speech_volume, True, False, cfg.duck_fade)
        if stamp_ns is not None and any(e.kind is not None for e in events):
            arrived = self._arrival(stamp_ns)
            if arrived is not None:
                self.latencies.append(self._now() - arrived + self.live.latency)
                self.latency_times.append(self._stamp_time(stamp_ns) or 0.0)
        self._update_diagnostics()

    def _arrival(self, stamp_ns: int) -> float | None:
        """When the stereo pair of this stamp arrived here (steady s), if known."""
        return next((a for ns, a in reversed(self._arrivals) if ns == stamp_ns), None)

    def _update_diagnostics(self) -> None:
        lat = np.array(self.latencies) if self.latencies else None
        values = dict(
            output='sound device' if self.live.available else 'none (silent)',
            speech=self.renderer.speech.engine_name, wav_path=self.node_config.wav_path or '-',
            cues=self._dropped_cues + sum(1 for _, k in self.renderer.log
                                          if not k.startswith('phrase')),
            phrases=self._dropped_phrases + sum(1 for _, k in self.renderer.log
                                                if k.startswith('phrase')),
            latency_p50_ms='-' if lat is None else f'{np.percentile(lat, 50) * 1e3:.1f}',
            latency_p99_ms='-' if lat is None else f'{np.percentile(lat, 99) * 1e3:.1f}')
        if self.live.available:
            self._diag.update(Diagnostics.OK, 'playing to the sound device', **values)
        else:
            self._diag.update(Diagnostics.WARN, f'silent output: {self.live.why}', **values)

    def close(self) -> None:
        """Stop the device, write the WAV and the latencies (once)."""
        if self._closed:
            return
        self._closed = True
        self._tick_stop.set()
        if self._tick_thread is not threading.current_thread():
            self._tick_thread.join(timeout=2.0)
        self.live.close()
        with self._lock:
            cfg = self.node_config
            if cfg.wav_path:
                if self._anchor is not None and self._t0_ns is not None:
                    dur = (self._anchor[0] - self._t0_ns) * 1e-9 + cfg.wav_tail
                else:
                    dur = self.renderer.track.end / self.config.sample_rate
                self._wav.finish(self.renderer.track, int(round(dur * self.config.sample_rate)))
                log_path = Path(cfg.wav_path).with_suffix('.cues.json')
                log_path.write_text(json.dumps(
                    {'sample_rate': self.config.sample_rate, 't0_ns': self._t0_ns,
                     'alarms': self.alarm_log,
                     'duration_s': round(dur, 4),
                     'events': [{'t': round(t, 4), 'what': k}
                                for t, k in sorted(self.renderer.log) if t < dur]},
                    indent=1) + '\n')
                self.get_logger().info(f'wrote {cfg.wav_path} ({dur:.1f} s)')
            if cfg.latency_path:
                Path(cfg.latency_path).write_text(json.dumps(
                    {'latency_s': [round(x, 5) for x in self.latencies],
                     'contact_latency_s': [round(x, 5) for x in self.contact_latencies],
                     'latency_t_s': [round(x, 3) for x in self.latency_times],
                     'contact_t_s': [round(x, 3) for x in self.contact_times],
                     'detector_latency_s': [round(x, 5) for x in self.detector_latencies],
                     'alarm_latency_s': [round(x, 5) for x in self.alarm_latencies],
                     'output_latency_s': self.live.latency}) + '\n')

    def destroy_node(self):
        self.close()
        return super().destroy_node()


def main(args=None):
    run_node(AudioNode, args, name='audio_node')


if __name__ == '__main__':
    main()
