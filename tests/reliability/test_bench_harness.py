"""The 10k random bench's own harness (`bench/random_cases.py`): its per-case time limit must count as a failure.

It used to be SIGALRM raising inside the solvers.  The NLP keeps the LP feed in a window whose solve
raises ``Exception`` (bench seed 84, lp+nlp, 202 s, counted as passed), and CasADi turns an exception
raised while Ipopt runs into an interrupted solve, which the NLP handles as a failed window (bench
seed 68, 327 s, passed).  Cases now run in a worker process with a CPU-time limit (RLIMIT_CPU) and a
wall-time limit after which it is killed.
"""

from __future__ import annotations

import time
from typing import Any

import pytest

from bench import random_cases
from solvers import nlp
from tests.reliability import gen, harness

SEED = 3  # any case whose lp+nlp schedule reaches an NLP window
SLOW_WINDOW_S = 30.0
TIME_LIMIT_S = 2


@pytest.mark.parametrize("busy", [False, True], ids=["sleeping_wall_limit", "computing_cpu_limit"])
@pytest.mark.parametrize("swallowed", [False, True], ids=["raised", "swallowed_by_the_solver"])
def test_time_limit_inside_an_nlp_window_fails_the_case(
    monkeypatch: pytest.MonkeyPatch, swallowed: bool, busy: bool
) -> None:
    """A window that sleeps (the wall-time limit kills the worker) or computes (RLIMIT_CPU does); the
    solver's own failure handling may catch what it gets (as CasADi does inside Ipopt)."""
    real_window = nlp.NlpRefiner._window

    def slow_window(self: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < SLOW_WINDOW_S:  # the time limit runs out in here
                if not busy:
                    time.sleep(0.05)
        except BaseException as exc:
            if not swallowed:
                raise
            # what CasADi does with an exception raised inside Ipopt: a failed solve instead
            raise nlp.NlpFailure("Ipopt: user interrupt", 0, "Interrupted_By_User") from exc
        return real_window(self, *args, **kwargs)

    monkeypatch.setattr(nlp.NlpRefiner, "_window", slow_window)  # the worker forks with it
    if busy:
        monkeypatch.setattr(random_cases, "CASE_TIMEOUT_S", TIME_LIMIT_S)
    else:
        monkeypatch.setattr(random_cases, "CASE_WALL_S", TIME_LIMIT_S)
    t0 = time.perf_counter()
    rows = {r["method"]: r for r in random_cases.run_seed(SEED, "test")}
    assert rows["lp"]["ok"], rows["lp"]
    assert not rows["lp+nlp"]["ok"]
    assert "CaseTimeout" in rows["lp+nlp"]["error"]
    assert ("CPU" if busy else "wall") in rows["lp+nlp"]["error"]
    assert time.perf_counter() - t0 < SLOW_WINDOW_S  # the worker was stopped, not waited for


def test_worker_survives_a_killed_case_and_runs_the_next(monkeypatch: pytest.MonkeyPatch) -> None:
    """After a case's worker is killed, the next case runs in a fresh one (and passes)."""
    w = random_cases.Worker("test")
    try:
        w.proc.kill()  # as if the kernel's OOM killer took it mid-case
        w.proc.join()
        row = w.run(SEED, "lp", 60, 60)
        assert not row["ok"] and "worker died" in row["error"]
        row = w.run(SEED, "lp", 60, 60)
        assert row["ok"], row
    finally:
        w.close()


@pytest.mark.parametrize("check_budget_s", [1, 30], ids=["over_its_budget", "within_its_budget"])
def test_the_check_has_its_own_cpu_budget(monkeypatch: pytest.MonkeyPatch, check_budget_s: int) -> None:
    """The scheduling limit is the product's; the independent check (~20 us a sample) gets its own budget
    once the schedule is done (bench seed 388: 6.1 M samples scheduled in 36 s were a time-out while the
    checker ran).  A check computing CHECK_BUSY_S passes past a 2 s scheduling limit when its budget
    allows it, and is reported as the check's time-out when it does not."""
    from tests.reliability import checker

    real_check = checker.check

    def slow_check(*args: Any, **kwargs: Any) -> Any:
        t0 = time.process_time()
        while time.process_time() - t0 < CHECK_BUSY_S:
            pass
        return real_check(*args, **kwargs)

    monkeypatch.setattr(checker, "check", slow_check)  # the worker forks with it
    monkeypatch.setattr(random_cases, "CASE_TIMEOUT_S", TIME_LIMIT_S)
    monkeypatch.setattr(random_cases, "CHECK_TIMEOUT_S", check_budget_s)
    monkeypatch.setattr(random_cases, "CHECK_S_PER_SAMPLE", 0.0)
    w = random_cases.Worker("test")
    try:
        row = w.run(SEED, "lp", TIME_LIMIT_S, 120)
    finally:
        w.close()
    if check_budget_s > CHECK_BUSY_S:
        assert row["ok"], row
    else:
        assert not row["ok"]
        assert row["error"].startswith("CaseTimeout: the check of "), row["error"]


#: CPU seconds the slowed check computes: over the scheduling limit, under the larger check budget.
CHECK_BUSY_S = 3.0


def test_a_refusal_by_the_output_cap_is_counted_apart_from_failures(monkeypatch: pytest.MonkeyPatch) -> None:
    """A case over harness.MAX_SAMPLES (bench seed 3061: 70 M samples) is refused with a typed
    OutputTooLargeError before any sample is built; the summary counts it as refused, not failed."""
    monkeypatch.setattr(harness, "MAX_SAMPLES", 10)
    out = harness.run(gen.case(0, "test"), "lp")
    assert not out.ok and out.error is not None and out.error.startswith(harness.REFUSED), out.error
    row = {"seed": 0, "method": "lp", "ok": False, "error": out.error, "violations": [], "utilisation": {},
           "seconds": 0.1, "tags": {}}
    good = {**row, "seed": 1, "ok": True, "error": None}
    bad = {**row, "seed": 2, "error": "solvers.errors.LimitViolationError: x"}
    s = random_cases.summarise([row, good, bad], "test", 3)
    assert (s["refused_runs"], s["failed_runs"]) == (1, 1)
    assert s["per_method"]["lp"] == {"runs": 3, "ok": 1, "failed": 1, "refused": 1}
    assert [f["seed"] for f in s["refusals"]] == [0] and [f["seed"] for f in s["failures"]] == [2]
