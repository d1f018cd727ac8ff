"""Carving the fast model's grid by the visual hull of the masks (issue 14): the carve mask of a
sphere, its tolerance to a bad mask, marching that never leaves the hull (fused and PyTorch), and
fits on masked and unmasked scenes with their checkpoints."""

import numpy as np
import pytest
import torch

import sphere_helpers
from windowshop.config import FastConfig, FitConfig
from windowshop.field import kernels
from windowshop.field.fast import FastModel
from windowshop.field.occupancy import OccupancyGrid, hull_cells
from windowshop.fit.checkpoint import load_run
from windowshop.fit.trainer import fit
from windowshop.model import Bounds
from windowshop.rays import camera_rays
from windowshop.scene import hull
from windowshop.scene.synthetic import synthetic_scene

BOX = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
CENTRE, RADIUS = np.array([0.2, -0.1, 0.3]), 0.5
CELLS = (24, 24, 24)


def sphere_mask(cam, centre=CENTRE, radius=RADIUS):
    return sphere_helpers.sphere_mask(cam, centre, radius)


def cell_centres(cells=CELLS, box=BOX):
    """(X, Y, Z, 3) centres of the cells of `box`."""
    axes = [box[0, i] + (np.arange(n) + 0.5) * (box[1, i] - box[0, i]) / n for i, n in enumerate(cells)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1)


def touches_sphere(cells=CELLS, box=BOX):
    """(X, Y, Z) bool: cells with a point of the sphere (the nearest point of the cell's box)."""
    half = (box[1] - box[0]) / np.array(cells) / 2
    nearest = np.clip(CENTRE, cell_centres(cells, box) - half, cell_centres(cells, box) + half)
    return np.linalg.norm(nearest - CENTRE, axis=-1) <= RADIUS


@pytest.fixture(scope="module")
def cameras():
    return sphere_helpers.all_around()


def test_the_carve_mask_holds_a_sphere_and_not_the_corners(cameras):
    mask = hull.carve_mask(cameras, [sphere_mask(c) for c in cameras], BOX, CELLS)
    assert mask.shape == CELLS
    assert mask[touches_sphere()].all()  # every cell the sphere reaches survives
    for corner in np.ndindex(2, 2, 2):
        assert not mask[tuple(-c for c in corner)]
    # tight: the sphere's cells and a thin shell (measured: 1665 cells for the sphere's 1296)
    assert mask.sum() < 1.5 * touches_sphere().sum()
    # the dilation is what keeps the cells the surface crosses off their centres
    assert not hull.carve_mask(cameras, [sphere_mask(c) for c in cameras], BOX, CELLS,
                               dilate=0)[touches_sphere()].all()


def test_one_empty_mask_does_not_cut_the_object(cameras):
    masks = [sphere_mask(c) for c in cameras]
    masks[5] = np.zeros_like(masks[5])  # a failed mask: all background
    mask = hull.carve_mask(cameras, masks, BOX, CELLS)
    assert mask[touches_sphere()].all()
    assert not mask[0, 0, 0]


def test_hull_cells_resample_without_cutting():
    hull_mask = torch.zeros(4, 4, 4, dtype=torch.bool)
    hull_mask[1, 1, 1] = True
    coarse = hull_cells(hull_mask, (2, 2, 2))
    assert coarse.sum() == 1 and coarse[0, 0, 0]
    fine = hull_cells(hull_mask, (8, 8, 8))
    expected = torch.zeros(8, 8, 8, dtype=torch.bool)
    expected[2:4, 2:4, 2:4] = True
    assert torch.equal(fine, expected)
    odd = hull_cells(hull_mask, (3, 3, 3))  # cell 1 of 4 overlaps cells 0 and 1 of 3
    assert odd[:2, :2, :2].all() and odd.sum() == 8


def test_set_and_growth_never_occupy_carved_cells():
    grid = OccupancyGrid((8, 8, 8), torch.tensor(BOX, dtype=torch.float32))
    inside = torch.zeros(8, 8, 8, dtype=torch.bool)
    inside[2:5, 3:6, 1:7] = True
    grid.carve(inside)
    assert torch.equal(grid.occupied, inside)
    grid.set(torch.ones(16, 16, 16, dtype=torch.bool))  # as growth does
    assert torch.equal(grid.occupied, hull_cells(inside, (16, 16, 16)))
    assert grid.blocks.sum() < grid.blocks.numel()


@pytest.mark.parametrize("fused", [True, False])
def test_nothing_outside_the_hull_is_drawn(cameras, fused, monkeypatch):
    if fused and not kernels.available("cpu"):
        pytest.skip("no C compiler")
    model = FastModel(FastConfig(voxels=24**3, growth=()), Bounds(aabb=tuple(map(tuple, BOX)),
                                                                  near=0.1, far=10.0)).eval()
    with torch.no_grad():
        model.density_grid.values.fill_(50.0)  # opaque everywhere
    model.carve(torch.from_numpy(touches_sphere(model.carve_cells)))
    assert model.density(torch.tensor([[-0.99, -0.99, -0.99]])) < 1e-3  # carved space is empty
    if not fused:
        monkeypatch.setattr(kernels, "available", lambda device: False)
    cam = cameras[3]
    origins, directions = camera_rays(cam)
    with torch.no_grad():
        out = model.render_rays(origins, directions, torch.ones(len(origins), 3))
    # distance of each ray from the centre: past the sphere plus a cell's diagonal, it misses
    oc = torch.tensor(CENTRE, dtype=torch.float32) - origins
    miss = (oc - (oc * directions).sum(-1, keepdim=True) * directions).norm(dim=-1)
    cell = float((BOX[1] - BOX[0]).max()) / 24
    far_off = miss > RADIUS + 2 * cell * 3**0.5
    assert far_off.sum() > len(origins) / 3
    assert torch.all(out.opacity[far_off] == 0)
    assert out.opacity[miss < RADIUS - cell].min() > 0.99
    model_twin_agrees(model, origins, directions, out, monkeypatch, fused)


def model_twin_agrees(model, origins, directions, out, monkeypatch, fused):
    """The fused render of the carved model against its PyTorch twin."""
    if not fused:
        return
    monkeypatch.setattr(kernels, "available", lambda device: False)
    with torch.no_grad():
        plain = model.render_rays(origins, directions, torch.ones(len(origins), 3))
    assert torch.equal(plain.opacity == 0, out.opacity == 0)
    assert (plain.opacity - out.opacity).abs().max() < 2 * model.config.render_threshold


@pytest.fixture(scope="module")
def carved_run(tmp_path_factory):
    scene = synthetic_scene(n_train=16, n_test=2, size=32, background="alpha")
    out = tmp_path_factory.mktemp("carved")
    config = FastConfig(voxels=20**3, occupancy_warmup=10, occupancy_every=5)
    fit(scene, "fast", config, FitConfig(iters=40, batch_rays=1024), out, "cpu", show_progress=False)
    return scene, out


def test_a_carved_fit_draws_nothing_outside_the_hull(carved_run):
    scene, out = carved_run
    model = load_run(out).model
    grid = model.occupancy
    assert grid.hull is not None and grid.hull.shape == model.carve_cells
    assert not torch.any(grid.occupied & ~grid.hull_at(grid.occupied.shape))
    # rays whose samples would all fall in carved cells: marched through the hull alone
    hull_only = OccupancyGrid(tuple(grid.hull.shape), grid.aabb, fused=False)
    hull_only.set(grid.hull)
    origins, directions = camera_rays(scene.split("test")[0].camera)
    samples = hull_only.march(origins, directions, model.bounds.near, model.bounds.far,
                              model.step_length, jitter=False)
    outside = samples.counts == 0
    assert outside.sum() > len(origins) / 5
    with torch.no_grad():
        opacity = model.render_rays(origins, directions, torch.ones(len(origins), 3)).opacity
    assert torch.all(opacity[outside] == 0)
    alpha = torch.from_numpy(scene.split("test")[0].alpha.reshape(-1))
    assert opacity[alpha > 0.5].mean() > 0.5  # and the object itself was learned


def test_a_checkpoint_keeps_the_carve(carved_run):
    scene, out = carved_run
    model = load_run(out).model
    again = FastModel(model.config, model.bounds)
    again.load_state_dict(model.state_dict())
    assert torch.equal(again.occupancy.hull, model.occupancy.hull)
    assert torch.equal(again.occupancy.occupied, model.occupancy.occupied)
    again.occupancy.set(torch.ones_like(again.occupancy.occupied))  # a refresh of the rebuilt model
    assert torch.equal(again.occupancy.occupied, again.occupancy.hull_at(again.occupancy.occupied.shape))


@pytest.mark.parametrize("background, carve, masked", [("white", True, False), ("alpha", False, None)])
def test_unmasked_or_unasked_fits_are_not_carved(tmp_path, background, carve, masked):
    scene = synthetic_scene(n_train=4, n_test=1, size=16, background=background)
    fit(scene, "fast", FastConfig(voxels=12**3, carve=carve, masked=masked),
        FitConfig(iters=2, batch_rays=256), tmp_path, "cpu", show_progress=False)
    model = load_run(tmp_path).model
    assert model.occupancy.hull is None
    assert model.occupancy.occupied.all()  # nothing skipped before the occupancy warm-up


def test_few_photos_over_white_with_mattes_are_carved(tmp_path):
    scene = synthetic_scene(n_train=4, n_test=1, size=16, background="white")  # 4 photos: few
    fit(scene, "fast", FastConfig(voxels=12**3), FitConfig(iters=2, batch_rays=256), tmp_path,
        "cpu", show_progress=False)
    model = load_run(tmp_path).model
    assert model.config.masked and model.occupancy.hull is not None
    assert 0 < model.occupancy.hull.float().mean() < 1
