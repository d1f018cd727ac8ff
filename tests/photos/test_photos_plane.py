"""The support plane, up from it, and the object's points above it; no object -> UserError."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from windowshop.errors import UserError
from windowshop.photos import plane
from windowshop.scene.cameras import look_at, up_vector
from windowshop.scene.types import Camera


def _rotation(axis: np.ndarray, degrees: float) -> np.ndarray:
    """(3, 3) rotation by `degrees` about the unit `axis`."""
    a = np.radians(degrees)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def _rolled(eye: np.ndarray, target: np.ndarray, up: np.ndarray, roll: float) -> Camera:
    """A 64 px camera at `eye` looking at `target`, turned `roll` degrees about its view axis."""
    c2w = look_at(eye, target, up)
    c2w[:3, :3] = c2w[:3, :3] @ _rotation(np.array([0.0, 0.0, 1.0]), roll)
    return Camera(fx=64, fy=64, cx=32, cy=32, width=64, height=64, c2w=c2w)


def _tilted_capture(rng: np.random.Generator, tilt: np.ndarray, table: bool = True
                    ) -> tuple[np.ndarray, list[Camera], int]:
    """(points (P, 3), cameras, how many points are the object's): a blob standing on a
    textured table (unless `table` is False), all turned by `tilt` (3, 3); 16 cameras circle it
    30 degrees above the table, each at a random roll."""
    blob = rng.normal(size=(300, 3))
    blob = 0.4 * blob / np.linalg.norm(blob, axis=1, keepdims=True) + [0.0, 0.0, 0.5]
    disk = rng.uniform(-2, 2, size=(2000, 2))
    disk = disk[np.linalg.norm(disk, axis=1) > 0.45]
    floor = np.column_stack([disk, rng.normal(0, 0.005, len(disk))])
    points = np.concatenate([blob, floor]) if table else blob
    cameras = []
    for a in np.linspace(0, 2 * np.pi, 16, endpoint=False):
        eye = 4 * np.array([np.cos(a) * np.cos(0.52), np.sin(a) * np.cos(0.52), np.sin(0.52)])
        cameras.append(_rolled(tilt @ eye, tilt @ [0, 0, 0.4], tilt @ [0.0, 0.0, 1.0],
                               rng.uniform(-180, 180)))
    return points @ tilt.T, cameras, len(blob)


def test_up_is_the_tilted_table_normal_at_any_roll():
    rng = np.random.default_rng(0)
    tilt = _rotation(np.array([0.6, 0.8, 0.0]), 35.0)
    points, cameras, blob = _tilted_capture(rng, tilt)
    isolated = plane.isolate(points, cameras)
    truth = tilt @ [0.0, 0.0, 1.0]
    angle = np.degrees(np.arccos(np.clip(isolated.up @ truth, -1, 1)))
    assert isolated.plane is not None and angle < 2.0  # also signed: toward the cameras
    assert isolated.plane.inlier_share > 0.5
    assert set(isolated.index) <= set(range(blob)) and len(isolated.index) > 0.5 * blob


def test_without_a_plane_up_falls_back_to_the_cameras():
    rng = np.random.default_rng(1)
    points, cameras, blob = _tilted_capture(rng, np.eye(3), table=False)
    for c in cameras:  # upright photos this time
        c.c2w[:] = look_at(c.center, np.array([0, 0, 0.4]), np.array([0.0, 0.0, 1.0]))
    isolated = plane.isolate(points, cameras)
    assert isolated.plane is None and isolated.up_source == "photos"  # level photos agree
    assert isolated.up[2] > 0.9999 and len(isolated.index) > 0.5 * blob
    for c, roll in zip(cameras, rng.uniform(-40, 40, len(cameras))):  # at random rolls: none
        c.c2w[:3, :3] = c.c2w[:3, :3] @ _rotation(np.array([0.0, 0.0, 1.0]), roll)
    isolated = plane.isolate(points, cameras)
    assert isolated.up_source == "cameras"
    np.testing.assert_allclose(isolated.up, up_vector(np.stack([c.c2w for c in cameras])))


def test_a_statue_photographed_from_below_stands_up_by_the_photos_level():
    """No support plane (a pedestal, a street), five level photos from the front looking up at
    the object: their mean up leans back, their right axes still lie level."""
    rng = np.random.default_rng(5)
    blob = rng.normal(size=(400, 3)) * [0.3, 0.3, 0.8] + [0, 0, 2.0]
    cameras = [_rolled(np.array([3 * np.sin(a), -3 * np.cos(a), 0.8]), np.array([0, 0, 2.0]),
                       np.array([0.0, 0.0, 1.0]), 0.0) for a in np.linspace(-0.5, 0.5, 5)]
    mean_up = up_vector(np.stack([c.c2w for c in cameras]))
    assert np.degrees(np.arccos(mean_up[2])) > 15  # the mean up would lean the statue
    isolated = plane.isolate(blob, cameras)
    assert isolated.plane is None and isolated.up_source == "photos"
    assert np.degrees(np.arccos(min(1.0, isolated.up[2]))) < 0.5


def test_a_flat_wall_is_no_object():
    rng = np.random.default_rng(2)
    wall = np.column_stack([rng.uniform(-3, 3, 3000), np.zeros(3000), rng.uniform(-2, 2, 3000)])
    cameras = [_rolled(np.array([x, -4.0, z]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.0)
               for x in np.linspace(-2, 2, 5) for z in (-0.5, 0.5)]
    with pytest.raises(UserError, match="no object found: .* one flat surface"):
        plane.isolate(wall, cameras)


def test_a_landscape_is_no_object():
    """Photos panning across a distant hillside from a walk: nothing where the views meet."""
    rng = np.random.default_rng(3)
    hill = np.column_stack([rng.uniform(-200, 200, 3000), rng.uniform(80, 120, 3000),
                            rng.uniform(0, 30, 3000)])
    cameras = [_rolled(np.array([x, 0.0, 1.5]), np.array([3 * x, 100.0, 10.0]),
                       np.array([0.0, 0.0, 1.0]), 0.0) for x in np.linspace(-5, 5, 8)]
    with pytest.raises(UserError, match="no object found"):
        plane.isolate(hill, cameras)


def test_a_wall_behind_the_object_is_no_support_for_upright_photos():
    """Upright photos from in front of a textured wall: the wall is a plane with every camera on
    one side and the object "above" it, but the photos agree that up runs along it."""
    rng = np.random.default_rng(4)
    blob = rng.normal(size=(300, 3))
    blob = 0.4 * blob / np.linalg.norm(blob, axis=1, keepdims=True)
    wall = np.column_stack([rng.uniform(-2, 2, 2000), np.full(2000, 1.0), rng.uniform(-2, 2, 2000)])
    cameras = [_rolled(4 * np.array([np.sin(a), -np.cos(a), 0.3]), np.zeros(3),
                       np.array([0.0, 0.0, 1.0]), rng.uniform(-10, 10))
               for a in np.linspace(-0.8, 0.8, 9)]
    isolated = plane.isolate(np.concatenate([blob, wall]), cameras)
    assert isolated.plane is None and isolated.up[2] > 0.95


@pytest.mark.parametrize("floor_roll, found", [(0.0, True), (20.0, False)])
def test_the_floor_is_found_under_an_object_before_a_wall_richer_in_points(floor_roll, found):
    """A can on a tiled floor against a tiled wall, photographed upright from in front: the
    wall holds more points than the floor, so it is the likeliest plane; the photos rule it out,
    and the floor, the likeliest of the planes they allow, is the support. A "floor" that would
    leave the upright photos rolled by 20 degrees is no support either."""
    rng = np.random.default_rng(7)
    blob = rng.normal(size=(300, 3))
    blob = 0.4 * blob / np.linalg.norm(blob, axis=1, keepdims=True) + [0.0, 0.0, 0.45]
    wall = np.column_stack([rng.uniform(-2, 2, 1500), np.full(1500, 1.0), rng.uniform(0, 2, 1500)])
    disk = rng.uniform([-2, -2], [2, 1], size=(600, 2))
    disk = disk[np.linalg.norm(disk, axis=1) > 0.45]
    floor = np.column_stack([disk, rng.normal(0, 0.005, len(disk))])
    floor = floor @ _rotation(np.array([0.0, 1.0, 0.0]), floor_roll).T  # about the view axis
    cameras = [_rolled(4 * np.array([np.sin(a), -np.cos(a), 0.6]), np.array([0, 0, 0.45]),
                       np.array([0.0, 0.0, 1.0]), rng.uniform(-10, 10))
               for a in np.linspace(-0.8, 0.8, 9)]
    points = np.concatenate([blob, wall, floor])
    wall_first = plane.fit_support_plane(points, cameras)
    assert wall_first is not None and abs(wall_first.normal[1]) > 0.99  # the wall wins alone
    isolated = plane.isolate(points, cameras)
    if not found:
        assert isolated.plane is None and isolated.up_source == "photos"
        return
    assert isolated.plane is not None and isolated.up_source == "plane"
    assert np.degrees(np.arccos(min(1.0, isolated.up[2]))) < 2.0
    assert (isolated.index < len(blob)).sum() > 0.5 * len(blob)


def _face_and_back(rng: np.random.Generator) -> np.ndarray:
    """(P, 3) points of an object whose textured front face (the plane y = -0.4, 2000 points)
    outnumbers those of the rest of it, behind and before that face (about 270)."""
    face = np.column_stack([rng.uniform(-0.4, 0.4, 2000), np.full(2000, -0.4),
                            rng.uniform(0.0, 1.0, 2000)])
    rest = rng.uniform([-0.4, -0.6, 0.0], [0.4, 0.4, 1.0], size=(300, 3))
    rest = rest[np.abs(rest[:, 1] + 0.4) > 0.05]
    return np.concatenate([face, rest])


def test_a_plane_far_off_the_photos_level_is_dropped_with_their_up():
    """Up from the photos' level (they turn round z): a plane fitted to the object's own side
    (82 degrees off, as on temple's 4-photo ring) is no support, and the object's points are
    all where the views meet, behind it too; a plane tilted 30 degrees stays the support."""
    rng = np.random.default_rng(6)
    points = _face_and_back(rng)
    cameras = [_rolled(4 * np.array([np.sin(a), -np.cos(a), 0.4]), np.array([0, 0, 0.5]),
                       np.array([0.0, 0.0, 1.0]), 0.0) for a in np.linspace(-0.6, 0.6, 6)]
    level = np.array([0.0, 0.0, 1.0])
    side = plane.Plane(normal=_rotation(np.array([1.0, 0, 0]), 82.0) @ level, offset=0.0,
                       tolerance=0.01, inlier_share=0.8)
    in_front = np.flatnonzero(points[:, 1] < -0.41)
    isolated = plane.level_up(plane.Isolated(side, side.normal, in_front), level, points, cameras)
    assert isolated.plane is None and isolated.up_source == "photos"
    assert np.allclose(isolated.up, level)
    behind = points[isolated.index, 1] > -0.39
    assert behind.sum() > 100  # the rest of the object, not only what stands before the face
    tilted = replace(side, normal=_rotation(np.array([1.0, 0, 0]), 30.0) @ level)
    kept = plane.level_up(plane.Isolated(tilted, tilted.normal, in_front), level, points, cameras)
    assert kept.plane is tilted and np.array_equal(kept.index, in_front)
