"""The sides no photo saw, closed smoothly instead of as the field's guesses.

Where no training photo looked (the back of a front-only capture), the field's density is
whatever training left there: marching cubes turns it into torn shards. Before marching cubes,
the lattice's surface points are tested against the training cameras as the texture's bake
tests texels (photos.py): a point is seen by a camera when the surface there faces it, it
projects into its photo, and it is the nearest surface in that pixel's neighbourhood (a depth
buffer splatted from the surface points themselves). Away from every seen point (beyond NEAR
cells, fully past NEAR + RAMP) the lattice's occupancy is replaced by the convex hull of the seen
points, less the space any photo saw through (in front of the nearest surface in its pixel), its
edges rounded by a Gaussian of SMOOTH cells: the back of a front-only capture is closed by the
hull its photographed front spans, the field's shards and hollows there go, concavities a photo
looked into stay open, and the seen surface is kept as it was.

`seen_points` is also what texture.py asks to colour neutrally (see `neutral_colour`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from windowshop.export.mesh import Mesh
from windowshop.export.photos import splat_depth
from windowshop.export.raster import screen
from windowshop.scene.types import Camera

MIN_COS = 0.15  # as photos.MIN_COS: a surface seen more obliquely is not seen
SIDE = 256  # pixels on a photo's longer side for the visibility test
# cells a seen point may lie behind the nearest surface in its pixel's 3x3 (plus what the
# slope allows). At 4, surface hidden 5-8 cells behind a nearer one passed as seen and kept the
# field's shards there: kermit's GLB had 1709 faces over 25 cells outside the hull of what its
# photos show (bench_models), 185 at 2, 68 at 1; the GLB's PSNR within 0.04 dB of 4's on the
# four shared captures at 2, dtu_skull 0.09 dB lower at 1
TOLERANCE = 2.0
# ... and what the slope there allows (two pixels' footprint times its tangent), at most this
# many cells: a surface seen nearly edge-on (cos 0.15: 13 footprints) passed as seen behind the
# folds of a crumpled surface, whose hidden sides then stayed the field's. Capped at 2 (on the
# four shared captures, bench_models): kermit's faces outside the photographed hull 185 -> 11,
# the surface's area over its hull 3.69 -> 2.12 (beer_can), 1.87 -> 1.48 (dtu_skull), the mean
# neighbour angle 4-6 degrees lower, the GLB -0.11 / -0.10 dB (dtu_skull, kermit), +0.07
# (beer_can), +0.01 (fruit); at 1, kermit's closure took 5738 faces outside
SLOPE_CELLS = 2.0
EMPTY = 2.0  # cells in front of the nearest surface in its pixel from which space counts as seen empty
STRIDE = 2  # the visibility is tested on every STRIDE-th lattice vertex along each axis
NEAR = 3.0  # cells from a seen surface point within which the field's own surface is kept
RAMP = 4.0  # cells over which the blurred occupancy takes over beyond NEAR
SMOOTH = 2.0  # cells: the Gaussian's sigma that rounds the hull's edges
HULL_POINTS = 5_000  # seen points the convex hull is taken of, at most (a random subset)
HULL_STRIDE = 4  # the hull's occupancy is tested on every HULL_STRIDE-th lattice vertex at most,
HULL_CELLS = 64  # keeping at least this many along the lattice's longest side
COVER_MARGIN = 0.02  # of the box's diagonal: how far past the seen faces' hull the model may reach


@dataclass
class Visibility:
    """Which of the lattice's surface points some training photo saw."""

    points: np.ndarray  # (S, 3) the lattice's surface points (normalised frame)
    index: np.ndarray  # (S, 3) their indices on the lattice thinned by `stride`
    seen: np.ndarray  # (S,) bool
    stride: int = 1
    cell: float = 0.0  # the thinned lattice's cell (world units)
    # each camera, made small, and the nearest surface point's depth in each of its pixels
    # (splat_depth's): what tells space a camera saw through from space it did not
    views: list[tuple[Camera, torch.Tensor]] = field(default_factory=list)
    # (S,) bool: on a piece the model keeps (surface_visibility's keep_share); None: all
    kept: np.ndarray | None = None

    @property
    def unseen_share(self) -> float:
        return float(1.0 - self.seen.mean()) if len(self.seen) else 0.0


def lattice_points(index: np.ndarray, aabb: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """(N, 3) the positions of lattice vertices `index` (N, 3) over `aabb` (2, 3)."""
    spacing = (aabb[1] - aabb[0]) / (np.asarray(shape) - 1)
    return aabb[0] + index * spacing


def surface_visibility(occupied: np.ndarray, aabb: np.ndarray, cameras: list[Camera],
                       side: int = SIDE, stride: int = STRIDE, keep_share: float = 0.0
                       ) -> Visibility:
    """Which surface points of the `occupied` (X, Y, Z) lattice over `aabb` (every `stride`-th
    vertex along each axis) the `cameras` see. `kept` marks the points on the pieces of the
    lattice whose surface holds at least `keep_share` of the largest piece's points (as
    mesh.keep_largest keeps pieces by area): the hull (hull_occupancy) is taken of those seen
    points only, so it does not reach out to a floater the model drops (kermit: 710 faces
    outside the seen part's hull, 550 of them on the hull's closure)."""
    thin = occupied[::stride, ::stride, ::stride]
    surface = thin & ~ndimage.binary_erosion(thin)
    index = np.argwhere(surface)
    kept = np.ones(len(index), dtype=bool)
    if keep_share > 0:
        label, count = ndimage.label(thin)
        if count > 1:
            size = np.bincount(label[surface], minlength=count + 1)
            size[0] = 0
            kept = (size >= keep_share * size.max())[label[tuple(index.T)]]
    points = lattice_points(index * stride, aabb, occupied.shape)
    blur = ndimage.gaussian_filter(thin.astype(np.float32), 1.0)
    grad = np.stack([ndimage.sobel(blur, axis=k)[tuple(index.T)] for k in range(3)], -1)
    normals = -grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-12)
    cell = stride * float((aabb[1] - aabb[0]).max()) / max(max(occupied.shape) - 1, 1)
    seen, views = seen_by(points, normals, cameras, cell, side, (aabb[0] + aabb[1]) / 2)
    return Visibility(points=points, index=index, seen=seen, stride=stride, cell=cell,
                      views=views, kept=kept)


def seen_by(points: np.ndarray, normals: np.ndarray, cameras: list[Camera], spacing: float,
            side: int, centre: np.ndarray) -> tuple[np.ndarray, list[tuple[Camera, torch.Tensor]]]:
    """((S,) bool: which surface `points` (S, 3) with outward `normals` (S, 3), about `spacing`
    apart, some camera of `cameras` sees; each camera made small and its depth buffer). A point
    is seen when it faces the camera, projects into its photo and is at most TOLERANCE spacings
    (plus what the slope allows) behind the nearest point in its pixel's 3x3; `centre` is the
    object's, whose distance sizes the small cameras."""
    p = torch.as_tensor(points, dtype=torch.float32)
    n = torch.as_tensor(normals, dtype=torch.float32)
    seen = torch.zeros(len(p), dtype=torch.bool)
    views = []
    for camera in cameras:
        # small enough that neighbouring surface points fall at most a pixel apart (the depth
        # buffer's 3x3 neighbourhood then has no holes to see through), at most `side` pixels
        distance = float(np.linalg.norm(camera.c2w[:3, 3] - centre))
        scale = min(side / max(camera.width, camera.height), distance / (spacing * camera.fx))
        small = camera.resized(max(1, round(camera.width * scale)), max(1, round(camera.height * scale)))
        xy, z = screen(p, small)
        depth = splat_depth(xy, z, small)
        views.append((small, depth))
        eye = torch.as_tensor(small.c2w[:3, 3], dtype=torch.float32)
        cos = (n * F.normalize(eye - p, dim=-1)).sum(-1)
        px = torch.floor(xy).long()
        inside = ((px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < small.width)
                  & (px[:, 1] < small.height) & (z > 0) & (cos > MIN_COS))
        k = inside.nonzero()[:, 0]
        c = cos[k]
        slope = 2 * z[k] / small.fx * torch.sqrt(1 - c * c) / c
        slack = TOLERANCE * spacing + torch.clamp(slope, max=SLOPE_CELLS * spacing)
        seen[k[z[k] <= depth[px[k, 1], px[k, 0]] + slack]] = True
    return seen.numpy(), views


def seen_empty(visibility: Visibility, points: torch.Tensor) -> torch.Tensor:
    """(N,) bool: whether some camera saw through each of `points` (N, 3): it lies in the
    camera's photo more than EMPTY cells in front of the nearest surface in its pixel."""
    empty = torch.zeros(len(points), dtype=torch.bool)
    for small, depth in visibility.views:
        xy, z = screen(points, small)
        px = torch.floor(xy).long()
        ok = ((px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < small.width)
              & (px[:, 1] < small.height) & (z > 0)).nonzero()[:, 0]
        empty[ok[z[ok] < depth[px[ok, 1], px[ok, 0]] - EMPTY * visibility.cell]] = True
    return empty


def unseen_weight(visibility: Visibility, shape: tuple[int, int, int]) -> np.ndarray:
    """(X, Y, Z) float32 in [0, 1]: 0 within NEAR cells of a seen surface point, rising to 1
    (unseen) over RAMP cells; all 0 when every point (or none) was seen."""
    weight = np.zeros(shape, dtype=np.float32)
    if visibility.seen.all() or not visibility.seen.any():
        return weight
    k = visibility.stride
    far = np.ones(tuple(-(-n // k) for n in shape), dtype=bool)  # the thinned lattice's shape
    far[tuple(visibility.index[visibility.seen].T)] = False
    distance = k * ndimage.distance_transform_edt(far).astype(np.float32)  # in full-size cells
    weight = torch.as_tensor(np.clip((distance - NEAR) / RAMP, 0.0, 1.0))
    size = tuple(n * k for n in far.shape)
    weight = F.interpolate(weight[None, None], size=size, mode="nearest")[0, 0]
    return weight[:shape[0], :shape[1], :shape[2]].numpy()


def hull_occupancy(visibility: Visibility, shape: tuple[int, int, int], aabb: np.ndarray,
                   weight: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """(X, Y, Z) float32 in [0, 1], 0.5 on the surface: inside the convex hull of the seen surface
    points and not where a camera saw through (seen_empty), over the lattice of `shape` over
    `aabb`. The hull's signed distance (the largest of its planes') and the seen-through space
    are found on every k-th vertex (k <= HULL_STRIDE) where the unseen `weight` (X, Y, Z) is not
    0 (nowhere else is the result used) and brought to full size trilinearly: a distance that is
    linear between the vertices stays exact, so the hull's faces come out flat, and its edges
    round over SMOOTH cells."""
    from scipy.spatial import ConvexHull, QhullError

    seen = visibility.points[visibility.seen if visibility.kept is None
                             else visibility.seen & visibility.kept]
    if len(seen) > HULL_POINTS:
        seen = seen[np.random.default_rng(0).choice(len(seen), HULL_POINTS, replace=False)]
    k = int(np.clip(max(shape) // HULL_CELLS, 1, HULL_STRIDE))
    try:
        planes = torch.as_tensor(ConvexHull(seen).equations, dtype=torch.float32)  # (P, 4)
    except (QhullError, ValueError):
        return np.zeros(shape, dtype=np.float32)
    cell = float((aabb[1] - aabb[0]).max()) / max(max(shape) - 1, 1)
    # every coarse vertex next to a wanted one too, so interpolation reads computed values only
    wanted = ndimage.binary_dilation(weight[::k, ::k, ::k] > 0, np.ones((3, 3, 3), bool))
    index = np.argwhere(wanted)
    distance = np.full(wanted.shape, 10.0 * SMOOTH * cell, dtype=np.float32)  # outside
    empty = np.zeros(wanted.shape, dtype=np.float32)
    p = torch.as_tensor(lattice_points(index * k, aabb, shape), dtype=torch.float32)
    d = torch.empty(len(p))
    for first in range(0, len(p), chunk):  # chunks of (points x planes) that stay in the cache
        d[first:first + chunk] = (p[first:first + chunk] @ planes[:, :3].T + planes[:, 3]).amax(1)
    distance[tuple(index.T)] = d.numpy()
    inside = (d < 0).nonzero()[:, 0]
    through = seen_empty(visibility, p[inside])  # never fill what a photo saw through
    empty[tuple(index[inside[through].numpy()].T)] = 1.0

    def full_size(coarse: np.ndarray) -> torch.Tensor:
        # coarse vertex i is full vertex i * k (align_corners), the last few padded by the edge
        size = tuple((n - 1) * k + 1 for n in coarse.shape)
        out = F.interpolate(torch.as_tensor(coarse)[None, None], size=size, mode="trilinear",
                            align_corners=True)
        pad = [max(0, n - m) for n, m in zip(shape, size)]
        if any(pad):
            out = F.pad(out, (0, pad[2], 0, pad[1], 0, pad[0]), mode="replicate")
        return out[0, 0, :shape[0], :shape[1], :shape[2]]

    # in place, float32: 0.5 - d / (2 SMOOTH cell), clipped, times 1 - the seen-through share
    solid = full_size(distance).div_(2 * SMOOTH * cell).neg_().add_(0.5).clamp_(0.0, 1.0)
    solid.mul_(full_size(ndimage.gaussian_filter(empty, SMOOTH / k)).neg_().add_(1.0))
    return solid.contiguous().numpy()


def close_unseen(volume: np.ndarray, level: float, weight: np.ndarray,
                 target: np.ndarray) -> np.ndarray:
    """(X, Y, Z) densities: `volume`'s where the unseen `weight` (X, Y, Z) is 0, the occupancy
    `target` (X, Y, Z) in [0, 1] (hull_occupancy; 0.5 is the surface) where it is 1, blended
    between, at the same `level`."""
    if not weight.any():
        return volume
    v, w, t = (torch.as_tensor(a) for a in (volume, weight, target))
    # both as "occupancy", 0.5 at the level: the field's density through d / (d + level)
    # (float32 in place: a few passes over the lattice instead of a dozen)
    field = v.clamp(min=0.0)
    field.div_(field + level)
    blended = w.neg().add_(1.0).mul_(field).add_(w * t)  # (1 - w) field + w target
    out = (level * blended).div_(blended.neg_().add_(1.0).clamp_(min=1e-6))
    return torch.where(w > 0, out, v).numpy().astype(volume.dtype, copy=False)


def held_to_covered(mesh: Mesh, cameras: list[Camera], aabb: np.ndarray,
                    margin: float = COVER_MARGIN, side: int = SIDE) -> Mesh:
    """`mesh` with every vertex beyond the region the `cameras` cover (the convex hull of the
    faces they see, seen_by, its corners grown by `margin` of `aabb`'s diagonal away from its
    centre) moved back onto that region's boundary along the line to its centre: the closure,
    tuned and smoothed after the hull was drawn, cannot bulge out past what the photos show."""
    from scipy.spatial import ConvexHull, Delaunay, QhullError

    tri = mesh.vertices[mesh.faces]
    centres = tri.mean(1)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    spacing = float(np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1).mean())
    seen, _ = seen_by(centres, normals, cameras, spacing, side, centres.mean(0))
    try:
        corners = centres[seen][ConvexHull(centres[seen]).vertices]
    except (QhullError, ValueError):
        return mesh  # too little seen to say what the photos cover
    middle = corners.mean(0)
    out = corners - middle
    grow = margin * float(np.linalg.norm(aabb[1] - aabb[0]))
    corners = corners + grow * out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
    planes = ConvexHull(corners).equations  # n . x + d <= 0 inside
    # only the vertices outside (few) against every plane: all of them would be (V, P) floats
    far = np.flatnonzero(Delaunay(corners).find_simplex(mesh.vertices) < 0)
    # the largest t <= 1 with middle + t (x - middle) inside every plane: n . (x - middle) t
    # <= room, the plane's distance from the middle (> 0), so t = 1 / max(1, max n . ray / room)
    scaled = planes[:, :3] / -(middle @ planes[:, :3].T + planes[:, 3])[:, None]
    vertices = mesh.vertices.copy()
    for first in range(0, len(far), 1024):
        ray = vertices[far[first:first + 1024]] - middle
        t = 1.0 / np.maximum((ray @ scaled.T).max(1), 1.0)
        vertices[far[first:first + 1024]] = middle + t[:, None] * ray
    return Mesh(vertices, mesh.faces)


def weight_at(weight: np.ndarray, aabb: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) the unseen `weight` (X, Y, Z) over `aabb` at the lattice vertex nearest each of
    `points` (N, 3)."""
    shape = np.asarray(weight.shape)
    index = np.round((points - aabb[0]) / (aabb[1] - aabb[0]) * (shape - 1)).astype(np.int64)
    index = np.clip(index, 0, shape - 1)
    return weight[tuple(index.T)]


def neutral_colour(colours: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(3,) the colour for surface no photo saw: grey at the mean brightness of the `colours`
    (N, 3) the photos gave (weighted by `weights` (N,)), so it neither shouts nor pretends."""
    if weights.sum() <= 0:
        return np.full(3, 0.6, dtype=np.float32)
    mean = (colours * weights[:, None]).sum(0) / weights.sum()
    grey = float(mean @ np.array([0.299, 0.587, 0.114]))
    return np.full(3, grey, dtype=np.float32)
