"""Run a grid in-process, one ordinary run folder per combination, resuming where it stopped.

`run_combination` trains (or skips, or finishes) one combination and returns its `ResultRow`; it
takes only plain records, so a later scheduler can hand combinations to other processes.
`run_study` runs them all in order and rewrites results.csv and REPORT.md after each one.

A study folder holds `study.json`, `runs/NN-name/` (run folders `eval` and `render` accept, plus
`study_row.json` once the combination is done and `study_view.png`, its render of one held-out
view), `truth_view.png` (that view's true image), `results.csv`, `REPORT.md` and the plots.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import json
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import torch
from PIL import Image

from windowshop.config import FitConfig, RunConfig, SceneOptions
from windowshop.errors import UserError
from windowshop.study.grids import Combination, Grid

DEFAULT_MODEL = "nerf"  # as `windowshop fit` when a grid names no model
RUNS = "runs"
STUDY = "study.json"
ROW = "study_row.json"
VIEW = "study_view.png"
TRUTH = "truth_view.png"


@dataclass(frozen=True)
class RunSettings:
    """A combination's switches sorted into what `fit` takes."""

    model: str
    preset: str | None
    model_config: Any  # the model's frozen config dataclass
    fit_config: FitConfig
    scene_options: SceneOptions

    def effective(self) -> dict[str, Any]:
        """Every switch's value as the run uses it (defaults included), for the table and CSV."""
        return {"model": self.model, "preset": self.preset,
                **dataclasses.asdict(self.scene_options), **dataclasses.asdict(self.fit_config),
                **dataclasses.asdict(self.model_config)}


@dataclass
class ResultRow:
    """One line of results.csv: a combination, what it reached and how long it took."""

    index: int
    name: str
    folder: str  # relative to the study folder
    settings: dict[str, Any]  # `RunSettings.effective()`, with `views` the training views used
    train_views: int
    test_views: int
    iterations: int
    train_seconds: float
    seconds_per_iter: float
    psnr: float | None
    ssim: float | None
    eval_seconds: float
    published: dict[str, float] = field(default_factory=dict)
    status: str = "trained"  # "trained", "resumed" or "skipped" (finished by an earlier call)
    machine: str = ""  # `describe_machine` of the call that finished the run
    load: float | None = None  # the machine's load average when that call started the run
    finished: str = ""  # when the row was written (ISO time)


@dataclass(frozen=True)
class StudyInfo:
    """What a study's numbers depend on besides the grid: where, with what budget, when."""

    grid: str
    scene: str
    budget: str
    overrides: dict[str, Any]
    machine: str
    device: str
    torch: str
    started: str
    command: str = ""


def resolve(settings: dict[str, Any], where: str) -> RunSettings:
    """Sort a combination's switches into model, preset, scene options, fit and model config (as
    `windowshop fit` does, windowshop.model.apply_run_overrides); a switch that none of them has
    is a UserError naming `where` (the combination)."""
    from windowshop.model import apply_run_overrides, model_config

    settings = {"model": DEFAULT_MODEL, **settings}
    config = apply_run_overrides(RunConfig(), settings, where)
    if not config.fit.iters and not config.fit.seconds:
        raise UserError(f"{where}: no training budget; give iters or seconds (or --iters/--seconds)")
    model = model_config(config.model, config.preset, **config.model_settings)
    return RunSettings(config.model, config.preset, model, config.fit, config.scene)


def cpu_model() -> str:
    """The processor's name as /proc/cpuinfo (Linux) or the platform module tells it."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def describe_machine(device: torch.device | str) -> str:
    """One line naming what the runs ran on: the GPU's name, or the CPU's model and cores."""
    device = torch.device(device)
    if device.type == "cuda":
        return f"GPU {torch.cuda.get_device_name(device)} (CUDA {torch.version.cuda})"
    return (f"CPU {cpu_model()} ({os.cpu_count()} logical cores, "
            f"{torch.get_num_threads()} torch threads)")


def load_average() -> float | None:
    """The machine's 1-minute load average (None where the OS has none): other work slows timings."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


def describe_budget(overrides: dict[str, Any], grid: Grid) -> str:
    """The budget every run had, in words."""
    if overrides.get("seconds") is not None:
        return f"{overrides['seconds']:g} s of training per run (--seconds; the grid's iterations ignored)"
    if overrides.get("iters") is not None:
        return f"{overrides['iters']} iterations per run (--iters; the grid's iterations ignored)"
    asked = sorted({str(c.settings.get("iters")) for c in grid.combinations})
    return f"the grid's own: {', '.join(asked)} iterations per run"


@functools.lru_cache(maxsize=1)
def _scene(path: str, options: SceneOptions):
    """The scene at `path` under `options`; the last one is kept, since rows often share it."""
    from windowshop.scene import load_scene

    return load_scene(path, options)


def _json_roundtrip(data: Any) -> Any:
    return json.loads(json.dumps(data))


def _mismatch(recorded: dict, spec: RunSettings, scene_path: str) -> str | None:
    """How the run folder's config.json differs from `spec` (None: it is the same run)."""
    asked = {"model": spec.model, "model_config": dataclasses.asdict(spec.model_config),
             "fit_config": dataclasses.asdict(spec.fit_config),
             "scene_options": dataclasses.asdict(spec.scene_options)}
    found = {"model": recorded.get("model"), "model_config": recorded.get("model_config"),
             "fit_config": recorded.get("fit_config"),
             "scene_options": recorded.get("scene", {}).get("options")}
    for part, value in _json_roundtrip(asked).items():
        if not isinstance(value, dict):
            if found[part] != value:
                return f"{part} {found[part]!r} there, {value!r} asked"
            continue
        for key, want in value.items():
            have = (found[part] or {}).get(key)
            if have != want:
                return f"{part}.{key} {have!r} there, {want!r} asked"
    source = recorded.get("scene", {}).get("source")
    if source is None or Path(source).resolve() != Path(scene_path).resolve():
        return f"scene {source!r} there, {scene_path!r} asked"
    return None


def run_state(run_dir: Path, spec: RunSettings, scene_path: str) -> str:
    """"new", "partial" (a checkpoint to carry on from), "trained" (measured) or "done"."""
    from windowshop.fit.checkpoint import CHECKPOINT, CONFIG, METRICS

    config = run_dir / CONFIG
    if not config.is_file():
        return "new"
    problem = _mismatch(json.loads(config.read_text()), spec, scene_path)
    if problem:
        raise UserError(f"{run_dir} was trained with other settings ({problem}); give the study a "
                        f"new --out folder or delete that run folder")
    if (run_dir / ROW).is_file() and (run_dir / METRICS).is_file():
        return "done"
    if (run_dir / METRICS).is_file():
        return "trained"
    return "partial" if (run_dir / CHECKPOINT).is_file() else "new"


def _keep_view(run_dir: Path, view_index: int, study_dir: Path) -> None:
    """Copy the run's render of held-out view `view_index` to `study_view.png` (and the true
    image to the study's `truth_view.png` once), for the contact sheet.

    Both are cut from the comparison image evaluation wrote (truth | render | error, see
    `evaluate.comparison_image`), so the view is not rendered a second time.
    """
    from windowshop.fit.evaluate import EVAL_DIR

    found = sorted((run_dir / EVAL_DIR).glob(f"{view_index:03d}_*.png"))
    if not found:
        return  # a scene without held-out views: no contact tile
    panel = Image.open(found[0]).convert("RGB")
    width = panel.width // 3
    panel.crop((width, 0, 2 * width, panel.height)).save(run_dir / VIEW)
    if not (study_dir / TRUTH).is_file():
        panel.crop((0, 0, width, panel.height)).save(study_dir / TRUTH)


def _result_row(combo: Combination, spec: RunSettings, metrics: dict, train_views: int,
                status: str, machine: str, load: float | None) -> ResultRow:
    iterations = int(metrics.get("iterations") or 0)
    seconds = float(metrics.get("train_seconds") or 0.0)
    settings = {**spec.effective(), "views": train_views}
    return ResultRow(index=combo.index, name=combo.name, folder=f"{RUNS}/{combo.folder}",
                     settings=settings, train_views=train_views,
                     test_views=int(metrics.get("test_views") or 0), iterations=iterations,
                     train_seconds=seconds, seconds_per_iter=seconds / max(iterations, 1),
                     psnr=metrics.get("psnr"), ssim=metrics.get("ssim"),
                     eval_seconds=float(metrics.get("eval_seconds") or 0.0),
                     published=dict(combo.published), status=status, machine=machine, load=load,
                     finished=_now())


def run_combination(combo: Combination, scene_path: str | Path, study_dir: str | Path,
                    device: torch.device | str, show_progress: bool = False,
                    view_index: int = 0) -> ResultRow:
    """Train `combo` into `study_dir/runs/NN-name` on the scene at `scene_path` and measure it.

    A finished combination is not trained again (its recorded row comes back with status
    "skipped"); an interrupted one carries on from its checkpoint ("resumed"). The row is also
    written to the run folder as `study_row.json`.
    """
    from windowshop.fit.checkpoint import LOG, METRICS
    from windowshop.fit.trainer import fit

    study_dir, scene_path = Path(study_dir), str(scene_path)
    run_dir = study_dir / RUNS / combo.folder
    spec = resolve(combo.settings, combo.folder)
    state = run_state(run_dir, spec, scene_path)
    if state == "done":
        recorded = json.loads((run_dir / ROW).read_text())
        names = {f.name for f in dataclasses.fields(ResultRow)}
        return ResultRow(**{**{k: v for k, v in recorded.items() if k in names}, "status": "skipped"})
    load = load_average()
    scene = _scene(scene_path, spec.scene_options)
    if state == "trained":
        metrics = json.loads((run_dir / METRICS).read_text())
    else:
        if state == "new" and (run_dir / LOG).is_file():
            (run_dir / LOG).unlink()  # lines of an attempt that never reached a checkpoint
        try:
            metrics = fit(scene, spec.model, spec.model_config, spec.fit_config, run_dir, device,
                          resume=run_dir if state == "partial" else None, show_progress=show_progress)
        except UserError as err:  # e.g. Ctrl-C, after fit checkpointed the run
            raise UserError(f"combination {combo.folder}: {err} (running the same study command "
                            f"again carries on the study)") from None
    _keep_view(run_dir, view_index, study_dir)
    row = _result_row(combo, spec, metrics, len(scene.split("train")),
                      "resumed" if state in ("partial", "trained") else "trained",
                      describe_machine(device), load)
    (run_dir / ROW).write_text(json.dumps(dataclasses.asdict(row), indent=2) + "\n")
    return row


def study_info(grid: Grid, scene_path: str | Path, overrides: dict[str, Any],
               device: torch.device | str, command: str = "") -> StudyInfo:
    """The StudyInfo of a study starting now on `device`."""
    return StudyInfo(grid=grid.name, scene=str(scene_path), budget=describe_budget(overrides, grid),
                     overrides=dict(overrides), machine=describe_machine(device), device=str(device),
                     torch=torch.__version__, command=command,
                     started=_now())


def _now() -> str:
    return datetime.datetime.now().isoformat(timespec="seconds")


def row_summary(row: ResultRow) -> str:
    """One line for the terminal."""
    psnr = "n/a" if row.psnr is None else f"{row.psnr:.2f} dB"
    return (f"[{row.index:2d}] {row.name}: PSNR {psnr} after {row.iterations} steps "
            f"({row.train_seconds:.1f} s, {row.seconds_per_iter:.3f} s/step) [{row.status}]")


def run_study(grid: Grid, scene_path: str | Path, out_dir: str | Path, device: torch.device | str,
              overrides: dict[str, Any] | None = None, command: str = "", show_progress: bool = True,
              log: Callable[[str], None] = print) -> list[ResultRow]:
    """Run every combination of `grid` into `out_dir`, writing the report after each one.

    All combinations are checked before any is trained, so a typo fails at once.
    """
    from windowshop.study.report import write_report

    for combo in grid.combinations:
        resolve(combo.settings, combo.folder)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    info = study_info(grid, scene_path, overrides or {}, device, command)
    (out_dir / STUDY).write_text(json.dumps({"info": dataclasses.asdict(info),
                                             "grid": _json_roundtrip(dataclasses.asdict(grid))},
                                            indent=2) + "\n")
    rows = []
    for combo in grid.combinations:
        log(f"study {grid.name}: combination {combo.index}/{len(grid.combinations)} {combo.folder}")
        rows.append(run_combination(combo, scene_path, out_dir, device, show_progress))
        log(row_summary(rows[-1]))
        if rows[-1].status != "skipped" or len(rows) == len(grid.combinations):
            write_report(out_dir, grid, rows, info)  # after every new result, so a stop loses none
    return rows
