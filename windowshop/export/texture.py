"""Texture coordinates and the base-colour texture, baked from the photos (else the field).

UVs: every face joins the chart of the axis (+-x, +-y, +-z) its normal faces most, a chart being
the faces of one axis joined through shared edges, flattened by projecting along that axis (no
face tilts more than 55 degrees from it, so texels stretch at most 1.7x); the charts' rectangles
are packed into the square in shelves. (xatlas makes tighter atlases, but takes a minute for
100k triangles on two cores; this takes well under a second.)
Baking: each texel's surface point and normal, from the face it lies on; its colour is the
training photos' that see it (photos.py: projected with visibility, view-averaged), baked at a
coarser size when the photos are coarser than the texels (bake_size) and resampled. Where no
photo sees it well enough, or the run's photos cannot be read again, the field's colour seen
head-on (along the inward normal), averaged over a few depths just under the surface: where a
ray would stop, so what the photos taught the field. (The colour at the iso-surface point itself
is not that: the fast model composites features along a ray, and the level's point is where a ray
has barely begun to stop. On two lego views, PSNR inside the silhouette: 15.8 dB at the surface,
18.1 averaged under it, 17.9 for a full head-on render of each texel at 15x the cost. On 8
held-out lego views, inside both silhouettes: the field's 17.6 dB, the photos' 19.9.)
Empty texels take their nearest baked texel's colour, so that filtering at a chart's edge never
reads the background.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import torch
from scipy import ndimage, sparse
from scipy.sparse import csgraph

from windowshop.export.mesh import Mesh, vertex_normals
from windowshop.export.photos import Photos, blend_with_field, low_weight, project_photos
from windowshop.export.unseen import neutral_colour
from windowshop.model import RadianceModel

AXES = np.concatenate([np.eye(3), -np.eye(3)])  # (6, 3) the directions charts face
PADDING = 2  # texels between charts
FILL = 0.85  # share of the square the packed rectangles aim for
TEXELS_PER_PIXEL = 1.0  # texels across a photo's pixel worth baking (more add no detail)
MIN_BAKE = 256  # texels a side, the coarsest a texture is baked at


@dataclass
class Unwrapped:
    """A mesh with texture coordinates: its vertices split where charts meet."""

    vertices: np.ndarray  # (V', 3) float64
    faces: np.ndarray  # (F, 3) int64
    normals: np.ndarray  # (V', 3) unit
    uv: np.ndarray  # (V', 2) in [0, 1], glTF's convention: v = 0 at the image's top row
    source: np.ndarray  # (V',) the vertex of the unsplit mesh each vertex is a copy of
    # texel_faces by size: the bake and the refinement read the same (moved keeps uv and faces)
    _texel_faces: dict = field(default_factory=dict, repr=False, compare=False)

    def texel_faces(self, size: int) -> np.ndarray:
        """(size, size) int64: the face under each texel's centre (-1: none), rasterise's."""
        if size not in self._texel_faces:
            self._texel_faces[size] = rasterise(self.uv, self.faces, size)
        return self._texel_faces[size]


def moved(unwrapped: Unwrapped, mesh: Mesh) -> Unwrapped:
    """`unwrapped` with the vertices and normals of `mesh`, the unsplit mesh it was made from
    after its vertices moved."""
    return replace(unwrapped, vertices=mesh.vertices[unwrapped.source],
                   normals=vertex_normals(mesh)[unwrapped.source])


def chart_labels(mesh: Mesh) -> np.ndarray:
    """(F,) the chart of every face (see the module docstring)."""
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    axis = np.argmax(np.cross(b - a, c - a) @ AXES.T, axis=1)
    edges = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    face = np.tile(np.arange(len(mesh.faces)), 3)
    key = np.sort(edges, axis=1) @ np.array([len(mesh.vertices), 1])
    order = np.argsort(key, kind="stable")
    key, face = key[order], face[order]
    pair = np.flatnonzero(key[1:] == key[:-1])  # an edge's two faces lie next to each other
    f0, f1 = face[pair], face[pair + 1]
    same = axis[f0] == axis[f1]
    n = len(mesh.faces)
    graph = sparse.coo_matrix((np.ones(int(same.sum())), (f0[same], f1[same])), shape=(n, n))
    return csgraph.connected_components(graph, directed=False)[1]


def _projection(axis: np.ndarray) -> np.ndarray:
    """(6, 3, 2): for each chart axis, the two world axes spanning its plane (right-handed)."""
    out = np.zeros((6, 3, 2))
    for k, n in enumerate(AXES):
        u = np.roll(np.abs(n), 1)  # a world axis perpendicular to n
        out[k, :, 0], out[k, :, 1] = u, np.cross(n, u)
    return out[axis]


def shelf_pack(sizes: np.ndarray, width: float) -> tuple[np.ndarray, float]:
    """Corners (N, 2) of rectangles `sizes` (N, 2) packed in shelves of `width`, tallest first,
    and the height used. A shelf at a time: its rectangles are the run whose widths, added one
    by one from the shelf's start, stay within `width` (a cumulative sum per shelf, so the
    same float sums as adding them in a loop)."""
    order = np.argsort(-sizes[:, 1], kind="stable")
    w, h = sizes[order, 0], sizes[order, 1]
    corners = np.zeros_like(sizes)
    y, start, n = 0.0, 0, len(order)
    while start < n:
        x = np.cumsum(w[start:])  # the shelf's right edges, were every rectangle on it
        # the first rectangle whose right edge passes the shelf's width starts the next shelf
        # (a rectangle wider than the shelf still has one of its own)
        end = start + max(1, int(np.searchsorted(x > width, True)))
        corners[order[start:end], 0] = np.concatenate([[0.0], x[:end - start - 1]])
        corners[order[start:end], 1] = y
        y += float(h[start:end].max())
        start = end
    return corners, y


def chart_padding(charts: int, size: int) -> float:
    """The texels between charts: PADDING, or none when so many charts (a rough surface of
    thousands of small ones) could not fit a `size` texture with it, however small they are
    drawn (4,365 charts in 256 x 256: the shrinking never ended)."""
    room = np.full((charts, 2), 2.0 * PADDING + 1.0)  # its padding and a texel of each chart
    return PADDING if shelf_pack(room, size)[1] <= size else 0.0


def unwrap(mesh: Mesh, size: int) -> Unwrapped:
    """`mesh` with texture coordinates of a `size` x `size` texture (see the module docstring)."""
    label = chart_labels(mesh)
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    axis = np.argmax(np.cross(b - a, c - a) @ AXES.T, axis=1)
    # every (vertex, chart) pair becomes one vertex of the output
    corner_chart = np.repeat(label, 3)
    charts = int(label.max()) + 1
    # one int64 key a pair, in the pairs' order (a 1-D unique is several times faster than the
    # rows' unique along axis 0)
    _, first, inverse = np.unique(mesh.faces.reshape(-1) * charts + corner_chart,
                                  return_index=True, return_inverse=True)
    pairs = np.stack([mesh.faces.reshape(-1)[first], corner_chart[first]], 1)
    chart_axis = np.zeros(label.max() + 1, dtype=np.int64)
    chart_axis[label] = axis
    basis = _projection(chart_axis[pairs[:, 1]])  # (V', 3, 2)
    flat = np.einsum("vi,vij->vj", mesh.vertices[pairs[:, 0]], basis)
    n_charts = label.max() + 1
    lo = np.full((n_charts, 2), np.inf)
    hi = np.full((n_charts, 2), -np.inf)
    np.minimum.at(lo, pairs[:, 1], flat)
    np.maximum.at(hi, pairs[:, 1], flat)
    extent = hi - lo
    scale = np.sqrt(FILL * size * size / np.sum((extent + 1e-12).prod(1)))  # texels per unit
    padding = chart_padding(n_charts, size)
    while True:
        sizes = extent * scale + 2 * padding
        corners, used = shelf_pack(sizes, size)
        if used <= size:
            break
        scale *= 0.95
    texel = (flat - lo[pairs[:, 1]]) * scale + corners[pairs[:, 1]] + padding
    out = Mesh(vertices=mesh.vertices[pairs[:, 0]], faces=inverse.reshape(-1, 3))
    return Unwrapped(vertices=out.vertices, faces=out.faces,
                     normals=vertex_normals(mesh)[pairs[:, 0]], uv=texel / size, source=pairs[:, 0])


def rasterise(uv: np.ndarray, faces: np.ndarray, size: int) -> np.ndarray:
    """(size, size) int64: the face under each texel's centre (-1: none); uv (V, 2) in [0, 1]."""
    import cv2

    ids = np.zeros((size, size), dtype=np.int32)
    corners = np.round((uv[faces] * size - 0.5) * 16).astype(np.int32)  # 4 fractional bits
    for k, triangle in enumerate(corners):
        cv2.fillConvexPoly(ids, triangle, k + 1, lineType=cv2.LINE_8, shift=4)
    return ids.astype(np.int64) - 1


def texel_surface(unwrapped: Unwrapped, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For the covered texels: flat indices (T,), surface points (T, 3) and unit normals (T, 3),
    interpolated barycentrically over the face `ids` names."""
    size = ids.shape[0]
    index = np.flatnonzero(ids.reshape(-1) >= 0)
    face = unwrapped.faces[ids.reshape(-1)[index]]  # (T, 3)
    p = np.stack([index % size + 0.5, index // size + 0.5], -1) / size
    a, b, c = (unwrapped.uv[face[:, i]] for i in range(3))
    v0, v1, v2 = b - a, c - a, p - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    det = np.where(np.abs(det) < 1e-20, 1e-20, det)
    w1 = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
    w2 = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
    weights = np.clip(np.stack([1 - w1 - w2, w1, w2], -1), 0.0, None)  # edge texels: clamped in
    weights /= np.maximum(weights.sum(-1, keepdims=True), 1e-12)
    weights = weights.astype(np.float32)
    points = sum(weights[:, k:k + 1] * unwrapped.vertices[face[:, k]].astype(np.float32)
                 for k in range(3))
    normals = sum(weights[:, k:k + 1] * unwrapped.normals[face[:, k]].astype(np.float32)
                  for k in range(3))
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return index, points, normals


@torch.no_grad()
def field_colour(model: RadianceModel, points: np.ndarray, normals: np.ndarray,
                 depths: tuple[float, ...], chunk: int = 1 << 18) -> np.ndarray:
    """(N, 3) in [0, 1]: the field's colour under each of `points` (N, 3), seen head-on along the
    inward normal (`normals` (N, 3) point outwards), averaged over `depths` (world units) below
    the surface."""
    device = next(model.parameters()).device
    out = []
    for first in range(0, len(points), chunk):
        p = torch.as_tensor(points[first:first + chunk], dtype=torch.float32, device=device)
        n = torch.as_tensor(normals[first:first + chunk], dtype=torch.float32, device=device)
        out.append(torch.stack([model.colour(p - d * n, -n) for d in depths]).mean(0).cpu())
    return torch.cat(out).numpy() if out else np.zeros((0, 3), dtype=np.float32)


def bake_texture(model: RadianceModel, unwrapped: Unwrapped, size: int,
                 depths: tuple[float, ...], photos: Photos | None = None,
                 tolerance: float = 0.0) -> np.ndarray:
    """(B, B, 3) uint8: the base-colour texture of `unwrapped` at its bake size B <= `size`
    (bake_image, then finish_texture)."""
    return finish_texture(bake_image(model, unwrapped, size, depths, photos, tolerance))


def bake_image(model: RadianceModel, unwrapped: Unwrapped, size: int,
               depths: tuple[float, ...], photos: Photos | None = None,
               tolerance: float = 0.0, unseen: Callable[[np.ndarray], np.ndarray] | None = None
               ) -> np.ndarray:
    """(B, B, 3) float32 in [0, 1]: the base-colour texture of `unwrapped` at its bake size B:
    from the `photos` where they see the surface (photos.py; `tolerance` its depth test's), else
    from the field (its colours read at `depths` under the surface; see the module docstring).
    Photos coarser than a `size` texture are baked at a coarser size (bake_size). `unseen`
    (N, 3) points -> (N,) weights in [0, 1]: how far a point lies in the side no photo saw,
    where the colour fades to a neutral grey (unseen.neutral_colour)."""
    bake = size if photos is None else bake_size(unwrapped, size, photos)
    ids = unwrapped.texel_faces(bake)
    index, points, normals = texel_surface(unwrapped, ids)
    image = np.zeros((bake * bake, 3), dtype=np.float32)
    image[index] = surface_colour(model, points, normals, depths, photos, tolerance,
                                  unseen=unseen)
    empty = (ids < 0)
    nearest = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
    return image.reshape(bake, bake, 3)[nearest[0], nearest[1]]


def finish_texture(image: np.ndarray) -> np.ndarray:
    """(B, B, 3) uint8: the baked `image` (B, B, 3) in [0, 1], at its bake size: texels finer
    than the photos' pixels add bytes, not detail (kermit's 2048^2 texture took 4 s more to bake,
    tune, refine and write than its bake size of 1024)."""
    return np.round(np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)


def bake_size(unwrapped: Unwrapped, size: int, photos: Photos) -> int:
    """The texture size, halved while its texels would still be no larger than the typical
    (median) photo's pixels on the object (TEXELS_PER_PIXEL of them a pixel across); never
    under MIN_BAKE. A 100x100 photo holds no detail a 2048^2 texel could show. (The finest
    photo's pixels kept kermit's 320x240 photos at 2048, the one close-up among nine.)"""
    a, b, c = (unwrapped.vertices[unwrapped.faces[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1).sum()
    ua, ub, uc = (unwrapped.uv[unwrapped.faces[:, i]] for i in range(3))
    e1, e2 = ub - ua, uc - ua
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    texels = np.sqrt(uv_area / max(area, 1e-12)) * size  # texels per world unit, at `size`
    centre = unwrapped.vertices.mean(0)
    pixels = float(np.median([cam.fx / np.linalg.norm(cam.c2w[:3, 3] - centre)
                              for cam in photos.cameras]))
    bake = size
    while bake // 2 >= MIN_BAKE and texels * (bake // 2) / size >= TEXELS_PER_PIXEL * pixels:
        bake //= 2
    return bake


def surface_samples(mesh: Mesh) -> np.ndarray:
    """(7F, 3) points on every face of `mesh`: its corners' midpoints and points between them,
    dense enough to hide what lies behind the surface (photos.project_photos) when only
    vertices are coloured."""
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    mids = [(a + b) / 2, (b + c) / 2, (c + a) / 2]
    inner = [(2 * a + b + c) / 4, (a + 2 * b + c) / 4, (a + b + 2 * c) / 4]
    return np.concatenate([*mids, *inner, (a + b + c) / 3])


def surface_colour(model: RadianceModel, points: np.ndarray, normals: np.ndarray,
                   depths: tuple[float, ...], photos: Photos | None, tolerance: float,
                   occluders: np.ndarray | None = None,
                   unseen: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """(N, 3) in [0, 1]: the base colour at surface `points` (N, 3) with outward `normals`: the
    photos' where they see it well enough, the field's where they do not (or no photos).
    `occluders` (M, 3) sample the whole surface densely (photos.project_photos; default: the
    points, which texels are); `unseen` as bake_image's."""
    if photos is None:
        return field_colour(model, points, normals, depths)
    total, weight = project_photos(points, normals, photos, tolerance, occluders)
    low = low_weight(weight)
    colour = blend_with_field(total, weight, field_colour(model, points[low], normals[low], depths),
                              low)
    if unseen is None:
        return colour
    fade = unseen(points)
    if not fade.any():
        return colour
    grey = neutral_colour(colour, weight)
    return (1.0 - fade[:, None]) * colour + fade[:, None] * grey
