"""Run every benchmark in its own subprocess; write bench/results.json and bench/results.md.

Each benchmark prints a JSON dict on its last stdout line with a ``rows`` list
(what, ours, peer, ratio_gap, target, verdict).  Subprocesses isolate memory;
each one's peak RSS comes from os.wait4 (Linux ru_maxrss, which starts from this
small parent's peak at fork).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from bench._common import emit

BENCHES = ("toppra_vel_acc", "copp_jerk", "ruckig_lines", "lp_switch", "long_path", "nlp_gain", "fresh_job",
           "dense_gcode", "low_feed", "f_words", "nlp_workers", "job_memory")
ROOT = Path(__file__).resolve().parents[1]
OUT_JSON = ROOT / "bench" / "results.json"
OUT_MD = ROOT / "bench" / "results.md"
TIMEOUT_S = 1800


def run_one(name: str) -> dict[str, Any]:
    """Run ``python -m bench.<name>``; its JSON result plus wall time, exit code and peak RSS."""
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        t0 = time.perf_counter()
        p = subprocess.Popen([sys.executable, "-m", f"bench.{name}"], cwd=ROOT, stdout=fo, stderr=fe, text=True)
        timer = threading.Timer(TIMEOUT_S, p.kill)
        timer.start()
        try:
            _, status, ru = os.wait4(p.pid, 0)
            rc = os.waitstatus_to_exitcode(status)
            p.returncode = rc
        except ChildProcessError:
            rc = p.wait(TIMEOUT_S)
            ru = None
        finally:
            timer.cancel()
        wall = time.perf_counter() - t0
        fo.seek(0)
        fe.seek(0)
        stdout, stderr = fo.read(), fe.read()
    meta = {"wall_time_s": wall, "exit_code": rc, "maxrss_mb": ru.ru_maxrss / 1024.0 if ru else None}
    lines = [ln for ln in stdout.strip().splitlines() if ln.strip()]
    try:
        result = json.loads(lines[-1]) if lines else None
    except json.JSONDecodeError:
        result = None
    if rc != 0 or not isinstance(result, dict):
        return {"error": f"bench.{name} failed (exit {rc}): {stderr.strip()[-800:]}", "run": meta}
    result["run"] = meta
    return result


def _cell(x: Any) -> str:
    return str(x).replace("|", "\\|").replace("\n", " ")


def write_md(results: dict[str, Any], path: Path) -> None:
    head = results["meta"]
    lines = [
        "# Benchmark results",
        "",
        f"Generated {head['generated']} at commit `{head['commit']}` on {head['platform']}, "
        f"Python {head['python']}. Each timing is the median of >= 3 runs after a warm-up, all in one "
        "process per benchmark; ratios compare figures measured in the same run.",
        "",
        "| what | ours | peer | ratio / gap | target | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for name in BENCHES:
        r = results["benches"].get(name, {})
        if "error" in r:
            lines.append(f"| bench.{name} | — | — | {_cell(r['error'])} | — | ERROR |")
            continue
        for rw in r.get("rows", []):
            lines.append("| " + " | ".join(_cell(rw[k]) for k in
                                             ("what", "ours", "peer", "ratio_gap", "target", "verdict")) + " |")
    lines += ["", "## Runs", "", "| bench | wall s | exit | peak RSS MB |", "|---|---|---|---|"]
    for name in BENCHES:
        m = results["benches"].get(name, {}).get("run", {})
        rss = m.get("maxrss_mb")
        lines.append(f"| {name} | {m.get('wall_time_s', float('nan')):.1f} | {m.get('exit_code')} | "
                     f"{'—' if rss is None else f'{rss:.0f}'} |")
    notes = _notes(results)
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    path.write_text("\n".join(lines) + "\n")


def _notes(results: dict[str, Any]) -> list[str]:
    b = results["benches"]
    notes: list[str] = []
    c = b.get("copp_jerk", {})
    if "match" in c:
        notes.append(f"copp_jerk resolution match: {c['match']}.")
    for label, rec in c.get("copp", {}).items():
        if isinstance(rec, dict):
            for key, sub in rec.items():
                if isinstance(sub, dict) and "error" in sub:
                    notes.append(f"copp-py, knots {label}, {key}: {sub['error'].splitlines()[0]}")
    if "error" in c.get("copp", {}):
        notes.append(f"copp-py: {c['copp']['error']}")
    t = b.get("toppra_vel_acc", {})
    if "toppra_ref" in t:
        notes.append("toppra: timing covers constraint setup + TOPPRA + compute_trajectory only; its spline path "
                     f"({t['toppra_spline_samples']} samples) is built untimed. Our compute time includes geometry "
                     "evaluation and the 1 kHz reconstruction; 'LP' is the LP windows alone.")
    r = b.get("ruckig_lines", {}).get("summary")
    if r:
        notes.append("Ruckig peer uses Synchronization.Phase (straight line, equals the 1-DoF optimum: "
                     f"{r['ruckig_phase_equals_1dof']}); the default Time sync leaves the line by up to "
                     f"{r['ruckig_time_sync_max_dev_mm']:.2f} mm (same duration as Phase: "
                     f"{r['ruckig_time_sync_same_duration']}).")
    lp = b.get("long_path", {})
    if "subprocess" in lp:
        sub = lp["subprocess"]
        base = sub.get("baseline_build_only", {}).get("peak_mb")
        if base is not None:
            notes.append(f"long_path memory: a subprocess that only imports and builds {lp['path']} peaks at "
                         f"{base:.0f} MB (VmHWM); the scheduling's own peak (VmHWM reset before it, minus "
                         "RSS before it): "
                         + ", ".join(f"{k}: +{v.get('schedule_increment_mb', float('nan')):.0f} MB (compute "
                                     f"{v.get('compute_time', float('nan')):.2f} s)"
                                     for k, v in sub.items() if k != "baseline_build_only")
                         + f". Path build (untimed) {lp.get('path_build_time', float('nan')):.1f} s. "
                         f"This process after all runs: {lp.get('maxrss_mb_this_process', float('nan')):.0f} MB.")
    return notes


def _commit() -> str:
    try:
        p = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                           check=False, timeout=10)
        return p.stdout.strip() or "?"
    except OSError:
        return "?"


def main() -> dict[str, Any]:
    import platform

    results: dict[str, Any] = {
        "meta": {"generated": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"), "commit": _commit(),
                 "platform": platform.platform(), "python": sys.version.split()[0], "cpus": os.cpu_count()},
        "benches": {},
    }
    for name in BENCHES:
        print(f"running bench.{name} ...", file=sys.stderr, flush=True)
        results["benches"][name] = run_one(name)
    OUT_JSON.write_text(json.dumps(results, indent=1))
    write_md(results, OUT_MD)
    summary = {
        "results_json": str(OUT_JSON), "results_md": str(OUT_MD),
        "verdicts": {
            name: [r["verdict"] for r in results["benches"][name].get("rows", [])] or ["ERROR"]
            for name in BENCHES
        },
    }
    emit(summary)
    return summary


if __name__ == "__main__":
    main()
