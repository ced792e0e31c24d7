"""In-process API tests (TestClient with the lifespan run): formats, machines, budgets, problem+json."""

from __future__ import annotations

import csv
import io
import json
import math
import struct
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.schemas import EXAMPLE
from solvers.machine import ROUTER_DRIVES, derive_limits
from tests.service.conftest import long_line

COLUMNS = ["t", "s", "feed", "x", "y", "z", "v_x", "v_y", "v_z", "a_x", "a_y", "a_z", "j_x", "j_y", "j_z",
           "u_x", "u_y", "u_z", "e_x", "e_y", "e_z"]


def bits(x: float) -> int:
    return int(struct.unpack("<q", struct.pack("<d", x))[0])


def assert_problem(r: Any, status: int, field: str | None = None) -> dict[str, Any]:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    body: dict[str, Any] = r.json()
    assert body["status"] == status and body["title"] and body["detail"] and body["type"].startswith("urn:")
    assert body["errors"] and all("rule" in e and "value" in e and "field" in e for e in body["errors"])
    if field is not None:
        assert any(e["field"] == field for e in body["errors"]), body
    return body


def test_healthz(client: TestClient) -> None:
    h = client.get("/healthz").json()
    assert h["status"] == "ok" and h["schedules_in_flight"] == 0 and h["schedules_limit"] == 4  # 2 x workers
    assert client.head("/healthz").status_code == 200  # (load balancers probe with HEAD: was 405)


@pytest.mark.parametrize("query", ["corner_blend_mm=nan", "sample_period=inf", "corner_tolerance_deg=nan"])
def test_non_finite_query_numbers_are_refused_as_such(client: TestClient, query: str) -> None:
    """``?corner_blend_mm=nan`` read "Input should be less than or equal to 100" (session 58's API probe)."""
    name, value = query.split("=")
    r = client.post(f"/v1/schedule/gcode?method=lp&{query}", content="G21 G90\nG01 X10 F600\n",
                    headers={"content-type": "text/x-gcode"})
    b = assert_problem(r, 422, f"query.{name}")
    assert b["errors"][0]["value"] == value and "finite" in b["errors"][0]["rule"]


def test_example_schedules_and_is_exact_arc(client: TestClient) -> None:
    r = client.post("/v1/schedule", json=EXAMPLE)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/json"
    body = r.json()
    smp = body["samples"]
    assert list(smp) == COLUMNS
    x, y = np.array(smp["x"]), np.array(smp["y"])
    # the example is a quarter circle of radius 40 about (0, 40)
    assert np.max(np.abs(np.hypot(x, y - 40.0) - 40.0)) < 1e-6
    assert body["summary"]["motion_time"] > 0
    assert all(math.isfinite(v) for col in smp.values() for v in col)
    assert len(smp["t"]) == body["summary"]["samples"] == int(r.headers["x-samples"])


def test_csv_and_ndjson_are_bit_identical_to_json(client: TestClient) -> None:
    js = client.post("/v1/schedule", json=EXAMPLE).json()["samples"]
    r = client.post("/v1/schedule", json=EXAMPLE, headers={"Accept": "text/csv"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.reader(io.StringIO(r.text)))
    assert rows[0] == COLUMNS
    assert len(rows) - 1 == len(js["t"])
    for j, name in enumerate(COLUMNS):
        assert [bits(float(row[j])) for row in rows[1:]] == [bits(v) for v in js[name]], name
    r = client.post("/v1/schedule", json=EXAMPLE, headers={"Accept": "application/x-ndjson"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("application/x-ndjson")
    lines = [json.loads(line) for line in r.text.splitlines()]
    *rows, end = lines  # the rows, then the summary line
    assert len(rows) == len(js["t"]) and all("event" not in row for row in rows)
    for name in COLUMNS:
        assert [bits(row[name]) for row in rows] == [bits(v) for v in js[name]], name
    assert end["event"] == "summary" and end["summary"]["samples"] == len(rows)


def test_accept_negotiation(client: TestClient) -> None:
    r = client.post("/v1/schedule", json=EXAMPLE, headers={"Accept": "text/html;q=1, text/csv;q=0.5"})
    assert r.headers["content-type"].startswith("text/csv")
    b = assert_problem(client.post("/v1/schedule", json=EXAMPLE, headers={"Accept": "image/png"}), 406, "Accept")
    assert b["errors"][0]["value"] == "image/png" and "text/csv" in b["errors"][0]["rule"]
    assert b["title"] == "Not Acceptable"


def _custom_machine(drive_only_z: bool) -> dict[str, Any]:
    axes: dict[str, Any] = {}
    for ax in ("x", "y", "z"):
        d = ROUTER_DRIVES[ax]
        drive = {k: getattr(d, k) for k in ("M", "b", "c", "d", "Kv", "Ka", "Kj", "umax", "emax")}
        if ax == "z" and drive_only_z:
            axes[ax] = {"drive": drive, "vmax_request": 150.0}
        else:
            axes[ax] = {"limits": {"vmax": 100.0, "amax": 400.0, "jmax": 50000.0}, "drive": drive}
    return {"name": "mill", "axes": axes, "feed_max": 80.0}


def test_custom_machine_with_limits_and_derived_limits(client: TestClient) -> None:
    body = {**EXAMPLE, "machine": _custom_machine(drive_only_z=True), "options": {"method": "lp"}}
    r = client.post("/v1/schedule", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert max(out["samples"]["feed"]) <= 80.0 * 1.001
    assert out["summary"]["peak_utilisation"]["acceleration_x"] <= 1.01
    # the derived z limits are the solver's own derivation
    assert derive_limits(ROUTER_DRIVES["z"], 150.0, "z").amax > 0


def test_custom_machine_limits_only_has_no_u_e_columns(client: TestClient) -> None:
    axes = {ax: {"limits": {"vmax": 100.0, "amax": 400.0, "jmax": 50000.0}} for ax in ("x", "y", "z")}
    r = client.post("/v1/schedule", json={**EXAMPLE, "machine": {"axes": axes}, "options": {"method": "lp"}})
    assert r.status_code == 200, r.text
    assert list(r.json()["samples"]) == COLUMNS[:15]
    # the NLP needs the drive model: a clear 422, not a 500
    assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "machine": {"axes": axes}}), 422, "machine.axes")


def test_custom_machine_errors_name_the_field(client: TestClient) -> None:
    axes: dict[str, Any] = {ax: {"limits": {"vmax": 100.0, "amax": 400.0, "jmax": 50000.0}} for ax in ("x", "y")}
    axes["z"] = {}
    b = assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "machine": {"axes": axes}}), 422, "machine.axes.z")
    assert "limits" in b["errors"][0]["rule"]
    axes["z"] = {"limits": {"vmax": -1, "amax": 1, "jmax": 1}}
    b = assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "machine": {"axes": axes}}), 422,
                       "machine.axes.z.limits.vmax")
    assert b["errors"][0]["value"] == -1 and b["errors"][0]["pointer"] == "#/machine/axes/z/limits/vmax"
    # a drive whose bias and friction leave no voltage: infeasible, 422 with the solver's explanation
    d = {"M": 1e-3, "b": 0.01, "c": 9.0, "d": 2.0, "Kv": 1e-5, "Ka": 1e-6, "Kj": 1e-8, "umax": 10.0, "emax": 0.02}
    axes["z"] = {"drive": d}
    b = assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "machine": {"axes": axes}}), 422,
                       "machine.axes.z.drive.umax")
    assert b["type"].endswith("invalid-machine")
    assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "machine": "mill"}), 422, "machine")


def test_lp_nlp_is_the_default_method_and_reports_drive_columns(client: TestClient) -> None:
    body = {k: v for k, v in EXAMPLE.items() if k != "options"}
    r = client.post("/v1/schedule", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["summary"]["method"] == "lp+nlp"
    assert out["summary"]["motion_time"] < out["summary"]["lp_motion_time"] + 1e-12
    assert {"u_x", "e_x", "u_y", "e_y"} <= set(out["samples"])
    assert out["diagnostics"]["nlp_fallbacks"] == []
    assert_problem(client.post("/v1/schedule", json={**EXAMPLE, "options": {"method": "nlp"}}), 422, "options.method")
    # (the jerk stage is off with method lp only: lp+nlp keeps the LP's feed in places, held by it)
    r = client.post("/v1/schedule", json={**EXAMPLE, "options": {"jerk": False}})
    assert_problem(r, 422, "options.jerk")
    assert "method lp" in r.text
    assert client.post("/v1/schedule", json={**EXAMPLE, "options": {"method": "lp", "jerk": False}}).status_code == 200


def test_bad_knots_is_problem_json_naming_field(client: TestClient) -> None:
    bad = {"toolpath": {"segments": [{"degree": 2, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [1, 0], [1, 1]]}]}}
    b = assert_problem(client.post("/v1/schedule", json=bad), 422, "toolpath.segments[0].knots")
    assert b["type"].endswith("invalid-toolpath")


def test_boolean_nan_inf_string_numbers_rejected(client: TestClient) -> None:
    seg = {"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [True, 0]]}
    assert_problem(client.post("/v1/schedule", json={"toolpath": {"segments": [seg]}}), 422,
                   "toolpath.segments[0].control_points[1][0]")
    for token in ("NaN", "Infinity", "-Infinity", "1e999", '"1"'):
        raw = ('{"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], ['
               + token + ', 0]]}]}}')
        assert_problem(client.post("/v1/schedule", content=raw, headers={"content-type": "application/json"}), 422,
                       "toolpath.segments[0].control_points[1][0]")


@pytest.mark.parametrize("jerk", ["false", 0, "no", 1])
def test_a_boolean_option_is_a_json_boolean(client: TestClient, jerk: object) -> None:
    """``options.jerk`` "false" read as False (pydantic's lax booleans), while numbers were strict: a string or a
    number sent for a boolean is a 422 naming it."""
    body = {**EXAMPLE, "options": {"method": "lp", "jerk": jerk}}
    assert_problem(client.post("/v1/schedule", json=body), 422, "options.jerk")


def test_malformed_json_is_problem(client: TestClient) -> None:
    """The decoder's error names the body and the character where it failed (not "[12]", a field it is not)."""
    hdr = {"content-type": "application/json"}
    b = assert_problem(client.post("/v1/schedule", content=b'{"toolpath":', headers=hdr), 422, "body")
    assert b["errors"][0]["pointer"] == "#" and b["errors"][0]["value"] == "character 12"
    assert "JSON" in b["errors"][0]["rule"] and "character 12" in b["errors"][0]["rule"]
    assert_problem(client.post("/v1/schedule", content=b"{nope", headers=hdr), 422, "body")


@pytest.mark.parametrize("body", [
    b'{"toolpath":{"gcode":"G01 X10 F600\\n"},"machine":"\\ud800"}',
    b'{"toolpath":{"gcode":"G01 X10 F600 (\\udfff)\\n"}}',
    b'{"toolpath":{"gcode":"G01 X10 F600\\n"},"\\ud800":1}',
])
def test_a_lone_surrogate_in_a_string_is_422_not_500(client: TestClient, body: bytes) -> None:
    """JSON may escape a lone UTF-16 surrogate ("\\ud800"), which no UTF-8 encodes: pydantic refuses the string,
    and the problem that echoes it was a 500 (UnicodeEncodeError while rendering it, session 58's API probe)."""
    b = assert_problem(client.post("/v1/schedule", content=body, headers={"content-type": "application/json"}), 422)
    assert "\\ud8" in json.dumps(b) or "\\udf" in json.dumps(b)  # (the escape, as text)
    assert client.get("/healthz").status_code == 200  # (the connection and the app are fine after it)


def test_body_size_cap(client: TestClient) -> None:
    big = {**EXAMPLE, "pad": "x" * 250_000}
    b = assert_problem(client.post("/v1/schedule", json=big), 413, "body")
    assert "FEEDSCHED_MAX_BODY_BYTES" in b["errors"][0]["rule"]

    def chunks() -> Any:  # no content-length: the streamed byte count trips the cap
        for _ in range(30):
            yield b" " * 10_000

    b = assert_problem(client.post("/v1/schedule", content=chunks(), headers={"content-type": "application/json"}),
                       413, "body")
    assert b["title"] == "Request body too large" and "FEEDSCHED_MAX_BODY_BYTES" in b["errors"][0]["rule"]
    assert b["errors"][0]["value"].startswith("more than ")


def test_sync_budget_points_to_jobs(client: TestClient) -> None:
    n = 600  # over the fixture's 500 control points
    seg = {"degree": 1, "knots": [0, *np.linspace(0, 1, n).tolist(), 1],
           "control_points": [[float(i), 0.0, 0.0] for i in range(n)]}
    b = assert_problem(client.post("/v1/schedule", json={"toolpath": {"segments": [seg]}}), 413, "toolpath.segments")
    assert b["jobs"] == "/v1/jobs"
    # few control points but a long path: the sample-count lower bound trips (fixture: 50 000 samples)
    b = assert_problem(client.post("/v1/schedule", json=long_line(20_000.0, 50.0)), 413, "options.sample_period")
    assert b["jobs"] == "/v1/jobs"
    # a program's lines are counted as the parser splits them: CR-only endings got 600 moves past as one line
    # (session 58's API probe)
    moves = "".join(f"G01 X{i % 2} Y{i * 0.01:.2f} F600\r" for i in range(n))
    assert_problem(client.post("/v1/schedule", json={"toolpath": {"gcode": moves}}), 413, "toolpath.segments")


def test_exact_sample_count_over_the_budget_is_413(client: TestClient) -> None:
    """The sample-count lower bound (``motion_time_floor``: the feed and acceleration limits, 11.9 s here) passes a
    jerk-bound machine's path; the exact count (62 s of motion), known once the pieces are solved, is over the
    fixture's 50 000: a 413 naming options.max_samples (no samples built).  Until session 60 the floor read no
    acceleration and this test's machine was amax 0.05, which the floor now refuses up front (53 s)."""
    axes = {ax: {"limits": {"vmax": 1e4, "amax": 1.0, "jmax": 0.02}} for ax in ("x", "y", "z")}
    body = {**EXAMPLE, "machine": {"axes": axes}, "options": {"method": "lp"}}
    b = assert_problem(client.post("/v1/schedule", json=body), 413, "options.max_samples")
    assert b["jobs"] == "/v1/jobs" and "50000 allowed" in b["detail"]


def test_404_405_problem(client: TestClient) -> None:
    assert_problem(client.get("/v2/nothing"), 404, "path")
    r = client.put("/v1/schedule", json=EXAMPLE)
    assert_problem(r, 405, "path")
    assert r.headers["allow"] == "POST"
    # every method of the path (FastAPI makes a route per method: Starlette's 405 named the first one's only)
    r = client.put("/v1/jobs/abc")
    assert r.headers["allow"] == "DELETE, GET, HEAD"
    rule = assert_problem(r, 405)["errors"][0]["rule"]
    assert rule == "PUT is not allowed on this route; it allows DELETE, GET, HEAD"
    assert client.post("/healthz").headers["allow"] == "GET, HEAD"
    r = client.head("/v1/schedule")  # (no GET there: HEAD is refused as itself, not as the GET it is passed on as)
    assert r.status_code == 405 and r.headers["allow"] == "POST" and r.content == b""


def test_head_is_get_without_the_body(client: TestClient) -> None:
    """HEAD answers as GET with no body (RFC 9110 9.3.2): the same status and headers.  FastAPI routes take only
    the methods they name, and ``HEAD /v1/machines`` was a 405 (only /healthz had a HEAD route)."""
    for url in ("/healthz", "/v1/machines", "/v1/machines/router", "/v1/examples/flower", "/v1/machines/nope"):
        get, head = client.get(url), client.head(url)
        assert head.status_code == get.status_code and head.content == b"", url
        assert head.headers["content-type"] == get.headers["content-type"], url
        assert head.headers["content-length"] == get.headers["content-length"] == str(len(get.content)), url
    assert_problem(client.get("/v1/machines/nope"), 404, "path.name")
    assert_problem(client.get("/v1/jobs/../../etc/passwd"), 404)
    # (a job id names its path parameter as a 422 and a 409 do: was "path" here, "job_id" in a 409)
    assert_problem(client.get("/v1/jobs/not-a-valid-id"), 404, "path.job_id")
    assert_problem(client.delete("/v1/jobs/not-a-valid-id"), 404, "path.job_id")
    assert_problem(client.get("/v1/examples/nope"), 404, "path.name")


def test_unknown_query_parameters_are_refused(client: TestClient) -> None:
    """A /v1 route refuses query parameters it does not read, each by name: the G-code upload ran ``?feed_max=5``
    uncapped and ``POST /v1/schedule?method=lp`` as lp+nlp.  Pages outside /v1 take any (a cache-buster)."""
    hdr = {"content-type": "text/x-gcode"}
    b = assert_problem(client.post("/v1/schedule/gcode?machine=router&feed_max=5", content="G1 X10 F600\n",
                                   headers=hdr), 422, "query.feed_max")
    assert [e["field"] for e in b["errors"]] == ["query.feed_max"] and b["errors"][0]["value"] == "5"
    assert "machine, method, sample_period" in b["errors"][0]["rule"]
    b = assert_problem(client.post("/v1/schedule?method=lp&feed_max=5", json=EXAMPLE), 422)
    assert [e["field"] for e in b["errors"]] == ["query.method", "query.feed_max"]
    assert "JSON body" in b["errors"][0]["rule"]
    assert_problem(client.get("/v1/machines?verbose=1"), 422, "query.verbose")
    assert_problem(client.get("/v1/jobs/abc/result?fmt=csv"), 422, "query.fmt")  # (``format``: a typo ran JSON)
    assert client.get("/v1/machines").status_code == 200
    assert client.get("/healthz?probe=1").status_code == 200
    ok = client.post("/v1/schedule/gcode?machine=router&method=lp", content="G1 X10 F600\n", headers=hdr)
    assert ok.status_code == 200 and ok.json()["summary"]["method"] == "lp"


def test_router_machine(client: TestClient) -> None:
    assert client.get("/v1/machines").json() == {"machines": ["router"]}
    r = client.get("/v1/machines/router")
    assert r.status_code == 200
    body = r.json()
    assert body["axes"][0]["limits"]["amax"] == 500.0
    assert body["axes"][2]["limits"] == body["axes"][2]["limits_from_drive"]  # z is derived from its drive
    assert body["units"]["jmax"] == "mm/s^3" and body["stopping_distance_mm"] > 0


def test_the_interval_budget_counts_the_knot_floor(client: TestClient) -> None:
    """30 mm at a 1 mm/s feed cap: the default knots (0.1 x the stopping distance, 0.4 um) would be 75,300
    intervals, over the synchronous budget of 20,000; the knot floor's (10 um) are 3,000, so the request is
    served, on the floor.  Explicit 1 um knots (the finest the API takes, 30,000 intervals) are still a 413."""
    line = {"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0, 0], [30.0, 0, 0]]}
    body = {"toolpath": {"segments": [line]}, "machine": "router", "options": {"method": "lp", "feed_max": 1.0}}
    r = client.post("/v1/schedule", json=body)
    assert r.status_code == 200, r.text
    summary = r.json()["summary"]
    assert summary["knot_floor_pieces"] == 1 and summary["control_points"] == 3002
    body["options"]["knot_spacing"] = 0.001
    assert_problem(client.post("/v1/schedule", json=body), 413, "options.knot_spacing")


@pytest.mark.parametrize("ctype", ["text/plain", "application/x-www-form-urlencoded", None])
def test_a_json_route_sent_another_media_type_is_415(client: TestClient, ctype: str | None) -> None:
    """``curl -d`` without a content-type sends a form: the JSON routes answer 415 naming the content type (a 422
    naming the field "" with the body's bytes as its value until session 58)."""
    body = json.dumps(EXAMPLE)
    hdr = {"content-type": ctype} if ctype else {}
    for route in ("/v1/schedule", "/v1/jobs"):
        b = assert_problem(client.post(route, content=body, headers=hdr), 415, "content-type")
        assert b["errors"][0]["value"] == ctype
    assert client.post("/v1/schedule", content=body, headers={"content-type": "application/json; charset=utf-8"}
                       ).status_code == 200


def test_an_empty_idempotency_key_is_422(client: TestClient) -> None:
    """"" would be one key for every client that sends it empty: refused, naming the header by its name."""
    r = client.post("/v1/jobs", json=EXAMPLE, headers={"Idempotency-Key": ""})
    b = assert_problem(r, 422, "Idempotency-Key")
    assert b["errors"][0]["value"] == ""


@pytest.mark.parametrize(("second", "field"), [
    ({"type": "polyline", "points": [[10, 1, 0], [20, 1, 0]]}, "toolpath.segments[1].points[0]"),
    ({"type": "line", "start": [10, 1, 0], "end": [20, 1, 0]}, "toolpath.segments[1].start"),
    ({"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[10, 1, 0], [20, 1, 0]]},
     "toolpath.segments[1].control_points[0]"),
])
def test_a_gap_names_the_segments_start_as_the_request_has_it(client: TestClient, second: dict[str, Any],
                                                              field: str) -> None:
    """The toolpath's errors named ``segments[1].control_points[0]``: no ``toolpath.`` and, for a polyline or a
    line, a field the request does not have (session 58's API probe).  Now the request's own path."""
    body = {"toolpath": {"segments": [{"type": "line", "start": [0, 0, 0], "end": [10, 0, 0]}, second]},
            "options": {"method": "lp"}}
    b = assert_problem(client.post("/v1/schedule", json=body), 422, field)
    assert b["errors"][0]["value"] == pytest.approx(1.0)
    blended = {**body, "toolpath": {**body["toolpath"], "corner_blend_mm": 0.1}}
    assert_problem(client.post("/v1/schedule", json=blended), 422, "toolpath.segments[1]")
    tol = {"toolpath": {"corner_tolerance_deg": 180, "segments": body["toolpath"]["segments"][:1]}}
    assert_problem(client.post("/v1/schedule", json=tol), 422, "toolpath.corner_tolerance_deg")


@pytest.mark.parametrize(("accept", "media"), [
    ("application/json;q=0, */*", "text/csv"),  # (JSON refused by name: */* admits the others)
    ("text/csv;Q=0, application/json", "application/json"),  # (parameter names are case-insensitive)
    ("text/csv;q=nan, application/json", "application/json"),  # (a q not in [0, 1] refuses its range)
    ("text/csv;q=inf, application/json", "application/json"),
    ("application/json;q=1.5, text/csv", "text/csv"),
    ("text/csv;q=0.5, application/json;q=0.5", "text/csv"),  # (a tie: the range named first)
    ("text/*", "text/csv"),
    ("text/csv;q=0, text/*", None),  # (the most specific range decides: CSV refused, nothing else is text/*)
])
def test_accept_follows_rfc_9110_precedence(client: TestClient, accept: str, media: str | None) -> None:
    """Session 59's probe: ``text/csv;q=0, text/*`` served CSV, an invalid q won, ``Q=0`` was not read."""
    r = client.post("/v1/schedule", json=EXAMPLE, headers={"Accept": accept})
    if media is None:
        assert_problem(r, 406, "Accept")
    else:
        assert r.status_code == 200 and r.headers["content-type"].startswith(media), (r.status_code, r.text[:200])


def test_a_trailing_slash_is_not_redirected(client: TestClient) -> None:
    """Starlette's 307 to the path without the slash built its absolute Location from the Host header (a client
    could make the service redirect to any host): now a 404 problem."""
    r = client.get("/healthz/", headers={"host": "evil.example"}, follow_redirects=False)
    assert_problem(r, 404)
    assert "location" not in r.headers


@pytest.mark.parametrize(("axis", "field"), [
    ({"limits": {"vmax": 100, "amax": 5e-324, "jmax": 1e5}}, "machine.axes.x.limits.amax"),
    ({"limits": {"vmax": 100, "amax": 1e3, "jmax": 1e-310}}, "machine.axes.x.limits.jmax"),
    ({"drive": {**{k: getattr(ROUTER_DRIVES["x"], k) for k in ("M", "c", "d", "Ka", "Kj", "umax", "emax")},
                "Kv": 5e-324, "b": 0.0}}, "machine.axes.x.drive"),
    ({"drive": {**{k: getattr(ROUTER_DRIVES["x"], k) for k in ("M", "b", "c", "d", "Kv", "Ka", "umax", "emax")},
                "Kj": 5e-324}}, "machine.axes.x.drive"),
])
def test_limits_out_of_scale_are_422_naming_what_was_sent(client: TestClient, axis: dict[str, Any],
                                                           field: str) -> None:
    """Session 59's probe: amax 5e-324 (an infinite stopping distance) and feed_max 1e-310 (a zero one) were 500s
    in the knot plan; a drive whose derived jmax is inf named ``machine.axes.x.jmax``, a field no request has."""
    n = {"limits": {"vmax": 100.0, "amax": 1000.0, "jmax": 1e5}}
    body = {"toolpath": {"segments": [{"type": "line", "start": [0, 0, 0], "end": [5, 0, 0]}]},
            "machine": {"axes": {"x": axis, "y": n, "z": n}}, "options": {"method": "lp"}}
    assert_problem(client.post("/v1/schedule", json=body), 422, field)
    tiny = {**EXAMPLE, "options": {"method": "lp", "feed_max": 1e-310}}
    assert_problem(client.post("/v1/schedule", json=tiny), 422, "options.feed_max")


def test_lp_holds_a_drive_s_own_vmax_when_its_limits_are_derived(client: TestClient) -> None:
    """A drive-only axis with ``drive.vmax`` 5 mm/s: lp+nlp held it, method lp's derived limits ignored it (51.5
    mm/s on a 5 mm line, session 59's probe).  The finite differences of the positions hold it now."""
    drive = {k: getattr(ROUTER_DRIVES["x"], k) for k in ("M", "b", "c", "d", "Kv", "Ka", "Kj", "umax", "emax")}
    axes = {"x": {"drive": {**drive, "vmax": 5.0}}, "y": {"drive": drive}, "z": {"drive": drive}}
    body = {"toolpath": {"segments": [{"type": "line", "start": [0, 0, 0], "end": [5, 0, 0]}]},
            "machine": {"axes": axes}, "options": {"method": "lp"}}
    r = client.post("/v1/schedule", json=body)
    assert r.status_code == 200, r.text
    x = np.asarray(r.json()["samples"]["x"])
    assert float(np.max(np.abs(np.diff(x)))) / 1e-3 <= 5.0 * 1.01


@pytest.mark.parametrize(("raw", "field"), [
    # options.method twice ran the last one: lp here, the first said lp+nlp
    ('"options": {"method": "lp+nlp", "sample_period": 0.001, "method": "lp"}', "options.method"),
    ('"options": {"method": "lp"}, "options": {"method": "lp+nlp"}', "options"),
])
def test_a_name_given_twice_in_a_json_object_is_422(client: TestClient, raw: str, field: str) -> None:
    """RFC 8259 leaves an object with a repeated name undefined; Python's parser kept the last (sessions 59-60's
    probes). Both JSON routes refuse it, naming the object's path and the name."""
    body = json.dumps({k: v for k, v in EXAMPLE.items() if k != "options"})[:-1] + ", " + raw + "}"
    for route in ("/v1/schedule", "/v1/jobs"):
        b = assert_problem(client.post(route, content=body, headers={"content-type": "application/json"}), 422,
                           field)
        assert b["errors"][0]["value"] == field.rsplit(".", 1)[-1] and "2 times" in b["errors"][0]["rule"]


def test_a_repeated_name_inside_a_list_is_found_where_it_is() -> None:
    from service.http import duplicate_name
    seg = '{"degree": 1, "knots": [0, 0, 1, 1], "weights": [1, 1], "control_points": [[0, 0, 0], [1, 0, 0]]}'
    dup = seg.replace('"weights": [1, 1]', '"weights": [1, 1], "weights": [1, 2], "weights": [2, 2]')
    doc = '{"toolpath": {"segments": [' + seg + ", " + dup + "]}}"
    assert duplicate_name(doc) == (("toolpath", "segments", 1), "weights", 3)
    assert duplicate_name('{"a": [{"b": {"c": 1}}, {"b": 2}], "c": {"a": 1}}') is None  # (names repeat across objects)
    many = "{" + ", ".join(f'"k{i}": {i}' for i in range(20_000)) + ', "k19999": 0, "k19999": 1}'
    assert duplicate_name('{"segments": [' + many + "]}") == (("segments", 0), "k19999", 3)  # (the last name)


def test_a_second_idempotency_key_header_is_422(client: TestClient) -> None:
    """Two Idempotency-Key headers: the route read the first and ignored the second (session 59's probe)."""
    r = client.post("/v1/jobs", json=EXAMPLE, headers=[("Idempotency-Key", "k-1"), ("Idempotency-Key", "k-2")])
    b = assert_problem(r, 422, "Idempotency-Key")
    assert b["errors"][0]["value"] == ["k-1", "k-2"]


@pytest.mark.parametrize("depth", [900, 3000])
def test_a_deeply_nested_body_is_422(client: TestClient, depth: int) -> None:
    """Arrays nested 900 deep: the 422's echo of the value recursed level by level (RecursionError: a 500); 3,000
    deep: Python's parser gives up (a 400 "must be UTF-8 JSON").  Both 422s now, the echo cut at VALUE_DEPTH levels;
    and a name given twice 900 levels down is found there (``duplicate_name`` keeps its own stack)."""
    from service.errors import VALUE_DEPTH

    body = '{"toolpath": ' + "[" * depth + '{"a": 1}' + "]" * depth + "}"
    for route in ("/v1/schedule", "/v1/jobs"):
        r = client.post(route, content=body, headers={"content-type": "application/json"})
        e = assert_problem(r, 422)["errors"][0]
        if depth == 900:
            assert e["field"] == "toolpath"
            v, levels = e["value"], 0
            while isinstance(v, list):
                v, levels = v[0], levels + 1
            assert v == "..." and levels == VALUE_DEPTH
        else:
            assert e["field"] == "body" and "nested too deep" in e["rule"] and "character" not in e["rule"]
    if depth == 900:
        dup = body.replace('{"a": 1}', '{"a": 1, "a": 2}')
        r = client.post("/v1/schedule", content=dup, headers={"content-type": "application/json"})
        assert assert_problem(r, 422, "toolpath" + "[0]" * depth + ".a")["errors"][0]["value"] == "a"


def test_a_limit_under_the_samples_float_resolution_is_a_422_naming_its_request_field(client: TestClient) -> None:
    """A line along x from 500 mm whose x jmax one unit in the last place of 500 mm reads twice over as a jerk at
    1 ms (``pipeline._noise_room``): 422 invalid-machine naming the request's field and pointer, given limits
    (``machine.axes.x.limits.jmax``) or limits derived from the drive model (``machine.axes.x.drive``)."""
    tiny = 2.0 * float(np.spacing(500.0)) / 1e-9 / 2.0
    line = {"segments": [{"type": "line", "start": [500.0, 20.0, 0.0], "end": [500.5, 20.0, 0.0]}]}
    axes: dict[str, Any] = {ax: {"limits": {"vmax": 100.0, "amax": 400.0, "jmax": 50000.0}} for ax in ("x", "y", "z")}
    axes["x"] = {"limits": {"vmax": 100.0, "amax": 400.0, "jmax": tiny}}
    body = {**EXAMPLE, "toolpath": line, "machine": {"axes": axes}, "options": {"method": "lp"}}
    b = assert_problem(client.post("/v1/schedule", json=body), 422, "machine.axes.x.limits.jmax")
    assert b["type"].endswith("invalid-machine") and b["errors"][0]["pointer"] == "#/machine/axes/x/limits/jmax"
    assert b["errors"][0]["value"] == tiny and "sample_period" in b["errors"][0]["rule"]
    # the same limits on y, which the line does not move: scheduled
    body["machine"] = {"axes": {**axes, "x": axes["y"], "y": axes["x"]}}
    assert client.post("/v1/schedule", json=body).status_code == 200
    # x's limits derived from a drive whose Kj leaves a jerk that small: the drive is the field
    d = {k: getattr(ROUTER_DRIVES["x"], k) for k in ("M", "b", "c", "d", "Kv", "Ka", "Kj", "umax", "emax")}
    lim = derive_limits(ROUTER_DRIVES["x"], 100.0, "x")
    d["Kj"] *= lim.jmax / tiny
    axes["x"] = {"drive": d, "vmax_request": 100.0}
    body["machine"] = {"axes": axes}
    b = assert_problem(client.post("/v1/schedule", json=body), 422, "machine.axes.x.drive")
    assert b["type"].endswith("invalid-machine")
