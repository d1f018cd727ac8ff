"""Poses against a photo's own pairs, weak ones too: a photo that no pair it has agrees with.

The pairs check reads only pairs of STRONG_INLIERS or more, as a weak pair's own rotation errs by
15-45 degrees. A photo held only by weak pairs escapes it. But a weak pair errs one way or
another, not every one of a photo's pairs the same way: a photo the model places where none of
its pairs puts it, each off by more than MAX_DEG, is misplaced. fruit's IMG_3690, given with
five photos taken 30 photos earlier in the walk: five pairs of 27-51 inliers, 31-74 degrees off
the model, which placed it 36 degrees off the other five. In bench_verify's seed-0 runs (492
photos of right models with MIN_PAIRS such pairs or more), a photo's nearest pair was at most
20.5 degrees off (fruit_rolled/arc100x8@0's IMG_3664; then beer_can/full's 0015, 16.6).

The photo is left out to be reshot (windowshop.photos.hypotheses, "without suspects"): mapped
again, the same matches place it no better (the global mapper put IMG_3690 22 degrees off, where
one of its weak pairs agreed to 1 degree).
"""

from __future__ import annotations

from windowshop.photos.verify.pairs import MISPLACED, disagreements, strong_pairs
from windowshop.photos.verify.types import Check, Hypothesis

MIN_INLIERS = 25  # pairs with at least this many verified inliers count
MIN_PAIRS = 3  # a photo with fewer says too little
MAX_DEG = 30.0  # none of a photo's pairs within this of the model: misplaced
# ... or, however few its pairs, every one turned by more than this, past what a weak pair's own
# error reaches (15-45 degrees): beer_can's 0000, 0005, ..., 0025 resampled six ways (stop 59)
# placed 0020 by the can's print repeated on its other side, 85-132 degrees from its one or two
# pairs; in bench_verify's seed 0 no photo of a delivered right model has all its pairs over 60
FAR_DEG = 70.0


def check(hypothesis: Hypothesis) -> Check | None:
    sfm = hypothesis.sfm
    if sfm.reconstruction is None or sfm.database is None:
        return None
    nearest: dict[str, list[float]] = {}
    for pair, degrees in disagreements(sfm.reconstruction,
                                       strong_pairs(sfm.reconstruction, sfm.database, MIN_INLIERS)):
        for name in (pair.first, pair.second):
            nearest.setdefault(name, []).append(degrees)
    far = {n for n, d in nearest.items() if min(d) > FAR_DEG}
    counted = {n: d for n, d in nearest.items() if len(d) >= MIN_PAIRS or n in far}
    if not counted:
        return None
    alone = tuple(sorted(n for n, d in counted.items() if min(d) > MAX_DEG))
    worst = max(counted, key=lambda n: min(counted[n]))
    detail = (f"{len(alone)} of {len(counted)} photos placed where none of their pairs "
              f"(>= {MIN_INLIERS} matches) puts them within {MAX_DEG:.0f} deg"
              + (f": {', '.join(alone)}" if alone else
                 f" (the farthest, {worst}, {min(counted[worst]):.0f} deg from its nearest)"))
    return Check("alone", -float(len(alone)), 0.0, detail, MISPLACED, suspects=alone,
                 passed=not alone)
