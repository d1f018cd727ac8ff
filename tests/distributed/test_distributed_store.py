"""The distributed job store's compare-and-set rules, on SQLite and on a real PostgreSQL server
(tests/conftest.py starts one on loopback when Debian's postgresql is installed), and the gpu-queue routing rule."""

from __future__ import annotations

import pytest

from windowshop.distributed.celery_app import gpu_workers
from windowshop.distributed.store import MAX_ATTEMPTS, PREPARE, TRAIN, ClusterStore

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
