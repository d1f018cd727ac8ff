"""A real `windowshop serve` running the real pipeline: killed during a job, started again, the job
completes; its results are served; a finished job survives another restart; deleting removes it all.
"""

from __future__ import annotations

import io
import sqlite3
import time

import httpx
import imageio_ffmpeg
import pytest
from PIL import Image

from service_helpers import FAST_JOB, LiveService, alive, posed_scene_zip


@pytest.fixture
def service(tmp_path):
    live = LiveService(tmp_path / "data")
    yield live
    live.stop()


def upload(service: LiveService, path) -> tuple[str, dict]:
    """The new job's id, and the header its owner's requests carry."""
    with open(path, "rb") as f:
        r = httpx.post(f"{service.url}/api/jobs", files=[("files", (path.name, f, "application/zip"))],
                       timeout=60)
    assert r.status_code == 201, r.text
    return r.json()["id"], {"Authorization": f"Bearer {r.json()['owner_token']}"}


def started_at(service: LiveService, job_id: str) -> float:
    """When the worker last started the job (the API does not show it)."""
    with sqlite3.connect(service.data / "jobs.sqlite3") as db:
        return db.execute("SELECT started_at FROM jobs WHERE id = ?", (job_id,)).fetchone()[0]


def test_a_job_survives_a_killed_service_and_its_results_are_served(service, tmp_path):
    scene = posed_scene_zip(tmp_path / "scene.zip")
    service.start()
    (first, first_owner), (second, second_owner) = upload(service, scene), upload(service, scene)
    running = service.wait_for(first, ("training", "rendering", "done"))
    assert running["state"] == "training", "the job finished before it could be interrupted"
    assert service.wait_for(second, ("queued",))["queue_position"] == 0

    killed_at = time.time()
    tree = service.kill()  # the web process dies at once; its worker and job must follow
    deadline = time.monotonic() + 10
    while any(alive(pid) for pid in tree) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [pid for pid in tree if alive(pid)], "processes of the killed service live on"

    service.start()
    assert service.wait_for(second, ("queued",))["state"] == "queued"  # queued jobs stay queued
    httpx.post(f"{service.url}/api/jobs/{second}/cancel", headers=second_owner)  # (no need to wait)
    done = service.wait_for(first, ("done", "failed"))
    assert done["state"] == "done", done["error"]
    assert started_at(service, first) > killed_at  # started again after the restart
    check_results(service, first, done)

    service.stop()  # a finished job stays finished across a restart
    service.start()
    assert httpx.get(f"{service.url}/api/jobs/{first}").json()["state"] == "done"
    assert httpx.get(f"{service.url}/api/jobs/{first}/video.mp4").status_code == 200

    assert httpx.delete(f"{service.url}/api/jobs/{first}", headers=first_owner).status_code == 204
    assert not (service.data / "jobs" / first).exists()
    assert httpx.get(f"{service.url}/api/jobs/{first}").status_code == 404


def check_results(service: LiveService, job_id: str, status: dict) -> None:
    frames = int(FAST_JOB["WINDOWSHOP_JOB__RENDER__FRAMES"])
    size = int(FAST_JOB["WINDOWSHOP_JOB__RENDER__WIDTH"])
    assert len(status["links"]["frames"]) == frames and status["progress"] == 1.0
    video = httpx.get(service.url + status["links"]["video"])
    assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
    part = httpx.get(service.url + status["links"]["video"], headers={"Range": "bytes=0-99"})
    assert part.status_code == 206 and len(part.content) == 100  # browsers seek with ranges
    path = service.data / "downloaded.mp4"
    path.write_bytes(video.content)
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["size"] == (size, size)
    assert sum(1 for _ in reader) == frames
    poster = httpx.get(service.url + status["links"]["poster"])
    assert Image.open(io.BytesIO(poster.content)).size == (size, size)
    images = [Image.open(io.BytesIO(httpx.get(service.url + url).content)).convert("RGB")
              for url in status["links"]["frames"]]
    assert all(im.size == (size, size) for im in images)
    assert images[0].tobytes() != images[frames // 4].tobytes()  # the object turns
    assert httpx.get(f"{service.url}/api/jobs/{job_id}/frames/{frames}.jpg").status_code == 404
