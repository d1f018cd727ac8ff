"""The `tiny_nerf_data.npz` layout: `images` (N, H, W, 3) on black, `poses` (N, 4, 4) OpenGL c2w,
`focal`. As tiny_nerf splits it: the first 100 images train, the rest test."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.cameras import c2w_matrix
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import Camera

TRAIN_COUNT = 100


def read_npz(path: Path) -> Source:
    """One frame per image; the pixels stay in memory (the file holds them)."""
    try:
        with np.load(path) as data:
            missing = {"images", "poses", "focal"} - set(data.files)
            if missing:
                raise UserError(f"{path}: missing array(s) {', '.join(sorted(missing))}; expected "
                                f"the tiny_nerf_data.npz layout (images, poses, focal)")
            images, poses = data["images"], data["poses"]
            focal = float(np.asarray(data["focal"]).reshape(-1)[0])
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise UserError(f"{path}: cannot read the npz file ({err})") from err
    if images.ndim != 4 or images.shape[-1] not in (3, 4) or len(poses) != len(images):
        raise UserError(f"{path}: expected images (N, H, W, 3) and poses (N, 4, 4), got "
                        f"{images.shape} and {poses.shape}")
    if len(images) == 0:
        raise UserError(f"{path}: the file holds no images (an empty frame list)")
    images = images.astype(np.float32)
    if images.max() > 1.5:  # stored as 0..255
        images = images / 255.0
    height, width = images.shape[1:3]
    frames = []
    for i, (image, pose) in enumerate(zip(images, poses)):
        camera = Camera(fx=focal, fy=focal, cx=width / 2, cy=height / 2, width=width, height=height,
                        c2w=c2w_matrix(pose, f"{path} pose {i}"))
        frames.append(SourceFrame(camera=camera, image_path=path.with_name(f"{path.name}#{i}"),
                                  split="train" if i < TRAIN_COUNT else "test", pixels=image))
    # tiny_nerf_data.npz holds Blender renders: a z-up world
    return Source(format="npz", path=path, frames=frames, background="black",
                  up=np.array([0.0, 0.0, 1.0]))
