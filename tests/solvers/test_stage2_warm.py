"""Stage 2 (the jerk rows) going on in stage 1's HiGHS model (``solvers.lp.STAGE2_WARM``).

Stage 1's optimum meets every stage-2 row but the jerk rows, so the dual simplex goes on from its basis
instead of starting over.  Independent truth: the same schedule with stage 2 from scratch (STAGE2_WARM off),
the finite differences of the sampled positions (``tests.fdcheck``), and HiGHS's own iteration counts.
"""

from __future__ import annotations

from typing import Any

import pytest

from geometry import Toolpath, primitives
from geometry import examples as ex
from solvers import lp
from solvers.errors import InfeasibleError
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
#: Motion time warm against from scratch, relative (another optimal vertex of integral q: measured <= 2e-7).
MOTION_REL_TOL = 1e-6


def _runs(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int]]:
    """(rows, simplex iterations) of every HiGHS run."""
    seen: list[tuple[int, int]] = []
    run = lp.WindowLP._timed_run

    def counted(h: Any) -> None:
        run(h)
        seen.append((int(h.getNumRow()), int(h.getInfo().simplex_iteration_count)))

    monkeypatch.setattr(lp.WindowLP, "_timed_run", staticmethod(counted))
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
