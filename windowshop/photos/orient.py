"""One lens held both ways: photos of one camera taken in portrait and in landscape, turned a
quarter so that structure from motion sees them all in one shape and fits one set of
intrinsics to all of them.

A phone's portrait and landscape photos (upright once their EXIF orientation is applied) come
from one sensor and lens, but differ in shape, and COLMAP gives each shape, and so each photo,
a camera of its own (CameraMode.PER_IMAGE): a focal length and a distortion per photo, which
few photos cannot pin down. fruit's 81 photos, every other one given as landscape: the focal
lengths came out at 418-544 px (truth 498), and 20 of them made a turntable whose held-out
PSNR in the mask was anywhere from 11.6 to 20.2 dB over four runs, 17.9-18.0 with one camera
(bench/RESULTS.md, stop 54). Turned a quarter (np.rot90, counter-clockwise),
a landscape photo is what the same camera rolled by 90 degrees would have taken in portrait:
COLMAP's camera keeps its principal point at the image centre and its distortion radial, both
unchanged by the turn, so one camera serves every photo exactly.

Only structure from motion sees the turned photos (the SfM image folder, its database and
models). What meets the photos themselves is turned back here: a keypoint's pixel
(`photo_xy`), a placed camera (`photo_camera`), and going the other way a vector in the
camera's frame (`sfm_vector`, the phone's gravity) and a pose guessed for the photo
(`sfm_c2w`, the ring's).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np

from windowshop.scene.types import Camera


def turned_names(photos: list) -> frozenset[str]:
    """Image file names (`<name>.jpg`) of the photos to turn: those whose camera (EXIF make, model
    and focal length; `Photo.camera_key` without its size) took most of the photos in the other
    orientation (landscape ones when it took as many each way), with the shape of those turned
    (H, W) -> (W, H)."""
    shapes: dict[tuple, Counter] = {}
    for p in photos:
        shapes.setdefault(p.camera_key[:3], Counter())[p.pixels.shape[:2]] += 1
    turned = set()
    for p in photos:
        counts = shapes[p.camera_key[:3]]
        height, width = p.pixels.shape[:2]
        other, mine = counts[(width, height)], counts[(height, width)]
        if other > mine or (other == mine and width > height):  # a tie: landscape turned
            turned.add(f"{p.name}.jpg")
    return frozenset(turned)


def sfm_key(photo, turned: bool) -> tuple:
    """What the photos that share one camera in structure from motion share, as it sees them:
    the camera key (its last entry the original size, which a cropped photo changes) and the
    working shape."""
    key, shape = tuple(photo.camera_key), photo.pixels.shape[:2]
    if not turned:
        return key, shape
    return (*key[:3], tuple(key[3])[::-1]), shape[::-1]


def for_sfm(pixels: np.ndarray) -> np.ndarray:
    """(H, W, ...) -> (W, H, ...): the photo turned a quarter counter-clockwise."""
    return np.ascontiguousarray(np.rot90(pixels, 1))


def photo_xy(xy: np.ndarray, photo_width: int) -> np.ndarray:
    """(K, 2) pixel coordinates in a turned photo (COLMAP's: pixel centres at +0.5) -> the same
    points in the photo as taken, `photo_width` wide: np.rot90 puts the photo's (u, v) at
    (v, W - u)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.stack([photo_width - xy[:, 1], xy[:, 0]], axis=1)


def photo_camera(camera: Camera) -> Camera:
    """The OpenGL camera structure from motion found for a turned photo -> the camera of the
    photo as taken: its image axes turned back a quarter about the optical axis (the turned
    image's right is the photo's down, its up the photo's right) and its intrinsics swapped."""
    c2w = camera.c2w.copy()
    c2w[:3, 0], c2w[:3, 1] = camera.c2w[:3, 1], -camera.c2w[:3, 0]
    return replace(camera, c2w=c2w, fx=camera.fy, fy=camera.fx, cx=camera.height - camera.cy,
                   cy=camera.cx, width=camera.height, height=camera.width)


def sfm_c2w(c2w: np.ndarray) -> np.ndarray:
    """An OpenGL camera-to-world (4, 4) of the photo as taken -> that of its turned image (the
    inverse of `photo_camera`'s turn)."""
    out = c2w.copy()
    out[:3, 0], out[:3, 1] = -c2w[:3, 1], c2w[:3, 0]
    return out


def sfm_vector(vector: np.ndarray) -> np.ndarray:
    """A direction in the photo's camera frame (OpenCV axes: x right, y down, z forward) -> in the
    turned photo's, whose right is the photo's down and whose down is the photo's left."""
    x, y, z = np.asarray(vector, dtype=np.float64)
    return np.array([y, -x, z])
