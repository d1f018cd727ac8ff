"""Real variants of the formats: LLFF beside an incomplete COLMAP model or without `images/`,
nerfstudio's point cloud and missing masks, a COLMAP model without its images file."""

import json
import struct

import numpy as np
import pytest
from PIL import Image
from shared_data import DATA

from windowshop.config import SceneOptions
from windowshop.errors import UserError
from windowshop.scene import detect_format, load_scene, read_source
from windowshop.scene.cameras import look_at
from windowshop.scene.colmap import load_model, model_points, read_points
from windowshop.scene.inspect import summary_dict, summary_text
from windowshop.scene.ply import read_ply_points

BEER = DATA / "beer_can"
POINTS_TXT = """# 3D point list with one line of data per point:
#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)
1 0.5 -0.25 0.125 255 0 0 0.5 1 0 2 0 3 0
2 9.0 9.0 9.0 0 255 0 0.5 1 0
3 -0.5 0.25 -0.125 0 0 255 0.5 1 1 2 1 3 1 4 1
"""


def _llff(root, folder="images", size=(80, 40), focal=100.0):
    """Three frames of an LLFF capture: poses_bounds.npy (full-size 80x40 intrinsics) and images."""
    (root / folder).mkdir(parents=True)
    rows = []
    for i in range(3):
        Image.new("RGB", size, (200, 10, 10)).save(root / folder / f"{i:03d}.png")
        c2w = np.eye(4)[:3]
        c2w[:, 3] = [i * 0.1, 0.0, 3.0]
        llff = np.concatenate([-c2w[:, 1:2], c2w[:, 0:1], c2w[:, 2:]], 1)  # (down, right, back)
        rows.append(np.concatenate([np.concatenate([llff, [[40.0], [80.0], [focal]]], 1).ravel(),
                                    [1.0, 5.0]]))
    np.save(root / "poses_bounds.npy", np.array(rows))
    return root


def test_llff_beside_a_model_without_its_images_file_is_read_as_llff(tmp_path, caplog):
    """cameras and points but no images.txt: the poses are LLFF's, the points the model's, and
    the scene says so."""
    root = _llff(tmp_path / "scene")
    model = root / "sparse" / "0"
    model.mkdir(parents=True)
    (model / "cameras.txt").write_text("1 PINHOLE 80 40 100 100 40 20\n")
    (model / "points3D.txt").write_text(POINTS_TXT)
    assert detect_format(root) == ("llff", root)
    source = read_source(root)
    assert source.format == "llff" and len(source.frames) == 3
    # points seen by fewer than 3 images are left out, as from a complete model
    np.testing.assert_allclose(source.points, [[0.5, -0.25, 0.125], [-0.5, 0.25, -0.125]])
    assert "lacks images" in caplog.text
    scene = load_scene(root, SceneOptions(normalize=False))
    text = summary_text(scene)
    assert "poses_bounds.npy: 3 poses" in text and "2 COLMAP points (the model lacks images" in text
    assert any("sparse/0" in note for note in summary_dict(scene)["notes"])


@pytest.mark.skipif(not (BEER / "sparse" / "0").is_dir(), reason="shared test data not present")
def test_binary_points_read_alone_match_pycolmaps(tmp_path):
    """beer_can's points3D.bin read without pycolmap (as for a model without images.bin)."""
    model = BEER / "sparse" / "0"
    alone, full = read_points(model), model_points(load_model(model))
    assert len(alone) == len(full) > 100
    np.testing.assert_allclose(alone[np.lexsort(alone.T)], full[np.lexsort(full.T)])
    partial = tmp_path / "sparse" / "0"
    partial.mkdir(parents=True)
    for name in ("cameras.bin", "points3D.bin"):
        (partial / name).symlink_to(model / name)
    with pytest.raises(UserError, match=r"incomplete: no images\.bin/\.txt"):
        read_source(partial)  # alone, a model without poses is refused, with the reason


def test_llff_without_full_size_images_reads_the_largest_copies(tmp_path):
    root = _llff(tmp_path / "scene", folder="images_4", size=(20, 10))
    (root / "images_8").mkdir()
    for i in range(3):
        Image.new("RGB", (10, 5), (10, 200, 10)).save(root / "images_8" / f"{i:03d}.png")
    source = read_source(root)
    camera = source.frames[0].camera
    assert (camera.width, camera.height, camera.fx, camera.cx) == (20, 10, 25.0, 10.0)
    assert source.frames[0].prescaled == {2: root / "images_8" / "000.png"}  # images_8 is half of images_4
    half = load_scene(root, SceneOptions(downscale=2, normalize=False))
    assert half.views[0].image[0, 0, 1] == pytest.approx(200 / 255)  # from images_8
    assert any("images_4" in note for note in source.notes)


def _ply(path, points, binary=True):
    header = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\ncomment open3d\n"
              f"element vertex {len(points)}\nproperty double x\nproperty double y\nproperty double z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    if binary:
        body = b"".join(struct.pack("<3d3B", *p, 1, 2, 3) for p in points)
    else:
        body = "".join(f"{p[0]} {p[1]} {p[2]} 1 2 3\n" for p in points).encode()
    path.write_bytes(header.encode() + body)


@pytest.mark.parametrize("binary", [True, False])
def test_ply_points(tmp_path, binary):
    points = np.array([[0.5, -1.25, 2.0], [3.0, 0.0, -0.75]])
    _ply(tmp_path / "p.ply", points, binary)
    np.testing.assert_array_equal(read_ply_points(tmp_path / "p.ply"), points)
    (tmp_path / "bad.ply").write_text("solid mesh\n")
    with pytest.raises(UserError, match="not a PLY"):
        read_ply_points(tmp_path / "bad.ply")


def _nerfstudio(root, **meta):
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    frames = []
    for k in range(4):
        eye = np.array([3 * np.cos(k * 1.5), 3 * np.sin(k * 1.5), 1.0])
        Image.new("RGB", (16, 12), (90, 90, 90)).save(root / "images" / f"{k}.png")
        Image.new("L", (16, 12), 255).save(root / "masks" / f"{k}.png")
        frames.append({"file_path": f"images/{k}.png", "mask_path": f"masks/{k}.png",
                       "depth_file_path": f"depths/{k}.png",
                       "transform_matrix": look_at(eye, np.zeros(3), np.array([0.0, 0, 1])).tolist()})
    path = root / "transforms.json"
    path.write_text(json.dumps({"camera_model": "OPENCV", "fl_x": 20.0, "fl_y": 20.0, "cx": 8.0,
                                "cy": 6.0, "w": 16, "h": 12, "k1": 0.0, "k2": 0.0, "k3": 0.0,
                                "k4": 0.0, "p1": 0.0, "p2": 0.0,
                                "applied_transform": np.eye(4)[:3].tolist(), "frames": frames, **meta}))
    return path


def test_nerfstudio_point_cloud_and_every_field_ns_process_data_writes(tmp_path):
    path = _nerfstudio(tmp_path, ply_file_path="sparse_pc.ply")
    points = np.array([[0.1, 0.2, 0.3]] * 8)
    _ply(tmp_path / "sparse_pc.ply", points)
    source = read_source(path)
    np.testing.assert_array_equal(source.points, points)
    assert all(f.distortion is None and f.mask_path is not None for f in source.frames)
    (tmp_path / "sparse_pc.ply").unlink()
    source = read_source(path)
    assert source.points is None and "missing" in source.notes[0]


def test_nerfstudio_missing_masks_leave_every_mask_out(tmp_path, caplog):
    path = _nerfstudio(tmp_path)
    (tmp_path / "masks" / "2.png").unlink()
    source = read_source(path)
    assert all(f.mask_path is None for f in source.frames)
    assert "masks/2.png" in caplog.text and "no masks used" in source.notes[0]
    scene = load_scene(path, SceneOptions(normalize=False))
    assert all(v.alpha is None for v in scene.views)


def test_nerfstudio_downscaled_copies_are_read_for_a_downscaled_scene(tmp_path):
    path = _nerfstudio(tmp_path)
    (tmp_path / "images_2").mkdir()
    for k in range(4):
        Image.new("RGB", (8, 6), (10, 200, 10)).save(tmp_path / "images_2" / f"{k}.png")
    assert read_source(path).frames[0].prescaled == {2: tmp_path / "images_2" / "0.png"}
    half = load_scene(path, SceneOptions(downscale=2, normalize=False))
    full = load_scene(path, SceneOptions(normalize=False))
    assert half.views[0].image[0, 0, 1] == pytest.approx(200 / 255)  # the copy
    assert full.views[0].image[0, 0, 1] == pytest.approx(90 / 255)  # the original
    assert half.views[0].camera.fx == pytest.approx(10.0)
