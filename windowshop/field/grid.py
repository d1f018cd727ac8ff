"""A dense grid of learned values over a box, read by trilinear interpolation.

`trilinear_reference` is the obvious PyTorch version (any device, any autograd); on the CPU with the
kernel library, `DenseGrid` uses the fused kernels instead, whose backward returns a *sparse*
row gradient (only the rows a batch touched), so neither the gradient nor the optimizer
(`optim.GridAdam`) ever sweeps the whole grid. Both agree to float rounding; tests hold them to it.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from windowshop.field import kernels
from windowshop.render.packed import ray_sum, sample_points


def corner_weights(points: torch.Tensor, shape: tuple[int, int, int]
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """Rows (N, 8) int64 and weights (N, 8) of the 8 lattice vertices around `points` (N, 3).

    Points are in grid units (vertex (i, j, k) at (i, j, k)) and clamped into the grid; corner
    c = 4 dx + 2 dy + dz, rows of a row-major (X, Y, Z) lattice. Every axis needs >= 2 vertices.
    """
    dims = torch.tensor(shape, device=points.device)
    g = torch.minimum(points.clamp(min=0.0), (dims - 1).to(points.dtype))
    cell = torch.minimum(g.floor().long(), dims - 2)  # the top face belongs to the last cell
    frac = g - cell.to(points.dtype)
    _, ny, nz = shape
    bits = torch.tensor([[c >> 2, (c >> 1) & 1, c & 1] for c in range(8)], device=points.device)
    offsets = (bits[:, 0] * ny + bits[:, 1]) * nz + bits[:, 2]  # (8,)
    base = (cell[:, 0] * ny + cell[:, 1]) * nz + cell[:, 2]
    pair = torch.stack([1.0 - frac, frac], dim=-1)  # (N, 3, 2)
    weights = (pair[:, 0, bits[:, 0]] * pair[:, 1, bits[:, 1]]) * pair[:, 2, bits[:, 2]]
    return base[:, None] + offsets, weights


def trilinear_reference(values: torch.Tensor, shape: tuple[int, int, int],
                        points: torch.Tensor) -> torch.Tensor:
    """Interpolate `values` (X*Y*Z, C) at `points` (N, 3) in grid units: (N, C). Plain autograd."""
    rows, weights = corner_weights(points, shape)
    gathered = values.index_select(0, rows.reshape(-1)).view(*rows.shape, values.shape[1])
    return (gathered * weights[..., None]).sum(dim=1)


def _sparse_gradient(accum: torch.Tensor, touched: torch.Tensor) -> torch.Tensor:
    """The rows accumulated in a grid's scratch buffers as a sparse gradient (clearing them)."""
    rows, rows_grad = kernels.harvest(accum, touched)
    return torch.sparse_coo_tensor(rows[None], rows_grad, accum.shape, is_coalesced=True,
                                   check_invariants=False)  # sorted and unique by construction


class _FusedTrilinear(torch.autograd.Function):
    """The kernel pair at points; the values' gradient is sparse (the touched rows)."""

    @staticmethod
    def forward(ctx, values: torch.Tensor, points: torch.Tensor, grid: "DenseGrid") -> torch.Tensor:
        ctx.save_for_backward(points)
        ctx.grid = grid
        return kernels.trilinear_forward(values.detach(), grid.shape, points)

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        (points,) = ctx.saved_tensors
        accum, touched = ctx.grid.scratch()
        kernels.trilinear_backward(points, ctx.grid.shape, grad_out.contiguous(), accum, touched)
        return _sparse_gradient(accum, touched), None, None


class _FusedAlongRays(torch.autograd.Function):
    """The kernel pair at packed ray samples (points never materialised)."""

    @staticmethod
    def forward(ctx, values, grid: "DenseGrid", origins, directions, t, ray):
        ctx.save_for_backward(origins, directions, t, ray)
        ctx.grid = grid
        lo, inv_voxel = grid.mapping()
        return kernels.trilinear_rays_forward(values.detach(), grid.shape,
                                              (origins, directions, t, ray), lo, inv_voxel)

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        grid, accum, touched = ctx.grid, *ctx.grid.scratch()
        kernels.trilinear_rays_backward(grid.shape, ctx.saved_tensors, *grid.mapping(),
                                        grad_out.contiguous(), accum, touched)
        return _sparse_gradient(accum, touched), None, None, None, None, None


class _FusedComposite(torch.autograd.Function):
    """Per-ray weighted sums of the values at packed ray samples, in one kernel pair."""

    @staticmethod
    def forward(ctx, values, weights, grid: "DenseGrid", origins, directions, t, ray, counts):
        lo, inv_voxel = grid.mapping()
        rays = (origins, directions, t, ray)
        out, features = kernels.composite_rays_forward(values.detach(), grid.shape, rays,
                                                       weights.detach().contiguous(), counts, lo,
                                                       inv_voxel)
        ctx.save_for_backward(origins, directions, t, ray, weights, features)
        ctx.grid = grid
        return out

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        *rays, weights, features = ctx.saved_tensors
        grid, accum, touched = ctx.grid, *ctx.grid.scratch()
        grad_w = kernels.composite_rays_backward(grid.shape, tuple(rays), weights.detach().contiguous(),
                                                 *grid.mapping(), features, grad_out.contiguous(),
                                                 accum, touched)
        return _sparse_gradient(accum, touched), grad_w, None, None, None, None, None, None


class DenseGrid(nn.Module):
    """`channels` values on each vertex of an X x Y x Z lattice whose corners are the box corners.

    `values` (X*Y*Z, channels) is the one parameter; `fused` picks the kernels (CPU only).
    """

    def __init__(self, shape: tuple[int, int, int], channels: int, aabb: torch.Tensor,
                 fill: float = 0.0, fused: bool = True):
        super().__init__()
        if min(shape) < 2:
            raise ValueError(f"a grid needs at least 2 vertices per axis, got {shape}")
        self.shape = tuple(int(s) for s in shape)
        self.fused = fused
        self.values = nn.Parameter(torch.full((self.numel, channels), float(fill)))
        self.register_buffer("aabb", aabb.detach().clone().float())  # (2, 3)
        self.register_buffer("size", torch.tensor(self.shape))  # saved, so a checkpoint resizes
        self._scratch: tuple[torch.Tensor, torch.Tensor] | None = None

    @property
    def numel(self) -> int:
        x, y, z = self.shape
        return x * y * z

    @property
    def voxel(self) -> torch.Tensor:
        """(3,) edge lengths of a cell."""
        return (self.aabb[1] - self.aabb[0]) / (torch.tensor(self.shape, device=self.aabb.device) - 1)

    def to_grid(self, points: torch.Tensor) -> torch.Tensor:
        """World `points` (N, 3) in grid units (N, 3)."""
        return ((points - self.aabb[0]) / self.voxel).contiguous()

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Values (N, channels) at world `points` (N, 3); outside the box, at its nearest face."""
        g = self.to_grid(points.detach())
        if self._fused_for(g):
            return _FusedTrilinear.apply(self.values, g, self)
        return trilinear_reference(self.values, self.shape, g)

    def along_rays(self, origins: torch.Tensor, directions: torch.Tensor, t: torch.Tensor,
                   ray: torch.Tensor) -> torch.Tensor:
        """Values (N, C) at packed ray samples: origins[ray] + t * directions[ray].

        `origins`, `directions` (R, 3); `t` (N,); `ray` (N,) int64.
        """
        if self._fused_for(origins):
            return _FusedAlongRays.apply(self.values, self, origins.contiguous(),
                                         directions.contiguous(), t.contiguous(), ray.contiguous())
        points = sample_points(origins, directions, t, ray)
        return trilinear_reference(self.values, self.shape, self.to_grid(points))

    def composite(self, origins: torch.Tensor, directions: torch.Tensor, t: torch.Tensor,
                  weights: torch.Tensor, ray: torch.Tensor, counts: torch.Tensor) -> torch.Tensor:
        """Per-ray sums (R, C) of `weights` (N,) times the values at packed ray samples.

        Samples are sorted by ray, `counts` (R,) int64 of them per ray; gradients reach the values
        and the weights.
        """
        if self._fused_for(origins):
            return _FusedComposite.apply(self.values, weights, self, origins.contiguous(),
                                         directions.contiguous(), t.contiguous(), ray.contiguous(),
                                         counts.contiguous())
        values = self.along_rays(origins, directions, t, ray)
        return ray_sum(weights[:, None] * values, ray, counts.shape[0])

    def mapping(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(lo (3,), inv_voxel (3,)): grid units are (x - lo) * inv_voxel."""
        return self.aabb[0].contiguous(), (1.0 / self.voxel).contiguous()

    def _fused_for(self, like: torch.Tensor) -> bool:
        return self.fused and kernels.available(like.device) and like.dtype == torch.float32

    def vertex_values(self) -> torch.Tensor:
        """The values as a (channels, X, Y, Z) volume (a view for channels == 1)."""
        return self.values.detach().T.reshape(-1, *self.shape)

    def scratch(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The fused backward's zeroed gradient accumulator (V, C) and touched flags (V,)."""
        if self._scratch is None or self._scratch[0].shape != self.values.shape:
            self._scratch = (torch.zeros(self.values.shape), torch.zeros(self.numel, dtype=torch.uint8))
        return self._scratch

    @torch.no_grad()
    def resize(self, shape: tuple[int, int, int]) -> None:
        """Resample to a lattice of `shape` over the same box (trilinear), keeping the Parameter."""
        shape = tuple(int(s) for s in shape)
        self._set(shape, self.resample(self.values, shape))

    def resample(self, table: torch.Tensor, shape: tuple[int, int, int]) -> torch.Tensor:
        """Any per-vertex `table` (X*Y*Z, C) of this lattice resampled to `shape` (trilinear).

        The fused kernel reads the table in its own (vertex, channel) layout at the new vertices
        (3-4x faster than interpolate's two transposes: growth happens inside the time budget).
        """
        table = table.detach()
        if self._fused_for(table):
            axes = [torch.linspace(0.0, old - 1, new) for old, new in zip(self.shape, shape)]
            points = torch.stack(torch.meshgrid(*axes, indexing="ij"), dim=-1).reshape(-1, 3)
            return kernels.trilinear_forward(table.contiguous(), self.shape, points)
        volume = table.T.reshape(1, -1, *self.shape)
        volume = F.interpolate(volume, size=tuple(shape), mode="trilinear", align_corners=True)
        return volume[0].reshape(table.shape[1], -1).T.contiguous()

    def _set(self, shape: tuple[int, int, int], values: torch.Tensor, in_graph: bool = True) -> None:
        self.shape = shape
        self.size.copy_(torch.tensor(shape))
        # Keep the Parameter object (the optimizer holds it). While a graph of the old shape is
        # alive, autograd keeps a gradient accumulator of the old shape, and swapping `.data` only
        # drops it on a change of dtype: so pass through an empty float64 tensor once (not
        # needed when loading).
        if in_graph:
            self.values.data = values.new_empty(0, dtype=torch.float64)
        self.values.data = values.contiguous()
        self.values.grad = None

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        size = state_dict.get(prefix + "size")
        if size is not None and tuple(size.tolist()) != self.shape:
            shape = tuple(int(s) for s in size.tolist())
            self._set(shape, torch.empty(shape[0] * shape[1] * shape[2], self.values.shape[1],
                                         device=self.values.device), in_graph=False)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
