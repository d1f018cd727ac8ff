"""Each photo's distance against the object's size in it: a camera the model places far from
where the others stand would see the object small, while its own outline shows it as large as
the other photos do.

The object's box, of radius r, seen from a camera d away with focal f, spans about 2 f r / d
pixels; its outline in the photo spans what it spans. Their ratio varies from photo to photo by
the box's shape and the outline's slack, a factor of two at most on the shared captures, and by
the same factor for every photo when the box is too large or small. A photo whose ratio lies
FAR times or more from the median one is placed at a distance its own outline denies: 12
rolled beer_can frames had one of them 140 units off where the others stood 2-5 from the can.
"""

from __future__ import annotations

import numpy as np

from windowshop.photos.verify.types import Check, Hypothesis

FAR = 4.0  # a photo whose outline-to-box ratio is more than this many times off the median's is blamed
MIN_VIEWS = 4
ADVICE = ("a photo is placed far from where it was taken: keep the whole object in every photo, "
          "at about the same distance, and walk round it in small steps")


def ratios(hypothesis: Hypothesis) -> dict[str, float]:
    """Each masked photo's outline span over the span its box would have from its camera (both
    as shares of the image's diagonal), by image name."""
    found = hypothesis.found
    centre = found.aabb.mean(0)
    radius = np.linalg.norm(found.aabb[1] - found.aabb[0]) / 2
    out = {}
    for photo in found.photos:
        mask = found.raw_masks.get(photo.name)
        if mask is None or not mask.any():
            continue
        rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
        outline = np.hypot(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1) / np.hypot(*mask.shape)
        camera = photo.camera
        distance = max(np.linalg.norm(camera.center - centre), radius)
        box = 2 * camera.fx * radius / distance / np.hypot(camera.width, camera.height)
        out[photo.image_name] = float(outline / box)
    return out


def check(hypothesis: Hypothesis) -> Check | None:
    found = hypothesis.found
    if found is None or len(found.raw_masks) < MIN_VIEWS:
        return None
    found_ratios = ratios(hypothesis)
    if len(found_ratios) < MIN_VIEWS:
        return None
    median = float(np.median(list(found_ratios.values())))
    off = {n: max(r / median, median / r) for n, r in found_ratios.items()}
    blamed = tuple(sorted(n for n, f in off.items() if f > FAR))
    worst = max(off, key=off.get)
    detail = (f"{len(blamed)} of {len(off)} photos placed at a distance their outline denies "
              f"(the worst, {worst}, {off[worst]:.1f} times off the others' object size; "
              f"over {FAR:.0f} fails)")
    # scored so that higher is better: how far the worst photo stays within FAR
    return Check("scale", FAR / off[worst], 1.0, detail, ADVICE, suspects=blamed)
