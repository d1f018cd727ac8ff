"""The NeRF of Mildenhall et al. 2020: an MLP field, coarse and fine passes, Adam with decay.

`NerfField` maps encoded positions (and directions) to density and colour; `NerfModel` samples
rays, composites them, and resamples where the coarse pass found matter for a separate fine field.
"""

from __future__ import annotations

import torch
from torch import nn

from windowshop.config import NERF_PRESETS, NerfConfig
from windowshop.field.encoding import PositionalEncoding
from windowshop.memory import per_chunk
from windowshop.model import Bounds, RadianceModel, RenderOutput
from windowshop.render.composite import Composite, composite
from windowshop.render.sampling import hierarchical, stratified

# floats per sample beyond the MLP's activations: points, directions, densities, colours and the
# compositing's (R, N) tensors
SAMPLE_OVERHEAD = 32
# autograd keeps about the activations counted (12.3 of the 12.9 kB counted a sample for the seed's
# 8 x 256 MLP: tests/test_memory.py); the backward pass adds its own temporaries on top
GRAD_FACTOR = 1.5
# raw output -> density >= 0. ReLU as the paper; a field whose densities all go negative early
# (a dark background makes "nothing anywhere" a strong pull) stops learning, softplus cannot.
DENSITY_ACTIVATIONS = {"relu": torch.relu, "softplus": torch.nn.functional.softplus}


class NerfField(nn.Module):
    """The paper's MLP: D x W ReLU trunk with the encoded input concatenated again after layer
    `skip`, a density head (ReLU or softplus), and a one-layer (W/2) colour branch that sees the
    encoded direction when view dependence is on (off: colour and density from one linear head on
    the trunk, as the reference code)."""

    def __init__(self, config: NerfConfig):
        super().__init__()
        if config.density_activation not in DENSITY_ACTIVATIONS:
            raise ValueError(f"density_activation must be one of {', '.join(DENSITY_ACTIVATIONS)}")
        self.config = config
        self.density = DENSITY_ACTIVATIONS[config.density_activation]
        self.encode_pos = PositionalEncoding(3, config.freqs, config.encoding_pi)
        self.encode_dir = PositionalEncoding(3, config.freqs_dir, config.encoding_pi)
        width, n_in = config.width, self.encode_pos.out_dims
        self.trunk = nn.ModuleList(
            nn.Linear(n_in if i == 0 else width + (n_in if i == config.skip else 0), width)
            for i in range(config.depth))
        if config.view_dependent:
            self.sigma_head = nn.Linear(width, 1)
            self.feature = nn.Linear(width, width)
            self.view = nn.Linear(width + self.encode_dir.out_dims, width // 2)
            self.rgb_head = nn.Linear(width // 2, 3)
        else:
            self.head = nn.Linear(width, 4)

    def bytes_per_sample(self, training: bool) -> float:
        """Memory one point's evaluation takes: every activation autograd keeps when `training`
        (the encodings, a W-wide output per layer, the skip's concatenation, the colour branch),
        else the widest few alive at once."""
        n_in, n_dir, width = self.encode_pos.out_dims, self.encode_dir.out_dims, self.config.width
        if not training:
            return 4.0 * (n_in + 3 * width + n_dir + SAMPLE_OVERHEAD)
        floats = 2 * n_in + (self.config.depth + 4) * width + 2 * n_dir + SAMPLE_OVERHEAD
        return 4.0 * GRAD_FACTOR * floats

    def forward(self, x: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Density (N,) >= 0 and colour (N, 3) in [0, 1] at points `x` (N, 3) seen along unit `d` (N, 3)."""
        inputs = self.encode_pos(x)
        h = inputs
        for i, layer in enumerate(self.trunk):
            if i == self.config.skip and i > 0:
                h = torch.cat([inputs, h], dim=-1)
            h = torch.relu(layer(h))
        if not self.config.view_dependent:
            raw = self.head(h)
            return self.density(raw[:, 3]), torch.sigmoid(raw[:, :3])
        sigma = self.density(self.sigma_head(h)[:, 0])
        h = torch.relu(self.view(torch.cat([self.feature(h), self.encode_dir(d)], dim=-1)))
        return sigma, torch.sigmoid(self.rgb_head(h))


def _query(field: NerfField, points: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """`field` at `points`, `dirs` (P, 3); without autograd in slices within the default memory
    budget, so `density` and `colour` hold a bounded set of activations however many points they
    are given (rendering's chunks of rays are already sized to fit)."""
    chunk = per_chunk(field.bytes_per_sample(training=False))
    if torch.is_grad_enabled() or points.shape[0] <= chunk:
        return field(points, dirs)
    parts = [field(p, d) for p, d in zip(points.split(chunk), dirs.split(chunk))]
    return torch.cat([sigma for sigma, _ in parts]), torch.cat([rgb for _, rgb in parts])


class NerfModel(RadianceModel):
    """Coarse field on N_c stratified samples; with N_f > 0 a fine field on N_c + N_f samples."""

    name = "nerf"
    config_type = NerfConfig
    presets = NERF_PRESETS

    def __init__(self, config: NerfConfig, bounds: Bounds):
        super().__init__(config, bounds)
        self.coarse = NerfField(config)
        self.fine = NerfField(config) if config.n_fine > 0 else None
        self.near = bounds.near if config.near is None else config.near
        self.far = bounds.far if config.far is None else config.far

    def _pass(self, field: NerfField, origins: torch.Tensor, directions: torch.Tensor,
              t: torch.Tensor, far: torch.Tensor, background: torch.Tensor) -> Composite:
        """Evaluate `field` at distances `t` (R, N) along the rays and composite."""
        n = t.shape[1]
        points = origins[:, None, :] + t[..., None] * directions[:, None, :]  # (R, N, 3)
        dirs = directions[:, None, :].expand_as(points)
        sigma, rgb = _query(field, points.reshape(-1, 3), dirs.reshape(-1, 3))
        return composite(sigma.view(-1, n), rgb.view(-1, n, 3), t, far, background)

    def bytes_per_ray(self, training: bool) -> float:
        """N_c coarse samples, and N_c + N_f fine ones, each as `NerfField.bytes_per_sample`."""
        samples = self.config.n_coarse + (self.config.n_coarse + self.config.n_fine if self.fine else 0)
        return samples * self.coarse.bytes_per_sample(training)

    def render_rays(self, origins: torch.Tensor, directions: torch.Tensor,
                    background: torch.Tensor) -> RenderOutput:
        """Render rays `origins` (R, 3), unit `directions` (R, 3) over `background` (R, 3)."""
        rays = origins.shape[0]
        near = torch.full((rays,), self.near, device=origins.device, dtype=origins.dtype)
        far = torch.full_like(near, self.far)
        t = stratified(near, far, self.config.n_coarse, jitter=self.training)
        coarse = self._pass(self.coarse, origins, directions, t, far, background)
        if self.fine is None:
            return RenderOutput(rgb=coarse.rgb, depth=coarse.depth, opacity=coarse.opacity,
                                num_samples=rays * t.shape[1])
        t_fine = hierarchical(t, coarse.weights, self.config.n_fine, jitter=self.training)
        fine = self._pass(self.fine, origins, directions, t_fine, far, background)
        return RenderOutput(rgb=fine.rgb, depth=fine.depth, opacity=fine.opacity,
                            aux={"rgb_coarse": coarse.rgb},
                            num_samples=rays * (t.shape[1] + t_fine.shape[1]))

    @property
    def _last_field(self) -> NerfField:
        """The field whose densities and colours the render composites last (the fine one)."""
        return self.coarse if self.fine is None else self.fine

    def density(self, points: torch.Tensor) -> torch.Tensor:
        # the density head never sees the direction: any unit vector will do
        dirs = torch.zeros_like(points)
        dirs[:, 2] = 1.0
        return _query(self._last_field, points, dirs)[0]

    def colour(self, points: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        return _query(self._last_field, points, directions)[1]

    def make_optimizer(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(self.parameters(), lr=self.config.lr)
