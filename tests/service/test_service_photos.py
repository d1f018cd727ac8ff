"""Slow: a seller's photos (kermit, 11 unposed JPEGs) through the live service, prepare included."""

from __future__ import annotations


import httpx
import pytest

from service_helpers import FAST_JOB, LiveService
from shared_data import DATA

KERMIT = DATA / "kermit"


@pytest.mark.slow
@pytest.mark.skipif(not KERMIT.is_dir(), reason=f"{KERMIT} is absent")
def test_photos_become_a_turntable(tmp_path):
    service = LiveService(tmp_path / "data").start()
    try:
        photos = sorted(KERMIT.glob("*.jpg"))
        files = [("files", (p.name, p.read_bytes(), "image/jpeg")) for p in photos]
        r = httpx.post(f"{service.url}/api/jobs", files=files, timeout=120)
        assert r.status_code == 201, r.text
        job_id = r.json()["id"]
        assert service.wait_for(job_id, ("preparing",))["input"] == "11 photos"
        status = service.wait_for(job_id, ("done", "failed"), timeout=600)
        assert status["state"] == "done", status["error"]
        assert status["stages"] == {"preparing": 1.0, "training": 1.0, "rendering": 1.0}
        assert len(status["links"]["frames"]) == int(FAST_JOB["WINDOWSHOP_JOB__RENDER__FRAMES"])
        video = httpx.get(service.url + status["links"]["video"])
        assert video.status_code == 200 and video.content[4:8] == b"ftyp"
        report = httpx.get(service.url + status["links"]["report"]).json()
        assert report["photos"] == 11 and report["placed"] >= 9 and isinstance(report["advice"], list)
        coverage = httpx.get(service.url + status["links"]["coverage"])
        assert coverage.content[:8] == b"\x89PNG\r\n\x1a\n"
    finally:
        service.stop()
