"""A COLMAP sparse model (cameras, images, points3D; binary or text) read through pycolmap.

COLMAP stores world-to-camera poses in OpenCV axes; images live in `images/` beside `sparse/`.
The points alone are also read without pycolmap (`read_points`), for a model that lacks its
images file (the poses), as some LLFF downloads ship it.
"""

from __future__ import annotations

import struct
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
    "SIMPLE_RADIAL_FISHEYE": ((0, 0, 1, 2), ("k1",)),
    "RADIAL_FISHEYE": ((0, 0, 1, 2), ("k1", "k2")),
    "OPENCV_FISHEYE": ((0, 1, 2, 3), ("k1", "k2", "k3", "k4")),
}
FILES = ("cameras", "images", "points3D")  # a model's files, each .bin or .txt
POINT_RECORD = struct.Struct("<Q3d3BdQ")  # points3D.bin: id, xyz, rgb, error, track length


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
    distortion = Distortion(**{k: float(v) for k, v in zip(keys, p[4 if ifx != ify else 3:])},
                            fisheye=name.endswith("FISHEYE"))
    cam = Camera(fx=p[ifx], fy=p[ify], cx=p[icx], cy=p[icy], width=int(camera.width),
                 height=int(camera.height), c2w=c2w)
    return cam, None if distortion.is_identity else distortion


def model_file(model_dir: Path, name: str) -> Path | None:
    """`name`.bin or `name`.txt in `model_dir` (the binary one first), if either exists."""
    return next((p for p in (model_dir / f"{name}.bin", model_dir / f"{name}.txt") if p.is_file()), None)


def missing_files(model_dir: Path) -> list[str]:
    """The model files (of FILES) that `model_dir` lacks."""
    return [name for name in FILES if model_file(model_dir, name) is None]


def load_model(model_dir: Path):
    """A pycolmap.Reconstruction, or a UserError naming the folder (and any file it lacks)."""
    import pycolmap

    if missing := missing_files(model_dir):
        raise UserError(f"{model_dir}: the COLMAP model is incomplete: no "
                        f"{' or '.join(f'{m}.bin/.txt' for m in missing)}")
    try:
        return pycolmap.Reconstruction(str(model_dir))
    except Exception as err:  # pycolmap raises plain RuntimeError/ValueError for bad files
        raise UserError(f"{model_dir}: cannot read the COLMAP model ({err})") from err


def model_points(reconstruction) -> np.ndarray:
    """(N, 3) points seen by at least MIN_TRACK images."""
    pts = [p.xyz for p in reconstruction.points3D.values() if p.track.length() >= MIN_TRACK]
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def _points_text(path: Path) -> np.ndarray:
    """(N, 3) from points3D.txt: `ID X Y Z R G B ERROR` then (IMAGE_ID, POINT2D_IDX) pairs."""
    pts = []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and not line.startswith("#") and (len(parts) - 8) // 2 >= MIN_TRACK:
            pts.append([float(v) for v in parts[1:4]])
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def _points_binary(path: Path) -> np.ndarray:
    """(N, 3) from points3D.bin: a uint64 count, then per point its id (uint64), xyz (3 double),
    rgb (3 uint8), error (double), track length (uint64) and that many (int32, int32) pairs."""
    data = path.read_bytes()
    (count,), offset, pts = struct.unpack_from("<Q", data), 8, []
    for _ in range(count):
        _, x, y, z, _, _, _, _, track = POINT_RECORD.unpack_from(data, offset)
        offset += POINT_RECORD.size + 8 * track
        if track >= MIN_TRACK:
            pts.append((x, y, z))
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def read_points(model_dir: Path) -> np.ndarray:
    """(N, 3) points seen by at least MIN_TRACK images, from the model's points3D file alone."""
    path = model_file(model_dir, "points3D")
    if path is None:
        raise UserError(f"{model_dir}: the COLMAP model has no points3D.bin/.txt")
    try:
        return _points_binary(path) if path.suffix == ".bin" else _points_text(path)
    except (OSError, ValueError, struct.error, UnicodeDecodeError) as err:
        raise UserError(f"{path}: cannot read the COLMAP points ({err})") from err


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
