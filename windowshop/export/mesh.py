"""The object's surface as a triangle mesh: the field's density on a lattice over the object's box,
marching cubes at the chosen level, only the largest pieces (floaters dropped), decimated.

The field already holds only the object: a masked scene's model is carved to the visual hull of
its masks (no table, no room), and nothing outside the box is ever trained. The lattice is padded
with empty space, so every piece is closed (watertight) even where the object meets the box.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from scipy import sparse
from scipy.sparse import csgraph

from windowshop.errors import UserError
from windowshop.model import RadianceModel


# lattice cells a field voxel: real captures' fields (95-139 voxels along the box's longest side)
# exported at 1.5 cells a voxel instead of 256 cells: the GLB at held-out photos dtu_skull +0.26,
# fruit +0.38, beer_can +0.10, kermit -0.18 dB, kermit's faces outside its covered hull 15 -> 0,
# dtu_skull's export 15 -> 9.5 s (ordinary CPU); lego's field (175 voxels) keeps 256 (at 160
# cells it lost 0.6 dB). bench/RESULTS.md
CELLS_PER_VOXEL = 1.5
MIN_CELLS = 8


@dataclass
class Mesh:
    """A triangle mesh in the scene's normalised frame."""

    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64, counter-clockwise seen from outside


def lattice_resolution(model: RadianceModel, aabb: np.ndarray, most: int) -> int:
    """Cells along the longest side of `aabb` (2, 3) for the lattice of `model`'s density:
    CELLS_PER_VOXEL a voxel of a grid field, at most `most` (`most` for a field with no grid).
    Finer, marching cubes traces only the grid's trilinear interpolation between voxels, and the
    export's later steps (carve, settle, tune, bake), which work in cells, work on that noise."""
    grid = getattr(model, "density_grid", None)
    if grid is None:
        return most
    cells = CELLS_PER_VOXEL * float((aabb[1] - aabb[0]).max()) / float(grid.voxel.min())
    return int(min(most, max(MIN_CELLS, np.ceil(cells))))


def lattice_shape(aabb: np.ndarray, resolution: int) -> tuple[int, int, int]:
    """Vertices per axis of a cubic lattice over `aabb` (2, 3), `resolution` cells along its
    longest side."""
    extent = aabb[1] - aabb[0]
    cell = float(extent.max()) / resolution
    return tuple(int(max(2, round(float(e) / cell) + 1)) for e in extent)


@torch.no_grad()
def sample_volume(model: RadianceModel, aabb: np.ndarray, resolution: int,
                  chunk: int = 1 << 18) -> torch.Tensor:
    """(X, Y, Z) densities of `model` at the vertices of the lattice over `aabb` (2, 3)."""
    device = next(model.parameters()).device
    shape = lattice_shape(aabb, resolution)
    axes = [torch.linspace(float(aabb[0, i]), float(aabb[1, i]), n, device=device)
            for i, n in enumerate(shape)]
    x, y, z = axes
    out = torch.empty(shape, device=device)
    flat = out.view(shape[0], -1)
    yz = torch.stack(torch.meshgrid(y, z, indexing="ij"), -1).reshape(-1, 2)
    rows = max(1, chunk // len(yz))
    for start in range(0, shape[0], rows):
        xs = x[start:start + rows]
        points = torch.cat([xs.repeat_interleave(len(yz))[:, None], yz.repeat(len(xs), 1)], -1)
        flat[start:start + len(xs)] = model.density(points).view(len(xs), -1)
    return out


def marching_cubes(volume: np.ndarray, level: float, aabb: np.ndarray) -> Mesh:
    """The iso-surface `volume` (X, Y, Z) = `level` over `aabb` (2, 3), closed at the box."""
    from skimage.measure import marching_cubes as skimage_mc

    if not np.isfinite(level) or float(volume.max()) <= level:
        raise UserError("the field holds no object (its density nowhere reaches a surface): "
                        "train longer, or check the photos and masks")
    padded = np.pad(volume.astype(np.float32), 1, constant_values=0.0)
    spacing = (aabb[1] - aabb[0]) / (np.array(volume.shape) - 1)
    vertices, faces, _, _ = skimage_mc(padded, level, spacing=tuple(spacing),
                                       gradient_direction="ascent", allow_degenerate=False)
    # gradient "ascent": density rises inwards, so the faces wind counter-clockwise from outside
    return Mesh(vertices=vertices.astype(np.float64) - spacing + aabb[0],
                faces=faces.astype(np.int64))


def components(mesh: Mesh) -> np.ndarray:
    """(F,) the connected piece each face belongs to (pieces share vertices)."""
    f = mesh.faces
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    n = len(mesh.vertices)
    graph = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, label = csgraph.connected_components(graph, directed=False)
    return label[f[:, 0]]


def face_areas(mesh: Mesh) -> np.ndarray:
    """(F,) the area of every face."""
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    u, v = (b - a).T, (c - a).T  # the cross product by its components: np.cross's, faster
    cross = np.stack([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                      u[0] * v[1] - u[1] * v[0]], -1)
    return 0.5 * np.linalg.norm(cross, axis=-1)


def keep_largest(mesh: Mesh, share: float) -> Mesh:
    """Only the pieces whose area is at least `share` of the largest piece's (floaters go)."""
    label = components(mesh)
    area = np.bincount(label, weights=face_areas(mesh))
    keep = area >= share * area.max()
    return compact(Mesh(mesh.vertices, mesh.faces[keep[label]]))


def compact(mesh: Mesh) -> Mesh:
    """The mesh without the vertices no face uses (their order kept)."""
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[mesh.faces] = True
    index = np.cumsum(used) - 1  # a used vertex's new index (a sort's np.unique, in one pass)
    return Mesh(vertices=mesh.vertices[used], faces=index[mesh.faces])


def decimate(mesh: Mesh, triangles: int) -> Mesh:
    """At most `triangles` faces, by quadric edge collapse (fast-simplification)."""
    if len(mesh.faces) <= triangles:
        return mesh
    import fast_simplification

    vertices, faces = fast_simplification.simplify(mesh.vertices.astype(np.float32), mesh.faces,
                                                   target_count=triangles)
    return compact(Mesh(vertices.astype(np.float64), drop_fins(faces.astype(np.int64))))


def drop_fins(faces: np.ndarray) -> np.ndarray:
    """`faces` (F, 3) without the pairs of faces on the same three vertices: the flat fins an
    edge collapse leaves where a thin part folded shut (they enclose nothing). Faces cancel in
    pairs: of an odd number on the same vertices (three, where a fin meets the surface) one
    stays, or the surface would open there."""
    _, first, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True,
                                          return_inverse=True, return_counts=True)
    keep = np.zeros(len(faces), dtype=bool)
    keep[first[counts % 2 == 1]] = True
    return faces[keep]


def open_edges(mesh: Mesh) -> int:
    """How many edges have one face only (0: the surface is closed)."""
    f = mesh.faces
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int(np.sum(counts == 1))


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """(V, 3) unit normals: the area-weighted mean of the faces around each vertex."""
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    face_normals = np.cross(b - a, c - a)  # length = twice the area: area weighting
    normals = np.zeros_like(mesh.vertices)
    for i in range(3):
        np.add.at(normals, mesh.faces[:, i], face_normals)
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    return normals / np.maximum(length, 1e-12)


def object_mesh(volume: torch.Tensor, level: float, aabb: np.ndarray, triangles: int,
                keep_share: float) -> Mesh:
    """The object's surface from densities `volume` (X, Y, Z) over `aabb`: see the module docstring."""
    mesh = marching_cubes(volume.cpu().numpy(), level, aabb)
    if len(mesh.faces) == 0:
        raise UserError("the field's surface has no triangles: train longer, or check the photos")
    return decimate(keep_largest(mesh, keep_share), triangles)


def face_pairs(faces: np.ndarray) -> np.ndarray:
    """(E, 2) the two faces across each edge that `faces` (F, 3) share."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(faces)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    pair = np.flatnonzero((edges[1:] == edges[:-1]).all(1))  # an edge's two faces, side by side
    return np.stack([owner[pair], owner[pair + 1]], 1)


def neighbour_angles(mesh: Mesh, pairs: np.ndarray | None = None) -> np.ndarray:
    """(E,) degrees between the normals of the two faces across each edge they share
    (`pairs`: face_pairs(mesh.faces), passed where one set of faces is measured again)."""
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-20)
    pairs = face_pairs(mesh.faces) if pairs is None else pairs
    cos = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def taubin(mesh: Mesh, steps: int, shrink: float = 0.5, inflate: float = -0.53,
           fixed: np.ndarray | None = None, enough: Callable[[Mesh], bool] | None = None) -> Mesh:
    """`mesh` smoothed by Taubin's lambda|mu filter (`steps` pairs of a step towards the
    neighbours' mean and one back out, so the surface smooths without shrinking); with
    `enough`, it stops in the first pair after which `enough(smoothed)` holds, as early along
    it as it holds (smoothing costs the photos' detail: take no more than needed); `fixed` (V,)
    bool vertices stay."""
    from windowshop.export.settle import neighbour_mean

    if steps <= 0:
        return mesh
    mean = neighbour_mean(mesh)
    x = mesh.vertices.copy()
    for _ in range(steps):
        previous = x
        for factor in (shrink, inflate):
            step = factor * (mean @ x - x)
            if fixed is not None:
                step[fixed] = 0.0
            x = x + step
        if enough is not None and enough(Mesh(x, mesh.faces)):
            return Mesh(_least_enough(previous, x, mesh.faces, enough), mesh.faces)
    return Mesh(x, mesh.faces)


def _least_enough(before: np.ndarray, after: np.ndarray, faces: np.ndarray,
                  enough: Callable[[Mesh], bool], halvings: int = 4) -> np.ndarray:
    """The vertices the shortest way from `before` to `after` (to 1/2^`halvings` of it) at
    which `enough` holds; it holds at `after`."""
    low, high = 0.0, 1.0
    for _ in range(halvings):
        middle = (low + high) / 2
        if enough(Mesh(before + middle * (after - before), faces)):
            high = middle
        else:
            low = middle
    return before + high * (after - before)
