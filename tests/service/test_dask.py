"""Jobs through a real Dask LocalCluster on loopback, including a worker killed mid-job."""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Iterator
from typing import Any

import pytest
from distributed import Client, LocalCluster
from fastapi.testclient import TestClient

from service.app import create_app
from service.config import Settings
from service.schemas import EXAMPLE
from service.worker import CANCELLED_TOPIC
from tests.service.conftest import long_line, pid_gone, wait_for
from tests.service.test_jobs import poll_done


@pytest.fixture(scope="module")
def cluster() -> Iterator[LocalCluster]:
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, worker_dashboard_address=None) as c:
        yield c


@pytest.fixture(scope="module")
def dask_client(cluster: LocalCluster, tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("dask"), dask_scheduler=cluster.scheduler_address))
    with TestClient(app) as c:
        assert c.app.state.service.executor.name == "dask"  # type: ignore[attr-defined]
        yield c


def worker_pids(cluster: LocalCluster) -> set[int]:
    with Client(cluster.scheduler_address) as cl:
        return set(cl.run(os.getpid).values())


def test_schedule_and_job_through_dask(dask_client: TestClient, cluster: LocalCluster) -> None:
    sync = dask_client.post("/v1/schedule", json=EXAMPLE)
    assert sync.status_code == 200, sync.text
    loc = dask_client.post("/v1/jobs", json=EXAMPLE).headers["location"]
    done = poll_done(dask_client, loc)
    assert done["status"] == "succeeded"
    assert dask_client.get(loc + "/result").json()["samples"] == sync.json()["samples"]
    bad = {"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [0, 0]]}]}}
    r = dask_client.post("/v1/schedule", json=bad)
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("toolpath.segments[0]")
    # NDJSON through Dask: the rows after the whole task, same protocol (summary line last)
    *rows, end = [json.loads(x) for x in dask_client.post(
        "/v1/schedule", json=EXAMPLE, headers={"Accept": "application/x-ndjson"}).text.splitlines()]
    assert [row["x"] for row in rows] == sync.json()["samples"]["x"]
    assert end["event"] == "summary" and end["summary"]["samples"] == len(rows)
    r = dask_client.post("/v1/schedule", json=bad, headers={"Accept": "application/x-ndjson"})
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"


def test_worker_killed_mid_job_is_rerun(dask_client: TestClient, cluster: LocalCluster) -> None:
    loc = dask_client.post("/v1/jobs", json=long_line(3_000.0)).headers["location"]
    running: dict[str, Any] = wait_for(
        lambda: (j := dask_client.get(loc).json())["progress"] > 0 and j["worker_pid"] and j, "progress on a worker")
    pid = running["worker_pid"]
    assert pid in worker_pids(cluster) and pid != os.getpid()
    os.kill(pid, signal.SIGKILL)
    wait_for(lambda: pid_gone(pid), "the killed worker to be gone")
    done = poll_done(dask_client, loc)
    assert done["status"] == "succeeded", done
    assert dask_client.get(loc + "/result").json()["summary"]["path_length"] == 3_000.0
    wait_for(lambda: len(worker_pids(cluster)) == 2, "the nanny to restart the worker")


def test_cancel_through_dask_stops_the_task(dask_client: TestClient, cluster: LocalCluster) -> None:
    loc = dask_client.post("/v1/jobs", json=long_line(40_000.0)).headers["location"]
    wait_for(lambda: dask_client.get(loc).json()["progress"] > 0, "progress")
    assert dask_client.delete(loc).json()["status"] == "cancelled"

    def idle() -> bool:  # no thread on any worker still executing a task (a cancelled future alone is not that)
        with Client(cluster.scheduler_address) as cl:
            return not any(cl.run(_executing).values())

    wait_for(idle, "the Dask worker threads to stop the cancelled solve")
    with Client(cluster.scheduler_address) as cl:  # stopped by the cancel Event, not by finishing
        assert cl.get_events(CANCELLED_TOPIC), "the solve was not interrupted"


def _executing(dask_worker: Any) -> int:
    return int(dask_worker.state.executing_count)
