"""The job API: create a job from an upload, read its state, fetch its results, cancel, delete.

A job is reachable only through its id (a random 128-bit token); there is no route that lists jobs.
Whoever has the id may watch the job; only its owner may cancel or delete it: creation answers an
`owner_token` (the store keeps its SHA-256 alone), which those two routes need as
`Authorization: Bearer <token>`. Every refusal answers `{"error": code, "detail": message}` with a
4xx (or 503, 507) status.
"""

from __future__ import annotations

import errno
import hashlib
import json
import re
import secrets
import shutil
from pathlib import Path

from fastapi import APIRouter, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse
from pydantic import BaseModel
from starlette.exceptions import HTTPException
from starlette.formparsers import MultiPartException

from windowshop.config import PipelineConfig
from windowshop.errors import UserError
from windowshop.overrides import leaves
from windowshop.service.jobs import FRAME_NAME, MODEL_FILES, job_config, save_job_config
from windowshop.service.retention import folder_bytes
from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.store import DONE, FINISHED, QUEUED, Job, JobQueue
from windowshop.service.uploads import UploadRefused, check_upload, copy_limited

router = APIRouter(prefix="/api")
_ID = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
_MULTIPART = {"requestBody": {"required": True, "content": {"multipart/form-data": {"schema": {
    "type": "object", "required": ["files"], "properties": {"files": {
        "type": "array", "items": {"type": "string", "format": "binary"},
        "description": "photos (JPEG, PNG, WebP), or one video, or one zip of photos or of a "
                       "posed scene"}, "settings": {
        "type": "string", "description": "optional JSON object of this job's settings by dotted "
        "path (budgets and sizes only lower than the service's), e.g. {\"render.frames\": 36}; "
        "the settings: " + ", ".join(leaves(PipelineConfig)) + ", model_settings.<any field of the "
        "model's config>"}}}}}}}


class ApiError(Exception):
    """A refusal: HTTP `status`, a short `code` and a message saying what to do."""

    def __init__(self, status: int, code: str, message: str, headers: dict | None = None):
        super().__init__(message)
        self.status, self.code, self.message, self.headers = status, code, message, headers


class JobCreated(BaseModel):
    id: str
    url: str  # the job's API address
    page: str  # the page that shows the job (the link to share)
    owner_token: str  # needed to cancel or delete the job (Authorization: Bearer ...); shown once


class JobLinks(BaseModel):
    video: str | None  # once done
    poster: str | None
    frames: list[str]  # per-frame images of the turntable, in order
    report: str | None = None  # the capture's quality report (JSON: advice, coverage, PSNR)
    coverage: str | None = None  # where the photos were taken from (PNG)
    model: str | None = None  # the object as a 3D model (GLB), when the job made one
    usdz: str | None = None  # ... and as USDZ, for AR Quick Look on iOS


class JobStatus(BaseModel):
    id: str
    state: str  # queued | preparing | training | rendering | done | failed | cancelled
    stage: str | None  # the running (or last) stage
    progress: float  # of that stage, 0..1
    stages: dict[str, float]  # progress of each stage run so far; a stage absent was skipped
    eta_seconds: float | None  # rough time left while running
    queue_position: int | None  # jobs ahead of this one while queued
    error: str | None
    input: str  # what was uploaded, in words
    created_at: float  # Unix time
    links: JobLinks


class ApiRefusal(BaseModel):
    error: str
    detail: str


_REFUSALS = {code: {"model": ApiRefusal} for code in (400, 403, 404, 409, 413, 415, 503, 507)}


def _store(request: Request) -> JobQueue:
    return request.app.state.store


def _settings(request: Request) -> ServiceSettings:
    return request.app.state.settings


def _job(request: Request, job_id: str) -> Job:
    job = _store(request).get(job_id) if _ID.match(job_id) else None
    if job is None:
        raise ApiError(404, "no_such_job", f"there is no job {job_id!r} (deleted, or a mistyped link)")
    return job


def owner_hash(token: str) -> str:
    """What the store keeps of an owner token (a random 256-bit one: a plain hash is enough)."""
    return hashlib.sha256(token.encode()).hexdigest()


def _owned(request: Request, job_id: str) -> Job:
    """The job, when the request carries its owner token (403 otherwise)."""
    job = _job(request, job_id)
    scheme, _, token = request.headers.get("authorization", "").partition(" ")
    if scheme.lower() != "bearer" or not token.strip():
        raise ApiError(403, "not_owner", "only the job's owner may do this: send the owner_token "
                       "its creation answered, as 'Authorization: Bearer <token>'")
    if job.owner_hash is None or not secrets.compare_digest(job.owner_hash,
                                                            owner_hash(token.strip())):
        raise ApiError(403, "not_owner", "this owner token is not the job's; only the browser "
                       "(or client) that created the job may cancel or delete it")
    return job


def _result(request: Request, job_id: str, name: str) -> Path:
    job = _job(request, job_id)
    if job.state != DONE:
        raise ApiError(409, "not_done", f"the job is {job.state}; its results exist once it is done")
    path = job_dir(_settings(request), job_id) / "result" / name
    if not path.is_file():
        raise ApiError(404, "no_such_file", f"the job has no {name}")
    return path


def job_status(request: Request, job: Job) -> JobStatus:
    base = f"/api/jobs/{job.id}"
    done = job.state == DONE
    return JobStatus(
        id=job.id, state=job.state, stage=job.stage, progress=job.progress, stages=job.stages,
        eta_seconds=job.eta_seconds, error=job.error, input=job.input_summary,
        queue_position=_store(request).queue_position(job) if job.state == QUEUED else None,
        created_at=job.created_at,
        links=JobLinks(video=f"{base}/video.mp4" if done else None,
                       poster=f"{base}/poster.jpg" if done else None,
                       frames=[f"{base}/frames/{i}.jpg" for i in range(job.frames if done else 0)],
                       report=f"{base}/report.json" if done else None,
                       coverage=f"{base}/coverage.png" if done else None,
                       **_model_links(request, job, base)))


def _model_links(request: Request, job: Job, base: str) -> dict:
    """The 3D models' links, once done and if the job made them (models can be turned off)."""
    result = job_dir(_settings(request), job.id) / "result"
    if job.state != DONE or not (result / MODEL_FILES["model.glb"]).is_file():
        return {}
    return {"model": f"{base}/model.glb", "usdz": f"{base}/model.usdz"}


class _LimitedBody:
    """The request's `receive`, refusing the body past `limit` bytes (a lying or absent length)."""

    def __init__(self, receive, limit: int):
        self.receive, self.limit, self.size, self.exceeded = receive, limit, 0, False

    async def __call__(self):
        message = await self.receive()
        self.size += len(message.get("body", b""))
        if self.size > self.limit:
            self.exceeded = True
            raise MultiPartException("upload too large")  # starlette then closes its temporary files
        return message


def _queue_full(settings: ServiceSettings) -> ApiError:
    return ApiError(503, "queue_full", f"{settings.max_queued} jobs are already waiting; try "
                    "again in a few minutes", headers={"Retry-After": "120"})


def _too_large(limit: int) -> ApiError:
    return ApiError(413, "upload_too_large", f"the upload is larger than the limit of "
                    f"{limit // 2**20} MiB; send fewer or smaller files")


@router.post("/jobs", status_code=201, response_model=JobCreated, openapi_extra=_MULTIPART,
             responses=_REFUSALS, summary="Create a job from photos, a video or a zip")
async def create_job(request: Request) -> JobCreated:
    settings, store = _settings(request), _store(request)
    if await run_in_threadpool(store.count_queued) >= settings.max_queued:  # before reading the upload
        raise _queue_full(settings)
    length = request.headers.get("content-length", "")
    if length.isdigit() and int(length) > settings.max_upload_bytes:
        raise _too_large(settings.max_upload_bytes)
    _check_free_space(settings)
    job_id, token = secrets.token_urlsafe(16), secrets.token_urlsafe(32)
    folder = job_dir(settings, job_id)
    try:
        checked = await _receive_upload(request, folder, settings)
        await run_in_threadpool(_check_stored_size, folder, settings)
    except BaseException as err:
        shutil.rmtree(folder, ignore_errors=True)  # this upload only: saved jobs are untouched
        if isinstance(err, OSError) and err.errno == errno.ENOSPC:
            raise ApiError(507, "disk_full", "the service's disk filled up while the upload was "
                           "saved; try again later", headers={"Retry-After": "600"}) from None
        raise
    job = await run_in_threadpool(store.create, job_id, checked.kind, checked.summary,
                                  settings.max_queued, owner_hash(token))
    if job is None:
        shutil.rmtree(folder, ignore_errors=True)  # the queue filled while this upload came in
        raise _queue_full(settings)
    return JobCreated(id=job_id, url=f"/api/jobs/{job_id}", page=f"/jobs/{job_id}",
                      owner_token=token)


def _check_free_space(settings: ServiceSettings) -> None:
    """507 while the data folder's disk has less than `min_free_bytes` free (running jobs need it)."""
    free = shutil.disk_usage(settings.jobs_dir).free
    if free < settings.min_free_bytes:
        raise ApiError(507, "disk_full", f"the service is short of disk space ({_mib(free)} free, "
                       f"{_mib(settings.min_free_bytes)} kept for running jobs); try again later",
                       headers={"Retry-After": "600"})


def _check_stored_size(folder: Path, settings: ServiceSettings) -> None:
    """413 when the checked upload takes more than `max_job_bytes`; 507 when it left too little free."""
    size = folder_bytes(folder)
    if size > settings.max_job_bytes:
        raise ApiError(413, "job_too_large", f"the upload takes {_mib(size)} once unpacked; one "
                       f"job may store at most {_mib(settings.max_job_bytes)}")
    _check_free_space(settings)


def _mib(n: int) -> str:
    return f"{n / 2**20:.1f} MiB"


async def _receive_upload(request: Request, folder: Path, settings: ServiceSettings):
    """Save the form's `files` under `folder/upload`, then check and lay them out (check_upload)."""
    body = _LimitedBody(request.receive, settings.max_upload_bytes)
    limited = Request(request.scope, body)
    try:
        form = await limited.form(max_files=settings.max_files, max_fields=20)
    except HTTPException as err:
        if body.exceeded:
            raise _too_large(settings.max_upload_bytes) from None
        code = "too_many_files" if "files" in str(err.detail) else "bad_form"
        raise ApiError(400, code, f"{err.detail} Send at most {settings.max_files} files in the "
                       "multipart field 'files'") from None
    uploads = form.getlist("files")
    try:
        config = _upload_settings(form.get("settings"), settings)
        if any(isinstance(u, str) for u in uploads):
            raise ApiError(400, "bad_form", "the field 'files' must hold files, not text")
        (folder / "upload").mkdir(parents=True)
        parts = []
        for i, upload in enumerate(uploads):
            dest = folder / "upload" / f"part-{i:04d}"
            name = upload.filename or f"file {i + 1}"
            await run_in_threadpool(copy_limited, upload.file, dest, settings.max_file_bytes, repr(name))
            parts.append((dest, name))
        checked = await run_in_threadpool(check_upload, parts, folder, settings)
        if config is not None:
            save_job_config(folder, config)
    except UploadRefused as err:
        raise ApiError(err.status, err.code, err.message) from None
    finally:
        await form.close()
    shutil.rmtree(folder / "upload")
    return checked


def _upload_settings(text, settings: ServiceSettings):
    """The form's optional `settings`: a JSON object of overrides of the job's config."""
    if text is None:
        return None
    try:
        overrides = json.loads(text) if isinstance(text, str) else None
        if not isinstance(overrides, dict):
            raise ValueError
        return job_config(settings, overrides)
    except ValueError:
        raise ApiError(422, "bad_settings", "the field 'settings' must be a JSON object of "
                       'settings, e.g. {"render.frames": 36}') from None
    except UserError as err:
        raise ApiError(422, "bad_settings", str(err)) from None


@router.get("/jobs/{job_id}", response_model=JobStatus, responses=_REFUSALS,
            summary="A job's state, stage progress, time left and error")
def get_job(request: Request, job_id: str) -> JobStatus:
    return job_status(request, _job(request, job_id))


@router.get("/jobs/{job_id}/video.mp4", response_class=FileResponse, responses=_REFUSALS,
            summary="The turntable video (H.264 MP4), once done")
def get_video(request: Request, job_id: str) -> FileResponse:
    return FileResponse(_result(request, job_id, "video.mp4"), media_type="video/mp4")


@router.get("/jobs/{job_id}/poster.jpg", response_class=FileResponse, responses=_REFUSALS,
            summary="One frame of the turntable, as the video's poster")
def get_poster(request: Request, job_id: str) -> FileResponse:
    return FileResponse(_result(request, job_id, "poster.jpg"), media_type="image/jpeg")


@router.get("/jobs/{job_id}/report.json", responses=_REFUSALS,
            summary="The capture's quality report: photos placed, held-out PSNR, coverage, advice")
def get_report(request: Request, job_id: str) -> FileResponse:
    return FileResponse(_result(request, job_id, "video_report.json"), media_type="application/json")


@router.get("/jobs/{job_id}/coverage.png", response_class=FileResponse, responses=_REFUSALS,
            summary="Where the photos were taken from around the object, unphotographed arcs in red")
def get_coverage(request: Request, job_id: str) -> FileResponse:
    return FileResponse(_result(request, job_id, "video_coverage.png"), media_type="image/png")


# the page's embed snippet puts these addresses in a shop's own page, where model-viewer fetches
# them from another origin: a model is as public as its link, so any origin may read it
_EMBEDDABLE = {"Access-Control-Allow-Origin": "*"}


@router.get("/jobs/{job_id}/model.glb", response_class=FileResponse, responses=_REFUSALS,
            summary="The object as a 3D model (binary glTF, +Y up, metres or the scene's units)")
def get_model(request: Request, job_id: str) -> FileResponse:
    return FileResponse(_result(request, job_id, MODEL_FILES["model.glb"]),
                        media_type="model/gltf-binary", headers=_EMBEDDABLE)


@router.get("/jobs/{job_id}/model.usdz", response_class=FileResponse, responses=_REFUSALS,
            summary="The object as USDZ, for AR Quick Look on iOS")
def get_usdz(request: Request, job_id: str) -> FileResponse:
    return FileResponse(_result(request, job_id, MODEL_FILES["model.usdz"]),
                        media_type="model/vnd.usdz+zip", headers=_EMBEDDABLE)


@router.get("/jobs/{job_id}/frames/{index}.jpg", response_class=FileResponse, responses=_REFUSALS,
            summary="Frame `index` of the turntable (for the drag-to-spin viewer)")
def get_frame(request: Request, job_id: str, index: int) -> FileResponse:
    return FileResponse(_result(request, job_id, f"frames/{FRAME_NAME.format(index)}"),
                        media_type="image/jpeg")


@router.post("/jobs/{job_id}/cancel", response_model=JobStatus, responses=_REFUSALS,
             summary="Cancel a queued or running job (its owner only: Authorization: Bearer)")
def cancel_job(request: Request, job_id: str) -> JobStatus:
    job = _owned(request, job_id)
    if job.state in FINISHED:
        raise ApiError(409, "finished", f"the job is already {job.state}")
    return job_status(request, _store(request).cancel(job_id))


@router.delete("/jobs/{job_id}", status_code=204, response_class=Response, responses=_REFUSALS,
               summary="Delete a job and all its files (its owner only; a running job is stopped)")
def delete_job(request: Request, job_id: str) -> Response:
    _owned(request, job_id)
    _store(request).delete(job_id)
    shutil.rmtree(job_dir(_settings(request), job_id), ignore_errors=True)
    return Response(status_code=204)


@router.get("/health", summary="Whether the service and its worker are up, and the queue's length")
def health(request: Request) -> dict:
    worker = request.app.state.worker
    return {"ok": True, "worker": worker.is_alive() if worker else None,
            "queued": _store(request).count_queued()}
