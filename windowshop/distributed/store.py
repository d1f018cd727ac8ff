"""The shared job store of the distributed mode: one SQL table, through SQLAlchemy Core.

SQLite (the default, a file in the service's data folder) or PostgreSQL (`postgresql://...`, with
psycopg). Only the service opens it: workers reach the jobs through the service's HTTP routes, so
a worker needs no database access and no shared disk. Every change a worker asks for is a single
conditional UPDATE (compare-and-set on the job's `run_token`), so it is atomic on both databases
without explicit locks; a delivery that lost the race changes nothing.

A job runs in phases, each one Celery task: "prepare" (photos or a video -> a posed scene, on the
`cpu` queue) then "train" (fit and render, on `gpu` when such workers exist). `attempts` counts the
tries of the current phase; a try failed by the user's input fails the job at once, and the
MAX_ATTEMPTS-th try ended by a transient fault (or lost with its worker) fails it with its last error.
"""

from __future__ import annotations

import json
import time

import sqlalchemy as sa

from windowshop.service.store import (CANCELLED, DONE, FAILED, FINISHED, MAX_ATTEMPTS, QUEUED, RUNNING,
                                      Job, JobStore)

PREPARE, TRAIN = "prepare", "train"
PHASE_STATE = {PREPARE: "preparing", TRAIN: "training"}
LOST = "the worker running it was lost (killed, or out of memory?)"

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
    sa.Column("dispatched_at", sa.Float),  # when its task was sent; None: the send failed
    sa.Column("owner_hash", sa.String(64)),  # SHA-256 of the owner token (cancel, delete)
    sa.Index("jobs_state", "state", "created_at"),
)
_ADDED = ("dispatched_at", "owner_hash")  # columns created in an older store's table on first use
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
        have = {c["name"] for c in sa.inspect(self.engine).get_columns("jobs")}
        with self.engine.begin() as db:
            for name in _ADDED:
                if name not in have:
                    kind = jobs.c[name].type.compile(self.engine.dialect)
                    db.exec_driver_sql(f"ALTER TABLE jobs ADD COLUMN {name} {kind}")

    def _update(self, where, **values) -> bool:
        with self.engine.begin() as db:
            return db.execute(sa.update(jobs).where(*where).values(**values)).rowcount == 1

    def create(self, job_id: str, input_kind: str, input_summary: str, phase: str, worker_key: str,
               max_queued: int | None = None, owner_hash: str | None = None) -> Job | None:
        """Queue a new job; None (and nothing stored) when `max_queued` jobs already wait."""
        with self.engine.begin() as db:
            if max_queued is not None and self._queued(db) >= max_queued:
                return None
            now = time.time()
            db.execute(sa.insert(jobs).values(
                id=job_id, state=QUEUED, input_kind=input_kind, input_summary=input_summary,
                created_at=now, phase=phase, worker_key=worker_key, stages="{}",
                progress=0.0, attempts=0, frames=0, dispatched_at=now, owner_hash=owner_hash))
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
            last = row["error"] or LOST
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
                            error=None, dispatched_at=time.time())

    def finish(self, job_id: str, run_token: str, frames: int) -> bool:
        """The try finished the job; False (nothing changed) when it is not the current one."""
        return self._update((jobs.c.id == job_id, jobs.c.run_token == run_token), state=DONE,
                            error=None, frames=frames, eta_seconds=None, finished_at=time.time(),
                            run_token=None, heartbeat_at=None)

    def fail_try(self, job_id: str, run_token: str, error: str, transient: bool = True) -> str | None:
        """The try failed with `error`: "failed" (a user's error, or its last try) or "retry" (a
        transient fault: the job is queued again); None when the try is not current."""
        with self.engine.connect() as db:
            attempts = db.execute(sa.select(jobs.c.attempts).where(
                jobs.c.id == job_id, jobs.c.run_token == run_token)).scalar()
        if attempts is None:
            return None
        mine = (jobs.c.id == job_id, jobs.c.run_token == run_token)
        if not transient or attempts >= MAX_ATTEMPTS:
            final = error if not transient else f"the job failed {MAX_ATTEMPTS} times; last error: {error}"
            done = self._update(mine, state=FAILED, error=final, run_token=None, eta_seconds=None,
                                finished_at=time.time(), heartbeat_at=None)
            return "failed" if done else None
        done = self._update(mine, state=QUEUED, error=error, run_token=None, eta_seconds=None,
                            heartbeat_at=None, dispatched_at=time.time())
        return "retry" if done else None

    def requeue_silent(self, stale_seconds: float) -> list[str]:
        """Running jobs whose try has been silent `stale_seconds` (its worker is lost) go back to
        the queue, or fail after MAX_ATTEMPTS tries; returns the requeued ids, to dispatch again.

        Each change is conditional on the heartbeat still being old, so a try that spoke up in
        between keeps its job.
        """
        now = time.time()
        silent = (jobs.c.state.in_(RUNNING), jobs.c.heartbeat_at < now - stale_seconds)
        with self.engine.connect() as db:
            rows = db.execute(sa.select(jobs.c.id, jobs.c.attempts).where(*silent)).all()
        requeued = []
        for job_id, attempts in rows:
            if attempts >= MAX_ATTEMPTS:
                self._update((jobs.c.id == job_id, *silent), state=FAILED, run_token=None,
                             eta_seconds=None, finished_at=now, heartbeat_at=None,
                             error=f"the job failed {MAX_ATTEMPTS} times; last error: {LOST}")
            elif self._update((jobs.c.id == job_id, *silent), state=QUEUED, run_token=None,
                              eta_seconds=None, heartbeat_at=None, dispatched_at=now, error=LOST):
                requeued.append(job_id)
        return requeued

    def set_dispatched(self, job_id: str, sent: bool) -> None:
        """Record whether the job's task reached the broker (None: the sweep sends it again)."""
        self._update((jobs.c.id == job_id,), dispatched_at=time.time() if sent else None)

    def queued(self, undispatched_only: bool = False) -> list[str]:
        """Ids of the queued jobs (only those whose task could not be sent, if asked)."""
        where = [jobs.c.state == QUEUED]
        if undispatched_only:
            where.append(jobs.c.dispatched_at.is_(None))
        with self.engine.connect() as db:
            return list(db.execute(sa.select(jobs.c.id).where(*where)
                                   .order_by(jobs.c.created_at)).scalars())

    def expired(self, finished_before: float) -> list[str]:
        with self.engine.connect() as db:
            return list(db.execute(sa.select(jobs.c.id).where(
                jobs.c.state.in_(FINISHED), jobs.c.finished_at < finished_before)).scalars())

    def cancel(self, job_id: str) -> Job | None:
        self._update((jobs.c.id == job_id, jobs.c.state.in_((QUEUED, *RUNNING))), state=CANCELLED,
                     eta_seconds=None, finished_at=time.time(), run_token=None)
        return self.get(job_id)

    def delete(self, job_id: str) -> bool:
        with self.engine.begin() as db:
            return db.execute(sa.delete(jobs).where(jobs.c.id == job_id)).rowcount == 1
