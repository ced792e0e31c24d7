"""Time to the first NDJSON row against the whole schedule, on paths with and without corners.

    python -m bench.stream_latency [--repeats 3] [--out bench/results/stream.json]

Starts a server on a loopback port (default settings) and POSTs each case to /v1/schedule with
``Accept: application/x-ndjson``: the time from sending the request to the first row line, and to the
summary line (the whole answer); the same request as JSON (whole answer) for comparison.  In process,
``schedule_stream``: the time to the first block and to the end item.  Medians over the repeats.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench.load import start_server
from geometry import examples, gcode
from solvers.machine import router
from solvers.pipeline import Options, SampleBlock, schedule_stream

ROOT = Path(__file__).resolve().parents[1]


def zigzag(moves: int = 8, step: float = 10.0) -> str:
    """``moves`` G01 moves of a zigzag, a corner between each two (``moves`` pieces)."""
    return "G21 G90\nG01 X0 Y0 F6000\n" + "".join(f"G01 X{step * (i + 1):g} Y{(i % 2) * step:g}\n"
                                                  for i in range(moves))


def pocket(turns: int = 10, size: float = 100.0, step: float = 2.5) -> str:
    """A rectangular spiral pocket from the outside in: 4 ``turns`` corners (90 degrees), ~3.6 m for 10 turns."""
    lines = ["G21 G90", "G00 X0 Y0", "F6000"]
    x0, y0, x1, y1 = 0.0, 0.0, size, size
    for _ in range(turns):
        lines += [f"G01 X{x1:g} Y{y0:g}", f"G01 X{x1:g} Y{y1:g}", f"G01 X{x0:g} Y{y1:g}", f"G01 X{x0:g} Y{y0 + step:g}"]
        x0, y0, x1, y1 = x0 + step, y0 + step, x1 - step, y1 - step
    return "\n".join(lines) + "\n"


CASES: dict[str, dict[str, Any]] = {
    "zigzag, 8 pieces (80 mm)": {"gcode": zigzag()},
    "pocket, 40 pieces (3.6 m)": {"gcode": pocket()},
}


def flower_body() -> dict[str, Any]:
    """The bundled flower (one piece: no corner) as a request body."""
    from service.reports import example

    return dict(example("flower")["toolpath"])


def http_case(url: str, toolpath: dict[str, Any], method: str, repeats: int) -> dict[str, Any]:
    body = {"toolpath": toolpath, "machine": "router", "options": {"method": method}}
    first: list[float] = []
    total: list[float] = []
    whole: list[float] = []
    rows = 0
    summary: dict[str, Any] = {}
    for _ in range(repeats):
        t0 = time.perf_counter()
        t_first = None
        n = 0
        with httpx.stream("POST", url + "/v1/schedule", json=body, headers={"Accept": "application/x-ndjson"},
                          timeout=600) as r:
            r.raise_for_status()
            for line in r.iter_lines():  # (rows are not parsed: the JSON answer's body is not either)
                if t_first is None:
                    t_first = time.perf_counter() - t0
                    assert "t" in json.loads(line)
                if line.startswith('{"event"'):
                    obj = json.loads(line)
                    assert obj["event"] == "summary", obj
                    summary = obj["summary"]
                    break
                n += 1
        total.append(time.perf_counter() - t0)
        assert t_first is not None
        first.append(t_first)
        rows = n
        t0 = time.perf_counter()
        httpx.post(url + "/v1/schedule", json=body, timeout=600).raise_for_status()
        whole.append(time.perf_counter() - t0)
    return {"method": method, "rows": rows, "motion_time_s": summary.get("motion_time"),
            "first_row_s": statistics.median(first), "ndjson_total_s": statistics.median(total),
            "json_total_s": statistics.median(whole),
            "first_row_share": statistics.median(first) / statistics.median(total),
            "runs_first_s": first, "runs_total_s": total}


def inprocess_case(toolpath: Any, method: str, repeats: int) -> dict[str, Any]:
    first: list[float] = []
    total: list[float] = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        t_first = None
        for item in schedule_stream(toolpath, router(), Options(method=method)):
            if t_first is None and isinstance(item, SampleBlock):
                t_first = time.perf_counter() - t0
        total.append(time.perf_counter() - t0)
        assert t_first is not None
        first.append(t_first)
    t_first, t_total = statistics.median(first), statistics.median(total)
    return {"method": method, "pieces": len(toolpath.pieces), "first_block_s": t_first, "total_s": t_total,
            "first_block_share": t_first / t_total}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "stream.json"))
    a = ap.parse_args()
    cases = {**CASES, "flower, 1 piece (no corner)": flower_body()}
    out: dict[str, Any] = {"http": {}, "inprocess": {}}
    with tempfile.TemporaryDirectory() as data:
        proc, url = start_server(data)
        try:
            for name, tp in cases.items():
                for method in ("lp", "lp+nlp"):
                    r = http_case(url, tp, method, a.repeats)
                    out["http"][f"{name} / {method}"] = r
                    print(f"HTTP  {name:30s} {method:7s} rows {r['rows']:6d}  first row {r['first_row_s']:.3f} s  "
                          f"NDJSON total {r['ndjson_total_s']:.3f} s  JSON {r['json_total_s']:.3f} s  "
                          f"({100 * r['first_row_share']:.0f} %)", flush=True)
        finally:
            proc.terminate()
            proc.wait(30)
    paths = {name: gcode.parse(v["gcode"]).toolpath(0.5) for name, v in CASES.items()}
    paths["flower, 1 piece (no corner)"] = examples.flower(1)
    for name, tp in paths.items():
        for method in ("lp", "lp+nlp"):
            r = inprocess_case(tp, method, a.repeats)
            out["inprocess"][f"{name} / {method}"] = r
            print(f"proc  {name:30s} {method:7s} pieces {r['pieces']:3d}  first block {r['first_block_s']:.3f} s  "
                  f"total {r['total_s']:.3f} s  ({100 * r['first_block_share']:.0f} %)", flush=True)
    with open("/proc/loadavg") as f:
        out["loadavg_after"] = f.read().split()[:3]
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
