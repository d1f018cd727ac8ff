"""Volume rendering (NeRF eq. 3) of packed samples: a ragged number of samples per ray.

Samples are stored ray after ray, each ray's in order of distance, with `ray` (S,) naming the ray
of each and `counts` (R,) how many each ray has (occupancy.Samples). Nothing here knows about fields.
Sample i stands for an interval of length `dt_i` (the marching step); w_i = T_i (1 - exp(-s_i dt_i)),
T_i = exp(-sum of s_j dt_j over the earlier samples j of the same ray).
"""

from __future__ import annotations

import torch

from windowshop.field import kernels


def ray_starts(counts: torch.Tensor) -> torch.Tensor:
    """Index (R,) of each ray's first sample, given samples per ray `counts` (R,)."""
    return torch.cumsum(counts, dim=0) - counts


def _exclusive_segment_cumsum(values: torch.Tensor, counts: torch.Tensor) -> torch.Tensor:
    """Per-ray sums (S,) of `values` (S,) over the earlier samples of the same ray, in float64.

    A global cumulative sum minus its value at the ray's first sample (a ray without samples has
    its start past the end: clamped, and repeated zero times).
    """
    total = torch.cumsum(values.double(), dim=0)
    before = total - values.double()
    if before.numel():
        first = before[ray_starts(counts).clamp(max=before.numel() - 1)]
        before = before - first.repeat_interleave(counts, output_size=before.numel())
    return before


def arrival_transmittance(weights: torch.Tensor, counts: torch.Tensor) -> torch.Tensor:
    """The transmittance (S,) each packed sample is reached with: one minus the compositing
    `weights` (S,) of the earlier samples of its ray (`counts` (R,) samples a ray)."""
    return (1.0 - _exclusive_segment_cumsum(weights, counts)).to(weights.dtype)


def packed_weights(sigma: torch.Tensor, dt: torch.Tensor | float, ray: torch.Tensor,
                   counts: torch.Tensor) -> torch.Tensor:
    """Compositing weights (S,) of densities `sigma` (S,) over intervals `dt` (S,) or a scalar.

    The per-ray exclusive sum of optical depth is a global cumulative sum minus its value at the
    ray's first sample, taken in float64 so long batches do not lose precision.
    """
    optical = sigma * dt
    before = _exclusive_segment_cumsum(optical, counts)
    return torch.exp(-before).to(sigma.dtype) * (1.0 - torch.exp(-optical))


class _FusedRayWeights(torch.autograd.Function):
    """packed_weights and the weights' per-ray sums (opacity, depth) in one kernel pair."""

    @staticmethod
    def forward(ctx, sigma, t, counts, dt: float):
        starts = ray_starts(counts).contiguous()
        w, opacity, depth = kernels.ray_weights_forward(sigma.detach(), t, starts, counts, dt)
        ctx.save_for_backward(sigma, t, w, starts, counts)
        ctx.dt = dt
        return w, opacity, depth

    @staticmethod
    def backward(ctx, grad_w, grad_opacity, grad_depth):
        sigma, t, w, starts, counts = ctx.saved_tensors
        grads = tuple(w.new_zeros(size) if g is None else g.contiguous()
                      for g, size in ((grad_w, w.shape), (grad_opacity, counts.shape),
                                      (grad_depth, counts.shape)))
        grad = kernels.ray_weights_backward(sigma.detach(), t, w, starts, counts, ctx.dt, grads)
        return grad, None, None, None


def ray_weights(sigma: torch.Tensor, dt: float, t: torch.Tensor, ray: torch.Tensor,
                counts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Compositing weights (S,) of densities `sigma` (S,) over intervals `dt` at distances `t`
    (S,), and per ray (R,) the opacity (their sum) and depth (their sum times t): packed_weights
    and two ray_sums, fused into one kernel pair on the CPU."""
    if kernels.available(sigma.device) and sigma.dtype == torch.float32:
        return _FusedRayWeights.apply(sigma.contiguous(), t.contiguous(), counts.contiguous(),
                                      float(dt))
    weights = packed_weights(sigma, dt, ray, counts)
    n_rays = counts.shape[0]
    return weights, ray_sum(weights, ray, n_rays), ray_sum(weights * t, ray, n_rays)


def sample_points(origins: torch.Tensor, directions: torch.Tensor, t: torch.Tensor,
                  ray: torch.Tensor) -> torch.Tensor:
    """World points (S, 3) of packed samples: origins[ray] + t * directions[ray]."""
    return origins.index_select(0, ray) + t[:, None] * directions.index_select(0, ray)


def ray_sum(values: torch.Tensor, ray: torch.Tensor, n_rays: int) -> torch.Tensor:
    """Per-ray sums (R, ...) of per-sample `values` (S, ...) whose rays are `ray` (S,)."""
    out = torch.zeros((n_rays, *values.shape[1:]), dtype=values.dtype, device=values.device)
    if values.dim() == 1:
        return out.index_add(0, ray, values)
    flat = (ray[:, None] * values.shape[1] + torch.arange(values.shape[1], device=ray.device))
    return out.view(-1).index_add(0, flat.reshape(-1), values.reshape(-1)).view_as(out)


def packed_distortion(weights: torch.Tensor, t: torch.Tensor, dt: torch.Tensor | float,
                      ray: torch.Tensor, counts: torch.Tensor) -> torch.Tensor:
    """Mip-NeRF 360's distortion loss per ray (R,), in linear time over samples sorted by `t`.

    sum_ij w_i w_j |t_i - t_j| + 1/3 sum_i w_i^2 dt_i: small when each ray's weight sits in one
    short interval (a surface), large for weight smeared along the ray (fog, floaters).
    """
    w = weights.double()
    wt = w * t.double()
    pairs = 2.0 * w * (t.double() * _exclusive_segment_cumsum(w, counts)
                       - _exclusive_segment_cumsum(wt, counts))
    own = w * w * dt / 3.0
    return ray_sum((pairs + own).to(weights.dtype), ray, counts.shape[0])
