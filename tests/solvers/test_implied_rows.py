"""Rows one axis implies for another (``solvers.lp.implied_rows``, ``PARALLEL_ROW_TOL``).

At a point where two axes' acceleration (or jerk) rows are multiples of one row, v_x = lambda v_y with
|lambda| <= 1, x's row holds whenever y's does and is left out of the LP.  On a straight line this is every
point (x_ss = x_sss = 0).

Independent truth: brute force over random points z for the implication itself, and for the LP the same
schedule with every row kept (PARALLEL_ROW_TOL < 0: nothing is parallel) and the finite differences of the
sampled positions (``tests.fdcheck``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from geometry import Toolpath, primitives
from solvers import lp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
#: Motion time with the implied rows left out against all rows kept, relative (measured <= 3e-14 on these lines).
MOTION_REL_TOL = 1e-9
#: Random points z per case in the brute-force check of the implication.
PROBES = 2000


def test_parallel_rows_the_larger_implies_the_smaller() -> None:
    rng = np.random.default_rng(3)
    K = 200
    base = rng.normal(size=(K, 3))
    lam = rng.uniform(-1.5, 1.5, size=K)
    other = rng.normal(size=(K, 3))  # not parallel to base (almost surely)
    vecs = {0: base, 1: lam[:, None] * base, 2: other}
    out = lp.implied_rows(vecs)
    # axis 1 is implied where |lambda| <= 1, axis 0 where |lambda| > 1; axis 2 never
    assert np.array_equal(out[1], np.abs(lam) <= 1.0)
    assert np.array_equal(out[0], np.abs(lam) > 1.0)
    assert not out[2].any()
    # brute force: wherever a row is left out, every z meeting the kept rows meets it too
    z = rng.normal(size=(PROBES, 3)) * 10.0
    for ax, implied in out.items():
        for k in np.flatnonzero(implied):
            kept = [b for b in vecs if not out[b][k]]
            ok = np.all([np.abs(z @ vecs[b][k]) <= 1.0 for b in kept], axis=0)
            assert np.all(np.abs(z[ok] @ vecs[ax][k]) <= 1.0 + 1e-12)


def test_equal_rows_keep_exactly_one_and_zero_rows_go() -> None:
    v = np.array([[0.0, 2.0], [1.0, 0.0], [0.0, 0.0]])
    out = lp.implied_rows({0: v, 1: v.copy(), 2: np.array([[0.0, -3.0], [0.0, 1.0], [0.0, 1.0]])})
    # point 0: axis 2 (norm 3) implies both; point 1: the first of the equal pair keeps its row, axis 2 is not
    # parallel; point 2: the zero rows of axes 0 and 1 are implied by anything
    assert out[0].tolist() == [True, False, True]
    assert out[1].tolist() == [True, True, True]
    assert out[2].tolist() == [False, False, False]


def test_two_dimensional_rows_off_parallel_are_kept() -> None:
    u = np.array([[1.0, 0.0]])
    for angle in (1e-9, 1e-6, 0.3):
        v = 0.5 * np.array([[np.cos(angle), np.sin(angle)]])
        out = lp.implied_rows({0: u, 1: v})
        assert not out[0].any() and not out[1].any(), angle
    v = 0.5 * np.array([[1.0, 1e-14]])
    assert lp.implied_rows({0: u, 1: v})[1].all()


def _rows_passed(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    rows: list[int] = []
    run = lp.WindowLP._timed_run

    def counted(h: Any) -> None:
        run(h)
        rows.append(int(h.getNumRow()))

    monkeypatch.setattr(lp.WindowLP, "_timed_run", staticmethod(counted))
    return rows


@pytest.mark.parametrize("end", [(0.4, 0.3, 0.0), (3.0, -2.0, 1.5)])
@pytest.mark.parametrize("jerk", [False, True])
def test_lines_solve_on_fewer_rows_to_the_same_motion(monkeypatch: pytest.MonkeyPatch, end: tuple[float, ...],
                                                      jerk: bool) -> None:
    tp = Toolpath([primitives.line((0.0, 0.0, 0.0), end)])
    opt = Options(method="lp", jerk=jerk)
    rows = _rows_passed(monkeypatch)
    sch = schedule(tp, router(), opt)
    fewer = list(rows)
    rows.clear()
    # the same line along x alone: one moving axis, nothing to leave out, the same points (same length)
    schedule(Toolpath([primitives.line((0.0, 0.0, 0.0), (float(np.linalg.norm(end)), 0.0, 0.0))]), router(), opt)
    one_axis = list(rows)
    rows.clear()
    monkeypatch.setattr(lp, "PARALLEL_ROW_TOL", -1.0)
    full = schedule(tp, router(), opt)
    # each stage's first solve has the rows of one moving axis, where all of them had every moving axis's
    assert fewer[0] == one_axis[0] < rows[0]
    if jerk:  # stage 2 (v + a rows under q <= q*, and the jerk rows): within a few rows of one axis's (measured 0-2)
        assert abs(fewer[1] - one_axis[1]) <= 0.01 * one_axis[1] and fewer[1] < rows[1], (fewer, one_axis, rows)
    assert sum(fewer) < sum(rows)
    assert float(sch.summary["motion_time"]) == pytest.approx(float(full.summary["motion_time"]), rel=MOTION_REL_TOL)
    vmax, amax, jmax = router().limit_arrays()
    u = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(v for k, v in u.items() if jerk or k[0] in "va") <= LIMIT_FACTOR, u
