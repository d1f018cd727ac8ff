"""`windowshop prepare` isolates a skull on a cardboard table (dtu_skull) against hand-made masks,
and stands it upright on the table's plane."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pycolmap
import pytest
from PIL import Image

from windowshop.config import PrepareOptions
from windowshop.photos.prepare import prepare
from windowshop.scene import read_source
from shared_data import DATA

SKULL = DATA / "dtu_skull"
pytestmark = pytest.mark.skipif(not SKULL.is_dir(), reason="needs ../shared/data/dtu_skull")


@pytest.fixture(scope="module")
def skull(tmp_path_factory):
    """12 of the 49 photos, evenly spread, prepared at 320 px."""
    root = tmp_path_factory.mktemp("skull")
    photos = root / "photos"
    photos.mkdir()
    files = sorted((SKULL / "images").glob("*.jpg"))
    for i in np.linspace(0, len(files) - 1, 12).round().astype(int):
        shutil.copyfile(files[i], photos / files[i].name)
    return prepare(photos, root / "scene", PrepareOptions(max_side=320), show=False)


@pytest.mark.slow
def test_masks_match_the_hand_made_ones(skull):
    report = skull.report
    assert report["masks"] == "segmented" and report["plane"]["found"]
    ious = []
    for view in report["views"]:
        mask = Image.open(skull.out_dir / "masks" / f"{view['name']}.png").convert("L")
        truth = np.asarray(Image.open(SKULL / "masks" / f"{view['name']}.png").convert("L")) > 127
        mask = np.asarray(mask.resize(truth.shape[::-1], Image.NEAREST)) > 127
        ious.append((mask & truth).sum() / (mask | truth).sum())
    # before: 0.65 mean, 0.31 worst (masks from the outline of the object's features)
    assert np.mean(ious) > 0.85 and min(ious) > 0.6, ious


@pytest.mark.slow
def test_the_skull_stands_upright_on_the_table(skull):
    """Up is the table's normal: the table's sparse points around the box lie in a plane at the
    box's floor, square to +z, and every camera sees it from above."""
    meta = json.loads((skull.out_dir / "transforms.json").read_text())["windowshop"]
    transform, aabb = np.array(meta["transform"]), np.array(meta["aabb"])
    model = pycolmap.Reconstruction(skull.out_dir / "colmap")
    points = np.array([p.xyz for p in model.points3D.values()])
    points = points @ transform[:3, :3].T + transform[:3, 3]
    floor = aabb[0, 2]
    table = points[(np.abs(points[:, 2] - floor) < 0.1) & (np.abs(points[:, :2]).max(1) < 3)]
    assert len(table) > 30
    normal = np.linalg.svd(table - table.mean(0))[2][-1]
    assert np.degrees(np.arccos(abs(normal[2]))) < 5.0
    assert np.median(table[:, 2]) == pytest.approx(floor, abs=0.05)
    heights = np.array([f.camera.center[2] for f in read_source(skull.out_dir).frames])
    assert np.all(heights > np.median(table[:, 2]))  # the lowest views graze the table
