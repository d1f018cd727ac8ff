"""The surface fitted to the photos by gradient descent: each vertex moves along its normal so
that the mesh, drawn with its baked texture at the training cameras, matches the photos: in
colour where it covers the object (weighted by the photo's alpha), and in coverage against the
photo's mask along its outline.

Whether a pixel is drawn has no gradient; at the outline the coverage follows nvdiffrast's
analytic anti-aliasing (Laine et al. 2020, "Modular primitives for high-performance
differentiable rendering"): where a covered pixel and an uncovered neighbour lie either side of a
silhouette edge (between a face turned to the camera and one turned away), the point t (0..1
from the covered centre) where that edge crosses the line between their centres gives them
coverages 0.5 + t and t - 0.5 (a box filter along that line, clamped to 0..1). t is a function of
the edge's two vertices, so the mask's disagreement moves them. Inside, a pixel's colour moves the
vertices through its barycentrics (where on the texture it reads).

Settling (settle.py) moves each vertex on its own to where the bake photos' colours agree; it
moves the outline inwards with the rest and opens thin parts (the holes in lego's base plate).
This step weighs every training photo and its mask at once, as no rule tried before could
(bench/RESULTS.md). Lego 400x400, a 950-step fit, 8 held-out views drawn anti-aliased: the GLB's
squared error 27.40 -> 21.65 (x1e-4, +1.0 dB), the object's pixels it misses 0.33% -> 0.06%.
Each vertex moves at most about STEPS x LEARNING_RATE = 5 cells. Also tried (same run): the
penalty's weight 0 / 0.2 / 1 (20.75 / 22.58 / 23.60; 0 scores best on lego and on four real
captures, but leaves a flat-coloured surface's vertices where they were while the outline's
move); at weight 0: 200 steps 21.46, 60 steps 21.33, twice the rate 22.94, without settling
first 22.72; with the weight at 1 (23.38 in that prototype): two photos a step 23.21, the texture
optimised with the vertices 23.45 (refine.py solves it afterwards anyway), colour only 26.93,
the outline only 24.30.
"""

from __future__ import annotations

import contextlib
import math
import time

import numpy as np
import torch
import torch.nn.functional as F
from scipy import sparse

from windowshop.device import ThreadTuner
from windowshop.export.mesh import Mesh, vertex_normals
from windowshop.export.photos import Photos
from windowshop.export.raster import barycentrics, screen, visible_faces
from windowshop.export.settle import neighbour_mean
from windowshop.scene.types import Camera

STEPS = 100  # Adam steps, one training photo each (the photos in a shuffled cycle)
LEARNING_RATE = 0.05  # lattice cells a step
# weight of the offsets' squared Laplacian (a mean over vertices): where the colour is flat and
# gives no gradient, a vertex on the outline in some views drags its neighbours along instead of
# leaving a ridge
SMOOTH = 0.05


class Adam:
    """torch.optim.Adam's update (betas 0.9, 0.999, eps 1e-8, its single-tensor arithmetic: the
    same numbers to the bit) of one tensor, by hand: constructing torch's optimiser imports
    torch._dynamo, 1.0-1.5 s of a `windowshop export` that has not imported it yet (a fifth of
    the tune on a 20-photo capture), for one parameter."""

    BETAS = (0.9, 0.999)
    EPS = 1e-8

    def __init__(self, parameter: torch.Tensor, lr: float):
        self.parameter, self.lr, self.steps = parameter, lr, 0
        self.mean = torch.zeros_like(parameter)
        self.square = torch.zeros_like(parameter)

    @torch.no_grad()
    def step(self, grad: torch.Tensor) -> None:
        beta1, beta2 = self.BETAS
        self.steps += 1
        self.mean.lerp_(grad, 1 - beta1)
        self.square.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
        size = self.lr / (1 - beta1 ** self.steps)
        denom = (self.square.sqrt() / math.sqrt(1 - beta2 ** self.steps)).add_(self.EPS)
        self.parameter.addcdiv_(self.mean, denom, value=-size)


def manifold_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(edges (E, 2) vertex pairs, sides (E, 2) their two faces) of the edges exactly two of
    `faces` (F, 3) share."""
    corners = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(len(faces)), 3)
    pairs = np.sort(corners, 1)
    # one int64 key per edge, ordered as the vertex pairs are (a 1-D unique is several times
    # faster than the rows' unique along axis 0)
    n = int(faces.max()) + 1 if len(faces) else 1
    _, first, inverse, counts = np.unique(pairs[:, 0] * n + pairs[:, 1], return_index=True,
                                          return_inverse=True, return_counts=True)
    key = pairs[first]
    order = np.argsort(inverse.reshape(-1), kind="stable")
    start = np.cumsum(counts) - counts
    two = counts == 2
    return key[two], np.stack([owner[order[start[two]]], owner[order[start[two] + 1]]], 1)


def front_facing(position: torch.Tensor, faces: torch.Tensor, eye: torch.Tensor) -> torch.Tensor:
    """(F,) bool: whether each of `faces` (F, 3) of vertices at `position` (V, 3) turns towards
    `eye`."""
    corner = position.index_select(0, faces.reshape(-1)).view(-1, 3, 3)
    normal = torch.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0], dim=-1)
    return ((eye - corner[:, 0]) * normal).sum(-1) > 0


def silhouette_edges(position: torch.Tensor, faces: torch.Tensor, edges: torch.Tensor,
                     sides: torch.Tensor, eye: torch.Tensor) -> torch.Tensor:
    """(S, 2) the `edges` between a face turned towards `eye` and one turned away."""
    front = front_facing(position, faces, eye)
    return edges[front[sides[:, 0]] != front[sides[:, 1]]]


def outline_edges(xy: torch.Tensor, position: torch.Tensor, faces: torch.Tensor,
                  edges: torch.Tensor, sides: torch.Tensor, eye: torch.Tensor,
                  covered: torch.Tensor) -> torch.Tensor:
    """(S, 2) the silhouette_edges that may cross between a `covered` (H, W) pixel and an
    uncovered neighbour (the only ones outline_coverage uses), vertices at pixel coordinates `xy`
    (V, 2): an edge crosses the line between two pixel centres only inside its own bounding
    box, so edges whose box (grown by a pixel for rounding) holds no pixel of such a pair (a
    summed-area table says) cannot, and their faces are not even tested (dtu_skull, kermit at
    100k faces: 2,400-2,900 outline edges of their 22-34k silhouette edges, of 146-148k)."""
    h, w = covered.shape
    pair = torch.zeros(h, w, dtype=torch.int32, device=covered.device)
    across = covered[:, :-1] != covered[:, 1:]
    pair[:, :-1] |= across
    pair[:, 1:] |= across
    down = covered[:-1] != covered[1:]
    pair[:-1] |= down
    pair[1:] |= down
    table = torch.zeros(h + 1, w + 1, dtype=torch.int32, device=covered.device)
    table[1:, 1:] = pair.cumsum(0).cumsum(1)
    table = table.view(-1)
    # each vertex's pixel column and row, then each edge's ends', int32 and contiguous, and
    # index_select throughout (several times faster than indexing on the CPU)
    column, row = torch.floor(xy).clamp_(-2**30, 2**30).to(torch.int32).T.contiguous()
    first, second = edges[:, 0].contiguous(), edges[:, 1].contiguous()
    a, b = column.index_select(0, first), column.index_select(0, second)
    x0, x1 = torch.minimum(a, b).sub_(1).clamp_(0, w), torch.maximum(a, b).add_(2).clamp_(0, w)
    a, b = row.index_select(0, first), row.index_select(0, second)
    y0 = torch.minimum(a, b).sub_(1).clamp_(0, h).mul_(w + 1)  # the box grown by a pixel,
    y1 = torch.maximum(a, b).add_(2).clamp_(0, h).mul_(w + 1)  # as the table's rows

    def at(index: torch.Tensor) -> torch.Tensor:
        return table.index_select(0, index)

    count = at(y1 + x1) - at(y0 + x1) - at(y1 + x0) + at(y0 + x0)
    near = (count > 0).nonzero()[:, 0]
    edges, sides = edges.index_select(0, near), sides.index_select(0, near)
    front = front_facing(position, faces.index_select(0, sides.reshape(-1)), eye).view(-1, 2)
    return edges[front[:, 0] != front[:, 1]]


def row_crossings(xy: torch.Tensor, edges: torch.Tensor, covered: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Left-right neighbours of which one is `covered` (H, W), and where a silhouette edge
    (`edges` (S, 2) of vertices at pixel coordinates `xy` (V, 2)) crosses between their centres:
    (inside (N,), outside (N,) flat pixel indices, t (N,) from the inside centre, in pixels).
    Where several edges cross between two pixels, the one nearest the outside pixel is the
    outline's."""
    h, w = covered.shape
    rows, cols = (covered[:, :-1] != covered[:, 1:]).nonzero(as_tuple=True)
    pair_key = rows * w + cols  # the pair (rows, cols) - (rows, cols + 1)
    if len(pair_key) == 0:  # no covered pixel beside an uncovered one: no outline to cross
        empty = torch.zeros(0, dtype=torch.int64, device=xy.device)
        return empty, empty, xy[:0, 0]
    a, b = xy[edges[:, 0]], xy[edges[:, 1]]
    lo, hi = torch.minimum(a[:, 1], b[:, 1]).detach(), torch.maximum(a[:, 1], b[:, 1]).detach()
    first = torch.ceil(lo - 0.5).clamp(min=0).long()
    count = (torch.floor(hi - 0.5).clamp(max=h - 1).long() - first + 1).clamp(min=0)
    count = torch.where(hi - lo > 1e-9, count, torch.zeros_like(count))
    edge = torch.repeat_interleave(torch.arange(len(edges), device=xy.device), count)
    row = first[edge] + torch.arange(len(edge), device=xy.device) - torch.repeat_interleave(
        torch.cumsum(count, 0) - count, count)
    a, b = a[edge], b[edge]
    x = a[:, 0] + (row.to(xy) + 0.5 - a[:, 1]) / (b[:, 1] - a[:, 1]) * (b[:, 0] - a[:, 0])
    col = torch.floor(x.detach() - 0.5).long()  # the crossing lies between centres col, col + 1
    key = row * w + col
    order = torch.argsort(pair_key)
    position = torch.searchsorted(pair_key[order], key).clamp(max=len(order) - 1)
    hit = (col >= 0) & (col < w - 1) & (pair_key[order][position] == key)
    pair, x, col = order[position[hit]], x[hit], col[hit]
    left_inside = covered[rows[pair], cols[pair]]
    t = torch.where(left_inside, x - (col + 0.5), (col + 1.5) - x).clamp(0.0, 1.0)
    nearest = torch.full((len(pair_key),), -1.0, device=xy.device, dtype=t.dtype)
    nearest = nearest.scatter_reduce(0, pair, t.detach(), "amax")
    keep = t.detach() == nearest[pair]
    pair, t, left_inside = pair[keep], t[keep], left_inside[keep]
    left = rows[pair] * w + cols[pair]
    return torch.where(left_inside, left, left + 1), torch.where(left_inside, left + 1, left), t


def outline_coverage(xy: torch.Tensor, edges: torch.Tensor, covered: torch.Tensor
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """(pixels (N,) flat indices, coverage (N,)): the anti-aliased coverage (see the module
    docstring) of the pixels on either side of the outline of `covered` (H, W), whose silhouette
    `edges` (S, 2) join vertices at pixel coordinates `xy` (V, 2). Differentiable in `xy`."""
    h, w = covered.shape
    coverage = covered.reshape(-1).to(xy.dtype)
    touched = []
    for transposed in (False, True):
        if transposed:  # columns: the same along rows of the transposed image
            inside, outside, t = row_crossings(xy.flip(-1), edges, covered.T)
            inside, outside = (inside % h) * w + inside // h, (outside % h) * w + outside // h
        else:
            inside, outside, t = row_crossings(xy, edges, covered)
        coverage = coverage.index_add(0, inside, -(0.5 - t).clamp(min=0.0))
        coverage = coverage.index_add(0, outside, (t - 0.5).clamp(min=0.0))
        touched += [inside, outside]
    pixels = torch.unique(torch.cat(touched))
    return pixels, coverage[pixels].clamp(0.0, 1.0)


def photo_loss(position: torch.Tensor, faces: torch.Tensor, corner_uv: torch.Tensor,
               texture: torch.Tensor, edges: torch.Tensor, sides: torch.Tensor, camera: Camera,
               image: torch.Tensor, alpha: torch.Tensor | None) -> torch.Tensor:
    """How the mesh at `position` (V, 3), textured by `texture` (1, 3, S, S) at `corner_uv`
    (F, 3, 2), drawn at `camera` differs from `image` (H*W, 3) and its `alpha` (H*W,) (see the
    module docstring), summed over pixels over their number."""
    h, w = camera.height, camera.width
    xy, depth = screen(position, camera)
    face = visible_faces(xy.detach(), depth.detach(), faces, w, h)
    pixels = (face >= 0).nonzero()[:, 0]
    drawn = face.index_select(0, pixels)  # (index_select: faster than indexing on the CPU)
    weights = barycentrics(xy, depth, faces.index_select(0, drawn), pixels, w)
    at = (weights[..., None] * corner_uv.index_select(0, drawn)).sum(1)
    colour = F.grid_sample(texture, (2.0 * at - 1.0)[None, None], align_corners=False)[0, :, 0].T
    error = ((colour - image.index_select(0, pixels)) ** 2).mean(-1)
    if alpha is None:
        return error.sum() / (h * w)
    eye = torch.as_tensor(camera.c2w[:3, 3]).to(position)
    covered = (face >= 0).view(h, w)
    outline = outline_edges(xy.detach(), position.detach(), faces, edges, sides, eye, covered)
    edge_pixels, coverage = outline_coverage(xy, outline, covered)
    return ((alpha.index_select(0, pixels) * error).sum()
            + ((coverage - alpha[edge_pixels]) ** 2).sum()) / (h * w)


def tune_surface(mesh: Mesh, corner_uv: np.ndarray, texture: np.ndarray, photos: Photos,
                 cell: float) -> Mesh:
    """`mesh` with its vertices moved along their normals to match `photos` (see the module
    docstring), textured by `texture` (S, S, 3) in [0, 1] at `corner_uv` (F, 3, 2) (glTF's);
    `cell` is the lattice's cell size (world units)."""
    base = torch.as_tensor(mesh.vertices, dtype=torch.float32)
    normals = torch.as_tensor(vertex_normals(mesh), dtype=torch.float32) * cell
    faces = torch.as_tensor(mesh.faces, dtype=torch.int64)
    edges, sides = (torch.as_tensor(x) for x in manifold_edges(mesh.faces))
    uv = torch.as_tensor(corner_uv, dtype=torch.float32)
    image = torch.as_tensor(texture, dtype=torch.float32).permute(2, 0, 1)[None]
    laplacian = sparse.eye(len(base)) - neighbour_mean(mesh)
    # the penalty's gradient, 2 SMOOTH L^T L x / V, by hand: through autograd the sparse product
    # and its backward took a third of the step
    smoothing = ((2.0 * SMOOTH / len(base)) * (laplacian.T @ laplacian)).astype(np.float32).tocsr()
    offset = torch.zeros(len(base), requires_grad=True)
    optimiser = Adam(offset, LEARNING_RATE)
    order = np.random.default_rng(0).permutation(len(photos.cameras))
    # the thread count that steps fastest, as the fit's: beside another job, torch's threads
    # spin while one of them waits for a core (bench/RESULTS.md, stop 55)
    tuner = ThreadTuner(base.device)
    with contextlib.closing(tuner):
        for step in range(STEPS):
            tuner.before_step()
            began = time.perf_counter()
            i = int(order[step % len(order)])
            photo = torch.as_tensor(photos.images[i], dtype=torch.float32).reshape(-1, 3)
            alpha = None if photos.alphas[i] is None else torch.as_tensor(
                photos.alphas[i], dtype=torch.float32).reshape(-1)
            loss = photo_loss(base + offset[:, None] * normals, faces, uv, image, edges, sides,
                              photos.cameras[i], photo, alpha)
            offset.grad = None
            loss.backward()
            offset.grad += torch.from_numpy(smoothing @ offset.detach().numpy())
            optimiser.step(offset.grad)
            tuner.after_step(time.perf_counter() - began)
    moved = base + offset.detach()[:, None] * normals
    return Mesh(moved.numpy().astype(np.float64), mesh.faces)
