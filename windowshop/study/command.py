"""`windowshop study` behind the CLI: flags in, a study folder with REPORT.md out."""

from __future__ import annotations

import shlex
from pathlib import Path

import torch

from windowshop.overrides import parse_assignments
from windowshop.study.grids import budget_overrides, load_grid
from windowshop.study.report import REPORT
from windowshop.study.runner import ResultRow, run_study


def command_line(preset: str | None, grid_file: str | None, scene: str, out: str,
                 iters: int | None, seconds: float | None, assignments: list[str]) -> str:
    """The `windowshop study` command that repeats (or resumes) this study, for the report."""
    words = ["windowshop", "study"]
    words += ["--preset", preset] if preset else ["--grid", str(grid_file)]
    words += ["--scene", str(scene), "--out", str(out)]
    if iters is not None:
        words += ["--iters", str(iters)]
    if seconds is not None:
        words += ["--seconds", f"{seconds:g}"]
    for item in assignments:
        words += ["--set", item]
    return shlex.join(words)


def study_command(preset: str | None, grid_file: str | None, scene: str, out: str,
                  iters: int | None, seconds: float | None, assignments: list[str],
                  device: torch.device, show_progress: bool = True) -> list[ResultRow]:
    """Run (or resume) a study and print where its report is."""
    overrides = {**parse_assignments(assignments), **budget_overrides(iters, seconds)}
    grid = load_grid(preset, grid_file, overrides)
    rows = run_study(grid, scene, out, device, overrides,
                     command_line(preset, grid_file, scene, out, iters, seconds, assignments),
                     show_progress=show_progress)
    print(f"wrote {Path(out) / REPORT}")
    return rows
