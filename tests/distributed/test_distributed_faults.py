"""The distributed mode's promises under faults, with real processes: Redis restarted mid-job (without
persistence: the queued tasks are lost with it) and PostgreSQL restarted mid-job. Every accepted job
ends done or failed with a reason; none vanishes or waits forever."""

from __future__ import annotations

import time

import pytest

from distributed_helpers import REDIS, Cluster, end
from postgres_helpers import PostgresServer, postgres_bin
from service_helpers import posed_scene_zip

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(REDIS is None, reason="redis-server is not installed")]
ENDED = {"done", "failed", "cancelled"}


def ends_well(cluster: Cluster, job_id: str) -> dict:
    status = cluster.wait_for(job_id, ENDED, timeout=300)
    assert status["state"] == "done" or (status["state"] == "failed" and status["error"]), status
    return status


def test_jobs_survive_a_redis_restart_that_loses_the_queue(tmp_path):
    cluster = Cluster(tmp_path).start()
    try:
        cluster.start_worker("w1")
        scene = posed_scene_zip(tmp_path / "scene.zip")
        running, queued = cluster.submit(scene), cluster.submit(scene)
        cluster.wait_for(running, {"training"})
        assert cluster.status(queued)["state"] == "queued"  # its task waits in Redis ...
        end(cluster.redis)  # ... and is lost with it (no persistence)
        during = cluster.submit(scene)  # accepted while the broker is away
        time.sleep(2)
        cluster.start_redis()
        states = [ends_well(cluster, job)["state"] for job in (running, queued, during)]
        assert states == ["done"] * 3, cluster.logs()
    finally:
        cluster.stop()


@pytest.fixture
def postgres():
    bin_dir = postgres_bin()
    if bin_dir is None:
        pytest.skip("PostgreSQL is not installed (apt-get install postgresql)")
    pytest.importorskip("psycopg", reason="psycopg is not installed (pip install psycopg[binary])")
    server = PostgresServer(bin_dir).start()
    yield server
    server.remove()


def test_jobs_survive_a_postgresql_restart(tmp_path, postgres):
    cluster = Cluster(tmp_path, db=postgres.url).start()
    try:
        cluster.start_worker("w1")
        scene = posed_scene_zip(tmp_path / "scene.zip")
        running, queued = cluster.submit(scene), cluster.submit(scene)
        cluster.wait_for(running, {"training"})
        postgres.stop()  # progress, heartbeats and maybe the upload meet a database that is away
        time.sleep(8)
        postgres.start()
        states = [ends_well(cluster, job)["state"] for job in (running, queued)]
        assert states == ["done"] * 2, cluster.logs()
    finally:
        cluster.stop()
