"""The training loop every model shares, using only the `RadianceModel` contract.

Each step runs the model's schedule hooks (learning rate, grid growth, ...: fit/schedule.py),
draws `batch_rays` random rays across all training views, renders them over the scene's background
(a random colour per ray for masked scenes, the target composited over the same colour; mattes
over a known colour return to that colour late in the budget: TrainingBackground), steps
the optimizer on the loss terms its config asks for (fit/losses.py), and logs loss, PSNR and
throughput. A fresh model of a masked scene is first carved to the visual hull of the training
masks (models with a `carve`, when their config asks). Progress is the larger of steps/iters and
seconds/budget, so with `seconds` the schedule follows elapsed training time. Callers follow and
stop a fit through `FitCallbacks`.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from windowshop.config import FitConfig
from windowshop.device import ThreadTuner
from windowshop.errors import UserError
from windowshop.fit.batches import CameraRays, PixelBank
from windowshop.fit.callbacks import FitCallbacks, FitCancelled
from windowshop.fit.checkpoint import LOG, load_checkpoint, save_checkpoint, scene_record, write_config
from windowshop.fit.evaluate import EVAL_DIR, evaluate_views, held_out_views, write_metrics
from windowshop.fit.losses import LossInput, LossTerm, loss_terms, total_loss
from windowshop.fit.schedule import Hook, StepInfo, schedule_for
from windowshop.fit.virtual import virtual_rays
from windowshop.memory import spans
from windowshop.metrics import psnr_of_mse
from windowshop.model import Bounds, RadianceModel, model_class
from windowshop.progress import bar as progress_bar
from windowshop.scene.hull import carve_mask
from windowshop.scene.types import BACKGROUNDS, Camera, Scene

log = logging.getLogger(__name__)


@dataclass
class Progress:
    """Where training stands: steps taken and seconds spent in them."""

    step: int = 0
    elapsed: float = 0.0

    def fraction(self, config: FitConfig) -> float:
        """Fraction of the budget used, in [0, inf); training stops at 1."""
        parts = [self.step / config.iters if config.iters else 0.0,
                 self.elapsed / config.seconds if config.seconds else 0.0]
        return max(parts)


@dataclass
class TrainingRun:
    """A training session: the model, its optimizer and budget, where checkpoints go, and the
    hooks of the loop. `schedule` and `losses` default to the model's own (from its config)."""

    model: RadianceModel
    optimizer: torch.optim.Optimizer
    config: FitConfig
    record: dict  # scene_record of the training scene
    out_dir: Path
    progress: Progress
    callbacks: FitCallbacks = field(default_factory=FitCallbacks)
    schedule: list[Hook] | None = None
    losses: list[LossTerm] | None = None
    virtual: CameraRays | None = None  # rays from cameras with no photo, for `virtual` loss terms

    def __post_init__(self) -> None:
        if self.schedule is None:
            self.schedule = schedule_for(self.model)
        if self.losses is None:
            self.losses = loss_terms(self.model.config)

    def checkpoint(self, final: bool = False) -> None:
        optimizer = None if final and not self.config.final_optimizer else self.optimizer
        path = save_checkpoint(self.out_dir, self.model, optimizer, self.record, self.config,
                               self.progress.step, self.progress.elapsed)
        self.callbacks.checkpointed(path)


def fit(scene: Scene, model_name: str, model_config: Any, fit_config: FitConfig,
        out_dir: str | Path, device: torch.device | str,
        resume: str | Path | None = None, show_progress: bool = True,
        callbacks: FitCallbacks = FitCallbacks(), extra_losses: Sequence[LossTerm] = (),
        virtual_cameras: Sequence[Camera] | None = None) -> dict:
    """Train `model_name` with `model_config` on `scene` into the run folder `out_dir`.

    With `resume` (a run folder) the model, optimizer, step and elapsed time come from its
    checkpoint and training carries on to the budget of `fit_config`. Returns the held-out metrics
    (also written to `out_dir/metrics.json`). `callbacks` hear of every step and checkpoint; when
    its `should_stop()` is true the run is checkpointed and `FitCancelled` raised (no evaluation).
    `extra_losses` are added to the model's; those marked `virtual` are fed rays from
    `virtual_cameras` (default: random cameras around the training ones), which need no photo.
    """
    if not fit_config.iters and not fit_config.seconds:
        raise UserError("give a training budget: --iters N or --seconds S")
    train_views = scene.split("train")
    if not train_views:
        raise UserError(f"{scene.source}: no training views to fit")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(fit_config.seed)
    model_config = model_class(model_name).for_scene(model_config, scene)
    model = model_class(model_name)(model_config, Bounds.of_scene(scene)).to(device)
    optimizer = model.make_optimizer()
    for group in optimizer.param_groups:
        group.setdefault("initial_lr", group["lr"])
    if resume:
        progress = _restore(model, optimizer, resume)  # with the carve it was trained with
    else:
        progress = Progress()
        carve_to_scene(model, scene)
    torch.manual_seed(fit_config.seed + progress.step)  # a resumed run draws fresh batches
    record = scene_record(scene)
    losses = loss_terms(model_config, extra_losses)
    virtual = virtual_sampler(losses, [v.camera for v in train_views], model.bounds, device,
                              fit_config.seed + progress.step, virtual_cameras)
    bank, background = training_pixels(scene, model_config, device)
    budget = capped_by_passes(fit_config, model, len(bank))
    run = TrainingRun(model, optimizer, budget, record, out_dir, progress, callbacks,
                      losses=losses, virtual=virtual)
    write_config(out_dir, model_name, model_config, budget, run.record)
    try:
        _train(run, bank, background, show_progress)
        finish(run, bank)
    except FitCancelled:
        run.checkpoint()
        raise
    except KeyboardInterrupt:
        run.checkpoint()
        raise UserError(f"interrupted at step {progress.step}; carry on with --resume {out_dir}")
    run.checkpoint(final=True)
    results = evaluate_views(model, held_out_views(scene), scene.background,
                             fit_config.memory_budget, out_dir / EVAL_DIR, fit_config.refine_held_out)
    metrics = {**results, "model": model_name, "train_seconds": progress.elapsed,
               "iterations": progress.step,
               "stopped_by_passes": budget.iters != fit_config.iters and progress.step >= budget.iters}
    write_metrics(out_dir, metrics)
    return metrics


def finish(run: TrainingRun, bank: PixelBank) -> None:
    """The budget is spent: the model may tidy its field, given every training ray."""
    rays = bank.chunks(run.model.bytes_per_ray(training=False), run.config.memory_budget)
    run.model.finish_training((r.origins, r.directions) for r in rays)


def _restore(model: RadianceModel, optimizer: torch.optim.Optimizer, run_dir: str | Path) -> Progress:
    """Load a run folder's weights and optimizer state; return where it stopped."""
    state = load_checkpoint(run_dir)
    if state["model_name"] != model.name:
        raise UserError(f"{run_dir} holds a {state['model_name']!r} model, not {model.name!r}")
    model.load_state_dict(state["model_state"])
    if state["optimizer_state"] is not None:
        optimizer.load_state_dict(state["optimizer_state"])
    else:
        log.info("%s was saved without its optimizer state: Adam starts afresh", run_dir)
    return Progress(step=int(state["step"]), elapsed=float(state["elapsed_seconds"]))


def capped_by_passes(config: FitConfig, model: RadianceModel, pixels: int) -> FitConfig:
    """`config` with its steps capped at the model's `max_passes` (if it has one) over the
    `pixels` training pixels: a fit on few small photos learns no more after that many passes,
    it only fits the photos closer (bench/RESULTS.md). The schedule follows the capped budget."""
    passes = getattr(model.config, "max_passes", 0) or 0
    if passes <= 0:
        return config
    cap = math.ceil(passes * pixels / (config.batch_rays or model.batch_rays))
    if config.iters and config.iters <= cap:
        return config
    log.info("stopping after %d steps at the latest: %g passes over %d training pixels",
             cap, passes, pixels)
    return replace(config, iters=cap)


def masked_training(scene: Scene, model_config: Any) -> bool:
    """Whether training sees the object alone (random backgrounds, carving): always for "alpha"
    scenes, and for scenes composited over a known colour when every training view carries its
    matte and the model asks for it (its `masked` setting: the fast model's few-photo prior)."""
    if scene.background == "alpha":
        return True
    return (bool(getattr(model_config, "masked", False)) and scene.background in BACKGROUNDS
            and all(v.alpha is not None for v in scene.split("train")))


@dataclass(frozen=True)
class TrainingBackground:
    """What training rays are composited over: `kind` (a scene background, or "alpha": a random
    colour per ray) until `until` of the budget, then `finish` (None: `kind` to the end)."""

    kind: str
    finish: str | None = None
    until: float = 1.0

    def at(self, fraction: float) -> str:
        return self.finish if self.finish is not None and fraction >= self.until else self.kind


def training_pixels(scene: Scene, model_config: Any, device) -> tuple[PixelBank, TrainingBackground]:
    """The training views' pixels and the background their rays are drawn over: a masked scene's
    random colours, which one composited over a known colour leaves for that colour after its
    model's `masked_until` share of the budget."""
    views = scene.split("train")
    if not masked_training(scene, model_config):
        return PixelBank(views, device), TrainingBackground(scene.background)
    over = BACKGROUNDS.get(scene.background)  # None: "alpha" scenes keep straight colour
    finish = scene.background if over is not None else None
    until = getattr(model_config, "masked_until", None)
    background = TrainingBackground("alpha", finish, 1.0 if until is None else until)
    return PixelBank(views, device, use_alpha=True, over=over), background


def carve_to_scene(model: RadianceModel, scene: Scene) -> None:
    """Confine a model that can be carved (and is asked to) to the visual hull of the scene's
    training masks (at its `carve_cells`) when it trains on the object alone (masked_training);
    scenes without masks stay whole, and so does a model whose masks leave nothing (better
    floaters than no object at all)."""
    if not getattr(model.config, "carve", False) or not masked_training(scene, model.config):
        return
    views = [v for v in scene.split("train") if v.alpha is not None]
    if not views:
        return
    aabb = np.asarray(model.bounds.aabb, dtype=np.float64)
    mask = carve_mask([v.camera for v in views], [v.alpha for v in views], aabb, model.carve_cells)
    if mask.any():
        model.carve(torch.from_numpy(mask))


def virtual_sampler(losses: Sequence[LossTerm], cameras: list[Camera], bounds: Bounds, device,
                    seed: int, virtual_cameras: Sequence[Camera] | None = None) -> CameraRays | None:
    """Rays from `virtual_cameras` (default: random ones around the training `cameras`, looking at
    the centre of `bounds`) when a loss term is `virtual`, else None."""
    if not any(term.virtual for term in losses):
        return None
    if virtual_cameras:
        return CameraRays(list(virtual_cameras), device, seed=seed)
    return virtual_rays(cameras, np.mean(np.asarray(bounds.aabb, dtype=np.float64), axis=0), device, seed)


def _backgrounds(kind: str, rays: int, device: torch.device) -> torch.Tensor:
    """(rays, 3) background colours: the scene's own, or uniform random ones for "alpha"."""
    if kind == "alpha":
        return torch.rand(rays, 3, device=device)
    return torch.tensor(BACKGROUNDS[kind], device=device).expand(rays, 3)


def train_step(run: TrainingRun, bank: PixelBank, background: TrainingBackground) -> dict:
    """One optimisation step on a fresh random batch of `run.config.batch_rays` rays (None: the
    model's own `batch_rays`) over `background` at this point of the budget; advances
    `run.progress` and returns the step's log record."""
    model, optimizer, config, progress = run.model, run.optimizer, run.config, run.progress
    rays = config.batch_rays or model.batch_rays
    info = StepInfo(model, optimizer, progress.step, progress.fraction(config), rays)
    start = time.perf_counter()
    for hook in run.schedule:
        hook.before_step(info)
    batch = bank.sample(rays)
    bg = _backgrounds(background.at(info.fraction), rays, bank.device)
    optimizer.zero_grad(set_to_none=True)
    loss, error, samples = _backward_in_chunks(run, batch.origins, batch.directions, bg, batch.target(bg))
    optimizer.step()
    for hook in run.schedule:
        hook.after_step(info)
    error = float(error)  # syncs, so the timing is true
    seconds = time.perf_counter() - start
    progress.step += 1
    progress.elapsed += seconds
    return {"step": progress.step, "loss": float(loss), "psnr": psnr_of_mse(error), "seconds": seconds,
            "lr": optimizer.param_groups[0]["lr"], "rays_per_s": rays / seconds,
            "samples_per_s": samples / seconds, "elapsed": progress.elapsed}


def _backward_in_chunks(run: TrainingRun, origins: torch.Tensor, directions: torch.Tensor,
                        bg: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, int]:
    """Render the batch `origins`, `directions`, `bg`, `target` (R, 3) and back-propagate its loss,
    in chunks of rays within `run.config.memory_budget` (autograd keeps every activation of a
    chunk until its backward pass). Each chunk's loss is weighted by its share of the rays, so the
    summed gradients are those of the whole batch's mean losses. Returns the loss and the colour's
    mean squared error (scalar tensors) and the number of samples."""
    rays = origins.shape[0]
    loss_sum = torch.zeros((), device=origins.device)
    squared = torch.zeros((), device=origins.device)
    samples = 0
    for span in spans(rays, run.model.bytes_per_ray(training=True), run.config.memory_budget):
        out = run.model.render_rays(origins[span], directions[span], bg[span])
        share = (span.stop - span.start) / rays
        loss = share * total_loss(run.losses, LossInput(run.model, out, target[span], bg[span], run.virtual))
        loss.backward()
        loss_sum += loss.detach()
        squared += torch.sum((out.rgb.detach() - target[span]) ** 2)
        samples += int(out.num_samples)
    return loss_sum, squared / target.numel(), samples


def _train(run: TrainingRun, bank: PixelBank, background: TrainingBackground,
           show_progress: bool) -> None:
    """Step until the budget is spent or the callbacks ask to stop (`FitCancelled`), logging to
    log.jsonl, reporting each step and checkpointing now and then."""
    config, progress = run.config, run.progress
    run.model.train()
    total = config.iters if config.iters and not config.seconds else None
    bar = progress_bar(total=total, desc="fit", unit="step", initial=progress.step, show=show_progress)
    tuner = ThreadTuner(bank.device)
    with open(run.out_dir / LOG, "a") as log, bar, contextlib.closing(tuner):
        while progress.fraction(config) < 1.0:
            tuner.before_step()
            stats = train_step(run, bank, background)
            tuner.after_step(stats["seconds"])
            stats["threads"] = torch.get_num_threads()
            bar.update(1)
            bar.set_postfix(loss=f"{stats['loss']:.4f}", psnr=f"{stats['psnr']:.2f}",
                            rays_s=f"{stats['rays_per_s']:.0f}", refresh=False)
            if progress.step % config.log_every == 0 or progress.step == 1:
                log.write(json.dumps({k: (v if math.isfinite(v) else None) for k, v in stats.items()}) + "\n")
                log.flush()
            if progress.step % config.checkpoint_every == 0:
                run.checkpoint()
            run.callbacks.stepped(progress.fraction(config), stats)
            if run.callbacks.stop_requested():
                raise FitCancelled(progress.step, run.out_dir)
