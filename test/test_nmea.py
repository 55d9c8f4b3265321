"""core.nmea: attitude sentences, checksums, line splitting, REP 103 conversion."""
import math

import numpy as np
import pytest

from asmonc_vision.core.gait.rotations import quaternion_to_rpy, rpy_to_quaternion
from asmonc_vision.core.nmea import (CompassConfig, LineSplitter, NmeaError, accepts,
                                     checksum, format_ptnthpr, format_tcm, parse_sentence,
                                     to_rep103)


def test_checksum_of_the_hmr3000_manual_example():
    line = '$PTNTHPR,85.9,N,-0.9,N,0.8,N*2C'
    assert checksum('PTNTHPR,85.9,N,-0.9,N,0.8,N') == 0x2C
    r = parse_sentence(line)
    assert (r.kind, r.heading_deg, r.pitch_deg, r.roll_deg) == ('PTNTHPR', 85.9, -0.9, 0.8)
    assert r.flags == (False, False, False)
    assert format_ptnthpr(85.9, -0.9, 0.8) == line + '\r\n'


def test_tcm_fields_any_order_and_error_code():
    body = 'C328.3P28.4R-12.5X55.11Y12.33Z-18.43T22.0E00A'
    r = parse_sentence(f'${body}*{checksum(body):02X}')
    assert (r.kind, r.heading_deg, r.pitch_deg, r.roll_deg) == ('TCM', 328.3, 28.4, -12.5)
    assert r.flags == (True, False, False) and r.status == '00A'
    r = parse_sentence(format_tcm(10.0, -5.0, 3.0))
    assert r.flags == (False, False, False)


@pytest.mark.parametrize('line, reason', [
    ('$PTNTHPR,85.9,N,-0.9,N,0.8,N*2D', 'checksum'),
    ('$PTNTHPR,85.9,N,-0.9,N,0.8,N', 'checksum'),
    ('$PTNTHPR,85.9,N,-0.9,N,0.8,N*Z1', 'checksum'),
    ('garbage without a dollar', 'format'),
    ('$PTNTHPR,abc,N,-0.9,N,0.8,N*' + format(checksum('PTNTHPR,abc,N,-0.9,N,0.8,N'), '02X'),
     'format'),
    ('$PTNTHPR,1,N,2,N*' + format(checksum('PTNTHPR,1,N,2,N'), '02X'), 'format'),
    ('$PTNTHPR,1,N,95,N,0,N*' + format(checksum('PTNTHPR,1,N,95,N,0,N'), '02X'), 'format'),
    ('$C1P2*' + format(checksum('C1P2'), '02X'), 'format'),
    ('$C1P2R3Q*' + format(checksum('C1P2R3Q'), '02X'), 'format'),
    ('$GPGGA,1,2*' + format(checksum('GPGGA,1,2'), '02X'), 'unknown'),
])
def test_bad_lines_raise_with_a_reason(line, reason):
    with pytest.raises(NmeaError) as e:
        parse_sentence(line)
    assert e.value.reason == reason


def test_garbage_before_the_sentence_and_optional_checksum():
    r = parse_sentence('\x00noise$PTNTHPR,85.9,N,-0.9,N,0.8,N*2C')
    assert r.heading_deg == 85.9
    r = parse_sentence('$PTNTHPR,85.9,N,-0.9,N,0.8,N', require_checksum=False)
    assert r.roll_deg == 0.8
    r = parse_sentence('$PTNTHPR,,N,1.0,N,2.0,L*' + format(
        checksum('PTNTHPR,,N,1.0,N,2.0,L'), '02X'))
    assert r.heading_deg is None and r.flags == (False, False, True)


def test_line_splitter_handles_any_line_end_and_runaway_garbage():
    s = LineSplitter()
    assert s.feed(b'$A*00\r\n$B') == ['$A*00']
    assert s.feed(b'*11\r$C*22\n\n') == ['$B*11', '$C*22']
    assert s.feed(b'\xff\xfe\r\n') == ['\ufffd\ufffd']
    s.feed(b'x' * 1000)
    assert s.overflows == 1 and s.feed(b'$D*33\n') == ['$D*33']


def test_rep103_conversion_signs_and_yaw_reference():
    c = CompassConfig()
    r = parse_sentence(format_ptnthpr(0.0, 10.0, 5.0))          # north, nose up, right down
    rpy, var = to_rep103(r, c)
    assert np.degrees(rpy) == pytest.approx([5.0, -10.0, 90.0])  # yaw CCW from east
    assert var == pytest.approx([math.radians(0.5) ** 2] * 3)
    rpy, _ = to_rep103(parse_sentence(format_ptnthpr(90.0, 0.0, 0.0)), c)
    assert math.degrees(rpy[2]) == pytest.approx(0.0, abs=1e-9)  # east = yaw 0
    rpy, _ = to_rep103(parse_sentence(format_ptnthpr(270.0, 0.0, 0.0)), c)
    assert abs(math.degrees(rpy[2])) == pytest.approx(180.0)
    north = CompassConfig(yaw_zero='north', declination_deg=10.0,
                          pitch_convention='nose_down_positive',
                          roll_convention='left_down_positive')
    rpy, _ = to_rep103(parse_sentence(format_ptnthpr(20.0, 10.0, 5.0)), north)
    assert np.degrees(rpy) == pytest.approx([-5.0, 10.0, -30.0])


def test_mount_rotation_and_flagged_variances():
    # a device mounted level on a rig whose cameras look 20 deg down
    c = CompassConfig(mount_pitch_deg=20.0, flagged_sigma_deg=4.0)
    r = parse_sentence(format_ptnthpr(90.0, 0.0, 0.0, status='NNO'))
    rpy, var = to_rep103(r, c)
    assert np.degrees(rpy) == pytest.approx([0.0, 20.0, 0.0], abs=1e-9)
    assert var[0] == pytest.approx(math.radians(4.0) ** 2)
    assert var[1] == pytest.approx(math.radians(0.5) ** 2)
    r = parse_sentence('$PTNTHPR,,N,1.0,N,2.0,N*' + format(
        checksum('PTNTHPR,,N,1.0,N,2.0,N'), '02X'))
    assert to_rep103(r, c)[1][2] == pytest.approx((2 * math.pi) ** 2)


def test_protocol_filter_and_settings_validation():
    hpr = parse_sentence(format_ptnthpr(1.0, 2.0, 3.0))
    tcm = parse_sentence(format_tcm(1.0, 2.0, 3.0))
    assert accepts(CompassConfig(), hpr) and accepts(CompassConfig(), tcm)
    assert not accepts(CompassConfig(protocol='tcm'), hpr)
    with pytest.raises(ValueError, match='protocol'):
        CompassConfig(protocol='nmea0183')
    with pytest.raises(ValueError, match='sigma_deg'):
        CompassConfig(sigma_deg=0.0)


def test_quaternion_round_trip():
    rpy = np.radians([3.0, 21.0, -135.0])
    q = rpy_to_quaternion(rpy)
    assert np.linalg.norm(q) == pytest.approx(1.0) and q[3] >= 0
    assert quaternion_to_rpy(q) == pytest.approx(rpy)
