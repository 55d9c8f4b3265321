"""GPOD on a real road: the KITTI odometry stereo sequence in ../shared/data (its README
describes it; the tests fail when it is missing: it ships beside the project).

The 20 rectified pairs (1241 x 376, f = 718.9 px, B = 0.532 m, cameras 1.65 m above the
road) are run through one GpodDetector in order; the first three frames calibrate the
ground plane (the road ahead is clear of obstacles near the car). Checked:

* the road plane implies the camera height 1.65 m to within 5 %;
* nothing is reported on the painted road: the ego lane and the hatched marking zone left
  of it, with the painted arrows, from the image rows of the near road (>= 230, about
  < 25 m) down -- no obstacle edge pixel, and no reported obstacle's foot, lies there;
* the raised kerb (and pavement) right of the lane is found in most frames, and the car
  passing on the left in the frames it is within range (``max_range_m``, 10 m: frames
  12-13; nothing is reported farther).

The image regions are in kitti_regions.py (shared with test_kitti_run.py).

The detector runs with the default settings (those of the wearable rig of Molton et al.,
f = 300 px, B = 0.35 m): every gate that depends on the rig is derived from the camera
(f, B, image size) and the calibrated plane, not set per rig.
"""
import glob

import cv2
import numpy as np
import pytest

from asmonc_vision.core.camera import StereoCamera, metric_from_plane
from asmonc_vision.core.gpod import GpodConfig, GpodDetector

from kitti_regions import KITTI, foot_pixel, in_painted_road, is_car_left, is_kerb, \
    require_kitti

#: every test shares the one run over the sequence (seconds)
pytestmark = pytest.mark.slow


def _foot(ob, plane, cam):
    return foot_pixel(ob.position, ob.height, plane.normal_up, cam)


@pytest.fixture(scope='module')
def run():
    require_kitti()
    files_l = sorted(glob.glob(str(KITTI / 'image_2' / '*.png')))
    files_r = sorted(glob.glob(str(KITTI / 'image_3' / '*.png')))
    assert len(files_l) == len(files_r) == 20, (len(files_l), len(files_r))
    calib = {ln.split(':')[0]: np.array(ln.split()[1:], float).reshape(3, 4)
             for ln in open(KITTI / 'calib.txt') if ':' in ln}
    left = [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in files_l]
    right = [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in files_r]
    h, w = left[0].shape
    cam = StereoCamera.from_projection(calib['P2'], calib['P3'], w, h)
    det = GpodDetector(GpodConfig())
    results = [det.process(l_, r_, cam) for l_, r_ in zip(left, right)]
    return cam, det, results


def test_road_plane_gives_the_camera_height(run):
    cam, det, results = run
    assert abs(cam.baseline - 0.532) < 0.01 and len(results) == 20
    assert [r.status for r in results[:3]] == ['initialising', 'initialising', 'tracking']
    assert all(r.status == 'tracking' for r in results[2:])
    height = metric_from_plane(cam, det.calibrated_plane.abc).height
    assert abs(height - 1.65) < 0.05 * 1.65
    for r in results[2:]:                     # the refitted plane too, frame by frame
        assert abs(r.metric_plane.height - 1.65) < 0.05 * 1.65
    assert 0.2 < det.sigma_px < 2.0          # the residual spread of the initial fit, px


def test_nothing_on_the_lane_markings_or_the_arrows(run):
    cam, _, results = run
    for i, r in enumerate(results[2:], start=2):
        f = r.features
        on_road = in_painted_road(f.u_left, f.v)
        assert on_road.sum() > 1000                 # the road is matched densely ...
        assert not (f.is_obstacle & on_road).any(), i   # ... and none of it is an obstacle
        for ob in r.obstacles:
            assert not in_painted_road(*_foot(ob, r.metric_plane, cam)), (i, ob.roi)


def test_kerb_and_cars_are_found(run):
    cam, _, results = run

    def kerb(r):
        return any(is_kerb(*_foot(ob, r.metric_plane, cam), ob.height) for ob in r.obstacles)

    def car_left(r):
        return any(is_car_left(ob.roi, ob.range, ob.height) for ob in r.obstacles)

    tracking = results[2:]
    assert np.mean([kerb(r) for r in tracking]) >= 0.8
    assert all(car_left(r) for r in results[12:14])
    max_range = GpodConfig().detection.max_range_m
    assert all(ob.range <= max_range for r in tracking for ob in r.obstacles)
