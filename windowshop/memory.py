"""Working memory by budget, not by count: every chunked loop over rays or points asks here how
many items one chunk may hold, given the bytes one item takes (a model's own estimate) and a budget
in bytes (`memory_budget` of FitConfig and VideoOptions, default `MEMORY_BUDGET`)."""

from __future__ import annotations

from collections.abc import Iterator

from windowshop.config import MEMORY_BUDGET

__all__ = ["MEMORY_BUDGET", "per_chunk", "spans"]


def per_chunk(bytes_each: float, budget: int = MEMORY_BUDGET) -> int:
    """How many items of `bytes_each` bytes fit in `budget` bytes (at least one)."""
    if budget <= 0:
        raise ValueError(f"memory budget must be positive, got {budget}")
    return max(1, int(budget // max(bytes_each, 1.0)))


def spans(total: int, bytes_each: float, budget: int = MEMORY_BUDGET) -> Iterator[slice]:
    """Consecutive slices covering range(total), each within `budget` bytes (of equal size but
    the last)."""
    step = per_chunk(bytes_each, budget)
    for start in range(0, total, step):
        yield slice(start, min(start + step, total))
