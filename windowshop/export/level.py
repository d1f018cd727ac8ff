"""The density at which the object's surface lies, chosen from what the field shows in its views.

A density field has no surface of its own; the one that matters is the one whose outline is the
object's outline in the photos. A training view's silhouette is where the field's accumulated
opacity passes one half (its transmittance, which is what the masks trained it to); an iso-surface
at level L covers the pixels whose ray meets a density above L. So each ray's peak density is
read once (from a coarse copy of the lattice), and the level is the one whose
silhouettes agree best (IoU) with the field's own, over a few training views.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from windowshop.model import RadianceModel
from windowshop.rays import camera_rays
from windowshop.scene.types import Camera

COARSE = 128  # the level is chosen on a lattice of at most this many cells a side
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
def peak_density(volume: torch.Tensor, aabb: torch.Tensor, camera: Camera) -> torch.Tensor:
    """(H*W,) the highest density of `volume` (X, Y, Z), lattice vertices over `aabb` (2, 3),
    along each pixel's ray, read (trilinear, as marching cubes reads it) every lattice cell."""
    origins, dirs = camera_rays(camera, volume.device)
    step = float(((aabb[1] - aabb[0]) / (torch.tensor(volume.shape) - 1).to(aabb)).min())
    centre, radius = aabb.mean(0), 0.5 * float((aabb[1] - aabb[0]).norm())
    t_mid = ((centre - origins) * dirs).sum(-1)  # where each ray passes nearest the box's centre
    offsets = torch.arange(-radius, radius + step, step, device=volume.device)
    grid = volume.permute(2, 1, 0)[None, None]  # grid_sample reads (x, y, z) as (W, H, D)
    peak = torch.zeros(len(origins), device=volume.device)
    for part in offsets.split(32):
        t = (t_mid[:, None] + part[None]).clamp(min=0.0)  # never behind the camera
        points = origins[:, None] + t[..., None] * dirs[:, None]
        unit = 2.0 * (points - aabb[0]) / (aabb[1] - aabb[0]) - 1.0
        values = F.grid_sample(grid, unit[None, None], align_corners=True, padding_mode="zeros")
        peak = torch.maximum(peak, values[0, 0, 0].amax(-1))
    return peak


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
    peaks, targets = [], []
    for cam in spread_views(cameras, views, aabb.mean(0).cpu().numpy(), float(cell.max()) * k):
        peaks.append(peak_density(coarse, coarse_box, cam))
        targets.append(field_silhouette(model, cam).to(volume.device))
    return best_level(torch.cat(peaks), torch.cat(targets))
