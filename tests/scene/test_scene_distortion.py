"""Lens distortion: the undistorted image shows each point where the pinhole camera projects it."""

import numpy as np

from windowshop.scene.distortion import (Distortion, bilinear, distort, distort_pixels, remap,
                                         undistort_image, undistorted_camera)
from windowshop.scene.types import Camera

STORED = Camera(fx=120.0, fy=118.0, cx=81.0, cy=59.5, width=160, height=120, c2w=np.eye(4))
LENS = Distortion(k1=0.08, k2=-0.02, p1=0.004, p2=-0.003)


def test_opencv_model_on_a_known_point():
    d = Distortion(k1=0.1, k2=0.01, p1=0.02, p2=0.03)
    x, y = 0.3, -0.2
    r2 = x * x + y * y
    radial = 1 + 0.1 * r2 + 0.01 * r2 * r2
    expected = [x * radial + 2 * 0.02 * x * y + 0.03 * (r2 + 2 * x * x),
                y * radial + 0.02 * (r2 + 2 * y * y) + 2 * 0.03 * x * y]
    np.testing.assert_allclose(distort(np.array([[x, y]]), d)[0], expected)


def test_fast_remap_equals_the_numpy_reference():
    rng = np.random.default_rng(1)
    image = rng.random((30, 40, 4)).astype(np.float32)
    uv = rng.uniform(-2, 42, (25, 35, 2)) * [1.0, 0.75]
    np.testing.assert_allclose(remap(image, uv), bilinear(image, uv), atol=1e-5)


def test_pinhole_camera_zooms_just_enough_to_stay_inside_the_photo():
    pinhole = undistorted_camera(STORED, LENS)
    assert pinhole.fx > STORED.fx  # pincushion (k1 > 0) pushes the border out: zoom in
    edge = np.array([[0.0, 0.0], [160.0, 0.0], [0.0, 120.0], [160.0, 120.0], [80.0, 0.0], [0.0, 60.0]])
    src = distort_pixels(edge, pinhole, STORED, LENS)
    assert np.all((src >= -1e-6) & (src <= [160 + 1e-6, 120 + 1e-6]))
    looser = Camera(**{**pinhole.__dict__, "fx": pinhole.fx * 0.99, "fy": pinhole.fy * 0.99})
    src = distort_pixels(edge, looser, STORED, LENS)
    assert not np.all((src >= 0) & (src <= [160, 120]))


def test_a_dot_moves_to_its_pinhole_projection():
    """Paint a Gaussian dot where the lens puts a point; after undistortion it sits where the
    ideal pinhole camera projects that point."""
    lens = Distortion(k1=0.3, p1=0.01, p2=-0.01)
    pinhole = undistorted_camera(STORED, lens)
    for xy in ([0.3, 0.25], [-0.4, 0.1], [0.0, -0.3]):
        ideal = np.array([pinhole.fx * xy[0] + pinhole.cx, pinhole.fy * xy[1] + pinhole.cy])
        seen = distort_pixels(ideal[None], pinhole, STORED, lens)[0]  # where the lens put it
        j, i = np.mgrid[0:120, 0:160] + 0.5
        dot = np.exp(-((i - seen[0]) ** 2 + (j - seen[1]) ** 2) / (2 * 1.5 ** 2))
        out = undistort_image(dot[..., None].astype(np.float32), STORED, pinhole, lens)[..., 0]
        centroid = np.array([(out * i).sum(), (out * j).sum()]) / out.sum()
        assert np.linalg.norm(centroid - ideal) < 0.15
        assert np.linalg.norm(seen - ideal) > 1.5  # the lens did move it
