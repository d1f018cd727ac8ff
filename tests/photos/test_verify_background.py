"""The background check on real photos: 8 frames of beer_can's walk (1.5 turns round a can
printed with its logo twice) that structure from motion folds, placing photos of opposite sides
side by side; their matches all lie on the can, none on the room behind it, and prepare refuses
the fold with what to reshoot instead of delivering it. (Against this repository's own model of
all 70 frames, bench/bench_verify.py: 5 of these 8 photos land 156-180 degrees off.)"""

from __future__ import annotations

import pytest

from windowshop.config import PrepareOptions
from windowshop.errors import UserError
from windowshop.photos.prepare import prepare
from windowshop.photos.verify import background
from shared_data import DATA

FOLDED = ("0002", "0008", "0020", "0026", "0027", "0047", "0060", "0064")


# the published focal length and centre (photo pixels): with them known, as `--intrinsics` or
# a phone's EXIF focal length give them, the pairs across the fold keep 1-5 chance matches on
# the floor's tiles (shares 0.01-0.04 of their inliers), which the model holds in no 3D point
PUBLISHED = (1105.13, 1105.13, 360.0, 640.0)


@pytest.mark.parametrize("intrinsics", [None, PUBLISHED], ids=["default prior", "focal known"])
def test_a_fold_whose_matches_all_lie_on_the_object_is_refused(tmp_path, intrinsics):
    photos = tmp_path / "photos"
    photos.mkdir()
    for name in FOLDED:
        (photos / f"{name}.jpg").symlink_to(DATA / "beer_can" / "images" / f"{name}.jpg")
    with pytest.raises(UserError) as refused:
        prepare(photos, tmp_path / "scene", PrepareOptions(intrinsics=intrinsics), show=False)
    message = str(refused.value)
    assert "match only on the object" in message, message
    assert "look alike" in message  # what to reshoot: the check's advice
    assert not (tmp_path / "scene" / "transforms.json").exists()  # nothing a later run could take


def test_a_few_photos_folded_once_are_refused(tmp_path):
    """Six frames over 155 degrees of the walk, every fifth: the wide retry places them all, 0025
    (at 32 degrees round the can) beside 0000 (at 237) by the logo they both show, and 0020 off
    the circle. Only 3 pairs stand side by side, too few for MIN_CONFLICTS; the one that matches
    only on the can is a third of them (SMALL_SHARE), and no other hypothesis passes."""
    photos = tmp_path / "photos"
    photos.mkdir()
    for name in ("0000", "0005", "0010", "0015", "0020", "0025"):
        (photos / f"{name}.jpg").symlink_to(DATA / "beer_can" / "images" / f"{name}.jpg")
    with pytest.raises(UserError) as refused:
        prepare(photos, tmp_path / "scene", PrepareOptions(), show=False)
    message = str(refused.value)
    # refused as a fold by the background check, or with the photos the print on the can's far
    # side misplaced left out, too few to check (verify.alone's FAR_DEG, stop 59)
    assert ("0000.jpg-0025.jpg" in message and "look alike" in message
            or "could only place 4 of 6" in message and "0020.jpg" in message), message
    assert not (tmp_path / "scene" / "transforms.json").exists()


@pytest.mark.parametrize("conflicts, near, folded", [
    (1, 3, True), (2, 5, True), (1, 5, False), (3, 19, False),  # a few photos
    (4, 18, True), (19, 181, False), (0, 2, False)])  # many
def test_a_share_of_the_side_by_side_pairs_folds_however_few(conflicts, near, folded):
    assert background.folded(conflicts, near) is folded


def test_the_check_does_not_apply_without_outlines():
    from windowshop.photos.verify.types import Hypothesis

    assert background.check(Hypothesis("as mapped", sfm=None)) is None


def _two_cameras():
    """Two placed photos of a 500-px pinhole camera, the second a unit step to the right of the
    first, both looking down +z (COLMAP's axes)."""
    import numpy as np
    import pycolmap

    model = pycolmap.Reconstruction()
    model.add_camera_with_trivial_rig(pycolmap.Camera(
        model="SIMPLE_PINHOLE", width=640, height=480, params=[500, 320, 240], camera_id=1))
    for image_id, x in ((1, 0.0), (2, 1.0)):
        model.add_image_with_trivial_frame(
            pycolmap.Image(name=f"{image_id}.jpg", keypoints=np.zeros((0, 2)), camera_id=1,
                           image_id=image_id),
            pycolmap.Rigid3d(pycolmap.Rotation3d(np.eye(3)), np.array([-x, 0.0, 0.0])))
    return model.images[1], model.images[2]


def test_a_match_the_poses_explain_meets_in_front_of_both_cameras():
    import numpy as np

    first, second = _two_cameras()
    points = np.array([[0.0, 0.0, 5.0], [0.5, 0.3, 8.0], [-1.0, 0.2, 3.0]])
    row = 240 + 500 * points[:, 1] / points[:, 2]
    seen = np.c_[320 + 500 * points[:, 0] / points[:, 2], row]
    other = np.c_[320 + 500 * (points[:, 0] - 1) / points[:, 2], row]
    assert background._explained(first, second, seen, other).all()
    # along the epipolar line (the same row): another depth, still in front of both
    assert background._explained(first, second, seen, other - [100, 0]).all()
    # off it by 20 px: no point projects within MAX_ERROR_PX of both
    assert not background._explained(first, second, seen, other + [0, 20]).any()
    # past the point at infinity: the rays meet behind the cameras
    assert not background._explained(first, second, seen, other + [300, 0]).any()
