"""The surface the object stands on: a plane fitted by RANSAC to the sparse points around the
object, "up" as its normal, and the object's points as those standing above it.

A support plane is opaque: the cameras are all on one side of it and no point is ever seen
beneath it; it reaches beyond the object's footprint; something stands on it. That, not the
photos' roll, tells a table from a plane through the object itself, so "up" holds for photos
taken at any roll. Only photos that agree on an up (upright ones) can overrule it: a plane far
off their up is a wall. Without a support plane, up is the level the photos agree on, else the
cameras' mean up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from windowshop.errors import UserError
from windowshop.photos.objectbox import NEAR_TARGET, object_index
from windowshop.scene.cameras import agreed_level, nearest_point_to_axes, up_vector
from windowshop.scene.types import Camera

TOLERANCE = 0.01  # inlier distance, as a share of the median camera distance to the object
TRIALS = 2000  # RANSAC hypotheses
NEIGHBOURS = 12  # each is drawn from a point and its nearest neighbours
MAX_POINTS = 3000  # a random subset of the points near the object scores them (memory, time)
CAMERA_SIDE = 0.9  # at least this share of the cameras must lie above a support plane
BELOW_WEIGHT = 2.0  # each point seen beneath a hypothesis cancels this many inliers
MIN_SHARE = 0.1  # a plane needs this share of the points near the object ...
MIN_INLIERS = 30  # ... and at least this many inliers
BEYOND = 0.15  # ... of which this share lie beyond the footprint of the points above it
ABOVE = 3.0  # the object's points stand more than this many tolerances above the plane
FLAT_SHARE = 0.95  # more of the points near the object on the plane: nothing stands on it
UPRIGHT_AGREE = 0.9  # photos whose mean up is this long agree on an up ...
WALL_ANGLE = 60.0  # ... and a plane further off it (degrees) stands upright: no support
GRAVITY_DEG = 12.0  # a plane further off the phone's gravity is not what the object stands on
LEVEL_DEG = 12.0  # a plane sought past a wall must leave upright photos level within this
MIN_OBJECT_POINTS = 20  # fewer points above the plane that most views see: no object
ADVICE = ("photograph one object standing on a surface, walking around it and keeping it in "
          "the middle of every photo")


@dataclass(frozen=True)
class Plane:
    """n . x = offset; `normal` (3,) unit, pointing to the cameras' side."""

    normal: np.ndarray
    offset: float
    tolerance: float  # inlier distance, world units
    inlier_share: float  # share of the points near the object that lie on it

    def height(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distance of `points` (N, 3) above the plane."""
        return points @ self.normal - self.offset

    def z_at(self, rotation: np.ndarray, xy: np.ndarray) -> float:
        """The plane's z at `xy` (2,) in the frame `rotation` (3, 3) turns the world into, whose
        +z is near the normal (up from gravity, within GRAVITY_DEG of it)."""
        n = rotation @ self.normal
        return float((self.offset - n[:2] @ xy) / n[2])


@dataclass(frozen=True)
class Isolated:
    """The support plane (None if none was found), up, and the object's sparse points."""

    plane: Plane | None
    up: np.ndarray  # (3,) unit
    index: np.ndarray  # (Q,) int: which of the points given are the object's
    up_source: str = "plane"  # or "gravity" (the phone's), or with no support plane, "photos"
    # (their level) or "cameras"


def capture_scale(cameras: list[Camera]) -> tuple[np.ndarray, float]:
    """(the point the cameras look at (3,), their median distance to it)."""
    c2ws = np.stack([c.c2w for c in cameras])
    target = nearest_point_to_axes(c2ws)
    return target, float(np.median(np.linalg.norm(c2ws[:, :3, 3] - target, axis=-1)))


def _hypotheses(near: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(normals (T, 3) unit, offsets (T,)) of planes through three points of `near` (P, 3): a
    random point and two of its NEIGHBOURS nearest (planes are local: far likelier to draw three
    of the surface's points than from anywhere); degenerate triples dropped."""
    k = min(NEIGHBOURS, len(near) - 1)
    _, neighbours = cKDTree(near).query(near, k + 1)
    first = rng.integers(len(near), size=TRIALS)
    pick = neighbours[first[:, None], 1 + rng.integers(k, size=(TRIALS, 2))]
    a, b, c = near[first], near[pick[:, 0]], near[pick[:, 1]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    keep = length > 1e-12
    normals = normals[keep] / length[keep, None]
    return normals, np.sum(normals * a[keep], axis=1)


def _best(near: np.ndarray, centres: np.ndarray, tol: float, rng: np.random.Generator,
          up: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """(normal (3,) toward the cameras, inliers (P,) bool) of the best hypothesis: most points
    on it, BELOW_WEIGHT less for each point seen beneath it, CAMERA_SIDE of the cameras above
    it, and its normal within `up`'s angle (degrees) of its direction (3,) when given; None if
    no hypothesis qualifies."""
    normals, offsets = _hypotheses(near, rng)
    flip = np.where(np.median(centres @ normals.T - offsets, axis=0) < 0, -1.0, 1.0)
    normals, offsets = normals * flip[:, None], offsets * flip
    heights = near @ normals.T - offsets  # (P, T)
    score = (np.abs(heights) <= tol).sum(0) - BELOW_WEIGHT * (heights < -ABOVE * tol).sum(0)
    allowed = np.mean(centres @ normals.T - offsets > tol, axis=0) >= CAMERA_SIDE
    if up is not None:
        allowed &= normals @ up[0] >= np.cos(np.radians(up[1]))
    score = np.where(allowed, score, -np.inf)
    best = int(np.argmax(score))
    if not np.isfinite(score[best]):
        return None
    return normals[best], np.abs(heights[:, best]) <= tol


def fit_support_plane(points: np.ndarray, cameras: list[Camera], seed: int = 0,
                      up: tuple[np.ndarray, float] | None = None) -> Plane | None:
    """The plane (RANSAC, then least squares on its inliers) the object stands on, among the
    points (P, 3) near the cameras' look-at point, its normal within `up`'s angle (degrees) of
    its direction when given; None when no plane qualifies."""
    target, distance = capture_scale(cameras)
    near = points[np.linalg.norm(points - target, axis=-1) <= NEAR_TARGET * distance]
    if len(near) < MIN_INLIERS:
        return None
    near = near[np.random.default_rng(seed).permutation(len(near))[:MAX_POINTS]]
    tol = TOLERANCE * distance
    best = _best(near, np.stack([c.center for c in cameras]), tol, np.random.default_rng(seed),
                 up)
    if best is None or best[1].sum() < max(MIN_INLIERS, MIN_SHARE * len(near)):
        return None
    normal, inliers = best
    on = near[inliers]
    refined = np.linalg.svd(on - on.mean(0))[2][-1]
    refined = refined if refined @ normal > 0 else -refined
    found = Plane(normal=refined, offset=float(refined @ on.mean(0)), tolerance=tol,
                  inlier_share=float(np.mean(np.abs(near @ refined - refined @ on.mean(0)) <= tol)))
    return found if _reaches_beyond(found, near) else None


def _reaches_beyond(found: Plane, near: np.ndarray) -> bool:
    """Whether enough of the plane's points lie beyond the footprint of the points above it: a
    surface the object stands on extends past it, unlike a slice through the object's own
    curved side."""
    height = found.height(near)
    above, on = near[height > ABOVE * found.tolerance], near[np.abs(height) <= found.tolerance]
    if len(above) < MIN_INLIERS:
        return True  # nothing stands on it: a bare surface, which isolate() reports
    above, on = (p - np.outer(p @ found.normal, found.normal) for p in (above, on))  # in-plane
    centre = above.mean(0)
    footprint = np.percentile(np.linalg.norm(above - centre, axis=1), 90)
    return float(np.mean(np.linalg.norm(on - centre, axis=1) > footprint)) >= BEYOND


def isolate(points: np.ndarray, cameras: list[Camera], seed: int = 0,
            by_points: bool = True, gravity: np.ndarray | None = None) -> Isolated:
    """Support plane, up and the object's points (see the module docstring) of a capture.

    A plane with nothing standing on it (a wall behind the object) is no support: up then
    comes from the cameras. UserError when no object stands out: nearly every point lies on one
    surface, or too few points that most views see sit where the views meet. Not `by_points`
    (a plain object on a richly textured table, whose points are nearly all the table's), the
    object is wherever the cameras look, its points those there, however few (none: the box
    around the look-at point that every view sees whole, objectbox.object_box). With the
    phone's `gravity` (world up (3,), windowshop.photos.sensors), a plane more than GRAVITY_DEG
    off it is no support (a slope, a wall or a pedestal's side), and up is gravity.
    """
    plane = fit_support_plane(points, cameras, seed)
    if by_points and plane is not None and plane.inlier_share >= FLAT_SHARE:
        raise UserError(f"no object found: {plane.inlier_share:.0%} of the points around the "
                        f"middle of the photos lie on one flat surface (a wall, a floor or an "
                        f"empty table); {ADVICE}")
    if plane is not None and (_across_upright_photos(plane, cameras) if gravity is None
                              else plane.normal @ gravity < np.cos(np.radians(GRAVITY_DEG))):
        # photos or gravity that agree on up show a wall or a side, not a support (a can on a
        # floor, the tiled wall behind it richer in points): the support is sought again among
        # the planes they allow, and without gravity kept only if it leaves the photos level
        plane = fit_support_plane(points, cameras, seed, (gravity, GRAVITY_DEG)
                                  if gravity is not None else (_photos_up(cameras), WALL_ANGLE))
        if plane is not None and gravity is None and _tilts_the_photos(plane, cameras):
            plane = None
    if plane is not None:
        chosen = _most_seen(points, cameras, plane.height(points) > ABOVE * plane.tolerance)
        if by_points and len(chosen) < MIN_OBJECT_POINTS:  # nothing on it: a wall behind
            plane, chosen = None, None
    if plane is None:
        chosen = where_views_meet(points, cameras)
    if by_points and len(chosen) < MIN_OBJECT_POINTS:
        raise UserError(f"no object found: only {len(chosen)} points that most photos see sit "
                        f"where the photos meet (at least {MIN_OBJECT_POINTS} are needed); "
                        f"{ADVICE}")
    if gravity is not None:  # a phone's gravity is truer than a plane fitted to sparse points
        return Isolated(plane=plane, up=gravity, index=chosen, up_source="gravity")
    if plane is not None:
        return Isolated(plane=plane, up=plane.normal, index=chosen)
    up, source = _cameras_up(np.stack([c.c2w for c in cameras]))
    return Isolated(plane=None, up=up, index=chosen, up_source=source)


def level_up(isolated: Isolated, level: np.ndarray, points: np.ndarray,
             cameras: list[Camera]) -> Isolated:
    """`isolated` with up from the photos' `level` (3,) instead of its plane. A plane more than
    WALL_ANGLE off that level is a wall or the object's own side, as for upright photos in
    `isolate`: it is dropped, and the object's points are all those where the views meet, not
    only the ones in front of it (temple's 4-photo ring, its photos turned a quarter: a face of
    the temple taken for the support, 82 degrees off their level, left the rest of the temple
    out of its box and cut its masks in two). A plane nearer the level stays the support, its
    fit tilted by few points."""
    found = isolated.plane
    if found is not None and _stands_upright(found, level):
        return Isolated(plane=None, up=level, index=where_views_meet(points, cameras),
                        up_source="photos")
    return Isolated(plane=found, up=level, index=isolated.index, up_source="photos")


def _cameras_up(c2ws: np.ndarray) -> tuple[np.ndarray, str]:
    """(up (3,), where it came from) with no support plane: the level the photos agree on (a
    statue on a pedestal, photographed from below: their pitch would tilt the mean up), else
    the cameras' mean up."""
    level = agreed_level(c2ws)
    return (level, "photos") if level is not None else (up_vector(c2ws), "cameras")


def _across_upright_photos(found: Plane, cameras: list[Camera]) -> bool:
    """Whether the photos agree on an up (_photos_up) that is more than WALL_ANGLE degrees off
    the plane's normal. Photos at random rolls agree on nothing, and then the plane alone
    decides."""
    up = _photos_up(cameras)
    return up is not None and _stands_upright(found, up)


def _tilts_the_photos(found: Plane, cameras: list[Camera]) -> bool:
    """Whether upright photos would stand rolled on `found`: their right axes' median tilt
    against it over LEVEL_DEG. Over a narrow arc the photos' level is loose across their view,
    not in it (beer_can's frames 0007-0011: a plane 22 deg off the floor tilted them 14-24 deg,
    the floor 4-7)."""
    rights = np.stack([c.c2w[:3, 0] for c in cameras])
    tilt = np.degrees(np.arcsin(np.clip(np.abs(rights @ found.normal), 0.0, 1.0)))
    return float(np.median(tilt)) > LEVEL_DEG


def _photos_up(cameras: list[Camera]) -> np.ndarray | None:
    """The unit mean of the photos' up axes (3,) when they agree (their rolls within about 25
    degrees of each other, as upright photos), else None."""
    mean_up = np.stack([c.c2w[:3, 1] for c in cameras]).mean(0)
    length = float(np.linalg.norm(mean_up))
    return mean_up / length if length >= UPRIGHT_AGREE else None


def _stands_upright(found: Plane, up: np.ndarray) -> bool:
    """Whether `found`'s normal lies more than WALL_ANGLE degrees off the unit `up` (3,): a
    wall or a side, no support."""
    return float(found.normal @ up) < np.cos(np.radians(WALL_ANGLE))


def where_views_meet(points: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """(Q,) indices of the `points` (P, 3) that are the object's with no plane to stand on."""
    return _most_seen(points, cameras, np.ones(len(points), dtype=bool))


def _most_seen(points: np.ndarray, cameras: list[Camera], allowed: np.ndarray) -> np.ndarray:
    """(Q,) indices of the `allowed` (P,) bool `points` (P, 3) that are the object's by
    objectbox.object_index (near the look-at point, seen by most views)."""
    index = np.flatnonzero(allowed)
    return index[object_index(points[index], cameras)]
