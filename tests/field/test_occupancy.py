"""Ray marching through an occupancy grid: box intersection, the fused kernel against the
reference, and that skipping never drops a sample where the density matters."""

import math

import pytest
import torch
import torch.nn.functional as F

from windowshop.field import kernels
from windowshop.field.grid import DenseGrid
from windowshop.field.occupancy import OccupancyGrid, any_of_corners, march_reference, ray_box

needs_kernels = pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")
BOX = torch.tensor([[-1.0, -0.5, -0.8], [1.0, 0.5, 0.8]])


def random_rays(n, seed=0):
    """Rays from a sphere of radius 3 towards random points near the box."""
    g = torch.Generator().manual_seed(seed)
    origins = F.normalize(torch.randn(n, 3, generator=g), dim=-1) * 3.0
    targets = torch.randn(n, 3, generator=g) * 0.6
    return origins, F.normalize(targets - origins, dim=-1)


def test_ray_box_known_answers():
    origins = torch.tensor([[-3.0, 0.0, 0.0], [-3.0, 2.0, 0.0], [0.0, 0.0, 0.0]])
    directions = torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    t_min, t_max = ray_box(origins, directions, BOX, near=0.1, far=10.0)
    torch.testing.assert_close(t_min, torch.tensor([2.0, t_min[1], 0.1]))
    torch.testing.assert_close(t_max, torch.tensor([4.0, t_min[1], 0.8]))  # the miss is empty


@needs_kernels
@pytest.mark.parametrize("share", [0.3, 0.002])  # sparse: most blocks are empty and jumped over
@pytest.mark.parametrize("room", [0.0, 1000.0])  # samples a ray: a run overflows, or all fit
def test_fused_march_equals_the_reference(share, room, monkeypatch):
    monkeypatch.setattr(kernels, "_samples_per_ray", [room])
    origins, directions = random_rays(300)
    g = torch.Generator().manual_seed(3)
    grid = OccupancyGrid((23, 14, 18), BOX)
    grid.set(torch.rand(23, 14, 18, generator=g) < share)
    t_min, t_max = ray_box(origins, directions, BOX, 0.5, 6.0)
    offsets = torch.rand(300, generator=g)
    args = (origins, directions, t_min, t_max, offsets, 0.019)
    ref = march_reference(*args, grid.occupied, BOX[0], grid.inv_cell)
    t, ray, counts = kernels.march(*args, grid.kernel_grid())
    assert len(ref) > 20
    assert torch.equal(counts, ref.counts) and torch.equal(ray, ref.ray)
    assert torch.equal(t, ref.t)


@pytest.mark.parametrize("fused", [False, True])
def test_skipping_never_drops_a_sample_in_occupied_space(fused):
    if fused and not kernels.available("cpu"):
        pytest.skip("no C compiler")
    torch.manual_seed(0)
    shape = (13, 8, 11)
    density = DenseGrid(shape, 1, BOX, fused=False)
    with torch.no_grad():  # sparse blobs of matter in an empty box
        density.values.copy_(torch.where(torch.rand(density.numel, 1) < 0.05, 3.0, -5.0))
    threshold = 0.0
    occupancy = OccupancyGrid(tuple(s - 1 for s in shape), BOX, fused=fused)
    occupancy.set_from_vertices(density.vertex_values()[0], threshold)
    assert 0.05 < occupancy.fraction() < 0.6
    origins, directions = random_rays(400, seed=1)
    everything = OccupancyGrid(tuple(s - 1 for s in shape), BOX, fused=False)  # all occupied
    dense = everything.march(origins, directions, 0.0, 10.0, 0.01, jitter=False)
    kept = occupancy.march(origins, directions, 0.0, 10.0, 0.01, jitter=False)
    def points(s):
        return origins[s.ray] + s.t[:, None] * directions[s.ray]
    matter = density(points(dense))[:, 0] > threshold
    assert matter.sum() > 100
    dense_keys = set(zip(dense.ray[matter].tolist(), dense.t[matter].tolist()))
    kept_keys = set(zip(kept.ray.tolist(), kept.t.tolist()))
    assert dense_keys <= kept_keys  # every sample with matter survives
    assert len(kept) < 0.7 * len(dense)  # and empty space was skipped


def test_set_from_vertices_marks_cells_by_their_densest_corner():
    occupancy = OccupancyGrid((2, 1, 1), torch.tensor([[0.0, 0, 0], [2, 1, 1]]))
    vertex = torch.zeros(3, 2, 2)
    vertex[2, 1, 1] = 1.0  # only a corner of the second cell is dense
    occupancy.set_from_vertices(vertex, 0.5)
    assert occupancy.occupied[:, 0, 0].tolist() == [False, True]
    assert math.isclose(occupancy.fraction(), 0.5)


@pytest.mark.parametrize("shape", [(9, 6, 7), (2, 13, 4), (8, 8, 8)])
def test_corners_and_blocks_equal_max_pooling(shape):
    """Any corner of a cell set, and any cell of a block, as max pooling gives them (the last
    blocks of an axis of cells that BLOCK does not divide are partial)."""
    vertex = torch.rand(shape, generator=torch.Generator().manual_seed(sum(shape))) > 0.97
    pooled = F.max_pool3d(vertex[None, None].float(), kernel_size=2, stride=1)[0, 0] > 0
    assert torch.equal(any_of_corners(vertex), pooled)
    cells = vertex.clone()
    blocks = OccupancyGrid._blocks(cells)
    pooled = F.max_pool3d(cells[None, None].float(), kernel_size=kernels.BLOCK, ceil_mode=True)[0, 0]
    assert blocks.dtype == torch.uint8 and torch.equal(blocks, (pooled > 0).to(torch.uint8))


@needs_kernels
def test_fused_render_composite_equals_marching_then_compositing():
    """The early-terminating one-pass render kernel against march_reference + trilinear + packed
    weights + the features composited over the samples above the threshold."""
    from windowshop.field.grid import trilinear_reference
    from windowshop.render.packed import packed_weights, ray_sum

    torch.manual_seed(4)
    shape = (9, 6, 8)
    density = torch.randn(9 * 6 * 8) * 3
    features = torch.randn(9 * 6 * 8, 5)
    occupancy = OccupancyGrid((8, 5, 7), BOX)
    occupancy.set_from_vertices(density.view(shape), -1.0)
    origins, directions = random_rays(300, seed=2)
    t_min, t_max = ray_box(origins, directions, BOX, 0.5, 6.0)
    step, shift, scale, threshold = 0.02, -1.0, 8.0, 1e-3
    inv_voxel = (torch.tensor(shape) - 1) / (BOX[1] - BOX[0])
    composited, counts, opacity, depth = kernels.render_composite(
        origins, directions, t_min, t_max, step, occupancy.kernel_grid(), density, features,
        shape, inv_voxel, shift, scale, threshold)
    ref = march_reference(origins, directions, t_min, t_max, torch.full((300,), 0.5), step,
                          occupancy.occupied, BOX[0].contiguous(), occupancy.inv_cell)
    points = origins[ref.ray] + ref.t[:, None] * directions[ref.ray]
    grid_points = (points - BOX[0]) * inv_voxel
    raw = trilinear_reference(density[:, None], shape, grid_points)[:, 0]
    w = packed_weights(F.softplus(raw + shift) * scale, step, ref.ray, ref.counts)
    keep = w >= threshold
    expected = ray_sum(w[keep, None] * trilinear_reference(features, shape, grid_points[keep]),
                       ref.ray[keep], 300)
    assert int(counts.sum()) > 500 and 0.0 < float((opacity > 0.99).float().mean()) < 1.0
    assert torch.equal(counts, torch.bincount(ref.ray[keep], minlength=300))
    torch.testing.assert_close(composited, expected, rtol=1e-4, atol=1e-4)
    # terminated rays lose at most `threshold` of their opacity
    assert (ray_sum(w, ref.ray, 300) - opacity).abs().max() <= threshold + 1e-5
    assert (ray_sum(w * ref.t, ref.ray, 300) - depth).abs().max() <= 6.0 * threshold + 1e-4
