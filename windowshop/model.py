"""The contract between a radiance model, the trainer and the renderers.

A model is an `nn.Module` that turns rays into colours and answers for its density and colour at
any point (so an exporter or a loss needs nothing model-specific); its losses (windowshop.fit.losses)
and schedule (windowshop.fit.schedule) live with the trainer. The trainer, `eval`, `render`, the
study and the service only use what is declared here, so every model (`nerf`, `fast`, ...) plugs
into all of them. Models are registered by name in `MODELS` and rebuilt from their checkpoint's own config.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from windowshop.errors import UserError
from windowshop.overrides import apply_overrides, leaves, named


@dataclass(frozen=True)
class Bounds:
    """Where a model may sample, in the scene's normalised frame."""

    aabb: tuple[tuple[float, float, float], tuple[float, float, float]]  # min corner, max corner
    near: float
    far: float

    @classmethod
    def of_scene(cls, scene) -> "Bounds":
        lo, hi = np.asarray(scene.aabb, dtype=float)
        return cls(aabb=(tuple(lo.tolist()), tuple(hi.tolist())), near=float(scene.near),
                   far=float(scene.far))

    def aabb_tensor(self, device: torch.device | str = "cpu") -> torch.Tensor:
        """(2, 3) float32 tensor of the box."""
        return torch.tensor(self.aabb, dtype=torch.float32, device=device)


@dataclass
class RenderOutput:
    """What a model returns for R rays."""

    rgb: torch.Tensor  # (R, 3) composited over the given background
    depth: torch.Tensor  # (R,) expected distance along the (unit) ray
    opacity: torch.Tensor  # (R,) accumulated alpha
    aux: dict[str, torch.Tensor] = field(default_factory=dict)  # e.g. "rgb_coarse" (R, 3)
    num_samples: int = 0  # samples evaluated for this batch (for samples/s figures)


class RadianceModel(nn.Module):
    """Base class of every model. Subclasses set `name` and implement `render_rays`."""

    name: str = ""
    config_type: type = object  # the frozen dataclass of its settings
    batch_rays: int = 1024  # rays per training step unless FitConfig.batch_rays says otherwise
    presets: dict[str, Any] = {}  # named instances of config_type; the first is the default

    def __init__(self, config: Any, bounds: Bounds):
        super().__init__()
        self.config = config
        self.bounds = bounds

    @classmethod
    def for_scene(cls, config: Any, scene) -> Any:
        """`config` with any choices it leaves to the training scene filled in (e.g. a grid sized
        to the photos' resolution). The trainer calls this once; the run stores the result."""
        return config

    def bytes_per_ray(self, training: bool) -> float:
        """Working memory one ray of `render_rays` takes at most, in bytes: with autograd's saved
        tensors when `training`. Chunks of rays are sized by it (windowshop/memory.py); this
        default is a generous guess, models give their own."""
        return 64 * 1024.0

    def render_rays(self, origins: torch.Tensor, directions: torch.Tensor,
                    background: torch.Tensor) -> RenderOutput:
        """Render rays `origins` (R, 3), unit `directions` (R, 3) over `background` (R, 3)."""
        raise NotImplementedError

    def density(self, points: torch.Tensor) -> torch.Tensor:
        """Density (N,) >= 0 at world points (N, 3), as `render_rays` composites it."""
        raise NotImplementedError

    def colour(self, points: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        """Colour (N, 3) in [0, 1] at world points (N, 3) seen along unit `directions` (N, 3)."""
        raise NotImplementedError

    def make_optimizer(self) -> torch.optim.Optimizer:
        """The optimizer the trainer steps; its groups' `lr` are the initial learning rates."""
        raise NotImplementedError

    def finish_training(self, training_rays: Iterable[tuple[torch.Tensor, torch.Tensor]]) -> None:
        """Called once when a fit's budget is spent, with every training ray as chunks of
        (origins (R, 3), directions (R, 3)): a model may tidy what the photos leave free."""


MODELS = {
    "nerf": "windowshop.field.nerf:NerfModel",
    "fast": "windowshop.field.fast:FastModel",
}


def model_class(name: str) -> type[RadianceModel]:
    """The class registered under `name`."""
    if name not in MODELS:
        raise UserError(f"unknown model {name!r}; choose one of {', '.join(sorted(MODELS))}")
    module, attr = MODELS[name].split(":")
    return getattr(importlib.import_module(module), attr)


def apply_run_overrides(config: Any, overrides: dict[str, Any], where: str = "settings") -> Any:
    """`config` (a RunConfig or PipelineConfig) with `overrides`; a bare key that only the model's
    own config has (`voxel_pixels`) goes to `model_settings`, and the model's settings are checked."""
    model = overrides.get("model", config.model)
    names = {f.name for f in dataclasses.fields(model_class(model).config_type)}
    paths = leaves(type(config))
    if unknown := sorted(k for k in overrides if not named(k, paths) and "." not in k
                         and k.replace("-", "_") not in names):
        raise UserError(f"{where}: model {model!r} has no setting {', '.join(unknown)}; its "
                        f"settings: {', '.join(sorted(names))}; the run's: {', '.join(sorted(paths))}")
    routed = {(f"model_settings.{k}" if k.replace("-", "_") in names and not named(k, paths) else k): v
              for k, v in overrides.items()}
    config = apply_overrides(config, routed, where)
    model_config(config.model, config.preset, **config.model_settings)  # a bad setting fails now
    return config


def model_config(name: str, preset: str | None = None, **overrides: Any) -> Any:
    """The config of model `name`: its `preset` (default: its first) with `overrides` applied,
    each checked against the field's type; UserError names an unknown preset or setting."""
    cls = model_class(name)
    preset = preset or next(iter(cls.presets))
    if preset not in cls.presets:
        raise UserError(f"unknown preset {preset!r} of model {name!r}; "
                        f"choose one of {', '.join(cls.presets)}")
    return apply_overrides(cls.presets[preset], overrides, f"model {name!r}")
