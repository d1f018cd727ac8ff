"""Any Scene -> a nerfstudio `transforms.json` + PNG images (+ masks), which the nerfstudio reader
reads back. Cameras are written in the scene's (normalised) frame, with per-frame intrinsics;
the extra key `windowshop` keeps the normalisation `transform` (x_norm = T @ x_source), the
object box and the background, so everything maps back to the source's frame."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from windowshop.scene.nerfstudio import WRITER_KEY
from windowshop.scene.types import SPLITS, Scene, View


def _to_uint8(array: np.ndarray) -> np.ndarray:
    return np.round(np.clip(array, 0.0, 1.0) * 255.0).astype(np.uint8)


def _frame(view: View, index: int, out_dir: Path) -> dict:
    """Write one view's image (and mask) and return its frame entry."""
    cam = view.camera
    name = f"images/{index:04d}_{view.split}.png"
    Image.fromarray(_to_uint8(view.image)).save(out_dir / name)
    frame = {"file_path": name, "transform_matrix": cam.c2w.tolist(), "fl_x": cam.fx,
             "fl_y": cam.fy, "cx": cam.cx, "cy": cam.cy, "w": cam.width, "h": cam.height}
    if view.alpha is not None:
        frame["mask_path"] = f"masks/{index:04d}_{view.split}.png"
        Image.fromarray(_to_uint8(view.alpha)).save(out_dir / frame["mask_path"])
    return frame


def write_transforms(scene: Scene, out_dir: str | Path) -> Path:
    """Save `scene` under `out_dir`; returns the path of the written transforms.json."""
    out_dir = Path(out_dir)
    (out_dir / "images").mkdir(parents=True, exist_ok=True)
    if any(v.alpha is not None for v in scene.views):
        (out_dir / "masks").mkdir(exist_ok=True)
    frames = [_frame(view, i, out_dir) for i, view in enumerate(scene.views)]
    meta = {
        "camera_model": "OPENCV",
        "frames": frames,
        **{f"{split}_filenames": [f["file_path"] for f, v in zip(frames, scene.views)
                                  if v.split == split] for split in SPLITS},
        WRITER_KEY: {"transform": scene.transform.tolist(), "aabb": np.asarray(scene.aabb).tolist(),
                     "near": scene.near, "far": scene.far, "background": scene.background,
                     "source": str(scene.source), "format": scene.format},
    }
    path = out_dir / "transforms.json"
    path.write_text(json.dumps(meta, indent=2))
    return path
