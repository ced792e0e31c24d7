"""The same API against a real uvicorn server on loopback (subprocess), including a hard restart mid-job."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable
from typing import Any

import httpx

from service.schemas import EXAMPLE
from tests.service.conftest import WAIT_S, Server, long_line, pid_gone, wait_for
from tests.service.test_inprocess import COLUMNS, bits


def poll_done(url: str) -> dict[str, Any]:
    def done() -> dict[str, Any] | None:
        j: dict[str, Any] = httpx.get(url).json()
        return j if j["status"] not in ("queued", "running") else None

    out: dict[str, Any] = wait_for(done, f"{url} to finish", every=0.1)
    return out


def test_schedule_json_csv_ndjson(server: Server) -> None:
    u = server.url + "/v1/schedule"
    js = httpx.post(u, json=EXAMPLE, timeout=WAIT_S)
    assert js.status_code == 200 and js.headers["content-type"] == "application/json"
    cols = js.json()["samples"]
    r = httpx.post(u, json=EXAMPLE, headers={"Accept": "text/csv"}, timeout=WAIT_S)
    rows = list(csv.reader(io.StringIO(r.text)))
    assert rows[0] == COLUMNS
    assert [bits(float(row[1])) for row in rows[1:]] == [bits(v) for v in cols["s"]]
    n = 0
    end = None
    with httpx.stream("POST", u, json=EXAMPLE, headers={"Accept": "application/x-ndjson"}, timeout=WAIT_S) as s:
        assert s.headers["content-type"].startswith("application/x-ndjson")
        assert s.headers.get("transfer-encoding") == "chunked"  # streamed, not buffered with a length
        for line in s.iter_lines():
            row = json.loads(line)
            assert end is None, "nothing after the summary line"
            if "event" in row:
                end = row
                continue
            assert bits(row["x"]) == bits(cols["x"][n])
            n += 1
    assert n == len(cols["t"])
    assert end is not None and end["event"] == "summary" and end["summary"]["samples"] == n


def test_errors_are_problem_json(server: Server) -> None:
    r = httpx.post(server.url + "/v1/schedule", content=b'{"toolpath": {"segments": [{"degree": true}]}}',
                   headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    assert r.json()["errors"][0]["field"].startswith("toolpath.segments[0]")
    r = httpx.get(server.url + "/v1/jobs/AAAAAAAAAAAAAAAAAAAAAAAA")
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_jobs_submit_poll_result_cancel_idempotency(server: Server) -> None:
    h = {"Idempotency-Key": "server-test-1"}
    r = httpx.post(server.url + "/v1/jobs", json=EXAMPLE, headers=h)
    assert r.status_code == 202
    url = server.url + r.headers["location"]
    again = httpx.post(server.url + "/v1/jobs", json=EXAMPLE, headers=h)
    assert again.status_code == 200 and again.json()["id"] == r.json()["id"]
    assert poll_done(url)["status"] == "succeeded"
    res = httpx.get(url + "/result", headers={"Accept": "text/csv"})
    assert res.status_code == 200 and res.text.startswith("t,s,feed,")

    long = httpx.post(server.url + "/v1/jobs", json=long_line(40_000.0))
    lurl = server.url + long.headers["location"]
    j = wait_for(lambda: (x := httpx.get(lurl).json())["progress"] > 0 and x["worker_pid"] and x, "progress")
    assert 0 < j["progress"] < 1
    d = httpx.delete(lurl)
    assert d.status_code == 200 and d.json()["status"] == "cancelled"
    wait_for(lambda: pid_gone(j["worker_pid"]), "the cancelled solver process to die")


def test_restart_mid_job_loses_nothing(server_factory: Callable[..., Server]) -> None:
    srv = server_factory(FEEDSCHED_WORKERS="1").start()
    fin_path = httpx.post(srv.url + "/v1/jobs", json=EXAMPLE).headers["location"]
    assert poll_done(srv.url + fin_path)["status"] == "succeeded"
    before = httpx.get(srv.url + fin_path + "/result").content
    loc = httpx.post(srv.url + "/v1/jobs", json=long_line(3_000.0)).headers["location"]
    j = wait_for(lambda: (x := httpx.get(srv.url + loc).json())["progress"] > 0 and x["worker_pid"] and x,
                 "the long job to make progress")
    srv.kill()  # SIGKILL: no shutdown handler runs
    wait_for(lambda: pid_gone(j["worker_pid"]), "the orphaned solver process to exit")
    srv.start()  # same data dir, new port
    assert httpx.get(srv.url + fin_path + "/result").content == before
    done = poll_done(srv.url + loc)
    assert done["status"] == "succeeded" and done["attempts"] == 2, done
    res = httpx.get(srv.url + loc + "/result", headers={"Accept": "application/x-ndjson"}, timeout=WAIT_S)
    lines = res.text.splitlines()
    assert res.status_code == 200 and json.loads(lines[-2])["s"] == 3_000.0
    assert json.loads(lines[-1])["event"] == "summary"
