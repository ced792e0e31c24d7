"""Stage 2 (the jerk rows) going on in stage 1's HiGHS model (``solvers.lp.STAGE2_WARM``).

Stage 1's optimum meets every stage-2 row but the jerk rows, so the dual simplex goes on from its basis
instead of starting over.  Independent truth: the same schedule with stage 2 from scratch (STAGE2_WARM off),
the finite differences of the sampled positions (``tests.fdcheck``), and HiGHS's own iteration counts.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp

from geometry import Toolpath, primitives
from geometry import examples as ex
from solvers import lp
from solvers.errors import InfeasibleError
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.solvers.highs_runs import watch_highs_runs

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
#: Motion time warm against from scratch, relative (another optimal vertex of integral q: measured <= 2e-7).
MOTION_REL_TOL = 1e-6


def _runs(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int]]:
    """(rows, simplex iterations) of every HiGHS run."""
    seen: list[tuple[int, int]] = []
    watch_highs_runs(monkeypatch, after=lambda h: seen.append((int(h.getNumRow()),
                                                                int(h.getInfo().simplex_iteration_count))))
    return seen


@pytest.mark.parametrize("name", ["flower", "line"])
def test_stage2_goes_on_from_stage1s_basis(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    tp = ex.flower(1) if name == "flower" else Toolpath([primitives.line((0.0, 0.0, 0.0), (20.0, 6.0, 2.0))])
    runs = _runs(monkeypatch)
    sch = schedule(tp, router(), Options(method="lp"))
    warm = list(runs)
    runs.clear()
    monkeypatch.setattr(lp, "STAGE2_WARM", False)
    cold = schedule(tp, router(), Options(method="lp"))
    assert float(sch.summary["motion_time"]) == pytest.approx(float(cold.summary["motion_time"]), rel=MOTION_REL_TOL)
    # the same model grows (stage 1's rows kept): stage 2's first run has more rows than stage 1's last, and
    # (measured: flower 44 against 290, line 8 against 120) far fewer iterations than from scratch
    first_cold_stage2 = next(i for i in range(1, len(runs)) if runs[i][0] > runs[i - 1][0] + 200)
    first_warm_stage2 = next(i for i in range(1, len(warm)) if warm[i][0] > warm[i - 1][0] + 200)
    assert warm[first_warm_stage2][1] < 0.5 * runs[first_cold_stage2][1], (warm, runs)
    # stage 1's velocity rows take q <= q* in place: the warm model is not much larger than the cold one (its
    # extra rows are stage 1's cut rows and velocity rows at points q* does not need; measured +8 % / +0 %)
    assert warm[first_warm_stage2][0] <= 1.15 * runs[first_cold_stage2][0], (warm, runs)
    assert int(sch.summary["solver_iterations"]) < int(cold.summary["solver_iterations"])
    vmax, amax, jmax = router().limit_arrays()
    u = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(u.values()) <= LIMIT_FACTOR, u


def test_a_failed_warm_stage2_is_solved_from_scratch(monkeypatch: pytest.MonkeyPatch) -> None:
    tp = Toolpath([primitives.line((0.0, 0.0, 0.0), (20.0, 6.0, 2.0))])
    cold_opt = Options(method="lp")
    monkeypatch.setattr(lp, "STAGE2_WARM", False)
    cold = schedule(tp, router(), cold_opt)
    monkeypatch.setattr(lp, "STAGE2_WARM", True)
    jerk_rows = lp.WindowLP._jerk_rows
    failed: list[int] = []

    def jerk_or_fail(self: lp.WindowLP, rows: Any, *args: Any) -> None:
        if rows.highs is not None and not failed:  # the warm model (stage 1's, already solved): fail it
            failed.append(1)
            raise InfeasibleError("injected", window=self.spec.index)
        jerk_rows(self, rows, *args)

    monkeypatch.setattr(lp.WindowLP, "_jerk_rows", jerk_or_fail)
    sch = schedule(tp, router(), cold_opt)
    assert failed
    assert float(sch.summary["motion_time"]) == pytest.approx(float(cold.summary["motion_time"]), rel=1e-12)


def test_bounds_changed_in_place_give_the_fresh_models_optimum() -> None:
    """``_Rows.change_bounds`` on rows already in the HiGHS model (scaled as they were passed), then a hot
    re-solve: the same optimum as a model built from scratch with the new bounds (HiGHS on both)."""
    rng = np.random.default_rng(7)
    n = 12

    def model(hi_first: np.ndarray) -> lp._Rows:
        rows = lp._Rows(n)
        A1 = sp.csr_matrix(rng_a1)
        rows.add(A1, np.zeros(A1.shape[0]), hi_first)
        rows.add(sp.csr_matrix(rng_a2), -np.full(rng_a2.shape[0], 20.0), np.full(rng_a2.shape[0], 20.0))
        return rows

    rng_a1 = np.abs(rng.normal(size=(20, n))) * (rng.uniform(size=(20, n)) < 0.4) + np.eye(20, n)
    rng_a2 = rng.normal(size=(30, n)) * (rng.uniform(size=(30, n)) < 0.3)
    w = rng.uniform(0.5, 1.0, size=n)
    lo_c, hi_c = np.zeros(n), np.full(n, 50.0)
    hi1 = rng.uniform(5.0, 10.0, size=20)
    hi2 = hi1 * rng.uniform(0.3, 1.0, size=20)

    def solve(rows: lp._Rows) -> np.ndarray:
        win = lp.WindowLP.__new__(lp.WindowLP)  # (only ``_highs`` and its run: no window geometry)
        win.iterations = 0
        win.fallback_left = False
        win.spec = type("S", (), {"index": 0})()
        return win._highs(rows, w, lo_c, hi_c)

    hot = model(hi1)
    solve(hot)
    hot.change_bounds(0, np.zeros(20), hi2)
    x_hot = solve(hot)
    x_fresh = solve(model(hi2))
    assert float(w @ x_hot) == pytest.approx(float(w @ x_fresh), rel=1e-9)
    assert np.all(rng_a1 @ x_hot <= hi2 * (1 + 1e-7) + 1e-9)
    # the new bounds bind (the test would not see them otherwise)
    assert np.any(rng_a1 @ x_hot >= hi2 * (1 - 1e-7)) and float(w @ x_fresh) < float(w @ solve(model(hi1))) - 1e-6
