"""Shared fixtures of the suite: the datasets in ../shared/data (read in place, never copied) and a
real PostgreSQL server on loopback for the job stores. Helper modules beside this file
(`shared_data`, `service_helpers`, `distributed_helpers`, `postgres_helpers`) are importable from every test folder
(pyproject's `pythonpath`)."""

from __future__ import annotations

import pytest

from postgres_helpers import PostgresServer, postgres_bin
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


@pytest.fixture(scope="module")
def postgres_url():
    bin_dir = postgres_bin()
    if bin_dir is None:
        pytest.skip("PostgreSQL is not installed (apt-get install postgresql)")
    pytest.importorskip("psycopg", reason="psycopg is not installed (pip install psycopg[binary])")
    server = PostgresServer(bin_dir).start()
    try:
        yield server.url
    finally:
        server.remove()
