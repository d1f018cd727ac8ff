"""Up against the photos: the scene's up (the support plane's normal) against the up the photos
themselves show.

Phone photos are taken level, turned upright by their EXIF orientation: each camera's right axis
is then horizontal, so gravity is the direction most perpendicular to all of them, whatever each
photo's pitch (a photo turned a quarter, its EXIF lost, has its up axis horizontal instead: see
scene.cameras.photos_level). When those axes agree on one such direction (their rolls spread by
a few degrees) the photos know where up is; a support plane far from it is a slope, a wall or a
pedestal's side, and the object would lean in every frame. Photos at random rolls know nothing,
and the check does not apply; nor does it to photos turned by quarters (their EXIF lost), whose
level is weaker evidence than the plane. Where up already is the photos' own level, it passes as
it is: a hypothesis made to answer this check's failure (hypotheses.photos_up) then ranks beside
the one it answered by its other checks, and a refusal reports what it failed instead of the
lean it mended.

With neither a support plane nor a level the photos agree on, up is the cameras' mean up (or
their ring's normal): an up only if the photos stand upright about it, give or take a hand's
tilt. Photos turned sideways or upside down about it (their EXIF orientation lost, and a model
too wrong for their quarter turns to agree on a level) say nothing about which way is up, and
the object would be delivered lying on its side: the check fails. So it does for cameras that
do not go all round: each camera's up leans toward what it looks at by its pitch, and only a
ring cancels that lean.
"""

from __future__ import annotations

import numpy as np

from windowshop.photos.verify.types import Check, Hypothesis
from windowshop.scene.cameras import nearest_point_to_axes, photos_level, rolls, upright_level
from windowshop.video.coverage import FULL_TURN_SPAN, azimuths_about, covered_arc

AGREE_DEG = 12.0  # a scene up further than this from the photos' agreed level fails the check
ADVICE = ("the object would lean: the surface it stands on is not level in the photos; "
          "photograph it with the phone held upright, or on a level surface that shows around it")
# A photo rolled further than this about the cameras' up is held sideways or upside down: past
# the tilt of a hand-held "upright" photo (random rolls of +-40 degrees still give a mean up
# within a few degrees), short of a quarter turn less a hand's tilt. Measured: fruit's photos
# turned by random quarters (bench/cases.py --seed 1, fruit_rolled/8@2): 4 of 8 placed 45 deg
# wrong, up 81 deg off, from the cameras' mean; the photos rolled 48, 114, 168 and 48 deg about it
MAX_ROLL_DEG = 60.0
TURNED_ADVICE = ("the photos are turned different ways (sideways, upside down) and show no "
                 "surface or level to tell which way is up, so the object would lie on its "
                 "side: keep the photos' orientation when copying them off the phone, or "
                 "photograph the object standing on a surface that shows around it, with the "
                 "phone held upright")
ONE_SIDE_ADVICE = ("which way is up cannot be told: the photos show no surface around the "
                   "object, were not held level and see it from one side; photograph it "
                   "standing on a surface that shows around it, holding the phone level, or "
                   "walk all round it")


def angle(a: np.ndarray, b: np.ndarray) -> float:
    """Degrees between two directions (3,)."""
    cosine = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def _cameras_up(c2ws: np.ndarray) -> Check:
    up = np.array([0.0, 0.0, 1.0])  # the normalised frame's
    roll = np.abs(rolls(c2ws, up))
    turned = int(np.sum(roll > MAX_ROLL_DEG))
    why = "up is the cameras' mean (no surface under the object, no level the photos agree on)"
    if turned:
        detail = (f"{why}: {turned} of {len(c2ws)} photos are turned more than "
                  f"{MAX_ROLL_DEG:.0f} deg about it")
        return Check("upright", -float(turned), 0.0, detail, TURNED_ADVICE)
    # each camera's up leans toward what it looks at by its pitch, which only cameras all
    # round cancel: five frames of a can over 21 degrees were delivered leaning 24 degrees
    span = covered_arc(azimuths_about(c2ws[:, :3, 3], nearest_point_to_axes(c2ws), up,
                                      np.array([1.0, 0.0, 0.0])))[1]
    detail = (f"{why}, which leans by their pitch unless they go all round: they cover "
              f"{span:.0f} deg of the circle (all round is {FULL_TURN_SPAN:.0f})")
    return Check("upright", span - FULL_TURN_SPAN, 0.0, detail, ONE_SIDE_ADVICE)


def check(hypothesis: Hypothesis) -> Check | None:
    found = hypothesis.found
    if found is None or found.up_source not in ("plane", "photos", "cameras"):
        return None  # up comes from the phone's gravity
    c2ws = np.stack([p.camera.c2w for p in found.photos])
    if found.up_source == "cameras":
        return _cameras_up(c2ws)
    if found.up_source == "photos":
        return Check("upright", AGREE_DEG, 0.0, f"up is the photos' own level (their rolls "
                     f"spread {photos_level(c2ws)[1]:.1f} deg)", ADVICE)
    # only photos held upright outweigh the plane: quarter-turned ones can agree on a wrong up
    # as well as on the right one, told apart by the walk's steady height, which a one-sided
    # capture does not show (fruit_rolled/arc60x6@0: their right axes agreed on an up the
    # cameras looked 73-87 deg along, 54 deg from the true up, their quarter rule on one 27
    # deg off, the plane 7; the photos' up was delivered)
    theirs = upright_level(c2ws)
    if theirs is None:
        return None
    off = angle(theirs[0], np.array([0.0, 0.0, 1.0]))  # the normalised frame's up is the plane's
    detail = (f"the support plane's up is {off:.1f} deg from the photos' own "
              f"(their rolls spread {theirs[1]:.1f} deg)")
    # scored so that higher is better and the threshold is 0: AGREE_DEG minus the angle
    return Check("upright", AGREE_DEG - off, 0.0, detail, ADVICE)
