"""GridAdam: dense steps equal torch's Adam; lazy sparse steps touch only their rows; the kernel
equals the PyTorch twin."""

import pytest
import torch

from windowshop.field import kernels
from windowshop.field.optim import GridAdam, _adam_rows_reference


def test_dense_steps_equal_torch_adam():
    torch.manual_seed(0)
    a = torch.nn.Parameter(torch.randn(6, 4))
    b = torch.nn.Parameter(a.detach().clone())
    ours, theirs = GridAdam([a], lr=0.05, eps=1e-8), torch.optim.Adam([b], lr=0.05, betas=(0.9, 0.99))
    for _ in range(5):
        target = torch.randn(6, 4)
        for p, opt in ((a, ours), (b, theirs)):
            opt.zero_grad()
            ((p - target) ** 2).sum().backward()
            opt.step()
    torch.testing.assert_close(a, b)


def test_sparse_steps_update_only_their_rows_as_dense_adam_would():
    torch.manual_seed(1)
    start = torch.randn(10, 3)
    sparse_p = torch.nn.Parameter(start.clone())
    dense_p = torch.nn.Parameter(start.clone())
    rows = torch.tensor([1, 4, 7])
    grad = torch.randn(3, 3)
    opt_s, opt_d = GridAdam([sparse_p], lr=0.1), GridAdam([dense_p], lr=0.1)
    sparse_p.grad = torch.sparse_coo_tensor(rows[None], grad, (10, 3), check_invariants=True)
    dense_p.grad = torch.zeros(10, 3).index_copy(0, rows, grad)
    opt_s.step()
    opt_d.step()
    torch.testing.assert_close(sparse_p[rows], dense_p[rows])
    untouched = torch.tensor([0, 2, 3, 5, 6, 8, 9])
    assert torch.equal(sparse_p[untouched], start[untouched])


def test_state_restarts_when_a_parameter_grows():
    p = torch.nn.Parameter(torch.zeros(4, 2))
    opt = GridAdam([p], lr=0.1)
    p.grad = torch.ones(4, 2)
    opt.step()
    p.data = torch.zeros(9, 2)
    p.grad = torch.ones(9, 2)
    opt.step()
    assert opt.state[p]["exp_avg"].shape == (9, 2) and opt.state[p]["step"] == 1
    torch.testing.assert_close(p.detach(), torch.full((9, 2), -0.1))


@pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")
def test_adam_rows_kernel_equals_reference():
    torch.manual_seed(2)
    tensors = [torch.randn(50, 5), torch.randn(50, 5), torch.rand(50, 5)]
    copies = [t.clone() for t in tensors]
    rows = torch.tensor([0, 3, 17, 49])
    grad = torch.randn(4, 5)
    kernels.adam_rows(*tensors, rows, grad, 0.01, (0.9, 0.99), 1e-15, 7)
    _adam_rows_reference(*copies, rows, grad, 0.01, (0.9, 0.99), 1e-15, 7)
    for ours, ref in zip(tensors, copies):
        torch.testing.assert_close(ours, ref)


def test_a_sparse_gradient_without_rows_changes_nothing():
    p = torch.nn.Parameter(torch.ones(5, 3))
    opt = GridAdam([p], lr=0.1)
    p.grad = torch.sparse_coo_tensor(torch.zeros(1, 0, dtype=torch.long), torch.zeros(0, 3), (5, 3),
                                     check_invariants=True)
    opt.step()
    assert torch.equal(p.detach(), torch.ones(5, 3))
