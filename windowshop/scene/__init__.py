"""Posed images of one object, from any supported format, as one `Scene`.

`load_scene(path)` picks the reader from what the path holds; every reader returns a `Source`
that `loading.build_scene` turns into a normalised Scene the same way for all formats.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from windowshop.config import SceneOptions
from windowshop.errors import UserError
from windowshop.scene.colmap import find_model
from windowshop.scene.images import IMAGE_SUFFIXES
from windowshop.scene.source import Source
from windowshop.scene.types import Camera, Scene, View

__all__ = ["Camera", "Scene", "View", "load_scene", "read_source", "detect_format", "READERS"]

# format name -> "module:function" taking the path the format's detection settled on
READERS = {
    "blender": "windowshop.scene.blender:read_blender",
    "nerfstudio": "windowshop.scene.nerfstudio:read_nerfstudio",
    "npz": "windowshop.scene.npz:read_npz",
    "llff": "windowshop.scene.llff:read_llff",
    "colmap": "windowshop.scene.colmap:read_colmap",
    "middlebury": "windowshop.scene.middlebury:read_middlebury",
}


def _detect_file(path: Path) -> tuple[str, Path] | None:
    name, suffix = path.name.lower(), path.suffix.lower()
    if suffix == ".npz":
        return "npz", path
    if name.startswith("transforms_") and suffix == ".json":
        return "blender", path.parent
    if suffix == ".json":
        return "nerfstudio", path
    if name == "poses_bounds.npy":
        return "llff", path.parent
    if name.endswith("_par.txt"):
        return "middlebury", path
    if name in ("cameras.bin", "cameras.txt", "images.bin", "images.txt"):
        return "colmap", path.parent
    return None


def _detect_folder(path: Path) -> tuple[str, Path] | None:
    if (path / "transforms_train.json").is_file():
        return "blender", path
    if (path / "transforms.json").is_file():
        return "nerfstudio", path / "transforms.json"
    if (path / "poses_bounds.npy").is_file():
        return "llff", path
    model = find_model(path)
    if model is not None:
        return "colmap", model
    par = sorted(path.glob("*_par.txt"))
    if par:
        return "middlebury", par[0]
    return None


def detect_format(path: str | Path) -> tuple[str, Path]:
    """(reader name, the path to hand it) for a dataset file or folder; UserError if unknown."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"{path}: no such file or folder")
    found = _detect_file(path) if path.is_file() else _detect_folder(path)
    if found is not None:
        return found
    if path.is_dir() and any(p.suffix.lower() in IMAGE_SUFFIXES for p in path.iterdir()):
        raise UserError(f"{path}: these images have no camera poses; run `windowshop prepare "
                        f"{path}` to estimate them (structure from motion) first")
    raise UserError(f"{path}: unknown scene format; expected one of: Blender transforms_*.json, "
                    f"nerfstudio/instant-ngp transforms.json, tiny_nerf .npz, LLFF "
                    f"poses_bounds.npy, a COLMAP sparse model, or a Middlebury *_par.txt")


def read_source(path: str | Path) -> Source:
    """The raw `Source` of a dataset (cameras in its own frame, no pixels decoded)."""
    name, target = detect_format(path)
    module, function = READERS[name].split(":")
    return getattr(importlib.import_module(module), function)(target)


def load_scene(path: str | Path, options: SceneOptions = SceneOptions()) -> Scene:
    """The normalised Scene of the dataset at `path` (any supported format), under `options`."""
    from windowshop.scene.loading import build_scene

    return build_scene(read_source(path), options)
