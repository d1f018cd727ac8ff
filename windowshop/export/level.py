"""The density at which the object's surface lies, chosen from what the field shows in its views.

A density field has no surface of its own; the one that matters is the one whose outline is the
object's outline in the photos. A training view's silhouette is where the field's accumulated
opacity passes one half (its transmittance, which is what the masks trained it to); an iso-surface
at level L covers the pixels onto which some density above L projects. So each pixel's peak
density is found once (the lattice splatted into the view), and the level is the one whose
silhouettes agree best (IoU) with the field's own, over a few training views.
"""

from __future__ import annotations

import numpy as np
import torch

from windowshop.model import RadianceModel
from windowshop.rays import camera_rays
from windowshop.scene.types import Camera

COARSE = 128  # the level is chosen on a lattice of at most this many cells a side
FLOOR_ALPHA = 0.01  # no surface where a whole coarse cell is less opaque than this
LEVELS = 96  # candidate levels, spaced evenly in log density
CELLS_PER_PIXEL = 2.0  # pixels of the views that choose the level, in lattice cells
PLATEAU = 2e-3  # levels this close to the best IoU count as equally good (middle one taken)


def spread_views(cameras: list[Camera], count: int, centre: np.ndarray,
                 cell: float) -> list[Camera]:
    """`count` of `cameras` spread evenly through the list, each with pixels about two lattice
    cells (`cell` world units) wide at the object's `centre` (3,) (never finer than its own)."""
    step = max(1, len(cameras) // max(count, 1))
    out = []
    for cam in cameras[::step][:count]:
        footprint = np.linalg.norm(cam.center - centre) / cam.fx  # a full-size pixel, world units
        scale = min(1.0, footprint / (CELLS_PER_PIXEL * cell))
        out.append(cam.resized(max(1, round(cam.width * scale)), max(1, round(cam.height * scale))))
    return out


@torch.no_grad()
def field_silhouette(model: RadianceModel, camera: Camera, chunk: int = 16384) -> torch.Tensor:
    """(H*W,) bool: pixels where the field's opacity passes 0.5 (its transmittance is below half)."""
    device = next(model.parameters()).device
    origins, dirs = camera_rays(camera, device)
    background = torch.zeros_like(origins[:chunk])
    opacity = [model.render_rays(o, d, background[:len(o)]).opacity
               for o, d in zip(origins.split(chunk), dirs.split(chunk))]
    return torch.cat(opacity) > 0.5


@torch.no_grad()
def peak_density(volume: torch.Tensor, aabb: torch.Tensor, camera: Camera,
                 floor: float) -> torch.Tensor:
    """(H*W,) the highest density of `volume` (X, Y, Z), lattice vertices over `aabb` (2, 3),
    that projects into each pixel of `camera` (0 where none above `floor` does).

    Splatting the vertices is exact for the pixels as long as a pixel is wider than a lattice
    cell where it sees the object (no gaps between the splats); `spread_views` sizes them so."""
    index = (volume > floor).nonzero()
    values = volume[index[:, 0], index[:, 1], index[:, 2]]
    cell = (aabb[1] - aabb[0]) / (torch.tensor(volume.shape, device=volume.device) - 1)
    points = aabb[0] + index.to(aabb.dtype) * cell
    w2c = torch.linalg.inv(torch.as_tensor(camera.c2w, dtype=points.dtype, device=points.device))
    local = points @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -local[:, 2]
    u = torch.floor(camera.fx * local[:, 0] / depth.clamp(min=1e-9) + camera.cx).long()
    v = torch.floor(-camera.fy * local[:, 1] / depth.clamp(min=1e-9) + camera.cy).long()
    ok = (depth > 0) & (u >= 0) & (v >= 0) & (u < camera.width) & (v < camera.height)
    peak = torch.zeros(camera.width * camera.height, device=volume.device)
    return peak.scatter_reduce(0, v[ok] * camera.width + u[ok], values[ok], "amax")


def best_level(peaks: torch.Tensor, targets: torch.Tensor) -> tuple[float, float]:
    """(level, IoU): the density level whose silhouettes `peaks > level` (P,) best match the
    `targets` (P,) bool, among LEVELS candidates spaced in log density; on a plateau of equally
    good levels, its middle (in log density), so a sharp field's surface sits mid-edge."""
    positive = peaks[peaks > 0]
    if not bool(targets.any()) or len(positive) == 0:
        return float("nan"), 0.0
    lo = max(float(torch.quantile(positive, 0.01)), 1e-6)
    hi = max(float(positive.max()), lo * 1.0001)
    levels = torch.logspace(np.log10(lo), np.log10(hi), LEVELS, device=peaks.device)
    inside = peaks[None] > levels[:, None]  # (L, P)
    inter = (inside & targets[None]).sum(-1).float()
    union = (inside | targets[None]).sum(-1).float()
    iou = inter / union.clamp(min=1)
    good = (iou >= iou.max() - PLATEAU).nonzero()[:, 0]
    pick = int(good[len(good) // 2])
    return float(levels[pick]), float(iou[pick])


def choose_level(model: RadianceModel, volume: torch.Tensor, aabb: torch.Tensor,
                 cameras: list[Camera], views: int = 8) -> tuple[float, float]:
    """(level, IoU) of the surface of `volume` (X, Y, Z), densities over `aabb` (2, 3), chosen
    against the field's silhouettes in `views` of the training `cameras` (see the module docstring).

    Read on every few vertices only (at most COARSE cells a side): the level is a single number."""
    cell = (aabb[1] - aabb[0]) / (torch.tensor(volume.shape) - 1).to(aabb)
    k = max(1, -(-max(volume.shape) // COARSE))
    coarse = volume[::k, ::k, ::k]
    span = torch.tensor([(n - 1) // k * k for n in volume.shape]).to(aabb) * cell
    coarse_box = torch.stack([aabb[0], aabb[0] + span])
    floor = -np.log(1.0 - FLOOR_ALPHA) / float(cell.max() * k)
    peaks, targets = [], []
    for cam in spread_views(cameras, views, aabb.mean(0).cpu().numpy(), float(cell.max()) * k):
        peaks.append(peak_density(coarse, coarse_box, cam, floor))
        targets.append(field_silhouette(model, cam).to(volume.device))
    return best_level(torch.cat(peaks), torch.cat(targets))
