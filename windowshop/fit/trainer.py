"""The training loop every model shares, using only the `RadianceModel` contract.

Each step draws `batch_rays` random rays across all training views, renders them over the scene's
background (a random colour per ray for "alpha" scenes, the target composited over the same
colour), steps the model's optimizer with its learning-rate factor at the current progress, and
logs loss, PSNR and throughput. Progress is the larger of steps/iters and seconds/budget, so with
`seconds` the schedule follows elapsed training time.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from windowshop.config import FitConfig
from windowshop.device import ThreadTuner
from windowshop.errors import UserError
from windowshop.fit.batches import PixelBank
from windowshop.fit.checkpoint import LOG, load_checkpoint, save_checkpoint, scene_record, write_config
from windowshop.fit.evaluate import EVAL_DIR, evaluate_views, held_out_views, write_metrics
from windowshop.metrics import psnr_of_mse
from windowshop.model import Bounds, RadianceModel, model_class
from windowshop.scene.types import BACKGROUNDS, Scene


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
    """A training session: the model, its optimizer and budget, and where checkpoints go."""

    model: RadianceModel
    optimizer: torch.optim.Optimizer
    config: FitConfig
    record: dict  # scene_record of the training scene
    out_dir: Path
    progress: Progress

    def checkpoint(self) -> None:
        save_checkpoint(self.out_dir, self.model, self.optimizer, self.record, self.config,
                        self.progress.step, self.progress.elapsed)


def fit(scene: Scene, model_name: str, model_config: Any, fit_config: FitConfig,
        out_dir: str | Path, device: torch.device | str,
        resume: str | Path | None = None,
        show_progress: bool = True) -> dict:
    """Train `model_name` with `model_config` on `scene` into the run folder `out_dir`.

    With `resume` (a run folder) the model, optimizer, step and elapsed time come from its
    checkpoint and training carries on to the budget of `fit_config`. Returns the held-out metrics
    (also written to `out_dir/metrics.json`).
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
    progress = _restore(model, optimizer, resume) if resume else Progress()
    torch.manual_seed(fit_config.seed + progress.step)  # a resumed run draws fresh batches
    record = scene_record(scene)
    run = TrainingRun(model, optimizer, fit_config, record, out_dir, progress)
    write_config(out_dir, model_name, model_config, fit_config, run.record)
    bank = PixelBank(train_views, device, use_alpha=scene.background == "alpha")
    try:
        _train(run, bank, scene.background, show_progress)
    except KeyboardInterrupt:
        run.checkpoint()
        raise UserError(f"interrupted at step {progress.step}; carry on with --resume {out_dir}")
    run.checkpoint()
    results = evaluate_views(model, held_out_views(scene), scene.background,
                             fit_config.eval_chunk, out_dir / EVAL_DIR)
    metrics = {**results, "model": model_name, "train_seconds": progress.elapsed,
               "iterations": progress.step}
    write_metrics(out_dir, metrics)
    return metrics


def _restore(model: RadianceModel, optimizer: torch.optim.Optimizer, run_dir: str | Path) -> Progress:
    """Load a run folder's weights and optimizer state; return where it stopped."""
    state = load_checkpoint(run_dir)
    if state["model_name"] != model.name:
        raise UserError(f"{run_dir} holds a {state['model_name']!r} model, not {model.name!r}")
    model.load_state_dict(state["model_state"])
    optimizer.load_state_dict(state["optimizer_state"])
    return Progress(step=int(state["step"]), elapsed=float(state["elapsed_seconds"]))


def _backgrounds(kind: str, rays: int, device: torch.device) -> torch.Tensor:
    """(rays, 3) background colours: the scene's own, or uniform random ones for "alpha"."""
    if kind == "alpha":
        return torch.rand(rays, 3, device=device)
    return torch.tensor(BACKGROUNDS[kind], device=device).expand(rays, 3)


def train_step(run: TrainingRun, bank: PixelBank, background: str) -> dict:
    """One optimisation step on a fresh random batch of `run.config.batch_rays` rays (None: the
    model's own `batch_rays`) over the scene's `background` kind; advances `run.progress` and
    returns the step's log record."""
    model, optimizer, config, progress = run.model, run.optimizer, run.config, run.progress
    fraction = progress.fraction(config)
    start = time.perf_counter()
    for group in optimizer.param_groups:
        group["lr"] = group["initial_lr"] * model.lr_factor(fraction)
    model.before_step(progress.step, fraction)
    rays = config.batch_rays or model.batch_rays
    batch = bank.sample(rays)
    bg = _backgrounds(background, rays, bank.device)
    target = batch.target(bg)
    out = model.render_rays(batch.origins, batch.directions, bg)
    loss = model.loss(out, target)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    error = float(torch.mean((out.rgb.detach() - target) ** 2))  # syncs, so the timing is true
    seconds = time.perf_counter() - start
    progress.step += 1
    progress.elapsed += seconds
    return {"step": progress.step, "loss": float(loss.detach()), "psnr": psnr_of_mse(error), "seconds": seconds,
            "lr": optimizer.param_groups[0]["lr"], "rays_per_s": rays / seconds,
            "samples_per_s": out.num_samples / seconds, "elapsed": progress.elapsed}


def _train(run: TrainingRun, bank: PixelBank, background: str, show_progress: bool) -> None:
    """Step until the budget is spent, logging to log.jsonl and checkpointing now and then."""
    config, progress = run.config, run.progress
    run.model.train()
    total = config.iters if config.iters and not config.seconds else None
    bar = tqdm(total=total, initial=progress.step, disable=not show_progress, unit="step",
               dynamic_ncols=True)
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
