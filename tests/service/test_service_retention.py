"""Disk bounds: expired jobs swept (by a call, and by the service on its own), uploads refused with 507
under the free-space floor and with 413 over one job's size cap, nothing saved lost on a refusal."""

from __future__ import annotations

import errno
import os
import threading
import time
from collections import namedtuple

import pytest
from fastapi.testclient import TestClient

from test_service_api import photos, refused
from windowshop.distributed.celery_app import ClusterSettings
from windowshop.distributed.service import ClusterJobs
from windowshop.distributed.store import TRAIN
from windowshop.service.app import create_app
from windowshop.service.db import SQLiteJobStore
from windowshop.service.retention import DAY, ORPHAN_SECONDS, Sweeper, sweep_expired
from windowshop.service.settings import ServiceSettings, job_dir


def _sqlite(settings):
    store = SQLiteJobStore(settings.db_path)
    return store, lambda job_id: store.create(job_id, "photos", "3 photos")


def _cluster(settings):
    jobs = ClusterJobs(settings, ClusterSettings(broker="redis://127.0.0.1:1/0"))
    # no broker here: revoking would connect Celery's (process-wide) app to this fake address
    jobs.revoke = lambda job_id: None
    return jobs, lambda job_id: jobs.store.create(job_id, "photos", "3 photos", TRAIN, "key")


@pytest.mark.parametrize("make_store", [_sqlite, _cluster], ids=["sqlite", "cluster"])
def test_the_sweep_deletes_expired_jobs_and_orphans_only(tmp_path, make_store):
    settings = ServiceSettings(data_dir=tmp_path / "data", retention_days=7)
    settings.jobs_dir.mkdir(parents=True)
    store, create = make_store(settings)
    ids = {name: name * 22 for name in ("old", "new", "live")}
    for job_id in ids.values():
        (job_dir(settings, job_id) / "input").mkdir(parents=True)
        create(job_id)
    store.cancel(ids["old"])
    store.cancel(ids["new"])
    stale, fresh = job_dir(settings, "x" * 22), job_dir(settings, "y" * 22)
    for folder in (stale, fresh):  # folders without a row: an upload killed, one coming in
        (folder / "upload").mkdir(parents=True)
    ago = time.time() - 2 * ORPHAN_SECONDS
    os.utime(stale, (ago, ago))

    assert sweep_expired(settings, store) == ["x" * 22]
    assert not stale.exists() and fresh.exists()
    later = time.time() + 3 * DAY  # no job has expired yet; the other orphan is old by then
    assert sweep_expired(settings, store, now=later) == ["y" * 22]
    swept = sweep_expired(settings, store, now=time.time() + 8 * DAY)  # both ended 8 days before
    assert sorted(swept) == sorted([ids["old"], ids["new"]])
    for name in ("old", "new"):
        assert store.get(ids[name]) is None and not job_dir(settings, ids[name]).exists()
    assert store.get(ids["live"]).state == "queued" and job_dir(settings, ids["live"]).is_dir()


def test_the_service_sweeps_on_its_own(tmp_path):
    settings = ServiceSettings(data_dir=tmp_path / "data", retention_days=0,
                               retention_check_seconds=0.1)
    with TestClient(create_app(settings, start_worker=False)) as client:
        created = client.post("/api/jobs", files=photos()).json()
        job_id, token = created["id"], created["owner_token"]
        client.post(f"/api/jobs/{job_id}/cancel", headers={"Authorization": f"Bearer {token}"})
        deadline = time.monotonic() + 10
        while client.get(f"/api/jobs/{job_id}").status_code != 404:
            assert time.monotonic() < deadline, "the ended job was never swept"
            time.sleep(0.1)
    assert not job_dir(settings, job_id).exists()


def test_a_failing_sweep_is_logged_and_run_again(caplog):
    calls, twice = [], threading.Event()

    def flaky() -> None:
        calls.append(1)
        if len(calls) == 1:
            raise ConnectionError("the database is restarting")
        twice.set()

    sweeper = Sweeper([(0.05, flaky)]).start()
    try:
        assert twice.wait(10)
    finally:
        sweeper.stop()
    assert "the database is restarting" in caplog.text


Usage = namedtuple("Usage", "total used free")


def _two_clients(tmp_path, **limits):
    """A normal service and one with `limits`, on the same data folder (the first holds a job)."""
    normal = TestClient(create_app(ServiceSettings(data_dir=tmp_path / "data"), start_worker=False))
    limited = TestClient(create_app(ServiceSettings(data_dir=tmp_path / "data", **limits),
                                    start_worker=False))
    return normal, limited


def test_uploads_are_refused_under_the_free_space_floor(tmp_path, monkeypatch):
    normal, limited = _two_clients(tmp_path, min_free_bytes=2**30)
    saved = normal.post("/api/jobs", files=photos()).json()["id"]
    monkeypatch.setattr("windowshop.service.routes.shutil.disk_usage",
                        lambda path: Usage(2**40, 2**40 - 2**29, 2**29))  # 512 MiB free
    detail = refused(limited.post("/api/jobs", files=photos()), 507, "disk_full")
    assert "512.0 MiB free" in detail
    jobs = sorted(p.name for p in (tmp_path / "data" / "jobs").iterdir())
    assert jobs == [saved] and normal.get(f"/api/jobs/{saved}").json()["state"] == "queued"


def test_an_upload_over_the_job_size_cap_is_refused(tmp_path):
    normal, limited = _two_clients(tmp_path, max_job_bytes=3000)
    saved = normal.post("/api/jobs", files=photos()).json()["id"]
    big = photos()  # 5 photos of noise, over 3000 bytes together
    assert "at most 0.0 MiB" in refused(limited.post("/api/jobs", files=big), 413, "job_too_large")
    assert sorted(p.name for p in (tmp_path / "data" / "jobs").iterdir()) == [saved]
    assert (tmp_path / "data" / "jobs" / saved / "input").is_dir()


def test_a_disk_that_fills_up_during_an_upload_refuses_it_alone(tmp_path, monkeypatch):
    normal, _ = _two_clients(tmp_path)
    saved = normal.post("/api/jobs", files=photos()).json()["id"]

    def no_space(*_args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("windowshop.service.routes.copy_limited", no_space)
    assert "filled up" in refused(normal.post("/api/jobs", files=photos()), 507, "disk_full")
    assert sorted(p.name for p in (tmp_path / "data" / "jobs").iterdir()) == [saved]
