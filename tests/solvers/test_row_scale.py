"""The LP rows' scaling (``solvers.lp._Rows.build``): a bound of at least ``lp.ROW_BOUND_FLOOR`` is never passed
smaller; a smaller one (~0: q <= q* next to a rest end) is scaled as before.

HiGHS runs with its own scaling off (``lp.SIMPLEX_SCALE``) and holds each row to its absolute primal feasibility
tolerance (1e-7).  Rows divided by their largest coefficient alone were passed with bounds as small as ~3.5e-6
(an acceleration row next to a corner's rest end on 0.01 mm knots, coefficients up to 2.8e5 against its bound 1),
which HiGHS then held to ~1 % of the limit: bench seed 16610's solution and its 1 kHz samples read 1.0098 x the x
axis's amax, and 38 cut rounds added the same rows again (1,859 points left unverified).

Independent truth: the rows recomputed from the blocks with scipy (the scaling is diag(r) A diag(sigma)), and the
finite differences of the sampled positions (``tests.fdcheck``) against the machine's limits.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers import lp
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.reliability import gen

TS = 1e-3
#: Relative agreement of the passed rows with diag(r) A diag(sigma) recomputed here (rounding only).
REL_TOL = 1e-12
#: Bench seed 16610 (lp): the x acceleration of its 1 kHz samples at most this x amax.  The LP's own check
#: (``lp.VERIFY_TOL`` 2e-3) and the sampling between its points leave ~0.4 %; before the floor it read 1.0098.
SEED_16610_A_X = 1.006


def _rows() -> lp._Rows:
    """Four rows over two columns: coefficients 2.8e5 against bound 1 (floored), a plain one, an equality at 0, and
    q <= 1e-12 Q (a bound below the floor as given: not lifted)."""
    rows = lp._Rows(2)
    rows.add(sp.csr_matrix(np.array([[-2.8e5, 3.0e5]])), np.array([-1.0]), np.array([1.0]))
    rows.add(sp.csr_matrix(np.array([[0.5, 2.0], [1.0e3, 0.0]])), np.array([-np.inf, 0.0]), np.array([4.0, 0.0]))
    rows.add(sp.csr_matrix(np.array([[0.5, 0.5]])), np.array([0.0]), np.array([1.0e-12]))
    rows.col_scale = np.array([2.0, 0.5])
    return rows


def test_rows_are_the_blocks_scaled_and_bounds_of_at_least_the_floor_are_passed_at_least_that_large() -> None:
    rows = _rows()
    A, lo, hi, r = rows.build()
    A0 = sp.vstack(rows.blocks).toarray() * rows.col_scale[None, :]
    lo0, hi0 = np.concatenate(rows.lo), np.concatenate(rows.hi)
    np.testing.assert_allclose(A.toarray(), r[:, None] * A0, rtol=REL_TOL)
    np.testing.assert_allclose(lo, lo0 * r, rtol=REL_TOL)
    np.testing.assert_allclose(hi, hi0 * r, rtol=REL_TOL)
    coef = np.abs(A.toarray()).max(axis=1)
    bound = np.maximum(np.abs(np.where(np.isfinite(lo), lo, 0.0)), np.abs(np.where(np.isfinite(hi), hi, 0.0)))
    # the first row: its largest coefficient (5.6e5 with the column scale) alone would have left the bound at 1.8e-6
    assert bound[0] >= lp.ROW_BOUND_FLOOR * (1 - REL_TOL), bound[0]
    assert coef[0] <= lp.ROW_COEF_CAP * (1 + REL_TOL), coef[0]
    # the others as before: divided by the larger of their largest coefficient and bound
    assert np.isclose(max(coef[1], bound[1]), 1.0) and np.isclose(coef[2], 1.0) and bound[2] == 0.0
    # q <= 1e-12 Q: its largest coefficient (1 with the column scale) divides it, its bound stays ~0
    assert np.isclose(coef[3], 1.0) and np.isclose(hi[3], 1.0e-12)


def test_the_cap_limits_how_far_a_row_is_scaled_up() -> None:
    rows = lp._Rows(1)
    rows.add(sp.csr_matrix(np.array([[1.0e12]])), np.array([-1.0]), np.array([1.0]))
    A, lo, hi, _ = rows.build()
    assert np.isclose(abs(A.data[0]), lp.ROW_COEF_CAP)
    assert np.isclose(hi[0], lp.ROW_COEF_CAP / 1.0e12) and np.isclose(lo[0], -hi[0])


def test_seed_16610_rows_next_to_a_corner_hold_the_x_acceleration() -> None:
    case = gen.case(16610, "bench")
    m = case.lp_machine
    sch = schedule(case.toolpath(), m, Options(method="lp", sample_period=TS))
    assert sch.summary["unverified_points"] == 0, sch.summary["unverified_points"]
    assert sch.summary["sample_repairs"] == 0, sch.summary["sample_repairs"]
    lim = gen.limits_of(m)
    u = utilisation(sch.samples.position, TS, lim.vmax, lim.amax, lim.jmax)
    assert u["ax"] <= SEED_16610_A_X, u
    assert max(u.values()) <= SEED_16610_A_X, u
