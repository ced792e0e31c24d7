"""Input validation (NurbsSegment.create, Toolpath) and corner / piece detection."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from geometry import examples
from geometry.errors import GeometryError
from geometry.nurbs import DEGENERATE_SPAN_MM, NurbsSegment
from geometry.toolpath import Toolpath
from tests.geometry.nurbs_factory import clamped_knots

NAME = "segments[0]"
#: Gap (mm) between consecutive segments allowed by default: 1 um.
DEFAULT_GAP_TOL_MM = 1e-3
ANGLE_TOL_DEG = 1e-9
S_TOL_MM = 1e-9
POS_TOL_MM = 1e-9

# a valid rational quadratic with one interior knot
DEGREE = 2
KNOTS = [0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0]
POINTS = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0], [20.0, 10.0, 5.0]]
WEIGHTS = [1.0, 2.0, 0.5, 1.0]


def make(**overrides: Any) -> NurbsSegment:
    args: dict[str, Any] = {
        "degree": DEGREE,
        "knots": KNOTS,
        "control_points": POINTS,
        "weights": WEIGHTS,
        "name": NAME,
    }
    args.update(overrides)
    return NurbsSegment.create(**args)


def rejected(**overrides: Any) -> GeometryError:
    with pytest.raises(GeometryError) as info:
        make(**overrides)
    err = info.value
    assert isinstance(err, ValueError)
    # the message carries field and rule
    assert str(err).startswith(f"{err.field}: {err.rule}")
    return err


def with_value(seq: list[Any], index: int, value: Any) -> list[Any]:
    out = [list(x) if isinstance(x, list) else x for x in seq]
    out[index] = value
    return out


def test_baseline_is_valid() -> None:
    seg = make()
    assert seg.degree == DEGREE
    assert seg.name == NAME
    assert seg.domain == (0.0, 1.0)
    np.testing.assert_array_equal(seg.weights, WEIGHTS)


def test_weights_default_to_one() -> None:
    np.testing.assert_array_equal(make(weights=None).weights, 1.0)


# --------------------------------------------------------------------------- knots


@pytest.mark.parametrize("knots", [KNOTS[:-1], [*KNOTS, 1.0], [0.0, 1.0]])
def test_wrong_knot_count(knots: list[float]) -> None:
    err = rejected(knots=knots)
    assert err.field == f"{NAME}.knots"
    assert err.value == len(knots)
    assert "n + p + 1 = 4 + 2 + 1 = 7 knots" in err.rule


def test_decreasing_knots() -> None:
    err = rejected(knots=[0.0, 0.0, 0.0, 0.7, 0.6, 1.0, 1.0])
    assert err.field == f"{NAME}.knots[4]"
    assert err.value == 0.6
    assert "non-decreasing" in err.rule
    assert "0.7" in err.rule


def test_decreasing_end_knots() -> None:
    err = rejected(knots=[0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 0.9])
    assert err.field == f"{NAME}.knots[6]"
    assert "non-decreasing" in err.rule


def test_interior_multiplicity_above_degree() -> None:
    pts = [[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 0], [4, 0, 0], [5, 0, 0]]
    err = rejected(knots=[0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1], control_points=pts, weights=None)
    assert err.field == f"{NAME}.knots"
    assert err.value == 0.5
    assert "multiplicity 3 exceeds degree 2" in err.rule


def test_interior_multiplicity_equal_to_degree_is_accepted() -> None:
    pts = [[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 0], [4, 0, 0]]
    seg = make(knots=[0, 0, 0, 0.5, 0.5, 1, 1, 1], control_points=pts, weights=None)
    assert len(seg.split_at_c0_knots()) == 2


def test_empty_parameter_domain() -> None:
    err = rejected(knots=[0.0] * 7)
    assert err.field == f"{NAME}.knots"
    assert "domain" in err.rule and "empty" in err.rule


def test_knots_must_be_flat() -> None:
    err = rejected(knots=[KNOTS])
    assert err.field == f"{NAME}.knots"
    assert "flat list" in err.rule


def test_knots_must_be_numbers() -> None:
    err = rejected(knots=["a"] * 7)
    assert err.field == f"{NAME}.knots"
    assert "list of numbers" in err.rule


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_knot(bad: float) -> None:
    err = rejected(knots=with_value(KNOTS, 3, bad))
    assert err.field == f"{NAME}.knots[3]"
    assert "finite" in err.rule
    assert err.value == bad or (math.isnan(bad) and math.isnan(err.value))


# --------------------------------------------------------------------------- weights


@pytest.mark.parametrize("bad", [0.0, -1.0, -1e-300])
def test_non_positive_weight(bad: float) -> None:
    err = rejected(weights=with_value(WEIGHTS, 2, bad))
    assert err.field == f"{NAME}.weights[2]"
    assert err.value == bad
    assert "> 0" in err.rule


def test_first_bad_weight_is_named() -> None:
    err = rejected(weights=[1.0, -2.0, 0.0, 1.0])
    assert err.field == f"{NAME}.weights[1]"


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_weight(bad: float) -> None:
    err = rejected(weights=with_value(WEIGHTS, 1, bad))
    assert err.field == f"{NAME}.weights[1]"
    assert "finite" in err.rule


@pytest.mark.parametrize("weights", [WEIGHTS[:-1], [*WEIGHTS, 1.0]])
def test_wrong_weight_count(weights: list[float]) -> None:
    err = rejected(weights=weights)
    assert err.field == f"{NAME}.weights"
    assert err.value == len(weights)
    assert "one weight per control point (4)" in err.rule


# --------------------------------------------------------------------------- control points


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_control_point(bad: float) -> None:
    err = rejected(control_points=with_value(POINTS, 1, [10.0, 0.0, bad]))
    assert err.field == f"{NAME}.control_points[1][2]"
    assert "finite" in err.rule


@pytest.mark.parametrize(("degree", "n_points"), [(2, 2), (3, 3), (5, 1)])
def test_too_few_control_points(degree: int, n_points: int) -> None:
    pts = POINTS[:n_points]
    knots = [0.0] * (degree + 1) + [1.0] * (n_points)  # count is irrelevant: checked later
    err = rejected(degree=degree, knots=knots, control_points=pts, weights=None)
    assert err.field == f"{NAME}.control_points"
    assert err.value == n_points
    assert f"degree {degree} needs at least {degree + 1} control points" in err.rule


def test_degree_above_the_cap() -> None:
    """Degree 13 is refused naming the degree (``nurbs.MAX_DEGREE``; the API's schema says the same); 12 builds."""
    n = 14
    pts = [[float(i), float(i % 2), 0.0] for i in range(n)]
    err = rejected(degree=13, knots=[0.0] * 14 + [1.0] * 14, control_points=pts, weights=None)
    assert err.field == f"{NAME}.degree" and err.value == 13 and "<= 12" in err.rule
    seg = NurbsSegment.create(12, [0.0] * 13 + [1.0] * 13, pts[:13], None, name=NAME)
    assert seg.degree == 12


def test_all_control_points_equal() -> None:
    err = rejected(control_points=[[3.0, 4.0, 5.0]] * 4)
    assert err.field == f"{NAME}.control_points"
    assert err.value == 0.0
    assert "degenerate" in err.rule


def test_control_points_within_degenerate_span() -> None:
    pts = [[1.0, 1.0, 1.0 + i * DEGENERATE_SPAN_MM / 4] for i in range(4)]
    err = rejected(control_points=pts)
    assert "degenerate" in err.rule


def test_small_but_nondegenerate_segment_is_accepted() -> None:
    pts = [[0.0, 0.0, i * 1e-6] for i in range(4)]
    assert make(control_points=pts).control_points.shape == (4, 3)


@pytest.mark.parametrize(
    "points",
    [
        [[0, 0, 0, 0], [1, 0, 0, 0], [2, 0, 0, 0], [3, 0, 0, 0]],  # 4-D
        [[0], [1], [2], [3]],  # 1-D
        [0.0, 1.0, 2.0, 3.0],  # flat
        [],  # empty
        [[[0, 0, 0]], [[1, 0, 0]], [[2, 0, 0]], [[3, 0, 0]]],  # nested too deep
    ],
    ids=["4d", "1d", "flat", "empty", "3-level"],
)
def test_wrong_point_shape(points: list[Any]) -> None:
    err = rejected(control_points=points, weights=None)
    assert err.field == f"{NAME}.control_points"
    assert "[x, y] or [x, y, z] points" in err.rule


def test_ragged_points() -> None:
    err = rejected(control_points=[[0, 0, 0], [1, 0], [2, 0, 0], [3, 0, 0]])
    assert err.field == f"{NAME}.control_points"
    assert "[x, y, z] points" in err.rule


def test_planar_points_are_accepted() -> None:
    seg = make(control_points=[p[:2] for p in POINTS])
    np.testing.assert_array_equal(seg.control_points[:, 2], 0.0)


# --------------------------------------------------------------------------- degree


@pytest.mark.parametrize("degree", [0, -1])
def test_degree_below_one(degree: int) -> None:
    err = rejected(degree=degree)
    assert err.field == f"{NAME}.degree"
    assert err.value == degree
    assert ">= 1" in err.rule


@pytest.mark.parametrize("degree", [2.5, True, False, "2", None, math.nan, math.inf, np.bool_(True)])
def test_degree_not_an_integer(degree: object) -> None:
    err = rejected(degree=degree)
    assert err.field == f"{NAME}.degree"
    assert "integer" in err.rule


@pytest.mark.parametrize("degree", [2.0, np.int64(2), np.float64(2.0)])
def test_integral_degree_values_are_accepted(degree: object) -> None:
    seg = make(degree=degree)
    assert seg.degree == 2
    assert type(seg.degree) is int


def test_default_name_is_used_in_field() -> None:
    with pytest.raises(GeometryError) as info:
        NurbsSegment.create(0, KNOTS, POINTS)
    assert info.value.field == "segment.degree"


def test_long_values_are_shortened_in_message() -> None:
    err = GeometryError("f", list(range(1000)), "rule")
    assert len(str(err)) < 200
    assert str(err).endswith("...)")


# --------------------------------------------------------------------------- toolpath


def line(a: tuple[float, float, float], b: tuple[float, float, float]) -> NurbsSegment:
    return examples.line(a, b)


def test_empty_toolpath() -> None:
    with pytest.raises(GeometryError) as info:
        Toolpath([])
    assert info.value.field == "segments"
    assert "at least one segment" in info.value.rule


@pytest.mark.parametrize("tol", [-1.0, 180.0, math.nan, math.inf])
def test_invalid_corner_tolerance(tol: float) -> None:
    with pytest.raises(GeometryError) as info:
        Toolpath([line((0, 0, 0), (1, 0, 0))], corner_tol_deg=tol)
    assert info.value.field == "corner_tolerance_deg"
    assert "[0, 180)" in info.value.rule


@pytest.mark.parametrize("gap_mm", [1.5e-3, 2e-3, 0.1])
def test_gap_above_one_micron_names_segment(gap_mm: float) -> None:
    segs = [
        line((0, 0, 0), (10, 0, 0)),
        line((10, 0, 0), (20, 0, 0)),
        line((20, gap_mm, 0), (30, 0, 0)),
    ]
    with pytest.raises(GeometryError) as info:
        Toolpath(segs)
    err = info.value
    assert err.segment == 2
    assert err.field == "segments[2].control_points[0]"
    assert err.value == pytest.approx(gap_mm, rel=1e-9)
    assert "gap" in err.rule
    assert str(DEFAULT_GAP_TOL_MM) in err.rule


def test_gap_of_half_a_micron_is_accepted() -> None:
    gap = 0.5e-3
    tp = Toolpath([line((0, 0, 0), (10, 0, 0)), line((10, gap, 0), (20, gap, 0))])
    # closed: both lines end at the gap's midpoint (``close_gaps``), each tilted by gap / 2 over 10 mm
    assert tp.closed_gaps == [(1, pytest.approx(gap, rel=1e-12))]
    assert tp.length == pytest.approx(2.0 * np.hypot(10.0, 0.5 * gap), abs=1e-12)
    assert tp.corners == []
    assert len(tp.pieces) == 1


def test_custom_gap_tolerance() -> None:
    segs = [line((0, 0, 0), (10, 0, 0)), line((10, 0, 0.01), (20, 0, 0.01))]
    with pytest.raises(GeometryError):
        Toolpath(segs)
    assert Toolpath(segs, gap_tol=0.02).length == pytest.approx(20.0)


def test_zero_length_segment_is_rejected_with_its_index() -> None:
    """Control points spread just over DEGENERATE_SPAN_MM pass create(), but the curve
    goes out and back (length 8/9 of the spread) and is shorter than 1e-9 mm."""
    eps = 1.05 * DEGENERATE_SPAN_MM
    seg = NurbsSegment.create(3, [0, 0, 0, 0, 1, 1, 1, 1], [[0, 0, 0], [eps, 0, 0], [0, 0, 0], [0, 0, 0]])
    with pytest.raises(GeometryError) as info:
        Toolpath([line((-1, 0, 0), (0, 0, 0)), seg])
    assert info.value.segment == 1
    assert info.value.field == "segments[1]"
    assert "zero-length" in info.value.rule


def test_right_angle_between_two_lines() -> None:
    tp = Toolpath([line((0, 0, 0), (30, 0, 0)), line((30, 0, 0), (30, 40, 0))])
    assert tp.length == pytest.approx(70.0, abs=S_TOL_MM)
    assert len(tp.corners) == 1
    c = tp.corners[0]
    assert c.angle_deg == pytest.approx(90.0, abs=ANGLE_TOL_DEG)
    assert c.s == pytest.approx(30.0, abs=S_TOL_MM)
    assert c.segment == 1
    np.testing.assert_allclose(c.position, (30.0, 0.0, 0.0), atol=POS_TOL_MM)
    assert len(tp.pieces) == 2
    p0, p1 = tp.pieces
    assert (p0.index, p0.s_start, p0.first_sub, p0.last_sub) == (0, 0.0, 0, 0)
    assert p0.s_end == pytest.approx(30.0, abs=S_TOL_MM)
    assert (p1.index, p1.first_sub, p1.last_sub) == (1, 1, 1)
    assert p1.s_start == pytest.approx(30.0, abs=S_TOL_MM)
    assert p1.s_end == pytest.approx(70.0, abs=S_TOL_MM)
    assert p0.length + p1.length == pytest.approx(tp.length)


def test_square_corner_example() -> None:
    tp = examples.square_corner(50.0)
    assert [c.s for c in tp.corners] == [pytest.approx(50.0)]
    assert tp.corners[0].angle_deg == pytest.approx(90.0, abs=ANGLE_TOL_DEG)


def test_evaluate_at_corner_uses_the_piece_side() -> None:
    tp = Toolpath([line((0, 0, 0), (30, 0, 0)), line((30, 0, 0), (30, 40, 0))])
    s = np.array([30.0])
    before = tp.evaluate(s, piece=tp.pieces[0])
    after = tp.evaluate(s, piece=tp.pieces[1])
    np.testing.assert_allclose(before.d1[0], (1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(after.d1[0], (0, 1, 0), atol=1e-12)
    np.testing.assert_allclose(before.position[0], (30, 0, 0), atol=POS_TOL_MM)
    np.testing.assert_allclose(after.position[0], (30, 0, 0), atol=POS_TOL_MM)
    # beyond a piece's end, evaluation is clamped to the piece
    np.testing.assert_allclose(tp.positions(np.array([50.0]), piece=tp.pieces[0])[0], (30, 0, 0), atol=POS_TOL_MM)


def tangent_break(angle_deg: float) -> list[NurbsSegment]:
    a = math.radians(angle_deg)
    return [
        line((0, 0, 0), (10, 0, 0)),
        line((10, 0, 0), (10 + 10 * math.cos(a), 10 * math.sin(a), 0)),
    ]


def test_small_tangent_break_below_default_tolerance_is_not_a_corner() -> None:
    tp = Toolpath(tangent_break(0.3))
    assert tp.corners == []
    assert len(tp.pieces) == 1
    assert tp.pieces[0].s_end == pytest.approx(20.0)


def test_small_tangent_break_above_custom_tolerance_is_a_corner() -> None:
    tp = Toolpath(tangent_break(0.3), corner_tol_deg=0.1)
    assert len(tp.corners) == 1
    assert tp.corners[0].angle_deg == pytest.approx(0.3, abs=1e-7)
    assert tp.corners[0].s == pytest.approx(10.0, abs=S_TOL_MM)
    assert len(tp.pieces) == 2


def test_polyline_corner_inside_one_segment_is_split() -> None:
    seg = NurbsSegment.create(1, [0, 0, 0.5, 1, 1], [[0, 0, 0], [10, 0, 0], [10, 10, 0]])
    tp = Toolpath([seg])
    assert len(tp.subs) == 2
    assert list(tp.sub_origin) == [0, 0]
    assert tp.length == pytest.approx(20.0, abs=S_TOL_MM)
    assert len(tp.corners) == 1
    c = tp.corners[0]
    assert c.segment == 0
    assert c.s == pytest.approx(10.0, abs=S_TOL_MM)
    assert c.angle_deg == pytest.approx(90.0, abs=ANGLE_TOL_DEG)
    np.testing.assert_allclose(c.position, (10, 0, 0), atol=POS_TOL_MM)
    assert len(tp.pieces) == 2


def test_polyline_with_two_corners_and_a_straight_joint() -> None:
    pts = [[0, 0, 0], [10, 0, 0], [20, 0, 0], [20, 10, 0], [10, 10, 0]]
    seg = NurbsSegment.create(1, [0, 0, 1, 2, 3, 4, 4], pts)
    tp = Toolpath([line((-5, 0, 0), (0, 0, 0)), seg])
    assert len(tp.subs) == 5
    assert tp.length == pytest.approx(45.0, abs=S_TOL_MM)
    assert [c.s for c in tp.corners] == [pytest.approx(25.0), pytest.approx(35.0)]
    assert [c.segment for c in tp.corners] == [1, 1]
    assert [c.angle_deg for c in tp.corners] == [pytest.approx(90.0), pytest.approx(90.0)]
    assert [(p.first_sub, p.last_sub) for p in tp.pieces] == [(0, 2), (3, 3), (4, 4)]


def test_c0_knot_corner_in_rational_quadratic() -> None:
    """Multiplicity-p knot in a degree-2 rational segment: split there, corner detected."""
    pts = [[0, 0, 0], [5, 0, 0], [10, 0, 0], [10, 5, 0], [10, 10, 0]]
    seg = NurbsSegment.create(2, [0, 0, 0, 0.5, 0.5, 1, 1, 1], pts, [1, 3, 1, 0.5, 1])
    tp = Toolpath([seg])
    assert len(tp.subs) == 2
    assert len(tp.corners) == 1
    assert tp.corners[0].s == pytest.approx(10.0, abs=S_TOL_MM)
    assert tp.corners[0].angle_deg == pytest.approx(90.0, abs=ANGLE_TOL_DEG)
    # the split pieces reproduce the original curve
    u = np.linspace(0, 1, 41)
    lo = u[u <= 0.5]
    hi = u[u >= 0.5]
    left, right = seg.split_at_c0_knots()
    np.testing.assert_allclose(left.points(lo), seg.points(lo), atol=1e-12)
    np.testing.assert_allclose(right.points(hi), seg.points(hi), atol=1e-12)


def test_reversal_is_a_180_degree_corner() -> None:
    tp = Toolpath([line((0, 0, 0), (10, 0, 0)), line((10, 0, 0), (4, 0, 0))])
    assert len(tp.corners) == 1
    assert tp.corners[0].angle_deg == pytest.approx(180.0, abs=ANGLE_TOL_DEG)
    assert tp.length == pytest.approx(16.0, abs=S_TOL_MM)


@pytest.mark.parametrize("seed", range(6))
def test_c0_split_pieces_reproduce_the_curve(seed: int) -> None:
    """Random rational segments with some interior knots at multiplicity p: one piece per
    C0 knot, each on the right sub-domain and equal to the original curve there."""
    rng = np.random.default_rng(seed)
    p = int(rng.integers(1, 6))
    interior = np.array([0.2, 0.45, 0.6, 0.85])
    mults = np.array([p, int(rng.integers(1, p + 1)), p, int(rng.integers(1, p + 1))])
    knots = clamped_knots(p, interior, mults)
    n = knots.size - p - 1
    seg = NurbsSegment.create(p, knots, rng.uniform(-10, 10, (n, 3)), rng.uniform(0.2, 5, n))
    parts = seg.split_at_c0_knots()
    cuts = interior[mults == p]
    edges = np.concatenate([[0.0], cuts, [1.0]])
    assert len(parts) == len(edges) - 1
    for part, a, b in zip(parts, edges[:-1], edges[1:], strict=True):
        assert part.domain == pytest.approx((a, b), abs=1e-15)
        u = np.linspace(a, b, 23)
        np.testing.assert_allclose(part.points(u), seg.points(u), rtol=0, atol=1e-12)
        inner = u[1:-1]  # derivatives may jump at the cut itself
        np.testing.assert_allclose(part.derivatives(inner)[:3], seg.derivatives(inner)[:3], rtol=1e-10, atol=1e-10)
    tp = Toolpath([seg])
    assert len(tp.subs) == len(parts)
    assert tp.length == pytest.approx(sum(Toolpath([q]).length for q in parts), rel=1e-12)


# --------------------------------------------------------------------------- known bug


def _zero_speed_start_path() -> Toolpath:
    """Line along +x, then a cubic going +y whose first two control points coincide,
    so C'(u) = 0 at its start (a common CAM output; the tangent there is still +y)."""
    cubic = NurbsSegment.create(3, [0, 0, 0, 0, 1, 1, 1, 1], [[10, 0, 0], [10, 0, 0], [10, 10, 0], [10, 20, 0]])
    return Toolpath([line((0, 0, 0), (10, 0, 0)), cubic])


def test_corner_detected_when_next_segment_starts_with_zero_speed() -> None:
    with np.errstate(all="ignore"):
        tp = _zero_speed_start_path()
    assert len(tp.corners) == 1
    assert tp.corners[0].angle_deg == pytest.approx(90.0, abs=1e-6)


def test_evaluate_is_finite_at_zero_speed_point() -> None:
    with np.errstate(all="ignore"):
        tp = _zero_speed_start_path()
        ev = tp.evaluate(np.array([10.0]), piece=tp.pieces[-1])
    assert np.all(np.isfinite(ev.d1))
    np.testing.assert_allclose(ev.d1[0], (0, 1, 0), atol=1e-6)


@pytest.mark.parametrize("scale", [1e-300, 1e-154, 1e-120, 1e-60, 1e100, 1e200])
def test_a_knot_domain_of_any_width_is_the_same_curve(scale: float) -> None:
    """Knots spanning 1e-120 (or 1e100, 1e200, 1e-154...) describe the same quarter circle as on [0, 1]: their
    u-derivatives overflowed, and the schedule came back 200 with NaN accelerations or a "zero-length segment"
    (session 58's probe).  The toolpath scales such a domain by a power of two (exact): the same length, the same
    points and unit tangents along s, finite curvature 1 / R."""
    pts, w = [[10.0, 0.0, 0.0], [10.0, 10.0, 0.0], [0.0, 10.0, 0.0]], [1.0, 0.7071067811865476, 1.0]
    ref = Toolpath([NurbsSegment.create(2, [0, 0, 0, 1, 1, 1], pts, w, name=NAME)])
    tp = Toolpath([NurbsSegment.create(2, [0, 0, 0, scale, scale, scale], pts, w, name=NAME)])
    assert tp.length == pytest.approx(ref.length, rel=1e-12) and ref.length == pytest.approx(5 * math.pi, rel=1e-12)
    s = np.linspace(0.0, ref.length, 201)
    g, g_ref = tp.evaluate(s), ref.evaluate(s)
    np.testing.assert_allclose(g.position, g_ref.position, rtol=0, atol=1e-9)
    np.testing.assert_allclose(g.d1, g_ref.d1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(g.d2, axis=1), 0.1, rtol=1e-8)
    assert np.all(np.isfinite(g.d3))
