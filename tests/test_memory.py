"""Chunks sized by a memory budget: the helper, and the NeRF's footprint against a measured one."""

import pytest
import torch

from windowshop.config import NerfConfig
from windowshop.memory import per_chunk, spans


def test_chunks_fit_the_budget_and_cover_every_item():
    assert per_chunk(100.0, 1000) == 10
    assert per_chunk(5000.0, 1000) == 1  # one item over the budget still makes progress
    parts = list(spans(25, 100.0, 1000))
    assert [(s.start, s.stop) for s in parts] == [(0, 10), (10, 20), (20, 25)]
    with pytest.raises(ValueError):
        per_chunk(1.0, 0)


def _saved_bytes(field, points: int) -> int:
    """Bytes autograd keeps for a forward pass of `field` on `points` points (what a training
    chunk holds until its backward pass), each storage once (a ReLU's output is also the next
    layer's input)."""
    storages = {}

    def pack(tensor):
        storages[tensor.untyped_storage().data_ptr()] = tensor.untyped_storage().nbytes()
        return tensor

    x = torch.rand(points, 3)
    d = torch.nn.functional.normalize(torch.rand(points, 3), dim=-1)
    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        field(x, d)
    return sum(storages.values())


@pytest.mark.parametrize("view_dependent", [True, False])
def test_the_nerf_estimate_covers_what_autograd_keeps(view_dependent):
    from windowshop.field.nerf import NerfField

    field = NerfField(NerfConfig(freqs=6, view_dependent=view_dependent))  # the seed's 8 x 256
    saved = _saved_bytes(field, 1000) / 1000
    estimate = field.bytes_per_sample(training=True)
    assert saved <= estimate <= 3 * saved  # never under, and not wastefully over
