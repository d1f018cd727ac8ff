"""Run folders and self-describing checkpoints.

A run folder holds `config.json` (what was asked for, readable), `checkpoint.pt` (everything
needed to rebuild the model and carry on training), `log.jsonl`, `metrics.json` and `eval/`.
The checkpoint stores only tensors, numbers, strings, lists and dicts, so it loads with
`torch.load(weights_only=True)`; the model is rebuilt from its registered name and its own config.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from windowshop.config import FitConfig, SceneOptions
from windowshop.errors import UserError
from windowshop.model import Bounds, RadianceModel, model_class
from windowshop.scene.types import Camera, Scene

CHECKPOINT = "checkpoint.pt"
CONFIG = "config.json"
LOG = "log.jsonl"
METRICS = "metrics.json"
FORMAT = "windowshop-run/1"


@dataclass
class LoadedRun:
    """A trained model and what it was trained on, as read back from a run folder."""

    model: RadianceModel  # in eval mode, on the requested device
    model_name: str
    train_cameras: list[Camera]  # in the normalised frame
    background: str  # the scene's: "white" | "black" | "alpha"
    bounds: Bounds
    scene_source: str  # path the scene was loaded from
    scene_format: str
    scene_options: SceneOptions
    transform: np.ndarray  # (4, 4) source frame -> normalised frame
    fit_config: FitConfig
    step: int
    elapsed_seconds: float
    optimizer_state: dict | None


def camera_to_dict(camera: Camera) -> dict:
    """Plain Python numbers only (readers may hand numpy scalars, which weights_only refuses)."""
    return {"fx": float(camera.fx), "fy": float(camera.fy), "cx": float(camera.cx),
            "cy": float(camera.cy), "width": int(camera.width), "height": int(camera.height),
            "c2w": np.asarray(camera.c2w, dtype=float).tolist()}


def camera_from_dict(data: dict) -> Camera:
    return Camera(fx=float(data["fx"]), fy=float(data["fy"]), cx=float(data["cx"]),
                  cy=float(data["cy"]), width=int(data["width"]), height=int(data["height"]),
                  c2w=np.asarray(data["c2w"], dtype=np.float64))


def scene_record(scene: Scene) -> dict:
    """What a run must remember of its scene to be evaluated, resumed or rendered again."""
    source = Path(scene.source)
    source = source.resolve() if source.exists() else source  # eval may run from elsewhere
    return {"source": str(source), "format": scene.format,
            "options": dataclasses.asdict(scene.options or SceneOptions()), "background": scene.background,
            "transform": np.asarray(scene.transform, dtype=float).tolist(),
            "aabb": np.asarray(scene.aabb, dtype=float).tolist(),
            "near": float(scene.near), "far": float(scene.far),
            "train_cameras": [camera_to_dict(v.camera) for v in scene.split("train")]}


def write_config(run_dir: Path, model_name: str, model_config: Any, fit_config: FitConfig,
                 scene: dict) -> None:
    """`config.json`: the run's settings for people (the checkpoint is what gets loaded)."""
    record = {"model": model_name, "model_config": dataclasses.asdict(model_config),
              "fit_config": dataclasses.asdict(fit_config),
              "scene": {k: v for k, v in scene.items() if k != "train_cameras"}}
    (run_dir / CONFIG).write_text(json.dumps(record, indent=2) + "\n")


def save_checkpoint(run_dir: Path, model: RadianceModel, optimizer: torch.optim.Optimizer | None,
                    scene: dict, fit_config: FitConfig, step: int, elapsed: float) -> Path:
    """Write `checkpoint.pt` atomically (a crash mid-write leaves the previous one intact);
    without `optimizer`, its state is stored as None."""
    state = {"format": FORMAT, "model_name": model.name,
             "model_config": dataclasses.asdict(model.config),
             "bounds": dataclasses.asdict(model.bounds), "scene": scene,
             "fit_config": dataclasses.asdict(fit_config),
             "model_state": model.state_dict(), "optimizer_state": None if optimizer is None else optimizer.state_dict(),
             "step": int(step), "elapsed_seconds": float(elapsed)}
    path = run_dir / CHECKPOINT
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    tmp.replace(path)
    return path


def _bounds(data: dict) -> Bounds:
    lo, hi = data["aabb"]
    return Bounds(aabb=(tuple(lo), tuple(hi)), near=float(data["near"]), far=float(data["far"]))


def dataclass_from_dict(cls: type, data: dict) -> Any:
    """Rebuild `cls` from `data`, ignoring keys a newer or older version does not know."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items() if k in names})


def load_checkpoint(run_dir: str | Path) -> dict:
    """The raw checkpoint dict of a run folder (on the CPU)."""
    path = Path(run_dir) / CHECKPOINT
    if not path.is_file():
        raise UserError(f"{path} not found: give a run folder written by `windowshop fit --out`")
    # mapped, not read: rendering never touches the optimizer's state (two thirds of the file)
    state = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    if state.get("format") != FORMAT:
        raise UserError(f"{path} is not a windowshop checkpoint ({FORMAT})")
    return state


def load_run(run_dir: str | Path, device: torch.device | str = "cpu") -> LoadedRun:
    """Rebuild the model of a run folder on `device` (eval mode) with its scene's description."""
    state = load_checkpoint(run_dir)
    cls = model_class(state["model_name"])
    bounds = _bounds(state["bounds"])
    model = cls(dataclass_from_dict(cls.config_type, state["model_config"]), bounds)
    model.load_state_dict(state["model_state"])
    model.to(device).eval()
    scene = state["scene"]
    return LoadedRun(
        model=model, model_name=state["model_name"],
        train_cameras=[camera_from_dict(c) for c in scene["train_cameras"]],
        background=scene["background"], bounds=bounds, scene_source=scene["source"],
        scene_format=scene["format"], scene_options=dataclass_from_dict(SceneOptions, scene["options"]),
        transform=np.asarray(scene["transform"], dtype=np.float64),
        fit_config=dataclass_from_dict(FitConfig, state["fit_config"]), step=int(state["step"]),
        elapsed_seconds=float(state["elapsed_seconds"]),
        optimizer_state=state["optimizer_state"])
