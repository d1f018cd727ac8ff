"""Cameras to rays, and points back to pixels, as pure functions on tensors.

Both directions share one convention: OpenGL camera axes (the camera looks along -z, y up) and
continuous pixel coordinates whose top-left pixel centre is (0.5, 0.5).
"""

from __future__ import annotations

import numpy as np
import torch

from windowshop.scene.types import Camera


def pixel_directions(fx: float, fy: float, cx: float, cy: float, u: torch.Tensor,
                     v: torch.Tensor) -> torch.Tensor:
    """Camera-space directions (N, 3) through continuous pixel coordinates u, v (N,), z = -1."""
    return torch.stack([(u - cx) / fx, -(v - cy) / fy, -torch.ones_like(u)], dim=-1)


def camera_rays(camera: Camera, device: torch.device | str = "cpu",
                dtype: torch.dtype = torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """Rays through every pixel centre of `camera`, row-major.

    Returns origins (H*W, 3) and unit directions (H*W, 3) in world coordinates.
    """
    j, i = torch.meshgrid(torch.arange(camera.height, device=device, dtype=dtype),
                          torch.arange(camera.width, device=device, dtype=dtype), indexing="ij")
    dirs = pixel_directions(camera.fx, camera.fy, camera.cx, camera.cy,
                            i.reshape(-1) + 0.5, j.reshape(-1) + 0.5)
    c2w = torch.as_tensor(camera.c2w, device=device, dtype=dtype)
    return rays_from_directions(c2w, dirs)


def rays_from_directions(c2w: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """World rays for camera-space directions `dirs` (N, 3) of a camera `c2w` (4, 4) or (N, 4, 4)."""
    rot, origin = c2w[..., :3, :3], c2w[..., :3, 3]
    world = (rot @ dirs.unsqueeze(-1)).squeeze(-1) if rot.dim() == 3 else dirs @ rot.T
    world = world / world.norm(dim=-1, keepdim=True)
    return origin.expand_as(world), world


def project(points: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Project world points (N, 3) into `camera`.

    Returns pixel coordinates (N, 2) and depths (N,) along the viewing axis (positive in front).
    """
    w2c = np.linalg.inv(camera.c2w)
    cam = points @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -cam[:, 2]
    uv = np.stack([camera.fx * cam[:, 0] / depth + camera.cx,
                   -camera.fy * cam[:, 1] / depth + camera.cy], axis=-1)
    return uv, depth
