"""`windowshop inspect`: a summary of a posed scene, its machine-readable form, and a plot of the
cameras around the object box with a thumbnail strip."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from windowshop.config import SceneOptions
from windowshop.scene.types import SPLITS, Camera, Scene, View


def _stored(scene: Scene, view: View) -> Camera:
    """The view's camera as the source gives it (derived from the normalised one if unknown)."""
    return view.stored_camera if view.stored_camera is not None else scene.source_camera(view.camera)


def summary_dict(scene: Scene) -> dict:
    """The `--json` form: format and per view split, image, size, intrinsics and source-frame c2w
    (pixels of the stored image, before any downscale), plus bounds in the normalised frame."""
    views = []
    for view in scene.views:
        cam = _stored(scene, view)
        entry = {"split": view.split, "image": view.name, "width": cam.width, "height": cam.height,
                 "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "c2w": cam.c2w.tolist()}
        if view.distortion:
            entry["distortion"] = view.distortion
        views.append(entry)
    return {"format": scene.format, "source": str(scene.source), "notes": list(scene.notes), "views": views,
            "background": scene.background,
            "bounds": {"aabb": np.asarray(scene.aabb).tolist(), "near": scene.near, "far": scene.far},
            "transform": scene.transform.tolist()}


def _range(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.2f}" if np.isclose(lo, hi) else f"{lo:.2f}..{hi:.2f}"


def summary_text(scene: Scene) -> str:
    """A few human-readable lines."""
    stored = [_stored(scene, v) for v in scene.views]
    counts = ", ".join(f"{len(scene.split(s))} {s}" for s in SPLITS if scene.split(s))
    sizes = sorted({(c.width, c.height) for c in stored})
    loaded = sorted({(v.camera.width, v.camera.height) for v in scene.views})
    lo, hi = np.asarray(scene.aabb)
    lines = [
        f"format:      {scene.format} ({scene.source})",
        f"views:       {len(scene.views)} ({counts})",
        f"resolution:  stored {', '.join(f'{w}x{h}' for w, h in sizes)}; "
        f"loaded {', '.join(f'{w}x{h}' for w, h in loaded)}",
        f"intrinsics:  fx {_range([c.fx for c in stored])}  fy {_range([c.fy for c in stored])}  "
        f"cx {_range([c.cx for c in stored])}  cy {_range([c.cy for c in stored])} (stored pixels)",
        f"distortion:  {'undistorted on load' if any(v.distortion for v in scene.views) else 'none'}",
        f"background:  {scene.background}; alpha {'yes' if any(v.alpha is not None for v in scene.views) else 'no'}",
        f"bounds:      aabb [{', '.join(f'{x:.3f}' for x in lo)}] .. [{', '.join(f'{x:.3f}' for x in hi)}]"
        f"  near {scene.near:.3f}  far {scene.far:.3f} (normalised frame)",
        f"normalise:   scale {scene.scale:.4g} (normalised units per source unit)",
    ]
    return "\n".join(lines + [f"read:        {note}" for note in scene.notes])


def inspect_command(path: str, options: SceneOptions, as_json: bool = False,
                    plot: str | None = None) -> None:
    """Load the scene at `path` and print its summary (and draw the plot)."""
    from windowshop.scene import load_scene

    scene = load_scene(path, options)
    print(json.dumps(summary_dict(scene), indent=1) if as_json else summary_text(scene))
    if plot:
        from windowshop.scene.plot import plot_scene

        plot_scene(scene, Path(plot))
        if not as_json:
            print(f"plot:        {plot}")
