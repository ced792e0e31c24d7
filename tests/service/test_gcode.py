"""G-code in the service: JSON body and text/x-gcode upload, F words as feed limits, errors with line and column."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.config import Settings
from solvers.machine import router
from tests.service.test_inprocess import assert_problem
from tests.solvers.test_optimality import ramp_from_rest

#: A 60 x 40 mm rectangle at F1200 (20 mm/s) after a rapid to its corner, then a G2 quarter circle at F3000.
PROGRAM = """(rectangle and an arc)
G21 G90 G17
G00 X10 Y10
G01 X70 F1200
Y50
G02 X90 Y70 I20 J0 F3000
M30
"""
FEED_TOL = 2e-3


@pytest.mark.parametrize("method", ["lp", "lp+nlp"])
def test_gcode_json_body_feed_limits_and_path(client: TestClient, method: str) -> None:
    r = client.post("/v1/schedule", json={"toolpath": {"gcode": PROGRAM}, "options": {"method": method}})
    assert r.status_code == 200, r.text
    smp = r.json()["samples"]
    x, y, feed = np.array(smp["x"]), np.array(smp["y"]), np.array(smp["feed"])
    # starts at the origin (the rapid), ends at the arc's end
    assert abs(x[0]) < 1e-9 and abs(y[0]) < 1e-9
    assert abs(x[-1] - 90) < 1e-9 and abs(y[-1] - 70) < 1e-9
    # on the G01 legs (y = 10 with x in (10, 70), and x = 70) the feed stays under F1200 = 20 mm/s
    leg = ((np.abs(y - 10) < 1e-9) & (x > 10 + 1e-6)) | ((np.abs(x - 70) < 1e-9) & (y < 50 - 1e-6) & (y > 10))
    assert leg.sum() > 100
    assert np.max(feed[leg]) <= 20.0 * (1 + FEED_TOL)
    assert np.max(feed[leg]) >= 20.0 * (1 - 1e-3)
    # on the arc (centre (90, 50), R 20) the feed stays under F3000 = 50 mm/s
    on_arc = (np.abs(np.hypot(x - 90, y - 50) - 20) < 1e-6) & (y > 50 + 1e-6)
    assert on_arc.sum() > 10
    assert np.max(feed[on_arc]) <= 50.0 * (1 + FEED_TOL)
    # the rapid is not held to a programmed feed: it runs faster than either F word
    rapid = (np.abs(x - y) < 1e-9) & (x > 1e-6) & (x < 10 - 1e-6)
    assert np.max(feed[rapid]) > 50.0


def test_gcode_upload_text_x_gcode(client: TestClient) -> None:
    r = client.post("/v1/schedule/gcode?method=lp", content=PROGRAM, headers={"content-type": "text/x-gcode",
                                                                             "accept": "text/csv"})
    assert r.status_code == 200, r.text
    rows = r.text.strip().splitlines()
    assert rows[0].startswith("t,s,feed,x,y,z")
    last = rows[-1].split(",")
    assert abs(float(last[3]) - 90) < 1e-9 and abs(float(last[4]) - 70) < 1e-9


def test_gcode_upload_method_with_an_unescaped_plus(client: TestClient) -> None:
    """``?method=lp+nlp`` typed into a URL reads as "lp nlp" (a `+` in a query string is a space): taken as
    lp+nlp, the same schedule as ``lp%2Bnlp``; another method name is still a 422 naming the query parameter."""
    short = "G21 G90\nG01 X10 F1200\n"
    hdr = {"content-type": "text/x-gcode"}
    plain = client.post("/v1/schedule/gcode?method=lp+nlp", content=short, headers=hdr)
    escaped = client.post("/v1/schedule/gcode?method=lp%2Bnlp", content=short, headers=hdr)
    assert plain.status_code == escaped.status_code == 200, plain.text
    assert plain.json()["summary"]["method"] == "lp+nlp"
    assert plain.json()["samples"]["x"] == escaped.json()["samples"]["x"]
    b = assert_problem(client.post("/v1/schedule/gcode?method=nlp", content=short, headers=hdr), 422, "query.method")
    assert b["errors"][0]["value"] == "nlp"


def test_gcode_errors_name_line_and_column(client: TestClient) -> None:
    bad = "G21 G90\nG01 X10 F600\nG01 X20 Q5\n"
    b = assert_problem(client.post("/v1/schedule", json={"toolpath": {"gcode": bad}}), 422)
    assert "line 3" in b["errors"][0]["field"] and "col" in b["errors"][0]["field"]
    r = client.post("/v1/schedule/gcode", content=bad, headers={"content-type": "text/x-gcode"})
    assert_problem(r, 422)
    r = client.post("/v1/schedule/gcode", content=PROGRAM, headers={"content-type": "application/json"})
    assert_problem(r, 415)
    both = {"toolpath": {"gcode": PROGRAM, "segments": [{"degree": 1, "knots": [0, 0, 1, 1],
                                                          "control_points": [[0, 0], [1, 0]]}]}}
    assert_problem(client.post("/v1/schedule", json=both), 422)


def test_a_program_whose_f_words_alone_pass_the_budget_is_413_up_front(client: TestClient) -> None:
    """F1 (mm/min) over 1 m takes 60,000 s at the F word alone: over the fixture's 50 000 samples before any
    solve (``motion_time_floor``; the old estimate, the length over the axes' vmax, read 4,577 samples and let it
    through to the solver).  The same program at F6000 is under the budget."""
    slow = "G21 G90 G01 F1\nX1000\n"
    r = client.post("/v1/schedule/gcode?method=lp", content=slow, headers={"content-type": "text/x-gcode"})
    b = assert_problem(r, 413, "query.sample_period")  # (the upload's own name for the sample period)
    assert "at its feed and acceleration limits" in b["detail"] and b["jobs"] == "/v1/jobs"
    same = assert_problem(client.post("/v1/schedule", json={"toolpath": {"gcode": slow}, "options": {
        "method": "lp"}}), 413, "options.sample_period")  # (as JSON, the body's field)
    assert same["detail"] == b["detail"]
    r = client.post("/v1/schedule/gcode?method=lp", content=slow.replace("F1", "F6000"),
                    headers={"content-type": "text/x-gcode"})
    assert r.status_code == 200, r.text


#: The blended zig-zag's motion against stopping at its corners, at most (measured 1.9979 / 2.5263 s = 0.791 until
#: session 47; 1.9403 / 2.4106 s = 0.805 since the LP leaves and reaches rest faster, ``bspline.LP_REST_RISE_POWERS``)
BLEND_GAIN = 0.85
#: A pocketing-style zig-zag of G01 moves at one feed: 8 legs turning 53 degrees.
ZIGZAG = "G21 G90 G01 F6000\n" + "\n".join(f"X{10 * i} Y{5 * (i % 2)}" for i in range(1, 9)) + "\n"


def test_gcode_corner_blend_runs_through_corners(client: TestClient) -> None:
    stop = client.post("/v1/schedule", json={"toolpath": {"gcode": ZIGZAG}, "options": {"method": "lp"}}).json()
    blend = client.post("/v1/schedule/gcode?method=lp&corner_blend_mm=0.1", content=ZIGZAG,
                        headers={"content-type": "text/x-gcode"})
    assert blend.status_code == 200, blend.text
    b = blend.json()
    assert len(stop["diagnostics"]["corners"]) == 7 and b["diagnostics"]["corners"] == []
    assert b["summary"]["motion_time"] < BLEND_GAIN * stop["summary"]["motion_time"]
    # the blended path stays within the blend distance of the programmed corners' polyline
    x, y = np.array(b["samples"]["x"]), np.array(b["samples"]["y"])
    pts = np.array([[10.0 * i, 5.0 * (i % 2)] for i in range(9)])
    a, c = pts[:-1], pts[1:]
    d = c - a
    t = np.clip(((x[:, None] - a[:, 0]) * d[:, 0] + (y[:, None] - a[:, 1]) * d[:, 1]) / np.sum(d * d, axis=1), 0, 1)
    dist = np.hypot(x[:, None] - (a[:, 0] + t * d[:, 0]), y[:, None] - (a[:, 1] + t * d[:, 1])).min(axis=1)
    assert np.max(dist) <= 0.1 + 1e-9
    # programmed feed 6000 mm/min = 100 mm/s is held
    assert max(b["samples"]["feed"]) <= 100.0 * (1 + FEED_TOL)


#: The G-code pocket's first pass as JSON segments: a line, a G03 arc and a line back (two 33.6 degree
#: tangent breaks), the arc given by its radius, the lines' starts left to the chain.
JSON_CHAIN = [
    {"type": "line", "start": [0, 0], "end": [20, 0]},
    {"type": "arc", "end": [20, 10], "radius": 6, "plane": "G17", "direction": "ccw"},
    {"type": "polyline", "points": [[20, 10], [0, 10], [0, 20]]},
]


@pytest.mark.parametrize("blend", [1e-9, 5e-4, 0.000999])
def test_blend_under_the_path_fidelity_is_refused(client: TestClient, blend: float) -> None:
    """A blend tolerance between 0 and 1 um (``arcblend.MIN_BLEND_TOLERANCE_MM``) is a 422 naming the field,
    on both routes: such blends ran 129,079 s of lp+nlp motion (4,547 s lp) or stalled the LP."""
    r = client.post(f"/v1/schedule/gcode?method=lp&corner_blend_mm={blend!r}", content=ZIGZAG,
                    headers={"content-type": "text/x-gcode"})
    body = assert_problem(r, 422, "query.corner_blend_mm")  # (the upload's own parameter)
    assert any("0.001" in e["rule"] for e in body["errors"]), body
    r = client.post("/v1/schedule", json={"toolpath": {"gcode": ZIGZAG, "corner_blend_mm": blend},
                                          "options": {"method": "lp"}})
    assert_problem(r, 422, "toolpath.corner_blend_mm")
    ok = client.post("/v1/schedule/gcode?method=lp&corner_blend_mm=0.001", content=ZIGZAG,
                     headers={"content-type": "text/x-gcode"})
    assert ok.status_code == 200, ok.text


def test_json_lines_arcs_polylines_blended_through_corners(client: TestClient) -> None:
    # knots every 0.5 mm: at the default spacing (0.1 x stopping distance, 2.3 mm on the router) the
    # one-piece LP is too coarse for 0.05 mm blends on this short path (2.13 s blended vs 1.96 s stopping)
    body = {"toolpath": {"segments": JSON_CHAIN}, "options": {"method": "lp", "knot_spacing": 0.5}}
    stop = client.post("/v1/schedule", json=body)
    assert stop.status_code == 200, stop.text
    s = stop.json()
    assert len(s["diagnostics"]["corners"]) == 3 and s["diagnostics"]["unblended_corners"] == []
    body["toolpath"]["corner_blend_mm"] = 0.05
    blend = client.post("/v1/schedule", json=body)
    assert blend.status_code == 200, blend.text
    b = blend.json()
    assert b["diagnostics"]["corners"] == [] and b["diagnostics"]["unblended_corners"] == []
    # 1.349 s vs 1.424 s (before the LP's rest shapes, which make a stop cheaper, 1.431 s vs 1.835 s)
    assert b["summary"]["motion_time"] < 0.97 * s["summary"]["motion_time"]
    # every sample within 0.05 mm of the programmed lines and the R6 arc (centre (16.683, 5))
    x, y = np.array(b["samples"]["x"]), np.array(b["samples"]["y"])
    cx, cy = 20 - (36 - 25) ** 0.5, 5.0
    d_arc = np.abs(np.hypot(x - cx, y - cy) - 6.0)
    d_lines = np.minimum.reduce([np.hypot(x - np.clip(x, 0, 20), y), np.hypot(x - np.clip(x, 0, 20), y - 10),
                                 np.hypot(x, y - np.clip(y, 10, 20))])
    assert np.max(np.minimum(d_arc, d_lines)) <= 0.05 + 1e-9


def test_json_chain_errors_name_the_segment(client: TestClient) -> None:
    r = client.post("/v1/schedule", json={"toolpath": {"segments": [{"type": "line", "end": [1, 0]}]}})
    assert_problem(r, 422, "toolpath.segments[0].start")
    bad_arc = [{"type": "line", "start": [0, 0], "end": [10, 0]},
               {"type": "arc", "end": [20, 0], "centre": [14, 0]}]
    r = client.post("/v1/schedule", json={"toolpath": {"segments": bad_arc}})
    assert_problem(r, 422, "toolpath.segments[1].end")
    assert "inconsistent arc radii" in r.text
    r = client.post("/v1/schedule", json={"toolpath": {"segments": [{"type": "arc", "start": [0, 0], "end": [1, 1],
                                                                     "radius": 1, "plane": "G20"}]}})
    assert r.status_code == 422 and "toolpath.segments[0].plane" in r.text


#: A 20 mm square at F600 (10 mm/s), a corner at each vertex.
SQUARE_F600 = """G21 G90
G01 X20 F600
Y20
X0
Y0
M30
"""
#: lp+nlp on it at most this far over L / F, its rest ends included (1.0169 on the machine's knots, before session 54).
SQUARE_OVER_TRAVEL = 0.01


def test_f_words_set_lp_nlps_knots_through_the_service(client: TestClient) -> None:
    """The F words reach the knot plan: each leg's knots are 0.1 x the router's stopping distance at 10 mm/s (the
    largest S-curve ramp of an axis to 10 mm/s, ``test_optimality.ramp_from_rest``; ~14 um against the machine's
    2.3 mm), and the ramps at its corners cost under 1 % of L / F."""
    r = client.post("/v1/schedule", json={"toolpath": {"gcode": SQUARE_F600}, "options": {"method": "lp+nlp"}})
    assert r.status_code == 200, r.text
    summary = r.json()["summary"]
    v = 10.0
    D = max(ramp_from_rest(v, ax.limits.amax, ax.limits.jmax)[1] for ax in router().axes)
    assert summary["knot_spacing"] == pytest.approx(20.0 / np.ceil(20.0 / (0.1 * D)), rel=1e-9)
    assert summary["motion_time"] <= (1.0 + SQUARE_OVER_TRAVEL) * 80.0 / v


#: A square of 2 mm legs at F600: 144 intervals a leg on its F word's knots (0.1 x 0.14 mm), 16 on the machine's.
SMALL_SQUARE_F600 = SQUARE_F600.replace("X20", "X2").replace("Y20", "Y2")


def test_f_word_knots_over_the_budget_are_coarsened_to_fit_not_refused(tmp_path: Path) -> None:
    """A synchronous budget of 400 intervals: the F words' knots (576) are over it, the machine's (64) are not. The
    service coarsens them to 100 a leg (``pipeline.fit_intervals``), reports the feed that sized them in
    ``summary.knot_feed_floor``, and serves the program at its F word; before, it answered 413.  An explicit knot
    spacing is the client's and is still refused."""
    app = create_app(Settings(data_dir=tmp_path, workers=1, sync_max_intervals=400))
    body: dict[str, Any] = {"toolpath": {"gcode": SMALL_SQUARE_F600}, "options": {"method": "lp+nlp"}}
    with TestClient(app, raise_server_exceptions=False) as c:
        r = c.post("/v1/schedule", json=body)
        assert r.status_code == 200, r.text
        summary = r.json()["summary"]
        floor = summary["knot_feed_floor"]
        D = max(ramp_from_rest(min(ax.limits.vmax, floor), ax.limits.amax, ax.limits.jmax)[1] for ax in router().axes)
        assert 10.0 < floor and summary["knot_spacing"] == pytest.approx(2.0 / 100, rel=1e-12)
        assert np.ceil(2.0 / (0.1 * D) - 1e-9) == 100
        assert max(r.json()["samples"]["feed"]) <= 1.01 * 10.0
        body["options"]["knot_spacing"] = 0.004  # 500 a leg
        assert_problem(c.post("/v1/schedule", json=body), 413, "options.knot_spacing")


def test_upload_errors_name_what_the_upload_sent(client: TestClient) -> None:
    """The G-code upload has no ``options`` or ``toolpath`` body fields: its problems name the program (``body``)
    for what its moves decide (the control-point budget, a line's error) and ``query.*`` for its parameters."""
    hdr = {"content-type": "text/x-gcode"}
    bad = "G21 G90\nG01 X10 F600\nG01 X20 Q5\n"
    e = assert_problem(client.post("/v1/schedule/gcode", content=bad, headers=hdr), 422)["errors"][0]
    assert e["field"].startswith("gcode:line 3") and e["pointer"] == "#"
    e = assert_problem(client.post("/v1/schedule", json={"toolpath": {"gcode": bad}}), 422)["errors"][0]
    assert e["field"].startswith("gcode:line 3") and e["pointer"] == "#/toolpath/gcode"
    many = "G21 G90 G01 F6000\n" + "".join(f"X{i % 2} Y{i}\n" for i in range(600))
    b = assert_problem(client.post("/v1/schedule/gcode?method=lp", content=many, headers=hdr), 413, "body")
    assert b["errors"][0]["pointer"] == "#" and "control points" in b["detail"]


@pytest.mark.parametrize("sep", ["\u2028", "\x85", "\x1e"])
def test_only_lf_and_cr_end_a_program_line(client: TestClient, sep: str) -> None:
    """``str.splitlines`` also splits at NEL, U+2028, record separators...: a program line holding one was read as
    two moves; it is an unexpected character on its line, as in a controller."""
    prog = f"G21 G90 G01 F600 X10{sep}Y5\n"
    e = assert_problem(client.post("/v1/schedule/gcode?method=lp", content=prog.encode(),
                                   headers={"content-type": "text/x-gcode"}), 422)["errors"][0]
    assert e["field"].startswith("gcode:line 1:") and e["value"] == sep


def test_upload_query_errors_and_stream_errors_name_the_query(client: TestClient) -> None:
    """The upload's query parameters checked with the request (an unknown preset, a blend under 1 um) named the
    body fields ``machine`` and ``toolpath.corner_blend_mm``; an error line after streamed rows named
    ``options.max_samples`` (session 59's probe).  Each names the query parameter now."""
    hdr = {"content-type": "text/x-gcode"}
    prog = "G21 G90\nG1 X1 F6000\nG1 Y1\n"
    assert_problem(client.post("/v1/schedule/gcode?machine=x", content=prog, headers=hdr), 422, "query.machine")
    assert_problem(client.post("/v1/schedule/gcode?method=lp&corner_blend_mm=0.0001", content=prog, headers=hdr),
                   422, "query.corner_blend_mm")
    long = "G21 G90\nG1 X1 F6000\nG2 X1 Y0 I0.01 J0 P60\n"  # (a first piece, then one over the sample budget)
    r = client.post("/v1/schedule/gcode?method=lp&sample_period=0.00001", content=long,
                    headers={**hdr, "accept": "application/x-ndjson"})
    lines = r.text.strip().split("\n")
    assert r.status_code == 200, r.text[:300]  # (the first piece's rows, then the error in-band)
    last = json.loads(lines[-1])
    assert len(lines) > 1 and last["event"] == "error" and last["status"] == 413
    assert last["errors"][0]["field"] == "query.sample_period" and last["detail"].startswith("query.")


@pytest.mark.parametrize("f", ["F0." + "0" * 310 + "1", "F0.00000000001"])
def test_a_feed_word_under_the_smallest_feed_is_its_line_s_error(client: TestClient, f: str) -> None:
    """F0.000...1 (310 zeros) made the knots' stopping distance 0: a 500 (session 59's probe).  F words under
    1e-12 mm/s (6e-11 mm/min) are the line's error."""
    r = client.post("/v1/schedule/gcode?method=lp", content=f"G21 G90\nG1 X1 {f}\n",
                    headers={"content-type": "text/x-gcode"})
    e = assert_problem(r, 422)["errors"][0]
    assert e["field"].startswith("gcode:line 2:") and "at least" in e["rule"]
