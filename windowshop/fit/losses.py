"""The training losses as functions, composed by the trainer from the model's config.

Every term takes a `LossInput` (the rendered batch, its target, the model, and a sampler of rays
from cameras that have no photo) and returns a scalar. The photometric term is always on; each
regulariser in `REGULARISERS` is on when the model's config has a field of the same name with a
positive weight. Adding a regulariser is one function here, one line in `REGULARISERS` and one
config field. Terms that need internals of the model's renderer (the fast model's distortion and
density total variation) read what `render_rays` put into `RenderOutput.aux` while training.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
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


# config field (the term's weight) -> term
REGULARISERS: dict[str, Callable[[LossInput], torch.Tensor]] = {
    "distortion": distortion,
    "tv_density": tv_density,
}


def loss_terms(config: Any, extra: Iterable[LossTerm] = ()) -> list[LossTerm]:
    """The photometric term, the regularisers `config` weighs above zero, then `extra`."""
    terms = [LossTerm("photometric", 1.0, photometric)]
    for name, fn in REGULARISERS.items():
        weight = float(getattr(config, name, 0.0) or 0.0)
        if weight > 0:
            terms.append(LossTerm(name, weight, fn))
    return terms + list(extra)


def total_loss(terms: Iterable[LossTerm], inp: LossInput) -> torch.Tensor:
    """The weighted sum of `terms` on `inp` (a scalar)."""
    return sum(term.weight * term.fn(inp) for term in terms)
