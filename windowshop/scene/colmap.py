"""A COLMAP sparse model (cameras, images, points3D; binary or text) read through pycolmap.

COLMAP stores world-to-camera poses in OpenCV axes; images live in `images/` beside `sparse/`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from windowshop.errors import UserError
from windowshop.scene.cameras import opencv_w2c_to_gl_c2w
from windowshop.scene.distortion import Distortion
from windowshop.scene.source import Source, SourceFrame
from windowshop.scene.types import Camera

MIN_TRACK = 3  # points seen by fewer views are too often outliers to bound the object

# model name -> (indices of fx, fy, cx, cy in params, distortion keys in param order after them)
MODELS = {
    "SIMPLE_PINHOLE": ((0, 0, 1, 2), ()),
    "PINHOLE": ((0, 1, 2, 3), ()),
    "SIMPLE_RADIAL": ((0, 0, 1, 2), ("k1",)),
    "RADIAL": ((0, 0, 1, 2), ("k1", "k2")),
    "OPENCV": ((0, 1, 2, 3), ("k1", "k2", "p1", "p2")),
}


def find_model(folder: Path) -> Path | None:
    """The COLMAP model folder at or in `folder` (holding cameras.bin or cameras.txt), if any."""
    for candidate in (folder, folder / "sparse" / "0", folder / "sparse"):
        if (candidate / "cameras.bin").is_file() or (candidate / "cameras.txt").is_file():
            return candidate
    return None


def colmap_camera(camera, c2w: np.ndarray, where: str) -> tuple[Camera, Distortion | None]:
    """Our pinhole Camera and its distortion from a pycolmap.Camera."""
    name = camera.model.name
    if name not in MODELS:
        raise UserError(f"{where}: COLMAP camera model {name} is not supported; use one of "
                        f"{', '.join(MODELS)} or undistort with COLMAP's image_undistorter")
    (ifx, ify, icx, icy), keys = MODELS[name]
    p = np.asarray(camera.params, dtype=np.float64)
    distortion = Distortion(**{k: float(v) for k, v in zip(keys, p[4 if ifx != ify else 3:])})
    cam = Camera(fx=p[ifx], fy=p[ify], cx=p[icx], cy=p[icy], width=int(camera.width),
                 height=int(camera.height), c2w=c2w)
    return cam, None if distortion.is_identity else distortion


def load_model(model_dir: Path):
    """A pycolmap.Reconstruction, or a UserError naming the folder."""
    import pycolmap

    try:
        return pycolmap.Reconstruction(str(model_dir))
    except Exception as err:  # pycolmap raises plain RuntimeError/ValueError for bad files
        raise UserError(f"{model_dir}: cannot read the COLMAP model ({err})") from err


def model_points(reconstruction) -> np.ndarray:
    """(N, 3) points seen by at least MIN_TRACK images."""
    pts = [p.xyz for p in reconstruction.points3D.values() if p.track.length() >= MIN_TRACK]
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def image_folder(model_dir: Path) -> Path:
    """Where the images of a model in `<root>/sparse[/0]` are: `<root>/images`."""
    for parent in (model_dir, *model_dir.parents):
        if (parent / "images").is_dir():
            return parent / "images"
        if parent.name == "sparse":
            return parent.parent / "images"
    return model_dir / "images"


def read_colmap(model_dir: Path) -> Source:
    """One frame per registered image, sorted by name."""
    rec = load_model(model_dir)
    images = sorted((im for im in rec.images.values() if im.has_pose), key=lambda im: im.name)
    if not images:
        raise UserError(f"{model_dir}: the COLMAP model has no registered images (an empty frame list)")
    folder = image_folder(model_dir)
    frames = []
    for image in images:
        where = f"{model_dir} image {image.name}"
        pose = image.cam_from_world  # a method since pycolmap 3.12, a property before
        w2c = (pose() if callable(pose) else pose).matrix()
        c2w = opencv_w2c_to_gl_c2w(w2c[:, :3], w2c[:, 3], where)
        camera, distortion = colmap_camera(rec.cameras[image.camera_id], c2w, where)
        frames.append(SourceFrame(camera=camera, image_path=folder / image.name,
                                  distortion=distortion))
    return Source(format="colmap", path=model_dir, frames=frames, points=model_points(rec))
