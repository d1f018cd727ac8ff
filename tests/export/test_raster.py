"""The checking rasteriser: coverage and depth order against hand-computed answers, in the C
kernel and in its pure-PyTorch twin, and the two against each other."""

from pathlib import Path

import numpy as np
import pytest
import torch

from export_helpers import square, top_camera, two_spheres
from windowshop.export.raster import nearest_faces, rasterise, render_mesh, screen
from windowshop.field import kernels


def test_a_square_covers_the_pixels_its_projection_covers(zbuffer):
    v, f = square(0.0, 1.0)  # at distance 4: 2 units wide = 20 pixels of a 40-pixel focal length
    _, silhouette = render_mesh(v, f, top_camera(), colours=np.zeros((4, 3), np.uint8))
    assert silhouette.sum() == 20 * 20
    assert silhouette[10:30, 10:30].all()


def test_the_nearer_face_wins_and_texture_coordinates_reach_the_texture(zbuffer):
    near_v, near_f = square(1.0, 0.5)
    far_v, far_f = square(0.0, 1.0)
    vertices = np.concatenate([far_v, near_v])
    faces = np.concatenate([far_f, near_f + 4])
    colours = np.array([[255, 0, 0]] * 4 + [[0, 0, 255]] * 4, dtype=np.uint8)
    image, _ = render_mesh(vertices, faces, top_camera(), colours=colours)
    assert np.allclose(image[20, 20], [0, 0, 1]) and np.allclose(image[11, 11], [1, 0, 0])
    # a texture whose top half is green: glTF v = 0 is its top row, here the square's +y side
    texture = np.zeros((8, 8, 3), np.uint8)
    texture[:4, :, 1] = 255
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])
    image, _ = render_mesh(far_v, far_f, top_camera(), uv=uv, texture=texture)
    assert image[12, 20, 1] == 1.0 and image[27, 20, 1] == 0.0  # image row 12 is at +y


@pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")
def test_the_kernel_and_its_twin_see_the_same_faces():
    """Two overlapping spheres (2,500 faces, depth order everywhere) from an oblique camera: the
    same pixels covered, the same face at all but pixels on an edge two faces share."""
    vertices, faces, camera = two_spheres()
    fused = rasterise(vertices, faces, camera).face.view(-1)
    xy, depth = screen(vertices, camera)
    twin = nearest_faces(xy, depth, faces, camera.width, camera.height, 1e-3)
    assert 2000 < int((twin >= 0).sum()) < 96 * 80  # the spheres fill part of the view
    assert torch.equal(fused >= 0, twin >= 0)
    assert float((fused == twin).float().mean()) > 0.995


RASTER_SCRIPT = """
import hashlib, sys
sys.path.insert(0, sys.argv[1])
from export_helpers import two_spheres
from windowshop.field import kernels
from windowshop.export.raster import rasterise
assert kernels.available("cpu")
r = rasterise(*two_spheres())
print(hashlib.sha256(r.face.numpy().tobytes() + r.bary.numpy().tobytes()).hexdigest(),
      int((r.face >= 0).sum()))
"""


@pytest.mark.skipif(not kernels.available("cpu"), reason="no C compiler")
def test_the_kernel_draws_the_same_on_any_number_of_threads():
    """Each thread draws a band of rows: on one thread and on three (bands meeting inside both
    spheres) every pixel gets the same face and barycentrics, to the bit."""
    import os
    import subprocess
    import sys

    out = {}
    for threads in ("1", "3"):
        env = {**os.environ, "OMP_NUM_THREADS": threads}
        done = subprocess.run([sys.executable, "-c", RASTER_SCRIPT, str(Path(__file__).parents[1])],
                              env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        out[threads] = done.stdout.split()
    assert int(out["1"][1]) > 1000  # the spheres cover part of the view
    assert out["1"] == out["3"]
