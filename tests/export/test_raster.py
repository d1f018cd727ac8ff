"""The checking rasteriser: coverage and depth order against hand-computed answers."""

import numpy as np

from export_helpers import square, top_camera
from windowshop.export.raster import render_mesh


def test_a_square_covers_the_pixels_its_projection_covers():
    v, f = square(0.0, 1.0)  # at distance 4: 2 units wide = 20 pixels of a 40-pixel focal length
    _, silhouette = render_mesh(v, f, top_camera(), colours=np.zeros((4, 3), np.uint8))
    assert silhouette.sum() == 20 * 20
    assert silhouette[10:30, 10:30].all()


def test_the_nearer_face_wins_and_texture_coordinates_reach_the_texture():
    near_v, near_f = square(1.0, 0.5)
    far_v, far_f = square(0.0, 1.0)
    vertices = np.concatenate([far_v, near_v])
    faces = np.concatenate([far_f, near_f + 4])
    colours = np.array([[255, 0, 0]] * 4 + [[0, 0, 255]] * 4, dtype=np.uint8)
    image, _ = render_mesh(vertices, faces, top_camera(), colours=colours)
    assert np.allclose(image[20, 20], [0, 0, 1]) and np.allclose(image[11, 11], [1, 0, 0])
    # a texture whose top half is green: glTF v = 0 is its top row, here the square's +y side
    texture = np.zeros((8, 8, 3), np.uint8)
    texture[:4, :, 1] = 255
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])
    image, _ = render_mesh(far_v, far_f, top_camera(), uv=uv, texture=texture)
    assert image[12, 20, 1] == 1.0 and image[27, 20, 1] == 0.0  # image row 12 is at +y
