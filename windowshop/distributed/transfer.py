"""Folders travelling between the service and the workers over HTTP, as zip files.

A worker downloads a job's input (or its posed scene) and uploads its posed scene or its results;
every call carries the job's worker key, every write also the try's run token, so the service can
refuse a try that is no longer the job's current one (HTTP 409).
"""

from __future__ import annotations

import shutil
import tempfile
import threading
import time
import zipfile
from pathlib import Path

import httpx


class Abandoned(Exception):
    """The service no longer wants this try (cancelled, deleted, or taken over by another)."""


def zip_folder(folder: Path, out: Path) -> Path:
    """`folder`'s files into the zip `out` (stored, not compressed: JPEG and MP4 are already)."""
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                archive.write(path, path.relative_to(folder).as_posix())
    return out


def unzip_to(archive: Path, folder: Path) -> Path:
    """Unpack a zip made by `zip_folder` into `folder` (refusing entries that escape it)."""
    folder.mkdir(parents=True, exist_ok=True)
    root = folder.resolve()
    with zipfile.ZipFile(archive) as z:
        for entry in z.infolist():
            if not (root / entry.filename).resolve().is_relative_to(root):
                raise ValueError(f"zip entry {entry.filename!r} escapes its folder")
        z.extractall(folder)
    return folder


class ServiceClient:
    """One try of one job talking to the service at `url` (`/internal/jobs/<id>/...`)."""

    def __init__(self, url: str, job_id: str, key: str, token: str, timeout: float = 120.0):
        self.base = f"{url.rstrip('/')}/internal/jobs/{job_id}"
        self.token = token
        self.http = httpx.Client(headers={"X-Worker-Key": key}, timeout=timeout)
        self.abandoned = threading.Event()

    def close(self) -> None:
        self.http.close()

    def _post(self, path: str, **kwargs) -> httpx.Response:
        response = self.http.post(f"{self.base}/{path}", **kwargs)
        if response.status_code in (404, 409):
            self.abandoned.set()
            raise Abandoned(response.text)
        response.raise_for_status()
        return response

    def claim(self, phase: str, worker: str) -> str:
        """"run", "busy" or "skip" (see ClusterStore.claim)."""
        response = self.http.post(f"{self.base}/claim", json={
            "phase": phase, "token": self.token, "worker": worker})
        if response.status_code == 404:
            return "skip"
        response.raise_for_status()
        return response.json()["answer"]

    def download(self, what: str, folder: Path) -> Path:
        """The job's `what` ("input" or "scene") unpacked into `folder`."""
        with tempfile.TemporaryDirectory() as tmp:
            archive = Path(tmp) / f"{what}.zip"
            with self.http.stream("GET", f"{self.base}/{what}", params={"token": self.token}) as r:
                if r.status_code in (404, 409):
                    raise Abandoned(f"{what}: HTTP {r.status_code}")
                r.raise_for_status()
                with open(archive, "wb") as f:
                    for chunk in r.iter_bytes():
                        f.write(chunk)
            return unzip_to(archive, folder)

    def upload(self, what: str, folder: Path, waits: tuple[float, ...] = (2.0, 5.0, 10.0),
               **params) -> dict:
        """`folder` as the job's `what` ("scene" or "result") from this try; sent again after each
        of `waits` seconds while the service (or its database) is unreachable or failing, so a
        brief restart does not cost the whole try."""
        with tempfile.TemporaryDirectory() as tmp:
            archive = zip_folder(folder, Path(tmp) / f"{what}.zip")
            for wait in waits:
                try:
                    return self._send(what, archive, params)
                except httpx.HTTPStatusError as err:
                    if err.response.status_code < 500:
                        raise
                except httpx.TransportError:
                    pass
                time.sleep(wait)
            return self._send(what, archive, params)

    def _send(self, what: str, archive: Path, params: dict) -> dict:
        with open(archive, "rb") as f:
            return self._post(what, params={"token": self.token, **params}, content=f).json()

    def report(self, job_id: str, run_token: str, stage: str, progress: float,
               stages: dict[str, float], eta_seconds: float | None) -> bool:
        """ProgressReporter's store interface; a refusal marks the try abandoned."""
        try:
            self._post("progress", json={"token": run_token, "stage": stage, "progress": progress,
                                         "stages": stages, "eta_seconds": eta_seconds})
        except Abandoned:
            if threading.current_thread() is threading.main_thread():
                raise
            return False  # the fit's helper thread: the main thread stops at its next report
        except httpx.HTTPError:
            return True  # progress is best effort; the result upload is what counts
        return True

    def beat(self) -> None:
        try:
            self._post("heartbeat", json={"token": self.token})
        except (Abandoned, httpx.HTTPError):
            pass

    def fail(self, error: str, transient: bool) -> str | None:
        """Report the try's failure: "retry", "failed", or None when the try was no longer current
        or the service could not be told (its sweep then notices the silent try)."""
        try:
            return self._post("fail", json={"token": self.token, "error": error,
                                            "transient": transient}).json()["verdict"]
        except (Abandoned, httpx.HTTPError):
            return None


def replace_folder(new: Path, dest: Path) -> None:
    """Put `new` where `dest` is, removing what was there."""
    shutil.rmtree(dest, ignore_errors=True)
    new.rename(dest)
