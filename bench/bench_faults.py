"""Faults the distributed mode survives, with DEFAULT cluster settings (heartbeat 5 s, stale 30 s,
sweep every 5 s, Redis visibility timeout 3600 s): real redis-server, `windowshop serve --broker` and
`windowshop worker` processes on loopback, tiny posed-scene jobs (the service's fast job settings).

    python bench/bench_faults.py [--faults worker redis postgres] [--repeats 3]

Prints JSON, one object per fault: the jobs accepted, how they ended (done, failed with a reason,
vanished: never ended within 5 minutes), and for `worker` (one of two workers SIGKILLed mid-training)
the seconds from the kill to the job running again on the other worker, and to its end.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from distributed_helpers import Cluster, end  # noqa: E402
from postgres_helpers import PostgresServer, postgres_bin  # noqa: E402
from service_helpers import posed_scene_zip  # noqa: E402

ENDED = {"done", "failed", "cancelled"}


def outcomes(cluster: Cluster, ids: list[str]) -> dict:
    """How each accepted job ended: done, failed (with a reason), or vanished."""
    counts = {"accepted": len(ids), "done": 0, "failed_with_reason": 0, "vanished": 0}
    for job_id in ids:
        try:
            status = cluster.wait_for(job_id, ENDED, timeout=300)
        except AssertionError:
            counts["vanished"] += 1
            continue
        if status["state"] == "done":
            counts["done"] += 1
        elif status["error"]:
            counts["failed_with_reason"] += 1
    return counts


def worker_killed(root: Path) -> dict:
    from windowshop.distributed.store import ClusterStore, default_db_url

    cluster = Cluster(root, env={}).start()
    try:
        cluster.start_worker("w1")
        cluster.start_worker("w2")
        store = ClusterStore(default_db_url(root / "data"))
        job_id = cluster.submit(posed_scene_zip(root / "scene.zip"))
        cluster.wait_for(job_id, {"training"})
        victim = store.row(job_id)["worker"]
        cluster.kill_worker(victim.split("@")[0])
        killed = time.monotonic()
        while store.row(job_id)["worker"] == victim and time.monotonic() - killed < 600:
            time.sleep(0.2)
        resumed = time.monotonic() - killed
        result = outcomes(cluster, [job_id])
        return {**result, "seconds_to_resume": round(resumed, 1),
                "seconds_to_end": round(time.monotonic() - killed, 1)}
    finally:
        cluster.stop()


def redis_restarted(root: Path) -> dict:
    cluster = Cluster(root, env={}).start()
    try:
        cluster.start_worker("w1")
        scene = posed_scene_zip(root / "scene.zip")
        ids = [cluster.submit(scene), cluster.submit(scene)]  # one running, one queued in Redis
        cluster.wait_for(ids[0], {"training"})
        end(cluster.redis)  # no persistence: the queued task is lost
        ids.append(cluster.submit(scene))  # accepted while the broker is away
        time.sleep(2)
        cluster.start_redis()
        return outcomes(cluster, ids)
    finally:
        cluster.stop()


def postgres_restarted(root: Path) -> dict:
    server = PostgresServer(postgres_bin()).start()
    cluster = Cluster(root, env={}, db=server.url).start()
    try:
        cluster.start_worker("w1")
        scene = posed_scene_zip(root / "scene.zip")
        ids = [cluster.submit(scene), cluster.submit(scene)]
        cluster.wait_for(ids[0], {"training"})
        server.stop()
        time.sleep(8)
        server.start()
        return outcomes(cluster, ids)
    finally:
        cluster.stop()
        server.remove()


FAULTS = {"worker": worker_killed, "redis": redis_restarted, "postgres": postgres_restarted}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faults", nargs="+", choices=list(FAULTS), default=list(FAULTS))
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    for name in args.faults:
        for repeat in range(args.repeats):
            root = Path(tempfile.mkdtemp(prefix=f"windowshop-fault-{name}-"))
            try:
                figures = FAULTS[name](root)
            finally:
                shutil.rmtree(root, ignore_errors=True)
            print(json.dumps({"fault": name, "repeat": repeat, **figures,
                              "load_average": round(os.getloadavg()[0], 1)}), flush=True)


if __name__ == "__main__":
    main()
