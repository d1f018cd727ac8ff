"""LLFF `poses_bounds.npy`: per image a 3x5 [R | t | (h, w, focal)] with camera axes ordered
(down, right, backward), plus near/far depths; images in `images/` (and `images_N/` copies
downscaled by N; without `images/`, the largest of these). Poses pair with the image names in
sorted order, as LLFF's imgs2poses wrote them. The COLMAP model the poses came from, when it sits
beside them, lends its points (the object's box), even when it lacks its images file; the
source's `notes` say which files were used.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.cameras import c2w_matrix
from windowshop.scene.colmap import find_model, missing_files, read_points
from windowshop.scene.images import IMAGE_SUFFIXES, image_size
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import Camera

log = logging.getLogger(__name__)

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


def _sparse_points(root: Path, notes: list[str]) -> np.ndarray | None:
    """The points of the COLMAP model beside the poses (the same frame), if it has them; what was
    used goes into `notes` (an unreadable points file is skipped: the box has other evidence)."""
    model = find_model(root)
    if model is None:
        return None
    missing = missing_files(model)
    if "points3D" in missing:
        notes.append(f"{model}: COLMAP model without points3D.bin/.txt, not used")
        return None
    try:
        points = read_points(model)
    except UserError as err:
        log.warning("%s; going on without the points", err)
        notes.append(f"{model}: COLMAP points unreadable, not used")
        return None
    incomplete = f" (the model lacks {', '.join(missing)}: poses from poses_bounds.npy)" if missing else ""
    notes.append(f"{model}: {len(points)} COLMAP points{incomplete}")
    if missing:
        log.warning("%s: read as LLFF from %s; the COLMAP model lacks %s, only its points are used",
                    root, root / "poses_bounds.npy", ", ".join(missing))
    return points


def _relative(prescaled: dict[int, Path], factor: int) -> dict[int, Path]:
    """The copies smaller than the `factor` ones read, keyed by their factor relative to those."""
    return {k // factor: v for k, v in prescaled.items() if k > factor and k % factor == 0}


def _image_folder(root: Path) -> tuple[Path, int]:
    """`images/`, else the least downscaled `images_N/`, and N (1 for `images/`)."""
    if (root / "images").is_dir():
        return root / "images", 1
    factors = sorted(int(f.name[7:]) for f in root.glob("images_*") if f.name[7:].isdigit() and f.is_dir())
    if not factors:
        raise UserError(f"{root / 'images'}: the LLFF images folder is missing (and no images_N/)")
    return root / f"images_{factors[0]}", factors[0]


def _camera(row: np.ndarray, image: Path, factor: int, where: str) -> Camera:
    """The full-resolution camera of one poses_bounds row, resized to `image` when it is a copy
    downscaled by `factor` (its actual size: LLFF's resizes round)."""
    mat = row[:15].reshape(3, 5)
    height, width, focal = mat[:, 4]
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = mat[:, :3] @ LLFF_TO_GL, mat[:, 3]
    camera = Camera(fx=focal, fy=focal, cx=width / 2, cy=height / 2, width=int(round(width)),
                    height=int(round(height)), c2w=c2w_matrix(c2w, where))
    return camera if factor == 1 else camera.resized(*image_size(image))


def read_llff(root: Path) -> Source:
    """One frame per row of poses_bounds.npy."""
    path = root / "poses_bounds.npy"
    try:
        data = np.load(path)
    except (OSError, ValueError) as err:
        raise UserError(f"{path}: cannot read ({err})") from err
    if data.ndim != 2 or data.shape[1] != 17:
        raise UserError(f"{path}: expected an (N, 17) array, got {data.shape}")
    folder, factor = _image_folder(root)
    names = image_names(folder)
    if len(names) != len(data):
        raise UserError(f"{path}: {len(data)} poses but {len(names)} images in {folder}; "
                        f"poses pair with the sorted image names, so the counts must agree")
    if not len(data):
        raise UserError(f"{path}: no poses (an empty frame list)")
    notes = [f"{path}: {len(data)} poses; images from {folder}"]
    frames = [SourceFrame(camera=_camera(row, name, factor, f"{path} row for {name.name}"), image_path=name,
                          prescaled=_relative(_prescaled(root, name.name), factor))
              for name, row in zip(names, data)]
    points = _sparse_points(root, notes)
    return Source(format="llff", path=root, frames=frames, points=points, notes=notes)
