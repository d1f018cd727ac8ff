"""The posed scene on disk: nerfstudio `transforms.json`, `images/`, `masks/`, the COLMAP model.

Each frame keeps its photo's file stem (`images/<stem>.jpg`), so a view traces back to its photo.
Cameras are written in the normalised frame (object at the origin, up = +z, box in [-1, 1]^3); the
`windowshop` key holds the normalising transform from the COLMAP frame and the object box, which
`windowshop.scene.load_scene` reads (see windowshop/scene/nerfstudio.py).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pycolmap
from PIL import Image

from windowshop.photos import orient
from windowshop.scene.cameras import opencv_w2c_to_gl_c2w
from windowshop.scene.nerfstudio import WRITER_KEY
from windowshop.scene.types import Camera

RADIAL_MODELS = {"SIMPLE_RADIAL": ("k1",), "RADIAL": ("k1", "k2")}  # params after f, cx, cy
JPEG_QUALITY = 95


@dataclass
class PosedPhoto:
    """One placed photo: its camera (OpenGL, COLMAP frame until normalised) and lens distortion."""

    name: str  # the photo's stem
    image_name: str  # file name in the SfM image folder
    camera: Camera
    distortion: dict[str, float]  # OpenCV terms (k1, k2), empty for a pinhole


def posed_photos(reconstruction: pycolmap.Reconstruction,
                 turned: frozenset[str] = frozenset()) -> list[PosedPhoto]:
    """The placed images of a COLMAP model as OpenGL cameras, sorted by name; those of the
    `turned` images are the cameras of the photos as taken (windowshop.photos.orient)."""
    out = []
    for image in sorted(reconstruction.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            continue
        cam = reconstruction.cameras[image.camera_id]
        pose = image.cam_from_world()
        c2w = opencv_w2c_to_gl_c2w(pose.rotation.matrix(), pose.translation, image.name)
        camera = Camera(fx=cam.focal_length_x, fy=cam.focal_length_y, cx=cam.principal_point_x,
                        cy=cam.principal_point_y, width=cam.width, height=cam.height, c2w=c2w)
        if image.name in turned:
            camera = orient.photo_camera(camera)
        keys = RADIAL_MODELS.get(cam.model_name, ())
        distortion = {k: float(v) for k, v in zip(keys, list(cam.params)[3:])}
        out.append(PosedPhoto(Path(image.name).stem, image.name, camera, distortion))
    return out


def _intrinsics(photo: PosedPhoto) -> dict:
    cam = photo.camera
    return {"fl_x": cam.fx, "fl_y": cam.fy, "cx": cam.cx, "cy": cam.cy, "w": cam.width,
            "h": cam.height, **photo.distortion}


def write_transforms_json(out_dir: Path, photos: list[PosedPhoto], transform: np.ndarray,
                          aabb: np.ndarray, near_far: tuple[float, float], background: str,
                          masks: bool, source: str) -> Path:
    """Write `transforms.json` for `photos` (cameras already normalised by `transform`)."""
    shared = all(_intrinsics(p) == _intrinsics(photos[0]) for p in photos)
    frames = []
    for p in photos:
        frame = {"file_path": f"images/{p.name}.jpg", "transform_matrix": p.camera.c2w.tolist()}
        if masks:
            frame["mask_path"] = f"masks/{p.name}.png"
        frames.append(frame if shared else {**frame, **_intrinsics(p)})
    meta = {"camera_model": "OPENCV", **(_intrinsics(photos[0]) if shared else {}),
            "frames": frames,
            WRITER_KEY: {"transform": transform.tolist(), "aabb": aabb.tolist(),
                         "near": near_far[0], "far": near_far[1], "background": background,
                         "source": source, "format": "photos"}}
    path = out_dir / "transforms.json"
    path.write_text(json.dumps(meta, indent=2))
    return path


def write_image(out_dir: Path, name: str, pixels: np.ndarray) -> None:
    """`images/<name>.jpg` from (H, W, 3) uint8 pixels."""
    Image.fromarray(pixels).save(out_dir / "images" / f"{name}.jpg", quality=JPEG_QUALITY)


def normalised(photos: list[PosedPhoto], transform: np.ndarray) -> list[PosedPhoto]:
    """The photos with their cameras moved by the similarity `transform` (4, 4)."""
    return [replace(p, camera=p.camera.transformed(transform)) for p in photos]
