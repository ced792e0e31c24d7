"""The 10k random bench's own harness (`bench/random_cases.py`): its per-case time limit must count as a failure.

The NLP keeps the LP feed in a window whose solve raises ``Exception``; a time limit that raised an
``Exception`` there was swallowed, and a 202 s case (bench seed 84, lp+nlp) was counted as passed.
CasADi also catches an exception raised while Ipopt runs and reports an interrupted solve (bench
seed 68, 327 s), so a case whose alarm fired fails whatever it returns.
"""

from __future__ import annotations

import signal
import time
from typing import Any

import pytest

from bench import random_cases
from solvers import nlp

SEED = 3  # any case whose lp+nlp schedule reaches an NLP window
SLOW_WINDOW_S = 3.0


@pytest.mark.parametrize("swallowed", [False, True], ids=["raised", "swallowed_by_the_solver"])
def test_time_limit_inside_an_nlp_window_fails_the_case(monkeypatch: pytest.MonkeyPatch, swallowed: bool) -> None:
    real_window = nlp.NlpRefiner._window
    calls = []

    def slow_window(self: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        try:
            time.sleep(SLOW_WINDOW_S)  # the alarm fires in here
        except BaseException as exc:
            if not swallowed:
                raise
            # what CasADi does with an exception raised inside Ipopt: a failed solve instead
            raise nlp.NlpFailure("Ipopt: user interrupt", 0, "Interrupted_By_User") from exc
        return real_window(self, *args, **kwargs)

    monkeypatch.setattr(nlp.NlpRefiner, "_window", slow_window)
    monkeypatch.setattr(random_cases, "CASE_TIMEOUT_S", 1)
    old = signal.signal(signal.SIGALRM, random_cases._alarm)
    try:
        rows = {r["method"]: r for r in random_cases.run_seed(SEED, "test")}
    finally:
        signal.signal(signal.SIGALRM, old)
    assert calls, "the case never reached an NLP window; pick another SEED"
    assert rows["lp"]["ok"], rows["lp"]
    assert not rows["lp+nlp"]["ok"]
    assert "CaseTimeout" in rows["lp+nlp"]["error"]
    assert rows["lp+nlp"]["seconds"] < SLOW_WINDOW_S + 30
