"""Carving the lattice with masks: haze the photos show as background goes, the object stays."""

import numpy as np
import torch

from windowshop.export.carve import carve_volume
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

RADIUS = 0.5  # the object: a ball at the origin


def ring_cameras(count: int = 8, size: int = 64) -> list[Camera]:
    """`count` cameras on a ring 3 units out, 20 degrees above the ball's equator, looking at it."""
    out = []
    for angle in np.linspace(0, 2 * np.pi, count, endpoint=False):
        eye = 3.0 * np.array([np.cos(angle) * np.cos(0.35), np.sin(angle) * np.cos(0.35),
                              np.sin(0.35)])
        c2w = look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        out.append(Camera(fx=size, fy=size, cx=size / 2, cy=size / 2, width=size, height=size,
                          c2w=c2w))
    return out


def ball_mask(camera: Camera) -> np.ndarray:
    """(H, W) 1 where the pixel centre's ray passes within RADIUS of the origin, else 0."""
    rows, cols = np.mgrid[0:camera.height, 0:camera.width] + 0.5
    dirs = np.stack([(cols - camera.cx) / camera.fx, -(rows - camera.cy) / camera.fy,
                     -np.ones_like(rows)], -1) @ camera.c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origin = camera.c2w[:3, 3]
    closest = np.linalg.norm(np.cross(dirs, -origin), axis=-1)  # distance of the ray to the origin
    return (closest < RADIUS).astype(np.float32)


AABB = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def ball_in_haze() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(densities (41, 41, 41) over AABB, the ball there (bool), a sheet of haze under it)."""
    axis = torch.linspace(-1, 1, 41)
    x, y, z = torch.meshgrid(axis, axis, axis, indexing="ij")
    ball = (x**2 + y**2 + z**2).sqrt() < RADIUS - 0.05
    haze = ((z + 0.75).abs() < 0.03) & (x.abs() < 0.8) & (y.abs() < 0.8)
    return 10.0 * ball.float() + 5.0 * haze.float(), ball, haze


def test_haze_the_masks_see_as_background_is_emptied_and_the_ball_kept():
    volume, ball, haze = ball_in_haze()
    cameras = ring_cameras()
    carved = carve_volume(volume, AABB, 1.0, cameras, [ball_mask(c) for c in cameras])
    assert torch.equal(carved[ball], volume[ball])
    assert bool((carved[haze] < 0).all())
    assert torch.equal(carved[~ball & ~haze], volume[~ball & ~haze])  # below the level: untouched


def test_the_boxes_vote_as_the_vertices_one_by_one():
    # an uneven lump with haze about it, cameras near enough that the lattice spills out of
    # some photos, masks of a smaller ball: every way a box can be decided or not
    from windowshop.export.carve import (ESTIMATED, TOLERANCE, background_lattice,
                                         background_votes)

    n = 45
    axis = torch.linspace(-1, 1, n)
    x, y, z = torch.meshgrid(axis, axis, axis, indexing="ij")
    generator = torch.Generator().manual_seed(0)
    haze = torch.rand(n, n, n, generator=generator) < 0.1
    occupied = ((x**2 + 0.6 * y**2 + z**2).sqrt() < 0.8) | haze
    aabb = AABB
    cameras = ring_cameras(6, 48)
    for camera in cameras[::2]:
        camera.c2w[:3, 3] *= 0.55  # close up: parts of the lattice outside the photo
    masks = [ball_mask(c) for c in cameras]
    points = aabb[0] + occupied.nonzero().float() * (aabb[1] - aabb[0]) / (n - 1)
    seen, background = background_votes(points, cameras, masks)
    for tolerance in (TOLERANCE, ESTIMATED):
        expected = torch.zeros_like(occupied)
        expected[occupied] = background > torch.clamp(tolerance * seen, min=1.0)
        assert 0 < int(expected.sum()) < int(occupied.sum())
        for blocks in [(16, 4), (8,), (4, 2), ()]:
            got = background_lattice(occupied, aabb, cameras, masks, blocks, tolerance)
            assert torch.equal(got, expected)


def test_estimated_masks_that_miss_part_of_the_object_in_a_few_views_do_not_bite_it():
    """Two of eight masks lose the ball's right third (a segmentation's slip): given masks carve
    it away; estimated ones (carve.ESTIMATED: only what most views see on the background) keep
    the ball whole, and still empty the haze every view sees on the background."""
    from windowshop.export.carve import ESTIMATED

    volume, ball, haze = ball_in_haze()
    cameras = ring_cameras()
    masks = [ball_mask(c) for c in cameras]
    for mask in masks[:2]:
        mask[:, int(mask.shape[1] * 0.58):] = 0.0
    strict = carve_volume(volume, AABB, 1.0, cameras, masks)
    assert int((strict[ball] < 0).sum()) > 0.05 * int(ball.sum())  # bitten
    carved = carve_volume(volume, AABB, 1.0, cameras, masks, ESTIMATED)
    assert torch.equal(carved[ball], volume[ball])
    assert bool((carved[haze] < 0).all())
