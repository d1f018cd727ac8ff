"""The fast model: dense density and feature grids, a tiny colour MLP, occupancy skipping.

A ray is marched only through occupied cells of the object's box (occupancy.py); densities come
from a one-channel grid (post-activation: interpolate, then softplus) and compositing weights from
packed volume rendering (render/packed.py). Colour is deferred: each ray's features, read from a
feature grid where a sample's weight matters and composited with those weights, are decoded once
by a small MLP of the features and the view direction's spherical harmonics. The grids start
coarse and grow (trilinear resampling) during training; the occupancy grid holds the cells with a
corner dense enough to matter, refreshed every few steps; once `carve`d (the visual hull of a
masked scene's photos), never a cell outside the hull. Rendering (eval mode) uses one fused
kernel that also stops each ray once nothing behind can show (kernels.c render_ray).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import replace

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from windowshop.config import FAST_PRESETS, FastConfig
from windowshop.field.grid import DenseGrid
from windowshop.field import kernels
from windowshop.field.occupancy import OccupancyGrid, any_of_corners, ray_box
from windowshop.field.optim import GridAdam
from windowshop.model import Bounds, RadianceModel, RenderOutput
from windowshop.render.packed import (arrival_transmittance, packed_distortion, ray_weights,
                                      sample_points)

EMPTY_ALPHA = 1e-6  # opacity of one final step that carved space starts at (next to none)
DEFAULT_VOXELS = 64**3  # without a scene to size the grid by (FastModel.for_scene)
MIN_VOXELS = 16**3
TV_RAYS = 8  # training rays per probe pair of the features' total variation (2 or 4: no better)
TV_SPAN = 128  # the density's total variation: its changes over 1/TV_SPAN of the box's longest side
CARVE_VOXELS = 96**3  # the finest carve mask (FastModel.carve_cells)
# bytes one marched sample takes (t, weight, ray index, its density and feature reads), and while
# training with its gradients: lego_tiny's final grid with every cell occupied peaked at 96 and 220
SAMPLE_BYTES = 96
SAMPLE_BYTES_TRAINING = 256


def lattice_shape(extent: torch.Tensor, voxels: int) -> tuple[int, int, int]:
    """Vertices per axis of a lattice of about `voxels` cubic cells over a box of `extent` (3,)."""
    side = float(torch.prod(extent) / voxels) ** (1.0 / 3.0)
    return tuple(max(2, int(round(float(e) / side)) + 1) for e in extent)


def spherical_harmonics(d: torch.Tensor, degree: int) -> torch.Tensor:
    """Real spherical harmonics up to `degree` (0..3) of unit directions (N, 3): (N, (degree+1)^2)."""
    x, y, z = d.unbind(-1)
    out = [torch.full_like(x, 0.28209479)]
    if degree >= 1:
        out += [-0.48860251 * y, 0.48860251 * z, -0.48860251 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        out += [1.09254843 * x * y, -1.09254843 * y * z, 0.31539157 * (3 * zz - 1),
                -1.09254843 * x * z, 0.54627421 * (xx - yy)]
    if degree >= 3:
        out += [-0.59004359 * y * (3 * xx - yy), 2.89061144 * x * y * z,
                -0.45704580 * y * (5 * zz - 1), 0.37317633 * z * (5 * zz - 3),
                -0.45704580 * x * (5 * zz - 1), 1.44530572 * z * (xx - yy),
                -0.59004359 * x * (xx - 3 * yy)]
    return torch.stack(out, dim=-1)


def pixel_footprint(scene) -> float:
    """Median width of a training pixel at the centre of the scene's box, in scene units."""
    centre = np.mean(np.asarray(scene.aabb, dtype=float), axis=0)
    sizes = [np.linalg.norm(v.camera.center - centre) / v.camera.fx for v in scene.split("train")]
    return float(np.median(sizes))


def with_priors(config: FastConfig, photos: int | None) -> FastConfig:
    """`config` with the few-photo priors it leaves open (None) settled for `photos` training
    photos (None: not known, so not few)."""
    few = photos is not None and photos <= config.few_views
    distortion = (0.01 if few else 0.0) if config.distortion is None else config.distortion
    tv_features = (0.003 if few else 0.0) if config.tv_features is None else config.tv_features
    tv_density = (1e-4 if few else 0.0) if config.tv_density is None else config.tv_density
    max_passes = (50.0 if few else 0.0) if config.max_passes is None else config.max_passes
    masked = True if config.masked is None else config.masked
    masked_until = (1.0 if few else 0.5) if config.masked_until is None else config.masked_until
    step = (0.5 if few else 0.7) if config.step is None else config.step
    threshold = (1e-4 if few else 3e-3) if config.weight_threshold is None else config.weight_threshold
    return replace(config, distortion=distortion, tv_features=tv_features, tv_density=tv_density,
                   max_passes=max_passes, masked=masked, masked_until=masked_until, step=step,
                   weight_threshold=threshold)


class FastModel(RadianceModel):
    """Grids + tiny MLP + occupancy skipping; see the module docstring."""

    name = "fast"
    config_type = FastConfig
    presets = FAST_PRESETS
    batch_rays = 4096  # per CPU second, 4096-ray steps beat 1024 or 2048 (fixed costs per step)

    @classmethod
    def for_scene(cls, config: FastConfig, scene) -> FastConfig:
        """Fill in the few-photo priors from the number of training photos, and the voxel count
        from the training pixels' size: finer photos, finer grid."""
        config = with_priors(config, len(scene.split("train")))
        if config.voxels is not None:
            return config
        extent = np.diff(np.asarray(scene.aabb, dtype=float), axis=0)[0]
        voxel = pixel_footprint(scene) * config.voxel_pixels
        pixels = sum(v.camera.width * v.camera.height for v in scene.split("train"))
        voxels = min(config.max_voxels, int(np.prod(extent) / voxel**3),
                     int(config.max_voxels_per_pixel * pixels))
        return replace(config, voxels=max(voxels, MIN_VOXELS))

    def __init__(self, config: FastConfig, bounds: Bounds):
        super().__init__(with_priors(config, None), bounds)
        aabb = bounds.aabb_tensor()
        self.extent = aabb[1] - aabb[0]
        self.voxels = config.voxels or DEFAULT_VOXELS
        shape = self.lattice(config.start_fraction if config.growth else 1.0)
        final_voxel = float(torch.prod(self.extent) / self.voxels) ** (1.0 / 3.0)
        self.density_scale = 1.0 / final_voxel  # softplus units are "per final voxel"
        self.shift = 0.0  # raw 0 starts at opacity alpha_init over a final-resolution step:
        self.shift = self._raw_at_alpha(config.alpha_init)
        self.density_grid = DenseGrid(shape, 1, aabb)
        self.feature_grid = DenseGrid(shape, config.features, aabb)
        self.occupancy = OccupancyGrid(tuple(s - 1 for s in shape), aabb)
        n_dir = (config.sh_degree + 1) ** 2 if config.sh_degree >= 0 else 0
        self.mlp = nn.Sequential(nn.Linear(config.features + n_dir, config.hidden), nn.ReLU(),
                                 nn.Linear(config.hidden, 3))
        self._optimizer = None  # a weak reference to the optimizer of make_optimizer

    # --- geometry -------------------------------------------------------------------------------
    def _raw_at_alpha(self, alpha: float) -> float:
        """The raw grid value whose density has opacity `alpha` over one final-resolution step."""
        softplus = -math.log(1.0 - alpha) / self.config.step
        return math.log(math.expm1(softplus)) - self.shift

    @property
    def step_length(self) -> float:
        """Marching step in world units for the current grid (training's or rendering's)."""
        step = self.config.step if self.training else self.config.render_step
        return float(self.density_grid.voxel.min()) * step

    def density(self, points: torch.Tensor) -> torch.Tensor:
        """Density (N,) at world points (N, 3): the grid's interpolated raw value, activated."""
        return self._activate(self.density_grid(points)[:, 0])

    def colour(self, points: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        """Colour (N, 3) at world points (N, 3) seen along unit `directions` (N, 3): the MLP's
        decoding of the point's interpolated features (a ray's colour decodes the composited ones)."""
        return self.decode(self.feature_grid(points), directions)

    def _activate(self, raw: torch.Tensor) -> torch.Tensor:
        """Density from raw grid values (post-activation: interpolate, then softplus)."""
        return F.softplus(raw + self.shift) * self.density_scale

    def decode(self, h: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        """Colour (N, 3) in [0, 1] of features (N, C) seen along unit directions (N, 3)."""
        if self.config.sh_degree >= 0:
            h = torch.cat([h, spherical_harmonics(directions, self.config.sh_degree)], dim=-1)
        with torch.autocast(h.device.type, dtype=torch.bfloat16, enabled=self._bf16(h.device)):
            return torch.sigmoid(self.mlp(h).float())

    def _bf16(self, device: torch.device) -> bool:
        """Whether the MLP runs in bfloat16: asked for and fast on this device (3x on AVX512-BF16)."""
        if not self.config.mlp_bf16:
            return False
        if device.type == "cuda":
            return torch.cuda.is_bf16_supported()
        return device.type == "cpu" and torch.ops.mkldnn._is_mkldnn_bf16_supported()

    # --- rendering ------------------------------------------------------------------------------
    def bytes_per_ray(self, training: bool) -> float:
        """A ray straight through the final grid's longest side, sampled every `step` voxels
        (empty-space skipping only lowers it)."""
        samples = max(lattice_shape(self.extent, self.voxels)) / self.config.step
        return samples * (SAMPLE_BYTES_TRAINING if training else SAMPLE_BYTES)

    def render_rays(self, origins: torch.Tensor, directions: torch.Tensor,
                    background: torch.Tensor) -> RenderOutput:
        aux = {}
        if self.training or not kernels.available(origins.device):
            features, opacity, depth, count = self._composite_features(origins, directions, aux)
        else:
            features, opacity, depth, count = self._composite_features_fused(origins, directions)
        # Each ray's features are composited, then decoded once (deferred shading).
        threshold = self.config.weight_threshold if self.training else self.config.render_threshold
        mean = features / opacity.detach().clamp(min=threshold)[:, None]
        color = opacity[:, None] * self.decode(mean, directions) + (1.0 - opacity)[:, None] * background
        return RenderOutput(rgb=color, depth=depth, opacity=opacity, aux=aux, num_samples=count)

    def _composite_features(self, origins: torch.Tensor, directions: torch.Tensor, aux: dict):
        """Features (R, C) composited over every occupied sample (jittered when training), with
        opacity (R,), depth (R,) and the number of samples marched.

        Colour is read only where it shows: samples under the weight threshold (after
        termination, or in near-empty space) add no features.
        """
        n_rays = origins.shape[0]
        t, weights, ray, opacity, depth, count = self._march_and_weigh(origins, directions, aux)
        threshold = self.config.weight_threshold if self.training else self.config.render_threshold
        keep = (weights.detach() >= threshold).nonzero()[:, 0]  # still sorted by ray
        kept_ray, kept_t = ray.index_select(0, keep), t.index_select(0, keep)
        samples = (origins, directions, kept_t, weights.index_select(0, keep), kept_ray,
                   torch.bincount(kept_ray, minlength=n_rays))
        tv = self.training and self.config.tv_features > 0 and len(keep) > 0
        if tv:
            samples = self._with_tv_probes(*samples)
        features = self.feature_grid.composite(*samples)
        if tv:
            probes = features[n_rays:].view(2, -1, features.shape[1])  # points, then neighbours
            aux["tv_features"] = torch.mean((probes[1] - probes[0]) ** 2)
            features = features[:n_rays]
        return features, opacity, depth, count

    def _with_tv_probes(self, origins, directions, t, weights, ray, counts):
        """The composite's packed samples with one-sample rays of weight 1 appended, so that the
        same composite reads the features for the total variation: at a random kept sample per
        TV_RAYS rays and one voxel from it along a random axis. (Read in a separate grid call, the
        features would get a second sparse gradient, and adding the two costs more than the
        reads.)"""
        n_rays = origins.shape[0]
        pick = torch.randint(len(t), (max(1, n_rays // TV_RAYS),), device=t.device)
        points = sample_points(origins, directions, t.index_select(0, pick), ray.index_select(0, pick))
        # one neighbour per point, along a random axis: the same expected variation as all three
        axis = torch.randint(3, (len(pick),), device=t.device)
        points = torch.cat([points, points + torch.diag(self.feature_grid.voxel).index_select(0, axis)])
        n = points.shape[0]
        ones = torch.ones(n, device=t.device)
        return (torch.cat([origins, points]), torch.cat([directions, torch.zeros_like(points)]),
                torch.cat([t, torch.zeros_like(ones)]), torch.cat([weights, ones]),
                torch.cat([ray, torch.arange(n_rays, n_rays + n, device=t.device)]),
                torch.cat([counts, torch.ones_like(counts[:1]).expand(n)]))

    def _march_and_weigh(self, origins: torch.Tensor, directions: torch.Tensor, aux: dict):
        """Every occupied sample (jittered when training) and its compositing weight.

        Returns t (S,), weights (S,), ray (S,), opacity (R,), depth (R,) and S; when training
        with regularisers, puts each ray's distortion (R,), the density's total variation and
        the occlusion penalty (scalars) into `aux`. With `density_dropout`, training drops
        samples' density at random (DropGaussian's idea carried to a grid).
        """
        step = self.step_length
        samples = self.occupancy.march(origins, directions, self.bounds.near, self.bounds.far,
                                       step, jitter=self.training)
        ray, t = samples.ray, samples.t
        if self.training and self.config.tv_density > 0:
            raw, aux["tv_density"] = self._density_with_tv(origins, directions, t, ray)
        else:
            raw = self.density_grid.along_rays(origins, directions, t, ray)[:, 0]
        sigma = self._activate(raw)
        if self.training and self.config.occlusion > 0:
            aux["occlusion"] = self._occlusion(origins, directions, t, ray, sigma * step)
        if self.training and self.config.density_dropout > 0:
            sigma = F.dropout(sigma, self.config.density_dropout)  # the rest scaled up by 1/(1-p)
        weights, opacity, depth = ray_weights(sigma, step, t, ray, samples.counts)
        if self.training and self.config.distortion > 0:
            aux["distortion"] = packed_distortion(weights, t, step, ray, samples.counts)
        return t, weights, ray, opacity, depth, len(samples)

    def _occlusion(self, origins, directions, t, ray, thickness) -> torch.Tensor:
        """FreeNeRF's occlusion penalty for a box: the rays' mean optical thickness (`thickness`
        (S,): density times step) within `occlusion_reach` (world units) of where they enter it."""
        entry = ray_box(origins, directions, self.occupancy.aabb, self.bounds.near, self.bounds.far)[0]
        near = (t - entry.index_select(0, ray)) < self.config.occlusion_reach
        return torch.sum(thickness * near) / origins.shape[0]

    def _density_with_tv(self, origins, directions, t, ray) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw density (S,) at the samples and its total variation: the mean squared change from
        every sample to one voxel away along each axis, scaled to a change over 1/TV_SPAN of the
        box's longest side (one grid read, so one sparse gradient)."""
        points = sample_points(origins, directions, t, ray)
        voxel = self.density_grid.voxel
        steps = torch.diag(voxel)  # (3, 3)
        neighbours = (points[None] + steps[:, None, :]).reshape(-1, 3)
        raw = self.density_grid(torch.cat([points, neighbours]))[:, 0]
        here, there = raw[:len(points)], raw[len(points):].view(3, -1)
        # Changes per TV_SPAN of the box's longest side, not per voxel: the field's gradient, so
        # one weight smooths alike at any resolution (per voxel, a weight that gains 0.7 dB on
        # 8 photos of 400x400 loses 1 on 10 of 100x100, whose voxels are 2.3x as wide)
        per_span = (self.density_grid.aabb[1] - self.density_grid.aabb[0]).max() / TV_SPAN / voxel
        return here, torch.mean(((there - here[None]) * per_span[:, None]) ** 2)

    @torch.no_grad()
    def _composite_features_fused(self, origins: torch.Tensor, directions: torch.Tensor):
        """As `_composite_features` without jitter, in one kernel that stops each ray once its
        transmittance is below `render_threshold` and composites the samples above it as it goes."""
        occupancy, density = self.occupancy, self.density_grid
        t_min, t_max = ray_box(origins, directions, occupancy.aabb, self.bounds.near, self.bounds.far)
        features, counts, opacity, depth = kernels.render_composite(
            origins.contiguous(), directions.contiguous(), t_min, t_max, self.step_length,
            occupancy.kernel_grid(), density.values.detach().view(-1),
            self.feature_grid.values.detach(), density.shape, density.mapping()[1], self.shift,
            self.density_scale, self.config.render_threshold)
        return features, opacity, depth, int(counts.sum())

    # --- training: primitives the schedule (fit/schedule.py) calls ------------------------------
    def make_optimizer(self) -> torch.optim.Optimizer:
        cfg = self.config
        # kept (weakly) so that growing grids take their Adam moments along (see grow)
        optimizer = GridAdam([
            {"params": [self.density_grid.values, self.feature_grid.values], "lr": cfg.lr_grid},
            {"params": list(self.mlp.parameters()), "lr": cfg.lr_mlp},
        ])
        self._optimizer = weakref.ref(optimizer)
        return optimizer

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        """Vertices per axis of both grids now."""
        return self.density_grid.shape

    def lattice(self, share: float) -> tuple[int, int, int]:
        """The lattice of `share` of the final voxel count over the object's box."""
        return lattice_shape(self.extent, round(self.voxels * share))

    def limit_voxels(self, voxels: int) -> None:
        """Make the final voxel count the smaller of `voxels` (at least MIN_VOXELS) and the count
        the model was built with; the grids grow to the new lattices from the next growth point
        on. Density keeps its units (per voxel of the built count), so the grids mean the same."""
        self.voxels = min(self.config.voxels or DEFAULT_VOXELS, max(voxels, MIN_VOXELS))

    def get_extra_state(self) -> dict:
        return {"voxels": self.voxels}  # the final count, once limit_voxels lowered it

    def set_extra_state(self, state: dict) -> None:
        self.voxels = int(state["voxels"])

    @torch.no_grad()
    def grow(self, shape: tuple[int, int, int]) -> None:
        """Resample both grids, and their Adam moments, to `shape`; every cell of the new lattice
        starts occupied. (Fresh moments would make Adam's first steps move every voxel by the
        full learning rate at once, a jolt that costs several dB at 400x400.)"""
        optimizer = self._optimizer() if self._optimizer is not None else None
        states = optimizer.state if optimizer is not None else {}
        for grid in (self.density_grid, self.feature_grid):
            state = states.get(grid.values)
            if state and state["exp_avg"].shape == grid.values.shape:
                for key in ("exp_avg", "exp_avg_sq"):
                    state[key] = grid.resample(state[key], shape)
            grid.resize(shape)
        self.occupancy.set(torch.ones(tuple(s - 1 for s in shape), dtype=torch.bool,
                                      device=self.occupancy.occupied.device))

    @property
    def carve_cells(self) -> tuple[int, int, int]:
        """The resolution to carve at: the occupancy cells once the grids have grown, but no more
        than about CARVE_VOXELS (carving 160^3 cells takes seconds; a coarser mask is as safe,
        since the occupancy grid keeps every cell that overlaps it)."""
        return tuple(s - 1 for s in lattice_shape(self.extent, min(self.voxels, CARVE_VOXELS)))

    @torch.no_grad()
    def carve(self, hull: torch.Tensor) -> None:
        """Confine the object to the carve mask `hull` (HX, HY, HZ) bool over the box (any
        resolution; scene.hull.carve_mask): cells outside are never occupied, so never sampled,
        trained or drawn, and the density at vertices with no cell inside starts empty (what
        `density` tells an exporter). The mask is saved with the model."""
        self.occupancy.carve(hull)
        inside = self.occupancy.hull_at(self.occupancy.occupied.shape)
        # a vertex touches the cells on either side of it along each axis
        near = any_of_corners(F.pad(inside, (1, 1, 1, 1, 1, 1)))
        self.density_grid.values[~near.view(-1)] = self._raw_at_alpha(EMPTY_ALPHA)

    @torch.no_grad()
    def finish_training(self, training_rays) -> None:
        """Empty the space no training ray reached with `empty_unseen` transmittance or more: each
        sample's arrival transmittance goes to its nearest vertex (the highest wins), and a vertex
        is kept when it or a neighbour was seen (a sample reads its cell's 8 corners)."""
        if self.config.empty_unseen <= 0:
            return
        was_training = self.training
        self.eval()  # the render's own samples: no jitter
        shape = self.grid_shape
        seen = torch.zeros(shape, device=self.density_grid.values.device)
        last = torch.tensor(shape, device=seen.device) - 1
        for origins, directions in training_rays:
            t, weights, ray, *_ = self._march_and_weigh(origins, directions, {})
            points = sample_points(origins, directions, t, ray)
            vertex = torch.minimum(self.density_grid.to_grid(points).round().long().clamp(min=0), last)
            flat = (vertex[:, 0] * shape[1] + vertex[:, 1]) * shape[2] + vertex[:, 2]
            arrival = arrival_transmittance(weights, torch.bincount(ray, minlength=origins.shape[0]))
            seen.view(-1).scatter_reduce_(0, flat, arrival, reduce="amax")
        near_seen = F.max_pool3d((seen >= self.config.empty_unseen)[None, None].float(), 3, 1, 1)[0, 0]
        self.density_grid.values[near_seen.view(-1) == 0] = self._raw_at_alpha(EMPTY_ALPHA)
        self.refresh_occupancy()
        self.train(was_training)

    @torch.no_grad()
    def refresh_occupancy(self) -> None:
        """Skip the cells where no corner reaches `occupancy_alpha` over one step."""
        raw = self._raw_at_alpha(self.config.occupancy_alpha)
        self.occupancy.set_from_vertices(self.density_grid.vertex_values()[0], raw)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        # checkpoints written before the grids were renamed call them "density" and "features"
        for old, new in (("density.", "density_grid."), ("features.", "feature_grid.")):
            for key in [k for k in state_dict if k.startswith(prefix + old)]:
                state_dict[prefix + new + key[len(prefix + old):]] = state_dict.pop(key)
        state_dict.setdefault(prefix + "_extra_state", self.get_extra_state())  # older: no limit
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
