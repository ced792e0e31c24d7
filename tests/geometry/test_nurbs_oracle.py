"""NurbsSegment evaluation (C, C', C'', C''') against the independent geomdl implementation.

geomdl 5.4 evaluates rational curves with Piegl & Tiller A3.1/A4.2 in pure Python;
``NurbsSegment`` uses scipy's BSpline on homogeneous points plus the quotient rule.
geomdl is built with ``normalize_kv=False`` so both see the same parameter domain.
"""

from __future__ import annotations

import numpy as np
import pytest
from geomdl import NURBS
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from geometry.nurbs import NurbsSegment
from tests.geometry.nurbs_factory import RawNurbs, clamped_knots, random_nurbs

#: Relative tolerance (to each derivative order's scale over the samples).
REL_TOL = 1e-9
#: Parameters sampled per curve in the parametrised oracle cases.
N_SAMPLES = 120
HYPOTHESIS_EXAMPLES = 50


def geomdl_curve(raw: RawNurbs, homogeneous: bool = True) -> NURBS.Curve:
    """The same curve in geomdl, via ``ctrlptsw`` (default) or ``ctrlpts`` + ``weights``."""
    curve = NURBS.Curve(normalize_kv=False)
    curve.degree = raw.degree
    if homogeneous:
        pw = np.column_stack([raw.control_points * raw.weights[:, None], raw.weights])
        curve.ctrlptsw = pw.tolist()
    else:
        curve.ctrlpts = raw.control_points.tolist()
        curve.weights = raw.weights.tolist()
    curve.knotvector = raw.knots.tolist()
    return curve


def geomdl_derivatives(curve: NURBS.Curve, u: np.ndarray) -> np.ndarray:
    """(4, K, 3): geomdl's C and derivatives 1..3 at each u."""
    d = [curve.derivatives(float(x), order=3) for x in u]
    return np.asarray(d, dtype=np.float64).transpose(1, 0, 2)


def order_scales(raw: RawNurbs, ref: np.ndarray) -> np.ndarray:
    """Tolerance scale for each derivative order k: the largest |ref_k| seen, floored by
    the natural size extent / (domain length)^k so near-zero derivatives are not over-tight."""
    lo, hi = raw.knots[raw.degree], raw.knots[-raw.degree - 1]
    extent = float(np.max(np.ptp(raw.control_points, axis=0)))
    return np.array([max(float(np.max(np.abs(ref[k]))), extent / (hi - lo) ** k) for k in range(4)])


def assert_matches_geomdl(raw: RawNurbs, u: np.ndarray, orders: range = range(4)) -> None:
    seg = raw.segment()
    ref = geomdl_derivatives(geomdl_curve(raw), u)
    got = seg.derivatives(u)
    assert got.shape == (4, u.size, 3)
    scale = order_scales(raw, ref)
    for k in orders:
        err = np.max(np.abs(got[k] - ref[k]))
        assert err <= REL_TOL * scale[k], f"order {k}: max |ours - geomdl| = {err:.3e}, scale {scale[k]:.3e}"


def sample_params(rng: np.random.Generator, raw: RawNurbs, k: int = N_SAMPLES) -> np.ndarray:
    lo, hi = raw.knots[raw.degree], raw.knots[-raw.degree - 1]
    return np.concatenate([[lo, hi], rng.uniform(lo, hi, k)])


ORACLE_CASES = [
    # (seed, degree, distinct interior knots, domain)
    (1, 2, 3, (0.0, 1.0)),
    (2, 2, 6, (0.0, 1.0)),
    (3, 3, 4, (0.0, 1.0)),
    (4, 3, 7, (-2.0, 5.0)),
    (5, 4, 4, (0.0, 1.0)),
    (6, 4, 5, (10.0, 10.5)),
    (7, 5, 3, (0.0, 1.0)),
    (8, 5, 5, (0.0, 30.0)),
]


@pytest.mark.parametrize(("seed", "degree", "n_interior", "domain"), ORACLE_CASES)
def test_derivatives_match_geomdl(seed: int, degree: int, n_interior: int, domain: tuple[float, float]) -> None:
    rng = np.random.default_rng(seed)
    raw = random_nurbs(rng, degree, n_interior, *domain)
    assert not np.allclose(raw.weights, 1.0)
    assert_matches_geomdl(raw, sample_params(rng, raw))


@pytest.mark.parametrize("degree", [2, 3, 4, 5])
def test_max_multiplicity_knots_match_geomdl(degree: int) -> None:
    """Every interior knot at multiplicity degree-1 (curve only C1 there)."""
    rng = np.random.default_rng(100 + degree)
    interior = np.array([0.2, 0.45, 0.7])
    knots = clamped_knots(degree, interior, np.full(3, degree - 1))
    n = knots.size - degree - 1
    raw = RawNurbs(degree, knots, rng.uniform(-20, 20, (n, 3)), rng.uniform(0.2, 5.0, n))
    assert_matches_geomdl(raw, sample_params(rng, raw))


@pytest.mark.parametrize(("seed", "degree"), [(11, 2), (12, 3), (13, 5)])
def test_derivatives_at_knots_match_geomdl(seed: int, degree: int) -> None:
    """At the knots themselves, for the derivative orders that are continuous there."""
    rng = np.random.default_rng(seed)
    raw = random_nurbs(rng, degree, 4)
    seg = raw.segment()
    ends = np.array(seg.domain)
    assert_matches_geomdl(raw, ends)  # all orders at the domain ends
    vals, counts = np.unique(raw.knots, return_counts=True)
    inner = (vals > ends[0]) & (vals < ends[1])
    for v, m in zip(vals[inner], counts[inner], strict=True):
        # C^(p - m) at a knot of multiplicity m
        assert_matches_geomdl(raw, np.array([v]), orders=range(min(3, degree - m) + 1))


def test_ctrlpts_plus_weights_api_agrees_with_ctrlptsw() -> None:
    """Sanity check of the oracle itself: both geomdl input forms give the same curve."""
    rng = np.random.default_rng(21)
    raw = random_nurbs(rng, 3, 4)
    u = sample_params(rng, raw, 20)
    a = geomdl_derivatives(geomdl_curve(raw, homogeneous=True), u)
    b = geomdl_derivatives(geomdl_curve(raw, homogeneous=False), u)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", [31, 32])
def test_points_match_geomdl_evaluate_single(seed: int) -> None:
    rng = np.random.default_rng(seed)
    raw = random_nurbs(rng, 3, 5)
    seg = raw.segment()
    curve = geomdl_curve(raw)
    u = sample_params(rng, raw, 50)
    ref = np.array([curve.evaluate_single(float(x)) for x in u])
    extent = float(np.max(np.ptp(raw.control_points, axis=0)))
    np.testing.assert_allclose(seg.points(u), ref, rtol=0, atol=REL_TOL * extent)
    np.testing.assert_array_equal(seg.points(u), seg.derivatives(u)[0])


def test_planar_input_is_padded_with_z0_and_matches_geomdl() -> None:
    rng = np.random.default_rng(41)
    raw3 = random_nurbs(rng, 3, 3)
    pts2 = raw3.control_points[:, :2]
    seg2 = NurbsSegment.create(raw3.degree, raw3.knots, pts2, raw3.weights)
    raw_flat = RawNurbs(raw3.degree, raw3.knots, np.column_stack([pts2, np.zeros(len(pts2))]), raw3.weights)
    u = sample_params(rng, raw_flat, 40)
    np.testing.assert_array_equal(seg2.control_points[:, 2], 0.0)
    got = seg2.derivatives(u)
    np.testing.assert_array_equal(got[:, :, 2], 0.0)
    ref = geomdl_derivatives(geomdl_curve(raw_flat), u)
    scale = order_scales(raw_flat, ref)
    for k in range(4):
        assert np.max(np.abs(got[k] - ref[k])) <= REL_TOL * scale[k]


# --------------------------------------------------------------------------- hypothesis


@st.composite
def valid_nurbs(draw: st.DrawFn) -> tuple[RawNurbs, np.ndarray]:
    degree = draw(st.integers(2, 5))
    n_interior = draw(st.integers(0, 5))
    spans = np.array(draw(st.lists(st.floats(0.25, 1.0), min_size=n_interior + 1, max_size=n_interior + 1)))
    lo = draw(st.floats(-10.0, 10.0))
    length = draw(st.floats(0.5, 20.0))
    interior = lo + length * np.cumsum(spans)[:-1] / spans.sum()
    mults = np.array(
        draw(st.lists(st.integers(1, degree - 1), min_size=n_interior, max_size=n_interior)),
        dtype=int,
    )
    knots = clamped_knots(degree, interior, mults, lo, lo + length)
    # a knot equal to an end after rounding would change the structure; keep them distinct
    assume(np.all(np.diff(np.unique(knots)) > 1e-3 * length))
    n = knots.size - degree - 1
    coord = st.floats(-100.0, 100.0, allow_nan=False, allow_infinity=False)
    points = np.array(draw(st.lists(st.tuples(coord, coord, coord), min_size=n, max_size=n)))
    assume(np.max(np.ptp(points, axis=0)) > 1e-3)
    weights = np.array(draw(st.lists(st.floats(0.2, 5.0), min_size=n, max_size=n)))
    fractions = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=12)))
    u = np.concatenate([[lo, lo + length], lo + length * fractions])
    return RawNurbs(degree, knots, points, weights), u


@settings(
    max_examples=HYPOTHESIS_EXAMPLES,
    deadline=None,
    database=None,  # do not write .hypothesis/ into the project
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(valid_nurbs())
def test_random_nurbs_match_geomdl(case: tuple[RawNurbs, np.ndarray]) -> None:
    raw, u = case
    # u may land exactly on an interior knot (fraction 0.5 etc.): compare only the
    # orders that are continuous at every knot hit, elsewhere all orders.
    vals, counts = np.unique(raw.knots, return_counts=True)
    lo, hi = raw.knots[raw.degree], raw.knots[-raw.degree - 1]
    inner = (vals > lo) & (vals < hi)
    on_knot = np.isin(u, vals[inner])
    assert_matches_geomdl(raw, u[~on_knot])
    if on_knot.any():
        worst = int(counts[inner].max())
        assert_matches_geomdl(raw, u[on_knot], orders=range(min(3, raw.degree - worst) + 1))


#: Knot insertion leaves the curve unchanged to rounding (mm, on a 50 mm control net).
INSERTION_TOL_MM = 1e-9


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), degree=st.integers(2, 5), at_knot=st.booleans())
def test_knot_insertion_keeps_the_curve(seed: int, degree: int, at_knot: bool) -> None:
    """Boehm insertion (NurbsSegment.insert_knot) at a random u or at an existing interior knot,
    up to multiplicity p: the same curve (geomdl evaluates the original), split at a C0 knot when
    full, and each piece evaluates to the original over its own domain."""
    rng = np.random.default_rng(seed)
    raw = random_nurbs(rng, degree, 3)
    seg = raw.segment()
    lo, hi = seg.domain
    inner = np.unique(raw.knots[(raw.knots > lo) & (raw.knots < hi)])
    u0 = float(rng.choice(inner)) if at_knot else float(rng.uniform(lo + 0.05, hi - 0.05))
    have = int(np.sum(raw.knots == u0))
    times = degree - have
    ins = seg.insert_knot(u0, times)
    assert ins.knots.size == raw.knots.size + times and int(np.sum(ins.knots == u0)) == degree
    u = np.linspace(lo, hi, 301)
    ref = geomdl_curve(raw)
    np.testing.assert_allclose(ins.points(u), np.array(ref.evaluate_list(list(u))), atol=INSERTION_TOL_MM)
    parts = ins._split_c0()
    assert any(p.domain[1] == u0 for p in parts)
    for part in parts:
        a, b = part.domain
        uu = np.linspace(a, b, 101)
        np.testing.assert_allclose(part.points(uu), seg.points(uu), atol=INSERTION_TOL_MM)


def test_zero_speed_knot_found_only_where_control_points_repeat() -> None:
    """p equal control points stop a degree-p curve at one knot; p - 1 of them do not."""
    cusp = NurbsSegment.create(3, [0, 0, 0, 0, 0.5, 1, 1, 1, 1], [[0, 0], [10, 0], [10, 0], [10, 0], [0, 10]])
    np.testing.assert_array_equal(cusp.zero_speed_knots(), [0.5])
    assert len(cusp.split_at_c0_knots()) == 2
    double = NurbsSegment.create(3, [0, 0, 0, 0, 0.5, 1, 1, 1, 1], [[0, 0], [10, 0], [10, 0], [10, 5], [0, 10]])
    assert double.zero_speed_knots().size == 0 and len(double.split_at_c0_knots()) == 1
