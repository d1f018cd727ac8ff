"""Alpha compositing against closed forms for a slab of constant density."""

import math

import pytest
import torch

from windowshop.render.composite import composite, compositing_weights, intervals


def slab(sigma_value, a, b, n=1024, near=0.0, far=4.0):
    """A ray through density `sigma_value` on [a, b], zero elsewhere, sampled at n bin starts
    (spacing 1/256: exact in binary, so the slab edges fall on samples)."""
    t = torch.linspace(near, far, n + 1, dtype=torch.float64)[:-1][None]
    sigma = sigma_value * ((t >= a) & (t < b)).to(torch.float64)
    return t, sigma, torch.tensor([far], dtype=torch.float64)


@pytest.mark.parametrize("sigma_value", [0.3, 2.0, 25.0])
def test_constant_slab_matches_closed_form(sigma_value):
    a, b = 1.0, 2.5
    t, sigma, far = slab(sigma_value, a, b)
    color = torch.tensor([0.2, 0.6, 0.9], dtype=torch.float64)
    bg = torch.tensor([[1.0, 0.0, 0.5]], dtype=torch.float64)
    out = composite(sigma, color.expand(1, t.shape[1], 3), t, far, bg)
    transmitted = math.exp(-sigma_value * (b - a))
    # piecewise-constant density on sample-aligned intervals: colour and opacity are exact
    assert out.opacity.item() == pytest.approx(1 - transmitted, rel=1e-9)
    assert out.rgb[0].tolist() == pytest.approx((color * (1 - transmitted) + bg[0] * transmitted).tolist(),
                                                rel=1e-9)
    # expected depth: integral of t sigma exp(-sigma (t - a)) over [a, b], up to the sample spacing
    s, length = sigma_value, b - a
    depth = a * (1 - transmitted) + (1 / s - (length + 1 / s) * transmitted)
    assert out.depth.item() == pytest.approx(depth, abs=4.0 / 1024)


def test_empty_ray_shows_background():
    t = torch.linspace(2, 6, 9)[None]
    bg = torch.tensor([[0.1, 0.2, 0.3]])
    out = composite(torch.zeros_like(t), torch.rand(1, 9, 3), t, torch.tensor([6.0]), bg)
    assert out.opacity.item() == 0.0
    assert torch.allclose(out.rgb, bg)
    assert out.depth.item() == 0.0


def test_intervals_end_at_far():
    t = torch.tensor([[1.0, 1.5, 3.0]])
    assert intervals(t, torch.tensor([4.0])).tolist() == [[0.5, 1.5, 1.0]]


def test_weights_sum_to_opacity_and_first_sample_is_unoccluded():
    sigma = torch.rand(4, 16) * 3
    deltas = torch.rand(4, 16) * 0.2
    w = compositing_weights(sigma, deltas)
    assert torch.allclose(w[:, 0], 1 - torch.exp(-sigma[:, 0] * deltas[:, 0]))
    assert torch.allclose(w.sum(-1), 1 - torch.exp(-(sigma * deltas).sum(-1)), atol=1e-6)


def test_composite_gradients_match_finite_differences():
    torch.manual_seed(0)
    t = torch.sort(torch.rand(3, 6, dtype=torch.float64) * 4 + 2, dim=-1).values
    far = torch.full((3,), 6.5, dtype=torch.float64)
    bg = torch.rand(3, 3, dtype=torch.float64)
    sigma = (torch.rand(3, 6, dtype=torch.float64) * 2).requires_grad_()
    rgb = torch.rand(3, 6, 3, dtype=torch.float64, requires_grad=True)

    def f(sigma, rgb):
        out = composite(sigma, rgb, t, far, bg)
        return out.rgb, out.depth, out.opacity

    assert torch.autograd.gradcheck(f, (sigma, rgb))
