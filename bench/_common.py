"""Shared helpers: machine limits, repeated timing, result rows, JSON output."""

from __future__ import annotations

import json
import math
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from solvers.machine import Machine
from solvers.pipeline import Options, Schedule, schedule

#: Repeats per timed measurement (the median is reported), after WARMUP untimed runs.
REPEATS = 3
WARMUP = 1
#: Allowed overshoot of any limit in the sampled output (tests/solvers/test_limits.py, issue: 1.01 x).
LIMIT_FACTOR = 1.01
TS = 1e-3


def limits(m: Machine) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-axis (vmax, amax, jmax) arrays (3,): the machine's input limits."""
    return m.limit_arrays()


def repeat(fn: Callable[[], Any], repeats: int = REPEATS, warmup: int = WARMUP) -> tuple[float, list[float], Any]:
    """Median wall time of ``fn()`` over ``repeats`` runs after ``warmup`` runs; also all times and the last result."""
    for _ in range(warmup):
        fn()
    times: list[float] = []
    out: Any = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times, out


def run_ours(toolpath: Any, machine: Machine, opts: Options, repeats: int = REPEATS,
             warmup: int = WARMUP) -> tuple[Schedule, dict[str, float]]:
    """Schedule ``repeats`` times after ``warmup`` runs; medians of the summary's compute and LP times."""
    for _ in range(warmup):
        schedule(toolpath, machine, opts)
    comp: list[float] = []
    lp: list[float] = []
    wall: list[float] = []
    sch: Schedule | None = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        sch = schedule(toolpath, machine, opts)
        wall.append(time.perf_counter() - t0)
        comp.append(sch.summary["compute_time"])
        lp.append(sch.summary["lp_time"])
    assert sch is not None
    return sch, {
        "compute_time": statistics.median(comp),
        "lp_time": statistics.median(lp),
        "wall_time": statistics.median(wall),
        "compute_times": comp,
    }


def summary_subset(sch: Schedule) -> dict[str, Any]:
    keys = ("motion_time", "windows", "solver_iterations", "checkpoints", "control_points", "knot_spacing",
            "cut_rounds", "cut_points", "samples")
    return {k: sch.summary[k] for k in keys}


def row(what: str, ours: str, peer: str, ratio: str, target: str, verdict: str) -> dict[str, str]:
    """One line of bench/results.md."""
    return {"what": what, "ours": ours, "peer": peer, "ratio_gap": ratio, "target": target, "verdict": verdict}


def verdict(ok: bool | None) -> str:
    if ok is None:
        return "info"
    return "pass" if ok else "FAIL"


def gap_pct(ours: float, peer: float) -> float:
    """(ours - peer) / peer in %; positive = ours slower."""
    return 100.0 * (ours - peer) / peer


def env_info() -> dict[str, Any]:
    return {"python": sys.version.split()[0], "platform": platform.platform(), "repeats": REPEATS,
            "warmup": WARMUP, "timer": "time.perf_counter (median)"}


def _clean(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        return _clean(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def emit(result: dict[str, Any]) -> None:
    """Print the result as one JSON line (the last stdout line)."""
    sys.stdout.flush()
    print(json.dumps(_clean(result)), flush=True)


def fmt(x: float, unit: str = "", digits: int = 4) -> str:
    return f"{x:.{digits}g}{(' ' + unit) if unit else ''}"


def proc_status_mb(key: str) -> float:
    """VmRSS / VmHWM of this process from /proc/self/status, MB (nan if unavailable)."""
    try:
        for ln in Path("/proc/self/status").read_text().splitlines():
            if ln.startswith(key + ":"):
                return float(ln.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def reset_hwm() -> bool:
    """Reset the kernel's peak-RSS mark (VmHWM) of this process; False where not permitted."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def run_module(module: str, args: list[str], timeout: float) -> dict[str, Any]:
    """``python -m module args`` from the project root in a fresh process; its last stdout line as JSON,
    or {"error": "exit N: <end of stderr>"} if it failed."""
    root = Path(__file__).resolve().parents[1]
    p = subprocess.run([sys.executable, "-m", module, *args], cwd=root, capture_output=True, text=True,
                       timeout=timeout, check=False)
    if p.returncode != 0:
        return {"error": f"exit {p.returncode}: {p.stderr.strip()[-500:]}"}
    return dict(json.loads(p.stdout.strip().splitlines()[-1]))
