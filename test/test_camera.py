"""Camera model and room calibration file."""
from __future__ import annotations

import numpy as np
import pytest

from mbtrack_ros.core.camera import CalibrationError, Camera, RoomCalibration, look_at


def test_principal_point_and_known_pixel():
    R, t = look_at((0.0, 0.0, 2.0), (4.0, 0.0, 2.0))  # looking along +x, horizontal
    cam = Camera('c', 320, 240, [[200, 0, 160], [0, 200, 120], [0, 0, 1]], [0] * 5, R, t)
    # the look-at point lands on the principal point
    assert np.allclose(cam.project(np.array([4.0, 0.0, 2.0])), [160, 120])
    # 1 m to the left (+y world) at 4 m depth: x = cx - f * 1 / 4; 0.5 m up: y = cy - f*0.5/4
    assert np.allclose(cam.project(np.array([4.0, 1.0, 2.5])), [160 - 50, 120 - 25])
    assert np.allclose(cam.center, [0, 0, 2])
    assert cam.depth(np.array([4.0, 1.0, 2.5])) == pytest.approx(4.0)


def test_points_behind_camera_are_nan(room):
    cam = room.cameras['cam0']
    behind = cam.center - 1.0 * cam.R[2]
    assert np.all(np.isnan(cam.project(behind[None])))


def test_floor_point_inverts_projection_with_distortion(room, rng):
    cam = room.cameras['cam0']
    pts = np.column_stack([rng.uniform(1, 5, 50), rng.uniform(1, 4, 50), np.zeros(50)])
    pix = cam.project(pts)
    ok = cam.in_image(pix)
    assert ok.sum() > 20
    back = cam.floor_point(pix[ok])
    assert np.allclose(back, pts[ok], atol=1e-6)
    # a head point at 1.7 m is recovered on the plane z = 1.7 as well
    head = pts[ok][:5] + [0, 0, 1.7]
    assert np.allclose(cam.floor_point(cam.project(head), height=1.7), head, atol=1e-6)


def test_scaled_camera_scales_pixels(room):
    cam = room.cameras['cam1']
    big = cam.scaled(cam.width * 2, cam.height * 2)
    p = np.array([[3.0, 2.5, 1.0], [2.0, 3.0, 0.0]])
    assert np.allclose((cam.project(p) + 0.5) * 2 - 0.5, big.project(p), atol=1e-9)


def _square_16_9(room) -> Camera:
    """``room``'s cam1 as a 1280x720 camera with square pixels (fx = fy, a wider view)."""
    cam = room.cameras['cam1']
    K = cam.K * np.array([[8.0], [8.0], [1.0]])
    K[0, 2], K[1, 2] = 639.5, 359.5
    return Camera('wide', 1280, 720, K, cam.dist, cam.R, cam.t)


def test_scaled_camera_with_another_aspect_ratio_scales_each_axis_by_its_own_factor(room):
    """A 16:9 picture with square pixels shrunk to the working size (1280x720 -> 370x208:
    369.5 rounded up, 208 from 207.8) scales columns by 370/1280 and rows by 208/720, each
    about the pixel centres: every projected point lands where the resized picture shows
    it."""
    cam = _square_16_9(room)
    small = cam.at_most(320 * 240)
    assert (small.width, small.height) == (370, 208)
    sx, sy = 370 / 1280, 208 / 720
    rng = np.random.default_rng(5)
    p = np.c_[rng.uniform(0.5, 5.5, 40), rng.uniform(0.5, 4.5, 40), rng.uniform(0, 2, 40)]
    big, got = cam.project(p), small.project(p)
    ok = np.isfinite(big).all(axis=1)
    assert ok.sum() > 20
    np.testing.assert_allclose(got[ok, 0], (big[ok, 0] + 0.5) * sx - 0.5, atol=1e-9)
    np.testing.assert_allclose(got[ok, 1], (big[ok, 1] + 0.5) * sy - 0.5, atol=1e-9)
    # the pixel aspect of the scaled camera follows the two factors
    assert small.K[0, 0] / small.K[1, 1] == pytest.approx(cam.K[0, 0] / cam.K[1, 1] * sx / sy)


@pytest.mark.parametrize('size', [(1280, 720), (1920, 1080), (640, 480), (1600, 240),
                                  (320, 1200), (400, 300), (200, 150)])
def test_a_stretched_view_works_at_its_own_square_pixel_size(room, size):
    """``at_most``: a 320x240 view stretched to another size (non-square pixels,
    fx / fy = (w / 320) / (h / 240)) works at 320x240 with the view's own intrinsics
    (square pixels, 76800 of them); a smaller image is left as it is."""
    base = room.cameras['cam1'].scaled(320, 240)
    cam = base.scaled(*size)
    work = cam.at_most(320 * 240)
    if size[0] * size[1] <= 320 * 240:
        assert work is cam
        return
    assert (work.width, work.height) == (320, 240)
    np.testing.assert_allclose(work.K, base.K, atol=1e-9)


@pytest.mark.parametrize('aspect', [0.5, 0.8, 1.0, 1.1, 1.6, 3.0])
@pytest.mark.parametrize('size', [(1280, 720), (1000, 700), (2000, 100), (90, 1500), (400, 120),
                                  (120, 400)])
def test_working_camera_has_square_pixels_of_about_the_pixels_asked(room, size, aspect):
    """Any pixel aspect ``fx / fy`` and size: square working pixels (fx = fy up to the
    rounding of a side), never a side larger than the input, and the pixels asked up to
    that rounding, or fewer when a side had to stay (the input is coarser there)."""
    w, h = size
    cam = room.cameras['cam1'].scaled(w, h)
    K = cam.K.copy()
    K[0, 0] = K[1, 1] * aspect
    cam = Camera('c', w, h, K, cam.dist, cam.R, cam.t)
    pixels = 40_000
    work = cam.at_most(pixels)
    assert work.width <= w and work.height <= h
    ratio = work.K[0, 0] / work.K[1, 1]
    assert abs(ratio - 1.0) <= 0.5 / work.width + 0.5 / work.height + 1e-9
    kept = work.width == w or work.height == h
    assert work.width * work.height <= pixels + (work.width + work.height) / 2 + 1
    if not kept:
        assert work.width * work.height >= pixels - (work.width + work.height) / 2 - 1


def test_working_camera_of_a_square_pixel_camera_is_uniformly_scaled(room):
    """Square pixels: both sides by ``sqrt(pixels / (w h))`` (the size rounded)."""
    cam = room.cameras['cam1'].scaled(1280, 960)
    assert cam.K[0, 0] == pytest.approx(cam.K[1, 1])
    work = cam.at_most(320 * 240)
    assert (work.width, work.height) == (320, 240)
    work = _square_16_9(room).at_most(100_000)
    f = np.sqrt(100_000 / (1280 * 720))
    assert (work.width, work.height) == (round(1280 * f), round(720 * f))


def test_calibration_round_trip(tmp_path, room):
    path = tmp_path / 'room.yaml'
    room.save(path)
    back = RoomCalibration.load(path)
    assert back.names == room.names and back.floor == room.floor
    assert back.entry_zones == room.entry_zones
    p = np.array([[3.0, 2.0, 1.2]])
    for name in room.names:
        assert np.allclose(back.cameras[name].project(p), room.cameras[name].project(p))
        assert back.cameras[name].frame_id == room.cameras[name].frame_id


@pytest.mark.parametrize('text, message', [
    ('cameras: []', 'at least one camera'),
    ('foo: 1', 'no "cameras"'),
    (': : :', 'not valid YAML'),
])
def test_bad_calibration_files(tmp_path, text, message):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message):
        RoomCalibration.load(path)


def test_missing_calibration_file(tmp_path):
    with pytest.raises(CalibrationError, match='cannot read'):
        RoomCalibration.load(tmp_path / 'nope.yaml')


def test_not_a_rotation_is_refused():
    with pytest.raises(CalibrationError, match='rotation'):
        Camera('c', 10, 10, np.eye(3), [0] * 5, np.diag([1.0, 1.0, -1.0]), [0, 0, 0])


def test_projection_matches_opencv_project_points_bit_for_bit(room, rng):
    """The numba projection against cv2.projectPoints (the straightforward version), with
    and without distortion, including points behind the camera (NaN there)."""
    import cv2
    cams = list(room.cameras.values())
    R, t = look_at((0.3, -3.0, 2.5), (0.5, 1.0, 0.8))
    cams.append(Camera('d', 320, 240, [[210, 0, 158.7], [0, 205, 121.2], [0, 0, 1]],
                       [-0.21, 0.04, 0.001, -0.0007, 0.012], R, t))
    pts = np.column_stack([rng.uniform(-4, 6, 5000), rng.uniform(-4, 6, 5000),
                           rng.uniform(-0.5, 3.0, 5000)])
    for cam in cams:
        rvec, _ = cv2.Rodrigues(cam.R)
        ref, _ = cv2.projectPoints(pts, rvec, cam.t, cam.K, cam.dist)
        ref = ref.reshape(-1, 2)
        ref[cam.depth(pts) <= 1e-6] = np.nan
        got = cam.project(pts)
        assert np.array_equal(got, ref, equal_nan=True), cam.name
        assert np.isnan(got).any() and np.isfinite(got).any()
        assert np.array_equal(cam.project(pts.reshape(50, 100, 3)), got.reshape(50, 100, 2),
                              equal_nan=True)


def test_pixel_rays_project_back_onto_their_pixels_in_wide_angle_corners():
    """The wide ceiling camera of the synthetic rooms (f = 120 px at 320x240, k1 = -0.2,
    k2 = 0.04): OpenCV's fixed-point undistortion alone leaves its corner rays pixels off;
    with the Newton polish every pixel's ray projects back onto it."""
    import cv2

    R, t = look_at((3.0, 2.5, 3.0), (3.0, 2.51, 0.0))
    cam = Camera('ceiling', 320, 240, [[120, 0, 159.5], [0, 120, 119.5], [0, 0, 1]],
                 [-0.2, 0.04, 0.0, 0.0, 0.0], R, t)
    u, v = np.meshgrid(np.arange(0, 320, 7.5), np.arange(0, 240, 7.5))
    pix = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
    back = cam.project(cam.center + 2.0 * cam.pixel_rays(pix))
    assert np.abs(back - pix).max() < 1e-5
    # what the polish corrects: the fixed point alone is off by more than a pixel there
    plain = cv2.undistortPoints(pix.reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)
    rays = np.concatenate([plain, np.ones((len(plain), 1))], axis=1) @ cam.R
    off = np.abs(cam.project(cam.center + rays) - pix).max()
    assert off > 1.0, off
