"""The mesh moved onto the surface where the photos agree (multi-view photo-consistency).

The surface's level is chosen by silhouettes (level.py), which puts it at the outer edge of the
field's density ramp: where grazing rays turn opaque, not where a head-on ray ends. Photos
projected onto a surface in front of the true one disagree (a texture edge lands a pixel or two
apart in each view) and the baked colour blurs. So each vertex tries offsets along its normal
(OFFSETS, in lattice cells); at each, the photos that see the vertex (photos.visible_views: the
bake's visibility and weights) lend their colours there, and the offset where they vary least
wins. Costs are averaged over each vertex's neighbours first (one pixel's colour is noisy), moving
costs STAY per cell (flat colour agrees everywhere: it stays put), and vertices too few photos
see well stay. The offsets are smoothed over the neighbours once more.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy import sparse

from windowshop.export.mesh import Mesh, vertex_normals
from windowshop.export.photos import Photos, bilinear, visible_views
from windowshop.export.raster import screen
from windowshop.export.texture import surface_samples

OFFSETS = np.arange(-2.0, 1.0 + 1e-9, 0.25)  # cells along the outward normal a vertex may move
STAY = 0.002  # cost (colour variance, summed over RGB) of moving one cell
MIN_WEIGHT = 1.0  # vertices whose views' weights sum to less stay where they are
SMOOTHING = 2  # neighbour averages of the costs, and of the offsets


def neighbour_mean(mesh: Mesh) -> sparse.csr_matrix:
    """(V, V) the mean over each vertex and its neighbours along the mesh's edges."""
    f, n = mesh.faces, len(mesh.vertices)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    adjacent = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    adjacent = ((adjacent + adjacent.T + sparse.eye(n)) > 0).astype(np.float64).tocsr()
    return sparse.diags(1.0 / np.asarray(adjacent.sum(1)).ravel()) @ adjacent


@torch.no_grad()
def disagreement(mesh: Mesh, normals: np.ndarray, photos: Photos, cell: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(cost (V, K), weight (V,)): the weighted variance of the photos' colours at each vertex
    moved OFFSETS (K,) cells along its normal, and the sum of the views' weights there."""
    p = torch.as_tensor(mesh.vertices, dtype=torch.float32)
    n = torch.as_tensor(normals, dtype=torch.float32)
    occluders = torch.as_tensor(surface_samples(mesh), dtype=torch.float32)
    weight = torch.zeros(len(p))
    first = torch.zeros(len(OFFSETS), len(p), 3)  # weighted sums of the colours ...
    second = torch.zeros(len(OFFSETS), len(p))  # ... and of their squares
    for camera, image, index, _, w in visible_views(p, n, photos, cell, occluders):
        image = torch.as_tensor(image, dtype=torch.float32)
        weight.index_add_(0, index, w)
        for k, offset in enumerate(OFFSETS):
            colour = bilinear(image, screen(p[index] + float(offset * cell) * n[index], camera)[0])
            first[k].index_add_(0, index, w[:, None] * colour)
            second[k].index_add_(0, index, w * (colour * colour).sum(-1))
    safe = weight.clamp(min=1e-9)
    mean = first / safe[None, :, None]
    variance = second / safe[None] - (mean * mean).sum(-1)
    return variance.T.numpy().astype(np.float64), weight.numpy()


def settle(mesh: Mesh, photos: Photos, cell: float) -> Mesh:
    """`mesh` with each vertex moved along its normal to where `photos` agree best (see the
    module docstring); `cell` is the lattice's cell size (world units)."""
    normals = vertex_normals(mesh)
    cost, weight = disagreement(mesh, normals, photos, cell)
    mean = neighbour_mean(mesh)
    cost = cost + STAY * np.abs(OFFSETS)[None]
    for _ in range(SMOOTHING):
        cost = mean @ cost
    offset = np.where(weight >= MIN_WEIGHT, OFFSETS[cost.argmin(1)], 0.0)
    for _ in range(SMOOTHING):
        offset = mean @ offset
    return Mesh(mesh.vertices + normals * (offset * cell)[:, None], mesh.faces)
