r"""Probe (session 33): an interior-point method on the LP that HiGHS solves first in the flower's v + a schedule.

Not the shipped solver: a measurement for the next step.  The flower loop's stage-1 model (1,894 rows, 179
columns; ``solvers.lp.WindowLP`` with HiGHS, ``Options(method="lp", jerk=False)``) is captured as HiGHS gets
it (scaled rows and columns) and solved three ways, each timed as the median of REPEATS in turn:

- HiGHS from scratch (its dual simplex, as the pipeline runs it: ~490 iterations);
- a Mehrotra predictor-corrector interior point in numpy with the normal matrix G^T D G banded;
- the same, with a dense Cholesky (the iteration count and solution are the same: a check of the banded one).

Every finite row bound and column bound is one inequality c = G y + o >= 0 (two per two-sided row), slack
w > 0, multiplier z > 0; minimise cost . y (HiGHS's cost, -w of ``WindowLP``).  Newton step with the slack
and multiplier steps eliminated:

    (G^T D G) dy = G^T z - cost + G^T (t / w - z - D r_p),   D = z / w,   r_p = c - w
    dw = G dy + r_p,   dz = t / w - z - D dw

predictor t = 0, corrector t = sigma mu - dw_aff dz_aff with sigma = (mu_aff / mu)^3; steps 0.995 of the way to
the boundary, w and z separately; stop when the residuals and the gap are below TOL (relative).  Each row of G
reads <= 3 consecutive control points (a uniform quadratic B-spline), so G^T D G is pentadiagonal; it is formed by
one ``bincount`` over each row's pairs of non-zeros.

Measured in session 33 (one run): 15 iterations; the solution within 1.6e-8 of HiGHS's (|y| <= 2), objective
4e-11 relative; numpy banded ~15 ms (~1 ms an iteration, ~30 numpy calls on arrays of 4,140-20,796 elements:
overhead-bound), HiGHS ~7-10 ms.  A compiled kernel would do an iteration's ~100 kflop in ~0.05 ms.

    python -m bench.lp_ipm_probe
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

import highspy
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.typing import NDArray

from bench._common import emit, env_info
from geometry import examples
from solvers import lp
from solvers.machine import router
from solvers.pipeline import Options, schedule

FloatArray = NDArray[np.float64]

#: relative tolerance of the residuals and the gap
TOL = 1e-9
MAX_ITERATIONS = 80
#: share of the way to the boundary of w and z
STEP_SHARE = 0.995
REPEATS = 7


def capture() -> tuple[highspy.HighsLp, FloatArray]:
    """The first HiGHS model of the flower's v + a schedule as passed to HiGHS, and HiGHS's solution of it."""
    seen: list[Any] = []
    run = lp.WindowLP.__dict__["_timed_run"].__func__

    def keep(h: highspy.Highs) -> None:
        if not seen:
            seen.append(h.getLp())
            run(h)
            seen.append(np.asarray(h.getSolution().col_value, dtype=np.float64))
        else:
            run(h)

    lp.WindowLP._timed_run = staticmethod(keep)  # type: ignore[method-assign]
    try:
        schedule(examples.flower(1), router(), Options(method="lp", jerk=False))
    finally:
        lp.WindowLP._timed_run = staticmethod(run)  # type: ignore[method-assign]
    return seen[0], seen[1]


def inequalities(model: highspy.HighsLp) -> tuple[sp.csr_matrix, FloatArray, FloatArray]:
    """(G, o, cost): c = G y + o >= 0, one row per finite bound of a row or a column (an equality, lo = hi, as
    two: their slacks go to 0 together, which the infeasible start takes in its stride on this model)."""
    n, m = model.num_col_, model.num_row_
    a = model.a_matrix_
    if a.format_ != highspy.MatrixFormat.kRowwise:
        raise ValueError("expected HiGHS's model row-wise, as WindowLP passes it")
    A = sp.csr_matrix((np.asarray(a.value_), np.asarray(a.index_), np.asarray(a.start_)), shape=(m, n))
    I = sp.identity(n, format="csr")
    blocks, offs = [], []
    for M, lo, hi in ((A, model.row_lower_, model.row_upper_), (I, model.col_lower_, model.col_upper_)):
        for b, sgn in ((np.asarray(lo), 1.0), (np.asarray(hi), -1.0)):
            f = np.isfinite(b) & (np.abs(b) < highspy.kHighsInf)
            blocks.append(sgn * M[f])
            offs.append(-sgn * b[f])
    return sp.vstack(blocks, format="csr"), np.concatenate(offs), np.asarray(model.col_cost_, dtype=np.float64)


class BandedNormal:
    """G^T diag(D) G of G (m, n) in LAPACK's lower band form (bw + 1, n), by one ``bincount`` over each row's
    pairs of non-zeros."""

    def __init__(self, G: sp.csr_matrix) -> None:
        ptr, ind, val = G.indptr, G.indices, G.data
        per_row = np.diff(ptr)
        rows = np.repeat(np.arange(G.shape[0]), per_row)
        P, Q = [], []
        for k in range(int(per_row.max())):
            for l in range(k + 1):
                has = per_row > k
                P.append(ptr[:-1][has] + k)
                Q.append(ptr[:-1][has] + l)
        p, q = np.concatenate(P), np.concatenate(Q)
        hi, lo = np.maximum(ind[p], ind[q]), np.minimum(ind[p], ind[q])
        self.n = G.shape[1]
        self.bw = int(np.max(hi - lo))
        self.index = (hi - lo) * self.n + lo
        self.value = val[p] * val[q]
        self.row = rows[p]

    def __call__(self, D: FloatArray) -> FloatArray:
        return np.asarray(np.bincount(self.index, weights=D[self.row] * self.value,
                                     minlength=(self.bw + 1) * self.n), dtype=np.float64).reshape(self.bw + 1, self.n)


def _banded_solver(ab: FloatArray) -> Callable[[FloatArray], FloatArray]:
    factor = sla.cholesky_banded(ab, lower=True)
    return lambda rhs: np.asarray(sla.cho_solve_banded((factor, True), rhs), dtype=np.float64)


def _dense_solver(M: FloatArray) -> Callable[[FloatArray], FloatArray]:
    cf = sla.cho_factor(M)
    return lambda rhs: np.asarray(sla.cho_solve(cf, rhs), dtype=np.float64)


def _max_step(v: FloatArray, dv: FloatArray) -> float:
    neg = dv < 0.0
    return float(min(1.0, np.min(-v[neg] / dv[neg]))) if neg.any() else 1.0


def mehrotra(G: sp.csr_matrix, o: FloatArray, cost: FloatArray, banded: bool) -> tuple[FloatArray, int]:
    """min cost . y s.t. G y + o >= 0: (y, iterations); raises RuntimeError without convergence."""
    m, n = G.shape
    Gt = G.T.tocsr()
    normal = BandedNormal(G) if banded else None
    y = np.zeros(n)
    w = np.maximum(G @ y + o, 1.0)
    z = np.ones(m)
    scale_p, scale_d = 1.0 + float(np.max(np.abs(o))), 1.0 + float(np.max(np.abs(cost)))
    for it in range(MAX_ITERATIONS):
        rp = G @ y + o - w
        Gtz = Gt @ z
        mu = float(w @ z) / m
        if (np.max(np.abs(rp)) < TOL * scale_p and np.max(np.abs(cost - Gtz)) < TOL * scale_d
                and mu * m < TOL * (1.0 + abs(float(cost @ y)))):
            return y, it
        D = z / w
        if normal is not None:
            solve = _banded_solver(normal(D))
        else:
            solve = _dense_solver((Gt @ sp.diags(D) @ G).toarray())
        base = Gtz - cost

        def direction(t: FloatArray, w: FloatArray = w, z: FloatArray = z, D: FloatArray = D, rp: FloatArray = rp,
                      base: FloatArray = base, solve: Callable[[FloatArray], FloatArray] = solve,
                      ) -> tuple[FloatArray, FloatArray, FloatArray]:
            dy = solve(base + Gt @ (t / w - z - D * rp))
            dw = G @ dy + rp
            return dy, dw, t / w - z - D * dw

        dy, dw, dz = direction(np.zeros(m))
        mu_aff = float((w + _max_step(w, dw) * dw) @ (z + _max_step(z, dz) * dz)) / m
        dy, dw, dz = direction((mu_aff / mu) ** 3 * mu - dw * dz)
        ap, ad = STEP_SHARE * _max_step(w, dw), STEP_SHARE * _max_step(z, dz)
        y, w, z = y + ap * dy, w + ap * dw, z + ad * dz
    raise RuntimeError(f"no convergence in {MAX_ITERATIONS} iterations")


def _highs_cold(model: highspy.HighsLp) -> tuple[float, int]:
    h = highspy.Highs()  # type: ignore[no-untyped-call]
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", lp.PRESOLVE)
    h.setOptionValue("simplex_dual_edge_weight_strategy", lp.DUAL_EDGE_WEIGHT)
    h.setOptionValue("simplex_scale_strategy", lp.SIMPLEX_SCALE)
    h.passModel(model)
    t0 = time.perf_counter()
    h.run()
    return time.perf_counter() - t0, int(h.getInfo().simplex_iteration_count)


def main() -> dict[str, Any]:
    model, y_highs = capture()
    G, o, cost = inequalities(model)
    out: dict[str, Any] = {"bench": "lp_ipm_probe", "env": {**env_info(), "repeats": REPEATS}, "rows": model.num_row_,
                           "columns": model.num_col_, "inequalities": int(G.shape[0])}
    times: dict[str, list[float]] = {"highs": [], "ipm_banded": [], "ipm_dense": []}
    for _ in range(REPEATS):
        t, its = _highs_cold(model)
        times["highs"].append(t)
        out["highs_iterations"] = its
        for key, banded in (("ipm_banded", True), ("ipm_dense", False)):
            t0 = time.perf_counter()
            y, its = mehrotra(G, o, cost, banded)
            times[key].append(time.perf_counter() - t0)
            out[f"{key}_iterations"] = its
            out[f"{key}_max_abs_diff"] = float(np.max(np.abs(y - y_highs)))
            out[f"{key}_objective_rel"] = float((cost @ y - cost @ y_highs) / abs(cost @ y_highs))
    out["bandwidth"] = BandedNormal(G).bw
    out["max_abs_y"] = float(np.max(np.abs(y_highs)))
    out["median_ms"] = {k: 1e3 * statistics.median(v) for k, v in times.items()}
    out["ratio_banded_over_highs"] = out["median_ms"]["ipm_banded"] / out["median_ms"]["highs"]
    return out


if __name__ == "__main__":
    emit(main())
