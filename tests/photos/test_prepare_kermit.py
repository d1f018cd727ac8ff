"""`windowshop prepare` on kermit (11 unposed photos) through the real CLI."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pycolmap
import pytest
from PIL import Image, ImageFilter

from windowshop.cli import main
from windowshop.rays import project
from windowshop.scene import load_scene
from windowshop.scene.cameras import LEVEL_SPREAD_DEG
from shared_data import DATA

KERMIT = DATA / "kermit"


def _hashes(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    """kermit's photos plus an exact copy and a blurred one, prepared by the CLI."""
    root = tmp_path_factory.mktemp("kermit")
    photos = root / "photos"
    photos.mkdir()
    for path in sorted(KERMIT.glob("*.jpg")):
        shutil.copyfile(path, photos / path.name)
    shutil.copyfile(KERMIT / "kermit004.jpg", photos / "kermit004_copy.jpg")
    Image.open(KERMIT / "kermit007.jpg").filter(ImageFilter.GaussianBlur(4)).save(
        photos / "shaky.jpg", quality=95)
    before = _hashes(photos)
    code = main(["prepare", str(photos), "--out", str(root / "scene")])
    return root, before, code


def test_kermit_is_placed(prepared, capsys):
    root, _, code = prepared
    assert code == 0
    report = json.loads((root / "scene" / "report.json").read_text())
    assert report["used"] == 11 and report["placed"] >= 10
    assert report["dropped"] == {"kermit004_copy.jpg": "exact duplicate of kermit004.jpg",
                                 "shaky.jpg": report["dropped"]["shaky.jpg"]}
    assert report["dropped"]["shaky.jpg"].startswith("too blurred")
    assert report["reprojection_error_px"] < 1.0
    assert (root / "scene" / "cameras.png").stat().st_size > 10_000


def test_inputs_are_untouched(prepared):
    root, before, _ = prepared
    assert _hashes(root / "photos") == before


def test_frames_keep_the_photo_names_and_load(prepared):
    root, _, _ = prepared
    meta = json.loads((root / "scene" / "transforms.json").read_text())
    stems = [Path(f["file_path"]).stem for f in meta["frames"]]
    assert len(stems) >= 10 and set(stems) <= {f"kermit{i:03d}" for i in range(11)}
    scene = load_scene(root / "scene")
    assert scene.format == "nerfstudio" and len(scene.views) == len(stems)
    assert sorted(Path(v.name).stem for v in scene.views) == sorted(stems)
    assert np.all(np.abs(scene.aabb) <= 1.0 + 1e-6) and np.isclose(np.abs(scene.aabb).max(), 1.0)
    # no support plane is found under kermit: up (+z) is the level its hand-held photos agree
    # on, each camera's right axis horizontal (the cameras' mean up leans with their pitch)
    rights_z = np.array([v.camera.c2w[2, 0] for v in scene.views])
    assert np.degrees(np.arcsin(np.sqrt(np.mean(rights_z**2)))) < LEVEL_SPREAD_DEG
    up = np.mean([v.camera.c2w[:3, 1] for v in scene.views], axis=0)
    assert up[2] / np.linalg.norm(up) > 0.9  # and the photos are upright


def test_cameras_project_the_colmap_points_where_colmap_does(prepared):
    """Each sparse point, moved into the normalised frame, projects through our camera (OpenGL,
    from transforms.json) to the pixel the COLMAP pose gives (pinhole part) within 0.01 px."""
    root, _, _ = prepared
    meta = json.loads((root / "scene" / "transforms.json").read_text())
    transform = np.array(meta["windowshop"]["transform"])
    model = pycolmap.Reconstruction(root / "scene" / "colmap")
    images = {Path(im.name).stem: im for im in model.images.values()}
    points = np.array([p.xyz for p in model.points3D.values()])
    normalised = points @ transform[:3, :3].T + transform[:3, 3]
    from windowshop.scene import read_source

    for frame in read_source(root / "scene").frames:
        image = images[frame.image_path.stem]
        cam = model.cameras[image.camera_id]
        local = np.array([image.cam_from_world() * p for p in points])
        front = local[:, 2] > 0
        expected = local[front, :2] / local[front, 2:] * cam.focal_length + [cam.principal_point_x,
                                                                           cam.principal_point_y]
        uv, depth = project(normalised[front], frame.camera)
        assert np.all(depth > 0)
        np.testing.assert_allclose(uv, expected, atol=1e-2)


def test_two_photos_upside_down_do_not_tip_kermit_over(tmp_path):
    """kermit's eleven photos, two of them turned upside down (their EXIF orientation lost):
    the nine upright ones tell the level, which the scene's up follows (a weak plane 64 degrees
    off it was delivered before: kermit leaning in every frame)."""
    from windowshop.photos.verify.upright import angle
    from windowshop.scene.cameras import upright_level

    photos = tmp_path / "photos"
    photos.mkdir()
    for path in sorted(KERMIT.glob("*.jpg")):
        image = Image.open(path)
        if path.stem in ("kermit003", "kermit006"):
            image = image.rotate(180)
        image.save(photos / path.name, quality=95)
    assert main(["prepare", str(photos), "--out", str(tmp_path / "scene")]) == 0
    frames = json.loads((tmp_path / "scene" / "transforms.json").read_text())["frames"]
    c2ws = np.stack([np.array(f["transform_matrix"]) for f in frames])
    level, _ = upright_level(c2ws)
    assert angle(level, np.array([0.0, 0.0, 1.0])) < 5.0
    centres = c2ws[:, :3, 3]
    elevations = np.degrees(np.arcsin(centres[:, 2] / np.linalg.norm(centres, axis=1)))
    assert 10.0 < np.median(elevations) < 35.0  # kermit's photos look down about 20 degrees
