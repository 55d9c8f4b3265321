"""Stereo capture core (no ROS): calibration files, rectification, frame sources."""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from asmonc_vision.core.capture import (CalibrationError, CaptureConfig, DevicePairSource,
                                        FolderSource, FrameSizeError, SideBySideSource,
                                        SourceEnded, SourceError, StereoCalibration,
                                        StereoRectifier, load_calibration,
                                        load_kitti_projections, make_rectifier, make_source,
                                        split_side_by_side, write_opencv_calibration)

REPO = Path(__file__).resolve().parent.parent

#: the calibration rows of the KITTI sequence in shared/data (cameras 2 and 3)
KITTI_ROWS = {
    'P0': (718.856, 0, 607.1928, 0.0, 0, 718.856, 185.2157, 0.0, 0, 0, 1, 0.0),
    'P1': (718.856, 0, 607.1928, -386.1448, 0, 718.856, 185.2157, 0.0, 0, 0, 1, 0.0),
    'P2': (718.856, 0, 607.1928, 45.38225, 0, 718.856, 185.2157, -0.1130887, 0, 0, 1,
           0.003779761),
    'P3': (718.856, 0, 607.1928, -337.2877, 0, 718.856, 185.2157, 2.369057, 0, 0, 1,
           0.004915215),
}
KITTI_CALIB = ''.join(f'{name}: ' + ' '.join(f'{v:.12e}' for v in row) + '\n'
                      for name, row in KITTI_ROWS.items())
KITTI_F = 718.856
KITTI_B = (45.38225 + 337.2877) / 718.856  # 0.5323 m


def kitti_dir() -> Path | None:
    """The KITTI sequence shipped in shared/data, if this checkout has it."""
    for cand in (os.environ.get('ASMONC_KITTI_DIR', ''),
                 REPO.parent / 'shared' / 'data' / 'kitti_road_seq'):
        if cand and (Path(cand) / 'calib.txt').is_file():
            return Path(cand)
    return None


# --- a synthetic raw stereo rig ------------------------------------------------------------

W, H = 640, 480
K1 = np.array([[500.0, 0, 320], [0, 505.0, 236], [0, 0, 1]])
K2 = np.array([[510.0, 0, 330], [0, 508.0, 244], [0, 0, 1]])
D1 = np.array([-0.12, 0.03, 0.001, -0.001, 0.0])
D2 = np.array([-0.09, 0.02, -0.001, 0.001, 0.0])
R = cv2.Rodrigues(np.array([0.025, -0.04, 0.015]))[0]   # right camera rotated ~2.8 deg
T = np.array([-0.30, 0.012, 0.006])                       # right camera 0.3 m to the right
POINTS = np.array([[0.3, -0.2, 3.0], [-0.5, 0.4, 2.0], [0.0, 0.0, 5.0], [0.6, 0.45, 2.5],
                   [-0.7, -0.5, 4.0]])


def synthetic_calibration() -> StereoCalibration:
    return StereoCalibration(k1=K1, d1=D1, k2=K2, d2=D2, r=R, t=T, width=W, height=H)


def raw_pixels(x: np.ndarray):
    """Pixel of a left-frame point in the raw left and right images."""
    pl = cv2.projectPoints(x.reshape(1, 3), np.zeros(3), np.zeros(3), K1, D1)[0].reshape(2)
    pr = cv2.projectPoints(x.reshape(1, 3), cv2.Rodrigues(R)[0], T, K2, D2)[0].reshape(2)
    return pl, pr


def blob(p, sigma=1.6) -> np.ndarray:
    """A bright Gaussian dot at sub-pixel position p = (u, v) on black."""
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    img = 250.0 * np.exp(-((uu - p[0]) ** 2 + (vv - p[1]) ** 2) / (2 * sigma ** 2))
    return img.astype(np.uint8)


def centroid(img: np.ndarray):
    v, u = np.unravel_index(np.argmax(img), img.shape)
    win = img[v - 4:v + 5, u - 4:u + 5].astype(float)
    vv, uu = np.mgrid[v - 4:v + 5, u - 4:u + 5]
    return (uu * win).sum() / win.sum(), (vv * win).sum() / win.sum()


def test_rectification_aligns_rows_and_gives_the_right_disparity():
    rect = StereoRectifier.from_stereo_calibration(synthetic_calibration())
    baseline = float(np.linalg.norm(T))
    assert rect.baseline == pytest.approx(baseline, rel=1e-6)
    assert rect.p_right[0, 3] == pytest.approx(-rect.f * baseline)
    assert rect.p_left[0, 3] == 0.0
    assert rect.remaps
    raw_row_error = 0.0
    for x in POINTS:
        pl, pr = raw_pixels(x)
        raw_row_error = max(raw_row_error, abs(pl[1] - pr[1]))
        left, right = rect.rectify(blob(pl), blob(pr))
        assert left.dtype == np.uint8 and left.shape == (H, W)
        ul, vl = centroid(left)
        ur, vr = centroid(right)
        assert abs(vl - vr) < 0.25, (x, vl, vr)
        z = (rect.r_left @ x)[2]  # depth in the rectified left frame
        assert ul - ur == pytest.approx(rect.f * baseline / z, abs=0.3)
        # the rectified left pixel is the projection with P_left
        q = rect.p_left @ np.append(rect.r_left @ x, 1.0)
        assert (ul, vl) == pytest.approx((q[0] / q[2], q[1] / q[2]), abs=0.3)
    # the rig is really misaligned: the raw rows disagree by pixels
    assert raw_row_error > 5.0


def test_opencv_calibration_file_round_trip(tmp_path):
    path = tmp_path / 'stereo.yaml'
    write_opencv_calibration(path, synthetic_calibration())
    assert path.read_text().startswith('%YAML:1.0')
    rect = load_calibration(path)
    ref = StereoRectifier.from_stereo_calibration(synthetic_calibration())
    np.testing.assert_allclose(rect.p_left, ref.p_left)
    np.testing.assert_allclose(rect.p_right, ref.p_right)
    assert (rect.width, rect.height) == (W, H)


def test_plain_yaml_calibration(tmp_path):
    path = tmp_path / 'stereo_plain.yaml'
    path.write_text(yaml.safe_dump({
        'image_size': [W, H], 'K1': K1.tolist(), 'D1': D1.tolist(), 'K2': K2.tolist(),
        'D2': D2.tolist(), 'R': R.reshape(-1).tolist(), 'T': T.tolist()}))
    rect = load_calibration(path)
    assert rect.baseline == pytest.approx(np.linalg.norm(T))


def test_ros_camera_info_pair(tmp_path):
    ref = StereoRectifier.from_stereo_calibration(synthetic_calibration())

    def info(k, d, r, p):
        return {'image_width': W, 'image_height': H, 'camera_name': 'x',
                'camera_matrix': {'rows': 3, 'cols': 3, 'data': k.reshape(-1).tolist()},
                'distortion_model': 'plumb_bob',
                'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': d.tolist()},
                'rectification_matrix': {'rows': 3, 'cols': 3, 'data': r.reshape(-1).tolist()},
                'projection_matrix': {'rows': 3, 'cols': 4, 'data': p.reshape(-1).tolist()}}
    (tmp_path / 'left.yaml').write_text(yaml.safe_dump(info(K1, D1, ref.r_left, ref.p_left)))
    (tmp_path / 'right.yaml').write_text(yaml.safe_dump(info(K2, D2, ref.r_right, ref.p_right)))
    rect = load_calibration(tmp_path / 'left.yaml', tmp_path / 'right.yaml')
    np.testing.assert_allclose(rect.p_right, ref.p_right)
    pl, pr = raw_pixels(POINTS[0])
    (_, vl), (_, vr) = (centroid(i) for i in rect.rectify(blob(pl), blob(pr)))
    assert abs(vl - vr) < 0.25
    with pytest.raises(CalibrationError, match='right_calibration_file'):
        load_calibration(tmp_path / 'left.yaml')


def test_calibration_errors_are_clear(tmp_path):
    with pytest.raises(CalibrationError, match='does not exist'):
        load_calibration(tmp_path / 'nope.yaml')
    swapped = dataclasses.replace(synthetic_calibration(), t=-T)
    with pytest.raises(CalibrationError, match='swapped'):
        StereoRectifier.from_stereo_calibration(swapped)
    mm = dataclasses.replace(synthetic_calibration(), t=T * 1000.0)
    with pytest.raises(CalibrationError, match='millimetres'):
        StereoRectifier.from_stereo_calibration(mm)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('K1: [1, 2, 3]\n')
    with pytest.raises(CalibrationError, match='missing'):
        load_calibration(bad)


def test_size_mismatch_is_an_error_not_a_crash():
    rect = StereoRectifier.from_stereo_calibration(synthetic_calibration())
    with pytest.raises(FrameSizeError, match='640x480 but right is 320x240'):
        rect.rectify(np.zeros((480, 640), np.uint8), np.zeros((240, 320), np.uint8))
    with pytest.raises(FrameSizeError, match='calibration is for 640x480'):
        rect.rectify(np.zeros((240, 320), np.uint8), np.zeros((240, 320), np.uint8))


# --- side by side ----------------------------------------------------------------------------

def test_split_side_by_side():
    frame = np.zeros((4, 10, 3), np.uint8)
    frame[:, :5] = 10
    frame[:, 5:] = 200
    left, right = split_side_by_side(frame)
    assert left.shape == right.shape == (4, 5, 3)
    assert (left == 10).all() and (right == 200).all()
    with pytest.raises(FrameSizeError, match='even width'):
        split_side_by_side(np.zeros((4, 9), np.uint8))


# --- KITTI ----------------------------------------------------------------------------------

def test_kitti_calibration_gives_f_and_baseline(tmp_path):
    (tmp_path / 'calib.txt').write_text(KITTI_CALIB)
    pl, pr = load_kitti_projections(tmp_path / 'calib.txt', 'P2', 'P3')
    rect = load_calibration(tmp_path / 'calib.txt')
    assert rect.f == pytest.approx(KITTI_F)
    assert rect.baseline == pytest.approx(0.532, abs=0.001)
    assert rect.baseline == pytest.approx(KITTI_B, rel=1e-9)
    np.testing.assert_allclose(rect.p_left, pl)
    assert pl[0, 3] == 0.0 and pl[1, 3] == 0.0
    assert pr[0, 3] == pytest.approx(-KITTI_F * KITTI_B)
    assert not rect.remaps
    cam = rect.camera(1241, 376)
    assert cam.fb == pytest.approx(KITTI_F * KITTI_B)
    # cameras 0/1 (grey) have their own baseline
    rect01 = load_calibration(tmp_path / 'calib.txt', kitti_cameras=('P0', 'P1'))
    assert rect01.baseline == pytest.approx(386.1448 / 718.856)


def test_kitti_folder_source_gives_rectified_pairs():
    folder = kitti_dir()
    assert folder is not None, 'the KITTI sequence is missing: ../shared/data/kitti_road_seq'
    cfg = CaptureConfig(source='folder', folder=str(folder))
    ticks = iter(range(1_000, 1_000_000, 1_000))
    src = make_source(cfg, clock=lambda: next(ticks))
    assert isinstance(src, FolderSource)
    src.open()
    assert src.resolve_subdirs() == ('image_2', 'image_3')
    assert src.kitti_cameras() == ('P2', 'P3')
    rect = make_rectifier(cfg, src)
    assert rect.f == pytest.approx(KITTI_F)
    assert rect.baseline == pytest.approx(0.532, abs=0.001)
    n = len(src.pairs)
    assert n >= 3
    stamps = []
    for _ in range(3):
        frame = src.read()
        left, right = rect.rectify(frame.left, frame.right)
        assert left.shape == right.shape == (376, 1241) and left.dtype == np.uint8
        assert left.std() > 10  # a real picture, not blank
        assert not np.array_equal(left, right)
        stamps.append(frame.stamp_ns)
    assert stamps == sorted(stamps) and len(set(stamps)) == 3
    for _ in range(n - 3):
        src.read()
    with pytest.raises(SourceEnded):
        src.read()


def test_folder_source_pairs_by_name_and_loops(tmp_path):
    for side, value in (('left', 50), ('right', 100)):
        (tmp_path / side).mkdir()
        for k in range(3):
            cv2.imwrite(str(tmp_path / side / f'{k:04d}.png'),
                        np.full((8, 12), value + k, np.uint8))
    cv2.imwrite(str(tmp_path / 'left' / '9999.png'), np.zeros((8, 12), np.uint8))  # unpaired
    src = FolderSource(str(tmp_path), loop=True)
    src.open()
    assert len(src.pairs) == 3 and src.unpaired == 1
    values = [(int(f.left[0, 0]), int(f.right[0, 0])) for f in (src.read() for _ in range(4))]
    assert values == [(50, 100), (51, 101), (52, 102), (50, 100)]


def test_missing_folder_or_device_is_a_source_error(tmp_path):
    with pytest.raises(SourceError, match='does not exist'):
        FolderSource(str(tmp_path / 'nothing')).open()
    with pytest.raises(SourceError, match='no left/right image folders'):
        FolderSource(str(tmp_path)).open()
    with pytest.raises(SourceError, match="left camera '/nonexistent/cam0'"):
        DevicePairSource('/nonexistent/cam0', '/nonexistent/cam1').open()
    with pytest.raises(SourceError, match="stereo camera '/nonexistent/sbs'"):
        SideBySideSource('/nonexistent/sbs').open()


# --- video files as cameras ------------------------------------------------------------------

def _video(path: Path, values, size=(64, 48)) -> bool:
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 10.0, size)
    if not vw.isOpened():
        return False
    for v in values:
        vw.write(np.full((size[1], size[0], 3), v, np.uint8))
    vw.release()
    return True


def test_device_pair_source_pairs_frames_in_order(tmp_path):
    if not (_video(tmp_path / 'l.avi', [20, 60, 100, 140])
            and _video(tmp_path / 'r.avi', [40, 80, 120, 160])):
        pytest.skip('this OpenCV build cannot write MJPG video')
    ticks = iter(range(1, 100))
    src = DevicePairSource(str(tmp_path / 'l.avi'), str(tmp_path / 'r.avi'),
                           clock=lambda: next(ticks) * 1_000_000)
    assert not src.live
    src.open()
    got = []
    for _ in range(4):
        f = src.read()
        got.append((round(float(f.left.mean())), round(float(f.right.mean())), f.stamp_ns))
    values = [v for g in got for v in g[:2]]
    assert values == pytest.approx([20, 40, 60, 80, 100, 120, 140, 160], abs=3)
    assert [g[2] for g in got] == [1_000_000, 2_000_000, 3_000_000, 4_000_000]
    with pytest.raises(SourceEnded):
        src.read()
    src.close()
    looping = DevicePairSource(str(tmp_path / 'l.avi'), str(tmp_path / 'r.avi'), loop=True)
    looping.open()
    means = [round(float(looping.read().left.mean())) for _ in range(6)]
    assert means == pytest.approx([20, 60, 100, 140, 20, 60], abs=3)
    looping.close()


def test_side_by_side_source_splits_frames(tmp_path):
    path = tmp_path / 'sbs.avi'
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 10.0, (128, 48))
    if not vw.isOpened():
        pytest.skip('this OpenCV build cannot write MJPG video')
    for k in range(2):
        frame = np.zeros((48, 128, 3), np.uint8)
        frame[:, :64] = 30 + 50 * k
        frame[:, 64:] = 200 - 50 * k
        vw.write(frame)
    vw.release()
    cfg = CaptureConfig(source='side_by_side', stereo_device=str(path))
    src = make_source(cfg)
    src.open()
    f = src.read()
    assert f.left.shape[:2] == f.right.shape[:2] == (48, 64)
    assert float(f.left[4:-4, 4:-4].mean()) == pytest.approx(30, abs=4)
    assert float(f.right[4:-4, 4:-4].mean()) == pytest.approx(200, abs=4)
    src.close()


# --- settings -----------------------------------------------------------------------------

def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match=r'CaptureConfig.fps = 0.0 is out of range \[0.5, 120.0\]'):
        CaptureConfig(fps=0.0)
    with pytest.raises(ValueError, match='source'):
        CaptureConfig(source='webcam')
    with pytest.raises(ValueError, match='folder'):
        CaptureConfig(source='folder')


def test_missing_calibration_is_explained():
    with pytest.raises(CalibrationError, match='calibration_file'):
        make_rectifier(CaptureConfig())


def test_yaml_equals_dataclass_defaults():
    data = yaml.safe_load((REPO / 'config' / 'stereo_capture.yaml').read_text())
    params = data['stereo_capture_node']['ros__parameters']
    defaults = {f.name: f.default for f in dataclasses.fields(CaptureConfig)}
    assert params == defaults
    for k, v in params.items():
        assert type(v) is type(defaults[k]), k
