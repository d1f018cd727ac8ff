"""Per-photo object masks on any background: GrabCut on colour, seeded by the object's own
sparse points and its box, then made consistent across views through their visual hull.

    inside the box above the support plane ──> may be the object; outside it ──> is not
    object keypoints ──> sure object; other keypoints (the surface, the room) ──> sure background
    a still backdrop (the phone did not move; windowshop.photos.still) ──> probable background,
        and what stands out from it ──> sure object
    no points of its own, on a patterned table: what stands off the table's plane in the
        neighbouring photos (windowshop.photos.offplane) ──> sure object
    GrabCut per photo ──> visual hull of the masks (forgiving a few bad ones) ──> GrabCut again
    within each photo's view of the hull (its background model now learns the colours right
    around the object) ──> cut to the hull of the results (segment.consistent): a pixel stays
    the object's only if its ray crosses the hull the other views carve

Photos are handled in the normalised frame, where the box's floor is the support plane, so the
hull (and every mask) stops at the surface the object stands on.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from windowshop.rays import project
from windowshop.scene.cameras import box_corners
from windowshop.scene.hull import GRID, hull_points
from windowshop.scene.images import parallel_map
from windowshop.scene.selection import evenly_spaced
from windowshop.scene.types import Camera

ITERATIONS = 5  # GrabCut rounds
WORK_SIDE = 256  # GrabCut runs on the box's part of the photo scaled to at most this many pixels
COARSE_SIDE = 160  # ... and this many in the first round, which only has to feed the hull
MARGIN = 0.03  # the box's outline grows by this share of the image diagonal (background beyond)
CONTEXT = 0.1  # GrabCut sees this share of the image diagonal around the box (background colours)
SEED_RADIUS = 0.006  # keypoint seeds are disks of this share of the image diagonal
HULL_TOLERANCE = 0.15  # a hull voxel survives this share of views missing it (imperfect masks)
SEE_THROUGH = 0.8  # a hole is the object's where its ray meets a voxel this share of views see
# The first round, which only feeds the hull, cuts at most this many photos spread over the set;
# the second cuts every photo within the hull they carve (the first round's own cut, else the
# hull's outline, as its guess of the object)
HULL_VIEWS = 24


@dataclass(frozen=True)
class View:
    """One placed photo and the sparse points it observes (pixels), camera in the normalised
    frame."""

    name: str
    pixels: np.ndarray  # (H, W, 3) uint8 RGB
    camera: Camera
    object_uv: np.ndarray  # (K, 2) the object's points seen in this photo
    background_uv: np.ndarray  # (B, 2) points off the object: the support surface, the room
    # (H, W) bool: a still backdrop, the same in every photo (windowshop.photos.still), and
    # what stands out from it (or off the support plane: windowshop.photos.offplane), or None
    backdrop: np.ndarray | None = None
    stands_out: np.ndarray | None = None


def _disks(shape: tuple[int, int], uv: np.ndarray, radius: int) -> np.ndarray:
    """(H, W) bool: disks of `radius` px around the pixels `uv` (N, 2) inside the image."""
    out = np.zeros(shape, dtype=np.uint8)
    for u, v in np.floor(uv).astype(int):
        if 0 <= u < shape[1] and 0 <= v < shape[0]:
            cv2.circle(out, (int(u), int(v)), radius, 1, -1)
    return out > 0


def polygon(shape: tuple[int, int], uv: np.ndarray) -> np.ndarray:
    """(H, W) bool: the convex hull of the pixels `uv` (N, 2), N >= 3."""
    out = np.zeros(shape, dtype=np.uint8)
    cv2.fillConvexPoly(out, cv2.convexHull(np.round(uv).astype(np.int32)), 1)
    return out > 0


def box_outline(aabb: np.ndarray, camera: Camera, grow: float = MARGIN) -> np.ndarray:
    """(H, W) bool: the projected box `aabb` (2, 3), grown by `grow` of the image diagonal;
    the whole image when a camera sits inside or beside the box."""
    shape = (camera.height, camera.width)
    uv, depth = project(box_corners(aabb), camera)
    if np.any(depth <= 0):
        return np.ones(shape, dtype=bool)
    outline = polygon(shape, uv)
    radius = round(grow * np.hypot(*shape))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    return cv2.dilate(outline.astype(np.uint8), kernel) > 0


def _seed_points(seeds: np.ndarray, view: View, inside: np.ndarray) -> np.ndarray:
    """`seeds` (H, W) with sure labels at the view's keypoints: background ones everywhere, the
    object's where `inside` (H, W) bool allows, as are the pixels standing out from a still
    backdrop, which itself starts as probable background."""
    if view.backdrop is not None:
        seeds[view.backdrop & (seeds == cv2.GC_PR_FGD)] = cv2.GC_PR_BGD
    radius = max(1, round(SEED_RADIUS * np.hypot(*seeds.shape)))
    seeds[_disks(seeds.shape, view.background_uv, radius)] = cv2.GC_BGD
    seeds[_disks(seeds.shape, view.object_uv, radius) & inside] = cv2.GC_FGD
    if view.stands_out is not None:
        seeds[view.stands_out & inside] = cv2.GC_FGD
    return seeds


def grabcut_mask(view: View, aabb: np.ndarray) -> np.ndarray:
    """(H, W) bool: the object in one photo by GrabCut, seeded as the module docstring says:
    anything inside the projected box may be the object, nothing outside it is."""
    outline = box_outline(aabb, view.camera)
    seeds = np.where(outline, cv2.GC_PR_FGD, cv2.GC_BGD).astype(np.uint8)
    return _run(view, _seed_points(seeds, view, outline), outline, COARSE_SIDE)


def refined_mask(view: View, mask: np.ndarray, silhouette: np.ndarray) -> np.ndarray:
    """(H, W) bool: GrabCut again, now that the hull's `silhouette` (H, W) bool bounds the object
    tightly: its background model then learns the colours right around the object (shadows,
    the surface beside it) rather than the far room."""
    seeds = np.where(silhouette, cv2.GC_PR_BGD, cv2.GC_BGD).astype(np.uint8)
    seeds[mask & silhouette] = cv2.GC_PR_FGD
    return _run(view, _seed_points(seeds, view, mask & silhouette), silhouette,
                WORK_SIDE) & silhouette


def _run(view: View, seeds: np.ndarray, region: np.ndarray, side: int) -> np.ndarray:
    """(H, W) bool: GrabCut from `seeds` on the part of the photo around `region` (H, W) bool,
    scaled to at most `side` pixels."""
    if not region.any():
        return region
    rows, cols = _crop(region, round(CONTEXT * np.hypot(*seeds.shape)))
    crop = seeds[rows, cols]
    if not np.any(crop == cv2.GC_BGD) or not np.any((crop == cv2.GC_FGD) | (crop == cv2.GC_PR_FGD)):
        return region  # GrabCut needs both kinds; the region is the best guess left
    mask = np.zeros(seeds.shape, dtype=bool)
    mask[rows, cols] = _grabcut(view.pixels[rows, cols], crop, side)
    return _clean(mask, seeds == cv2.GC_FGD)


def _grabcut(pixels: np.ndarray, seeds: np.ndarray, side: int) -> np.ndarray:
    """(h, w) bool foreground of GrabCut on `pixels` (h, w, 3) uint8 RGB from `seeds` (h, w)
    (cv2.GC_* labels), run at most `side` pixels wide (its time grows with the pixels)."""
    h, w = seeds.shape
    scale = min(1.0, side / max(h, w))
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    image = cv2.resize(np.ascontiguousarray(pixels[..., ::-1]), size, interpolation=cv2.INTER_AREA)
    labels = cv2.resize(seeds, size, interpolation=cv2.INTER_NEAREST)
    cv2.setRNGSeed(0)
    cv2.grabCut(image, labels, None, np.zeros((1, 65)), np.zeros((1, 65)), ITERATIONS,
                cv2.GC_INIT_WITH_MASK)
    foreground = ((labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)).astype(np.uint8)
    return cv2.resize(foreground, (w, h), interpolation=cv2.INTER_LINEAR) > 0


def _crop(region: np.ndarray, pad: int) -> tuple[slice, slice]:
    """Row and column slices of the bounding box of `region` (H, W) bool grown by `pad` px."""
    rows, cols = np.flatnonzero(region.any(1)), np.flatnonzero(region.any(0))
    h, w = region.shape
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + pad + 1, h)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)))


def _clean(mask: np.ndarray, sure: np.ndarray) -> np.ndarray:
    """`mask` (H, W) bool as the parts that hold sure object pixels (or its largest part when
    none does), holes filled: GrabCut's stray specks are background lookalikes."""
    labels, count = ndimage.label(mask)
    if not count:
        return mask
    keep = np.unique(labels[sure & mask])
    keep = keep[keep > 0]
    if not len(keep):
        keep = [1 + int(np.argmax(ndimage.sum(mask, labels, index=np.arange(1, count + 1))))]
    return ndimage.binary_fill_holes(np.isin(labels, keep))


def hull_silhouette(points: np.ndarray, voxel: float, camera: Camera) -> np.ndarray:
    """(H, W) bool: the pixels covered by voxels of side `voxel` centred at `points` (M, 3).

    Each voxel is drawn as a square of its projected size, on a grid coarse enough that the
    squares are a few pixels wide (fast), then brought back to full size."""
    shape = (camera.height, camera.width)
    uv, depth = project(points, camera)
    front = depth > 1e-9
    uv, depth = uv[front], depth[front]
    if not len(uv):
        return np.zeros(shape, dtype=bool)
    size = voxel * camera.fx / depth  # projected voxel side, pixels
    step = max(1, int(np.median(size) // 2))
    small = np.zeros((-(-shape[0] // step), -(-shape[1] // step)), dtype=np.uint8)
    cells = np.floor(uv / step).astype(int)
    inside = (cells[:, 0] >= 0) & (cells[:, 1] >= 0) & (cells[:, 0] < small.shape[1]) \
        & (cells[:, 1] < small.shape[0])
    small[cells[inside, 1], cells[inside, 0]] = 1
    reach = int(np.ceil(0.87 * size.max() / step))  # half the voxel's diagonal, in cells
    small = cv2.dilate(small, np.ones((2 * reach + 1, 2 * reach + 1), np.uint8))
    full = np.repeat(np.repeat(small, step, 0), step, 1)
    return full[:shape[0], :shape[1]] > 0


def _hull(masks: list[np.ndarray], cameras: list[Camera], aabb: np.ndarray
          ) -> tuple[np.ndarray, float] | None:
    """(centres (M, 3) of the visual hull's voxels inside the box `aabb` (2, 3), their side), or
    None when nothing survives; HULL_TOLERANCE of the views may miss a voxel."""
    centre, half = aabb.mean(0), float(np.max(aabb[1] - aabb[0])) / 2
    points = hull_points(cameras, [m.astype(np.float32) for m in masks], centre, half,
                         tolerance=HULL_TOLERANCE)
    if points is not None:
        points = points[np.all((points >= aabb[0]) & (points <= aabb[1]), axis=1)]
    if points is None or not len(points):
        return None
    return points, 2 * half / GRID


def carve(masks: list[np.ndarray], cameras: list[Camera], aabb: np.ndarray
          ) -> tuple[list[np.ndarray], np.ndarray] | None:
    """(each camera's view of the visual hull of `masks` (H, W) bool, as (H, W) bool; the hull's
    box (2, 3)), or None when nothing survives. Cameras are in the frame of the box `aabb`
    (2, 3) searched, whose floor is the support plane; the hull stops at the box."""
    hull = _hull(masks, cameras, aabb)
    if hull is None:
        return None
    points, voxel = hull
    box = np.stack([np.maximum(points.min(0) - voxel, aabb[0]), points.max(0) + voxel])
    return [hull_silhouette(points, voxel, c) for c in cameras], box


def _covered_share(points: np.ndarray, cameras: list[Camera], masks: list[np.ndarray]
                   ) -> np.ndarray:
    """(M,) the share of the views whose mask (H, W) bool covers each point (M, 3)."""
    hits = np.zeros(len(points))
    for cam, mask in zip(cameras, masks):
        uv, depth = project(points, cam)
        ui, vi = np.floor(uv).astype(int).T
        valid = (depth > 0) & (ui >= 0) & (vi >= 0) & (ui < mask.shape[1]) & (vi < mask.shape[0])
        hits[valid] += mask[vi[valid], ui[valid]]
    return hits / len(cameras)


def consistent(masks: list[np.ndarray], cameras: list[Camera], aabb: np.ndarray
               ) -> tuple[list[np.ndarray], np.ndarray | None]:
    """(the `masks` (H, W) bool cut to the visual hull of them all (see carve), the hull's box
    (2, 3) or None when the views disagree entirely)."""
    carved = carve(masks, cameras, aabb)
    if carved is None:
        return masks, None
    silhouettes, box = carved
    return [m & s for m, s in zip(masks, silhouettes)], box


def see_through(silhouettes: list[np.ndarray], raw: list[np.ndarray], cameras: list[Camera],
                aabb: np.ndarray) -> list[np.ndarray]:
    """The `silhouettes` (H, W) bool with their holes (pixels not in `raw`) reopened where the
    views see through them: a hole stays the object's (a white label, a background-coloured
    part) if its ray crosses a voxel of the silhouettes' hull that at least SEE_THROUGH of the
    raw masks cover. Only the views facing a label miss the object behind it; a real gap (a
    handle, a frame) is seen through from many directions, so no voxel in it is that covered."""
    hull = _hull(silhouettes, cameras, aabb)
    if hull is None:
        return silhouettes
    points, voxel = hull
    solid = points[_covered_share(points, cameras, raw) >= SEE_THROUGH]
    return [s & (r | hull_silhouette(solid, voxel, c))
            for s, r, c in zip(silhouettes, raw, cameras)]


def segment(views: list[View], aabb: np.ndarray) -> list[np.ndarray]:
    """(H, W) bool object masks of the `views` of an object in the box `aabb` (2, 3): GrabCut in
    each photo, then again within the visual hull of the first round's masks."""
    # OpenCV lets go of the GIL inside grabCut, so the photos are cut on every core at once
    first = evenly_spaced(len(views), min(len(views), HULL_VIEWS)).tolist()
    masks = dict(zip(first, parallel_map(lambda k: grabcut_mask(views[k], aabb), first)))
    hull = _hull(list(masks.values()), [views[k].camera for k in masks], aabb)
    if hull is None:  # no hull to cut within: each photo's own cut
        return [masks[k] if k in masks else grabcut_mask(v, aabb) for k, v in enumerate(views)]
    silhouettes = [hull_silhouette(*hull, v.camera) for v in views]
    return parallel_map(lambda k: refined_mask(views[k], masks.get(k, silhouettes[k]), silhouettes[k]),
                        range(len(views)))
