"""Distinct photos placed at one viewpoint: two photos that the model puts within a few degrees
of each other, seen from the object, yet a quarter of the walk or more apart in shooting order,
with the walk between them not going all the way round.

A seller takes photo after photo walking round; two shots from one spot are a burst or a step
back (a few photos apart: fruit's 81 hold five such pairs, 2-10 photos apart), a duplicate
(dropped when read), or a second turn (the walk between them, in the model, goes a full circle:
beer_can's video walks 1.5 turns). Photos from opposite sides
of an object whose sides look alike are the other case: structure from motion takes each for
the other and stacks them on one spot, and the walk in between turns back (the doppelganger
fold of a few wide photos, which no pair contradicts since every pair agrees with the fold).
"""

from __future__ import annotations

import numpy as np

from windowshop.photos.verify.types import Check, Hypothesis
from windowshop.photos.verify.pairs import ALIKE

SAME_DEG = 4.0  # two cameras' directions from the object this close: one viewpoint
ROUND_DEG = 270.0  # the walk between two photos turns this far about the object: a new turn
APART_SHARE = 0.25  # photos this share of the walk or more apart in shooting order are far apart
# Pairs of photos so stacked that fail it.
# Measured (bench/RESULTS.md, "Right or refused"): the doppelganger box's 8-photo subsets stack
# 3-4 such pairs (0.1-3.3 degrees apart); the shared captures' subsets none (the nearest: two of
# beer_can's photos 5.6 degrees apart); temple's ring holds one true repeat (0001 and 0011)
MAX_STACKED = 1
# ... in a ring of 16. A repeat is a dense walk's: in fewer photos than this none is allowed.
# The global mapper folded the doppelganger box's 8@0 (stop 49): 7 photos, 4 of them 128 deg
# off, stacking one pair (box_004 and box_024, 0.6 deg) and passing every other check
REPEAT_PHOTOS = 12


def walked(names: list[str], centres: np.ndarray) -> np.ndarray:
    """(N,) degrees the walk has turned about the object (+z at the origin) at each photo, in
    shooting order (sorted `names`), unwrapped: each step between neighbours the shorter way."""
    order = np.argsort(names)
    azimuth = np.degrees(np.arctan2(centres[order, 1], centres[order, 0]))
    steps = (np.diff(azimuth) + 180.0) % 360.0 - 180.0
    turned = np.empty(len(names))
    turned[order] = np.concatenate([[0.0], np.cumsum(steps)])
    return turned


def stacked(names: list[str], centres: np.ndarray, degrees: float = SAME_DEG
            ) -> list[tuple[str, str, float]]:
    """(name, name, degrees) for each pair of photos whose camera `centres` (N, 3), seen from
    the object at the origin, are within `degrees`, that lie APART_SHARE of the walk or more
    apart in shooting order (sorted `names`), and between which the walk does not go round
    (ROUND_DEG). A fold stacks photos half a walk apart."""
    directions = centres / np.linalg.norm(centres, axis=1, keepdims=True)
    angles = np.degrees(np.arccos(np.clip(directions @ directions.T, -1.0, 1.0)))
    order = {name: k for k, name in enumerate(sorted(names))}
    turned = walked(names, centres)
    return [(names[i], names[j], float(angles[i, j]))
            for i in range(len(names)) for j in range(i + 1, len(names))
            if angles[i, j] < degrees
            and abs(order[names[i]] - order[names[j]]) >= max(2, APART_SHARE * len(names))
            and abs(turned[i] - turned[j]) < ROUND_DEG]


def check(hypothesis: Hypothesis) -> Check | None:
    found = hypothesis.found
    if found is None or len(found.photos) < 3:
        return None
    names = [p.image_name for p in found.photos]
    pairs = stacked(names, np.stack([p.camera.center for p in found.photos]))
    detail = (f"{len(pairs)} pairs of photos far apart in shooting order placed at one "
              f"viewpoint"
              + (": " + ", ".join(f"{a}-{b} {d:.1f} deg" for a, b, d in pairs[:5]) if pairs
                 else ""))
    blamed = tuple(sorted({n for a, b, _ in pairs for n in (a, b)}))
    allowed = MAX_STACKED if len(names) >= REPEAT_PHOTOS else 0
    return Check("viewpoints", -float(len(pairs)), -float(allowed), detail, ALIKE, blamed)
