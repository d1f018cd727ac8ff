"""Random batches of training rays drawn from the pixels of every training view (each pixel once a
pass), and rays from cameras with no photo (for losses on views nobody took).

Only the pixel colours live in memory; a batch's rays are computed from its pixels' cameras, so
100 views of 400x400 cost their 192 MB of colour, 64 MB of drawing order and nothing per ray.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch

from windowshop.memory import spans
from windowshop.rays import pixel_directions, rays_from_directions
from windowshop.scene.types import Camera, View


@dataclass
class RayBatch:
    """R training rays and what their pixels saw."""

    origins: torch.Tensor  # (R, 3)
    directions: torch.Tensor  # (R, 3) unit
    rgb: torch.Tensor  # (R, 3) the pixel colour as stored
    alpha: torch.Tensor | None  # (R,) the pixel's alpha when the views carry one
    over: torch.Tensor | None = None  # (3,) the colour rgb is already composited over, if it is

    def target(self, background: torch.Tensor) -> torch.Tensor:
        """The colour (R, 3) the model must reproduce over `background` (R, 3)."""
        if self.alpha is None:
            return self.rgb
        behind = 1.0 - self.alpha[:, None]
        if self.over is not None:  # compositing is linear: swap the stored colour for the new one
            return self.rgb + (background - self.over) * behind
        return self.rgb * self.alpha[:, None] + background * behind


def camera_tables(cameras: list[Camera], device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Intrinsics fx, fy, cx, cy (V, 4) and camera-to-world matrices (V, 4, 4) of `cameras`."""
    intrinsics = torch.tensor([[c.fx, c.fy, c.cx, c.cy] for c in cameras], dtype=torch.float32,
                              device=device)
    c2w = torch.tensor(np.stack([c.c2w for c in cameras]), dtype=torch.float32, device=device)
    return intrinsics, c2w


class PixelBank:
    """All pixels of `views` on `device`, flattened view after view, row-major within a view."""

    def __init__(self, views: list[View], device: torch.device | str, use_alpha: bool = False,
                 over: tuple[float, float, float] | None = None):
        """`use_alpha` keeps each pixel's alpha, for targets over any background; `over` is the
        colour the images are composited over (None: their colour is straight, as "alpha" scenes
        keep it)."""
        if use_alpha and any(v.alpha is None for v in views):
            raise ValueError("use_alpha needs an alpha channel in every view")
        self.device = torch.device(device)
        self.over = torch.tensor(over, dtype=torch.float32, device=device) if over is not None else None
        self.rgb = torch.from_numpy(np.concatenate(
            [v.image.reshape(-1, 3) for v in views]).astype(np.float32)).to(device)
        self.alpha = torch.from_numpy(np.concatenate(
            [v.alpha.reshape(-1) for v in views]).astype(np.float32)).to(device) if use_alpha else None
        sizes = [v.camera.width * v.camera.height for v in views]
        self.starts = torch.tensor(np.cumsum([0] + sizes[:-1]), dtype=torch.long, device=device)
        self.widths = torch.tensor([v.camera.width for v in views], dtype=torch.long, device=device)
        self.intrinsics, self.c2w = camera_tables([v.camera for v in views], self.device)
        self._order, self._at = torch.empty(0, dtype=torch.long, device=self.device), 0  # see sample

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
        return RayBatch(origins=origins, directions=directions, rgb=self.rgb[index], alpha=alpha,
                        over=self.over)

    def chunks(self, bytes_per_ray: float, budget: int) -> Iterator[RayBatch]:
        """Every pixel's ray in order, in chunks of rays that each take at most `budget` bytes."""
        for span in spans(len(self), bytes_per_ray, budget):
            yield self.rays(torch.arange(span.start, span.stop, device=self.device))

    def sample(self, n: int) -> RayBatch:
        """`n` rays through pixels drawn without replacement, pass by pass: each pass over the
        bank takes a fresh random order (torch's global generator), as the NeRF paper's code
        shuffles its rays. Under one pass every ray is then a new pixel: lego 400x400 in 60 s sees
        90% of its pixels, against 59% drawn with replacement (bench/RESULTS.md, "Each pixel once
        a pass")."""
        parts = [self._order[:0]]
        while n > 0:
            if self._at == len(self._order):
                dtype = torch.int32 if len(self) < 2**31 else torch.int64  # a third of the colours
                self._order, self._at = torch.randperm(len(self), dtype=dtype, device=self.device), 0
            parts.append(self._order[self._at:self._at + n])
            self._at += len(parts[-1])
            n -= len(parts[-1])
        return self.rays(torch.cat(parts).long())


class CameraRays:
    """Rays through uniformly random points of the images of `cameras`, which need no photo.

    Draws from its own generator (seeded by `seed`), so using it leaves the training batches as
    they would have been.
    """

    def __init__(self, cameras: list[Camera], device: torch.device | str, seed: int = 0):
        if not cameras:
            raise ValueError("CameraRays needs at least one camera")
        self.device = torch.device(device)
        self.intrinsics, self.c2w = camera_tables(cameras, self.device)
        self.sizes = torch.tensor([[c.width, c.height] for c in cameras], dtype=torch.float32,
                                  device=self.device)  # (V, 2)
        self.generator = torch.Generator(device=self.device).manual_seed(seed)

    def sample(self, n: int) -> tuple[torch.Tensor, torch.Tensor]:
        """`n` rays: origins (n, 3) and unit directions (n, 3), cameras drawn uniformly."""
        view = torch.randint(len(self.c2w), (n,), generator=self.generator, device=self.device)
        uv = torch.rand(n, 2, generator=self.generator, device=self.device) * self.sizes[view]
        return self._rays(view, uv)

    def patches(self, n: int, size: int) -> tuple[torch.Tensor, torch.Tensor]:
        """The rays through `n` square patches of `size` x `size` neighbouring pixel centres, each
        at a uniformly random place in a uniformly random camera's image: origins and unit
        directions (n * size * size, 3), patch after patch, row-major within a patch."""
        view = torch.randint(len(self.c2w), (n,), generator=self.generator, device=self.device)
        room = (self.sizes[view] - size).clamp(min=0)  # (n, 2) where a patch's corner may go
        corner = torch.floor(torch.rand(n, 2, generator=self.generator, device=self.device) * (room + 1))
        step = torch.arange(size, device=self.device, dtype=torch.float32) + 0.5
        v, u = torch.meshgrid(step, step, indexing="ij")
        uv = corner[:, None, :] + torch.stack([u, v], dim=-1).view(1, -1, 2)  # (n, size^2, 2)
        return self._rays(view.repeat_interleave(size * size), uv.view(-1, 2))

    def _rays(self, view: torch.Tensor, uv: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Rays through the image points `uv` (n, 2) of the cameras `view` (n,)."""
        fx, fy, cx, cy = self.intrinsics[view].unbind(-1)
        return rays_from_directions(self.c2w[view], pixel_directions(fx, fy, cx, cy, uv[:, 0], uv[:, 1]))
