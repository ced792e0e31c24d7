"""Upper bounds on the LP's control points that its velocity rows imply (``solvers.lp.WindowLP._implied_col_hi``).

Independent truth: each bound is checked against the largest value the column can take under the model's own
rows with every upper bound removed (a fresh HiGHS model maximising that column), bench seed 664 in a worker
limited in CPU as the random bench runs it, checked by ``tests.reliability``'s checker, and ``column_reach``
against a loop.
"""

from __future__ import annotations

from typing import Any

import highspy
import numpy as np
import pytest

from geometry import Toolpath, primitives
from geometry import examples as ex
from solvers import bspline, lp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.solvers.highs_runs import watch_highs_runs

#: Models checked per schedule (each window's first HiGHS model) and columns per model.
MODELS_PER_CASE = 3
COLUMNS_PER_MODEL = 24
#: A column's largest value under the rows may reach its bound by HiGHS's feasibility tolerance (scaled units).
BOUND_TOL = 1e-6


def _first_models(monkeypatch: pytest.MonkeyPatch) -> dict[int, Any]:
    """The ``HighsLp`` at the first run of each of the first MODELS_PER_CASE HiGHS models (copies, as built: rows,
    scaled columns, bounds), by the model's id."""
    seen: dict[int, Any] = {}

    def kept(h: Any) -> None:
        if id(h) not in seen and len(seen) < MODELS_PER_CASE:
            seen[id(h)] = h.getLp()

    watch_highs_runs(monkeypatch, before=kept)
    return seen


def _largest(model: Any, j: int) -> float:
    """max y_j under the model's rows and column lower bounds, with no column upper bound."""
    h = highspy.Highs()  # type: ignore[no-untyped-call]
    h.setOptionValue("output_flag", False)
    h.passModel(model)
    n = model.num_col_
    h.changeColsBounds(n, np.arange(n, dtype=np.int32), np.asarray(model.col_lower_), np.full(n, highspy.kHighsInf))
    cost = np.zeros(n)
    cost[j] = -1.0
    h.changeColsCost(n, np.arange(n, dtype=np.int32), cost)
    h.run()
    status = h.getModelStatus()
    if status == highspy.HighsModelStatus.kUnbounded:
        return np.inf
    assert status == highspy.HighsModelStatus.kOptimal, status
    return float(h.getSolution().col_value[j])


CASES = {
    "flower": (lambda: ex.flower(1), Options(method="lp")),
    "flower v+a": (lambda: ex.flower(1), Options(method="lp", jerk=False)),
    "corner": (ex.square_corner, Options(method="lp")),
    "wave3d": (lambda: Toolpath([ex.wave3d()]), Options(method="lp")),
    "line": (lambda: Toolpath([primitives.line((0.0, 0.0, 0.0), (20.0, 6.0, 2.0))]), Options(method="lp")),
}


@pytest.mark.parametrize("name", list(CASES))
def test_column_bounds_leave_the_rows_feasible_set_as_it_is(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """No column bound cuts into what the rows allow: the column's largest value under the rows alone is within
    its bound.  And the bounds are there: most free columns of every model have one.  (Not the flat bounds
    (``lp.FLAT_CAP_COLUMNS``): those cut into it on purpose, ``tests/solvers/test_flat_caps.py``.)"""
    make, opt = CASES[name]
    monkeypatch.setattr(lp, "FLAT_CAP_COLUMNS", False)
    models = _first_models(monkeypatch)
    schedule(make(), router(), opt)
    assert len(models) >= 1
    for model in models.values():
        hi = np.asarray(model.col_upper_)
        lo = np.asarray(model.col_lower_)
        bounded = np.flatnonzero(np.isfinite(hi) & (hi > lo))
        free = np.flatnonzero(hi > lo)
        assert bounded.size >= 0.5 * free.size, (bounded.size, free.size)
        for j in bounded[np.linspace(0, bounded.size - 1, min(COLUMNS_PER_MODEL, bounded.size)).astype(int)]:
            top = _largest(model, int(j))
            assert top <= hi[j] + BOUND_TOL * max(1.0, hi[j]), (name, int(j), top, hi[j])


#: CPU (and wall) seconds bench seed 664 lp may take in its worker (~4 s with the column bounds, held rows on or off;
#: without them 7.6 s, and over 120 s with the held rows).
CASE_CPU_S = 60


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("held", [False, True])
def test_infeasible_floors_are_found_quickly(monkeypatch: pytest.MonkeyPatch, held: bool) -> None:
    """Bench seed 664 (lp): piece 1 (15 mm, limits up to 1.4e6 mm/s^2) refined to 128 knot intervals with its rest
    floor, whose floors make the window infeasible.  Without column upper bounds HiGHS's dual simplex ran 0.3-4.6 s
    (10 ms an iteration, the objective at 1e13) to status unknown, then 2 s more with presolve to prove it
    infeasible; with ``lp.POINT_HELD_ROWS`` the refinements to 256 and 512 intervals did the same, over 120 s of
    CPU in all (a ``CaseTimeout``).  With the bounds those runs end in 0.03-1 s (infeasible; one at 256 intervals
    with status unknown, in 0.12 s, and the next floor goes on).  Run in a worker
    limited to CASE_CPU_S, as the random bench runs it, and checked by its checker."""
    from bench import random_cases

    monkeypatch.setattr(lp, "POINT_HELD_ROWS", held)
    w = random_cases.Worker("bench")  # forked with the setting above; killed past its CPU limit
    try:
        row = w.run(664, "lp", CASE_CPU_S, CASE_CPU_S)
    finally:
        w.close()
    assert row["ok"], row


@pytest.mark.parametrize("shuffled", [False, True])
def test_column_reach_is_the_smallest_cap_over_each_basis_function(shuffled: bool) -> None:
    """``lp.column_reach`` against a loop over every (point, column) pair, with points in order of s (the
    reduceat path) and shuffled (``np.minimum.at``)."""
    rng = np.random.default_rng(7)
    n_int, d = 12, 0.5
    s = np.sort(rng.uniform(0.0, n_int * d, 400))
    if shuffled:
        s = rng.permutation(s)
    k, W0, _, _ = bspline.basis(s, d, n_int)
    cap = rng.uniform(0.1, 2.0, s.size)
    ok = rng.uniform(size=s.size) > 0.2
    got = lp.column_reach(k, W0, cap, n_int + 2, 0.25, ok)
    want = np.full(n_int + 2, np.inf)
    for p in range(s.size):
        for i in range(3):
            if ok[p] and W0[p, i] >= 0.25:
                want[k[p] + i] = min(want[k[p] + i], cap[p] / W0[p, i])
    assert np.isfinite(want).sum() >= n_int  # (most columns have points)
    np.testing.assert_array_equal(got, want)
