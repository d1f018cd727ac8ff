"""Settling the mesh where the photos agree: a surface drawn in front of the photographed one
moves back onto it, and one already on it (or with nothing to agree on) stays."""

import numpy as np
import pytest

from windowshop.export.mesh import Mesh
from windowshop.export.photos import Photos
from windowshop.export.settle import settle
from windowshop.rays import camera_rays
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

CELL = 0.05
SIZE, FOCAL = 96, 96.0
PERIOD = 0.4  # of the painted pattern (about 10 pixels in the photos)


def grid_square(half: float = 1.0, step: float = CELL) -> Mesh:
    """A flat square at z = 0 facing +z, triangulated every `step`."""
    axis = np.arange(-half, half + 1e-9, step)
    n = len(axis)
    x, y = np.meshgrid(axis, axis, indexing="xy")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], -1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None]  # lower-left corner of each quad
    i = i.ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n + 1], -1), np.stack([i, i + n + 1, i + n], -1)])
    return Mesh(vertices, faces)


def painted(z: float, flat: bool = False) -> Photos:
    """Photos from 5 directions (head-on and 40 degrees off to four sides) of the plane at
    height `z` painted with a pattern of PERIOD (or one flat grey)."""
    cameras, images = [], []
    for eye in ([0, 0, 4.0], [2.57, 0, 3.06], [-2.57, 0, 3.06], [0, 2.57, 3.06], [0, -2.57, 3.06]):
        c2w = look_at(np.array(eye), np.zeros(3), np.array([0.0, 1.0, 0.0]) if eye[1] == 0
                      else np.array([1.0, 0.0, 0.0]))
        camera = Camera(FOCAL, FOCAL, SIZE / 2, SIZE / 2, SIZE, SIZE, c2w)
        origins, directions = (t.numpy().astype(np.float64) for t in camera_rays(camera))
        t = (z - origins[:, 2]) / directions[:, 2]
        hit = origins + t[:, None] * directions
        value = 0.5 + 0.4 * np.sin(2 * np.pi * hit[:, 0] / PERIOD) * np.cos(2 * np.pi * hit[:, 1] / PERIOD)
        grey = np.full_like(value, 0.5) if flat else value
        image = np.stack([grey, 0.5 + 0.0 * grey, 1.0 - grey], -1).reshape(SIZE, SIZE, 3)
        cameras.append(camera)
        images.append(image.astype(np.float32))
    return Photos(cameras, images, [None] * len(cameras))


def middle_heights(mesh: Mesh) -> np.ndarray:
    """The heights of the vertices away from the square's rim (where the views' edges are)."""
    inner = np.abs(mesh.vertices[:, :2]).max(-1) < 0.6
    return mesh.vertices[inner, 2]


@pytest.mark.parametrize("depth_cells", [1.0, 1.5])
def test_a_surface_in_front_of_the_photographed_one_moves_onto_it(depth_cells):
    settled = settle(grid_square(), painted(-depth_cells * CELL), CELL)
    heights = middle_heights(settled) / CELL
    assert np.median(heights) == pytest.approx(-depth_cells, abs=0.3)
    assert np.percentile(np.abs(heights + depth_cells), 90) < 0.6


def test_a_surface_where_the_photos_agree_stays():
    heights = middle_heights(settle(grid_square(), painted(0.0), CELL)) / CELL
    assert np.percentile(np.abs(heights), 90) < 0.3


def test_flat_colour_gives_no_reason_to_move():
    heights = middle_heights(settle(grid_square(), painted(-CELL, flat=True), CELL))
    assert np.abs(heights).max() < 1e-9
