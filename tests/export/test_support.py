"""The support plane (export/support.py): a contact shadow's slab cut away, the base flat on it."""

import json

import numpy as np
import pytest

from windowshop.export.mesh import marching_cubes, open_edges
from windowshop.export.support import (GROW, cut_support, flatten_base, plane_found,
                                       prepared_report)

N = 96
AABB = np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 2.0]])  # the floor at z = 0: the plane
LEVEL = 5.0
CELL = 2.0 / (N - 1)


def can_on_a_shadow() -> np.ndarray:
    """A can (radius 0.4, 1.2 tall) standing on the floor in a wide, thin shadow (radius 0.8,
    four cells thick)."""
    axes = [np.linspace(AABB[0, i], AABB[1, i], N) for i in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    r = np.hypot(x, y)
    solid = (r < 0.4) & (z < 1.2) | (r < 0.8) & (z < 3 * CELL + 1e-9)
    return np.where(solid, 2 * LEVEL, 0.0).astype(np.float32)


def test_the_shadow_is_cut_and_the_base_stands_flat_on_the_plane():
    volume = can_on_a_shadow()
    cut, cut_z, floor_z = cut_support(volume, LEVEL, AABB)
    mesh = marching_cubes(cut, LEVEL, AABB)
    assert floor_z == 0.0
    vertices = flatten_base(mesh.vertices, cut_z, floor_z, CELL)
    assert open_edges(mesh) == 0
    assert np.hypot(vertices[:, 0], vertices[:, 1]).max() < 0.4 + (GROW + 1) * CELL  # no slab left
    base = vertices[vertices[:, 2] < 0.5 * CELL]
    assert np.all(base[:, 2] == 0.0) and vertices[:, 2].min() == 0.0  # flat, on the plane
    assert np.hypot(base[:, 0], base[:, 1]).max() > 0.4 - 1.5 * CELL  # the whole footprint
    assert vertices[:, 2].max() > 1.2 - 1.5 * CELL  # and nothing of the can itself lost


def test_a_wide_base_of_the_object_itself_is_kept():
    axes = [np.linspace(AABB[0, i], AABB[1, i], N) for i in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    r = np.hypot(x, y)
    lamp = (r < 0.15) & (z < 1.5) | (r < 0.6) & (z < 0.25)  # a stem on a wide foot, 0.25 tall
    volume = np.where(lamp, 2 * LEVEL, 0.0).astype(np.float32)
    cut, _, _ = cut_support(volume, LEVEL, AABB)
    foot = (r > 0.3) & (r < 0.55) & (z > 0.1) & (z < 0.2)
    assert (cut[foot] > LEVEL).all()


def test_plane_found_reads_the_prepared_report(tmp_path):
    assert not plane_found(prepared_report(tmp_path))
    (tmp_path / "report.json").write_text(json.dumps({"plane": {"found": True}}))
    assert plane_found(prepared_report(tmp_path))
    assert plane_found(prepared_report(tmp_path / "transforms.json"))
    (tmp_path / "report.json").write_text(json.dumps({"plane": {"found": False}}))
    assert not plane_found(prepared_report(tmp_path))


def test_the_floor_is_the_lowest_layer_the_object_occupies():
    """Without a plane at the box's floor (up from the photos' level), the object's own lowest
    layer is the floor it stands on."""
    volume = np.roll(can_on_a_shadow(), 10, axis=2)  # the can and its shadow 10 cells up
    _, cut_z, floor_z = cut_support(volume, LEVEL, AABB)
    assert floor_z == pytest.approx(10 * CELL) and cut_z > floor_z


def test_low_small_pieces_on_the_support_go_and_a_second_object_stays():
    """Beside a can: lumps on the floor (a plate's visual hull: low, small) go; a second can (a
    pair) and a low wide box larger than SMALL of the can stay."""
    axes = [np.linspace(AABB[0, i], AABB[1, i], N) for i in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    can = (np.hypot(x + 0.5, y) < 0.25) & (z < 1.2)
    pair = (np.hypot(x - 0.5, y) < 0.25) & (z < 1.2)
    lumps = [(np.hypot(x - px, y - 0.7) < 0.06) & (z < 0.25) for px in (-0.6, 0.0, 0.6)]
    box = (np.abs(x) < 0.6) & (np.abs(y + 0.65) < 0.3) & (z < 0.2)  # low, a third of a can
    volume = np.where(can | pair | box | np.any(lumps, axis=0), 2 * LEVEL, 0.0).astype(np.float32)
    cut, _, _ = cut_support(volume, LEVEL, AABB)
    kept = cut > LEVEL
    above = z > 0.1  # above the cut layers
    assert not any((kept & lump).any() for lump in lumps)
    for part in (can, pair, box):
        assert (kept[part & above]).all()
