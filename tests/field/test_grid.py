"""Trilinear grids: known answers, gradients against finite differences, the fused kernels
against the PyTorch reference, resizing and reloading."""

import pytest
import torch

from windowshop.field import kernels
from windowshop.field.grid import DenseGrid, corner_weights, trilinear_reference

needs_kernels = pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")

SHAPE = (4, 5, 6)
BOX = torch.tensor([[-1.0, -2.0, 0.0], [1.0, 2.0, 3.0]])


def lattice(shape, dtype=torch.float64):
    """(X*Y*Z, 3) grid coordinates of every vertex, row-major."""
    axes = [torch.arange(s, dtype=dtype) for s in shape]
    return torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def affine(points):
    return (2.0 * points[:, 0] - 3.0 * points[:, 1] + 0.5 * points[:, 2] + 1.0)[:, None]


def test_reference_reproduces_affine_functions_and_vertex_values():
    values = torch.cat([affine(lattice(SHAPE)), torch.randn(4 * 5 * 6, 1, dtype=torch.float64)], 1)
    points = torch.rand(200, 3, dtype=torch.float64) * (torch.tensor(SHAPE) - 1)
    out = trilinear_reference(values, SHAPE, points)
    torch.testing.assert_close(out[:, :1], affine(points))  # exact for affine data
    vertices = lattice(SHAPE)
    torch.testing.assert_close(trilinear_reference(values, SHAPE, vertices), values)


def test_points_outside_are_clamped_to_the_nearest_face():
    values = affine(lattice(SHAPE))
    outside = torch.tensor([[-3.0, 1.0, 1.0], [9.0, 9.0, 9.0]], dtype=torch.float64)
    clamped = torch.tensor([[0.0, 1.0, 1.0], [3.0, 4.0, 5.0]], dtype=torch.float64)
    torch.testing.assert_close(trilinear_reference(values, SHAPE, outside), affine(clamped))


def test_corner_weights_sum_to_one_and_name_the_enclosing_cell():
    points = torch.tensor([[1.25, 2.5, 4.75]])
    rows, weights = corner_weights(points, SHAPE)
    assert torch.allclose(weights.sum(-1), torch.ones(1))
    assert rows[0, 0] == (1 * 5 + 2) * 6 + 4 and rows[0, 7] == (2 * 5 + 3) * 6 + 5
    assert torch.isclose(weights[0, 7], torch.tensor(0.25 * 0.5 * 0.75))


def test_gradient_matches_finite_differences():
    torch.manual_seed(0)
    values = torch.randn(4 * 5 * 6, 2, dtype=torch.float64, requires_grad=True)
    points = torch.rand(30, 3, dtype=torch.float64) * (torch.tensor(SHAPE) - 1)
    probe = torch.randn(30, 2, dtype=torch.float64)

    def objective(v):
        return (trilinear_reference(v, SHAPE, points) * probe).sum()

    objective(values).backward()
    numeric = torch.zeros_like(values)
    eps = 1e-6
    for index in torch.randperm(values.numel())[:40].tolist():
        bump = torch.zeros(values.numel(), dtype=torch.float64)
        bump[index] = eps
        bump = bump.view_as(values)
        numeric.view(-1)[index] = (objective(values + bump) - objective(values - bump)) / (2 * eps)
        assert abs(numeric.view(-1)[index] - values.grad.view(-1)[index]) < 1e-6


@needs_kernels
@pytest.mark.parametrize("channels", [1, 12])
def test_fused_kernels_equal_the_reference(channels):
    torch.manual_seed(1)
    shape = (21, 9, 8)  # wide enough in x for the backward's per-thread slabs
    fused = DenseGrid(shape, channels, BOX)
    plain = DenseGrid(shape, channels, BOX, fused=False)
    with torch.no_grad():
        fused.values.copy_(torch.randn_like(fused.values))
        plain.values.copy_(fused.values)
    # inside, on the faces and outside the box
    points = torch.cat([BOX[0] + torch.rand(500, 3) * (BOX[1] - BOX[0]), BOX.repeat(2, 1),
                        torch.randn(50, 3) * 4])
    probe = torch.randn(points.shape[0], channels)
    out_fused, out_plain = fused(points), plain(points)
    torch.testing.assert_close(out_fused, out_plain, rtol=1e-5, atol=1e-5)
    (out_fused * probe).sum().backward()
    (out_plain * probe).sum().backward()
    assert fused.values.grad.is_sparse
    torch.testing.assert_close(fused.values.grad.to_dense(), plain.values.grad, rtol=1e-5, atol=1e-5)
    # the scratch buffers are left clean for the next step
    accum, touched = fused.scratch()
    assert accum.abs().sum() == 0 and touched.sum() == 0


@pytest.mark.parametrize("fused", [False, True])  # F.interpolate, or the kernel at the vertices
def test_resize_keeps_affine_data_and_a_checkpoint_restores_its_shape(fused):
    grid = DenseGrid(SHAPE, 1, BOX, fused=fused)
    with torch.no_grad():
        grid.values.copy_(affine(lattice(SHAPE, torch.float32)))
    param = grid.values
    grid.resize((7, 9, 11))
    assert grid.values is param and grid.values.shape == (7 * 9 * 11, 1)
    points = BOX[0] + torch.rand(100, 3) * (BOX[1] - BOX[0])
    expected = affine(grid.to_grid(points) / (torch.tensor([7, 9, 11]) - 1) * (torch.tensor(SHAPE) - 1))
    torch.testing.assert_close(grid(points), expected, rtol=1e-4, atol=1e-4)
    fresh = DenseGrid(SHAPE, 1, BOX, fused=False)
    fresh.load_state_dict(grid.state_dict())
    assert fresh.shape == (7, 9, 11)
    torch.testing.assert_close(fresh(points), grid(points))


@pytest.mark.parametrize("fused", [False, True])
def test_a_grid_can_grow_while_the_last_steps_graph_is_alive(fused):
    grid = DenseGrid(SHAPE, 2, BOX, fused=fused)
    points = BOX[0] + torch.rand(20, 3) * (BOX[1] - BOX[0])
    old = grid(points).sum()
    old.backward()  # `old` still holds its graph, as a training loop's last loss does
    grid.resize((6, 7, 8))
    grid(points).sum().backward()
    assert grid.values.grad.shape == (6 * 7 * 8, 2)


@needs_kernels
@pytest.mark.parametrize("channels", [1, 16])  # the density's width (a constant in C) and the features'
def test_fused_ray_sample_kernels_equal_the_reference(channels):
    """Values at packed ray samples, and their per-ray weighted sums, with both gradients."""
    torch.manual_seed(2)
    shape = (16, 8, 7)
    fused = DenseGrid(shape, channels, BOX)
    plain = DenseGrid(shape, channels, BOX, fused=False)
    with torch.no_grad():
        fused.values.copy_(torch.randn_like(fused.values))
        plain.values.copy_(fused.values)
    origins = torch.randn(20, 3) * 4
    directions = torch.nn.functional.normalize(-origins + torch.randn(20, 3), dim=-1)
    counts = torch.randint(0, 9, (20,))
    ray = torch.repeat_interleave(torch.arange(20), counts)
    t = torch.rand(len(ray)) * 8
    weights = torch.rand(len(ray))
    probe_samples, probe_rays = torch.randn(len(ray), channels), torch.randn(20, channels)
    results = []
    for grid in (fused, plain):
        w = weights.clone().requires_grad_()
        along = grid.along_rays(origins, directions, t, ray)
        summed = grid.composite(origins, directions, t, w, ray, counts)
        ((along * probe_samples).sum() + (summed * probe_rays).sum()).backward()
        results.append((along, summed, w.grad, grid.values.grad.to_dense()))
    assert fused.values.grad.is_sparse and not plain.values.grad.is_sparse
    for ours, ref in zip(*results):
        torch.testing.assert_close(ours, ref, rtol=1e-4, atol=1e-4)


@needs_kernels
@pytest.mark.parametrize("rows, channels", [(1_000_003, 1), (4_099, 16)])
def test_harvest_gives_every_touched_row_in_order_and_clears_them(rows, channels):
    """Touched rows in clumps and alone, at both ends and across the scan's word and span edges
    (the row counts are neither multiples of 8 nor of the spans)."""
    generator = torch.Generator().manual_seed(3)
    touched = (torch.rand(rows, generator=generator) < 0.02).to(torch.uint8)
    touched[:11] = 1
    touched[rows // 2 - 9: rows // 2 + 30] = 1
    touched[-3:] = 1
    accum = torch.randn(rows, channels, generator=generator) * touched[:, None]
    expected_rows = torch.nonzero(touched).flatten()
    expected_values = accum[expected_rows].clone()
    got_rows, got_values = kernels.harvest(accum, touched)
    assert torch.equal(got_rows, expected_rows)
    assert torch.equal(got_values, expected_values)
    assert not touched.any() and not accum.any()
    empty_rows, empty_values = kernels.harvest(accum, touched)  # nothing touched since
    assert empty_rows.numel() == 0 and empty_values.shape == (0, channels)
