"""The distributed mode end to end: redis-server, `windowshop serve --broker` and two
`windowshop worker` processes on loopback, running the real pipeline on tiny posed scenes."""

from __future__ import annotations

import json
import time
import zipfile

import httpx
import pytest

from distributed_helpers import REDIS, Cluster
from service_helpers import posed_scene_zip
from windowshop.distributed.store import ClusterStore, default_db_url

pytestmark = pytest.mark.skipif(REDIS is None, reason="redis-server is not installed "
                                "(apt-get install redis-server)")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    root = tmp_path_factory.mktemp("cluster")
    cluster = Cluster(root).start()
    try:
        cluster.start_worker("w1")
        cluster.start_worker("w2")
        cluster.scene = posed_scene_zip(root / "scene.zip")
        cluster.store = ClusterStore(default_db_url(root / "data"))
        yield cluster
    finally:
        cluster.stop()


def test_six_jobs_complete_spread_over_both_workers(cluster):
    ids = [cluster.submit(cluster.scene) for _ in range(6)]
    for job_id in ids:
        status = cluster.wait_for(job_id, {"done", "failed", "cancelled"})
        assert status["state"] == "done", status
        assert len(status["links"]["frames"]) == 8  # FAST_JOB's frames, rendered by a worker
        video = httpx.get(cluster.url + status["links"]["video"], timeout=10)
        assert video.status_code == 200 and video.content[4:8] == b"ftyp"
    rows = [cluster.store.row(i) for i in ids]
    assert {r["worker"] for r in rows} == {"w1@test", "w2@test"}
    assert all(r["attempts"] == 1 and r["run_token"] is None for r in rows)


def test_a_users_error_fails_the_job_at_once_with_its_reason(cluster, tmp_path):
    broken = tmp_path / "broken.zip"
    good = zipfile.ZipFile(cluster.scene)
    with zipfile.ZipFile(broken, "w") as archive:
        image = next(n for n in good.namelist() if n.endswith(".png"))
        archive.writestr(image, good.read(image))  # one real image, so the upload is accepted
        archive.writestr("tiny-scene/transforms.json", json.dumps({"camera_angle_x": 0.7,
                                                                   "frames": []}))
    job_id = cluster.submit(broken)
    status = cluster.wait_for(job_id, {"done", "failed", "cancelled"})
    assert status["state"] == "failed" and status["error"]
    assert "internal error" not in status["error"] and "times" not in status["error"]
    assert cluster.store.row(job_id)["attempts"] == 1  # not tried again: the input is at fault


def test_cancel_revokes_a_running_job_and_its_worker_takes_the_next(cluster):
    job_id = cluster.submit(cluster.scene)
    cluster.wait_for(job_id, {"training", "rendering"})
    cancelled = cluster.cancel(job_id)
    assert cancelled["state"] == "cancelled"
    time.sleep(6)  # long enough for the tiny job to have finished had it not been stopped
    status = cluster.status(job_id)
    assert status["state"] == "cancelled" and status["links"]["video"] is None
    assert httpx.get(f"{cluster.url}/api/jobs/{job_id}/video.mp4", timeout=10).status_code == 409
    busy = [cluster.submit(cluster.scene) for _ in range(2)]
    for job in busy:  # both workers at work, so the next job waits in the queue ...
        cluster.wait_for(job, {"training", "rendering"})
    queued = cluster.submit(cluster.scene)
    cancelled = cluster.cancel(queued)
    after = cluster.submit(cluster.scene)  # both workers must still be there to run this one
    assert cluster.wait_for(after, {"done", "failed"})["state"] == "done"
    assert cluster.status(queued)["state"] == "cancelled"
    assert cluster.store.row(queued)["attempts"] == 0  # ... and is discarded, never run
    # the busy jobs ran on: `after` took the first worker freed, the other busy job may still render
    assert all(cluster.wait_for(job, {"done", "failed"})["state"] == "done" for job in busy)


def test_a_job_on_a_sigkilled_worker_completes_on_the_other(cluster):
    job_id = cluster.submit(cluster.scene)
    cluster.wait_for(job_id, {"training"})
    victim = cluster.store.row(job_id)["worker"].split("@")[0]
    cluster.kill_worker(victim)  # the worker and its pool process, as a lost machine
    status = cluster.wait_for(job_id, {"done", "failed", "cancelled"})
    assert status["state"] == "done", status
    row = cluster.store.row(job_id)
    assert row["worker"] != f"{victim}@test" and row["attempts"] == 2
    assert len(status["links"]["frames"]) == 8
