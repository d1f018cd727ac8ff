"""Turntable camera paths: orbit fitting, orbit and spiral poses, camera-path files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from windowshop.config import VideoOptions
from windowshop.errors import UserError
from windowshop.model import Bounds
from windowshop.rays import project
from windowshop.scene.types import Camera
from windowshop.video.paths import (
    fit_orbit,
    read_camera_path,
    spiral_elevations,
    turntable_path,
    write_camera_path,
)
from shared_data import DATA

LEGO = DATA / "lego"
BOX = Bounds(aabb=((-1.0,) * 3, (1.0,) * 3), near=0.01, far=100.0)  # about the capture's centre


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by `angle` radians about unit `axis` (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def capture(azimuths_deg, elevations_deg, radius=3.0, centre=(0, 0, 0), world=np.eye(3), size=40,
            focal=50.0) -> list[Camera]:
    """Level cameras looking at `centre` on a sphere about +z, then rotated by `world` (3, 3).

    Built from explicit formulas (not the module under test): right is horizontal, up is the
    projection of +z, the camera looks along -z of its own axes.
    """
    cameras = []
    for az, el in zip(np.radians(azimuths_deg), np.radians(elevations_deg)):
        offset = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        right = np.array([-math.sin(az), math.cos(az), 0.0])
        back = offset
        up = np.cross(back, right)
        c2w = np.eye(4)
        c2w[:3, :3] = world @ np.stack([right, up, back], axis=1)
        c2w[:3, 3] = np.asarray(centre) + world @ (radius * offset)
        cameras.append(Camera(focal, focal, size / 2, size / 2, size, size, c2w))
    return cameras


def orbit_coordinates(cameras, centre, up, reference):
    """Azimuth (deg), elevation (deg) and distance of every camera centre about `centre`, `up`."""
    side = np.cross(up, reference)
    eyes = np.stack([c.center for c in cameras]) - centre
    dist = np.linalg.norm(eyes, axis=1)
    az = np.degrees(np.arctan2(eyes @ side, eyes @ reference))
    el = np.degrees(np.arcsin(eyes @ up / dist))
    return az, el, dist


def assert_centred_and_upright(cameras, centre, up):
    """The centre projects to the image centre and a point above it straight above it."""
    for cam in cameras:
        uv, depth = project(np.stack([centre, centre + 0.1 * up]), cam)
        assert depth[0] > 0
        np.testing.assert_allclose(uv[0], [cam.width / 2, cam.height / 2], atol=1e-6)
        assert abs(uv[1, 0] - uv[0, 0]) < 1e-6 and uv[1, 1] < uv[0, 1]  # same column, higher row


def test_fit_orbit_recovers_a_tilted_offset_partial_arc():
    # A 120-degree arc at several heights, in a world whose up is tilted and whose object is
    # off the origin: the average camera up would lean towards the arc; the right axes do not.
    world = rotation(np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5]), 0.7)
    centre = np.array([0.4, -0.3, 0.2])
    cams = capture(np.linspace(10, 130, 9), [20, 35, 50, 20, 35, 50, 20, 35, 50], radius=2.5,
                   centre=centre, world=world)
    orbit = fit_orbit(cams)
    np.testing.assert_allclose(orbit.centre, centre, atol=1e-3)
    np.testing.assert_allclose(orbit.up, world[:, 2], atol=1e-9)
    assert orbit.radius == pytest.approx(2.5, abs=1e-3)
    assert orbit.elevation == pytest.approx(35.0, abs=1e-3)
    assert orbit.fov == pytest.approx(math.degrees(2 * math.atan(20 / 50)))


def test_orbit_is_centred_evenly_spaced_at_constant_elevation_and_radius():
    train = capture(np.arange(0, 360, 30) + 17, [10, 40] * 6, radius=4.0)
    options = VideoOptions(frames=24, width=64, height=48, start_angle=15.0)
    cams = turntable_path(train, options, BOX)
    orbit = fit_orbit(train)
    assert len(cams) == 24 and all((c.width, c.height) == (64, 48) for c in cams)
    az, el, dist = orbit_coordinates(cams, orbit.centre, orbit.up, orbit.reference)
    steps = np.diff(np.unwrap(np.radians(az)))
    np.testing.assert_allclose(np.degrees(steps), 15.0, atol=1e-9)
    assert az[0] == pytest.approx(15.0)  # start angle is measured from the first training camera
    np.testing.assert_allclose(el, 25.0, atol=1e-6)  # median of the training elevations
    np.testing.assert_allclose(dist, dist[0], atol=1e-9)  # one radius (framing the box: test_framing)
    assert_centred_and_upright(cams, orbit.centre, orbit.up)


def test_orbit_options_override_radius_elevation_and_fov():
    train = capture(np.arange(0, 360, 45), [30] * 8)
    cams = turntable_path(train, VideoOptions(frames=8, width=32, height=32, radius=2.0,
                                              elevation=-10.0, fov=60.0), BOX)
    az, el, dist = orbit_coordinates(cams, np.zeros(3), np.array([0, 0, 1.0]), np.array([1.0, 0, 0]))
    np.testing.assert_allclose(dist, 2.0, atol=1e-9)
    np.testing.assert_allclose(el, -10.0, atol=1e-9)
    assert cams[0].fy == pytest.approx(16 / math.tan(math.radians(30)))


def test_a_portrait_turntable_keeps_the_training_view_across_its_narrow_side():
    train = capture(np.arange(0, 360, 45), [30] * 8, size=40, focal=50.0)  # square photos
    # a box that is widest seen from the first camera and far enough to need no zoom
    box = Bounds(aabb=((-0.1, -0.5, -0.2), (0.1, 0.5, 0.2)), near=0.01, far=100.0)
    (cam,) = turntable_path(train, VideoOptions(frames=1, width=32, height=64), box)
    assert cam.fx == pytest.approx(50.0 * 32 / 40) and cam.fy == cam.fx  # width sees what they saw


def test_spiral_swings_elevation_up_and_down_around_the_orbit():
    train = capture(np.arange(0, 360, 45), [30] * 8)
    cams = turntable_path(train, VideoOptions(frames=40, width=32, height=32, path="spiral",
                                              spiral_amplitude=12.0, radius=3.0), BOX)
    up, ref = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
    az, el, dist = orbit_coordinates(cams, np.zeros(3), up, ref)
    np.testing.assert_allclose(el, spiral_elevations(30.0, 12.0, 40), atol=1e-9)
    assert el.max() == pytest.approx(42.0) and el.min() == pytest.approx(18.0)
    np.testing.assert_allclose(dist, 3.0, atol=1e-9)
    np.testing.assert_allclose(np.degrees(np.diff(np.unwrap(np.radians(az)))), 9.0, atol=1e-9)
    assert_centred_and_upright(cams, np.zeros(3), up)


def test_camera_path_json_round_trip(tmp_path):
    train = capture(np.arange(0, 360, 45), [30] * 8)
    cams = turntable_path(train, VideoOptions(frames=6, width=40, height=30, fov=50.0), BOX)
    path = write_camera_path(cams, tmp_path / "path.json", fps=24)
    doc = json.loads(path.read_text())
    assert doc["render_width"] == 40 and doc["render_height"] == 30
    assert len(doc["camera_path"]) == 6 and len(doc["camera_path"][0]["camera_to_world"]) == 16
    assert doc["camera_path"][0]["fov"] == pytest.approx(50.0)
    back = read_camera_path(path)
    for a, b in zip(cams, back):
        np.testing.assert_allclose(b.c2w, a.c2w, atol=1e-12)
        assert (b.fx, b.fy, b.cx, b.cy, b.width, b.height) == pytest.approx(
            (a.fx, a.fy, a.cx, a.cy, a.width, a.height))
    # a path file is a path option too
    assert len(turntable_path(train, VideoOptions(path=str(path)), BOX)) == 6


def test_camera_path_reads_nerfstudio_row_major_layout(tmp_path):
    c2w = np.eye(4)
    c2w[:3, 3] = [1.0, 2.0, 3.0]  # translation is the last column of the first three rows
    doc = {"render_width": 20, "render_height": 10,
           "camera_path": [{"camera_to_world": c2w.reshape(-1).tolist(), "fov": 90.0, "aspect": 2.0}]}
    (tmp_path / "p.json").write_text(json.dumps(doc))
    (cam,) = read_camera_path(tmp_path / "p.json")
    np.testing.assert_allclose(cam.center, [1.0, 2.0, 3.0])
    assert cam.fy == pytest.approx(5.0) and cam.fx == pytest.approx(5.0)  # vertical fov, square pixels


@pytest.mark.parametrize("content", ["not json", '{"camera_path": []}',
                                     '{"render_width": 8, "render_height": 8, "camera_path": '
                                     '[{"camera_to_world": [1, 0, 0], "fov": 40}]}'])
def test_bad_camera_path_is_a_user_error_naming_the_file(tmp_path, content):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(UserError, match="bad.json"):
        read_camera_path(path)
    with pytest.raises(UserError, match="missing.json"):
        read_camera_path(tmp_path / "missing.json")


@pytest.mark.skipif(not LEGO.is_dir(), reason="shared lego data not present")
def test_lego_orbit_matches_its_capture_ring():
    from windowshop.config import SceneOptions
    from windowshop.scene import load_scene

    from windowshop.scene.cameras import box_corners

    scene = load_scene(LEGO, SceneOptions(max_side=20, test_views=1))  # few images: quick
    train = [v.camera for v in scene.split("train")]
    orbit = fit_orbit(train)
    bounds = Bounds.of_scene(scene)
    cams = turntable_path(train, VideoOptions(frames=12, width=32, height=32), bounds)
    # Back in lego's own frame the photos' ring has radius 4.03 about the origin, up +z.
    assert orbit.radius / scene.scale == pytest.approx(4.03, abs=0.05)
    # The turntable frames lego's box instead, within the depths the model renders.
    for cam in cams:
        uv, depth = project(box_corners(bounds.aabb), cam)
        assert (uv > 0).all() and (uv < 32).all()
        assert max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1])) / 32 == pytest.approx(0.8, abs=0.05)
        assert depth.max() <= bounds.far + 1e-6
    # ... about its centre, at the photos' median elevation about that centre
    centre = np.asarray(bounds.aabb).mean(0)
    _, el, _ = orbit_coordinates(cams, centre, orbit.up, orbit.reference)
    train_el = orbit_coordinates(train, centre, orbit.up, orbit.reference)[1]
    assert np.ptp(el) < 1e-6 and train_el.min() < el[0] < train_el.max()
    assert el[0] == pytest.approx(np.median(train_el), abs=0.5)
    assert_centred_and_upright(cams, centre, orbit.up)
