"""The intrinsics of one frame of a `transforms*.json` (Blender, instant-ngp, nerfstudio): every
key their producers write, per frame or for the whole file, the frame's own keys winning.

Size: `w`, `h` (else the image's). Focal lengths: `fl_x`, `fl_y` in pixels, or the fields of view
`camera_angle_x`, `camera_angle_y` (radians); one given axis serves both. Principal point: `cx`,
`cy` (else the image centre). Lens: `k1`..`k4`, `p1`, `p2` under `camera_model` OPENCV (or none),
PINHOLE / SIMPLE_PINHOLE, or OPENCV_FISHEYE (also instant-ngp's `is_fisheye`).
"""

from __future__ import annotations

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.distortion import Distortion
from windowshop.scene.types import Camera

DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
SIZE_KEYS = ("w", "h")
CAMERA_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "OPENCV_FISHEYE")


def _focal(levels: list[dict], pixels_key: str, angle_key: str, extent: int) -> float | None:
    """The focal length (pixels) along one axis from the most specific level that gives one."""
    for level in levels:
        if level.get(pixels_key) is not None:
            return float(level[pixels_key])
        if level.get(angle_key) is not None:
            return 0.5 * extent / np.tan(0.5 * float(level[angle_key]))
    return None


def frame_intrinsics(meta: dict, frame: dict, size: tuple[int, int] | None,
                     where: str) -> tuple[Camera, Distortion]:
    """The frame's camera (identity pose) and lens: `frame`'s keys override `meta`'s.

    `size` (width, height) is the image's, used when neither gives `w` and `h` (None: they must).
    """
    levels = [frame, meta]

    def get(key: str):
        return next((level[key] for level in levels if level.get(key) is not None), None)

    model = str(get("camera_model") or "OPENCV").upper()
    if model not in CAMERA_MODELS:
        raise UserError(f"{where}: camera_model {model} is not supported; use one of "
                        f"{', '.join(CAMERA_MODELS)} or undistort the images first")
    if size is None and (get("w") is None or get("h") is None):
        raise UserError(f"{where}: give both 'w' and 'h', or neither (the image's size)")
    width = int(round(get("w") if get("w") is not None else size[0]))
    height = int(round(get("h") if get("h") is not None else size[1]))
    fx = _focal(levels, "fl_x", "camera_angle_x", width)
    fy = _focal(levels, "fl_y", "camera_angle_y", height)
    if fx is None and fy is None:
        raise UserError(f"{where}: no focal length: give 'fl_x' (pixels) or 'camera_angle_x'")
    fx, fy = fx or fy, fy or fx
    cx, cy = get("cx"), get("cy")
    camera = Camera(fx=fx, fy=fy, cx=width / 2 if cx is None else float(cx),
                    cy=height / 2 if cy is None else float(cy), width=width, height=height,
                    c2w=np.eye(4))
    fisheye = model == "OPENCV_FISHEYE" or bool(get("is_fisheye"))
    terms = {k: float(get(k) or 0.0) for k in DISTORTION_KEYS}
    if fisheye and (terms["p1"] or terms["p2"]):
        raise UserError(f"{where}: a fisheye lens has no tangential terms p1, p2")
    return camera, Distortion(**terms, fisheye=fisheye)


def needs_image_size(meta: dict, frame: dict) -> bool:
    """Whether the frame's size must come from its image (neither it nor the file gives w, h)."""
    return not all(frame.get(k) is not None or meta.get(k) is not None for k in SIZE_KEYS)
