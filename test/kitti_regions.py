"""Image regions of the KITTI road sequence in ../shared/data (1241 x 376, f = 718.9 px),
shared by the tests that run it (test_kitti.py: the core detector; test_kitti_run.py: the
node graph).

The regions were read off debug images (core.draw.draw_debug) of the sequence; the car
drives straight along its lane, so the painted lane stays in the same image region.
"""
import numpy as np

from conftest import SHARED

KITTI = SHARED / 'data' / 'kitti_road_seq'

NEAR_ROW = 230          # image rows of the near road start here (about < 25 m)


def require_kitti() -> None:
    """Fail (not skip) when the sequence is missing: it ships beside the project."""
    assert (KITTI / 'calib.txt').is_file(), f'the KITTI sequence is missing: {KITTI}'


def lane_left(v):
    """Left edge (u, px) of the hatched marking zone at image row v."""
    return 545.0 + (235.0 - 545.0) * (np.asarray(v, float) - 195.0) / (376.0 - 195.0)


def lane_right(v):
    """Right edge (u, px) of the ego lane (the lane line before the kerb) at row v."""
    return 612.0 + (780.0 - 612.0) * (np.asarray(v, float) - 195.0) / (376.0 - 195.0)


def in_painted_road(u, v):
    """Whether image points lie on the near painted road (lane, hatching, arrows)."""
    v = np.asarray(v, float)
    u = np.asarray(u, float)
    return (v >= NEAR_ROW) & (u > lane_left(v)) & (u < lane_right(v))


def foot_pixel(position, height, normal_up, cam):
    """(u, v) left-image point of the foot on the ground of obstacles whose tops are at
    ``position`` ((3,) or (N, 3), left optical frame) ``height`` above the ground plane of
    unit normal ``normal_up``: the top moved down the plane's normal, projected."""
    foot = (np.asarray(position, float)
            - np.asarray(height, float)[..., None] * np.asarray(normal_up, float))
    return (cam.f * foot[..., 0] / foot[..., 2] + cam.cx,
            cam.f * foot[..., 1] / foot[..., 2] + cam.cy)


def is_kerb(u, v, height) -> bool:
    """A low obstacle (the kerb, 10-20 cm) whose foot (u, v) is right of the lane line."""
    return bool(v >= 240 and lane_right(v) < u < lane_right(v) + 250 and 0.04 < height < 0.4)


def is_car_left(roi, range_m, height) -> bool:
    """An obstacle of the car passing on the left: its box (x, y, w, h) centred left of
    u = 330 on the rows of the car, within 10 m, over 25 cm high."""
    x, y, w, h = roi
    return bool(x + w / 2 < 330 and 180 < y + h / 2 < 340 and range_m < 10 and height > 0.25)
