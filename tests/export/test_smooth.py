"""Taubin smoothing (mesh.taubin) and the roughness it is measured by (mesh.neighbour_angles)."""

import numpy as np
import trimesh

from windowshop.export.mesh import Mesh, neighbour_angles, taubin


def noisy_sphere() -> Mesh:
    sphere = trimesh.creation.icosphere(4, 1.0)
    rng = np.random.default_rng(0)
    vertices = sphere.vertices * (1 + 0.01 * rng.standard_normal(len(sphere.vertices)))[:, None]
    return Mesh(vertices, np.asarray(sphere.faces))


def test_neighbour_angles_match_trimesh():
    mesh = noisy_sphere()
    ours = np.sort(neighbour_angles(mesh))
    theirs = np.sort(np.degrees(trimesh.Trimesh(mesh.vertices, mesh.faces).face_adjacency_angles))
    assert np.allclose(ours, theirs, atol=1e-6)


def test_taubin_smooths_without_shrinking_and_keeps_fixed_vertices():
    mesh = noisy_sphere()
    smoothed = taubin(mesh, 3)
    assert neighbour_angles(smoothed).mean() < 0.6 * neighbour_angles(mesh).mean()
    radius = np.linalg.norm(smoothed.vertices, axis=1)
    assert abs(radius.mean() - 1.0) < 0.01  # no shrinking (plain Laplacian steps would)
    fixed = mesh.vertices[:, 2] < 0
    kept = taubin(mesh, 3, fixed=fixed)
    assert np.array_equal(kept.vertices[fixed], mesh.vertices[fixed])
    assert taubin(mesh, 0) is mesh


def test_taubin_smooths_just_enough():
    mesh = noisy_sphere()
    target = 0.4 * neighbour_angles(mesh).mean()
    smoothed = taubin(mesh, 20, enough=lambda m: neighbour_angles(m).mean() <= target)
    angle = neighbour_angles(smoothed).mean()
    assert angle <= target
    # the first whole step that is enough, and the one before it
    steps = next(k for k in range(1, 20) if neighbour_angles(taubin(mesh, k)).mean() <= target)
    assert steps > 1
    before, after = taubin(mesh, steps - 1).vertices, taubin(mesh, steps).vertices
    # part of the way along that last step, not all of it: smoothed no more than it needs
    t = np.sum((smoothed.vertices - before) * (after - before)) / np.sum((after - before) ** 2)
    assert 0 < t < 1 and np.allclose(smoothed.vertices, before + t * (after - before))
    assert angle > neighbour_angles(taubin(mesh, steps)).mean()


def test_compact_drops_unused_vertices_and_keeps_their_order():
    from windowshop.export.mesh import Mesh, compact

    vertices = np.arange(18, dtype=np.float64).reshape(6, 3)
    mesh = compact(Mesh(vertices, np.array([[5, 1, 3], [3, 1, 4]])))
    assert np.array_equal(mesh.vertices, vertices[[1, 3, 4, 5]])
    assert np.array_equal(mesh.faces, [[3, 0, 1], [1, 0, 2]])
