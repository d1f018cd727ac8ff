"""What a study writes and reads back: its file names, a result row and the study's circumstances.

`runner` writes them and `report` reads them; both import them from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

RUNS = "runs"
STUDY = "study.json"
ROW = "study_row.json"
VIEW = "study_view.png"
TRUTH = "truth_view.png"


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
