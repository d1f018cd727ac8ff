"""The NeRF field and model: architecture, view dependence, gradients, sampling passes."""

import dataclasses

import pytest
import torch

from windowshop.config import NERF_PRESETS, NerfConfig
from windowshop.field.nerf import NerfField, NerfModel
from windowshop.fit.losses import LossInput, loss_terms, total_loss
from windowshop.fit.schedule import StepInfo, schedule_for
from windowshop.model import Bounds, model_class, model_config

BOUNDS = Bounds(aabb=((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)), near=2.0, far=6.0)
SMALL = NerfConfig(freqs=3, freqs_dir=2, depth=3, width=16, skip=2, n_coarse=8, n_fine=8)


def rays(n, dtype=torch.float32):
    origins = torch.tensor([[0.0, 0.0, 4.0]], dtype=dtype).expand(n, 3)
    directions = torch.nn.functional.normalize(
        torch.tensor([[0.0, 0.0, -1.0]], dtype=dtype) + 0.1 * torch.randn(n, 3, dtype=dtype), dim=-1)
    return origins, directions


def count(module):
    return sum(p.numel() for p in module.parameters())


def test_paper_network_has_the_reference_parameter_count():
    # nerf-pytorch / bmild's network with L=10, L_dir=4, D=8, W=256, skip after layer 5: 595,844
    assert count(NerfField(NERF_PRESETS["paper"])) == 595_844
    assert count(NerfModel(NERF_PRESETS["paper"], BOUNDS)) == 2 * 595_844  # coarse + fine


def test_tiny_preset_is_one_position_only_network():
    model = NerfModel(NERF_PRESETS["tiny"], BOUNDS)
    assert model.fine is None and not model.config.view_dependent and model.config.freqs == 6
    assert model_class("nerf") is NerfModel
    assert model_config("nerf", "tiny", width=32).width == 32


def test_skip_connection_feeds_the_input_again():
    field = NerfField(SMALL)
    assert field.trunk[2].in_features == 16 + 3 * (1 + 2 * 3)
    assert field.trunk[1].in_features == 16


@pytest.mark.parametrize("view_dependent", [True, False])
def test_view_dependence_switch(view_dependent):
    torch.manual_seed(0)
    field = NerfField(dataclasses.replace(SMALL, view_dependent=view_dependent))
    x = torch.randn(10, 3)
    d1 = torch.nn.functional.normalize(torch.randn(10, 3), dim=-1)
    sigma1, rgb1 = field(x, d1)
    sigma2, rgb2 = field(x, -d1)
    assert torch.equal(sigma1, sigma2)  # density never depends on the direction
    assert torch.equal(rgb1, rgb2) != view_dependent
    assert sigma1.min() >= 0 and 0 <= rgb1.min() and rgb1.max() <= 1


@pytest.mark.parametrize("view_dependent", [True, False])
def test_field_gradients_match_finite_differences(view_dependent):
    torch.manual_seed(0)
    field = NerfField(dataclasses.replace(SMALL, view_dependent=view_dependent)).double()
    with torch.no_grad():  # keep densities away from ReLU's kink so finite differences are valid
        head = field.sigma_head if view_dependent else field.head
        head.bias.fill_(3.0)
    x = torch.randn(4, 3, dtype=torch.float64, requires_grad=True)
    d = torch.nn.functional.normalize(torch.randn(4, 3, dtype=torch.float64), dim=-1).requires_grad_()
    assert torch.autograd.gradcheck(field, (x, d))


def test_rendered_colour_gradients_match_finite_differences():
    torch.manual_seed(0)
    model = NerfModel(dataclasses.replace(SMALL, n_fine=0), BOUNDS).double().eval()
    with torch.no_grad():
        model.coarse.sigma_head.bias.fill_(0.5)
    origins, directions = rays(3, torch.float64)
    origins = origins.clone().requires_grad_()
    background = torch.rand(3, 3, dtype=torch.float64, requires_grad=True)

    def render(o, bg):
        out = model.render_rays(o, directions, bg)
        return out.rgb, out.depth, out.opacity

    assert torch.autograd.gradcheck(render, (origins, background))


def test_fine_pass_reports_both_colours_and_all_samples():
    torch.manual_seed(0)
    model = NerfModel(SMALL, BOUNDS)
    origins, directions = rays(5)
    out = model.render_rays(origins, directions, torch.ones(5, 3))
    assert out.rgb.shape == (5, 3) and out.depth.shape == (5,) and out.opacity.shape == (5,)
    assert out.aux["rgb_coarse"].shape == (5, 3)
    assert out.num_samples == 5 * (8 + 8 + 8)
    target = torch.zeros(5, 3)
    loss = total_loss(loss_terms(model.config), LossInput(model, out, target, torch.ones(5, 3)))
    loss.backward()
    assert model.coarse.trunk[0].weight.grad is not None  # coarse colour is supervised too
    assert model.fine.trunk[0].weight.grad is not None


def test_eval_mode_is_deterministic_and_training_jitters():
    torch.manual_seed(0)
    model = NerfModel(dataclasses.replace(SMALL, n_fine=0), BOUNDS)
    origins, directions = rays(4)
    bg = torch.ones(4, 3)
    model.eval()
    assert torch.equal(model.render_rays(origins, directions, bg).rgb,
                       model.render_rays(origins, directions, bg).rgb)
    model.train()
    assert not torch.equal(model.render_rays(origins, directions, bg).depth,
                           model.render_rays(origins, directions, bg).depth)


def test_near_far_default_to_the_bounds_and_can_be_overridden():
    assert (NerfModel(SMALL, BOUNDS).near, NerfModel(SMALL, BOUNDS).far) == (2.0, 6.0)
    model = NerfModel(dataclasses.replace(SMALL, near=1.0, far=3.0), BOUNDS)
    assert (model.near, model.far) == (1.0, 3.0)


def test_learning_rate_decays_exponentially_to_the_final_rate():
    model = NerfModel(SMALL, BOUNDS)
    optimizer = model.make_optimizer()
    assert optimizer.param_groups[0]["lr"] == 5e-4
    optimizer.param_groups[0]["initial_lr"] = 5e-4
    (schedule,) = schedule_for(model)
    for fraction, factor in ((0.0, 1.0), (1.0, 0.1), (0.5, 0.1 ** 0.5), (2.0, 0.1)):
        schedule.before_step(StepInfo(model, optimizer, 0, fraction, 1024))
        assert optimizer.param_groups[0]["lr"] == pytest.approx(5e-4 * factor)


def test_rendering_without_gradients_slices_the_points_and_agrees():
    torch.manual_seed(0)
    model = NerfModel(dataclasses.replace(SMALL, n_coarse=70), BOUNDS).eval()
    origins, directions = rays(1000)  # 70,000 coarse + 86,000 fine points: more than one slice
    bg = torch.ones(1000, 3)
    with torch.no_grad():
        sliced = model.render_rays(origins, directions, bg)
    whole = model.render_rays(origins, directions, bg)
    assert torch.allclose(sliced.rgb, whole.rgb, atol=1e-6)
    assert torch.allclose(sliced.depth, whole.depth, atol=1e-5)


@pytest.mark.parametrize("activation", ["relu", "softplus"])
def test_softplus_density_keeps_a_gradient_where_relu_is_dead(activation):
    torch.manual_seed(0)
    field = NerfField(dataclasses.replace(SMALL, density_activation=activation))
    with torch.no_grad():
        field.sigma_head.bias.fill_(-30.0)  # every raw density far below zero
    sigma, _ = field(torch.randn(8, 3), torch.nn.functional.normalize(torch.randn(8, 3), dim=-1))
    sigma.sum().backward()
    alive = field.sigma_head.bias.grad.abs().item() > 0
    assert alive == (activation == "softplus")
    assert sigma.min() >= 0


def test_unknown_density_activation_is_rejected():
    with pytest.raises(ValueError, match="density_activation"):
        NerfField(dataclasses.replace(SMALL, density_activation="exp"))
