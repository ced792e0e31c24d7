"""Dense CAM output (issue 7 item 4): a finely tessellated spiral of N G01 moves (about 0.5 mm each).

Each size runs in its own process (``--single``): it generates the program, parses it,
blends the corners of the G01 run with clothoids (``corner_blend_mm``), schedules it
(method ``lp`` by default) and checks the 1 kHz positions against every limit by
independent finite differences (``tests/fdcheck.py``: v, a, j from the sampled
positions only). Reported per size: parse / toolpath / schedule seconds, time per
metre, peak memory of the process (VmHWM) and of each stage (VmHWM reset before it,
where the kernel allows), FD utilisation of v, a and j (worst axis), and, across
sizes, linearity (time per metre and MB per metre against the smallest size). A
stop-at-every-vertex run of the smallest size shows what blending buys.

    python -m bench.dense_gcode                          # 2,000 and 20,000 moves (what bench/run_all runs)
    python -m bench.dense_gcode --moves 150000 --no-stop # the issue's size; merged into the results file

Results are merged by size into ``bench/results/dense_gcode.json`` (a later run of
one size replaces that size only), so the 150,000-move run can be made on its own.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench._common import LIMIT_FACTOR, emit, env_info, proc_status_mb, reset_hwm, row, verdict

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results" / "dense_gcode.json"
DEFAULT_SIZES = (2000, 20_000)
STEP_MM = 0.5


def spiral_program(moves: int, step_mm: float = STEP_MM) -> str:
    """An Archimedean-like spiral (r 10 -> 60 mm) of ``moves`` G01 moves about ``step_mm`` long, F6000."""
    u = np.linspace(0.0, 1.0, moves + 1)
    turns = step_mm * moves / (2 * np.pi * 35.0)
    theta = u * turns * 2 * np.pi
    r = 10.0 + 50.0 * u
    x, y = r * np.cos(theta), r * np.sin(theta)
    body = [f"X{a:.4f} Y{b:.4f}" for a, b in zip(x[1:], y[1:], strict=True)]
    return "\n".join(["G21 G90", f"G00 X{x[0]:.4f} Y{y[0]:.4f}", "G01 F6000", *body])


def _hwm() -> float:
    hwm = proc_status_mb("VmHWM")
    return hwm if np.isfinite(hwm) else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run(moves: int, blend_mm: float, method: str) -> dict[str, Any]:
    """One size in this process: stage times, memory, FD utilisation."""
    from geometry import gcode
    from solvers.machine import router
    from solvers.pipeline import Options, schedule
    from tests.fdcheck import utilisation

    text = spiral_program(moves)
    base_mb = proc_status_mb("VmRSS")
    can_reset = reset_hwm()
    stage_mb: dict[str, float] = {}
    t0, c0 = time.perf_counter(), time.process_time()
    prog = gcode.parse(text)
    t1, c1 = time.perf_counter(), time.process_time()
    stage_mb["parse"] = _hwm()
    if can_reset:
        reset_hwm()
    tp = prog.toolpath(0.5, blend_mm=blend_mm)
    t2, c2 = time.perf_counter(), time.process_time()
    stage_mb["toolpath"] = _hwm()
    n_lines = len(prog.segments)
    del prog, text
    if can_reset:
        reset_hwm()
    m = router()
    sch = schedule(tp, m, Options(method=method))
    t3, c3 = time.perf_counter(), time.process_time()
    stage_mb["schedule"] = _hwm()
    vmax, amax, jmax = m.limit_arrays()
    util = utilisation(sch.samples.position, sch.summary["sample_period"], vmax, amax, jmax)
    fd = {q: max(util[f"{q}{ax}"] for ax in "xyz") for q in "vaj"}
    metres = tp.length / 1000.0
    kinds = np.bincount(tp.sub_kind, minlength=3)
    total = t3 - t0
    return {
        "moves": moves, "blend_mm": blend_mm, "method": method, "g01_segments": n_lines,
        "length_m": metres, "segments": len(tp.segments), "sub_segments": len(tp.subs),
        "sub_kinds": {"generic": int(kinds[0]), "line": int(kinds[1]), "clothoid": int(kinds[2])},
        "pieces": len(tp.pieces), "corners": len(tp.corners),
        "parse_s": t1 - t0, "toolpath_s": t2 - t1, "schedule_s": t3 - t2, "total_s": total,
        "per_metre_s": total / metres, "schedule_per_metre_s": (t3 - t2) / metres,
        # CPU seconds of this process (all its threads): less sensitive than wall time to other work on the cores
        "cpu_s": {"parse": c1 - c0, "toolpath": c2 - c1, "schedule": c3 - c2}, "cpu_per_metre_s": (c3 - c0) / metres,
        "motion_s": sch.summary["motion_time"], "samples": sch.summary["samples"],
        "lp_windows": sch.summary["windows"], "lp_cut_rounds": sch.summary["cut_rounds"],
        "lp_cut_points": sch.summary["cut_points"], "lp_unverified_points": sch.summary["unverified_points"],
        "lp_time_s": sch.summary["lp_time"], "sample_repairs": sch.summary.get("sample_repairs"),
        "fd_utilisation": fd, "fd_utilisation_axes": util, "worst_fd_utilisation": max(fd.values()),
        "rss_before_mb": base_mb, "stage_peak_mb": stage_mb, "hwm_reset": can_reset,
        "peak_rss_mb": max(stage_mb.values()) if can_reset else _hwm(),
        "peak_above_start_mb": (max(stage_mb.values()) if can_reset else _hwm()) - base_mb,
        "load_average": os.getloadavg(),
    }


def run_sub(moves: int, blend_mm: float, method: str, timeout_s: float | None) -> dict[str, Any]:
    """``run`` in a fresh process (its own peak memory)."""
    cmd = [sys.executable, "-m", "bench.dense_gcode", "--single", str(moves), "--blend-mm", str(blend_mm),
           "--method", method]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout_s, check=False)
    lines = [ln for ln in p.stdout.strip().splitlines() if ln.strip()]
    if p.returncode != 0 or not lines:
        return {"moves": moves, "blend_mm": blend_mm, "error": f"exit {p.returncode}: {p.stderr.strip()[-800:]}"}
    out: dict[str, Any] = json.loads(lines[-1])
    out["process_wall_s"] = time.perf_counter() - t0
    return out


def _key(r: dict[str, Any]) -> str:
    return f"{r['moves']}@{r['blend_mm']}@{r.get('method', 'lp')}"


def merge(new: list[dict[str, Any]], path: Path = RESULTS) -> dict[str, Any]:
    old: dict[str, Any] = {}
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except json.JSONDecodeError:
            old = {}
    runs = {_key(r): r for r in old.get("runs", [])}
    for r in new:
        runs[_key(r)] = r
    ordered = sorted(runs.values(), key=lambda r: (r["blend_mm"] == 0.0, r["moves"]))
    blended = [r for r in ordered if r["blend_mm"] > 0.0 and "error" not in r]
    lin: list[dict[str, Any]] = []
    if blended:
        ref = blended[0]
        for r in blended:
            lin.append({
                "moves": r["moves"], "length_m": r["length_m"],
                "per_metre_s": r["per_metre_s"], "per_metre_vs_smallest": r["per_metre_s"] / ref["per_metre_s"],
                "cpu_per_metre_s": r["cpu_per_metre_s"],
                "cpu_per_metre_vs_smallest": r["cpu_per_metre_s"] / ref["cpu_per_metre_s"],
                "mb_per_metre": r["peak_above_start_mb"] / r["length_m"],
                "mb_per_metre_vs_smallest": (r["peak_above_start_mb"] / r["length_m"])
                / (ref["peak_above_start_mb"] / ref["length_m"]),
            })
    doc = {"bench": "dense_gcode", "env": env_info(), "runs": ordered, "linearity": lin}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    return doc


def rows(doc: dict[str, Any]) -> list[dict[str, str]]:
    out: list[dict[str, str]] = []
    runs = doc["runs"]
    stops = {r["moves"]: r for r in runs if r["blend_mm"] == 0.0 and "error" not in r}
    for r in runs:
        if "error" in r:
            out.append(row(f"{r['moves']} G01 moves, blend {r['blend_mm']} mm", "—", "—", r["error"][:200], "runs",
                           "FAIL"))
            continue
        if r["blend_mm"] == 0.0:
            continue
        fd = r["fd_utilisation"]
        out.append(row(
            f"{r['moves']} G01 moves ({r['length_m']:.2f} m), blended {r['blend_mm']} mm, {r['method']}: "
            "time per metre (parse + toolpath + schedule)",
            f"{r['per_metre_s']:.3f} s/m (parse {r['parse_s']:.1f} s, toolpath {r['toolpath_s']:.1f} s, "
            f"schedule {r['schedule_s']:.1f} s)", f"peak {r['peak_rss_mb']:.0f} MB", "—", "linear", "info"))
        out.append(row(
            f"{r['moves']} G01 moves: sampled FD utilisation v / a / j (1 kHz positions)",
            f"{fd['v']:.4f} / {fd['a']:.4f} / {fd['j']:.4f}", "—", "—", f"<= {LIMIT_FACTOR}",
            verdict(r["worst_fd_utilisation"] <= LIMIT_FACTOR)))
        s = stops.get(r["moves"])
        if s is not None:
            out.append(row(f"{r['moves']} G01 moves: blended vs stop at every vertex (motion time)",
                           f"{r['motion_s']:.2f} s", f"stop {s['motion_s']:.2f} s",
                           f"{s['motion_s'] / r['motion_s']:.1f}x faster", "faster", verdict(s['motion_s'] >
                                                                                          r['motion_s'])))
    for ln in doc["linearity"][1:]:
        out.append(row(f"{ln['moves']} G01 moves vs smallest: wall time / CPU time / MB per metre",
                       f"{ln['per_metre_vs_smallest']:.2f}x / {ln['cpu_per_metre_vs_smallest']:.2f}x / "
                       f"{ln['mb_per_metre_vs_smallest']:.2f}x", "—", "—", "about 1x (linear)", "info"))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moves", type=int, nargs="+", default=list(DEFAULT_SIZES))
    ap.add_argument("--blend-mm", type=float, default=0.02)
    ap.add_argument("--method", default="lp")
    ap.add_argument("--no-stop", action="store_true", help="skip the stop-at-every-vertex run")
    ap.add_argument("--timeout", type=float, default=None, help="per size, s")
    ap.add_argument("--single", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.single is not None:
        emit(run(a.single, a.blend_mm, a.method))
        return
    new: list[dict[str, Any]] = []
    for n in a.moves:
        print(f"dense_gcode: {n} moves ...", file=sys.stderr, flush=True)
        new.append(run_sub(n, a.blend_mm, a.method, a.timeout))
    if not a.no_stop:
        n = min(a.moves)
        print(f"dense_gcode: {n} moves, stop at every vertex ...", file=sys.stderr, flush=True)
        new.append(run_sub(n, 0.0, a.method, a.timeout))
    doc = merge(new)
    emit({"bench": "dense_gcode", "env": env_info(), "rows": rows(doc), "runs": new,
          "linearity": doc["linearity"], "results_file": str(RESULTS)})


if __name__ == "__main__":
    main()
