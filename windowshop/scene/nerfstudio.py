"""nerfstudio / instant-ngp `transforms.json`: OpenGL c2w per frame, intrinsics global or per
frame (scene/intrinsics.py: `fl_x fl_y cx cy w h`, fields of view, OPENCV or OPENCV_FISHEYE
lenses), optional `mask_path` (frames whose mask file is missing leave every mask out, with a
warning), optional `{train,val,test}_filenames` splits, the `images_N/` copies ns-process-data writes
(decoded instead when the scene is loaded downscaled), optional `ply_file_path` (nerfstudio's sparse
points, in the file's frame: they bound the object; a missing one is noted and skipped).
`depth_file_path`, `applied_transform`
(how nerfstudio moved COLMAP's frame: the poses already carry it) and instant-ngp's `aabb_scale`,
`scale`, `offset` are not needed and left alone."""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.blender import image_file, read_json
from windowshop.scene.cameras import c2w_matrix
from windowshop.scene.images import image_size
from windowshop.scene.intrinsics import frame_intrinsics, needs_image_size
from windowshop.scene.ply import read_ply_points
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import SPLITS

log = logging.getLogger(__name__)

WRITER_KEY = "windowshop"  # extra key our writer adds: normalisation, box and background
PRESCALED = (2, 4, 8)  # ns-process-data's downscaled copies: images_2/, images_4/, images_8/


def _splits(meta: dict) -> dict[str, str]:
    """normalised file path -> split, from nerfstudio's optional `<split>_filenames` lists."""
    return {os.path.normpath(name): split for split in SPLITS
            for name in meta.get(f"{split}_filenames") or []}


def read_nerfstudio(path: Path) -> Source:
    """Frames of a transforms.json (`path` is the JSON file; images are relative to its folder)."""
    meta = read_json(path)
    root = path.parent
    frames_meta = meta.get("frames")
    if not isinstance(frames_meta, list) or not frames_meta:
        raise UserError(f"{path}: the 'frames' list is missing or empty (an empty frame list)")
    splits = _splits(meta)
    global_size: tuple[int, int] | None = None
    frames = []
    for i, frame in enumerate(frames_meta):
        where = f"{path} frame {i}"
        if "file_path" not in frame or "transform_matrix" not in frame:
            raise UserError(f"{where}: every frame needs 'file_path' and 'transform_matrix'")
        image = image_file(root, frame["file_path"])
        size = None
        if needs_image_size(meta, frame):  # one image size for all (a mismatch is reported on decoding)
            global_size = size = global_size or image_size(image)
        camera, distortion = frame_intrinsics(meta, frame, size, f"{where} ({image.name})")
        mask = root / frame["mask_path"] if frame.get("mask_path") else None
        frames.append(SourceFrame(
            camera=replace(camera, c2w=c2w_matrix(frame["transform_matrix"], where)),
            image_path=image, split=splits.get(os.path.normpath(frame["file_path"])),
            distortion=None if distortion.is_identity else distortion, mask_path=mask,
            prescaled=_prescaled(image)))
    extra = meta.get(WRITER_KEY) or {}
    box = np.asarray(extra["aabb"], dtype=np.float64) if "aabb" in extra else None
    notes: list[str] = []
    return Source(format="nerfstudio", path=path, frames=_masks_or_none(frames, path, notes), box=box,
                  background=extra.get("background"), normalized="transform" in extra,
                  points=_points(meta, root, notes), notes=notes)


def _prescaled(image: Path) -> dict[int, Path]:
    """factor -> nerfstudio's downscaled copy of `image`, in `images_N/` beside its `images/`."""
    if image.parent.name != "images":
        return {}
    copies = {f: image.parent.with_name(f"images_{f}") / image.name for f in PRESCALED}
    return {f: path for f, path in copies.items() if path.is_file()}


def _points(meta: dict, root: Path, notes: list[str]) -> np.ndarray | None:
    """The sparse points of `ply_file_path`, if the file names one and it exists."""
    if not meta.get("ply_file_path"):
        return None
    path = root / meta["ply_file_path"]
    if not path.is_file():
        notes.append(f"{path}: the point cloud ply_file_path names is missing, not used")
        return None
    points = read_ply_points(path)
    notes.append(f"{path}: {len(points)} points")
    return points


def _masks_or_none(frames: list[SourceFrame], path: Path, notes: list[str]) -> list[SourceFrame]:
    """`frames`, without masks when any frame's mask file is missing (a scene is masked or not)."""
    missing = [f.mask_path for f in frames if f.mask_path is not None and not f.mask_path.is_file()]
    if not missing:
        return frames
    log.warning("%s: %d mask file(s) missing (first %s); every mask is left out", path,
                len(missing), missing[0])
    notes.append(f"{len(missing)} mask file(s) missing (first {missing[0]}): no masks used")
    return [replace(f, mask_path=None) for f in frames]
