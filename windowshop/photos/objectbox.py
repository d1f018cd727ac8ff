"""Where the object is: its box from the sparse points most views see, and per-view foreground
masks when the photos have a plain background.

An object-centred capture keeps the object in frame in every photo, while the background drifts
in and out of view; so the points that project into the central part of most photos, near the
point the cameras look at, are the object's (and the surface it stands on, right around it).
"""

from __future__ import annotations

import numpy as np
from PIL import Image
from scipy import ndimage

from windowshop.rays import project
from windowshop.scene import normalize
from windowshop.scene.cameras import box_corners, nearest_point_to_axes
from windowshop.scene.types import Camera

MOST_VIEWS = 0.75  # a point counts as the object's when at least this share of views see it ...
INNER = 0.1  # ... inside the image less this margin (a share of width and height) on each side ...
NEAR_TARGET = 0.5  # ... within this share of the median camera distance from the look-at point
MIN_POINTS = 10  # fewer object points than this: fall back to the sphere all views see whole
BORDER = 0.04  # share of the image side that forms the border band sampled for the background
PLAIN_SPREAD = 40  # border pixels within this (0-255, max over channels) of its median ...
PLAIN_SHARE = 0.9  # ... for at least this share of the band: a plain background
PLAIN_VIEWS = 0.8  # masks are made when at least this share of the views has one
FOREGROUND = 60  # pixels further than this from the background colour are the object's
# ... and a plain border is a background only when this share of the photo stands out from it:
# a photo too dark for anything to (kermit's at a quarter of their light) has a plain border too
STANDS_OUT = 0.01


def seen_counts(points: np.ndarray, cameras: list[Camera], inner: float = INNER) -> np.ndarray:
    """(P,) how many `cameras` see each point (P, 3) in front of them, inside the inner image."""
    counts = np.zeros(len(points), dtype=np.int64)
    for cam in cameras:
        uv, depth = project(points, cam)
        inside = ((depth > 0)
                  & (uv[:, 0] >= inner * cam.width) & (uv[:, 0] <= (1 - inner) * cam.width)
                  & (uv[:, 1] >= inner * cam.height) & (uv[:, 1] <= (1 - inner) * cam.height))
        counts += inside
    return counts


def object_index(points: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """(Q,) indices of the sparse points (P, 3) that are the object's (see the module's
    docstring)."""
    c2ws = np.stack([c.c2w for c in cameras])
    target = nearest_point_to_axes(c2ws)
    reach = NEAR_TARGET * float(np.median(np.linalg.norm(c2ws[:, :3, 3] - target, axis=-1)))
    near = np.flatnonzero(np.linalg.norm(points - target, axis=-1) <= reach)
    return near[seen_counts(points[near], cameras) >= MOST_VIEWS * len(cameras)]


def object_box(chosen: np.ndarray, cameras: list[Camera], rotation: np.ndarray,
               support: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)) of the object in the `rotation`-ed frame, from its points `chosen` (Q, 3).

    The box is the 2-98 percentile range of the points, grown 5% on each side; with fewer than
    MIN_POINTS of them, where the cameras look: on a `support` plane (unit normal (3,) towards
    the cameras, offset) below the look-at point, photos aim at the middle of what stands there,
    so the box reaches from the plane to twice the look-at point's height, and as far to each
    side; otherwise the cube around the look-at point that every view sees whole.
    """
    if len(chosen) >= MIN_POINTS:
        return normalize.box_of(chosen, rotation, percentile=2.0)
    target = nearest_point_to_axes(np.stack([c.c2w for c in cameras]))
    centre = rotation @ target
    height = None if support is None else float(support[0] @ target - support[1])
    if height is not None and height > 0:
        return centre - height, centre + height
    radius = normalize.inscribed_radius(cameras, target)
    return centre - radius, centre + radius


def plain_colour(pixels: np.ndarray) -> np.ndarray | None:
    """(3,) the background colour if the border band of `pixels` (H, W, 3) uint8 is plain and
    something in the photo stands out from it."""
    band = max(1, round(BORDER * min(pixels.shape[:2])))
    border = np.concatenate([pixels[:band].reshape(-1, 3), pixels[-band:].reshape(-1, 3),
                             pixels[:, :band].reshape(-1, 3), pixels[:, -band:].reshape(-1, 3)])
    colour = np.median(border, axis=0)
    spread = np.abs(border.astype(np.float32) - colour).max(-1)
    if np.mean(spread <= PLAIN_SPREAD) < PLAIN_SHARE:
        return None
    standing = np.abs(pixels.astype(np.float32) - colour).max(-1) > FOREGROUND
    return colour if standing.mean() >= STANDS_OUT else None


def box_region(aabb: np.ndarray, camera: Camera, margin: float = 0.05) -> np.ndarray:
    """(H, W) bool: the image rectangle around the box `aabb` (2, 3) (in the camera's world),
    grown by `margin` of the image size."""
    uv, depth = project(box_corners(aabb), camera)
    region = np.zeros((camera.height, camera.width), dtype=bool)
    if np.any(depth <= 0):  # a camera inside or beside the box: no useful rectangle
        region[:] = True
        return region
    pad = margin * np.array([camera.width, camera.height])
    (u0, v0), (u1, v1) = np.floor(uv.min(0) - pad).astype(int), np.ceil(uv.max(0) + pad).astype(int)
    region[max(v0, 0):max(v1, 0), max(u0, 0):max(u1, 0)] = True
    return region


def foreground_mask(pixels: np.ndarray, colour: np.ndarray, region: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(silhouette, raw), both (H, W) bool: the object on a plain background of `colour` (3,),
    in `pixels` (H, W, 3).

    raw: pixels far from the background colour (inside `region`, if given), cleaned of specks,
    kept as the large connected parts, grown by a pixel so edges stay on it. silhouette: raw
    with every hole filled, for an object's own white or background-coloured parts look just
    like the background; only other views can tell a hole seen through (segment.see_through).
    """
    mask = np.abs(pixels.astype(np.float32) - colour).max(-1) > FOREGROUND
    if region is not None:
        mask &= region
    mask = ndimage.binary_opening(mask, iterations=2)
    labels, count = ndimage.label(mask)
    if count:
        sizes = ndimage.sum(mask, labels, index=np.arange(1, count + 1))
        mask = np.isin(labels, 1 + np.flatnonzero(sizes >= 0.05 * sizes.max()))
    raw = ndimage.binary_dilation(mask, iterations=1)
    return ndimage.binary_fill_holes(raw), raw


def background_colour(images: list[np.ndarray]) -> np.ndarray | None:
    """(3,) the shared plain background colour of most images, or None (no masks)."""
    colours = [c for c in (plain_colour(p) for p in images) if c is not None]
    if len(colours) < PLAIN_VIEWS * len(images):
        return None
    return np.median(np.stack(colours), axis=0)


def mask_image(mask: np.ndarray) -> Image.Image:
    """A mask (H, W) bool as an 8-bit image, white = object."""
    return Image.fromarray(np.where(mask, 255, 0).astype(np.uint8))

