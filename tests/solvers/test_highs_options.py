"""The options HiGHS runs the LP windows with (``solvers.lp.new_highs``) and its second try.

Every first run goes with ``lp.PRESOLVE`` and ``lp.SIMPLEX_SCALE`` (HiGHS's scaling off: the rows and columns
reach it scaled); a window whose run does not reach optimality is solved once more, cold, with the other presolve
setting, ``lp.SIMPLEX_SCALE_RETRY`` (HiGHS's equilibration) and the primal simplex (``lp.SIMPLEX_STRATEGY_RETRY``),
after which the model's later runs (its cut rounds, hot-started) go back to the dual simplex.  Independent truth:
the options HiGHS reports before each run, HiGHS's model status after it, the same schedule without the forced
failure, and the finite differences of the sampled positions (``tests.fdcheck``).
"""

from __future__ import annotations

from typing import Any

import pytest

from geometry import examples as ex
from solvers import lp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.solvers.highs_runs import watch_highs_runs

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
#: Motion time after a second try against the schedule without one, relative (another optimal vertex of
#: integral q at most).
MOTION_REL_TOL = 1e-6
#: Simplex iterations the forced first run may take (far from the optimum: HiGHS stops at its limit).
FORCED_LIMIT = 3
#: HiGHS's ``simplex_strategy`` values: the dual simplex (its default) and the primal.
DUAL, PRIMAL = 1, 4


def _option(h: Any, name: str) -> Any:
    got = h.getOptionValue(name)
    return got[1] if isinstance(got, tuple) else got


def _flower_v_a() -> tuple[Any, Options]:
    return ex.flower(1), Options(method="lp", jerk=False)


def test_first_runs_use_the_configured_options(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[int, str, int]] = []
    watch_highs_runs(monkeypatch, before=lambda h: seen.append((int(_option(h, "simplex_scale_strategy")),
                                                                str(_option(h, "presolve")),
                                                                int(_option(h, "simplex_strategy")))))
    tp, opt = _flower_v_a()
    schedule(tp, router(), opt)
    assert seen, "no HiGHS run"
    assert set(seen) == {(lp.SIMPLEX_SCALE, lp.PRESOLVE, DUAL)}, seen
    assert lp.SIMPLEX_STRATEGY == DUAL


def test_a_run_short_of_optimality_is_solved_again_scaled(monkeypatch: pytest.MonkeyPatch) -> None:
    tp, opt = _flower_v_a()
    plain = schedule(tp, router(), opt)
    runs: list[dict[str, Any]] = []

    def before(h: Any) -> None:
        # the first run of the first window stops after FORCED_LIMIT iterations; every later run is free
        h.setOptionValue("simplex_iteration_limit", FORCED_LIMIT if not runs else 2**31 - 1)
        runs.append({"scale": int(_option(h, "simplex_scale_strategy")), "presolve": str(_option(h, "presolve")),
                     "strategy": int(_option(h, "simplex_strategy"))})

    def after(h: Any) -> None:
        runs[-1]["status"] = str(h.getModelStatus())

    watch_highs_runs(monkeypatch, after=after, before=before)
    sch = schedule(tp, router(), opt)
    assert runs[0] == {"scale": lp.SIMPLEX_SCALE, "presolve": lp.PRESOLVE, "strategy": DUAL,
                       "status": "HighsModelStatus.kIterationLimit"}, runs[0]
    other = "on" if lp.PRESOLVE == "off" else "off"
    assert runs[1] == {"scale": lp.SIMPLEX_SCALE_RETRY, "presolve": other, "strategy": lp.SIMPLEX_STRATEGY_RETRY,
                       "status": "HighsModelStatus.kOptimal"}, runs[1]
    assert lp.SIMPLEX_SCALE_RETRY != lp.SIMPLEX_SCALE and lp.SIMPLEX_STRATEGY_RETRY == PRIMAL
    # the retried model's cut rounds (hot-started from its basis) and every other model: the dual simplex
    assert len(runs) > 2 and {r["strategy"] for r in runs[2:]} == {DUAL}, runs[2:]
    assert float(sch.summary["motion_time"]) == pytest.approx(float(plain.summary["motion_time"]),
                                                              rel=MOTION_REL_TOL)
    vmax, amax, jmax = router().limit_arrays()
    u = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(u[f"{k}{ax}"] for k in "va" for ax in "xyz") <= LIMIT_FACTOR, u
