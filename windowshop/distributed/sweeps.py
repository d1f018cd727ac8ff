"""The distributed service's sweep: jobs whose task is lost are sent again.

A task can be lost three ways, and each has its sign:
- its worker died (SIGKILL, a lost machine, the OOM killer): the try's heartbeat falls silent. Redis
  would hand the unacknowledged task to another worker only after the visibility timeout (an hour by
  default); the sweep puts the job back in the queue once it has been silent `stale_seconds` and
  sends it again at once;
- the broker could not be reached when the service sent it: the job is marked unsent, and sent
  again here once the broker answers;
- the broker restarted without its data: Redis's `run_id` changed, so every queued job is sent
  again (a copy still in the broker is harmless: the claim lets only one delivery run the job).

Every resend is a duplicate at worst, and duplicates are harmless (see store.py's claim).
"""

from __future__ import annotations

import logging

import redis

from windowshop.distributed.store import ClusterStore

log = logging.getLogger("windowshop.service")


class BrokerWatch:
    """Tells whether the Redis broker at `url` restarted since it was last asked."""

    def __init__(self, url: str):
        self.client = (redis.Redis.from_url(url, socket_timeout=2, socket_connect_timeout=2)
                       if url.startswith(("redis://", "rediss://", "unix://")) else None)
        self.run_id: str | None = None

    def restarted(self) -> bool:
        """True on the first answer (the broker may have restarted while the service was down)
        and whenever Redis's run id changes; False when the broker cannot be reached."""
        if self.client is None:
            return False
        try:
            run_id = self.client.info("server")["run_id"]
        except redis.RedisError:
            return False
        changed, self.run_id = run_id != self.run_id, run_id
        return changed


def resend_lost(jobs, store: ClusterStore, broker: BrokerWatch, stale_seconds: float) -> list[str]:
    """One sweep: send again the jobs whose task is lost (`jobs.dispatch`); returns their ids."""
    resend = store.requeue_silent(stale_seconds)
    for job_id in resend:
        log.warning("job %s: its try has been silent for %.0f s (worker lost); it is sent again",
                    job_id, stale_seconds)
    if broker.restarted():
        resend += store.queued()
    else:
        resend += store.queued(undispatched_only=True)
    resend = list(dict.fromkeys(resend))
    for job_id in resend:
        if not jobs.dispatch(job_id):
            break  # the broker is away: the rest stay marked unsent for the next sweep
    return resend
