"""A sphere seen from all around, for the visual-hull tests: exact silhouettes and cameras above
and below its equator (so a hull closes underneath)."""

import numpy as np

from windowshop.scene.synthetic import orbit_cameras


def sphere_mask(cam, centre, radius):
    """Exact silhouette (H, W) of a sphere: pixels whose ray passes within `radius` of `centre`."""
    j, i = np.mgrid[0:cam.height, 0:cam.width] + 0.5
    d = np.stack([(i - cam.cx) / cam.fx, -(j - cam.cy) / cam.fy, -np.ones_like(i)], -1) @ cam.c2w[:3, :3].T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = centre - cam.center
    miss = np.linalg.norm(oc - (d @ oc)[..., None] * d, axis=-1)
    return (miss < radius).astype(np.float32)


def all_around(n_upper=24, n_lower=12, size=64):
    """Cameras above and (mirrored) below the equator, so that a hull closes underneath."""
    cams = orbit_cameras(n_upper, size) + orbit_cameras(n_lower, size, offset=0.5)
    for c in cams[n_upper:]:
        c.c2w[2, :] *= -1
        c.c2w[:3, 1] *= -1  # keep a right-handed rotation
    return cams
