"""The job API through FastAPI's TestClient, without a worker: every route and every refusal."""

from __future__ import annotations

import io
import json
import zipfile

import imageio_ffmpeg
import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from windowshop.service.app import create_app
from windowshop.service.db import SQLiteJobStore
from windowshop.service.settings import ServiceSettings



def image_bytes(fmt: str = "JPEG", size=(40, 30), seed: int = 0) -> bytes:
    rng = np.random.default_rng(seed)
    buf = io.BytesIO()
    Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)).save(buf, fmt)
    return buf.getvalue()


def photos(n: int = 5, fmt: str = "JPEG") -> list:
    return [("files", (f"IMG_{i}.jpg", image_bytes(fmt, seed=i), "image/jpeg")) for i in range(n)]


def video_bytes(tmp_path, seconds: float = 1.0, fps: int = 10) -> bytes:
    path = tmp_path / "clip.mp4"
    writer = imageio_ffmpeg.write_frames(str(path), (64, 48), fps=fps)
    writer.send(None)
    for i in range(int(seconds * fps)):
        writer.send(np.full((48, 64, 3), i * 20 % 255, np.uint8))
    writer.close()
    return path.read_bytes()


def zip_bytes(entries: dict[str, bytes], links: tuple[str, ...] = ()) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in entries.items():
            z.writestr(name, data)
        for name in links:
            info = zipfile.ZipInfo(name)
            info.external_attr = (0o120777 << 16)  # a symbolic link
            z.writestr(info, "../../etc/passwd")
    return buf.getvalue()


def posed_zip() -> bytes:
    frames = [{"file_path": f"images/{i}.png", "transform_matrix": np.eye(4).tolist()} for i in range(3)]
    entries = {"scene/transforms.json": json.dumps({"fl_x": 30, "fl_y": 30, "cx": 20, "cy": 15,
                                                   "w": 40, "h": 30, "frames": frames}).encode()}
    entries.update({f"scene/images/{i}.png": image_bytes("PNG", seed=i) for i in range(3)})
    entries["__MACOSX/scene/._transforms.json"] = b"\x00\x05\x16\x07junk"
    return zip_bytes(entries)


@pytest.fixture
def make_client(tmp_path):
    clients = []

    def make(**overrides) -> TestClient:
        settings = ServiceSettings(data_dir=tmp_path / "data", **overrides)
        client = TestClient(create_app(settings, start_worker=False))
        client.__enter__()
        client.settings = settings
        clients.append(client)
        return client

    yield make
    for client in clients:
        client.__exit__(None, None, None)


@pytest.fixture
def client(make_client):
    return make_client()


def job_folders(client) -> list:
    return sorted(p.name for p in client.settings.jobs_dir.iterdir())


def refused(response, status: int, code: str) -> str:
    assert response.status_code == status, response.text
    body = response.json()
    assert body["error"] == code
    assert body["detail"]
    return body["detail"]


# ---- creating jobs -------------------------------------------------------------------------

def test_a_job_may_lower_its_settings_but_not_raise_them(client):
    from windowshop.service.jobs import load_job_config

    job = client.post("/api/jobs", files=photos(), data={"settings": '{"render.frames": 12}'})
    assert job.status_code == 201, job.text
    folder = client.settings.jobs_dir / job.json()["id"]
    config = load_job_config(folder, client.settings)
    assert config.render.frames == 12 and config.fit == client.settings.job.fit
    detail = refused(client.post("/api/jobs", files=photos(),
                                 data={"settings": '{"fit.seconds": 9999}'}), 422, "bad_settings")
    assert "fit.seconds may be at most 30" in detail
    refused(client.post("/api/jobs", files=photos(), data={"settings": "[1]"}), 422, "bad_settings")
    refused(client.post("/api/jobs", files=photos(), data={"settings": '{"warp": 9}'}), 422,
            "bad_settings")
    assert len(job_folders(client)) == 1  # refused uploads leave nothing behind


def test_photos_make_a_queued_job_with_an_unguessable_id(client):
    first = client.post("/api/jobs", files=photos(5))
    second = client.post("/api/jobs", files=photos(6))
    assert first.status_code == second.status_code == 201
    a, b = first.json(), second.json()
    assert len(a["id"]) >= 22 and a["id"] != b["id"]  # 128 random bits, URL-safe
    assert a["url"] == f"/api/jobs/{a['id']}" and a["page"] == f"/jobs/{a['id']}"
    status = client.get(a["url"]).json()
    assert (status["state"], status["error"], status["input"]) == ("queued", None, "5 photos")
    assert status["queue_position"] == 0
    assert client.get(b["url"]).json()["queue_position"] == 1
    assert status["links"] == {"video": None, "poster": None, "frames": [], "report": None,
                               "coverage": None, "model": None, "usdz": None}
    names = sorted(p.name for p in (client.settings.jobs_dir / a["id"] / "input").iterdir())
    assert names == [f"IMG_{i}.jpg" for i in range(5)]  # photo names kept, upload parts gone


def test_photo_names_are_made_safe_and_suffixes_follow_content(client):
    files = [("files", ("../../evil name.png", image_bytes("JPEG", seed=1), "image/png")),
             ("files", ("a.webp", image_bytes("WEBP", seed=2), "image/webp")),
             ("files", ("a.jpg", image_bytes("PNG", seed=3), "image/jpeg")),
             ("files", ("b.jpg", image_bytes("JPEG", seed=4), "image/jpeg")),
             ("files", ("c.jpg", image_bytes("JPEG", seed=5), "image/jpeg"))]
    job = client.post("/api/jobs", files=files).json()
    names = sorted(p.name for p in (client.settings.jobs_dir / job["id"] / "input").iterdir())
    assert names == ["a-002.png", "a.webp", "b.jpg", "c.jpg", "evil_name.jpg"]


def capture_json(names: list[str], **overrides) -> bytes:
    entries = [{"file": n, "order": i, "up": [0.0, -0.9, -0.43], "heading_deg": 12.0 * i}
               for i, n in enumerate(names)]
    return json.dumps({"format": "windowshop-capture", "version": 1, "sensors": "deviceorientation",
                       "photos": entries, **overrides}).encode()


def test_photos_shot_on_the_page_bring_their_capture_json(client):
    names = [f"capture-{i:03d}.jpg" for i in range(5)]
    files = [("files", (n, image_bytes(seed=i), "image/jpeg")) for i, n in enumerate(names)]
    files.append(("files", ("capture.json", capture_json(names), "application/json")))
    job = client.post("/api/jobs", files=files)
    assert job.status_code == 201, job.text
    folder = client.settings.jobs_dir / job.json()["id"] / "input"
    assert sorted(p.name for p in folder.iterdir()) == [*names, "capture.json"]
    assert client.get(job.json()["url"]).json()["input"] == "5 photos"  # the JSON is no photo
    assert json.loads((folder / "capture.json").read_text())["photos"][2]["heading_deg"] == 24.0


def test_a_capture_json_that_is_not_the_pages_is_refused(client):
    files = photos() + [("files", ("capture.json", b'{"photos": 3}', "application/json"))]
    detail = refused(client.post("/api/jobs", files=files), 400, "bad_capture")
    assert "capture.json" in detail and "windowshop-capture" in detail
    assert job_folders(client) == []  # nothing of the refused upload is kept


def test_heic_photos_from_phones_are_taken(client):
    pytest.importorskip("pillow_heif")
    files = [("files", (f"IMG_{i}.HEIC", image_bytes("HEIF", seed=i), "image/heic")) for i in range(5)]
    job = client.post("/api/jobs", files=files)
    assert job.status_code == 201, job.text
    names = sorted(p.name for p in (client.settings.jobs_dir / job.json()["id"] / "input").iterdir())
    assert names == [f"IMG_{i}.heic" for i in range(5)]


def test_a_video_makes_a_job(client, tmp_path):
    r = client.post("/api/jobs", files=[("files", ("walk.MOV", video_bytes(tmp_path), "video/mp4"))])
    assert r.status_code == 201, r.text
    job_id = r.json()["id"]
    assert client.get(f"/api/jobs/{job_id}").json()["input"] == "a 1 s video, 64x48"
    assert [p.name for p in (client.settings.jobs_dir / job_id / "input").iterdir()] == ["walk.mp4"]


def test_a_zip_of_a_posed_scene_is_unpacked(client):
    r = client.post("/api/jobs", files=[("files", ("scene.zip", posed_zip(), "application/zip"))])
    assert r.status_code == 201, r.text
    job_id = r.json()["id"]
    assert client.get(f"/api/jobs/{job_id}").json()["input"] == "a zip of a posed scene with 3 images"
    inputs = client.settings.jobs_dir / job_id / "input"
    assert (inputs / "scene" / "transforms.json").is_file()
    assert len(list((inputs / "scene" / "images").iterdir())) == 3
    assert not (inputs / "__MACOSX").exists()


# ---- refusals: each a 4xx with JSON, and nothing left on disk --------------------------------

def test_refusals_of_the_form(make_client, tmp_path):
    client = make_client(max_files=5)
    refused(client.post("/api/jobs", data={"other": "x"}), 400, "no_files")
    refused(client.post("/api/jobs", data={"files": "not a file"}), 400, "bad_form")
    detail = refused(client.post("/api/jobs", files=photos(6)), 400, "too_many_files")
    assert "5" in detail
    refused(client.post("/api/jobs", files=photos(4)), 400, "too_few_photos")
    mixed = photos(2) + [("files", ("v.mp4", video_bytes(tmp_path), "video/mp4"))]
    refused(client.post("/api/jobs", files=mixed), 400, "mixed_upload")
    assert job_folders(client) == []


def test_refusals_of_types_by_content(client, tmp_path):
    text = [("files", ("photo.jpg", b"just some text, named like a photo", "image/jpeg"))] * 5
    assert "'photo.jpg'" in refused(client.post("/api/jobs", files=text), 415, "unsupported_type")
    truncated = photos(4) + [("files", ("cut.jpg", image_bytes()[:300], "image/jpeg"))]
    assert "'cut.jpg'" in refused(client.post("/api/jobs", files=truncated), 415, "broken_image")
    gif = io.BytesIO()
    Image.new("RGB", (8, 8)).save(gif, "GIF")
    # A GIF starts with no signature we take, so it is refused before decoding.
    refused(client.post("/api/jobs", files=[("files", ("a.gif", gif.getvalue(), "image/gif"))] * 5),
            415, "unsupported_type")
    fake_video = b"\x00\x00\x00\x18ftypisom" + bytes(200)
    refused(client.post("/api/jobs", files=[("files", ("v.mp4", fake_video, "video/mp4"))]),
            415, "broken_video")
    broken_zip = [("files", ("s.zip", b"PK\x03\x04" + bytes(50), "application/zip"))]
    refused(client.post("/api/jobs", files=broken_zip), 415, "broken_zip")
    assert job_folders(client) == []


def test_refusals_of_sizes(make_client, tmp_path):
    client = make_client(max_pixels=4000, max_file_bytes=50_000, max_upload_bytes=200_000,
                         max_video_seconds=0.5)
    big = [("files", ("big.png", image_bytes("PNG", size=(80, 60)), "image/png"))] * 5
    assert "4800" in refused(client.post("/api/jobs", files=big), 413, "too_many_pixels")
    heavy = [("files", ("heavy.bin", bytes(60_000), "image/jpeg"))]
    refused(client.post("/api/jobs", files=heavy), 413, "file_too_large")
    many = [("files", (f"{i}.bin", bytes(45_000), "image/jpeg")) for i in range(5)]
    refused(client.post("/api/jobs", files=many), 413, "upload_too_large")
    long_video = [("files", ("v.mp4", video_bytes(tmp_path, seconds=2.0), "video/mp4"))]
    refused(client.post("/api/jobs", files=long_video), 413, "video_too_long")
    assert job_folders(client) == []


def test_a_body_without_length_is_cut_at_the_limit(make_client):
    client = make_client(max_upload_bytes=100_000)
    boundary = "x0x0x0"

    def body():  # a generator body goes out chunked, with no Content-Length to trust
        yield (f"--{boundary}\r\nContent-Disposition: form-data; name=\"files\"; filename=\"a.jpg\"\r\n"
               "Content-Type: image/jpeg\r\n\r\n").encode()
        for _ in range(20):
            yield bytes(10_000)
        yield f"\r\n--{boundary}--\r\n".encode()

    r = client.post("/api/jobs", content=body(),
                    headers={"content-type": f"multipart/form-data; boundary={boundary}"})
    refused(r, 413, "upload_too_large")
    assert job_folders(client) == []


def test_a_decompression_bomb_is_refused(client):
    bomb = io.BytesIO()
    Image.new("L", (10_000, 10_000)).save(bomb, "PNG")  # 100 Mpx in under 100 kB
    assert len(bomb.getvalue()) < 200_000
    files = photos(4) + [("files", ("bomb.png", bomb.getvalue(), "image/png"))]
    assert "'bomb.png'" in refused(client.post("/api/jobs", files=files), 413, "too_many_pixels")


@pytest.mark.parametrize("entries, links, status, code", [
    ({"../evil.json": b"{}", "a.png": image_bytes("PNG")}, (), 400, "zip_slip"),
    ({"/etc/evil.json": b"{}"}, (), 400, "zip_slip"),
    ({"scene\\..\\..\\evil.json": b"{}"}, (), 400, "zip_slip"),
    ({"C:/evil.json": b"{}"}, (), 400, "zip_slip"),
    ({"a.png": image_bytes("PNG")}, ("images/link.png",), 400, "zip_link"),
    ({"a.png": image_bytes("PNG"), "run.exe": b"MZ\x90\x00"}, (), 415, "unsupported_type"),
    ({"a.png": image_bytes("PNG"), "clip.mp4": b"\x00\x00\x00\x18ftypisom" + bytes(20)}, (), 415,
     "unsupported_type"),
    ({"notes.txt": b"hello"}, (), 400, "no_images"),
    ({"a.png": image_bytes("PNG")[:60]}, (), 415, "broken_image"),
])
def test_refusals_of_zips(client, entries, links, status, code):
    upload = [("files", ("s.zip", zip_bytes(entries, links), "application/zip"))]
    r = client.post("/api/jobs", files=upload)
    detail = refused(r, status, code)
    assert "'s.zip'" in detail
    assert job_folders(client) == []


def test_zip_bombs_and_crowds_are_refused_from_the_index(make_client):
    client = make_client(max_unpacked_bytes=1_000_000, max_zip_entries=5)
    bomb = zip_bytes({"a.png": image_bytes("PNG"), "big.bin": bytes(2_000_000)})
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("a.png", image_bytes("PNG"))
        z.writestr("big.bin", bytes(2_000_000))
    assert len(buf.getvalue()) < 20_000  # 2 MB of zeros deflates to almost nothing
    for data in (bomb, buf.getvalue()):
        r = client.post("/api/jobs", files=[("files", ("s.zip", data, "application/zip"))])
        refused(r, 413, "zip_too_large")
    crowd = zip_bytes({f"{i}.png": image_bytes("PNG", seed=i) for i in range(6)})
    refused(client.post("/api/jobs", files=[("files", ("s.zip", crowd, "application/zip"))]),
            413, "too_many_entries")


def test_a_full_queue_refuses_new_jobs_with_a_retry_time(make_client):
    client = make_client(max_queued=2)
    assert [client.post("/api/jobs", files=photos()).status_code for _ in range(2)] == [201, 201]
    r = client.post("/api/jobs", files=photos())
    refused(r, 503, "queue_full")
    assert r.headers["retry-after"] == "120"


# ---- reading, cancelling, deleting -----------------------------------------------------------

def test_unknown_and_malformed_ids_are_404(client):
    for job_id in ("A" * 22, "../../etc/passwd", "short"):
        for path in ("", "/video.mp4", "/poster.jpg", "/frames/0.jpg"):
            r = client.get(f"/api/jobs/{job_id}{path}")
            assert r.status_code == 404, (job_id, path)
    refused(client.post(f"/api/jobs/{'A' * 22}/cancel"), 404, "no_such_job")
    refused(client.delete(f"/api/jobs/{'A' * 22}"), 404, "no_such_job")


def test_results_wait_until_the_job_is_done(client):
    job_id = client.post("/api/jobs", files=photos()).json()["id"]
    for path in ("video.mp4", "poster.jpg", "frames/0.jpg"):
        assert "queued" in refused(client.get(f"/api/jobs/{job_id}/{path}"), 409, "not_done")


def owner(created) -> dict:
    return {"Authorization": f"Bearer {created.json()['owner_token']}"}


def test_cancel_a_queued_job(client):
    created = client.post("/api/jobs", files=photos())
    job_id = created.json()["id"]
    r = client.post(f"/api/jobs/{job_id}/cancel", headers=owner(created))
    assert r.status_code == 200 and r.json()["state"] == "cancelled"
    assert client.get(f"/api/jobs/{job_id}").json()["state"] == "cancelled"
    refused(client.post(f"/api/jobs/{job_id}/cancel", headers=owner(created)), 409, "finished")
    assert SQLiteJobStore(client.settings.db_path).claim_next("token") is None  # the worker won't run it


def test_delete_removes_the_job_and_its_files(client):
    created = client.post("/api/jobs", files=photos())
    job_id = created.json()["id"]
    assert (client.settings.jobs_dir / job_id / "input").is_dir()
    assert client.delete(f"/api/jobs/{job_id}", headers=owner(created)).status_code == 204
    assert not (client.settings.jobs_dir / job_id).exists()
    refused(client.get(f"/api/jobs/{job_id}"), 404, "no_such_job")


def test_no_route_lists_jobs(client):
    client.post("/api/jobs", files=photos())
    assert client.get("/api/jobs").status_code == 405
    assert client.get("/api/jobs/").status_code in (404, 405)
    paths = client.get("/openapi.json").json()["paths"]
    assert "get" not in paths["/api/jobs"]


def test_openapi_describes_the_upload_field(client):
    spec = client.get("/openapi.json").json()
    body = spec["paths"]["/api/jobs"]["post"]["requestBody"]["content"]["multipart/form-data"]
    assert body["schema"]["properties"]["files"]["type"] == "array"
    assert set(spec["paths"]["/api/jobs/{job_id}"]) == {"get", "delete"}
    assert "state" in spec["components"]["schemas"]["JobStatus"]["properties"]


def test_the_page_and_its_files_are_served(client):
    for path in ("/", f"/jobs/{'A' * 22}"):
        r = client.get(path)
        assert r.status_code == 200 and "<title>windowshop" in r.text
        assert r.headers["referrer-policy"] == "no-referrer"  # ids in links must not leak
        assert "default-src 'self'" in r.headers["content-security-policy"]
    assert "startSpin" in client.get("/static/app.js").text
    assert client.get("/static/style.css").headers["content-type"].startswith("text/css")
    assert client.get("/api/health").json() == {"ok": True, "worker": None, "queued": 0}
