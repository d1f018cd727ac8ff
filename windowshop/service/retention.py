"""Keeping the service's disk in bounds: expired jobs are deleted, uploads refused when space is short.

`sweep_expired` deletes the jobs that ended more than `retention_days` ago (the row first, then the
folder, so no job is ever visible without its files) and the folders an interrupted upload left
without a row. The service runs it every `retention_check_seconds` (a `Sweeper` thread of the web
process, which also runs the distributed mode's sweep); it can also be called on its own.
"""

from __future__ import annotations

import logging
import shutil
import threading
import time
from pathlib import Path
from typing import Callable

from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.store import JobQueue

log = logging.getLogger("windowshop.service")
DAY = 86400.0
# A job folder without a row this old is what an interrupted upload left (an upload that is still
# coming in has a folder and no row yet, but takes minutes at most).
ORPHAN_SECONDS = 3600.0


def sweep_expired(settings: ServiceSettings, store: JobQueue, now: float | None = None) -> list[str]:
    """Delete the jobs that ended before `now - retention_days` and orphaned job folders; returns
    the ids of the deleted jobs (orphans included)."""
    now = time.time() if now is None else now
    removed = []
    for job_id in store.expired(now - settings.retention_days * DAY):
        store.delete(job_id)
        shutil.rmtree(job_dir(settings, job_id), ignore_errors=True)
        removed.append(job_id)
    for folder in settings.jobs_dir.iterdir() if settings.jobs_dir.is_dir() else ():
        if folder.stat().st_mtime < now - ORPHAN_SECONDS and store.get(folder.name) is None:
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder.name)
    if removed:
        log.info("retention: deleted %d expired or orphaned job(s)", len(removed))
    return removed


def folder_bytes(folder: Path) -> int:
    """The size of the files under `folder`."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


class Sweeper:
    """Runs each `(period seconds, function)` in a thread of the web process until `stop()`; a sweep
    that raises is logged and tried again at its next period (a database or broker briefly away)."""

    def __init__(self, sweeps: list[tuple[float, Callable[[], object]]]):
        self.sweeps = sweeps
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True, name="windowshop-sweeper")

    def start(self) -> "Sweeper":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(30)

    def _loop(self) -> None:
        due = [0.0] * len(self.sweeps)
        while self.sweeps and not self._stop.is_set():
            for i, (period, sweep) in enumerate(self.sweeps):
                if time.monotonic() >= due[i]:
                    due[i] = time.monotonic() + period
                    try:
                        sweep()
                    except Exception as err:  # noqa: BLE001 - a sweep must never stop the others
                        first_line = str(err).splitlines()[0] if str(err) else ""
                        log.warning("a sweep failed (%s: %s); tried again in %.0f s",
                                    type(err).__name__, first_line, period)
            self._stop.wait(max(0.0, min(due) - time.monotonic()))
