"""A real PostgreSQL server on loopback in a temporary folder (`initdb` + `postgres`, as the
`postgres` user when run by root), which a test may stop and start again on the same port."""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import tempfile
import time

from service_helpers import free_port


def postgres_bin() -> str | None:
    found = shutil.which("postgres") or next(iter(sorted(glob.glob("/usr/lib/postgresql/*/bin/postgres"))), None)
    return os.path.dirname(os.path.realpath(found)) if found else None


class PostgresServer:
    """`initdb` once, then `start()` / `stop()` as often as needed; `url` for SQLAlchemy."""

    def __init__(self, bin_dir: str):
        self.bin_dir, self.root = bin_dir, tempfile.mkdtemp(prefix="windowshop-pg-")
        self.as_user: list[str] = []
        if os.geteuid() == 0:  # the server refuses to run as root
            shutil.chown(self.root, "postgres")
            self.as_user = ["runuser", "-u", "postgres", "--"]
        self.data, self.port, self.process = os.path.join(self.root, "data"), free_port(), None
        self.url = f"postgresql+psycopg://windowshop@127.0.0.1:{self.port}/postgres"
        subprocess.run([*self.as_user, f"{bin_dir}/initdb", "-D", self.data, "-U", "windowshop",
                        "--auth=trust"], check=True, capture_output=True)

    def start(self) -> "PostgresServer":
        self.process = subprocess.Popen(
            [*self.as_user, f"{self.bin_dir}/postgres", "-D", self.data, "-p", str(self.port),
             "-k", self.root, "-c", "listen_addresses=127.0.0.1"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(100):
            if subprocess.run([f"{self.bin_dir}/pg_isready", "-h", "127.0.0.1", "-p", str(self.port)],
                              capture_output=True).returncode == 0:
                break
            time.sleep(0.2)
        return self

    def stop(self) -> None:
        """A fast shutdown: open connections are cut, as a restart would."""
        if self.process is not None:
            subprocess.run([*self.as_user, f"{self.bin_dir}/pg_ctl", "stop", "-D", self.data, "-m",
                            "fast", "-w"], capture_output=True)
            self.process.wait(30)
            self.process = None

    def remove(self) -> None:
        self.stop()
        shutil.rmtree(self.root, ignore_errors=True)
