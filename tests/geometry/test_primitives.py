"""Lines, arcs and polylines (geometry.primitives) against analytic geometry.

Truth: the circle c + r (cos t e1 + sin t e2) with the sweep computed here from
the inputs independently of the implementation (atan2 of the end relative to
the centre), arc length r |sweep|, straight lines A + s (B - A) / |B - A|.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry.errors import GeometryError
from geometry.primitives import (
    ARC_RADIUS_ABS_TOL_MM,
    ARC_RADIUS_REL_TOL,
    PLANES,
    arc,
    line,
    polyline,
    radius_tolerance,
)
from geometry.toolpath import Toolpath

#: Distance of arc points from the analytic circle (mm).
RADIUS_TOL_MM = 1e-9
#: Arc length vs. r |sweep| (relative), measured through Toolpath's arc-length tables.
LENGTH_REL_TOL = 1e-9
#: Position of C(s) vs. the analytic circle / line at the same arc length (relative to the radius).
POS_REL_TOL = 1e-9
#: Samples along each arc.
N_SAMPLES = 201
HYPOTHESIS_EXAMPLES = 60

UNIT = np.eye(3)


def plane_frame(plane: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors (e1, e2, normal) of a plane, from the RS274/NGC table (not from the module)."""
    first, second, normal = {"G17": ("X", "Y", "Z"), "G18": ("Z", "X", "Y"), "G19": ("Y", "Z", "X")}[plane]
    idx = {"X": 0, "Y": 1, "Z": 2}
    return UNIT[idx[first]], UNIT[idx[second]], UNIT[idx[normal]]


def circle_point(c: np.ndarray, r: float, t: np.ndarray, plane: str) -> np.ndarray:
    e1, e2, _ = plane_frame(plane)
    t = np.atleast_1d(t)
    return c + r * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)


def check_arc(
    tp: Toolpath, centre: np.ndarray, r: float, t0: float, sweep: float, plane: str
) -> None:
    """C(s) = c + r (cos(t0 + sign s / r) e1 + sin(...) e2) for s in [0, r |sweep|]."""
    assert tp.length == pytest.approx(r * abs(sweep), rel=LENGTH_REL_TOL)
    s = np.linspace(0.0, tp.length, N_SAMPLES)
    expected = circle_point(centre, r, t0 + math.copysign(1.0, sweep) * s / r, plane)
    got = tp.positions(s)
    np.testing.assert_allclose(got, expected, rtol=0, atol=POS_REL_TOL * max(r, 1.0))
    np.testing.assert_allclose(np.linalg.norm(got - centre, axis=1), r, rtol=0, atol=RADIUS_TOL_MM)
    assert tp.corners == []


# --------------------------------------------------------------------------- lines


def test_line_is_exact_and_parameterised_by_length() -> None:
    a, b = np.array([1.0, 2.0, 3.0]), np.array([4.0, 6.0, 15.0])
    seg = line(a, b)
    assert seg.degree == 1
    assert seg.domain == (0.0, 13.0)
    u = np.linspace(0.0, 13.0, 27)
    np.testing.assert_allclose(seg.points(u), a + u[:, None] * (b - a) / 13.0, rtol=0, atol=1e-13)
    assert Toolpath([seg]).length == pytest.approx(13.0, rel=1e-14)


def test_planar_line_points_are_padded() -> None:
    seg = line((0, 0), (3, 4))
    np.testing.assert_array_equal(seg.control_points, [[0, 0, 0], [3, 4, 0]])


@pytest.mark.parametrize("end", [(1.0, 2.0, 3.0), (1.0, 2.0, 3.0 + 5e-10)])
def test_zero_length_line(end: tuple[float, float, float]) -> None:
    with pytest.raises(GeometryError) as info:
        line((1.0, 2.0, 3.0), end, name="segments[4]")
    assert info.value.field == "segments[4].end"
    assert "zero-length" in info.value.rule


@pytest.mark.parametrize(("which", "bad"), [("start", math.nan), ("end", math.inf), ("end", -math.inf)])
def test_line_rejects_non_finite(which: str, bad: float) -> None:
    pts: dict[str, Any] = {"start": [0.0, 0.0, 0.0], "end": [1.0, 1.0, 1.0]}
    pts[which] = [0.5, bad, 0.0]
    with pytest.raises(GeometryError) as info:
        line(pts["start"], pts["end"])
    assert info.value.field == f"line.{which}[1]"
    assert "finite" in info.value.rule


@pytest.mark.parametrize("bad", [[1, 2, 3, 4], [[1, 2, 3]], "abc", [1]])
def test_line_rejects_bad_shapes(bad: object) -> None:
    with pytest.raises(GeometryError) as info:
        line(bad, (0, 0, 0))
    assert info.value.field == "line.start"


# --------------------------------------------------------------------------- polylines


def test_polyline_is_exact_with_corners() -> None:
    pts = np.array([[0, 0, 0], [10, 0, 0], [10, 5, 0], [10, 5, 12]], dtype=float)
    seg = polyline(pts)
    np.testing.assert_array_equal(seg.knots, [0, 0, 10, 15, 27, 27])
    np.testing.assert_allclose(seg.points(np.array([0, 10, 15, 27.0])), pts, atol=1e-14)
    tp = Toolpath([seg])
    assert tp.length == pytest.approx(27.0, rel=1e-14)
    assert [c.s for c in tp.corners] == [pytest.approx(10.0), pytest.approx(15.0)]
    assert [c.angle_deg for c in tp.corners] == [pytest.approx(90.0), pytest.approx(90.0)]


def test_polyline_repeated_point_names_its_index() -> None:
    with pytest.raises(GeometryError) as info:
        polyline([[0, 0], [1, 0], [1, 0], [2, 0]], name="segments[2]")
    err = info.value
    assert err.field == "segments[2].points[2]"
    assert err.value == 0.0
    assert "repeated point" in err.rule and "points[1]" in err.rule


@pytest.mark.parametrize(
    ("points", "fld", "text"),
    [
        ([[0, 0, 0]], "polyline.points", "at least 2"),
        ([[0, 0, 0], [1, math.nan, 0]], "polyline.points[1][1]", "finite"),
        ([0, 1, 2], "polyline.points", "points"),
    ],
)
def test_polyline_validation(points: object, fld: str, text: str) -> None:
    with pytest.raises(GeometryError) as info:
        polyline(points)
    assert info.value.field == fld
    assert text in info.value.rule


# --------------------------------------------------------------------------- arcs: analytic circles

ARC_CASES = [
    # (start angle deg, sweep deg, radius): quarter, small, > 180, nearly full
    (0.0, 90.0, 10.0),
    (30.0, 7.5, 0.25),
    (-120.0, 250.0, 1234.5),
    (45.0, 359.0, 3.0),
]


@pytest.mark.parametrize("plane", ["G17", "G18", "G19"])
@pytest.mark.parametrize("direction", ["cw", "ccw"])
@pytest.mark.parametrize(("t0_deg", "sweep_deg", "r"), ARC_CASES)
def test_centre_format_arc_is_the_analytic_circle(
    plane: str, direction: str, t0_deg: float, sweep_deg: float, r: float
) -> None:
    centre = np.array([3.0, -7.0, 11.0])
    sign = 1.0 if direction == "ccw" else -1.0
    t0 = math.radians(t0_deg)
    sweep = sign * math.radians(sweep_deg)
    start, end = circle_point(centre, r, np.array([t0, t0 + sweep]), plane)
    seg = arc(start, end, centre=centre, plane=plane, direction=direction)
    n_pieces = math.ceil(sweep_deg / 90.0 - 1e-12)
    assert seg.control_points.shape == (2 * n_pieces + 1, 3)
    np.testing.assert_array_equal(seg.control_points[0], start)
    np.testing.assert_array_equal(seg.control_points[-1], end)
    check_arc(Toolpath([seg]), centre, r, t0, sweep, plane)


@pytest.mark.parametrize("plane", ["G17", "G18", "G19"])
@pytest.mark.parametrize("direction", ["cw", "ccw"])
#: R format is ill-conditioned at 180 degrees (the centre's distance from the chord is
#: sqrt(R^2 - (chord/2)^2)); 0.1 degree away the data still fix it to ~1e-11 mm.
@pytest.mark.parametrize("sweep_deg", [60.0, 180.0 - 0.1, 180.0 + 0.1, 300.0])
def test_radius_format_picks_the_short_or_long_arc(plane: str, direction: str, sweep_deg: float) -> None:
    """R > 0: the arc of at most 180 degrees; R < 0: the other one."""
    centre = np.array([1.0, 2.0, 3.0])
    r = 25.0
    sign = 1.0 if direction == "ccw" else -1.0
    t0 = 0.3
    sweep = sign * math.radians(sweep_deg)
    start, end = circle_point(centre, r, np.array([t0, t0 + sweep]), plane)
    R = r if sweep_deg <= 180.0 else -r
    seg = arc(start, end, radius=R, plane=plane, direction=direction)
    # the sign of R is the only information about the centre's side: both radii give one circle each
    check_arc(Toolpath([seg]), centre, r, t0, sweep, plane)


@pytest.mark.parametrize("plane", ["G17", "G18", "G19"])
@pytest.mark.parametrize("direction", ["cw", "ccw"])
@pytest.mark.parametrize("turns", [0, 1, 3])
def test_full_circles_and_turns(plane: str, direction: str, turns: int) -> None:
    centre = np.array([-4.0, 0.5, 2.0])
    r = 6.0
    t0 = 1.1
    start = circle_point(centre, r, np.array([t0]), plane)[0]
    seg = arc(start, start, centre=centre, plane=plane, direction=direction, turns=turns)
    sign = 1.0 if direction == "ccw" else -1.0
    check_arc(Toolpath([seg]), centre, r, t0, sign * 2.0 * math.pi * (1 + turns), plane)
    np.testing.assert_array_equal(seg.control_points[-1], start)


def test_turns_add_full_circles_to_a_partial_arc() -> None:
    centre = np.zeros(3)
    start, end = np.array([5.0, 0, 0]), np.array([0, 5.0, 0])
    tp = Toolpath([arc(start, end, centre=centre, direction="ccw", turns=2)])
    check_arc(tp, centre, 5.0, 0.0, 2.5 * math.pi + 2 * math.pi, "G17")


def test_g18_counter_clockwise_turns_from_z_towards_x() -> None:
    """RS274/NGC: G18 arcs are seen from +Y with Z as the first axis, so G03 from +Z goes to +X."""
    seg = arc((0, 0, 10), (10, 0, 0), centre=(0, 0, 0), plane="G18", direction="ccw")
    tp = Toolpath([seg])
    assert tp.length == pytest.approx(5.0 * math.pi, rel=LENGTH_REL_TOL)
    mid = tp.positions(np.array([tp.length / 2]))[0]
    np.testing.assert_allclose(mid, [10 / math.sqrt(2), 0, 10 / math.sqrt(2)], atol=1e-12)


def test_centre_normal_coordinate_is_not_used() -> None:
    a = arc((10, 0, 2), (0, 10, 2), centre=(0, 0, 99))
    b = arc((10, 0, 2), (0, 10, 2), centre=(0, 0, 2))
    np.testing.assert_array_equal(a.control_points, b.control_points)
    np.testing.assert_array_equal(a.control_points[:, 2], 2.0)


# --------------------------------------------------------------------------- arcs: validation


def test_inconsistent_radii_are_rejected_with_both_numbers() -> None:
    r0 = 10.0
    r1 = 10.0 + 2.5 * ARC_RADIUS_ABS_TOL_MM
    with pytest.raises(GeometryError) as info:
        arc((r0, 0, 0), (0, r1, 0), centre=(0, 0, 0), name="segments[3]")
    err = info.value
    assert err.field == "segments[3].end"
    assert err.value == [pytest.approx(r0), pytest.approx(r1)]
    assert f"{r0:.9g}" in err.rule and f"{r1:.9g}" in err.rule
    assert f"{ARC_RADIUS_ABS_TOL_MM:.3g} mm" in err.rule
    assert "inconsistent arc radii" in err.rule


def test_relative_radius_tolerance_for_large_arcs() -> None:
    r = 1.0e4
    assert radius_tolerance(r) == pytest.approx(ARC_RADIUS_REL_TOL * r)
    ok = r + 0.9 * ARC_RADIUS_REL_TOL * r  # 9 um off, above the absolute 2 um, inside 1e-6 x 10 m
    arc((r, 0, 0), (0, ok, 0), centre=(0, 0, 0))
    with pytest.raises(GeometryError):
        arc((r, 0, 0), (0, r + 1.1 * ARC_RADIUS_REL_TOL * r, 0), centre=(0, 0, 0))


@pytest.mark.parametrize("delta", [0.9 * ARC_RADIUS_ABS_TOL_MM, -0.9 * ARC_RADIUS_ABS_TOL_MM])
def test_radii_within_tolerance_give_a_circle_through_both_ends(delta: float) -> None:
    start = np.array([10.0, 0.0, 0.0])
    end = np.array([0.0, 10.0 + delta, 0.0])
    seg = arc(start, end, centre=(0, 0, 0), direction="ccw")
    tp = Toolpath([seg])
    ends = tp.positions(np.array([0.0, tp.length]))
    np.testing.assert_array_equal(ends[0], start)
    np.testing.assert_array_equal(ends[1], end)
    # a circle: constant curvature, centre on the chord's bisector, within delta / 2 of the given one
    k = np.linalg.norm(tp.evaluate(np.linspace(0, tp.length, 101)).d2, axis=1)
    np.testing.assert_allclose(k, k[0], rtol=1e-9)
    r = 1.0 / k[0]
    assert abs(r - 10.0) <= abs(delta)


@pytest.mark.parametrize(
    ("kwargs", "fld", "text"),
    [
        ({"end": (0, 10, 0.01)}, "arc.end[2]", "helical"),
        ({"end": (0, 10, 0), "plane": "G18", "centre": None, "radius": 10}, "arc.end[1]", "helical"),
        ({"centre": None}, "arc.centre", "exactly one of"),
        ({"radius": 10}, "arc.radius", "exactly one of"),  # (both given: the radius is the one too many)
        ({"centre": (10, 0, 0)}, "arc.centre", "zero radius"),
        ({"centre": (0, 0, math.nan)}, "arc.centre[2]", "finite"),
        ({"end": (0, 10, math.inf)}, "arc.end[2]", "finite"),
        ({"plane": "G20"}, "arc.plane", "G17"),
        ({"direction": "left"}, "arc.direction", "cw"),
        ({"turns": -1}, "arc.turns", "integer >= 0"),
        ({"turns": 1.5}, "arc.turns", "integer >= 0"),
        ({"turns": 1001}, "arc.turns", "<= 1000"),
        ({"centre": None, "radius": 0.0}, "arc.radius", "non-zero"),
        ({"centre": None, "radius": math.nan}, "arc.radius", "finite"),
        ({"centre": None, "radius": "10"}, "arc.radius", "number"),
        ({"centre": None, "radius": 7.0}, "arc.radius", "cannot reach"),
        ({"end": (10, 0, 0), "centre": None, "radius": 10.0}, "arc.radius", "full circle"),
    ],
)
def test_arc_validation(kwargs: dict[str, Any], fld: str, text: str) -> None:
    args: dict[str, Any] = {"start": (10, 0, 0), "end": (0, 10, 0), "centre": (0, 0, 0)}
    args.update(kwargs)
    with pytest.raises(GeometryError) as info:
        arc(args.pop("start"), args.pop("end"), **args)
    assert info.value.field == fld
    assert text in info.value.rule


def test_radius_too_small_names_chord_and_radius() -> None:
    with pytest.raises(GeometryError) as info:
        arc((0, 0, 0), (20, 0, 0), radius=9.0)
    assert "chord is 20 mm" in info.value.rule and "2 |R| = 18 mm" in info.value.rule


def test_radius_within_tolerance_of_half_chord_is_a_half_circle() -> None:
    seg = arc((0, 0, 0), (20, 0, 0), radius=10.0 - 0.5 * ARC_RADIUS_ABS_TOL_MM, direction="cw")
    tp = Toolpath([seg])
    check_arc(tp, np.array([10.0, 0, 0]), 10.0, math.pi, -math.pi, "G17")


# --------------------------------------------------------------------------- property: random arcs

finite = st.floats(min_value=-500.0, max_value=500.0, allow_nan=False)


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(
    cx=finite,
    cy=finite,
    cz=finite,
    r=st.floats(min_value=0.05, max_value=2000.0),
    t0=st.floats(min_value=-math.pi, max_value=math.pi),
    sweep_deg=st.floats(min_value=0.5, max_value=359.5),
    plane=st.sampled_from(sorted(PLANES)),
    direction=st.sampled_from(["cw", "ccw"]),
    turns=st.integers(min_value=0, max_value=2),
    use_radius=st.booleans(),
)
def test_random_arcs_keep_radius_and_end_point(
    cx: float,
    cy: float,
    cz: float,
    r: float,
    t0: float,
    sweep_deg: float,
    plane: str,
    direction: str,
    turns: int,
    use_radius: bool,
) -> None:
    centre = np.array([cx, cy, cz])
    sign = 1.0 if direction == "ccw" else -1.0
    sweep = sign * math.radians(sweep_deg)
    start, end = circle_point(centre, r, np.array([t0, t0 + sweep]), plane)
    if use_radius and abs(sweep_deg - 180.0) > 1.0:  # R format is ill-conditioned at 180 degrees
        R = r if sweep_deg <= 180.0 else -r
        seg = arc(start, end, radius=R, plane=plane, direction=direction, turns=turns)
    else:
        seg = arc(start, end, centre=centre, plane=plane, direction=direction, turns=turns)
    total = sweep + sign * 2.0 * math.pi * turns
    u = np.linspace(*seg.domain, 97)
    p = seg.points(u)
    # every point on the circle (mm), the end exactly reached, the sweep as programmed
    np.testing.assert_allclose(np.linalg.norm(p - centre, axis=1), r, rtol=0, atol=RADIUS_TOL_MM)
    np.testing.assert_array_equal(p[-1], end)
    _, _, normal = plane_frame(plane)
    rel = p - centre
    turning = np.einsum("ij,j->i", np.cross(rel[:-1], rel[1:]), normal)
    assert np.all(np.sign(turning) == sign)
    n_pieces = math.ceil(abs(total) / (0.5 * math.pi) - 1e-12)
    assert seg.control_points.shape[0] == 2 * n_pieces + 1
    if r >= 1.0:  # arc length through the Toolpath tables (skip tiny arcs to keep the test fast)
        assert Toolpath([seg]).length == pytest.approx(r * abs(total), rel=LENGTH_REL_TOL)
