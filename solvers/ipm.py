r"""A dense, condensed primal-dual interior-point method for NLPs with few variables and many inequality rows.

An NLP window (``solvers.nlp``) has ~40 variables (feed control points) and 1,200-1,700 rows (u, e, feed
per checkpoint and axis).  Ipopt factors the (n + m)-sized augmented KKT system with MUMPS every iteration
and spends ~3 ms an iteration on it, about 15 % of it in the function evaluations.  Here the rows are
condensed into an n x n system, dense Cholesky, so an iteration costs ~1.1 ms (about a quarter of it the
CasADi evaluation of the derivatives, ~0.3 ms).  A solve that does not converge here is handed to Ipopt by the caller.

Problem (CasADi's ``nlpsol`` form; x: n variables, p: parameters, g: m rows)::

    min f(x, p)   s.t.   lbg <= g(x, p) <= ubg,   lbx <= x <= ubx

Lifted variables: the problem may also give y (m_y SX symbols) and L (m_y x n, constant), with f and g written
in y and x for y = L x (an NLP window's rows read its control points only through the feed spline's value
and derivatives at each checkpoint, ``solvers.nlp``).  The derivatives are then taken in v = (y, x), where
each row reads ~3 variables, and carried to x inside the same CasADi function as products with the constant
L_v = [L; I]:  J = J_v L_v,  H = L_v^T H_v L_v.  Against the Hessian taken in x directly (forward over reverse
through L x): 64 replayed window solves (flower x10) 4.38 -> 3.98 G instructions (callgrind), the CasADi
evaluation 1.91 -> 1.42 G of it; a window shape builds 10-30 % faster.

Given derivatives: the problem may instead carry ``derivatives`` (MX, in v = (y, x) and its own multiplier
symbol ``lam`` of g): f and g as computed alongside them, grad f, J_v (m x n_v), H_v (n_v x n_v, full) and which
rows are linear; nothing is differentiated here (``solvers.nlp`` maps one checkpoint's derivatives over a
window: a window shape builds in ~1/3 of the time, each evaluation costs ~10-40 % more).

Variables with lbx = ubx are fixed and eliminated.  The other finite bounds of x are rows of their own
(g is extended by x).  Every finite bound is one inequality c_i(x) >= 0 with slack w_i > 0 and multiplier
z_i > 0:

    c_i = sigma_i g_{r_i}(x) + o_i,   sigma_i = +1, o_i = -lbg_{r_i} (lower)  or  -1, o_i = ubg_{r_i} (upper)

Primal-dual Newton step on  grad f - A^T z = 0,  c - w = 0,  W z = t  (A = dc/dx, t the centring target),
with the slack and multiplier steps eliminated:

    (H + A^T D A) dx = -grad f + A^T (t / w - D (c - w)),   D = z / w
    dw = A dx + (c - w),   dz = t / w - z - D dw

H is the Hessian of the Lagrangian f - z^T c = f + lam^T g (lam: CasADi's / Ipopt's row multipliers, positive
at an upper bound).  Since sigma_i^2 = 1, A^T D A = J^T diag(D_g) J with D_g summed over a row's two bounds:
J's sparse rows (each row of g reads a few consecutive control points) give it by one ``bincount`` over the
pairs of a row's non-zeros.  The system is solved by Cholesky after symmetric diagonal scaling; when it is
not positive definite (a non-convex H), delta I is added (delta from DELTA0, x8 until it factors).  A window's
M is banded: a row reads a few consecutive control points, and only the rest ends' rise factors (the last
variables) reach the first and last few.  Reordered by reverse Cuthill-McKee, a window of n = 1,130 on
0.07 mm knots has half-bandwidth 9, and M is factored as a band (``_BandKkt``, BAND_SHARE): a zig-zag at a
1 um blend, refined to 2,048 intervals, spent 9.2 s in dense factorisations and 0.3 s in band ones (the
O(n^2) assembly and solves too: 34.6 -> 22.6 s of CPU in all, same motion).

Centring: Mehrotra's predictor-corrector (affine step with t = 0, sigma = (mu_aff / mu)^3, corrector
t = sigma mu - dW_aff dZ_aff), mu = w^T z / m_i, never below MU_MIN.  Step: fraction to the boundary
tau = max(0.99, 1 - mu) on w and z separately, and on the linear rows' c at their lower bounds where they hold
(feed rows f >= 0: the travel time 1 / f is singular past f = 0).  Not at their upper bounds (a feed cap, an F
word), which no singularity lies past: there a row that starts within rounding of its bound (c ~ 3e-10, its slack
pushed to PUSH) while the objective pulls across it held every step under 1e-10, and the line search failed at
the first iteration, warm and cold (cam seed 1215 lp+nlp: 3 windows handed to Ipopt, 9.5 s of CPU; 1.6 s
without, the same motion to 1.4e-7).  Line search on the primal step, with the slacks reset to
w = max(w, c) at the trial point (a row that holds does not count as infeasible):
theta = ||c - w||_1, phi = f - mu_t sum log w; accepted by Armijo on phi when theta is small and the step
descends (Ipopt's switching condition), else by a decrease of theta or phi (a one-entry filter, reset every
iteration as mu moves), theta never above THETA_MAX_FACTOR x max(1, theta_0).  If the corrected direction
finds no step, the plain centring direction (no corrector) is tried before the solve is declared failed.

Converged when  ||grad f - A^T z||_inf / s_d <= TOL_DUAL  (Ipopt's scaling s_d = max(100, ||z||_1 / m_i) /
100),  max(-c) <= TOL_VIOL  and  max(w z) <= TOL_COMPL.

Elastic start (``solve(elastic=True)``, ``solvers.nlp``'s third attempt at a window before Ipopt): a start far
outside its rows fails above, since a violated row's slack sits at PUSH while its Newton step wants
c + A dx < 0, so the fraction to the boundary caps every step (an NLP window whose hand-over reads 600 x emax
in its x_sss envelope: steps of 1e-4 to 1e-9, then Line_Search_Failed or Factorization_Failed).  Each row
violated at x0 gets r_i >= 0 (c_i + r_i >= 0, r_i = w_i - c_i at the start) and the objective rho sum r
(an exact penalty for rho over the rows' multipliers, ELASTIC_RHO); r and its multiplier zeta are eliminated
row by row (``_Step``), so M keeps its band.  Bench seed 44's n = 505 window (start theta 250): 80 iterations
to Ipopt's objective (2.126964 vs 2.1269635), where the plain method failed after 58 and Ipopt needed 64
with four restoration iterations.  Where the elastic problem is solved with r left over, the rows are called
locally infeasible after a second elastic solve with every row elastic (ELASTIC_RHO_GROWTH): ``solvers.nlp``
then skips Ipopt in its tightening rounds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, cast

import casadi as ca
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg.lapack import dpbtrf as _pbtrf
from scipy.linalg.lapack import dpbtrs as _pbtrs
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs
from scipy.sparse.csgraph import reverse_cuthill_mckee

from solvers import csr

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: scaled dual infeasibility at convergence (Ipopt's ``tol`` in ``solvers.nlp`` is 1e-6 on the same measure)
TOL_DUAL = 1e-6
#: largest violation of a row's bound at convergence (rows are scaled: u / umax, e / emax, f / Fs)
TOL_VIOL = 1e-9
#: largest complementarity w_i z_i at convergence
TOL_COMPL = 1e-7
#: the centring target never drops below this (D = z / w stays within what a dense Cholesky resolves)
MU_MIN = 1e-9
#: first regularisation delta I when Cholesky fails (the condensed system in the problem's own scaling)
#: and the largest tried
DELTA0 = 1e-6
DELTA_MAX = 1e20
#: fraction to the boundary, at least (tau = max(TAU_MIN, 1 - mu))
TAU_MIN = 0.99
#: Armijo and sufficient-decrease constants of the line search, its shortest step
ARMIJO = 1e-4
GAMMA = 1e-5
ALPHA_MIN = 1e-8
#: trial points with theta over this many times max(1, theta at the start) are rejected
THETA_MAX_FACTOR = 1e4
#: below this share of max(1, theta at the start), steps must satisfy Armijo on phi (switching condition)
THETA_MIN_FACTOR = 1e-4
#: iterations per solve
MAX_ITER = 100
#: slack and multiplier floor at the start
PUSH = 1e-3
#: Start from given multipliers (a re-solve after its bounds moved, or the previous window's shifted duals):
#: z = max(lam, WARM_Z_MIN), w = max(c, WARM_MU0 / z), z = max(z, WARM_MU0 / w), so w z >= WARM_MU0 with
#: the active rows' multipliers kept.  59 replayed flower re-solves at Ipopt's duals: 928 -> 725 iterations
#: (1e-4: a worse local optimum, 1e-2: 794); 8 of 92 bench-seed solves did not finish from it (solved
#: then from unit multipliers: ``solvers.nlp._dense_solve``).  Without multipliers z = 1, w = max(c, PUSH).
WARM_MU0 = 1e-3
WARM_Z_MIN = 1e-3
#: The condensed system is factored as a band (LAPACK ``dpbtrf``, n kd^2 flops against the dense n^3 / 3) when
#: its variables, reordered by reverse Cuthill-McKee, have half-bandwidth kd with (kd + 1) x BAND_SHARE <= n
#: and n >= BAND_MIN_N.  An NLP window's control points couple only their neighbours; only its rest ends'
#: rise factors, the last variables, read the first and last few control points, which RCM moves next to them.
BAND_SHARE = 4
BAND_MIN_N = 64
#: Elastic start (``solve(elastic=True)``): each row violated at x0 (c_i < 0) gets an elastic variable r_i >= 0,
#: c_i + r_i >= 0, and rho sum r_i joins the objective (an exact penalty once rho is over the rows' multipliers):
#: the start is then interior, where the plain method's fraction to the boundary holds a violated row's slack
#: at PUSH and lets the step move ~1e-4..1e-9 (windows whose hand-over reads up to 600 x a limit).
#: rho = max(ELASTIC_RHO, ELASTIC_RHO_FACTOR x the largest starting multiplier); zeta (r's multiplier) starts at
#: rho - z, at least ELASTIC_ZETA_MIN.  A solve succeeds only where every row holds without r (c >= -TOL_VIOL).
ELASTIC_RHO = 1e3
ELASTIC_RHO_FACTOR = 10.0
ELASTIC_ZETA_MIN = 1.0
#: An elastic solve still unfinished this many iterations after its centring target reached MU_MIN stops
#: (status Elastic_Stalled): bench seed 44's two elastic solves converged 6 and 3 iterations after it; seed
#: 276's three that did not ran out their 100 iterations at MU_MIN (4.5 s of its 20.6 s, for Ipopt to solve
#: them after).
ELASTIC_STALL_ITER = 10
#: An elastic solve whose elastic problem is solved (its own KKT conditions to TOL_DUAL and TOL_COMPL, every row
#: within TOL_VIOL once r is added) with some r_i > ELASTIC_INFEASIBLE_R sits where the penalty does not lower the
#: violation.  Only the rows violated at x0 were elastic, the others hard, so a fresh solve goes on from that point
#: with every row of g elastic (those that hold start at r = PUSH) and the linear ones among them no longer kept
#: feasible by the step; the variable bounds stay hard, as in Ipopt's restoration phase (on contradicting random
#: rows, test_ipm, keeping the linear rows feasible left the verdict to 19 of 60 draws, the line search failing on
#: the others; without it 46).
#: Solved so again, its rho grows by ELASTIC_RHO_GROWTH (zeta = rho - z) up to ELASTIC_RHO_MAX_FACTOR x its first;
#: still so there, the point is stationary for f + rho sum max(0, -c_i) with rho 100 x over every multiplier it
#: needed, and the rows are called locally infeasible: status Infeasible_Problem_Detected, Ipopt's verdict when
#: its restoration phase converges to a point of non-zero violation.  The verdict is a local one, as Ipopt's: on
#: a random non-convex draw it came at a local minimiser of the violation (8.7e-3) from which Ipopt found the rows'
#: feasible set (test_ipm).  With only the first rows elastic it also came where hard rows held the elastic ones
#: (52 rows at a violation of 104, hard multipliers 20 x rho), not at a minimiser.  The 18.35 m flower at the
#: default knots: the 4 solves the dense method handed to Ipopt were tightening rounds that left two rows 1-2 %
#: over their bound; Ipopt's safe settings answered Infeasible_Problem_Detected on each after 15-37 iterations
#: (~0.2 s each, plus ~0.5 s to build its solver), the dense method now says so in 40-42 iterations (~0.05 s).
ELASTIC_RHO_GROWTH = 10.0
ELASTIC_RHO_MAX_FACTOR = 100.0
#: An elastic solve whose corrected and plain centring directions both find no step tries a third, centred on
#: max(mu_t, ELASTIC_RECENTRE x the largest primal residual |c + r - w|): mu had fallen to 1e-7 with the rows
#: still 0.025 apart from their slacks, which sat at their bounds (a random convex draw of test_ipm, seed 3,
#: n 4, 12 rows, from x0 = 2.66: the line search failed at iteration 10; with it, solved in 13).
ELASTIC_RECENTRE = 0.01
#: ... only where some r_i is over this (Ipopt's default ``constr_viol_tol``, under which Ipopt's own solve
#: would call a point feasible): a smaller r stays for the stall rule and Ipopt.
ELASTIC_INFEASIBLE_R = 1e-4
#: The status of that verdict (``solvers.nlp.DENSE_INFEASIBLE``).
STATUS_INFEASIBLE = "Infeasible_Problem_Detected"


@dataclass(frozen=True)
class IpmResult:
    """One solve.  x (n), lam_g (m) and lam_x (n) in CasADi's / Ipopt's sign convention
    (grad f + J^T lam_g + lam_x = 0; positive at an upper bound)."""

    x: FloatArray
    lam_g: FloatArray
    lam_x: FloatArray
    iterations: int
    status: str

    @property
    def success(self) -> bool:
        return self.status == "Solve_Succeeded"


class DenseIpm:
    """The method above for one problem structure (``{"x", "p", "f", "g"}`` of SX), built once, called per
    parameter and bound set.  Evaluations go through CasADi's zero-copy buffers."""

    def __init__(self, problem: dict[str, Any], banded: bool | None = None) -> None:
        """banded: factor the condensed system as a band (True), dense (False), or as BAND_SHARE chooses
        (None)."""
        x, p, f, g = problem["x"], problem["p"], problem["f"], problem["g"]
        n, m0 = int(x.size1()), int(g.size1())
        y = problem.get("y")
        if y is None:
            v, Lf = x, sp.identity(n, format="csr")
        else:
            v = ca.vertcat(y, x)
            Lf = sp.vstack([sp.csr_matrix(problem["L"]), sp.identity(n)], format="csr")
        #: v = L x and L^T (CSR both: a product is one pass over ~3 non-zeros a row; a dense L starts BLAS
        #: threads and grows with the window squared, scipy's L.T builds a matrix per call)
        self._L: sp.csr_matrix = Lf
        self._LT: sp.csr_matrix = sp.csr_matrix(Lf.T)
        gx = ca.vertcat(g, x)  # the variables' own bounds are rows m0.. of the extended g
        fg = ca.Function("ipm_fg", [v, p], [ca.densify(ca.vertcat(f, gx))])
        m = m0 + n
        given = problem.get("derivatives")
        gradf: Any
        lam: Any
        if given is None:
            lam = ca.SX.sym("lam", m)
            Hv, _ = ca.hessian(f + ca.dot(lam, gx), v)
            Jv: Any = ca.jacobian(gx, v)
            gradf = ca.gradient(f, v)
            #: rows whose value is linear in x (feed rows, the variables' own): kept feasible at their lower bounds
            #: by the step rule
            self.linear = ~np.asarray(ca.which_depends(gx, v, 2, True), dtype=bool)
        else:
            # derivatives in v given by the problem (MX: ``solvers.nlp``'s mapped checkpoint rows), in its
            # multipliers of g; the variables' own rows are linear and have no curvature
            lam = ca.vertcat(given["lam"], ca.MX.sym("lam_x", n))
            # (f and g as the derivatives' function computes them alongside)
            f, gx, Hv, gradf = given["f"], ca.vertcat(given["g"], x), given["hess"], given["grad"]
            ny = int(v.size1()) - n
            Jv = ca.vertcat(given["jac"], _dm(sp.hstack([sp.csc_matrix((n, ny)), sp.identity(n)], format="csc")))
            self.linear = np.concatenate([np.asarray(given["linear"], dtype=bool), np.ones(n, dtype=bool)])
        Ld = _dm(Lf)
        J: Any = ca.mtimes(Jv, Ld)
        Hl: Any = ca.tril(ca.mtimes(ca.mtimes(Ld.T, Hv), Ld))
        self.n, self.m, self.m0 = n, m, m0
        jr, jc = J.sparsity().get_triplet()
        self._jr: IntArray = np.asarray(jr, dtype=np.int64)
        self._jc: IntArray = np.asarray(jc, dtype=np.int64)
        hr, hc = Hl.sparsity().get_triplet()
        hr_a, hc_a = np.asarray(hr, dtype=np.int64), np.asarray(hc, dtype=np.int64)
        #: H's non-zeros (its lower triangle) as flat positions in an n x n matrix
        self._h_at: IntArray = hr_a * n + hc_a
        self._nj = self._jr.size
        #: J's non-zeros are in CasADi's column-major order: with its column pointers they are J^T in CSR, whose
        #: products (``_jt``, ``_jx``) sum each entry's terms in the order np.bincount over the non-zeros did
        #: (bit for bit), ~4x faster (session 45: 120 -> 28 us for J^T y at 3,500 rows)
        self._jptr: NDArray[np.int32] | None = None
        if self._nj < np.iinfo(np.int32).max and np.all(np.diff(self._jc) >= 0):
            self._jptr = np.searchsorted(self._jc, np.arange(n + 1)).astype(np.int32)
        self._jr32: NDArray[np.int32] = self._jr.astype(np.int32)
        ia, ib = self._pairs(m)
        self._kkt: _DenseKkt | _BandKkt = _choose_kkt(n, self._jc[ia], self._jc[ib], hr_a, hc_a, banded)
        if self._kkt.pair_keep is not None:  # (the band reads one of each symmetric pair: the others are not formed)
            ia, ib = ia[self._kkt.pair_keep], ib[self._kkt.pair_keep]
        #: the pairs ``factor`` reads: their non-zeros of J and their row
        self._ia: IntArray = ia
        self._ib: IntArray = ib
        self._pair_row: IntArray = self._jr[ia]
        full = ca.Function("ipm_full", [v, p, lam],
                           [ca.vertcat(f, ca.densify(gradf), ca.densify(gx), _nonzeros(J), _nonzeros(Hl))])
        self._v: FloatArray = np.zeros(int(v.size1()))
        self._p: FloatArray = np.zeros(int(p.size1()))
        self._lam: FloatArray = np.zeros(m)
        self._out: FloatArray = np.zeros(int(full.size1_out(0)))
        self._out_fg: FloatArray = np.zeros(1 + m)
        self._buf_full: Any
        self._buf_fg: Any
        self._buf_full, self._eval_full = full.buffer()
        for i, a in enumerate((self._v, self._p, self._lam)):
            self._buf_full.set_arg(i, _view(a))
        self._buf_full.set_res(0, _view(self._out))
        self._buf_fg, self._eval_fg = fg.buffer()
        self._buf_fg.set_arg(0, _view(self._v))
        self._buf_fg.set_arg(1, _view(self._p))
        self._buf_fg.set_res(0, _view(self._out_fg))

    def _pairs(self, m: int) -> tuple[IntArray, IntArray]:
        """Pairs (a, b) of non-zeros of J in one row: (A^T D A)[col a, col b] += D_row J_a J_b."""
        order = np.argsort(self._jr, kind="stable")
        rows = self._jr[order]
        counts = np.bincount(rows, minlength=m)
        width = int(counts.max()) if counts.size else 0
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(rows.size) - starts[rows]
        table = np.full((m, max(width, 1)), -1, dtype=np.int64)
        table[rows, slot] = order
        ia, ib = [], []
        for i in range(width):
            for j in range(width):
                ok = (table[:, i] >= 0) & (table[:, j] >= 0)
                ia.append(table[ok, i])
                ib.append(table[ok, j])
        empty = np.zeros(0, dtype=np.int64)
        return (np.concatenate(ia) if ia else empty), (np.concatenate(ib) if ib else empty)

    def _lx(self, x: FloatArray) -> FloatArray:
        """v = L x."""
        return np.asarray(self._L @ x, dtype=np.float64)

    def _jt(self, jv: FloatArray, y: FloatArray) -> FloatArray:
        """J^T y (n,) for J's non-zeros jv."""
        if self._jptr is None:
            return _bincount(self._jc, jv * y[self._jr], self.n)
        return np.asarray(csr.make(jv, self._jr32, self._jptr, (self.n, self.m)) @ y, dtype=np.float64)

    def _jx(self, jv: FloatArray, x: FloatArray) -> FloatArray:
        """J x (m,) for J's non-zeros jv."""
        if self._jptr is None:
            return _bincount(self._jr, jv * x[self._jc], self.m)
        return np.asarray(csr.make_csc(jv, self._jr32, self._jptr, (self.m, self.n)) @ x, dtype=np.float64)

    def _fg(self, x: FloatArray) -> tuple[float, FloatArray]:
        """f and the extended g at x; g is a view of the output buffer, valid until the next evaluation."""
        self._v[:] = self._lx(x)
        self._eval_fg()
        return float(self._out_fg[0]), self._out_fg[1:]

    def solve(self, x0: FloatArray, p: FloatArray, lbx: FloatArray, ubx: FloatArray, lbg: FloatArray,
              ubg: FloatArray, lam_g0: FloatArray | None = None, max_iter: int | None = None,
              elastic: bool = False) -> IpmResult:
        """Solve from x0; lam_g0 (m0, Ipopt's convention) seeds the multipliers of the rows at a bound;
        at most max_iter iterations (default MAX_ITER); ``elastic``: the rows violated at x0 start elastic
        (ELASTIC_RHO).  Floating-point overflow (slacks of a solve that is
        failing reach ~1e-300) ends the solve as Invalid_Number_Detected, without warnings."""
        with np.errstate(all="ignore"):
            return self._solve(x0, p, lbx, ubx, lbg, ubg, lam_g0, max_iter, elastic)

    def _solve(self, x0: FloatArray, p: FloatArray, lbx: FloatArray, ubx: FloatArray, lbg: FloatArray,
               ubg: FloatArray, lam_g0: FloatArray | None, max_iter: int | None, elastic: bool,
               every_row: bool = False) -> IpmResult:
        n, m, m0 = self.n, self.m, self.m0
        max_iter = MAX_ITER if max_iter is None else max_iter
        nv = self._v.size
        fixed = lbx == ubx
        lo_x = np.where(fixed, -np.inf, lbx)
        hi_x = np.where(fixed, np.inf, ubx)
        lb = np.concatenate([lbg, lo_x])
        ub = np.concatenate([ubg, hi_x])
        lo = np.flatnonzero(np.isfinite(lb))
        hi = np.flatnonzero(np.isfinite(ub))
        idx = np.concatenate([lo, hi])
        sgn = np.concatenate([np.ones(lo.size), -np.ones(hi.size)])
        offs = np.concatenate([-lb[lo], ub[hi]])
        mi = idx.size
        x = np.array(x0, dtype=np.float64)
        x[fixed] = lbx[fixed]
        self._p[:] = p
        if mi == 0:
            return IpmResult(x, np.zeros(m0), np.zeros(n), 0, "No_Inequality_Rows")
        lin_i = self.linear[idx] & (sgn > 0)  # (linear rows' lower bounds: kept feasible by the step)
        _, gv = self._fg(x)
        c = sgn * gv[idx] + offs
        w = np.maximum(c, PUSH)
        if lam_g0 is not None and np.any(lam_g0):
            lam0 = np.concatenate([lam_g0, np.zeros(n)])
            z0 = np.concatenate([np.maximum(-lam0[lo], 0.0), np.maximum(lam0[hi], 0.0)])
            z = np.maximum(z0, WARM_Z_MIN)
            w = np.maximum(c, WARM_MU0 / z)
            z = np.maximum(z, WARM_MU0 / w)
        else:
            z = np.ones(mi)
        ela: _Elastic | None = None
        hard = np.ones(mi, dtype=bool)  # (the linear rows the step keeps feasible where they hold: ``lin_i``)
        if elastic:
            el = np.flatnonzero(idx < m0) if every_row else np.flatnonzero(c < 0.0)
            if el.size == 0:  # (the plain solve from x0 is the one)
                return IpmResult(x, np.zeros(m0), np.zeros(n), 0, "No_Elastic_Rows")
            if every_row:  # (ELASTIC_RHO_GROWTH) the rows that hold start with r = PUSH, their slack over it
                hard[el] = False
                w[el] = np.where(c[el] < 0.0, w[el], c[el] + PUSH)
            rho = max(ELASTIC_RHO, ELASTIC_RHO_FACTOR * float(z.max()))
            ela = _Elastic(el, w[el] - c[el], np.maximum(rho - z[el], ELASTIC_ZETA_MIN), rho)
        rho_max = ELASTIC_RHO_MAX_FACTOR * ela.rho if ela is not None else 0.0
        at_floor = 0
        ne = 0 if ela is None else ela.el.size
        theta_start = max(1.0, float(np.abs(c - w).sum()))
        theta_max = THETA_MAX_FACTOR * theta_start
        theta_min = THETA_MIN_FACTOR * theta_start
        status = "Maximum_Iterations_Exceeded"
        it = 0
        for it in range(max_iter + 1):
            self._v[:] = self._lx(x)
            self._lam[:] = np.bincount(idx, -sgn * z, minlength=m)
            self._eval_full()
            o = self._out
            if not np.all(np.isfinite(o)):
                status = "Invalid_Number_Detected"
                break
            fv = float(o[0])
            gf = np.asarray(self._LT @ o[1 : 1 + nv], dtype=np.float64)
            gv = o[1 + nv : 1 + nv + m]
            k = 1 + nv + m
            jv = o[k : k + self._nj].copy()
            hv = o[k + self._nj :]
            c = sgn * gv[idx] + offs
            rp = c - w
            rr = np.zeros(0)
            if ela is not None:
                rp[ela.el] += ela.r
                rr = ela.rho - z[ela.el] - ela.zeta
            zg = -self._lam  # the rows' z summed over their two bounds, signed
            rd = gf - self._jt(jv, zg)
            rd[fixed] = 0.0
            mu = float(w @ z) / mi if ela is None else (float(w @ z) + float(ela.r @ ela.zeta)) / (mi + ne)
            s_d = max(100.0, float(z.sum()) / mi) / 100.0
            # stationarity and complementarity (of r too), then the rows: each on its own, or with r added
            centred = (float(np.abs(rd).max()) / s_d <= TOL_DUAL and float((w * z).max()) <= TOL_COMPL
                       and (ela is None or (float(np.abs(rr).max()) / s_d <= TOL_DUAL
                                            and float((ela.r * ela.zeta).max()) <= TOL_COMPL)))
            if centred and max(0.0, -float(c.min())) <= TOL_VIOL:
                status = "Solve_Succeeded"
                break
            if centred and ela is not None and _elastic_solved(c, ela):
                # (ELASTIC_RHO_GROWTH) first a fresh solve from here with every row elastic, then rho up there,
                # then the verdict
                if not every_row:
                    res = self._solve(x, p, lbx, ubx, lbg, ubg, None, max_iter - it, True, every_row=True)
                    return replace(res, iterations=it + res.iterations)
                if ela.rho >= rho_max:
                    status = STATUS_INFEASIBLE
                    break
                rho = ELASTIC_RHO_GROWTH * ela.rho
                ela = _Elastic(ela.el, ela.r, np.maximum(rho - z[ela.el], ELASTIC_ZETA_MIN), rho)
                rr = rho - z[ela.el] - ela.zeta
                at_floor = 0
            if it == max_iter:
                break
            # condensed system M = H + J^T diag(D_g) J, fixed variables' rows and columns identity
            D = z / w
            if ela is not None:  # an elastic row's slack and r in series: 1 / (w / z + r / zeta)
                D[ela.el] = 1.0 / (w[ela.el] / z[ela.el] + ela.r / ela.zeta)
            Dg = np.bincount(idx, D, minlength=m)
            failed = self._kkt.factor(Dg[self._pair_row] * jv[self._ia] * jv[self._ib], hv, fixed)
            if failed is not None:
                status = failed
                break
            step = _Step(self, w, z, rp, gf, jv, D, idx, sgn, fixed, ela, rr)
            _, dwa, dza, _, dra, dqa = step.direction(np.zeros(mi), np.zeros(ne))
            ap = _max_step(w, dwa, 0.995)
            ad = _max_step(z, dza, 0.995)
            if ela is None:
                mu_aff = float((w + ap * dwa) @ (z + ad * dza)) / mi
            else:
                ap = min(ap, _max_step(ela.r, dra, 0.995))
                ad = min(ad, _max_step(ela.zeta, dqa, 0.995))
                mu_aff = (float((w + ap * dwa) @ (z + ad * dza))
                          + float((ela.r + ap * dra) @ (ela.zeta + ad * dqa))) / (mi + ne)
            mu_t = max(min(1.0, mu_aff / mu) ** 3 * mu, MU_MIN)
            if ela is not None and mu_t <= MU_MIN:
                at_floor += 1
                if at_floor > ELASTIC_STALL_ITER:
                    status = "Elastic_Stalled"
                    break
            tau = max(TAU_MIN, 1.0 - mu)
            accepted = None
            targets = [(mu_t - dwa * dza, mu_t - dra * dqa, mu_t), (np.full(mi, mu_t), np.full(ne, mu_t), mu_t)]
            mu_c = max(mu_t, ELASTIC_RECENTRE * float(np.abs(rp).max())) if ela is not None else mu_t
            if mu_c > mu_t:
                targets.append((np.full(mi, mu_c), np.full(ne, mu_c), mu_c))
            for t, tq, mu_ls in targets:
                dx, dw, dz, dc, dr, dq = step.direction(t, tq)
                ap = _max_step(w, dw, tau)
                if ela is not None:
                    ap = min(ap, _max_step(ela.r, dr, tau))
                keep = lin_i & (c > 0) & hard
                if keep.any():
                    ap = min(ap, _max_step(c[keep], dc[keep], tau))
                accepted = self._line_search(x, w, rp, fv, gf, dx, dw, ap, mu_ls, idx, sgn, offs, theta_min,
                                             theta_max, ela, dr)
                if accepted is not None:
                    break
            if accepted is None:
                status = "Line_Search_Failed"
                break
            x, w, r_new = accepted
            a_z = _max_step(z, dz, tau)
            if ela is None:
                z = z + a_z * dz
                mu_n = float(w @ z) / mi
            else:
                a_z = min(a_z, _max_step(ela.zeta, dq, tau))
                z = z + a_z * dz
                zeta = ela.zeta + a_z * dq
                mu_n = (float(w @ z) + float(r_new @ zeta)) / (mi + ne)
                ela = _Elastic(ela.el, r_new, np.clip(zeta, mu_n / (1e10 * r_new), 1e10 * mu_n / r_new), ela.rho)
            z = np.clip(z, mu_n / (1e10 * w), 1e10 * mu_n / w)
        lam_all = _bincount(idx, -sgn * z, m)
        lam_g = lam_all[:m0].copy()
        lam_x = lam_all[m0:].copy()
        if status == "Solve_Succeeded":
            # the fixed variables' multipliers close grad f + J^T lam_g + lam_x = 0 (gf, jv: at this x and z)
            lam_x[fixed] = -(gf + self._jt(jv, lam_all))[fixed]
        return IpmResult(x, lam_g, lam_x, it, status)

    def _line_search(self, x: FloatArray, w: FloatArray, rp: FloatArray, fv: float, gf: FloatArray,
                     dx: FloatArray, dw: FloatArray, a: float, mu_t: float, idx: IntArray, sgn: FloatArray,
                     offs: FloatArray, theta_min: float, theta_max: float, ela: _Elastic | None, dr: FloatArray,
                     ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """(x, w, r) at the accepted step, or None; with ``ela`` the elastic rows read c + r and phi has
        rho sum r - mu sum log r."""
        theta0 = float(np.abs(rp).sum())
        phi0 = fv - mu_t * float(np.log(w).sum())
        dphi = float(gf @ dx) - mu_t * float((dw / w).sum())
        rn = np.zeros(0)
        if ela is not None:
            phi0 += ela.rho * float(ela.r.sum()) - mu_t * float(np.log(ela.r).sum())
            dphi += ela.rho * float(dr.sum()) - mu_t * float((dr / ela.r).sum())
        while a >= ALPHA_MIN:
            xn = x + a * dx
            fn, gn = self._fg(xn)
            cn = sgn * gn[idx] + offs
            if ela is not None:
                rn = ela.r + a * dr
                cn[ela.el] += rn
                fn += ela.rho * float(rn.sum()) - mu_t * float(np.log(rn).sum())
            wn = np.maximum(w + a * dw, cn)
            theta = float(np.abs(cn - wn).sum())
            with np.errstate(invalid="ignore", divide="ignore"):
                phi = fn - mu_t * float(np.log(wn).sum())
            if np.isfinite(phi) and theta <= theta_max:
                switching = dphi < 0 and math.log(a) + 2.3 * math.log(-dphi) > 1.1 * math.log(max(theta0, 1e-300))
                if switching and theta0 <= theta_min:
                    if phi <= phi0 + ARMIJO * a * dphi:
                        return xn, wn, rn
                elif theta <= (1 - GAMMA) * theta0 or phi <= phi0 - GAMMA * theta0:
                    return xn, wn, rn
            a *= 0.5
        return None


def _dm(a: Any) -> Any:
    """A scipy sparse matrix as a CasADi DM of the same sparsity (its explicit zeros kept, as ``ca.DM(a)``
    keeps them) and values, from its CSC arrays: ``ca.DM(a)`` took ~5 ms for a 70-interval window's L (the
    condensing map: ~3,200 non-zeros), twice a shape build (session 45)."""
    c = sp.csc_matrix(a)
    if not c.has_sorted_indices:
        c = c.sorted_indices()
    return ca.DM(ca.Sparsity(int(c.shape[0]), int(c.shape[1]), c.indptr.tolist(), c.indices.tolist()),
                 np.asarray(c.data, dtype=np.float64))


def _nonzeros(a: Any) -> Any:
    """The non-zeros of a sparse SX or MX matrix as a column (in its sparsity's order)."""
    return ca.vertcat(*cast(Any, a.nonzeros())) if isinstance(a, ca.SX) else a.nz[:]


def _view(a: FloatArray) -> memoryview:
    """A float64 array as the buffer CasADi reads or writes in place."""
    return memoryview(cast(Any, a))


def _bincount(at: IntArray, weights: FloatArray, size: int) -> FloatArray:
    """Sums of weights per index in [0, size)."""
    return np.asarray(np.bincount(at, weights, minlength=size), dtype=np.float64)


def _choose_kkt(n: int, pa: IntArray, pb: IntArray, hr: IntArray, hc: IntArray,
                banded: bool | None) -> _DenseKkt | _BandKkt:
    """The condensed system's factorisation for the entries (pa, pb) of J^T D J and (hr, hc) of H's lower
    triangle: a band in reverse Cuthill-McKee order where it is narrow (``BAND_SHARE``), else dense."""
    if banded is False or n == 0:
        return _DenseKkt(n, pa, pb, hr, hc)
    rows, cols = np.concatenate([pa, hr, hc]), np.concatenate([pb, hc, hr])
    graph = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    perm = np.asarray(reverse_cuthill_mckee(graph, symmetric_mode=True), dtype=np.int64)
    pos = np.empty(n, dtype=np.int64)
    pos[perm] = np.arange(n)
    kd = int(np.abs(pos[rows] - pos[cols]).max()) if rows.size else 0
    if banded or (n >= BAND_MIN_N and (kd + 1) * BAND_SHARE <= n):
        return _BandKkt(n, pa, pb, hr, hc, perm, pos, kd)
    return _DenseKkt(n, pa, pb, hr, hc)


class _DenseKkt:
    r"""M = H + J^T diag(D_g) J as a dense n x n matrix, Cholesky (``dpotrf``) after symmetric diagonal scaling
    sc = 1 / sqrt|diag M|; when M is not positive definite delta I is added to it (delta from DELTA0, x8) until
    it factors."""

    def __init__(self, n: int, pa: IntArray, pb: IntArray, hr: IntArray, hc: IntArray) -> None:
        self.n = n
        #: the pairs ``factor`` reads (None: every one)
        self.pair_keep: NDArray[np.bool_] | None = None
        #: flat positions in M (n x n, C order) of the pairs, of H's lower triangle, and of its mirror
        self._pair_at: IntArray = pa * n + pb
        self._h_at: IntArray = hr * n + hc
        self._h_off = hr != hc
        self._h_mirror: IntArray = (hc * n + hr)[self._h_off]
        self._cf: FloatArray = np.zeros((0, 0))
        self._sc: FloatArray = np.zeros(0)

    def factor(self, pair_w: FloatArray, hv: FloatArray, fixed: NDArray[np.bool_]) -> str | None:
        """Assemble M from the pairs' weights D_row J_a J_b and H's non-zeros (fixed variables' rows and
        columns: identity) and factor it; returns the failure status, or None."""
        n = self.n
        M = _bincount(self._pair_at, pair_w, n * n)
        M[self._h_at] += hv
        M[self._h_mirror] += hv[self._h_off]
        M = M.reshape(n, n)
        M[fixed, :] = 0.0
        M[:, fixed] = 0.0
        M[fixed, fixed] = 1.0
        sc = 1.0 / np.sqrt(np.maximum(np.abs(np.diag(M)), 1e-300))
        Ms = M * sc[:, None] * sc[None, :]
        if not np.all(np.isfinite(Ms)):
            return "Invalid_Number_Detected"
        c = _first_factor(lambda delta: _potrf(Ms + np.diag(delta * sc * sc) if delta else Ms, lower=0, clean=0))
        if c is None:
            return "Factorization_Failed"
        self._cf, self._sc = c, sc
        return None

    def solve(self, rhs: FloatArray) -> FloatArray:
        """M^-1 rhs with the last factorisation."""
        return np.asarray(self._sc * _potrs(self._cf, self._sc * rhs, lower=0)[0], dtype=np.float64)


class _BandKkt:
    r"""M as ``_DenseKkt``, with the variables in the order perm (M_p = M[perm][:, perm], pos: perm's inverse)
    where M_p has half-bandwidth kd: LAPACK's upper band storage, column-major (kd + 1) x n,
    ab[kd + i - j, j] = M_p[i, j] for j - kd <= i <= j; ``dpbtrf`` / ``dpbtrs``.  Scaling, fixed variables
    and delta I as in the dense system, so the two agree to rounding.  Assembly and scaling cost
    O(pairs + n kd), the factorisation n kd^2."""

    def __init__(self, n: int, pa: IntArray, pb: IntArray, hr: IntArray, hc: IntArray, perm: IntArray,
                 pos: IntArray, kd: int) -> None:
        self.n, self.kd, self.perm = n, kd, perm
        w = kd + 1
        i, j = pos[pa], pos[pb]
        #: the pairs in the upper triangle of M_p (J^T D J holds both (a, b) and (b, a)), the only ones ``factor``
        #: reads, and their places in ab
        self.pair_keep: NDArray[np.bool_] | None = i <= j
        self._pair_at: IntArray = (kd + i - j + j * w)[i <= j]
        # H's lower triangle (r >= c) is one entry of M_p's upper triangle each
        hi, hj = np.minimum(pos[hr], pos[hc]), np.maximum(pos[hr], pos[hc])
        self._h_at: IntArray = kd + hi - hj + hj * w
        col = np.broadcast_to(np.arange(n), (w, n))
        row = col - kd + np.arange(w)[:, None]
        #: each band cell's row and column in M_p (rows above the matrix: 0, their cells stay 0)
        self._row: IntArray = np.maximum(row, 0)
        self._col: IntArray = np.asarray(col)
        self._cf: FloatArray = np.zeros((0, 0))
        self._sc: FloatArray = np.zeros(0)

    def factor(self, pair_w: FloatArray, hv: FloatArray, fixed: NDArray[np.bool_]) -> str | None:
        """As ``_DenseKkt.factor``, on the band; pair_w holds the weights of the pairs in ``pair_keep`` only."""
        n, kd = self.n, self.kd
        size = (kd + 1) * n
        ab = (_bincount(self._pair_at, pair_w, size) + _bincount(self._h_at, hv, size))
        ab = ab.reshape((kd + 1, n), order="F")
        fx = fixed[self.perm]
        if fx.any():
            ab[fx[self._row] | fx[self._col]] = 0.0
            ab[kd, fx] = 1.0
        sc = 1.0 / np.sqrt(np.maximum(np.abs(ab[kd]), 1e-300))
        abs_ = ab * sc[self._row] * sc[None, :]
        if not np.all(np.isfinite(abs_)):
            return "Invalid_Number_Detected"

        def attempt(delta: float) -> tuple[Any, int]:
            trial = abs_
            if delta:
                trial = abs_.copy(order="F")
                trial[kd] += delta * sc * sc
            return cast(tuple[Any, int], _pbtrf(trial, lower=0))

        c = _first_factor(attempt)
        if c is None:
            return "Factorization_Failed"
        self._cf, self._sc = c, sc
        return None

    def solve(self, rhs: FloatArray) -> FloatArray:
        """M^-1 rhs with the last factorisation."""
        b = self._sc * rhs[self.perm]
        xp = self._sc * _pbtrs(self._cf, b[:, None], lower=0)[0][:, 0]
        out = np.empty(self.n)
        out[self.perm] = xp
        return out


def _first_factor(attempt: Callable[[float], tuple[Any, int]]) -> Any:
    """The first factorisation attempt(delta) returns with info 0, for delta I added to the unscaled system
    (0, then from DELTA0, x8, up to DELTA_MAX); None if none does."""
    delta = 0.0
    while delta <= DELTA_MAX:
        c, info = attempt(delta)
        if info == 0:
            return c
        delta = 8.0 * delta if delta else DELTA0
    return None


def _elastic_solved(c: FloatArray, ela: _Elastic) -> bool:
    """With the solve's stationarity and complementarity met (``DenseIpm._solve``): every row holds once r is
    added, while some r is over ELASTIC_INFEASIBLE_R (ELASTIC_RHO_GROWTH)."""
    ce = c.copy()
    ce[ela.el] += ela.r
    return float(ela.r.max()) > ELASTIC_INFEASIBLE_R and max(0.0, -float(ce.min())) <= TOL_VIOL


def _max_step(v: FloatArray, dv: FloatArray, tau: float) -> float:
    """Largest step in (0, 1] with v + a dv >= (1 - tau) v (v > 0)."""
    r = float((dv / v).min()) if v.size else 0.0
    return 1.0 if r >= -tau else -tau / r


@dataclass(frozen=True)
class _Elastic:
    """The elastic rows of a solve (``ELASTIC_RHO``): their places el in the inequality list, r (> 0) and its
    multiplier zeta (> 0), and the penalty rho."""

    el: IntArray
    r: FloatArray
    zeta: FloatArray
    rho: float


class _Step:
    r"""The Newton directions of one iteration (one factorisation, several right-hand sides).

    An elastic row (c + r - w = 0, w z = t, r zeta = t_r, rho - z - zeta = rr) condenses as a plain row with
    D = 1 / (w / z + r / zeta) and  dz = D (-rp - dc + s),  s = (t / z - w) - (t_r / zeta - r - r rr / zeta);
    then  dzeta = rr - dz,  dr = (t_r - r zeta - r dzeta) / zeta,  dw = dc + dr + rp."""

    def __init__(self, ipm: DenseIpm, w: FloatArray, z: FloatArray, rp: FloatArray, gf: FloatArray,
                 jv: FloatArray, D: FloatArray, idx: IntArray, sgn: FloatArray, fixed: NDArray[np.bool_],
                 ela: _Elastic | None, rr: FloatArray) -> None:
        self.ipm, self.w, self.z, self.rp, self.gf, self.jv, self.D = ipm, w, z, rp, gf, jv, D
        self.idx, self.sgn, self.fixed, self.ela, self.rr = idx, sgn, fixed, ela, rr

    def direction(self, t: FloatArray, tr: FloatArray) -> tuple[FloatArray, ...]:
        """(dx, dw, dz, dc, dr, dzeta) for the centring targets t (one per inequality) and tr (one per elastic
        row; dr and dzeta are empty without them)."""
        ipm, idx, sgn, ela = self.ipm, self.idx, self.sgn, self.ela
        val = t / self.w - self.D * self.rp
        if ela is not None:
            el, r, q = ela.el, ela.r, ela.zeta
            s_el = (t[el] / self.z[el] - self.w[el]) - (tr / q - r - r * self.rr / q)
            val[el] = self.z[el] - self.D[el] * (self.rp[el] - s_el)
        y = _bincount(idx, sgn * val, ipm.m)
        rhs = -self.gf + ipm._jt(self.jv, y)
        rhs[self.fixed] = 0.0
        dx = ipm._kkt.solve(rhs)
        jdx = ipm._jx(self.jv, dx)
        dc = sgn * jdx[idx]
        dw = dc + self.rp
        dz = t / self.w - self.z - self.D * dw
        if ela is None:
            return dx, dw, dz, dc, np.zeros(0), np.zeros(0)
        dz_el = self.D[el] * (-self.rp[el] - dc[el] + s_el)
        dq = self.rr - dz_el
        dr = (tr - r * q - r * dq) / q
        dz[el] = dz_el
        dw[el] = dc[el] + dr + self.rp[el]
        return dx, dw, dz, dc, dr, dq
