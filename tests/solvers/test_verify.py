"""The sampled-output re-check (solvers.verify) and the verification grid it exposed.

On the 18.35 m path the emitted (analytic) jerk reached 1.07 x jmax at five samples while every
LP window reported 0 unverified points: the checkpoint on a knot of q (and the point "on" a
geometry knot) landed on one side of it by rounding, so the other side, where q'' or x_sss jumps,
was never verified.  These tests pin both sides, and the re-check's behaviour on spoiled samples.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import examples as ex
from solvers import bspline, verify
from solvers.lp import LimitSet, WindowLP, WindowSpec
from solvers.machine import router
from solvers.pipeline import Options, _breaks, _local, plan_piece, schedule

#: How close to a knot a verification point must be to count as "at" it, mm.
AT_KNOT_MM = 1e-5


def _window() -> tuple[WindowLP, np.ndarray]:
    tp = ex.flower(1)
    m = router()
    piece = tp.pieces[0]
    plan = plan_piece(piece, m, Options(method="lp"))
    k0, k1 = 10, 60
    spec = WindowSpec(0, k0, k1, plan.d, plan.n_int, None, False, None, None)
    lim = LimitSet.from_machine(m, 1e-3, True)
    w = WindowLP(spec, lim, _local(tp, piece), "highs", _breaks(tp, piece))
    s_check = np.linspace(k0 * plan.d, k1 * plan.d, (k1 - k0) * 5 + 1)
    return w, s_check


def test_every_knot_of_q_is_verified_from_both_sides() -> None:
    w, s_check = _window()
    fine = w._fine(s_check)
    k_of = bspline.basis(fine, w.spec.d, w.spec.n_int)[0]
    for k in range(w.spec.k0 + 1, w.spec.k1):
        near = np.abs(fine - k * w.spec.d) < AT_KNOT_MM
        assert {k - 1, k} <= set(k_of[near].tolist()), f"knot {k}: intervals {set(k_of[near].tolist())}"


def test_every_geometry_knot_is_verified_from_both_sides() -> None:
    tp = ex.flower(1)
    w, s_check = _window()
    fine = w._fine(s_check)
    lo, hi = s_check[0], s_check[-1]
    br = w.breaks[(w.breaks > lo + 1e-3) & (w.breaks < hi - 1e-3)]
    assert br.size > 10
    _, u = tp.locate(fine)
    u_knots = np.unique(tp.subs[0].segment.knots)
    for b in br:
        near = np.abs(fine - b) < AT_KNOT_MM
        ub = u_knots[np.argmin(np.abs(u_knots - np.median(u[near])))]
        assert (u[near] < ub).any() and (u[near] > ub).any(), f"break at s = {b}"


def test_recheck_flags_a_spoiled_sample_and_schedule_holds() -> None:
    """A clean flower schedule passes the re-check without repairs; one position nudged by 1 um
    is flagged (acceleration by differences ~ 1e-3 mm / Ts^2 = 1000 mm/s^2 over the limit)."""
    m = router()
    sch = schedule(ex.flower(1), m, Options(method="lp"))
    assert sch.summary["sample_repairs"] == 0
    smp = sch.samples
    vmax, amax, jmax = m.limit_arrays()
    lim = verify.Limits(vmax, amax, jmax, None, None)
    ok = verify.check(1e-3, smp.position, smp.feed, smp.velocity, smp.acceleration, smp.jerk, lim)
    assert not ok.failed and ok.worst[2] <= 1.0 + verify.FAIL_TOL
    pos = smp.position.copy()
    k = pos.shape[0] // 2
    pos[k, 0] += 1e-3
    bad = verify.check(1e-3, pos, smp.feed, smp.velocity, smp.acceleration, smp.jerk, lim)
    assert bad.failed and bad.repair[k] and bad.worst[0] in ("acceleration", "jerk")
    assert abs(bad.worst[3] - k) <= 2


def test_a_sample_that_is_not_finite_fails_the_check() -> None:
    """A NaN in the emitted values compares false against every limit: it passed the re-check, and a quarter arc
    on knots spanning 1e-120 came back 200 with NaN accelerations (session 58's probe).  NaN now reads as over
    every limit (infinite utilisation), in the analytic values and in the feed."""
    m = router()
    sch = schedule(ex.flower(1), m, Options(method="lp"))
    smp = sch.samples
    vmax, amax, jmax = m.limit_arrays()
    lim = verify.Limits(vmax, amax, jmax, None, None)
    k = smp.t.size // 3
    acc = smp.acceleration.copy()
    acc[k, 1] = np.nan
    bad = verify.check(1e-3, smp.position, smp.feed, smp.velocity, acc, smp.jerk, lim)
    assert bad.failed and bad.repair[k] and bad.worst[0] == "acceleration" and bad.worst[2] == np.inf


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_long_chained_path_emits_no_analytic_overshoot() -> None:
    """The 5-loop flower (several LP windows): the emitted analytic a and j stay within
    1 + VERIFY_TOL-ish of the limits, like their finite differences."""
    m = router()
    sch = schedule(ex.flower(5), m, Options(method="lp"))
    _, amax, jmax = m.limit_arrays()
    assert np.max(np.abs(sch.samples.acceleration) / amax) <= 1.0 + verify.REPAIR_TOL
    assert np.max(np.abs(sch.samples.jerk) / jmax) <= 1.0 + verify.REPAIR_TOL


def test_recheck_in_chunks_equals_one_pass(monkeypatch: pytest.MonkeyPatch) -> None:
    """The check runs in chunks of verify.CHUNK samples; chunk edges change nothing (the
    differences read the padded positions across them)."""
    m = router()
    sch = schedule(ex.flower(1), m, Options(method="lp+nlp"))
    smp = sch.samples
    _, amax, jmax = m.limit_arrays()
    lim = verify.Limits(None, amax, jmax, m.drive_arrays(), None)
    args = (1e-3, smp.position, smp.feed, smp.velocity, smp.acceleration, smp.jerk, lim)
    whole = verify.check(*args)
    monkeypatch.setattr(verify, "CHUNK", 97)
    parts = verify.check(*args)
    assert whole.worst == parts.worst
    np.testing.assert_array_equal(whole.repair, parts.repair)
