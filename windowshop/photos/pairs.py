"""Which photo pairs to match: every pair grows with the square of the count, so the pairs are
chosen by count and capture.

- "exhaustive": every pair; only for small sets (at most EXHAUSTIVE_MAX photos).
- "sequential": each photo with its next SEQUENTIAL_OVERLAP photos; for video frames and for
  photos whose file names follow the walk around the object (each photo's next is among the few
  that look most alike).
- "retrieval": each photo with the RETRIEVAL_K photos that look most alike, by a tiny-image
  descriptor (a blurred 16x16 grey thumbnail, zero mean and unit norm; Torralba et al. 2008),
  and with its next SEQUENTIAL_OVERLAP in file order: large sets whose thumbnails do not follow
  a walk (unordered, or turned every which way), with no vocabulary tree to download.
- "heading": photos shot on the page with the phone's heading (capture.json): each with its next
  in shooting order and with every photo taken within HEADING_PAIR_DEG of its heading. Photos
  from opposite sides are never matched, so sides that look alike cannot fold the walk.
"""

from __future__ import annotations

from itertools import combinations
from pathlib import Path

import numpy as np
from PIL import Image, ImageFilter

EXHAUSTIVE_MAX = 40  # photos; 780 pairs, about a minute of matching on 2 cores at 640 px
# Video frames are matched with this many next frames only: frames far apart on a walk around a
# symmetric object (a can on a tiled floor) match "through" the symmetry and fold the path over.
SEQUENTIAL_OVERLAP = 5
RETRIEVAL_K = 8  # most alike photos matched with each photo of a large unordered set
WALK_SHARE = 0.7  # photos whose next is among their SEQUENTIAL_OVERLAP most alike: a walk
THUMB = 16  # side of the tiny image, pixels
# Photos this far apart in heading may still share surface (a side seen obliquely, the top);
# further apart they face opposite sides, whose alike prints fold a walk (the doppelganger
# box's contradicted pairs are all at 159-180 deg), and a compass drifting 10-20 degrees over
# a walk moves no pair across it by much
HEADING_PAIR_DEG = 100.0
# ... but only for photos this close in heading (the median step round the circle; the page
# shoots every 12 deg): a sparse ring needs every pair it has. fruit's and temple's 8-photo rings
# (45 deg steps) placed 2-3 of 8 with pairs within 60 deg, and temple/8@0 lost the points that
# told its object (11 of 20 needed) within 100 deg (bench_verify --sensors)
DENSE_STEP_DEG = 30.0
MATCHERS = ("exhaustive", "sequential", "retrieval")


def tiny_descriptors(paths: list[Path]) -> np.ndarray:
    """(N, THUMB * THUMB) float32: each image blurred, shrunk to THUMB x THUMB grey, with zero
    mean and unit norm, so a dot product is a correlation (1: alike)."""
    rows = []
    for path in paths:
        with Image.open(path) as image:
            image.draft("L", (THUMB * 4, THUMB * 4))  # a JPEG decodes at 1/2-1/8 size: fast
            small = image.convert("L").filter(ImageFilter.BoxBlur(1))
            pixels = np.asarray(small.resize((THUMB, THUMB), Image.Resampling.BOX), np.float32)
        flat = pixels.ravel() - pixels.mean()
        rows.append(flat / max(float(np.linalg.norm(flat)), 1e-6))
    return np.stack(rows)


def _most_alike(descriptors: np.ndarray, k: int) -> np.ndarray:
    """(N, k) indices of each row's k most similar other rows, most similar first."""
    similarity = descriptors @ descriptors.T
    np.fill_diagonal(similarity, -np.inf)
    return np.argsort(-similarity, axis=1)[:, :k]


def is_walk(descriptors: np.ndarray) -> bool:
    """True when the images, in the order given, follow a walk: for most of them, the next
    image is among the SEQUENTIAL_OVERLAP that look most alike."""
    count = len(descriptors)
    if count < 3:
        return True
    alike = _most_alike(descriptors, min(SEQUENTIAL_OVERLAP, count - 1))
    follows = [i + 1 in alike[i] for i in range(count - 1)]
    return float(np.mean(follows)) >= WALK_SHARE


def choose(count: int, descriptors: np.ndarray | None) -> str:
    """The matcher for `count` photos (file-name order) with their tiny `descriptors`."""
    if count <= EXHAUSTIVE_MAX:
        return "exhaustive"
    return "sequential" if descriptors is None or is_walk(descriptors) else "retrieval"


def image_pairs(count: int, matcher: str, descriptors: np.ndarray | None = None
                ) -> list[tuple[int, int]]:
    """Index pairs (i < j) to match among `count` images in order; "retrieval" needs the
    images' `descriptors` (N, D)."""
    if matcher == "exhaustive":
        return list(combinations(range(count), 2))
    if matcher == "sequential":
        return [(i, j) for i in range(count)
                for j in range(i + 1, min(i + 1 + SEQUENTIAL_OVERLAP, count))]
    if matcher == "retrieval":
        alike = _most_alike(descriptors, min(RETRIEVAL_K, count - 1))
        chosen = {(min(i, int(j)), max(i, int(j))) for i in range(count) for j in alike[i]}
        # and each photo's next in file order, which is the shooting order of most uploads:
        # photos turned by quarters (EXIF orientation lost) look alike to no thumbnail
        # (fruit's 81 so turned: 29 placed by retrieval alone, all 80 right with these)
        return sorted(chosen | set(image_pairs(count, "sequential")))
    raise ValueError(f"unknown matcher {matcher!r}")


def dense(headings: list[float | None]) -> bool:
    """Whether the photos' known `headings` step round the circle by at most DENSE_STEP_DEG
    (median), so that matching only neighbours in heading loses little."""
    known = np.sort([h % 360.0 for h in headings if h is not None])
    if len(known) < 3:
        return False
    steps = np.diff(np.append(known, known[0] + 360.0))
    return float(np.median(steps)) <= DENSE_STEP_DEG


def heading_pairs(headings: list[float | None]) -> list[tuple[int, int]]:
    """Index pairs (i < j) among photos in shooting order with the phone's `headings` (degrees,
    None where unknown): each photo with its next, those within HEADING_PAIR_DEG of each other,
    and a photo without heading with its next SEQUENTIAL_OVERLAP."""
    count = len(headings)
    chosen = {(i, i + 1) for i in range(count - 1)}
    chosen |= {(i, j) for i, j in image_pairs(count, "sequential")
               if headings[i] is None or headings[j] is None}
    known = [i for i, h in enumerate(headings) if h is not None]
    chosen |= {(i, j) for a, i in enumerate(known) for j in known[a + 1:]
               if abs((headings[i] - headings[j] + 180.0) % 360.0 - 180.0) <= HEADING_PAIR_DEG}
    return sorted(chosen)
