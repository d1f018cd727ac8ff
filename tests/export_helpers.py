"""The built-in object's scene as if from a source frame that is not the normalised one, so an
export's side-file matrix has work to do (tests/export/)."""

import dataclasses

import numpy as np
import torch
import trimesh

from windowshop.scene.cameras import look_at
from windowshop.scene.synthetic import synthetic_scene
from windowshop.scene.types import Camera

# source frame -> normalised frame: a turn about x, a scale and a shift (a similarity)
TURN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
SOURCE_TO_NORMALISED = np.block([[0.5 * TURN, np.array([[0.2], [-0.1], [0.3]])],
                                 [np.zeros((1, 3)), np.ones((1, 1))]])


def object_scene():
    """The built-in object's scene, said to come from a source frame SOURCE_TO_NORMALISED away."""
    scene = synthetic_scene(n_train=24, n_test=4, size=32)
    scene.transform = SOURCE_TO_NORMALISED
    scene.views = [dataclasses.replace(v, stored_camera=scene.source_camera(v.camera))
                   for v in scene.views]
    return scene


def square(z: float, half: float) -> tuple[np.ndarray, np.ndarray]:
    """Two triangles making the square |x|, |y| <= half at height z (facing +z)."""
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def top_camera(size: int = 40) -> Camera:
    """Looking straight down from z = 4 with a focal length of `size` pixels."""
    c2w = look_at(np.array([0.0, 0.0, 4.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    return Camera(fx=size, fy=size, cx=size / 2, cy=size / 2, width=size, height=size, c2w=c2w)


def two_spheres() -> tuple[torch.Tensor, torch.Tensor, Camera]:
    """(vertices, faces, camera): two overlapping spheres (2,500 faces) from an oblique camera."""
    a = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    b = trimesh.creation.icosphere(subdivisions=3, radius=0.7)
    vertices = torch.as_tensor(np.concatenate([a.vertices, b.vertices + [0.8, 0.3, 0.2]]),
                               dtype=torch.float32)
    faces = torch.as_tensor(np.concatenate([a.faces, b.faces + len(a.vertices)]), dtype=torch.int64)
    camera = Camera(150.0, 150.0, 47.0, 41.0, 96, 80,
                    look_at(np.array([3.0, -2.5, 2.0]), np.zeros(3), np.array([0.0, 0.0, 1.0])))
    return vertices, faces, camera
