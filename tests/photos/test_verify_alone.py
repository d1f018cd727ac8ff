"""A photo that none of its pairs places where the model does (windowshop.photos.verify.alone):
five of fruit's photos taken one after another and IMG_3690, taken 30 photos later in the walk.
Structure from motion places IMG_3690 about 36 degrees off the other five, on five pairs of
27-51 inliers that each disagree by 31-74 degrees; before the check it was delivered so (the
pairs check reads only pairs of 100 inliers or more)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from shared_data import DATA
from windowshop.config import PrepareOptions
from windowshop.photos.align import rotation_angle
from windowshop.photos.prepare import prepare
from windowshop.scene import read_source

CLOSE = ("IMG_3655", "IMG_3656", "IMG_3657", "IMG_3659", "IMG_3660")
FAR = "IMG_3690"


@pytest.mark.skipif(not (DATA / "fruit").exists(), reason="needs ../shared/data/fruit")
def test_a_photo_none_of_whose_pairs_agree_is_left_out_to_be_reshot(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for name in CLOSE + (FAR,):
        (photos / f"{name}.jpg").symlink_to(DATA / "fruit" / "newfruit_small" / f"{name}.jpg")
    result = prepare(photos, tmp_path / "scene", PrepareOptions(), show=False)
    first = result.report["verification"]["tried"][0]
    alone = next(c for c in first["checks"] if c["name"] == "alone")
    assert not alone["passed"] and alone["suspects"] == [f"{FAR}.jpg"], alone
    assert {v["name"] for v in result.report["views"]} == set(CLOSE)
    assert f"{FAR}.jpg" in result.report["unplaced"]  # named for a retake
    # the five delivered agree with the published cameras, each against the others
    published = {f.image_path.stem: f.camera.c2w for f in read_source(DATA / "fruit").frames}
    meta = json.loads((tmp_path / "scene" / "transforms.json").read_text())
    placed = {Path(f["file_path"]).stem: np.array(f["transform_matrix"]) for f in meta["frames"]}
    for name, c2w in placed.items():
        errors = [rotation_angle((c2w[:3, :3].T @ other[:3, :3]).T
                                 @ (published[name][:3, :3].T @ published[o][:3, :3]))
                  for o, other in placed.items() if o != name]
        assert np.median(errors) <= 5.0, (name, errors)


FOLD = ("0000", "0005", "0010", "0015", "0020", "0025")


def test_a_photo_placed_by_a_print_repeated_on_the_far_side_is_not_delivered(tmp_path):
    """beer_can's frames 0000, 0005, ..., 0025 (155 degrees of the walk round a can printed alike
    on two sides), shrunk to the working size with a level of noise, as another phone's pixels
    would differ: 0025 is left out as alone, and the remapped five place 0020 by the print on the
    can's far side, 93 degrees from its one pair of 25 inliers or more. Before FAR_DEG that model
    passed and was delivered with 0020 wrong (10 degrees median against beer_loop's poses)."""
    from PIL import Image

    from windowshop.errors import UserError

    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for name in FOLD:
        with Image.open(DATA / "beer_can" / "images" / f"{name}.jpg") as image:
            pixels = np.asarray(image.convert("RGB").resize((360, 640), Image.LANCZOS), int)
        noise = rng.integers(-1, 2, pixels.shape)
        rng.integers(-1, 2, pixels.shape)  # a second draw, as the case was first made
        Image.fromarray(np.clip(pixels + noise, 0, 255).astype(np.uint8)).save(photos / f"{name}.png")
    with pytest.raises(UserError) as refused:
        prepare(photos, tmp_path / "scene", PrepareOptions(), show=False)
    assert "0020.jpg" in str(refused.value)
    assert not (tmp_path / "scene" / "transforms.json").exists()
