"""The phone's sensors as priors (windowshop.photos.sensors): capture.json read and checked, the
up each photo measured carried into the world by its pose, pairs chosen by heading, and the
gravity written where pycolmap's global mapper reads it."""

from __future__ import annotations

import json

import numpy as np
import pycolmap
import pytest

from windowshop.errors import UserError
from windowshop.photos import pairs, sensors, sfm
from windowshop.scene.cameras import look_at


def capture(path, photos, **extra):
    path.write_text(json.dumps({"format": sensors.FORMAT, "version": 1,
                                "sensors": "deviceorientation", "photos": photos, **extra}))
    return path


def test_capture_json_is_read_by_file_name(tmp_path):
    path = capture(tmp_path / "capture.json", [
        {"file": "a.jpg", "order": 1, "up": [0, -2, 0], "heading_deg": 370.0},
        {"file": "b.jpg", "order": 0, "up": None, "heading_deg": None},
        {"file": "gone.jpg", "order": 2, "up": [0, -1, 0]}])  # a photo not sent: ignored
    priors = sensors.read_capture(path, {"a.jpg": "a", "b.jpg": "b"})
    assert priors.sensors == "deviceorientation"
    np.testing.assert_allclose(priors.up["a"], [0, -1, 0])  # made unit length
    assert "b" not in priors.up and priors.heading == {"a": 10.0}
    assert priors.order == {"a": 1, "b": 0}
    assert priors.usable(["a", "b"], priors.up) and not priors.usable(["a", "b", "c"], priors.up)


@pytest.mark.parametrize("content, words", [
    ("not json", "not valid JSON"),
    (json.dumps({"photos": []}), "not a windowshop-capture file"),
    (json.dumps({"format": sensors.FORMAT, "photos": [{"file": "a.jpg", "up": [0, 1]}]}),
     "the up of a.jpg is not a direction"),
    (json.dumps({"format": sensors.FORMAT, "photos": [{"file": "a.jpg", "up": [0, 0, 0]}]}),
     "the up of a.jpg is not a direction"),
    (json.dumps({"format": sensors.FORMAT, "photos": [{"file": "a.jpg", "heading_deg": "x"}]}),
     "the heading of a.jpg is not a number"),
])
def test_a_capture_json_that_lies_is_refused_with_what_is_wrong(tmp_path, content, words):
    path = tmp_path / "capture.json"
    path.write_text(content)
    with pytest.raises(UserError, match=words) as err:
        sensors.read_capture(path, {"a.jpg": "a"})
    assert "remove it" in str(err.value)


def test_a_camera_frame_up_is_carried_into_the_world_by_the_pose():
    # an OpenGL camera at (0, -3, 1) looking down at the origin with +z up: its image's "up"
    # (OpenCV -y), tilted back toward the camera by the pitch (as the page writes it for a phone
    # pitched down), must come out as the world's +z
    c2w = look_at(np.array([0.0, -3.0, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    up_cv = c2w[:3, :3].T @ np.array([0.0, 0.0, 1.0]) * np.array([1.0, -1.0, -1.0])
    assert up_cv[1] < -0.9 and up_cv[2] < -0.2
    np.testing.assert_allclose(sensors.gl_up(c2w, up_cv), [0, 0, 1], atol=1e-12)


def test_world_up_is_a_robust_mean_and_names_the_photo_that_disagrees():
    rng = np.random.default_rng(0)
    c2ws, ups = {}, {}
    for i, azimuth in enumerate(np.radians(np.arange(0, 360, 30))):
        eye = np.array([3 * np.cos(azimuth), 3 * np.sin(azimuth), 1.5])
        c2ws[f"{i}.jpg"] = look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        noisy = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.02, 3)  # ~1 degree of sensor noise
        ups[f"{i}.jpg"] = c2ws[f"{i}.jpg"][:3, :3].T @ noisy * np.array([1.0, -1.0, -1.0])
    ups["3.jpg"] = -ups["3.jpg"]  # upside down: a lying sensor or a folded pose
    up, angles = sensors.world_up(c2ws, ups)
    assert np.degrees(np.arccos(up[2])) < 1.5
    assert angles["3.jpg"] > 170 and max(a for n, a in angles.items() if n != "3.jpg") < 4


def test_heading_pairs_never_match_opposite_sides():
    headings = [float(h) for h in range(0, 360, 45)] + [None]  # 8 photos round, one without
    chosen = pairs.heading_pairs(headings)
    assert (0, 1) in chosen and (0, 7) in chosen  # neighbours; the ring closes (0 and 315)
    assert (0, 2) in chosen and (1, 7) in chosen  # 90 degrees apart: a side seen obliquely
    assert (0, 3) not in chosen and (0, 4) not in chosen  # 135 and 180: opposite sides
    assert {(i, 8) for i in range(3, 8)} <= set(chosen)  # the one without: its 5 before it
    assert (2, 8) not in chosen


def test_only_photos_dense_in_heading_are_matched_by_heading():
    assert pairs.dense([float(h) for h in range(0, 360, 12)])  # the page: every 12 degrees
    assert not pairs.dense([float(h) for h in range(0, 360, 45)])  # 8 round: every pair needed
    assert not pairs.dense([None] * 10 + [0.0, 10.0])


def test_gravity_is_written_as_colmap_pose_priors(tmp_path):
    database = tmp_path / "database.db"
    with pycolmap.Database.open(database) as db:
        camera = db.write_camera(pycolmap.Camera.create_from_model_name(
            1, "SIMPLE_PINHOLE", 100.0, 64, 48), use_camera_id=True)
        ids = [db.write_image(pycolmap.Image(name=n, camera_id=camera)) for n in ("a.jpg", "b.jpg")]
    sfm.write_gravity(database, {"a.jpg": np.array([0.0, -1.0, 0.0])})
    with pycolmap.Database.open(database) as db:
        priors = db.read_all_pose_priors()
    assert len(priors) == 1 and priors[0].corr_data_id.id == ids[0]
    np.testing.assert_allclose(priors[0].gravity, [0, 1, 0])  # COLMAP's: gravity itself, down
