"""The NLP's rest intervals (``solvers.nlp.REST_ENDS``): a chain from (to) a rest end solves the rest
interval too, as the quadratic q from rest to the f spline's state at the inner knot.

Independent truth: the B-spline algebra of q (value and slope at the inner knot, zero at rest), scipy's
adaptive quadrature for the rest interval's travel time, numpy's kinematics for the CasADi rows, and the
finite differences of the sampled positions for the drive limits (``tests.fdcheck``).
"""

from __future__ import annotations

from collections import OrderedDict

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import quad

from geometry import examples as ex
from geometry.toolpath import Toolpath
from solvers import bspline, kinematics, nlp, pipeline, verify
from solvers.machine import router
from solvers.pipeline import Options, schedule
from solvers.timing import PieceProfile, rest_interval_times
from tests.solvers.test_nlp import _assert_seams_continuous, _capture_stats, _check_drive

#: q's value and slope at the inner knot against f^2 and 2 f f' (relative).
STATE_RTOL = 1e-12
#: Rest-interval time against scipy's adaptive quadrature (relative).
TIME_RTOL = 1e-9
#: The NLP's control point next to rest against the LP's (its bound is REST_C_CEIL of it).
REST_STEP_RTOL = 1e-9
#: CasADi rows against numpy (relative to the row's scale; sqrt(q) is floored at sqrt(REST_Q_FLOOR) Fs at rest).
ROW_RTOL = 1e-9
#: ... at rest itself, where the floor meets the rise's q'' in the jerk (relative to the rows' largest).
REST_ROW_ATOL = 1e-7
#: Motion with the rest windows' slot rows from round 0 (REST_SLOTTED) against without: the same NLP
#: with unbounded rows more, so the same optimum to Ipopt's tolerance (relative).
SLOTTED_MOTION_RTOL = 1e-3


@pytest.mark.parametrize("head", [True, False])
def test_rest_cps_meet_rest_and_the_inner_state(head: bool) -> None:
    """``rest_cps``: q = 0 at the rest end, and q = f^2, q' = 2 f f' at the inner knot, where f and f' are
    those of the f spline's control points (p_k, p_k+1): f = (p_k + p_k+1) / 2, f' = (p_k+1 - p_k) / d."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        d = float(rng.uniform(0.3, 5.0))
        p_in, p_out = rng.uniform(5.0, 200.0, 2)
        f, f1 = 0.5 * (p_in + p_out), (p_out - p_in) / d
        c = nlp.rest_cps(p_in, p_out, d, head)
        s_rest, s_in = (0.0, d) if head else (d, 0.0)
        q_rest = bspline.evaluate(c, np.array([s_rest]), d, k_lo=0, k_hi=0)[0][0]
        q, q1, _ = (x[0] for x in bspline.evaluate(c, np.array([s_in]), d, k_lo=0, k_hi=0))
        assert abs(q_rest) <= 1e-12 * f * f
        assert q == pytest.approx(f * f, rel=STATE_RTOL)
        assert q1 == pytest.approx(2.0 * f * f1, rel=STATE_RTOL, abs=1e-12 * f * f / d)


def _bump_poly(head: bool) -> np.polynomial.Polynomial:
    """The rest interval's bump as a polynomial in tau (independent of ``bspline.rest_bump``'s closed forms):
    r (1 - r)^m, r = tau at the head, 1 - tau at the tail."""
    P = np.polynomial.Polynomial
    r = P([0.0, 1.0]) if head else P([1.0, -1.0])
    return r * (1 - r) ** bspline.REST_BUMP_POWER


def _rise_poly(head: bool, h: tuple[float, ...], powers: tuple[int, ...] | None = None) -> np.polynomial.Polynomial:
    """The rest interval's rises with amplitudes h as a polynomial in tau: sum_k h_k r^2 (1 - r)^k over the k of
    ``powers`` (default ``bspline.REST_RISE_POWERS``, the NLP's), r = tau at the head, 1 - tau at the tail."""
    P = np.polynomial.Polynomial
    r = P([0.0, 1.0]) if head else P([1.0, -1.0])
    ks = bspline.REST_RISE_POWERS if powers is None else powers
    return sum((hk * r * r * (1 - r) ** k for hk, k in zip(h, ks, strict=True)), P([0.0]))


def _amps(a: float) -> tuple[float, ...]:
    """Rise amplitudes, one per ``bspline.REST_RISE_POWERS``: a, -a / 2, a / 4, ..."""
    return tuple(a * (-0.5) ** i for i in range(len(bspline.REST_RISE_POWERS)))


@pytest.mark.parametrize("head", [True, False])
def test_rest_bump_keeps_rest_and_the_inner_state(head: bool) -> None:
    """``bspline.rest_bump`` against the polynomials r (1 - r)^m (bump) and r^2 (1 - r)^k (rises) and their
    derivatives (numpy), and its ends: both 0 at rest and at the inner knot with slope 0 at the inner knot;
    at rest the bump's |b'| = 1/d and the rise's slope 0 (it leaves the step at rest alone)."""
    d, k = 1.3, 5
    t = np.linspace(0.0, 1.0, 41)
    s = (k + t) * d
    rest, inner = (0, -1) if head else (-1, 0)
    R = len(bspline.REST_RISE_POWERS)
    units = [tuple(float(i == j) for j in range(R)) for i in range(R)]
    for g, h, P in ((1.0, (), _bump_poly(head)), *((0.0, u, _rise_poly(head, u)) for u in units),
                    (-2.5, _amps(4.0), -2.5 * _bump_poly(head) + _rise_poly(head, _amps(4.0)))):
        b, b1, b2 = bspline.rest_bump(s, d, k, head, g, h)
        np.testing.assert_allclose(b, P(t), atol=1e-14)
        np.testing.assert_allclose(b1, P.deriv(1)(t) / d, atol=1e-13)
        np.testing.assert_allclose(b2, P.deriv(2)(t) / d**2, atol=1e-12)
        assert b[rest] == 0.0 and abs(b[inner]) < 1e-14 and abs(b1[inner]) < 1e-14
        assert b1[rest] == pytest.approx((1.0 if head else -1.0) * g / d, rel=1e-14, abs=1e-15)
        # the time integrand's share, (g b + h e) / r, at the unit distance r from rest
        r = t if head else 1.0 - t
        np.testing.assert_allclose(bspline.rest_bump_quotient(r[r > 0], g, h), b[r > 0] / r[r > 0], rtol=1e-12,
                                   atol=1e-14)


def test_rest_interval_times_with_bumps_match_quadrature() -> None:
    """``rest_interval_times`` with bumps and rises (``PieceProfile.rest_g``, ``rest_h``; Gauss-Legendre)
    against scipy's quad of d / sqrt(q) with q evaluated by ``PieceProfile.feed``, and against the time
    table (``PieceTiming``)."""
    from solvers.timing import PieceTiming

    d = 1.7
    for (p_in, p_out), g, h in (((40.0, 80.0), (1500.0, -800.0), ((), ())),
                                ((60.0, 45.0), (-600.0, 2500.0), (_amps(9000.0), _amps(-1500.0))),
                                ((60.0, 45.0), (0.0, 0.0), (_amps(4000.0), _amps(6000.0)))):
        head, tail = nlp.rest_cps(p_in, p_out, d, True), nlp.rest_cps(p_out, p_in, d, False)
        c = np.concatenate([head, np.full(4, 2000.0), tail])
        prof = PieceProfile(s_start=0.0, length=(c.size - 2) * d, d=d, c=c, rest_g=g, rest_h=h)
        n = prof.n_int

        def inv(s: float, prof: PieceProfile = prof) -> float:
            return 1.0 / float(prof.feed(np.array([s]))[0][0])

        # 1 / sqrt(q) ~ (distance to rest)^(-1/2): in w, the distance d w^2, the integrand is smooth
        L = n * d
        t0 = quad(lambda w, d=d: 2 * d * w * inv(d * w * w), 0.0, 1.0, epsabs=0, epsrel=1e-12, limit=200)[0]
        t1 = quad(lambda w, L=L: 2 * d * w * inv(L - d * w * w), 0.0, 1.0, epsabs=0, epsrel=1e-12, limit=200)[0]
        got = rest_interval_times(prof)
        assert got[0] == pytest.approx(t0, rel=TIME_RTOL)
        assert got[1] == pytest.approx(t1, rel=TIME_RTOL)
        mid = sum(quad(inv, k * d, (k + 1) * d, epsabs=0, epsrel=1e-12)[0] for k in range(1, n - 1))
        assert PieceTiming.build(prof).duration == pytest.approx(t0 + t1 + mid, rel=TIME_RTOL)
        # the rest slopes: q' at rest, with the bump's g / d
        assert prof.rest_slopes() == pytest.approx(((2 * c[1] + g[0]) / d, -(2 * c[-2] + g[1]) / d), rel=1e-14)


def test_rest_interval_times_match_quadrature() -> None:
    """The closed form of ``rest_interval_times`` (asinh, asin, or 2 d / sqrt(A)) against scipy's quad of
    d / sqrt(q) over both rest intervals, with the acceleration rising (B > 0), falling (B < 0) or constant."""
    d = 1.7
    for p_in, p_out in ((40.0, 80.0), (60.0, 45.0), (30.0, 50.0)):
        head, tail = nlp.rest_cps(p_in, p_out, d, True), nlp.rest_cps(p_out, p_in, d, False)
        c = np.concatenate([head, np.full(4, 2000.0), tail])
        prof = PieceProfile(s_start=0.0, length=(c.size - 2) * d, d=d, c=c)
        n = prof.n_int

        def inv(s: float, c: np.ndarray = c) -> float:
            return 1.0 / float(np.sqrt(max(bspline.evaluate(c, np.array([s]), d)[0][0], 0.0)))

        t0 = quad(inv, 0.0, d, epsabs=0, epsrel=1e-12, limit=200)[0]
        t1 = quad(inv, (n - 1) * d, n * d, epsabs=0, epsrel=1e-12, limit=200)[0]
        got = rest_interval_times(prof)
        assert got[0] == pytest.approx(t0, rel=TIME_RTOL)
        assert got[1] == pytest.approx(t1, rel=TIME_RTOL)
    # a rest interval whose feed does not leave rest takes forever
    c = np.concatenate([[0.0, 0.0, 100.0], np.full(4, 2000.0), [100.0, 0.0, 0.0]])
    assert rest_interval_times(PieceProfile(0.0, 7 * d, d, c)) == (np.inf, np.inf)


def test_rest_rows_are_the_q_kinematics() -> None:
    """``_Shape`` with a head and a tail: its rows at the rest intervals' checkpoints are u, e of the feed
    sqrt(q), q from ``rest_cps`` of the free control points at the inner knots, evaluated here with numpy
    (``kinematics.from_q``, ``axis_kinematics``); its extra rows are the control points next to rest, and
    its objective's rest term is the rest intervals' time (``rest_interval_times``) over the window's length."""
    n, N, axes = 6, 4, (0, 1)
    shape = nlp._Shape(n, N, axes, False, head=True, tail=True)
    taus = nlp.rest_point_taus(N)
    Mt = 2 * taus.size  # the rest points: the head's, then the tail's
    assert shape.n_rest == 2 + 2 * len(axes) * Mt  # (u and e per axis at each rest point)
    k, tau = nlp.checkpoint_layout(n, N)
    K = k.size
    rng = np.random.default_rng(11)
    d, Fs = 1.5, 120.0
    s = (k + tau) * d
    s_pts = np.concatenate([taus * d, (n - 1 + taus) * d])

    def geo_at(s: np.ndarray) -> dict[str, np.ndarray]:
        return {name: np.column_stack([np.sin(s + i), np.cos(0.7 * s + i)])
                for i, name in enumerate(("d1", "d2", "d3"))}

    geo, geo_p = geo_at(s), geo_at(s_pts)
    coef = rng.uniform(0.5, 1.5, (len(axes), 8))
    # p_0 and p_n+1 carry the rest intervals' bumps (REST_BUMP): one raises q inside, one lowers it; the
    # variables after them the rises (REST_RISE, one per power: the head's, then the tail's)
    R = len(bspline.REST_RISE_POWERS)
    assert shape.n_rise == 2 * R
    rise_head, rise_tail = _amps(0.5), _amps(-0.2)
    x = np.concatenate([[0.2], rng.uniform(0.3, 0.6, n), [-0.1], rise_head, rise_tail])
    p = np.concatenate([
        [Fs, 1 / d], *geo["d1"].T, *geo["d2"].T, *geo["d3"].T, *geo["d3"].T, np.zeros(K), np.zeros(K),
        coef.ravel(),
        # the rest points' x_s, x_ss, x_sss per axis
        *(geo_p[name][:, m] for m in range(len(axes)) for name in ("d1", "d2", "d3")),
    ])
    fn = ca.Function("g", [shape._problem["x"], shape._problem["p"]], [shape._problem["g"], shape._problem["f"]])
    g_ca, obj = fn(x, p)
    g = np.asarray(g_ca).ravel()
    pw = x * Fs
    rest = (k == 0) | (k == n - 1)
    # independent: q of each rest interval (all its checkpoints, both ends included) from its control
    # points, through bspline and from_q
    c_head, c_tail = nlp.rest_cps(pw[1], pw[2], d, True), nlp.rest_cps(pw[n - 1], pw[n], d, False)
    g_head, g_tail = pw[0] * (pw[1] + pw[2]) / 2, pw[n + 1] * (pw[n - 1] + pw[n]) / 2
    h_head = tuple(r * Fs * (pw[1] + pw[2]) / 2 for r in rise_head)
    h_tail = tuple(r * Fs * (pw[n - 1] + pw[n]) / 2 for r in rise_tail)

    def rest_feed(s: np.ndarray, kk: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        head = kk == 0
        cq, gb, hb = (c_head, g_head, h_head) if head else (c_tail, g_tail, h_tail)
        q3 = bspline.evaluate(cq, s, d, k_lo=kk, k_hi=kk, col0=kk)
        bump = gb * _bump_poly(head) + _rise_poly(head, hb)
        t = s / d - kk
        return kinematics.from_q(q3[0] + bump(t), q3[1] + bump.deriv(1)(t) / d, q3[2] + bump.deriv(2)(t) / d**2)

    fd = tuple(np.zeros(K) for _ in range(3))
    for sel, kk in ((k == 0, 0), (k == n - 1, n - 1)):
        for o, v in zip(fd, rest_feed(s[sel], kk), strict=True):
            o[sel] = v
    # the verification's feed (``_window_feed``) is the same inside the rest intervals
    inside = rest & (tau > 0) & (tau < 1)
    for got, want in zip(nlp._window_feed(pw, s[inside], 0, n, d, True, True), fd, strict=True):
        np.testing.assert_allclose(got, want[inside], rtol=1e-12, atol=1e-9)
    from geometry.toolpath import PathSamples

    def drive(s: np.ndarray, geo: dict[str, np.ndarray], fd: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        z = np.zeros((s.size, 1))
        gs = PathSamples(s=s, position=np.zeros((s.size, 3)), d1=np.hstack([geo["d1"], z]),
                         d2=np.hstack([geo["d2"], z]), d3=np.hstack([geo["d3"], z]))
        return kinematics.axis_kinematics(gs, *fd)

    v, acc, j = drive(s, geo, fd)
    for m in range(len(axes)):
        u = coef[m, 0] * acc[:, m] + coef[m, 1] * v[:, m]
        e = coef[m, 2] * v[:, m] + coef[m, 3] * acc[:, m] + coef[m, 4] * j[:, m]
        blk = m * 3
        idx = np.flatnonzero(rest & (shape.row_index[blk] >= 0))
        np.testing.assert_allclose(g[shape.row_index[blk, idx]], u[idx], rtol=ROW_RTOL, atol=ROW_RTOL * np.abs(u).max())
        # (at rest itself the floored sqrt(q), 1e-10 Fs, times the rise's q'' = 2 h / d^2 is in the rows' jerk)
        at_rest = ((k == 0) & (tau == 0.0)) | ((k == n - 1) & (tau == 1.0))
        idx = np.flatnonzero(rest & ~at_rest)
        np.testing.assert_allclose(g[shape.row_index[blk + 1, idx]], e[idx], rtol=ROW_RTOL,
                                   atol=ROW_RTOL * np.abs(e).max())
        idx = np.flatnonzero(at_rest)
        np.testing.assert_allclose(g[shape.row_index[blk + 1, idx]], e[idx], atol=REST_ROW_ATOL * np.abs(e).max())
    # the extra rows: the acceleration step at rest, q' d / 2 there, ...
    first = shape.rows - shape.n_rest
    np.testing.assert_allclose(g[first : first + 2],
                               [(c_head[1] + g_head / 2) / Fs**2, (c_tail[1] + g_tail / 2) / Fs**2], rtol=1e-12)
    # ... then u and e per axis at the rest points (between the checkpoints, exact x_sss there)
    fd_p = tuple(np.concatenate(parts) for parts in zip(*(rest_feed(s_pts[sl], kk) for sl, kk in (
        (slice(0, Mt // 2), 0), (slice(Mt // 2, Mt), n - 1))), strict=True))
    v, acc, j = drive(s_pts, geo_p, fd_p)
    rows_p = g[first + 2 :].reshape(2 * len(axes), Mt)
    for m in range(len(axes)):
        u = coef[m, 0] * acc[:, m] + coef[m, 1] * v[:, m]
        e = coef[m, 2] * v[:, m] + coef[m, 3] * acc[:, m] + coef[m, 4] * j[:, m]
        np.testing.assert_allclose(rows_p[2 * m], u, rtol=ROW_RTOL, atol=ROW_RTOL * np.abs(u).max())
        np.testing.assert_allclose(rows_p[2 * m + 1], e, rtol=ROW_RTOL, atol=ROW_RTOL * np.abs(e).max())
    # with zero time weights on the checkpoints the objective is the rest intervals' time x Fs / (n d)
    c = np.concatenate([c_head, np.full(n - 4, 1.0), c_tail])
    t_rest = sum(rest_interval_times(PieceProfile(0.0, n * d, d, c, rest_g=(g_head, g_tail), rest_h=(h_head, h_tail))))
    assert float(obj) == pytest.approx(t_rest * Fs / (n * d), rel=1e-6)


def test_nlp_solves_the_rest_intervals(monkeypatch: pytest.MonkeyPatch) -> None:
    """One flower loop: with REST_ENDS the NLP moves the state at knots 1 and n_int - 1 (the rest intervals'
    q differs from the LP's, their acceleration at rest within the LP's), the motion is shorter than with
    the LP's rest intervals (same run), and shorter still with the bumps (REST_BUMP) than without, feed
    and tangential acceleration are continuous at every knot, and
    the drive limits hold in the finite differences of the samples."""
    tp, m = ex.flower(1), router()
    monkeypatch.setattr(nlp, "REST_ENDS", False)
    off = schedule(tp, m, Options(method="lp+nlp"))
    monkeypatch.setattr(nlp, "REST_ENDS", True)
    on = schedule(tp, m, Options(method="lp+nlp"))
    lp_c, c = off.profiles[0].c, on.profiles[0].c
    assert not np.allclose(c[:3], lp_c[:3]) and not np.allclose(c[-3:], lp_c[-3:])
    (q1_0, q1_L), (lp1_0, lp1_L) = on.profiles[0].rest_slopes(), off.profiles[0].rest_slopes()
    assert 0 < q1_0 <= lp1_0 * (1 + REST_STEP_RTOL) and lp1_L * (1 + REST_STEP_RTOL) <= q1_L < 0
    assert c[0] == -c[1] and c[-1] == -c[-2]
    assert on.summary["nlp_rest_retries"] == 0 and on.diagnostics["nlp_fallbacks"] == []
    assert on.summary["motion_time"] < off.summary["motion_time"]
    # the bumps (REST_BUMP) are used at both ends, and shorten the motion against the quadratic alone
    assert all(g != 0.0 for g in on.profiles[0].rest_g)
    monkeypatch.setattr(nlp, "REST_BUMP", False)
    plain = schedule(tp, m, Options(method="lp+nlp"))
    assert plain.profiles[0].rest_g == (0.0, 0.0)
    assert on.summary["motion_time"] < plain.summary["motion_time"] < off.summary["motion_time"]
    # ... and the rises (REST_RISE) too: used at both ends, shorter than the bumps alone
    assert all(any(h) for h in on.profiles[0].rest_h)
    monkeypatch.setattr(nlp, "REST_BUMP", True)
    monkeypatch.setattr(nlp, "REST_RISE", False)
    bumps = schedule(tp, m, Options(method="lp+nlp"))
    assert not any(any(h) for h in bumps.profiles[0].rest_h) and all(g != 0.0 for g in bumps.profiles[0].rest_g)
    assert on.summary["motion_time"] < bumps.summary["motion_time"] < plain.summary["motion_time"]
    _assert_seams_continuous(on)
    _check_drive(m, on)


@pytest.mark.parametrize("faulted", [(0,), (0, 1)])
def test_failed_rest_window_is_solved_again_from_the_lp_state(
    monkeypatch: pytest.MonkeyPatch, faulted: tuple[int, ...]
) -> None:
    """The chain's first window, from rest, fails: it is solved again without the rise (REST_RISE), and if that
    fails too, the chain is solved again from the LP's state at knot 1, so the first rest interval is the LP's
    again (each counted in ``nlp_rest_retries``, not a fallback); the limits hold."""
    tp, m = ex.flower(1), router()
    monkeypatch.setattr(nlp._SHAPE_CACHE, "shapes", OrderedDict(), raising=False)
    monkeypatch.setattr(nlp, "REST_ENDS", False)
    off = schedule(tp, m, Options(method="lp+nlp"))
    monkeypatch.setattr(nlp, "REST_ENDS", True)
    made = _capture_stats(monkeypatch)

    def fault(index: int) -> None:
        if index in faulted:
            raise RuntimeError("injected")

    sch = schedule(tp, m, Options(method="lp+nlp", nlp_fault=fault))
    assert sch.summary["nlp_rest_retries"] == made[-1].rest_retries == len(faulted)
    assert sch.diagnostics["nlp_fallbacks"] == []
    first = sch.profiles[0]
    assert not any(first.rest_h[0])
    if len(faulted) == 1:  # the NLP's rest interval, with its bump, without its rise
        assert not np.allclose(first.c[:3], off.profiles[0].c[:3]) and first.rest_g[0] != 0.0
    else:
        np.testing.assert_array_equal(first.c[:3], off.profiles[0].c[:3])
        assert first.rest_g[0] == 0.0
    assert not np.allclose(first.c[-3:], off.profiles[0].c[-3:])  # the end's still the NLP's
    assert any(first.rest_h[1])
    _assert_seams_continuous(sch)
    _check_drive(m, sch)


def test_bumps_only_where_the_machine_stands() -> None:
    """A path with a corner (two pieces): the bump (REST_BUMP) is used at the path's start and end, where the
    machine stands, and not on either side of the corner, whose acceleration step the two pieces share
    (``pipeline._standing_ends``); the drive limits hold in the finite differences of the samples."""
    m = router()
    sch = schedule(ex.square_corner(50.0), m, Options(method="lp+nlp"))
    first, second = sch.profiles
    assert first.rest_g[1] == 0.0 and second.rest_g[0] == 0.0
    assert not any(first.rest_h[1]) and not any(second.rest_h[0])
    assert first.rest_g[0] != 0.0 and second.rest_g[1] != 0.0
    _check_drive(m, sch)


@pytest.mark.parametrize("kinematic", [False, True])
def test_rest_points_bounds_and_tightening(kinematic: bool) -> None:
    """The rest points' rows (``REST_SUBDIV``): one u and one e row per axis with both bounds (``_exact_bounds``
    of ``_point_bounds``: e's upper bound from the e_hi row's, its lower from the e_lo row's, u's with the
    friction offset), and a violation tightens only the rest points within one spacing of it, by
    overshoot^-TIGHTEN_POWER - TIGHTEN_MARGIN (``_tighten_points``)."""
    lim = nlp.NlpLimits.from_machine(router(), False, kinematic)
    assert (lim.amax is not None) == kinematic
    moving = (0, 1)
    d1 = np.array([[1.0, -0.5, 0.0], [-0.3, 1e-12, 0.0], [0.2, 0.8, 0.0]])
    P = d1.shape[0]
    bu = np.full((P, 2), 0.9)
    be = np.full((P, 2), 0.8)
    lo, hi = nlp._point_bounds(lim, moving, d1, bu, be, np.full(P, 0.7))
    per_axis = 6 if lim.amax is not None else 3
    assert lo.shape == hi.shape == (2 * per_axis, P)
    xlo, xhi = nlp._exact_bounds(lo, hi, lim.amax is not None)
    assert xlo.shape == xhi.shape == (2 * (per_axis - per_axis // 3), P)
    for i, ax in enumerate(moving):
        um, c, dd = lim.umax[ax], lim.c[ax], lim.d[ax]
        sign = np.sign(d1[:, ax])
        unsure = np.abs(d1[:, ax]) < nlp.SIGN_EPS
        r = i * (per_axis - per_axis // 3)
        np.testing.assert_allclose(xhi[r], (0.9 * um - c - dd * np.where(unsure, 1.0, sign)) / um, rtol=1e-15)
        np.testing.assert_allclose(xlo[r], (-0.9 * um - c - dd * np.where(unsure, -1.0, sign)) / um, rtol=1e-15)
        np.testing.assert_array_equal(xhi[r + 1], 0.8)
        np.testing.assert_array_equal(xlo[r + 1], -0.8)
        if kinematic:  # a and j: the kinematic rows' factor, both bounds
            for k in (r + 2, r + 3):
                np.testing.assert_array_equal(xhi[k], 0.7)
                np.testing.assert_array_equal(xlo[k], -0.7)
    # (no rest points: nothing, without an error)
    e_lo, e_hi = nlp._exact_bounds(*nlp._point_bounds(lim, moving, np.zeros((0, 3)), np.zeros((0, 2)),
                                                     np.zeros((0, 2)), np.zeros(0)), lim.amax is not None)
    assert e_lo.shape[1] == e_hi.shape[1] == 0
    # tightening: points at s = 0.1, 0.2, 0.3 (spacing 0.1); one violation of 1.05 at s = 0.17
    fine = np.array([0.05, 0.17, 0.4])
    util = {"servo_error": np.array([[0.5, 0.5, 0.0], [0.2, 1.05, 0.0], [0.9, 0.1, 0.0]])}
    fac = np.full(3, nlp.BOUND_FACTOR)
    nlp._tighten_points(util, fine, np.array([0.1, 0.2, 0.3]), 0.1, fac)
    want = nlp.BOUND_FACTOR * (1.05 ** -nlp.TIGHTEN_POWER - nlp.TIGHTEN_MARGIN)
    np.testing.assert_allclose(fac, [want, want, nlp.BOUND_FACTOR], rtol=1e-15)


def test_rest_intervals_without_rest_points(monkeypatch: pytest.MonkeyPatch) -> None:
    """REST_SUBDIV = 1 (the rest intervals' N + 1 checkpoints only, no rest points) with one rise (session 16's
    rest intervals) still solves both rest intervals (no rest retries: an error in a window is a retry, not a
    crash), and the rest points with the default rises make the flower's motion shorter; the drive limits hold
    in the finite differences of the samples."""
    tp, m = ex.flower(1), router()
    monkeypatch.setattr(nlp, "REST_SUBDIV", 1)
    monkeypatch.setattr(bspline, "REST_RISE_POWERS", (2,))
    few = schedule(tp, m, Options(method="lp+nlp"))
    assert few.summary["nlp_rest_retries"] == 0 and few.diagnostics["nlp_fallbacks"] == []
    assert all(any(h) for h in few.profiles[0].rest_h)
    monkeypatch.undo()
    dense = schedule(tp, m, Options(method="lp+nlp"))
    assert dense.summary["motion_time"] < few.summary["motion_time"]
    _check_drive(m, few)


def test_rest_windows_start_with_their_slot_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """REST_SLOTTED: a window from or to rest asks for its shape with the cut slots' rows from round 0 (one
    shape to build, not two), the unused slots' rows unbounded.  Both rest intervals are still solved (an
    error in a rest window would be a rest retry, not a crash), the motion is the one the unslotted start
    gives to Ipopt's tolerance, and the drive limits hold in the finite differences of the samples."""
    tp, m = ex.flower(1), router()
    asked: list[tuple[int, bool, bool, bool]] = []
    real = nlp._cached_shape

    def spy(n: int, N: int, axes: tuple[int, ...], with_aj: bool, slotted: bool, head: bool = False,
            tail: bool = False) -> nlp._Shape:
        asked.append((n, slotted, head, tail))
        return real(n, N, axes, with_aj, slotted, head, tail)

    monkeypatch.setattr(nlp, "_cached_shape", spy)
    on = schedule(tp, m, Options(method="lp+nlp"))
    rest = [a for a in asked if a[2] or a[3]]
    assert rest and all(slotted for _, slotted, _, _ in rest)
    assert on.summary["nlp_rest_retries"] == 0 and on.diagnostics["nlp_fallbacks"] == []
    assert all(any(h) for h in on.profiles[0].rest_h)
    asked.clear()
    monkeypatch.setattr(nlp, "REST_SLOTTED", False)
    off = schedule(tp, m, Options(method="lp+nlp"))
    assert any(not slotted for _, slotted, head, tail in asked if head or tail)
    assert on.summary["motion_time"] == pytest.approx(off.summary["motion_time"], rel=SLOTTED_MOTION_RTOL)
    _assert_seams_continuous(on)
    _check_drive(m, on)


@pytest.mark.parametrize("keys", [(), (0,), (9,), (0, 1, 2, 7, 8, 9), (3, 5), tuple(range(10))])
def test_splice_replaces_exactly_the_given_entries(keys: tuple[int, ...]) -> None:
    """``nlp._splice`` (a rest window's checkpoints put into the window's rows): the entries at the keys are
    the given expressions, every other entry is the column's, in order."""
    x = ca.SX.sym("x", 10)
    col = 2.0 * x + 1.0
    rep = {k: x[k] * x[k] for k in keys}
    out = nlp._splice(col, rep)
    assert out.size1() == 10
    f = ca.Function("f", [x], [out])
    xv = np.arange(10.0) + 0.5
    want = 2.0 * xv + 1.0
    want[list(keys)] = xv[list(keys)] ** 2
    np.testing.assert_array_equal(np.asarray(f(xv)).ravel(), want)


#: The feed's largest drop below its running maximum while it leaves (or, reversed, reaches) rest, as a share
#: of the cap: a ramp under a feed cap is monotone to this (the samples' round-off; measured 0 at 1-6 mm/s).
RAMP_DIP = 1e-3


def _ramp_dip(feed: np.ndarray, cap: float) -> float:
    """Largest drop of ``feed`` below its running maximum over its first half and (reversed) its last."""
    h = feed.size // 2
    out = 0.0
    for f in (feed[:h], feed[::-1][:h]):
        out = max(out, float(np.max(np.maximum.accumulate(f) - f)) / cap)
    return out


@pytest.mark.parametrize("cap", [1.0, 5.0, 10.0])
def test_a_ramp_to_a_low_feed_cap_is_monotone(monkeypatch: pytest.MonkeyPatch, cap: float) -> None:
    """A line under a low feed cap reaches it within its rest intervals: with the rises the degree-7 rest
    polynomial cannot rise to the cap and stay flat and wobbled under it (session 58: 17.6 % of the cap at
    1 mm/s in the first 13 ms, 4.1 % at 5; 1.9 % at 10 with REST_RISE_CAP_SHARE 0.9, the LP at 0.85 of the cap at
    the inner knot).  Those ends are solved without their rises (REST_RISE_CAP_SHARE): monotone ramps, a few ms
    slower, within the drive limits (finite differences of the samples)."""
    from geometry import primitives
    from geometry.toolpath import Toolpath

    tp = Toolpath([primitives.line(np.zeros(3), np.array([8.0 * cap, 2.4 * cap, 0.0]))])
    m = router().with_feed_max(cap)
    sch = schedule(tp, m, Options(method="lp+nlp"))
    assert _ramp_dip(sch.samples.feed, cap) <= RAMP_DIP
    assert sch.summary["nlp_rest_rises_capped"] == 2
    assert float(np.max(sch.samples.feed)) <= cap * (1.0 + 1e-6)
    _check_drive(m, sch)
    monkeypatch.setattr(nlp, "REST_RISE_CAP_SHARE", None)  # (the switch off: the wobble is back)
    off = schedule(tp, m, Options(method="lp+nlp"))
    assert _ramp_dip(off.samples.feed, cap) > 10 * RAMP_DIP
    assert off.summary["nlp_rest_rises_capped"] == 0
    assert off.summary["motion_time"] < sch.summary["motion_time"]


#: lp+nlp with ``pipeline.NLP_REST_MIN_INTERVALS`` against without, short rest-to-rest moves on the router: at least
#: this much shorter (session 71 measured -0.9 % to -1.7 % on these).
FINER_REST_GAIN = 0.005
#: Short rest-to-rest paths whose pieces plan under ``pipeline.REST_MIN_INTERVALS`` knot intervals on the router.
SHORT_PATHS = {
    "line 1 mm": lambda: Toolpath([ex.line((0, 0, 0), (1.0, 0, 0))]),
    "line 5 mm": lambda: Toolpath([ex.line((0, 0, 0), (5.0, 0, 0))]),
    "square corner": lambda: ex.square_corner(50.0),
}


@pytest.mark.parametrize("name", ["line 1 mm", "line 5 mm", "square corner"])
def test_lp_nlp_solves_short_pieces_on_finer_knots(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """A piece kept on its first ``pipeline.REST_MIN_INTERVALS`` plan is solved on ``NLP_REST_MIN_INTERVALS``
    instead under lp+nlp (method lp keeps the first): every piece's control points say so (n + 2 of a quadratic
    B-spline), the motion is shorter than without it (the same code, the switch off), and the drive limits hold in
    the finite differences of the samples."""
    tp = SHORT_PATHS[name]()
    m = router()
    assert pipeline.NLP_REST_MIN_INTERVALS > pipeline.REST_MIN_INTERVALS
    finer = schedule(tp, m, Options(method="lp+nlp"))
    lp = schedule(tp, m, Options(method="lp"))
    assert [p.c.size for p in finer.profiles] == [pipeline.NLP_REST_MIN_INTERVALS + 2] * len(tp.pieces)
    assert [p.c.size for p in lp.profiles] == [pipeline.REST_MIN_INTERVALS + 2] * len(tp.pieces)
    monkeypatch.setattr(pipeline, "NLP_REST_MIN_INTERVALS", None)
    coarse = schedule(tp, m, Options(method="lp+nlp"))
    assert [p.c.size for p in coarse.profiles] == [pipeline.REST_MIN_INTERVALS + 2] * len(tp.pieces)
    assert finer.summary["motion_time"] <= (1.0 - FINER_REST_GAIN) * coarse.summary["motion_time"]
    assert finer.diagnostics["nlp_fallbacks"] == []
    assert finer.summary["finer_rest_plans"] == len(tp.pieces) and coarse.summary["finer_rest_plans"] == 0
    _check_drive(m, finer)


#: lp+nlp with ``pipeline.NLP_FINER_OWN_PLANS`` against without, on the router: at least this much shorter (session
#: 72 measured -0.61 % and -0.96 %; a 200 mm line -0.29 %, wave3d +0.05 %, the flower unchanged: its plan is finer).
FINER_OWN_GAIN = 0.003
#: Paths of one piece whose plan is REST_MIN_INTERVALS .. NLP_REST_MIN_INTERVALS - 1 knot intervals on the router.
OWN_PLAN_PATHS = {
    "line 150 mm": lambda: Toolpath([ex.line((0, 0, 0), (150.0, 0, 0))]),
    "circle R30": lambda: Toolpath([ex.circle(30.0)]),
}


@pytest.mark.parametrize("name", sorted(OWN_PLAN_PATHS))
def test_lp_nlp_solves_pieces_on_coarser_plans_on_finer_knots(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """A piece kept on its own plan of fewer than ``pipeline.NLP_REST_MIN_INTERVALS`` knot intervals (but at least
    ``REST_MIN_INTERVALS``) is solved on NLP_REST_MIN_INTERVALS too under lp+nlp (``NLP_FINER_OWN_PLANS``): its
    control points say so, the motion is shorter than with the switch off, and the drive limits hold in the finite
    differences of the samples."""
    tp, m = OWN_PLAN_PATHS[name](), router()
    n_plan = pipeline.plan_piece(tp.pieces[0], m, Options(method="lp+nlp")).n_int
    assert pipeline.REST_MIN_INTERVALS <= n_plan < pipeline.NLP_REST_MIN_INTERVALS
    finer = schedule(tp, m, Options(method="lp+nlp"))
    assert [p.c.size for p in finer.profiles] == [pipeline.NLP_REST_MIN_INTERVALS + 2]
    assert finer.summary["finer_rest_plans"] == 1 and finer.diagnostics["nlp_fallbacks"] == []
    monkeypatch.setattr(pipeline, "NLP_FINER_OWN_PLANS", False)
    plain = schedule(tp, m, Options(method="lp+nlp"))
    assert [p.c.size for p in plain.profiles] == [n_plan + 2] and plain.summary["finer_rest_plans"] == 0
    assert finer.summary["motion_time"] <= (1.0 - FINER_OWN_GAIN) * plain.summary["motion_time"]
    _check_drive(m, finer)


@pytest.mark.parametrize("name", ["line 5 mm", "square corner"])
def test_a_finer_rest_plan_whose_samples_need_repairs_is_solved_as_without_it(
    monkeypatch: pytest.MonkeyPatch, name: str,
) -> None:
    """Where the first samples of a piece on ``pipeline._finer_rest_plan``'s knots need a repair (here forced: every
    sample over half a limit is flagged, ``verify.REPAIR_TOL`` -0.5), the piece is solved again as without the finer
    plan, repairs and all: the positions are those of the same schedule with ``NLP_REST_MIN_INTERVALS`` off, bit for
    bit, and the summary counts each such piece in ``finer_rest_retries``."""
    tp = SHORT_PATHS[name]()
    m = router()
    monkeypatch.setattr(verify, "REPAIR_TOL", -0.5)
    monkeypatch.setattr(verify, "FD_REPAIR_TOL", -0.5)
    finer = schedule(tp, m, Options(method="lp+nlp", nlp_workers=1))
    assert finer.summary["finer_rest_plans"] == finer.summary["finer_rest_retries"] == len(tp.pieces)
    assert finer.summary["sample_repairs"] >= 1
    monkeypatch.setattr(pipeline, "NLP_REST_MIN_INTERVALS", None)
    plain = schedule(tp, m, Options(method="lp+nlp", nlp_workers=1))
    assert plain.summary["finer_rest_plans"] == plain.summary["finer_rest_retries"] == 0
    np.testing.assert_array_equal(finer.samples.position, plain.samples.position)
    assert finer.diagnostics["nlp_fallbacks"] == plain.diagnostics["nlp_fallbacks"]


@pytest.mark.parametrize("given", [{"lp_window": 40}, {"lp_overlap": 20}, {"nlp_window": 30}, {"nlp_overlap": 8},
                                   {"knot_feed_floor": 50.0}])
def test_no_finer_rest_plan_where_windows_are_given(given: dict[str, float]) -> None:
    """Windows and overlaps given in knot intervals (``Options.lp_window`` ... ``nlp_overlap``) would span half the
    path on ``NLP_REST_MIN_INTERVALS``' knots: there the piece stays on its first plan (bench+opts seed 3, an LP
    overlap of 5 intervals, ran 37.5 % longer on 128); with none given it takes them.  Nor where a knot feed floor
    is given (``Options.knot_feed_floor``: knots coarsened on purpose, as ``pipeline.fit_intervals`` does to fit
    a budget)."""
    tp, m = SHORT_PATHS["line 5 mm"](), router()
    sch = schedule(tp, m, Options(method="lp+nlp", **given))  # type: ignore[arg-type]
    assert sch.summary["finer_rest_plans"] == 0
    assert [p.c.size for p in sch.profiles] == [pipeline.REST_MIN_INTERVALS + 2]
    default = schedule(tp, m, Options(method="lp+nlp"))
    assert default.summary["finer_rest_plans"] == 1
