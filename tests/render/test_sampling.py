"""Stratified and hierarchical (inverse-CDF) sampling along rays."""

import torch

from windowshop.render.sampling import hierarchical, sample_pdf, stratified


def test_stratified_puts_one_sample_per_bin():
    near, far = torch.tensor([2.0, 1.0]), torch.tensor([6.0, 3.0])
    g = torch.Generator().manual_seed(0)
    t = stratified(near, far, 8, jitter=True, generator=g)
    width = (far - near)[:, None] / 8
    bins = torch.floor((t - near[:, None]) / width)
    assert torch.equal(bins, torch.arange(8.0).expand(2, 8))
    fixed = stratified(near, far, 8, jitter=False)
    assert torch.allclose(fixed, near[:, None] + width * (torch.arange(8) + 0.5))


def test_uniform_weights_give_evenly_spaced_quantiles():
    bins = torch.linspace(0, 1, 11)[None]
    t = sample_pdf(bins, torch.ones(1, 10), 4, jitter=False)
    assert torch.allclose(t, torch.tensor([[0.125, 0.375, 0.625, 0.875]]), atol=1e-5)


def test_samples_follow_the_weights():
    # two bins of weight 3 : 1 -> three quarters of the samples in the first bin
    bins = torch.tensor([[0.0, 1.0, 2.0]])
    g = torch.Generator().manual_seed(1)
    t = sample_pdf(bins.expand(4, 3), torch.tensor([[3.0, 1.0]]).expand(4, 2), 2000, True, g)
    share = (t < 1.0).float().mean().item()
    assert abs(share - 0.75) < 0.02
    assert torch.all(t[:, 1:] >= t[:, :-1])  # sorted


def test_fine_samples_go_where_the_coarse_weights_are():
    near, far = torch.full((5,), 2.0), torch.full((5,), 6.0)
    t = stratified(near, far, 64, jitter=False)
    peak = (t > 4.0) & (t < 4.3)  # a thin surface
    weights = torch.where(peak, 1.0, 0.001)
    g = torch.Generator().manual_seed(2)
    fine = hierarchical(t, weights, 128, jitter=True, generator=g)
    assert fine.shape == (5, 64 + 128)
    assert torch.all(fine[:, 1:] >= fine[:, :-1])
    new = fine.numel() - 5 * 64
    in_peak = ((fine > 3.95) & (fine < 4.35)).sum().item() - peak.sum().item()
    assert in_peak / new > 0.8  # the peak is 10% of the interval yet gets most fine samples


def test_fine_samples_carry_no_gradient():
    t = stratified(torch.zeros(2), torch.ones(2), 16, jitter=False)
    weights = torch.rand(2, 16, requires_grad=True)
    assert not hierarchical(t, weights, 8, jitter=False).requires_grad
