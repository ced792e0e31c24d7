"""Rows the LP leaves out because other rows at the same point hold them.

``solvers.lp.implied_rows``: where two axes' acceleration (or jerk) rows are multiples of one row,
v_x = lambda v_y with |lambda| <= 1, x's row holds whenever y's does (a straight line: every point).
``solvers.lp.held_rows``: in stage 1 the velocity row where two axes' slabs bound q below it, or a slab whose
p-interval contains another's over 0 <= q <= ub.

Independent truth: brute force over random points z, and scipy's linprog on each point's 2-D rows, for the
implications themselves; for the LP the same schedule with every row kept (PARALLEL_ROW_TOL < 0,
POINT_HELD_ROWS off) and the finite differences of the sampled positions (``tests.fdcheck``).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from geometry import Toolpath, primitives
from geometry import examples as ex
from solvers import lp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.solvers.highs_runs import watch_highs_runs

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
#: Motion time with the implied rows left out against all rows kept, relative: v + a measured <= 3e-14 on these
#: lines; with jerk (the LP's rest shapes) 3e-14 until session 47, 7.5e-6 / 3.8e-7 with its steeper rises
#: (``bspline.LP_REST_RISE_POWERS``; integral q within 3e-6: HiGHS meets the optimum of the larger model only to
#: its tolerances, and the rows left out change the cut rounds' points), 3.3e-4 (the shorter line, the fewer rows'
#: motion the longer) with the rows at a quarter octave towards rest (``lp.REST_ROW_R``), 1.08e-3 (the fewer rows'
#: motion the shorter) with stage 2's q* capped at the reach from rest (``lp.QSTAR_REST_REACH``: integral q weighs
#: the ramp from rest little, and the two models' vertices leave rest differently).
MOTION_REL_TOL = {False: 1e-9, True: 2e-3}
#: ... on the flower with the held rows left out against all kept (v + a: the same to 1e-12; with jerk 2e-7,
#: another optimal vertex of integral q).
HELD_MOTION_REL_TOL = 1e-6
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
    watch_highs_runs(monkeypatch, after=lambda h: rows.append(int(h.getNumRow())))
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
    assert float(sch.summary["motion_time"]) == pytest.approx(float(full.summary["motion_time"]),
                                                              rel=MOTION_REL_TOL[jerk])
    vmax, amax, jmax = router().limit_arrays()
    u = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(v for k, v in u.items() if jerk or k[0] in "va") <= LIMIT_FACTOR, u


def _max_over(rows: list[tuple[np.ndarray, float, float]], target: np.ndarray) -> float:
    """max target . z over lo <= n . z <= hi for the rows (n, lo, hi), z = (q, p) or (q, p, r) (scipy linprog; inf
    if unbounded)."""
    A = np.array([n for n, _, _ in rows] + [-n for n, _, _ in rows])
    b = np.array([hi for _, _, hi in rows] + [-lo for _, lo, _ in rows])
    keep = np.isfinite(b)
    res = linprog(-target, A_ub=A[keep], b_ub=b[keep], bounds=[(None, None)] * target.size, method="highs")
    assert res.status in (0, 3), res.message
    return np.inf if res.status == 3 else float(-res.fun)


@pytest.mark.parametrize("seed", range(4))
def test_held_rows_are_held_by_the_rows_kept(seed: int) -> None:
    """Every row left out meets its bound all over the polygon of the rows kept at its point (q >= 0: the columns)."""
    rng = np.random.default_rng(seed)
    K = 300
    axes = [0, 1, 2][: 2 + seed % 2]
    alpha = {ax: rng.normal(size=K) * rng.choice([0.0, 1.0, 10.0], size=K) for ax in axes}
    beta = {ax: rng.normal(size=K) * rng.choice([0.0, 1.0, 1.0, 5.0], size=K) for ax in axes}
    ub = rng.uniform(0.05, 3.0, size=K)
    plain = rng.uniform(size=K) < 0.9
    implied = {ax: np.zeros(K, dtype=bool) for ax in axes}
    v_held, a_held = lp.held_rows(alpha, beta, ub, plain, implied)
    assert v_held.any() and any(h.any() for h in a_held.values())
    assert not (v_held & ~plain).any() and not any((h & ~plain).any() for h in a_held.values())
    for k in range(K):
        held_here = [ax for ax in axes if a_held[ax][k]]
        assert not (v_held[k] and held_here), "the velocity row and a slab both left out"
        kept: list[tuple[np.ndarray, float, float]] = [(np.array([1.0, 0.0]), 0.0, np.inf)]  # q >= 0 (columns)
        if not v_held[k]:
            kept.append((np.array([1.0, 0.0]), -np.inf, float(ub[k])))
        kept += [(np.array([alpha[ax][k], beta[ax][k]]), -1.0, 1.0) for ax in axes if not a_held[ax][k]]
        if v_held[k]:
            assert _max_over(kept, np.array([1.0, 0.0])) <= ub[k] * (1.0 + 1e-9)
        for ax in held_here:
            n = np.array([alpha[ax][k], beta[ax][k]])
            assert max(_max_over(kept, n), _max_over(kept, -n)) <= 1.0 + 1e-9, (k, ax)


def test_held_rows_keep_rows_that_bind() -> None:
    """Two slabs crossing at right angles in (q, p) with U between the parallelogram's corners: nothing held."""
    alpha = {0: np.array([1.0]), 1: np.array([-1.0])}
    beta = {0: np.array([1.0]), 1: np.array([1.0])}
    # the parallelogram's largest q is (1 + 1) / |1 + 1| = 1: a velocity row at 0.9 binds, at 1.1 it is held
    for U, held in ((0.9, False), (1.1, True)):
        v, a = lp.held_rows(alpha, beta, np.array([U]), np.array([True]), {0: np.array([False]), 1: np.array([False])})
        assert bool(v[0]) is held and not a[0].any() and not a[1].any()


@pytest.mark.parametrize("jerk", [False, True])
def test_flower_solves_on_fewer_rows_to_the_same_motion(monkeypatch: pytest.MonkeyPatch, jerk: bool) -> None:
    tp = ex.flower(1)
    opt = Options(method="lp", jerk=jerk)
    rows = _rows_passed(monkeypatch)
    monkeypatch.setattr(lp, "POINT_HELD_ROWS", True)  # (the default: set here as this test is about it)
    sch = schedule(tp, router(), opt)
    fewer = list(rows)
    rows.clear()
    monkeypatch.setattr(lp, "POINT_HELD_ROWS", False)
    full = schedule(tp, router(), opt)
    # measured: 1,894 of 2,660 rows in the first solve; with jerk, stage 2's first solve 3,698 of 5,048
    assert fewer[0] < 0.8 * rows[0], (fewer, rows)
    if jerk:
        stage2 = 2  # (stage 1 and its cut round before it: the same count of solves either way, measured)
        assert len(fewer) == len(rows) and fewer[stage2] < 0.8 * rows[stage2], (fewer, rows)
    assert float(sch.summary["motion_time"]) == pytest.approx(float(full.summary["motion_time"]),
                                                              rel=HELD_MOTION_REL_TOL)
    vmax, amax, jmax = router().limit_arrays()
    u = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(v for k, v in u.items() if jerk or k[0] in "va") <= LIMIT_FACTOR, u


@pytest.mark.parametrize("seed", range(3))
def test_held_jerk_rows_are_held_by_the_rows_kept(seed: int) -> None:
    """Every jerk row left out meets its bound all over the polytope of the point's stage-1 rows (velocity,
    q >= 0, every acceleration slab) and the jerk rows kept."""
    rng = np.random.default_rng(100 + seed)
    K = 200
    axes = [0, 1, 2][: 2 + seed % 2]
    acc = {ax: (rng.normal(size=K), rng.normal(size=K) * rng.choice([0.0, 1.0, 3.0], size=K)) for ax in axes}
    jerk = {ax: (rng.normal(size=K) * 0.3, rng.normal(size=K), rng.normal(size=K) * rng.choice([0.0, 0.2, 1.0, 4.0],
                                                                                                size=K))
            for ax in axes}
    ub = rng.uniform(0.05, 2.0, size=K)
    plain = rng.uniform(size=K) < 0.9
    implied = {ax: np.zeros(K, dtype=bool) for ax in axes}
    held = lp.held_jerk_rows(acc, jerk, ub, plain, implied)
    assert any(h.any() for h in held.values())
    assert not any((h & ~plain).any() for h in held.values())
    for k in range(K):
        base = [(np.array([1.0, 0.0, 0.0]), 0.0, float(ub[k]))]
        base += [(np.array([a[k], b[k], 0.0]), -1.0, 1.0) for a, b in acc.values()]
        kept = base + [(np.array([g[k], d[k], e[k]]), -1.0, 1.0) for ax, (g, d, e) in jerk.items()
                       if not held[ax][k]]
        for ax in axes:
            if held[ax][k]:
                n = np.array([c[k] for c in jerk[ax]])
                assert max(_max_over(kept, n), _max_over(kept, -n)) <= 1.0 + 1e-9, (k, ax)


@pytest.mark.parametrize("seed", range(4))
def test_one_row_a_point_holds_nothing_and_is_told_at_once(monkeypatch: pytest.MonkeyPatch, seed: int) -> None:
    """Where at most one axis's row is left at each point (the others ``implied``), ``held_rows`` and
    ``held_jerk_rows`` return at once (``lp._one_row_each``): the same masks as their whole evaluation, which the
    random points above check against ``linprog``.  Half the seeds give one point two rows (the whole evaluation
    runs), half give flat rows (beta = 0, eps = 0: the rules of one row alone, which can hold)."""
    rng = np.random.default_rng(300 + seed)
    K, axes = 200, [0, 1, 2]
    live = rng.integers(0, 3, size=K)  # the one axis whose row is left at each point
    implied = {ax: live != ax for ax in axes}
    if seed % 2:
        implied[(int(live[7]) + 1) % 3][7] = False  # a second row at point 7
    flat = rng.uniform(size=K) < (0.1 if seed >= 2 else 0.0)
    alpha = {ax: rng.normal(size=K) * 3.0 for ax in axes}
    beta = {ax: np.where(flat, 0.0, rng.normal(size=K)) for ax in axes}
    acc = {ax: (alpha[ax], np.where(flat, 1.0, beta[ax])) for ax in axes}
    jerk = {ax: (rng.normal(size=K), rng.normal(size=K), np.where(flat, 0.0, rng.normal(size=K))) for ax in axes}
    ub = rng.uniform(0.05, 3.0, size=K)
    plain = rng.uniform(size=K) < 0.9
    quick = (lp.held_rows(alpha, beta, ub, plain, implied), lp.held_jerk_rows(acc, jerk, ub, plain, implied))
    told = lp._one_row_each(implied, {ax: beta[ax] == 0.0 for ax in axes}, plain & np.isfinite(ub))
    assert told == (seed == 0), told
    monkeypatch.setattr(lp, "_one_row_each", lambda *args: False)
    whole = (lp.held_rows(alpha, beta, ub, plain, implied), lp.held_jerk_rows(acc, jerk, ub, plain, implied))
    np.testing.assert_array_equal(quick[0][0], whole[0][0])
    for ax in axes:
        np.testing.assert_array_equal(quick[0][1][ax], whole[0][1][ax])
        np.testing.assert_array_equal(quick[1][ax], whole[1][ax])
    if seed >= 2:  # flat rows: the one-row rules hold some (returning at once would have missed them)
        masks = [whole[0][0], *whole[0][1].values(), *whole[1].values()]
        assert any(h.any() for h in masks)
