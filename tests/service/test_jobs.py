"""Jobs in-process: submit/poll/result, cancel kills the solver process, idempotency, restart recovery."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from service import jobs
from service.app import create_app
from service.config import Settings
from service.schemas import EXAMPLE
from service.store import JobStore
from tests.service.conftest import long_line, pid_gone, wait_for
from tests.service.test_inprocess import assert_problem


def poll_done(client: Any, loc: str) -> dict[str, Any]:
    def done() -> dict[str, Any] | None:
        j: dict[str, Any] = client.get(loc).json()
        return j if j["status"] not in ("queued", "running") else None

    out: dict[str, Any] = wait_for(done, f"job {loc} to finish", every=0.1)
    return out


def test_submit_poll_result_all_formats(client: TestClient) -> None:
    r = client.post("/v1/jobs", json=EXAMPLE)
    assert r.status_code == 202, r.text
    loc = r.headers["location"]
    job = r.json()
    assert loc == f"/v1/jobs/{job['id']}" and job["status"] in ("queued", "running") and len(job["id"]) >= 24
    done = poll_done(client, loc)
    assert done["status"] == "succeeded" and done["progress"] == 1.0 and done["attempts"] == 1
    t = done["timings"]
    assert t["created"] <= t["started"] <= t["finished"] and t["run_s"] >= 0
    res = client.get(loc + "/result")
    assert res.status_code == 200
    sync = client.post("/v1/schedule", json=EXAMPLE).json()
    assert res.json()["samples"] == sync["samples"]  # same floats as the synchronous answer
    assert done["summary"]["samples"] == len(sync["samples"]["t"])
    csv_text = client.get(loc + "/result", headers={"Accept": "text/csv"}).text
    head = client.head(loc + "/result", headers={"Accept": "text/csv"})  # (a streamed body: the headers alone)
    assert head.status_code == 200 and head.content == b"" and head.headers["content-type"].startswith("text/csv")
    assert head.headers["x-samples"] == str(done["summary"]["samples"])
    assert csv_text.splitlines()[1:] == client.post("/v1/schedule", json=EXAMPLE,
                                                   headers={"Accept": "text/csv"}).text.splitlines()[1:]
    nd = client.get(loc + "/result", headers={"Accept": "application/x-ndjson"}).text.splitlines()
    # rows, then the summary line (the NDJSON protocol: a result without it is incomplete)
    assert json.loads(nd[-2])["t"] == sync["samples"]["t"][-1]
    end = json.loads(nd[-1])
    assert end["event"] == "summary" and end["summary"] == done["summary"] and "corners" in end["diagnostics"]


def test_failed_job_keeps_the_problem(client: TestClient) -> None:
    bad = {"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [0, 0]]}]}}
    r = client.post("/v1/jobs", json=bad)
    assert r.status_code == 202
    done = poll_done(client, r.headers["location"])
    assert done["status"] == "failed"
    assert done["error"]["status"] == 422 and done["error"]["errors"][0]["field"].startswith("toolpath.segments[0]")
    b = assert_problem(client.get(r.headers["location"] + "/result"), 409)
    assert b["job_status"] == "failed"


def test_cancel_kills_the_solver_process(client: TestClient) -> None:
    r = client.post("/v1/jobs", json=long_line(40_000.0))
    loc = r.headers["location"]
    running = wait_for(lambda: (j := client.get(loc).json())["progress"] > 0 and j["worker_pid"] and j, "progress")
    pid = running["worker_pid"]
    assert not pid_gone(pid)
    d = client.delete(loc)
    assert d.status_code == 200 and d.json()["status"] == "cancelled"
    wait_for(lambda: pid_gone(pid), f"solver process {pid} to die")
    j = client.get(loc).json()
    assert j["status"] == "cancelled" and j["worker_pid"] is None
    assert_problem(client.get(loc + "/result"), 409)
    assert client.delete(loc).status_code == 200  # cancelling again is harmless


def test_a_cancelled_job_keeps_its_latest_progress(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    """A job's progress is written to the store at most every ``jobs.PROGRESS_WRITE_S`` (served from memory while
    it runs); a cancel wrote the status over the stored value, and the job read 0.025 where its last poll had read
    0.275.  With the writes held off entirely, the stored value stays 0 and only the flush on cancel keeps it."""
    monkeypatch.setattr(jobs, "PROGRESS_WRITE_S", 1e12)
    loc = client.post("/v1/jobs", json=long_line(40_000.0)).headers["location"]
    running = wait_for(lambda: (j := client.get(loc).json())["progress"] > 0 and j, "progress")
    d = client.delete(loc).json()
    assert d["status"] == "cancelled" and d["progress"] >= running["progress"] > 0, (d, running)
    assert client.get(loc).json()["progress"] == d["progress"]


def test_a_job_that_finishes_while_it_is_cancelled_is_a_conflict(client: TestClient,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """DELETE reads the job's status, then cancels: a job that finishes in between (here: fails, injected in the
    cancel itself) answered 200 with the finished status; now the 409 a finished job gets."""
    loc = client.post("/v1/jobs", json=long_line(40_000.0)).headers["location"]
    wait_for(lambda: client.get(loc).json()["progress"] > 0, "progress")
    jm = client.app.state.service.jobs  # type: ignore[attr-defined]
    real = jm.cancel

    async def finished_first(job_id: str) -> bool:
        jm.store.finish(job_id, "failed", error=None)
        out: bool = await real(job_id)
        return out

    monkeypatch.setattr(jm, "cancel", finished_first)
    b = assert_problem(client.delete(loc), 409, "path.job_id")
    assert b["detail"] == "the job has failed" and client.get(loc).json()["status"] == "failed"


def test_delete_finished_job_is_conflict(client: TestClient) -> None:
    loc = client.post("/v1/jobs", json=EXAMPLE).headers["location"]
    poll_done(client, loc)
    assert_problem(client.delete(loc), 409, "path.job_id")


def test_idempotency_key_returns_existing_job(client: TestClient) -> None:
    h = {"Idempotency-Key": "batch-7-part-12"}
    a = client.post("/v1/jobs", json=EXAMPLE, headers=h)
    b = client.post("/v1/jobs", json=EXAMPLE, headers=h)
    assert a.status_code == 202 and b.status_code == 200
    assert a.json()["id"] == b.json()["id"] and a.headers["location"] == b.headers["location"]
    other = {**EXAMPLE, "options": {"sample_period": 0.002}}
    assert_problem(client.post("/v1/jobs", json=other, headers=h), 422, "Idempotency-Key")
    c = client.post("/v1/jobs", json=EXAMPLE)
    assert c.json()["id"] != a.json()["id"]


def test_job_api_validates_like_schedule(client: TestClient) -> None:
    assert_problem(client.post("/v1/jobs", json={"toolpath": {"segments": []}}), 422, "toolpath.segments")


def test_restart_reruns_interrupted_job_and_keeps_results(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path, workers=1)
    with TestClient(create_app(settings)) as c:
        fin = c.post("/v1/jobs", json=EXAMPLE).headers["location"]
        assert poll_done(c, fin)["status"] == "succeeded"
        before = c.get(fin + "/result", headers={"Accept": "text/csv"}).text
        loc = c.post("/v1/jobs", json=long_line(3_000.0)).headers["location"]
        wait_for(lambda: c.get(loc).json()["progress"] > 0, "progress")
        pid = c.get(loc).json()["worker_pid"]
    # the service stopped mid-job: its solver process is gone, the job is still 'running' on disk
    wait_for(lambda: pid_gone(pid), "solver process to die with the service")
    with TestClient(create_app(settings)) as c:
        assert c.get(fin + "/result", headers={"Accept": "text/csv"}).text == before
        done = poll_done(c, loc)
        assert done["status"] == "succeeded" and done["attempts"] == 2
        assert c.get(loc + "/result").json()["summary"]["path_length"] == 3_000.0


def test_restart_fails_job_after_max_attempts(tmp_path: Path) -> None:
    store = JobStore(tmp_path)
    job, _ = store.create({"toolpath": EXAMPLE["toolpath"]}, None)
    store.mark_running(job.id)  # attempt 1 ... and the service died
    store.close()
    with TestClient(create_app(Settings(data_dir=tmp_path, workers=1, job_max_attempts=1))) as c:
        j = c.get(f"/v1/jobs/{job.id}").json()
        assert j["status"] == "failed" and j["error"]["type"].endswith("interrupted")
        assert "service stopped" in j["error"]["detail"]


def test_job_ids_are_unguessable_and_validated(client: TestClient) -> None:
    ids = {client.post("/v1/jobs", json=EXAMPLE).json()["id"] for _ in range(3)}
    assert len(ids) == 3 and all(len(i) == 24 for i in ids)
    assert_problem(client.get("/v1/jobs/%2e%2e%2fjobs.sqlite3/result"), 404)
