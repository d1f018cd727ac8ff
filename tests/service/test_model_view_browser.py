"""The page's 3D view (static/viewer.js) in a real browser: Debian's chromium, driven by Playwright.

A cube photographed from one side only (the cameras span yaw 75..105 degrees about the model's
+Y, the side facing +X painted red, the opposite one blue) is written as `windowshop export`
writes a GLB (orbit limits in its scene extras), served beside viewer.js on a small page. The
view must open facing the photographed (red) side, say in a note that its turn is limited, and
never turn past the covered arc plus its margin, however far it is dragged or keyed: the blue,
unphotographed side never shows.
"""

from __future__ import annotations

import functools
import http.server
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

from service_helpers import CHROMIUM, CHROMIUM_ARGS, canvas_shares, needs_chromium
from windowshop.export.asset import Asset
from windowshop.export.frame import ModelFrame
from windowshop.export.glb import write_glb
from windowshop.export.orbit import MARGIN, covered_orbit
from windowshop.scene.cameras import look_at
from windowshop.scene.types import Camera

STATIC = Path(__file__).resolve().parents[2] / "windowshop" / "service" / "static"
PAGE = """<!doctype html><html><head><meta charset="utf-8"></head><body style="margin:0">
<figure><canvas id="model-view" style="width:240px;height:240px" tabindex="0"></canvas></figure>
<script src="viewer.js"></script>
<script>window.showModel(document.getElementById('model-view'), 'cube.glb');</script>
</body></html>"""
# share of the view's pixels that are red (the photographed side) and blue (the other one)
COLOURS = canvas_shares("model-view", red="r > 2 * b + 40 && r > 2 * g + 40",
                        blue="b > 2 * r + 40 && b > 2 * g + 40")

pytestmark = needs_chromium


def cube_asset(orbit: dict) -> Asset:
    """A unit cube (model frame, +Y up), each face its own colour: +X red, -X blue, others grey."""
    vertices, faces, colours, normals = [], [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = np.roll(np.eye(3), 1, 0)[axis], np.roll(np.eye(3), 2, 0)[axis]
            corners = [n * 0.5 + su * u * 0.5 + sv * v * 0.5
                       for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            base = len(vertices)
            quad = [[0, 1, 2], [0, 2, 3]]
            if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), n) < 0:
                quad = [[0, 2, 1], [0, 3, 2]]
            faces += [[base + a, base + b, base + c] for a, b, c in quad]
            vertices += corners
            normals += [n] * 4
            colour = {(0, 1.0): (220, 20, 20), (0, -1.0): (20, 20, 220)}.get((axis, sign),
                                                                              (170, 170, 170))
            colours += [colour] * 4
    vertices = np.asarray(vertices, dtype=np.float32) + np.float32([0, 0.5, 0])
    return Asset(vertices=vertices, faces=np.asarray(faces, dtype=np.int64),
                 normals=np.asarray(normals, dtype=np.float32), uv=None, texture=None,
                 vertex_colours=np.asarray(colours, dtype=np.uint8), roughness=0.9,
                 frame=ModelFrame(np.eye(4), np.eye(4), 1.0, "source units"),
                 info={"orbit": orbit})


def front_orbit() -> dict:
    """The orbit of cameras at yaw 75..105 degrees (the normalised frame: yaw = atan2(x, -y))."""
    cameras = []
    for yaw in np.radians(np.linspace(75, 105, 7)):
        eye = 3.0 * np.array([np.sin(yaw), -np.cos(yaw), 0.3])
        cameras.append(Camera(fx=100, fy=100, cx=50, cy=50, width=100, height=100,
                              c2w=look_at(eye, np.zeros(3), [0.0, 0.0, 1.0])))
    return covered_orbit(cameras, np.zeros(3))


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:
        pass


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer")
    shutil.copy(STATIC / "viewer.js", root / "viewer.js")
    (root / "index.html").write_text(PAGE)
    write_glb(cube_asset(front_orbit()), root / "cube.glb")
    handler = functools.partial(QuietHandler, directory=str(root))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}/index.html"
    server.shutdown()


def test_orbit_of_a_front_capture():
    orbit = front_orbit()
    assert orbit["limited"] and abs(orbit["covered_degrees"] - 30) < 1
    assert abs(orbit["start"] - 90) < 3
    assert orbit["min"] == pytest.approx(75 - MARGIN, abs=0.2)
    assert orbit["max"] == pytest.approx(105 + MARGIN, abs=0.2)
    assert 'min-camera-orbit="60.0deg' in orbit["embed"]


def test_opens_on_the_photographed_side_and_stays_in_its_arc(site):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 400, "height": 400})
        page.goto(site)
        page.wait_for_function("['ready', 'failed'].includes("
                               "document.getElementById('model-view').dataset.state)")
        view = page.locator("#model-view")
        assert view.get_attribute("data-state") == "ready", view.get_attribute("data-error")
        yaw = lambda: float(view.get_attribute("data-yaw"))  # noqa: E731
        lo, hi = float(view.get_attribute("data-yaw-min")), float(view.get_attribute("data-yaw-max"))
        assert abs(yaw() - 90) < 3  # facing the photographed side
        opened = page.evaluate(COLOURS)
        assert opened["red"] > 0.05 and opened["blue"] == 0
        note = page.locator("#model-view-note")
        assert note.is_visible() and "30°" in note.inner_text()

        box = view.bounding_box()
        y = box["y"] + box["height"] / 2
        for direction in (1, -1):  # drag far each way: a full turn and more
            page.mouse.move(box["x"] + box["width"] / 2, y)
            page.mouse.down()
            for step in range(1, 31):
                page.mouse.move(box["x"] + box["width"] / 2 + direction * 25 * step, y)
                page.wait_for_timeout(10)
                assert lo - 0.1 <= yaw() <= hi + 0.1
                assert page.evaluate(COLOURS)["blue"] == 0, "the unphotographed side showed"
            page.mouse.up()
            page.wait_for_timeout(50)
            assert yaw() == pytest.approx(lo if direction > 0 else hi, abs=0.2)
        view.focus()
        for _ in range(40):
            page.keyboard.press("ArrowLeft")
        page.wait_for_timeout(50)
        assert yaw() == pytest.approx(hi, abs=0.2)
        browser.close()
