"""Photos structure from motion left over, when a few photos were taken on a ring (the
known-turntable prior, windowshop.photos.ring). Each is placed, in this order of preference:
1. "measured": by PnP against the model's sparse points its features match, kept if that pose
   lies on the placed cameras' ring (on bench_fewphoto's sets the sparse points are too few:
   16-36 matches, 5-9 inliers, so this never fires there);
2. "paired": from a placed neighbour it shares MIN_PAIR_INLIERS verified matches with: the
   pair's relative rotation (measured), its centre where the pair's baseline meets the ring
   (the prior sets only the distance); several such neighbours must agree; a photo so placed can
   be the next one's neighbour;
3. "guessed": on the ring between its placed neighbours in shooting order, looking at the centre
   (only when asked: sfm.SfmSettings.ring_guess).
The report names the photos placed by 2 and 3 as estimated from the ring, not measured.

Only for sets of at most sfm.WIDE_MAX_PHOTOS with MIN_PLACED or more placed; the model is
changed in place.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np
import pycolmap

from windowshop.photos import orient
from windowshop.photos.align import rotation_angle
from windowshop.photos.output import posed_photos
from windowshop.photos.ring import MIN_PLACED, Ring, fit_ring, guess_poses
from windowshop.scene.cameras import CV_TO_GL, opencv_w2c_to_gl_c2w

# PnP on raw (unverified) matches: most are wrong, so RANSAC looks for few inliers among many
PNP_MAX_ERROR = 8.0  # pixels
PNP_MIN_INLIERS = 15
PNP_MIN_INLIER_RATIO = 0.05
MIN_PAIR_INLIERS = 30  # verified matches a pair needs to place a photo from its neighbour
PAIR_AGREE_DEG = 10.0  # the rotations several such pairs give a photo must agree this well
# A PnP pose is kept only where the ring allows it: its distance from the axis within this share
# of the radius, its height within this share of the radius, looking this close to the centre
RING_RADIUS_SHARE = 0.3
RING_VIEW_DEG = 20.0


@dataclass
class Filled:
    measured: list[str] = field(default_factory=list)  # image names registered by PnP
    # rotation and direction from a placed neighbour, the distance from the ring
    paired: list[str] = field(default_factory=list)
    guessed: list[str] = field(default_factory=list)  # put on the ring by shooting order


def _correspondences(model: pycolmap.Reconstruction, db: pycolmap.Database, image_id: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(pixels (M, 2), points (M, 3)): the image's features matched to features of placed images
    that have a sparse point."""
    keypoints = db.read_keypoints(image_id)[:, :2].astype(np.float64)
    pixels, points = [], []
    for other in model.reg_image_ids():
        if not db.exists_matches(image_id, other):
            continue
        seen = model.images[other].points2D
        for mine, theirs in db.read_matches(image_id, other):
            point = seen[int(theirs)]
            if point.has_point3D():
                pixels.append(keypoints[mine])
                points.append(model.points3D[point.point3D_id].xyz)
    return np.array(pixels).reshape(-1, 2), np.array(points).reshape(-1, 3)


def on_ring(ring: Ring, c2w: np.ndarray) -> bool:
    """True when the OpenGL camera-to-world `c2w` (4, 4) could be a photo of the ring: near
    its circle and looking at its centre."""
    offset = c2w[:3, 3] - ring.centre
    along = offset @ ring.axis
    across = float(np.linalg.norm(offset - along * ring.axis))
    to_centre = -offset / np.linalg.norm(offset)
    view = float(np.degrees(np.arccos(np.clip(-c2w[:3, 2] @ to_centre, -1.0, 1.0))))
    return (abs(across - ring.radius) <= RING_RADIUS_SHARE * ring.radius
            and abs(along - ring.height) <= RING_RADIUS_SHARE * ring.radius
            and view <= RING_VIEW_DEG)


def register(model: pycolmap.Reconstruction, db: pycolmap.Database, image_id: int,
             camera: pycolmap.Camera, ring: Ring, seed: int) -> pycolmap.Rigid3d | None:
    """The image's pose (camera from world) by PnP against the model's points, if it has
    enough inliers and lies on the ring; else None."""
    pixels, points = _correspondences(model, db, image_id)
    if len(pixels) < PNP_MIN_INLIERS:
        return None
    options = pycolmap.AbsolutePoseEstimationOptions()
    options.ransac.max_error = PNP_MAX_ERROR
    options.ransac.min_inlier_ratio = PNP_MIN_INLIER_RATIO
    options.ransac.random_seed = seed
    found = pycolmap.estimate_and_refine_absolute_pose(pixels, points, camera, options)
    if found is None or found["num_inliers"] < PNP_MIN_INLIERS:
        return None
    pose = found["cam_from_world"]
    c2w = opencv_w2c_to_gl_c2w(pose.rotation.matrix(), pose.translation, "pnp")
    return pose if on_ring(ring, c2w) else None


def _cam_from_world(c2w: np.ndarray) -> pycolmap.Rigid3d:
    """COLMAP's world-to-camera (OpenCV axes) of an OpenGL camera-to-world (4, 4)."""
    return pycolmap.Rigid3d(matrix=np.linalg.inv(c2w @ CV_TO_GL)[:3, :4])


def _add(model: pycolmap.Reconstruction, db: pycolmap.Database, image_id: int,
         pose: pycolmap.Rigid3d) -> None:
    """Add the database's image `image_id` to the model with `pose`, its features as points."""
    image = db.read_image(image_id)
    if not model.exists_camera(image.camera_id):  # per-photo cameras: not refined, as read
        model.add_camera_with_trivial_rig(db.read_camera(image.camera_id))
    keypoints = db.read_keypoints(image_id)[:, :2].astype(np.float64)
    model.add_image_with_trivial_frame(
        pycolmap.Image(name=image.name, keypoints=keypoints, camera_id=image.camera_id,
                       image_id=image_id), pose)


def _relative(db: pycolmap.Database, placed_id: int, image_id: int,
              cameras: tuple[pycolmap.Camera, pycolmap.Camera]
              ) -> tuple[np.ndarray, np.ndarray, int] | None:
    """(rotation (3, 3), unit direction (3,) to the image's centre, both in the placed image's
    camera axes (OpenCV), inliers) from the pair's verified matches; None under MIN_PAIR_INLIERS
    (most pairs of a few wide photos pass verification by chance with 10-20 inliers)."""
    if not db.exists_two_view_geometry(placed_id, image_id):
        return None
    geometry = db.read_two_view_geometry(placed_id, image_id)
    matches = geometry.inlier_matches
    if len(matches) < MIN_PAIR_INLIERS:
        return None
    # pycolmap reads the inliers' features by index: it needs each image's whole keypoint list
    keypoints = [db.read_keypoints(i)[:, :2].astype(np.float64) for i in (placed_id, image_id)]
    if not pycolmap.estimate_two_view_geometry_pose(cameras[0], keypoints[0], cameras[1],
                                                     keypoints[1], geometry):
        return None
    pose = geometry.cam2_from_cam1  # image from placed
    rotation = pose.rotation.matrix()
    direction = -rotation.T @ pose.translation  # the image's centre, placed camera's axes
    return rotation, direction / np.linalg.norm(direction), len(matches)


def _agree(rotations: list[np.ndarray]) -> bool:
    """True when the rotations (3, 3) that several pairs give one photo agree (a wrong relative
    pose, e.g. a mirrored one, rarely agrees with another)."""
    return all(rotation_angle(a.T @ b) <= PAIR_AGREE_DEG for a, b in combinations(rotations, 2))


def _ray_to_ring(ring: Ring, origin: np.ndarray, direction: np.ndarray) -> np.ndarray | None:
    """The point farthest along the ray from `origin` (on the ring) where it meets the ring's
    cylinder (distance ring.radius from the axis), or None if it never does ahead."""
    def flat(v):
        return v - (v @ ring.axis) * ring.axis

    start, step = flat(origin - ring.centre), flat(direction)
    a, b, c = step @ step, 2 * start @ step, start @ start - ring.radius**2
    if a < 1e-12 or b * b - 4 * a * c < 0:
        return None
    far = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    return origin + far * direction if far > 0 else None


def from_neighbour(model: pycolmap.Reconstruction, db: pycolmap.Database, image_id: int,
                   camera: pycolmap.Camera, ring: Ring) -> pycolmap.Rigid3d | None:
    """The image's pose from its best-matched placed image: the pair's relative rotation
    (measured), its centre where the pair's baseline meets the ring (the prior sets the scale);
    None without such a pair, or if the camera would not look at the ring's centre."""
    found = []  # (placed image, (rotation, direction, inliers)) for each good pair
    for other in model.reg_image_ids():
        placed = model.images[other]
        pair = _relative(db, other, image_id, (placed.camera, camera))
        if pair is not None:
            found.append((placed, pair))
    if not found or not _agree([p[1][0] @ p[0].cam_from_world().rotation.matrix()
                                for p in found]):
        return None
    placed, (rotation, direction, _) = max(found, key=lambda p: p[1][2])
    world_from_placed = placed.cam_from_world().inverse()
    centre = _ray_to_ring(ring, world_from_placed.translation,
                          world_from_placed.rotation.matrix() @ direction)
    if centre is None:
        return None
    cam_rotation = rotation @ placed.cam_from_world().rotation.matrix()
    pose = pycolmap.Rigid3d(matrix=np.hstack([cam_rotation, (-cam_rotation @ centre)[:, None]]))
    c2w = opencv_w2c_to_gl_c2w(cam_rotation, pose.translation, "pair")
    return pose if on_ring(ring, c2w) else None


def _camera(model: pycolmap.Reconstruction, db: pycolmap.Database, image_id: int
            ) -> pycolmap.Camera:
    camera_id = db.read_image(image_id).camera_id
    return model.cameras[camera_id] if model.exists_camera(camera_id) else db.read_camera(camera_id)


def fill(model: pycolmap.Reconstruction, database: Path, names: list[str], seed: int,
         guess: bool = True, turned: frozenset[str] = frozenset()) -> Filled:
    """Place the images of `names` (shooting order) that `model` lacks: by PnP, else from a
    placed neighbour and the ring, else (when `guess`) on the ring by shooting order (see the
    module docstring). Nothing happens with fewer than MIN_PLACED placed. A guess for one of the
    `turned` images (windowshop.photos.orient) is turned with it."""
    placed = {p.image_name: p.camera.c2w for p in posed_photos(model)}
    filled = Filled()
    if len(placed) < MIN_PLACED or len(placed) == len(names):
        return filled
    ring = fit_ring(np.stack(list(placed.values())))
    with pycolmap.Database.open(database) as db:
        ids = {image.name: image.image_id for image in db.read_all_images()}
        missing = [n for n in names if n not in placed]
        # PnP against the SfM model's points only, before anything is added to it
        poses = {n: register(model, db, ids[n], _camera(model, db, ids[n]), ring, seed)
                 for n in missing}
        for name in [n for n in missing if poses[n] is not None]:
            filled.measured.append(name)
            _add(model, db, ids[name], poses[name])
        grown = True
        while grown:  # a photo placed from its neighbour can be the next one's neighbour
            grown = False
            for name in [n for n in missing if poses[n] is None]:
                poses[name] = from_neighbour(model, db, ids[name], _camera(model, db, ids[name]),
                                             ring)
                if poses[name] is not None:
                    filled.paired.append(name)
                    _add(model, db, ids[name], poses[name])
                    grown = True
        rest = [n for n in missing if poses[n] is None]
        if rest and guess:
            known = {names.index(p.image_name): p.camera.c2w for p in posed_photos(model)}
            guesses = guess_poses(known, len(names))
            for name in rest:
                filled.guessed.append(name)
                c2w = guesses[names.index(name)]
                _add(model, db, ids[name],
                     _cam_from_world(orient.sfm_c2w(c2w) if name in turned else c2w))
    return filled
