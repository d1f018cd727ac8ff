"""Carve the density lattice with the training photos' masks before the surface is taken from it.

A field keeps some haze where its training never needed it gone: a thin sheet whose opacity
stays under a half (so no photo shows it) can still be denser than the surface's level, and
marching cubes then draws it (on lego, a fringe under the base plate that the low views show as
several thousand extra silhouette pixels). Where a source has masks, they say what is empty: a
lattice vertex inside the surface that more than TOLERANCE of the views seeing it see on the
background is not the object, and is emptied. Only vertices above the level are tested (the
rest are outside the surface already), which is a few percent of the lattice.
"""

from __future__ import annotations

import numpy as np
import torch

from windowshop.export.raster import screen
from windowshop.scene.types import Camera

CARVE_VIEWS = 50  # masks carving the lattice, spread through the training views (lego: 32 of them
# leave more of the haze under the plate, seen by the few low views only)
TOLERANCE = 0.05  # share of the views (and at least one) that may see a vertex on the background
MASK_LEVEL = 0.5  # alpha above which a pixel is the object's


@torch.no_grad()
def background_votes(points: torch.Tensor, cameras: list[Camera],
                     masks: list[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
    """(seen (N,), background (N,)) int32: how many of the views (`cameras`, alpha `masks` (H, W))
    see each of `points` (N, 3) inside their image, and how many of those on the background."""
    seen = torch.zeros(len(points), dtype=torch.int32, device=points.device)
    background = torch.zeros_like(seen)
    for camera, mask in zip(cameras, masks):
        xy, depth = screen(points, camera)
        u, v = torch.floor(xy).long().unbind(-1)
        inside = (depth > 1e-9) & (u >= 0) & (v >= 0) & (u < mask.shape[1]) & (v < mask.shape[0])
        fg = torch.as_tensor(mask > MASK_LEVEL, device=points.device)
        hit = torch.zeros_like(inside)
        hit[inside] = fg[v[inside], u[inside]]
        seen += inside.int()
        background += (inside & ~hit).int()
    return seen, background


def carve_volume(volume: torch.Tensor, aabb: torch.Tensor, level: float, cameras: list[Camera],
                 masks: list[np.ndarray]) -> torch.Tensor:
    """`volume` (X, Y, Z), densities at the lattice vertices over `aabb` (2, 3), with the vertices
    above `level` that the masks call background set to zero (see the module docstring)."""
    candidates = (volume > level).nonzero()  # (N, 3) lattice indices
    step = (aabb[1] - aabb[0]) / (torch.tensor(volume.shape, device=aabb.device) - 1)
    points = aabb[0] + candidates.to(aabb) * step
    seen, background = background_votes(points, cameras, masks)
    empty = background > torch.clamp(TOLERANCE * seen, min=1.0)
    out = volume.clone()
    # -level, not 0: between a vertex at density d and an emptied one the surface then crosses at
    # (d - level) / (d + level) of the way, about midway, rather than next to the emptied vertex
    out[tuple(candidates[empty].T)] = -level
    return out
