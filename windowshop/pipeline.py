"""`windowshop video`: photos, a video or a posed scene -> a 360° turntable MP4, in one call.

    make_video(input, "spin.mp4")  =  prepare (unless the input is already posed)
                                   -> fit (the fast model, a short budget)
                                   -> render (an orbit turntable, poster, optional frames)
                                   -> export (spin.glb and spin.usdz, unless config.models is off)

The CLI and the web service both call `make_video`; it reports progress through
`on_stage(stage, fraction)` with stage "prepare", "fit" or "render" and fraction in [0, 1].
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import torch

from windowshop.config import FitConfig, PipelineConfig
from windowshop.errors import UserError
from windowshop.photos.progress import StageCallback

MARKER = "video.json"  # the summary a work folder of make_video holds (and may be replaced by)
# What the deadline sets aside after training, measured on a 2-core CPU (bench/bench_real.py):
# the fit's own work around its steps (carving, the held-out photos with 3 cameras refined,
# the checkpoint) ...
FIT_OVERHEAD_SECONDS = 6.0
RENDER_RAYS_PER_SECOND = 5e5  # ... the turntable, rendered and encoded at this many pixels/s ...
# ... and the GLB and USDZ when asked for: 5-14 s for 11-20 photos on the ordinary-CPU profile
# (bench/bench_real.py under bench/cpu_profile.py ordinary; bench/RESULTS.md, issue 35)
EXPORT_SECONDS = 12.0


@dataclass
class VideoResult:
    mp4: Path
    poster: Path | None
    scene_dir: Path
    run_dir: Path
    seconds: dict[str, float]  # stage -> seconds
    metrics: dict  # the fit's held-out metrics
    report: dict  # the capture's quality report (windowshop.quality), also at report_path
    report_path: Path
    models: list[Path]  # the 3D models beside the video (GLB, USDZ); none when config.models is off


def is_posed_scene(path: Path) -> bool:
    """True when `path` is a scene with camera poses that `load_scene` reads."""
    from windowshop.scene import detect_format

    try:
        detect_format(path)
    except UserError:
        return False
    return True


def _work_dir(work: Path) -> Path:
    """An empty work folder; an earlier make_video's (holding MARKER) is replaced."""
    if work.exists() and any(work.iterdir()):
        if not (work / MARKER).is_file():
            raise UserError(f"{work}: the work folder exists and is not from `windowshop video`; "
                            f"choose another --work folder")
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    (work / MARKER).write_text("{}")
    return work


def fit_within_deadline(config: PipelineConfig, spent: float) -> FitConfig:
    """The fit's settings with its time budget cut so that a job which has `spent` seconds
    before training still ends by `config.deadline` (estimating the rest: the fit's overhead,
    the turntable and, when asked for, the 3D models), to no less than
    `config.min_fit_seconds`; unchanged without a deadline or for a budget in steps."""
    fit, render = config.fit, config.render
    if config.deadline is None or fit.seconds is None:
        return fit
    after = (FIT_OVERHEAD_SECONDS + render.frames * render.width * render.height / RENDER_RAYS_PER_SECOND
             + (EXPORT_SECONDS if config.models else 0.0))
    left = config.deadline - spent - after
    return replace(fit, seconds=max(config.min_fit_seconds, min(fit.seconds, left)))


def make_video(source: str | Path, out_mp4: str | Path, config: PipelineConfig = PipelineConfig(),
               work_dir: str | Path | None = None, device: torch.device | str = "cpu",
               poster: bool | str = True, frames_dir: str | Path | None = None,
               on_stage: StageCallback | None = None, show: bool = True) -> VideoResult:
    """Photos (folder or zip), a video, or a posed scene at `source` -> the turntable `out_mp4`,
    every stage set by `config`.

    `work_dir` (default: `<out stem>_work` beside the MP4) keeps the posed scene (`scene/`) and
    the trained run (`run/`). `poster` writes the best-covered frame beside the MP4 (True) or to a
    path; `frames_dir` also writes every frame as a JPEG (PNG with alpha when transparent) there.
    The capture's quality report goes beside the video (`<stem>_report.json`, `<stem>_coverage.png`). `on_stage(stage, fraction)` is called
    with stage "prepare" (skipped for a posed scene), "fit" (after every training step) and "render"
    as each advances. Prints each stage and its time when `show`.
    """
    from windowshop.fit.callbacks import FitCallbacks
    from windowshop.fit.trainer import fit
    from windowshop.model import model_config
    from windowshop.photos.prepare import prepare
    from windowshop.scene import load_scene
    from windowshop.video.turntable import default_outputs, render_run
    from windowshop.quality import quality_report, summary_lines, write_quality_report

    source, out_mp4 = Path(source), Path(out_mp4)
    if not source.exists():
        raise UserError(f"{source}: no such file or folder")
    check_output(out_mp4, config.render.background)
    work = _work_dir(Path(work_dir) if work_dir else out_mp4.with_name(f"{out_mp4.stem}_work"))
    out_mp4.parent.mkdir(parents=True, exist_ok=True)
    report = on_stage or (lambda stage, fraction: None)
    seconds: dict[str, float] = {}

    def done(stage: str, start: float) -> None:
        seconds[stage] = time.perf_counter() - start
        report(stage, 1.0)
        if show:
            print(f"{stage}: {seconds[stage]:.1f} s", file=sys.stderr)

    start = time.perf_counter()
    scene_dir = source
    if not is_posed_scene(source):
        scene_dir = prepare(source, work / "scene", config.prepare, on_stage, show).out_dir
        done("prepare", start)

    start = time.perf_counter()
    report("fit", 0.0)
    fit_config = fit_within_deadline(config, sum(seconds.values()))
    prepared = scene_dir != source
    if show and fit_config.seconds != config.fit.seconds:
        print(f"fit: training for {fit_config.seconds:.0f} s instead of {config.fit.seconds:.0f} s to "
              f"be done in about {config.deadline:.0f} s (prepare took {seconds['prepare']:.0f} s; "
              "--deadline none trains for the whole budget)", file=sys.stderr)
    scene = load_scene(scene_dir, config.scene)
    model = model_config(config.model, config.preset, **config.model_settings)
    metrics = fit(scene, config.model, model, replace(fit_config, refine_held_out=prepared), work / "run",
                  device, show_progress=show,
                  callbacks=FitCallbacks(on_step=lambda fraction, stats: report("fit", fraction)))
    done("fit", start)
    held_out = _held_out(metrics, config.prepare.force) if prepared else None

    start = time.perf_counter()
    report("render", 0.0)
    transparent = config.render.background == "transparent"
    outputs = default_outputs(out_mp4, poster=poster, frames_dir=frames_dir, transparent=transparent,
                              frames_format="png" if transparent else "jpg")
    rendered = render_run(work / "run", config.render, outputs, device, progress=show,
                          on_frame=lambda k, n: report("render", k / n))
    done("render", start)

    quality = quality_report(scene, metrics, rendered.path, _prepare_report(scene_dir, source),
                             held_out)
    report_path, _ = write_quality_report(out_mp4.with_name(f"{out_mp4.stem}_report.json"), quality)

    models = _export(work / "run", out_mp4, config, device, seconds, show) if config.models else []
    result = VideoResult(mp4=out_mp4, poster=outputs.poster, scene_dir=Path(scene_dir),
                         run_dir=work / "run", seconds=seconds, metrics=metrics, report=quality,
                         report_path=report_path, models=models)
    (work / MARKER).write_text(json.dumps({**asdict(result), "config": asdict(config)},
                                          indent=2, default=str))
    if show:
        print("\n".join(summary_lines(quality)), file=sys.stderr)
        names = ", ".join(p.name for p in [report_path, *models])
        print(f"wrote {out_mp4} and {names} in {sum(seconds.values()):.0f} s", file=sys.stderr)
    return result


def _held_out(metrics: dict, force: bool) -> dict | None:
    """The held-out check of a capture prepared here (windowshop.photos.verify.heldout), for the
    quality report; UserError when it fails, unless `force`."""
    from windowshop.photos.verify import heldout

    check = heldout.check(metrics)
    if check is None:
        return None
    if not check.passed and not force:
        raise UserError(f"the result could not be verified: {check.detail}. "
                        f"{check.advice[0].upper()}{check.advice[1:]}. --force delivers it "
                        f"anyway, marked as unverified")
    return check.as_report()


def _export(run_dir: Path, out_mp4: Path, config: PipelineConfig, device: torch.device | str,
            seconds: dict[str, float], show: bool) -> list[Path]:
    """The run's object as `<stem>.glb` and `<stem>.usdz` beside the video (within the render
    stage's progress: the service knows three stages). A field with no surface to export costs
    the models, not the video: it is said and skipped."""
    from windowshop.export.command import export_models

    start = time.perf_counter()
    models = [out_mp4.with_suffix(".glb"), out_mp4.with_suffix(".usdz")]
    try:
        export_models(run_dir, models, config.export, device)
    except UserError as err:
        if show:
            print(f"export: skipped: {err}", file=sys.stderr)
        return []
    seconds["export"] = time.perf_counter() - start
    if show:
        print(f"export: {seconds['export']:.1f} s", file=sys.stderr)
    return models


def _prepare_report(scene_dir: Path, source: Path) -> dict | None:
    """What prepare said of the photos (None when the input was already a posed scene)."""
    path = Path(scene_dir) / "report.json"
    return json.loads(path.read_text()) if Path(scene_dir) != source and path.is_file() else None


def check_output(out: Path, background: str) -> None:
    """Refuse, before any work, a video file that cannot hold what was asked."""
    from windowshop.video.turntable import check_video_name

    check_video_name(out)
    if (background == "transparent") != (out.suffix.lower() == ".webm"):
        raise UserError(f"{out}: a transparent turntable is written as .webm (VP9 with alpha), "
                        f"any other as .mp4; name the output accordingly")
