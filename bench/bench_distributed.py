"""Capacity figures of the distributed mode: jobs/hour of one worker, broker and database load per job.

Starts redis-server on loopback, the service in this process (so its SQL statements can be
counted with an SQLAlchemy event) and `windowshop worker` processes, runs JOBS jobs made of a tiny
posed scene with the service's fast job settings (or the pipeline defaults with --default-job),
and prints JSON: wall seconds, jobs/hour, Redis commands per job (`INFO commandstats`), SQL
statements per job, and the internal HTTP calls per job.

    python bench/bench_distributed.py --jobs 6 --workers 1
"""

from __future__ import annotations

import argparse
import contextvars
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import redis
import sqlalchemy as sa
import uvicorn

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from distributed_helpers import CLUSTER_ENV, Cluster  # noqa: E402
from service_helpers import FAST_JOB, posed_scene_zip  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=6)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--heartbeat", type=float, default=5.0, help="the production default")
    args = parser.parse_args()
    os.environ.update({**FAST_JOB, **CLUSTER_ENV, "WINDOWSHOP_HEARTBEAT_SECONDS": str(args.heartbeat),
                       "WINDOWSHOP_STALE_SECONDS": str(max(30.0, 4 * args.heartbeat))})
    root = Path(tempfile.mkdtemp(prefix="windowshop-bench-"))
    cluster = Cluster(root)
    cluster.env = dict(os.environ)
    try:
        print(json.dumps(run(cluster, args), indent=2))
    finally:
        cluster.stop()


def run(cluster: Cluster, args) -> dict:
    from windowshop.distributed.celery_app import ClusterSettings
    from windowshop.distributed.service import create_cluster_app
    from windowshop.service.settings import ServiceSettings

    cluster.start_redis()
    settings = ServiceSettings(data_dir=cluster.root / "data", port=cluster.port)
    app = create_cluster_app(settings, ClusterSettings(broker=cluster.broker))
    statements, calls = {"n": 0}, {}
    counting = contextvars.ContextVar("counting", default=False)

    def statement(*_args, **_kwargs) -> None:
        if counting.get():
            statements["n"] += 1

    sa.event.listen(app.state.store.store.engine, "before_cursor_execute", statement)

    @app.middleware("http")
    async def count(request, call_next):
        """Count the work a job costs: its creation and its workers' calls, not status polls."""
        path = request.url.path
        if path.startswith("/internal/") or (request.method == "POST" and path == "/api/jobs"):
            route = path.rsplit("/", 1)[1]
            calls[route] = calls.get(route, 0) + 1
            counting.set(True)
        return await call_next(request)

    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=cluster.port, log_level="warning"))
    threading.Thread(target=server.run, daemon=True).start()
    for i in range(args.workers):
        cluster.start_worker(f"w{i + 1}")
    scene = posed_scene_zip(cluster.root / "scene.zip")
    broker = redis.Redis.from_url(cluster.broker)
    broker.config_resetstat()
    statements["n"], start = 0, time.monotonic()
    ids = [cluster.submit(scene) for _ in range(args.jobs)]
    states = [cluster.wait_for(i, {"done", "failed", "cancelled"}, timeout=3600)["state"] for i in ids]
    wall = time.monotonic() - start
    stats = broker.info("commandstats")
    redis_calls = sum(v["calls"] for k, v in stats.items() if k != "cmdstat_info")
    server.should_exit = True
    return {"jobs": args.jobs, "workers": args.workers, "states": sorted(set(states)),
            "wall_seconds": round(wall, 1), "jobs_per_hour_per_worker": round(
                3600 * args.jobs / wall / args.workers, 1),
            "redis_commands_per_job": round(redis_calls / args.jobs, 1),
            "redis_commands": {k.removeprefix("cmdstat_"): v["calls"] for k, v in stats.items()},
            "sql_statements_per_job": round(statements["n"] / args.jobs, 1),
            "internal_calls_per_job": {k: round(v / args.jobs, 1) for k, v in sorted(calls.items())},
            "heartbeat_seconds": args.heartbeat, "job": {k: v for k, v in FAST_JOB.items()},
            "cpus": os.cpu_count(), "load_average": os.getloadavg()[0]}


if __name__ == "__main__":
    main()
