"""The surface tuned against the photos: the outline's anti-aliased coverage against the areas a
pixel's box holds, its gradient, the silhouette edges of a cube, and a sphere drawn too small
growing to the photographed one."""

import numpy as np
import pytest
import torch
import trimesh

from windowshop.export.mesh import Mesh
from windowshop.export.photos import Photos
from windowshop.export.raster import render_mesh, visible_faces
from windowshop.export.tune import (Adam, manifold_edges, outline_coverage, outline_edges,
                                    silhouette_edges, tune_surface)
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera


def screen_square(x0, y0, x1, y1):
    """Two faces covering [x0, x1] x [y0, y1] in pixel coordinates, all at depth 1, their
    boundary edges, and the pixels they cover in a 16x16 image."""
    xy = torch.tensor([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=torch.float64,
                      requires_grad=True)
    faces = torch.tensor([[0, 1, 2], [0, 2, 3]])
    covered = visible_faces(xy.detach(), torch.ones(4, dtype=torch.float64), faces, 16, 16) >= 0
    return xy, torch.tensor([[0, 1], [1, 2], [2, 3], [3, 0]]), covered.view(16, 16)


def coverage_at(pixels, coverage, index):
    return coverage[(pixels == index).nonzero()[0, 0]]


def test_the_outline_covers_what_the_pixel_box_holds(zbuffer):
    # edges at x = 3.6 and 11.3, y = 2.4 and 9.8: the pixels astride them are covered by the
    # fractions 0.4, 0.3, 0.6 and 0.8 (away from the corners)
    xy, edges, covered = screen_square(3.6, 2.4, 11.3, 9.8)
    pixels, coverage = outline_coverage(xy.detach(), edges, covered)
    row, col = 6, 7
    assert float(coverage_at(pixels, coverage, row * 16 + 3)) == pytest.approx(0.4, abs=1e-6)
    assert float(coverage_at(pixels, coverage, row * 16 + 11)) == pytest.approx(0.3, abs=1e-6)
    assert float(coverage_at(pixels, coverage, 2 * 16 + col)) == pytest.approx(0.6, abs=1e-6)
    assert float(coverage_at(pixels, coverage, 9 * 16 + col)) == pytest.approx(0.8, abs=1e-6)
    assert float(coverage_at(pixels, coverage, row * 16 + 4)) == 1.0  # inside: whole


def test_the_outline_moves_with_its_edge_as_finite_differences_say(zbuffer):
    xy, edges, covered = screen_square(3.6, 2.4, 11.3, 9.8)
    pixels, coverage = outline_coverage(xy, edges, covered)
    target = 6 * 16 + 11  # astride the right edge (x = 11.3)
    coverage_at(pixels, coverage, target).backward()
    step = 1e-4
    moved = xy.detach().clone()
    moved[[1, 2], 0] += step
    p2, c2 = outline_coverage(moved, edges, covered)
    before = coverage_at(pixels, coverage, target).detach()
    numeric = float(coverage_at(p2, c2, target) - before) / step
    assert float(xy.grad[[1, 2], 0].sum()) == pytest.approx(numeric, abs=1e-4)
    assert numeric == pytest.approx(1.0, abs=1e-4)  # an edge moved by d covers d more


def test_a_cube_seen_from_a_corner_has_six_silhouette_edges():
    cube = trimesh.creation.box()
    edges, sides = manifold_edges(np.asarray(cube.faces))
    assert len(edges) == 18  # 12 cube edges and 6 diagonals, each between two faces
    outline = silhouette_edges(torch.as_tensor(cube.vertices, dtype=torch.float32),
                               torch.as_tensor(cube.faces), torch.as_tensor(edges),
                               torch.as_tensor(sides), torch.tensor([3.0, 5.0, 7.0]))
    assert len(outline) == 6


def ring_photos(mesh: trimesh.Trimesh, size: int = 48) -> Photos:
    """`mesh` drawn grey on white from 8 cameras around it, with its masks (2x2 samples a pixel)."""
    cameras, images, alphas = [], [], []
    for angle in np.linspace(0, 2 * np.pi, 8, endpoint=False):
        eye = 4.0 * np.array([np.cos(angle), np.sin(angle), 0.4])
        camera = Camera(fx=size, fy=size, cx=size / 2, cy=size / 2, width=size, height=size,
                        c2w=look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])))
        colours = np.full((len(mesh.vertices), 3), 128, np.uint8)
        image, mask = render_mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces),
                                  camera.resized(2 * size, 2 * size), colours=colours)
        cameras.append(camera)
        images.append(image.reshape(size, 2, size, 2, 3).mean((1, 3)).astype(np.float32))
        alphas.append(mask.reshape(size, 2, size, 2).mean((1, 3)).astype(np.float32))
    return Photos(cameras, images, alphas)


CELL = 0.08  # about a pixel (12 pixels a unit), as in an export


def grey_sphere(radius: float) -> Mesh:
    """An icosphere of `radius`, to be drawn with a flat grey texture (see tuned)."""
    start = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    return Mesh(np.asarray(start.vertices, dtype=np.float64), np.asarray(start.faces))


def tuned(mesh: Mesh, photos: Photos) -> Mesh:
    """`mesh` textured flat grey (the photos' own grey), tuned against `photos`."""
    grey = np.full((8, 8, 3), 128 / 255, np.float32)
    return tune_surface(mesh, np.zeros((len(mesh.faces), 3, 2)), grey, photos, cell=CELL)


@pytest.mark.parametrize("drawn", [0.85, 1.15])
def test_a_sphere_drawn_off_the_photographed_one_moves_onto_it(zbuffer, drawn):
    photos = ring_photos(trimesh.creation.icosphere(subdivisions=3, radius=1.0))
    threads = torch.get_num_threads()
    # the surface starts about 2 cells off the photographed one
    radius = np.linalg.norm(tuned(grey_sphere(drawn), photos).vertices, axis=1)
    assert abs(np.median(radius) - 1.0) < 0.4 * abs(drawn - 1.0)
    assert torch.get_num_threads() == threads  # its thread trials (device.ThreadTuner) undone


def test_without_masks_flat_colour_gives_no_reason_to_move(zbuffer):
    photos = ring_photos(trimesh.creation.icosphere(subdivisions=3, radius=1.0))
    photos = Photos(photos.cameras, photos.images, [None] * len(photos.cameras))
    mesh = grey_sphere(0.85)
    # the photos' grey is the texture's wherever the mesh is drawn: no colour pulls it outwards
    assert np.abs(tuned(mesh, photos).vertices - mesh.vertices).max() < CELL * 0.05


def test_the_hand_adam_steps_as_torchs_adam():
    """The tune's Adam (no torch.optim: its import costs a second) moves a parameter exactly as
    torch.optim.Adam does, bias corrections included, over steps of varied gradients."""
    torch.manual_seed(0)
    ours, theirs = torch.zeros(50, requires_grad=True), torch.zeros(50, requires_grad=True)
    adam, reference = Adam(ours, 0.05), torch.optim.Adam([theirs], lr=0.05)
    for step in range(30):
        grad = torch.randn(50) * (10.0 ** (step % 4 - 2))
        adam.step(grad.clone())
        theirs.grad = grad.clone()
        reference.step()
        assert torch.equal(ours.detach(), theirs.detach()), step
    assert ours.abs().max() > 0.5  # it did move


def test_the_edges_near_the_outline_give_the_whole_silhouette_s_coverage(zbuffer):
    # a lumpy sphere: silhouette edges inside the outline too (folds), of which outline_edges
    # keeps only those whose box meets a covered pixel beside an uncovered one
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    rng = np.random.default_rng(0)
    lumps = 1 + 0.04 * rng.standard_normal((len(sphere.vertices), 1))
    vertices = torch.as_tensor(sphere.vertices * lumps, dtype=torch.float32)
    faces = torch.as_tensor(sphere.faces)
    edges, sides = (torch.as_tensor(x) for x in manifold_edges(np.asarray(sphere.faces)))
    camera = ring_photos(sphere, 40).cameras[1]
    from windowshop.export.raster import screen

    xy, depth = screen(vertices, camera)
    covered = (visible_faces(xy, depth, faces, camera.width, camera.height) >= 0).view(
        camera.height, camera.width)
    eye = torch.as_tensor(camera.c2w[:3, 3]).float()
    every = silhouette_edges(vertices, faces, edges, sides, eye)
    near = outline_edges(xy, vertices, faces, edges, sides, eye, covered)
    assert len(near) < len(every)
    assert set(map(tuple, near.tolist())) <= set(map(tuple, every.tolist()))
    pixels, coverage = outline_coverage(xy, every, covered)
    pixels_near, coverage_near = outline_coverage(xy, near, covered)
    assert torch.equal(pixels, pixels_near) and torch.equal(coverage, coverage_near)
