"""Photo projection: a view lends its colour only to the surface it sees, and colours it right."""

import numpy as np

from export_helpers import top_camera
from windowshop.export.photos import (ENOUGH, Photos, blend_with_field, low_weight,
                                      project_photos, spread)
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera


def samples(z: float, half: float) -> np.ndarray:
    """(M, 3) points every 0.02 over the square |x|, |y| <= half at height z (many a pixel)."""
    axis = np.arange(-half, half + 1e-9, 0.02)
    x, y = np.meshgrid(axis, axis)
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], -1)


def two_squares() -> np.ndarray:
    """Samples of a 3x3 square at z = 0 and of a 1x1 square over its middle at z = 1."""
    return np.concatenate([samples(0.0, 1.5), samples(1.0, 0.5)])


def painted_photo(camera: Camera) -> np.ndarray:
    """(H, W, 3): each pixel's colour encodes where it is (red = column, green = row), so the
    colour a point takes tells which pixel it was read from."""
    rows, cols = np.mgrid[0:camera.height, 0:camera.width]
    return np.stack([(cols + 0.5) / camera.width, (rows + 0.5) / camera.height,
                     np.full(rows.shape, 0.5)], -1).astype(np.float32)


def test_an_occluded_point_takes_nothing_and_a_seen_one_its_own_pixel():
    camera = top_camera(40)
    photos = Photos([camera], [painted_photo(camera)], [None])
    points = np.array([[0.0, 0.0, 0.0],  # the far square, under the near one: hidden
                       [1.2, -1.2, 0.0],  # the far square, in the open
                       [0.1, 0.2, 1.0]])  # the near square
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    total, weight = project_photos(points, normals, photos, 0.01, two_squares())
    assert weight[0] == 0.0
    assert weight[1] > 0.5 and weight[2] > 0.5  # head-on, inside the silhouettes
    colour = total[1:] / weight[1:, None]
    # top_camera: fx = 40 at distance 4 (far) or 3 (near); x -> column, +y -> row up
    expected_xy = np.array([[20 + 40 * 1.2 / 4, 20 + 40 * 1.2 / 4],
                            [20 + 40 * 0.1 / 3, 20 - 40 * 0.2 / 3]])
    assert np.allclose(colour[:, :2] * 40, expected_xy, atol=1e-3)


def test_a_surface_facing_away_takes_nothing():
    camera = top_camera(40)
    photos = Photos([camera], [painted_photo(camera)], [None])
    point, down = np.array([[0.2, 0.2, 0.0]]), np.array([[0.0, 0.0, -1.0]])
    _, weight = project_photos(point, down, photos, 0.01, samples(0.0, 1.0))
    assert weight[0] == 0.0


def test_views_blend_by_weight_and_a_half_covered_pixel_lends_nothing():
    square = samples(0.0, 1.0)
    top = top_camera(40)
    tilted = look_at(np.array([0.0, -2.0, 2.0 * np.sqrt(3.0)]), np.zeros(3), np.array([0, 0, 1.0]))
    side = Camera(fx=40, fy=40, cx=20, cy=20, width=40, height=40, c2w=tilted)  # 30 degrees off
    red = np.zeros((40, 40, 3), np.float32)
    red[..., 0] = 1.0
    blue = np.zeros((40, 40, 3), np.float32)
    blue[..., 2] = 1.0
    half = np.full((40, 40), 0.5, np.float32)
    point, up = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]])
    total, weight = project_photos(point, up, Photos([top, side], [red, blue], [None, None]), 0.01,
                                   square)
    cos2 = np.cos(np.radians(30.0)) ** 2  # the weight of a view is cos^2 of its angle
    assert np.allclose(total[0] / weight[0], [1 / (1 + cos2), 0, cos2 / (1 + cos2)], atol=1e-4)
    _, weight = project_photos(point, up, Photos([top], [red], [half]), 0.01, square)
    assert weight[0] == 0.0


def test_the_field_fills_in_where_the_photos_are_not_enough():
    total = np.array([[1.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.0]])
    weight = np.array([1.0, 0.1, 0.0])
    low = low_weight(weight)
    assert list(low) == [1, 2]
    field = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    out = blend_with_field(total, weight, field, low)
    assert np.allclose(out[0], [1, 0, 0]) and np.allclose(out[2], [0, 0, 1])
    share = 0.1 / ENOUGH  # the photos' weight against the field's top-up
    assert np.allclose(out[1], [share, 1 - share, 0])


def test_spread_picks_evenly_and_never_more_than_there_are():
    assert spread(4, 100) == [0, 25, 50, 75]
    assert spread(8, 3) == [0, 1, 2]
