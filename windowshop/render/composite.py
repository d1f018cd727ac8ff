"""Volume rendering by alpha compositing (NeRF eq. 3) of samples along each ray.

Sample i of a ray sits at distance t_i and stands for the interval up to the next sample, the last
one for the interval up to `far`, so the whole [t_0, far] is covered (the reference code uses a
1e10 last interval instead, which makes any density at the far end fully opaque).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class Composite:
    """Composited quantities of R rays."""

    rgb: torch.Tensor  # (R, 3) over the background
    depth: torch.Tensor  # (R,) sum of weights times distance (0 for an empty ray)
    opacity: torch.Tensor  # (R,) accumulated alpha, 1 - final transmittance
    weights: torch.Tensor  # (R, N) each sample's contribution


def intervals(t: torch.Tensor, far: torch.Tensor) -> torch.Tensor:
    """Lengths (R, N) of the intervals that samples `t` (R, N) stand for, the last ending at `far` (R,)."""
    return torch.diff(t, dim=-1, append=far[:, None]).clamp(min=0.0)


def compositing_weights(sigma: torch.Tensor, deltas: torch.Tensor) -> torch.Tensor:
    """w_i = T_i (1 - exp(-sigma_i delta_i)), T_i = exp(-sum_{j<i} sigma_j delta_j); all (R, N)."""
    optical = sigma * deltas
    alpha = 1.0 - torch.exp(-optical)
    before = torch.cumsum(optical, dim=-1) - optical  # exclusive sum: depth before sample i
    return torch.exp(-before) * alpha


def composite(sigma: torch.Tensor, rgb: torch.Tensor, t: torch.Tensor, far: torch.Tensor,
              background: torch.Tensor) -> Composite:
    """Composite densities `sigma` (R, N) and colours `rgb` (R, N, 3) at distances `t` (R, N).

    `far` (R,) ends the last interval; `background` (R, 3) shows through what is left.
    """
    weights = compositing_weights(sigma, intervals(t, far))
    opacity = weights.sum(dim=-1)
    color = (weights[..., None] * rgb).sum(dim=-2) + (1.0 - opacity)[:, None] * background
    depth = (weights * t).sum(dim=-1)
    return Composite(rgb=color, depth=depth, opacity=opacity, weights=weights)
