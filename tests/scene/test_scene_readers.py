"""Every dataset in ../shared/data loads through the right reader, and each reader's specifics."""

import json
from pathlib import Path

import numpy as np
import pytest

from windowshop.config import SceneOptions
from windowshop.errors import UserError
from windowshop.scene import detect_format, load_scene, read_source
from shared_data import DATA

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason="shared datasets not present")
SMALL = SceneOptions(max_side=48)


@pytest.mark.parametrize("name, reader, views, size", [
    ("lego", "blender", 400, (400, 400)),
    ("lego/transforms_train.json", "blender", 400, (400, 400)),
    ("lego_tiny.npz", "npz", 106, (100, 100)),
    ("fruit", "nerfstudio", 81, (605, 806)),
    ("fruit/transforms.json", "nerfstudio", 81, (605, 806)),
    ("beer_can", "llff", 71, (720, 1280)),
    ("beer_can/poses_bounds.npy", "llff", 71, (720, 1280)),
    ("beer_can/sparse/0", "colmap", 71, (720, 1280)),
    ("temple_sparse", "middlebury", 16, (640, 480)),
    ("temple_sparse/templeSR_par.txt", "middlebury", 16, (640, 480)),
])
def test_each_dataset_is_read_by_its_reader(name, reader, views, size):
    assert detect_format(DATA / name)[0] == reader
    source = read_source(DATA / name)
    assert source.format == reader and len(source.frames) == views
    assert {(f.camera.width, f.camera.height) for f in source.frames} == {size}
    for frame in source.frames:
        rot = frame.camera.c2w[:3, :3]
        np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-9)


@pytest.mark.parametrize("name", ["lego_tiny.npz", "fruit", "beer_can", "beer_can/sparse/0",
                                  "temple_sparse"])
def test_each_dataset_loads_into_a_normalised_scene(name):
    scene = load_scene(DATA / name, SMALL)
    assert scene.views and all(max(v.image.shape[:2]) == 48 for v in scene.views)
    for view in scene.views:
        assert view.image.dtype == np.float32 and 0 <= view.image.min() and view.image.max() <= 1
        # the object box is in front of every camera: its centre projects inside the image
        w2c = np.linalg.inv(view.camera.c2w)
        local = w2c[:3, :3] @ scene.aabb.mean(0) + w2c[:3, 3]
        u = view.camera.fx * local[0] / -local[2] + view.camera.cx
        v = -view.camera.fy * local[1] / -local[2] + view.camera.cy
        assert local[2] < 0 and 0 <= u <= view.camera.width and 0 <= v <= view.camera.height
    assert np.all(scene.aabb[0] >= -1 - 1e-9) and np.all(scene.aabb[1] <= 1 + 1e-9)
    assert np.max(scene.aabb[1] - scene.aabb[0]) == pytest.approx(2.0)
    assert 0 < scene.near < scene.far


def test_kermit_has_no_poses_and_points_to_prepare():
    with pytest.raises(UserError, match="windowshop prepare"):
        load_scene(DATA / "kermit")


def test_lego_splits_and_rgba_background():
    scene = load_scene(DATA / "lego", SceneOptions(max_side=32, test_views=5))
    assert [len(scene.split(s)) for s in ("train", "val", "test")] == [100, 100, 5]
    names = [Path(v.name).name for v in scene.split("test")]
    assert names == ["r_0.png", "r_50.png", "r_100.png", "r_149.png", "r_199.png"]
    view = scene.views[0]
    background = view.alpha < 0.01
    assert background.any() and np.allclose(view.image[background], 1.0, atol=0.01)


def test_npz_split_as_tiny_nerf_and_black_background():
    scene = load_scene(DATA / "lego_tiny.npz")
    assert len(scene.split("train")) == 100 and len(scene.split("test")) == 6
    assert scene.background == "black" and scene.views[0].image.shape == (100, 100, 3)
    with np.load(DATA / "lego_tiny.npz") as data:
        np.testing.assert_array_equal(scene.views[3].image, data["images"][3])


def test_nerfstudio_keeps_the_files_intrinsics_and_undistorts(tmp_path):
    meta = json.loads((DATA / "fruit" / "transforms.json").read_text())
    scene = load_scene(DATA / "fruit", SceneOptions(max_side=64, views=4, test_views=1))
    view = scene.views[0]
    assert view.stored_camera.fx == pytest.approx(meta["fl_x"])
    assert view.stored_camera.cy == pytest.approx(meta["cy"])
    assert view.distortion["p1"] == pytest.approx(meta["p1"])
    # the pinhole camera is zoomed in a little so that no pixel falls outside the photo
    assert view.camera.fx / view.camera.width > meta["fl_x"] / meta["w"]


def test_llff_reads_downscaled_image_folders(tmp_path):
    """images_N copies are used when the requested size allows, with intrinsics still exact."""
    from PIL import Image

    scene_dir = tmp_path / "scene"
    (scene_dir / "images").mkdir(parents=True)
    (scene_dir / "images_4").mkdir()
    rows = []
    for i in range(3):
        Image.new("RGB", (80, 40), (200, 10, 10)).save(scene_dir / "images" / f"{i:03d}.png")
        Image.new("RGB", (20, 10), (10, 200, 10)).save(scene_dir / "images_4" / f"{i:03d}.png")
        c2w = np.eye(4)[:3]
        c2w[:, 3] = [i * 0.1, 0.0, 3.0]
        llff = np.concatenate([-c2w[:, 1:2], c2w[:, 0:1], c2w[:, 2:]], 1)  # (down, right, back)
        rows.append(np.concatenate([np.concatenate([llff, [[40.0], [80.0], [100.0]]], 1).ravel(),
                                    [1.0, 5.0]]))
    np.save(scene_dir / "poses_bounds.npy", np.array(rows))
    full = load_scene(scene_dir, SceneOptions(normalize=False))
    small = load_scene(scene_dir, SceneOptions(downscale=4, normalize=False))
    assert full.views[0].image[0, 0, 0] == pytest.approx(200 / 255)  # from images/
    assert small.views[0].image[0, 0, 1] == pytest.approx(200 / 255)  # from images_4/
    assert small.views[0].camera.fx == pytest.approx(25.0) and small.views[0].camera.cx == 10.0
    np.testing.assert_allclose(full.views[1].camera.c2w[:3], np.eye(4)[:3] + [[0, 0, 0, 0.1],
                                                                             [0, 0, 0, 0], [0, 0, 0, 3.0]])


def test_colmap_text_model_reads_like_the_binary_one(tmp_path):
    import pycolmap

    rec = pycolmap.Reconstruction(str(DATA / "beer_can" / "sparse" / "0"))
    model = tmp_path / "sparse" / "0"
    model.mkdir(parents=True)
    rec.write_text(str(model))
    assert (model / "cameras.txt").is_file()
    text, binary = read_source(tmp_path), read_source(DATA / "beer_can" / "sparse" / "0")
    assert text.format == "colmap" and len(text.frames) == len(binary.frames)
    assert text.frames[0].image_path == tmp_path / "images" / "0000.jpg"
    for a, b in zip(text.frames, binary.frames):
        np.testing.assert_allclose(a.camera.c2w, b.camera.c2w, atol=1e-9)
        assert a.camera.fx == pytest.approx(b.camera.fx) and a.distortion == b.distortion
    def by_position(pts):
        return pts[np.lexsort(pts.T)]

    np.testing.assert_allclose(by_position(text.points), by_position(binary.points), atol=1e-6)
