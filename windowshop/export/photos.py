"""The base colour from the training photos themselves, projected onto the mesh with visibility.

The field's colour at a surface point is a guess (see texture.py: read head-on, under the surface,
without its view dependence); the photos hold the colour itself. Each texel's surface point is
projected into some training views; a view lends its pixel only where it sees that point:
- visible: the point's depth is within a tolerance of the mesh's own depth at that pixel (the mesh
  drawn by export.raster in that view, so a part hidden behind another takes nothing);
- facing: the surface faces the camera; the weight grows with cos(normal, view)^2, so head-on
  views count most and grazing ones, smeared over few pixels, little;
- inside: the weight ramps up over EDGE_PIXELS from the mesh's silhouette in that view (and by the
  photo's alpha where it has one), so a pixel blended with the background lends nothing.
Views are averaged by weight (a view-averaged base colour, as a PBR texture should hold); texels
with too little weight are topped up with the field's colour (texture.field_colour).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from windowshop.errors import UserError
from windowshop.export.raster import rasterise, screen
from windowshop.scene.types import Camera

EDGE_PIXELS = 2.0  # the weight ramps from 0 at the mesh's silhouette to 1 this many pixels inside
MIN_COS = 0.15  # surfaces seen more obliquely than this (about 81 degrees) take nothing
ENOUGH = 0.5  # texels whose photo weight is below this are topped up with the field's colour


@dataclass
class Photos:
    """Training photos in the run's (normalised) frame."""

    cameras: list[Camera]
    images: list[np.ndarray]  # (H, W, 3) float32 in [0, 1]
    alphas: list[np.ndarray | None]  # (H, W) float32 in [0, 1], None where the source has none

    def spread(self, count: int) -> "Photos":
        """`count` of these photos spread evenly through them (all if fewer)."""
        pick = spread(count, len(self.cameras))
        return Photos(cameras=[self.cameras[i] for i in pick], images=[self.images[i] for i in pick],
                      alphas=[self.alphas[i] for i in pick])

    def masked(self) -> "Photos":
        """Only the photos that have an alpha mask."""
        keep = [i for i, a in enumerate(self.alphas) if a is not None]
        return Photos(cameras=[self.cameras[i] for i in keep], images=[self.images[i] for i in keep],
                      alphas=[self.alphas[i] for i in keep])


def training_photos(run) -> Photos | None:
    """The training photos of the loaded run `run` (fit.checkpoint.LoadedRun) with the run's own
    cameras; None when its scene cannot be read again as it was
    trained (moved, or read differently now): the texture then comes from the field alone."""
    from windowshop.scene import load_scene

    try:
        views = load_scene(run.scene_source, run.scene_options).split("train")
    except (UserError, OSError, ValueError):
        return None
    cameras = run.train_cameras
    if len(views) != len(cameras) or not all(
            np.allclose(v.camera.c2w, c.c2w, atol=1e-4) and v.image.shape[:2] == (c.height, c.width)
            for v, c in zip(views, cameras)):
        return None
    return Photos(cameras=list(cameras), images=[v.image for v in views],
                  alphas=[v.alpha for v in views])


def spread(count: int, total: int) -> list[int]:
    """`count` indices spread evenly through range(`total`) (all of them if fewer)."""
    if total <= count:
        return list(range(total))
    return sorted({int(i) for i in np.linspace(0, total, count, endpoint=False)})


def surface_depth(vertices: torch.Tensor, faces: torch.Tensor, camera: Camera) -> torch.Tensor:
    """(H, W) the depth (along the camera's axis) of the mesh at each pixel centre, inf where none."""
    raster = rasterise(vertices, faces, camera)
    _, depth = screen(vertices, camera)
    hit = raster.face >= 0
    out = torch.full(raster.face.shape, float("inf"), dtype=vertices.dtype, device=vertices.device)
    tri = depth[faces[raster.face[hit]]]  # (P, 3)
    out[hit] = (raster.bary[hit] * tri).sum(-1)  # perspective-correct weights: depth is linear in them
    return out


def _bilinear(image: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
    """(N, C) of `image` (H, W, C) at pixel coordinates `xy` (N, 2) (centres at +0.5)."""
    h, w = image.shape[:2]
    grid = torch.stack([2 * xy[:, 0] / w - 1, 2 * xy[:, 1] / h - 1], -1)
    out = F.grid_sample(image.permute(2, 0, 1)[None], grid[None, None].to(image.dtype),
                        align_corners=False, mode="bilinear", padding_mode="border")
    return out[0, :, 0].T


def edge_ramp(silhouette: np.ndarray) -> np.ndarray:
    """(H, W) float32: 0 outside `silhouette` (H, W) bool, rising to 1 EDGE_PIXELS inside."""
    inside = ndimage.distance_transform_edt(silhouette)
    return np.clip((inside - 0.5) / EDGE_PIXELS, 0.0, 1.0).astype(np.float32)


@torch.no_grad()
def project_photos(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray,
                   normals: np.ndarray, photos: Photos, tolerance: float) -> tuple[np.ndarray,
                                                                                  np.ndarray]:
    """(colour sum (N, 3), weight (N,)): the photos' weighted colours at surface `points` (N, 3)
    with outward unit `normals` (N, 3) of the mesh `vertices` (V, 3), `faces` (F, 3) (see the
    module docstring); a point is visible in a view when its depth is at most `tolerance` (world
    units) behind the mesh's depth at its pixel, plus what the slope there allows. colour sum / weight is the blended colour."""
    v = torch.as_tensor(vertices, dtype=torch.float32)  # float32: twice as fast as float64, as good
    f = torch.as_tensor(faces, dtype=torch.int64)
    p = torch.as_tensor(points, dtype=torch.float32)
    n = torch.as_tensor(normals, dtype=torch.float32)
    total = torch.zeros(len(p), 3)
    weight = torch.zeros(len(p))
    for camera, image, alpha in zip(photos.cameras, photos.images, photos.alphas):
        depth = surface_depth(v, f, camera)
        ramp = edge_ramp((depth < float("inf")).numpy())
        if alpha is not None:
            ramp = ramp * np.clip(2.0 * alpha - 1.0, 0.0, 1.0)  # half-covered pixels lend nothing
        centre = torch.as_tensor(camera.c2w[:3, 3], dtype=torch.float32)
        to_camera = F.normalize(centre - p, dim=-1)
        cos = (n * to_camera).sum(-1)
        index = (cos > MIN_COS).nonzero()[:, 0]
        xy, z = screen(p[index], camera)
        px = torch.floor(xy).long()
        inside = ((px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < camera.width)
                  & (px[:, 1] < camera.height) & (z > 0))
        index, xy, z, px = index[inside], xy[inside], z[inside], px[inside]
        # a pixel's depth is read at its centre: on a slope the point may lie up to a pixel's
        # footprint times the slope's tangent behind it and still be the surface seen
        c = cos[index]
        slack = tolerance + z / camera.fx * torch.sqrt(1 - c * c) / c
        seen = z <= depth[px[:, 1], px[:, 0]] + slack
        index, xy = index[seen], xy[seen]
        w = cos[index] ** 2 * _bilinear(torch.as_tensor(ramp)[..., None], xy)[:, 0]
        colour = _bilinear(torch.as_tensor(image, dtype=torch.float32), xy)
        total.index_add_(0, index, w[:, None] * colour)
        weight.index_add_(0, index, w)
    return total.numpy(), weight.numpy()


def blend_with_field(total: np.ndarray, weight: np.ndarray, field: np.ndarray,
                     low: np.ndarray) -> np.ndarray:
    """(N, 3) colours: the photos' blend where their `weight` (N,) reaches ENOUGH; below it the
    field's colours `field` (L, 3) at the texels `low` (L,) fill the missing weight."""
    out = total / np.maximum(weight, 1e-12)[:, None]
    w = weight[low, None]
    out[low] = (total[low] + (ENOUGH - w) * field) / ENOUGH
    return out


def low_weight(weight: np.ndarray) -> np.ndarray:
    """(L,) the indices of texels the photos do not colour well enough on their own."""
    return np.flatnonzero(weight < ENOUGH)
