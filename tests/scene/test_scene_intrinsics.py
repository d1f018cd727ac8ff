"""Every intrinsic a transforms file's producers write is used (Blender layout too): off-centre
principal points, per-frame overrides, fields of view on either axis, OpenCV and fisheye lenses."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from windowshop.config import SceneOptions
from windowshop.errors import UserError
from windowshop.rays import camera_rays, project
from windowshop.scene import load_scene, read_source
from windowshop.scene.cameras import look_at
from windowshop.scene.colmap import colmap_camera
from windowshop.scene.distortion import Distortion, distort
from windowshop.scene.intrinsics import frame_intrinsics

RAW = SceneOptions(normalize=False)


def _pose(k: int, n: int = 6) -> list:
    angle = 2 * np.pi * k / n
    eye = np.array([3 * np.cos(angle), 3 * np.sin(angle), 1.0])
    return look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])).tolist()


def _blender(root, meta: dict, size=(40, 30), frame_extra=None, n=6):
    """A Blender-layout folder: transforms_train.json with `meta` and n grey images."""
    (root / "train").mkdir(parents=True, exist_ok=True)
    frames = []
    for k in range(n):
        Image.new("RGB", size, (120, 120, 120)).save(root / "train" / f"r_{k}.png")
        frames.append({"file_path": f"./train/r_{k}", "transform_matrix": _pose(k, n),
                       **((frame_extra or {}).get(k, {}))})
    (root / "transforms_train.json").write_text(json.dumps({**meta, "frames": frames}))
    return root


def test_blender_layout_uses_instant_ngp_intrinsics(tmp_path):
    """A point projects where fx, fy, cx, cy say, not through the image centre."""
    meta = {"camera_angle_x": 0.9, "fl_x": 50.0, "fl_y": 45.0, "cx": 12.0, "cy": 20.0, "w": 40, "h": 30}
    scene = load_scene(_blender(tmp_path, meta), RAW)
    camera = scene.views[0].camera
    assert (camera.fx, camera.fy, camera.cx, camera.cy) == (50.0, 45.0, 12.0, 20.0)
    # a point 0.2 right of and 0.1 below the optical axis, 2 in front of the camera
    point = camera.c2w[:3, :3] @ np.array([0.2, -0.1, -2.0]) + camera.c2w[:3, 3]
    uv, depth = project(point[None], camera)
    np.testing.assert_allclose(uv[0], [12.0 + 50.0 * 0.1, 20.0 + 45.0 * 0.05])
    # and the ray through that pixel goes through the point
    origins, dirs = camera_rays(camera)
    pixel = int(uv[0, 1]) * camera.width + int(uv[0, 0])  # the pixel whose centre is (17.5, 22.5)
    to_point = (point - origins[pixel].numpy()) / np.linalg.norm(point - origins[pixel].numpy())
    assert np.degrees(np.arccos(np.clip(to_point @ dirs[pixel].numpy(), -1, 1))) < 1.0


def test_blender_frames_override_the_files_intrinsics(tmp_path):
    meta = {"camera_angle_x": 0.9}
    extra = {2: {"fl_x": 33.0, "cx": 10.0}, 4: {"camera_angle_x": 1.2, "cy": 11.0}}
    source = read_source(_blender(tmp_path, meta, frame_extra=extra))
    base = 0.5 * 40 / np.tan(0.45)
    cams = [f.camera for f in source.frames]
    assert cams[0].fx == pytest.approx(base) and (cams[0].cx, cams[0].cy) == (20.0, 15.0)
    assert (cams[2].fx, cams[2].fy, cams[2].cx) == (33.0, 33.0, 10.0)  # one focal: both axes
    assert cams[4].fx == pytest.approx(0.5 * 40 / np.tan(0.6)) and cams[4].cy == 11.0


def test_a_vertical_field_of_view_alone_or_beside_the_horizontal_one():
    cam, _ = frame_intrinsics({"camera_angle_y": 0.8}, {}, (40, 30), "test")
    assert cam.fx == cam.fy == pytest.approx(0.5 * 30 / np.tan(0.4))
    cam, _ = frame_intrinsics({"camera_angle_x": 0.9, "camera_angle_y": 0.8}, {}, (40, 30), "test")
    assert cam.fx == pytest.approx(20 / np.tan(0.45)) and cam.fy == pytest.approx(15 / np.tan(0.4))
    with pytest.raises(UserError, match="no focal length"):
        frame_intrinsics({}, {"cx": 3.0}, (40, 30), "test")


def test_blender_layout_distortion_is_undistorted(tmp_path):
    meta = {"fl_x": 50.0, "fl_y": 50.0, "cx": 20.0, "cy": 15.0, "k1": 0.2, "k2": 0.01,
            "p1": 0.003, "p2": -0.002}
    scene = load_scene(_blender(tmp_path, meta), RAW)
    view = scene.views[0]
    assert view.distortion == {"k1": 0.2, "k2": 0.01, "p1": 0.003, "p2": -0.002}
    assert view.camera.fx > 50.0  # pincushion: the pinhole zooms in to stay inside the photo


def test_fisheye_model_on_a_known_point():
    d = Distortion(k1=0.05, k2=-0.01, k3=0.002, k4=-0.001, fisheye=True)
    x, y = 0.3, -0.2
    r = np.hypot(x, y)
    theta = np.arctan(r)
    theta_d = theta * (1 + 0.05 * theta**2 - 0.01 * theta**4 + 0.002 * theta**6 - 0.001 * theta**8)
    np.testing.assert_allclose(distort(np.array([[x, y]]), d)[0], [x * theta_d / r, y * theta_d / r])
    assert not Distortion(fisheye=True).is_identity  # equidistant is not a pinhole


def test_a_fisheye_photo_undistorts_to_the_ray_of_its_point(tmp_path):
    """A dot painted where a fisheye lens images a 3D point ends, after loading, on the pixel whose
    ray goes through that point."""
    lens = {"camera_model": "OPENCV_FISHEYE", "fl_x": 40.0, "fl_y": 40.0, "cx": 41.0, "cy": 29.0,
            "w": 80, "h": 60, "k1": 0.02, "k2": -0.01}
    fisheye = Distortion(k1=0.02, k2=-0.01, fisheye=True)
    c2w = np.array(_pose(0))
    point_cam = np.array([0.9, 0.5, 1.5])  # OpenCV camera axes: far off the axis (31 degrees)
    xy = distort((point_cam[:2] / point_cam[2])[None], fisheye)[0]
    seen = np.array([40.0 * xy[0] + 41.0, 40.0 * xy[1] + 29.0])
    j, i = np.mgrid[0:60, 0:80] + 0.5
    dot = np.exp(-((i - seen[0]) ** 2 + (j - seen[1]) ** 2) / (2 * 1.2**2))
    (tmp_path / "images").mkdir()
    Image.fromarray((255 * dot).astype(np.uint8)).convert("RGB").save(tmp_path / "images" / "0.png")
    frames = [{"file_path": "images/0.png", "transform_matrix": c2w.tolist()}]
    (tmp_path / "transforms.json").write_text(json.dumps({**lens, "frames": frames}))
    view = load_scene(tmp_path / "transforms.json", RAW).views[0]
    image = view.image[..., 0]
    jj, ii = np.mgrid[0:view.camera.height, 0:view.camera.width] + 0.5
    centroid = np.array([(image * ii).sum(), (image * jj).sum()]) / image.sum()
    ideal = np.array([view.camera.fx * point_cam[0] / point_cam[2] + view.camera.cx,
                      view.camera.fy * point_cam[1] / point_cam[2] + view.camera.cy])
    assert np.linalg.norm(centroid - ideal) < 0.3
    # read as a pinhole, the painted dot would have given a ray degrees away from the point
    naive = np.array([(seen[0] - 41.0) / 40.0, (seen[1] - 29.0) / 40.0, 1.0])
    cosine = naive @ point_cam / np.linalg.norm(naive) / np.linalg.norm(point_cam)
    assert np.degrees(np.arccos(cosine)) > 2.0


def test_colmap_fisheye_models_map_their_parameters():
    def cam(name, params):
        return SimpleNamespace(model=SimpleNamespace(name=name), params=params, width=80, height=60)

    pinhole, d = colmap_camera(cam("OPENCV_FISHEYE", [40, 41, 39, 29, 0.1, 0.2, 0.3, 0.4]), np.eye(4), "t")
    assert (pinhole.fx, pinhole.fy, pinhole.cx, pinhole.cy) == (40, 41, 39, 29)
    assert d == Distortion(k1=0.1, k2=0.2, k3=0.3, k4=0.4, fisheye=True)
    _, d = colmap_camera(cam("RADIAL_FISHEYE", [40, 39, 29, 0.1, 0.2]), np.eye(4), "t")
    assert d == Distortion(k1=0.1, k2=0.2, fisheye=True)
    _, d = colmap_camera(cam("SIMPLE_RADIAL_FISHEYE", [40, 39, 29, 0.0]), np.eye(4), "t")
    assert d == Distortion(fisheye=True)  # still equidistant, so still undistorted
    with pytest.raises(UserError, match="FULL_OPENCV"):
        colmap_camera(cam("FULL_OPENCV", [40] * 12), np.eye(4), "t")
