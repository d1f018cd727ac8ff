"""Empty-space skipping: which cells of the box may hold matter, and ray marching that only
places samples in those.

Samples sit at t_min + (k + offset) * step along each ray, inside the box and [near, far]; a sample
is kept when its cell is marked occupied. `march_reference` is the plain PyTorch version;
`kernels.march` does the same without materialising the empty candidates.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from windowshop.field import kernels


@dataclass
class Samples:
    """S samples packed ray after ray (each ray's samples contiguous, in order of distance)."""

    t: torch.Tensor  # (S,) distance along the ray
    ray: torch.Tensor  # (S,) int64 index of the ray
    counts: torch.Tensor  # (R,) int64 samples per ray

    def __len__(self) -> int:
        return self.t.shape[0]


def ray_box(origins: torch.Tensor, directions: torch.Tensor, aabb: torch.Tensor, near: float,
            far: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Where rays (R, 3) are inside the box `aabb` (2, 3) and [near, far]: t_min, t_max (R,).

    Rays that miss get t_max == t_min (an empty interval).
    """
    safe = torch.where(directions.abs() < 1e-9, torch.full_like(directions, 1e-9), directions)
    inv = 1.0 / safe
    a, b = (aabb[0] - origins) * inv, (aabb[1] - origins) * inv
    t_min = torch.minimum(a, b).amax(dim=-1).clamp(min=near)
    t_max = torch.maximum(a, b).amin(dim=-1).clamp(max=far)
    return t_min.contiguous(), torch.maximum(t_max, t_min).contiguous()


def march_reference(origins: torch.Tensor, directions: torch.Tensor, t_min: torch.Tensor,
                    t_max: torch.Tensor, offsets: torch.Tensor, step: float,
                    occupancy: torch.Tensor, lo: torch.Tensor, inv_cell: torch.Tensor) -> Samples:
    """All candidates t_min + (k + offsets) step < t_max of rays (R, 3), kept where `occupancy`
    (OX, OY, OZ) bool is set for the cell floor((x - lo) * inv_cell) (clamped into the grid)."""
    span = float((t_max - t_min).max()) if t_min.numel() else 0.0
    k = torch.arange(int(span / step) + 2, device=origins.device, dtype=origins.dtype)
    t = t_min[:, None] + (k[None, :] + offsets[:, None]) * step  # (R, K)
    points = origins[:, None, :] + t[..., None] * directions[:, None, :]
    dims = torch.tensor(occupancy.shape, device=origins.device)
    cell = torch.minimum(torch.floor((points - lo) * inv_cell).long().clamp(min=0), dims - 1)
    keep = (t < t_max[:, None]) & occupancy[cell[..., 0], cell[..., 1], cell[..., 2]]
    ray, index = keep.nonzero(as_tuple=True)
    return Samples(t=t[ray, index], ray=ray, counts=keep.sum(dim=1))


def hull_cells(hull: torch.Tensor, cells: tuple[int, int, int]) -> torch.Tensor:
    """A carve mask `hull` (HX, HY, HZ) bool over the box, as `cells` (OX, OY, OZ) bool: a cell
    is in the hull when any hull cell it overlaps is (so a coarser grid never cuts the object)."""
    if tuple(hull.shape) == tuple(cells):
        return hull
    # adaptive pooling's window for output i spans input floor(i n / m) to ceil((i + 1) n / m):
    # exactly the input cells that output cell overlaps, whether it is coarser or finer
    peak = F.adaptive_max_pool3d(hull[None, None].float(), tuple(cells))
    return peak[0, 0] > 0


def any_of_corners(vertex: torch.Tensor) -> torch.Tensor:
    """(X-1, Y-1, Z-1) bool: the cells of a vertex lattice (X, Y, Z) bool with any corner set,
    one axis at a time (PyTorch's CPU max_pool3d took 88 ms on 4M vertices, this 1.4 ms)."""
    vertex = vertex[1:] | vertex[:-1]
    vertex = vertex[:, 1:] | vertex[:, :-1]
    return vertex[:, :, 1:] | vertex[:, :, :-1]


class OccupancyGrid(nn.Module):
    """A boolean grid of (OX, OY, OZ) cells tiling the box `aabb`; all cells start occupied.

    After `carve(hull)`, cells outside the hull are never occupied, whatever `set` is given.
    """

    def __init__(self, cells: tuple[int, int, int], aabb: torch.Tensor, fused: bool = True):
        super().__init__()
        self.fused = fused
        self.register_buffer("aabb", aabb.detach().clone().float())
        self.register_buffer("occupied", torch.ones(cells, dtype=torch.bool))
        # the kernels' copy: uint8 cells and blocks of kernels.BLOCK^3 cells that any occupied
        # cell sets, so marching can jump over empty blocks whole
        self.register_buffer("cells", torch.ones(cells, dtype=torch.uint8), persistent=False)
        self.register_buffer("blocks", self._blocks(self.occupied), persistent=False)
        self.register_buffer("hull", None)  # (HX, HY, HZ) bool once carved; saved with the model
        self._hull_at: torch.Tensor | None = None  # the hull at the occupied cells' size

    @staticmethod
    def _blocks(occupied: torch.Tensor) -> torch.Tensor:
        """(BX, BY, BZ) uint8: 1 where any cell of a block of kernels.BLOCK^3 cells is occupied
        (the last blocks of an axis whose cells do not divide evenly are partial)."""
        b = kernels.BLOCK
        padded = F.pad(occupied, [p for s in reversed(occupied.shape) for p in (0, -s % b)])
        bx, by, bz = (s // b for s in padded.shape)
        blocks = padded.view(bx, b, by, b, bz, b).any(dim=5).any(dim=3).any(dim=1)
        return blocks.to(torch.uint8)

    def set(self, occupied: torch.Tensor) -> None:
        """Replace the occupied cells by `occupied` (OX, OY, OZ) bool, of this or a new size
        (less the cells outside the hull, once carved)."""
        occupied = occupied.to(torch.bool)
        if self.hull is not None:
            occupied = occupied & self.hull_at(occupied.shape)
        self.occupied = occupied.contiguous()
        self.cells = self.occupied.to(torch.uint8)
        self.blocks = self._blocks(self.occupied)

    def carve(self, hull: torch.Tensor) -> None:
        """From now on, occupy only cells that overlap the carve mask `hull` (HX, HY, HZ) bool
        (any resolution over the same box)."""
        self.hull = hull.to(device=self.occupied.device, dtype=torch.bool).contiguous()
        self._hull_at = None
        self.set(self.occupied)

    def hull_at(self, cells: tuple[int, int, int]) -> torch.Tensor:
        """(OX, OY, OZ) bool: the hull at `cells` (cached: refreshes reuse the current size)."""
        cached = self._hull_at
        if cached is None or tuple(cached.shape) != tuple(cells) or cached.device != self.hull.device:
            self._hull_at = hull_cells(self.hull, cells)
        return self._hull_at

    @property
    def inv_cell(self) -> torch.Tensor:
        """(3,) cells per unit length along each axis."""
        dims = torch.tensor(self.occupied.shape, device=self.aabb.device, dtype=torch.float32)
        return dims / (self.aabb[1] - self.aabb[0])

    def fraction(self) -> float:
        """Share of the cells marked occupied."""
        return float(self.occupied.float().mean())

    @torch.no_grad()
    def set_from_vertices(self, vertex: torch.Tensor, threshold: float) -> None:
        """Occupy exactly the cells of a vertex lattice (X, Y, Z) with a corner above `threshold`.

        The cells are those of the lattice (X-1, Y-1, Z-1). Trilinear interpolation inside a cell
        never exceeds its largest corner, so no point whose interpolated value (or any monotone
        function of it) is above the threshold can lie in a skipped cell.
        """
        self.set(any_of_corners(vertex > threshold))

    @torch.no_grad()
    def march(self, origins: torch.Tensor, directions: torch.Tensor, near: float, far: float,
              step: float, jitter: bool) -> Samples:
        """Samples of rays (R, 3) in occupied cells; `jitter` draws each ray's offset in [0, 1)."""
        t_min, t_max = ray_box(origins, directions, self.aabb, near, far)
        if jitter:
            offsets = torch.rand(origins.shape[0], device=origins.device)
        else:
            offsets = torch.full((origins.shape[0],), 0.5, device=origins.device)
        args = (origins.contiguous(), directions.contiguous(), t_min, t_max, offsets, step)
        if self.fused and kernels.available(origins.device) and origins.dtype == torch.float32:
            return Samples(*kernels.march(*args, self.kernel_grid()))
        return march_reference(*args, self.occupied, self.aabb[0], self.inv_cell)

    def kernel_grid(self) -> tuple:
        """What the kernels take for this grid (kernels._occupancy)."""
        return self.cells, self.blocks, self.aabb[0].contiguous(), self.inv_cell.contiguous()

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        saved = state_dict.get(prefix + "occupied")
        if saved is not None and saved.shape != self.occupied.shape:
            self.occupied = torch.ones(saved.shape, dtype=torch.bool, device=self.occupied.device)
        hull = state_dict.get(prefix + "hull")  # a carved model's; None buffers expect no key
        self.hull = None if hull is None else torch.empty_like(hull, device=self.occupied.device)
        self._hull_at = None
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
        self.set(self.occupied)
