"""Stages of a long job, shown as lines and progress bars on stderr and reported to a callback.

The callback (`on_stage(stage, fraction)`) is how the web service follows a job; the bars are
for a person at a terminal. Each stage's duration is kept for the report and the benchmark.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from windowshop.progress import bar as progress_bar

StageCallback = Callable[[str, float], None]


class Stages:
    """Times named stages; `stage(...)` yields an `advance(n=1)` function for its progress.

    `report_as` is the stage name given to `on_stage` (a whole `prepare` is one pipeline stage,
    "prepare"); `fractions` maps this object's own stage names to the part of that pipeline
    stage each covers, so the fraction reported climbs from 0 to 1 over all of them.
    """

    def __init__(self, on_stage: StageCallback | None = None, show: bool = True,
                 report_as: str = "prepare", fractions: dict[str, float] | None = None):
        self.on_stage, self.show, self.report_as = on_stage, show, report_as
        self.fractions = fractions or {}
        self.seconds: dict[str, float] = {}
        self._done = 0.0  # fraction of the pipeline stage finished by earlier stages

    def _report(self, fraction: float) -> None:
        if self.on_stage is not None:
            self.on_stage(self.report_as, min(max(fraction, 0.0), 1.0))

    @contextmanager
    def stage(self, name: str, total: int | None = None) -> Iterator[Callable[[int], None]]:
        """Run one stage; `total` steps draws a bar (None: a line only)."""
        share = self.fractions.get(name, 0.0)
        start = time.perf_counter()
        bar = progress_bar(total=total, desc=name, unit="", leave=False,
                           show=self.show and total is not None)
        count = 0

        def advance(n: int = 1) -> None:
            nonlocal count
            count += n
            if not total:
                bar.update(n)
                return
            # the mapper calls back again for each start it tries, past the photos' count
            # (fruit's 80 turned photos: "placing cameras: 456/80"): the bar stops when full
            bar.update(min(count, total) - min(count - n, total))
            self._report(self._done + share * min(count / total, 1.0))

        self._report(self._done)
        try:
            yield advance
        finally:
            bar.close()
        self.seconds[name] = time.perf_counter() - start
        self._done += share
        self._report(self._done)
        if self.show:
            print(f"{name}: {self.seconds[name]:.1f} s", file=sys.stderr)
