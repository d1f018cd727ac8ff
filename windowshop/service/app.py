"""The web application: `create_app(settings)` wires the job API, the page and the worker process.

The worker runs in a process of its own, started and stopped with the application (see worker.py);
the web process only reads and writes the job store and the job folders.
"""

from __future__ import annotations

import multiprocessing
import os
from contextlib import asynccontextmanager
from importlib.resources import files

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from windowshop.service import routes
from windowshop.service.db import SQLiteJobStore
from windowshop.service.retention import Sweeper, sweep_expired
from windowshop.service.settings import ServiceSettings
from windowshop.service.worker import JobFunction, run_worker

STATIC = files("windowshop.service") / "static"
# The page loads nothing from elsewhere; job ids in its address must not leak through Referer.
_PAGE_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; media-src 'self' blob:",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-cache",
}


def create_app(settings: ServiceSettings | None = None, start_worker: bool = True,
               job_fn: JobFunction | None = None) -> FastAPI:
    """The service for `settings`; `start_worker=False` serves the API without running jobs."""
    settings = settings or ServiceSettings()
    settings.jobs_dir.mkdir(parents=True, exist_ok=True)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        app.state.worker = _start_worker(settings, job_fn) if start_worker else None
        sweeper = Sweeper(app.state.sweeps).start()
        yield
        sweeper.stop()
        if app.state.worker is not None:
            _stop_worker(app.state.worker)

    app = FastAPI(title="windowshop", lifespan=lifespan, version="0.1.0",
                  description="Photos of an object in, a 360° turntable video out.")
    app.state.settings, app.state.store, app.state.worker = settings, SQLiteJobStore(settings.db_path), None
    # (period, function) run by the web process; the store is looked up when it runs, since the
    # distributed mode replaces it (and adds its own sweep, distributed/sweeps.py)
    app.state.sweeps = [(settings.retention_check_seconds,
                         lambda: sweep_expired(settings, app.state.store))]
    app.include_router(routes.router)
    app.mount("/static", StaticFiles(directory=str(STATIC)), name="static")

    @app.exception_handler(routes.ApiError)
    async def refused(request: Request, err: routes.ApiError) -> JSONResponse:
        return JSONResponse({"error": err.code, "detail": err.message}, status_code=err.status,
                            headers=err.headers)

    @app.middleware("http")
    async def no_sniffing(request: Request, call_next):
        response = await call_next(request)
        response.headers["X-Content-Type-Options"] = "nosniff"
        return response

    @app.get("/", include_in_schema=False)
    @app.get("/jobs/{job_id}", include_in_schema=False)
    def page() -> FileResponse:
        return FileResponse(str(STATIC / "index.html"), headers=_PAGE_HEADERS)

    return app


def _start_worker(settings: ServiceSettings, job_fn: JobFunction | None) -> multiprocessing.Process:
    process = multiprocessing.get_context("spawn").Process(
        target=run_worker, args=(settings, os.getpid(), job_fn), name="windowshop-worker")
    process.start()
    return process


def _stop_worker(process: multiprocessing.Process, grace: float = 10.0) -> None:
    process.terminate()  # the worker kills its running jobs, which are requeued at the next start
    process.join(grace)
    if process.is_alive():
        process.kill()
        process.join()


def serve(settings: ServiceSettings) -> None:
    """Run the service in the foreground (`windowshop serve`) until Ctrl-C."""
    import uvicorn

    tls = settings.tls()
    print(f"windowshop: serving {settings.scheme}://{settings.host}:{settings.port}/ "
          f"(jobs in {settings.data_dir.resolve()})", flush=True)
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level="info",
                **tls)
