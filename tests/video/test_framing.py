"""Framing the object's box, the covered arc of a capture, the swing path and the poster's frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from windowshop.config import VideoOptions
from windowshop.model import Bounds
from windowshop.rays import project
from windowshop.scene.cameras import box_corners, look_at
from windowshop.scene.types import Camera
from windowshop.video.coverage import best_covered_frame, covered_arc, swing_azimuths
from windowshop.video.paths import plan_turntable

WIDE = (0.01, 100.0)  # near/far that never limit the distance


def ring(azimuths_deg, elevation_deg=20.0, radius=4.0, centre=(0.0, 0.0, 0.0), size=40,
         focal=50.0) -> list[Camera]:
    """Level cameras about +z on a ring round `centre`, looking at it (built with look_at only)."""
    cameras, el = [], math.radians(elevation_deg)
    for az in np.radians(azimuths_deg):
        eye = np.asarray(centre) + radius * np.array(
            [math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        cameras.append(Camera(focal, focal, size / 2, size / 2, size, size,
                              look_at(eye, np.asarray(centre, dtype=float), np.array([0, 0, 1.0]))))
    return cameras


def world_azimuths(cameras, centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Azimuths (degrees in [0, 360)) of camera centres about +z through `centre`."""
    eyes = np.stack([c.center for c in cameras]) - np.asarray(centre)
    return np.degrees(np.arctan2(eyes[:, 1], eyes[:, 0])) % 360


def box_in_frames(cameras, aabb) -> tuple[np.ndarray, np.ndarray]:
    """Per frame: the corners' (F, 8, 2) pixel positions and the larger projected extent (F,)
    as a fraction of the frame, through windowshop.rays.project (not the framing code)."""
    uvs, extents = [], []
    for cam in cameras:
        uv, depth = project(box_corners(aabb), cam)
        assert (depth > 0).all()
        uvs.append(uv)
        extents.append(max(np.ptp(uv[:, 0]) / cam.width, np.ptp(uv[:, 1]) / cam.height))
    return np.stack(uvs), np.array(extents)


@pytest.mark.parametrize("aabb", [((-1, -1, -1), (1, 1, 1)),  # a cube: wider seen corner-on
                                  ((-1.0, -0.3, -0.2), (1.0, 0.3, 0.2)),  # a long flat bar
                                  ((-0.2, -0.3, -1.0), (0.4, 0.3, 1.0)),  # a tall off-centre post
                                  ((0.5, 0.2, -0.1), (1.5, 0.6, 0.3))])  # a small box off the origin
@pytest.mark.parametrize("size,path", [((64, 64), "orbit"), ((96, 48), "orbit"), ((40, 80), "spiral")])
@pytest.mark.parametrize("elevation", [20.0, 60.0])
def test_the_box_fills_about_80_percent_of_every_frame_and_stays_inside(aabb, size, path, elevation):
    width, height = size
    train = ring(np.arange(0, 360, 30) + 5, elevation_deg=elevation, radius=4.0)
    plan = plan_turntable(train, VideoOptions(frames=36, width=width, height=height, path=path),
                          Bounds(aabb=aabb, near=WIDE[0], far=WIDE[1]))
    uv, extent = box_in_frames(plan.cameras, aabb)
    assert (uv[..., 0] > 0).all() and (uv[..., 0] < width).all()
    assert (uv[..., 1] > 0).all() and (uv[..., 1] < height).all()
    assert ((extent >= 0.75) & (extent <= 0.85)).all(), extent
    # the box's centre is what the camera looks at: the image centre
    centre = np.asarray(aabb, dtype=float).mean(0)
    for cam in plan.cameras:
        np.testing.assert_allclose(project(centre[None], cam)[0][0], [width / 2, height / 2], atol=1e-6)


def test_one_distance_all_round_and_the_widest_view_keeps_the_cameras_field_of_view():
    train = ring(np.arange(0, 360, 45), size=40, focal=100.0)  # 23 degrees: the distance is free
    plan = plan_turntable(train, VideoOptions(frames=8, width=64, height=64),
                          Bounds(aabb=((-1.0, -0.5, -0.5), (1.0, 0.5, 0.5)), near=WIDE[0], far=WIDE[1]))
    distances = [np.linalg.norm(c.center) for c in plan.cameras]
    np.testing.assert_allclose(distances, distances[0], rtol=1e-12)  # a circle, like a turntable
    focals = np.array([c.fy for c in plan.cameras])
    assert focals.min() == pytest.approx(100.0 * 64 / 40, rel=1e-6)  # broadside: the photos' view
    assert focals.max() > 1.3 * focals.min()  # end-on the bar is narrow: the view zooms in


def test_the_box_stays_within_the_models_near_and_far_and_the_focal_makes_up_the_fill():
    aabb = ((-1,) * 3, (1,) * 3)
    train = ring(np.arange(0, 360, 30), radius=4.0)
    free = plan_turntable(train, VideoOptions(frames=12, width=64, height=64),
                          Bounds(aabb=aabb, near=WIDE[0], far=WIDE[1])).cameras
    near, far = 1.5, 5.5  # the free framing (5.2 away) would put the far corners past 5.5
    plan = plan_turntable(train, VideoOptions(frames=12, width=64, height=64),
                          Bounds(aabb=aabb, near=near, far=far))
    corners = box_corners(aabb)
    for cam in plan.cameras:
        eye = cam.center
        assert np.linalg.norm(eye - np.clip(eye, -1, 1)) >= near - 1e-6
        assert np.linalg.norm(corners - eye, axis=1).max() <= far + 1e-6
    assert plan.cameras[0].fy < free[0].fy  # closer than it wished: a wider view ...
    _, extent = box_in_frames(plan.cameras, aabb)
    assert ((extent >= 0.75) & (extent <= 0.85)).all()  # ... that frames the box all the same


def test_an_explicit_radius_is_kept_and_the_view_zooms_to_frame_the_box():
    aabb = ((-0.5,) * 3, (0.5,) * 3)
    train = ring(np.arange(0, 360, 30))
    plan = plan_turntable(train, VideoOptions(frames=6, width=48, height=48, radius=6.0),
                          Bounds(aabb=aabb, near=WIDE[0], far=WIDE[1]))
    np.testing.assert_allclose([np.linalg.norm(c.center) for c in plan.cameras], 6.0, atol=1e-9)
    _, extent = box_in_frames(plan.cameras, aabb)
    assert ((extent >= 0.75) & (extent <= 0.85)).all()


@pytest.mark.parametrize("azimuths,start,span", [
    ([350.0, 10.0, 30.0], 350.0, 40.0),  # wraps round 0/360
    ([-20.0, 15.0, 5.0], 340.0, 35.0),  # negative angles are the same directions
    ([0.0, 30.0, 60.0, 90.0, 120.0], 0.0, 120.0),  # one-sided
    ([200.0, 100.0, 150.0, 120.0], 100.0, 100.0),  # unsorted
    ([42.0], 42.0, 0.0),  # one photo
])
def test_covered_arc(azimuths, start, span):
    got_start, got_span = covered_arc(np.array(azimuths))
    assert got_start == pytest.approx(start) and got_span == pytest.approx(span)


def test_covered_arc_of_a_full_circle_is_the_circle_less_its_widest_gap():
    azimuths = np.array([0, 30, 60, 90, 140, 180, 210, 240, 270, 300, 330.0])
    start, span = covered_arc(azimuths)
    assert (start, span) == (pytest.approx(140.0), pytest.approx(310.0))  # the gap is 90..140


def test_swing_goes_across_the_arc_and_back_smoothly():
    az = swing_azimuths(30.0, 100.0, 40)
    assert len(az) == 40 and az[0] == pytest.approx(30.0) and az.max() == pytest.approx(130.0)
    assert az[20] == pytest.approx(130.0)  # the far end half way through
    np.testing.assert_allclose(az[1:20], az[39:20:-1])  # back along the same way
    steps = np.diff(np.append(az, az[0]))
    assert np.abs(steps).max() <= 100.0 * math.pi / 40 + 1e-9  # no jump, the loop included
    assert abs(steps[0]) < abs(steps[10]) / 5  # eases in and out at the ends


def test_a_one_sided_capture_swings_across_the_photographed_arc_not_round():
    train = ring(np.linspace(40, 160, 9))  # the front only: 120 degrees
    plan = plan_turntable(train, VideoOptions(frames=30, width=32, height=32),
                          Bounds(aabb=((-1,) * 3, (1,) * 3), near=WIDE[0], far=WIDE[1]))
    assert plan.swing and len(plan.cameras) == 30
    assert plan.covered_span == pytest.approx(120.0, abs=1e-6)
    az = world_azimuths(plan.cameras)
    assert az.min() == pytest.approx(40.0, abs=1e-6) and az.max() == pytest.approx(160.0, abs=1e-6)
    summary = plan.summary()
    assert summary["swing"] is True and summary["covered_span_degrees"] == pytest.approx(120.0)
    full = plan_turntable(train, VideoOptions(frames=30, width=32, height=32, full_turn=True),
                          Bounds(aabb=((-1,) * 3, (1,) * 3), near=WIDE[0], far=WIDE[1]))
    assert not full.swing and np.ptp(world_azimuths(full.cameras)) > 340  # asked for: all round


def test_a_capture_all_round_gets_a_full_turn():
    train = ring(np.arange(0, 360, 40) + 3)  # 40-degree gaps: 320 covered
    plan = plan_turntable(train, VideoOptions(frames=12, width=32, height=32),
                          Bounds(aabb=((-1,) * 3, (1,) * 3), near=WIDE[0], far=WIDE[1]))
    assert not plan.swing and plan.covered_span == pytest.approx(320.0)
    steps = np.diff(np.unwrap(np.radians(world_azimuths(plan.cameras))))
    np.testing.assert_allclose(np.degrees(steps), 30.0, atol=1e-6)


def test_the_poster_faces_the_photographed_side():
    train = ring(np.concatenate([np.linspace(200, 240, 8), [20.0]]))  # a cluster and one stray
    bounds = Bounds(aabb=((-1,) * 3, (1,) * 3), near=WIDE[0], far=WIDE[1])
    for options in (VideoOptions(frames=24, width=32, height=32, full_turn=True),
                    VideoOptions(frames=24, width=32, height=32, start_angle=90.0, full_turn=True)):
        plan = plan_turntable(train, options, bounds)
        poster_az = world_azimuths([plan.cameras[plan.poster_frame]])[0]
        assert 205.0 <= poster_az <= 235.0  # the frame nearest the cluster's middle (220), not 20
    assert plan.poster_frame != 0


def test_best_covered_frame_prefers_the_dense_cluster_to_a_lone_camera():
    frames = np.arange(0, 360, 10.0)
    cameras = np.array([88.0, 90.0, 93.0, 95.0, 271.0])
    assert frames[best_covered_frame(frames, cameras)] == 90.0
    wrap = np.array([355.0, 358.0, 2.0, 4.0, 180.0])
    assert frames[best_covered_frame(frames, wrap)] == 0.0


def test_the_scenes_up_axis_keeps_photos_taken_sideways_upright():
    train = ring(np.arange(0, 360, 30))
    for cam in train:  # every photo rolled a quarter turn: their right axes all point up
        cam.c2w[:3, :2] = np.stack([cam.c2w[:3, 1], -cam.c2w[:3, 0]], axis=1)
    plan = plan_turntable(train, VideoOptions(frames=8, width=32, height=32),
                          Bounds(aabb=((-1,) * 3, (1,) * 3), near=WIDE[0], far=WIDE[1]),
                          up=np.array([0.0, 0.0, 1.0]))
    for cam in plan.cameras:
        np.testing.assert_allclose(cam.c2w[2, 0], 0.0, atol=1e-9)  # level: right is horizontal
        assert cam.c2w[2, 1] > 0.5  # the camera's up leans towards +z
    assert not plan.swing  # azimuths about +z: the ring all round
