"""The service in distributed mode: the same job API, with jobs sent to Celery workers.

`create_cluster_app` is `windowshop.service.app.create_app` without its local worker, whose store
is a `ClusterJobs` (the shared SQL store, plus dispatch to the broker on create and revoke on
cancel and delete), and which adds the worker-facing routes under `/internal/jobs/<id>/`: claim,
input and scene downloads, progress, heartbeat, scene and result uploads, failure. Inputs, posed
scenes and results live in the service's data folder as in single-machine mode; workers move them
over HTTP, so they share no disk with the service.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import secrets
import shutil
import tempfile
import threading
import time
from pathlib import Path

from fastapi import APIRouter, Body, FastAPI, Header, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse
from starlette.background import BackgroundTask

from windowshop.distributed.celery_app import ClusterSettings, configure, gpu_workers
from windowshop.distributed.store import PREPARE, TRAIN, ClusterStore, default_db_url
from windowshop.distributed.sweeps import BrokerWatch, resend_lost
from windowshop.distributed.transfer import replace_folder, unzip_to, zip_folder
from windowshop.errors import failure_reason
from windowshop.service.jobs import load_job_config
from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.store import FINISHED, Job, JobQueue

log = logging.getLogger("windowshop.service")


class ClusterJobs(JobQueue):
    """What the job routes ask of `app.state.store`, over the shared store and the broker."""

    def __init__(self, settings: ServiceSettings, cluster: ClusterSettings):
        self.settings, self.cluster = settings, cluster
        self.store = ClusterStore(cluster.db or default_db_url(settings.data_dir))
        self.celery = configure(cluster)
        self.url = cluster.public_url or f"http://{settings.host}:{settings.port}"
        self._gpu: tuple[float, bool] = (float("-inf"), False)
        self.install_lock = threading.Lock()

    def create(self, job_id: str, input_kind: str, input_summary: str,
               max_queued: int | None = None, owner_hash: str | None = None) -> Job | None:
        from windowshop.pipeline import is_posed_scene
        from windowshop.service.jobs import pipeline_input

        phase = TRAIN if is_posed_scene(pipeline_input(job_dir(self.settings, job_id))) else PREPARE
        job = self.store.create(job_id, input_kind, input_summary, phase, secrets.token_urlsafe(24),
                                max_queued, owner_hash)
        if job is not None:
            self.dispatch(job_id)
        return job

    def dispatch(self, job_id: str) -> bool:
        """Send the task of the job's current phase: prepare on `cpu`, train on `gpu` if any.

        A broker that cannot be reached leaves the job queued and marked unsent (False); the sweep
        (sweeps.py) sends it once the broker is back.
        """
        row = self.store.row(job_id)
        if row is None:
            return True
        # the worker runs the job as this service would: its job config, as JSON
        job = dataclasses.asdict(load_job_config(job_dir(self.settings, job_id), self.settings))
        try:
            queue = "gpu" if row["phase"] == TRAIN and self.have_gpu_workers() else "cpu"
            self.celery.send_task(
                "windowshop.job_phase", task_id=job_id, queue=queue,
                args=(job_id, row["phase"], self.url, row["worker_key"], job,
                      self.cluster.heartbeat_seconds, self.cluster.stale_seconds),
                retry_policy={"max_retries": 2, "interval_start": 0.2, "interval_step": 0.5})
        except Exception as err:  # noqa: BLE001 - kombu's connection errors have no common base
            self.store.set_dispatched(job_id, False)
            log.warning("job %s: the broker is unreachable (%s); it is sent again later", job_id, err)
            return False
        if row["dispatched_at"] is None:
            self.store.set_dispatched(job_id, True)
        log.info("job %s: %s sent to the %s queue", job_id, row["phase"], queue)
        return True

    def have_gpu_workers(self) -> bool:
        checked, found = self._gpu
        if time.monotonic() - checked > self.cluster.queue_check_seconds:
            replies = self.celery.control.inspect(timeout=1.0).active_queues()
            found = bool(gpu_workers(replies))
            self._gpu = (time.monotonic(), found)
        return found

    def revoke(self, job_id: str) -> None:
        """Kill the job's task wherever it runs. Best effort: a try that escapes (the broker is
        away) is refused by the store at its next call, see tasks.py."""
        try:
            self.celery.control.revoke(job_id, terminate=True, signal="SIGKILL")
        except Exception as err:  # noqa: BLE001 - kombu's connection errors have no common base
            log.warning("job %s: could not revoke its task (%s)", job_id, err)

    def cancel(self, job_id: str) -> Job | None:
        job = self.store.cancel(job_id)
        self.revoke(job_id)
        return job

    def delete(self, job_id: str) -> bool:
        job = self.store.get(job_id)
        deleted = self.store.delete(job_id)
        if job is not None and job.state not in FINISHED:
            self.revoke(job_id)
        return deleted

    def expired(self, finished_before: float) -> list[str]:
        return self.store.expired(finished_before)

    def get(self, job_id: str) -> Job | None:
        return self.store.get(job_id)

    def count_queued(self) -> int:
        return self.store.count_queued()

    def queue_position(self, job: Job) -> int:
        return self.store.queue_position(job)


internal = APIRouter(prefix="/internal/jobs/{job_id}", include_in_schema=False)
STALE_TRY = "this try is no longer the job's current one"  # 409: another try took the job over


def _jobs(request: Request) -> ClusterJobs:
    return request.app.state.store


def _checked(request: Request, job_id: str, key: str | None, token: str | None = None) -> dict:
    """The job's row when `key` is its worker key (and `token` its current try's, if given)."""
    row = _jobs(request).store.row(job_id)
    if row is None or key is None or not secrets.compare_digest(row["worker_key"], key):
        raise _Refused(404, "no such job for this key")
    if token is not None and row["run_token"] != token:
        raise _Refused(409, STALE_TRY)
    return row


class _Refused(Exception):
    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


@internal.post("/claim")
def claim(request: Request, job_id: str, body: dict = Body(...),
          x_worker_key: str | None = Header(None)) -> dict:
    _checked(request, job_id, x_worker_key)
    answer = _jobs(request).store.claim(job_id, body["phase"], body["token"], body["worker"],
                                        _jobs(request).cluster.stale_seconds)
    return {"answer": answer}


@internal.get("/{what}")
def download(request: Request, job_id: str, what: str, token: str,
             x_worker_key: str | None = Header(None)) -> FileResponse:
    """The job's input, or (for "scene") its posed scene when prepared, else its input."""
    if what not in ("input", "scene"):
        raise _Refused(404, f"no {what}")
    _checked(request, job_id, x_worker_key, token)
    folder = job_dir(_jobs(request).settings, job_id)
    source = folder / "scene" if what == "scene" and (folder / "scene").is_dir() else folder / "input"
    tmp = Path(tempfile.mkdtemp(prefix="windowshop-send-"))
    archive = zip_folder(source, tmp / f"{what}.zip")
    return FileResponse(archive, media_type="application/zip",
                        background=BackgroundTask(shutil.rmtree, tmp, ignore_errors=True))


@internal.post("/progress")
def progress(request: Request, job_id: str, body: dict = Body(...),
             x_worker_key: str | None = Header(None)) -> dict:
    _checked(request, job_id, x_worker_key)
    if not _jobs(request).store.report(job_id, body["token"], body["stage"], body["progress"],
                                       body["stages"], body["eta_seconds"]):
        raise _Refused(409, STALE_TRY)
    return {"ok": True}


@internal.post("/heartbeat")
def heartbeat(request: Request, job_id: str, body: dict = Body(...),
              x_worker_key: str | None = Header(None)) -> dict:
    _checked(request, job_id, x_worker_key)
    if not _jobs(request).store.beat(job_id, body["token"]):
        raise _Refused(409, STALE_TRY)
    return {"ok": True}


@internal.post("/fail")
def fail(request: Request, job_id: str, body: dict = Body(...),
         x_worker_key: str | None = Header(None)) -> dict:
    _checked(request, job_id, x_worker_key)
    jobs = _jobs(request)
    verdict = jobs.store.fail_try(job_id, body["token"], str(body["error"])[:2000],
                                  transient=bool(body.get("transient", True)))
    if verdict is None:
        raise _Refused(409, STALE_TRY)
    if verdict == "retry":
        jobs.dispatch(job_id)
    log.info("job %s: try failed (%s): %s", job_id, verdict, body["error"])
    return {"verdict": verdict}


async def _receive_folder(request: Request, job_id: str, token: str, dest: Path) -> Path:
    """The request's body (a zip) unpacked into a new folder beside `dest`.

    A body over the job's size cap, or a disk that fills up while it is written, fails the job with
    the reason (trying again would meet the same) and refuses the try (409).
    """
    jobs = _jobs(request)
    tmp = dest.with_name(f".{dest.name}-{secrets.token_hex(4)}")
    archive = tmp.with_suffix(".zip")
    reason, size = None, 0
    try:
        with open(archive, "wb") as f:
            async for chunk in request.stream():
                size += len(chunk)
                if size > jobs.settings.max_job_bytes:
                    reason = (f"the job's {dest.name} is larger than the "
                              f"{jobs.settings.max_job_bytes // 2**20} MiB one job may store")
                    break
                f.write(chunk)
        if reason is None:
            await run_in_threadpool(unzip_to, archive, tmp)
    except OSError as err:
        if err.errno != errno.ENOSPC:
            raise
        reason = failure_reason(err)
    finally:
        archive.unlink(missing_ok=True)
    if reason is not None:
        shutil.rmtree(tmp, ignore_errors=True)
        await run_in_threadpool(jobs.store.fail_try, job_id, token, reason, False)
        raise _Refused(409, reason)
    return tmp


@internal.post("/scene")
async def upload_scene(request: Request, job_id: str, token: str,
                       x_worker_key: str | None = Header(None)) -> dict:
    """The prepare try's posed scene: kept, and the train task sent, if the try is current."""
    jobs = _jobs(request)
    await run_in_threadpool(_checked, request, job_id, x_worker_key, token)
    dest = job_dir(jobs.settings, job_id) / "scene"
    new = await _receive_folder(request, job_id, token, dest)
    return await run_in_threadpool(_install, jobs, job_id, token, new, dest, None)


@internal.post("/result")
async def upload_result(request: Request, job_id: str, token: str, frames: int,
                        x_worker_key: str | None = Header(None)) -> dict:
    """The train try's results: the job is done with them, if the try is current (only once)."""
    jobs = _jobs(request)
    await run_in_threadpool(_checked, request, job_id, x_worker_key, token)
    dest = job_dir(jobs.settings, job_id) / "result"
    new = await _receive_folder(request, job_id, token, dest)
    return await run_in_threadpool(_install, jobs, job_id, token, new, dest, frames)


def _install(jobs: ClusterJobs, job_id: str, token: str, new: Path, dest: Path,
             frames: int | None) -> dict:
    """Move an uploaded folder in place and advance the job, all under the try's token."""
    with jobs.install_lock:  # one upload at a time: the token check and the move go together
        if not jobs.store.owns(job_id, token):
            shutil.rmtree(new, ignore_errors=True)
            raise _Refused(409, STALE_TRY)
        replace_folder(new, dest)
        advanced = (jobs.store.finish(job_id, token, frames) if frames is not None
                    else jobs.store.next_phase(job_id, token, TRAIN))
    if frames is None and advanced:
        jobs.dispatch(job_id)
    return {"ok": advanced}


def create_cluster_app(settings: ServiceSettings, cluster: ClusterSettings) -> FastAPI:
    """The job API and page of `create_app`, with jobs run by the broker's workers."""
    from windowshop.service.app import create_app

    app = create_app(settings, start_worker=False)
    jobs = app.state.store = ClusterJobs(settings, cluster)
    watch = BrokerWatch(cluster.broker)
    app.state.sweeps.append((cluster.silence_check_seconds,
                             lambda: resend_lost(jobs, jobs.store, watch, cluster.stale_seconds)))
    app.include_router(internal)

    @app.exception_handler(_Refused)
    async def refused(request: Request, err: _Refused) -> JSONResponse:
        return JSONResponse({"error": err.message}, status_code=err.status)

    return app


def serve_cluster(settings: ServiceSettings, cluster: ClusterSettings) -> None:
    """`windowshop serve --broker ...` in the foreground until Ctrl-C."""
    import uvicorn

    tls = settings.tls()
    app = create_cluster_app(settings, cluster)
    print(f"windowshop: serving {settings.scheme}://{settings.host}:{settings.port}/ with workers of "
          f"{cluster.broker} (jobs in {settings.data_dir.resolve()}, store "
          f"{app.state.store.store.engine.url.render_as_string(hide_password=True)})", flush=True)
    uvicorn.run(app, host=settings.host, port=settings.port, log_level="info", **tls)
