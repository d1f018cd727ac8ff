"""The built-in object: exact images for any camera, consistent with the scene it makes."""

import numpy as np
import pytest
import torch

from windowshop.rays import camera_rays, project
from windowshop.scene.cameras import look_at
from windowshop.scene.synthetic import BOUNDS, LIGHT, SPHERES, render_truth, synthetic_scene, trace
from windowshop.scene.types import Camera


@pytest.fixture(scope="module")
def scene():
    return synthetic_scene(n_train=12, n_test=4, size=40)


def test_scene_shape_and_splits(scene):
    assert len(scene.split("train")) == 12 and len(scene.split("test")) == 4
    assert scene.format == "synthetic" and np.allclose(scene.transform, np.eye(4))
    assert np.all(scene.aabb[0] <= BOUNDS[0]) and np.all(scene.aabb[1] >= BOUNDS[1])
    assert np.all(np.abs(scene.aabb) <= 1.0)
    for view in scene.views:
        assert view.image.shape == (40, 40, 3) and view.alpha.shape == (40, 40)


def test_cameras_on_upper_hemisphere_look_at_origin_and_do_not_repeat(scene):
    centres = np.stack([v.camera.center for v in scene.views])
    assert np.all(centres[:, 2] > 0)
    np.testing.assert_allclose(np.linalg.norm(centres, axis=1), 3.5)
    for view in scene.views:
        uv, _ = project(np.zeros((1, 3)), view.camera)
        np.testing.assert_allclose(uv[0], [20.0, 20.0], atol=1e-9)
    train = centres[:12]
    for c in centres[12:]:
        assert np.min(np.linalg.norm(train - c, axis=1)) > 0.1


def test_render_truth_reproduces_scene_images_and_masks(scene):
    for view in scene.views[::3]:
        rgb, alpha = render_truth(view.camera)
        np.testing.assert_array_equal(rgb, view.image)
        np.testing.assert_array_equal(alpha, view.alpha)
        assert np.allclose(rgb[alpha == 0], 1.0)  # white background by default
        assert 0.05 < alpha.mean() < 0.9


def test_black_and_alpha_backgrounds():
    black = synthetic_scene(n_train=2, n_test=0, size=24, background="black")
    view = black.views[0]
    assert np.allclose(view.image[view.alpha == 0], 0.0)
    rgb, _ = render_truth(view.camera, background=(0.0, 0.0, 0.0))
    np.testing.assert_array_equal(rgb, view.image)


def test_known_pixel_colours():
    """Straight down the axis onto the red sphere's centre: its colour; a ray past it: background."""
    centre, radius, albedo, _ = SPHERES[0]
    eye = np.asarray(centre) + np.array([2.0, 0.0, 0.5])
    cam = Camera(fx=50, fy=50, cx=16, cy=16, width=32, height=32,
                 c2w=look_at(eye, np.asarray(centre), np.array([0.0, 0.0, 1.0])))
    rgb, alpha = render_truth(cam)
    assert alpha[15:17, 15:17].all()
    centre_pixel = rgb[16, 16]
    assert centre_pixel[0] > 2 * centre_pixel[1] and centre_pixel[0] > 2 * centre_pixel[2]
    rgb_up, hit = trace(np.array([[0.0, 0.0, 5.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert not hit[0] and np.all(rgb_up == 0)


def test_alpha_matches_the_distance_to_a_sphere():
    """A ray hits iff it passes within the radius of the sphere's centre (known geometry).

    Horizontal rays at the height of the top sphere's centre can meet nothing else.
    """
    centre, radius, _, _ = SPHERES[2]
    centre = np.asarray(centre)
    origin = centre + np.array([-4.0, 0.0, 0.0])
    offsets = np.linspace(-1.5, 1.5, 61) * radius
    targets = centre + np.stack([np.zeros(61), offsets, np.zeros(61)], -1)
    dirs = targets - origin
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    _, hit = trace(np.broadcast_to(origin, dirs.shape), dirs)
    oc = centre - origin
    miss_distance = np.linalg.norm(oc - (dirs @ oc)[:, None] * dirs, axis=1)
    clear = np.abs(miss_distance - radius) > 1e-6
    np.testing.assert_array_equal(hit[clear], (miss_distance < radius)[clear])
    assert 10 < hit.sum() < 61


def test_specular_highlight_moves_with_the_viewer():
    """View-dependent colour: the top of the red sphere seen along the light's mirror direction
    carries the highlight; seen from the light's side it does not."""
    centre, radius, _, _ = SPHERES[0]
    point = np.asarray(centre) + radius * np.array([0.0, 0.0, 1.0])
    mirror = LIGHT * np.array([-1.0, -1.0, 1.0])  # the light reflected about the normal +z
    colours = []
    for direction in (mirror, LIGHT):
        eye = point + 3.0 * direction
        rgb, hit = trace(eye[None], -direction[None])
        assert hit[0]
        colours.append(rgb[0])
    assert np.all(colours[0] - colours[1] > 0.2)  # a white highlight: every channel brighter


def test_rays_of_a_scene_camera_agree_with_render_truth(scene):
    view = scene.views[0]
    origins, dirs = camera_rays(view.camera, dtype=torch.float64)
    rgb, hit = trace(origins.numpy(), dirs.numpy())
    rgb = rgb + (1 - hit[:, None])
    np.testing.assert_allclose(rgb.reshape(40, 40, 3), view.image, atol=1e-6)
