"""The fast model end to end: sizing, growth, a checkpoint round trip, the fused render path against
the PyTorch one, and a learning race against the NeRF at the same time budget."""


import pytest
import torch

from windowshop.config import FastConfig, FitConfig
from windowshop.field import kernels
from windowshop.field.fast import FastModel, pixel_footprint, spherical_harmonics
from windowshop.fit.losses import LossInput, loss_terms, total_loss
from windowshop.fit.schedule import StepInfo, schedule_for
from windowshop.fit.trainer import fit
from windowshop.model import Bounds, model_config
from windowshop.rays import camera_rays
from windowshop.scene.synthetic import synthetic_scene
from shared_data import DATA

LEGO_TINY = DATA / "lego_tiny.npz"


@pytest.fixture(scope="module")
def scene():
    return synthetic_scene(n_train=12, n_test=2, size=32)


def trained(scene, steps=40, **overrides):
    """A FastModel after `steps` plain training steps on the scene's training rays."""
    torch.manual_seed(0)
    config = FastModel.for_scene(FastConfig(occupancy_warmup=10, occupancy_every=5, **overrides), scene)
    model = FastModel(config, Bounds.of_scene(scene))
    optimizer = model.make_optimizer()
    for group in optimizer.param_groups:
        group["initial_lr"] = group["lr"]
    schedule, losses = schedule_for(model), loss_terms(config)
    views = scene.split("train")
    rays = [camera_rays(v.camera) for v in views]
    origins = torch.cat([o for o, _ in rays])
    directions = torch.cat([d for _, d in rays])
    target = torch.cat([torch.from_numpy(v.image.reshape(-1, 3)) for v in views])
    white = torch.ones(1024, 3)
    for step in range(steps):
        for hook in schedule:
            hook.before_step(StepInfo(model, optimizer, step, step / steps, 1024))
        pick = torch.randint(len(origins), (1024,))
        out = model.render_rays(origins[pick], directions[pick], white)
        optimizer.zero_grad()
        total_loss(losses, LossInput(model, out, target[pick], white)).backward()
        optimizer.step()
    return model.eval()


def test_the_grid_is_sized_by_the_photos_pixels(scene):
    config = FastModel.for_scene(FastConfig(), scene)
    extent = scene.aabb[1] - scene.aabb[0]
    voxel = (extent.prod() / config.voxels) ** (1 / 3)
    assert voxel == pytest.approx(pixel_footprint(scene), rel=0.01)
    finer = FastModel.for_scene(FastConfig(voxel_pixels=0.5, max_voxels_per_pixel=100.0), scene)
    assert finer.voxels == pytest.approx(8 * config.voxels, rel=0.01)
    assert FastModel.for_scene(FastConfig(voxels=1000), scene).voxels == 1000
    # never more voxels than training pixels (12 photos of 32x32 here): the finer grid is capped
    pixels = 12 * 32 * 32
    assert config.voxels < pixels  # this well-covered scene is sized by its pixels' footprint
    capped = FastModel.for_scene(FastConfig(voxel_pixels=0.5), scene)
    assert capped.voxels == pixels < finer.voxels


def test_spherical_harmonics_are_orthonormal_on_the_sphere():
    d = torch.nn.functional.normalize(torch.randn(200_000, 3, dtype=torch.float64), dim=-1)
    basis = spherical_harmonics(d, 3)
    gram = basis.T @ basis * (4 * torch.pi / len(d))
    torch.testing.assert_close(gram, torch.eye(16, dtype=torch.float64), atol=0.02, rtol=0)


def test_grids_grow_and_empty_space_is_skipped(scene):
    model = trained(scene)
    config = model.config
    assert model.grid_shape == model.lattice(1.0)
    assert model.density_grid.numel == pytest.approx(config.voxels, rel=0.15)
    assert 0.0 < model.occupancy.fraction() < 0.8  # the object fills much of its tight box


def test_a_checkpoint_rebuilds_the_same_model(scene):
    model = trained(scene, steps=25)
    fresh = FastModel(model.config, model.bounds)
    assert fresh.grid_shape != model.grid_shape  # it starts coarse ...
    fresh.load_state_dict(model.state_dict())  # ... and takes the checkpoint's shapes
    fresh.eval()
    origins, directions = camera_rays(scene.split("test")[0].camera)
    with torch.no_grad():
        a = model.render_rays(origins, directions, torch.ones(len(origins), 3))
        b = fresh.render_rays(origins, directions, torch.ones(len(origins), 3))
    torch.testing.assert_close(a.rgb, b.rgb)


@pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")
def test_the_fused_render_path_matches_the_pytorch_path(scene, monkeypatch):
    model = trained(scene)
    origins, directions = camera_rays(scene.split("test")[0].camera)
    white = torch.ones(len(origins), 3)
    with torch.no_grad():
        fused = model.render_rays(origins, directions, white)
        monkeypatch.setattr(kernels, "available", lambda device: False)
        plain = model.render_rays(origins, directions, white)
    assert fused.num_samples <= plain.num_samples  # early termination, and fewer kept
    # rays stop at transmittance render_threshold: colours differ by at most about that much
    assert (fused.rgb - plain.rgb).abs().max() < 10 * model.config.render_threshold
    assert (fused.opacity - plain.opacity).abs().max() < 2 * model.config.render_threshold


@pytest.mark.skipif(not LEGO_TINY.is_file(), reason="shared test data not present")
@pytest.mark.skipif(not kernels.available("cpu"), reason="the speed is the fused kernels'")
def test_fast_beats_the_nerf_at_the_same_time_budget(tmp_path):
    from windowshop.scene import load_scene

    scene = load_scene(LEGO_TINY)
    budget = FitConfig(iters=None, seconds=20.0, batch_rays=4096, seed=0)
    fast = fit(scene, "fast", model_config("fast"), budget, tmp_path / "fast", "cpu",
               show_progress=False)
    # the strongest NeRF for a budget this short (tests/test_fit_learning.py's)
    nerf_config = model_config("nerf", "tiny", depth=4, width=64, n_coarse=32, lr=5e-3,
                               lr_final=5e-4, density_activation="softplus")
    nerf = fit(scene, "nerf", nerf_config, FitConfig(iters=None, seconds=20.0, batch_rays=512, seed=0),
               tmp_path / "nerf", "cpu", show_progress=False)
    # Measured on the 2-core CPU at 20 s each with another job on one core: fast 21.5 dB, nerf
    # 14.5-15.7 dB (the mean colour alone gives 13.5 dB).
    assert fast["psnr"] >= nerf["psnr"] + 4.0, (fast["psnr"], nerf["psnr"])
    assert fast["psnr"] >= 20.0


def test_growing_takes_the_adam_moments_along(scene):
    config = FastModel.for_scene(FastConfig(), scene)
    model = FastModel(config, Bounds.of_scene(scene))
    optimizer = model.make_optimizer()
    origins, directions = camera_rays(scene.split("train")[0].camera)
    out = model.render_rays(origins, directions, torch.ones(len(origins), 3))
    torch.mean(out.rgb ** 2).backward()
    optimizer.step()
    grid = model.density_grid
    before = optimizer.state[grid.values]["exp_avg_sq"].sum()
    model.grow(model.lattice(1.0))  # the end of the budget: the final lattice
    state = optimizer.state[grid.values]
    assert state["exp_avg_sq"].shape == grid.values.shape
    assert state["exp_avg_sq"].sum() > 0.5 * before and state["step"] == 1


def test_the_pure_pytorch_path_learns_too(scene, monkeypatch):
    """What runs on CUDA (and without a C compiler): reference marching and interpolation, dense
    gradients and dense Adam steps."""
    monkeypatch.setattr(kernels, "available", lambda device: False)
    origins, directions = camera_rays(scene.split("test")[0].camera)
    truth = torch.from_numpy(scene.split("test")[0].image.reshape(-1, 3))
    errors = []
    for steps in (1, 40):
        model = trained(scene, steps=steps)
        assert not model.density_grid.values.grad.is_sparse
        with torch.no_grad():
            rgb = model.render_rays(origins, directions, torch.ones(len(origins), 3)).rgb
        errors.append(float(torch.mean((rgb - truth) ** 2)))
    assert errors[1] < 0.5 * errors[0], errors


def uniform_fog(**overrides) -> FastModel:
    """A fast model over the unit box filled with one density, in training mode."""
    bounds = Bounds(aabb=((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)), near=0.5, far=6.0)
    model = FastModel(FastConfig(**{"voxels": 16**3, "growth": (), **overrides}), bounds)
    with torch.no_grad():
        model.density_grid.values.fill_(model._raw_at_alpha(0.05))
    return model.train()


def test_the_occlusion_penalty_is_the_optical_thickness_next_to_the_box_entry():
    model = uniform_fog(occlusion=1.0, occlusion_reach=0.5)
    origins = torch.tensor([[-3.0, 0.1, 0.2], [0.2, -3.0, -0.3]])
    directions = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    aux = model.render_rays(origins, directions, torch.ones(2, 3)).aux
    sigma = float(model.density(torch.zeros(1, 3)).detach())
    # the samples (one every step, jittered) within 0.5 of the entry: 0.5 of fog, give or take a step
    assert abs(float(aux["occlusion"].detach()) - sigma * 0.5) <= sigma * model.step_length + 1e-6


def test_density_dropout_only_trains_on_a_random_share_of_the_samples():
    model = uniform_fog(density_dropout=0.5)
    origins = torch.tensor([[-3.0, 0.0, 0.0]]).expand(64, 3)
    directions = torch.tensor([[1.0, 0.0, 0.0]]).expand(64, 3)
    first = model.render_rays(origins, directions, torch.ones(64, 3)).opacity
    assert float(first.detach().std()) > 0  # the same ray, thinned differently each time
    model.eval()
    kept = model.render_rays(origins, directions, torch.ones(64, 3)).opacity
    torch.testing.assert_close(kept, kept[:1].expand(64))


def test_the_density_total_variation_is_the_fields_change_over_a_fixed_span_at_any_resolution():
    # raw density rising by 1 a world unit along x; rays along y, so every neighbour along x
    # lies inside the box: the change over 1/128 of the box's side (2) is 2/128 along x, none
    # along y and z, whatever the voxel
    origins = torch.tensor([[0.13, -3.0, -0.21]]).expand(64, 3)
    directions = torch.tensor([[0.0, 1.0, 0.0]]).expand(64, 3)
    for side in (16, 32):
        model = uniform_fog(tv_density=1.0, voxels=side**3)
        x = torch.linspace(-1.0, 1.0, model.grid_shape[0])
        with torch.no_grad():
            model.density_grid.values[:, 0] += x[:, None, None].expand(model.grid_shape).reshape(-1)
        tv = model.render_rays(origins, directions, torch.ones(64, 3)).aux["tv_density"]
        torch.testing.assert_close(float(tv.detach()), (2 / 128) ** 2 / 3, rtol=1e-4, atol=0)


def ramp_in_fog(**overrides) -> FastModel:
    """`uniform_fog` confined to the vertices 4..12 of its 17 a side (so every sample that shows
    and its neighbours lie inside the lattice), with features that rise by 0.1 a vertex along
    every axis: one voxel along any axis changes every channel by 0.1."""
    model = uniform_fog(**overrides)
    n = model.grid_shape[0]
    index = torch.arange(n, dtype=torch.float32)
    i, j, k = torch.meshgrid(index, index, index, indexing="ij")
    inside = ((i >= 4) & (i <= 12) & (j >= 4) & (j <= 12) & (k >= 4) & (k <= 12)).reshape(-1)
    with torch.no_grad():
        model.density_grid.values[~inside] = model._raw_at_alpha(1e-9)
        model.feature_grid.values.copy_((0.1 * (i + j + k)).reshape(-1, 1).expand(-1, 16))
    return model


def test_the_feature_total_variation_is_the_squared_change_one_voxel_away():
    model = ramp_in_fog(tv_features=1.0)
    assert model.grid_shape == (17, 17, 17)
    origins = torch.tensor([[-3.0, 0.05, -0.1]]).expand(256, 3)
    directions = torch.tensor([[1.0, 0.0, 0.0]]).expand(256, 3)
    tv = model.render_rays(origins, directions, torch.ones(256, 3)).aux["tv_features"]
    torch.testing.assert_close(float(tv.detach()), 0.1**2, rtol=1e-4, atol=0)


def test_the_feature_total_variation_leaves_the_colours_alone_and_trains_the_features():
    origins = torch.tensor([[-3.0, 0.05, -0.1]]).expand(256, 3)
    directions = torch.tensor([[1.0, 0.0, 0.0]]).expand(256, 3)
    colours = []
    for weight in (0.0, 1.0):
        torch.manual_seed(0)  # the same colour MLP, and the same jitter
        model = ramp_in_fog(tv_features=weight)
        out = model.render_rays(origins, directions, torch.ones(256, 3))
        colours.append(out.rgb.detach())
    torch.testing.assert_close(colours[0], colours[1])
    # the term's gradient reaches the features, not the density
    out.aux["tv_features"].backward()
    assert float(model.feature_grid.values.grad.coalesce().values().abs().sum()) > 0
    assert float(model.density_grid.values.grad.coalesce().values().abs().sum()) == 0


def test_finishing_empties_what_no_training_ray_saw_behind_a_wall():
    # an opaque wall at x in [-0.25, 0.25] (vertices 0.125 apart) in thin fog, seen only from -x
    # over |y|, |z| <= 0.6: one step into the wall a ray keeps a tenth of its light, so the fog in
    # front, the wall's face and the vertex behind it (a sample reads its cell's corners) stay;
    # from the wall's middle on, the space no ray saw is emptied, and a ray from +x, which no
    # photo took, meets the kept face
    model = uniform_fog(empty_unseen=0.1)
    x = torch.linspace(-1, 1, 17)[:, None, None].expand(model.grid_shape).reshape(-1)
    with torch.no_grad():
        model.density_grid.values[x.abs() <= 0.25] = model._raw_at_alpha(0.9)
        model.density_grid.values[x.abs() > 0.25] = model._raw_at_alpha(1e-3)
    before = model.density_grid.values.detach().clone()[:, 0]
    side = torch.linspace(-0.6, 0.6, 16)
    y, z = torch.meshgrid(side, side, indexing="ij")
    origins = torch.stack([torch.full_like(y, -3.0), y, z], dim=-1).reshape(-1, 3)
    directions = torch.tensor([[1.0, 0.0, 0.0]]).expand_as(origins)
    model.finish_training([(origins, directions)])
    after = model.density_grid.values.detach()[:, 0]
    middle = torch.linspace(-1, 1, 17).abs() <= 0.5
    inner = (middle[None, :, None] & middle[None, None, :]).expand(model.grid_shape).reshape(-1)
    assert model.training
    torch.testing.assert_close(after[inner & (x <= -0.125)], before[inner & (x <= -0.125)])
    assert bool((after[inner & (x >= 0)] < model._raw_at_alpha(1e-5)).all())
    back = model.eval().render_rays(torch.tensor([[3.0, 0.1, 0.1]]),
                                    torch.tensor([[-1.0, 0.0, 0.0]]), torch.ones(1, 3))
    assert float(back.opacity) > 0.95
    assert 3.0 < float(back.depth / back.opacity) < 3.25


def test_finishing_keeps_everything_by_default():
    model = uniform_fog()
    before = model.density_grid.values.detach().clone()
    model.finish_training([(torch.tensor([[-3.0, 0.0, 0.0]]), torch.tensor([[1.0, 0.0, 0.0]]))])
    torch.testing.assert_close(model.density_grid.values.detach(), before)
