"""End to end in a real browser: Debian's chromium, driven by Playwright, against `windowshop serve`.

A small posed scene goes up through the page; once the job is done the video must play (its time
advances), dragging the spin viewer must change the frame, and the 3D view must draw the model
(pixels other than its background) and turn when dragged. Screenshots of the result page on a
desktop and on a phone-sized screen are kept in test-artifacts/. The owner cancels a second job from
the page, where the share link opened in another browser shows neither cancel nor delete.
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from service_helpers import canvas_shares, live_service, needs_chromium, posed_scene_zip, wait_js

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"

pytestmark = needs_chromium


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    with live_service(tmp_path_factory.mktemp("e2e") / "data") as live:
        yield live



# the share of the 3D view's pixels that are not its white background
MODEL_PIXELS = canvas_shares("model-view", drawn="r < 240 || g < 240 || b < 240")


def wait_until_done(page, timeout_ms: int = 240_000) -> None:
    page.wait_for_selector("#job-state[data-state=done], #job-state[data-state=failed]",
                           timeout=timeout_ms)
    assert page.get_attribute("#job-state", "data-state") == "done", page.inner_text("#job")


def test_upload_watch_play_and_spin(service, browser, tmp_path):
    scene = posed_scene_zip(tmp_path / "scene.zip")
    ARTIFACTS.mkdir(exist_ok=True)
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    page.goto(service.url)
    assert page.is_visible("#drop") and page.is_disabled("#send")
    page.set_input_files("#pick", str(scene))
    assert "1 file chosen" in page.inner_text("#chosen-text")
    page.click("#send")
    page.wait_for_url("**/jobs/*")
    job_id = page.url.rsplit("/", 1)[1]
    page.wait_for_selector("#stages li[data-status=running]")  # a stage and its bar show up
    wait_until_done(page)

    wait_js(page, "document.getElementById('video').currentTime > 0.1")
    start = page.evaluate("document.getElementById('video').currentTime")
    page.wait_for_timeout(600)
    playing = page.evaluate("(() => { const v = document.getElementById('video');"
                            " return {t: v.currentTime, paused: v.paused, loop: v.loop}; })()")
    assert playing["t"] != start and not playing["paused"] and playing["loop"]

    spin = page.locator("#spin")
    wait_js(page, "document.getElementById('spin-img').complete"
                           " && document.getElementById('spin-img').naturalWidth > 0")
    def frame() -> tuple:
        image = page.get_attribute("#spin-img", "src")
        return spin.get_attribute("data-frame"), image, spin.screenshot()

    before = frame()
    box = spin.bounding_box()
    y = box["y"] + box["height"] / 2
    page.mouse.move(box["x"] + box["width"] * 0.3, y)
    page.mouse.down()
    for step in range(1, 11):
        page.mouse.move(box["x"] + box["width"] * (0.3 + 0.03 * step), y)
    page.mouse.up()
    wait_js(page, "document.getElementById('spin-img').complete")
    after = frame()
    assert after[0] != before[0] and after[1] != before[1]
    assert after[2] != before[2]  # the picture itself changed, not only the attribute

    assert page.is_visible("#download") and page.get_attribute("#download", "href").endswith("video.mp4")
    # the capture's quality report: what was placed and covered, the coverage plot
    wait_js(page, "document.getElementById('quality-summary').textContent.includes('photos placed')")
    assert "of the circle covered" in page.inner_text("#quality-summary")
    # which part to trust, as the report says it (a posed upload: nothing checked its poses)
    report = page.evaluate("fetch(document.querySelector('#video').src.replace('video.mp4', "
                           "'report.json')).then((r) => r.json())")
    assert page.inner_text("#quality-trust") == report["trust"]["summary"]
    assert page.get_attribute("#quality-trust", "data-level") == report["trust"]["level"]
    wait_js(page, "document.getElementById('coverage').complete"
                  " && document.getElementById('coverage').naturalWidth > 100")
    assert job_id in page.get_attribute(f"#my-jobs a[href='/jobs/{job_id}']", "href")

    # the 3D model: the GLB drawn by viewer.js (WebGL), turned by dragging
    assert page.get_attribute("#model-download", "href").endswith("/model.glb")
    assert page.get_attribute("#usdz-download", "href").endswith("/model.usdz")
    wait_js(page, "['ready', 'failed'].includes(document.getElementById('model-view').dataset.state)")
    assert page.get_attribute("#model-view", "data-state") == "ready", \
        page.get_attribute("#model-view", "data-error")
    assert not page.is_visible("#ar")  # AR Quick Look is offered on iOS only
    drawn = page.evaluate(MODEL_PIXELS)["drawn"]
    assert drawn > 0.02, "the 3D view is blank"
    view = page.locator("#model-view")
    view.scroll_into_view_if_needed()
    box = view.bounding_box()
    before = view.screenshot()
    page.mouse.move(box["x"] + box["width"] * 0.3, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.7, box["y"] + box["height"] / 2, steps=8)
    page.mouse.up()
    page.wait_for_timeout(200)
    assert view.screenshot() != before  # orbiting turned the model
    page.screenshot(path=str(ARTIFACTS / "e2e-desktop.png"), full_page=True)
    page.close()

    phone = browser.new_context(viewport={"width": 390, "height": 844}, device_scale_factor=2,
                                is_mobile=True, has_touch=True)
    page = phone.new_page()
    page.goto(f"{service.url}/jobs/{job_id}")  # the share link, opened elsewhere
    wait_until_done(page)
    wait_js(page, "document.getElementById('video').currentTime > 0.1")
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= 390, "the page scrolls sideways on a phone"
    page.screenshot(path=str(ARTIFACTS / "e2e-phone.png"), full_page=True)
    phone.close()


def test_the_owner_cancels_from_the_page_and_a_shared_link_cannot(service, browser, tmp_path):
    scene = posed_scene_zip(tmp_path / "scene.zip")
    owner = browser.new_context()
    page = owner.new_page()
    page.goto(service.url)
    page.set_input_files("#pick", str(scene))
    page.click("#send")
    page.wait_for_url("**/jobs/*")
    job_id = page.url.rsplit("/", 1)[1]
    assert page.evaluate(f"localStorage.getItem('windowshop.owner.{job_id}')")  # the owner token

    shared = browser.new_context().new_page()  # the share link in another browser: watch only
    shared.goto(f"{service.url}/jobs/{job_id}")
    shared.wait_for_selector("#job-state[data-state]")
    assert shared.is_hidden("#cancel") and shared.is_hidden("#delete")

    page.click("#cancel")  # shown to the owner while the job is queued or running
    page.wait_for_selector("#job-state[data-state=cancelled]", timeout=30_000)
    assert httpx.get(f"{service.url}/api/jobs/{job_id}").json()["state"] == "cancelled"
    owner.close()
    shared.context.close()
