"""Rays and projection agree: points along the ray through a pixel project back onto that pixel."""

import numpy as np
import torch

from windowshop.rays import camera_rays, project
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera


def _camera() -> Camera:
    c2w = look_at(np.array([1.5, -2.0, 1.2]), np.array([0.1, 0.2, -0.1]), np.array([0.0, 0.0, 1.0]))
    return Camera(fx=70.0, fy=65.0, cx=31.3, cy=22.8, width=60, height=40, c2w=c2w)


def test_points_along_a_pixels_ray_project_to_that_pixel_centre():
    cam = _camera()
    origins, dirs = camera_rays(cam, dtype=torch.float64)
    index = torch.tensor([0, 59, 40 * 60 - 1, 17 * 60 + 33])
    expected = np.stack([(index % 60).numpy() + 0.5, (index // 60).numpy() + 0.5], -1)
    for t in (0.5, 2.0, 7.5):
        points = (origins[index] + t * dirs[index]).numpy()
        uv, depth = project(points, cam)
        np.testing.assert_allclose(uv, expected, atol=1e-9)
        assert np.all(depth > 0)


def test_ray_origin_is_the_camera_centre_and_centre_pixel_looks_down_minus_z():
    cam = Camera(fx=50.0, fy=50.0, cx=20.0, cy=10.0, width=40, height=20, c2w=np.eye(4))
    origins, dirs = camera_rays(cam, dtype=torch.float64)
    assert torch.allclose(origins, torch.zeros_like(origins))
    # the pixel whose centre is (20.5, 10.5) is half a pixel right of and below the principal point
    d = dirs[10 * 40 + 20].numpy()
    np.testing.assert_allclose(d / -d[2], [0.5 / 50.0, -0.5 / 50.0, -1.0], atol=1e-12)


def test_projection_of_a_known_point():
    cam = Camera(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80, c2w=np.eye(4))
    uv, depth = project(np.array([[0.2, 0.1, -2.0]]), cam)
    np.testing.assert_allclose(uv, [[60.0, 35.0]])  # x right, y up: higher points are lower v
    np.testing.assert_allclose(depth, [2.0])
