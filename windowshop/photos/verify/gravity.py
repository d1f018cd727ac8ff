"""Poses against the phone's gravity: each photo's measured up (capture.json), carried into the
world by its pose, must point where the others' do.

A hand-held phone's accelerometer gives up to a degree or two; a pose that is right carries it
within a few degrees of the common up. A photo placed tilted or upside down (folded onto the
wrong side of an object whose sides look alike, or onto its top) carries it far off. A fold that
only turns a photo round the vertical keeps its gravity: the pairs and viewpoints checks see those.
"""

from __future__ import annotations

import numpy as np

from windowshop.photos import sensors
from windowshop.photos.output import posed_photos
from windowshop.photos.verify.types import Check, Hypothesis

AGREE_DEG = 10.0  # a photo further off the common up is blamed
# every photo within AGREE_DEG: the page keeps only steady photos, whose gravity is good to a
# degree or two, so one photo off is placed wrong (or was shaken) and is better left out
MIN_SHARE = 1.0
ADVICE = ("some photos are placed at angles the phone's own sensors deny: the object's sides may "
          "look alike; add photos that show a corner and two sides at once")


def check(hypothesis: Hypothesis) -> Check | None:
    if not hypothesis.gravity:
        return None
    posed = posed_photos(hypothesis.sfm.reconstruction, hypothesis.sfm.turned)
    c2ws = {p.image_name: p.camera.c2w for p in posed}
    measured = sensors.world_up(c2ws, hypothesis.gravity)
    if measured is None or len(measured[1]) < 3:
        return None
    angles = measured[1]
    off = tuple(sorted(n for n, a in angles.items() if a > AGREE_DEG))
    share = 1.0 - len(off) / len(angles)
    detail = (f"{len(off)} of {len(angles)} photos' gravity, carried by their poses, is more "
              f"than {AGREE_DEG:.0f} deg off the others' (median "
              f"{float(np.median(list(angles.values()))):.1f} deg)")
    return Check("gravity", share, MIN_SHARE, detail, ADVICE, suspects=off)
