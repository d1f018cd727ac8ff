"""The trainer's hooks: progress, checkpoint and cancel callbacks; losses and schedules as
functions; every model's density() and colour(); loss terms fed rays from cameras with no photo."""

import dataclasses
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from windowshop.config import FastConfig, FitConfig, NerfConfig
from windowshop.field import kernels
from windowshop.field.fast import FastModel, lattice_shape
from windowshop.field.nerf import NerfModel
from windowshop.fit.callbacks import FitCallbacks, FitCancelled
from windowshop.fit.checkpoint import load_checkpoint
from windowshop.fit.losses import LossInput, LossTerm, loss_terms, total_loss
from windowshop.fit.schedule import StepInfo, exponential, schedule_for
from windowshop.fit.trainer import fit
from windowshop.model import Bounds, RenderOutput
from windowshop.render.composite import composite
from windowshop.render.sampling import stratified
from windowshop.scene.cameras import look_at
from windowshop.scene.synthetic import synthetic_scene
from windowshop.scene.types import Camera

BOUNDS = Bounds(aabb=((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)), near=1.5, far=4.5)
TINY = NerfConfig(freqs=2, view_dependent=False, depth=2, width=16, n_coarse=8, n_fine=0)


def toy_scene():
    return synthetic_scene(n_train=4, n_test=1, size=12)


def test_progress_is_reported_every_step_and_ends_at_one(tmp_path):
    fractions, checkpoints = [], []
    callbacks = FitCallbacks(on_step=lambda fraction, stats: fractions.append((fraction, stats["step"])),
                             on_checkpoint=checkpoints.append)
    fit(toy_scene(), "nerf", TINY, FitConfig(iters=12, batch_rays=32, checkpoint_every=5),
        tmp_path, "cpu", show_progress=False, callbacks=callbacks)
    assert fractions == [(pytest.approx(k / 12), k) for k in range(1, 13)]  # monotone, ends at 1
    assert fractions[-1][0] == 1.0
    assert checkpoints == [tmp_path / "checkpoint.pt"] * 3  # steps 5, 10 and the end


def test_a_cancelled_fit_stops_at_once_and_resumes_from_its_checkpoint(tmp_path):
    steps = []
    callbacks = FitCallbacks(on_step=lambda fraction, stats: steps.append(stats["step"]),
                             should_stop=lambda: len(steps) >= 4)
    budget = FitConfig(iters=10, batch_rays=32, checkpoint_every=1000)
    with pytest.raises(FitCancelled) as cancelled:
        fit(toy_scene(), "nerf", TINY, budget, tmp_path, "cpu", show_progress=False,
            callbacks=callbacks)
    assert cancelled.value.step == 4 and steps == [1, 2, 3, 4]
    assert load_checkpoint(tmp_path)["step"] == 4
    assert not (tmp_path / "metrics.json").exists()  # a cancelled fit is not evaluated
    metrics = fit(toy_scene(), "nerf", TINY, budget, tmp_path, "cpu", resume=tmp_path,
                  show_progress=False)
    assert metrics["iterations"] == 10


def test_nerf_density_and_colour_are_what_render_rays_composites():
    torch.manual_seed(0)
    model = NerfModel(dataclasses.replace(TINY, view_dependent=True, n_coarse=16), BOUNDS).eval()
    origins = torch.tensor([[0.0, 0.0, 3.0], [0.3, -0.2, 3.0]])
    directions = F.normalize(torch.tensor([[0.0, 0.0, -1.0], [-0.1, 0.1, -1.0]]), dim=-1)
    background = torch.tensor([[1.0, 1.0, 1.0], [0.0, 0.5, 1.0]])
    near, far = torch.full((2,), 1.5), torch.full((2,), 4.5)
    t = stratified(near, far, 16, jitter=False)  # eval mode samples the midpoints
    points = (origins[:, None] + t[..., None] * directions[:, None]).reshape(-1, 3)
    dirs = directions[:, None].expand(2, 16, 3).reshape(-1, 3)
    with torch.no_grad():
        sigma, rgb = model.density(points), model.colour(points, dirs)
        expected = composite(sigma.view(2, 16), rgb.view(2, 16, 3), t, far, background)
        out = model.render_rays(origins, directions, background)
    torch.testing.assert_close(out.rgb, expected.rgb)
    torch.testing.assert_close(out.opacity, expected.opacity)


def test_nerf_density_and_colour_come_from_the_fine_field():
    torch.manual_seed(0)
    model = NerfModel(dataclasses.replace(TINY, view_dependent=True, n_fine=8), BOUNDS)
    points, dirs = torch.randn(5, 3), F.normalize(torch.randn(5, 3), dim=-1)
    sigma, rgb = model.fine(points, dirs)
    torch.testing.assert_close(model.density(points), sigma)
    torch.testing.assert_close(model.colour(points, dirs), rgb)
    assert not torch.allclose(model.coarse(points, dirs)[0], sigma)


def fast_model(**overrides) -> FastModel:
    """A small fast model on BOUNDS, by default without growth."""
    return FastModel(FastConfig(**{"voxels": 12**3, "growth": (), **overrides}), BOUNDS)


def scheduled(model: FastModel) -> tuple[torch.optim.Optimizer, list]:
    """The model's optimizer, its rates recorded as the trainer does, and its schedule's hooks."""
    optimizer = model.make_optimizer()
    for group in optimizer.param_groups:
        group["initial_lr"] = group["lr"]
    return optimizer, schedule_for(model)


def test_fast_density_and_colour_at_a_vertex_read_that_vertex():
    torch.manual_seed(0)
    model = fast_model()
    with torch.no_grad():
        model.density_grid.values.normal_()
        model.feature_grid.values.normal_()
    x, y, z = 3, 7, 5
    X, Y, Z = model.grid_shape
    vertex = x * Y * Z + y * Z + z  # the values are the lattice's vertices, row-major
    point = (model.density_grid.aabb[0] + torch.tensor([x, y, z]) * model.density_grid.voxel)[None]
    raw = model.density_grid.values[vertex, 0]
    expected = F.softplus(raw + model.shift) * model.density_scale
    torch.testing.assert_close(model.density(point), expected[None])
    direction = torch.tensor([[0.0, 0.6, 0.8]])
    with torch.no_grad():
        torch.testing.assert_close(model.colour(point, direction),
                                   model.decode(model.feature_grid.values[vertex][None], direction))


def test_fast_render_of_a_uniform_grid_follows_density_and_colour(monkeypatch):
    """Constant density and features: the ray's opacity is 1 - exp(-density * step * samples) and
    its colour that of any point, over the background."""
    monkeypatch.setattr(kernels, "available", lambda device: False)  # every sample, no early stop
    model = fast_model(render_threshold=1e-12).eval()
    with torch.no_grad():
        model.density_grid.values.fill_(2.0)
        model.feature_grid.values.copy_(torch.linspace(-1, 1, model.config.features))
    origins = torch.tensor([[0.1, 0.2, 3.0]])
    directions = torch.tensor([[0.0, 0.0, -1.0]])
    background = torch.tensor([[0.2, 0.4, 0.6]])
    with torch.no_grad():
        out = model.render_rays(origins, directions, background)
        point = torch.tensor([[0.3, -0.5, 0.1]])
        sigma, rgb = model.density(point), model.colour(point, directions)
    assert 0.05 < float(out.opacity) < 0.95  # a test of both terms
    opacity = 1.0 - torch.exp(-sigma * model.step_length * out.num_samples)
    torch.testing.assert_close(out.opacity, opacity)
    torch.testing.assert_close(out.rgb, opacity[:, None] * rgb + (1.0 - opacity[:, None]) * background)


def test_losses_are_the_former_formulas():
    torch.manual_seed(0)
    rgb, coarse, target = torch.rand(6, 3), torch.rand(6, 3), torch.rand(6, 3)
    distortion, tv = torch.rand(6), torch.rand(())
    nerf_out = RenderOutput(rgb=rgb, depth=torch.zeros(6), opacity=torch.ones(6),
                            aux={"rgb_coarse": coarse})
    nerf = NerfModel(TINY, BOUNDS)
    loss = total_loss(loss_terms(nerf.config), LossInput(nerf, nerf_out, target, torch.ones(6, 3)))
    torch.testing.assert_close(loss, ((rgb - target) ** 2).mean() + ((coarse - target) ** 2).mean())

    fast = fast_model(distortion=0.01, tv_density=0.1)
    fast_out = RenderOutput(rgb=rgb, depth=torch.zeros(6), opacity=torch.ones(6),
                            aux={"distortion": distortion, "tv_density": tv})
    terms = loss_terms(fast.config)
    assert [t.name for t in terms] == ["photometric", "distortion", "tv_density"]
    loss = total_loss(terms, LossInput(fast, fast_out, target, torch.ones(6, 3)))
    torch.testing.assert_close(loss, ((rgb - target) ** 2).mean() + 0.01 * distortion.mean() + 0.1 * tv)
    assert [t.name for t in loss_terms(FastConfig())] == ["photometric"]  # off by default


def test_the_fast_schedule_grows_the_grid_at_the_growth_points():
    model = fast_model(growth=(0.1, 0.2, 0.3), start_fraction=0.125, occupancy_warmup=10**9)
    optimizer, schedule = scheduled(model)
    extent = torch.tensor([2.0, 2.0, 2.0])
    # the lattice before the refactor: voxels * start ** (1 - passed / len(growth))
    former = [lattice_shape(extent, round(12**3 * 0.125 ** (1 - k / 3))) for k in range(4)]
    assert model.grid_shape == former[0]
    grown = []
    for step in range(100):
        shape = model.grid_shape
        for hook in schedule:
            hook.before_step(StepInfo(model, optimizer, step, step / 100, 4096))
        if model.grid_shape != shape:
            grown.append((step, model.grid_shape))
    assert grown == [(10, former[1]), (20, former[2]), (30, former[3])]
    config = model.config  # the grids' rate 99% of the way: inside the anneal of the last lr_tail
    tail = (0.99 - (1.0 - config.lr_tail)) / config.lr_tail
    assert optimizer.param_groups[0]["lr"] == pytest.approx(
        config.lr_grid * config.lr_final ** 0.99 * config.lr_tail_factor ** tail)


def test_the_learning_rate_decays_then_anneals_over_the_tail():
    factor = exponential(0.25, tail=0.2, tail_factor=0.1)
    assert factor(0.0) == 1.0 and factor(-1.0) == 1.0
    assert factor(0.5) == pytest.approx(0.5)  # 0.25 ** 0.5: the tail not reached
    assert factor(0.8) == pytest.approx(0.25 ** 0.8)  # the tail starts without a jump ...
    assert factor(0.9) == pytest.approx(0.25 ** 0.9 * 0.1 ** 0.5)  # ... halfway: sqrt(0.1) more
    assert factor(1.0) == pytest.approx(0.025) and factor(2.0) == pytest.approx(0.025)
    assert exponential(0.25)(1.0) == pytest.approx(0.25)  # no tail: the plain decay


def test_occupancy_refreshes_on_its_cadence_and_after_growth(monkeypatch):
    model = fast_model(growth=(0.25, 0.4), occupancy_warmup=4, occupancy_every=3)
    optimizer, schedule = scheduled(model)
    refreshed = []
    monkeypatch.setattr(model, "refresh_occupancy", lambda: refreshed.append(step))
    for step in range(12):
        for hook in schedule:
            hook.before_step(StepInfo(model, optimizer, step, step / 12, 4096))
    # grows at steps 3 (before the warm-up: no refresh) and 5 (refresh), then every 3 steps
    assert refreshed == [5, 6, 9]


def test_a_time_budget_caps_the_final_grid_at_the_rays_its_steps_will_bring():
    model = fast_model(voxels=32**3, growth=(0.1, 0.2, 0.3), start_fraction=0.125,
                       rays_per_voxel=4.0, occupancy_warmup=10**9)
    optimizer, schedule = scheduled(model)
    # each step takes 1% of the budget, then 2% once the grid first grows, then 1% again
    caps, sizes = {}, [math.prod(model.grid_shape)]
    for step in range(85):
        hundredths = step if step <= 10 else 10 + 2 * (step - 10) if step <= 15 else step + 5
        fraction = hundredths / 100
        for hook in schedule:
            hook.before_step(StepInfo(model, optimizer, step, fraction, 512))
        caps.setdefault(model.voxels, step)
        sizes.append(math.prod(model.grid_shape))
    # at 10% (step 10): 100 steps expected, 512 rays each, 4 a voxel; at 20% (step 15): the
    # rate halved, 15 + 50 * 0.8 = 55 steps expected; at 30% (step 25) 25 + 100 * 0.7 = 95
    assert caps == {32**3: 0, 100 * 128: 10, 55 * 128: 15, 95 * 128: 25}
    assert model.grid_shape == model.lattice(1.0) == lattice_shape(torch.tensor([2.0] * 3), 95 * 128)
    assert sizes == sorted(sizes)  # a lowered cap never shrinks the grids


def test_a_step_budget_caps_the_final_grid_at_its_rays_and_the_cap_is_saved():
    model = fast_model(voxels=32**3, growth=(0.5,), start_fraction=0.125, rays_per_voxel=4.0)
    optimizer, schedule = scheduled(model)
    for step in range(60):
        for hook in schedule:
            hook.before_step(StepInfo(model, optimizer, step, step / 60, 1024))
    assert model.voxels == 60 * 256
    fresh = fast_model(voxels=32**3, growth=(0.5,), start_fraction=0.125)
    fresh.load_state_dict(model.state_dict())
    assert fresh.voxels == 60 * 256 and fresh.lattice(1.0) == model.grid_shape
    unlimited = {k: v for k, v in model.state_dict().items() if not k.endswith("_extra_state")}
    older = fast_model(voxels=32**3, growth=(0.5,), start_fraction=0.125)
    older.load_state_dict(unlimited)  # checkpoints from before the cap: the config's count
    assert older.voxels == 32**3


def test_a_checkpoint_from_before_the_grid_rename_loads():
    torch.manual_seed(0)
    model = fast_model()
    with torch.no_grad():
        model.density_grid.values.normal_()
    old = {k.replace("density_grid.", "density.").replace("feature_grid.", "features."): v
           for k, v in model.state_dict().items()}
    fresh = fast_model()
    fresh.load_state_dict(old)
    torch.testing.assert_close(fresh.density_grid.values, model.density_grid.values)


def test_a_loss_term_gets_rays_from_cameras_without_photos(tmp_path):
    eye = np.array([0.0, -3.0, 0.5])
    camera = Camera(fx=20.0, fy=20.0, cx=10.0, cy=10.0, width=20, height=20,
                    c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])))
    seen = []

    def probe(inp: LossInput) -> torch.Tensor:
        origins, directions = inp.virtual.sample(64)
        seen.append((origins, directions))
        out = inp.model.render_rays(origins, directions, torch.ones(64, 3))
        return 0.0 * out.rgb.mean()  # a seam, not a regulariser: training is unchanged

    fit(toy_scene(), "nerf", TINY, FitConfig(iters=3, batch_rays=32), tmp_path, "cpu",
        show_progress=False, extra_losses=[LossTerm("probe", 1.0, probe, virtual=True)],
        virtual_cameras=[camera])
    assert len(seen) == 3
    for origins, directions in seen:
        torch.testing.assert_close(origins, torch.tensor(eye, dtype=torch.float32).expand(64, 3))
        torch.testing.assert_close(directions.norm(dim=-1), torch.ones(64))
        # inside the camera's field of view (half-angle atan(0.5)) around its axis to the origin
        axis = F.normalize(-torch.tensor(eye, dtype=torch.float32), dim=0)
        assert float((directions @ axis).min()) > np.cos(np.arctan(0.5 * np.sqrt(2))) - 1e-5
