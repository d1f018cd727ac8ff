"""The job record and the job store's interface, which both stores implement: the SQLite store of
one machine (`service.db.SQLiteJobStore`) and the SQL store shared by a cluster
(`distributed.store.ClusterStore`, SQLAlchemy). The routes, the worker's progress reports and the
tests are written against these protocols, not against either store.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

QUEUED = "queued"
RUNNING = ("preparing", "training", "rendering")
DONE, FAILED, CANCELLED = "done", "failed", "cancelled"
FINISHED = (DONE, FAILED, CANCELLED)
STATES = (QUEUED, *RUNNING, *FINISHED)
MAX_ATTEMPTS = 3  # a job tried (or interrupted) this often fails instead; it may be what kills workers


@dataclass
class Job:
    """One row of the store."""

    id: str
    state: str
    input_kind: str  # "photos" | "video" | "zip"
    input_summary: str
    created_at: float
    stage: str | None = None  # the running or last stage: "preparing" | "training" | "rendering"
    progress: float = 0.0  # of `stage`, in [0, 1]
    stages: dict[str, float] = field(default_factory=dict)  # progress of every stage seen so far
    eta_seconds: float | None = None
    error: str | None = None
    started_at: float | None = None
    finished_at: float | None = None
    run_token: str | None = None
    attempts: int = 0
    frames: int = 0  # per-frame images available once done
    owner_hash: str | None = None  # SHA-256 of the owner token that may cancel or delete the job


class ProgressStore(Protocol):
    """Where a running try reports its progress (a store, or a worker's link to the service)."""

    def report(self, job_id: str, run_token: str, stage: str, progress: float,
               stages: dict[str, float], eta_seconds: float | None) -> bool:
        """Record the running try's stage and progress; False when it is no longer the job's try."""


class JobLookup(Protocol):
    """What the job API reads and changes of existing jobs."""

    def get(self, job_id: str) -> Job | None:
        """The job, or None when there is none of that id."""

    def count_queued(self) -> int:
        """How many jobs wait in the queue."""

    def queue_position(self, job: Job) -> int:
        """How many queued jobs run before `job` (0: it is next)."""

    def cancel(self, job_id: str) -> Job | None:
        """Cancel a queued or running job; the job afterwards, None when unknown."""

    def delete(self, job_id: str) -> bool:
        """Forget the job; False when there was none."""


class JobStore(JobLookup, ProgressStore, Protocol):
    """A job store: both stores implement it (they differ in how tries claim and end jobs)."""


class JobQueue(JobLookup, Protocol):
    """The API's store: a JobLookup that also queues new jobs (SQLiteJobStore, or ClusterJobs)."""

    def create(self, job_id: str, input_kind: str, input_summary: str,
               max_queued: int | None = None, owner_hash: str | None = None) -> Job | None:
        """Queue a new job; None (and nothing stored) when `max_queued` jobs already wait."""

    def expired(self, finished_before: float) -> list[str]:
        """Ids of the jobs that ended (done, failed, cancelled) before this Unix time."""
