"""Volume rendering (NeRF eq. 3) of packed samples: a ragged number of samples per ray.

Samples are stored ray after ray, each ray's in order of distance, with `ray` (S,) naming the ray
of each and `counts` (R,) how many each ray has (occupancy.Samples). Nothing here knows about fields.
Sample i stands for an interval of length `dt_i` (the marching step); w_i = T_i (1 - exp(-s_i dt_i)),
T_i = exp(-sum of s_j dt_j over the earlier samples j of the same ray).
"""

from __future__ import annotations

import torch


def ray_starts(counts: torch.Tensor) -> torch.Tensor:
    """Index (R,) of each ray's first sample, given samples per ray `counts` (R,)."""
    return torch.cumsum(counts, dim=0) - counts


def packed_weights(sigma: torch.Tensor, dt: torch.Tensor | float, ray: torch.Tensor,
                   counts: torch.Tensor) -> torch.Tensor:
    """Compositing weights (S,) of densities `sigma` (S,) over intervals `dt` (S,) or a scalar.

    The per-ray exclusive sum of optical depth is a global cumulative sum minus its value at the
    ray's first sample, taken in float64 so long batches do not lose precision.
    """
    optical = sigma * dt
    total = torch.cumsum(optical.double(), dim=0)
    before = total - optical.double()  # exclusive global sum
    if before.numel():  # (a ray without samples has its start past the end: clamp, repeated 0 times)
        first = before[ray_starts(counts).clamp(max=before.numel() - 1)]
        before = before - first.repeat_interleave(counts, output_size=before.numel())
    return torch.exp(-before).to(sigma.dtype) * (1.0 - torch.exp(-optical))


def ray_sum(values: torch.Tensor, ray: torch.Tensor, n_rays: int) -> torch.Tensor:
    """Per-ray sums (R, ...) of per-sample `values` (S, ...) whose rays are `ray` (S,)."""
    out = torch.zeros((n_rays, *values.shape[1:]), dtype=values.dtype, device=values.device)
    if values.dim() == 1:
        return out.index_add(0, ray, values)
    flat = (ray[:, None] * values.shape[1] + torch.arange(values.shape[1], device=ray.device))
    return out.view(-1).index_add(0, flat.reshape(-1), values.reshape(-1)).view_as(out)
