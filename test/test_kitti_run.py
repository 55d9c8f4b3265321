"""The KITTI road sequence through the live node graph: the 20 pairs in ../shared/data
(its README describes them; the test fails when they are missing: they ship beside the
project) made into a contract bag by `asmonc images-bag`, replayed by `asmonc run` with
the default settings (nothing set for the rig: f = 719 px, B = 0.53 m, 1.65 m above the
road), and the recorded /ground_plane, /obstacles and /alarms checked here:

* /ground_plane TRACKING by 1.0 s of bag time and on every pair after, the camera
  height within 5 % of 1.65 m;
* no reported obstacle's foot (its top moved down the plane's normal by its height,
  projected into the left image with the bag's CameraInfo) on the painted road;
* the kerb right of the lane in >= 80 % of the tracking pairs, the car passing on the
  left in pairs 12-13 (when it is within ``max_range_m``), nothing farther;
* no obstacle alarm: within the CAUTION range (5 m) the walking corridor ahead of the
  car is the painted lane (and the road nearer than about 6 m is out of view).

The image regions and the kerb and car tests are those of test_kitti.py (the core
detector on the same pairs), in kitti_regions.py.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.gpod import GpodConfig
from asmonc_vision.io import bagio
from asmonc_vision.io.images_bag import write_images_bag

from conftest import next_domain_id
from kitti_regions import KITTI, foot_pixel, in_painted_road, is_car_left, is_kerb, \
    require_kitti

#: the node graph's start-up and 20 pairs of 1241 x 376 (about 15 s on a free machine)
pytestmark = pytest.mark.slow

PAIRS = 20
TRACKING = 1             # GroundPlane.TRACKING
CAUTION, STOP = 1, 3     # Alarm levels of obstacles


@pytest.fixture(scope='module')
def replay(tmp_path_factory):
    """The bag's left CameraInfo and pair stamps, and the recorded outputs by topic."""
    require_kitti()
    tmp = tmp_path_factory.mktemp('kitti_run')
    made = write_images_bag(KITTI, tmp / 'bag')
    assert made.pairs == made.frames == PAIRS
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(next_domain_id()))
    res = subprocess.run([sys.executable, '-m', 'asmonc_vision.cli', 'run', str(tmp / 'bag'),
                          '--out', str(tmp / 'out'), '--quiet', '--no-progress'],
                         env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert f'{PAIRS} of {PAIRS} processed, 0 dropped' in res.stdout, res.stdout
    infos = [m for _, _, m in bagio.read_messages(tmp / 'bag', ['/stereo/left/camera_info'])]
    rinfo = next(m for _, _, m in bagio.read_messages(tmp / 'bag',
                                                      ['/stereo/right/camera_info']))
    cam = StereoCamera.from_projection(infos[0].p, rinfo.p, infos[0].width, infos[0].height)
    stamps = sorted(bagio.header_stamp_ns(m) for m in infos)
    out: dict = {}
    for topic, _, m in bagio.read_messages(tmp / 'out', ['/ground_plane', '/obstacles',
                                                         '/alarms']):
        out.setdefault(topic, []).append(m)
    return cam, stamps, out


def _by_pair(stamps, msgs):
    """The messages of each input pair (by stamp), in pair order: one per pair."""
    by_stamp = {bagio.header_stamp_ns(m): m for m in msgs}
    assert len(by_stamp) == len(msgs) and set(by_stamp) == set(stamps)
    return [by_stamp[s] for s in stamps]


def test_the_road_is_tracked_within_a_second_at_the_camera_height(replay):
    _, stamps, out = replay
    planes = _by_pair(stamps, out['/ground_plane'])
    status = [int(p.status) for p in planes]
    first = status.index(TRACKING)
    assert (stamps[first] - stamps[0]) / 1e9 <= 1.0, status
    assert all(s == TRACKING for s in status[first:]), status
    heights = [p.height for p in planes[first:]]
    assert all(abs(h - 1.65) < 0.05 * 1.65 for h in heights), heights


def _feet(cam, plane, obstacles):
    """(u, v, height) of each obstacle's foot in the left image."""
    n = np.array([plane.normal.x, plane.normal.y, plane.normal.z])
    pos = np.array([[o.position.x, o.position.y, o.position.z] for o in obstacles])
    h = np.array([o.height for o in obstacles], float)
    u, v = foot_pixel(pos.reshape(-1, 3), h, n, cam)
    return u, v, h


def test_nothing_on_the_painted_road_the_kerb_and_the_car_are(replay):
    cam, stamps, out = replay
    planes = _by_pair(stamps, out['/ground_plane'])
    arrays = _by_pair(stamps, out['/obstacles'])
    tracking = [i for i, p in enumerate(planes) if int(p.status) == TRACKING]
    kerb = []
    for i in tracking:
        obs = list(arrays[i].obstacles)
        u, v, h = _feet(cam, planes[i], obs)
        on_road = in_painted_road(u, v)
        assert not on_road.any(), (i, [(o.roi.x_offset, o.roi.y_offset, o.height, o.range)
                                      for o, r in zip(obs, on_road) if r])
        kerb.append(any(is_kerb(*f) for f in zip(u, v, h)))
        assert all(o.range <= GpodConfig().detection.max_range_m for o in obs), i
    assert np.mean(kerb) >= 0.8, kerb
    for i in (12, 13):
        assert any(is_car_left((o.roi.x_offset, o.roi.y_offset, o.roi.width, o.roi.height),
                               o.range, o.height) for o in arrays[i].obstacles), i


def test_no_obstacle_alarm_on_the_painted_road(replay):
    _, _, out = replay
    alarms = out.get('/alarms', [])
    said = [(int(a.level), a.text, round(float(a.range), 2), round(float(a.bearing), 2))
            for a in alarms if CAUTION <= int(a.level) <= STOP]
    assert said == []
    assert any(int(a.level) == 0 for a in alarms)     # "all clear" once the road is seen
