"""Real servers on loopback for the distributed tests: redis-server, `windowshop serve --broker`
and `windowshop worker` processes, each in a session of its own so a test can SIGKILL a whole worker
(its Celery pool included) as a lost machine would be."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx

from service_helpers import FAST_JOB, free_port

# Failure detection scaled down to seconds: a lost worker's job is sent again ~5 s after its last
# heartbeat (by the service's sweep; Redis's visibility timeout keeps its default hour).
CLUSTER_ENV = {
    "WINDOWSHOP_HEARTBEAT_SECONDS": "1",
    "WINDOWSHOP_STALE_SECONDS": "5",
    "WINDOWSHOP_SILENCE_CHECK_SECONDS": "1",
}
REDIS = shutil.which("redis-server")


def _session(command: list[str], log: Path, env: dict) -> subprocess.Popen:
    with open(log, "w") as out:
        return subprocess.Popen(command, env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)


def end(process: subprocess.Popen | None, sig: int = signal.SIGKILL) -> None:
    """Signal `process`'s whole session (it leads one) and reap it."""
    if process is None or process.poll() is not None:
        return
    try:
        os.killpg(process.pid, sig)
    except ProcessLookupError:
        pass
    process.wait(30)


class Cluster:
    """A broker, a service and named workers, all under `root`."""

    def __init__(self, root: Path, env: dict | None = None, db: str | None = None):
        """`env`: the cluster's settings (default CLUSTER_ENV); `db`: the store's URL (--db)."""
        self.root, self.db = root, db
        self.env = {**os.environ, **FAST_JOB, **(CLUSTER_ENV if env is None else env)}
        self.redis_port, self.port = free_port(), free_port()
        self.broker = f"redis://127.0.0.1:{self.redis_port}/0"
        self.url = f"http://127.0.0.1:{self.port}"
        self.redis = self.service = None
        self.workers: dict[str, subprocess.Popen] = {}
        self.owners: dict[str, dict] = {}  # job id -> the header its owner's requests carry

    def start_redis(self) -> None:
        (self.root / "redis").mkdir(exist_ok=True)
        self.redis = _session([REDIS, "--port", str(self.redis_port), "--bind", "127.0.0.1",
                               "--dir", str(self.root / "redis"), "--save", "", "--appendonly", "no"],
                              self.root / "redis.log", self.env)

    def start(self) -> "Cluster":
        self.start_redis()
        db = ["--db", self.db] if self.db else []
        self.service = _session([sys.executable, "-m", "windowshop", "serve", "--broker", self.broker,
                                 "--data", str(self.root / "data"), "--port", str(self.port), *db],
                                self.root / "serve.log", self.env)
        self._wait(lambda: httpx.get(f"{self.url}/api/health", timeout=2).json()["ok"], "service")
        return self

    def start_worker(self, name: str) -> None:
        self.workers[name] = _session(
            [sys.executable, "-m", "windowshop", "worker", "--broker", self.broker, "--queues", "cpu",
             "--concurrency", "1", "--name", f"{name}@test"],
            self.root / f"worker-{name}.log", self.env)
        self._wait(lambda: "ready." in (self.root / f"worker-{name}.log").read_text(), name)

    def kill_worker(self, name: str) -> None:
        end(self.workers.pop(name))

    def stop(self) -> None:
        for name in list(self.workers):
            self.kill_worker(name)
        end(self.service, signal.SIGINT)
        end(self.service)
        end(self.redis)

    def _wait(self, ready, what: str, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                if ready():
                    return
            except (httpx.TransportError, FileNotFoundError):
                pass
            time.sleep(0.3)
        raise RuntimeError(f"{what} did not come up:\n{self.logs()}")

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-4000:]}" for p in sorted(self.root.glob("*.log")))

    def submit(self, zip_path: Path) -> str:
        with open(zip_path, "rb") as f:
            response = httpx.post(f"{self.url}/api/jobs", files={"files": (zip_path.name, f)},
                                  timeout=60)
        assert response.status_code == 201, response.text
        body = response.json()
        self.owners[body["id"]] = {"Authorization": f"Bearer {body['owner_token']}"}
        return body["id"]

    def cancel(self, job_id: str) -> dict:
        return httpx.post(f"{self.url}/api/jobs/{job_id}/cancel", headers=self.owners[job_id],
                          timeout=10).json()

    def status(self, job_id: str) -> dict:
        return httpx.get(f"{self.url}/api/jobs/{job_id}", timeout=10).json()

    def wait_for(self, job_id: str, states, timeout: float = 180.0) -> dict:
        """The job's status once in `states`; a service (or its database) briefly away is waited out."""
        deadline = time.monotonic() + timeout
        status = None
        while time.monotonic() < deadline:
            try:
                status = self.status(job_id)
            except (httpx.TransportError, ValueError):
                status = None
            if status and status.get("state") in states:
                return status
            time.sleep(0.3)
        raise AssertionError(f"job {job_id} never reached {states}: {status}\n{self.logs()}")
