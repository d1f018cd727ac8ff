"""The side no photo saw (export/unseen.py): closed by the hull of what was seen, shards gone,
concavities a photo looked into kept open, coloured a neutral grey."""

import numpy as np
import pytest

from windowshop.export.mesh import Mesh, components, marching_cubes, open_edges
from windowshop.export.unseen import (COVER_MARGIN, NEAR, RAMP, close_unseen, held_to_covered,
                                      hull_occupancy, neutral_colour, surface_visibility,
                                      unseen_weight, weight_at)
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

N = 64
AABB = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
LEVEL = 5.0


def lattice() -> np.ndarray:
    axes = [np.linspace(-1, 1, N)] * 3
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1)


def front_cameras() -> list[Camera]:
    """Three cameras looking at the origin from +x, 30 degrees either side of it."""
    out = []
    for azimuth in np.radians([-30.0, 0.0, 30.0]):
        eye = 3.0 * np.array([np.cos(azimuth), np.sin(azimuth), 0.2])
        out.append(Camera(fx=120, fy=120, cx=60, cy=60, width=120, height=120,
                          c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))))
    return out


def torn_ball() -> np.ndarray:
    """Densities of a ball of radius 0.6 whose back (x < -0.1), never photographed, is torn: a
    hole bitten out of it and shards standing off it."""
    p = lattice()
    r = np.linalg.norm(p, axis=-1)
    solid = r < 0.6
    solid &= ~((p[..., 0] < -0.3) & (np.abs(p[..., 1]) < 0.25) & (np.abs(p[..., 2]) < 0.25))
    rng = np.random.default_rng(1)
    for _ in range(12):  # shards behind the ball
        c = np.array([rng.uniform(-0.95, -0.6), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)])
        solid |= np.all(np.abs(p - c) < np.array([0.15, 0.02, 0.04]), axis=-1)
    return np.where(solid, 2 * LEVEL, 0.0).astype(np.float32)


def test_the_unseen_back_is_closed_by_the_hull_and_the_front_kept():
    volume = torn_ball()
    visibility = surface_visibility(volume > LEVEL, AABB, front_cameras())
    front = visibility.points[:, 0] > 0.3
    back = visibility.points[:, 0] < -0.5
    assert visibility.seen[front].mean() > 0.9 and visibility.seen[back].mean() < 0.05
    weight = unseen_weight(visibility, volume.shape)
    closed = close_unseen(volume, LEVEL, weight, hull_occupancy(visibility, volume.shape, AABB, weight))
    before, after = marching_cubes(volume, LEVEL, AABB), marching_cubes(closed, LEVEL, AABB)
    # one closed piece, nothing beyond the ball's radius (the shards went) ...
    assert len(np.unique(components(after))) == 1
    radius = np.linalg.norm(after.vertices, axis=1)
    assert radius.max() < 0.6 + 0.1
    assert np.linalg.norm(before.vertices, axis=1).max() > 0.8  # (the shards were there)
    # ... no hole and no shard: behind the photographed rim, the flat back of the seen part's hull
    assert open_edges(after) == 0
    rim = visibility.points[visibility.seen][:, 0].min()
    # (the field's own surface is kept up to NEAR + RAMP cells from a seen point)
    assert after.vertices[:, 0].min() > rim - (NEAR + RAMP) * 2.0 / (N - 1)
    # ... and the photographed front where it was
    seen_front = after.vertices[after.vertices[:, 0] > 0.35]
    assert np.abs(np.linalg.norm(seen_front, axis=1) - 0.6).max() < 2.0 / (N - 1) * 1.5


def test_a_concavity_the_photos_looked_into_stays_open():
    p = lattice()
    solid = (np.linalg.norm(p, axis=-1) < 0.6) & ~((p[..., 0] > 0.2) & (np.abs(p[..., 1]) < 0.2)
                                                   & (np.abs(p[..., 2]) < 0.2))  # a pit facing +x
    volume = np.where(solid, 2 * LEVEL, 0.0).astype(np.float32)
    visibility = surface_visibility(volume > LEVEL, AABB, front_cameras())
    weight = unseen_weight(visibility, volume.shape)
    closed = close_unseen(volume, LEVEL, weight, hull_occupancy(visibility, volume.shape, AABB, weight))
    pit = (p[..., 0] > 0.35) & (p[..., 0] < 0.55) & (np.abs(p[..., 1]) < 0.1) & (np.abs(p[..., 2]) < 0.1)
    assert (closed[pit] < LEVEL).all()


def test_everything_seen_changes_nothing():
    p = lattice()
    volume = np.where(np.linalg.norm(p, axis=-1) < 0.6, 2 * LEVEL, 0.0).astype(np.float32)
    cameras = []
    for azimuth in np.radians(np.arange(0, 360, 30)):
        for z in (-2.0, 0.3, 2.0):
            eye = np.array([3 * np.cos(azimuth), 3 * np.sin(azimuth), z])
            cameras.append(Camera(fx=120, fy=120, cx=60, cy=60, width=120, height=120,
                                  c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0]))))
    visibility = surface_visibility(volume > LEVEL, AABB, cameras)
    assert visibility.seen.mean() > 0.97
    weight = unseen_weight(visibility, volume.shape)
    assert weight_at(weight, AABB, np.array([[0.6, 0.0, 0.0], [0.0, 0.0, -0.6]])).max() == 0


def test_the_unseen_colour_is_a_neutral_grey():
    colours = np.array([[0.9, 0.1, 0.1], [0.8, 0.2, 0.1]])
    grey = neutral_colour(colours, np.array([1.0, 1.0]))
    assert np.ptp(grey) == 0 and 0.2 < grey[0] < 0.5
    assert neutral_colour(colours, np.zeros(2)) == pytest.approx([0.6, 0.6, 0.6])


def test_the_hull_does_not_reach_out_to_a_floater_the_model_drops():
    # the ball photographed from the front, and a small blob of haze standing above it in full
    # view: mesh.keep_largest drops it (a piece under keep_share of the ball's area), so the
    # seen surface's hull must not stretch up to it
    p = lattice()
    blob = np.linalg.norm(p - np.array([0.3, 0.0, 0.85]), axis=-1) < 0.08
    solid = (np.linalg.norm(p, axis=-1) < 0.6) | blob
    volume = np.where(solid, 2 * LEVEL, 0.0).astype(np.float32)
    between = np.linalg.norm(p - np.array([0.2, 0.0, 0.72]), axis=-1) < 0.03  # ball to blob
    on_blob = np.linalg.norm(p[::2, ::2, ::2] - np.array([0.3, 0.0, 0.85]), axis=-1) < 0.1
    hulls = {}
    for share in (0.0, 0.05):
        visibility = surface_visibility(volume > LEVEL, AABB, front_cameras(), keep_share=share)
        blob_points = on_blob[tuple(visibility.index.T)]
        assert visibility.seen[blob_points].any()  # the photos see it, as they see the ball
        assert visibility.kept[blob_points].all() == (share == 0.0)
        assert visibility.kept[~blob_points].all()
        weight = unseen_weight(visibility, volume.shape)
        hulls[share] = hull_occupancy(visibility, volume.shape, AABB, weight)
    assert (hulls[0.0][between] > 0.5).all()  # (the floater's points stretch the hull)
    assert (hulls[0.05][between] < 0.5).all()


def test_a_surface_hidden_behind_a_nearer_one_is_not_seen():
    """A plate stands about 0.3 (10 cells) behind a larger one, all three cameras in front of
    both: no photo shows it, so it is unseen (the depth test's slack, TOLERANCE cells and the
    slope's, stays under that gap; at 4 cells a fifth of it passed as seen), while the front
    plate is seen."""
    p = lattice()
    front = (p[..., 0] > 0.25) & (p[..., 0] < 0.40) & np.all(np.abs(p[..., 1:]) < 0.6, axis=-1)
    behind = (p[..., 0] > -0.1) & (p[..., 0] < 0.1) & np.all(np.abs(p[..., 1:]) < 0.35, axis=-1)
    volume = np.where(front | behind, 2 * LEVEL, 0.0).astype(np.float32)
    visibility = surface_visibility(volume > LEVEL, AABB, front_cameras())
    points = visibility.points
    facing = (points[:, 0] > 0.35) & np.all(np.abs(points[:, 1:]) < 0.5, axis=-1)
    hidden = ((points[:, 0] > 0.05) & (points[:, 0] < 0.15)
              & np.all(np.abs(points[:, 1:]) < 0.25, axis=-1))  # the hidden plate's front face
    assert hidden.sum() > 20 and facing.sum() > 20
    assert visibility.seen[facing].mean() > 0.9
    assert visibility.seen[hidden].mean() < 0.05


def test_a_hidden_surface_seen_edge_on_is_not_seen():
    """The top of a low box stands behind a plate that hides it from all three cameras, which
    see it nearly edge-on (cos about 0.2): its slope's allowance is capped (SLOPE_CELLS), so it
    does not pass as seen however steep it is (uncapped, the allowance reached past the plate)."""
    p = lattice()
    front = (p[..., 0] > 0.25) & (p[..., 0] < 0.40) & np.all(np.abs(p[..., 1:]) < 0.6, axis=-1)
    box = ((p[..., 0] > -0.3) & (p[..., 0] < 0.1) & (np.abs(p[..., 1]) < 0.3)
           & (p[..., 2] > -0.3) & (p[..., 2] < 0.2))
    volume = np.where(front | box, 2 * LEVEL, 0.0).astype(np.float32)
    visibility = surface_visibility(volume > LEVEL, AABB, front_cameras())
    points = visibility.points
    top = ((points[:, 2] > 0.12) & (points[:, 2] < 0.25) & (np.abs(points[:, 1]) < 0.2)
           & (points[:, 0] > -0.2) & (points[:, 0] < 0.0))
    assert top.sum() > 5
    assert visibility.seen[top].mean() < 0.05


def ball_mesh() -> Mesh:
    p = lattice()
    return marching_cubes(np.where(np.linalg.norm(p, axis=-1) < 0.6, 2 * LEVEL, 0.0), LEVEL, AABB)


def test_a_bulge_on_the_unseen_back_is_held_to_the_seen_part_s_hull():
    """The ball photographed from the front, a bulge on its back (never photographed) drawn out
    twice as far behind it, as a tuned closure may: the bulge is moved in to the hull of the
    faces the photos see plus the margin, toward the middle; the photographed front stays put."""
    ball = ball_mesh()
    vertices = ball.vertices.copy()
    back = vertices[:, 0] < -0.45
    vertices[back, 0] *= 2.0
    held = held_to_covered(Mesh(vertices, ball.faces), front_cameras(), AABB)
    # the three cameras (60 degrees apart) see the surface up to cos 0.15 off it: their rim
    # lies at x = 0.6 cos(30 + 81.4 degrees) = -0.22, and the back may reach the margin past it
    grow = COVER_MARGIN * float(np.linalg.norm(AABB[1] - AABB[0]))
    assert vertices[:, 0].min() < -1.1
    assert held.vertices[:, 0].min() > 0.6 * np.cos(np.radians(30 + 81.4)) - grow - 0.03
    moved = np.linalg.norm(held.vertices - vertices, axis=1) > 0
    facing = (vertices[:, 0] > 0.3) & (np.abs(vertices[:, 2]) < 0.3)  # what the cameras face
    assert moved[back].all() and not moved[facing].any()
    assert (np.linalg.norm(held.vertices, axis=1) < np.linalg.norm(vertices, axis=1))[moved].all()


def test_a_surface_seen_all_round_is_not_moved():
    ball = ball_mesh()
    cameras = [Camera(fx=120, fy=120, cx=60, cy=60, width=120, height=120,
                      c2w=look_at(3 * np.array(d, dtype=float), np.zeros(3),
                                  np.array([0.0, 1.0, 0.0]) if abs(d[2]) else np.array([0.0, 0.0, 1.0])))
               for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    held = held_to_covered(ball, cameras, AABB)
    assert np.array_equal(held.vertices, ball.vertices)
