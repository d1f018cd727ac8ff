"""Framing the object's box: how far away, and how zoomed, the turntable's cameras are.

Each frame looks at the box's centre from its own direction. The projected box (its eight
corners, not a bounding sphere: a long object seen end-on is narrow) should fill `target` of the
frame on its larger axis, width or height, in every frame. One distance serves the whole path, so
the camera circles at a constant distance like a real turntable and the perspective never
changes: the distance at which the widest view, with the given focal length, fills `target`. The
model only renders between the run's `near` and `far`, so the distance stays where the whole box
lies in that range. Each frame's focal length then zooms to exactly `target` (the widest view
keeps the given one), and never so far that a corner leaves the frame.
"""

from __future__ import annotations

import numpy as np

from windowshop.scene.cameras import box_corners, look_at

FILL = 0.8  # fraction of the frame the box's projection spans on its larger axis
INSIDE = 0.98  # no corner comes nearer the frame's edge than this fraction of the half-frame
MIN_DISTANCE = 3.0  # times the box's bounding radius: nearer, perspective swells its near end
BISECTIONS = 60  # halvings of the distance interval: far below a pixel


def view_rotations(directions: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(F, 3, 3) camera-to-world rotations of cameras on unit `directions` (F, 3) from the target,
    looking back at it, upright about `up` (3,); they do not depend on the distance."""
    return np.stack([look_at(d, np.zeros(3), up)[:3, :3] for d in directions])


def projected_extent(local: np.ndarray, distance: np.ndarray, focal: np.ndarray, width: int,
                     height: int) -> tuple[np.ndarray, np.ndarray]:
    """How much of each frame the corners fill, and how near the edge they reach.

    `local` (F, 8, 3) are the corners in each camera's axes, relative to the target it looks at,
    so at `distance` (F,) the camera sees them at depth `distance - z`; `focal` (F,) in pixels.
    Returns `fill` (F,), the larger of (width span / width, height span / height), and `reach`
    (F,), the larger distance of a corner from the frame's centre as a fraction of the half-frame.
    """
    depth = distance[:, None] - local[..., 2]  # (F, 8)
    u = focal[:, None] * local[..., 0] / depth
    v = focal[:, None] * local[..., 1] / depth
    fill = np.maximum(np.ptp(u, axis=1) / width, np.ptp(v, axis=1) / height)
    reach = np.maximum(np.abs(u).max(axis=1) * 2 / width, np.abs(v).max(axis=1) * 2 / height)
    return fill, reach


def smallest_distance(holds, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(F,) smallest distances in [lo, hi] (F,) where `holds(distance) -> (F,) bool` is true.

    `holds` must be monotone: false below some distance, true above it (bisection).
    """
    lo, hi = lo.astype(np.float64).copy(), hi.astype(np.float64).copy()
    for _ in range(BISECTIONS):
        mid = (lo + hi) / 2
        ok = holds(mid)
        hi, lo = np.where(ok, mid, hi), np.where(ok, lo, mid)
    return hi


def depth_limits(corners: np.ndarray, centre: np.ndarray, directions: np.ndarray, near: float,
                 far: float, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) closest and farthest distances along `directions` (F, 3) from `centre` (3,) at which the
    whole box (`corners` (8, 3)) lies between `near` and `far` of the camera, searched in [lo, hi]."""
    box_lo, box_hi = corners.min(0), corners.max(0)

    def eyes(d):
        return centre + d[:, None] * directions

    def clear_of_near(d):  # the box's nearest point is at least `near` away
        e = eyes(d)
        return np.linalg.norm(e - np.clip(e, box_lo, box_hi), axis=1) >= near

    def past_far(d):  # the box's farthest corner is beyond `far`
        return np.linalg.norm(eyes(d)[:, None] - corners[None], axis=2).max(axis=1) > far

    return smallest_distance(clear_of_near, lo, hi), smallest_distance(past_far, lo, hi)


def orbit_distance(local: np.ndarray, corners: np.ndarray, centre: np.ndarray,
                   directions: np.ndarray, width: int, height: int, focal: float,
                   depth_range: tuple[float, float] | None, target: float) -> float:
    """The one distance from `centre` at which the widest view fills `target` with `focal`, no
    nearer than `MIN_DISTANCE` box radii, moved into `depth_range` where the box must be.

    `local` (F, 8, 3) are `corners` (8, 3) in each view's axes about `centre` (see
    `projected_extent`); `directions` (F, 3) are the unit directions of the views from it.
    """
    frames = len(directions)
    lo = np.full(frames, 1.0001 * np.linalg.norm(corners - centre, axis=1).max())  # outside the box
    hi = lo * (2.0 + 4.0 * focal / min(width, height) / target)  # the box spans < target here
    focals = np.full(frames, float(focal))
    fits = smallest_distance(lambda d: projected_extent(local, d, focals, width, height)[0] <= target,
                             lo, hi)
    distance = max(fits.max(), MIN_DISTANCE * lo[0])
    if depth_range is not None:
        closest, farthest = depth_limits(corners, centre, directions, *depth_range, lo, 10 * hi)
        # Keeping the front unclipped matters more than the back if both cannot hold.
        distance = max(min(distance, farthest.min()), closest.max())
    return float(distance)


def frame_box(aabb, centre: np.ndarray, up: np.ndarray, directions: np.ndarray, width: int,
              height: int, focal: float, distance: float | None = None, zoom: bool = True,
              depth_range: tuple[float, float] | None = None,
              target: float = FILL) -> tuple[np.ndarray, np.ndarray]:
    """Distances (F,) (all equal) from `centre` and focal lengths (F,) in pixels framing `aabb`.

    Cameras sit on unit `directions` (F, 3) from `centre` (3,), looking at it, upright about `up`.
    `distance` fixes the distance instead of solving it; `zoom=False` keeps `focal` (the user's
    field of view) instead of zooming each frame to `target`; `depth_range` (near, far) is the
    model's: the whole box stays within it where it can.
    """
    corners = box_corners(aabb)
    local = np.einsum("fji,kj->fki", view_rotations(directions, up), corners - centre)  # R^T (p - c)
    if distance is None:
        distance = orbit_distance(local, corners, centre, directions, width, height, focal,
                                  depth_range, target)
    distances = np.full(len(directions), float(distance))
    focals = np.full(len(directions), float(focal))
    if zoom:
        fill, reach = projected_extent(local, distances, focals, width, height)
        scale = np.minimum(target / np.maximum(fill, 1e-12), INSIDE / np.maximum(reach, 1e-12))
        in_front = (distances[:, None] > local[..., 2]).all(axis=1)  # a too-short --radius
        focals = np.where(in_front, focals * scale, focals)
    return distances, focals
