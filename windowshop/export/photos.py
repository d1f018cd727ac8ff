"""The base colour from the training photos themselves, projected onto the mesh with visibility.

The field's colour at a surface point is a guess (see texture.py: read head-on, under the surface,
without its view dependence); the photos hold the colour itself. Each texel's surface point is
projected into some training views; a view lends its pixel only where it sees that point:
- visible: the point's depth is within a tolerance of the surface's nearest depth at that pixel
  (the texels themselves splatted into a depth buffer: every texel is a sample of the surface, so
  no rasteriser is needed), so a part hidden behind another takes nothing;
- facing: the surface faces the camera; the weight grows with cos(normal, view)^2, so head-on
  views count most and grazing ones, smeared over few pixels, little;
- inside: the weight ramps up over EDGE_PIXELS from the mesh's silhouette and its occluding edges
  in that view (and by the photo's alpha where it has one), so a pixel blended with the background
  or with a nearer part lends nothing.
Views are averaged by weight (a view-averaged base colour, as a PBR texture should hold); texels
with too little weight are topped up with the field's colour (texture.field_colour).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from windowshop.errors import UserError
from windowshop.export.raster import screen
from windowshop.scene.types import Camera

EDGE_PIXELS = 2.0  # the weight ramps from 0 at the mesh's silhouette to 1 this many pixels inside
MIN_COS = 0.15  # surfaces seen more obliquely than this (about 81 degrees) take nothing
COS_POWER = 2.0  # a view's weight: cos(normal, view) to this power
SLOPE = 3.0  # surfaces up to this steep (tangent, about 72 degrees) are not occluding edges
ENOUGH = 0.5  # texels whose photo weight is below this are topped up with the field's colour


@dataclass
class Photos:
    """Training photos in the run's (normalised) frame."""

    cameras: list[Camera]
    images: list[np.ndarray]  # (H, W, 3) float32 in [0, 1]
    alphas: list[np.ndarray | None]  # (H, W) float32 in [0, 1], None where the source has none

    def pick(self, indices: list[int]) -> "Photos":
        """The photos at `indices`."""
        return Photos(cameras=[self.cameras[i] for i in indices],
                      images=[self.images[i] for i in indices],
                      alphas=[self.alphas[i] for i in indices])

    def spread(self, count: int) -> "Photos":
        """`count` of these photos spread evenly through them (all if fewer)."""
        return self.pick(spread(count, len(self.cameras)))

    def masked(self) -> "Photos":
        """Only the photos that have an alpha mask."""
        return self.pick([i for i, a in enumerate(self.alphas) if a is not None])


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


def splat_depth(xy: torch.Tensor, z: torch.Tensor, camera: Camera) -> torch.Tensor:
    """(H, W) the nearest depth of points at pixel coordinates `xy` (M, 2) and depths `z` (M,)
    (export.raster.screen's) in `camera`'s image, in each pixel, then
    the nearest over each pixel's 3x3 neighbourhood (so a pixel that no point of a near surface
    happened to land in still sees that surface, and points just beside an occluding edge count
    as hidden); inf where none."""
    h, w = camera.height, camera.width
    px = torch.floor(xy).long()
    ok = (z > 0) & (px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < w) & (px[:, 1] < h)
    # the points off the image go to a spare last pixel: selecting the others first took three
    # quarters of the time (700k points a photo on dtu_skull's bake)
    pixel = torch.where(ok, px[:, 1] * w + px[:, 0], h * w)
    depth = torch.full((h * w + 1,), float("inf"), dtype=z.dtype, device=z.device)
    depth.scatter_reduce_(0, pixel, z, "amin")
    return -F.max_pool2d(-depth[:-1].view(1, 1, h, w), 3, stride=1, padding=1)[0, 0]


def edge_ramp(depth: np.ndarray, jump: float, focal: float) -> np.ndarray:
    """(H, W) float32: 0 off the surface (`depth` (H, W) inf) and at occluding edges, rising to 1
    EDGE_PIXELS away from both: pixels there mix the surface with what lies beside or behind it.
    An occluding edge is where the depth jumps within a pixel's 3x3 neighbourhood by more than
    `jump` plus what a surface sloping at up to SLOPE (tangent) would span there (pixels of
    `focal` length)."""
    finite = np.isfinite(depth)
    capped = np.where(finite, depth, 0.0)
    top = ndimage.maximum_filter(capped, 3)
    low = ndimage.minimum_filter(np.where(finite, depth, np.inf), 3)
    clean = finite & (top - low <= jump + 2 * SLOPE * low / focal)
    # the 3x3 nearest depth widened the silhouette by one pixel: the ramp starts one further in
    # OpenCV's exact Euclidean distance (as scipy's distance_transform_edt, to float32), 3-4x
    # faster: one call per photo in the settle, the bake and the vertex colours
    inside = cv2.distanceTransform(clean.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.clip((inside - 1.5) / EDGE_PIXELS, 0.0, 1.0).astype(np.float32)


def bilinear(image: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
    """(N, C) of `image` (H, W, C) at pixel coordinates `xy` (N, 2) (centres at +0.5)."""
    h, w = image.shape[:2]
    grid = torch.stack([2 * xy[:, 0] / w - 1, 2 * xy[:, 1] / h - 1], -1)
    out = F.grid_sample(image.permute(2, 0, 1)[None], grid[None, None].to(image.dtype),
                        align_corners=False, mode="bilinear", padding_mode="border")
    return out[0, :, 0].T


@torch.no_grad()
def visible_views(points: torch.Tensor, normals: torch.Tensor, photos: Photos, tolerance: float,
                  occluders: torch.Tensor | None = None
                  ) -> Iterator[tuple[Camera, np.ndarray, torch.Tensor, torch.Tensor,
                                      torch.Tensor]]:
    """For each photo: (camera, image, index (K,), xy (K, 2), weight (K,)): the `points` (N, 3)
    with outward unit `normals` (N, 3) it sees, their pixel coordinates (export.raster.screen's),
    and how much its pixel there counts (see the module docstring). What hides a point is
    `occluders` (M, 3), points sampling the whole surface densely (several a pixel; default:
    `points` themselves, as the texels of a texture do): a point is visible in a view when its
    depth is at most `tolerance` (world units), plus what the slope there allows, behind the
    nearest occluder in its pixel's neighbourhood (splat_depth)."""
    for camera, image, alpha in zip(photos.cameras, photos.images, photos.alphas):
        xy_all, z_all = screen(points, camera)
        depth = splat_depth(*(screen(occluders, camera) if occluders is not None
                              else (xy_all, z_all)), camera)
        ramp = edge_ramp(depth.numpy(), 4 * tolerance, camera.fx)
        if alpha is not None:
            ramp = ramp * np.clip(2.0 * alpha - 1.0, 0.0, 1.0)  # half-covered pixels lend nothing
        centre = torch.as_tensor(camera.c2w[:3, 3], dtype=torch.float32)
        cos = (normals * F.normalize(centre - points, dim=-1)).sum(-1)
        index = (cos > MIN_COS).nonzero()[:, 0]
        xy, z = xy_all[index], z_all[index]
        px = torch.floor(xy).long()
        inside = ((px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < camera.width)
                  & (px[:, 1] < camera.height) & (z > 0))
        index, xy, z, px = index[inside], xy[inside], z[inside], px[inside]
        # the nearest depth near a pixel may lie up to about two pixels' footprint times the
        # slope's tangent in front of a point of the same surface
        c = cos[index]
        slack = tolerance + 2 * z / camera.fx * torch.sqrt(1 - c * c) / c
        seen = z <= depth[px[:, 1], px[:, 0]] + slack
        index, xy = index[seen], xy[seen]
        weight = cos[index] ** COS_POWER * bilinear(torch.as_tensor(ramp)[..., None], xy)[:, 0]
        yield camera, image, index, xy, weight


@torch.no_grad()
def project_photos(points: np.ndarray, normals: np.ndarray, photos: Photos, tolerance: float,
                   occluders: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(colour sum (N, 3), weight (N,)): the photos' weighted colours at surface `points` (N, 3)
    with outward unit `normals` (N, 3), seen as visible_views says; colour sum / weight is the
    blend."""
    p = torch.as_tensor(points, dtype=torch.float32)
    o = None if occluders is None else torch.as_tensor(occluders, dtype=torch.float32)
    total = torch.zeros(len(p), 3)
    weight = torch.zeros(len(p))
    for _, image, index, xy, w in visible_views(p, torch.as_tensor(normals, dtype=torch.float32),
                                                photos, tolerance, o):
        colour = bilinear(torch.as_tensor(image, dtype=torch.float32), xy)
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
