"""Peak memory of a long single-piece path, streamed vs held (issue 3: "memory stays bounded by the window
size, not the path length: show the peak for 18.5 m and 185 m paths").

The flower chained N times has no corner: it is one piece.  Each run is a fresh subprocess that builds the
path, resets the kernel's peak-RSS mark (VmHWM) and then either

- ``schedule``: the whole result in memory (what ``POST /v1/jobs`` and the Python API return; its samples
  alone are 21 float64 columns, ~170 B a sample, so they grow with the path), or
- ``stream``: ``schedule_stream`` with its default ``block_samples`` (what NDJSON streaming uses), each block
  consumed (a running checksum of its positions) and dropped, as a writer to a socket or file would.

Reported: the peak over the RSS before scheduling, the compute time and the motion time, and for the stream
the samples, blocks and the largest block.
``python -m bench.stream_memory [--loops 45 450] [--method lp+nlp] [--modes stream schedule]`` updates
``bench/results/stream_memory.json`` (the latest run of each method, mode and path kept).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

from bench._common import emit, env_info, proc_status_mb, reset_hwm, run_module

ROOT = Path(__file__).resolve().parents[1]
#: The issue's resolution: 3965 control points on the 18.35 m path.
KNOT = 4.63
LOOPS = (45, 450)


def child(mode: str, loops: int, method: str) -> None:
    from geometry import examples as ex
    from solvers.machine import router
    from solvers.pipeline import Options, SampleBlock, schedule, schedule_stream

    tp = ex.flower(loops)
    # one process (no forked NLP workers, whose memory this process's VmHWM would not count)
    opt = Options(method=method, knot_spacing=KNOT, nlp_workers=1)
    rss_before = proc_status_mb("VmRSS")
    if not reset_hwm():
        raise SystemExit("cannot reset VmHWM (/proc/self/clear_refs)")
    t0 = time.perf_counter()
    res: dict[str, Any] = {"mode": mode, "loops": loops, "method": method, "path_length_mm": tp.length,
                           "pieces": len(tp.pieces), "rss_mb_before": rss_before}
    if mode == "schedule":
        sch = schedule(tp, router(), opt)
        res.update(samples=int(sch.samples.t.size), motion_time=sch.summary["motion_time"],
                   compute_time=sch.summary["compute_time"])
    else:
        h = hashlib.sha256()
        n = blocks = biggest = 0
        for item in schedule_stream(tp, router(), opt):
            if isinstance(item, SampleBlock):
                h.update(item.samples.position.tobytes())
                n += item.n
                blocks += 1
                biggest = max(biggest, item.n)
            else:
                res.update(motion_time=item.summary["motion_time"], compute_time=item.summary["compute_time"])
        res.update(samples=n, blocks=blocks, largest_block=biggest, position_sha256=h.hexdigest())
    res["wall"] = time.perf_counter() - t0
    res["peak_over_before_mb"] = proc_status_mb("VmHWM") - rss_before
    print(json.dumps(res), flush=True)


def run_child(mode: str, loops: int, method: str) -> dict[str, Any]:
    out = run_module("bench.stream_memory", ["--child", mode, "--loops", str(loops), "--method", method], 3600)
    return {"mode": mode, "loops": loops, **out} if "error" in out else out


def main(loops: tuple[int, ...] = LOOPS, method: str = "lp+nlp",
         modes: tuple[str, ...] = ("stream", "schedule")) -> dict[str, Any]:
    runs = [run_child(mode, n, method) for n in loops for mode in modes]
    for r in runs:
        if "error" not in r:
            print(f"{r['mode']:8s} x{r['loops']:<4d} {r['path_length_mm'] / 1e3:7.2f} m"
                  f"  peak +{r['peak_over_before_mb']:7.1f} MB  compute {r['compute_time']:7.2f} s"
                  f"  motion {r['motion_time']:8.2f} s  samples {r['samples']}",
                  file=sys.stderr)
    # the results file keeps every (method, mode, loops) measured, the latest of each
    path = ROOT / "bench" / "results" / "stream_memory.json"
    old = json.loads(path.read_text()).get("runs", []) if path.exists() else []
    new = {(r.get("method", method), r["mode"], r["loops"]) for r in runs}
    kept = [r for r in old if (r.get("method"), r.get("mode"), r.get("loops")) not in new]
    out: dict[str, Any] = {"bench": "stream_memory", "knot_spacing": KNOT, "env": env_info(), "runs": kept + runs}
    emit({**out, "runs": runs})
    path.write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", default=None)
    ap.add_argument("--loops", type=int, nargs="+", default=list(LOOPS))
    ap.add_argument("--method", default="lp+nlp")
    ap.add_argument("--modes", nargs="+", default=["stream", "schedule"], choices=["stream", "schedule"])
    a = ap.parse_args()
    if a.child:
        child(a.child, a.loops[0], a.method)
    else:
        main(tuple(a.loops), a.method, tuple(a.modes))
