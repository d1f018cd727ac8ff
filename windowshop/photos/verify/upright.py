"""Up against the photos: the scene's up (the support plane's normal) against the up the photos
themselves show.

Phone photos are taken level, turned upright by their EXIF orientation: each camera's right axis
is then horizontal, so gravity is the direction most perpendicular to all of them, whatever each
photo's pitch (a photo turned a quarter, its EXIF lost, has its up axis horizontal instead: see
scene.cameras.photos_level). When those axes agree on one such direction (their rolls spread by
a few degrees) the photos know where up is; a support plane far from it is a slope, a wall or a
pedestal's side, and the object would lean in every frame. Photos at random rolls know nothing,
and the check does not apply. Where up already is the photos' own level, it passes as it is:
a hypothesis made to answer this check's failure (hypotheses.photos_up) then ranks beside the
one it answered by its other checks, and a refusal reports what it failed instead of the lean
it mended.
"""

from __future__ import annotations

import numpy as np

from windowshop.photos.verify.types import Check, Hypothesis
from windowshop.scene.cameras import agreed_level, photos_level

AGREE_DEG = 12.0  # a scene up further than this from the photos' agreed level fails the check
ADVICE = ("the object would lean: the surface it stands on is not level in the photos; "
          "photograph it with the phone held upright, or on a level surface that shows around it")


def angle(a: np.ndarray, b: np.ndarray) -> float:
    """Degrees between two directions (3,)."""
    cosine = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def check(hypothesis: Hypothesis) -> Check | None:
    found = hypothesis.found
    if found is None or found.up_source not in ("plane", "photos"):
        return None  # up comes from the phone's gravity or the cameras
    c2ws = np.stack([p.camera.c2w for p in found.photos])
    if found.up_source == "photos":
        return Check("upright", AGREE_DEG, 0.0, f"up is the photos' own level (their rolls "
                     f"spread {photos_level(c2ws)[1]:.1f} deg)", ADVICE)
    theirs = agreed_level(c2ws)
    if theirs is None:
        return None
    off = angle(theirs, np.array([0.0, 0.0, 1.0]))  # the normalised frame's up is the plane's
    detail = (f"the support plane's up is {off:.1f} deg from the photos' own "
              f"(their rolls spread {photos_level(c2ws)[1]:.1f} deg)")
    # scored so that higher is better and the threshold is 0: AGREE_DEG minus the angle
    return Check("upright", AGREE_DEG - off, 0.0, detail, ADVICE)
