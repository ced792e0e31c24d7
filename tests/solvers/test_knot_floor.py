"""The knot floor (``pipeline.floor_intervals``): under a low feed cap a piece is first solved on knots the top
feed covers in KNOT_FLOOR_SAMPLES sample periods, kept only while its motion is within KNOT_FLOOR_TOL of the
piece's lower bound (``pipeline.piece_time_bound``), else solved as without the floor.

Truth: ``lp.acceleration_bound`` against scipy's LP at each point; ``piece_time_bound`` against the closed-form
S-curve of a straight line (``test_optimality.s_curve_time``, the exact jerk-limited optimum); schedules against
the same path on the default knots, and their samples by finite differences."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import linprog

from geometry import Toolpath
from geometry import examples as ex
from solvers import lp
from solvers import pipeline as P
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import fd_drive, utilisation
from tests.solvers.test_optimality import ramp_from_rest, s_curve_time

#: ``acceleration_bound`` against scipy's LP optimum (relative).
BOUND_RTOL = 1e-7
#: Sampled limits (issue 2's bound) and the drive's (lp+nlp).
LIMIT_FACTOR = 1.01
#: ``piece_time_bound`` of a line at most this far under the S-curve's exact optimum (relative).  The bound's slack
#: there: the acceleration step at rest the LP allows (a_rest), and where the line is too short to cruise, the reach,
#: which leaves out the jerk's rounding into the cruise (1 mm at the router's own feed: 0.948 of the S-curve).
LINE_BOUND_SLACK = 0.06
#: ... and where it cruises, the bound is the S-curve move from the acceleration step at rest (``_stepped_move``) to
#: rounding: the S-curve's ends (``pipeline._ramp_gain``; with the reach alone, 30 mm at 100 mm/s read 0.9699 of
#: the S-curve, 300 mm at the router's own feed 0.98297).
LINE_CRUISE_BOUND_RTOL = 1e-9
#: ``lp.s_curve`` against its closed form from rest (relative).
S_CURVE_RTOL = 1e-12


def _scipy_bound(d1: np.ndarray, d2: np.ndarray, amax: np.ndarray) -> float:
    """max q s.t. |x_ss q + x_s sddot| <= amax per axis (variables q >= 0, sddot free); inf if unbounded."""
    A = np.vstack([np.c_[d2, d1], -np.c_[d2, d1]])
    r = linprog([-1.0, 0.0], A_ub=A, b_ub=np.r_[amax, amax], bounds=[(0, None), (None, None)])
    return float(-r.fun) if r.status == 0 else np.inf


@pytest.mark.parametrize("shape", ["flower", "wave3d", "line"])
def test_the_acceleration_bound_is_the_largest_q_some_sddot_allows(shape: str) -> None:
    tp = {"flower": ex.flower(1), "wave3d": Toolpath([ex.wave3d()]),
          "line": Toolpath([ex.line((0.0, 0.0, 0.0), (10.0, 5.0, 0.0))])}[shape]
    amax = np.array([1500.0, 900.0, 400.0])
    g = tp.evaluate(np.linspace(0.0, tp.length, 41))
    got = lp.acceleration_bound(g, amax)
    want = np.array([_scipy_bound(g.d1[i], g.d2[i], amax) for i in range(41)])
    fin = np.isfinite(want)
    assert np.array_equal(fin, np.isfinite(got)), (got, want)
    assert np.allclose(got[fin], want[fin], rtol=BOUND_RTOL, atol=0.0)
    if shape == "line":
        assert not fin.any()  # (no curvature: nothing bounds q but the velocity)


@pytest.mark.parametrize("length", [1.0, 30.0, 300.0])
@pytest.mark.parametrize("cap", [1.0, 10.0, 100.0, None])
def test_the_time_bound_of_a_line_is_just_under_its_s_curve(length: float, cap: float | None) -> None:
    m = router().with_feed_max(cap)
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (length, 0.0, 0.0))])
    lim = P._limit_set(m, Options(method="lp"))
    vmax, amax, jmax = m.limit_arrays()
    exact = s_curve_time(length, vmax[0] if cap is None else min(cap, vmax[0]), amax[0], jmax[0])
    got = P.piece_time_bound(tp, tp.pieces[0], lim, 256)
    assert (1.0 - LINE_BOUND_SLACK) * exact <= got <= exact
    move, ramp = _stepped_move(length, vmax[0] if cap is None else min(cap, vmax[0]), amax[0], jmax[0],
                               float(lim.a_rest[0]))
    if length >= 2.0 * ramp:  # (it cruises)
        assert got == pytest.approx(move, rel=LINE_CRUISE_BOUND_RTOL)


def _stepped_ramp(V: float, A: float, J: float, a0: float) -> tuple[float, float]:
    """(time, distance) of the S-curve to V from rest with the acceleration step a0: the one from rest to
    V' = V + a0^2 / (2 J) entered where that one reaches a0 (t0 = a0 / J, at v0 = a0^2 / (2 J)), less the feed v0
    throughout: T = T_0(V') - t0, D = D_0(V') - J t0^3 / 6 - v0 T."""
    t0, v0 = a0 / J, a0 * a0 / (2.0 * J)
    T0, D0 = ramp_from_rest(V + v0, A, J)
    return T0 - t0, D0 - J * t0**3 / 6.0 - v0 * (T0 - t0)


def _stepped_move(length: float, V: float, A: float, J: float, a0: float) -> tuple[float, float]:
    """(time, ramp distance) of the rest-to-rest move of ``length`` that cruises at V between two stepped ramps."""
    T, D = _stepped_ramp(V, A, J, a0)
    return 2.0 * T + (length - 2.0 * D) / V, D


@pytest.mark.parametrize(("V", "A", "J", "a0"), [(150.0, 500.0, 63000.0, 0.0), (150.0, 500.0, 63000.0, 200.0),
                                                 (30.0, 3340.0, 156000.0, 1000.0), (352.0, 9.5e5, 1.6e8, 0.0),
                                                 (10.0, 500.0, 63000.0, 300.0), (2.0, 500.0, 63000.0, 490.0)])
def test_the_s_curve_from_a_step_at_rest_is_the_one_from_rest_shifted(V: float, A: float, J: float, a0: float) -> None:
    """``lp.s_curve`` against its closed form (``_stepped_ramp``), and from rest against ``s_curve_time``."""
    T, D = lp.s_curve(np.array([V]), a0, np.array([J]), np.array([A]))
    want_T, want_D = _stepped_ramp(V, A, J, a0)
    assert T[0] == pytest.approx(want_T, rel=S_CURVE_RTOL)
    assert D[0] == pytest.approx(want_D, rel=S_CURVE_RTOL)
    if a0 == 0.0:
        assert T[0] == pytest.approx(s_curve_time(4.0 * D[0], V, A, J) / 2.0 - D[0] / V, rel=S_CURVE_RTOL)
    over = lp.s_curve(np.array([a0 * a0 / (2.0 * J) * 0.99]), a0, np.array([J]), np.array([A]))
    assert np.isnan(over[0][0]) and np.isnan(over[1][0])  # (the step alone passes V)


@pytest.mark.parametrize(("shape", "cap"), [("flower", 40.0), ("wave3d", 20.0), ("flower", None)])
def test_the_time_bound_is_under_the_lps_motion_on_curves(shape: str, cap: float | None) -> None:
    """The bound, S-curve ends included, is under the motion of the LP on the plan's knots (the floor off: an
    explicit knot spacing), where curvature slows the feed near the rest ends too."""
    tp = {"flower": ex.flower(1), "wave3d": Toolpath([ex.wave3d()])}[shape]
    m = router().with_feed_max(cap)
    opt = Options(method="lp")
    n0 = P.plan_piece(tp.pieces[0], m, opt).n_int
    got = schedule(tp, m, Options(method="lp", knot_spacing=tp.length / n0))
    bound = P.piece_time_bound(tp, tp.pieces[0], P._limit_set(m, opt), P.KNOT_FLOOR_GRID * n0)
    assert bound <= got.summary["lp_motion_time"]
    plain = P.piece_time_bound
    assert bound >= plain(tp, tp.pieces[0], replace(P._limit_set(m, opt), jerk=False), P.KNOT_FLOOR_GRID * n0)


def test_a_low_feed_cap_on_a_line_keeps_the_floors_knots() -> None:
    """5 mm at 1 mm/s: the default knots are 0.4 um (12,550 intervals), the floor's 10 um (500)."""
    m = router().with_feed_max(1.0)
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (5.0, 0.0, 0.0))])
    opt = Options(method="lp")
    n0 = P.plan_piece(tp.pieces[0], m, opt).n_int
    got = schedule(tp, m, opt)
    assert got.summary["knot_floor_pieces"] == 1 and got.summary["knot_floor_fallbacks"] == 0
    assert got.summary["knot_spacing"] == pytest.approx(P.KNOT_FLOOR_SAMPLES * opt.sample_period * 1.0)
    fine = schedule(tp, m, Options(method="lp", knot_spacing=tp.length / n0))
    assert fine.summary["control_points"] > 10 * got.summary["control_points"]
    bound = P.piece_time_bound(tp, tp.pieces[0], P._limit_set(m, opt), P.KNOT_FLOOR_GRID * 500)
    assert bound <= fine.summary["motion_time"]
    assert got.summary["motion_time"] <= (1.0 + P.KNOT_FLOOR_TOL) * bound
    vmax, amax, jmax = m.limit_arrays()
    u = utilisation(got.samples.position, opt.sample_period, vmax, amax, jmax)
    assert max(u.values()) <= LIMIT_FACTOR, u


def test_where_the_feed_leaves_its_cap_the_piece_is_solved_on_its_own_knots(monkeypatch: pytest.MonkeyPatch) -> None:
    """Three flower loops at 40 mm/s dip under their cap at the petal tips: the floor's profile (0.4 mm knots, 3,059
    intervals against the plan's ~6,950) is over its bound, and the schedule is the one without the floor, bit for
    bit."""
    m = router().with_feed_max(40.0)
    tp = ex.flower(3)
    opt = Options(method="lp")
    got = schedule(tp, m, opt)
    assert got.summary["knot_floor_pieces"] == 0 and got.summary["knot_floor_fallbacks"] == 1
    monkeypatch.setattr(P, "KNOT_FLOOR_MIN_GAIN", np.inf)
    plain = schedule(tp, m, opt)
    assert plain.summary["knot_floor_fallbacks"] == 0
    assert got.summary["motion_time"] == plain.summary["motion_time"]
    assert np.array_equal(got.samples.position, plain.samples.position)


def test_the_floor_under_lp_nlp_holds_the_drives_limits() -> None:
    """A 3-D wave at a 20 mm/s cap, lp+nlp: on the floor's knots (1,356 intervals against the plan's 5,656), the
    samples within the drive's u and e."""
    m = router().with_feed_max(20.0)
    tp = Toolpath([ex.wave3d()])
    opt = Options(method="lp+nlp")
    got = schedule(tp, m, opt)
    assert got.summary["knot_floor_pieces"] == 1
    n0 = P.plan_piece(tp.pieces[0], m, opt).n_int
    assert got.summary["control_points"] * P.KNOT_FLOOR_MIN_GAIN <= n0 + 2
    dr = m.drive_arrays()
    u, e = fd_drive(got.samples.position, opt.sample_period, dr)
    assert np.max(np.abs(u) / dr["umax"]) <= LIMIT_FACTOR
    assert np.max(np.abs(e) / dr["emax"]) <= LIMIT_FACTOR
    bound = P.piece_time_bound(tp, tp.pieces[0], P._limit_set(m, opt), P.KNOT_FLOOR_GRID * n0)
    assert got.summary["lp_motion_time"] <= (1.0 + P.KNOT_FLOOR_TOL) * bound


def test_the_time_bound_walks_its_grid_in_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    """The flower at a 40 mm/s cap and a 3 mm line at 10 mm/s: the bound walked 7 intervals at a time (its reach
    stretches then span several chunks) is the one walked in one chunk, to rounding."""
    flower, line = ex.flower(1), Toolpath([ex.line((0.0, 0.0, 0.0), (3.0, 0.0, 0.0))])
    for tp, cap, m in ((flower, 40.0, 4000), (line, 10.0, 1000)):
        lim = P._limit_set(router().with_feed_max(cap), Options(method="lp"))
        assert P._reach_extent(lim) > 7 * tp.length / m  # (the reach's stretch is over one chunk)
        whole = P.piece_time_bound(tp, tp.pieces[0], lim, m)
        monkeypatch.setattr(P, "KNOT_FLOOR_CHUNK", 7)
        assert P.piece_time_bound(tp, tp.pieces[0], lim, m) == pytest.approx(whole, rel=1e-12)
        monkeypatch.undo()


def test_a_floor_over_its_bound_is_solved_again_on_finer_knots_first(monkeypatch: pytest.MonkeyPatch) -> None:
    """2 mm at a 1 mm/s cap, lp+nlp (whose LP has no rest shapes): on the floor's 200 intervals its ramps from and
    to rest take the LP over the bound; on 4x the knots (800, still 6x coarser than the plan's 5,020) it is
    within it and kept.  Without that level the piece falls back to the plan's knots."""
    m = router().with_feed_max(1.0)
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (2.0, 0.0, 0.0))])
    opt = Options(method="lp+nlp")
    n_f = P.floor_count(tp.pieces[0], m, opt)
    assert n_f == 200 and P.plan_piece(tp.pieces[0], m, opt).n_int >= 2 * P.KNOT_FLOOR_LEVEL_STEP * n_f
    got = schedule(tp, m, opt)
    assert got.summary["knot_floor_pieces"] == 1 and got.summary["knot_floor_levels"] == 1
    assert got.profiles[0].n_int == P.KNOT_FLOOR_LEVEL_STEP * n_f
    bound = P.piece_time_bound(tp, tp.pieces[0], P._limit_set(m, opt), P.KNOT_FLOOR_GRID * n_f)
    assert got.summary["lp_motion_time"] <= (1.0 + P.KNOT_FLOOR_TOL) * bound
    dr = m.drive_arrays()
    u, e = fd_drive(got.samples.position, opt.sample_period, dr)
    assert max(np.max(np.abs(u) / dr["umax"]), np.max(np.abs(e) / dr["emax"])) <= LIMIT_FACTOR
    monkeypatch.setattr(P, "KNOT_FLOOR_LEVEL_STEP", 10**9)
    single = schedule(tp, m, opt)
    assert single.summary["knot_floor_pieces"] == 0 and single.summary["knot_floor_fallbacks"] == 1
