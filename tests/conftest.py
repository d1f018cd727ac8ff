"""Shared fixtures of the suite: the datasets in ../shared/data (read in place, never copied) and a
real PostgreSQL server on loopback for the job stores. Helper modules beside this file
(`shared_data`, `service_helpers`, `distributed_helpers`) are importable from every test folder
(pyproject's `pythonpath`)."""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import tempfile
import time

import pytest

from service_helpers import free_port
from shared_data import DATA


def pytest_collection_modifyitems(config, items):
    """Without ../shared/data, skip the tests of every module that reads it (imports DATA), with
    the reason, instead of failing on missing files."""
    if DATA.is_dir():
        return
    skip = pytest.mark.skip(reason=f"{DATA} is absent (the shared datasets beside the repository)")
    for item in items:
        if getattr(item.module, "DATA", None) == DATA:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def shared_data():
    """The shared datasets' folder; tests that need it skip where it is absent."""
    if not DATA.is_dir():
        pytest.skip(f"{DATA} is absent")
    return DATA


def _postgres_bin() -> str | None:
    found = shutil.which("postgres") or next(iter(sorted(glob.glob("/usr/lib/postgresql/*/bin/postgres"))), None)
    return os.path.dirname(os.path.realpath(found)) if found else None


@pytest.fixture(scope="module")
def postgres_url():
    bin_dir = _postgres_bin()
    if bin_dir is None:
        pytest.skip("PostgreSQL is not installed (apt-get install postgresql)")
    pytest.importorskip("psycopg", reason="psycopg is not installed (pip install psycopg[binary])")
    root = tempfile.mkdtemp(prefix="windowshop-pg-")
    as_user: list[str] = []
    if os.geteuid() == 0:  # the server refuses to run as root
        shutil.chown(root, "postgres")
        as_user = ["runuser", "-u", "postgres", "--"]
    data, port = os.path.join(root, "data"), free_port()
    subprocess.run([*as_user, f"{bin_dir}/initdb", "-D", data, "-U", "windowshop", "--auth=trust"],
                   check=True, capture_output=True)
    server = subprocess.Popen([*as_user, f"{bin_dir}/postgres", "-D", data, "-p", str(port), "-k", root,
                               "-c", "listen_addresses=127.0.0.1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"postgresql+psycopg://windowshop@127.0.0.1:{port}/postgres"
    try:
        for _ in range(100):
            if subprocess.run([f"{bin_dir}/pg_isready", "-h", "127.0.0.1", "-p", str(port)],
                              capture_output=True).returncode == 0:
                break
            time.sleep(0.2)
        yield url
    finally:
        server.terminate()
        server.wait(30)
        shutil.rmtree(root, ignore_errors=True)
