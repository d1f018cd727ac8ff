"""Held-out evaluation of a trained model: PSNR and SSIM per view, comparison images, metrics.json.

Scenes trained on random backgrounds ("alpha") are judged over white: the target is the view's
colour composited over white and the render uses a white background.
"""

from __future__ import annotations

import json
import math
import re
import time
from pathlib import Path

import numpy as np
from PIL import Image

from windowshop.fit.checkpoint import METRICS, load_run
from windowshop.memory import MEMORY_BUDGET
from windowshop.fit.pose_refine import refine_camera
from windowshop.metrics import psnr, ssim
from windowshop.model import RadianceModel
from windowshop.render.frames import display_background, render_camera
from windowshop.scene.selection import evenly_spaced
from windowshop.scene.types import Scene, View

EVAL_DIR = "eval"
# held-out cameras refined at most: 0.7-0.9 s each on a 320x240 photo (2 cores), where 100
# photos hold out 13 and rendering all 13 takes about 1 s
REFINED_VIEWS = 3


def held_out_views(scene: Scene) -> list[View]:
    """The scene's test views, or its validation views when it has no test split."""
    return scene.split("test") or scene.split("val")


def target_image(view: View, background: str) -> np.ndarray:
    """What a perfect render of `view` looks like (H, W, 3) for a scene with `background`."""
    if background != "alpha" or view.alpha is None:
        return view.image
    bg = np.asarray(display_background(background), dtype=np.float32)
    return view.image * view.alpha[..., None] + bg * (1.0 - view.alpha[..., None])


def comparison_image(truth: np.ndarray, render: np.ndarray) -> np.ndarray:
    """Ground truth | render | absolute error (grey, x4 so small errors show), as (H, 3W, 3) uint8."""
    error = np.clip(4.0 * np.abs(truth - render).mean(axis=-1, keepdims=True), 0, 1)
    panel = np.concatenate([truth, render, np.repeat(error, 3, axis=-1)], axis=1)
    return (np.clip(panel, 0, 1) * 255 + 0.5).astype(np.uint8)


def image_name(index: int, view: View) -> str:
    """`007_r_12.png` for the 8th view, from image `.../r_12.png` (or `lego_tiny.npz#12`)."""
    name = re.sub(r"\.(png|jpe?g|webp|exr|tiff?)$", "", Path(view.name).name, flags=re.IGNORECASE)
    return f"{index:03d}_{re.sub(r'[^A-Za-z0-9_-]+', '_', name)}.png"


def evaluate_views(model: RadianceModel, views: list[View], background: str,
                   memory_budget: int = MEMORY_BUDGET, image_dir: Path | None = None,
                   refine: bool = False) -> dict:
    """Render `views`, measure them, and write one comparison PNG per view into `image_dir`.

    Returns {"psnr", "ssim" (means over views; None without views), "test_views", "per_view",
    "eval_seconds"}, and with `refine` also "psnr_refined": the mean PSNR of at most
    REFINED_VIEWS views spread over `views`, each camera first refined against the model
    (windowshop.fit.pose_refine; a refinement that does not help at full size is not taken), for
    cameras that come from structure-from-motion.
    """
    if image_dir is not None:
        image_dir.mkdir(parents=True, exist_ok=True)
    start, per_view = time.perf_counter(), []
    colour = display_background(background)
    refined = set(evenly_spaced(len(views), min(len(views), REFINED_VIEWS)).tolist()) if refine else set()
    for index, view in enumerate(views):
        truth = target_image(view, background)
        frame = render_camera(model, view.camera, colour, memory_budget)
        scores = {"name": view.name, "psnr": psnr(frame.rgb, truth), "ssim": ssim(frame.rgb, truth)}
        if index in refined:
            scores |= _refined(model, view, truth, colour, memory_budget, scores["psnr"])
        per_view.append(scores)
        if image_dir is not None:
            Image.fromarray(comparison_image(truth, frame.rgb)).save(image_dir / image_name(index, view))

    def mean(key: str) -> float | None:
        values = [v[key] for v in per_view if key in v]
        return float(np.mean(values)) if values else None

    results = {"psnr": mean("psnr"), "ssim": mean("ssim"), "test_views": len(views),
               "per_view": per_view, "eval_seconds": time.perf_counter() - start}
    return results | ({"psnr_refined": mean("psnr_refined")} if refine else {})


def _refined(model: RadianceModel, view: View, truth: np.ndarray, colour: tuple[float, float, float],
             memory_budget: int, before: float) -> dict:
    """A view's PSNR at its refined camera (never below `before`), and how far the camera moved."""
    refined = refine_camera(model, view.camera, truth, colour, memory_budget)
    after = psnr(render_camera(model, refined.camera, colour, memory_budget).rgb, truth)
    if after <= before:
        return {"psnr_refined": before, "pose_turn_deg": 0.0, "pose_shift": 0.0}
    return {"psnr_refined": after, "pose_turn_deg": refined.turn_deg, "pose_shift": refined.shift}


def mean_color_psnr(train: list[View], test: list[View], background: str) -> float:
    """PSNR on `test` of predicting every pixel as the mean training colour (the floor to beat)."""
    mean = np.mean([target_image(v, background).reshape(-1, 3).mean(axis=0) for v in train], axis=0)
    return float(np.mean([psnr(np.broadcast_to(mean, v.image.shape), target_image(v, background))
                          for v in test]))


def write_metrics(run_dir: Path, metrics: dict) -> Path:
    """metrics.json, with non-finite numbers (a perfect PSNR) written as null."""
    def clean(value):
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, list):
            return [clean(v) for v in value]
        return None if isinstance(value, float) and not math.isfinite(value) else value

    path = Path(run_dir) / METRICS
    path.write_text(json.dumps(clean(metrics), indent=2, allow_nan=False) + "\n")
    return path


def evaluate_run(run_dir: str | Path, device, scene: Scene | None = None) -> dict:
    """Recompute metrics.json and eval/*.png of a run folder on its held-out views.

    `scene` defaults to the run's own source, loaded again with its recorded options.
    """
    from windowshop.scene import load_scene

    run_dir = Path(run_dir)
    run = load_run(run_dir, device)
    if scene is None:
        scene = load_scene(run.scene_source, run.scene_options)
    results = evaluate_views(run.model, held_out_views(scene), run.background,
                             run.fit_config.memory_budget, run_dir / EVAL_DIR)
    metrics = {**results, "model": run.model_name, "train_seconds": run.elapsed_seconds,
               "iterations": run.step}
    write_metrics(run_dir, metrics)
    return metrics
