"""Positional encoding of NeRF (Mildenhall et al. 2020, eq. 4), with the identity kept.

gamma(p) = (p, sin(2^0 s p), cos(2^0 s p), ..., sin(2^(L-1) s p), cos(2^(L-1) s p)), applied to
each coordinate, with s = pi as the paper writes it or s = 1 as its released code (and the seed's
`tiny_nerf`) computes it. Our scenes are normalised into [-1, 1]^3, so with s = pi the lowest
frequency spans the object box once; s = 1 reproduces the authors' numbers, hence the default.
"""

from __future__ import annotations

import math

import torch
from torch import nn


def encoded_size(dims: int, freqs: int) -> int:
    """Width of the encoding of `dims` coordinates with `freqs` frequencies."""
    return dims * (1 + 2 * freqs)


def positional_encoding(x: torch.Tensor, freqs: int, use_pi: bool = False) -> torch.Tensor:
    """Encode `x` (..., D) into (..., D * (1 + 2 * freqs)).

    Layout as the reference code: [x, sin(f_0 x), cos(f_0 x), sin(f_1 x), cos(f_1 x), ...] with
    f_k = 2^k (times pi when `use_pi`), each block D wide.
    """
    scale = math.pi if use_pi else 1.0
    bands = scale * 2.0 ** torch.arange(freqs, dtype=x.dtype, device=x.device)  # (L,)
    angles = x.unsqueeze(-2) * bands.unsqueeze(-1)  # (..., L, D)
    pairs = torch.stack([torch.sin(angles), torch.cos(angles)], dim=-2)  # (..., L, 2, D)
    return torch.cat([x, pairs.flatten(-3)], dim=-1)


class PositionalEncoding(nn.Module):
    """`positional_encoding` as a module of fixed input width."""

    def __init__(self, dims: int, freqs: int, use_pi: bool = False):
        super().__init__()
        self.dims, self.freqs, self.use_pi = dims, freqs, use_pi
        self.out_dims = encoded_size(dims, freqs)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return positional_encoding(x, self.freqs, self.use_pi)
