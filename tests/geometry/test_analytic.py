"""Arc length and arc-length derivatives against closed forms, quadrature and finite differences."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
import pytest
from scipy.integrate import quad

from geometry import examples
from geometry.arclength import ArcLengthTable
from geometry.nurbs import NurbsSegment
from geometry.quadrature import QUINTIC_TOL
from geometry.toolpath import Toolpath
from tests.geometry.nurbs_factory import random_nurbs

#: Exact geometry (lines, circles): everything is rounding error.
EXACT_REL_TOL = 1e-12
#: Length of an exact curve vs. its closed form, and of any NURBS vs. scipy quad.
LENGTH_REL_TOL = 1e-9
#: Position error of C(s) for exact curves, relative to their size.
POS_REL_TOL = 1e-9
#: Unit tangent |d1| = 1, d1 . d2 = 0 (dimensionless / scaled by curvature).
UNIT_TOL = 1e-12
#: Curvature / d3 of exact curves, relative.
CURVATURE_REL_TOL = 1e-9
#: u_of_s(s_of_u(u)) round trip, measured in mm along the curve (|du| |C'|).
ROUNDTRIP_TOL_MM = 1e-9
#: Fitted flower vs. the analytic polar curve it interpolates.
FLOWER_LENGTH_REL_TOL = 1e-4
FLOWER_LENGTH_MM = 407.7
FLOWER_MIN_RADIUS_MM = 1.78
FLOWER_MIN_RADIUS_ABS_TOL_MM = 0.02
#: Central-difference step along s (mm) and the tolerances it supports (relative to
#: max(1, |d2|, |d3|)).  First differences are Richardson-extrapolated (steps h, h/2),
#: which removes the h^2 truncation term; higher differences of positions are limited
#: by rounding (positions ~100 mm, divided by h^2 or h^3).
FD_STEP_MM = 1e-3
FD_TOL_RICHARDSON = 1e-8  # d1 from positions, d2 from d1, d3 from d2
FD_TOL_D2_FROM_POSITIONS = 1e-5
FD_TOL_D3_FROM_POSITIONS = 5e-3
QUAD_EPSREL = 1e-12


def quad_length(seg: NurbsSegment, a: float, b: float) -> float:
    """Integral of |C'(u)| over [a, b] with scipy quad, split at the knots inside."""
    knots = seg.breakpoints
    cuts = np.concatenate([[a], knots[(knots > a) & (knots < b)], [b]])
    total = 0.0
    for x0, x1 in itertools.pairwise(cuts):
        val, _ = quad(
            lambda u: float(seg.speed(np.array([u]))[0]),
            x0,
            x1,
            epsabs=0.0,
            epsrel=QUAD_EPSREL,
            limit=200,
        )
        total += val
    return total


def interior_span_points_s(
    tp: Toolpath, min_margin_mm: float, fractions: tuple[float, ...] = (0.25, 0.5, 0.75)
) -> np.ndarray:
    """Arc lengths at the given parameter fractions of every knot span of every
    sub-segment, keeping only those at least ``min_margin_mm`` from the span ends (so
    finite differences never straddle a knot, where d3 may jump)."""
    out = []
    for k, tab in enumerate(tp.subs):
        bp = tab.segment.breakpoints
        s_bp = tab.s_of_u(bp)
        for f in fractions:
            s_in = tab.s_of_u(bp[:-1] + f * np.diff(bp))
            ok = (s_in - s_bp[:-1] > min_margin_mm) & (s_bp[1:] - s_in > min_margin_mm)
            out.append(tp.offsets[k] + s_in[ok])
    return np.sort(np.concatenate(out))


# --------------------------------------------------------------------------- straight lines

LINE_A = np.array([1.0, 2.0, 3.0])
LINE_B = np.array([4.0, 6.0, 15.0])  # |B - A| = 13
LINE_LEN = 13.0


def test_line_length_tangent_and_zero_curvature() -> None:
    tp = Toolpath([examples.line(tuple(LINE_A), tuple(LINE_B))])
    assert tp.length == pytest.approx(LINE_LEN, rel=EXACT_REL_TOL)
    s = np.linspace(0.0, tp.length, 101)
    ev = tp.evaluate(s)
    direction = (LINE_B - LINE_A) / LINE_LEN
    np.testing.assert_allclose(ev.d1, np.broadcast_to(direction, ev.d1.shape), atol=UNIT_TOL)
    np.testing.assert_array_equal(ev.d2, 0.0)
    np.testing.assert_array_equal(ev.d3, 0.0)
    expected = LINE_A + s[:, None] * direction
    np.testing.assert_allclose(ev.position, expected, rtol=0, atol=POS_REL_TOL * LINE_LEN)
    np.testing.assert_allclose(tp.positions(s), ev.position, rtol=0, atol=1e-15 * LINE_LEN)


def test_line_parameter_is_linear_in_arc_length() -> None:
    seg = examples.line(tuple(LINE_A), tuple(LINE_B))
    tab = ArcLengthTable.build(seg)
    assert tab.length == pytest.approx(LINE_LEN, rel=EXACT_REL_TOL)
    s = np.linspace(0.0, LINE_LEN, 57)
    np.testing.assert_allclose(tab.u_of_s(s), s / LINE_LEN, rtol=0, atol=EXACT_REL_TOL)
    u = np.linspace(0.0, 1.0, 57)
    np.testing.assert_allclose(tab.s_of_u(u), u * LINE_LEN, rtol=0, atol=EXACT_REL_TOL * LINE_LEN)


@pytest.mark.parametrize(
    ("degree", "knots", "params", "weights"),
    [
        # cubic with bunched control points: |C'| varies strongly, u(s) is not linear
        (3, [0, 0, 0, 0, 1, 1, 1, 1], [0.0, 0.05, 0.1, 1.0], None),
        # rational quadratic: a straight line with a rational parameterisation
        (2, [0, 0, 0, 1, 1, 1], [0.0, 0.3, 1.0], [1.0, 4.0, 0.5]),
        # two spans, interior knot
        (3, [0, 0, 0, 0, 0.3, 1, 1, 1, 1], [0.0, 0.02, 0.5, 0.6, 1.0], [1.0, 2.0, 0.7, 1.5, 1.0]),
    ],
)
def test_nonuniformly_parameterised_line(
    degree: int, knots: list[float], params: list[float], weights: list[float] | None
) -> None:
    """A line with |C'| far from constant: the chain rule must still give d1 constant,
    d2 = d3 = 0, and C(s) = A + s * direction."""
    pts = LINE_A + np.outer(params, LINE_B - LINE_A)
    seg = NurbsSegment.create(degree, knots, pts, weights)
    sp = seg.speed(np.linspace(0, 1, 11))
    assert sp.max() > 2.0 * sp.min()  # really non-uniform
    tp = Toolpath([seg])
    assert tp.length == pytest.approx(LINE_LEN, rel=LENGTH_REL_TOL)
    s = np.linspace(0.0, tp.length, 201)
    ev = tp.evaluate(s)
    direction = (LINE_B - LINE_A) / LINE_LEN
    np.testing.assert_allclose(ev.d1, np.broadcast_to(direction, ev.d1.shape), atol=1e-12)
    # d2, d3 are differences of large terms (u_s^k C^(k)); scale by the parameterisation
    np.testing.assert_allclose(ev.d2, 0.0, atol=1e-9)
    np.testing.assert_allclose(ev.d3, 0.0, atol=1e-8)
    np.testing.assert_allclose(ev.position, LINE_A + s[:, None] * direction, rtol=0, atol=POS_REL_TOL * LINE_LEN)


# --------------------------------------------------------------------------- exact circle

CIRCLE_RADII = [0.5, 10.0, 1000.0]


@pytest.mark.parametrize("radius", CIRCLE_RADII)
def test_circle_length(radius: float) -> None:
    seg = examples.circle(radius)
    assert ArcLengthTable.build(seg).length == pytest.approx(2 * math.pi * radius, rel=LENGTH_REL_TOL)
    tp = Toolpath([seg])
    assert tp.length == pytest.approx(2 * math.pi * radius, rel=LENGTH_REL_TOL)
    assert tp.corners == []  # the C0 knots of the quarter arcs are tangent-continuous
    assert len(tp.pieces) == 1


@pytest.mark.parametrize("radius", CIRCLE_RADII)
def test_circle_arc_length_derivatives(radius: float) -> None:
    tp = Toolpath([examples.circle(radius)])
    s = np.linspace(0.0, tp.length, 403)  # includes the quarter-arc joints
    ev = tp.evaluate(s)
    n1 = np.linalg.norm(ev.d1, axis=1)
    np.testing.assert_allclose(n1, 1.0, rtol=0, atol=UNIT_TOL)
    np.testing.assert_allclose(np.einsum("ij,ij->i", ev.d1, ev.d2) * radius, 0.0, rtol=0, atol=UNIT_TOL)
    np.testing.assert_allclose(np.linalg.norm(ev.d2, axis=1), 1.0 / radius, rtol=CURVATURE_REL_TOL)
    # d2 points to the centre
    np.testing.assert_allclose(ev.d2, -ev.position / radius**2, rtol=0, atol=CURVATURE_REL_TOL / radius)
    np.testing.assert_allclose(np.linalg.norm(ev.d3, axis=1), 1.0 / radius**2, rtol=CURVATURE_REL_TOL)
    np.testing.assert_allclose(ev.d3, -ev.d1 / radius**2, rtol=0, atol=CURVATURE_REL_TOL / radius**2)


@pytest.mark.parametrize("radius", CIRCLE_RADII)
def test_circle_positions_follow_arc_length(radius: float) -> None:
    """C(s) = R (cos(s/R), sin(s/R), 0): checks u(s) as well as C."""
    tp = Toolpath([examples.circle(radius)])
    s = np.linspace(0.0, tp.length, 997)
    expected = radius * np.column_stack([np.cos(s / radius), np.sin(s / radius), np.zeros_like(s)])
    np.testing.assert_allclose(tp.positions(s), expected, rtol=0, atol=POS_REL_TOL * radius)
    np.testing.assert_allclose(np.linalg.norm(tp.evaluate(s).position, axis=1), radius, rtol=EXACT_REL_TOL)


def test_offset_circle_stays_on_circle() -> None:
    seg = examples.circle(7.0, center=(3.0, -2.0))
    tp = Toolpath([seg])
    p = tp.positions(np.linspace(0.0, tp.length, 301))
    np.testing.assert_allclose(np.hypot(p[:, 0] - 3.0, p[:, 1] + 2.0), 7.0, rtol=EXACT_REL_TOL)
    np.testing.assert_array_equal(p[:, 2], 0.0)


#: Third differences of positions sampled densely along an exact circle, in ulps of its radius: the
#: rounding of the positions themselves and of u on a domain starting at 0 (measured <= 14).
D3_ROUNDING_ULPS = 32


@pytest.mark.parametrize("offset", [0.0, 1.0, 1000.0])
def test_positions_on_a_domain_far_from_zero_are_as_fine_as_the_domain_at_zero(offset: float) -> None:
    """Bench seed 5029: a segment on u in [-2.27, -2.25] moved its samples in steps of ulp(u) |C'| =
    1.9e-12 mm, which a slow machine's jerk limit sees.  The circle on knots offset + 1e-3 U (|C'| =
    6.3e4 mm) read 7.2e6 ulps at offset 1000 and 2.1e4 at offset 1 before the toolpath rebased its
    segments' domains to 0 (``NurbsSegment.rebased``); it must read as the same curve on [0, 1e-3]."""
    radius = 40.0
    c = examples.circle(radius)
    seg = NurbsSegment.create(c.degree, offset + 1e-3 * c.knots, c.control_points, c.weights)
    tp = Toolpath([seg])
    for where in (0.1, 0.5, 1.0):
        s = where * tp.length - 5e-5 * np.arange(400)
        p = tp.positions(s)
        expected = radius * np.column_stack([np.cos(s / radius), np.sin(s / radius), np.zeros_like(s)])
        np.testing.assert_allclose(p, expected, rtol=0, atol=POS_REL_TOL * radius)
        assert np.abs(np.diff(p, 3, axis=0)).max() <= D3_ROUNDING_ULPS * np.spacing(radius)


# --------------------------------------------------------------------------- random NURBS

RANDOM_CASES = [(101, 2, 3), (102, 3, 5), (103, 4, 4), (104, 5, 3)]


@pytest.mark.parametrize(("seed", "degree", "n_interior"), RANDOM_CASES)
def test_random_nurbs_length_matches_quad(seed: int, degree: int, n_interior: int) -> None:
    rng = np.random.default_rng(seed)
    seg = random_nurbs(rng, degree, n_interior).segment()
    tab = ArcLengthTable.build(seg)
    lo, hi = seg.domain
    assert tab.length == pytest.approx(quad_length(seg, lo, hi), rel=LENGTH_REL_TOL)
    # partial lengths s(u), including inside knot spans
    for u in rng.uniform(lo, hi, 5):
        assert float(tab.s_of_u(np.array([u]))[0]) == pytest.approx(quad_length(seg, lo, u), rel=LENGTH_REL_TOL)


@pytest.mark.parametrize(("seed", "degree", "n_interior"), RANDOM_CASES)
def test_arc_length_round_trip(seed: int, degree: int, n_interior: int) -> None:
    rng = np.random.default_rng(seed)
    seg = random_nurbs(rng, degree, n_interior, weight_range=(0.1, 10.0)).segment()
    tab = ArcLengthTable.build(seg)
    lo, hi = seg.domain
    u = np.concatenate([[lo, hi], seg.breakpoints, rng.uniform(lo, hi, 500)])
    s = tab.s_of_u(u)
    assert np.all((s >= 0.0) & (s <= tab.length * (1 + 1e-15)))
    assert s[0] == 0.0
    assert s[1] == pytest.approx(tab.length, rel=1e-14)
    u2 = tab.u_of_s(s)
    err_mm = np.abs(u2 - u) * seg.speed(u)
    assert err_mm.max() <= ROUNDTRIP_TOL_MM
    # and the other way: s_of_u(u_of_s(s)) = s
    s3 = np.linspace(0.0, tab.length, 501)
    np.testing.assert_allclose(tab.s_of_u(tab.u_of_s(s3)), s3, rtol=0, atol=ROUNDTRIP_TOL_MM)
    # s(u) is increasing
    order = np.argsort(u)
    assert np.all(np.diff(s[order]) >= -1e-12)


@pytest.mark.parametrize(("seed", "degree", "n_interior"), RANDOM_CASES)
def test_exact_u_of_s_by_the_quintic_guess_is_the_newton_steps(seed: int, degree: int, n_interior: int) -> None:
    """u_of_s(exact) takes the quintic guess in the intervals whose midpoint check holds it (most of them):
    the same point as the Newton step's to within QUINTIC_TOL mm along the curve, or 2 units in the last
    place of u where the speed is so high that those are more; the guess alone (the solvers') unchanged."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    seg = random_nurbs(rng, degree, n_interior, weight_range=(0.1, 10.0)).segment()
    tab = ArcLengthTable.build(seg)
    assert tab.table.quintic is not None and tab.table.quintic.mean() > 0.9
    s = np.concatenate([np.linspace(0.0, tab.length, 5001), rng.uniform(0.0, tab.length, 5000)])
    u = tab.u_of_s(s)
    newton = replace(tab.table, quintic=None).inverse(s)
    speed = seg.speed(newton)
    tol = np.maximum(2.0 * QUINTIC_TOL, 2.0 * np.spacing(np.abs(newton)) * speed)
    assert np.all(np.abs(u - newton) * speed <= tol)
    assert u[0] == seg.domain[0] and u[5000] == seg.domain[1]
    np.testing.assert_array_equal(tab.u_of_s(s, exact=False), replace(tab.table, quintic=None).inverse(s, False))


@pytest.mark.parametrize(("seed", "degree", "n_interior"), RANDOM_CASES)
def test_random_nurbs_derivative_identities(seed: int, degree: int, n_interior: int) -> None:
    """|d1| = 1, d1.d2 = 0, |d2| = |C' x C''| / |C'|^3, d1.d3 = -|d2|^2."""
    rng = np.random.default_rng(seed)
    seg = random_nurbs(rng, degree, n_interior).segment()
    tp = Toolpath([seg])
    s = np.linspace(0.0, tp.length, 301)
    ev = tp.evaluate(s)
    _, u = tp.locate(s)
    D = seg.derivatives(u)
    speed = np.linalg.norm(D[1], axis=1)
    kappa = np.linalg.norm(np.cross(D[1], D[2]), axis=1) / speed**3
    k2 = np.linalg.norm(ev.d2, axis=1)
    scale = max(1.0, float(k2.max()))
    np.testing.assert_allclose(np.linalg.norm(ev.d1, axis=1), 1.0, rtol=0, atol=UNIT_TOL)
    np.testing.assert_allclose(np.einsum("ij,ij->i", ev.d1, ev.d2), 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(k2, kappa, rtol=1e-9, atol=1e-12 * scale)
    np.testing.assert_allclose(np.einsum("ij,ij->i", ev.d1, ev.d3), -(k2**2), rtol=1e-8, atol=1e-10 * scale**2)
    np.testing.assert_allclose(ev.position, D[0], rtol=0, atol=0)
    # precise points: C(u) moved along the tangent by u's arc-length residual, C by de Boor (``Toolpath.evaluate``)
    precise = tp.evaluate(s, precise=True).position
    ulp = np.spacing(np.max(np.abs(seg.control_points)))  # (a point's rounding follows its control points)
    np.testing.assert_allclose(precise, D[0], rtol=0, atol=2.0 * QUINTIC_TOL + 8.0 * ulp)


# --------------------------------------------------------------------------- flower


def flower_polar_length() -> float:
    """Length of r = R0 + A cos(k th), th in [0, 2 pi], by quad over each half lobe."""
    r0, a, k = examples.FLOWER_R0, examples.FLOWER_A, examples.FLOWER_LOBES

    def ds(th: float) -> float:
        r = r0 + a * math.cos(k * th)
        dr = -a * k * math.sin(k * th)
        return math.sqrt(r * r + dr * dr)

    edges = np.linspace(0.0, 2 * math.pi, 2 * k + 1)
    return sum(quad(ds, x0, x1, epsabs=0.0, epsrel=QUAD_EPSREL)[0] for x0, x1 in itertools.pairwise(edges))


def flower_polar_min_radius() -> float:
    """Smallest radius of curvature of the polar curve (at the inner lobe tips)."""
    r0, a, k = examples.FLOWER_R0, examples.FLOWER_A, examples.FLOWER_LOBES
    th = np.linspace(0.0, 2 * math.pi, 100_001)
    r = r0 + a * np.cos(k * th)
    dr = -a * k * np.sin(k * th)
    ddr = -a * k * k * np.cos(k * th)
    kappa = np.abs(r * r + 2 * dr * dr - r * ddr) / (r * r + dr * dr) ** 1.5
    return float(1.0 / kappa.max())


@pytest.fixture(scope="module")
def flower() -> Toolpath:
    return examples.flower()


def test_flower_length(flower: Toolpath) -> None:
    ref = flower_polar_length()
    assert ref == pytest.approx(FLOWER_LENGTH_MM, abs=0.05)
    assert flower.length == pytest.approx(ref, rel=FLOWER_LENGTH_REL_TOL)
    assert flower.corners == []
    assert len(flower.pieces) == 1


def test_flower_min_radius_of_curvature(flower: Toolpath) -> None:
    s = np.linspace(0.0, flower.length, 40_001)
    ev = flower.evaluate(s)
    r_min = float(1.0 / np.linalg.norm(ev.d2, axis=1).max())
    assert r_min == pytest.approx(FLOWER_MIN_RADIUS_MM, abs=FLOWER_MIN_RADIUS_ABS_TOL_MM)
    assert r_min == pytest.approx(flower_polar_min_radius(), rel=0.015)
    np.testing.assert_allclose(np.linalg.norm(ev.d1, axis=1), 1.0, rtol=0, atol=UNIT_TOL)
    np.testing.assert_allclose(np.einsum("ij,ij->i", ev.d1, ev.d2), 0.0, atol=1e-12)


def test_flower_two_loops_is_twice_as_long() -> None:
    one = examples.flower(1)
    two = examples.flower(2)
    assert two.length == pytest.approx(2 * one.length, rel=1e-14)
    assert two.corners == []
    s = np.linspace(0.0, one.length, 101)
    np.testing.assert_allclose(two.positions(s + one.length), one.positions(s), atol=1e-9)


# --------------------------------------------------------------------------- finite differences


def random_rational_path() -> Toolpath:
    rng = np.random.default_rng(7)
    return Toolpath([random_nurbs(rng, 4, 4).segment()])


def central(f: Callable[[np.ndarray], np.ndarray], s: np.ndarray, h: float) -> np.ndarray:
    return (f(s + h) - f(s - h)) / (2 * h)


def richardson(f: Callable[[np.ndarray], np.ndarray], s: np.ndarray, h: float) -> np.ndarray:
    """Central first difference with the h^2 error term extrapolated away."""
    return (4 * central(f, s, h / 2) - central(f, s, h)) / 3


@pytest.mark.parametrize(
    "make_path",
    [examples.flower, lambda: Toolpath([examples.wave3d()]), random_rational_path],
    ids=["flower", "wave3d", "random_rational"],
)
def test_derivatives_match_central_differences(make_path: Callable[[], Toolpath]) -> None:
    tp = make_path()
    h = FD_STEP_MM
    s = interior_span_points_s(tp, min_margin_mm=5 * h)
    s = s[(s > 3 * h) & (s < tp.length - 3 * h)]
    assert s.size >= 10
    ev = tp.evaluate(s)
    P = tp.positions
    scale = max(1.0, float(np.abs(ev.d2).max()), float(np.abs(ev.d3).max()))

    np.testing.assert_allclose(ev.d1, richardson(P, s, h), rtol=0, atol=FD_TOL_RICHARDSON)
    fd2 = (P(s + h) - 2 * P(s) + P(s - h)) / h**2
    np.testing.assert_allclose(ev.d2, fd2, rtol=0, atol=FD_TOL_D2_FROM_POSITIONS * scale)
    fd3 = (P(s + 2 * h) - 2 * P(s + h) + 2 * P(s - h) - P(s - 2 * h)) / (2 * h**3)
    np.testing.assert_allclose(ev.d3, fd3, rtol=0, atol=FD_TOL_D3_FROM_POSITIONS * scale)

    # each derivative against differences of the one below it
    def d1(x: np.ndarray) -> np.ndarray:
        return tp.evaluate(x).d1

    def d2(x: np.ndarray) -> np.ndarray:
        return tp.evaluate(x).d2

    np.testing.assert_allclose(ev.d2, richardson(d1, s, h), rtol=0, atol=FD_TOL_RICHARDSON * scale)
    np.testing.assert_allclose(ev.d3, richardson(d2, s, h), rtol=0, atol=FD_TOL_RICHARDSON * scale)
