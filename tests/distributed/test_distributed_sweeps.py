"""The distributed service's sweep (lost tasks sent again), the broker-restart sign, the sorting of a
worker's failures into retried and final ones, and a full disk while a result comes in."""

from __future__ import annotations

import errno
import subprocess
import time

import httpx
import pytest
from fastapi.testclient import TestClient

from distributed_helpers import REDIS
from service_helpers import free_port
from windowshop.distributed.celery_app import ClusterSettings
from windowshop.distributed.service import create_cluster_app
from windowshop.distributed.store import TRAIN, ClusterStore, jobs
from windowshop.distributed.sweeps import BrokerWatch, resend_lost
from windowshop.distributed.tasks import _is_transient
from windowshop.errors import UserError
from windowshop.service.settings import ServiceSettings


class Dispatcher:
    """Stands in for ClusterJobs.dispatch: records the jobs sent and marks them as the real one does;
    the broker is away when `down`."""

    def __init__(self, store: ClusterStore):
        self.store, self.sent, self.down = store, [], False

    def dispatch(self, job_id: str) -> bool:
        self.store.set_dispatched(job_id, not self.down)
        if not self.down:
            self.sent.append(job_id)
        return not self.down


class Watch:
    def __init__(self, restarted: bool):
        self.answer = restarted

    def restarted(self) -> bool:
        return self.answer


@pytest.fixture
def store(tmp_path):
    return ClusterStore(f"sqlite:///{tmp_path / 'cluster.sqlite3'}")


def _queued(store: ClusterStore, job_id: str) -> str:
    store.create(job_id, "zip", "a zip", TRAIN, "key")
    return job_id


def test_the_sweep_resends_silent_and_unsent_jobs_only(store):
    running, waiting, unsent = (_queued(store, c * 22) for c in "rwu")
    store.claim(running, TRAIN, "t", "w1", stale_seconds=30)
    with store.engine.begin() as db:
        db.execute(jobs.update().where(jobs.c.id == running).values(heartbeat_at=time.time() - 60))
    store.set_dispatched(unsent, False)
    sender = Dispatcher(store)
    assert resend_lost(sender, store, Watch(False), stale_seconds=30) == [running, unsent]
    assert sender.sent == [running, unsent] and waiting not in sender.sent
    assert resend_lost(sender, store, Watch(False), stale_seconds=30) == []  # nothing lost now


def test_a_restarted_broker_gets_every_queued_job_again(store):
    ids = [_queued(store, c * 22) for c in "abc"]
    sender = Dispatcher(store)
    resend_lost(sender, store, Watch(True), stale_seconds=30)
    assert sender.sent == ids


def test_while_the_broker_is_away_jobs_stay_marked_unsent(store):
    job = _queued(store, "a" * 22)
    store.set_dispatched(job, False)
    sender = Dispatcher(store)
    sender.down = True
    resend_lost(sender, store, Watch(False), stale_seconds=30)
    assert store.queued(undispatched_only=True) == [job]


@pytest.mark.skipif(REDIS is None, reason="redis-server is not installed")
def test_the_broker_watch_sees_a_restart(tmp_path):
    port = free_port()
    command = [REDIS, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no",
               "--dir", str(tmp_path)]
    watch = BrokerWatch(f"redis://127.0.0.1:{port}/0")
    assert not watch.restarted()  # not running: no answer, no restart seen
    for run in range(2):
        server = subprocess.Popen(command, stdout=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 10
            while not watch.restarted():
                assert time.monotonic() < deadline, "redis-server did not answer"
                time.sleep(0.1)
            assert not watch.restarted()  # the same server: no change
        finally:
            server.kill()
            server.wait()


def test_only_transient_faults_are_retried():
    request = httpx.Request("POST", "http://service/internal/jobs/x/result")
    assert _is_transient(MemoryError())
    assert _is_transient(httpx.ConnectError("refused", request=request))
    assert _is_transient(httpx.HTTPStatusError("500", request=request,
                                               response=httpx.Response(500, request=request)))
    assert not _is_transient(httpx.HTTPStatusError("413", request=request,
                                                   response=httpx.Response(413, request=request)))
    assert not _is_transient(UserError("only 2 of 12 photos could be placed"))
    assert not _is_transient(KeyError("a bug"))


def test_a_full_disk_while_a_result_comes_in_fails_the_job_with_the_reason(tmp_path, monkeypatch):
    settings = ServiceSettings(data_dir=tmp_path / "data")
    app = create_cluster_app(settings, ClusterSettings(broker=f"redis://127.0.0.1:{free_port()}/0"))
    store = app.state.store.store
    job = _queued(store, "j" * 22)
    (settings.jobs_dir / job / "input").mkdir(parents=True)  # as the upload left it
    assert store.claim(job, TRAIN, "t", "w1", stale_seconds=30) == "run"

    def no_space(*_args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("windowshop.distributed.service.unzip_to", no_space)
    with TestClient(app) as client:
        answer = client.post(f"/internal/jobs/{job}/result", params={"token": "t", "frames": 8},
                             headers={"X-Worker-Key": "key"}, content=b"PK\x05\x06" + bytes(18))
        assert answer.status_code == 409  # the worker stops: trying again would meet the same
        status = client.get(f"/api/jobs/{job}").json()
    assert status["state"] == "failed" and "disk filled up" in status["error"]
    assert not list((settings.jobs_dir / job).glob(".result-*"))  # the partial upload removed
