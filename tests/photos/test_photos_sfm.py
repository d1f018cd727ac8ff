"""Structure from motion pieces: matching in chunks that advance a progress bar, and poses from
8 wide-baseline photos of dtu_skull against the dataset's own cameras."""

from __future__ import annotations

from itertools import combinations

import cv2
import numpy as np
import pycolmap
import pytest

from windowshop.photos import sfm
from windowshop.photos.align import rotation_angle
from windowshop.photos.ingest import Dropped, read_photos
from windowshop.photos.output import write_image
from windowshop.photos.progress import Stages
from shared_data import DATA

# 8 of dtu_skull's 49 views spread evenly in azimuth over its ~100 degree arc (steps of about
# 13 degrees), as bench/bench_fewphoto.py picks them
SKULL_VIEWS = (5, 8, 10, 21, 24, 27, 33, 41)
MAX_ROTATION_DEG = 3.0  # relative rotations of every placed pair against the dataset's


def _images(tmp_path, paths, max_side=640):
    photos = read_photos(paths, max_side, Dropped())
    (tmp_path / "images").mkdir()
    for photo in photos:
        write_image(tmp_path, photo.name, photo.pixels)
    return tmp_path / "images", [f"{p.name}.jpg" for p in photos]


def test_matching_advances_progress_and_verifies_every_pair(tmp_path, monkeypatch):
    image_dir, names = _images(tmp_path, sorted((DATA / "kermit").glob("*.jpg"))[:5], 320)
    names = names[:4]  # four neighbours, every pair of them matched (five is the least read)
    settings = sfm.SfmSettings()
    database = tmp_path / "database.db"
    sfm.extract(database, image_dir, names, settings, False, lambda n=1: None)
    pairs = list(combinations(names, 2))
    events = []
    stages = Stages(on_stage=lambda stage, fraction: events.append(fraction), show=False,
                    fractions={"matching": 1.0})
    monkeypatch.setattr(sfm, "MATCH_CHUNK", 2)
    with stages.stage("matching", len(pairs)) as advance:
        sfm.match(database, tmp_path, pairs, settings, False, advance)
    assert len(events) == 2 + len(pairs) // 2  # start, a report per chunk of 2 pairs, end
    assert events == sorted(events) and events[0] == 0.0 and events[-1] == 1.0
    with pycolmap.Database.open(database) as db:
        assert len(db.read_two_view_geometry_num_inliers()[0]) >= len(pairs) - 1


def _skull_rotations() -> dict[str, np.ndarray]:
    """View name -> world-to-camera rotation (3, 3) from the dataset's projection matrices."""
    cams = np.load(DATA / "dtu_skull" / "cameras_sphere.npz")
    return {f"{i:03d}": cv2.decomposeProjectionMatrix(cams[f"world_mat_{i}"][:3])[1]
            for i in SKULL_VIEWS}


@pytest.mark.slow
def test_eight_wide_baseline_skull_photos_are_placed_right(tmp_path):
    paths = [DATA / "dtu_skull" / "images" / f"{i:03d}.jpg" for i in SKULL_VIEWS]
    image_dir, names = _images(tmp_path, paths)
    result = sfm.reconstruct(image_dir, names, tmp_path, sfm.SfmSettings(), Stages(show=False))
    assert len(result.placed) >= 7, result.attempts
    assert result.matcher == "exhaustive" and result.pairs == 28
    truth = _skull_rotations()
    got = {im.name[:-4]: im.cam_from_world().rotation.matrix()
           for im in result.reconstruction.images.values() if im.has_pose}
    errors = {(a, b): rotation_angle((got[a] @ got[b].T).T @ (truth[a] @ truth[b].T))
              for a, b in combinations(sorted(got), 2)}
    assert max(errors.values()) < MAX_ROTATION_DEG, errors


def test_large_sets_keep_fewer_features_a_photo():
    from windowshop.photos.sfm import FEATURE_BUDGET, MIN_FEATURES, features_per_photo

    assert features_per_photo(8) == 8192 and features_per_photo(20) == 8192  # COLMAP's own cap
    assert features_per_photo(88) == FEATURE_BUDGET // 88 < 8192
    assert features_per_photo(1000) == MIN_FEATURES


def test_a_long_walk_is_mapped_from_every_other_photo_then_grown(tmp_path, monkeypatch):
    # 16 consecutive dtu_skull views (steps of about 2 degrees) as a "long" walk of more than 8
    monkeypatch.setattr(sfm, "LONG_WALK", 8)
    mapped = []
    real = sfm.map_once
    monkeypatch.setattr(sfm, "map_once", lambda *a, **k: mapped.append(k.get("only")) or real(*a, **k))
    paths = [DATA / "dtu_skull" / "images" / f"{i:03d}.jpg" for i in range(20, 36)]
    image_dir, names = _images(tmp_path, paths, max_side=320)
    result = sfm.reconstruct(image_dir, names, tmp_path, sfm.SfmSettings(), Stages(show=False))
    assert mapped[0] == names[::2] and mapped[1] is None  # half first, then all of them
    assert len(result.placed) == 16, result.attempts
    truth = {f"{i:03d}": cv2.decomposeProjectionMatrix(np.load(
        DATA / "dtu_skull" / "cameras_sphere.npz")[f"world_mat_{i}"][:3])[1] for i in range(20, 36)}
    got = {im.name[:-4]: im.cam_from_world().rotation.matrix()
           for im in result.reconstruction.images.values() if im.has_pose}
    errors = [rotation_angle((got[a] @ got[b].T).T @ (truth[a] @ truth[b].T))
              for a, b in combinations(sorted(got), 2)]
    assert max(errors) < MAX_ROTATION_DEG


def test_sift_starts_from_the_photos_own_size_only_where_they_are_rich_in_features(tmp_path):
    from windowshop.scene.products import figure_on_granite

    # a plain figure on a granite table, 13 photos of 640x480: the table gives ~1,400 features
    # a photo at their own size; fruit's photos 300-650, so SIFT doubles them
    granite = figure_on_granite(tmp_path / "granite", count=13, size=(640, 480)) / "images"
    names = sorted(p.name for p in granite.glob("*.jpg"))
    assert sfm.first_octave(tmp_path / "g.db", granite, names, sfm.SfmSettings()) == 0
    fruit = sorted((DATA / "fruit" / "newfruit_small").glob("*.jpg"))[::6][:13]
    (tmp_path / "fruit").mkdir()
    image_dir, fruit_names = _images(tmp_path / "fruit", fruit)
    assert sfm.first_octave(tmp_path / "f.db", image_dir, fruit_names, sfm.SfmSettings()) == -1
    assert sfm.first_octave(tmp_path / "s.db", granite, names[:12], sfm.SfmSettings()) == -1  # a few photos
    assert not list(tmp_path.glob("*_octave.db"))  # the scratch database is gone


def _extracted(database, image_dir, names):
    for name in names:  # one call a photo: written in this order
        pycolmap.extract_features(database, image_dir, image_names=[name],
                                  camera_mode=pycolmap.CameraMode.PER_IMAGE,
                                  device=pycolmap.Device.cpu)


def _mapped(database, image_dir, names, out):
    settings = sfm.SfmSettings()
    sfm.match(database, out.parent, list(combinations(names, 2)), settings, False,
              lambda n=1: None)
    model = sfm.map_once(database, image_dir, out, settings, False, lambda n=1: None)
    return {im.name: im.cam_from_world().matrix() for im in model.images.values() if im.has_pose}


def test_images_are_numbered_in_the_order_given_whatever_order_their_features_came(tmp_path):
    # features written last photo first, as extraction's threads may finish them: renumbered,
    # every photo keeps its own features and camera, and the mapper builds the very model it
    # builds from the photos written in order
    image_dir, names = _images(tmp_path, sorted((DATA / "kermit").glob("*.jpg"))[:5], 320)
    (tmp_path / "given").mkdir()
    (tmp_path / "reversed").mkdir()
    given, backwards = tmp_path / "given" / "database.db", tmp_path / "reversed" / "database.db"
    _extracted(given, image_dir, names)
    _extracted(backwards, image_dir, names[::-1])
    with pycolmap.Database.open(backwards) as db:
        before = {im.name: (im.camera_id, db.read_keypoints(im.image_id))
                  for im in db.read_all_images()}
        assert [im.name for im in db.read_all_images()] != names
        sfm.in_given_order(db, names)
    with pycolmap.Database.open(backwards) as db:
        images = sorted(db.read_all_images(), key=lambda im: im.image_id)
        assert [(im.image_id, im.name) for im in images] == list(enumerate(names, start=1))
        for im in images:
            assert im.camera_id == before[im.name][0]
            assert np.array_equal(db.read_keypoints(im.image_id), before[im.name][1])
            assert {(d.sensor_id.id, d.id) for d in db.read_frame(im.frame_id).data_ids} == {
                (im.camera_id, im.image_id)}
    expected = _mapped(given, image_dir, names, tmp_path / "given" / "sparse")
    got = _mapped(backwards, image_dir, names, tmp_path / "reversed" / "sparse")
    assert len(got) >= 4 and got.keys() == expected.keys()
    for name, pose in got.items():
        assert np.allclose(pose, expected[name], atol=1e-6), name
