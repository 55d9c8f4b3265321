"""`asmonc images-bag`: a contract bag from a folder of stereo pairs (io/images_bag.py).

A small KITTI-like folder (colour images, calib.txt, times.txt) written here is turned
into a bag and read back: the topic contract's four topics per pair at one stamp, mono8
images equal to the capture node's grey conversion, CameraInfo with right P[0,3] = -f*B,
the rate of times.txt, each pair repeated; then the real KITTI sequence in ../shared/data
(which ships beside the project: its test fails when it is missing).
"""
from pathlib import Path

import cv2
import numpy as np
import pytest

from asmonc_vision.io import bagio
from asmonc_vision.io.images_bag import folder_rate, write_images_bag
from asmonc_vision.cli.main import main as asmonc_main

from conftest import SHARED

F, CX, CY = 700.0, 40.0, 30.0
TX2, TX3 = 40.0, -330.0                  # P[0,3] of cameras 2 and 3 (relative to camera 0)
KITTI = SHARED / 'data' / 'kitti_road_seq'


def _calib_text() -> str:
    def row(name, tx):
        vals = [F, 0, CX, tx, 0, F, CY, 0, 0, 0, 1, 0]
        return f'{name}: ' + ' '.join(f'{x:.6e}' for x in vals)
    return '\n'.join([row('P0', 0.0), row('P1', -380.0), row('P2', TX2), row('P3', TX3)]) + '\n'


def _folder(root: Path, n: int = 3, period: float = 0.1036) -> list[np.ndarray]:
    """image_2/ + image_3/ colour pairs, calib.txt, times.txt; returns the left BGR images."""
    rng = np.random.default_rng(7)
    (root / 'image_2').mkdir(parents=True)
    (root / 'image_3').mkdir()
    lefts = []
    for k in range(n):
        left = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
        cv2.imwrite(str(root / 'image_2' / f'{k:06d}.png'), left)
        cv2.imwrite(str(root / 'image_3' / f'{k:06d}.png'), np.roll(left, -6, axis=1))
        lefts.append(left)
    (root / 'calib.txt').write_text(_calib_text())
    (root / 'times.txt').write_text(''.join(f'{k * period:.6e}\n' for k in range(n)))
    return lefts


def _read(bag: Path) -> dict:
    out: dict = {}
    topics = [bagio.TOPICS[k][0] for k in ('left_info', 'right_info', 'left_image',
                                            'right_image')]
    for topic, t, msg in bagio.read_messages(bag, topics):
        assert bagio.header_stamp_ns(msg) == t
        out.setdefault(topic, []).append(msg)
    return out


def test_folder_becomes_a_contract_bag(tmp_path):
    lefts = _folder(tmp_path / 'seq')
    bag = write_images_bag(tmp_path / 'seq', tmp_path / 'bag', start=1, count=2, repeat=3)
    assert (bag.frames, bag.pairs, bag.size) == (6, 2, (80, 60))
    assert bag.fps == pytest.approx(1 / 0.1036)
    assert bag.baseline == pytest.approx((TX2 - TX3) / F)
    msgs = _read(tmp_path / 'bag')
    li, ri = msgs['/stereo/left/camera_info'], msgs['/stereo/right/camera_info']
    limg, rimg = msgs['/stereo/left/image_rect'], msgs['/stereo/right/image_rect']
    assert len(li) == len(ri) == len(limg) == len(rimg) == 6
    stamps = [bagio.header_stamp_ns(m) for m in limg]
    assert stamps == [bagio.header_stamp_ns(m) for m in rimg]          # a pair shares a stamp
    assert stamps == [bagio.header_stamp_ns(m) for m in li]
    assert np.allclose(np.diff(stamps), 1e9 * 0.1036, atol=1)
    p_right = np.asarray(ri[0].p).reshape(3, 4)
    assert p_right[0, 3] == pytest.approx(-F * (TX2 - TX3) / F)         # -f*B
    assert np.asarray(li[0].p).reshape(3, 4)[0, 3] == 0.0
    assert (li[0].width, li[0].height) == (80, 60)
    for k, m in enumerate(limg):
        assert m.encoding == 'mono8' and m.step == 80
        img = np.asarray(m.data, np.uint8).reshape(60, 80)
        # pairs 1 and 2, each three times, grey as the capture node reads them
        grey = cv2.imread(str(tmp_path / 'seq' / 'image_2' / f'{1 + k // 3:06d}.png'),
                          cv2.IMREAD_GRAYSCALE)
        assert np.array_equal(img, grey)
        assert abs(int(img[5, 5]) - int(cv2.cvtColor(lefts[1 + k // 3],
                                                     cv2.COLOR_BGR2GRAY)[5, 5])) <= 1
    assert limg[0].header.frame_id == 'stereo_left_optical_frame'
    assert rimg[0].header.frame_id == 'stereo_right_optical_frame'


def test_cli_refuses_what_it_cannot_use(tmp_path, capsys):
    assert asmonc_main(['images-bag', str(tmp_path / 'missing'), str(tmp_path / 'b')]) == 2
    assert 'does not exist' in capsys.readouterr().err
    _folder(tmp_path / 'seq', n=2)
    (tmp_path / 'seq' / 'calib.txt').unlink()
    assert asmonc_main(['images-bag', str(tmp_path / 'seq'), str(tmp_path / 'b')]) == 2
    assert 'calib.txt' in capsys.readouterr().err
    assert folder_rate(tmp_path / 'seq') == pytest.approx(1 / 0.1036)
    (tmp_path / 'seq' / 'times.txt').unlink()
    assert folder_rate(tmp_path / 'seq') == 10.0


def test_kitti_sequence_bag(tmp_path, capsys):
    assert (KITTI / 'calib.txt').is_file(), f'the KITTI sequence is missing: {KITTI}'
    assert asmonc_main(['images-bag', str(KITTI), str(tmp_path / 'k'), '--count', '1',
                        '--repeat', '2']) == 0
    assert '2 stereo pairs' in capsys.readouterr().out
    msgs = _read(tmp_path / 'k')
    info = msgs['/stereo/right/camera_info'][0]
    p = np.asarray(info.p).reshape(3, 4)
    assert (info.width, info.height) == (1241, 376)
    assert p[0, 0] == pytest.approx(718.856)
    assert -p[0, 3] / p[0, 0] == pytest.approx(0.532, abs=0.001)         # B, metres
    img = np.asarray(msgs['/stereo/left/image_rect'][1].data, np.uint8).reshape(376, 1241)
    assert np.array_equal(img, cv2.imread(str(KITTI / 'image_2' / '000000.png'),
                                          cv2.IMREAD_GRAYSCALE))
