"""In-process API tests: a schedule round trip and problem+json errors."""

from __future__ import annotations

import math

import numpy as np
from fastapi.testclient import TestClient

from service.app import app
from service.schemas import EXAMPLE

client = TestClient(app)


def test_healthz() -> None:
    assert client.get("/healthz").json() == {"status": "ok"}


def test_example_schedules_and_is_exact_arc() -> None:
    r = client.post("/v1/schedule", json=EXAMPLE)
    assert r.status_code == 200, r.text
    body = r.json()
    smp = body["samples"]
    x, y = np.array(smp["x"]), np.array(smp["y"])
    # the example is a quarter circle of radius 40 about (0, 40)
    assert np.max(np.abs(np.hypot(x, y - 40.0) - 40.0)) < 1e-6
    assert body["summary"]["motion_time"] > 0
    assert all(math.isfinite(v) for v in smp["feed"])


def test_bad_knots_is_problem_json_naming_field() -> None:
    bad = {"toolpath": {"segments": [{"degree": 2, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [1, 0], [1, 1]]}]}}
    r = client.post("/v1/schedule", json=bad)
    assert r.status_code == 422
    assert r.headers["content-type"].startswith("application/problem+json")
    assert r.json()["errors"][0]["field"] == "toolpath.segments[0].knots"


def test_boolean_as_number_rejected() -> None:
    bad = {"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [True, 0]]}]}}
    r = client.post("/v1/schedule", json=bad)
    assert r.status_code == 422
    assert "control_points" in r.json()["errors"][0]["field"]


def test_router_machine() -> None:
    r = client.get("/v1/machines/router")
    assert r.status_code == 200
    assert r.json()["axes"][0]["limits"]["amax"] == 500.0
    assert client.get("/v1/machines/nope").status_code == 422
