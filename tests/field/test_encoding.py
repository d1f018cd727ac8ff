"""Positional encoding against the paper's formula, element by element."""

import math

import pytest
import torch

from windowshop.field.encoding import PositionalEncoding, encoded_size, positional_encoding


@pytest.mark.parametrize("use_pi", [False, True])
def test_encoding_matches_formula(use_pi):
    x = torch.tensor([[0.3, -1.2, 2.5], [0.0, 0.7, -0.05]], dtype=torch.float64)
    freqs = 4
    scale = math.pi if use_pi else 1.0
    out = positional_encoding(x, freqs, use_pi)
    assert out.shape == (2, 3 * (1 + 2 * freqs))
    for r in range(2):
        expected = list(x[r].tolist())  # identity first
        for k in range(freqs):
            expected += [math.sin(2 ** k * scale * p) for p in x[r].tolist()]
            expected += [math.cos(2 ** k * scale * p) for p in x[r].tolist()]
        assert out[r].tolist() == pytest.approx(expected, abs=1e-12)


def test_zero_frequencies_is_identity():
    x = torch.randn(5, 3)
    assert torch.equal(positional_encoding(x, 0), x)


def test_module_width_and_batch_dims():
    enc = PositionalEncoding(3, 10)
    assert enc.out_dims == encoded_size(3, 10) == 63  # the paper's 60 plus the identity
    assert enc(torch.zeros(2, 7, 3)).shape == (2, 7, 63)
    assert PositionalEncoding(3, 4).out_dims == 27  # the paper's 24 for directions, plus 3
