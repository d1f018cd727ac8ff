"""nerfstudio / instant-ngp `transforms.json`: OpenGL c2w per frame, intrinsics global or per
frame (`fl_x fl_y cx cy w h`, or `camera_angle_x`), OpenCV distortion, optional `mask_path`,
optional `{train,val,test}_filenames` splits."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.blender import image_file, read_json
from windowshop.scene.cameras import c2w_matrix
from windowshop.scene.distortion import Distortion
from windowshop.scene.images import image_size
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import SPLITS, Camera

DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
SIZE_KEYS = ("w", "h", "fl_x", "fl_y", "cx", "cy", "camera_angle_x")
WRITER_KEY = "windowshop"  # extra key our writer adds: normalisation, box and background


def _intrinsics(meta: dict, frame: dict, size: tuple[int, int], where: str) -> tuple[Camera, Distortion]:
    """The frame's camera (identity pose) and distortion: per-frame keys override global ones.

    `size` (width, height) is used when neither the frame nor the file gives `w` and `h`.
    """
    def get(key: str):
        return frame.get(key, meta.get(key))

    if get("camera_model") == "OPENCV_FISHEYE" or get("is_fisheye"):
        raise UserError(f"{where}: fisheye cameras are not supported; undistort the images "
                        f"(e.g. with COLMAP's image_undistorter) and pass the pinhole result")
    width = int(round(get("w") or size[0]))
    height = int(round(get("h") or size[1]))
    fx = get("fl_x")
    if fx is None:
        if get("camera_angle_x") is None:
            raise UserError(f"{where}: no focal length: give 'fl_x' (pixels) or 'camera_angle_x'")
        fx = 0.5 * width / np.tan(0.5 * float(get("camera_angle_x")))
    fy = get("fl_y") or fx
    cx, cy = get("cx"), get("cy")
    camera = Camera(fx=float(fx), fy=float(fy), cx=width / 2 if cx is None else float(cx),
                    cy=height / 2 if cy is None else float(cy), width=width, height=height,
                    c2w=np.eye(4))
    return camera, Distortion(**{k: float(get(k) or 0.0) for k in DISTORTION_KEYS})


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
        if any(k in frame for k in ("w", "h")):
            size = (0, 0)
        else:  # global intrinsics: one image size for all (a mismatch is reported on decoding)
            global_size = global_size or image_size(image)
            size = global_size
        camera, distortion = _intrinsics(meta, frame, size, f"{where} ({image.name})")
        mask = root / frame["mask_path"] if frame.get("mask_path") else None
        frames.append(SourceFrame(
            camera=replace(camera, c2w=c2w_matrix(frame["transform_matrix"], where)),
            image_path=image, split=splits.get(os.path.normpath(frame["file_path"])),
            distortion=None if distortion.is_identity else distortion, mask_path=mask))
    extra = meta.get(WRITER_KEY) or {}
    box = np.asarray(extra["aabb"], dtype=np.float64) if "aabb" in extra else None
    return Source(format="nerfstudio", path=path, frames=frames, box=box,
                  background=extra.get("background"), normalized="transform" in extra)
