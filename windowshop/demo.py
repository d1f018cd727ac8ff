"""`windowshop demo`: the whole pipeline on the built-in object, in a few minutes on a CPU.

Render the synthetic object's training views, fit a model, render its turntable to
`DIR/turntable.mp4` with a poster, and, since the object's true image is known for any camera,
measure the turntable itself against the exact frames of the same orbit (`DIR/demo.json`).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from windowshop.config import DemoConfig, SceneOptions
from windowshop.scene.types import Camera

def turntable_psnr(video: Path, cameras: list[Camera], background: tuple[float, float, float]) -> float:
    """Mean PSNR (dB) of the decoded frames of `video` against the exact images of `cameras`."""
    from windowshop.metrics import psnr
    from windowshop.scene.synthetic import render_truth
    from windowshop.video.encode import read_video

    _, frames = read_video(video)
    scores = [psnr(frame.astype(np.float32) / 255.0, render_truth(camera, background)[0])
              for frame, camera in zip(frames, cameras, strict=True)]
    return float(np.mean(scores))


def run_demo(out_dir: str | Path, config: DemoConfig, device: torch.device | str) -> dict:
    """Fit the built-in object into `out_dir/run` and render `out_dir/turntable.mp4` (+ poster).

    Returns (and writes to `out_dir/demo.json`) the held-out metrics, the turntable's PSNR
    against the true frames, timings and the files written.
    """
    from windowshop.fit.trainer import fit
    from windowshop.model import Bounds, model_config
    from windowshop.render.frames import display_background
    from windowshop.scene import load_scene
    from windowshop.scene.synthetic import synthetic_scene
    from windowshop.scene.writer import write_transforms
    from windowshop.video.encode import check_video_size
    from windowshop.video.paths import turntable_path
    from windowshop.video.turntable import default_outputs, render_run

    check_video_size(config.render.width, config.render.height)  # before minutes of training
    options = config.demo
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    # Written to disk first, so the run records a scene that `windowshop eval` can load again.
    synthetic = synthetic_scene(n_train=options.views, n_test=options.test_views,
                                size=options.image_size)
    scene_options = SceneOptions(background=synthetic.background)
    scene = load_scene(write_transforms(synthetic, out_dir / "scene"), scene_options)
    model = model_config(config.model, config.preset, **config.model_settings)
    metrics = fit(scene, config.model, model, config.fit, out_dir / "run", device)
    video = config.render
    outputs = default_outputs(out_dir / "turntable.mp4", poster=True)
    result = render_run(out_dir / "run", video, outputs, device)
    cameras = turntable_path([v.camera for v in scene.split("train")], video,
                             Bounds.of_scene(scene))  # as render_run's
    summary = {
        "model": config.model, "preset": config.preset, "config": asdict(config),
        "device": str(device),
        "held_out_psnr": metrics.get("psnr"), "held_out_ssim": metrics.get("ssim"),
        "turntable_psnr": turntable_psnr(outputs.mp4, cameras, display_background(scene.background)),
        "train_seconds": metrics.get("train_seconds"), "iterations": metrics.get("iterations"),
        "render_frames_per_second": result.frames_per_second,
        "total_seconds": time.perf_counter() - start,
        "files": [str(p) for p in result.files],
    }
    (out_dir / "demo.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def demo_command(out_dir: str | Path, config: DemoConfig, device: torch.device | str) -> dict:
    """`windowshop demo`: run it and say what came out."""
    summary = run_demo(out_dir, config, device)
    print(f"{summary['model']}: {summary['iterations']} steps in {summary['train_seconds']:.0f} s; "
          f"held-out PSNR {summary['held_out_psnr']:.2f} dB, turntable PSNR against the true "
          f"frames {summary['turntable_psnr']:.2f} dB; {summary['total_seconds']:.0f} s in all")
    for path in summary["files"]:
        print(f"wrote {path}")
    return summary
