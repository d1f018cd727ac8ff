"""Bad input gets a UserError that names the file and the problem."""

import json

import numpy as np
import pytest
from PIL import Image

from windowshop.config import SceneOptions
from windowshop.errors import UserError
from windowshop.scene import load_scene
from windowshop.scene.cameras import look_at


def _pose(k: int) -> list:
    angle = 2 * np.pi * k / 6
    eye = np.array([3 * np.cos(angle), 3 * np.sin(angle), 1.0])
    return look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])).tolist()


def _write(tmp_path, frames, **meta):
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps({"frames": frames, **meta}))
    return path


def _scene(tmp_path, n=6, size=(16, 12), **meta):
    (tmp_path / "images").mkdir(exist_ok=True)
    frames = []
    for k in range(n):
        Image.new("RGB", size, (k * 30, 90, 160)).save(tmp_path / "images" / f"{k}.png")
        frames.append({"file_path": f"images/{k}.png", "transform_matrix": _pose(k)})
    return frames, {"fl_x": 20.0, "fl_y": 20.0, **meta}


def test_a_good_scene_loads(tmp_path):
    frames, meta = _scene(tmp_path)
    scene = load_scene(_write(tmp_path, frames, **meta))
    assert len(scene.views) == 6 and scene.views[0].image.shape == (12, 16, 3)


def test_missing_image(tmp_path):
    frames, meta = _scene(tmp_path)
    (tmp_path / "images" / "3.png").unlink()
    with pytest.raises(UserError, match=r"3\.png: image file not found"):
        load_scene(_write(tmp_path, frames, **meta))


def test_undecodable_image(tmp_path):
    frames, meta = _scene(tmp_path)
    (tmp_path / "images" / "2.png").write_bytes(b"this is not a png")
    with pytest.raises(UserError, match=r"2\.png: cannot decode the image"):
        load_scene(_write(tmp_path, frames, **meta))


def test_a_pose_that_is_not_a_rotation(tmp_path):
    frames, meta = _scene(tmp_path)
    bad = np.array(frames[4]["transform_matrix"])
    bad[:3, :3] *= 1.5  # a scaled, not orthonormal, rotation block
    frames[4]["transform_matrix"] = bad.tolist()
    with pytest.raises(UserError, match=r"transforms\.json frame 4: the pose is not a rotation"):
        load_scene(_write(tmp_path, frames, **meta))


def test_a_reflection_is_not_a_rotation(tmp_path):
    frames, meta = _scene(tmp_path)
    frames[1]["transform_matrix"] = (np.array(frames[1]["transform_matrix"]) @ np.diag([-1, 1, 1, 1])).tolist()
    with pytest.raises(UserError, match="frame 1: the pose is not a rotation"):
        load_scene(_write(tmp_path, frames, **meta))


def test_mixed_image_sizes_with_one_global_intrinsic(tmp_path):
    frames, meta = _scene(tmp_path)
    Image.new("RGB", (20, 12)).save(tmp_path / "images" / "5.png")
    with pytest.raises(UserError, match=r"5\.png: the image is 20x12 but its camera is 16x12"):
        load_scene(_write(tmp_path, frames, **meta))


def test_mixed_sizes_are_fine_with_per_frame_intrinsics(tmp_path):
    frames, meta = _scene(tmp_path)
    Image.new("RGB", (20, 12)).save(tmp_path / "images" / "5.png")
    frames[5].update({"w": 20, "h": 12, "cx": 10.0})
    scene = load_scene(_write(tmp_path, frames, **meta), SceneOptions(normalize=False))
    assert scene.views[-1].image.shape == (12, 20, 3) and scene.views[-1].camera.cx == 10.0


def test_empty_frame_list(tmp_path):
    with pytest.raises(UserError, match=r"transforms\.json: .*empty"):
        load_scene(_write(tmp_path, [], fl_x=20.0))


def test_empty_blender_split_files(tmp_path):
    (tmp_path / "transforms_train.json").write_text(json.dumps({"camera_angle_x": 0.7, "frames": []}))
    with pytest.raises(UserError, match="empty frame list"):
        load_scene(tmp_path)


def test_unknown_format(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(UserError, match="unknown scene format"):
        load_scene(tmp_path)
    with pytest.raises(UserError, match="no such file"):
        load_scene(tmp_path / "missing")


def test_broken_json(tmp_path):
    (tmp_path / "transforms.json").write_text("{not json")
    with pytest.raises(UserError, match=r"transforms\.json: cannot read"):
        load_scene(tmp_path)


def test_an_unsupported_camera_model_is_refused(tmp_path):
    frames, meta = _scene(tmp_path)
    with pytest.raises(UserError, match="EQUIRECTANGULAR is not supported"):
        load_scene(_write(tmp_path, frames, camera_model="EQUIRECTANGULAR", **meta))


def test_too_many_views(tmp_path):
    frames, meta = _scene(tmp_path)
    with pytest.raises(UserError, match="asked for 9 training views"):
        load_scene(_write(tmp_path, frames, **meta), SceneOptions(views=9))


def test_middlebury_line_with_missing_numbers(tmp_path):
    (tmp_path / "x_par.txt").write_text("1\nimg.png 1 0 0 0 1 0 0 0 1\n")
    with pytest.raises(UserError, match=r"x_par\.txt line for img\.png: expected"):
        load_scene(tmp_path)


def test_llff_count_mismatch(tmp_path):
    (tmp_path / "images").mkdir()
    Image.new("RGB", (8, 8)).save(tmp_path / "images" / "a.png")
    np.save(tmp_path / "poses_bounds.npy", np.zeros((2, 17)))
    with pytest.raises(UserError, match="2 poses but 1 images"):
        load_scene(tmp_path)


def test_mask_of_the_wrong_size(tmp_path):
    frames, meta = _scene(tmp_path)
    (tmp_path / "masks").mkdir()
    for k, frame in enumerate(frames):
        Image.new("L", (16, 12) if k != 2 else (8, 6), 255).save(tmp_path / "masks" / f"{k}.png")
        frame["mask_path"] = f"masks/{k}.png"
    with pytest.raises(UserError, match=r"masks/2\.png: the mask is 8x6 but its image is 16x12"):
        load_scene(_write(tmp_path, frames, **meta))
