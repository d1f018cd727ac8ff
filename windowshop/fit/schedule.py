"""Training schedules as hooks: what changes with progress, decided here, done by the model.

The trainer calls every hook's `before_step` before a step's batch is rendered and `after_step`
once the optimizer has stepped, with the step number and the budget's fraction used. A model keeps
the primitive operations (the fast model's `grow(shape)` and `refresh_occupancy()`); its schedule
(`SCHEDULES[model.name]`) decides when. A new schedule is one hook class and one line there.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch

from windowshop.model import RadianceModel


@dataclass
class StepInfo:
    """Where training stands as a hook sees it."""

    model: RadianceModel
    optimizer: torch.optim.Optimizer
    step: int  # steps taken before this one
    fraction: float  # of the budget used, in [0, inf)
    rays: int  # in each step's batch


class Hook:
    """A schedule: override either or both."""

    def before_step(self, info: StepInfo) -> None:
        pass

    def after_step(self, info: StepInfo) -> None:
        pass


def exponential(final: float, tail: float = 0.0, tail_factor: float = 1.0
                ) -> Callable[[float], float]:
    """The factor falling from 1 at progress 0 to `final` at 1 (clamped to [0, 1]), and over the
    last `tail` of the progress by `tail_factor` more, exponentially too (so `final * tail_factor`
    at 1). The tail is the decay phase of warmup-stable-decay schedules (Hägele et al. 2024):
    a run of any length gains most of annealing's benefit from its last part."""
    def factor(fraction: float) -> float:
        x = min(max(fraction, 0.0), 1.0)
        into_tail = (x - (1.0 - tail)) / tail if tail > 0 else 0.0
        return final ** x * tail_factor ** max(into_tail, 0.0)
    return factor


@dataclass
class LearningRate(Hook):
    """Every group's `lr` = its `initial_lr` times `factor(fraction)`."""

    factor: Callable[[float], float]

    def before_step(self, info: StepInfo) -> None:
        scale = self.factor(info.fraction)
        for group in info.optimizer.param_groups:
            group["lr"] = group["initial_lr"] * scale


def grid_fraction(fraction: float, growth: tuple[float, ...], start: float) -> float:
    """The share of the final voxel count at `fraction`: `start` at first, multiplied by the same
    factor at each `growth` point passed, reaching 1 at the last."""
    if not growth:
        return 1.0
    done = sum(fraction >= p for p in growth)
    return start ** (1.0 - done / len(growth))


@dataclass
class GridGrowth(Hook):
    """Grow the model's grids (`model.lattice(share)`, `model.grow(shape)`) at each growth point.

    With `rays_per_voxel`, each growth point first caps the final voxel count
    (`model.limit_voxels`) at the rays the run will train on over `rays_per_voxel`: the steps
    taken plus those left at the rate since the previous growth point (the latest estimate wins:
    the first steps, before empty space is skipped, are slow). A time budget on a slow device gets
    a coarser grid; a step budget knows its rays exactly."""

    growth: tuple[float, ...]
    start: float
    rays_per_voxel: float = 0.0
    passed: int | None = None  # growth points passed at the last call (None: no call yet)
    mark: tuple[int, float] = (0, 0.0)  # step and fraction when that count last changed

    def before_step(self, info: StepInfo) -> None:
        passed = sum(info.fraction >= p for p in self.growth)
        if self.passed is not None and passed > self.passed and self.rays_per_voxel > 0:
            info.model.limit_voxels(round(self.expected_steps(info) * info.rays / self.rays_per_voxel))
        if passed != self.passed:
            self.passed, self.mark = passed, (info.step, info.fraction)
        shape = info.model.lattice(grid_fraction(info.fraction, self.growth, self.start))
        if math.prod(shape) > math.prod(info.model.grid_shape):  # a lowered cap never shrinks it
            info.model.grow(shape)

    def expected_steps(self, info: StepInfo) -> float:
        """Steps the run will have taken at the end of its budget, at the rate since `mark`."""
        step, fraction = self.mark
        if info.fraction <= fraction:
            return float(info.step)
        rate = (info.step - step) / (info.fraction - fraction)
        return info.step + rate * max(1.0 - info.fraction, 0.0)


@dataclass
class OccupancyRefresh(Hook):
    """`model.refresh_occupancy()` every `every` steps from step `warmup` on, and at once after
    the grids grew (growth marks every new cell occupied)."""

    warmup: int
    every: int
    seen: tuple[int, int, int]  # the lattice at the last call (at first: the model's)

    def before_step(self, info: StepInfo) -> None:
        shape = info.model.grid_shape
        grew, self.seen = shape != self.seen, shape
        if info.step >= self.warmup and (grew or info.step % self.every == 0):
            info.model.refresh_occupancy()


def nerf_schedule(model: RadianceModel) -> list[Hook]:
    """The paper's: learning rate decayed exponentially from `lr` to `lr_final`."""
    return [LearningRate(exponential(model.config.lr_final / model.config.lr))]


def fast_schedule(model: RadianceModel) -> list[Hook]:
    """Learning rates decayed to `lr_final` of their start, then annealed over the budget's last
    `lr_tail` by `lr_tail_factor`; grids grown coarse to fine, the occupancy grid refreshed (order
    matters: a refresh follows the growth of the same step)."""
    config = model.config
    return [LearningRate(exponential(config.lr_final, config.lr_tail, config.lr_tail_factor)),
            GridGrowth(config.growth, config.start_fraction, config.rays_per_voxel),
            OccupancyRefresh(config.occupancy_warmup, config.occupancy_every, model.grid_shape)]


# model name -> its schedule, built for a model as it stands (fresh, or restored to resume)
SCHEDULES: dict[str, Callable[[RadianceModel], list[Hook]]] = {
    "nerf": nerf_schedule,
    "fast": fast_schedule,
}


def schedule_for(model: RadianceModel) -> list[Hook]:
    """The hooks of `model`'s schedule, in call order (none for a model without one)."""
    make = SCHEDULES.get(model.name)
    return make(model) if make else []
