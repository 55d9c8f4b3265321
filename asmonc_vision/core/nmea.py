"""Attitude sentences of serial compass/inclinometer modules, and their conversion to the
REP 103 attitude of ``inclinometer_link`` (pure Python/numpy, no I/O).

Two sentence families are understood:

* NMEA-style ``$PTNTHPR,<heading>,<st>,<pitch>,<st>,<roll>,<st>*hh`` (True North
  Technologies; Honeywell HMR3000): degrees, each followed by a status letter
  (``N`` normal; ``L``/``M`` low alarm/warning, ``O``/``P`` high warning/alarm, ``C``
  tuning -- anything but ``N`` flags that angle).
* TCM-style ``$C<heading>P<pitch>R<roll>[X..Y..Z..][T<temp>][E<code>]*hh`` (PNI TCM2):
  letter-tagged fields in any order; a nonzero error code ``E`` flags the heading (the
  magnetic measurement), roll and pitch are kept.

``hh`` is the NMEA checksum: two hex digits, the XOR of every character between ``$``
and ``*``. Other sentences (``$HCHDG`` ...) are recognised as well-formed but unknown.

Conventions (configurable, see ``CompassConfig``): devices report heading clockwise from
north (magnetic; ``declination_deg`` turns it into true north), pitch positive nose up and
roll positive right side down (the marine/aviation convention). REP 103 wants yaw
counter-clockwise from east (``yaw_zero = 'east'``: yaw = 90 deg - heading) or, with
``yaw_zero = 'north'``, counter-clockwise from the heading reference (yaw = -heading);
pitch positive nose *down* (so pitch_rep = -pitch_device) and roll positive right side
down (unchanged).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.config import check_fields, param
from asmonc_vision.core.gait.rotations import matrix_to_rpy, rpy_to_matrix, wrap_angle

#: longest line kept while waiting for its end (a device spewing garbage without
#: newlines must not grow the buffer without bound)
MAX_LINE = 256


class NmeaError(ValueError):
    """A line that is not a usable attitude sentence. ``reason`` is one of 'checksum',
    'format', 'unknown' (well formed, another sentence type)."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class AttitudeReading:
    """One attitude sentence, in the device's own conventions.

    Attributes:
        kind: 'PTNTHPR' or 'TCM'.
        heading_deg: clockwise from (magnetic) north, or None if the sentence had none.
        pitch_deg, roll_deg: as the device reports them.
        flags: (heading, pitch, roll) True where the device says that angle is not
            normal (status letter other than N, or a TCM error code for the heading).
        status: the raw status text ('NNN' for PTNTHPR, the E code for TCM, '' if none).
    """

    kind: str
    heading_deg: float | None
    pitch_deg: float
    roll_deg: float
    flags: tuple[bool, bool, bool]
    status: str = ''


def checksum(body: str) -> int:
    """NMEA checksum: XOR of the characters of `body` (between '$' and '*')."""
    c = 0
    for ch in body.encode('ascii', 'replace'):
        c ^= ch
    return c


def _number(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise NmeaError('format', f'{what} is not a number: {text!r}') from None
    if not math.isfinite(v):
        raise NmeaError('format', f'{what} is not finite: {text!r}')
    return v


#: TCM fields: compass, pitch, roll, magnetometer x y z, temperature, error code
_TCM_KEYS = frozenset('CPRXYZTE')
_TCM_FIELD = re.compile(r'(E)([0-9A-Fa-f]*)|([A-Z])([-+]?[0-9.]*)')


def parse_sentence(line: str, require_checksum: bool = True) -> AttitudeReading:
    """Parse one line (with or without the line end).

    Raises:
        NmeaError: reason 'checksum' (missing or wrong), 'format' (not a sentence, bad
            fields or values out of range) or 'unknown' (another sentence type).
    """
    line = line.strip()
    start = line.rfind('$')
    if start < 0:
        raise NmeaError('format', 'no $ in the line')
    line = line[start:]                       # garbage before the last '$' is dropped
    star = line.find('*')
    if star < 0:
        if require_checksum:
            raise NmeaError('checksum', 'sentence has no checksum')
        body = line[1:]
    else:
        body, given = line[1:star], line[star + 1:star + 3]
        if len(given) != 2 or not all(ch in '0123456789abcdefABCDEF' for ch in given):
            raise NmeaError('checksum', f'bad checksum field {line[star:]!r}')
        if int(given, 16) != checksum(body):
            raise NmeaError('checksum', f'checksum {given} does not match '
                            f'{checksum(body):02X}')
    if not body or any(ord(ch) < 32 or ord(ch) > 126 for ch in body):
        raise NmeaError('format', 'empty sentence or non-printable characters')
    if body.startswith('PTNTHPR,'):
        return _parse_hpr(body)
    if body.startswith('C') and len(body) > 1 and (body[1].isdigit() or body[1] in '.-+'):
        return _parse_tcm(body)
    raise NmeaError('unknown', f'not an attitude sentence: {body.split(",")[0][:12]!r}')


def _parse_hpr(body: str) -> AttitudeReading:
    f = body.split(',')
    if len(f) != 7:
        raise NmeaError('format', f'PTNTHPR needs 6 fields, got {len(f) - 1}')
    heading = _number(f[1], 'heading') if f[1] else None
    pitch = _number(f[3], 'pitch')
    roll = _number(f[5], 'roll')
    st = [s[:1] if s else '' for s in (f[2], f[4], f[6])]
    _check_ranges(heading, pitch, roll)
    flags = (st[0] != 'N', st[1] != 'N', st[2] != 'N')
    return AttitudeReading('PTNTHPR', heading, pitch, roll, flags, ''.join(s or '-' for s in st))


def _parse_tcm(body: str) -> AttitudeReading:
    fields: dict[str, str] = {}
    pos = 0
    for m in _TCM_FIELD.finditer(body):
        if m.start() != pos:
            raise NmeaError('format', f'unexpected text in TCM sentence at {pos}')
        key, value = (m.group(1), m.group(2)) if m.group(1) else (m.group(3), m.group(4))
        if key not in _TCM_KEYS or not value:
            raise NmeaError('format', f'TCM field {key!r} unknown or empty')
        if key in fields:
            raise NmeaError('format', f'TCM field {key} twice')
        fields[key] = value
        pos = m.end()
    if pos != len(body):
        raise NmeaError('format', 'trailing text in TCM sentence')
    for key in 'CPR':
        if key not in fields or not fields[key]:
            raise NmeaError('format', f'TCM sentence has no {key} field')
    heading = _number(fields['C'], 'heading')
    pitch = _number(fields['P'], 'pitch')
    roll = _number(fields['R'], 'roll')
    _check_ranges(heading, pitch, roll)
    code = fields.get('E', '')
    try:
        err = int(code, 16) if code else 0
    except ValueError:
        raise NmeaError('format', f'TCM error code is not hex: {code!r}') from None
    return AttitudeReading('TCM', heading, pitch, roll, (err != 0, False, False), code)


def _check_ranges(heading, pitch, roll) -> None:
    if heading is not None and not (-360.0 <= heading <= 360.0):
        raise NmeaError('format', f'heading {heading} out of range')
    if not (-90.0 <= pitch <= 90.0):
        raise NmeaError('format', f'pitch {pitch} out of range')
    if not (-180.0 <= roll <= 180.0):
        raise NmeaError('format', f'roll {roll} out of range')


class LineSplitter:
    """Cuts a byte stream into text lines (ends: CR, LF or CRLF). Bytes that are not
    ASCII become '?' (the checksum then fails); a line longer than ``MAX_LINE`` without
    an end is dropped (counted in ``overflows``)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.overflows = 0

    def feed(self, data: bytes) -> list[str]:
        """Add bytes; return the complete, non-empty lines they finish."""
        self._buf.extend(data)
        out = []
        while True:
            ends = [i for i in (self._buf.find(b'\n'), self._buf.find(b'\r')) if i >= 0]
            if not ends:
                break
            i = min(ends)
            raw = bytes(self._buf[:i])
            del self._buf[:i + 1]
            if raw:
                out.append(raw.decode('ascii', 'replace'))
        if len(self._buf) > MAX_LINE:
            keep = self._buf.rfind(b'$')
            self._buf = self._buf[keep:] if 0 <= keep and len(self._buf) - keep <= MAX_LINE \
                else bytearray()
            self.overflows += 1
        return out

    def reset(self) -> None:
        """Forget a partial line (after a reconnect)."""
        self._buf.clear()


@dataclass(frozen=True)
class CompassConfig:
    """compass_node: the serial device, its sentence conventions and the published Imu.
    Frozen; validated on construction."""

    port: str = param('/dev/ttyUSB0', 'serial device of the compass/inclinometer')
    baud: int = param(19200, 'serial speed, baud', range=(300, 4000000))
    protocol: str = param('auto', 'sentence family accepted: auto (both), ptnthpr '
                          '($PTNTHPR, True North / Honeywell) or tcm ($C..P..R.., PNI '
                          'TCM)', choices=('auto', 'ptnthpr', 'tcm'))
    require_checksum: bool = param(True, 'reject sentences without a valid *hh checksum')
    frame_id: str = param('inclinometer_link', 'frame id of the published Imu')
    sigma_deg: float = param(0.5, 'standard deviation of each published angle, degrees '
                             '(orientation_covariance diagonal)', range=(0.001, 90.0))
    flagged_sigma_deg: float = param(5.0, 'standard deviation of an angle the device flags '
                                     'as not normal, degrees', range=(0.001, 180.0))
    yaw_zero: str = param('east', 'yaw reference: east (REP 103 ENU: yaw = 90 deg - '
                          'heading) or north (yaw = -heading, counter-clockwise from the '
                          'heading reference)', choices=('east', 'north'))
    declination_deg: float = param(0.0, 'magnetic declination added to the heading '
                                   '(east positive), degrees', range=(-180.0, 180.0))
    pitch_convention: str = param('nose_up_positive', "the device's pitch sign",
                                  choices=('nose_up_positive', 'nose_down_positive'))
    roll_convention: str = param('right_down_positive', "the device's roll sign",
                                 choices=('right_down_positive', 'left_down_positive'))
    mount_roll_deg: float = param(0.0, 'rotation from the device frame to inclinometer_link '
                                  '(REP 103 roll), degrees', range=(-180.0, 180.0))
    mount_pitch_deg: float = param(0.0, 'rotation from the device frame to '
                                   'inclinometer_link (REP 103 pitch; e.g. 20 for a level '
                                   'device and cameras tilted 20 deg down), degrees',
                                   range=(-90.0, 90.0))
    mount_yaw_deg: float = param(0.0, 'rotation from the device frame to inclinometer_link '
                                 '(REP 103 yaw), degrees', range=(-180.0, 180.0))
    latency: float = param(0.0, 'subtracted from the arrival time of a sentence for its '
                           'stamp, s', range=(0.0, 5.0))
    timeout: float = param(1.0, 'no valid sentence for this long: diagnostics WARN, s',
                           range=(0.05, 60.0))
    reconnect_period: float = param(1.0, 'wait between attempts to (re)open the port, s',
                                    range=(0.05, 60.0))

    def __post_init__(self) -> None:
        check_fields(self)


def accepts(config: CompassConfig, reading: AttitudeReading) -> bool:
    """Whether the configured protocol takes this sentence family."""
    return config.protocol == 'auto' or config.protocol == reading.kind.lower()


def to_rep103(reading: AttitudeReading, config: CompassConfig
              ) -> tuple[np.ndarray, np.ndarray]:
    """REP 103 roll, pitch, yaw (rad) of inclinometer_link in the world and the three
    angle variances (rad^2).

    The device's attitude is R_world_device = R(roll_rep, pitch_rep, yaw); the mount
    rotation gives R_world_link = R_world_device R(mount). A missing heading gives yaw 0
    with variance (2 pi)^2 (unknown); flagged angles get ``flagged_sigma_deg``.
    """
    roll = math.radians(reading.roll_deg)
    if config.roll_convention == 'left_down_positive':
        roll = -roll
    pitch = math.radians(reading.pitch_deg)
    if config.pitch_convention == 'nose_up_positive':
        pitch = -pitch
    if reading.heading_deg is None:
        yaw = 0.0
    else:
        heading = math.radians(reading.heading_deg + config.declination_deg)
        yaw = (0.5 * math.pi - heading) if config.yaw_zero == 'east' else -heading
    yaw = wrap_angle(float(yaw))
    mount = np.radians([config.mount_roll_deg, config.mount_pitch_deg, config.mount_yaw_deg])
    if np.any(mount != 0.0):
        rpy = matrix_to_rpy(rpy_to_matrix(np.array([roll, pitch, yaw])) @ rpy_to_matrix(mount))
    else:
        rpy = np.array([roll, pitch, yaw])
    sig = np.full(3, math.radians(config.sigma_deg))
    flagged = math.radians(config.flagged_sigma_deg)
    hf, pf, rf = reading.flags
    if rf:
        sig[0] = max(sig[0], flagged)
    if pf:
        sig[1] = max(sig[1], flagged)
    if hf:
        sig[2] = max(sig[2], flagged)
    var = sig * sig
    if reading.heading_deg is None:
        var[2] = (2.0 * math.pi) ** 2
    return rpy, var


def format_ptnthpr(heading: float, pitch: float, roll: float, status: str = 'NNN',
                   checksum_override: int | None = None) -> str:
    """A ``$PTNTHPR`` line (with CRLF) as a device would send it (for tests and
    simulators)."""
    body = (f'PTNTHPR,{heading:.1f},{status[0]},{pitch:.1f},{status[1]},'
            f'{roll:.1f},{status[2]}')
    cs = checksum(body) if checksum_override is None else checksum_override
    return f'${body}*{cs:02X}\r\n'


def format_tcm(heading: float, pitch: float, roll: float, error: str = '',
               checksum_override: int | None = None) -> str:
    """A TCM ``$C..P..R..`` line (with CRLF), temperature 22.0 C, optional error code."""
    body = f'C{heading:.1f}P{pitch:.1f}R{roll:.1f}T22.0' + (f'E{error}' if error else '')
    cs = checksum(body) if checksum_override is None else checksum_override
    return f'${body}*{cs:02X}\r\n'
