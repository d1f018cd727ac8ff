"""`windowshop fit` and `windowshop eval` behind the CLI: settings in, run folder out."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch

from windowshop.config import FitConfig, RunConfig, SceneOptions
from windowshop.errors import UserError
from windowshop.fit.checkpoint import dataclass_from_dict, load_checkpoint
from windowshop.fit.evaluate import evaluate_run
from windowshop.fit.trainer import fit
from windowshop.model import apply_run_overrides, model_class, model_config


def fit_command(scene_path: str | None, overrides: dict[str, Any], out: str | None,
                resume: str | None, device: torch.device) -> dict:
    """Train a new run configured by `overrides` of RunConfig (or carry on `resume`, where only
    the training budget may change) and return its held-out metrics."""
    from windowshop.scene import load_scene

    if resume:
        state = load_checkpoint(resume)
        if changed := sorted(k for k in overrides if not _is_fit_key(k)):
            raise UserError(f"a resumed run keeps its model and scene settings; drop {', '.join(changed)}")
        config = RunConfig(model=state["model_name"],
                           scene=dataclass_from_dict(SceneOptions, state["scene"]["options"]),
                           fit=dataclass_from_dict(FitConfig, state["fit_config"]))
        config = apply_run_overrides(config, overrides)
        model = dataclass_from_dict(model_class(config.model).config_type, state["model_config"])
        scene_path = scene_path or state["scene"]["source"]
        out = out or resume
    else:
        if not scene_path or not out:
            raise UserError("give a scene and --out RUN (or --resume RUN to carry on a run)")
        config = apply_run_overrides(RunConfig(), overrides)
        model = model_config(config.model, config.preset, **config.model_settings)
    scene = load_scene(scene_path, config.scene)
    return fit(scene, config.model, model, config.fit, Path(out), device, resume=resume)


def _is_fit_key(key: str) -> bool:
    name = key.replace("-", "_").removeprefix("fit.")
    return name in {f.name for f in dataclasses.fields(FitConfig)}


def eval_command(run_dir: str, device: torch.device) -> dict:
    """Recompute a run's metrics.json and eval/ images."""
    return evaluate_run(run_dir, device)


PASSES_NOTE = "; stopped early: more passes over so few pixels would only overfit them"


def summary(metrics: dict) -> str:
    """One line for the terminal."""
    def fmt(value, spec):
        return "n/a" if value is None else format(value, spec)
    return (f"{metrics['model']}: PSNR {fmt(metrics['psnr'], '.2f')} dB, SSIM {fmt(metrics['ssim'], '.3f')} "
            f"on {metrics['test_views']} held-out views after {metrics['iterations']} steps "
            f"({metrics['train_seconds']:.0f} s{PASSES_NOTE if metrics.get('stopped_by_passes') else ''})")
