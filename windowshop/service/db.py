"""The job store: one SQLite table shared by the web process, the worker and the job processes.

Every process opens its own short-lived connections (WAL mode, so readers never wait for the
writer). A running job carries a `run_token` drawn when the worker claims it; progress and results
are written only while the token still matches, so a job process left over from before a restart,
a cancellation or a deletion can no longer change the job.
"""

from __future__ import annotations

import json
import sqlite3
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from windowshop.service.store import (CANCELLED, FAILED, FINISHED, MAX_ATTEMPTS, QUEUED, RUNNING,
                                      Job, JobStore)

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    stage TEXT,
    progress REAL NOT NULL DEFAULT 0,
    stages TEXT NOT NULL DEFAULT '{}',
    eta_seconds REAL,
    error TEXT,
    input_kind TEXT NOT NULL,
    input_summary TEXT NOT NULL DEFAULT '',
    created_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    run_token TEXT,
    attempts INTEGER NOT NULL DEFAULT 0,
    frames INTEGER NOT NULL DEFAULT 0,
    owner_hash TEXT
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs (state, created_at);
"""
# Columns added since the first release, created in an older store's table on first use.
_ADDED = {"owner_hash": "TEXT"}


class SQLiteJobStore(JobStore):
    """Jobs in `path` (an SQLite file, created with its table on first use)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self._connect() as db:
            db.execute("PRAGMA journal_mode=WAL")
            db.executescript(_SCHEMA)
            have = {row["name"] for row in db.execute("PRAGMA table_info(jobs)")}
            for name, kind in _ADDED.items():
                if name not in have:
                    db.execute(f"ALTER TABLE jobs ADD COLUMN {name} {kind}")

    @contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        db = sqlite3.connect(self.path, timeout=30, isolation_level=None)
        db.row_factory = sqlite3.Row
        try:
            yield db
        finally:
            db.close()

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """A write transaction that takes the lock up front, so read-then-write steps are atomic."""
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")

    def create(self, job_id: str, input_kind: str, input_summary: str,
               max_queued: int | None = None, owner_hash: str | None = None) -> Job | None:
        """Queue a new job; None (and nothing stored) when `max_queued` jobs already wait."""
        with self._transaction() as db:
            waiting = db.execute("SELECT COUNT(*) FROM jobs WHERE state = ?", (QUEUED,)).fetchone()[0]
            if max_queued is not None and waiting >= max_queued:
                return None
            db.execute("INSERT INTO jobs (id, state, input_kind, input_summary, created_at, "
                       "owner_hash) VALUES (?, ?, ?, ?, ?, ?)",
                       (job_id, QUEUED, input_kind, input_summary, time.time(), owner_hash))
        return self.get(job_id)

    def expired(self, finished_before: float) -> list[str]:
        with self._connect() as db:
            rows = db.execute(f"SELECT id FROM jobs WHERE state IN ({_marks(len(FINISHED))}) "
                              "AND finished_at < ?", (*FINISHED, finished_before)).fetchall()
        return [r["id"] for r in rows]

    def get(self, job_id: str) -> Job | None:
        with self._connect() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return _job(row) if row else None

    def count_queued(self) -> int:
        with self._connect() as db:
            return db.execute("SELECT COUNT(*) FROM jobs WHERE state = ?", (QUEUED,)).fetchone()[0]

    def queue_position(self, job: Job) -> int:
        """How many queued jobs run before `job` (0: it is next)."""
        with self._connect() as db:
            return db.execute("SELECT COUNT(*) FROM jobs WHERE state = ? AND created_at < ?",
                              (QUEUED, job.created_at)).fetchone()[0]

    def claim_next(self, run_token: str) -> Job | None:
        """Move the oldest queued job to its first stage under `run_token`; None when none waits."""
        with self._transaction() as db:
            row = db.execute("SELECT id FROM jobs WHERE state = ? ORDER BY created_at LIMIT 1",
                             (QUEUED,)).fetchone()
            if row is None:
                return None
            db.execute("UPDATE jobs SET state = ?, stage = ?, progress = 0, stages = '{}', "
                       "eta_seconds = NULL, error = NULL, run_token = ?, attempts = attempts + 1, "
                       "started_at = ? WHERE id = ?",
                       (RUNNING[0], RUNNING[0], run_token, time.time(), row["id"]))
        return self.get(row["id"])

    def report(self, job_id: str, run_token: str, stage: str, progress: float,
               stages: dict[str, float], eta_seconds: float | None) -> bool:
        """Record the running job's stage and progress; False when the job is no longer this run's."""
        with self._connect() as db:
            cur = db.execute("UPDATE jobs SET state = ?, stage = ?, progress = ?, stages = ?, "
                             "eta_seconds = ? WHERE id = ? AND run_token = ?",
                             (stage, stage, progress, json.dumps(stages), eta_seconds, job_id,
                              run_token))
        return cur.rowcount == 1

    def finish(self, job_id: str, run_token: str, state: str, error: str | None = None,
               frames: int = 0) -> bool:
        """End this run of the job as `state` (done or failed); False when it is no longer this run's."""
        with self._connect() as db:
            cur = db.execute("UPDATE jobs SET state = ?, error = ?, frames = ?, eta_seconds = NULL, "
                             "finished_at = ?, run_token = NULL WHERE id = ? AND run_token = ?",
                             (state, error, frames, time.time(), job_id, run_token))
        return cur.rowcount == 1

    def retry(self, job_id: str, run_token: str, error: str) -> str | None:
        """This run met a transient fault (out of memory, its process killed): the job is queued
        again ("retry"), or failed after MAX_ATTEMPTS tries ("failed"); None when not this run's."""
        with self._transaction() as db:
            row = db.execute("SELECT attempts FROM jobs WHERE id = ? AND run_token = ?",
                             (job_id, run_token)).fetchone()
            if row is None:
                return None
            if row["attempts"] < MAX_ATTEMPTS:
                db.execute("UPDATE jobs SET state = ?, error = ?, run_token = NULL, eta_seconds = NULL "
                           "WHERE id = ?", (QUEUED, error, job_id))
                return "retry"
            db.execute("UPDATE jobs SET state = ?, error = ?, run_token = NULL, eta_seconds = NULL, "
                       "finished_at = ? WHERE id = ?",
                       (FAILED, f"the job failed {MAX_ATTEMPTS} times; last error: {error}",
                        time.time(), job_id))
            return "failed"

    def cancel(self, job_id: str) -> Job | None:
        """Cancel a queued or running job (the worker then stops its process); None when unknown."""
        with self._connect() as db:
            db.execute(f"UPDATE jobs SET state = ?, eta_seconds = NULL, finished_at = ?, "
                       f"run_token = NULL WHERE id = ? AND state IN ({_marks(1 + len(RUNNING))})",
                       (CANCELLED, time.time(), job_id, QUEUED, *RUNNING))
        return self.get(job_id)

    def delete(self, job_id: str) -> bool:
        with self._connect() as db:
            return db.execute("DELETE FROM jobs WHERE id = ?", (job_id,)).rowcount == 1

    def release(self, job_id: str, run_token: str) -> bool:
        """Put a job stopped by an orderly shutdown back in the queue; that try does not count."""
        with self._connect() as db:
            cur = db.execute("UPDATE jobs SET state = ?, run_token = NULL, eta_seconds = NULL, "
                             "attempts = attempts - 1 WHERE id = ? AND run_token = ?",
                             (QUEUED, job_id, run_token))
        return cur.rowcount == 1

    def requeue_interrupted(self) -> tuple[list[str], list[str]]:
        """After a restart: running jobs go back to the queue, or fail after MAX_ATTEMPTS tries.

        Returns (requeued ids, failed ids).
        """
        with self._transaction() as db:
            rows = db.execute(f"SELECT id, attempts FROM jobs WHERE state IN ({_marks(len(RUNNING))})",
                              RUNNING).fetchall()
            requeued = [r["id"] for r in rows if r["attempts"] < MAX_ATTEMPTS]
            failed = [r["id"] for r in rows if r["attempts"] >= MAX_ATTEMPTS]
            db.executemany("UPDATE jobs SET state = ?, run_token = NULL, eta_seconds = NULL "
                           "WHERE id = ?", [(QUEUED, i) for i in requeued])
            message = f"the job was interrupted {MAX_ATTEMPTS} times while running; it was given up"
            db.executemany("UPDATE jobs SET state = ?, error = ?, run_token = NULL, finished_at = ? "
                           "WHERE id = ?", [(FAILED, message, time.time(), i) for i in failed])
        return requeued, failed


def _marks(n: int) -> str:
    return ", ".join("?" * n)


def _job(row: sqlite3.Row) -> Job:
    values = dict(row)
    values["stages"] = json.loads(values["stages"])
    return Job(**values)
