"""Whole images from any `RadianceModel`: rays of a camera rendered in chunks, without gradients.

Memory is bounded by a budget in bytes whatever the image size: each chunk holds as many rays as
the model's `bytes_per_ray` lets fit in it (windowshop/memory.py). Results come back as numpy.
Pixels are rendered tile by tile: neighbouring rays read the same grid cells, which then stay in
the CPU's caches (1.3-1.5x faster than row by row on a 256x256 turntable frame of a real capture).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from windowshop.memory import MEMORY_BUDGET, spans
from windowshop.model import RadianceModel
from windowshop.rays import camera_rays
from windowshop.scene.types import BACKGROUNDS, Camera


@dataclass
class Frame:
    """One rendered image."""

    rgb: np.ndarray  # (H, W, 3) float32 in [0, 1]
    depth: np.ndarray  # (H, W) float32, expected distance along the ray (0 where empty)
    opacity: np.ndarray  # (H, W) float32 in [0, 1]


def display_background(name: str) -> tuple[float, float, float]:
    """The colour to show a scene's background as: its own, or white for "alpha" scenes."""
    return BACKGROUNDS.get(name, BACKGROUNDS["white"])


def model_device(model: torch.nn.Module) -> torch.device:
    """The device of the model's first parameter or buffer (the CPU for an empty model)."""
    for tensor in list(model.parameters()) + list(model.buffers()):
        return tensor.device
    return torch.device("cpu")


@torch.no_grad()
def render_rays_chunked(model: RadianceModel, origins: torch.Tensor, directions: torch.Tensor,
                        background: torch.Tensor, memory_budget: int = MEMORY_BUDGET
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Render rays `origins`, `directions` (R, 3) over `background` (3,) in chunks of rays that
    each take at most `memory_budget` bytes.

    Returns rgb (R, 3), depth (R,), opacity (R,) on the rays' device. Switches the model to eval
    mode (deterministic samples) for the call and restores its previous mode.
    """
    was_training = model.training
    model.eval()
    try:
        parts = []
        for span in spans(origins.shape[0], model.bytes_per_ray(training=False), memory_budget):
            o, d = origins[span], directions[span]
            out = model.render_rays(o, d, background.expand(o.shape[0], 3))
            parts.append((out.rgb, out.depth, out.opacity))
    finally:
        model.train(was_training)
    rgb, depth, opacity = (torch.cat(p, dim=0) for p in zip(*parts))
    return rgb, depth, opacity


TILE = 16  # pixels per side of the tiles rendered together


def tile_order(height: int, width: int, tile: int = TILE) -> torch.Tensor:
    """Pixel indices (H*W,) of a row-major image, tile by tile (each tile row-major inside)."""
    rows, cols = torch.meshgrid(torch.arange(height), torch.arange(width), indexing="ij")
    tiles_across = -(-width // tile)
    key = ((rows // tile) * tiles_across + cols // tile) * tile * tile + (rows % tile) * tile + cols % tile
    return torch.argsort(key.reshape(-1))


def render_camera(model: RadianceModel, camera: Camera,
                  background: tuple[float, float, float] = (1.0, 1.0, 1.0),
                  memory_budget: int = MEMORY_BUDGET) -> Frame:
    """Render every pixel of `camera` (in the model's normalised frame) on the model's device."""
    device = model_device(model)
    origins, directions = camera_rays(camera, device=device)
    order = tile_order(camera.height, camera.width).to(device)
    bg = torch.tensor(background, dtype=torch.float32, device=device)
    tiled = render_rays_chunked(model, origins[order], directions[order], bg, memory_budget)
    rgb, depth, opacity = (torch.empty_like(v).index_copy_(0, order, v) for v in tiled)
    shape = (camera.height, camera.width)
    return Frame(rgb=rgb.clamp(0, 1).reshape(*shape, 3).cpu().numpy(),
                 depth=depth.reshape(shape).cpu().numpy(),
                 opacity=opacity.reshape(shape).cpu().numpy())
