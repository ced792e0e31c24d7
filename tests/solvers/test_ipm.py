"""The dense interior point (solvers/ipm.py) against analytic optima, Ipopt (the reference NLP solver) on
random strictly convex problems, and the KKT conditions recomputed by CasADi on non-convex ones."""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from solvers.ipm import TOL_COMPL, TOL_VIOL, DenseIpm

#: Distance of the solution from the analytic optimum (both stop at ~1e-7 complementarity).
X_TOL = 1e-5
#: ... and from Ipopt's on the random convex problems, whose objective is only weakly convex (curvature
#: 0.2 from |x - c|^2 / 10): a weakly active row's slack ~ TOL_COMPL / z moves x; 1,000 random cases
#: read up to 3.7e-5 (the objectives agree to 3e-9, under F_RTOL).  The lifted case seed 4, n 4, 7 rows a
#: variable reads 1.02e-4 (objective 1.1e-8 over Ipopt's, 3.5e-9 relative; the same against Ipopt with
#: bound_relax_factor 0 and constr_viol_tol 1e-12, so it is this method's stopping point, not Ipopt's):
#: 300 other random lifted cases read up to 2.7e-5.
X_TOL_RANDOM = 2e-4
#: Relative objective gap to Ipopt's optimum on the convex problems.
F_RTOL = 1e-7
#: Stationarity residual |grad f + J^T lam_g + lam_x| of a returned point.
KKT_TOL = 1e-5
#: Rows' bound violation allowed in a returned point (the method's own TOL_VIOL).
VIOL_TOL = TOL_VIOL
#: multiplier x slack of a row's bound at a returned point (the method stops at w z <= TOL_COMPL)
COMPL_TOL = 10 * TOL_COMPL
HYPOTHESIS_EXAMPLES = 40


def _ipopt(problem: dict[str, Any], args: dict[str, Any]) -> tuple[np.ndarray, float]:
    s = ca.nlpsol("ref", "ipopt", problem, {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                                           "ipopt.tol": 1e-10})
    r = s(**args)
    assert s.stats()["success"]
    return np.asarray(r["x"]).ravel(), float(r["f"])


def _kkt(problem: dict[str, Any], args: dict[str, Any], res: Any) -> None:
    """Stationarity, feasibility and the multipliers' signs at the returned point, recomputed by CasADi."""
    x, p, f, g = problem["x"], problem["p"], problem["f"], problem["g"]
    fun = ca.Function("kkt", [x, p], [ca.gradient(f, x), g, ca.jacobian(g, x)])
    gf, gv, J = (np.asarray(v) for v in fun(res.x, args["p"]))
    gf, gv = gf.ravel(), gv.ravel()
    assert np.abs(gf + J.T @ res.lam_g + res.lam_x).max() <= KKT_TOL
    assert np.all(gv >= args["lbg"] - VIOL_TOL) and np.all(gv <= args["ubg"] + VIOL_TOL)
    assert np.all(res.x >= args["lbx"] - VIOL_TOL) and np.all(res.x <= args["ubx"] + VIOL_TOL)
    # a multiplier pushes only at its bound: lam_g > 0 at the upper, < 0 at the lower (Ipopt's convention),
    # complementary to the row's slack there
    slack_hi = np.minimum(args["ubg"] - gv, 1e300)
    slack_lo = np.minimum(gv - args["lbg"], 1e300)
    assert np.all(np.maximum(res.lam_g, 0.0) * slack_hi <= COMPL_TOL)
    assert np.all(np.maximum(-res.lam_g, 0.0) * slack_lo <= COMPL_TOL)


def test_linear_objective_on_a_disc_reaches_the_analytic_optimum() -> None:
    """min -x - y s.t. x^2 + y^2 <= 1: x = y = 1 / sqrt 2, the row's multiplier 1 / sqrt 2 (upper bound)."""
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p", 1)
    prob = {"x": x, "p": p, "f": -x[0] - x[1], "g": ca.vertcat(x[0] ** 2 + x[1] ** 2)}
    res = DenseIpm(prob).solve(np.zeros(2), np.zeros(1), np.full(2, -np.inf), np.full(2, np.inf),
                               np.array([-np.inf]), np.array([1.0]))
    assert res.success
    assert np.abs(res.x - 1 / math.sqrt(2)).max() <= X_TOL
    assert abs(res.lam_g[0] - 1 / math.sqrt(2)) <= X_TOL


def test_fixed_variables_and_bounds_are_kept_and_their_multipliers_close_stationarity() -> None:
    """Fixed variables stay at their value, a variable's own bounds hold, and lam_x closes the KKT system:
    min sum (x_i - 2)^2 with x_0 fixed at 0.5, x_1 <= 1, row x_0 + x_2 >= 3 (x_2 = 2.5, its multiplier)."""
    x = ca.SX.sym("x", 3)
    p = ca.SX.sym("p", 1)
    prob = {"x": x, "p": p, "f": ca.sumsqr(x - 2), "g": ca.vertcat(x[0] + x[2])}
    args = {"x0": np.zeros(3), "p": np.zeros(1), "lbx": np.array([0.5, -np.inf, -np.inf]),
            "ubx": np.array([0.5, 1.0, np.inf]), "lbg": np.array([3.0]), "ubg": np.array([np.inf])}
    res = DenseIpm(prob).solve(**args)
    assert res.success
    assert res.x[0] == 0.5
    assert np.abs(res.x - [0.5, 1.0, 2.5]).max() <= X_TOL
    assert abs(res.lam_g[0] + 1.0) <= X_TOL  # d/dx2 (x2 - 2)^2 = 1 = -lam (lower bound: lam < 0)
    assert abs(res.lam_x[1] - 2.0) <= X_TOL  # x_1 at its upper bound 1: 2 (1 - 2) + lam = 0
    _kkt(prob, args, res)


def test_an_infeasible_problem_is_not_reported_solved() -> None:
    """x^2 <= -1 has no solution: the result says so (the caller hands the window to Ipopt)."""
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p", 1)
    prob = {"x": x, "p": p, "f": x[0] + x[1], "g": ca.vertcat(ca.sumsqr(x), x[0] - x[1])}
    res = DenseIpm(prob).solve(np.ones(2), np.zeros(1), np.full(2, -np.inf), np.full(2, np.inf),
                               np.array([-np.inf, -1.0]), np.array([-1.0, 1.0]))
    assert not res.success
    assert res.status != "Solve_Succeeded"


def _random_problem(seed: int, n: int, m: int, convex: bool) -> tuple[dict[str, Any], dict[str, Any]]:
    """min sum w_i / (x_i + 1) + |x - c|^2 / 10 (strictly convex for x > -1) over banded rows like an NLP
    window's: row k reads x_i .. x_i+2.  Convex: a_k . x + b_k |x_(i..i+2)|^2 <= 1 (b_k >= 0); non-convex:
    -1 <= a_k . x + b_k x_i x_i+2 <= 1.  Every row holds at x = 0 (the start, as the LP's hand-over feed)
    and x_0 is fixed (as the inherited state)."""
    rng = np.random.default_rng(seed)
    x = ca.SX.sym("x", n)
    p = ca.SX.sym("p", n)
    rows = []
    for k in range(m):
        i = k % (n - 2)
        a = rng.normal(size=3)
        b = rng.uniform(0.1, 1.0)
        lin = a[0] * x[i] + a[1] * x[i + 1] + a[2] * x[i + 2]
        rows.append(lin + b * (x[i] ** 2 + x[i + 1] ** 2 + x[i + 2] ** 2) if convex else lin + b * x[i] * x[i + 2])
    g = ca.vertcat(*rows)
    f = ca.sum1(p / (x + 1.0)) + ca.sumsqr(x - 0.5) / 10.0
    lbx = np.full(n, -0.9)
    ubx = np.full(n, np.inf)
    lbx[0] = ubx[0] = 0.0
    args = {"x0": np.zeros(n), "p": rng.uniform(0.5, 2.0, n), "lbx": lbx, "ubx": ubx,
            "lbg": np.full(m, -np.inf if convex else -1.0), "ubg": np.ones(m)}
    return {"x": x, "p": p, "f": f, "g": g}, args


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(4, 30), rows_per_var=st.integers(1, 12))
def test_convex_problems_reach_ipopts_optimum(seed: int, n: int, rows_per_var: int) -> None:
    """Strictly convex: one optimum, which Ipopt (tol 1e-10) finds; the dense method's is the same point."""
    prob, args = _random_problem(seed, n, n * rows_per_var, convex=True)
    res = DenseIpm(prob).solve(**args)
    assert res.success, res.status
    x_ref, f_ref = _ipopt(prob, args)
    fun = ca.Function("f", [prob["x"], prob["p"]], [prob["f"]])
    f = float(fun(res.x, args["p"]))
    assert abs(f - f_ref) <= F_RTOL * max(1.0, abs(f_ref))
    assert np.abs(res.x - x_ref).max() <= X_TOL_RANDOM
    _kkt(prob, args, res)


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(4, 30), rows_per_var=st.integers(1, 12))
def test_non_convex_problems_end_at_a_kkt_point_or_say_they_failed(seed: int, n: int, rows_per_var: int) -> None:
    """Non-convex rows (bilinear, two-sided): a solve reported successful is a KKT point (stationary,
    feasible, multipliers on the right side of their bounds); one not finished is never reported solved."""
    prob, args = _random_problem(seed, n, n * rows_per_var, convex=False)
    res = DenseIpm(prob).solve(**args)
    if res.success:
        _kkt(prob, args, res)
    assert np.all(np.isfinite(res.x))


@pytest.mark.parametrize("max_iter", [0, 1, 3])
def test_a_capped_solve_is_not_reported_solved(max_iter: int) -> None:
    """The iteration cap ends a solve unfinished (the convex problem needs more than 3 iterations)."""
    prob, args = _random_problem(7, 20, 200, convex=True)
    res = DenseIpm(prob).solve(**args, max_iter=max_iter)
    assert not res.success
    assert res.iterations == max_iter


def _lifted_problem(seed: int, n: int, m: int) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """The convex rows of ``_random_problem`` read through y = L x as an NLP window's do (``solvers.nlp``:
    y = B0 x, B1 x, B2 x at its checkpoints): row k reads (y0, y1, y2)_k = (x_i + x_i+1) / 2, x_i+1 - x_i,
    x_i - 2 x_i+1 + x_i+2 and is a . y_k + b |y_k|^2 <= 1.  Returns the lifted problem (f and g in y and x,
    with "y" and "L"), the same problem in x alone (y = L x substituted) and the solve's arguments."""
    rng = np.random.default_rng(seed)
    x = ca.SX.sym("x", n)
    p = ca.SX.sym("p", n)
    y = ca.SX.sym("y", 3 * m)
    L = np.zeros((3 * m, n))
    rows = []
    for k in range(m):
        i = k % (n - 2)
        L[3 * k, i : i + 2] = 0.5
        L[3 * k + 1, i : i + 2] = [-1.0, 1.0]
        L[3 * k + 2, i : i + 3] = [1.0, -2.0, 1.0]
        yk = y[3 * k : 3 * k + 3]
        a = rng.normal(size=3)
        rows.append(ca.dot(ca.DM(a), yk) + rng.uniform(0.1, 1.0) * ca.sumsqr(yk))
    g = ca.vertcat(*rows)
    f = ca.sum1(p / (x + 1.0)) + ca.sumsqr(x - 0.5) / 10.0 + 0.01 * ca.sumsqr(y)
    lbx = np.full(n, -0.9)
    ubx = np.full(n, np.inf)
    lbx[0] = ubx[0] = 0.0
    args = {"x0": np.zeros(n), "p": rng.uniform(0.5, 2.0, n), "lbx": lbx, "ubx": ubx,
            "lbg": np.full(m, -np.inf), "ubg": np.ones(m)}
    f_x, g_x = ca.substitute([f, g], [y], [ca.mtimes(ca.DM(L), x)])
    lifted = {"x": x, "p": p, "f": f, "g": g, "y": y, "L": L}
    return lifted, {"x": x, "p": p, "f": f_x, "g": g_x}, args


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(4, 30), rows_per_var=st.integers(1, 12))
@example(seed=4, n=4, rows_per_var=7)  # (the farthest from Ipopt's x found: X_TOL_RANDOM)
def test_lifted_problems_reach_the_optimum_of_the_problem_in_x(seed: int, n: int, rows_per_var: int) -> None:
    """Derivatives taken in (y, x) and carried to x through L are the problem's own: the lifted solve ends at
    Ipopt's optimum of the problem written in x alone, a KKT point of it."""
    lifted, plain, args = _lifted_problem(seed, n, n * rows_per_var)
    res = DenseIpm(lifted).solve(**args)
    assert res.success, res.status
    x_ref, f_ref = _ipopt(plain, args)
    fun = ca.Function("f", [plain["x"], plain["p"]], [plain["f"]])
    assert abs(float(fun(res.x, args["p"])) - f_ref) <= F_RTOL * max(1.0, abs(f_ref))
    assert np.abs(res.x - x_ref).max() <= X_TOL_RANDOM
    _kkt(plain, args, res)
