"""Admission control: synchronous schedules beyond FEEDSCHED_MAX_INFLIGHT and jobs beyond
FEEDSCHED_JOB_QUEUE_DEPTH are answered 503 problem+json with Retry-After, at once."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.config import Settings
from service.errors import ServiceError, problem_from_exception
from service.limits import Gate
from service.schemas import EXAMPLE
from tests.service.conftest import WAIT_S, Server, long_line, wait_for
from tests.service.test_inprocess import assert_problem

#: A synchronous request that keeps a solver busy for a while (lp: seconds on the shared cores).
SLOW = {**long_line(2_000.0, 0.5), "options": {"method": "lp", "knot_spacing": 0.5}}


def assert_busy(r: Any) -> dict[str, Any]:
    body = assert_problem(r, 503)
    assert body["type"] == "urn:feedsched:problem:busy"
    assert int(r.headers["retry-after"]) >= 1
    e = body["errors"][0]
    assert isinstance(e["value"], int) and "FEEDSCHED_" in e["rule"]
    return body


def test_gate_counts_and_refuses_without_waiting() -> None:
    g = Gate(2, "things", "FEEDSCHED_X")
    with g.enter(), g.enter():
        assert g.current == 2
        with pytest.raises(ServiceError) as exc, g.enter():
            pass
        p = problem_from_exception(exc.value)
        assert p["status"] == 503 and p["errors"][0]["value"] == 2 and "FEEDSCHED_X" in p["errors"][0]["rule"]
        assert exc.value.headers == {"Retry-After": "1"}
    assert g.stats() == {"in_flight": 0, "limit": 2, "admitted": 2, "refused": 1}
    with g.enter():  # free again
        pass
    g._avg_s = 7.2
    assert g.retry_after() == 8
    g._avg_s = 1e6
    assert g.retry_after() == 60


def test_settings_defaults_follow_workers(monkeypatch: pytest.MonkeyPatch) -> None:
    for k in ("FEEDSCHED_MAX_INFLIGHT", "FEEDSCHED_JOB_QUEUE_DEPTH"):
        monkeypatch.delenv(k, raising=False)
    s = Settings(workers=3)
    assert s.max_inflight == 6 and s.job_queue_depth == 96
    monkeypatch.setenv("FEEDSCHED_MAX_INFLIGHT", "5")
    assert Settings(workers=3).max_inflight == 5


@pytest.fixture(scope="module")
def tight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("tight"), workers=1, max_inflight=1,
                              job_queue_depth=1, job_retry_after=7))
    with TestClient(app, raise_server_exceptions=False) as c:
        yield c


def test_inprocess_excess_schedule_is_503_at_once(tight: TestClient) -> None:
    out: dict[str, Any] = {}
    t = threading.Thread(target=lambda: out.setdefault("r", tight.post("/v1/schedule", json=SLOW)))
    t.start()
    wait_for(lambda: tight.get("/healthz").json()["schedules_in_flight"] == 1, "the slow schedule to be admitted")
    t0 = time.monotonic()
    gcode = {"content": b"G01 X10 F100\n", "headers": {"content-type": "text/x-gcode"}}
    for path, kw in (("/v1/schedule", {"json": EXAMPLE}), ("/v1/schedule/gcode", gcode)):
        assert_busy(tight.post(path, **kw))
    refused_in = time.monotonic() - t0
    assert tight.get("/healthz").json()["schedules_in_flight"] == 1, "answered while the slow one still ran"
    t.join(WAIT_S)
    assert out["r"].status_code == 200, out["r"].text
    h = tight.get("/healthz").json()
    assert h["schedules_in_flight"] == 0 and h["schedules_refused"] == 2
    assert tight.post("/v1/schedule", json=EXAMPLE).status_code == 200  # a free slot admits again
    assert refused_in < WAIT_S


def test_inprocess_job_queue_full_is_503(tight: TestClient) -> None:
    first = tight.post("/v1/jobs", json=long_line(40_000.0), headers={"Idempotency-Key": "limits-1"})
    assert first.status_code == 202
    r = tight.post("/v1/jobs", json=EXAMPLE)
    body = assert_busy(r)
    assert r.headers["retry-after"] == "7" and body["errors"][0]["value"] == 1
    again = tight.post("/v1/jobs", json=long_line(40_000.0), headers={"Idempotency-Key": "limits-1"})
    assert again.status_code == 200 and again.json()["id"] == first.json()["id"]  # a repeat is not new work
    assert tight.delete(first.headers["location"]).json()["status"] == "cancelled"
    wait_for(lambda: tight.get("/healthz").json()["jobs_active"] == 0, "the cancelled job to leave the queue")
    ok = tight.post("/v1/jobs", json=EXAMPLE)
    assert ok.status_code == 202
    wait_for(lambda: tight.get(ok.headers["location"]).json()["status"] == "succeeded", "the job")


def test_server_admits_the_limit_and_refuses_the_excess(server_factory: Callable[..., Server]) -> None:
    """Real uvicorn, FEEDSCHED_MAX_INFLIGHT=2 on one solver process: 2 slow requests are admitted (one
    solving, one waiting for the process), 6 more at the same time get 503 while those two still run."""
    srv = server_factory(FEEDSCHED_WORKERS="1", FEEDSCHED_MAX_INFLIGHT="2", FEEDSCHED_JOB_QUEUE_DEPTH="1").start()
    health = srv.url + "/healthz"
    slow: list[httpx.Response] = []
    threads = [threading.Thread(target=lambda: slow.append(httpx.post(srv.url + "/v1/schedule", json=SLOW,
                                                                      timeout=WAIT_S))) for _ in range(2)]
    for t in threads:
        t.start()
    wait_for(lambda: httpx.get(health).json()["schedules_in_flight"] == 2, "both slow schedules admitted")
    excess: list[httpx.Response] = []
    burst = [threading.Thread(target=lambda: excess.append(httpx.post(srv.url + "/v1/schedule", json=EXAMPLE,
                                                                      timeout=WAIT_S))) for _ in range(6)]
    for t in burst:
        t.start()
    for t in burst:
        t.join(WAIT_S)
    assert httpx.get(health).json()["schedules_in_flight"] == 2, "the excess was answered while the two still ran"
    assert len(excess) == 6
    for r in excess:
        assert_busy(r)
    for t in threads:
        t.join(WAIT_S)
    assert [r.status_code for r in slow] == [200, 200], [r.text[:300] for r in slow]
    h = httpx.get(health).json()
    assert h["schedules_refused"] == 6 and h["schedules_in_flight"] == 0
    assert httpx.post(srv.url + "/v1/schedule", json=EXAMPLE, timeout=WAIT_S).status_code == 200


def test_readme_documents_the_settings() -> None:
    text = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    for var in ("FEEDSCHED_MAX_INFLIGHT", "FEEDSCHED_JOB_QUEUE_DEPTH", "FEEDSCHED_JOB_RETRY_AFTER"):
        assert var in text
