"""`windowshop fit` and `windowshop eval` behind the CLI: settings in, run folder out."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch

from windowshop.config import FitConfig, SceneOptions
from windowshop.errors import UserError
from windowshop.fit.checkpoint import dataclass_from_dict, load_checkpoint
from windowshop.fit.evaluate import evaluate_run
from windowshop.fit.trainer import fit
from windowshop.model import model_class, model_config


def build_model_config(model_name: str, preset: str | None, overrides: dict[str, Any]) -> Any:
    """The chosen preset of `model_name` with `overrides`; a setting it lacks is a UserError."""
    cls = model_class(model_name)
    names = {f.name for f in dataclasses.fields(cls.config_type)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise UserError(f"model {model_name!r} has no setting {', '.join(unknown)}; its settings: "
                        f"{', '.join(sorted(names))}")
    try:
        return model_config(model_name, preset, **overrides)
    except ValueError as err:
        raise UserError(str(err)) from None


def fit_command(scene_path: str | None, options: SceneOptions, model_name: str, preset: str | None,
                model_overrides: dict[str, Any], fit_overrides: dict[str, Any], out: str | None,
                resume: str | None, device: torch.device) -> dict:
    """Train a new run (or carry on `resume`) and return its held-out metrics."""
    from windowshop.scene import load_scene

    fit_overrides = {k: v for k, v in fit_overrides.items() if v is not None}
    if "seconds" in fit_overrides and "iters" not in fit_overrides:
        fit_overrides["iters"] = None  # --seconds alone replaces the default step budget
    if resume:
        if model_overrides or preset:
            raise UserError("a resumed run keeps its model settings; drop --preset and model flags")
        state = load_checkpoint(resume)
        model_name = state["model_name"]
        config = dataclass_from_dict(model_class(model_name).config_type, state["model_config"])
        fit_config = dataclasses.replace(dataclass_from_dict(FitConfig, state["fit_config"]), **fit_overrides)
        options = dataclass_from_dict(SceneOptions, state["scene"]["options"])
        scene_path = scene_path or state["scene"]["source"]
        out = out or resume
    else:
        if not scene_path or not out:
            raise UserError("give a scene and --out RUN (or --resume RUN to carry on a run)")
        config = build_model_config(model_name, preset, model_overrides)
        fit_config = dataclasses.replace(FitConfig(), **fit_overrides)
    scene = load_scene(scene_path, options)
    return fit(scene, model_name, config, fit_config, Path(out), device, scene_options=options,
               resume=resume)


def eval_command(run_dir: str, device: torch.device) -> dict:
    """Recompute a run's metrics.json and eval/ images."""
    return evaluate_run(run_dir, device)


def summary(metrics: dict) -> str:
    """One line for the terminal."""
    def fmt(value, spec):
        return "n/a" if value is None else format(value, spec)
    return (f"{metrics['model']}: PSNR {fmt(metrics['psnr'], '.2f')} dB, SSIM {fmt(metrics['ssim'], '.3f')} "
            f"on {metrics['test_views']} held-out views after {metrics['iterations']} steps "
            f"({metrics['train_seconds']:.0f} s)")
