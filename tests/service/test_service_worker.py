"""The worker's lifecycle and the job store, with small job functions standing in for the pipeline.

The job functions below run in the worker's spawned job processes (imported from this module);
the real pipeline runs in test_service_restart.py and test_e2e_browser.py.
"""

from __future__ import annotations

import errno
import json
import os
import time
from pathlib import Path

import pytest

from windowshop.errors import UserError
from windowshop.service.db import MAX_ATTEMPTS, SQLiteJobStore
from windowshop.service.jobs import ProgressReporter
from windowshop.config import FitConfig
from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.worker import Worker


def _mark(settings: ServiceSettings, job_id: str, what: str) -> None:
    """Append `what` and the time to the job's marks file (read by the tests)."""
    with open(settings.data_dir / f"{job_id}.marks", "a") as f:
        f.write(json.dumps([what, time.time()]) + "\n")


def quick_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    _mark(settings, job_id, "start")
    time.sleep(0.6)
    reporter = ProgressReporter(SQLiteJobStore(settings.db_path), job_id, run_token)
    reporter("render", 1.0)
    _mark(settings, job_id, "end")
    return 7


def endless_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    (job_dir(settings, job_id) / "work").mkdir(parents=True, exist_ok=True)
    reporter = ProgressReporter(SQLiteJobStore(settings.db_path), job_id, run_token, min_interval=0)
    reporter("fit", 0.25)
    _mark(settings, job_id, "start")
    time.sleep(600)
    return 0


def refusing_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    raise UserError("only 2 of 12 photos could be placed; take more photos with overlap")


def buggy_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    return {}["missing"]


def crashing_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    os._exit(3)  # as a segfault or the kernel's out-of-memory killer would end it


def disk_full_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    """Fails as writing the results would on a full disk (the edge faked: no tmpfs without root)."""
    result = job_dir(settings, job_id) / "result"
    result.mkdir(parents=True, exist_ok=True)
    (result / "poster.jpg").write_bytes(b"half")
    raise OSError(errno.ENOSPC, "No space left on device", str(result / "video.mp4"))


def once_out_of_memory_job(settings: ServiceSettings, job_id: str, run_token: str) -> int:
    _mark(settings, job_id, "start")
    if len(marks(settings, job_id)) == 1:
        raise MemoryError("cannot allocate 12 GiB")
    return 5


def marks(settings: ServiceSettings, job_id: str) -> list:
    path = settings.data_dir / f"{job_id}.marks"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def run_until(worker: Worker, condition, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "the worker did not get there in time"
        worker.step()
        time.sleep(0.05)


@pytest.fixture
def make_worker(tmp_path):
    workers = []

    def make(job_fn, **overrides) -> Worker:
        settings = ServiceSettings(data_dir=tmp_path / "data", **overrides)
        worker = Worker(settings, job_fn)
        worker.start()
        workers.append(worker)
        return worker

    yield make
    for worker in workers:
        worker.stop()


def add_jobs(worker: Worker, n: int) -> list[str]:
    ids = [f"job{i:02d}-0123456789abcdef" for i in range(n)]
    for job_id in ids:
        (job_dir(worker.settings, job_id) / "input").mkdir(parents=True)
        worker.store.create(job_id, "photos", "3 photos")
        time.sleep(0.002)  # distinct creation times keep the queue's order
    return ids


def state(worker: Worker, job_id: str) -> str | None:
    job = worker.store.get(job_id)
    return job.state if job else None


@pytest.mark.parametrize("concurrency", [1, 2])
def test_jobs_run_to_done_one_at_a_time_unless_configured(make_worker, concurrency):
    worker = make_worker(quick_job, concurrency=concurrency)
    ids = add_jobs(worker, 3)
    run_until(worker, lambda: all(state(worker, i) == "done" for i in ids))
    job = worker.store.get(ids[0])
    assert (job.frames, job.error, job.stages, job.run_token) == (7, None, {"rendering": 1.0}, None)
    spans = sorted((marks(worker.settings, i)[0][1], marks(worker.settings, i)[1][1]) for i in ids)
    overlaps = sum(later[0] < earlier[1] for earlier, later in zip(spans, spans[1:]))
    assert overlaps == 0 if concurrency == 1 else overlaps >= 1
    started = [worker.store.get(i).started_at for i in ids]
    assert started == sorted(started)  # claimed in the queue's order


@pytest.mark.parametrize("job_fn, message, attempts", [
    (refusing_job, "only 2 of 12 photos could be placed; take more photos with overlap", 1),
    (buggy_job, "internal error (KeyError: 'missing')", 1),
    (disk_full_job, "the service's disk filled up while the job wrote its files", 1),
    # a killed process is a transient fault (the OOM killer?): tried MAX_ATTEMPTS times
    (crashing_job, f"the job failed {MAX_ATTEMPTS} times; last error: the job stopped "
                   "unexpectedly (exit code 3", MAX_ATTEMPTS),
])
def test_failures_end_the_job_with_a_message(make_worker, job_fn, message, attempts):
    worker = make_worker(job_fn)
    [job_id] = add_jobs(worker, 1)
    run_until(worker, lambda: state(worker, job_id) == "failed")
    job = worker.store.get(job_id)
    assert job.error.startswith(message) and job.attempts == attempts
    if job_fn is buggy_job:
        assert "KeyError" in (job_dir(worker.settings, job_id) / "error.log").read_text()
    run_until(worker, lambda: not worker.running)


def test_out_of_memory_is_tried_again_and_the_job_completes(make_worker):
    worker = make_worker(once_out_of_memory_job)
    [job_id] = add_jobs(worker, 1)
    run_until(worker, lambda: state(worker, job_id) == "done")
    job = worker.store.get(job_id)
    assert (job.attempts, job.frames, len(marks(worker.settings, job_id))) == (2, 5, 2)


def test_cancel_stops_the_running_process(make_worker):
    worker = make_worker(endless_job)
    first, second = add_jobs(worker, 2)
    run_until(worker, lambda: marks(worker.settings, first))
    job = worker.store.get(first)
    assert (job.state, job.stage, job.progress, job.stages) == ("training", "training", 0.25,
                                                                {"training": 0.25})
    process = worker.running[first][0]
    assert worker.store.cancel(first).state == "cancelled"
    run_until(worker, lambda: not process.is_alive() and second in worker.running)
    assert state(worker, first) == "cancelled"
    assert not (job_dir(worker.settings, first) / "work").exists()  # partial work removed
    assert (job_dir(worker.settings, first) / "input").is_dir()


def test_deleting_a_running_job_stops_it_and_removes_its_files(make_worker):
    worker = make_worker(endless_job)
    [job_id] = add_jobs(worker, 1)
    run_until(worker, lambda: marks(worker.settings, job_id))
    process = worker.running[job_id][0]
    worker.store.delete(job_id)
    run_until(worker, lambda: not worker.running)
    assert not process.is_alive()
    assert not job_dir(worker.settings, job_id).exists()


def test_an_orderly_stop_puts_running_jobs_back_without_counting_a_try(make_worker):
    worker = make_worker(endless_job)
    [job_id] = add_jobs(worker, 1)
    run_until(worker, lambda: marks(worker.settings, job_id))
    process = worker.running[job_id][0]
    worker.stop()
    assert not process.is_alive()
    job = worker.store.get(job_id)
    assert (job.state, job.attempts, job.run_token) == ("queued", 0, None)


def test_start_requeues_interrupted_jobs_and_gives_up_after_a_few(tmp_path):
    settings = ServiceSettings(data_dir=tmp_path)
    store = SQLiteJobStore(settings.db_path)
    for job_id in ("a" * 22, "b" * 22, "c" * 22):
        store.create(job_id, "photos", "3 photos")
    old = store.claim_next("old-token")  # "a": running when its worker died
    assert old.id == "a" * 22 and old.state == "preparing"
    store.cancel("c" * 22)
    worker = Worker(settings, quick_job)
    worker.start()
    assert [state(worker, i * 22) for i in "abc"] == ["queued", "queued", "cancelled"]
    assert not store.report(old.id, "old-token", "training", 0.5, {}, None)  # a stale process
    assert not store.finish(old.id, "old-token", "done")
    assert state(worker, old.id) == "queued"
    for attempt in range(2, MAX_ATTEMPTS + 1):
        assert store.claim_next(f"token-{attempt}").attempts == attempt
        store.requeue_interrupted()
    assert store.get(old.id).state == "failed" and "interrupted" in store.get(old.id).error


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_progress_reporter_states_and_time_left(tmp_path):
    store = SQLiteJobStore(tmp_path / "jobs.sqlite3")
    store.create("j" * 22, "photos", "12 photos")
    store.claim_next("t")
    clock = Clock()
    report = ProgressReporter(store, "j" * 22, "t", clock=clock, min_interval=1.0)
    clock.now = 10.0
    report("prepare", 0.5)  # weights 0.3 / 0.55 / 0.15: 0.15 of the job in 10 s
    job = store.get("j" * 22)
    assert (job.state, job.stage, job.progress) == ("preparing", "preparing", 0.5)
    assert job.eta_seconds == pytest.approx(10 * 0.85 / 0.15, abs=0.1)
    clock.now = 10.5
    report("prepare", 0.6)  # within min_interval: not written
    assert store.get("j" * 22).progress == 0.5
    clock.now = 20.0
    report("fit", 0.0)  # a new stage: written at once, the earlier one is over
    job = store.get("j" * 22)
    assert job.state == "training" and job.stages == {"preparing": 1.0, "training": 0.0}
    assert job.eta_seconds == pytest.approx(20 * 0.7 / 0.3, abs=0.1)
    report("something else", 0.3)  # names that are no stage are ignored
    assert store.get("j" * 22).state == "training"


def test_progress_of_a_posed_scene_counts_only_the_stages_it_runs(tmp_path):
    store = SQLiteJobStore(tmp_path / "jobs.sqlite3")
    store.create("p" * 22, "zip", "a posed scene")
    store.claim_next("t")
    clock = Clock()
    report = ProgressReporter(store, "p" * 22, "t", clock=clock)
    clock.now = 0.0
    report("fit", 0.0)
    assert store.get("p" * 22).eta_seconds is None  # nothing to extrapolate from yet
    clock.now = 30.0
    report("fit", 0.5)  # half of training is 0.5 * 0.55 / 0.7 of this job
    done = 0.5 * 0.55 / 0.7
    assert store.get("p" * 22).eta_seconds == pytest.approx(30 * (1 - done) / done, abs=0.1)
    assert "preparing" not in store.get("p" * 22).stages
    assert Path(store.path).exists()


def test_service_settings_reach_the_pipeline(monkeypatch, tmp_path):
    from windowshop.config import PipelineConfig
    from windowshop.errors import UserError
    from windowshop.service.jobs import job_config, load_job_config, save_job_config

    assert ServiceSettings().job == PipelineConfig()  # the pipeline's own defaults
    monkeypatch.setenv("WINDOWSHOP_JOB__FIT__ITERS", "100")
    monkeypatch.setenv("WINDOWSHOP_JOB__FIT__SECONDS", "none")
    monkeypatch.setenv("WINDOWSHOP_JOB__RENDER__FRAMES", "8")
    monkeypatch.setenv("WINDOWSHOP_JOB__MODEL", "nerf")
    job = ServiceSettings().job  # each field is an environment variable by its dotted path
    assert (job.fit.iters, job.fit.seconds, job.render.frames, job.model) == (100, None, 8, "nerf")
    # An upload's settings: the same dotted keys, typed, and only lower budgets than the service's
    settings = ServiceSettings(job=PipelineConfig())
    mine = job_config(settings, {"render.frames": 12, "fit.seconds": 5, "voxel_pixels": 2})
    assert (mine.render.frames, mine.fit.seconds, mine.model_settings) == (12, 5.0, {"voxel_pixels": 2})
    with pytest.raises(UserError, match="fit.seconds may be at most 30"):
        job_config(settings, {"fit.seconds": 600})
    with pytest.raises(UserError, match="fit.iters may be at most"):
        job_config(ServiceSettings(job=PipelineConfig(fit=FitConfig(iters=50, seconds=None))),
                   {"seconds": 5})  # a time budget would lift the service's step cap
    with pytest.raises(UserError, match="render.memory_budget may be at most"):
        job_config(settings, {"render.memory_budget": 64 * 2**30})  # memory is the service's too
    with pytest.raises(UserError, match="must be an integer"):
        job_config(settings, {"render.frames": "many"})
    with pytest.raises(UserError, match="MP4 turntables, which have no alpha"):
        job_config(settings, {"render.background": "transparent"})
    save_job_config(tmp_path, mine)
    assert load_job_config(tmp_path, settings) == mine
