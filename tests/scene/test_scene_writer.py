"""Any Scene written as a nerfstudio transforms.json reads back the same, and maps back."""

import json

import numpy as np
import pytest

from windowshop.config import SceneOptions
from windowshop.scene import load_scene
from windowshop.scene.synthetic import synthetic_scene
from windowshop.scene.writer import write_transforms
from shared_data import DATA



def _assert_same(a, b, image_tol=0.5 / 255 + 1e-6):
    assert [v.split for v in a.views] == [v.split for v in b.views]
    for va, vb in zip(a.views, b.views):
        np.testing.assert_allclose(va.camera.c2w, vb.camera.c2w, atol=1e-9)
        for key in ("fx", "fy", "cx", "cy", "width", "height"):
            assert getattr(va.camera, key) == pytest.approx(getattr(vb.camera, key))
        np.testing.assert_allclose(va.image, vb.image, atol=image_tol)
        assert (va.alpha is None) == (vb.alpha is None)
        if va.alpha is not None:
            np.testing.assert_allclose(va.alpha, vb.alpha, atol=image_tol)
    np.testing.assert_allclose(a.aabb, b.aabb, atol=1e-9)
    assert a.near == pytest.approx(b.near) and a.far == pytest.approx(b.far)
    assert a.background == b.background


def test_synthetic_scene_round_trip(tmp_path):
    scene = synthetic_scene(n_train=6, n_test=2, size=24)
    path = write_transforms(scene, tmp_path / "out")
    assert path.name == "transforms.json"
    back = load_scene(tmp_path / "out")
    assert back.format == "nerfstudio"
    np.testing.assert_allclose(back.transform, np.eye(4), atol=1e-12)  # already normalised
    _assert_same(scene, back)


@pytest.mark.skipif(not DATA.is_dir(), reason="shared datasets not present")
def test_real_scene_round_trip_keeps_the_way_back_to_the_source(tmp_path):
    scene = load_scene(DATA / "temple_sparse", SceneOptions(max_side=40))
    write_transforms(scene, tmp_path)
    back = load_scene(tmp_path / "transforms.json")
    _assert_same(scene, back)
    meta = json.loads((tmp_path / "transforms.json").read_text())
    to_source = np.linalg.inv(np.array(meta["windowshop"]["transform"]))
    for view, frame in zip(scene.views, meta["frames"]):
        # the written camera, mapped back with the kept transform, is the source's own camera
        c2w = to_source @ np.array(frame["transform_matrix"])
        c2w[:3, :3] /= np.cbrt(np.linalg.det(c2w[:3, :3]))
        np.testing.assert_allclose(c2w, view.stored_camera.c2w, atol=1e-9)


def test_written_splits_and_masks(tmp_path):
    scene = synthetic_scene(n_train=3, n_test=2, size=16)
    write_transforms(scene, tmp_path)
    meta = json.loads((tmp_path / "transforms.json").read_text())
    assert len(meta["train_filenames"]) == 3 and len(meta["test_filenames"]) == 2
    assert all((tmp_path / f["mask_path"]).is_file() for f in meta["frames"])
