"""The LP's rest shapes (method lp with jerk, ``solvers.lp.WindowSpec.rest_shapes``): a bump and rises added to q in
a piece's first and last knot interval, their amplitudes LP variables.

Independent truth: numpy polynomials for the shapes and their integrals, the time table's own evaluation of a
profile's bumps (``timing.PieceProfile.feed``) for the LP's rows, the closed-form jerk-limited optimum of a
straight line (``tests.solvers.test_optimality.s_curve_time``) and the finite differences of the sampled
positions for the limits (``tests.fdcheck``).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from geometry import Toolpath
from geometry import examples as ex
from solvers import bspline, pipeline
from solvers.lp import LimitSet, WindowLP, WindowSpec
from solvers.machine import router
from solvers.pipeline import Options, schedule
from solvers.timing import PieceProfile, rest_dips
from tests.fdcheck import utilisation
from tests.solvers.test_nlp_rest import _bump_poly, _rise_poly
from tests.solvers.test_optimality import s_curve_time

#: The shapes against their polynomials (absolute, per unit amplitude; derivatives scaled by d^-1, d^-2).
SHAPE_ATOL = 1e-13
#: The LP's rows against the time table's evaluation of the same q (relative to the largest value).
ROWS_RTOL = 1e-12
#: Lines of these lengths (mm) on the router: with the shapes within this share of the jerk-limited optimum
#: (measured 6.6 / 2.0 / 1.2 % since session 47's steeper rises, ``bspline.LP_REST_RISE_POWERS``, and 1.9 / 1.9 /
#: 1.2 % with session 48's cap on q* next to rest, ``test_lp_rest_reach``, 1.2 / 1.5 / 0.96 % with its rise of
#: power 256; 7.7 / 7.5 / 7.9 % with the NLP's four
#: alone, which spent 15-35 ms per rest end bringing q' up from 2 a_rest; without any shapes 25.8-28.5 %,
#: ``test_optimality.LINE_JERK_GAP``) ...
SHAPED_LINE_GAP = {1.0: 0.075, 20.0: 0.03, 100.0: 0.02}
LINES_MM = tuple(SHAPED_LINE_GAP)
#: ... and at most this share of their time without the shapes (measured 0.847 / 0.794 / 0.795, 0.810 / 0.793 /
#: 0.795 with the cap, 0.804 / 0.790 / 0.793 with the power 256; 0.836-0.855 with the four rises alone)
SHAPED_GAIN = 0.87
#: Sampled limits (finite differences at 1 kHz), as everywhere (issue 2).
LIMIT_FACTOR = 1.01


def _shape_by_product_rule(r: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shape i of ``bspline.rest_shapes`` (0: the bump r u^m, else the rise r^2 u^k of the (i - 1)-th of
    LP_REST_RISE_POWERS; u = 1 - r) and its first two r-derivatives, expanded by the product rule with numpy's
    powers (the library factors them and builds the powers by products).  Numpy's polynomials cannot stand in for
    the steep rises: (1 - r)^128 in the power basis cancels to nothing."""
    u = 1.0 - r
    if i == 0:
        m = bspline.REST_BUMP_POWER
        return r * u**m, u**m - m * r * u ** (m - 1), -2.0 * m * u ** (m - 1) + m * (m - 1) * r * u ** (m - 2)
    k = bspline.LP_REST_RISE_POWERS[i - 1]
    return (r * r * u**k, 2.0 * r * u**k - k * r * r * u ** (k - 1),
            2.0 * u**k - 4.0 * k * r * u ** (k - 1) + k * (k - 1) * r * r * u ** (k - 2))


@pytest.mark.parametrize("head", [True, False])
def test_rest_shapes_are_the_unit_bump_and_rises(head: bool) -> None:
    """``bspline.rest_shapes``: column 0 the bump r (1 - r)^m, then the rises r^2 (1 - r)^k of LP_REST_RISE_POWERS,
    whose first powers are the NLP's REST_RISE_POWERS (those against numpy polynomials too), with their derivatives,
    each equal to ``rest_bump`` at unit amplitude; ``rest_shape_integrals`` their integrals over the interval
    (scipy's quad) and ``rest_shape_peaks`` their largest values (on a grid of 10^5 points)."""
    d, k = 0.9, 7
    t = np.linspace(0.0, 1.0, 33)
    s = (k + t) * d
    S0, S1, S2 = bspline.rest_shapes(s, d, k, head)
    ks = bspline.LP_REST_RISE_POWERS
    R, R_nlp = len(ks), len(bspline.REST_RISE_POWERS)
    assert ks[:R_nlp] == bspline.REST_RISE_POWERS  # (the NLP's rises read the first shapes)
    assert S0.shape == (t.size, bspline.REST_SHAPES) == (t.size, 1 + R)
    polys = [_bump_poly(head)] + [_rise_poly(head, tuple(float(i == j) for j in range(R_nlp))) for i in range(R_nlp)]
    for i, P in enumerate(polys):
        np.testing.assert_allclose(S0[:, i], P(t), atol=SHAPE_ATOL)
        np.testing.assert_allclose(S1[:, i], P.deriv(1)(t) / d, atol=SHAPE_ATOL / d)
        np.testing.assert_allclose(S2[:, i], P.deriv(2)(t) / d**2, atol=SHAPE_ATOL / d**2)
    r = t if head else 1.0 - t
    sign = 1.0 if head else -1.0
    integrals, peaks = bspline.rest_shape_integrals(d), bspline.rest_shape_peaks()
    grid = np.linspace(0.0, 1.0, 100_001)
    for i in range(1 + R):
        e0, e1, e2 = _shape_by_product_rule(r, i)
        scale = max(1.0, float(np.max(np.abs(e2))))  # (the steepest rise's r-derivatives reach ~1e2 .. 1e3)
        np.testing.assert_allclose(S0[:, i], e0, atol=SHAPE_ATOL)
        np.testing.assert_allclose(S1[:, i], sign * e1 / d, atol=SHAPE_ATOL * scale / d)
        np.testing.assert_allclose(S2[:, i], e2 / d**2, atol=SHAPE_ATOL * scale / d**2)
        ref, _ = quad(lambda x, i=i: float(_shape_by_product_rule(np.array([x]), i)[0][0]), 0.0, 1.0,
                      epsabs=1e-15, epsrel=1e-13, limit=200)
        assert integrals[i] == pytest.approx(d * ref, rel=1e-11)
        assert peaks[i] == pytest.approx(float(np.max(_shape_by_product_rule(grid, i)[0])), rel=1e-6)
        unit = (1.0, ()) if i == 0 else (0.0, tuple(float(j == i - 1) for j in range(R)))
        for got, want in zip((S0[:, i], S1[:, i], S2[:, i]), bspline.rest_bump(s, d, k, head, *unit), strict=True):
            np.testing.assert_array_equal(got, want)


def test_a_point_on_a_rest_intervals_inner_knot_is_evaluated_as_the_interval_it_is_in() -> None:
    """``bspline.evaluate`` puts s = k d in interval k (floor(s / d)); the shapes go with it
    (``bspline.on_rest_interval``).  At the last interval's inner knot q'' is its right-hand limit (with the tail's
    shapes), at the first interval's outer knot its right-hand limit (the next interval's, without the head's):
    bench seeds 1478 and 1617 lp read jerk 1.11 / 1.25 x exactly at such a knot, with s > k d leaving the tail's
    shapes out there."""
    rng = np.random.default_rng(3)
    n, d = 12, 0.7
    R = len(bspline.LP_REST_RISE_POWERS)
    prof = PieceProfile(s_start=0.0, length=n * d, d=d, c=np.concatenate([[0.0], rng.uniform(1e3, 2e3, n), [0.0]]),
                        rest_g=(350.0, -420.0),
                        rest_h=(tuple(rng.uniform(-200, 200, R)), tuple(rng.uniform(-200, 200, R))))
    for s_knot in ((n - 1) * d, d):
        assert np.floor(s_knot / d) == round(s_knot / d)  # (exactly on the knot in evaluate's arithmetic)
        at = prof.feed(np.array([s_knot]))
        right = prof.feed(np.array([s_knot + 1e-9 * d]))
        for got, want in zip(at, right, strict=True):
            assert got[0] == pytest.approx(want[0], rel=1e-6)
    assert bspline.on_rest_interval(np.array([(n - 1) * d]), d, n - 1, False)[0]
    assert not bspline.on_rest_interval(np.array([d]), d, 0, True)[0]


def test_lp_rows_and_evaluation_match_the_time_tables_profile() -> None:
    """A one-window piece with rest shapes at both ends: the LP's designs of q, q', q'' (its rows) times a
    solution vector, and its own evaluation, equal the profile the pipeline builds from it
    (``PieceProfile`` with ``rest_g``, ``rest_h``, evaluated by the time table's ``feed``) at points across the
    piece, the two rest intervals included."""
    m = router()
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (30.0, 9.0, 3.0))])
    piece = tp.pieces[0]
    n, d = 24, tp.length / 24
    lim = LimitSet.from_machine(m, 1e-3, True)

    def geometry(s: np.ndarray) -> object:
        return tp.evaluate(np.asarray(s, dtype=np.float64) + piece.s_start, piece)

    spec = WindowSpec(0, 0, n, d, n, None, True, rest_shapes=True)
    w = WindowLP(spec, lim, geometry, "highs")  # type: ignore[arg-type]
    assert [e[:2] for e in w.shape_ends] == [(True, 0), (False, n - 1)]
    assert w.nvar == n + 2 + 2 * bspline.REST_SHAPES
    rng = np.random.default_rng(3)
    x = rng.uniform(10.0, 1000.0, w.nvar)
    x[n + 2 :] = rng.normal(0.0, 500.0, 2 * bspline.REST_SHAPES)
    s = np.concatenate([np.linspace(0.0, tp.length, 301), d * rng.uniform(0, 1, 20),
                        tp.length - d * rng.uniform(0, 1, 20)])
    B = w._mats(s)
    # each row's columns ascending, none twice (the solver gets the rows as given)
    assert all(Bi.has_canonical_format and Bi.shape == (s.size, w.nvar) for Bi in B)
    inner = w._mats(np.linspace(2.0 * d, tp.length - 2.0 * d, 50))  # no point in a rest interval
    assert all(Bi.shape == (50, w.nvar) and Bi.nnz == 150 for Bi in inner)
    ev = w._eval(x, s)
    head, tail = w._shapes(x)
    assert head is not None and tail is not None
    prof = PieceProfile(0.0, tp.length, d, x[: n + 2], rest_g=(float(head[0]), float(tail[0])),
                        rest_h=(tuple(head[1:]), tuple(tail[1:])))
    q = prof.feed(s)  # (sdot, sddot, sdddot): sdot^2 = q, 2 sddot = q', 2 sdddot / sdot = q''
    ref = (q[0] ** 2, 2.0 * q[1])
    for Bi, ei, ri in zip(B[:2], ev[:2], ref, strict=True):
        scale = float(np.max(np.abs(ri)))
        np.testing.assert_allclose(Bi @ x, ri, rtol=0, atol=ROWS_RTOL * scale * 10)
        np.testing.assert_allclose(ei, ri, rtol=0, atol=ROWS_RTOL * scale * 10)
    np.testing.assert_allclose(B[2] @ x, ev[2], rtol=0, atol=ROWS_RTOL * float(np.max(np.abs(ev[2]))))


@pytest.mark.parametrize("length", LINES_MM)
def test_line_with_rest_shapes_is_near_the_jerk_limited_optimum(monkeypatch: pytest.MonkeyPatch,
                                                                 length: float) -> None:
    """A rest-to-rest x move on the router (method lp, jerk): with the shapes within SHAPED_LINE_GAP of the
    closed-form S-curve optimum and at most SHAPED_GAIN of the time without them; every sampled limit holds
    (finite differences of the 1 kHz positions)."""
    m = router()
    ax = m.axes[0].limits
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (length, 0.0, 0.0))])
    shaped = schedule(tp, m, Options(method="lp"))
    monkeypatch.setattr(pipeline, "LP_REST_SHAPES", False)
    plain = schedule(tp, m, Options(method="lp"))
    t_opt = s_curve_time(length, ax.vmax, ax.amax, ax.jmax)
    t = float(shaped.summary["motion_time"])
    assert t_opt * (1.0 - 1e-9) <= t <= (1.0 + SHAPED_LINE_GAP[length]) * t_opt, (t, t_opt)
    assert t <= SHAPED_GAIN * float(plain.summary["motion_time"]), (t, plain.summary["motion_time"])
    assert shaped.summary["rest_shape_fallbacks"] == 0
    assert any(p.rest_g[0] or any(p.rest_h[0]) for p in shaped.profiles)
    vmax, amax, jmax = m.limit_arrays()
    u = utilisation(shaped.samples.position, shaped.summary["sample_period"], vmax, amax, jmax)
    assert max(u.values()) <= LIMIT_FACTOR, u


def test_no_rest_shapes_without_jerk_or_under_lp_nlp(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without jerk a quadratic leaves rest at amax already, and under lp+nlp the NLP has its own rest shapes:
    no LP window there is given them (with jerk under lp, the first and the last are)."""
    specs: list[WindowSpec] = []

    class Spy(WindowLP):
        def __init__(self, spec: WindowSpec, *args: object, **kw: object) -> None:
            specs.append(spec)
            super().__init__(spec, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, "WindowLP", Spy)
    m = router()
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (20.0, 0.0, 0.0))])
    for opts, want in ((Options(method="lp", jerk=False), False), (Options(method="lp+nlp"), False),
                       (Options(method="lp"), True)):
        specs.clear()
        schedule(tp, m, opts)
        assert specs and all(sp.rest_shapes is want for sp in specs), opts


def test_rest_dips_flags_a_rest_slope_at_rounding_level() -> None:
    """``timing.rest_dips``: a rest interval whose factor q / r reaches REST_DIP_SHARE of its largest (at rest
    itself: q' there a rounding residue, bench seed 894) or dips inside is a dip; a profile without shapes or
    with shapes that keep q / r up is not."""
    d, c = 0.5, np.array([-100.0, 100.0, 400.0, 600.0, 600.0, 400.0, 100.0, -100.0])
    base = PieceProfile(0.0, 6 * d, d, c)
    assert not rest_dips(base)
    ok = PieceProfile(0.0, 6 * d, d, c, rest_g=(-50.0, 0.0), rest_h=((300.0, 0.0, 0.0, 0.0), ()))
    assert not rest_dips(ok)
    # q'(0) = (2 c_1 + g) / d: g = -2 c_1 (1 - 1e-15) leaves it at a residue
    flat = PieceProfile(0.0, 6 * d, d, c, rest_g=(-200.0 * (1.0 - 1e-15), 0.0), rest_h=((300.0, 0.0, 0.0, 0.0), ()))
    assert rest_dips(flat)
    # a dip inside the tail's interval: a rise pulling q / r under 0 near r = 1 / 2
    dip = PieceProfile(0.0, 6 * d, d, c, rest_g=(0.0, 0.0), rest_h=((), (-8000.0, 0.0, 0.0, 0.0)))
    assert rest_dips(dip)
