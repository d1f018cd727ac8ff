"""The priors that look where no photo does (issue 17): patches of rays from random cameras around
the training ones, RegNeRF's depth smoothness on them and the entropy of their opacity."""

import math
from types import SimpleNamespace

import numpy as np
import torch

from windowshop.config import FastConfig, FitConfig
from windowshop.field.fast import with_priors
from windowshop.fit.batches import CameraRays
from windowshop.fit.losses import (LossInput, depth_smoothness, loss_terms, patch_smoothness,
                                   virtual_entropy)
from windowshop.fit.trainer import fit
from windowshop.fit.virtual import virtual_cameras
from windowshop.model import RenderOutput
from windowshop.scene.cameras import look_at
from windowshop.scene.synthetic import synthetic_scene
from windowshop.scene.types import Camera

UP = np.array([0.0, 0.0, 1.0])


def step_patch(size: int = 4) -> torch.Tensor:
    """One patch (size * size,) of depth 1 on its left half and 2 on its right."""
    return torch.tensor([[1.0] * (size // 2) + [2.0] * (size // 2)] * size).view(-1)


def test_patch_smoothness_is_zero_on_a_constant_patch_and_counts_a_step():
    ones = torch.ones(16)
    assert float(patch_smoothness(torch.full((16,), 3.0), ones, 4)) == 0.0
    # one unit step in each of the 4 rows, over 12 pairs across and 12 down
    assert math.isclose(float(patch_smoothness(step_patch(), ones, 4)), 4 / 24, rel_tol=1e-6)
    # pairs with a weightless pixel do not count
    assert float(patch_smoothness(step_patch(), torch.zeros(16), 4)) == 0.0


def test_patch_smoothness_gradients_match_finite_differences():
    values = torch.rand(2 * 9, dtype=torch.float64, requires_grad=True)
    weights = torch.rand(2 * 9, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda v, w: patch_smoothness(v, w, 3), (values, weights))


def patches_input(depth: torch.Tensor, opacity: torch.Tensor) -> LossInput:
    """A LossInput whose virtual patches (of side 4) rendered `depth` and `opacity` (P * 16,)."""
    out = RenderOutput(rgb=torch.zeros(len(depth), 3), depth=depth, opacity=opacity)
    model = SimpleNamespace(config=FastConfig(patch_size=4))
    return LossInput(model, out, torch.zeros(1, 3), torch.zeros(1, 3), _patches=out)


def test_depth_smoothness_smooths_surface_depth_where_the_rays_hit():
    opacity = torch.full((16,), 0.5)
    # a flat surface half transparent: its expected depth is half its surface depth, and flat
    assert float(depth_smoothness(patches_input(torch.full((16,), 1.5), opacity))) == 0.0
    depth = (0.5 * step_patch()).requires_grad_()
    loss = depth_smoothness(patches_input(depth, opacity))
    assert math.isclose(float(loss.detach()), 0.25 * 4 / 24, rel_tol=1e-5)  # a unit step, pairs weighed 1/4
    loss.backward()
    grad = depth.grad.view(4, 4)
    assert (grad[:, 1] < 0).all() and (grad[:, 2] > 0).all()  # the two sides are pulled together
    # a ray that misses (no opacity) is not pulled towards its neighbours
    missing = torch.where(torch.arange(16) % 4 == 3, 0.0, 0.5)
    assert float(depth_smoothness(patches_input(0.5 * step_patch() * (missing > 0), missing))) > 0
    assert float(depth_smoothness(patches_input(torch.full((16,), 0.75) * (missing > 0), missing))) == 0


def test_virtual_entropy_is_zero_for_hits_and_misses_and_largest_for_haze():
    solid = virtual_entropy(patches_input(torch.zeros(16), (torch.arange(16) % 2).float()))
    haze = virtual_entropy(patches_input(torch.zeros(16), torch.full((16,), 0.5)))
    assert float(solid) < 1e-2
    assert math.isclose(float(haze), math.log(2.0), rel_tol=1e-5)


def test_patches_are_squares_of_neighbouring_pixels_inside_the_image():
    camera = Camera(fx=10.0, fy=10.0, cx=6.0, cy=5.0, width=12, height=10, c2w=np.eye(4))
    origins, directions = CameraRays([camera], "cpu", seed=3).patches(20, 4)
    assert origins.shape == directions.shape == (20 * 16, 3)
    torch.testing.assert_close(origins, torch.zeros_like(origins))
    # back to pixel coordinates (OpenGL camera: x right, y up, looking down -z)
    u = 6.0 + 10.0 * directions[:, 0] / -directions[:, 2]
    v = 5.0 - 10.0 * directions[:, 1] / -directions[:, 2]
    u, v = u.view(20, 4, 4), v.view(20, 4, 4)
    torch.testing.assert_close(u - u[:, :1, :1], torch.arange(4.0).expand(20, 4, 4))
    torch.testing.assert_close(v - v[:, :1, :1], torch.arange(4.0)[:, None].expand(20, 4, 4))
    assert float(u.min()) >= 0.5 and float(u.max()) <= 11.5
    assert float(v.min()) >= 0.5 and float(v.max()) <= 9.5
    torch.testing.assert_close(u[:, 0, 0], u[:, 0, 0].floor() + 0.5)  # on pixel centres


def ring(count: int, distance: float, heights: tuple[float, float]) -> list[Camera]:
    """`count` cameras round the origin looking at it, alternating between two heights."""
    cameras = []
    for k in range(count):
        angle = 2 * math.pi * k / count
        eye = np.array([distance * math.cos(angle), distance * math.sin(angle), heights[k % 2]])
        cameras.append(Camera(fx=30.0, fy=30.0, cx=16.0, cy=16.0, width=32, height=32,
                              c2w=look_at(eye, np.zeros(3), UP)))
    return cameras


def test_virtual_cameras_look_at_the_centre_from_where_the_photos_were_taken():
    training = ring(6, 3.0, (0.5, 2.0))
    centre = np.array([0.1, -0.2, 0.3])
    cameras = virtual_cameras(training, centre, count=50, seed=1)
    distances = [np.linalg.norm(c.center - centre) for c in training]
    heights = [math.asin((c.center - centre)[2] / d) for c, d in zip(training, distances)]
    for camera in cameras:
        offset = camera.center - centre
        forward = -camera.c2w[:3, 2]  # OpenGL cameras look down their -z
        np.testing.assert_allclose(forward, -offset / np.linalg.norm(offset), atol=1e-9)
        assert min(distances) - 1e-9 <= np.linalg.norm(offset) <= max(distances) + 1e-9
        assert min(heights) - 1e-9 <= math.asin(offset[2] / np.linalg.norm(offset)) <= max(heights) + 1e-9
        assert (camera.width, camera.height, camera.fx) == (32, 32, 30.0)
    azimuths = [math.atan2(c.center[1] - centre[1], c.center[0] - centre[0]) for c in cameras]
    assert np.ptp(azimuths) > math.pi  # all round, not only where the photos are


def test_virtual_priors_are_virtual_terms_and_train_the_fast_model(tmp_path):
    config = FastConfig(voxels=16**3, depth_smoothness=1.0, virtual_entropy=0.1, virtual_patches=2,
                        patch_size=4)
    assert {t.name: t.virtual for t in loss_terms(with_priors(config, 4))} == {
        "photometric": False, "distortion": False, "tv_density": False, "tv_features": False,
        "depth_smoothness": True, "virtual_entropy": True}
    metrics = fit(synthetic_scene(n_train=4, n_test=1, size=12), "fast", config,
                  FitConfig(iters=3, batch_rays=64), tmp_path, "cpu", show_progress=False)
    assert metrics["iterations"] == 3 and math.isfinite(metrics["psnr"])
