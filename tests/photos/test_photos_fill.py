"""Photos structure from motion left over, placed with the known-turntable prior, on a synthetic
ring of 8 cameras around a cloud of points: one by PnP against the model's points, one from a
placed neighbour's relative pose and the ring, the rest by shooting order."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from windowshop.photos import fill
from windowshop.photos.output import posed_photos
from windowshop.photos.ring import Ring
from windowshop.scene.cameras import CV_TO_GL

RING = Ring(centre=np.zeros(3), axis=np.array([0.0, 0.0, 1.0]), radius=4.0, height=1.0)
COUNT, PLACED = 8, (0, 1, 2, 3)
PNP, PAIRED = 4, 7  # 7 is the neighbour of 0 across the wrap: placed from it
WIDTH, HEIGHT, FOCAL = 640, 480, 500.0


def _w2c(index: int) -> np.ndarray:
    """(3, 4) OpenCV world-to-camera of the ring's photo `index` (45 degrees apart)."""
    return np.linalg.inv(RING.camera(np.radians(45.0 * index)) @ CV_TO_GL)[:3, :4]


def _project(w2c: np.ndarray, points: np.ndarray) -> np.ndarray:
    cam = points @ w2c[:, :3].T + w2c[:, 3]
    return FOCAL * cam[:, :2] / cam[:, 2:] + [WIDTH / 2, HEIGHT / 2]


def _essential(w2c1: np.ndarray, w2c2: np.ndarray) -> np.ndarray:
    rot = w2c2[:, :3] @ w2c1[:, :3].T
    t = w2c2[:, 3] - rot @ w2c1[:, 3]
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ rot


def _camera() -> pycolmap.Camera:
    return pycolmap.Camera(model="SIMPLE_PINHOLE", width=WIDTH, height=HEIGHT,
                           params=[FOCAL, WIDTH / 2, HEIGHT / 2], camera_id=1)


def _verified(matches: np.ndarray) -> pycolmap.TwoViewGeometry:
    """The calibrated geometry of photos 0 and PAIRED with inlier `matches` (M, 2)."""
    geometry = pycolmap.TwoViewGeometry()
    geometry.config = pycolmap.TwoViewGeometryConfiguration.CALIBRATED
    geometry.E = _essential(_w2c(0), _w2c(PAIRED))
    geometry.inlier_matches = matches
    return geometry


def _scene(tmp_path):
    """(model with photos PLACED and their points, database, image names in shooting order)."""
    rng = np.random.default_rng(0)
    seen = rng.uniform(-1, 1, (200, 3))  # the model's points
    unseen = rng.uniform(-1, 1, (60, 3))  # points only photos 0 and PAIRED see
    camera = _camera()
    model = pycolmap.Reconstruction()
    model.add_camera_with_trivial_rig(camera)
    names = [f"{i:02d}.jpg" for i in range(COUNT)]
    database = tmp_path / "database.db"
    with pycolmap.Database.open(database) as db:
        db.write_camera(camera, use_camera_id=True)
        for i, name in enumerate(names):
            points = np.concatenate([seen, unseen]) if i in (0, PAIRED) else seen
            keypoints = _project(_w2c(i), points)
            image_id = db.write_image(pycolmap.Image(name=name, camera_id=1, image_id=i + 1),
                                      use_image_id=True)
            db.write_keypoints(image_id, np.hstack([keypoints, np.zeros((len(points), 4))])
                               .astype(np.float32))
            if i in PLACED:
                model.add_image_with_trivial_frame(
                    pycolmap.Image(name=name, keypoints=keypoints, camera_id=1,
                                   image_id=image_id), pycolmap.Rigid3d(matrix=_w2c(i)))
        same = np.stack([np.arange(len(seen))] * 2, axis=1)
        for i in PLACED:
            db.write_matches(i + 1, PNP + 1, same)
        db.write_two_view_geometry(1, PAIRED + 1, _verified(np.stack(
            [np.arange(len(seen), len(seen) + len(unseen))] * 2, axis=1)))
    for k, xyz in enumerate(seen):
        track = pycolmap.Track()
        for i in PLACED:
            track.add_element(i + 1, k)
        point_id = model.add_point3D(xyz, track)
        for i in PLACED:
            model.images[i + 1].set_point3D_for_point2D(k, point_id)
    return model, database, names


def test_leftover_photos_are_measured_paired_or_guessed(tmp_path):
    model, database, names = _scene(tmp_path)
    filled = fill.fill(model, database, names, seed=0)
    assert filled.measured == [names[PNP]]
    assert filled.paired == [names[PAIRED]]
    assert filled.guessed == [names[5], names[6]]
    poses = {p.image_name: p.camera.c2w for p in posed_photos(model)}
    assert sorted(poses) == names
    for i, name in enumerate(names):  # the synthetic ring is perfect: every way lands exactly
        truth = RING.camera(np.radians(45.0 * i))
        assert np.allclose(poses[name][:3, 3], truth[:3, 3], atol=1e-3), name
        assert np.allclose(poses[name][:3, :3], truth[:3, :3], atol=1e-3), name


def test_without_guessing_the_rest_stay_unplaced(tmp_path):
    model, database, names = _scene(tmp_path)
    filled = fill.fill(model, database, names, seed=0, guess=False)
    assert filled.guessed == [] and filled.paired == [names[PAIRED]]
    poses = {p.image_name for p in posed_photos(model)}
    assert names[5] not in poses and names[6] not in poses


def test_a_pose_off_the_ring_is_refused():
    on = RING.camera(0.3)
    assert fill.on_ring(RING, on)
    far = on.copy()
    far[:3, 3] *= 2.0  # twice as far from the centre, still looking at it
    turned = on @ np.diag([-1.0, 1.0, -1.0, 1.0])  # on the ring, looking away
    assert not fill.on_ring(RING, far) and not fill.on_ring(RING, turned)


def test_fill_needs_three_placed(tmp_path):
    model, database, names = _scene(tmp_path)
    for image_id in (3, 4):  # leaves 2 placed
        model.deregister_frame(image_id)
    assert fill.fill(model, database, names, seed=0) == fill.Filled()
    assert model.num_reg_images() == 2


@pytest.mark.parametrize("seed", range(12))
def test_a_pairs_pose_reads_each_match_by_its_own_features(tmp_path, seed):
    """The verified matches index each image's whole feature list (pycolmap reads them by
    index): with features neither photo shares listed first and photo 7's in a shuffled order,
    the pair (0, 7) gives the true relative pose."""
    rng = np.random.default_rng(seed)
    shared, own = rng.uniform(-1, 1, (40, 3)), rng.uniform(-1, 1, (100, 3))
    order = rng.permutation(len(shared))  # photo 7's shared feature k shows point order[k]
    camera = _camera()
    database = tmp_path / "database.db"
    with pycolmap.Database.open(database) as db:
        db.write_camera(camera, use_camera_id=True)
        for image_id, index, points in ((1, 0, np.concatenate([own, shared])),
                                        (2, PAIRED, np.concatenate([own[::-1], shared[order]]))):
            keypoints = _project(_w2c(index), points)
            db.write_image(pycolmap.Image(name=f"{index:02d}.jpg", camera_id=1,
                                          image_id=image_id), use_image_id=True)
            db.write_keypoints(image_id, np.hstack([keypoints, np.zeros((len(points), 4))])
                               .astype(np.float32))
        db.write_two_view_geometry(1, 2, _verified(
            len(own) + np.stack([order, np.arange(len(shared))], axis=1)))
        rotation, direction, inliers = fill._relative(db, 1, 2, (camera, camera))
    first, second = _w2c(0), _w2c(PAIRED)
    truth = second[:, :3] @ first[:, :3].T  # photo 7's camera from photo 0's
    centre = first[:, :3] @ (-second[:, :3].T @ second[:, 3]) + first[:, 3]  # in 0's axes
    assert inliers == len(shared)
    assert np.allclose(rotation, truth, atol=1e-6)
    assert np.allclose(direction, centre / np.linalg.norm(centre), atol=1e-6)
