"""The surface's density level, chosen from the field's own silhouettes, on an analytic sphere."""

import numpy as np
import pytest
import torch
from torch import nn

from windowshop.export.level import best_level, choose_level
from windowshop.export.mesh import marching_cubes, sample_volume
from windowshop.model import Bounds, RadianceModel, RenderOutput
from windowshop.scene.synthetic import orbit_cameras

RADIUS, WIDTH = 0.5, 0.004  # the sphere's density falls from its peak to 0 over about 2 WIDTH


class SphereField(RadianceModel):
    """Density `peak` * sigmoid((RADIUS - |x|) / WIDTH); rays integrated by dense quadrature."""

    name = "sphere"

    def __init__(self, peak: float):
        super().__init__(None, Bounds(aabb=((-1.0,) * 3, (1.0,) * 3), near=2.0, far=5.0))
        self.peak = peak
        self.anchor = nn.Parameter(torch.zeros(1))  # gives the model a device

    def density(self, points):
        return self.peak * torch.sigmoid((RADIUS - points.norm(dim=-1)) / WIDTH)

    def colour(self, points, directions):
        return torch.full_like(points, 0.5)

    def render_rays(self, origins, directions, background):
        t = torch.linspace(self.bounds.near, self.bounds.far, 3001)
        points = origins[:, None] + t[None, :, None] * directions[:, None]
        sigma = self.density(points.reshape(-1, 3)).view(len(origins), -1)
        opacity = 1.0 - torch.exp(-sigma.sum(-1) * float(t[1] - t[0]))
        return RenderOutput(rgb=background, depth=torch.zeros_like(opacity), opacity=opacity)


def silhouette_radius(peak: float) -> float:
    """The distance from the centre at which a ray's opacity through the sphere is one half."""
    s = np.linspace(-1.0, 1.0, 20001)
    for b in np.linspace(RADIUS - 0.05, RADIUS + 0.1, 3001):
        r = np.sqrt(b * b + s * s)
        optical = np.sum(peak / (1.0 + np.exp(-(RADIUS - r) / WIDTH))) * (s[1] - s[0])
        if optical < np.log(2.0):
            return float(b)
    raise AssertionError("no edge found")


@pytest.mark.parametrize("peak", [40.0, 4000.0])
def test_level_puts_the_surface_on_the_silhouette(peak):
    model = SphereField(peak)
    aabb = np.array(model.bounds.aabb)
    volume = sample_volume(model, aabb, 64)
    cameras = orbit_cameras(6, 40, radius=3.0)
    level, iou = choose_level(model, volume, torch.tensor(aabb, dtype=torch.float32), cameras, 6)
    mesh = marching_cubes(volume.numpy(), level, aabb)
    radius = np.median(np.linalg.norm(mesh.vertices, axis=-1))
    cell = 2.0 / 64
    assert iou > 0.97
    # a field 100x denser has its outline 2 cells further out: the level follows it (no constant)
    assert radius == pytest.approx(silhouette_radius(peak), abs=0.5 * cell)  # sub-cell: linear MC


def test_best_level_takes_the_middle_of_a_plateau():
    # pixels 0..3 inside at any level up to 10, pixels 4..7 never: every level below 10 is exact
    peaks = torch.tensor([10.0, 10.0, 10.0, 10.0, 0.1, 0.1, 0.1, 0.1])
    targets = peaks > 1.0
    level, iou = best_level(peaks, targets)
    assert iou == 1.0
    assert 0.3 < level < 3.0  # the geometric middle of (0.1, 10), not either end


def test_best_level_without_any_object_is_undefined():
    level, iou = best_level(torch.zeros(16), torch.zeros(16, dtype=torch.bool))
    assert np.isnan(level) and iou == 0.0
