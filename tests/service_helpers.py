"""A real `windowshop serve` in a process of its own, a tiny posed scene to give it, and Debian's
chromium for the browser tests (driven by Playwright).

Used by the restart test and the browser tests, which must run the real pipeline.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import zipfile
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
needs_chromium = pytest.mark.skipif(shutil.which(CHROMIUM) is None,
                                    reason=f"{CHROMIUM} is absent (apt-get install chromium)")


def wait_js(page, expression: str, timeout: float = 30.0, poll: float = 0.1) -> None:
    """Poll `expression` in `page` until true (page.wait_for_function would eval() in the page,
    which the page's Content-Security-Policy rightly forbids)."""
    deadline = time.monotonic() + timeout
    while not page.evaluate(expression):
        assert time.monotonic() < deadline, f"never true: {expression}"
        time.sleep(poll)


def canvas_shares(canvas_id: str, **tests: str) -> str:
    """A page expression: for each name in `tests`, the share of the canvas `canvas_id`'s pixels
    for which its JavaScript condition on the pixel's `r`, `g`, `b` holds (read through a 2D copy,
    so a WebGL canvas counts too)."""
    counts = "".join(f"if ({condition}) n.{name}++;\n    " for name, condition in tests.items())
    return f"""(() => {{
  const source = document.getElementById('{canvas_id}');
  const copy = document.createElement('canvas');
  [copy.width, copy.height] = [source.width, source.height];
  const context = copy.getContext('2d');
  context.drawImage(source, 0, 0);
  const p = context.getImageData(0, 0, copy.width, copy.height).data;
  const n = {{{", ".join(f"{name}: 0" for name in tests)}}};
  for (let i = 0; i < p.length; i += 4) {{
    const [r, g, b] = [p[i], p[i + 1], p[i + 2]];
    {counts}}}
  for (const k in n) n[k] /= p.length / 4;
  return n;
}})()"""


@contextmanager
def live_service(data: Path, env: dict[str, str] | None = None):
    """A LiveService on `data`, stopped on leaving."""
    live = LiveService(data, env).start()
    try:
        yield live
    finally:
        live.stop()


# Service settings that make a job take seconds: few training steps, few small frames, a small model.
FAST_JOB = {
    "WINDOWSHOP_JOB__MODEL": "fast",
    "WINDOWSHOP_JOB__FIT__SECONDS": "4",
    "WINDOWSHOP_JOB__RENDER__FRAMES": "8",
    "WINDOWSHOP_JOB__RENDER__WIDTH": "48",
    "WINDOWSHOP_JOB__RENDER__HEIGHT": "48",
    "WINDOWSHOP_JOB__RENDER__FPS": "12",
    "WINDOWSHOP_JOB__EXPORT__TEXTURE": "256",
    "WINDOWSHOP_JOB__EXPORT__RESOLUTION": "64",
    "WINDOWSHOP_JOB__EXPORT__TRIANGLES": "5000",
    "WINDOWSHOP_DEVICE": "cpu",
    "WINDOWSHOP_POLL_SECONDS": "0.2",
}


def posed_scene_zip(out: Path, views: int = 12, size: int = 32) -> Path:
    """A zip of the built-in object seen from `views` cameras, as a nerfstudio transforms.json scene."""
    from windowshop.scene.synthetic import synthetic_scene
    from windowshop.scene.writer import write_transforms

    folder = out.parent / "tiny-scene"
    write_transforms(synthetic_scene(n_train=views, n_test=2, size=size), folder)
    with zipfile.ZipFile(out, "w") as archive:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                archive.write(path, Path("tiny-scene") / path.relative_to(folder))
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def process_tree(pid: int) -> list[int]:
    """`pid` and all its descendants (from /proc)."""
    found, todo = [], [pid]
    while todo:
        current = todo.pop()
        found.append(current)
        for task in Path(f"/proc/{current}/task").glob("*"):
            children = (task / "children").read_text().split() if (task / "children").exists() else []
            todo.extend(int(c) for c in children)
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return False
    return state != "Z"  # a zombie has exited; only its parent's bookkeeping is left


class LiveService:
    """`windowshop serve --data DATA` on a free port, its output in DATA/../serve-N.log."""

    def __init__(self, data: Path, env: dict[str, str] | None = None):
        self.data, self.env = Path(data), {**os.environ, **FAST_JOB, **(env or {})}
        self.port, self.process, self.runs = free_port(), None, 0
        self.sessions: list[int] = []  # one per start: the process groups to end at teardown

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 60.0) -> "LiveService":
        self.runs += 1
        self.log = self.data.parent / f"serve-{self.runs}.log"
        command = [sys.executable, "-m", "windowshop", "serve", "--data", str(self.data),
                   "--port", str(self.port)]
        with open(self.log, "w") as log:  # a session of its own, so teardown can end the whole tree
            self.process = subprocess.Popen(command, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                            start_new_session=True)
        self.sessions.append(self.process.pid)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"the service exited:\n{self.log.read_text()}")
            try:
                if httpx.get(f"{self.url}/api/health", timeout=2).json()["worker"]:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        raise RuntimeError(f"the service did not come up:\n{self.log.read_text()}")

    def kill(self) -> list[int]:
        """SIGKILL the web process alone (as a crash would); returns the pids of its tree before."""
        tree = process_tree(self.process.pid)
        self.process.kill()
        self.process.wait()
        return tree

    def stop(self) -> None:
        """Stop as Ctrl-C would, then make sure nothing of its sessions is left."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(30)
            except subprocess.TimeoutExpired:
                pass
        for group in self.sessions:
            try:
                os.killpg(group, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.process = None

    def wait_for(self, job_id: str, states, timeout: float = 240.0) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            status = httpx.get(f"{self.url}/api/jobs/{job_id}", timeout=10).json()
            if status["state"] in states:
                return status
            time.sleep(0.2)
        raise AssertionError(f"job {job_id} never reached {states}: {status}\n{self.log.read_text()}")
