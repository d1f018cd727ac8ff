"""LLFF `poses_bounds.npy`: per image a 3x5 [R | t | (h, w, focal)] with camera axes ordered
(down, right, backward), plus near/far depths; images in `images/` (and `images_N/` copies
downscaled by N). Poses pair with the image names in sorted order, as LLFF's imgs2poses wrote them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.cameras import c2w_matrix
from windowshop.scene.colmap import find_model, load_model, model_points
from windowshop.scene.images import IMAGE_SUFFIXES
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import Camera

# LLFF (down, right, backward) columns -> OpenGL (right, up, backward)
LLFF_TO_GL = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def image_names(folder: Path) -> list[Path]:
    """The images in `folder`, sorted by name."""
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)


def _prescaled(root: Path, name: str) -> dict[int, Path]:
    """factor -> `images_<factor>/<stem>.*` copies of one image, where they exist."""
    found = {}
    for folder in root.glob("images_*"):
        factor = folder.name.split("_", 1)[1]
        if factor.isdigit():
            matches = sorted(folder.glob(Path(name).stem + ".*"))
            if matches:
                found[int(factor)] = matches[0]
    return found


def _sparse_points(root: Path) -> np.ndarray | None:
    """The COLMAP points LLFF's poses came from, when the model sits beside them (same frame)."""
    model = find_model(root)
    return None if model is None else model_points(load_model(model))


def read_llff(root: Path) -> Source:
    """One frame per row of poses_bounds.npy."""
    path = root / "poses_bounds.npy"
    try:
        data = np.load(path)
    except (OSError, ValueError) as err:
        raise UserError(f"{path}: cannot read ({err})") from err
    if data.ndim != 2 or data.shape[1] != 17:
        raise UserError(f"{path}: expected an (N, 17) array, got {data.shape}")
    if not (root / "images").is_dir():
        raise UserError(f"{root / 'images'}: the LLFF images folder is missing")
    names = image_names(root / "images")
    if len(names) != len(data):
        raise UserError(f"{path}: {len(data)} poses but {len(names)} images in {root / 'images'}; "
                        f"poses pair with the sorted image names, so the counts must agree")
    if not len(data):
        raise UserError(f"{path}: no poses (an empty frame list)")
    frames = []
    for name, row in zip(names, data):
        mat = row[:15].reshape(3, 5)
        height, width, focal = mat[:, 4]
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = mat[:, :3] @ LLFF_TO_GL, mat[:, 3]
        camera = Camera(fx=focal, fy=focal, cx=width / 2, cy=height / 2, width=int(round(width)),
                        height=int(round(height)), c2w=c2w_matrix(c2w, f"{path} row for {name.name}"))
        frames.append(SourceFrame(camera=camera, image_path=name,
                                  prescaled=_prescaled(root, name.name)))
    return Source(format="llff", path=root, frames=frames, points=_sparse_points(root))
