"""Plot routes, the report page, the start page and the synchronous `plots` option (in-process)."""

from __future__ import annotations

import base64
import csv
import io
import json
import re
import threading
import xml.etree.ElementTree as ET
from html.parser import HTMLParser
from typing import Any

import pytest
from fastapi.testclient import TestClient

from service import reports
from service.schemas import EXAMPLE
from tests.service.test_inprocess import COLUMNS, assert_problem
from tests.service.test_jobs import poll_done


class Links(HTMLParser):
    """Every src/href of a page, and the text of the summary table."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self.imgs: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for k, v in attrs:
            if k in ("src", "href") and v is not None:
                self.urls.append(v)
                if tag == "img":
                    self.imgs.append(v)


def links(page: str) -> Links:
    p = Links()
    p.feed(page)
    return p


def run_job(client: TestClient, body: dict[str, Any]) -> str:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    done = poll_done(client, r.headers["location"])
    assert done["status"] == "succeeded", done
    assert done["links"]["report"] == f"/v1/jobs/{done['id']}/report"
    job_id: str = done["id"]
    return job_id


def svg_meta(data: bytes) -> dict[str, Any]:
    root = ET.fromstring(data)
    desc = [e.text for e in root.iter() if e.tag.endswith("}description")]
    out: dict[str, Any] = json.loads(desc[0] or "")
    return out


@pytest.fixture(scope="module")
def nlp_job(client: TestClient) -> str:
    """One lp+nlp job of the quarter arc, shared (its plots are rendered once, then cached)."""
    return run_job(client, EXAMPLE)


def test_job_plots_svg_png_cached(client: TestClient, nlp_job: str) -> None:
    job_id = nlp_job
    result = client.get(f"/v1/jobs/{job_id}/result").json()
    base = f"/v1/jobs/{job_id}/plots"
    for name in ("toolpath", "feed", "axes", "comparison"):
        r = client.get(f"{base}/{name}.svg")
        assert r.status_code == 200, r.text
        assert r.headers["content-type"] == "image/svg+xml"
        md = svg_meta(r.content)
        assert md["plot"] == name and md["samples"] == len(result["samples"]["t"])
        p = client.get(f"{base}/{name}.png")
        assert p.status_code == 200 and p.headers["content-type"] == "image/png"
        assert p.content.startswith(b"\x89PNG\r\n\x1a\n")
    md = svg_meta(client.get(f"{base}/toolpath.svg").content)
    assert md["feed_range"] == [min(result["samples"]["feed"]), max(result["samples"]["feed"])]
    # cached per job: the file next to the results, served again byte for byte
    svc = client.app.state.service  # type: ignore[attr-defined]
    cached = svc.plots.cache_path(job_id, "axes", "svg")
    assert cached.read_bytes() == client.get(f"{base}/axes.svg").content
    cached.write_bytes(cached.read_bytes().replace(b"axis profiles", b"AXIS PROFILES"))
    assert b"AXIS PROFILES" in client.get(f"{base}/axes.svg").content  # not re-rendered
    # unknown plot / format: 422 naming the parameter; unknown job: 404
    assert_problem(client.get(f"{base}/nope.svg"), 422, "path.name")
    assert_problem(client.get(f"{base}/axes.gif"), 422, "path.fmt")
    assert_problem(client.get("/v1/jobs/AAAAAAAAAAAAAAAAAAAAAAAA/plots/feed.svg"), 404)


def test_comparison_needs_both_methods_and_rendering_is_off_the_loop(client: TestClient,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    job_id = run_job(client, {**EXAMPLE, "options": {"method": "lp"}})
    threads: list[str] = []
    real = reports.plots.render

    def spy(*args: Any) -> bytes:
        threads.append(threading.current_thread().name)
        return real(*args)

    monkeypatch.setattr(reports.plots, "render", spy)
    assert client.get(f"/v1/jobs/{job_id}/plots/feed.svg").status_code == 200
    assert len(threads) == 1 and threads[0].startswith("feedsched-plots")  # the dedicated plot thread
    assert client.get(f"/v1/jobs/{job_id}/plots/feed.svg").status_code == 200
    assert len(threads) == 1  # second time from the cache
    assert_problem(client.get(f"/v1/jobs/{job_id}/plots/comparison.svg"), 404)
    page = client.get(f"/v1/jobs/{job_id}/report").text
    assert "plots/comparison.svg" not in page and "plots/toolpath.svg" in page


def test_report_page(client: TestClient, nlp_job: str) -> None:
    job_id = nlp_job
    r = client.get(f"/v1/jobs/{job_id}/report")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    page = r.text
    summary = client.get(f"/v1/jobs/{job_id}").json()["summary"]
    # summary table: length, motion time, compute time, method, peak utilisation, diagnostics
    table = page[page.index('id="summary"'):page.index("</table>", page.index('id="summary"'))]
    assert f"{summary['motion_time']:.4g} s" in table and f"{summary['path_length']:.4g} mm" in table
    assert "compute time" in table and "lp+nlp" in table and "NLP gain over LP" in table
    util = page[page.index('id="utilisation"'):]
    pu = summary["peak_utilisation"]
    assert f"{100 * pu['servo_error_x']:.1f} %" in util and f"{100 * pu['velocity_y']:.1f} %" in util
    assert 'id="diagnostics"' in page and "servo error binds at" in page
    lk = links(page)
    assert lk.imgs == [f"/v1/jobs/{job_id}/plots/{n}.svg" for n in ("toolpath", "feed", "axes", "comparison")]
    for url in lk.imgs:
        assert client.get(url).status_code == 200
    # every link is local (no CDN) and works
    for url in lk.urls:
        assert url.startswith(("/", "data:")), url
        if url.startswith("/") and url != "/docs" and not url.endswith(".png"):  # PNGs: test_job_plots_svg_png_cached
            assert client.get(url).status_code == 200, url
    csv_url = next(u for u in lk.urls if u.endswith("format=csv"))
    rows = list(csv.reader(io.StringIO(client.get(csv_url).text)))
    assert rows[0] == COLUMNS and len(rows) - 1 == summary["samples"]
    js = client.get(next(u for u in lk.urls if u.endswith("format=json")))
    assert js.headers["content-type"] == "application/json" and js.json()["summary"]["samples"] == summary["samples"]


def test_report_of_failed_and_unknown_jobs(client: TestClient) -> None:
    bad = {"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [0, 0]]}]}}
    r = client.post("/v1/jobs", json=bad)
    done = poll_done(client, r.headers["location"])
    assert done["status"] == "failed"
    page = client.get(f"/v1/jobs/{done['id']}/report")
    assert page.status_code == 200 and "failed" in page.text and done["error"]["detail"] in page.text
    assert 'http-equiv="refresh"' not in page.text  # finished: no reloading
    assert_problem(client.get(f"/v1/jobs/{done['id']}/plots/feed.svg"), 409)
    assert_problem(client.get("/v1/jobs/AAAAAAAAAAAAAAAAAAAAAAAA/report"), 404)


def test_start_page_and_examples(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    lk = links(r.text)
    assert "/docs" in lk.urls
    assert all(u.startswith(("/", "data:")) for u in lk.urls), lk.urls  # nothing from a CDN
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", r.text)
    assert '<option value="flower" selected>' in r.text and '<option value="router">' in r.text
    names = [e["name"] for e in client.get("/v1/examples").json()["examples"]]
    assert names[0] == "flower" and set(names) >= {"flower", "quarter-arc", "square-corner"}
    flower = client.get("/v1/examples/flower").json()
    seg = flower["toolpath"]["segments"][0]
    assert seg["degree"] == 3 and len(seg["control_points"]) > 700 and flower["machine"] == "router"
    assert_problem(client.get("/v1/examples/nope"), 404)
    # Swagger UI without a CDN: every asset from this service
    docs = client.get("/docs")
    assert docs.status_code == 200 and "https://" not in docs.text and "http://" not in docs.text
    assets = [u for u in links(docs.text).urls if u.startswith("/static/")]
    assert len(assets) >= 2 and any(u.endswith("swagger-ui-bundle.js") for u in assets)
    for u in assets:
        assert client.get(u).status_code == 200, u


def test_sync_plots_option(client: TestClient) -> None:
    body = {**EXAMPLE, "options": {"method": "lp+nlp", "plots": ["toolpath", "comparison"]}}
    r = client.post("/v1/schedule", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert set(out["plots"]) == {"toolpath", "comparison"}
    head, _, b64 = out["plots"]["toolpath"].partition(",")
    assert head == "data:image/svg+xml;base64"
    md = svg_meta(base64.b64decode(b64))
    assert md["feed_range"] == [min(out["samples"]["feed"]), max(out["samples"]["feed"])]
    png = client.post("/v1/schedule", json={**EXAMPLE, "options": {"plots": ["feed"], "plot_format": "png"}}).json()
    assert base64.b64decode(png["plots"]["feed"].partition(",")[2]).startswith(b"\x89PNG")
    assert "plots" not in client.post("/v1/schedule", json=EXAMPLE).json()
    # plots only in JSON; the comparison only when the NLP ran
    assert_problem(client.post("/v1/schedule", json=body, headers={"Accept": "text/csv"}), 406, "options.plots")
    # ... JSON wherever Accept admits it: JSON at q=0.1 beside CSV was a 406 (session 59's probe)
    low = client.post("/v1/schedule", json={**EXAMPLE, "options": {"method": "lp", "plots": ["feed"]}},
                      headers={"Accept": "application/json;q=0.1, text/csv"})
    assert low.status_code == 200 and low.headers["content-type"].startswith("application/json")
    assert set(low.json()["plots"]) == {"feed"}
    assert client.post("/v1/schedule", json={**EXAMPLE, "options": {"method": "lp"}},
                       headers={"Accept": "application/json;q=0.1, text/csv"}).headers["content-type"].startswith(
                           "text/csv")  # (without plots CSV wins)
    assert_problem(client.post("/v1/schedule", json=body, headers={"Accept": "text/csv, application/json;q=0"}), 406,
                   "options.plots")
    assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "options": {"method": "lp", "plots": ["comparison"]}}),
                   422, "options.plots")
    assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "options": {"plots": ["pie"]}}), 422,
                   "options.plots[0]")
