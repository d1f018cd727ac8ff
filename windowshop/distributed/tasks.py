"""The worker's side: the Celery task that runs one phase of one job, and `windowshop worker`.

A delivery first claims the job from the service (compare-and-set on a fresh run token, so a
duplicate delivery of a job that is running, finished or cancelled runs nothing), then downloads
what it needs, runs the phase in a temporary folder (no disk shared with the service), and uploads
its output; the service keeps an upload only from the job's current try. A heartbeat thread tells
the service the try is alive; a try whose job was cancelled finds out from the service's answers
(and is also killed by Celery's revoke).
"""

from __future__ import annotations

import logging
import socket
import tempfile
import threading
from pathlib import Path

from celery.utils.log import get_task_logger

from windowshop.distributed.celery_app import ClusterSettings, app, configure
from windowshop.distributed.transfer import Abandoned, ServiceClient
from windowshop.errors import failure_reason, is_transient

log = get_task_logger("windowshop.worker")
_DEVICE: dict[str, str | None] = {"device": None}  # the worker's --device, for its task processes


@app.task(bind=True, name="windowshop.job_phase")
def job_phase(self, job_id: str, phase: str, service_url: str, key: str, job: dict,
              beat_seconds: float, _stale_seconds: float) -> str:
    """Run `phase` ("prepare" or "train") of the job; returns what happened, for the log.

    (`_stale_seconds` is unused since the service itself resends the job of a silent try; it stays
    so that services and workers of both versions understand each other's messages.)
    """
    import secrets

    client = ServiceClient(service_url, job_id, key, secrets.token_hex(8))
    try:
        # "busy": another live try runs it (this is a duplicate delivery); should that try die, the
        # service's sweep notices its silence and sends the job again (distributed/sweeps.py)
        answer = client.claim(phase, self.request.hostname or socket.gethostname())
        if answer != "run":
            return answer
        log.info("job %s: %s (try %s)", job_id, phase, client.token)
        return _run_try(client, phase, job, beat_seconds)
    finally:
        client.close()


def _run_try(client: ServiceClient, phase: str, job: dict, beat_seconds: float) -> str:
    stop = threading.Event()
    beat = threading.Thread(target=_beat, args=(client, stop, beat_seconds), daemon=True)
    beat.start()
    try:
        with tempfile.TemporaryDirectory(prefix="windowshop-job-") as tmp:
            (_prepare if phase == "prepare" else _train)(client, Path(tmp), job)
        return "done"
    except Abandoned:
        return "abandoned"
    except Exception as err:  # noqa: BLE001 - any failure ends the try; the service judges a retry
        if client.abandoned.is_set():
            return "abandoned"
        log.exception("job try failed")
        return client.fail(failure_reason(err), _is_transient(err)) or "abandoned"
    finally:
        stop.set()
        beat.join()


def _is_transient(err: Exception) -> bool:
    """Retried: out of memory, a timeout, the service or its database briefly unreachable."""
    import httpx

    if isinstance(err, httpx.HTTPStatusError):
        return err.response.status_code >= 500
    return is_transient(err)


def _beat(client: ServiceClient, stop: threading.Event, seconds: float) -> None:
    while not stop.wait(seconds):
        client.beat()


def _config(job: dict):
    """The service's job config (windowshop.config.PipelineConfig) from its JSON form."""
    from pydantic import TypeAdapter

    from windowshop.config import PipelineConfig

    return TypeAdapter(PipelineConfig).validate_python(job)


def _prepare(client: ServiceClient, tmp: Path, job: dict) -> None:
    """Photos or a video -> a posed scene, uploaded to the service."""
    from windowshop.photos.prepare import prepare
    from windowshop.service.jobs import ProgressReporter, pipeline_input

    client.download("input", tmp / "input")
    report = ProgressReporter(client, "", client.token)
    out = prepare(pipeline_input(tmp), tmp / "scene", _config(job).prepare, report, False).out_dir
    report("prepare", 1.0)
    client.upload("scene", Path(out))


def _train(client: ServiceClient, tmp: Path, job: dict) -> None:
    """The posed scene (prepared, or uploaded as one) -> the turntable, uploaded as the result."""
    from windowshop.device import pick_device
    from windowshop.pipeline import make_video
    from windowshop.service.jobs import FRAME_GLOB, ProgressReporter, pipeline_input

    client.download("scene", tmp / "input")
    result = tmp / "result"
    report = ProgressReporter(client, "", client.token)
    make_video(pipeline_input(tmp), result / "video.mp4",
               _config(job), work_dir=tmp / "work", device=pick_device(_DEVICE["device"]),
               poster=str(result / "poster.jpg"), frames_dir=result / "frames", on_stage=report,
               show=False)
    if client.abandoned.is_set():
        raise Abandoned("cancelled while running")
    client.upload("result", result, frames=len(list((result / "frames").glob(FRAME_GLOB))))


def run_worker(settings: ClusterSettings, queues: list[str], concurrency: int, name: str | None,
               device: str | None, loglevel: str = "INFO") -> None:
    """`windowshop worker`: a Celery worker consuming `queues`, in the foreground until stopped."""
    logging.basicConfig(level=loglevel, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    _DEVICE["device"] = device
    configure(settings)
    argv = ["worker", f"--queues={','.join(queues)}", f"--concurrency={concurrency}",
            f"--loglevel={loglevel}", "--pool=prefork", "--without-gossip", "--without-mingle"]
    if name:
        argv.append(f"--hostname={name}")
    app.worker_main(argv)
