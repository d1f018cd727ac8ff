"""Which views go to which split: deterministic, spread evenly, test views never trained on."""

from __future__ import annotations

import numpy as np

from windowshop.errors import UserError

LLFF_HOLDOUT = 8  # with no split in the source, every 8th view is held out (the LLFF convention)


def evenly_spaced(n: int, k: int) -> np.ndarray:
    """k indices spread evenly over range(n), first and last included."""
    return np.unique(np.round(np.linspace(0, n - 1, k)).astype(int)) if k > 0 else np.array([], int)


def farthest_directions(directions: np.ndarray, k: int) -> np.ndarray:
    """Indices of k unit `directions` (N, 3) spread as evenly as possible, sorted.

    Greedy farthest-point sampling on the sphere seeded from index 0, so it is deterministic.
    """
    chosen = [0]
    closest = directions @ directions[0]  # cosine to the nearest chosen direction
    for _ in range(k - 1):
        nxt = int(np.argmin(closest))
        chosen.append(nxt)
        closest = np.maximum(closest, directions @ directions[nxt])
    return np.sort(np.array(chosen))


def assign_splits(source_splits: list[str | None], centres: np.ndarray, target: np.ndarray,
                  views: int | None, test_views: int | None) -> list[str | None]:
    """The split of every source frame after selection (None: dropped).

    `source_splits` are the source's own splits (all None if it has none); `centres` (N, 3) the
    camera centres and `target` (3,) the object centre, used to spread the `views` training views.
    """
    n = len(source_splits)
    has_splits = any(s is not None for s in source_splits)
    if has_splits:
        splits = [s or "train" for s in source_splits]
        tests = [i for i, s in enumerate(splits) if s == "test"]
        if test_views is not None:
            keep = {tests[i] for i in evenly_spaced(len(tests), min(test_views, len(tests)))}
            splits = [None if s == "test" and i not in keep else s for i, s in enumerate(splits)]
    else:
        held = (evenly_spaced(n, min(test_views, n - 1)) if test_views is not None
                else np.arange(0, n, LLFF_HOLDOUT) if n > 1 else np.array([], int))
        splits = ["test" if i in set(held.tolist()) else "train" for i in range(n)]
    train = [i for i, s in enumerate(splits) if s == "train"]
    if views is not None:
        if views < 1 or views > len(train):
            raise UserError(f"asked for {views} training views but the source has {len(train)}; "
                            f"choose --views between 1 and {len(train)}")
        dirs = centres[train] - target
        dirs = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-12)
        keep = {train[i] for i in farthest_directions(dirs, views)}
        splits = [None if s == "train" and i not in keep else s for i, s in enumerate(splits)]
    return splits
