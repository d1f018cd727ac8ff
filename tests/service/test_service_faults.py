"""A real `windowshop serve` SIGKILLed while an upload comes in: after the restart no half-made job
is visible (no row in the store, no folder but what the orphan sweep removes) and uploads work."""

from __future__ import annotations

import socket
import sqlite3
import time

import httpx
import pytest

from service_helpers import LiveService, alive, posed_scene_zip
from windowshop.service.db import SQLiteJobStore
from windowshop.service.retention import ORPHAN_SECONDS, sweep_expired
from windowshop.service.settings import ServiceSettings

BOUNDARY = "windowshop-fault-test"


@pytest.fixture
def service(tmp_path):
    live = LiveService(tmp_path / "data")
    yield live
    live.stop()


def start_upload(url_port: int, data: bytes) -> socket.socket:
    """Send a multipart upload of `data` up to its middle, and keep the connection open."""
    head = (f"--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"files\"; "
            f"filename=\"scene.zip\"\r\nContent-Type: application/zip\r\n\r\n").encode()
    tail = f"\r\n--{BOUNDARY}--\r\n".encode()
    request = (f"POST /api/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: "
               f"{len(head) + len(data) + len(tail)}\r\nContent-Type: multipart/form-data; "
               f"boundary={BOUNDARY}\r\n\r\n").encode()
    sock = socket.create_connection(("127.0.0.1", url_port), timeout=10)
    sock.sendall(request + head + data[: len(data) // 2])
    return sock


def rows(service: LiveService) -> int:
    with sqlite3.connect(service.data / "jobs.sqlite3") as db:
        return db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]


def test_a_service_killed_during_an_upload_leaves_no_half_made_job(service, tmp_path):
    data = posed_scene_zip(tmp_path / "scene.zip").read_bytes()
    service.start()
    sock = start_upload(service.port, data)
    time.sleep(1.0)  # the service is reading the body
    tree = service.kill()
    sock.close()
    deadline = time.monotonic() + 10
    while any(alive(pid) for pid in tree) and time.monotonic() < deadline:
        time.sleep(0.1)

    service.start()
    assert rows(service) == 0  # the interrupted upload made no job
    store = SQLiteJobStore(service.data / "jobs.sqlite3")
    settings = ServiceSettings(data_dir=service.data)
    sweep_expired(settings, store, now=time.time() + 2 * ORPHAN_SECONDS)  # any leftover folder
    assert not any(settings.jobs_dir.iterdir())
    created = httpx.post(f"{service.url}/api/jobs", timeout=60,
                         files=[("files", ("scene.zip", data, "application/zip"))])
    assert created.status_code == 201 and rows(service) == 1  # (test_service_restart runs one)
