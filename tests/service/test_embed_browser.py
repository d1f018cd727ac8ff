"""The result page's "Embed on your shop" snippet (static/app.js) in a real browser: Debian's
chromium, driven by Playwright.

The service runs in this process without a worker; two jobs are put in its store as done, each
with a small GLB whose scene extras hold an orbit as `windowshop export` writes it: one from
cameras on one side only (a limited orbit), one from cameras all round (a free one). The page must
show the <model-viewer> snippet with the job's absolute GLB and USDZ addresses and the GLB's own
orbit attributes, exactly as export/orbit.py's embed_snippet writes it, never load model-viewer
itself, and copy exactly the snippet with its Copy button.
"""

from __future__ import annotations

import re
import secrets
import threading
import time

import numpy as np
import pytest

from service_helpers import free_port, needs_chromium
from windowshop.export.asset import Asset
from windowshop.export.frame import ModelFrame
from windowshop.export.glb import read_extras, write_glb
from windowshop.export.orbit import covered_orbit, embed_snippet
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera
from windowshop.service.jobs import MODEL_FILES
from windowshop.service.settings import ServiceSettings, job_dir
from windowshop.service.store import DONE

SCRIPT = ('<script type="module" src="https://ajax.googleapis.com/ajax/libs/model-viewer/3.5.0/'
          'model-viewer.min.js"></script>')

pytestmark = needs_chromium


def orbit_of(yaws) -> dict:
    """The orbit of cameras at `yaws` degrees (the normalised frame: yaw = atan2(x, -y))."""
    cameras = [Camera(fx=100, fy=100, cx=50, cy=50, width=100, height=100,
                      c2w=look_at(3.0 * np.array([np.sin(a), -np.cos(a), 0.3]), np.zeros(3),
                                  [0.0, 0.0, 1.0]))
               for a in np.radians(yaws)]
    return covered_orbit(cameras, np.zeros(3))


def tetrahedron(orbit: dict) -> Asset:
    """The smallest closed mesh, grey, carrying `orbit` into the GLB's extras."""
    vertices = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    normals = vertices - vertices.mean(0)
    return Asset(vertices=vertices, faces=np.int64([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
                 normals=normals / np.linalg.norm(normals, axis=1, keepdims=True),
                 uv=None, texture=None, vertex_colours=np.full((4, 3), 170, np.uint8),
                 roughness=1.0, frame=ModelFrame(np.eye(4), np.eye(4), 1.0, "source units"),
                 info={"orbit": orbit})


def done_job(app, orbit: dict) -> str:
    """A job in `app`'s store, done, whose result is a GLB carrying `orbit`; its id."""
    store, job_id = app.state.store, secrets.token_urlsafe(16)
    store.create(job_id, "zip", "a test model")
    token = secrets.token_hex(8)
    assert store.claim_next(token).id == job_id
    result = job_dir(app.state.settings, job_id) / "result"
    result.mkdir(parents=True)
    write_glb(tetrahedron(orbit), result / MODEL_FILES["model.glb"])
    assert store.finish(job_id, token, DONE)
    return job_id


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    """The service (no worker) on a free port, with a limited and a free job: (url, app, ids)."""
    import uvicorn

    from windowshop.service.app import create_app

    app = create_app(ServiceSettings(data_dir=tmp_path_factory.mktemp("embed") / "data"),
                     start_worker=False)
    jobs = {"limited": done_job(app, orbit_of(np.linspace(75, 105, 7))),
            "free": done_job(app, orbit_of(np.arange(0, 360, 30)))}
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=free_port(),
                                           log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert time.monotonic() < deadline and thread.is_alive(), "the service did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{server.config.port}", app, jobs
    server.should_exit = True
    thread.join(10)


def open_snippet(browser, url: str, job_id: str, before: str | None = None):
    """The job's page once its snippet shows (`before`: a script run ahead of the page's own),
    and the addresses the page asked for."""
    context = browser.new_context(permissions=["clipboard-read", "clipboard-write"])
    page = context.new_page()
    if before:
        page.add_init_script(before)
    requested = []
    page.on("request", lambda request: requested.append(request.url))
    page.goto(f"{url}/jobs/{job_id}")
    page.wait_for_selector("#embed-code", state="visible", timeout=20_000)
    return page, requested


def expected(url: str, app, job_id: str) -> str:
    """The snippet of the job's GLB extras, as export/orbit.py writes it, with its addresses."""
    glb = job_dir(app.state.settings, job_id) / "result" / MODEL_FILES["model.glb"]
    attributes = read_extras(glb)["windowshop"]["orbit"]["model_viewer"]
    base = f"{url}/api/jobs/{job_id}"
    return f"{SCRIPT}\n{embed_snippet(attributes, f'{base}/model.glb', f'{base}/model.usdz')}"


def test_a_limited_orbit_is_embedded_and_copied(service, browser):
    url, app, jobs = service
    page, requested = open_snippet(browser, url, jobs["limited"])
    snippet = page.input_value("#embed-code")
    assert snippet == expected(url, app, jobs["limited"])
    assert f'src="{url}/api/jobs/{jobs["limited"]}/model.glb"' in snippet
    orbit = orbit_of(np.linspace(75, 105, 7))
    for end in ("min", "max"):
        found = re.search(rf'{end}-camera-orbit="([-\d.]+)deg auto auto"', snippet)
        assert found and float(found.group(1)) == pytest.approx(orbit[end], abs=0.05)
    # model-viewer's script is only text: the page asked nothing of any other site
    assert all(r.startswith(url) for r in requested), requested

    page.click("#embed-copy")
    page.wait_for_selector("#embed-status:has-text('Copied')", timeout=5_000)
    assert page.evaluate("navigator.clipboard.readText()") == snippet
    page.context.close()


def test_a_free_orbit_has_camera_orbit_only(service, browser):
    url, app, jobs = service
    page, _ = open_snippet(browser, url, jobs["free"])
    snippet = page.input_value("#embed-code")
    assert snippet == expected(url, app, jobs["free"])
    assert "camera-orbit=" in snippet and "min-camera-orbit" not in snippet
    assert "max-camera-orbit" not in snippet
    page.context.close()


def test_without_a_clipboard_copy_selects_the_snippet(service, browser):
    url, _, jobs = service
    # as on a plain-HTTP address other than localhost, where browsers give pages no clipboard
    no_clipboard = "Object.defineProperty(navigator, 'clipboard', {value: undefined})"
    page, _ = open_snippet(browser, url, jobs["limited"], before=no_clipboard)
    page.click("#embed-copy")
    page.wait_for_selector("#embed-status:has-text('Selected')", timeout=5_000)
    selected = page.evaluate("(() => { const c = document.getElementById('embed-code'); return "
                             "[document.activeElement === c, c.selectionStart, c.selectionEnd, "
                             "c.value.length]; })()")
    assert selected[:3] == [True, 0, selected[3]] and selected[3] > 0
    page.context.close()


def test_the_model_files_may_be_read_from_a_shops_own_page(service):
    import urllib.request

    url, _, jobs = service
    request = urllib.request.Request(f"{url}/api/jobs/{jobs['limited']}/model.glb",
                                     headers={"Origin": "https://shop.example"})
    with urllib.request.urlopen(request, timeout=10) as response:
        assert response.headers["Access-Control-Allow-Origin"] == "*"
        assert response.read(4) == b"glTF"
