"""The service's settings: flags of `windowshop serve`, or `WINDOWSHOP_*` environment variables.

Every limit on uploads and every knob of the job the worker runs lives here, so tests and the load
check make jobs fast (few training seconds, few small frames) without touching code.
"""

from __future__ import annotations

from pathlib import Path

from pydantic_settings import BaseSettings, SettingsConfigDict

from windowshop.config import PipelineConfig
from windowshop.errors import UserError
from windowshop.photos.ingest import MIN_PHOTOS


class ServiceSettings(BaseSettings):
    """Settings of one service: its data folder, its upload limits and the jobs its worker runs."""

    model_config = SettingsConfigDict(env_prefix="WINDOWSHOP_", env_nested_delimiter="__",
                                      env_parse_none_str="none", frozen=True)

    data_dir: Path = Path("windowshop-data")  # jobs.sqlite3 and one folder per job
    host: str = "127.0.0.1"
    port: int = 8000
    # HTTPS: a phone's browser opens its camera only for https:// pages (or localhost), so a
    # phone reaching this machine by its LAN address needs a certificate (docs/capture.md)
    certfile: Path | None = None
    keyfile: Path | None = None

    @property
    def scheme(self) -> str:
        return "https" if self.certfile else "http"

    def tls(self) -> dict:
        """uvicorn's TLS arguments; UserError when only one of the files is given or is missing."""
        if self.certfile is None and self.keyfile is None:
            return {}
        if self.certfile is None or self.keyfile is None:
            raise UserError("HTTPS needs both --certfile and --keyfile (a certificate and its "
                            "private key, PEM files)")
        for path in (self.certfile, self.keyfile):
            if not Path(path).is_file():
                raise UserError(f"{path}: no such file; give the PEM certificate and key "
                                f"(docs/capture.md shows how to make a self-signed pair)")
        return {"ssl_certfile": str(self.certfile), "ssl_keyfile": str(self.keyfile)}

    # Uploads (checked by content, see uploads.py).
    max_files: int = 200  # files per job
    max_file_bytes: int = 200 * 2**20  # one file (a video or a zip may be large)
    max_upload_bytes: int = 500 * 2**20  # the whole request
    max_pixels: int = 40_000_000  # per image: larger ones are refused as decompression bombs
    min_photos: int = MIN_PHOTOS  # fewer photos cannot be checked
    max_zip_entries: int = 2000
    max_unpacked_bytes: int = 1 * 2**30  # a zip's entries together, once unpacked
    max_video_seconds: float = 300.0
    max_queued: int = 100  # jobs waiting; more are refused with 503 until the queue drains

    # Disk (see retention.py).
    retention_days: float = 7.0  # a job's files and row are deleted this long after it ended
    retention_check_seconds: float = 3600.0  # how often the service looks for expired jobs
    min_free_bytes: int = 1 * 2**30  # uploads are refused (507) while the data disk has less free
    max_job_bytes: int = 2 * 2**30  # one job's stored upload, once checked and unpacked (else 413)

    # The worker.
    concurrency: int = 1  # jobs run at once, each in its own process
    poll_seconds: float = 0.5  # how often the worker looks at the queue and at cancellations
    device: str | None = None  # torch device of the jobs; None picks CUDA when present

    # Every job's settings: the pipeline's (windowshop.config.PipelineConfig), each field an
    # environment variable by its dotted path, e.g. WINDOWSHOP_JOB__FIT__SECONDS=20,
    # WINDOWSHOP_JOB__RENDER__FRAMES=36 (the turntable's frames are also the drag-to-spin viewer's
    # images), WINDOWSHOP_JOB__MODEL=nerf ("none" for None), or the whole as JSON in WINDOWSHOP_JOB.
    job: PipelineConfig = PipelineConfig()

    @property
    def db_path(self) -> Path:
        return self.data_dir / "jobs.sqlite3"

    @property
    def jobs_dir(self) -> Path:
        return self.data_dir / "jobs"


def job_dir(settings: ServiceSettings, job_id: str) -> Path:
    """The folder of one job: its input, work and result."""
    return settings.jobs_dir / job_id
