"""Benchmark of the paper's NeRF on this machine; prints one JSON object.

- seconds per training step of the `tiny` and `paper` presets at 1024 rays per batch;
- held-out PSNR/SSIM of `tiny` on lego_tiny.npz after a fixed training budget (seconds), next to
  the floor of predicting the mean training colour.

These are the baseline the fast model must beat.
Usage: python bench/bench_nerf.py [--budget 120] [--device cpu] [--steps 5]
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

from windowshop.config import NERF_PRESETS, FitConfig
from windowshop.device import pick_device
from windowshop.field.nerf import NerfModel
from windowshop.fit.batches import PixelBank
from windowshop.fit.evaluate import held_out_views, mean_color_psnr
from windowshop.fit.trainer import Progress, TrainingBackground, TrainingRun, fit, train_step
from windowshop.model import Bounds
from windowshop.scene import load_scene

LEGO_TINY = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "lego_tiny.npz"
RAYS = 1024


def seconds_per_step(scene, preset: str, steps: int, device: torch.device) -> float:
    """Median wall time of `steps` training steps (after one warm-up step) at RAYS rays."""
    torch.manual_seed(0)
    model = NerfModel(NERF_PRESETS[preset], Bounds.of_scene(scene)).to(device)
    optimizer = model.make_optimizer()
    for group in optimizer.param_groups:
        group["initial_lr"] = group["lr"]
    bank = PixelBank(scene.split("train"), device)
    run = TrainingRun(model, optimizer, FitConfig(iters=steps + 1, batch_rays=RAYS), {},
                      Path(tempfile.gettempdir()), Progress())
    model.train()
    times = []
    for _ in range(steps + 1):
        start = time.perf_counter()
        train_step(run, bank, TrainingBackground(scene.background))
        times.append(time.perf_counter() - start)
    times = sorted(times[1:])
    return times[len(times) // 2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=120.0, help="training seconds of tiny")
    parser.add_argument("--steps", type=int, default=5, help="timed steps per preset")
    parser.add_argument("--device", default=None)
    args = parser.parse_args()
    device = pick_device(args.device)
    scene = load_scene(LEGO_TINY)
    result = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                          "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
                          "device": str(device)},
              "rays_per_batch": RAYS,
              "seconds_per_iter": {p: seconds_per_step(scene, p, args.steps, device)
                                   for p in ("tiny", "paper")}}
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        metrics = fit(scene, "nerf", NERF_PRESETS["tiny"],
                      FitConfig(iters=None, seconds=args.budget, batch_rays=RAYS), out, device,
                      show_progress=False)
        wall = time.perf_counter() - start
    result["tiny_lego_tiny"] = {
        "budget_seconds": args.budget, "iterations": metrics["iterations"],
        "psnr": metrics["psnr"], "ssim": metrics["ssim"], "test_views": metrics["test_views"],
        "mean_color_psnr": mean_color_psnr(scene.split("train"), held_out_views(scene), scene.background),
        "eval_seconds": metrics["eval_seconds"], "wall_seconds": wall}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
