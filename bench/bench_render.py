"""Turntable rendering speed: frames per second at 256x256 for every model that exists; JSON out.

Each model is trained briefly on the built-in object (a trained model matters: the fast model
skips empty space it has learnt), or loaded from `--run` folders, then renders an orbit into an
H.264 MP4 exactly as `windowshop render` does; the time covers rendering and encoding.
Usage: python bench/bench_render.py [--size 256] [--frames 3] [--train-iters 300]
       [--train-seconds 60] [--run RUN ...]
       [--model nerf:tiny --model fast] [--device cpu]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import torch

from provenance import commit
from windowshop.config import FitConfig, VideoOptions
from windowshop.device import pick_device
from windowshop.fit.checkpoint import load_run
from windowshop.fit.trainer import fit
from windowshop.model import MODELS, model_class, model_config
from windowshop.render.frames import display_background, render_camera
from windowshop.scene.synthetic import synthetic_scene
from windowshop.video.encode import VideoOutputs
from windowshop.video.paths import turntable_path
from windowshop.video.turntable import render_turntable

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MODELS = {"nerf": "tiny", "fast": None}  # model -> preset (None: the model's default)


def available(name: str) -> bool:
    """Whether model `name` is registered and its module imports."""
    try:
        model_class(name)
    except (ImportError, AttributeError, ValueError):
        return False
    return True


def train_briefly(name: str, preset: str | None, budget: FitConfig, out: Path, device) -> dict:
    """Fit `name` on the built-in object within `budget`; returns fit's metrics."""
    scene = synthetic_scene(n_train=40, n_test=1, size=64)  # one held-out view: a sanity PSNR
    return fit(scene, name, model_config(name, preset), budget, out, device, show_progress=False)


def time_run(run_dir: Path, size: int, frames: int, device) -> dict:
    """Render `frames` orbit frames of `size` px from a run folder into an MP4; speed figures."""
    run = load_run(run_dir, device)
    cameras = turntable_path(run.train_cameras, VideoOptions(frames=frames, width=size, height=size),
                             run.model.bounds)
    background = display_background(run.background)
    render_camera(run.model, cameras[0].resized(32, 32), background)  # warm up kernels and caches
    if torch.cuda.is_available() and str(device).startswith("cuda"):
        torch.cuda.synchronize()
    with tempfile.TemporaryDirectory() as tmp:
        result = render_turntable(run.model, cameras, VideoOutputs(mp4=Path(tmp) / "spin.mp4"),
                                  fps=30.0, background=background, progress=False)
    return {"model": run.model_name, "step": run.step, "frames": frames,
            "seconds_per_frame": round(result.render_seconds / frames, 4),
            "frames_per_second": round(result.frames_per_second, 3),
            "rays_per_second": round(result.frames_per_second * size * size)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256, help="pixels a side")
    parser.add_argument("--frames", type=int, default=3, help="timed frames per model")
    parser.add_argument("--train-iters", type=int, default=300, help="training steps of each model")
    parser.add_argument("--train-seconds", type=float, default=60.0,
                        help="... or training seconds, whichever ends first")
    parser.add_argument("--model", action="append", default=None, metavar="NAME[:PRESET]",
                        help="models to train and time (default: nerf:tiny and fast, if present)")
    parser.add_argument("--run", action="append", default=[], help="time these run folders too")
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    device = pick_device(args.device)
    wanted = ([tuple((m.split(":") + [None])[:2]) for m in args.model] if args.model is not None
              else [(n, p) for n, p in DEFAULT_MODELS.items() if n in MODELS and available(n)])
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, preset in wanted:
            start = time.perf_counter()
            budget = FitConfig(iters=args.train_iters, seconds=args.train_seconds)
            metrics = train_briefly(name, preset, budget, Path(tmp) / name, device)
            entry = time_run(Path(tmp) / name, args.size, args.frames, device)
            results.append({**entry, "preset": preset, "source": "built-in object",
                            "train_iters": metrics["iterations"],
                            "train_seconds": round(metrics["train_seconds"], 1),
                            "held_out_psnr": round(metrics["psnr"], 2),
                            "wall_seconds": round(time.perf_counter() - start, 1)})
    for run_dir in args.run:
        results.append({**time_run(Path(run_dir), args.size, args.frames, device), "source": run_dir})
    print(json.dumps({
        "bench": "render", "size": args.size, "results": results,
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
                    "device": str(device),
                    "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None},
        "commit": commit(),
    }, indent=2))


if __name__ == "__main__":
    main()
