"""The LP window cache (``solvers.pipeline.WindowCache``) keeps a window's failure as it keeps its result: the same
window on bit-equal inputs is not solved again but fails again at once (bench seed 11994: a 64-interval plan's
stalling windows were solved twice, ~11 s each time, ``tests/reliability/test_regressions.py``)."""

from __future__ import annotations

from typing import Any

import pytest

from geometry import Toolpath
from geometry import examples as ex
from solvers import lp
from solvers import pipeline as P
from solvers.errors import SolverFailure
from solvers.machine import router


def test_a_failed_window_is_not_solved_again(monkeypatch: pytest.MonkeyPatch) -> None:
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (20.0, 0.0, 0.0))])
    m = router()
    opt = P.Options(method="lp")
    lim = P._limit_set(m, opt)
    piece = tp.pieces[0]
    plan = P.plan_piece(piece, m, opt, 16)
    calls: list[int] = []

    def failing(self: Any, s_check: Any) -> Any:
        calls.append(self.spec.k0)
        raise SolverFailure("HiGHS did not reach optimality", window=self.spec.index, status="kUnknown")

    monkeypatch.setattr(lp.WindowLP, "solve", failing)
    cache: P.WindowCache = {}
    stats: dict[str, Any] = {"windows": 0, "iterations": 0, "cut_rounds": 0, "cut_points": 0, "unverified": 0,
                             "window_times": []}
    with pytest.raises(SolverFailure):
        P._solve_windows(tp, piece, plan, opt, lim, stats, None, None, cache)
    solved = len(calls)
    assert solved >= 1
    with pytest.raises(SolverFailure):
        P._solve_windows(tp, piece, plan, opt, lim, stats, None, None, cache)
    assert len(calls) == solved, "the failed window was solved again on the same inputs"
    # a fresh cache solves it again (the cache, not something else, kept it from running)
    with pytest.raises(SolverFailure):
        P._solve_windows(tp, piece, plan, opt, lim, stats, None, None, {})
    assert len(calls) == 2 * solved
