"""The distributed job store's compare-and-set rules, on SQLite and on a real PostgreSQL server
(tests/conftest.py starts one on loopback when Debian's postgresql is installed), and the gpu-queue routing rule."""

from __future__ import annotations

import time

import pytest

from windowshop.distributed.celery_app import gpu_workers
from windowshop.distributed.store import MAX_ATTEMPTS, PREPARE, TRAIN, ClusterStore, jobs

STALE = 5.0


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request, tmp_path):
    if request.param == "sqlite":
        return ClusterStore(f"sqlite:///{tmp_path / 'cluster.sqlite3'}")
    store = ClusterStore(request.getfixturevalue("postgres_url"))
    with store.engine.begin() as db:
        db.exec_driver_sql("DELETE FROM jobs")
    return store


def _job(store: ClusterStore, phase: str = TRAIN, job_id: str = "job-0123456789abcdef") -> str:
    store.create(job_id, "zip", "a zip", phase, "key")
    return job_id


def test_one_delivery_runs_a_job_a_duplicate_waits_and_only_one_result_counts(store):
    job = _job(store)
    assert store.claim(job, TRAIN, "a", "w1", STALE) == "run"
    assert store.claim(job, TRAIN, "b", "w2", STALE) == "busy"  # "a" is alive (fresh heartbeat)
    assert store.report(job, "a", "rendering", 0.5, {"training": 1.0, "rendering": 0.5}, 3.0)
    assert not store.report(job, "b", "rendering", 0.9, {}, None)
    assert store.finish(job, "a", frames=8)
    assert not store.finish(job, "a", frames=8)  # a repeated upload changes nothing
    assert store.claim(job, TRAIN, "c", "w2", STALE) == "skip"
    row = store.row(job)
    assert (row["state"], row["frames"], row["attempts"], row["worker"]) == ("done", 8, 1, "w1")


def test_a_silent_try_is_taken_over_and_its_late_result_refused(store):
    job = _job(store)
    assert store.claim(job, TRAIN, "a", "w1", STALE) == "run"
    assert store.claim(job, TRAIN, "b", "w2", stale_seconds=0.0) == "run"  # "a" counts as dead
    assert not store.finish(job, "a", frames=8)
    assert store.finish(job, "b", frames=8)
    assert store.row(job)["attempts"] == 2


def test_three_failed_tries_fail_the_job_with_the_last_error(store):
    job = _job(store)
    for attempt in range(1, MAX_ATTEMPTS + 1):
        assert store.claim(job, TRAIN, f"t{attempt}", "w1", STALE) == "run"
        verdict = store.fail_try(job, f"t{attempt}", f"boom {attempt}")
        assert verdict == ("failed" if attempt == MAX_ATTEMPTS else "retry")
        assert store.get(job).state == ("failed" if attempt == MAX_ATTEMPTS else "queued")
    assert store.get(job).error == f"the job failed {MAX_ATTEMPTS} times; last error: boom 3"
    assert store.claim(job, TRAIN, "t4", "w1", STALE) == "skip"


def test_a_job_whose_workers_keep_dying_fails_at_the_next_delivery(store):
    job = _job(store)
    for attempt in range(MAX_ATTEMPTS):
        assert store.claim(job, TRAIN, f"t{attempt}", "w1", stale_seconds=0.0) == "run"
    assert store.claim(job, TRAIN, "t9", "w2", stale_seconds=0.0) == "skip"
    job_row = store.get(job)
    assert job_row.state == "failed" and "worker running it was lost" in job_row.error


def test_a_users_error_fails_the_job_at_once_with_its_reason(store):
    job = _job(store)
    assert store.claim(job, TRAIN, "t1", "w1", STALE) == "run"
    reason = "only 2 of 12 photos could be placed; take more photos with overlap"
    assert store.fail_try(job, "t1", reason, transient=False) == "failed"
    row = store.row(job)
    assert (row["state"], row["error"], row["attempts"]) == ("failed", reason, 1)
    assert store.claim(job, TRAIN, "t2", "w1", STALE) == "skip"


def test_a_silent_try_is_put_back_in_the_queue_by_the_sweep(store):
    silent, alive = _job(store, job_id="s" * 22), _job(store, job_id="a" * 22)
    assert store.claim(silent, TRAIN, "t1", "w1", STALE) == "run"
    assert store.claim(alive, TRAIN, "u1", "w2", STALE) == "run"
    with store.engine.begin() as db:  # the first try's worker died a minute ago
        db.execute(jobs.update().where(jobs.c.id == silent).values(heartbeat_at=time.time() - 60))
    assert store.requeue_silent(stale_seconds=30) == [silent]
    assert store.requeue_silent(stale_seconds=30) == []  # once: it is queued now
    row = store.row(silent)
    assert (row["state"], row["run_token"], row["attempts"]) == ("queued", None, 1)
    assert "worker running it was lost" in row["error"]
    assert not store.beat(silent, "t1") and not store.finish(silent, "t1", frames=8)  # too late
    assert store.claim(silent, TRAIN, "t2", "w2", STALE) == "run"
    assert store.get(alive).state == "training"  # its heartbeat is fresh


def test_a_job_whose_tries_all_fall_silent_fails(store):
    job = _job(store)
    for attempt in range(MAX_ATTEMPTS):
        assert store.claim(job, TRAIN, f"t{attempt}", "w1", STALE) == "run"
        assert store.requeue_silent(stale_seconds=-1.0) == ([job] if attempt < MAX_ATTEMPTS - 1 else [])
    row = store.row(job)
    assert row["state"] == "failed" and "worker running it was lost" in row["error"]


def test_unsent_jobs_are_listed_until_sent(store):
    first, second = _job(store, job_id="a" * 22), _job(store, job_id="b" * 22)
    assert store.queued() == [first, second] and store.queued(undispatched_only=True) == []
    store.set_dispatched(second, False)  # the broker was away
    assert store.queued(undispatched_only=True) == [second]
    store.set_dispatched(second, True)
    assert store.queued(undispatched_only=True) == []


def test_prepare_hands_over_to_train_and_cancel_stops_both(store):
    job = _job(store, PREPARE)
    assert store.claim(job, TRAIN, "x", "w1", STALE) == "skip"  # not its phase: never sent so
    assert store.claim(job, PREPARE, "p", "w1", STALE) == "run"
    assert store.next_phase(job, "p", TRAIN)
    assert store.claim(job, PREPARE, "p2", "w1", STALE) == "skip"  # a duplicate prepare
    row = store.row(job)
    assert (row["phase"], row["state"], row["attempts"]) == (TRAIN, "queued", 0)
    assert store.claim(job, TRAIN, "t", "w2", STALE) == "run"
    assert store.cancel(job).state == "cancelled"
    assert not store.beat(job, "t")  # the running try learns it was cancelled
    assert store.claim(job, TRAIN, "t2", "w2", STALE) == "skip"


def test_queue_counts(store):
    first, second = _job(store, job_id="a" * 22), _job(store, job_id="b" * 22)
    assert store.count_queued() == 2
    assert store.queue_position(store.get(second)) == 1
    store.claim(first, TRAIN, "t", "w1", STALE)
    assert store.count_queued() == 1 and store.queue_position(store.get(second)) == 0
    assert store.delete(second) and store.get(second) is None


def test_training_goes_to_gpu_only_when_a_worker_consumes_it():
    replies = {"cpu1@a": [{"name": "cpu"}], "gpu1@b": [{"name": "cpu"}, {"name": "gpu"}]}
    assert gpu_workers(replies) == ["gpu1@b"]
    assert gpu_workers({"cpu1@a": [{"name": "cpu"}]}) == []
    assert gpu_workers(None) == []  # no worker answered
