"""lp+nlp in a service job: the CPU of one schedule in a fresh process, against the same schedule warm.

The service runs every job in a process forked from its forkserver, which has imported the solver and run
``solvers.nlp.warm_interval_functions`` (the NLP's interval, cut-slot and rest-end functions); the NLP's window
shapes (``solvers.nlp._Shape``: one per window length and kind) are built per job.  Each fresh run here is one
such process: imports, ``warm_interval_functions`` (untimed, as in the forkserver), then one lp+nlp schedule
with one NLP worker (a job's own process), timed by its process CPU.  The warm figure is the same schedule again
in a process that has scheduled it once: its shapes cached, and whatever else the same toolpath finds warm, so
fresh - warm bounds what a job pays for starting cold.  (Session 45: scheduling another path first in the fresh
process, as a forkserver could, left the flower at 0.32-0.33 s and the corner at 0.16-0.22 s: the gap is the
case's own shapes and caches, not first-use costs a warm-up would take.)

Cases: the flower (one loop: 3 NLP windows, two from or to rest) and the square corner (two pieces, each from
rest to rest).  Medians of RUNS fresh processes; the warm figure the median of RUNS schedules in one process.

    python -m bench.fresh_job
"""

from __future__ import annotations

import statistics
import sys
import time
import warnings
from typing import Any

from bench._common import emit, env_info, row, run_module

RUNS = 5
CASES = ("flower", "square_corner")
TIMEOUT_S = 300


def _case(name: str) -> Any:
    from geometry import examples as ex

    return ex.flower(1) if name == "flower" else ex.square_corner()


def child(name: str, warm_runs: int) -> dict[str, Any]:
    """One fresh process: the forkserver's warm-up, then the timed schedule(s)."""
    warnings.simplefilter("ignore")
    from solvers import nlp
    from solvers import pipeline as pl
    from solvers.machine import router
    from solvers.pipeline import Options, schedule

    pl.NLP_AUTO_WORKERS_MAX = 1  # (a job's own process: its NLP in it)
    opts = Options(method="lp+nlp", nlp_workers=1)
    nlp.warm_interval_functions(opts.nlp_checkpoints_per_interval)
    tp, m = _case(name), router()
    cpu: list[float] = []
    builds = [0]
    init = nlp._Shape.__init__

    def counted(self: Any, *a: Any, **k: Any) -> None:
        builds[0] += 1
        init(self, *a, **k)

    nlp._Shape.__init__ = counted  # type: ignore[method-assign]
    motion = float("nan")
    for _ in range(1 + warm_runs):
        t0 = time.process_time()
        sch = schedule(tp, m, opts)
        cpu.append(time.process_time() - t0)
        motion = float(sch.summary["motion_time"])
    return {"fresh_cpu": cpu[0], "warm_cpu": statistics.median(cpu[1:]) if warm_runs else None,
            "shape_builds": builds[0], "motion_time": motion}


def main() -> dict[str, Any]:
    out: dict[str, Any] = {"bench": "fresh_job", "env": env_info(), "runs": RUNS, "cases": {}, "rows": []}
    for name in CASES:
        runs = [run_module("bench.fresh_job", ["--child", name, "0"], TIMEOUT_S) for _ in range(RUNS)]
        warm = run_module("bench.fresh_job", ["--child", name, str(RUNS)], TIMEOUT_S)
        errors = [r["error"] for r in [*runs, warm] if "error" in r]
        if errors:
            out["cases"][name] = {"error": errors[0]}
            out["rows"].append(row(f"lp+nlp service job, {name}", "—", "—", errors[0], "—", "ERROR"))
            continue
        fresh = statistics.median(r["fresh_cpu"] for r in runs)
        w = float(warm["warm_cpu"])
        out["cases"][name] = {"fresh_cpu": [r["fresh_cpu"] for r in runs], "fresh_median": fresh, "warm_median": w,
                              "shape_builds": runs[0]["shape_builds"], "motion_time": runs[0]["motion_time"]}
        out["rows"].append(row(
            f"lp+nlp service job, {name}: CPU of one schedule in a fresh process (forkserver warm-up untimed; "
            f"{runs[0]['shape_builds']} window shapes built), median of {RUNS}",
            f"{fresh:.3f} s", f"the same schedule warm {w:.3f} s", f"fresh/warm {fresh / w:.2f}x", "report", "info"))
    emit(out)
    return out


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        emit(child(sys.argv[2], int(sys.argv[3])))
    else:
        main()
