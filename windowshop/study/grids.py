"""Grids of runs: the seed paper's Table 1, the NeRF paper's ablation, or a YAML/JSON file.

A grid is data: `base` switches shared by every run, `rows` that each change some of them (and may
carry the paper's published numbers), and an optional `product` whose every combination of values
is applied to every row. A switch is any setting of `windowshop fit`: `model`, `preset`, a scene
option (`views`, `downscale`, ...), a `FitConfig` field (`iters`, `batch_rays`, ...) or a field of
the model's config (`freqs`, `n_coarse`, ...), spelt as the flag (`n-coarse`) or the field
(`n_coarse`). Switches are checked against the model when a study starts (`runner.resolve`).
"""

from __future__ import annotations

import itertools
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from windowshop.errors import UserError

BUDGET_KEYS = ("iters", "seconds")  # set by --iters / --seconds for every run; never a table column
LEADING_COLUMNS = ("model", "preset", "views")  # shown first in the table when a grid varies them
GRID_KEYS = {"name", "description", "reference", "base", "rows", "product"}

SEED = {
    "name": "seed",
    "reference": "seed Table 2",
    "description": (
        "The ten combinations of the seed paper's Table 1 (number of training images, L, N_c, "
        "view dependence; 2000 iterations each) with its published PSNR from Table 2. The rest "
        "follows the seed's code (tiny_nerf): an 8x256 MLP with the input concatenated again "
        "after layer 5, one set of samples per ray (no fine network), Adam at a constant 5e-4, "
        "and 10,000 rays per step (one 100x100 image's worth). Its published code never feeds "
        "the direction to the MLP, so its 'view dependency' rows may have run without it; we "
        "follow Table 1 as written."),
    "base": {"model": "nerf", "preset": "tiny", "iters": 2000, "batch_rays": 10000,
             "lr": 5e-4, "lr_final": 5e-4},
    "rows": [
        {"name": "img100-L6-Nc64", "views": 100, "freqs": 6, "n_coarse": 64, "view_dependent": True,
         "published": {"psnr": 23.5}},
        {"name": "img100-L10-Nc64", "views": 100, "freqs": 10, "n_coarse": 64, "view_dependent": True,
         "published": {"psnr": 23.8}},
        {"name": "img100-L6-Nc128", "views": 100, "freqs": 6, "n_coarse": 128, "view_dependent": True,
         "published": {"psnr": 24.2}},
        {"name": "img25-L6-Nc64", "views": 25, "freqs": 6, "n_coarse": 64, "view_dependent": True,
         "published": {"psnr": 25.0}},
        {"name": "img25-L10-Nc64", "views": 25, "freqs": 10, "n_coarse": 64, "view_dependent": True,
         "published": {"psnr": 23.8}},
        {"name": "img10-L6-Nc64-novd", "views": 10, "freqs": 6, "n_coarse": 64, "view_dependent": False,
         "published": {"psnr": 22.5}},
        {"name": "img5-L6-Nc64", "views": 5, "freqs": 6, "n_coarse": 64, "view_dependent": True,
         "published": {"psnr": 23.0}},
        {"name": "img5-L6-Nc128", "views": 5, "freqs": 6, "n_coarse": 128, "view_dependent": True,
         "published": {"psnr": 15.0}},
        {"name": "img5-L10-Nc64", "views": 5, "freqs": 10, "n_coarse": 64, "view_dependent": True,
         "published": {"psnr": 24.0}},
        {"name": "img5-L10-Nc128", "views": 5, "freqs": 10, "n_coarse": 128, "view_dependent": True,
         "published": {"psnr": 16.0}},
    ],
}

NERF_ABLATION = {
    "name": "nerf-ablation",
    "reference": "NeRF Table 4",
    "description": (
        "The rows of the NeRF paper's ablation (Mildenhall et al. 2020, Table 4; the seed's "
        "Figure 3): positional encoding, view dependence, hierarchical sampling, fewer images, "
        "fewer and more frequencies, against the complete model. Its published numbers average "
        "the eight synthetic scenes at 800x800 after 100k-300k iterations of 4096 rays; ours use "
        "4096 rays per step and the seed's 2000 iterations unless --iters/--seconds say otherwise."),
    "base": {"model": "nerf", "preset": "paper", "iters": 2000, "batch_rays": 4096, "views": 100},
    "rows": [
        {"name": "no-PE-VD-H", "freqs": 0, "freqs_dir": 0, "view_dependent": False, "n_coarse": 256,
         "n_fine": 0, "published": {"psnr": 26.67, "ssim": 0.906, "lpips": 0.136}},
        {"name": "no-PE", "freqs": 0, "freqs_dir": 0, "view_dependent": True, "n_coarse": 64,
         "n_fine": 128, "published": {"psnr": 28.77, "ssim": 0.924, "lpips": 0.108}},
        {"name": "no-VD", "freqs": 10, "view_dependent": False, "n_coarse": 64, "n_fine": 128,
         "published": {"psnr": 27.66, "ssim": 0.925, "lpips": 0.117}},
        {"name": "no-H", "freqs": 10, "view_dependent": True, "n_coarse": 256, "n_fine": 0,
         "published": {"psnr": 30.06, "ssim": 0.938, "lpips": 0.109}},
        {"name": "img25", "views": 25, "freqs": 10, "n_coarse": 64, "n_fine": 128,
         "published": {"psnr": 27.78, "ssim": 0.925, "lpips": 0.107}},
        {"name": "img50", "views": 50, "freqs": 10, "n_coarse": 64, "n_fine": 128,
         "published": {"psnr": 29.79, "ssim": 0.940, "lpips": 0.096}},
        {"name": "L5", "freqs": 5, "n_coarse": 64, "n_fine": 128,
         "published": {"psnr": 30.59, "ssim": 0.944, "lpips": 0.088}},
        {"name": "L15", "freqs": 15, "n_coarse": 64, "n_fine": 128,
         "published": {"psnr": 30.81, "ssim": 0.946, "lpips": 0.096}},
        {"name": "complete", "freqs": 10, "view_dependent": True, "n_coarse": 64, "n_fine": 128,
         "published": {"psnr": 31.01, "ssim": 0.947, "lpips": 0.081}},
    ],
}

PRESETS = {"seed": SEED, "nerf-ablation": NERF_ABLATION}


@dataclass(frozen=True)
class Combination:
    """One run of a grid: a plain record, so it can be handed to another process as is."""

    index: int  # 1-based, the paper's combination number for the presets
    name: str  # short label; the run folder is `runs/{index:02d}-{name}`
    settings: dict[str, Any]  # every switch of this run: base, row, --set and budget merged
    published: dict[str, float] = field(default_factory=dict)  # the paper's numbers for this row

    @property
    def folder(self) -> str:
        return f"{self.index:02d}-{self.name}"


@dataclass(frozen=True)
class Grid:
    """A named list of combinations and the switches that tell them apart (the table's columns)."""

    name: str
    description: str
    reference: str  # where the published numbers come from ("" if none)
    combinations: tuple[Combination, ...]
    columns: tuple[str, ...]  # switches that rows or the product set, budget keys left out


def normalise_keys(settings: dict, where: str) -> dict[str, Any]:
    """Switch names as `fit`'s config fields: `n-coarse` -> `n_coarse`; mappings only."""
    if not isinstance(settings, dict):
        raise UserError(f"{where}: expected a mapping of switches, got {type(settings).__name__}")
    return {str(key).replace("-", "_"): value for key, value in settings.items()}


def _slug(text: str) -> str:
    """A file-name-safe version of `text`."""
    return re.sub(r"[^A-Za-z0-9_.=-]+", "-", text).strip("-") or "run"


def _default_name(settings: dict[str, Any]) -> str:
    return "-".join(f"{key}={value}" for key, value in settings.items()) or "base"


def _expand(rows: list[dict], product: dict[str, list], where: str) -> list[dict]:
    """Every row combined with every combination of the product's values (rows first)."""
    if not isinstance(product, dict) or not all(isinstance(v, list) and v for v in product.values()):
        raise UserError(f"{where}: 'product' must map switches to non-empty lists of values")
    product = normalise_keys(product, f"{where} product")
    rows = rows or [{}]
    expanded = []
    for row in rows:
        for values in itertools.product(*product.values()):
            extra = dict(zip(product, values))
            named = {"name": f"{row['name']}-{_default_name(extra)}"} if row.get("name") else {}
            expanded.append({**row, **extra, **named})  # unnamed rows are named by all their switches
    return expanded


def grid_from_dict(data: dict, where: str, overrides: dict[str, Any] | None = None) -> Grid:
    """Build a Grid from preset or file data; `overrides` (--set, budget) apply to every run last."""
    if not isinstance(data, dict):
        raise UserError(f"{where}: a grid is a mapping with 'base' and 'rows' (or 'product')")
    unknown = sorted(set(data) - GRID_KEYS)
    if unknown:
        raise UserError(f"{where}: unknown key(s) {', '.join(unknown)}; a grid has "
                        f"{', '.join(sorted(GRID_KEYS))}")
    rows = data.get("rows") or []
    if not isinstance(rows, list):
        raise UserError(f"{where}: 'rows' must be a list of mappings of switches")
    rows = [normalise_keys(row, f"{where} row {i + 1}") for i, row in enumerate(rows)]
    if "product" in data:
        rows = _expand(rows, data["product"], where)
    if not rows:
        raise UserError(f"{where}: the grid has no runs; give 'rows' or 'product'")
    base = normalise_keys(data.get("base") or {}, f"{where} base")
    overrides = normalise_keys(overrides or {}, "overrides")
    combinations, columns = [], []
    for index, row in enumerate(rows, start=1):
        published = row.pop("published", {}) or {}
        name = _slug(str(row.pop("name", None) or _default_name(row)))
        columns += [key for key in row if key not in columns and key not in BUDGET_KEYS]
        combinations.append(Combination(index=index, name=name, settings={**base, **row, **overrides},
                                        published={k: float(v) for k, v in published.items()}))
    clash = [key for key in overrides if key in columns]
    if clash:  # the rows' own names and columns would then lie about what ran
        raise UserError(f"{where}: the rows themselves set {', '.join(clash)}, which the study "
                        f"compares; change the grid instead of --set {clash[0]}=...")
    lead = {key: i for i, key in enumerate(LEADING_COLUMNS)}
    columns.sort(key=lambda key: lead.get(key, len(lead)))
    return Grid(name=str(data.get("name") or Path(where).stem),
                description=str(data.get("description", "")),
                reference=str(data.get("reference", "")), combinations=tuple(combinations),
                columns=tuple(columns))


def read_grid_file(path: str | Path) -> dict:
    """The raw data of a grid file: YAML (.yaml/.yml) or JSON (.json)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such grid file")
    try:
        if path.suffix.lower() == ".json":
            return json.loads(path.read_text())
        if path.suffix.lower() in (".yaml", ".yml"):
            return yaml.safe_load(path.read_text())
    except (json.JSONDecodeError, yaml.YAMLError) as err:
        raise UserError(f"{path}: cannot parse the grid file ({err})") from None
    raise UserError(f"{path}: a grid file ends in .yaml, .yml or .json")


def load_grid(preset: str | None = None, path: str | Path | None = None,
              overrides: dict[str, Any] | None = None) -> Grid:
    """The grid of a named `preset` or of the file at `path` (exactly one), with `overrides`."""
    if (preset is None) == (path is None):
        raise UserError("give a study: --preset NAME or --grid FILE (one of them)")
    if preset is not None:
        if preset not in PRESETS:
            raise UserError(f"unknown study preset {preset!r}; choose one of {', '.join(PRESETS)}")
        return grid_from_dict(PRESETS[preset], preset, overrides)
    return grid_from_dict(read_grid_file(path), str(path), overrides)


def budget_overrides(iters: int | None, seconds: float | None) -> dict[str, Any]:
    """The switches that make `--iters N` or `--seconds S` every run's whole budget."""
    if iters is not None and seconds is not None:
        raise UserError("give --iters or --seconds, not both")
    if iters is not None:
        if iters < 1:
            raise UserError(f"--iters must be at least 1, got {iters}")
        return {"iters": iters, "seconds": None}
    if seconds is not None:
        if seconds <= 0:
            raise UserError(f"--seconds must be positive, got {seconds}")
        return {"iters": None, "seconds": seconds}
    return {}
