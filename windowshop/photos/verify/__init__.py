"""The verifier: scores a posed, masked scene (a hypothesis) before any training, with no learned
weights, so that a wrong reconstruction is retried or refused instead of trained and delivered.

Each check is one function `check(hypothesis) -> Check | None` (None: it does not apply, e.g.
no masks to compare) in a module of its own:

    pairs        the model's relative rotations against each strongly matched pair's own (the
                 two-view geometry its matches give): a folded or misplaced photo contradicts
                 the pairs that tie it to its true neighbours (Heinly et al. 2014)
    alone        a photo that none of its pairs, weak ones too, places where the model does:
                 left out to be reshot
    silhouettes  each mask against the visual hull the *other* views carve (silhouette
                 coherence, Hernandez et al. 2007): a wrong pose carves the object away
    upright      the support plane's normal against the photos' own up (photos are taken
                 level, so their right axes are horizontal); without either, the photos
                 upright about the cameras' mean up
    gravity      each photo's gravity from the phone (capture.json), carried into the world by
                 its pose, against the other photos'
    viewpoints   distinct photos, far apart in shooting order, stacked on one viewpoint (a few
                 photos of an object whose sides look alike, folded)
    background   pairs placed side by side whose matches all lie on the object, none on a
                 background that other pairs do match (a fold of an object printed alike)
    scale        each photo's distance from the object against the object's size in its
                 outline: a photo placed far off would see it small
    support      the sparse points each photo sees: one placed on a handful of matches is
                 blamed and left out

`verify` runs them all; windowshop.photos.hypotheses decides what to try next.
"""

from __future__ import annotations

from windowshop.photos.verify import (alone, background, gravity, pairs, scale, silhouettes,
                                      support, upright, viewpoints)
from windowshop.photos.verify.types import Check, Hypothesis, Verdict

__all__ = ["Check", "Hypothesis", "Verdict", "verify"]


def verify(hypothesis: Hypothesis) -> Verdict:
    """Every check that applies to `hypothesis`."""
    checks = (check(hypothesis) for check in (pairs.check, alone.check, silhouettes.check,
                                               upright.check, gravity.check, viewpoints.check,
                                               scale.check, background.check, support.check))
    return Verdict([c for c in checks if c is not None])
