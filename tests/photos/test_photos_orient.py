"""Photos of one lens held both ways: structure from motion sees them turned to one shape, and what
it finds comes back to the photos as taken (windowshop.photos.orient)."""

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from shared_data import DATA
from windowshop.config import PrepareOptions
from windowshop.photos import orient
from windowshop.photos.align import pose_errors
from windowshop.photos.ingest import Inputs, Photo
from windowshop.photos.prepare import _settings, prepare
from windowshop.rays import project
from windowshop.scene import read_source
from windowshop.scene.types import Camera


def _photo(name: str, height: int, width: int, key=("Phone", "X", 4.2)) -> Photo:
    return Photo(name, Path(f"{name}.jpg"), np.zeros((height, width, 3), np.uint8), 1.0,
                 (*key, (width, height)))


def test_the_photos_held_the_other_way_from_most_of_their_lens_are_turned():
    photos = [_photo("p1", 8, 6), _photo("p2", 8, 6), _photo("l1", 6, 8),
              _photo("other", 6, 8, key=("Other", "Y", 3.0))]  # another lens: left as it is
    assert orient.turned_names(photos) == {"l1.jpg"}
    tie = [_photo("p1", 8, 6), _photo("l1", 6, 8)]
    assert orient.turned_names(tie) == {"l1.jpg"}  # as many each way: landscape turned
    assert orient.turned_names([_photo("a", 8, 6), _photo("b", 8, 6)]) == frozenset()


def test_one_camera_for_a_lens_held_both_ways_and_another_for_a_cropped_photo():
    photos = [_photo("p1", 8, 6), _photo("p2", 8, 6), _photo("l1", 6, 8)]
    settings = _settings(Inputs("photos", []), photos, PrepareOptions())
    assert settings.cameras == () and settings.turned == {"l1.jpg"}
    cropped = _photo("c", 6, 8)
    cropped.camera_key = (*cropped.camera_key[:3], (7, 5))  # its original: another size
    settings = _settings(Inputs("photos", []), photos + [cropped], PrepareOptions())
    assert settings.turned == {"l1.jpg", "c.jpg"}  # as many each way: landscape turned
    assert sorted(map(sorted, settings.cameras)) == [["c.jpg"], ["l1.jpg", "p1.jpg", "p2.jpg"]]


def test_a_pixel_of_the_turned_photo_comes_back_to_where_it_was_taken():
    pixels = np.zeros((6, 8, 3), np.uint8)  # 8 wide, 6 high
    pixels[1, 6] = 255  # row 1, column 6: centre (6.5, 1.5)
    turned = orient.for_sfm(pixels)
    assert turned.shape == (8, 6, 3)
    row, col = np.argwhere(turned[..., 0] == 255)[0]
    np.testing.assert_allclose(orient.photo_xy([[col + 0.5, row + 0.5]], 8), [[6.5, 1.5]])


def _rolled(camera: Camera, degrees: float) -> Camera:
    """`camera` turned by `degrees` about its optical axis, intrinsics as the turned photo's."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    c2w = camera.c2w.copy()
    c2w[:3, :3] = camera.c2w[:3, :3] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return Camera(fx=camera.fy, fy=camera.fx, cx=camera.cy, cy=camera.width - camera.cx,
                  width=camera.height, height=camera.width, c2w=c2w)


def test_the_camera_found_for_a_turned_photo_projects_as_the_photo_does():
    rng = np.random.default_rng(3)
    c2w = np.eye(4)
    c2w[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0] * [1, 1, -1]
    c2w[:3, :3] *= np.sign(np.linalg.det(c2w[:3, :3]))
    photo = Camera(fx=510.0, fy=505.0, cx=300.0, cy=410.0, width=605, height=806, c2w=c2w)
    # which way the turned camera rolls is what the projections decide, not this test
    back = {deg: orient.photo_camera(_rolled(photo, deg)) for deg in (90.0, -90.0)}
    matching = [deg for deg, cam in back.items() if np.allclose(cam.c2w, photo.c2w)]
    assert len(matching) == 1
    sfm_camera = _rolled(photo, matching[0])
    came_back = back[matching[0]]
    np.testing.assert_allclose(orient.sfm_c2w(photo.c2w), sfm_camera.c2w, atol=1e-12)
    assert (came_back.fx, came_back.fy, came_back.cx, came_back.cy, came_back.width,
            came_back.height) == (510.0, 505.0, 300.0, 410.0, 605, 806)
    points = c2w[:3, 3] + rng.normal(size=(20, 3)) * 0.3 - 3.0 * c2w[:3, 2]  # in front
    uv, _ = project(points, photo)
    uv_turned, _ = project(points, sfm_camera)
    np.testing.assert_allclose(orient.photo_xy(uv_turned, photo.width), uv, atol=1e-6)
    # the phone's gravity, in each camera's OpenCV axes, turns with the photo
    down = np.array([0.2, -0.9, 0.1])
    opencv = np.diag([1.0, -1.0, -1.0])
    in_photo = opencv @ photo.c2w[:3, :3].T @ down
    in_turned = opencv @ sfm_camera.c2w[:3, :3].T @ down
    np.testing.assert_allclose(orient.sfm_vector(in_photo), in_turned, atol=1e-12)


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """20 of fruit's photos over its walk, every other one given in landscape (turned a quarter,
    as a phone held sideways writes it once its orientation is applied), prepared."""
    root = tmp_path_factory.mktemp("mixed")
    frames = read_source(DATA / "fruit").frames[::4][:20]
    (root / "photos").mkdir()
    for k, frame in enumerate(frames):
        image = Image.open(frame.image_path).convert("RGB")
        image = image.transpose(Image.Transpose.ROTATE_90) if k % 2 else image
        image.save(root / "photos" / frame.image_path.name, quality=95)
    prepare(root / "photos", root / "scene", PrepareOptions(), show=False)
    return root / "scene", frames


@pytest.mark.skipif(not (DATA / "fruit").exists(), reason="needs ../shared/data/fruit")
def test_portrait_and_landscape_photos_of_one_lens_share_its_intrinsics(mixed):
    scene, frames = mixed
    meta = json.loads((scene / "transforms.json").read_text())
    shapes = {(f["w"], f["h"]) for f in meta["frames"]}
    assert shapes == {(480, 640), (640, 480)}  # each photo written as it was taken
    for f in meta["frames"]:  # one focal length and lens; the principal point at each centre
        assert (f["fl_x"], f["fl_y"], f["k1"]) == pytest.approx(
            (meta["frames"][0]["fl_x"],) * 2 + (meta["frames"][0]["k1"],))
        assert (f["cx"], f["cy"]) == (f["w"] / 2, f["h"] / 2)
        size = Image.open(scene / f["file_path"]).size
        assert size == Image.open(scene / f["mask_path"]).size == (f["w"], f["h"])
    # the published focal length, 627.8 px at 806 px high, at the working 640
    assert meta["frames"][0]["fl_x"] == pytest.approx(627.8 * 640 / 806, rel=0.05)


@pytest.mark.skipif(not (DATA / "fruit").exists(), reason="needs ../shared/data/fruit")
def test_the_turned_photos_cameras_agree_with_the_published_ones(mixed):
    scene, frames = mixed
    recovered = {Path(f.image_path).stem: f.camera.c2w for f in read_source(scene).frames}
    published = {}
    for k, frame in enumerate(frames):
        c2w = frame.camera.c2w.copy()
        if k % 2:  # the landscape photo's camera: its right is the portrait's down
            c2w[:3, 0], c2w[:3, 1] = -frame.camera.c2w[:3, 1], frame.camera.c2w[:3, 0]
        published[frame.image_path.stem] = c2w
    errors = pose_errors(recovered, published)
    assert len(errors.names) >= 18
    assert np.median(errors.rotation_deg) <= 3.0 and np.max(errors.rotation_deg) <= 6.0
