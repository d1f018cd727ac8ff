"""One job, run in its own process by the worker: the uploaded input through the pipeline.

A job's folder holds `input/` (the checked upload), `work/` (the pipeline's scene and run, removed
when the job ends) and `result/` (video.mp4, poster.jpg, frames/frame_0000.jpg ...), which the API
serves.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import threading
import time
from pathlib import Path

from windowshop.config import PipelineConfig
from windowshop.errors import UserError
from windowshop.overrides import get_path
from windowshop.media import VIDEO_SUFFIXES
from windowshop.service.db import SQLiteJobStore
from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.store import RUNNING, ProgressStore

# The pipeline's stage names, and the job states they put the job in.
STAGE_STATES = {"prepare": "preparing", "fit": "training", "train": "training", "render": "rendering"}
FRAME_NAME = "frame_{:04d}.jpg"  # per-frame images in result/frames, as the turntable writes them
# API name -> file in result/: make_video names the 3D models after the video (video.mp4)
MODEL_FILES = {"model.glb": "video.glb", "model.usdz": "video.usdz"}
FRAME_GLOB = "frame_*.jpg"
# Rough share of a job's time each stage takes, for the time-left estimate.
STAGE_WEIGHTS = {"preparing": 0.3, "training": 0.55, "rendering": 0.15}


class ProgressReporter:
    """Records the pipeline's `on_stage(stage, fraction)` calls as the job's state and time left.

    The estimate extrapolates the time spent so far over the job's weighted progress, counting only
    the stages this job runs (a posed scene skips "preparing"). Writes are throttled to one every
    `min_interval` seconds, except stage changes and stage ends.
    """

    def __init__(self, store: ProgressStore, job_id: str, run_token: str, clock=time.monotonic,
                 min_interval: float = 0.5):
        self.store, self.job_id, self.run_token = store, job_id, run_token
        self.clock, self.min_interval = clock, min_interval
        self.started = clock()
        self.stages: dict[str, float] = {}
        self.state: str | None = None
        self._last_write = float("-inf")
        self._lock = threading.Lock()

    def __call__(self, stage: str, fraction: float) -> None:
        with self._lock:  # the pipeline reports the fit's progress from a helper thread
            self._record(stage, fraction)

    def _record(self, stage: str, fraction: float) -> None:
        state = STAGE_STATES.get(stage, stage)
        if state not in RUNNING:
            return
        fraction = min(max(float(fraction), 0.0), 1.0)
        changed = state != self.state
        if changed:
            for earlier in self.stages:  # a later stage began: the earlier ones are over
                self.stages[earlier] = 1.0
            self.state = state
        self.stages[state] = fraction
        now = self.clock()
        if changed or fraction >= 1.0 or now - self._last_write >= self.min_interval:
            self._last_write = now
            self.store.report(self.job_id, self.run_token, state, fraction, dict(self.stages),
                              self.eta_seconds(now))

    def overall(self) -> float:
        """The job's progress in [0, 1] over the stages it runs."""
        first = RUNNING.index(next(iter(self.stages))) if self.stages else 0
        runs = RUNNING[first:]
        total = sum(STAGE_WEIGHTS[s] for s in runs)
        return sum(STAGE_WEIGHTS[s] * self.stages.get(s, 0.0) for s in runs) / total

    def eta_seconds(self, now: float) -> float | None:
        done, elapsed = self.overall(), now - self.started
        if done < 0.02 or elapsed < 1.0:  # too early to say anything useful
            return None
        return round(elapsed * (1.0 - done) / done, 1)


def reset_folders(folder: Path) -> tuple[Path, Path]:
    """Empty `work/` and `result/` (a requeued job starts over); returns them."""
    work, result = folder / "work", folder / "result"
    for path in (work, result):
        shutil.rmtree(path, ignore_errors=True)
        path.mkdir(parents=True)
    return work, result


def pipeline_input(folder: Path) -> Path:
    """What the pipeline reads: the input folder, the one folder a zip held, or the video file."""
    entries = list((folder / "input").iterdir())
    if len(entries) == 1 and (entries[0].is_dir() or entries[0].suffix in VIDEO_SUFFIXES):
        return entries[0]
    return folder / "input"


# Settings an upload may only lower: the service's own values bound each job's time and size.
CAPPED = ("fit.seconds", "fit.iters", "deadline", "scene.max_side", "prepare.max_side",
          "render.frames", "render.width", "render.height", "fit.memory_budget",
          "render.memory_budget")
JOB_CONFIG = "job.json"  # in the job's folder: its PipelineConfig when the upload chose settings


def job_config(settings: ServiceSettings, overrides: dict) -> PipelineConfig:
    """The service's job config with an upload's `overrides` (dotted keys, as `--set`); UserError
    for an unknown or ill-typed setting, or one that raises a capped budget or size."""
    from windowshop.model import apply_run_overrides

    config = apply_run_overrides(settings.job, overrides, "settings")
    for path in CAPPED:
        limit, asked = get_path(settings.job, path), get_path(config, path)
        if limit is not None and (asked is None or asked > limit):
            raise UserError(f"settings: {path} may be at most {limit} on this service, got {asked}")
    if config.render.background == "transparent":
        raise UserError("settings: the service serves MP4 turntables, which have no alpha; a "
                        "transparent one is `windowshop video ... --out spin.webm --background "
                        "transparent`")
    return config


def save_job_config(folder: Path, config: PipelineConfig) -> None:
    (folder / JOB_CONFIG).write_text(json.dumps(dataclasses.asdict(config)))


def load_job_config(folder: Path, settings: ServiceSettings) -> PipelineConfig:
    """The job's own config (saved at upload), else the service's."""
    from pydantic import TypeAdapter

    path = folder / JOB_CONFIG
    if not path.is_file():
        return settings.job
    return TypeAdapter(PipelineConfig).validate_python(json.loads(path.read_text()))


def run_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    """The worker's job function: the pipeline on the job's input; returns the frame count."""
    from windowshop.device import pick_device
    from windowshop.pipeline import make_video

    folder = job_dir(settings, job_id)
    work, result = reset_folders(folder)
    report = ProgressReporter(SQLiteJobStore(settings.db_path), job_id, run_token)
    make_video(pipeline_input(folder), result / "video.mp4", load_job_config(folder, settings),
               work_dir=work,
               device=pick_device(settings.device), poster=str(result / "poster.jpg"),
               frames_dir=result / "frames", on_stage=report, show=False)
    shutil.rmtree(work, ignore_errors=True)  # the scene and the trained run: not served, and large
    return len(list((result / "frames").glob(FRAME_GLOB)))
