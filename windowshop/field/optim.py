"""Adam that takes dense gradients (any parameter) and sparse row gradients (grids).

A sparse gradient (a coalesced COO tensor of rows, as `DenseGrid`'s fused backward returns) gets
the *lazy* update of `torch.optim.SparseAdam`: only those rows, and their moments, change. A
parameter whose shape changed since the last step (a grid that grew) starts its moments afresh.
"""

from __future__ import annotations

import math

import torch

from windowshop.field import kernels


def _adam_rows_reference(param: torch.Tensor, exp_avg: torch.Tensor, exp_avg_sq: torch.Tensor,
                         rows: torch.Tensor, grad: torch.Tensor, lr: float,
                         betas: tuple[float, float], eps: float, step: int) -> None:
    """The plain PyTorch twin of kernels.adam_rows."""
    beta1, beta2 = betas
    m = exp_avg.index_select(0, rows) * beta1 + (1.0 - beta1) * grad
    v = exp_avg_sq.index_select(0, rows) * beta2 + (1.0 - beta2) * grad * grad
    exp_avg.index_copy_(0, rows, m)
    exp_avg_sq.index_copy_(0, rows, v)
    denom = v.sqrt() / (1.0 - beta2 ** step) ** 0.5 + eps
    param.index_add_(0, rows, -(lr / (1.0 - beta1 ** step)) * m / denom)


def _unique_rows(grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rows (M,) and row gradients (M, C) of a sparse gradient, each row once.

    Autograd drops the coalesced flag, so check for strictly increasing rows (what the fused
    backward returns, O(M)) before paying for a sort.
    """
    rows, values = grad._indices()[0], grad._values()
    if not bool((rows[1:] > rows[:-1]).all()):
        grad = grad.coalesce()
        rows, values = grad.indices()[0], grad.values()
    # An explicit width: reshape(0, -1) is ambiguous when no row received a gradient.
    width = math.prod(values.shape[1:])
    return rows.contiguous(), values.reshape(rows.shape[0], width).contiguous()


class GridAdam(torch.optim.Optimizer):
    """Adam (Kingma & Ba) with per-group `lr`, `betas`, `eps`; lazy on sparse row gradients."""

    def __init__(self, params, lr: float = 1e-3, betas: tuple[float, float] = (0.9, 0.99),
                 eps: float = 1e-15):
        super().__init__(params, dict(lr=lr, betas=betas, eps=eps))

    def _state(self, p: torch.Tensor) -> dict:
        state = self.state[p]
        if not state or state["exp_avg"].shape != p.shape:
            state["step"] = 0
            state["exp_avg"] = torch.zeros_like(p, memory_format=torch.contiguous_format)
            state["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.contiguous_format)
        return state

    @torch.no_grad()
    def step(self, closure=None):
        for group in self.param_groups:
            lr, betas, eps = group["lr"], group["betas"], group["eps"]
            for p in group["params"]:
                if p.grad is None:
                    continue
                state = self._state(p)
                state["step"] += 1
                if p.grad.is_sparse:
                    self._sparse_step(p, state, lr, betas, eps)
                else:
                    self._dense_step(p, state, lr, betas, eps)

    @staticmethod
    def _sparse_step(p, state, lr, betas, eps) -> None:
        rows, values = _unique_rows(p.grad)
        args = (p.data.view(p.shape[0], -1), state["exp_avg"].view(p.shape[0], -1),
                state["exp_avg_sq"].view(p.shape[0], -1), rows, values, lr, betas,
                eps, state["step"])
        if kernels.available(p.device) and p.dtype == torch.float32 and p.is_contiguous():
            kernels.adam_rows(*args)
        else:
            _adam_rows_reference(*args)

    @staticmethod
    def _dense_step(p, state, lr, betas, eps) -> None:
        beta1, beta2 = betas
        step = state["step"]
        state["exp_avg"].lerp_(p.grad, 1.0 - beta1)
        state["exp_avg_sq"].mul_(beta2).addcmul_(p.grad, p.grad, value=1.0 - beta2)
        denom = (state["exp_avg_sq"].sqrt() / (1.0 - beta2 ** step) ** 0.5).add_(eps)
        p.addcdiv_(state["exp_avg"], denom, value=-lr / (1.0 - beta1 ** step))
