"""Where along each ray to evaluate a field: stratified samples and inverse-CDF resampling.

Pure functions on distances `t` along unit rays; nothing here knows about fields or networks.
"""

from __future__ import annotations

import torch


def stratified(near: torch.Tensor, far: torch.Tensor, n: int, jitter: bool,
               generator: torch.Generator | None = None) -> torch.Tensor:
    """`n` distances per ray in [near, far] (R,), one per equal bin, sorted: (R, n).

    With `jitter` each sample is uniform within its bin (training); without it, at the bin's
    middle, the mean of the jittered sample.
    """
    steps = torch.arange(n, device=near.device, dtype=near.dtype)  # (n,)
    offset = torch.full((near.shape[0], n), 0.5, device=near.device, dtype=near.dtype)
    if jitter:
        offset = torch.rand(offset.shape, device=near.device, dtype=near.dtype, generator=generator)
    fraction = (steps + offset) / n  # (R, n) in [0, 1)
    return near[:, None] + (far - near)[:, None] * fraction


def sample_pdf(bins: torch.Tensor, weights: torch.Tensor, n: int, jitter: bool,
               generator: torch.Generator | None = None) -> torch.Tensor:
    """Draw `n` distances per ray from the piecewise-constant density given by `weights`.

    `bins` (R, B+1) are sorted bin edges, `weights` (R, B) non-negative. Inverse transform
    sampling of the piecewise-linear CDF; `jitter` False uses evenly spaced quantiles so the result
    is deterministic. Returns (R, n), sorted, detached (no gradient flows into the coarse weights).
    """
    weights = weights.detach() + 1e-5  # keep empty rays sampling uniformly, avoid 0/0
    pdf = weights / weights.sum(dim=-1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, dim=-1)], dim=-1)  # (R, B+1)
    cdf = cdf.clamp(max=1.0).contiguous()
    if jitter:
        u = torch.rand(pdf.shape[0], n, device=pdf.device, dtype=pdf.dtype, generator=generator)
        u = u.sort(dim=-1).values
    else:
        u = ((torch.arange(n, device=pdf.device, dtype=pdf.dtype) + 0.5) / n).expand(pdf.shape[0], n)
    u = u.contiguous()
    hi = torch.searchsorted(cdf, u, right=True).clamp(1, cdf.shape[-1] - 1)  # (R, n)
    lo = hi - 1
    cdf_lo, cdf_hi = cdf.gather(-1, lo), cdf.gather(-1, hi)
    bin_lo, bin_hi = bins.detach().gather(-1, lo), bins.detach().gather(-1, hi)
    span = torch.where(cdf_hi - cdf_lo < 1e-5, torch.ones_like(cdf_lo), cdf_hi - cdf_lo)
    return bin_lo + (u - cdf_lo) / span * (bin_hi - bin_lo)


def hierarchical(t_coarse: torch.Tensor, weights: torch.Tensor, n: int, jitter: bool,
                 generator: torch.Generator | None = None) -> torch.Tensor:
    """The fine pass's distances: coarse `t_coarse` (R, N) plus `n` drawn from its `weights` (R, N).

    As the paper: bins are the midpoints between coarse samples and the two end weights are
    dropped. Returns (R, N + n) sorted and detached.
    """
    mids = 0.5 * (t_coarse[:, 1:] + t_coarse[:, :-1])  # (R, N-1) edges of N-2 bins
    fine = sample_pdf(mids, weights[:, 1:-1], n, jitter, generator)
    return torch.cat([t_coarse.detach(), fine], dim=-1).sort(dim=-1).values
