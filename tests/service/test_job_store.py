"""The job-store contract (service/store.py), the same assertions on both stores: the SQLite store of
one machine, and the cluster's SQLAlchemy store on SQLite and on PostgreSQL (tests/conftest.py's
server, skipped where PostgreSQL is not installed)."""

from __future__ import annotations

import sqlite3
import time
from dataclasses import dataclass
from typing import Callable

import pytest

from windowshop.distributed.store import PREPARE, ClusterStore
from windowshop.service.db import SQLiteJobStore
from windowshop.service.store import CANCELLED, QUEUED, RUNNING, JobStore


@dataclass
class Subject:
    """A store, and the store's own ways to queue a job and to start a try of it."""

    store: JobStore
    create: Callable[..., object]  # (job id, max queued, owner hash=None) -> Job | None
    start: Callable[[str], str]  # job id -> the try's run token


def _sqlite(tmp_path) -> Subject:
    store = SQLiteJobStore(tmp_path / "jobs.sqlite3")

    def start(job_id: str) -> str:
        claimed = store.claim_next(f"token-{job_id}")
        assert claimed is not None and claimed.id == job_id
        return f"token-{job_id}"

    return Subject(store, lambda job_id, most, owner=None: store.create(job_id, "photos", "3 photos",
                                                                        most, owner), start)


def _cluster(url: str) -> Subject:
    store = ClusterStore(url)
    with store.engine.begin() as db:
        db.exec_driver_sql("DELETE FROM jobs")

    def start(job_id: str) -> str:
        assert store.claim(job_id, PREPARE, f"token-{job_id}", "w1", stale_seconds=60) == "run"
        return f"token-{job_id}"

    return Subject(store, lambda job_id, most, owner=None: store.create(
        job_id, "photos", "3 photos", PREPARE, "key", most, owner), start)


@pytest.fixture(params=["sqlite", "cluster-sqlite", "cluster-postgresql"])
def subject(request, tmp_path) -> Subject:
    if request.param == "sqlite":
        return _sqlite(tmp_path)
    if request.param == "cluster-sqlite":
        return _cluster(f"sqlite:///{tmp_path / 'cluster.sqlite3'}")
    return _cluster(request.getfixturevalue("postgres_url"))


def test_both_stores_declare_the_interface():
    for cls in (SQLiteJobStore, ClusterStore):
        assert JobStore in cls.__mro__  # declared, not only matching by shape
        for name in ("get", "count_queued", "queue_position", "report", "cancel", "delete"):
            assert getattr(cls, name) is not getattr(JobStore, name), f"{cls.__name__}.{name}"


def test_a_new_job_waits_in_order(subject):
    store = subject.store
    assert store.get("nope") is None
    first = subject.create("job-a", None)
    time.sleep(0.01)  # created_at orders the queue
    second = subject.create("job-b", None)
    assert (first.id, first.state, first.input_kind, first.input_summary) == \
        ("job-a", QUEUED, "photos", "3 photos")
    assert store.count_queued() == 2
    assert [store.queue_position(first), store.queue_position(second)] == [0, 1]
    assert subject.create("job-c", 2) is None  # the queue is full: nothing stored
    assert store.get("job-c") is None and store.count_queued() == 2


def test_only_the_current_try_reports(subject):
    store = subject.store
    subject.create("job-a", None)
    assert not store.report("job-a", "not-a-try", RUNNING[0], 0.5, {}, None)  # not started yet
    token = subject.start("job-a")
    assert store.count_queued() == 0
    assert store.report("job-a", token, RUNNING[0], 0.25, {RUNNING[0]: 0.25}, 12.0)
    job = store.get("job-a")
    assert (job.state, job.stage, job.progress, job.stages, job.eta_seconds) == \
        (RUNNING[0], RUNNING[0], 0.25, {RUNNING[0]: 0.25}, 12.0)
    assert not store.report("job-a", "stale-token", RUNNING[0], 0.9, {}, None)
    assert store.get("job-a").progress == 0.25


def test_cancel_stops_reports_and_delete_forgets(subject):
    store = subject.store
    subject.create("job-a", None)
    token = subject.start("job-a")
    cancelled = store.cancel("job-a")
    assert cancelled.state == CANCELLED and cancelled.finished_at is not None
    assert not store.report("job-a", token, RUNNING[0], 0.5, {}, None)  # the try lost the job
    assert store.cancel("job-a").state == CANCELLED  # cancelling again changes nothing
    assert store.cancel("nope") is None
    assert store.delete("job-a") and store.get("job-a") is None
    assert not store.delete("job-a")


def test_the_owner_hash_is_kept_and_ended_jobs_expire(subject):
    store = subject.store
    subject.create("job-b", None)
    assert store.get("job-b").owner_hash is None
    subject.start("job-b")  # running: never expired, however old
    assert subject.create("job-a", None, "ab" * 32).owner_hash == "ab" * 32
    ended = store.cancel("job-a").finished_at
    assert store.expired(ended + 1) == ["job-a"]
    assert store.expired(ended - 1) == []


def _reopen_without_new_columns(store):
    """Drop the columns added since the first release, then open the store again."""
    if isinstance(store, SQLiteJobStore):
        with sqlite3.connect(store.path) as db:
            db.execute("ALTER TABLE jobs DROP COLUMN owner_hash")
        return SQLiteJobStore(store.path)
    with store.engine.begin() as db:
        db.exec_driver_sql("ALTER TABLE jobs DROP COLUMN owner_hash")
        db.exec_driver_sql("ALTER TABLE jobs DROP COLUMN dispatched_at")
    url = store.engine.url.render_as_string(hide_password=False)
    store.engine.dispose()
    return ClusterStore(url)


def test_a_table_from_before_owner_tokens_gains_the_column(subject):
    subject.create("job-a", None)
    store = _reopen_without_new_columns(subject.store)
    assert store.get("job-a").owner_hash is None  # a job from before: no owner can be proven
    assert subject.create("job-b", None, "cd" * 32).owner_hash == "cd" * 32
