"""The Celery application shared by the service (which sends tasks) and the workers (which run them).

Trusted-queue settings: a task is acknowledged only once it has finished (`acks_late`), and put
back when the process running it dies (`reject_on_worker_lost`); a worker that vanishes altogether
(a machine lost, SIGKILL) leaves its message unacknowledged in Redis, which hands it to another
worker once `visibility_timeout` has passed. The service does not wait that long: its sweep sends
the job again once the try's heartbeat has been silent `stale_seconds` (sweeps.py). The timeout
must still exceed the longest job, or a live job is delivered twice (harmless: the store's
compare-and-set lets only one try run, see store.py, but wasteful). Each worker takes one task at a
time per process (prefetch 1).
"""

from __future__ import annotations

from celery import Celery
from pydantic_settings import BaseSettings, SettingsConfigDict

QUEUES = ("cpu", "gpu")

app = Celery("windowshop", include=["windowshop.distributed.tasks", "windowshop.distributed.study"])


class ClusterSettings(BaseSettings):
    """The distributed mode's knobs (`WINDOWSHOP_*` environment variables, or flags)."""

    model_config = SettingsConfigDict(env_prefix="WINDOWSHOP_", frozen=True)

    broker: str = "redis://127.0.0.1:6379/0"
    db: str | None = None  # SQLAlchemy URL; None: SQLite in the service's data folder
    public_url: str | None = None  # how workers reach the service; None: http://host:port
    visibility_timeout: float = 3600.0  # seconds before an unacknowledged task is redelivered
    restore_interval: float = 10.0  # seconds between the workers' sweeps for such tasks
    heartbeat_seconds: float = 5.0  # how often a running try tells the service it is alive
    stale_seconds: float = 30.0  # a try silent this long is dead: the service sends its job again
    silence_check_seconds: float = 5.0  # how often the service looks for silent tries and lost tasks
    queue_check_seconds: float = 30.0  # how long the service trusts its list of gpu workers


def configure(settings: ClusterSettings) -> Celery:
    """Point the application at the broker with the trusted-queue settings; returns it."""
    app.conf.update(
        broker_url=settings.broker,
        broker_connection_retry_on_startup=True,
        broker_transport_options={
            "visibility_timeout": settings.visibility_timeout,
            "unacked_restore_interval": settings.restore_interval,
            "unacked_restore_throttle": 1,  # sweep every interval, not every tenth one
        },
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_acks_on_failure_or_timeout=True,
        worker_prefetch_multiplier=1,
        task_default_queue="cpu",
        task_ignore_result=True,  # results travel through the service, not a result backend
        result_backend=settings.broker,  # ... except a study run's (distributed/study.py)
        task_serializer="json",
        accept_content=["json"],
        worker_hijack_root_logger=False,
        worker_send_task_events=False,
    )
    return app


def gpu_workers(replies: dict | None) -> list[str]:
    """Names of the workers consuming the `gpu` queue, from `inspect().active_queues()`'s reply."""
    return sorted(name for name, queues in (replies or {}).items()
                  if any(q.get("name") == "gpu" for q in queues))
