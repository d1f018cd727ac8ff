"""Load check of `windowshop serve`: N clients create jobs at once against a local service.

Every creation must end accepted (201) or clearly refused (a 4xx/503 with a JSON error); no accepted
job may be lost (each one readable afterwards). Meanwhile, and afterwards while the worker trains,
a prober loads the page and a job's status; their latencies are reported. Prints one JSON object.

    python bench/bench_service_load.py [--clients 20] [--max-queued 12] [--probe-seconds 15]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from pathlib import Path

import httpx

FAST_JOB = {"WINDOWSHOP_JOB__MODEL": "fast", "WINDOWSHOP_JOB__FIT__SECONDS": "20",
            "WINDOWSHOP_JOB__RENDER__FRAMES": "12", "WINDOWSHOP_JOB__RENDER__WIDTH": "64",
            "WINDOWSHOP_JOB__RENDER__HEIGHT": "64", "WINDOWSHOP_DEVICE": "cpu"}


def scene_zip(folder: Path) -> bytes:
    """A posed scene of the built-in object (24 views of 48 px), zipped."""
    from windowshop.scene.synthetic import synthetic_scene
    from windowshop.scene.writer import write_transforms

    write_transforms(synthetic_scene(n_train=24, n_test=2, size=48), folder / "scene")
    with zipfile.ZipFile(folder / "scene.zip", "w") as archive:
        for path in sorted((folder / "scene").rglob("*")):
            archive.write(path, path.relative_to(folder))
    return (folder / "scene.zip").read_bytes()


def start_service(data: Path, max_queued: int) -> tuple[subprocess.Popen, str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, **FAST_JOB, "WINDOWSHOP_MAX_QUEUED": str(max_queued)}
    process = subprocess.Popen([sys.executable, "-m", "windowshop", "serve", "--data", str(data),
                                "--port", str(port)], env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    for _ in range(300):
        try:
            if httpx.get(f"{url}/api/health", timeout=2).json()["worker"]:
                return process, url
        except httpx.TransportError:
            time.sleep(0.2)
    raise SystemExit("the service did not start")


def create(url: str, data: bytes, barrier: threading.Barrier, out: list, i: int) -> None:
    """One client: wait for the others, then create a job; record what came back."""
    barrier.wait()
    start = time.perf_counter()
    try:
        r = httpx.post(f"{url}/api/jobs", files=[("files", ("scene.zip", data, "application/zip"))],
                       timeout=120)
        body = r.json()
        out[i] = {"status": r.status_code, "id": body.get("id"), "error": body.get("error"),
                  "owner_token": body.get("owner_token"), "seconds": time.perf_counter() - start}
    except (httpx.HTTPError, ValueError) as err:  # no clear answer: counted as lost
        out[i] = {"status": None, "error": f"{type(err).__name__}: {err}",
                  "seconds": time.perf_counter() - start}


def probe(url: str, job_id: str | None, stop: threading.Event, out: list[tuple[str, float]],
          phase: list[str], period: float = 0.1) -> None:
    """Load the page and a status every `period` s; record (phase, seconds) for each."""
    with httpx.Client(timeout=30) as client:
        while not stop.is_set():
            for path in ("/", "/static/app.js", f"/api/jobs/{job_id or 'x' * 22}"):
                start = time.perf_counter()
                client.get(url + path)
                out.append((phase[0], time.perf_counter() - start))
            stop.wait(period)


def summary(seconds: list[float]) -> dict:
    if not seconds:
        return {}
    ms = sorted(s * 1000 for s in seconds)
    return {"n": len(ms), "p50_ms": round(statistics.median(ms), 1),
            "p95_ms": round(ms[int(0.95 * (len(ms) - 1))], 1), "max_ms": round(ms[-1], 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=20)
    parser.add_argument("--max-queued", type=int, default=12, help="the service's queue limit")
    parser.add_argument("--probe-seconds", type=float, default=15.0,
                        help="how long to keep probing after the burst, while the worker trains")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = scene_zip(tmp)
        process, url = start_service(tmp / "data", args.max_queued)
        try:
            report = run(url, data, args)
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(30)
    report.update(machine=platform.machine(), cpus=os.cpu_count(), python=platform.python_version())
    print(json.dumps(report, indent=2))


def run(url: str, data: bytes, args: argparse.Namespace) -> dict:
    results: list = [None] * args.clients
    barrier = threading.Barrier(args.clients + 1)
    latencies: list[tuple[str, float]] = []
    phase, stop = ["idle"], threading.Event()
    prober = threading.Thread(target=probe, args=(url, None, stop, latencies, phase))
    prober.start()
    time.sleep(1.0)
    clients = [threading.Thread(target=create, args=(url, data, barrier, results, i))
               for i in range(args.clients)]
    for thread in clients:
        thread.start()
    phase[0] = "burst"
    start = time.perf_counter()
    barrier.wait()
    for thread in clients:
        thread.join()
    burst_seconds = time.perf_counter() - start
    phase[0] = "training"
    time.sleep(args.probe_seconds)
    stop.set()
    prober.join()

    accepted = [r["id"] for r in results if r["status"] == 201]
    tokens = {r["id"]: r["owner_token"] for r in results if r["status"] == 201}
    refused = [r for r in results if r["status"] and r["status"] != 201 and r["error"]]
    unclear = [r for r in results if r not in refused and r["status"] != 201]
    states = {}
    for job_id in accepted:
        status = httpx.get(f"{url}/api/jobs/{job_id}", timeout=30)
        states[job_id] = status.json()["state"] if status.status_code == 200 else "LOST"
    for job_id in accepted:
        httpx.delete(f"{url}/api/jobs/{job_id}", timeout=30,
                     headers={"Authorization": f"Bearer {tokens[job_id]}"})
    return {
        "benchmark": "service_load", "clients": args.clients, "max_queued": args.max_queued,
        "upload_bytes": len(data), "accepted": len(accepted),
        "refused": {code: sum(r["error"] == code for r in refused)
                    for code in {r["error"] for r in refused}},
        "unclear": len(unclear), "lost": sum(s == "LOST" for s in states.values()),
        "states_after": {s: sum(v == s for v in states.values()) for s in set(states.values())},
        "burst_seconds": round(burst_seconds, 2),
        "create_latency": summary([r["seconds"] for r in results]),
        "page_latency": {p: summary([s for q, s in latencies if q == p])
                         for p in ("idle", "burst", "training")},
        "ok": not unclear and all(s != "LOST" for s in states.values()),
    }


if __name__ == "__main__":
    main()
