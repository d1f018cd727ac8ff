"""The worker: a process apart from the web process that runs the queued jobs.

Each job runs in a child process of its own (spawned, so torch starts clean), which the worker
kills when the job is cancelled or deleted, or when the worker itself has to stop. Only one worker
serves a data folder at a time (an exclusive lock on `worker.lock`); when it starts, jobs that were
running when the previous one died go back to the queue. Processes left behind by a killed service
notice that their parent is gone and exit.
"""

from __future__ import annotations

import fcntl
import logging
import multiprocessing
import os
import secrets
import shutil
import signal
import threading
import time
import traceback
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Callable

from windowshop.errors import UserError, failure_reason, is_transient
from windowshop.service.db import SQLiteJobStore
from windowshop.service.jobs import run_job
from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.store import DONE, FAILED

log = logging.getLogger("windowshop.service")

# A job function runs one job to its end and returns the number of per-frame images it made:
# (settings, job id, run token) -> frames. It raises UserError for problems the user can fix.
JobFunction = Callable[[ServiceSettings, str, str], int]


class Worker:
    """Runs up to `settings.concurrency` jobs at once; `step()` is one look at the queue."""

    def __init__(self, settings: ServiceSettings, job_fn: JobFunction):
        self.settings, self.job_fn = settings, job_fn
        self.store = SQLiteJobStore(settings.db_path)
        self.running: dict[str, tuple[BaseProcess, str]] = {}  # job id -> (process, run token)
        self._spawn = multiprocessing.get_context("spawn")

    def start(self) -> None:
        """Put the jobs a dead worker left running back in the queue."""
        requeued, failed = self.store.requeue_interrupted()
        for job_id in requeued:
            log.info("job %s was interrupted; it is queued again", job_id)
        for job_id in failed:
            log.warning("job %s was interrupted too often; it failed", job_id)

    def step(self) -> None:
        self._reap()
        self._stop_abandoned()
        self._launch()

    def stop(self) -> None:
        """Kill the running jobs' processes and put their jobs back in the queue, to start over."""
        for job_id, (process, token) in self.running.items():
            process.kill()
            process.join()
            self.store.release(job_id, token)
        self.running.clear()

    def _launch(self) -> None:
        while len(self.running) < self.settings.concurrency:
            token = secrets.token_hex(8)
            job = self.store.claim_next(token)
            if job is None:
                return
            process = self._spawn.Process(target=_job_main, name=f"windowshop-job-{job.id[:8]}",
                                          args=(self.job_fn, self.settings, job.id, token, os.getpid()))
            process.start()
            self.running[job.id] = (process, token)
            log.info("job %s started (attempt %d)", job.id, job.attempts)

    def _reap(self) -> None:
        """Forget finished processes; a process that died without ending its job (killed, as by the
        OOM killer) puts the job back in the queue, or fails it after MAX_ATTEMPTS tries."""
        for job_id, (process, token) in list(self.running.items()):
            if process.is_alive():
                continue
            process.join()
            del self.running[job_id]
            if process.exitcode != 0:  # killed (the OOM killer?): a transient fault, tried again
                self.store.retry(job_id, token, error=f"the job stopped unexpectedly (exit code "
                                 f"{process.exitcode}, out of memory?); try fewer or smaller photos")
            self._clean_up(job_id)

    def _stop_abandoned(self) -> None:
        """Kill the processes of jobs cancelled or deleted since they started."""
        for job_id, (process, token) in list(self.running.items()):
            job = self.store.get(job_id)
            if job is not None and job.run_token == token:
                continue
            process.kill()
            process.join()
            del self.running[job_id]
            log.info("job %s stopped (%s)", job_id, "deleted" if job is None else job.state)
            self._clean_up(job_id)

    def _clean_up(self, job_id: str) -> None:
        """Remove the folder of a deleted job, and the work files of a cancelled one."""
        job = self.store.get(job_id)
        folder = job_dir(self.settings, job_id)
        if job is None:
            shutil.rmtree(folder, ignore_errors=True)
        elif job.state != DONE and job.run_token is None:
            shutil.rmtree(folder / "work", ignore_errors=True)


def run_worker(settings: ServiceSettings, parent_pid: int, job_fn: JobFunction | None = None) -> None:
    """The worker process: loop over the queue until told to stop or the web process is gone."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s worker %(levelname)s %(message)s")
    stopping = threading.Event()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the web process, which stops us
    signal.signal(signal.SIGTERM, lambda *_: stopping.set())
    if job_fn is None:
        job_fn = run_job
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    with open(settings.data_dir / "worker.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # waits for a worker of a killed service to exit
        worker = Worker(settings, job_fn)
        worker.start()
        while not stopping.is_set() and os.getppid() == parent_pid:
            worker.step()
            stopping.wait(settings.poll_seconds)
        worker.stop()


def _job_main(job_fn: JobFunction, settings: ServiceSettings, job_id: str, token: str,
              parent_pid: int) -> None:
    """A job's process: run `job_fn` and record how it ended."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with_parent(parent_pid)
    store = SQLiteJobStore(settings.db_path)
    try:
        frames = job_fn(settings, job_id, token)
    except UserError as err:  # the user's to fix: failed at once, never tried again
        store.finish(job_id, token, FAILED, error=str(err))
    except Exception as err:  # noqa: BLE001 - any bug must end as a failed job, not a hung one
        _write_error_log(job_dir(settings, job_id) / "error.log")
        if is_transient(err):
            store.retry(job_id, token, failure_reason(err))
        else:
            store.finish(job_id, token, FAILED, error=failure_reason(err))
    else:
        store.finish(job_id, token, DONE, frames=frames)


def _write_error_log(path: Path) -> None:
    """The traceback beside the job, for its operator; skipped when the disk itself is full."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(traceback.format_exc())
    except OSError:
        pass


def _exit_with_parent(parent_pid: int, period: float = 0.5) -> None:
    """End this process soon after its parent dies (a killed service must not leave jobs running)."""
    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(period)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="parent-watch").start()
