"""Recovered poses against published ones, after a similarity alignment (windowshop.photos.align):
beer_can's first 14 photos against its COLMAP model, and the Middlebury temple with known
intrinsics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pycolmap
import pytest
from PIL import Image

from windowshop.config import PrepareOptions
from windowshop.photos.align import pose_errors
from windowshop.photos.prepare import prepare
from windowshop.rays import project
from windowshop.scene import read_source
from shared_data import DATA

MAX_ROTATION_DEG = 2.0
MAX_CENTRE_SHARE = 0.02  # of the capture radius


def _recovered(scene_dir: Path) -> dict[str, np.ndarray]:
    meta = json.loads((scene_dir / "transforms.json").read_text())
    return {Path(f["file_path"]).stem: np.array(f["transform_matrix"]) for f in meta["frames"]}


def _reference(path: Path) -> dict[str, np.ndarray]:
    return {f.image_path.stem: f.camera.c2w for f in read_source(path).frames}


def beer_sample() -> list[Path]:
    """The beer_can photos whose published pose is trustworthy: frames 0000-0013.

    beer_can's own COLMAP model is folded after them: the can is printed with its logo twice,
    and its frames 0014-0034 and 0053-0070 lie 160-180 degrees from where the walk puts them
    (0000 with a railing behind and 0027 with a door behind it 1.4 degrees apart; this
    repository's model of all 70 frames puts them 177 degrees apart). A sample over the whole
    walk is folded the same way by structure from motion and refused by the background check
    (tests/photos/test_verify_background.py).
    """
    return [DATA / "beer_can" / "images" / f"{i:04d}.jpg" for i in range(14)]


@pytest.fixture(scope="module")
def beer(tmp_path_factory):
    photos = tmp_path_factory.mktemp("beer") / "photos"
    photos.mkdir()
    for path in beer_sample():
        (photos / path.name).symlink_to(path)
    return prepare(photos, photos.parent / "scene", PrepareOptions(max_side=640), show=False)


def test_beer_can_photos_of_its_first_side_agree_with_its_colmap_model(beer):
    assert beer.report["placed"] >= 13
    errors = pose_errors(_recovered(beer.out_dir), _reference(DATA / "beer_can" / "sparse" / "0"))
    assert len(errors.names) == beer.report["placed"]
    by_name = dict(zip(errors.names, zip(errors.rotation_deg, errors.centre_share)))
    assert errors.rotation_deg.max() < MAX_ROTATION_DEG, by_name
    assert errors.centre_share.max() < MAX_CENTRE_SHARE, by_name


def test_beer_can_masks_outline_its_features(beer):
    """The tiled floor is no plain background: each mask is the can segmented by colour, seeded
    by its keypoints, so most of the object's sparse points (seen there or not) project into
    it, and it is much smaller than the photo."""
    assert beer.report["masks"] == "segmented" and beer.report["background"] == "alpha"
    meta = json.loads((beer.out_dir / "transforms.json").read_text())["windowshop"]
    transform, aabb = np.array(meta["transform"]), np.array(meta["aabb"])
    model = pycolmap.Reconstruction(beer.out_dir / "colmap")
    points = np.array([p.xyz for p in model.points3D.values()])
    points = points @ transform[:3, :3].T + transform[:3, 3]
    points = points[np.all((points >= aabb[0]) & (points <= aabb[1]), axis=1)]
    inside = []
    for frame in read_source(beer.out_dir).frames:
        mask = np.asarray(Image.open(frame.mask_path)) > 127
        uv = np.clip(project(points, frame.camera)[0].astype(int), 0, [mask.shape[1] - 1,
                                                                       mask.shape[0] - 1])
        inside.append(mask[uv[:, 1], uv[:, 0]].mean())
        assert 0.01 < mask.mean() < 0.3
    assert np.median(inside) > 0.9 and min(inside) > 0.5, inside


def _temple_intrinsics() -> tuple[float, float, float, float]:
    """fx, fy, cx, cy shared by every temple view, from its calibration file."""
    lines = (DATA / "temple_sparse" / "templeSR_par.txt").read_text().splitlines()[1:]
    rows = [line.split() for line in lines]
    k = np.array([[float(v) for v in row[1:10]] for row in rows]).reshape(-1, 3, 3)
    assert np.allclose(k, k[0])
    return k[0, 0, 0], k[0, 1, 1], k[0, 0, 2], k[0, 1, 2]


@pytest.fixture(scope="module")
def temple(tmp_path_factory):
    out = tmp_path_factory.mktemp("temple") / "scene"
    options = PrepareOptions(max_side=640, intrinsics=_temple_intrinsics())
    return prepare(DATA / "temple_sparse", out, options, show=False)


def test_temple_with_known_intrinsics_is_one_model(temple):
    report = temple.report
    assert report["placed"] >= 13
    assert report["attempts"][0]["label"] == "default"
    errors = pose_errors(_recovered(temple.out_dir), _reference(DATA / "temple_sparse"))
    assert len(errors.names) == report["placed"]  # every placed view is in the one model
    assert errors.rotation_deg.max() < MAX_ROTATION_DEG
    assert errors.centre_share.max() < MAX_CENTRE_SHARE


def test_temple_intrinsics_are_kept(temple):
    meta = json.loads((temple.out_dir / "transforms.json").read_text())
    fx, fy, cx, cy = _temple_intrinsics()
    assert (meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"]) == pytest.approx((fx, fy, cx, cy))
    assert "k1" not in meta


def test_temple_masks_lie_on_the_temple(temple):
    """The masks (black background) fall inside the temple's published bounding box as each
    calibrated camera sees it, and cover a good part of it."""
    assert temple.report["masks"] == "colour" and temple.report["background"] == "alpha"
    lo = np.array([-0.073568, 0.021728, -0.012445])
    hi = np.array([0.028855, 0.181892, 0.062736])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    for frame in read_source(DATA / "temple_sparse").frames:
        mask_file = temple.out_dir / "masks" / f"{frame.image_path.stem}.png"
        mask = np.asarray(Image.open(mask_file)) > 127
        uv, _ = project(corners, frame.camera)
        (u0, v0), (u1, v1) = np.floor(uv.min(0)).astype(int) - 3, np.ceil(uv.max(0)).astype(int) + 3
        inside = mask[max(v0, 0):v1, max(u0, 0):u1].sum()
        assert inside >= 0.98 * mask.sum()
        assert mask.sum() >= 0.25 * (v1 - v0) * (u1 - u0)


def _exif(make: str, focal: float, zoom: float | None) -> Image.Exif:
    exif = Image.Exif()
    exif[0x010F], exif[0x0110] = make, "Model X"
    details = exif.get_ifd(0x8769)
    details[0x920A] = focal  # FocalLength
    if zoom is not None:
        details[0xA404] = zoom  # DigitalZoomRatio
    return exif


def test_close_ups_of_a_phones_digital_zoom_are_placed_with_their_own_focal_length(tmp_path):
    """16 dtu_skull photos and three close-ups a phone's 2x digital zoom took (the middle of
    other views, at the same pixel size and EXIF focal length, with its DigitalZoomRatio): the
    close-ups get twice the focal length and stand as far from the skull as the others. With
    one camera for all, they were placed at half the distance."""
    photos, images = tmp_path / "photos", DATA / "dtu_skull" / "images"
    photos.mkdir()
    for i in range(2, 48, 3):
        Image.open(images / f"{i:03d}.jpg").resize((400, 300), Image.Resampling.LANCZOS).save(
            photos / f"{i:03d}.jpg", quality=92, exif=_exif("Phone", 4.25, None))
    for i in (10, 25, 40):
        Image.open(images / f"{i:03d}.jpg").crop((200, 135, 600, 435)).save(
            photos / f"zoom{i:03d}.jpg", quality=92, exif=_exif("Phone", 4.25, 2.0))
    prepare(photos, tmp_path / "scene", PrepareOptions(), show=False)
    meta = json.loads((tmp_path / "scene" / "transforms.json").read_text())
    focal = {Path(f["file_path"]).stem: f["fl_x"] for f in meta["frames"]}
    distance = {name: np.linalg.norm(c2w[:3, 3])
                for name, c2w in _recovered(tmp_path / "scene").items()}
    zoomed = [name for name in focal if name.startswith("zoom")]
    others = [name for name in focal if not name.startswith("zoom")]
    assert len(zoomed) == 3 and len(others) >= 12
    ratio = np.median([focal[n] for n in zoomed]) / np.median([focal[n] for n in others])
    assert ratio == pytest.approx(2.0, rel=0.1)
    far = np.median([distance[n] for n in others])
    assert all(distance[n] == pytest.approx(far, rel=0.15) for n in zoomed), (
        {n: round(float(d), 2) for n, d in distance.items()}, focal)


def test_photos_named_with_spaces_are_placed(tmp_path):
    """COLMAP reads the list of pairs to match split on whitespace: kermit's 11 photos named as
    a computer names copies ("Photo 1 (copy).jpg") were all left unplaced, with advice to walk
    in smaller steps. Working names replace the whitespace; the report keeps the user's."""
    photos = tmp_path / "photos"
    photos.mkdir()
    for k, path in enumerate(sorted((DATA / "kermit").glob("*.jpg"))):
        (photos / f"Photo {k + 1} (copy).jpg").write_bytes(path.read_bytes())
    result = prepare(photos, tmp_path / "scene", PrepareOptions(max_side=320), show=False)
    assert result.report["placed"] >= 10  # as with their own names at 320 px (before: 0)
    shown = {f"Photo {k + 1} (copy).jpg" for k in range(11)}
    assert {Path(v["photo"]).name for v in result.report["views"]} <= shown
    assert set(result.report["unplaced"]) <= shown
    assert not any(" " in v["name"] for v in result.report["views"])
