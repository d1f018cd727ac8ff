"""Cameras with no photo, for the losses that look where no photo does (RegNeRF's virtual views).

They stand where the training cameras might have: random azimuths all round the object, at the
elevations and distances the photos span, looking at the object's centre, upright, with the photos'
median focal length and image size.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from windowshop.fit.batches import CameraRays
from windowshop.scene.types import Camera

VIRTUAL_CAMERAS = 256  # poses drawn once per fit; each step draws patches from them


def virtual_cameras(cameras: Sequence[Camera], centre: np.ndarray, count: int = VIRTUAL_CAMERAS,
                    seed: int = 0) -> list[Camera]:
    """`count` random cameras between and around the training `cameras`, looking at `centre` (3,)."""
    from windowshop.video.paths import fit_orbit, orbit_cameras  # video/ is heavy; only fits need it

    orbit = fit_orbit(list(cameras), centre=np.asarray(centre, dtype=np.float64))
    offsets = np.stack([c.center for c in cameras]) - orbit.centre
    distances = np.linalg.norm(offsets, axis=1)
    elevations = np.degrees(np.arcsin(np.clip(offsets @ orbit.up / distances, -1.0, 1.0)))
    rng = np.random.default_rng(seed)
    return orbit_cameras(orbit, rng.uniform(0.0, 360.0, count),
                         rng.uniform(elevations.min(), min(elevations.max(), 85.0), count),
                         cameras[0].width, cameras[0].height,
                         rng.uniform(distances.min(), distances.max(), count),
                         np.full(count, float(np.median([c.fx for c in cameras]))))


def virtual_rays(cameras: Sequence[Camera], centre: np.ndarray, device: torch.device | str,
                 seed: int = 0) -> CameraRays:
    """A sampler of rays from `virtual_cameras` of the training `cameras` around `centre` (3,)."""
    return CameraRays(virtual_cameras(cameras, centre, seed=seed), device, seed=seed)
