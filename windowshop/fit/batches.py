"""Random batches of training rays drawn uniformly from the pixels of every training view.

Only the pixel colours live in memory; a batch's rays are computed from its pixels' cameras, so
100 views of 400x400 cost their 192 MB of colour and nothing per ray.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from windowshop.rays import pixel_directions, rays_from_directions
from windowshop.scene.types import View


@dataclass
class RayBatch:
    """R training rays and what their pixels saw."""

    origins: torch.Tensor  # (R, 3)
    directions: torch.Tensor  # (R, 3) unit
    rgb: torch.Tensor  # (R, 3) the pixel colour as stored
    alpha: torch.Tensor | None  # (R,) the pixel's alpha when the views carry one

    def target(self, background: torch.Tensor) -> torch.Tensor:
        """The colour (R, 3) the model must reproduce over `background` (R, 3)."""
        if self.alpha is None:
            return self.rgb
        return self.rgb * self.alpha[:, None] + background * (1.0 - self.alpha[:, None])


class PixelBank:
    """All pixels of `views` on `device`, flattened view after view, row-major within a view."""

    def __init__(self, views: list[View], device: torch.device | str, use_alpha: bool = False):
        if use_alpha and any(v.alpha is None for v in views):
            raise ValueError("use_alpha needs an alpha channel in every view")
        self.device = torch.device(device)
        self.rgb = torch.from_numpy(np.concatenate(
            [v.image.reshape(-1, 3) for v in views]).astype(np.float32)).to(device)
        self.alpha = torch.from_numpy(np.concatenate(
            [v.alpha.reshape(-1) for v in views]).astype(np.float32)).to(device) if use_alpha else None
        sizes = [v.camera.width * v.camera.height for v in views]
        self.starts = torch.tensor(np.cumsum([0] + sizes[:-1]), dtype=torch.long, device=device)
        self.widths = torch.tensor([v.camera.width for v in views], dtype=torch.long, device=device)
        self.intrinsics = torch.tensor([[v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy]
                                        for v in views], dtype=torch.float32, device=device)  # (V, 4)
        self.c2w = torch.tensor(np.stack([v.camera.c2w for v in views]), dtype=torch.float32,
                                device=device)  # (V, 4, 4)

    def __len__(self) -> int:
        return self.rgb.shape[0]

    def rays(self, index: torch.Tensor) -> RayBatch:
        """The rays through the pixels with flat indices `index` (R,)."""
        view = torch.searchsorted(self.starts, index, right=True) - 1
        local = index - self.starts[view]
        width = self.widths[view]
        u = (local % width).float() + 0.5
        v = torch.div(local, width, rounding_mode="floor").float() + 0.5
        fx, fy, cx, cy = self.intrinsics[view].unbind(-1)
        origins, directions = rays_from_directions(self.c2w[view], pixel_directions(fx, fy, cx, cy, u, v))
        alpha = None if self.alpha is None else self.alpha[index]
        return RayBatch(origins=origins, directions=directions, rgb=self.rgb[index], alpha=alpha)

    def sample(self, n: int) -> RayBatch:
        """`n` rays through pixels drawn uniformly with replacement (torch's global generator)."""
        return self.rays(torch.randint(len(self), (n,), device=self.device))
