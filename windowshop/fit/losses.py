"""The training losses as functions, composed by the trainer from the model's config.

Every term takes a `LossInput` (the rendered batch, its target, the model, and a sampler of rays
from cameras that have no photo) and returns a scalar. The photometric term is always on; each
regulariser in `REGULARISERS` is on when the model's config has a field of the same name with a
positive weight. Adding a regulariser is one function here, one line in `REGULARISERS` and one
config field. Terms that need internals of the model's renderer (the fast model's distortion and
density total variation) read what `render_rays` put into `RenderOutput.aux` while training.
Terms in `VIRTUAL` look at patches of rays from cameras with no photo (RegNeRF's priors), rendered
once per step for all of them (`LossInput.patches`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import torch

from windowshop.fit.batches import CameraRays
from windowshop.model import RadianceModel, RenderOutput


@dataclass
class LossInput:
    """What a loss term may look at for one training step of R rays."""

    model: RadianceModel
    out: RenderOutput  # the model's render of the batch
    target: torch.Tensor  # (R, 3) the photos' colours over `background`
    background: torch.Tensor  # (R, 3)
    virtual: CameraRays | None = None  # rays from cameras with no photo (for terms that ask)
    _patches: RenderOutput | None = field(default=None, repr=False)

    def patches(self) -> tuple[RenderOutput, int]:
        """The model's render of `virtual_patches` square patches of `patch_size`^2 virtual rays
        (its config's settings), patch after patch, row-major (rendered once, then kept), and
        the patches' side."""
        config = self.model.config
        if self._patches is None:
            origins, directions = self.virtual.patches(config.virtual_patches, config.patch_size)
            self._patches = self.model.render_rays(origins, directions, torch.zeros_like(origins))
        return self._patches, config.patch_size


@dataclass(frozen=True)
class LossTerm:
    """`weight * fn(input)`; `virtual` terms get `LossInput.virtual` (see `fit(virtual_cameras=)`)."""

    name: str
    weight: float
    fn: Callable[[LossInput], torch.Tensor]
    virtual: bool = False


def photometric(inp: LossInput) -> torch.Tensor:
    """MSE of the colour, plus that of every auxiliary colour (the NeRF's coarse pass)."""
    loss = torch.mean((inp.out.rgb - inp.target) ** 2)
    for key, value in inp.out.aux.items():
        if key.startswith("rgb_"):
            loss = loss + torch.mean((value - inp.target) ** 2)
    return loss


def distortion(inp: LossInput) -> torch.Tensor:
    """mip-NeRF 360's distortion: the rays' mean of aux["distortion"] (R,)."""
    return inp.out.aux["distortion"].mean()


def tv_density(inp: LossInput) -> torch.Tensor:
    """Total variation of the raw density at the samples, aux["tv_density"] (a scalar)."""
    return inp.out.aux["tv_density"]


def tv_features(inp: LossInput) -> torch.Tensor:
    """Total variation of the features at the samples that show, aux["tv_features"] (a scalar)."""
    return inp.out.aux["tv_features"]


def occlusion(inp: LossInput) -> torch.Tensor:
    """FreeNeRF's occlusion penalty: density near where the rays enter the box, aux["occlusion"]."""
    return inp.out.aux["occlusion"]


def patch_smoothness(values: torch.Tensor, weights: torch.Tensor, size: int) -> torch.Tensor:
    """The mean over every pair of neighbouring pixels (across and down) of square patches of their
    `weights`' product times the squared difference of their `values`: both (P * size * size,),
    patch after patch, row-major within a patch. Zero for constant values."""
    v, w = values.view(-1, size, size), weights.view(-1, size, size)
    across = (v[:, :, 1:] - v[:, :, :-1]) ** 2 * w[:, :, 1:] * w[:, :, :-1]
    down = (v[:, 1:] - v[:, :-1]) ** 2 * w[:, 1:] * w[:, :-1]
    return (across.sum() + down.sum()) / (across.numel() + down.numel())


def depth_smoothness(inp: LossInput) -> torch.Tensor:
    """RegNeRF's depth smoothness on virtual patches: the surface depth (expected depth over the
    opacity, so that fading a ray moves no surface) of neighbouring rays should agree where both
    hit the object (pairs weighed by their opacities, which get no gradient from the weighing:
    the object's outline is left to the photos)."""
    out, size = inp.patches()
    return patch_smoothness(out.depth / out.opacity.clamp(min=1e-3), out.opacity.detach(), size)


def virtual_entropy(inp: LossInput) -> torch.Tensor:
    """The mean binary entropy of the virtual patches' opacities: each ray should hit the object
    or miss it, not pass through haze."""
    opacity = inp.patches()[0].opacity.clamp(1e-4, 1.0 - 1e-4)
    return -torch.mean(opacity * torch.log(opacity) + (1.0 - opacity) * torch.log1p(-opacity))


# config field (the term's weight) -> term
REGULARISERS: dict[str, Callable[[LossInput], torch.Tensor]] = {
    "distortion": distortion,
    "tv_density": tv_density,
    "tv_features": tv_features,
    "occlusion": occlusion,
    "depth_smoothness": depth_smoothness,
    "virtual_entropy": virtual_entropy,
}
VIRTUAL = frozenset({"depth_smoothness", "virtual_entropy"})  # terms on virtual rays


def loss_terms(config: Any, extra: Iterable[LossTerm] = ()) -> list[LossTerm]:
    """The photometric term, the regularisers `config` weighs above zero, then `extra`."""
    terms = [LossTerm("photometric", 1.0, photometric)]
    for name, fn in REGULARISERS.items():
        weight = float(getattr(config, name, 0.0) or 0.0)
        if weight > 0:
            terms.append(LossTerm(name, weight, fn, virtual=name in VIRTUAL))
    return terms + list(extra)


def total_loss(terms: Iterable[LossTerm], inp: LossInput) -> torch.Tensor:
    """The weighted sum of `terms` on `inp` (a scalar)."""
    return sum(term.weight * term.fn(inp) for term in terms)
