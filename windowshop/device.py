"""Pick the torch device once; only the CLI and the service call this."""

from __future__ import annotations

import torch


def pick_device(name: str | None = None) -> torch.device:
    """`name` ('cpu', 'cuda', 'cuda:1') wins; otherwise CUDA when present, else the CPU."""
    if name:
        return torch.device(name)
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")
