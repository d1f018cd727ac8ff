"""Each photo's exposure and white balance, evened out by the colours its points share with others.

A phone sets exposure and white balance anew for every shot. The same point of the object then has
another colour in each photo, which the field learns as colour that changes with the view: the
turntable flickers through colour casts. Structure from motion already knows which pixels show one
point (its tracks). On them, log(pixel) = log(exposure of the photo) + log(colour of the point), per
channel: an exposure per photo and channel solves it in least squares (the gain compensation of
panorama stitching, Brown & Lowe 2007), with observations far off their fit dropped. The exposures
are scaled to a median of 1, so the scene keeps the exposure most photos have, and each photo is
divided by its own.
"""

from __future__ import annotations

import numpy as np
import pycolmap

MAX_EXPOSURE = 2.0  # an exposure is taken out up to this factor either way, per channel
MIN_OBSERVATIONS = 20  # a photo with fewer usable track pixels keeps its colours
CLIPPED = (10, 245)  # pixel values outside these (per channel) may be clipped: no evidence
OUTLIER_LOG = 0.15  # an observation further than this (or 3 MADs) off its fit is dropped
ROUNDS = 12  # alternating passes (point colours, then exposures) per fit
NEGLIGIBLE_LOG = 0.01  # a photo whose exposures all lie within 1% of 1 is left as it is


def track_colours(reconstruction: pycolmap.Reconstruction, pixels: dict[str, np.ndarray]
                  ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(placed image names, image index and point index of each observation, its log colour
    (N, 3)): every observation of a point seen by two photos or more, its colour the mean of the
    3 x 3 pixels at the keypoint in `pixels` (H, W, 3) uint8 by image name, each photo as
    structure from motion saw it."""
    names = sorted(im.name for im in reconstruction.images.values() if im.has_pose)
    index = {name: i for i, name in enumerate(names)}
    images, points, colours = [], [], []
    for point_id, point in enumerate(reconstruction.points3D.values()):
        if point.track.length() < 2:
            continue
        for element in point.track.elements:
            image = reconstruction.images[element.image_id]
            if image.name not in index:
                continue
            x, y = (int(v) for v in image.points2D[element.point2D_idx].xy)
            photo = pixels[image.name]
            if 1 <= x < photo.shape[1] - 1 and 1 <= y < photo.shape[0] - 1:
                images.append(index[image.name])
                points.append(point_id)
                colours.append(photo[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3).mean(0, np.float32))
    colours = np.array(colours, np.float32).reshape(-1, 3)
    usable = np.all((colours > CLIPPED[0]) & (colours < CLIPPED[1]), axis=1)
    return (names, np.array(images, int)[usable], np.array(points, int)[usable],
            np.log(colours[usable] / 255.0))


def _fit(images: np.ndarray, points: np.ndarray, logs: np.ndarray, photos: int
         ) -> tuple[np.ndarray, np.ndarray]:
    """(log exposures (photos, 3), log point colours): alternating least squares of
    logs = exposure[image] + colour[point], the exposures' mean held at 0 (the scale is free)."""
    count = np.bincount(images, minlength=photos)[:, None]
    exposures = np.zeros((photos, 3))
    per_point = np.maximum(np.bincount(points), 1)[:, None]
    for _ in range(ROUNDS):
        colour = np.stack([np.bincount(points, logs[:, c] - exposures[images, c])
                           for c in range(3)], 1) / per_point
        exposures = np.stack([np.bincount(images, logs[:, c] - colour[points, c], minlength=photos)
                              for c in range(3)], 1) / np.maximum(count, 1)
        exposures -= exposures[count[:, 0] > 0].mean(0)
    return exposures, colour


def photo_exposures(reconstruction: pycolmap.Reconstruction, pixels: dict[str, np.ndarray]
                    ) -> dict[str, np.ndarray]:
    """Each placed image's exposure (3,) against the others', by image name (see `solve`;
    `pixels` as in `track_colours`)."""
    names, images, points, logs = track_colours(reconstruction, pixels)
    return dict(zip(names, solve(images, points, logs, len(names))))


def solve(images: np.ndarray, points: np.ndarray, logs: np.ndarray, photos: int) -> np.ndarray:
    """(photos, 3) exposures from observations (image index, point index, log colour (N, 3)):
    how much brighter each channel of a photo shows the points it shares with the others; 1 where
    a photo has under MIN_OBSERVATIONS observations that fit, within MAX_EXPOSURE either way,
    scaled so that the photos' median is 1."""
    if photos < 2 or len(logs) == 0:
        return np.ones((photos, 3))
    exposures, colour = _fit(images, points, logs, photos)
    residual = np.abs(logs - exposures[images] - colour[points]).max(1)
    spread = 1.4826 * np.median(residual)
    kept = residual <= max(OUTLIER_LOG, 3.0 * spread)  # highlights, occlusions, misplaced pixels
    images, points, logs = images[kept], points[kept], logs[kept]
    exposures, _ = _fit(images, points, logs, photos)
    seen = np.bincount(images, minlength=photos) >= MIN_OBSERVATIONS
    exposures[~seen] = 0.0
    if seen.any():
        exposures[seen] -= np.median(exposures[seen], axis=0)
    bound = np.log(MAX_EXPOSURE)
    return np.exp(np.clip(exposures, -bound, bound))


def negligible(exposure: np.ndarray) -> bool:
    """Whether evening out a photo's exposure would change its colours by under NEGLIGIBLE_LOG
    (it is kept as taken)."""
    return bool(np.all(np.abs(np.log(exposure)) < NEGLIGIBLE_LOG))


def evened(pixels: np.ndarray, exposure: np.ndarray) -> np.ndarray:
    """The photo (H, W, 3) uint8 with each channel divided by its exposure."""
    return np.clip(np.rint(pixels.astype(np.float32) / exposure.astype(np.float32)), 0, 255
                   ).astype(np.uint8)
