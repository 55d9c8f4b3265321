"""Tests of core.alignment: the rectified pair's vertical misalignment, measured on
simulated rigs turned off their calibration, and its correction (no ROS)."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from asmonc_vision.core.alignment import (AlignmentConfig, VerticalAlignment,
                                          brightness_gain_offset, corner_displacement_steps,
                                          corner_displacements, fit_misalignment,
                                          matched_brightness)
from asmonc_vision.core.config import override
from asmonc_vision.core.gpod import GpodConfig, GpodDetector
from asmonc_vision.sim import RigSettings
from asmonc_vision.sim.scenarios import make_scenario, simulate_frame


def _frames(scenario: str, seed: int, ks, **rig):
    sc = make_scenario(scenario, seed=seed, rig=RigSettings(**rig))
    return sc, [simulate_frame(sc, k) for k in ks]


def _truth_dv(rig: RigSettings, u: np.ndarray) -> np.ndarray:
    """The rows' displacement at right-image columns u of a rig turned off its
    calibration, to first order: f * tilt - f * roll * x."""
    x = (u - rig.cx) / rig.focal
    return (rig.focal * np.tan(np.radians(rig.right_tilt_deg))
            - rig.focal * np.radians(rig.right_roll_deg) * x)


def test_config_is_validated():
    with pytest.raises(ValueError, match='every_frames'):
        AlignmentConfig(every_frames=0)
    with pytest.raises(ValueError, match='min_matches'):
        AlignmentConfig(max_corners=10, min_matches=20)


def test_fit_recovers_offset_and_roll_and_ignores_outliers():
    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(0, 320, 120), rng.uniform(0, 240, 120)])
    dv = 0.6 - 1.5 * (pts[:, 0] - 160) / 300 + rng.normal(0, 0.05, 120)
    dv[:10] += 3.0                                    # mismatches
    m = fit_misalignment(pts, dv, 300.0, 160.0)
    assert m is not None and m.matches == 120
    assert m.p == pytest.approx([0.6, -1.5], abs=0.05)
    assert np.all(np.sqrt(np.diag(m.cov)) < 0.1)
    assert fit_misalignment(pts[:3], dv[:3], 300.0, 160.0) is None


def _sides_px(left, right, rig) -> np.ndarray:
    """One pair's measured misalignment at the image's left and right edges, pixels."""
    p, disp = corner_displacements(left, right)
    m = fit_misalignment(p + disp, disp[:, 1], rig.focal, rig.cx)
    return m.p[0] + m.p[1] * (np.array([0.0, rig.width - 1.0]) - rig.cx) / rig.focal


@pytest.mark.parametrize('tilt,roll', [(0.25, 0.0), (-0.2, 0.3), (0.1, 0.0)])
@pytest.mark.slow
def test_a_turned_right_camera_is_measured_and_corrected(tilt, roll):
    sc, frames = _frames('static_obstacles', 31, range(0, 30, 3),
                         right_tilt_deg=tilt, right_roll_deg=roll)
    rig = sc.rig
    al = VerticalAlignment()
    for f in frames:
        al.update(f.left, f.right, rig.focal, rig.cx, rig.cy)
    sides = np.array([0.0, rig.width - 1.0])
    dv, sd = al.sides_px()
    assert dv == pytest.approx(_truth_dv(rig, sides), abs=0.15)
    assert np.all(sd < 0.1) and al.settled()
    assert al.wanted()
    f = frames[-1]
    assert np.max(np.abs(_sides_px(f.left, f.right, rig))) > 0.4
    assert np.max(np.abs(_sides_px(f.left, al.correct(f.right), rig))) < 0.15


def test_matched_brightness_undoes_a_gain_and_an_offset():
    rng = np.random.default_rng(6)
    left = np.clip(rng.normal(110, 30, (60, 80)), 0, 255).astype(np.uint8)
    right = np.clip(np.rint(1.4 * left.astype(float) - 20), 0, 255).astype(np.uint8)
    back = matched_brightness(left, right).astype(float)
    assert np.abs(back - left).mean() < 1.0
    flat = np.full((60, 80), 90, np.uint8)
    assert matched_brightness(left, flat) is flat          # nothing to scale


def test_matched_brightness_is_the_gain_and_offset_rounded_and_clipped():
    """The table of grey levels gives every pixel gain * right + offset rounded and
    clipped, as computed pixel by pixel (float64)."""
    rng = np.random.default_rng(7)
    left = rng.integers(0, 256, (48, 64)).astype(np.uint8)
    for gain, offset in ((1.4, -20.0), (0.55, 30.0), (2.5, 3.0)):
        right = np.clip(np.rint((left - offset) / gain), 0, 255).astype(np.uint8)
        go = brightness_gain_offset(left, right)
        assert go is not None
        want = np.clip(np.rint(right * go[0] + go[1]), 0, 255).astype(np.uint8)
        np.testing.assert_array_equal(matched_brightness(left, right), want)


@pytest.mark.parametrize('gain,offset', [(1.05, 4.0), (1.5, -25.0), (0.7, 15.0)])
@pytest.mark.slow
def test_the_cameras_exposures_do_not_bias_the_measurement(gain, offset):
    """Two cameras with their own gain and black level (the simulator's default is 1.05
    and +4 grey levels) on a well-rectified rig, in the scene that biased the measurement
    most (a walk that starts facing a wall, where the ground meets it): measured within
    0.1 px of zero, and nothing corrected. Lucas-Kanade on the raw pair measured 0.55 px
    there at the default exposures, and matched no corner at all at the others."""
    sc, frames = _frames('walk_stop_turn', 9016, range(0, 30, 3), right_gain=gain,
                         right_offset=offset)
    rig = sc.rig
    al = VerticalAlignment(AlignmentConfig(every_frames=1))
    for f in frames:
        al.update(f.left, f.right, rig.focal, rig.cx, rig.cy)
    assert al.measurements >= len(frames) - 1
    dv, _ = al.sides_px()
    assert np.all(np.abs(dv) < 0.1), dv
    assert not al.wanted()


@pytest.mark.slow
def test_a_well_rectified_rig_is_left_untouched():
    """No correction, and the detector's output is bit for bit that without the check."""
    sc, frames = _frames('static_obstacles', 32, range(0, 36, 2))
    on = GpodDetector(GpodConfig())
    off = GpodDetector(override(GpodConfig(), {'image.align_vertical': False}))
    cam = sc.rig.camera()
    h_on, h_off = hashlib.sha1(), hashlib.sha1()
    for f in frames:
        r_on = on.process(f.left, f.right, cam)
        r_off = off.process(f.left, f.right, cam)
        for r, h in ((r_on, h_on), (r_off, h_off)):
            for o in r.obstacles:
                h.update(np.round([o.range, o.bearing, o.height, o.confidence], 6).tobytes())
        assert not r_on.misalignment_corrected
        assert r_on.misalignment_px < 0.2
        assert np.isnan(r_off.misalignment_px)
    assert h_on.hexdigest() == h_off.hexdigest()
    assert on.alignment.measurements < len(frames)       # settled: measured 1 pair in 5


@pytest.mark.slow
def test_the_correction_brings_the_obstacle_threshold_back():
    """A misalignment raises the ground's disparity spread and the obstacle threshold
    taken from it; corrected, the spread is taken again and is that of the well-rectified
    rig."""
    sigma = {}
    # the turned rig's pairs rendered once, seen with and without the correction
    rendered = {tilt: _frames('clear_static', 33, range(10), right_tilt_deg=tilt)
                for tilt in (0.0, 0.2)}
    for name, tilt, align in (('good', 0.0, True), ('turned', 0.2, False),
                              ('corrected', 0.2, True)):
        sc, frames = rendered[tilt]
        det = GpodDetector(override(GpodConfig(), {'image.align_vertical': align}))
        res = [det.process(f.left, f.right, sc.rig.camera()) for f in frames]
        assert res[-1].status == 'tracking'
        sigma[name] = res[-1].sigma_px
        assert res[-1].misalignment_corrected == (name == 'corrected')
    assert sigma['turned'] > 1.2 * sigma['good'], sigma
    assert sigma['corrected'] < 1.1 * sigma['good'], sigma


def test_a_bumped_rig_is_followed():
    """A rig that changes (a bump) restarts the estimate after a few pairs that disagree."""
    al = VerticalAlignment(AlignmentConfig(every_frames=1))
    rng = np.random.default_rng(5)
    left = (rng.uniform(0, 255, (120, 160))).astype(np.uint8)
    import cv2
    left = cv2.GaussianBlur(left, (0, 0), 1.5)
    for dv_true, n in ((0.0, 6), (1.0, 6)):
        m = np.float32([[1, 0, -4], [0, 1, dv_true]])       # right = left 4 px over, dv down
        right = cv2.warpAffine(left, m, (160, 120), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_REFLECT)
        for _ in range(n):
            al.update(left, right, 150.0, 79.5, 59.5)
        assert al.sides_px()[0] == pytest.approx([dv_true, dv_true], abs=0.1)


def _textured_pairs(n: int, dv_true: float, seed: int = 7):
    """n synthetic pairs: a blurred random texture (its grain changes each pair) and its
    copy 4 px over and dv_true px down (160x120)."""
    import cv2
    rng = np.random.default_rng(seed)
    base = rng.uniform(0, 255, (120, 160))
    pairs = []
    for _ in range(n):
        left = cv2.GaussianBlur(base + rng.normal(0, 20, base.shape), (0, 0), 1.5)
        left = np.clip(left, 0, 255).astype(np.uint8)
        m = np.float32([[1, 0, -4], [0, 1, dv_true]])
        pairs.append((left, cv2.warpAffine(left, m, (160, 120), flags=cv2.INTER_LINEAR,
                                           borderMode=cv2.BORDER_REFLECT)))
    return pairs


def test_a_spread_measurement_is_the_same_a_few_pairs_later():
    """Once settled, a measurement done in steps over the following pairs leaves the filter
    exactly where measuring it all at once does (its corners' result is the same bit for
    bit however the second pass is chunked); it only arrives later, and every due pair
    is still measured."""
    pairs = _textured_pairs(40, 0.6)
    left, right = pairs[0]
    whole = corner_displacements(left, right, 60)
    yields = []
    for chunk in (1, 7, 60):
        steps = corner_displacement_steps(left, right, 60, 5.0, 0.25, chunk)
        n = 0
        while True:
            try:
                next(steps)
                n += 1
            except StopIteration as done:
                pts, disp = done.value
                break
        yields.append(n)
        assert np.array_equal(pts, whole[0]) and np.array_equal(disp, whole[1])
    assert yields[0] > yields[1] > yields[2] == 2 and len(whole[0]) >= 20
    at_once = VerticalAlignment(AlignmentConfig(spread=False, every_frames=8))
    spread = VerticalAlignment(AlignmentConfig(spread=True, every_frames=8,
                                               chunk_corners=60))
    running = compared = 0
    for left, right in pairs:
        at_once.update(left, right, 150.0, 79.5, 59.5)
        spread.update(left, right, 150.0, 79.5, 59.5)
        if spread._job is not None:
            running += 1
            continue
        compared += 1
        assert np.array_equal(spread.x, at_once.x) and np.array_equal(spread.P, at_once.P)
        assert spread.measurements == at_once.measurements
    assert running >= 8 and compared >= 20 and at_once.measurements >= 8
