"""NDJSON streaming of POST /v1/schedule against a real uvicorn server whose solver processes are instrumented
(``tests.service.gate_hook``): the last piece of the path can be held until the test releases it, and a piece
can be made to fail.  No timing is asserted: ordering is proven by the hold (the last piece cannot finish
before the client has the first row)."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.service.conftest import WAIT_S, Server, pid_gone, wait_for
from tests.service.test_inprocess import COLUMNS, bits
from tests.solvers.test_stream import MIXED, TIMINGS, ZIGZAG

NDJSON = {"Accept": "application/x-ndjson"}
PIECES = 8  # of ZIGZAG


def body(gcode: str, method: str = "lp") -> dict[str, Any]:
    return {"toolpath": {"gcode": gcode}, "machine": "router", "options": {"method": method}}


@pytest.fixture(scope="module")
def gate(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("gate")


@pytest.fixture(scope="module")
def gated(tmp_path_factory: pytest.TempPathFactory, gate: Path) -> Iterator[Server]:
    s = Server(tmp_path_factory.mktemp("srv"), app="tests.service.gated_app:app", FEEDSCHED_WORKERS="2",
               FEEDSCHED_TEST_GATE_DIR=str(gate)).start()
    yield s
    s.stop()


@pytest.fixture(autouse=True)
def clear_gate(gate: Path) -> Iterator[None]:
    for f in gate.iterdir():
        f.unlink()
    yield
    (gate / "go").touch()  # never leave a solver process waiting


def waiting_pid(gate: Path) -> int:
    f: Path = wait_for(lambda: next(gate.glob("waiting-*"), None), "the solver to reach the held last piece")
    return int(f.name.split("-")[1])


def test_first_row_arrives_before_the_last_piece_is_solved(gated: Server, gate: Path) -> None:
    """The last of 8 pieces is held until ``go``; the client creates ``go`` only once it has a row.  Had the rows
    waited for the whole solve, neither side would have moved and the read would have timed out (WAIT_S)."""
    (gate / "hold").touch()
    rows: list[dict[str, Any]] = []
    end = None
    with httpx.stream("POST", gated.url + "/v1/schedule", json=body(ZIGZAG), headers=NDJSON, timeout=WAIT_S) as r:
        assert r.status_code == 200 and r.headers["content-type"].startswith("application/x-ndjson")
        for line in r.iter_lines():
            obj = json.loads(line)
            if not rows:
                assert not (gate / "go").exists()
                (gate / "go").touch()  # release the last piece
            if "event" in obj:
                end = obj
                break
            rows.append(obj)
    assert end is not None and end["event"] == "summary", end
    assert end["summary"]["samples"] == len(rows)
    assert waiting_pid(gate) > 0  # the last piece was held, and released after the first row had arrived
    assert rows[-1]["s"] == end["summary"]["path_length"]


@pytest.mark.parametrize("method", ["lp", "lp+nlp"])
def test_ndjson_equals_json_and_csv_bit_for_bit(gated: Server, method: str) -> None:
    """Six pieces: the streamed rows are the JSON columns and the CSV rows, bit for bit; the summary line is the
    JSON summary (but the wall-clock timings) and diagnostics."""
    url = gated.url + "/v1/schedule"
    js = httpx.post(url, json=body(MIXED, method), timeout=WAIT_S).json()
    cols = js["samples"]
    assert list(cols) == COLUMNS
    text = httpx.post(url, json=body(MIXED, method), headers={"Accept": "text/csv"}, timeout=WAIT_S).text
    table = list(csv.reader(io.StringIO(text)))
    lines = [json.loads(x) for x in httpx.post(url, json=body(MIXED, method), headers=NDJSON,
                                               timeout=WAIT_S).text.splitlines()]
    *rows, end = lines
    assert len(rows) == len(cols["t"]) == len(table) - 1
    for j, name in enumerate(COLUMNS):
        want = [bits(v) for v in cols[name]]
        assert [bits(row[name]) for row in rows] == want, name
        assert [bits(float(row[j])) for row in table[1:]] == want, name
    assert end["event"] == "summary" and set(end) == {"event", "summary", "diagnostics"}
    assert {k: v for k, v in end["summary"].items() if k not in TIMINGS} == \
        {k: v for k, v in js["summary"].items() if k not in TIMINGS}
    assert end["diagnostics"] == js["diagnostics"]


def test_failure_after_rows_is_an_error_line_without_summary(gated: Server, gate: Path) -> None:
    """Piece 7 of 8 fails (an injected LimitViolationError): the rows of the pieces before it, then one error line
    with the problem+json fields, and no summary line.  A failure in the first piece is still a plain 422."""
    (gate / f"fail-{PIECES - 1}").touch()
    r = httpx.post(gated.url + "/v1/schedule", json=body(ZIGZAG), headers=NDJSON, timeout=WAIT_S)
    assert r.status_code == 200
    *rows, last = [json.loads(x) for x in r.text.splitlines()]
    assert rows and all("event" not in row for row in rows)
    assert last["event"] == "error" and last["status"] == 422 and last["instance"] == "/v1/schedule"
    assert last["type"] == "urn:feedsched:problem:cannot-schedule" and "injected" in last["detail"]
    assert last["errors"][0]["field"] == "toolpath" and last["axis"] == "x"
    full = httpx.post(gated.url + "/v1/schedule", json=body(ZIGZAG), timeout=WAIT_S)
    assert full.status_code == 422  # the JSON answer fails as a whole
    (gate / f"fail-{PIECES - 1}").unlink()
    (gate / "fail-0").touch()
    r = httpx.post(gated.url + "/v1/schedule", json=body(ZIGZAG), headers=NDJSON, timeout=WAIT_S)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    assert r.json()["type"] == "urn:feedsched:problem:cannot-schedule"


def test_client_going_away_stops_the_solver(gated: Server, gate: Path) -> None:
    """The client reads rows while the solver holds the last piece, then closes the connection: the solver
    process is killed and the admission slot freed.  (A raw socket read by a thread: the client keeps reading,
    so the solver is never held back by a full buffer, and the main thread can close it.)"""
    (gate / "hold").touch()
    payload = json.dumps(body(ZIGZAG)).encode()
    sock = socket.create_connection(("127.0.0.1", gated.port))
    sock.sendall(b"POST /v1/schedule HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                 b"Accept: application/x-ndjson\r\nContent-Length: %d\r\n\r\n%s" % (len(payload), payload))
    got = bytearray()

    def read() -> None:
        with contextlib.suppress(OSError):
            while data := sock.recv(1 << 16):
                got.extend(data)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    pid = waiting_pid(gate)
    wait_for(lambda: b'{"t":' in got, "the first row")
    assert got.startswith(b"HTTP/1.1 200")
    assert httpx.get(gated.url + "/healthz").json()["schedules_in_flight"] == 1
    sock.shutdown(socket.SHUT_RDWR)  # the client goes away; "go" never comes
    sock.close()
    reader.join(WAIT_S)
    wait_for(lambda: pid_gone(pid), "the solver process of the abandoned stream to be killed")
    wait_for(lambda: httpx.get(gated.url + "/healthz").json()["schedules_in_flight"] == 0, "the slot to be freed")
    assert b'"event"' not in got
