"""The visual hull of a sphere's silhouettes bounds the sphere tightly."""

import numpy as np

from windowshop.scene import hull
from windowshop.scene.synthetic import orbit_cameras


def _sphere_mask(cam, centre, radius):
    """Exact silhouette (H, W) of a sphere: pixels whose ray passes within `radius` of `centre`."""
    j, i = np.mgrid[0:cam.height, 0:cam.width] + 0.5
    d = np.stack([(i - cam.cx) / cam.fx, -(j - cam.cy) / cam.fy, -np.ones_like(i)], -1) @ cam.c2w[:3, :3].T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = centre - cam.center
    miss = np.linalg.norm(oc - (d @ oc)[..., None] * d, axis=-1)
    return (miss < radius).astype(np.float32)


def test_hull_of_a_sphere_seen_from_all_around():
    centre, radius = np.array([0.2, -0.1, 0.3]), 0.5
    cams = orbit_cameras(24, 96) + [c for c in orbit_cameras(12, 96, offset=0.5)]
    for c in cams[24:]:  # mirror the second set below the equator so the hull closes underneath
        c.c2w[2, :] *= -1
        c.c2w[:3, 1] *= -1  # keep a right-handed rotation
    masks = [_sphere_mask(c, centre, radius) for c in cams]
    points = hull.hull_points(cams, masks, np.zeros(3), 1.5, tolerance=0.0)
    voxel = 2 * 1.5 / hull.GRID
    lo, hi = points.min(0), points.max(0)
    np.testing.assert_allclose(lo, centre - radius, atol=2 * voxel)
    np.testing.assert_allclose(hi, centre + radius, atol=2 * voxel)
    assert np.all(np.linalg.norm(points - centre, axis=1) < radius + 2 * voxel)


def test_nothing_survives_empty_masks():
    cams = orbit_cameras(4, 16)
    assert hull.hull_points(cams, [np.zeros((16, 16), np.float32)] * 4, np.zeros(3), 1.0) is None
