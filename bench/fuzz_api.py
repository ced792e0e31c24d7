"""schemathesis against a real uvicorn server: generated requests for every operation of the served spec.

    python -m bench.fuzz_api [--examples 80] [--time-limit 1500] [--url http://127.0.0.1:8000]

Without --url a uvicorn server is started on a free loopback port (FEEDSCHED_WORKERS=2, sync and job timeouts
10 s, a job queue deep enough that sequential requests never fill it) and stopped at the end.  For each
operation and each generation mode (positive: schema-valid inputs; negative: schema-invalid ones) hypothesis
draws up to --examples cases; each is sent once and checked with schemathesis' response checks (no 5xx,
status code, content type, headers and body as documented).  A failed check is recorded and the run goes
on (no shrinking).  Reports request counts by status and by operation, and every failure; writes
bench/results/fuzz_api.json.  Only loopback addresses; bounded by --examples and --time-limit.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]


class Tally:
    def __init__(self, time_limit: float) -> None:
        self.by_status: Counter[int] = Counter()
        self.by_op: dict[str, Counter[int]] = {}
        self.failures: list[dict[str, Any]] = []
        self.transport_errors: list[str] = []
        self.stop = time.monotonic() + time_limit


def known_values(url: str) -> dict[str, list[str]]:
    """Path parameter values that exist on the server: jobs that succeeded, failed and were cancelled, preset
    and example names.  Positive cases use one of them half of the time, so the routes answer 200/409 too."""
    from service.schemas import EXAMPLE

    with httpx.Client(base_url=url, timeout=60) as c:
        ok = c.post("/v1/jobs", json=EXAMPLE).json()["id"]
        lp = c.post("/v1/jobs", json={**EXAMPLE, "options": {"method": "lp"}}).json()["id"]
        bad = c.post("/v1/jobs", json={"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1],
                                                                  "control_points": [[0, 0], [0, 0]]}]}}).json()["id"]
        long = {"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1],
                                           "control_points": [[0, 0, 0], [40_000, 0, 0]]}]}, "machine": "router"}
        cancelled = c.post("/v1/jobs", json=long).json()["id"]
        c.delete(f"/v1/jobs/{cancelled}")
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if all(c.get(f"/v1/jobs/{i}").json()["status"] not in ("queued", "running") for i in (ok, lp, bad)):
                break
            time.sleep(0.2)
        return {"job_id": [ok, lp, bad, cancelled], "name": c.get("/v1/machines").json()["machines"]
                + [e["name"] for e in c.get("/v1/examples").json()["examples"]]}


def run_operation(op: Any, mode: Any, examples: int, t: Tally, known: dict[str, list[str]]) -> None:
    """Up to ``examples`` generated cases of one operation in one mode, each sent and checked once."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from hypothesis.errors import Unsatisfiable
    from schemathesis.generation.modes import GenerationMode
    from schemathesis.specs.openapi.checks import positive_data_acceptance

    label = f"{op.method.upper()} {op.path}"
    counts = t.by_op.setdefault(label, Counter())
    # path parameters that can take known values (positive mode only: negative cases must stay invalid)
    params = [p for p in known if "{" + p + "}" in op.path] if mode == GenerationMode.POSITIVE else []
    pick = st.integers(0, 2 * max((len(known[p]) for p in params), default=0))

    @given(case=op.as_strategy(mode), k=pick)
    @settings(max_examples=examples, deadline=None, suppress_health_check=list(HealthCheck), database=None,
              derandomize=True)
    def one(case: Any, k: int) -> None:
        if time.monotonic() > t.stop:
            return
        for p in params:
            if k < len(known[p]) and not (p == "name" and "plots" in op.path):
                case.path_parameters[p] = known[p][k]
        try:
            resp = case.call(timeout=60)
        except Exception as exc:  # connection refused / reset: the server must never do that
            t.transport_errors.append(f"{label} ({mode.value}): {type(exc).__name__}: {exc}"[:300])
            return
        t.by_status[resp.status_code] += 1
        counts[resp.status_code] += 1
        try:
            # a schema-valid toolpath can still be geometrically invalid (knots, zero length): 422 is right for it
            case.validate_response(resp, excluded_checks=[positive_data_acceptance])
        except Exception as exc:
            t.failures.append({"operation": label, "mode": mode.value, "status": resp.status_code,
                               "request": {"path": case.formatted_path, "query": case.query,
                                           "body": repr(case.body)[:300]},
                               "response": resp.text[:300], "failure": str(exc)[:1500]})

    try:
        one()
    except Unsatisfiable:  # no way to break the input of a GET without parameters
        pass


def fuzz(url: str, examples: int, time_limit: float) -> dict[str, Any]:
    import schemathesis
    from schemathesis.generation.modes import GenerationMode

    schema = schemathesis.openapi.from_url(url + "/openapi.json")
    ops = [r.ok() for r in schema.get_all_operations()]
    t = Tally(time_limit)
    t0 = time.monotonic()
    known = known_values(url)
    for mode, op in itertools.product((GenerationMode.POSITIVE, GenerationMode.NEGATIVE), ops):
        if time.monotonic() > t.stop:
            break
        run_operation(op, mode, examples, t, known)
    wall = time.monotonic() - t0
    return {
        "operations": len(ops), "examples_per_operation_and_mode": examples,
        "requests": sum(t.by_status.values()), "wall_s": wall, "time_limit_hit": time.monotonic() > t.stop,
        "by_status": {str(k): v for k, v in sorted(t.by_status.items())},
        "server_errors_5xx": sum(v for k, v in t.by_status.items() if k >= 500),
        "failures": len(t.failures), "transport_errors": len(t.transport_errors),
        "by_operation": {k: {str(s): n for s, n in sorted(v.items())} for k, v in t.by_op.items()},
        "failure_samples": t.failures[:30], "transport_error_samples": t.transport_errors[:10],
    }


def main() -> None:
    from bench.load import start_server

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=80, help="cases per operation and generation mode")
    ap.add_argument("--time-limit", type=float, default=1500.0, help="stop generating after this many seconds")
    ap.add_argument("--url", default=None, help="an already running server (loopback); default: start one")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "fuzz_api.json"))
    a = ap.parse_args()
    tmp = tempfile.TemporaryDirectory(prefix="feedsched-fuzz-")
    proc = None
    url = a.url
    if url is None:
        for k, v in {"FEEDSCHED_WORKERS": "2", "FEEDSCHED_SYNC_TIMEOUT": "10", "FEEDSCHED_JOB_TIMEOUT": "10",
                     "FEEDSCHED_JOB_QUEUE_DEPTH": "100000"}.items():
            os.environ.setdefault(k, v)
        proc, url = start_server(tmp.name)
    if httpx.URL(url).host not in ("127.0.0.1", "localhost", "::1"):
        raise SystemExit("fuzz only against loopback")
    try:
        res = fuzz(url, a.examples, a.time_limit)
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=30)
        tmp.cleanup()
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k not in ("failure_samples", "by_operation")}, indent=2))
    for f in res["failure_samples"][:10]:
        print(f"\nFAIL {f['operation']} ({f['mode']}) -> {f['status']}\n{f['failure'][:800]}")
    if res["server_errors_5xx"] or res["failures"] or res["transport_errors"]:
        sys.exit(1)


if __name__ == "__main__":
    main()
