"""The visual hull of a sphere's silhouettes bounds the sphere tightly."""

import numpy as np

from sphere_helpers import all_around, sphere_mask
from windowshop.scene import hull
from windowshop.scene.synthetic import orbit_cameras


def test_hull_of_a_sphere_seen_from_all_around():
    centre, radius = np.array([0.2, -0.1, 0.3]), 0.5
    cams = all_around(24, 12, 96)
    masks = [sphere_mask(c, centre, radius) for c in cams]
    points = hull.hull_points(cams, masks, np.zeros(3), 1.5, tolerance=0.0)
    voxel = 2 * 1.5 / hull.GRID
    lo, hi = points.min(0), points.max(0)
    np.testing.assert_allclose(lo, centre - radius, atol=2 * voxel)
    np.testing.assert_allclose(hi, centre + radius, atol=2 * voxel)
    assert np.all(np.linalg.norm(points - centre, axis=1) < radius + 2 * voxel)


def test_nothing_survives_empty_masks():
    cams = orbit_cameras(4, 16)
    assert hull.hull_points(cams, [np.zeros((16, 16), np.float32)] * 4, np.zeros(3), 1.0) is None
