"""Owner tokens: whoever has a job's link may watch it; only the creator's token cancels or deletes it."""

from __future__ import annotations

import hashlib
import sqlite3

import pytest
from fastapi.testclient import TestClient

from test_service_api import photos, refused
from windowshop.service.app import create_app
from windowshop.service.settings import ServiceSettings


@pytest.fixture
def client(tmp_path):
    settings = ServiceSettings(data_dir=tmp_path / "data")
    with TestClient(create_app(settings, start_worker=False)) as client:
        client.settings = settings
        yield client


def bearer(token: str) -> dict:
    return {"Authorization": f"Bearer {token}"}


def create(client) -> tuple[str, str]:
    body = client.post("/api/jobs", files=photos()).json()
    return body["id"], body["owner_token"]


def stored_row(client, job_id: str) -> dict:
    with sqlite3.connect(client.settings.db_path) as db:
        db.row_factory = sqlite3.Row
        return dict(db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone())


def test_creation_answers_a_token_of_which_only_a_hash_is_kept(client):
    (first, token), (_, other) = create(client), create(client)
    assert len(token) >= 40 and token != other
    row = stored_row(client, first)
    assert row["owner_hash"] == hashlib.sha256(token.encode()).hexdigest()
    assert token not in map(str, row.values())


@pytest.mark.parametrize("headers", [
    {}, {"Authorization": "Bearer"}, {"Authorization": "Basic dXNlcjpwYXNz"}, bearer("not-the-token"),
])
def test_cancel_and_delete_without_the_owner_token_are_refused(client, headers):
    job_id, _ = create(client)
    other_id, other_token = create(client)
    for attempt in (headers, bearer(other_token)):  # also: another job's valid token
        assert "owner" in refused(client.post(f"/api/jobs/{job_id}/cancel", headers=attempt),
                                  403, "not_owner")
        refused(client.delete(f"/api/jobs/{job_id}", headers=attempt), 403, "not_owner")
    status = client.get(f"/api/jobs/{job_id}")  # viewing stays open to whoever has the link
    assert status.status_code == 200 and status.json()["state"] == "queued"
    assert (client.settings.jobs_dir / job_id / "input").is_dir()


def test_the_owner_token_cancels_and_deletes(client):
    job_id, token = create(client)
    cancelled = client.post(f"/api/jobs/{job_id}/cancel", headers=bearer(token))
    assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled"
    assert client.delete(f"/api/jobs/{job_id}", headers=bearer(f"  {token} ")).status_code == 204
    refused(client.get(f"/api/jobs/{job_id}"), 404, "no_such_job")


def test_a_job_from_before_owner_tokens_cannot_be_removed_through_the_api(client):
    job_id, token = create(client)
    with sqlite3.connect(client.settings.db_path) as db:
        db.execute("UPDATE jobs SET owner_hash = NULL WHERE id = ?", (job_id,))
    refused(client.delete(f"/api/jobs/{job_id}", headers=bearer(token)), 403, "not_owner")


def test_openapi_documents_the_token_and_the_refusal(client):
    schema = client.get("/openapi.json").json()
    assert "owner_token" in schema["components"]["schemas"]["JobCreated"]["properties"]
    assert "403" in schema["paths"]["/api/jobs/{job_id}/cancel"]["post"]["responses"]
