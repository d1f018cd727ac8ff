"""What a caller of `fit` hears from the training loop, and how it asks it to stop.

The web service and `windowshop video` follow a fit through these hooks rather than by reading
`log.jsonl`; a cancel request is honoured between steps, after a checkpoint, so the run resumes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from windowshop.errors import UserError


class FitCancelled(UserError):
    """`fit` stopped because `FitCallbacks.should_stop` said so; the run folder holds a checkpoint
    of the last step, so `fit(..., resume=run_dir)` carries on from it."""

    def __init__(self, step: int, run_dir: Path):
        super().__init__(f"cancelled at step {step}; carry on with --resume {run_dir}")
        self.step, self.run_dir = step, run_dir


@dataclass(frozen=True)
class FitCallbacks:
    """Optional hooks called by the trainer, all from the training thread.

    `on_step(fraction, stats)` after every step: the budget used so far in [0, 1] (non-decreasing,
    1.0 on the last step) and the step's log record. `on_checkpoint(path)` after each checkpoint
    is written. `should_stop()` after every step: True stops training with `FitCancelled`.
    """

    on_step: Callable[[float, dict], None] | None = None
    on_checkpoint: Callable[[Path], None] | None = None
    should_stop: Callable[[], bool] | None = None

    def stepped(self, fraction: float, stats: dict) -> None:
        if self.on_step is not None:
            self.on_step(min(fraction, 1.0), stats)

    def checkpointed(self, path: Path) -> None:
        if self.on_checkpoint is not None:
            self.on_checkpoint(path)

    def stop_requested(self) -> bool:
        return self.should_stop is not None and bool(self.should_stop())
