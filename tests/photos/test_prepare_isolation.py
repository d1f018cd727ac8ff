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
from windowshop.quality import advice
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


def _cut_out(folder, crop: bool = False):
    """12 of the photos as PNGs whose background a remover took away (transparent, black under
    it), cropped to the object and 10 pixels round it if `crop`."""
    folder.mkdir()
    files = sorted((SKULL / "images").glob("*.jpg"))
    for i in np.linspace(0, len(files) - 1, 12).round().astype(int):
        rgb = np.asarray(Image.open(files[i]).convert("RGB"))
        alpha = np.asarray(Image.open(SKULL / "masks" / f"{files[i].stem}.png").convert("L")) > 127
        cut = np.dstack([rgb * alpha[..., None], np.where(alpha, 255, 0)]).astype(np.uint8)
        if crop:
            ys, xs = np.nonzero(alpha)
            cut = cut[max(ys.min() - 10, 0):ys.max() + 11, max(xs.min() - 10, 0):xs.max() + 11]
        Image.fromarray(cut).save(folder / f"{files[i].stem}.png")
    return folder


def test_photos_cut_out_by_their_owner_keep_their_outlines(tmp_path):
    """Their transparency is their mask, as drawn, and the object is still placed upright."""
    result = prepare(_cut_out(tmp_path / "photos"), tmp_path / "scene",
                     PrepareOptions(max_side=320), show=False)
    assert result.report["masks"] == "given" and not result.report["cropped"]
    assert len(result.report["views"]) >= 10
    for view in result.report["views"]:
        mask = np.asarray(Image.open(result.out_dir / "masks" / f"{view['name']}.png")) > 127
        truth = Image.open(SKULL / "masks" / f"{view['name']}.png").convert("L")
        truth = np.asarray(truth.resize(mask.shape[::-1], Image.BILINEAR)) > 127
        assert (mask & truth).sum() / (mask | truth).sum() > 0.97, view["name"]
    heights = np.array([f.camera.center[2] for f in read_source(result.out_dir).frames])
    assert np.all(heights > 0)  # seen from above, as the photos were taken


def test_cut_outs_cropped_to_the_object_are_named_with_what_to_do(tmp_path):
    result = prepare(_cut_out(tmp_path / "photos", crop=True), tmp_path / "scene",
                     PrepareOptions(max_side=320), show=False)
    assert len(result.report["cropped"]) == 12
    tips = advice(result.report)
    assert any("cropped to the object" in tip and "full size" in tip for tip in tips)
