"""Blender synthetic (NeRF): `transforms_{train,val,test}.json` + RGBA images, OpenGL c2w.

The files carry `camera_angle_x` (a centred pinhole); files written by instant-ngp's and other
tools in the same layout may add any intrinsic of a transforms.json (`fl_x`, `fl_y`, `cx`, `cy`,
`k1`, `k2`, `p1`, `p2`, `w`, `h`, `camera_angle_y`, ...), for the file or per frame: see
scene/intrinsics.py.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.cameras import c2w_matrix
from windowshop.scene.images import image_size
from windowshop.scene.intrinsics import frame_intrinsics, needs_image_size
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import SPLITS


def read_json(path: Path) -> dict:
    """A JSON object from `path`, or a UserError naming the file."""
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise UserError(f"{path}: cannot read the scene description ({err})") from err
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object with a 'frames' list")
    return data


def image_file(root: Path, file_path: str) -> Path:
    """The image a frame's `file_path` names (Blender leaves out the '.png')."""
    path = root / file_path
    if path.suffix.lower() in (".png", ".jpg", ".jpeg", ".exr", ".tif", ".tiff", ".bmp", ".webp"):
        return path
    return path.with_name(path.name + ".png")


def read_blender(root: Path) -> Source:
    """Every split's frames, each with the intrinsics its file (or the frame itself) gives."""
    frames: list[SourceFrame] = []
    size: tuple[int, int] | None = None
    for split in SPLITS:
        meta_path = root / f"transforms_{split}.json"
        if not meta_path.is_file():
            continue
        meta = read_json(meta_path)
        for i, frame in enumerate(meta.get("frames") or []):
            where = f"{meta_path} frame {i}"
            if "file_path" not in frame or "transform_matrix" not in frame:
                raise UserError(f"{where}: every frame needs 'file_path' and 'transform_matrix'")
            path = image_file(root, frame["file_path"])
            if needs_image_size(meta, frame):  # one size for all images (checked on decoding)
                size = size or image_size(path)
            camera, distortion = frame_intrinsics(meta, frame, size, where)
            camera = replace(camera, c2w=c2w_matrix(frame["transform_matrix"], where))
            frames.append(SourceFrame(camera=camera, image_path=path, split=split,
                                      distortion=None if distortion.is_identity else distortion))
    if not frames:
        raise UserError(f"{root}: the transforms_*.json files have an empty frame list")
    # Blender's world is z-up, and the synthetic scenes are modelled upright in it
    return Source(format="blender", path=root, frames=frames, up=np.array([0.0, 0.0, 1.0]))
