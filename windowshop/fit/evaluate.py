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
from windowshop.metrics import aligned_psnr, psnr, ssim
from windowshop.model import RadianceModel
from windowshop.render.frames import display_background, render_camera
from windowshop.scene.types import Scene, View

EVAL_DIR = "eval"


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
                   memory_budget: int = MEMORY_BUDGET, image_dir: Path | None = None) -> dict:
    """Render `views`, measure them, and write one comparison PNG per view into `image_dir`.

    Returns {"psnr", "ssim", "psnr_aligned" (means over views; None without views; the last
    after the shift that best aligns each render with its photo, windowshop.metrics.aligned_psnr),
    "test_views", "per_view", "eval_seconds"}.
    """
    if image_dir is not None:
        image_dir.mkdir(parents=True, exist_ok=True)
    start, per_view = time.perf_counter(), []
    for index, view in enumerate(views):
        truth = target_image(view, background)
        frame = render_camera(model, view.camera, display_background(background), memory_budget)
        per_view.append({"name": view.name, "psnr": psnr(frame.rgb, truth), "ssim": ssim(frame.rgb, truth),
                         "psnr_aligned": aligned_psnr(frame.rgb, truth)})
        if image_dir is not None:
            Image.fromarray(comparison_image(truth, frame.rgb)).save(image_dir / image_name(index, view))

    def mean(key: str) -> float | None:
        return float(np.mean([v[key] for v in per_view])) if per_view else None

    return {"psnr": mean("psnr"), "ssim": mean("ssim"), "psnr_aligned": mean("psnr_aligned"),
            "test_views": len(views),
            "per_view": per_view, "eval_seconds": time.perf_counter() - start}


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
