"""What stands off the support plane: a plain object on a patterned table, told by parallax.

A smooth, single-colour object on a richly patterned table leaves every sparse point on the
table, so its masks (windowshop.photos.segment) start from one sure pixel, where the photos
look, and GrabCut keeps only the part whose colour differs most from the table's (the granite
figure's orange body, without its blue head and base: masks IoU 0.59). But the table is flat
and patterned: a neighbouring photo warped onto this one through the plane (the homography the
plane induces) matches it wherever the table shows, and differs where something stands off the
plane and hides a different patch of table in each photo. Each photo is compared with its
NEIGHBOURS nearest photos; a pixel stands off where every one of them differs by more than
OFF_PLANE, so that the table a neighbour sees hidden behind the object (which only that one
differs on) is not taken. Only the part of the photo that the table's points span is compared:
beyond it the plane is not the surface seen (the room behind a table's edge).
"""

from __future__ import annotations

import cv2
import numpy as np

from windowshop.photos.segment import View, polygon
from windowshop.rays import project

NEIGHBOURS = 2
# grey levels (of 255) between a photo and a neighbour warped onto it through the plane. On the
# rendered granite figure (20 photos, 640 x 480), pixels over 30 are 13% of the figure's and
# 0.01% of the table's; over 20, 19% and 0.14% (the warp's resampling of the granite's speckle)
OFF_PLANE = 30.0
BLUR = 0.002  # of the image diagonal: the grey images are smoothed by this sigma before comparing
MIN_TABLE_POINTS = 8  # fewer points on the plane seen by a photo and its neighbour: no warp


def _grey(pixels: np.ndarray) -> np.ndarray:
    sigma = BLUR * np.hypot(*pixels.shape[:2])
    return cv2.GaussianBlur(pixels.astype(np.float32).mean(-1), (0, 0), sigma)


def _seen(table: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray]:
    """(uv (P, 2) of the `table` points (P, 3) in the view, (P,) bool: in front and inside it)."""
    uv, depth = project(table, view.camera)
    inside = ((depth > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < view.camera.width)
              & (uv[:, 1] < view.camera.height))
    return uv, inside


def _difference(grey: np.ndarray, seen: tuple[np.ndarray, np.ndarray], other_grey: np.ndarray,
                other_seen: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """(H, W) absolute difference between a photo's `grey` (_grey) and another's warped onto it
    through the plane of the table points each sees (`seen`, `other_seen`: _seen), NaN where the
    warp has nothing; None when too few table points are seen by both."""
    (uv, inside), (uv_other, inside_other) = seen, other_seen
    both = inside & inside_other
    if both.sum() < MIN_TABLE_POINTS:
        return None
    homography, _ = cv2.findHomography(uv_other[both].astype(np.float32),
                                       uv[both].astype(np.float32), 0)
    if homography is None:
        return None
    warped = cv2.warpPerspective(other_grey, homography, grey.shape[::-1], flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    # a phone sets each photo's exposure anew: the table, most of what both show, sets the gain
    # (every other photo of the granite figure 1.3 times brighter: 13% of the table stood off)
    shared = np.isfinite(warped) & polygon(grey.shape, uv[both])
    gain = np.median(grey[shared]) / max(float(np.median(warped[shared])), 1.0)
    return np.abs(grey - gain * warped)


def stands_off(views: list[View], table: np.ndarray) -> list[np.ndarray | None]:
    """Per view, (H, W) bool: the pixels standing off the plane of the points `table` (P, 3),
    in the views' frame (the support plane's inliers), by parallax against the nearest views
    (module docstring); None for a view with no neighbour to compare with."""
    centres = np.stack([v.camera.center for v in views])
    greys = [_grey(v.pixels) for v in views]
    seen = [_seen(table, v) for v in views]
    found: list[np.ndarray | None] = []
    for k in range(len(views)):
        distance = np.linalg.norm(centres - centres[k], axis=1)
        distance[k] = np.inf
        differences = [d for j in np.argsort(distance)[:NEIGHBOURS]
                       if (d := _difference(greys[k], seen[k], greys[j], seen[j])) is not None]
        uv, inside = seen[k]
        if not differences or inside.sum() < 3:
            found.append(None)
            continue
        least = np.min(np.stack(differences), axis=0)  # NaN (no warp) anywhere: not standing off
        off = np.nan_to_num(least, nan=0.0) > OFF_PLANE
        off &= polygon(off.shape, uv[inside])  # where the table's points reach
        off = cv2.morphologyEx(off.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        found.append(off > 0)
    return found
