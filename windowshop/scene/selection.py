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
                  views: int | None, test_views: int | None,
                  view_ids: tuple[int, ...] | None = None,
                  test_every: int | None = None) -> list[str | None]:
    """The split of every source frame after selection (None: dropped).

    `source_splits` are the source's own splits (all None if it has none); `centres` (N, 3) the
    camera centres and `target` (3,) the object centre, used to spread the `views` training views.
    `view_ids` names the training views to keep instead (indices among the training frames, in
    the source's order), `test_every` keeps every k-th held-out view instead of `test_views`.
    """
    if views is not None and view_ids is not None:
        raise UserError("give either --views (a count) or --view-ids (the views), not both")
    if test_views is not None and test_every is not None:
        raise UserError("give either --test-views (a count) or --test-every (a stride), not both")
    splits = _held_out(source_splits, test_views, test_every)
    train = [i for i, s in enumerate(splits) if s == "train"]
    if view_ids is not None:
        bad = sorted(set(i for i in view_ids if not 0 <= i < len(train)))
        if bad or not view_ids:
            raise UserError(f"--view-ids {','.join(map(str, bad))}: the source has {len(train)} "
                            f"training views, numbered 0 to {len(train) - 1}")
        keep = {train[i] for i in view_ids}
        return [None if s == "train" and i not in keep else s for i, s in enumerate(splits)]
    if views is not None:
        if views < 1 or views > len(train):
            raise UserError(f"asked for {views} training views but the source has {len(train)}; "
                            f"choose --views between 1 and {len(train)}")
        dirs = centres[train] - target
        dirs = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-12)
        keep = {train[i] for i in farthest_directions(dirs, views)}
        splits = [None if s == "train" and i not in keep else s for i, s in enumerate(splits)]
    return splits


def _held_out(source_splits: list[str | None], test_views: int | None,
              test_every: int | None) -> list[str]:
    """Every frame's split once the held-out views are chosen: the source's test frames (or,
    without splits, every 8th frame) thinned to `test_views` evenly spaced or every `test_every`-th."""
    n = len(source_splits)
    if test_every is not None and test_every < 1:
        raise UserError(f"--test-every must be at least 1, got {test_every}")
    if any(s is not None for s in source_splits):
        splits = [s or "train" for s in source_splits]
        tests = [i for i, s in enumerate(splits) if s == "test"]
        if test_views is not None:
            picks = evenly_spaced(len(tests), min(test_views, len(tests)))
        elif test_every is not None:
            picks = np.arange(0, len(tests), test_every)
        else:
            return splits
        keep = {tests[i] for i in picks}
        return [None if s == "test" and i not in keep else s for i, s in enumerate(splits)]
    held = (evenly_spaced(n, min(test_views, n - 1)) if test_views is not None
            else np.arange(0, n, test_every or LLFF_HOLDOUT) if n > 1 else np.array([], int))
    held = set(held.tolist())
    return ["test" if i in held else "train" for i in range(n)]
