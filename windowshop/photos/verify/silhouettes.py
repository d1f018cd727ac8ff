"""Silhouettes against each other (silhouette coherence, Hernandez et al. 2007): each photo's
mask against the visual hull that the *other* photos' masks carve, seen from its camera.

With right poses the others' hull projects onto each photo's mask (up to the masks' own
errors); a misplaced photo sees that hull somewhere its mask is not, and its own mask carves the
others' away, so its agreement drops. Scored as intersection over union, the median over the
photos (a few poor masks, from GrabCut on a busy table, do not sink it).
"""

from __future__ import annotations

import numpy as np

from windowshop.photos.segment import hull_silhouette
from windowshop.photos.verify.types import Check, Hypothesis
from windowshop.scene.hull import cube_grid, projection
from windowshop.scene.types import Camera

GRID = 48  # voxels per side of the object's box
TOLERANCE = 0.15  # a voxel survives this share of the other views missing it (imperfect masks)
MIN_VIEWS = 4  # fewer masked photos: no hull to speak of
PASS_IOU = 0.6  # the photos' median agreement must reach this ...
SUSPECT_IOU = 0.4  # ... and a photo below this is blamed
ADVICE = ("the object's outline in some photos does not match what the others show, so their "
          "cameras are probably misplaced: retake them with the whole object in view and more "
          "overlap with their neighbours")


def coherence(masks: list[np.ndarray], cameras: list[Camera], aabb: np.ndarray) -> np.ndarray:
    """(N,) each mask's (H, W) bool intersection over union with the hull of the other masks,
    projected into its camera; cameras and the box `aabb` (2, 3) in one frame."""
    centre, half = aabb.mean(0), float(np.max(aabb[1] - aabb[0])) / 2
    points, voxel = cube_grid(centre, half, GRID), 2 * half / GRID
    # (in the photo's frame, on its mask) per voxel, at the masks' full size
    seen = [projection(points, c, m, max(m.shape)) for c, m in zip(cameras, masks)]
    frames = np.sum([s[0] for s in seen], axis=0)
    covered = np.sum([s[1] for s in seen], axis=0)
    scores = []
    for (inside, mine), camera, mask in zip(seen, cameras, masks):
        others = frames - inside
        missed = (others - (covered - mine))  # other views that see background there
        keep = (others >= 2) & (missed <= TOLERANCE * others)
        hull = hull_silhouette(points[keep], voxel, camera)
        union = np.count_nonzero(hull | mask)
        scores.append(np.count_nonzero(hull & mask) / union if union else 0.0)
    return np.array(scores)


def check(hypothesis: Hypothesis) -> Check | None:
    found = hypothesis.found
    if found is None or len(found.raw_masks) < MIN_VIEWS:
        return None
    photos = [p for p in found.photos if p.name in found.raw_masks]
    scores = coherence([found.raw_masks[p.name] for p in photos], [p.camera for p in photos],
                       found.aabb)
    worst = np.argsort(scores)[:3]
    detail = (f"median agreement of each photo's mask with the hull of the others: "
              f"{np.median(scores):.2f} (lowest: "
              + ", ".join(f"{photos[i].name} {scores[i]:.2f}" for i in worst) + ")")
    suspects = tuple(photos[i].image_name for i in np.flatnonzero(scores < SUSPECT_IOU))
    return Check("silhouettes", float(np.median(scores)), PASS_IOU, detail, ADVICE, suspects)
