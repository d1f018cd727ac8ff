"""Carve the density lattice with the training photos' masks before the surface is taken from it.

A field keeps some haze where its training never needed it gone: a thin sheet whose opacity
stays under a half (so no photo shows it) can still be denser than the surface's level, and
marching cubes then draws it (on lego, a fringe under the base plate that the low views show as
several thousand extra silhouette pixels). Where a source has masks, they say what is empty: a
lattice vertex inside the surface that more than TOLERANCE of the views seeing it see on the
background is not the object, and is emptied; where the masks were estimated from the photos
(ESTIMATED), more than half of them. Only vertices above the level are tested (the
rest are outside the surface already), which is a few percent of the lattice, and most of them a
box of lattice cells at a time (background_lattice: the same votes as vertex by vertex; 2.65M
vertices on dtu_skull, of which some 0.4M are left to project one by one).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from windowshop.export.raster import screen
from windowshop.scene.types import Camera

CARVE_VIEWS = 50  # masks carving the lattice, spread through the training views (lego: 32 of them
# leave more of the haze under the plate, seen by the few low views only)
TOLERANCE = 0.05  # share of the views (and at least one) that may see a vertex on the background
# ... where the masks were estimated from the photos (`windowshop prepare`'s segmentation), not
# given with them: each errs by a few pixels somewhere, and a vertex any two of them put on the
# background went, so the surface shrank inside the photographed outline. Carved only where most
# views that see it see the background (bench_models, the GLB in the mask at held-out photos:
# beer_can 15.93 -> 17.29 dB, its IoU 0.902 -> 0.912; fruit 14.57 -> 15.12; kermit 18.63 ->
# 19.12; dtu_skull 17.68 -> 17.71, IoU 0.976 -> 0.965)
ESTIMATED = 0.5
MASK_LEVEL = 0.5  # alpha above which a pixel is the object's
BLOCKS = (16, 4)  # lattice cells a side of the boxes whose vertices the masks vote on together,
# the larger first (background_lattice)


@torch.no_grad()
def background_votes(points: torch.Tensor, cameras: list[Camera],
                     masks: list[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
    """(seen (N,), background (N,)) int32: how many of the views (`cameras`, alpha `masks` (H, W))
    see each of `points` (N, 3) inside their image, and how many of those on the background."""
    seen = torch.zeros(len(points), dtype=torch.int32, device=points.device)
    background = torch.zeros_like(seen)
    for camera, mask in zip(cameras, masks):
        h, w = mask.shape
        xy, depth = screen(points, camera)
        u, v = torch.floor(xy).long().unbind(-1)
        inside = (depth > 1e-9) & (u >= 0) & (v >= 0) & (u < w) & (v < h)
        fg = torch.as_tensor(mask > MASK_LEVEL, device=points.device).reshape(-1)
        hit = fg[v.clamp(0, h - 1) * w + u.clamp(0, w - 1)] & inside
        seen += inside.int()
        background += (inside & ~hit).int()
    return seen, background


def box_votes(boxes: torch.Tensor, block: int, size: torch.Tensor, aabb: torch.Tensor,
              cameras: list[Camera], foreground: list[torch.Tensor], tables: list[torch.Tensor]
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(seen (M,), background (M,), undecided (M,)) int32: of the views, how many see every
    lattice vertex of each box of `boxes` (M, 3) (box i covers vertices i * `block` .. i * block
    + block - 1 along each axis, of the lattice of `size` (3,) vertices over `aabb` (2, 3)), how
    many of those on the background, and in how many the box's vertices may vote differently
    (see background_lattice). `foreground` (H, W) bool masks and their summed-area `tables`
    (H + 1, W + 1), one a view."""
    device = boxes.device
    step = (aabb[1] - aabb[0]) / (size - 1)
    offsets = torch.tensor([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)],
                           device=device)
    corners = torch.minimum((boxes[:, None] + offsets) * block, size - 1)  # (M, 8, 3)
    points = aabb[0] + corners.reshape(-1, 3).to(aabb) * step
    seen = torch.zeros(len(boxes), dtype=torch.int32, device=device)
    background = torch.zeros_like(seen)
    undecided = torch.zeros_like(seen)
    for camera, fg, table in zip(cameras, foreground, tables):
        h, w = fg.shape
        xy, depth = screen(points, camera)
        xy, depth = xy.view(-1, 8, 2), depth.view(-1, 8)
        front, behind = (depth > 1e-9).all(1), (depth <= 1e-9).all(1)
        lo = torch.floor(xy.amin(1)).long() - 1  # a pixel's margin for rounding
        hi = torch.floor(xy.amax(1)).long() + 1
        off = front & ((hi[:, 0] < 0) | (hi[:, 1] < 0) | (lo[:, 0] >= w) | (lo[:, 1] >= h))
        within = front & (lo >= 0).all(1) & (hi[:, 0] < w) & (hi[:, 1] < h)
        x0, y0 = lo[:, 0].clamp(0, w - 1), lo[:, 1].clamp(0, h - 1)
        x1, y1 = hi[:, 0].clamp(0, w - 1) + 1, hi[:, 1].clamp(0, h - 1) + 1
        count = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
        full = within & (count == (x1 - x0) * (y1 - y0))
        empty = within & (count == 0)
        seen += (full | empty).int()
        background += empty.int()
        undecided += (~(off | behind | full | empty)).int()
    return seen, background, undecided


def _boxes_any(grid: torch.Tensor, block: int) -> torch.Tensor:
    """(ceil(X / block), ...) bool: whether any vertex of each box is set in `grid` (X, Y, Z)."""
    pad = [(-n) % block for n in grid.shape]
    padded = F.pad(grid[None, None].to(torch.uint8), (0, pad[2], 0, pad[1], 0, pad[0]))[0, 0]
    x, y, z = padded.shape
    return padded.view(x // block, block, y // block, block, z // block, block).amax((1, 3, 5)) > 0


def _boxes_spread(boxes: torch.Tensor, block: int, shape: tuple[int, ...]) -> torch.Tensor:
    """(X, Y, Z): each box's value of `boxes` at every lattice vertex it covers."""
    out = boxes
    for axis in range(3):
        out = out.repeat_interleave(block, dim=axis)
    return out[:shape[0], :shape[1], :shape[2]]


@torch.no_grad()
def background_lattice(occupied: torch.Tensor, aabb: torch.Tensor, cameras: list[Camera],
                       masks: list[np.ndarray], blocks: tuple[int, ...] = BLOCKS,
                       tolerance: float = TOLERANCE) -> torch.Tensor:
    """(X, Y, Z) bool: the vertices of `occupied` (X, Y, Z) (a lattice over `aabb` (2, 3)) that
    more than `tolerance` of the views seeing them (`cameras`, alpha `masks`) see on the
    background, as background_votes would count them vertex by vertex: the same votes, found a
    box at a time where they can be. A box of lattice cells projects inside the hull of its
    corners' projections, so where that footprint (grown by a pixel for rounding) lies off a
    photo, or inside it on the mask's object only or on its background only (a summed-area
    table says), every vertex of the box has the same vote there; a box whose votes so far
    settle the question whatever its other views say is decided for all its vertices. Boxes of
    each size of `blocks` in turn; only the vertices no box decided are projected one by one
    (on a capture, those near where the masks' outlines cross in more than one view)."""
    device = occupied.device
    size = torch.tensor(occupied.shape, device=device)
    foreground = [torch.as_tensor(m > MASK_LEVEL, device=device) for m in masks]
    tables = []
    for fg in foreground:
        table = torch.zeros(fg.shape[0] + 1, fg.shape[1] + 1, dtype=torch.int64, device=device)
        table[1:, 1:] = fg.long().cumsum(0).cumsum(1)
        tables.append(table)
    todo = occupied.clone()
    out = torch.zeros_like(occupied)
    for block in blocks:
        wanted = _boxes_any(todo, block)
        boxes = wanted.nonzero()
        if len(boxes) == 0:
            break
        seen, background, undecided = box_votes(boxes, block, size, aabb, cameras, foreground,
                                                tables)
        # whatever the undecided views say, a vertex is background (or not) when ...
        sure = background > torch.clamp(tolerance * (seen + undecided), min=1.0)
        kept = background + undecided <= torch.clamp(tolerance * seen, min=1.0)
        empty = torch.zeros_like(wanted)
        empty[tuple(boxes.T)] = sure
        done = torch.zeros_like(wanted)
        done[tuple(boxes.T)] = sure | kept
        out |= todo & _boxes_spread(empty, block, occupied.shape)
        todo &= ~_boxes_spread(done, block, occupied.shape)
    rest = todo.nonzero()
    if len(rest):
        step = (aabb[1] - aabb[0]) / (size - 1)
        seen, background = background_votes(aabb[0] + rest.to(aabb) * step, cameras, masks)
        out[tuple(rest[background > torch.clamp(tolerance * seen, min=1.0)].T)] = True
    return out


def carve_volume(volume: torch.Tensor, aabb: torch.Tensor, level: float, cameras: list[Camera],
                 masks: list[np.ndarray], tolerance: float = TOLERANCE) -> torch.Tensor:
    """`volume` (X, Y, Z), densities at the lattice vertices over `aabb` (2, 3), with the vertices
    above `level` that the masks call background (more than `tolerance` of the views that see
    them) set to zero (see the module docstring)."""
    empty = background_lattice(volume > level, aabb, cameras, masks, tolerance=tolerance)
    out = volume.clone()
    # -level, not 0: between a vertex at density d and an emptied one the surface then crosses at
    # (d - level) / (d + level) of the way, about midway, rather than next to the emptied vertex
    out[empty] = -level
    return out
