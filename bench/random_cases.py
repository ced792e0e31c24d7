"""Randomized verification at scale (issue 5): N random toolpaths x machines, both methods, checked independently.

    python -m bench.random_cases --n 10000            # the documented run
    python -m bench.random_cases --n 1000 --profile bench

Each seed is one case from ``tests.reliability.gen.case(seed, profile)``; each case is scheduled with
``lp`` (checked for v, a, j) and ``lp+nlp`` (checked for u, e and v) and checked by
``tests.reliability.checker`` (no solver code).  Outcomes are appended per seed to
``<out>.jsonl`` so an interrupted run resumes where it stopped; the summary (counts, failures,
worst utilisation per constraint) is written to ``<out>`` (default bench/results/random_cases.json).
Cases run in a worker process, bounded in memory (RLIMIT_AS) and time (RLIMIT_CPU: CASE_TIMEOUT_S of
CPU to schedule, plus CASE_S_PER_MOTION_S per second of the motion-time floor, then CHECK_TIMEOUT_S +
CHECK_S_PER_SAMPLE a sample for the check; and CASE_WALL_S of wall time, after which the worker is
killed); hitting any counts as a failure, and the worker is replaced.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import queue
import resource
import signal
import subprocess
import sys
import threading
import time
import warnings
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from tests.reliability import gen, harness

DEFAULT_OUT = Path(__file__).parent / "results" / "random_cases.json"
#: A worker's address-space limit (RLIMIT_AS).  The schedule's samples are the memory: bench seed 615
#: (lp+nlp) is 60 mm at 15,305 s of motion, 15.3 M samples at 1 kHz, 5.0 GB peak to schedule and
#: 6.5 GB with the check; 4 GB made it (and seed 388 lp, 5.5 M samples) a MemoryError.  Two workers at
#: 8 GB fit the machine's 24 GB.
MEMORY_LIMIT_BYTES = 8 * 2**30
#: A case's time limit, in CPU seconds of its worker (RLIMIT_CPU): on this shared machine a case's
#: wall time depends on the load (bench seed 30 lp+nlp: 22 s alone, over 120 s at nice 19 under a
#: load of 4), its CPU time does not.
CASE_TIMEOUT_S = 120
#: ... plus this many CPU seconds per second of the case's motion-time floor
#: (``solvers.pipeline.motion_time_floor``, known before the schedule): the issue's target for long paths is a
#: compute time of 1 % of the motion.  cam-bench seed 39 lp: 0.8 um knots (a 0.22 mm/s machine), 1.15 M
#: knot intervals over 926 mm, 10,841 s of motion scheduled in 152 s (1.4 %) and counted as a time-out at 120 s.
CASE_S_PER_MOTION_S = 0.01
#: ... and in wall seconds, for a case that hangs without using CPU.
CASE_WALL_S = 1800
#: The independent check of the samples has its own CPU budget, set when the schedule is done: this
#: many seconds plus CHECK_S_PER_SAMPLE per sample.  The limit above is the product's (scheduling);
#: the check is the bench's own cost, ~20 us a sample (bench seed 388: 6.1 M samples for 6,139 s of
#: motion, scheduled in 36 s, were counted as a time-out while the checker ran).
CHECK_TIMEOUT_S = 60
CHECK_S_PER_SAMPLE = 1e-4


def _cpu_used(since: float = 0.0) -> float:
    """CPU seconds this process has used (since ``since``, an earlier reading)."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime - since


def _cpu_limit(cpu_s: float) -> None:
    """SIGXCPU (which kills) once this process has used cpu_s more seconds of CPU."""
    soft = math.ceil(_cpu_used() + cpu_s)
    resource.setrlimit(resource.RLIMIT_CPU, (soft, resource.RLIM_INFINITY))


def _serve(conn: Connection, profile: str) -> None:
    """Worker process: run (seed, method) requests, answer each with its row fields."""
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, MEMORY_LIMIT_BYTES))
    warnings.simplefilter("ignore")
    cases: dict[int, gen.Case] = {}
    while True:
        try:
            seed, method, cpu_s = conn.recv()
        except EOFError:
            return
        start = _cpu_used()
        _cpu_limit(cpu_s)
        try:
            c = cases.get(seed) or gen.case(seed, profile)
            cases = {seed: c}

            def before_schedule(floor: float, cpu_s: float = cpu_s, start: float = start) -> None:
                budget = cpu_s + CASE_S_PER_MOTION_S * floor
                _cpu_limit(budget - _cpu_used(start))
                conn.send(("budget", budget))

            def before_check(samples: int) -> None:
                _cpu_limit(CHECK_TIMEOUT_S + CHECK_S_PER_SAMPLE * samples)
                conn.send(("checking", samples))

            o = harness.run(c, method, before_check, before_schedule)
            row = {"ok": o.ok, "error": o.error, "violations": o.violations, "utilisation": o.utilisation,
                   "samples": o.samples, "nlp_fallbacks": o.nlp_fallbacks}
        except BaseException as exc:  # whatever happens is the case's outcome
            row = {"ok": False, "error": f"{type(exc).__name__}: {exc}", "violations": [], "utilisation": {},
                   "samples": 0, "nlp_fallbacks": 0}
        conn.send(row)


class Worker:
    """One forked process that runs cases one after another (its NLP shape caches stay warm) and is
    killed and replaced when a case runs over the time limit.

    The time limit used to be SIGALRM in this process, raising inside the solvers: the NLP's
    per-window failure handling caught it (bench seed 84, lp+nlp, 202 s, counted as passed), and
    CasADi, which turns an exception raised while Ipopt runs into an interrupted solve, made it a
    failed window that kept the LP feed (bench seed 68, 327 s, passed).  A killed process cannot
    return a fallback."""

    def __init__(self, profile: str) -> None:
        self.profile = profile
        self._start()

    def _start(self) -> None:
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(child, self.profile), daemon=True)
        self.proc.start()
        child.close()

    def run(self, seed: int, method: str, cpu_s: float, wall_s: float) -> dict[str, Any]:
        """One case: at most cpu_s seconds of the worker's CPU (RLIMIT_CPU) to schedule, then the check's
        own budget (CHECK_TIMEOUT_S + CHECK_S_PER_SAMPLE a sample), and wall_s of wall time in all."""
        checking: int | None = None  # samples being checked, once the schedule is done
        deadline = time.monotonic() + wall_s
        try:
            self.conn.send((seed, method, cpu_s))
            while True:
                left = deadline - time.monotonic()
                if left <= 0 or not self.conn.poll(left):
                    error = f"CaseTimeout: over {wall_s:g} s of wall time"
                    break
                msg = self.conn.recv()
                if isinstance(msg, tuple) and msg[0] == "checking":
                    checking = int(msg[1])
                    continue
                if isinstance(msg, tuple) and msg[0] == "budget":
                    cpu_s = float(msg[1])
                    continue
                row: dict[str, Any] = msg
                return row
        except (EOFError, OSError):
            self.proc.join(5)
            code = self.proc.exitcode
            if code != -signal.SIGXCPU:
                error = f"worker died: exit code {code}"
            elif checking is None:
                error = f"CaseTimeout: scheduling over {cpu_s:g} s of CPU"
            else:
                budget = CHECK_TIMEOUT_S + CHECK_S_PER_SAMPLE * checking
                error = f"CaseTimeout: the check of {checking} samples over {budget:g} s of CPU"
        self.close()
        self._start()
        return {"ok": False, "error": error, "violations": [], "utilisation": {}, "samples": 0, "nlp_fallbacks": 0}

    def close(self) -> None:
        self.proc.kill()
        self.proc.join()
        self.conn.close()


def run_seed(seed: int, profile: str, worker: Worker | None = None) -> list[dict[str, Any]]:
    own = worker is None
    w = Worker(profile) if worker is None else worker
    out = []
    tags = dict(gen.case(seed, profile).tags)
    try:
        for method in harness.METHODS:
            t0 = time.perf_counter()
            row = w.run(seed, method, CASE_TIMEOUT_S, CASE_WALL_S)
            out.append({"seed": seed, "method": method, **row, "seconds": time.perf_counter() - t0, "tags": tags})
    finally:
        if own:
            w.close()
    return out


def summarise(rows: list[dict[str, Any]], profile: str, n: int) -> dict[str, Any]:
    worst: dict[str, dict[str, float]] = {}
    failures = []
    per_method: dict[str, dict[str, int]] = {}
    per_commit: dict[str, dict[str, int]] = {}  # a resumed run may span solver fixes: which rows ran on which
    refusals = []  # typed refusals (harness.REFUSED: output cap, limit below float resolution), not failures
    for r in rows:
        refused = not r["ok"] and (r.get("error") or "").startswith(harness.REFUSED)
        outcome = "ok" if r["ok"] else "refused" if refused else "failed"
        for key, tab in ((r["method"], per_method), (r.get("commit", "unrecorded"), per_commit)):
            pm = tab.setdefault(key, {"runs": 0, "ok": 0, "failed": 0, "refused": 0})
            pm["runs"] += 1
            pm[outcome] = pm.get(outcome, 0) + 1
        if outcome != "ok":
            (refusals if refused else failures).append(
                {k: r[k] for k in ("seed", "method", "error", "violations", "tags")})
        for key, val in r["utilisation"].items():
            w = worst.setdefault(r["method"], {})
            if key not in w or val > w[key]:
                w[key] = val
    seeds = sorted({r["seed"] for r in rows})
    return {
        "profile": profile,
        "requested": n,
        "cases": len(seeds),
        "runs": len(rows),
        "failed_runs": len(failures),
        "failed_cases": len({f["seed"] for f in failures}),
        "refused_runs": len(refusals),
        "per_method": per_method,
        "per_commit": per_commit,
        "worst_utilisation": worst,
        "failures": failures,
        "refusals": refusals,
        "seconds": sum(r["seconds"] for r in rows),
    }


def _commit() -> str:
    """The checked-out commit (with "+dirty" for local edits), or "unknown" outside git."""
    here = Path(__file__).parent
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "geometry", "solvers"], cwd=here.parent,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=10_000, help="number of cases (seeds start..start+n-1)")
    ap.add_argument("--start", type=int, default=0, help="first seed")
    ap.add_argument("--profile", default="bench", choices=sorted(gen.LENGTHS))
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--fresh", action="store_true", help="ignore earlier outcomes in <out>.jsonl")
    ap.add_argument("--retry-failed", action="store_true",
                    help="run again the seeds that failed earlier (after a fix), keep the rest")
    ap.add_argument("--seeds", type=Path, default=None,
                    help="file of seeds (whitespace-separated) to run instead of start..start+n-1, e.g. the "
                         "seeds a change touches (write to their own --out)")
    ap.add_argument("--workers", type=int, default=1,
                    help="worker processes running cases side by side (each its own CPU limit; on an idle "
                         "2-core machine 2 halves the wall time)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    log = args.out.with_suffix(".jsonl")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    wanted = (list(range(args.start, args.start + args.n)) if args.seeds is None
              else [int(x) for x in args.seeds.read_text().split()])
    if args.seeds is not None:
        args.n = len(wanted)
    if log.exists() and not args.fresh:
        rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
        keep = set(wanted)
        rows = [r for r in rows if r["seed"] in keep]
    if args.retry_failed:
        failed = {r["seed"] for r in rows if not r["ok"]}
        rows = [r for r in rows if r["seed"] not in failed]
        if log.exists():
            kept = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
            log.write_text("".join(json.dumps(r) + "\n" for r in kept if r["seed"] not in failed))
    done = {r["seed"] for r in rows}
    todo = queue.SimpleQueue[int]()
    for seed in wanted:
        if seed not in done:
            todo.put(seed)
    lock = threading.Lock()
    commit = _commit()
    with log.open("w" if args.fresh else "a") as fh:

        def serve(worker: Worker) -> None:
            """One thread per worker process: take seeds until none are left, log each seed's runs."""
            try:
                while True:
                    try:
                        seed = todo.get_nowait()
                    except queue.Empty:
                        return
                    new = run_seed(seed, args.profile, worker)
                    for r in new:
                        r["commit"] = commit  # which solvers produced the row (a run may span fixes)
                    with lock:
                        for r in new:
                            fh.write(json.dumps(r) + "\n")
                        fh.flush()
                        rows.extend(new)
                        for r in new:
                            if not r["ok"]:
                                print(f"seed {seed} {r['method']}: {r['error'] or '; '.join(r['violations'])}",
                                      file=sys.stderr)
                        if len({r["seed"] for r in rows}) % 50 == 0:
                            args.out.write_text(json.dumps(summarise(rows, args.profile, args.n), indent=1))
            finally:
                worker.close()

        # the processes are forked here, before any thread runs (a replacement after a time-out is forked
        # by its thread while the others wait on their pipes)
        threads = [threading.Thread(target=serve, args=(Worker(args.profile),)) for _ in range(max(1, args.workers))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    summary = summarise(rows, args.profile, args.n)
    args.out.write_text(json.dumps(summary, indent=1))
    print(json.dumps({k: v for k, v in summary.items() if k != "failures"}, indent=1))
    return 0 if summary["failed_runs"] == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
