"""Packed (ragged) compositing against the dense compositing of the NeRF renderer."""

import pytest
import torch

from windowshop.field import kernels
from windowshop.render import packed
from windowshop.render.composite import compositing_weights
from windowshop.render.packed import (packed_distortion, packed_weights, ray_starts, ray_sum,
                                      ray_weights)

needs_kernels = pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")


def test_packed_weights_equal_dense_weights_ray_by_ray():
    torch.manual_seed(0)
    counts = torch.tensor([5, 0, 1, 12, 3])
    ray = torch.repeat_interleave(torch.arange(5), counts)
    sigma = torch.rand(int(counts.sum())) * 20
    dt = torch.rand(int(counts.sum())) * 0.1
    weights = packed_weights(sigma, dt, ray, counts)
    for r, (start, n) in enumerate(zip(ray_starts(counts).tolist(), counts.tolist())):
        if n:
            dense = compositing_weights(sigma[start:start + n][None], dt[start:start + n][None])[0]
            torch.testing.assert_close(weights[start:start + n], dense)


def test_an_opaque_first_sample_takes_all_the_weight():
    counts = torch.tensor([3])
    weights = packed_weights(torch.tensor([1e4, 5.0, 5.0]), 0.1, torch.zeros(3, dtype=torch.long), counts)
    torch.testing.assert_close(weights, torch.tensor([1.0, 0.0, 0.0]))


def test_long_batches_keep_precision():
    # 200k samples of dense rays before the last one: a float32 global sum would lose it
    counts = torch.tensor([200_000, 2])
    ray = torch.repeat_interleave(torch.arange(2), counts)
    sigma = torch.full((200_002,), 50.0)
    sigma[-2:] = torch.tensor([1.0, 2.0])
    weights = packed_weights(sigma, 0.1, ray, counts)
    expected = compositing_weights(torch.tensor([[1.0, 2.0]]), torch.tensor([[0.1, 0.1]]))[0]
    torch.testing.assert_close(weights[-2:], expected)


def test_ray_sum_and_its_gradient():
    ray = torch.tensor([0, 0, 2, 2, 2])
    values = torch.arange(10.0).view(5, 2).requires_grad_()
    out = ray_sum(values, ray, 4)
    torch.testing.assert_close(out, torch.tensor([[2.0, 4.0], [0, 0], [18, 21], [0, 0]]))
    (out * torch.tensor([[1.0, 2.0], [0, 0], [3, 4], [0, 0]])).sum().backward()
    torch.testing.assert_close(values.grad, torch.tensor([[1.0, 2.0]] * 2 + [[3.0, 4.0]] * 3))
    torch.testing.assert_close(ray_sum(torch.ones(5), ray, 3), torch.tensor([2.0, 0.0, 3.0]))


def test_distortion_equals_the_quadratic_definition():
    torch.manual_seed(1)
    counts = torch.tensor([4, 0, 7])
    ray = torch.repeat_interleave(torch.arange(3), counts)
    t = torch.cat([torch.rand(4).sort().values, torch.rand(7).sort().values]) * 3
    weights = torch.rand(11) / 4
    out = packed_distortion(weights, t, 0.05, ray, counts)
    for r, (start, n) in enumerate(zip(ray_starts(counts).tolist(), counts.tolist())):
        w, s = weights[start:start + n], t[start:start + n]
        expected = (w[:, None] * w[None, :] * (s[:, None] - s[None, :]).abs()).sum() + (w * w).sum() * 0.05 / 3
        torch.testing.assert_close(out[r], expected)


def test_distortion_prefers_a_surface_to_fog():
    counts = torch.tensor([10, 10])
    ray = torch.repeat_interleave(torch.arange(2), counts)
    t = torch.linspace(2.0, 3.0, 10).repeat(2)
    surface = torch.zeros(10)
    surface[4] = 0.9
    weights = torch.cat([surface, torch.full((10,), 0.09)])
    loss = packed_distortion(weights, t, 0.1, ray, counts)
    assert loss[0] < 0.2 * loss[1]


def _ragged(seed: int, counts: list[int]):
    torch.manual_seed(seed)
    counts = torch.tensor(counts)
    ray = torch.repeat_interleave(torch.arange(len(counts)), counts)
    t = torch.rand(int(counts.sum())).sort().values * 4
    return counts, ray, t


def _ray_weights_and_grad(fn, sigma, t, ray, counts, upstream):
    sigma = sigma.clone().requires_grad_()
    outs = fn(sigma, 0.05, t, ray, counts)
    sum(torch.sum(o * u) for o, u in zip(outs, upstream)).backward()
    return (*outs, sigma.grad)


def _twin(sigma, dt, t, ray, counts):
    weights = packed_weights(sigma, dt, ray, counts)
    return weights, ray_sum(weights, ray, len(counts)), ray_sum(weights * t, ray, len(counts))


@needs_kernels
def test_fused_ray_weights_equal_the_pytorch_twin_and_its_gradient():
    # rays with no sample, one, many; densities from empty to opaque
    counts, ray, t = _ragged(2, [0, 1, 7, 0, 40, 3])
    sigma = torch.rand(len(t)) * 60
    upstream = (torch.randn(len(t)), torch.randn(len(counts)), torch.randn(len(counts)))
    fused = _ray_weights_and_grad(ray_weights, sigma, t, ray, counts, upstream)
    twin = _ray_weights_and_grad(_twin, sigma, t, ray, counts, upstream)
    for a, b in zip(fused, twin):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)
    assert fused[1][0] == 0 and fused[1][3] == 0  # rays with no samples are empty


@needs_kernels
def test_fused_ray_weights_gradient_matches_finite_differences():
    counts, ray, t = _ragged(3, [6, 2, 9])
    sigma = (torch.rand(len(t)) * 30).double()
    upstream = (torch.randn(len(t)), torch.randn(3), torch.randn(3))

    def loss(s):  # the fused kernels run in float32: differences of a float32 loss
        outs = ray_weights(s.float(), 0.05, t, ray, counts)
        return float(sum(torch.sum(o * u) for o, u in zip(outs, upstream)))

    grad = _ray_weights_and_grad(ray_weights, sigma.float(), t, ray, counts, upstream)[-1]
    h = 1e-2
    for i in range(len(t)):
        step = torch.zeros_like(sigma)
        step[i] = h
        numeric = (loss(sigma + step) - loss(sigma - step)) / (2 * h)
        assert abs(numeric - float(grad[i])) < 2e-3 * max(1.0, abs(numeric)), i


def test_ray_weights_without_kernels_is_the_twin(monkeypatch):
    monkeypatch.setattr(packed.kernels, "available", lambda device: False)
    counts, ray, t = _ragged(4, [3, 0, 5])
    sigma = torch.rand(len(t)) * 10
    for a, b in zip(ray_weights(sigma, 0.05, t, ray, counts), _twin(sigma, 0.05, t, ray, counts)):
        torch.testing.assert_close(a, b)


@needs_kernels
def test_fused_ray_weights_gradient_through_the_opacity_alone():
    counts, ray, t = _ragged(5, [4, 0, 6])
    sigma = torch.rand(len(t)) * 20
    grads = []
    for fn in (ray_weights, _twin):
        s = sigma.clone().requires_grad_()
        fn(s, 0.05, t, ray, counts)[1].sum().backward()  # weights and depth get no gradient
        grads.append(s.grad)
    torch.testing.assert_close(*grads)
