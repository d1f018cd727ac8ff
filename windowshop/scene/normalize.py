"""The normalising similarity: object centred at the origin, average camera up along +z, the
object box scaled into [-1, 1]^3; plus near/far bounds for the normalised cameras.

The object box comes from whatever evidence the source has (a published box, sparse points,
a visual hull of alpha masks, or the region every camera sees whole); see `object_box`.
"""

from __future__ import annotations

import numpy as np

from windowshop.scene.types import Camera

BOX_PADDING = 0.05  # estimated boxes grow by this fraction of their size on each side
MIN_NEAR = 0.02  # normalised units; keeps near positive when a camera sits inside the box


def rotation_to_z(up: np.ndarray) -> np.ndarray:
    """(3, 3) the smallest rotation taking unit `up` to +z."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = np.linalg.norm(axis), float(up @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def inscribed_radius(cameras: list[Camera], target: np.ndarray) -> float:
    """Radius of the largest sphere around `target` (3,) that every camera sees whole."""
    radii = []
    for cam in cameras:
        half_fov = min(np.arctan2(cam.width / 2, cam.fx), np.arctan2(cam.height / 2, cam.fy))
        radii.append(np.linalg.norm(cam.center - target) * np.sin(half_fov))
    return float(min(radii))


def similarity(rotation: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (4, 4) transform and the normalised aabb (2, 3) for a box [lo, hi] given in the
    `rotation`-ed source frame (x_rot = rotation @ x_source)."""
    centre = 0.5 * (lo + hi)
    scale = 1.0 / max(float(np.max(hi - lo)) / 2.0, 1e-12)
    transform = np.eye(4)
    transform[:3, :3] = scale * rotation
    transform[:3, 3] = -scale * centre
    return transform, np.stack([(lo - centre) * scale, (hi - centre) * scale])


def box_of(points: np.ndarray, rotation: np.ndarray, percentile: float = 0.0,
           padding: float = BOX_PADDING) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of `points` (N, 3) in the rotated frame, trimmed to [p, 100 - p] percentiles per
    axis (robust to stray points) and grown by `padding` of the size on each side."""
    rotated = points @ rotation.T
    lo, hi = np.percentile(rotated, [percentile, 100.0 - percentile], axis=0)
    grow = padding * (hi - lo) + 1e-9
    return lo - grow, hi + grow


def near_far(centres: np.ndarray, aabb: np.ndarray) -> tuple[float, float]:
    """Near/far (normalised units) covering the box from every camera centre (N, 3)."""
    nearest = np.clip(centres, aabb[0], aabb[1])
    near = float(np.min(np.linalg.norm(centres - nearest, axis=-1)))
    corners = np.array([[aabb[i, 0], aabb[j, 1], aabb[k, 2]]
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    far = float(np.max(np.linalg.norm(centres[:, None] - corners[None], axis=-1)))
    return max(near, MIN_NEAR), far
