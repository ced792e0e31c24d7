"""The start page and the report in headless Chromium (Debian's `chromium`, driven by Playwright's Python client).

Skipped when Chromium or the Playwright client is missing, unless FEEDSCHED_REQUIRE_BROWSER=1 (then it fails):
`make browser` installs Chromium (apt) where it can.  Never runs `playwright install` (no browser downloads).
Set FEEDSCHED_SCREENSHOT=path.png to keep the report screenshot (docs/report-flower.png comes from here).
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from service.schemas import EXAMPLE
from tests.service.conftest import WAIT_S, Server

CHROMIUM = os.environ.get("FEEDSCHED_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
VIEWPORT = {"width": 1280, "height": 900}


def _missing() -> str | None:
    if CHROMIUM is None:
        return "no chromium executable (Debian package `chromium`; `make browser` installs it)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright Python client is not installed (pip install playwright; dev extra)"
    return None


@pytest.fixture(scope="module")
def browser_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    why = _missing()
    if why is not None:
        if os.environ.get("FEEDSCHED_REQUIRE_BROWSER") == "1":
            pytest.fail(why)
        pytest.skip(why)
    s = Server(tmp_path_factory.mktemp("browser"), FEEDSCHED_WORKERS="2").start()
    yield s
    s.stop()


def test_run_the_flower_from_the_start_page_and_see_the_report(browser_server: Server, tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    errors: list[str] = []
    shot = tmp_path / "report.png"
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            page.set_default_timeout(WAIT_S * 1000)
            page.on("console", lambda m: errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
            page.on("requestfailed", lambda r: errors.append(f"request failed: {r.url}"))
            page.goto(browser_server.url + "/")
            assert page.locator("#example").input_value() == "flower"
            # the bundled flower is loaded into the text area (723 control points)
            page.wait_for_function("document.getElementById('toolpath').value.length > 10000")
            assert page.locator("a[href='/docs']").count() >= 1
            # uploading a file replaces the text; picking the example again brings the flower back
            upload = tmp_path / "arc.json"
            upload.write_text(json.dumps(EXAMPLE["toolpath"]))
            page.set_input_files("#file", str(upload))
            page.wait_for_function("document.getElementById('toolpath').value.includes('0.7071067811865476')")
            page.select_option("#example", "flower")
            page.wait_for_function("document.getElementById('toolpath').value.length > 10000")
            page.select_option("#machine", "router")
            page.select_option("#method", "lp+nlp")
            page.click("#run")
            page.wait_for_url("**/v1/jobs/*/report")
            # the report reloads itself until the job is done, then shows the plots
            page.wait_for_selector("img.plot")
            page.wait_for_function(
                "Array.from(document.querySelectorAll('img.plot')).every(i => i.complete && i.naturalWidth > 0)")
            imgs = page.locator("img.plot")
            assert imgs.count() == 4  # toolpath, feed, axes, comparison (lp+nlp ran both methods)
            for i in range(imgs.count()):
                img = imgs.nth(i)
                assert img.is_visible()
                box = img.bounding_box()
                assert box is not None and box["width"] > 300 and box["height"] > 200
            assert page.locator("#summary").inner_text().count("\n") >= 8
            assert "motion time" in page.locator("#summary").inner_text()
            page.screenshot(path=str(shot), full_page=True)
            height = page.evaluate("document.documentElement.scrollHeight")
            # the start page links to Swagger UI, served by the service itself (this machine has no CDN)
            page.goto(browser_server.url + "/docs")
            assert "feedsched" in page.locator(".swagger-ui .info .title").inner_text()
            page.get_by_text("/v1/jobs/{job_id}/report", exact=True).wait_for()
        finally:
            browser.close()
    assert errors == []
    img = Image.open(shot)
    assert img.size == (VIEWPORT["width"], height) and height > 2000  # the whole report: four plots, stacked
    px = np.asarray(img.convert("RGB"))
    assert (px.min(axis=2) < 200).mean() > 0.05  # not blank
    top = px[: VIEWPORT["height"]]
    assert len(np.unique(top.reshape(-1, 3)[::5], axis=0)) > 100  # the feed colour map is on screen
    keep = os.environ.get("FEEDSCHED_SCREENSHOT")
    if keep:
        shutil.copyfile(shot, keep)
