"""The shared job store of the distributed mode: one SQL table, through SQLAlchemy Core.

SQLite (the default, a file in the service's data folder) or PostgreSQL (`postgresql://...`, with
psycopg). Only the service opens it: workers reach the jobs through the service's HTTP routes, so
a worker needs no database access and no shared disk. Every change a worker asks for is a single
conditional UPDATE (compare-and-set on the job's `run_token`), so it is atomic on both databases
without explicit locks; a delivery that lost the race changes nothing.

A job runs in phases, each one Celery task: "prepare" (photos or a video -> a posed scene, on the
`cpu` queue) then "train" (fit and render, on `gpu` when such workers exist). `attempts` counts the
tries of the current phase; the MAX_ATTEMPTS-th failed try fails the job with its last error.
"""

from __future__ import annotations

import json
import time

import sqlalchemy as sa

from windowshop.service.store import (CANCELLED, DONE, FAILED, FINISHED, MAX_ATTEMPTS, QUEUED, RUNNING,
                                      Job, JobStore)

PREPARE, TRAIN = "prepare", "train"
PHASE_STATE = {PREPARE: "preparing", TRAIN: "training"}

_meta = sa.MetaData()
jobs = sa.Table(
    "jobs", _meta,
    sa.Column("id", sa.String(64), primary_key=True),
    sa.Column("state", sa.String(16), nullable=False),
    sa.Column("stage", sa.String(16)),
    sa.Column("progress", sa.Float, nullable=False, default=0.0),
    sa.Column("stages", sa.Text, nullable=False, default="{}"),
    sa.Column("eta_seconds", sa.Float),
    sa.Column("error", sa.Text),
    sa.Column("input_kind", sa.String(16), nullable=False),
    sa.Column("input_summary", sa.Text, nullable=False, default=""),
    sa.Column("created_at", sa.Float, nullable=False),
    sa.Column("started_at", sa.Float),
    sa.Column("finished_at", sa.Float),
    sa.Column("run_token", sa.String(32)),
    sa.Column("attempts", sa.Integer, nullable=False, default=0),
    sa.Column("frames", sa.Integer, nullable=False, default=0),
    # Distributed mode only:
    sa.Column("phase", sa.String(16), nullable=False, default=PREPARE),
    sa.Column("worker_key", sa.String(64), nullable=False),  # the tasks' key to the worker routes
    sa.Column("worker", sa.Text),  # Celery hostname of the worker running (or last running) it
    sa.Column("heartbeat_at", sa.Float),  # last sign of life of the running attempt
    sa.Index("jobs_state", "state", "created_at"),
)
_PUBLIC = [c.name for c in jobs.columns if c.name in Job.__dataclass_fields__]


def default_db_url(data_dir) -> str:
    return f"sqlite:///{(data_dir / 'cluster.sqlite3').resolve()}"


def make_engine(url: str) -> sa.Engine:
    """An engine for `url`; SQLite waits for the writer instead of failing at once."""
    if url.startswith("sqlite"):
        engine = sa.create_engine(url, connect_args={"timeout": 30})
        with engine.begin() as db:
            db.exec_driver_sql("PRAGMA journal_mode=WAL")
        return engine
    return sa.create_engine(url, pool_pre_ping=True)


class ClusterStore(JobStore):
    """The jobs table at `url`, created on first use."""

    def __init__(self, url: str):
        self.engine = make_engine(url)
        _meta.create_all(self.engine)

    def _update(self, where, **values) -> bool:
        with self.engine.begin() as db:
            return db.execute(sa.update(jobs).where(*where).values(**values)).rowcount == 1

    def create(self, job_id: str, input_kind: str, input_summary: str, phase: str, worker_key: str,
               max_queued: int | None = None) -> Job | None:
        """Queue a new job; None (and nothing stored) when `max_queued` jobs already wait."""
        with self.engine.begin() as db:
            if max_queued is not None and self._queued(db) >= max_queued:
                return None
            db.execute(sa.insert(jobs).values(
                id=job_id, state=QUEUED, input_kind=input_kind, input_summary=input_summary,
                created_at=time.time(), phase=phase, worker_key=worker_key, stages="{}",
                progress=0.0, attempts=0, frames=0))
        return self.get(job_id)

    def row(self, job_id: str) -> dict | None:
        """Every column of the job (the distributed ones too), or None."""
        with self.engine.connect() as db:
            row = db.execute(sa.select(jobs).where(jobs.c.id == job_id)).mappings().first()
        return dict(row) if row else None

    def get(self, job_id: str) -> Job | None:
        row = self.row(job_id)
        if row is None:
            return None
        return Job(**{**{k: row[k] for k in _PUBLIC}, "stages": json.loads(row["stages"])})

    @staticmethod
    def _queued(db) -> int:
        return db.execute(sa.select(sa.func.count()).select_from(jobs)
                          .where(jobs.c.state == QUEUED)).scalar_one()

    def count_queued(self) -> int:
        with self.engine.connect() as db:
            return self._queued(db)

    def queue_position(self, job: Job) -> int:
        with self.engine.connect() as db:
            return db.execute(sa.select(sa.func.count()).select_from(jobs).where(
                jobs.c.state == QUEUED, jobs.c.created_at < job.created_at)).scalar_one()

    def claim(self, job_id: str, phase: str, token: str, worker: str, stale_seconds: float) -> str:
        """A delivery of the job's `phase` task asks to run it under `token`.

        Returns "run" (the try is this delivery's), "busy" (another live try runs it: ask again
        later), or "skip" (finished, cancelled, deleted, past this phase, or just failed for
        having been tried MAX_ATTEMPTS times).
        """
        now = time.time()
        claimable = sa.or_(jobs.c.state == QUEUED, sa.and_(
            jobs.c.state.in_(RUNNING),
            sa.or_(jobs.c.heartbeat_at.is_(None), jobs.c.heartbeat_at < now - stale_seconds)))
        where = (jobs.c.id == job_id, jobs.c.phase == phase, claimable)
        if self._update((*where, jobs.c.attempts < MAX_ATTEMPTS), state=PHASE_STATE[phase],
                        stage=PHASE_STATE[phase], progress=0.0, eta_seconds=None, run_token=token,
                        attempts=jobs.c.attempts + 1, worker=worker, heartbeat_at=now,
                        started_at=sa.func.coalesce(jobs.c.started_at, now)):
            return "run"
        row = self.row(job_id)
        if row is None or row["state"] in FINISHED or row["phase"] != phase:
            return "skip"
        if row["attempts"] >= MAX_ATTEMPTS:
            last = row["error"] or "the worker running it was lost (killed, or out of memory?)"
            self._update(where, state=FAILED, run_token=None, eta_seconds=None, finished_at=now,
                         error=f"the job failed {MAX_ATTEMPTS} times; last error: {last}")
            return "skip"
        return "busy"

    def report(self, job_id: str, run_token: str, stage: str, progress: float,
               stages: dict[str, float], eta_seconds: float | None) -> bool:
        """Record the running try's progress (and that it is alive); False when it is not current."""
        return self._update((jobs.c.id == job_id, jobs.c.run_token == run_token), state=stage,
                            stage=stage, progress=progress, stages=json.dumps(stages),
                            eta_seconds=eta_seconds, heartbeat_at=time.time())

    def beat(self, job_id: str, run_token: str) -> bool:
        return self._update((jobs.c.id == job_id, jobs.c.run_token == run_token),
                            heartbeat_at=time.time())

    def owns(self, job_id: str, run_token: str) -> bool:
        row = self.row(job_id)
        return row is not None and row["run_token"] == run_token

    def next_phase(self, job_id: str, run_token: str, phase: str) -> bool:
        """The try finished its phase: the job waits for the `phase` task (tries counted anew)."""
        return self._update((jobs.c.id == job_id, jobs.c.run_token == run_token), phase=phase,
                            state=QUEUED, run_token=None, heartbeat_at=None, attempts=0,
                            error=None)

    def finish(self, job_id: str, run_token: str, frames: int) -> bool:
        """The try finished the job; False (nothing changed) when it is not the current one."""
        return self._update((jobs.c.id == job_id, jobs.c.run_token == run_token), state=DONE,
                            error=None, frames=frames, eta_seconds=None, finished_at=time.time(),
                            run_token=None, heartbeat_at=None)

    def fail_try(self, job_id: str, run_token: str, error: str) -> str | None:
        """The try failed with `error`: "failed" (its last try) or "retry"; None when not current."""
        with self.engine.connect() as db:
            attempts = db.execute(sa.select(jobs.c.attempts).where(
                jobs.c.id == job_id, jobs.c.run_token == run_token)).scalar()
        if attempts is None:
            return None
        mine = (jobs.c.id == job_id, jobs.c.run_token == run_token)
        if attempts >= MAX_ATTEMPTS:
            final = f"the job failed {MAX_ATTEMPTS} times; last error: {error}"
            done = self._update(mine, state=FAILED, error=final, run_token=None, eta_seconds=None,
                                finished_at=time.time())
            return "failed" if done else None
        done = self._update(mine, state=QUEUED, error=error, run_token=None, eta_seconds=None,
                            heartbeat_at=None)
        return "retry" if done else None

    def cancel(self, job_id: str) -> Job | None:
        self._update((jobs.c.id == job_id, jobs.c.state.in_((QUEUED, *RUNNING))), state=CANCELLED,
                     eta_seconds=None, finished_at=time.time(), run_token=None)
        return self.get(job_id)

    def delete(self, job_id: str) -> bool:
        with self.engine.begin() as db:
            return db.execute(sa.delete(jobs).where(jobs.c.id == job_id)).rowcount == 1
