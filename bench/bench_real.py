"""`windowshop video` on every shared real capture, with the product's defaults, as JSON.

    python bench/bench_real.py [--rows beer_can fruit dtu_skull kermit] [--photos 20] [--out FILE]
                               [--set fit.seconds=30 ...]

Per capture: seconds per stage and in all, photos placed, the mask kind, the held-out PSNR (every
8th photo, over white) and the same PSNR within the photo's object mask, and how clean the
turntable's background is: the share of pixels outside the object's visual hull (carved from the
training masks, projected into each turntable camera and grown by a few pixels) that the model
renders with opacity above 0.1 (floaters, a slab of table, haze). 0 is clean.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage

from provenance import emit, machine
from windowshop.config import PipelineConfig, VideoOptions
from windowshop.device import pick_device
from windowshop.fit.checkpoint import load_run
from windowshop.fit.evaluate import held_out_views, target_image
from windowshop.metrics import psnr
from windowshop.model import apply_run_overrides
from windowshop.overrides import parse_assignments
from windowshop.pipeline import make_video
from windowshop.rays import project
from windowshop.render.frames import render_camera
from windowshop.scene import load_scene
from windowshop.scene.hull import hull_points
from windowshop.scene.types import Camera, Scene
from windowshop.video.turntable import run_plan

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
OPAQUE = 0.1  # opacity that counts as something drawn
GROW_PX = 3  # the hull's silhouette is grown by this many pixels (its voxels are coarse)
CHECK_SIDE = 96  # turntable frames are checked at this size


def spread(files: list[Path], count: int) -> list[Path]:
    picks = np.linspace(0, len(files) - 1, min(count, len(files))).round().astype(int)
    return [files[i] for i in sorted(set(picks.tolist()))]


def captures(count: int) -> dict[str, list[Path]]:
    """Photos of each shared real capture (no poses, no masks given to the pipeline)."""
    beer = sorted((DATA / "beer_can" / "images").glob("*.jpg"))
    return {"beer_can": spread(beer, count),
            "fruit": spread(sorted((DATA / "fruit" / "newfruit_small").glob("*.jpg")), count),
            "dtu_skull": spread(sorted((DATA / "dtu_skull" / "images").glob("*.jpg")), count),
            "kermit": sorted((DATA / "kermit").glob("*.jpg"))}


def masked_psnr(run, scene: Scene) -> float | None:
    """Mean PSNR of the held-out photos within their object masks (None without masks)."""
    scores = []
    for view in held_out_views(scene):
        if view.alpha is None:
            return None
        inside = view.alpha > 0.5
        frame = render_camera(run.model, view.camera, (1.0, 1.0, 1.0))
        scores.append(psnr(frame.rgb[inside], target_image(view, scene.background)[inside]))
    return float(np.mean(scores)) if scores else None


def silhouette(points: np.ndarray, camera: Camera, grow: int) -> np.ndarray:
    """(H, W) bool: pixels the points (M, 3) project onto, grown by `grow` pixels."""
    uv, depth = project(points, camera)
    u, v = np.round(uv[depth > 0]).astype(int).T
    hit = np.zeros((camera.height + 2 * grow, camera.width + 2 * grow), bool)
    ok = (u >= -grow) & (v >= -grow) & (u < camera.width + grow) & (v < camera.height + grow)
    hit[v[ok] + grow, u[ok] + grow] = True  # points just off the image still reach into it
    brush = np.ones((2 * grow + 1, 2 * grow + 1), bool)  # every pixel within `grow` of a point
    return ndimage.binary_dilation(hit, brush)[grow:-grow, grow:-grow]


def unclean_share(run, scene: Scene, options: VideoOptions) -> float | None:
    """Share of the turntable's background (outside the grown visual hull) drawn opaque."""
    turntable = run_plan(run, options).cameras
    train = [v for v in scene.split("train") if v.alpha is not None]
    if not train:
        return None
    lo, hi = np.asarray(scene.aabb, dtype=float)
    points = hull_points([v.camera for v in train], [v.alpha for v in train], (lo + hi) / 2,
                         float(np.max(hi - lo)) / 2 * 1.1)
    if points is None:
        return None
    dirty, background = 0, 0
    for camera in turntable:
        scale = CHECK_SIDE / max(camera.width, camera.height)
        small = camera.resized(round(camera.width * scale), round(camera.height * scale))
        outside = ~silhouette(points, small, GROW_PX)
        opacity = render_camera(run.model, small).opacity
        dirty += int(np.sum((opacity > OPAQUE) & outside))
        background += int(np.sum(outside))
    return dirty / max(background, 1)


def run_row(name: str, photos: list[Path], tmp: Path, device: torch.device,
            config: PipelineConfig) -> dict:
    folder = tmp / name / "photos"
    folder.mkdir(parents=True)
    for path in photos:
        (folder / path.name).symlink_to(path)
    start = time.perf_counter()
    result = make_video(folder, tmp / name / "spin.mp4", config, device=device, show=False)
    total = time.perf_counter() - start
    report = json.loads((result.scene_dir / "report.json").read_text())
    run = load_run(result.run_dir, device)
    scene = load_scene(run.scene_source, run.scene_options)
    return {"photos": len(photos), "placed": report.get("placed"), "masks": report.get("masks"),
            "seconds": {k: round(v, 2) for k, v in result.seconds.items()},
            "total_seconds": round(total, 2),
            "steps": result.metrics.get("iterations"), "voxels": getattr(run.model, "voxels", None),
            "held_out_psnr": result.metrics.get("psnr"),
            "held_out_psnr_in_mask": masked_psnr(run, scene),
            "background_unclean": unclean_share(run, scene, config.render),
            "covered_degrees": result.report["covered_degrees"], "advice": result.report["advice"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", nargs="+", default=["beer_can", "fruit", "dtu_skull", "kermit"])
    parser.add_argument("--photos", type=int, default=20, help="photos taken from each capture")
    parser.add_argument("--out", default=None, help="also write the JSON here")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a pipeline setting other than the default, e.g. fit.seconds=30")
    args = parser.parse_args()
    device = pick_device(None)
    config = apply_run_overrides(PipelineConfig(), parse_assignments(args.set), "--set")
    results = {**machine(), "settings": args.set, "device": str(device), "rows": {}}
    photos = captures(args.photos)
    with tempfile.TemporaryDirectory(prefix="windowshop-bench-real-") as tmp:
        for name in args.rows:
            try:
                results["rows"][name] = run_row(name, photos[name], Path(tmp), device, config)
            except Exception as err:  # noqa: BLE001 - a capture that fails is a result too
                results["rows"][name] = {"error": f"{type(err).__name__}: {err}"}
            print(json.dumps({name: results["rows"][name]}), flush=True)
    emit(results, args.out)


if __name__ == "__main__":
    main()
