"""Stereo geometry and the disparity-space ground plane (core.camera)."""
import numpy as np
import pytest

from asmonc_vision.core.camera import (MetricPlane, StereoCamera, align_right_image,
                                       ground_range_bearing, metric_from_plane,
                                       plane_disparity, plane_from_metric,
                                       principal_offset_px)

CAM = StereoCamera(f=300.0, cx=159.5, cy=119.5, baseline=0.35, width=320, height=240)


def _pitched_plane(pitch_deg, roll_deg=0.0, height=1.25):
    t, r = np.radians(pitch_deg), np.radians(roll_deg)
    down = np.array([0.0, np.cos(t), np.sin(t)])         # pitched down by t
    cr, sr = np.cos(r), np.sin(r)
    down = np.array([cr * down[0] - sr * down[1], sr * down[0] + cr * down[1], down[2]])
    return MetricPlane(normal_up=-down, height=height)


def test_project_triangulate_round_trip():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-2, 2, 50), rng.uniform(-1, 1.5, 50),
                           rng.uniform(1, 20, 50)])
    u, v, d = CAM.project(pts)
    np.testing.assert_allclose(CAM.triangulate(u, v, d), pts, rtol=1e-12, atol=1e-12)
    # left/right columns from cyclopean u and d agree with direct projection
    ul = CAM.f * pts[:, 0] / pts[:, 2] + CAM.cx
    np.testing.assert_allclose(u + d / 2, ul, atol=1e-9)


@pytest.mark.parametrize('pitch,roll', [(20, 0), (15, 4), (30, -5)])
def test_plane_conversions_are_exact_for_ground_points(pitch, roll):
    plane = _pitched_plane(pitch, roll)
    abc = plane_from_metric(CAM, plane)
    # points on the plane, spread over the ground ahead
    rng = np.random.default_rng(1)
    down = -plane.normal_up
    fwd = np.array([0.0, 0.0, 1.0]) - down[2] * down
    fwd /= np.linalg.norm(fwd)
    side = np.cross(down, fwd)
    pts = (plane.height * down + rng.uniform(2, 10, (40, 1)) * fwd
           + rng.uniform(-2, 2, (40, 1)) * side)
    np.testing.assert_allclose(plane.signed_height(pts), 0, atol=1e-12)
    u, v, d = CAM.project(pts)
    np.testing.assert_allclose(plane_disparity(abc, u, v), d, rtol=1e-10)
    back = metric_from_plane(CAM, abc)
    np.testing.assert_allclose(back.normal_up, plane.normal_up, atol=1e-12)
    assert back.height == pytest.approx(plane.height, abs=1e-12)


def test_obstacle_disparity_excess_matches_paper_eq1():
    # Eq. 1: an obstacle of height S at range Y exceeds the ground disparity behind it by
    # f I S / (Y H), for a camera looking level.
    plane = _pitched_plane(0.0)
    abc = plane_from_metric(CAM, plane)
    S, Y = 0.10, 5.0
    top = np.array([[CAM.baseline / 2, plane.height - S, Y]])  # on the cyclopean axis
    u, v, d = CAM.project(top)
    excess = d - plane_disparity(abc, u, v)
    assert excess[0] == pytest.approx(CAM.f * CAM.baseline * S / (Y * plane.height), rel=1e-9)


def test_metric_from_plane_rejects_degenerate():
    assert metric_from_plane(CAM, (0.0, 0.0, 0.0)) is None


def test_range_and_bearing():
    plane = _pitched_plane(20)
    down = -plane.normal_up
    fwd = np.array([0.0, -np.sin(np.radians(20)), np.cos(np.radians(20))])
    p = plane.height * down + 4.0 * fwd + np.array([-1.0, 0, 0])  # 1 m to the left
    rng_, bearing = ground_range_bearing(plane, p[None, :])
    assert rng_[0] == pytest.approx(np.hypot(4.0, 1.0))
    assert bearing[0] == pytest.approx(np.arctan2(1.0, 4.0))


def test_from_projection_and_validation():
    pl = [300, 0, 160, 0, 0, 300, 120, 0, 0, 0, 1, 0]
    pr = [300, 0, 160, -300 * 0.35, 0, 300, 120, 0, 0, 0, 1, 0]
    cam = StereoCamera.from_projection(pl, pr, 320, 240)
    assert cam.baseline == pytest.approx(0.35) and cam.f == 300
    with pytest.raises(ValueError, match='baseline'):
        StereoCamera.from_projection(pr, pl, 320, 240)
    with pytest.raises(ValueError, match='f must be'):
        StereoCamera(f=-1, cx=0, cy=0, baseline=0.3, width=10, height=10)


def test_the_column_helpers_are_numpys_broadcasts():
    """`row_norms`, `sub_rows`, `add_rows` and `sub_scaled` give numpy's
    np.linalg.norm(x, axis=1), p - v, p + v and p - s[:, None] * n[None, :] byte for byte."""
    from asmonc_vision.core.camera import add_rows, row_norms, sub_rows, sub_scaled
    rng = np.random.default_rng(11)
    for n_rows in (0, 1, 2, 7, 300, 4001):
        p = rng.normal(size=(n_rows, 3)) * 10.0 ** rng.uniform(-3, 3, (n_rows, 1))
        s, n, v = rng.normal(size=n_rows), rng.normal(size=3), rng.normal(size=3)
        assert row_norms(p).tobytes() == np.linalg.norm(p, axis=1).tobytes()
        assert sub_rows(p, v).tobytes() == (p - v[None, :]).tobytes()
        assert add_rows(p, v).tobytes() == (p + v[None, :]).tobytes()
        assert sub_scaled(p, s, n).tobytes() == (p - s[:, None] * n[None, :]).tobytes()
        assert sub_rows(p[:, :2], v[:2]).tobytes() == (p[:, :2] - v[None, :2]).tobytes()


def test_the_ground_axes_of_a_plane_asked_again_are_its_own():
    """`ground_axes` gives a plane's axes as computed afresh, for planes asked for again
    (kept), new ones and more planes than it keeps."""
    from asmonc_vision.core import camera
    rng = np.random.default_rng(12)
    planes = []
    for _ in range(12):
        n = np.array([0.0, -1.0, 0.0]) + rng.normal(0.0, 0.2, 3)
        planes.append(MetricPlane(normal_up=n / np.linalg.norm(n), height=rng.uniform(0.5, 2)))
    for plane in planes + planes[::-1] + planes:
        got = camera.ground_axes(plane)
        want = camera._ground_axes(np.asarray(plane.normal_up, float), plane.height)
        assert all(a.tobytes() == b.tobytes() for a, b in zip(got, want))


def test_columns_is_np_stack_on_the_last_axis():
    """`columns` gives np.stack(cols, axis=-1) byte for byte (values, dtype, shape): 1-D
    and 2-D arrays, numpy scalars (so3_log's of one matrix), mixed dtypes, and arrays
    of different shapes (np.stack's own answer or error)."""
    from asmonc_vision.core.camera import columns
    rng = np.random.default_rng(4)
    a, b, c = rng.normal(size=(3, 50))
    m = rng.normal(size=(3, 3))
    cases = [(a, b), (a, b, c), (a[:0], b[:0]), (a.astype(np.float32), b),
             (a.reshape(5, 10), c.reshape(5, 10)), (np.arange(4), np.arange(4.0)),
             (m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]),
             (a[::2], b[1::2])]
    for cols in cases:
        want = np.stack(cols, axis=-1)
        got = columns(*cols)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert got.tobytes() == want.tobytes()
    with pytest.raises(ValueError):
        columns(a, b[:3])


def test_a_right_principal_point_of_its_own_is_moved_to_the_left_one():
    """cx_left - cx_right from the P matrices; the right image moved by it (bilinear
    for a fraction, the edge column repeated), so that a column's content lands where
    the left camera's principal point puts it."""
    pl = [300.0, 0, 159.5, 0, 0, 300.0, 119.5, 0, 0, 0, 1, 0]
    pr = list(pl)
    pr[2], pr[3] = 152.25, -105.0
    assert principal_offset_px(pl, pr) == pytest.approx(7.25)
    assert principal_offset_px(pl, pl) == 0.0
    with pytest.raises(ValueError, match='cx_left - cx_right = 7.25'):
        principal_offset_px(pl, pr, width=28)
    row = np.arange(0, 100, 10, dtype=np.uint8)[None, :].repeat(3, 0)
    np.testing.assert_array_equal(align_right_image(row, 2.0)[0],
                                  [0, 0, 0, 10, 20, 30, 40, 50, 60, 70])
    np.testing.assert_array_equal(align_right_image(row, -1.0)[0],
                                  [10, 20, 30, 40, 50, 60, 70, 80, 90, 90])
    np.testing.assert_array_equal(align_right_image(row, 2.5)[0],
                                  [0, 0, 0, 5, 15, 25, 35, 45, 55, 65])
    assert align_right_image(row, 0.0) is row
    assert align_right_image(row, 2.5).dtype == np.uint8
