"""3D model export (`windowshop export`): its speed, its size, and how faithfully the exported GLB
reproduces held-out photos; one JSON line per row.

speed:   lego_tiny.npz (100 views 100x100) trained --tiny-seconds, then `export --out model.glb`
         at the defaults, timed whole (in-process: load, mesh, texture, write); also the USDZ.
quality: lego 400x400 (--views held out) trained --lego-seconds, exported at the defaults; the
         GLB, read back with trimesh and put in the scene's frame through its side file, is drawn
         by windowshop.export.raster at each held-out camera: silhouette IoU against the true
         alpha, PSNR against the true image (over white), beside the field's own PSNR there;
         PSNR also anti-aliased (SUPERSAMPLE^2 samples a pixel, as a 3D viewer draws it and as
         the photos were rendered; the plain rasteriser samples pixel centres only).
Usage: python bench/bench_export.py [--rows speed quality] [--tiny-seconds 30]
       [--lego-seconds 60] [--views 8] [--tiny-run RUN] [--lego-run RUN]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

from provenance import machine
from windowshop.config import ExportOptions, FitConfig, SceneOptions
from windowshop.export.command import export_command, side_file
from windowshop.export.frame import apply
from windowshop.export.raster import render_mesh
from windowshop.fit.checkpoint import load_run
from windowshop.fit.trainer import fit
from windowshop.metrics import psnr
from windowshop.model import model_config
from windowshop.render.frames import render_camera
from windowshop.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
SUPERSAMPLE = 2  # samples a pixel side of the anti-aliased PSNR


def trained(source: Path, options: SceneOptions, seconds: float, out: Path) -> tuple[Path, dict]:
    """A fast model trained `seconds` on `source` into `out`, and its held-out metrics."""
    scene = load_scene(source, options)
    metrics = fit(scene, "fast", model_config("fast"), FitConfig(iters=None, seconds=seconds), out,
                  "cpu", show_progress=False)
    return out, metrics


def speed_row(run: Path, work: Path) -> dict:
    """Seconds to export `run` as GLB and as USDZ at the defaults, and the files' sizes."""
    row = {"row": "speed", "run": str(run)}
    for fmt in ("glb", "usdz"):
        out = work / f"model.{fmt}"
        start = time.perf_counter()
        asset = export_command(str(run), str(out), None, ExportOptions())
        row[f"{fmt}_seconds"] = round(time.perf_counter() - start, 2)
        row[f"{fmt}_mb"] = round(out.stat().st_size / 1e6, 2)
        row[f"{fmt}_stages"] = asset.info["seconds"]
    row["triangles"] = asset.info["triangles"]
    return row


def supersampled(vertices: np.ndarray, faces: np.ndarray, camera, uv: np.ndarray,
                 texture: np.ndarray, k: int) -> np.ndarray:
    """(H, W, 3) the textured mesh drawn at `k` x `k` samples a pixel, averaged: anti-aliased,
    as a viewer (model-viewer, Quick Look) draws it and as the photos were rendered."""
    image, _ = render_mesh(vertices, faces, camera.resized(camera.width * k, camera.height * k),
                           (1.0, 1.0, 1.0), uv=uv, texture=texture)
    return image.reshape(camera.height, k, camera.width, k, 3).mean((1, 3))


def load_glb(glb: Path, run) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (V, 3) in the scene's normalised frame, faces (F, 3), uv (V, 2) glTF's, texture,
    the file's unit vertex normals (V, 3) turned into that frame)."""
    loaded = trimesh.load(glb, force="mesh", process=False)
    to_normalised = run.transform @ np.array(json.loads(side_file(glb).read_text())["model_to_source"])
    vertices = apply(to_normalised, np.asarray(loaded.vertices))
    uv = np.asarray(loaded.visual.uv).copy()
    uv[:, 1] = 1.0 - uv[:, 1]  # trimesh's v = 0 at the bottom; glTF's (and the rasteriser's) top
    texture = np.asarray(loaded.visual.material.baseColorTexture.convert("RGB"))
    normals = np.asarray(loaded.vertex_normals) @ to_normalised[:3, :3].T
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return vertices, np.asarray(loaded.faces), uv, texture, normals


def quality_row(run_dir: Path, views: int, work: Path) -> dict:
    """The exported GLB of `run_dir` against its scene's held-out views (see the docstring)."""
    glb = work / "lego.glb"
    asset = export_command(str(run_dir), str(glb), None, ExportOptions())
    run = load_run(run_dir)
    scene = load_scene(run.scene_source, run.scene_options)
    vertices, faces, uv, texture, _ = load_glb(glb, run)
    ious, mesh_psnr, smooth_psnr, field_psnr = [], [], [], []
    for view in scene.split("test")[:views]:
        image, silhouette = render_mesh(vertices, faces, view.camera,
                                        (1.0, 1.0, 1.0), uv=uv, texture=texture)
        alpha = view.alpha > 0.5
        ious.append(float((alpha & silhouette).sum() / max((alpha | silhouette).sum(), 1)))
        mesh_psnr.append(psnr(image, view.image))
        smooth_psnr.append(psnr(supersampled(vertices, faces, view.camera, uv,
                                             texture, SUPERSAMPLE), view.image))
        field_psnr.append(psnr(render_camera(run.model, view.camera).rgb, view.image))
    return {"row": "quality", "run": str(run_dir), "step": run.step, "views": len(ious),
            "silhouette_iou": round(float(np.mean(ious)), 4),
            "silhouette_iou_min": round(float(np.min(ious)), 4),
            "mesh_psnr": round(float(np.mean(mesh_psnr)), 2),
            f"mesh_psnr_ssaa{SUPERSAMPLE}": round(float(np.mean(smooth_psnr)), 2),
            "field_psnr": round(float(np.mean(field_psnr)), 2),
            "level": asset.info["level"], "level_iou": asset.info["silhouette_iou"],
            "photos": asset.info["photos"],
            "triangles": asset.info["triangles"], "glb_mb": round(glb.stat().st_size / 1e6, 2),
            "export_seconds": asset.info["seconds"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", nargs="+", default=["speed", "quality"])
    parser.add_argument("--tiny-seconds", type=float, default=30.0)
    parser.add_argument("--lego-seconds", type=float, default=60.0)
    parser.add_argument("--views", type=int, default=8, help="held-out lego views compared")
    parser.add_argument("--tiny-run", type=Path, default=None, help="a trained lego_tiny run")
    parser.add_argument("--lego-run", type=Path, default=None, help="a trained lego 400x400 run")
    args = parser.parse_args()
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory(prefix="bench-export-") as tmp:
        work = Path(tmp)
        if "speed" in args.rows:
            run, metrics = args.tiny_run, None
            if run is None:
                run, metrics = trained(DATA / "lego_tiny.npz", SceneOptions(), args.tiny_seconds,
                                       work / "tiny")
            row = speed_row(run, work)
            if metrics:
                row["fit_psnr"] = round(metrics["psnr"], 2)
            print(json.dumps({**row, **machine()}), flush=True)
        if "quality" in args.rows:
            run = args.lego_run
            if run is None:
                run, _ = trained(DATA / "lego", SceneOptions(test_views=args.views),
                                 args.lego_seconds, work / "lego")
            print(json.dumps({**quality_row(run, args.views, work), **machine()}), flush=True)


if __name__ == "__main__":
    main()
