"""Visual hulls (space carving) of alpha masks: a coarse one for the object box of masked sources
(`hull_points`), and a carve mask over a model's box (`carve_mask`) so that training never
learns empty space or the table."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from windowshop.scene.types import Camera

GRID = 64  # voxels per side
MAX_VIEWS = 32  # carving with more views barely tightens the box
MASK_SIDE = 128  # masks are subsampled to about this many pixels on the longer side
CARVE_MASK_SIDE = 512  # ... for the finer carve mask


def cube_grid(centre: np.ndarray, half_size: float, cells: int = GRID) -> np.ndarray:
    """(cells^3, 3) float32 centres of the voxels filling the cube `centre` +- `half_size`."""
    axis = (np.arange(cells) + 0.5) / cells * 2.0 - 1.0
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    return (centre + half_size * grid).astype(np.float32)  # float32: half the memory traffic


def hull_points(cameras: list[Camera], masks: list[np.ndarray], centre: np.ndarray,
                half_size: float, tolerance: float = 0.05) -> np.ndarray | None:
    """Centres (M, 3) of the voxels inside the visual hull, or None if nothing survives.

    The grid spans the cube `centre` +- `half_size`. A voxel survives unless more than
    `tolerance` of the views see background there (alpha < 0.5, or outside the image), which
    forgives a few imperfect masks. Each centre stands for a voxel of side 2 * half_size / GRID.
    """
    step = max(1, len(cameras) // MAX_VIEWS)
    cameras, masks = cameras[::step], masks[::step]
    points = cube_grid(centre, half_size)
    misses = np.zeros(len(points), dtype=np.int32)
    allowed = int(tolerance * len(cameras))
    for cam, mask in zip(cameras, masks):
        misses += ~_covered(points, cam, mask)
        keep = misses <= allowed  # carved voxels are dropped at once: later views test fewer
        points, misses = points[keep], misses[keep]
    return points if len(points) else None


def carve_mask(cameras: list[Camera], masks: list[np.ndarray], aabb: np.ndarray,
               cells: tuple[int, int, int], tolerance: float = 0.05, dilate: int = 1) -> np.ndarray:
    """(X, Y, Z) bool over the box `aabb` (2, 3) cut into `cells`: True where the object may be.

    A cell is carved when more views than `tolerance` of them (and at least one) see background
    at its centre, so one bad mask cannot cut the object; a cell seen by no view (outside its
    image or behind it) keeps it, since an object cropped by a photo is no evidence of space.
    The survivors grow by `dilate` cells, so a surface crossing a cell off its centre is kept.
    """
    aabb = np.asarray(aabb, dtype=np.float64)
    axes = [aabb[0, i] + (np.arange(n) + 0.5) * (aabb[1, i] - aabb[0, i]) / n
            for i, n in enumerate(cells)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
    index = np.arange(len(points))
    misses = np.zeros(len(points), dtype=np.int32)
    allowed = max(1, int(tolerance * len(cameras)))
    for cam, mask in zip(cameras, masks):
        seen, hit = projection(points, cam, mask, CARVE_MASK_SIDE)
        misses += seen & ~hit
        keep = misses <= allowed
        points, index, misses = points[keep], index[keep], misses[keep]
    inside = np.zeros(int(np.prod(cells)), dtype=bool)
    inside[index] = True
    if dilate <= 0:
        return inside.reshape(cells)
    cube = np.ones((3, 3, 3), dtype=bool)
    return ndimage.binary_dilation(inside.reshape(cells), cube, iterations=dilate)


def _covered(points: np.ndarray, cam: Camera, mask: np.ndarray) -> np.ndarray:
    """(N,) bool: points that project in front of `cam` onto its foreground (mask (H, W))."""
    return projection(points, cam, mask, MASK_SIDE)[1]


def projection(points: np.ndarray, cam: Camera, mask: np.ndarray,
                side: int) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool each: points that project in front of `cam` inside its image, and those of them
    that land on its foreground (mask (H, W), subsampled to about `side` pixels)."""
    sub = max(1, max(mask.shape) // side)
    h, w = (mask.shape[0] // sub) * sub, (mask.shape[1] // sub) * sub
    # max-pool, so thin parts of the object are never lost by the subsampling
    small = mask[:h, :w].reshape(h // sub, sub, w // sub, sub).max(axis=(1, 3)) > 0.5
    w2c = np.linalg.inv(cam.c2w).astype(np.float32)
    local = points @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -local[:, 2]
    front = depth > 1e-9
    depth = np.where(front, depth, 1.0)
    u = (cam.fx * local[:, 0] / depth + cam.cx) / sub
    v = (-cam.fy * local[:, 1] / depth + cam.cy) / sub
    ui, vi = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    valid = front & (ui >= 0) & (vi >= 0) & (ui < small.shape[1]) & (vi < small.shape[0])
    hit = np.zeros(len(points), dtype=bool)
    hit[valid] = small[vi[valid], ui[valid]]
    return valid, hit
