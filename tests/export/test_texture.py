"""The texture's bake size follows the photos' resolution on the object."""

import dataclasses

import numpy as np

from export_helpers import square, top_camera
from windowshop.export import texture
from windowshop.export.mesh import Mesh
from windowshop.export.photos import Photos
from windowshop.export.texture import Unwrapped, bake_size


def test_photos_coarser_than_the_texels_bake_a_coarser_texture():
    vertices, faces = square(0.0, 0.5)  # one world unit square, 4 units from the camera
    uv = np.array([[0.0, 0.5], [0.5, 0.5], [0.5, 0.0], [0.0, 0.0]])  # a quarter of the texture
    unwrapped = Unwrapped(vertices, faces, np.tile([0.0, 0.0, 1.0], (4, 1)), uv, np.arange(4))
    texels = 1024  # a side of 2048 texels, half of it across one unit

    def photo_with(pixels_per_unit: float) -> Photos:
        camera = dataclasses.replace(top_camera(40), fx=4 * pixels_per_unit, fy=4 * pixels_per_unit)
        return Photos([camera], [np.zeros((40, 40, 3), np.float32)], [None])

    # 1.5 texels a pixel at 512, 0.75 at 256
    assert bake_size(unwrapped, 2048, photo_with(texels / 6)) == 512
    assert bake_size(unwrapped, 2048, photo_with(2 * texels)) == 2048  # finer photos: full size


def test_the_typical_photo_sets_the_bake_size_not_one_close_up():
    vertices, faces = square(0.0, 0.5)
    uv = np.array([[0.0, 0.5], [0.5, 0.5], [0.5, 0.0], [0.0, 0.0]])
    unwrapped = Unwrapped(vertices, faces, np.tile([0.0, 0.0, 1.0], (4, 1)), uv, np.arange(4))
    cameras = [dataclasses.replace(top_camera(40), fx=4 * p, fy=4 * p) for p in (170, 170, 2048)]
    photos = Photos(cameras, [np.zeros((40, 40, 3), np.float32)] * 3, [None] * 3)
    assert bake_size(unwrapped, 2048, photos) == 512  # two photos at 170 pixels a unit, one close-up


def test_thousands_of_charts_are_packed_without_padding_rather_than_never():
    # a rough surface of 4,500 one-triangle charts (each facing its own axis) in a 64 x 64
    # texture: with 2 texels of padding they cannot fit however small, so they are packed with none
    rng = np.random.default_rng(0)
    centres = rng.uniform(-1, 1, (4500, 3))
    corners = centres[:, None, :] + rng.normal(0, 0.01, (4500, 3, 3))
    mesh = Mesh(vertices=corners.reshape(-1, 3), faces=np.arange(4500 * 3).reshape(-1, 3))
    assert texture.chart_padding(4500, 64) == 0.0 and texture.chart_padding(20, 64) == texture.PADDING
    unwrapped = texture.unwrap(mesh, 64)
    assert unwrapped.uv.min() >= 0.0 and unwrapped.uv.max() <= 1.0
