"""A built-in analytic object, ray-traced exactly for any camera: tests and the demo use it when no
dataset is at hand, and it gives ground truth for any new view.

Coloured primitives (a checkered plinth, spheres, a box) lit by one directional light: ambient +
Lambert diffuse + a Blinn-Phong specular highlight, so the object also has view-dependent colour.
It lives directly in the normalised frame (up = +z, inside [-1, 1]^3), so `transform` is identity.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from windowshop.scene.cameras import look_at
from windowshop.scene.normalize import near_far
from windowshop.scene.types import BACKGROUND_CHOICES, Camera, Scene, View, composite_colour

# (centre, radius, albedo, shininess weight)
SPHERES = [
    ((-0.30, -0.25, -0.12), 0.33, (0.85, 0.15, 0.12), 0.6),
    ((0.32, 0.30, -0.20), 0.25, (0.15, 0.30, 0.85), 0.6),
    ((0.00, 0.15, 0.42), 0.20, (0.95, 0.80, 0.10), 0.6),
]
# (min corner, max corner, albedo, shininess weight); the plinth (first) is checkered on top
BOXES = [
    ((-0.70, -0.70, -0.75), (0.70, 0.70, -0.45), (0.90, 0.90, 0.90), 0.1),
    ((0.20, -0.55, -0.45), (0.50, -0.25, 0.20), (0.20, 0.70, 0.25), 0.3),
]
CHECKER = 0.175  # side of the plinth's checker squares
CHECKER_DARK = np.array([0.25, 0.25, 0.30])
LIGHT = np.array([0.4, 0.3, 0.85]) / np.linalg.norm([0.4, 0.3, 0.85])
AMBIENT, DIFFUSE, SPECULAR, SHININESS = 0.3, 0.7, 0.6, 40.0
BOUNDS = np.array([[-0.70, -0.70, -0.75], [0.70, 0.70, 0.62]])  # tight box around everything


def _hit_spheres(o: np.ndarray, d: np.ndarray, t: np.ndarray, normal: np.ndarray,
                 albedo: np.ndarray, shine: np.ndarray) -> None:
    """Update the nearest hit distance `t` (N,), `normal`, `albedo` (N, 3), `shine` (N,) in place."""
    for centre, radius, colour, weight in SPHERES:
        oc = o - np.asarray(centre)
        b = np.einsum("ij,ij->i", oc, d)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - radius * radius)
        root = np.sqrt(np.maximum(disc, 0.0))
        ts = np.where(-b - root > 1e-6, -b - root, -b + root)
        hit = (disc > 0) & (ts > 1e-6) & (ts < t)
        t[hit] = ts[hit]
        normal[hit] = (oc[hit] + ts[hit, None] * d[hit]) / radius
        albedo[hit], shine[hit] = colour, weight


def _hit_boxes(o: np.ndarray, d: np.ndarray, t: np.ndarray, normal: np.ndarray,
               albedo: np.ndarray, shine: np.ndarray) -> None:
    """As `_hit_spheres`, for the axis-aligned boxes (slab test)."""
    safe = np.where(np.abs(d) < 1e-12, 1e-12, d)
    for index, (lo, hi, colour, weight) in enumerate(BOXES):
        t1, t2 = (np.asarray(lo) - o) / safe, (np.asarray(hi) - o) / safe
        t_in, t_out = np.minimum(t1, t2), np.maximum(t1, t2)
        entry, axis = t_in.max(-1), t_in.argmax(-1)
        hit = (t_out.min(-1) >= entry) & (entry > 1e-6) & (entry < t)
        t[hit] = entry[hit]
        n = np.zeros((int(hit.sum()), 3))
        n[np.arange(len(n)), axis[hit]] = -np.sign(d[hit, axis[hit]])
        normal[hit] = n
        albedo[hit], shine[hit] = colour, weight
        if index == 0:  # checker the plinth's top face
            p = o[hit] + entry[hit, None] * d[hit]
            dark = (np.floor(p[:, 0] / CHECKER) + np.floor(p[:, 1] / CHECKER)) % 2 == 1
            top = n[:, 2] > 0.5
            idx = np.flatnonzero(hit)[dark & top]
            albedo[idx] = CHECKER_DARK


def trace(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shaded colour (N, 3) and hit mask (N,) of rays `origins`, unit `directions` (N, 3)."""
    n = len(origins)
    t = np.full(n, np.inf)
    normal, albedo, shine = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
    _hit_spheres(origins, directions, t, normal, albedo, shine)
    _hit_boxes(origins, directions, t, normal, albedo, shine)
    hit = np.isfinite(t)
    lambert = np.clip(normal @ LIGHT, 0.0, None)
    half = LIGHT - directions
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    highlight = np.clip(np.einsum("ij,ij->i", normal, half), 0.0, None) ** SHININESS
    rgb = albedo * (AMBIENT + DIFFUSE * lambert)[:, None] + (SPECULAR * shine * highlight)[:, None]
    return np.clip(rgb, 0.0, 1.0) * hit[:, None], hit


def render_truth(camera: Camera, background: tuple[float, float, float] = (1.0, 1.0, 1.0)
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Exact image of the object through every pixel centre of `camera` (normalised frame).

    Returns rgb (H, W, 3) float32 composited over `background`, and alpha (H, W) float32 in {0, 1}.
    """
    j, i = np.meshgrid(np.arange(camera.height) + 0.5, np.arange(camera.width) + 0.5, indexing="ij")
    local = np.stack([(i - camera.cx) / camera.fx, -(j - camera.cy) / camera.fy,
                      -np.ones_like(i)], -1).reshape(-1, 3)
    dirs = local @ camera.c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origins = np.broadcast_to(camera.c2w[:3, 3], dirs.shape)
    rgb, hit = trace(origins, dirs)
    rgb = rgb + (1.0 - hit[:, None]) * np.asarray(background, dtype=np.float64)
    shape = (camera.height, camera.width)
    return rgb.reshape(*shape, 3).astype(np.float32), hit.reshape(shape).astype(np.float32)


def orbit_cameras(n: int, size: int, radius: float = 3.5, fov_deg: float = 45.0,
                  offset: float = 0.0) -> list[Camera]:
    """`n` cameras on the upper hemisphere (elevation 10..70 degrees) looking at the origin.

    Azimuths follow the golden angle (a Fibonacci spiral), so any n is spread evenly; `offset`
    (in steps) shifts the spiral so a second set (test views) never repeats the first.
    """
    focal = 0.5 * size / np.tan(np.radians(fov_deg) / 2)
    golden = np.pi * (3.0 - np.sqrt(5.0))
    cameras = []
    for k in range(n):
        s = (k + 0.5 + offset) / n
        elevation = np.radians(10.0 + 60.0 * (s % 1.0))
        azimuth = (k + offset) * golden
        eye = radius * np.array([np.cos(elevation) * np.cos(azimuth),
                                 np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        c2w = look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        cameras.append(Camera(fx=focal, fy=focal, cx=size / 2, cy=size / 2, width=size,
                              height=size, c2w=c2w))
    return cameras


def synthetic_scene(n_train: int = 40, n_test: int = 8, size: int = 64, radius: float = 3.5,
                    fov_deg: float = 45.0, background: str = "white") -> Scene:
    """A Scene of the built-in object: `n_train` + `n_test` views of `size` x `size` pixels.

    Poses, alpha masks and images are exact; test cameras sit between the training ones.
    """
    if background not in BACKGROUND_CHOICES:
        raise ValueError(f"unknown background {background!r}; use white, black or alpha")
    colour = composite_colour(background)
    views = []
    for split, cams in (("train", orbit_cameras(n_train, size, radius, fov_deg)),
                        ("test", orbit_cameras(n_test, size, radius, fov_deg, offset=0.5))):
        for k, cam in enumerate(cams):
            rgb, alpha = render_truth(cam, colour)
            views.append(View(camera=cam, image=rgb, split=split, name=f"synthetic/{split}_{k:03d}",
                              alpha=alpha, stored_camera=cam))
    aabb = BOUNDS + np.array([[-0.05], [0.05]])
    near, far = near_far(np.stack([v.camera.center for v in views]), aabb)
    return Scene(views=views, format="synthetic", source=Path("synthetic"), aabb=aabb, near=near,
                 far=far, transform=np.eye(4), background=background)
