r"""Probe (session 33): an interior point on the LP that HiGHS solves first in the flower's v + a schedule.

Not the shipped solver: a measurement for the next step.  The flower loop's stage-1 model (1,894 rows, 179
columns; ``solvers.lp.WindowLP`` with HiGHS, ``Options(method="lp", jerk=False)``) is captured as HiGHS gets it
(scaled rows and columns) and solved four ways, each timed as the median of REPEATS in turn:

- HiGHS from its slack basis, as the pipeline runs it (its dual simplex: ~490 iterations);
- Mehrotra's predictor-corrector interior point in numpy, the normal matrix G^T D G banded (``mehrotra``);
- the same compiled (``lp_ipm_probe.c``: a row's two bounds share its coefficients);
- HiGHS from the basis the compiled solution points to (``basis``: the n rows and columns with the largest z / w,
  each at the bound where it is largest, nonbasic; the others basic).

Every finite row bound and column bound is one inequality c = G y + o >= 0 (two per two-sided row; an equality as
two, whose slacks go to 0 together: the infeasible start takes it in its stride), slack w > 0, multiplier z > 0;
minimise cost . y (HiGHS's cost, -w of ``WindowLP``).  Newton step with the slack and multiplier steps eliminated:

    (G^T D G) dy = G^T z - cost + G^T (t / w - z - D r_p),   D = z / w,   r_p = c - w
    dw = G dy + r_p,   dz = t / w - z - D dw

predictor t = 0, corrector t = sigma mu - dw_aff dz_aff with sigma = (mu_aff / mu)^3; steps 0.995 of the way to
the boundary, w and z separately; stop when the residuals and the gap are below TOL (relative).  Each row of G
reads <= 3 consecutive control points (a uniform quadratic B-spline), so G^T D G is pentadiagonal.

Measured in session 33: 15 iterations; the solution within 1.6e-8 of HiGHS's (|y| <= 2), objective 4e-11
relative.  numpy ~1 ms an iteration (overhead-bound), 1.3-1.4x HiGHS's cold run; compiled ~0.15 ms an iteration on
the 2-core machine (its loops over the ~4,000 bounds fused; the scatter-adds into the normal matrix and A^T u are
chained through memory); HiGHS from the basis: 8 iterations to its own vertex (within 1.2e-13), ~2-3 ms, most of it
a run's fixed cost (the basis's factorisation).

In the pipeline (branch ``lp-start``, not merged: ``solvers/lpstart.py``, ``lp.LP_START`` for models of >= 100
columns, the rest shapes' columns placed by reverse Cuthill-McKee): flower v + a 0.91x, with jerk 0.96x (in-process
pairs), the same samples.  Not safe as it is: on random bench seeds 0-699 (lp) four windows' guessed bases left
HiGHS at status NotSet ("excessive primal values"; a retry from the slack basis fixes them), and seed 503's guessed
basis was singular (its 463 x 463 kernel, rows nonbasic x columns basic, cond 1.8e56) and **HiGHS 1.15.1
segfaulted** on it.  Such bases are singular as a rule (the flower's 179 x 179 kernel too: a degenerate vertex has
more active rows than columns in places); HiGHS mends them, so a singularity check rejects them all.  A
rank-revealing choice (branch ``lp-start`` f524bae: greedy by z / w, a row kept only if independent of those kept)
makes the flower's basis optimal as it is (0 iterations), but HiGHS still segfaulted from such bases on seeds 96
and ~397, with highspy 1.15.1 and 1.16.0 alike: not safe in the solving process.

    python -m bench.lp_ipm_probe
"""

from __future__ import annotations

import ctypes
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import highspy
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.typing import NDArray

from bench._common import emit, env_info
from geometry import examples
from geometry import native as gnative
from geometry.native import f64, ptr
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
#: the compiled interior point (the same algorithm, a row's two bounds sharing its coefficients)
C_SOURCE = Path(__file__).with_name("lp_ipm_probe.c")


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


def inequalities(A: sp.csr_matrix, lo: FloatArray, hi: FloatArray, col_lo: FloatArray,
                 col_hi: FloatArray) -> tuple[sp.csr_matrix, FloatArray]:
    """(G, o): c = G y + o >= 0, one row per finite bound of a row of A or a column (an equality, lo = hi, as two:
    their slacks go to 0 together, which the infeasible start takes in its stride on this model)."""
    I = sp.identity(A.shape[1], format="csr")
    blocks, offs = [], []
    for M, lower, upper in ((A, lo, hi), (I, col_lo, col_hi)):
        for b, sgn in ((lower, 1.0), (upper, -1.0)):
            f = np.isfinite(b)
            blocks.append(sgn * M[f])
            offs.append(-sgn * b[f])
    return sp.vstack(blocks, format="csr"), np.concatenate(offs)


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


def _max_step(v: FloatArray, dv: FloatArray) -> float:
    neg = dv < 0.0
    return float(min(1.0, np.min(-v[neg] / dv[neg]))) if neg.any() else 1.0


def mehrotra(G: sp.csr_matrix, o: FloatArray, cost: FloatArray) -> tuple[FloatArray, int]:
    """min cost . y s.t. G y + o >= 0: (y, iterations); raises RuntimeError without convergence."""
    m, n = G.shape
    Gt = G.T.tocsr()
    normal = BandedNormal(G)
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
        solve = _banded_solver(normal(D))
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


# ----- compiled (``lp_ipm_probe.c``), and HiGHS from the basis its solution points to ------------------------------


def _declare(lib: ctypes.CDLL) -> None:
    i, d, P = ctypes.c_int, ctypes.c_double, gnative.P
    lib.fs_lp_ipm.restype = ctypes.c_int
    lib.fs_lp_ipm.argtypes = [i, i, P, P, P, P, P, P, P, P, i, d, i, d, P, P, P, P, P]


def _bandwidth(A: sp.csr_matrix) -> int:
    """The largest spread of the columns within one row of A (the normal matrix's half-bandwidth)."""
    full = np.diff(A.indptr) > 0
    if not full.any():
        return 0
    starts = A.indptr[:-1][full]
    return int(np.max(np.maximum.reduceat(A.indices, starts) - np.minimum.reduceat(A.indices, starts)))


@dataclass(frozen=True)
class Activity:
    """The compiled interior point's result: y (n,), its iterations, and per row and column the largest z / w over
    its bounds (-1 without a finite bound) and whether that bound is the upper one."""

    y: FloatArray
    iterations: int
    ratio_row: FloatArray
    upper_row: NDArray[np.bool_]
    ratio_col: FloatArray
    upper_col: NDArray[np.bool_]


def compiled(A: sp.csr_matrix, lo: FloatArray, hi: FloatArray, col_lo: FloatArray, col_hi: FloatArray,
             cost: FloatArray, tol: float = TOL) -> Activity:
    """min cost . y s.t. lo <= A y <= hi, col_lo <= y <= col_hi (infinite bounds as +-inf), compiled; A's columns
    in their order (banded: the flower's rows read <= 3 consecutive control points)."""
    lib = gnative.load(C_SOURCE, "bench_lp_ipm_probe", _declare)
    if lib is None:
        raise RuntimeError("no C compiler (or FEEDSCHED_NO_COMPILE): the compiled interior point is not available")
    nr, n = A.shape
    indptr, indices, val = A.indptr.astype(np.int32), A.indices.astype(np.int32), f64(A.data)
    lo_c, hi_c, clo_c, chi_c, cost_c = f64(lo), f64(hi), f64(col_lo), f64(col_hi), f64(cost)
    y, rr, rc = np.empty(n), np.empty(nr), np.empty(n)
    ur, uc = np.empty(nr, dtype=np.int32), np.empty(n, dtype=np.int32)
    its = lib.fs_lp_ipm(nr, n, ptr(indptr), ptr(indices), ptr(val), ptr(lo_c), ptr(hi_c), ptr(clo_c), ptr(chi_c),
                        ptr(cost_c), _bandwidth(A), tol, MAX_ITERATIONS, STEP_SHARE, ptr(y), ptr(rr), ptr(ur), ptr(rc),
                        ptr(uc))
    if its < 0:
        raise RuntimeError(f"the compiled interior point stopped with status {its}")
    return Activity(y, int(its), rr, ur.astype(bool), rc, uc.astype(bool))


def basis(act: Activity) -> highspy.HighsBasis:
    """HiGHS's basis with the n rows and columns of the largest z / w nonbasic (each at the bound where it is
    largest: active at the optimum), the others basic."""
    n, nr = act.ratio_col.size, act.ratio_row.size
    ratio = np.concatenate([act.ratio_col, act.ratio_row])
    chosen = np.argpartition(-ratio, n - 1)[:n]
    upper = np.concatenate([act.upper_col, act.upper_row])[chosen]
    S = highspy.HighsBasisStatus
    cols, rows = [S.kBasic] * n, [S.kBasic] * nr
    for e, u in zip(chosen.tolist(), upper.tolist(), strict=True):
        if e < n:
            cols[e] = S.kUpper if u else S.kLower
        else:
            rows[e - n] = S.kUpper if u else S.kLower
    out = highspy.HighsBasis()
    out.col_status, out.row_status = cols, rows
    out.valid = True
    return out


def _bounds(model: highspy.HighsLp) -> tuple[sp.csr_matrix, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The model's rows (CSR) and bounds, HiGHS's infinity as +-inf."""
    a = model.a_matrix_
    if a.format_ != highspy.MatrixFormat.kRowwise:
        raise ValueError("expected HiGHS's model row-wise, as WindowLP passes it")
    A = sp.csr_matrix((np.asarray(a.value_), np.asarray(a.index_), np.asarray(a.start_)),
                      shape=(model.num_row_, model.num_col_))

    def finite(x: Any) -> FloatArray:
        x = np.asarray(x, dtype=np.float64)
        return np.where(x >= highspy.kHighsInf, np.inf, np.where(x <= -highspy.kHighsInf, -np.inf, x))

    return (A, finite(model.row_lower_), finite(model.row_upper_), finite(model.col_lower_),
            finite(model.col_upper_))


def _highs(model: highspy.HighsLp, start: highspy.HighsBasis | None = None) -> tuple[float, int, FloatArray]:
    """HiGHS as ``WindowLP`` sets it up, from its slack basis or ``start``: (seconds, iterations, solution)."""
    h = lp.new_highs()
    h.passModel(model)
    t0 = time.perf_counter()
    if start is not None:
        h.setBasis(start)
    h.run()
    return (time.perf_counter() - t0, int(h.getInfo().simplex_iteration_count),
            np.asarray(h.getSolution().col_value, dtype=np.float64))


def main() -> dict[str, Any]:
    model, y_highs = capture()
    A, lo, hi, col_lo, col_hi = _bounds(model)
    cost = np.asarray(model.col_cost_, dtype=np.float64)
    G, o = inequalities(A, lo, hi, col_lo, col_hi)
    out: dict[str, Any] = {"bench": "lp_ipm_probe", "env": {**env_info(), "repeats": REPEATS}, "rows": model.num_row_,
                           "columns": model.num_col_, "inequalities": int(G.shape[0]), "bandwidth": _bandwidth(A),
                           "max_abs_y": float(np.max(np.abs(y_highs)))}
    keys = ("highs_cold", "ipm_numpy", "ipm_compiled", "basis", "highs_from_basis")
    times: dict[str, list[float]] = {k: [] for k in keys}
    for _ in range(REPEATS):
        t, its, _ = _highs(model)
        times["highs_cold"].append(t)
        out["highs_cold_iterations"] = its
        t0 = time.perf_counter()
        y, its = mehrotra(G, o, cost)
        times["ipm_numpy"].append(time.perf_counter() - t0)
        out["ipm_numpy_iterations"] = its
        out["ipm_numpy_max_abs_diff"] = float(np.max(np.abs(y - y_highs)))
        out["ipm_numpy_objective_rel"] = float((cost @ y - cost @ y_highs) / abs(cost @ y_highs))
        t0 = time.perf_counter()
        act = compiled(A, lo, hi, col_lo, col_hi, cost)
        t1 = time.perf_counter()
        start = basis(act)
        times["ipm_compiled"].append(t1 - t0)
        times["basis"].append(time.perf_counter() - t1)
        out["ipm_compiled_iterations"] = act.iterations
        out["ipm_compiled_max_abs_diff"] = float(np.max(np.abs(act.y - y_highs)))
        t, its, x = _highs(model, start)
        times["highs_from_basis"].append(t)
        out["highs_from_basis_iterations"] = its
        out["highs_from_basis_max_abs_diff"] = float(np.max(np.abs(x - y_highs)))
    med = {k: 1e3 * statistics.median(v) for k, v in times.items()}
    out["median_ms"] = med
    out["ratio_numpy_over_highs"] = med["ipm_numpy"] / med["highs_cold"]
    started = med["ipm_compiled"] + med["basis"] + med["highs_from_basis"]
    out["ratio_ipm_start_over_highs"] = started / med["highs_cold"]
    return out


if __name__ == "__main__":
    emit(main())
