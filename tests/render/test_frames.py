"""Whole frames: pixels rendered tile by tile land where the row-major image puts them."""

import numpy as np
import torch

from windowshop.config import NerfConfig
from windowshop.field.nerf import NerfModel
from windowshop.model import Bounds
from windowshop.rays import camera_rays
from windowshop.render.frames import render_camera, render_rays_chunked, tile_order
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera


def test_tile_order_visits_every_pixel_once_tile_by_tile():
    order = tile_order(5, 7, tile=2).tolist()
    assert sorted(order) == list(range(35))
    assert order[:8] == [0, 1, 7, 8, 2, 3, 9, 10]  # the first 2x2 tile, then the next across
    assert order[-1] == 34  # the ragged bottom-right tile comes last


def test_tiled_frame_equals_the_row_major_render():
    torch.manual_seed(0)
    model = NerfModel(NerfConfig(freqs=2, view_dependent=False, depth=2, width=16, n_coarse=8,
                                 n_fine=0), Bounds(aabb=((-1, -1, -1), (1, 1, 1)), near=1.0, far=5.0))
    pose = look_at(np.array([0.0, -3.0, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    camera = Camera(width=37, height=21, fx=30.0, fy=30.0, cx=18.5, cy=10.5, c2w=pose)
    frame = render_camera(model, camera, background=(1.0, 1.0, 1.0))
    origins, directions = camera_rays(camera)
    rgb, _, opacity = render_rays_chunked(model, origins, directions, torch.ones(3))
    assert np.allclose(frame.rgb, rgb.clamp(0, 1).reshape(21, 37, 3).numpy(), atol=1e-6)
    assert np.allclose(frame.opacity, opacity.reshape(21, 37).numpy(), atol=1e-6)
    assert frame.opacity.std() > 1e-3  # the image is not uniform, so misplaced pixels would show
