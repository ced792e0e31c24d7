"""G-code reader (geometry.gcode): behaviour, NURBS round trips, arcs against circles, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry.errors import GeometryError
from geometry.gcode import MM_PER_INCH, GcodeError, parse, tokenize
from geometry.nurbs import NurbsSegment
from geometry.toolpath import Toolpath
from tests.geometry.gcode_writers import fanuc, linuxcnc, linuxcnc_knots, num, siemens
from tests.geometry.nurbs_factory import clamped_knots, random_nurbs
from tests.geometry.test_primitives import check_arc, circle_point

#: A curve read back from G-code vs. the NurbsSegment it was written from (mm).
ROUNDTRIP_TOL_MM = 1e-9
#: Points compared per curve.
N_COMPARE = 400
#: Inch program vs. its mm twin: coordinates (mm) and feeds (relative).
TWIN_TOL_MM = 1e-9
FEED_REL_TOL = 1e-12
HYPOTHESIS_EXAMPLES = 40


def same_curve(a: NurbsSegment, b: NurbsSegment) -> float:
    """Largest distance (mm) between a(u) and b(u') at matching parameters, u' = affine map of u.

    An affine change of the knot vector does not change the curve, so parameters are matched
    by mapping a's domain onto b's."""
    (a0, a1), (b0, b1) = a.domain, b.domain
    u = np.linspace(a0, a1, N_COMPARE)
    v = b0 + (u - a0) * (b1 - b0) / (a1 - a0)
    return float(np.max(np.linalg.norm(a.points(u) - b.points(v), axis=1)))


# --------------------------------------------------------------------------- basics

BASIC = """%
O1000 (a program)
N10 G21 G90 G17 G94
N20 G0 X0 Y0 Z5 M3 S12000 T1
N30 G1 Z0 F600
N40 X10
N50 Y10 ; axis-only line: modal G01
n60 g1 x 20.5   y = 10
N70 G1 X20.5
N80 M30
N90 G1 X1000
"""


def test_basic_program() -> None:
    prog = parse(BASIC)
    assert prog.line == (4, 5, 6, 7, 8)
    assert prog.rapid == (True, False, False, False, False)
    assert prog.feed == (None, 10.0, 10.0, 10.0, 10.0)
    assert prog.units == "mm"
    assert prog.ignored == ((2, "O1000"), (3, "G94"), (4, "M3"), (4, "S12000"), (4, "T1"), (10, "M30"))
    assert prog.null_moves == (9,)
    ends = [seg.points(np.array([seg.domain[1]]))[0] for seg in prog.segments]
    np.testing.assert_array_equal(ends, [[0, 0, 5], [0, 0, 0], [10, 0, 0], [10, 10, 0], [20.5, 10, 0]])
    assert all(seg.degree == 1 for seg in prog.segments)
    tp = prog.toolpath()
    assert tp.length == pytest.approx(5 + 5 + 10 + 10 + 10.5, rel=1e-14)
    assert [c.angle_deg for c in tp.corners] == [pytest.approx(a) for a in (180, 90, 90, 90)]


def test_start_position_and_initial_units() -> None:
    prog = parse("G1 X1 F10", start=(0.0, 0.0, 2.0), units="inch")
    np.testing.assert_array_equal(prog.segments[0].control_points, [[0, 0, 2], [MM_PER_INCH, 0, 2]])
    assert prog.feed == (pytest.approx(10 * MM_PER_INCH / 60, rel=FEED_REL_TOL),)
    assert prog.units == "inch"


@pytest.mark.parametrize(("switch", "lines"), [(False, (1, 2, 3)), (True, (1, 3))])
def test_block_delete(switch: bool, lines: tuple[int, ...]) -> None:
    prog = parse("G1 X1 F100\n/G1 X2\nX3\n", block_delete=switch)
    assert prog.line == lines


def test_incremental_and_absolute_arc_centres() -> None:
    text = """G21 G17 F60
G91 G1 X10 Y0
X0 Y10
G90 G2 X20 Y0 I0 J-10 (centre incremental from the start: 10, 0)
G90.1 G3 X40 Y0 I30 J0 (absolute centre 30, 0)
G91.1 G91 G3 X-20 Y0 R10
"""
    prog = parse(text)
    assert prog.feed == (1.0,) * 5
    tp = prog.toolpath()
    assert tp.length == pytest.approx(20 + 5 * math.pi + 10 * math.pi + 10 * math.pi, rel=1e-12)
    arcs = prog.segments[2:]
    np.testing.assert_allclose(arcs[0].points(np.array(arcs[0].domain)), [[10, 10, 0], [20, 0, 0]], atol=1e-12)
    mid = arcs[0].points(np.array([np.mean(arcs[0].domain)]))[0]
    np.testing.assert_allclose(np.hypot(mid[0] - 10, mid[1]), 10.0, atol=1e-12)
    mid = arcs[1].points(np.array([np.mean(arcs[1].domain)]))[0]
    np.testing.assert_allclose(mid, [30, -10, 0], atol=1e-12)  # G03 from (20,0) to (40,0) about (30,0): below
    mid = arcs[2].points(np.array([np.mean(arcs[2].domain)]))[0]
    np.testing.assert_allclose(mid, [30, 10, 0], atol=1e-12)


def test_full_circle_without_axis_words_and_turns() -> None:
    prog = parse("G0 X10 Y0\nG2 I-10 F60\nG3 X10 Y0 I-10 P3\n")
    tp = Toolpath([prog.segments[1]])
    check_arc(tp, np.zeros(3), 10.0, 0.0, -2 * math.pi, "G17")
    tp = Toolpath([prog.segments[2]])
    check_arc(tp, np.zeros(3), 10.0, 0.0, 3 * 2 * math.pi, "G17")


@pytest.mark.parametrize(("plane", "offs"), [("G17", "IJ"), ("G18", "KI"), ("G19", "JK")])
@pytest.mark.parametrize("code", ["G2", "G3"])
@pytest.mark.parametrize("fmt", ["ijk", "r"])
def test_arcs_in_every_plane_are_analytic_circles(plane: str, offs: str, code: str, fmt: str) -> None:
    centre = np.array([1.5, -2.0, 0.75])
    r = 12.5
    t0 = 0.4
    sweep = math.radians(130.0) * (-1 if code == "G2" else 1)
    start, end = circle_point(centre, r, np.array([t0, t0 + sweep]), plane)
    axis = {"I": 0, "J": 1, "K": 2}
    if fmt == "ijk":
        spec = " ".join(f"{o}{num(centre[axis[o]] - start[axis[o]])}" for o in offs)
    else:
        spec = f"R{num(r)}"
    text = f"G21 G90 {plane}\nG0 X{num(start[0])} Y{num(start[1])} Z{num(start[2])}\n"
    text += f"{code} X{num(end[0])} Y{num(end[1])} Z{num(end[2])} {spec} F300\n"
    prog = parse(text)
    assert prog.feed == (None, 5.0)
    check_arc(Toolpath([prog.segments[1]]), centre, r, t0, sweep, plane)


def test_inch_program_equals_its_mm_twin() -> None:
    inch = """G20 G90 G17 G94
G0 X1 Y0.5 Z0.25
G1 Z0 F10
G1 X2.5 Y0.5
G2 X3.5 Y1.5 I0 J1
G3 X3.5 Y3.5 R-1.0
G91 G1 X-0.125 Y0.0625 Z0.001
G90 G06.2 P3 K0 X3.375 Y3.5625 Z0.001 F20
K0 X3 Y4 R0.75
K0 X2.5 Y3.75
K1
K1
K1
"""
    mm = """G21 G90 G17 G94
G0 X25.4 Y12.7 Z6.35
G1 Z0 F254
G1 X63.5 Y12.7
G2 X88.9 Y38.1 I0 J25.4
G3 X88.9 Y88.9 R-25.4
G91 G1 X-3.175 Y1.5875 Z0.0254
G90 G06.2 P3 K0 X85.725 Y90.4875 Z0.0254 F508
K0 X76.2 Y101.6 R0.75
K0 X63.5 Y95.25
K1
K1
K1
"""
    a, b = parse(inch), parse(mm)
    assert a.units == "inch" and b.units == "mm"
    assert a.line == b.line and a.rapid == b.rapid
    assert len(a.segments) == 7
    for fa, fb in zip(a.feed, b.feed, strict=True):
        assert (fa is None and fb is None) or fa == pytest.approx(fb, rel=FEED_REL_TOL)
    for sa, sb in zip(a.segments, b.segments, strict=True):
        assert sa.degree == sb.degree
        np.testing.assert_allclose(sa.control_points, sb.control_points, rtol=0, atol=TWIN_TOL_MM)
        np.testing.assert_allclose(sa.weights, sb.weights, rtol=1e-15)
        assert same_curve(sa, sb) <= TWIN_TOL_MM
    assert a.toolpath().length == pytest.approx(b.toolpath().length, rel=1e-12)


def test_units_switch_mid_program_is_mixed() -> None:
    prog = parse("G21 G1 X10 F600\nG20 X1 F10\n")
    assert prog.units == "mixed"
    np.testing.assert_array_equal(prog.segments[1].control_points[-1], [25.4, 0, 0])
    assert prog.feed == (10.0, pytest.approx(25.4 * 10 / 60))


def test_fanuc_hpcc_and_noop_codes_are_listed() -> None:
    prog = parse("G05 P10000\nG05.1 Q1\nG40 G49 G80 G54 G64 G61\nG1 X1 F60\nG05 P0\n")
    assert prog.ignored == (
        (1, "G05 P10000"), (2, "G05.1 Q1"), (3, "G40"), (3, "G49"), (3, "G80"), (3, "G54"), (3, "G64"), (3, "G61"),
        (5, "G05 P0"),
    )
    assert len(prog.segments) == 1


def test_tokenizer_words_and_columns() -> None:
    (block,) = tokenize("  /N5 g06.2 p3 ( c ) K-.5 X = 1. SD=2 BSPLINE ; tail")
    assert block.deleted
    assert [(w.name, w.value, w.col) for w in block.words] == [
        ("N", 5.0, 4), ("G", 6.2, 7), ("P", 3.0, 13), ("K", -0.5, 22), ("X", 1.0, 27), ("SD", 2.0, 34),
        ("BSPLINE", None, 39),
    ]


# --------------------------------------------------------------------------- NURBS round trips

ROUNDTRIP_SEEDS = range(6)


@pytest.mark.parametrize("seed", ROUNDTRIP_SEEDS)
@pytest.mark.parametrize("degree", [1, 2, 3])
def test_fanuc_g06_2_round_trip(seed: int, degree: int) -> None:
    rng = np.random.default_rng(100 * degree + seed)
    original = random_nurbs(rng, degree, n_interior=int(rng.integers(0, 6)), lo=-1.0, hi=2.5).segment()
    prog = parse(fanuc(original))
    assert prog.rapid == (True, False, True)
    seg = prog.segments[1]
    assert prog.line[1] == 3
    assert prog.feed[1] == pytest.approx(20.0)
    assert seg.degree == degree
    np.testing.assert_array_equal(seg.knots, original.knots)
    np.testing.assert_array_equal(seg.weights, original.weights)
    assert same_curve(original, seg) <= ROUNDTRIP_TOL_MM


def siemens_nurbs(rng: np.random.Generator, degree: int) -> NurbsSegment:
    """Random clamped NURBS Siemens can express: simple interior knots, weights in (0, 3], w_0 = 1."""
    m = int(rng.integers(0, 6))
    spans = rng.uniform(0.3, 1.0, m + 1)
    interior = np.cumsum(spans)[:-1] / spans.sum() * 4.0
    knots = clamped_knots(degree, interior, np.ones(m, dtype=int), 0.0, 4.0)
    n = knots.size - degree - 1
    w = rng.uniform(0.6, 1.7, n)
    return NurbsSegment.create(degree, knots, rng.uniform(-50, 50, (n, 3)), w / w[0])


@pytest.mark.parametrize("seed", ROUNDTRIP_SEEDS)
@pytest.mark.parametrize("degree", [2, 3])
def test_siemens_bspline_round_trip(seed: int, degree: int) -> None:
    original = siemens_nurbs(np.random.default_rng(200 * degree + seed), degree)
    prog = parse(siemens(original))
    assert prog.rapid == (True, False, True)
    seg = prog.segments[1]
    assert prog.line[1] == 4  # the BSPLINE block
    assert seg.degree == degree
    np.testing.assert_allclose(seg.knots, original.knots, rtol=0, atol=1e-14)
    assert same_curve(original, seg) <= ROUNDTRIP_TOL_MM


@pytest.mark.parametrize("degree", [2, 3])
def test_siemens_without_pl_uses_uniform_knots(degree: int) -> None:
    rng = np.random.default_rng(7 + degree)
    n = 7
    uniform = np.concatenate([np.zeros(degree), np.arange(n - degree + 1, dtype=float), np.full(degree, n - degree)])
    w = rng.uniform(0.6, 1.7, n)
    original = NurbsSegment.create(degree, uniform, rng.uniform(-20, 20, (n, 3)), w / w[0])
    seg = parse(siemens(original, write_pl=False)).segments[1]
    np.testing.assert_array_equal(seg.knots, uniform)
    assert same_curve(original, seg) <= ROUNDTRIP_TOL_MM
    # scaling every PL by the same factor draws the same curve
    scaled = siemens(original).replace("PL=1 ", "PL=3 ").replace("PL=1\n", "PL=3\n")
    assert "PL=3" in scaled
    assert same_curve(original, parse(scaled).segments[1]) <= ROUNDTRIP_TOL_MM


@pytest.mark.parametrize("seed", ROUNDTRIP_SEEDS)
@pytest.mark.parametrize("order", [3, 4, 5])
def test_linuxcnc_g5_2_round_trip(seed: int, order: int) -> None:
    rng = np.random.default_rng(300 * order + seed)
    n = int(rng.integers(order, order + 6))
    P = np.column_stack([rng.uniform(-40, 40, (n, 2)), np.full(n, 3.25)])
    original = NurbsSegment.create(order - 1, linuxcnc_knots(n, order), P, rng.uniform(0.3, 3.0, n))
    prog = parse(linuxcnc(original))
    assert prog.rapid == (True, False, True)
    seg = prog.segments[1]
    assert seg.degree == order - 1
    np.testing.assert_array_equal(seg.knots, original.knots)
    assert same_curve(original, seg) <= ROUNDTRIP_TOL_MM


def test_fanuc_defaults_first_block_and_incremental_points() -> None:
    """P omitted = rank 4; no control point in the first block = current position; the knot
    omitted in the first block = the second block's; G91 control points are increments."""
    absolute = "G0 X1 Y2 Z3\nG06.2 P4 K0 X1 Y2 Z3 F600\nK0 X4 Y2 Z3\nK0 X4 Y6\nK0 X9 Y6 Z0 R2\nK1\nK1\nK1\nK1\n"
    implicit = "G0 X1 Y2 Z3\nG06.2 F600\nK0 X4 Y2 Z3\nK0 X4 Y6\nK0 X9 Y6 Z0 R2\nK1\nK1\nK1\nK1\n"
    incremental = "G0 X1 Y2 Z3\nG91 G06.2 K0 X0 Y0 Z0 F600\nK0 X3\nK0 Y4\nK0 X5 Z-3 R2\nK1\nK1\nK1\nK1\n"
    segs = [parse(t).segments[1] for t in (absolute, implicit, incremental)]
    for seg in segs:
        assert seg.degree == 3
        np.testing.assert_array_equal(seg.control_points, [[1, 2, 3], [4, 2, 3], [4, 6, 3], [9, 6, 0]])
        np.testing.assert_array_equal(seg.weights, [1, 1, 1, 2])
        np.testing.assert_array_equal(seg.knots, [0, 0, 0, 0, 1, 1, 1, 1])


def test_fanuc_mode_is_modal_across_curves() -> None:
    text = "G0 X0 Y0 Z0\nG06.2 P2 K0 X0 Y0 Z0 F600\nK0 X10\nK1\nK1\nP2 K0 X10 Y0 Z0\nK0 Y10\nK1\nK1\nG1 X0\n"
    prog = parse(text)
    assert prog.line == (2, 6, 10)
    assert prog.null_moves == (1,)
    np.testing.assert_array_equal(prog.segments[1].control_points, [[10, 0, 0], [10, 10, 0]])


def test_siemens_incremental_points_and_spline_end_at_m30() -> None:
    text = "G1 X0 Y0 F600\nG91 BSPLINE SD=2\nX10 Y10\nX10 Y-10 PW=2\nX10\nM30\n"
    seg = parse(text).segments[0]
    np.testing.assert_array_equal(seg.control_points, [[0, 0, 0], [10, 10, 0], [20, 0, 0], [30, 0, 0]])
    np.testing.assert_array_equal(seg.weights, [1, 1, 2, 1])
    np.testing.assert_array_equal(seg.knots, [0, 0, 0, 1, 2, 2, 2])


# --------------------------------------------------------------------------- hypothesis: arcs as text


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(
    cx=st.floats(-300, 300),
    cy=st.floats(-300, 300),
    r=st.floats(0.1, 500),
    t0=st.floats(-math.pi, math.pi),
    sweep_deg=st.floats(1.0, 359.0),
    ccw=st.booleans(),
    use_r=st.booleans(),
)
def test_random_g2_g3_text_reaches_the_end_on_the_circle(
    cx: float, cy: float, r: float, t0: float, sweep_deg: float, ccw: bool, use_r: bool
) -> None:
    centre = np.array([cx, cy, 0.0])
    sweep = math.radians(sweep_deg) * (1 if ccw else -1)
    start, end = circle_point(centre, r, np.array([t0, t0 + sweep]), "G17")
    if use_r and abs(sweep_deg - 180.0) > 1.0:
        spec = f"R{num(r if sweep_deg < 180 else -r)}"
    else:
        spec = f"I{num(cx - start[0])} J{num(cy - start[1])}"
    text = f"G0 X{num(start[0])} Y{num(start[1])}\n{'G3' if ccw else 'G2'} X{num(end[0])} Y{num(end[1])} {spec} F100\n"
    seg = parse(text).segments[1]
    p = seg.points(np.linspace(*seg.domain, 64))
    # IJK offsets are start-relative and rounded: the centre is exact to ~1e-13 of the coordinates
    np.testing.assert_allclose(np.linalg.norm(p - centre, axis=1), r, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(p[-1], end)


# --------------------------------------------------------------------------- malformed programs

F = "F100\n"  # a feed so that cutting moves are otherwise valid
FANUC_HEAD = "G06.2 P2 K0 X0 Y0 Z0 F100\n"

MALFORMED = [
    # (program, line, col, fragment of the rule)
    ("G1 X10 F100\nG1 X1.2.3", 2, 8, "unexpected character '.'"),
    ("G1 X F100", 1, 4, "X must be followed by a number"),
    ("G1 X10 (comment", 1, 8, "not closed"),
    ("G1 X10 ) F100", 1, 8, "without an opening"),
    ("G1 X#1 F100", 1, 4, "X must be followed by a number"),
    ("G1 X10 * 5", 1, 8, "unexpected character '*'"),
    ("% junk", 1, 1, "unexpected character '%'"),
    ("G1 X" + "9" * 400, 1, 4, "out of range"),
    ("G1 X10 A5 F100", 1, 8, "axis A is not supported"),
    ("G41 X10", 1, 1, "unsupported G code G41"),
    ("G1.23 X1", 1, 1, "at most one decimal"),
    ("G93 G1 X10", 1, 1, "feed per minute (G94)"),
    ("G1 G0 X10", 1, 4, "two G codes of one modal group"),
    ("BSPLINE G1 X1", 1, 1, "two motion commands"),
    ("G1 X10 X20 F100", 1, 8, "appears twice"),
    ("G1 X10 F0", 1, 8, "F must be > 0"),
    ("G1 X10", 1, 4, "without a feed rate"),
    ("G1 X10 I5 F100", 1, 8, "word I is not used"),
    ("G1 X10 F100 D1", 1, 13, "unsupported word D1"),
    ("GOTOF LABEL", 1, 1, "unsupported word GOTOF"),
    ("X10", 1, 1, "no motion mode is active"),
    ("G1 X10 F100 SD=2", 1, 13, "B spline points"),
    ("M98 P100", 1, 1, "sub-programs"),
    (F + "G2 X10 Y0", 2, 4, "arc needs a centre"),
    (F + "G2 X10 Y0 R5 I5", 2, 11, "either R or I J K"),
    (F + "G17 G2 X10 Y0 I5 K1", 2, 18, "word K is not used"),
    (F + "G2 X10 Y0 Z1 I5", 2, 11, "helical arc"),
    (F + "G3 X10 Y0.5 I5", 2, 4, "inconsistent arc radii: |start - centre| = 5 mm, |end - centre| = 5.02"),
    (F + "G2 X20 R5", 2, 8, "cannot reach the end point"),
    (F + "G2 R5", 2, 4, "full circle"),
    (F + "G2 X10 P0 I5", 2, 8, "P (number of turns)"),
    (F + "G2 X10 P1000000 I5", 2, 8, "turns must be <= 1000"),
    ("G1 X\u0661\u0660 F100", 1, 4, "X must be followed by a number"),
    ("G1 X\uff11\uff10 F100", 1, 4, "X must be followed by a number"),
    ("G90.1 F100\nG2 X10 Y0 I5", 2, 11, "needs both I and J"),
    ("G05 X10 Y10 I1 J1 P1 Q1", 1, 1, "high-speed mode switch"),
    # Fanuc G06.2
    ("G06.2 P5 K0 X0 Y0 Z0 F100", 1, 7, "rank P must be 2, 3 or 4"),
    ("G06.2 P3 K0 X1 Y0 Z0 F100", 1, 13, "PS1009"),
    (FANUC_HEAD + "K0 X10\nK1\nG1 X20", 4, 1, "PS1005"),
    (FANUC_HEAD + "K0 X10\nK1", 1, 1, "program ends inside"),
    (FANUC_HEAD + "K0 X10\nK2 X20\nK1\nK1", 4, 1, "must not decrease"),
    (FANUC_HEAD + "K0.5 X10\nK1\nK1", 2, 1, "PS1007"),
    (FANUC_HEAD + "K0 X10\nK0 X20\nK0 X30\nK1\nK1", 4, 1, "repeats too often"),
    (FANUC_HEAD + "X10", 2, 1, "needs a knot K"),
    ("G06.2 P3 K0 X0 Y0 Z0 F100\nK0 X10\nK0 X20\nK1\nK1 X30", 5, 4, "PS1004"),
    ("G06.2 P2 K0 X0 Y0 Z0 R0 F100", 1, 22, "weight R must be > 0"),
    (FANUC_HEAD + "K0 X10 M8", 2, 8, "M codes are not allowed"),
    (FANUC_HEAD + "K0 X10 P3", 2, 8, "rank P only in the first block"),
    (FANUC_HEAD + "G17 K0 X10", 2, 1, "only control-point words"),
    ("G06.2 P2 K0 X0 Y0 Z0\nK0 X10\nK1\nK1", 1, 1, "without a feed rate"),
    # Siemens BSPLINE
    (F + "BSPLINE\nX10 Y10 PW=4", 3, 9, "PW must be in (0, 3]"),
    ("BSPLINE SD=4", 1, 9, "SD must be 2 or 3"),
    (F + "BSPLINE\nX10 Y10\nX20 Y0\nG1 X30", 2, 1, "needs at least 3 points"),
    (F + "BSPLINE SD=2\nX10 Y10 PL=1\nX20 Y0\nX30 Y5\nG1 X40", 4, 1, "on every point of the B spline or on none"),
    (F + "BSPLINE SD=3\nX10 Y10 PL=1\nX20 Y0 PL=1\nX30 Y5\nG1 X40", 4, 8, "have no parameter interval"),
    (F + "BSPLINE SD=2\nX10 Y10 PL=0\nX20 Y0 PL=1\nX30 Y5", 3, 9, "PL must be > 0"),
    (F + "BSPLINE PW=2", 2, 9, "needs a point"),
    (F + "BSPLINE\nX10 Y10\nX20 Y0 SD=2", 4, 8, "SD must be programmed on or before the first point"),
    (F + "BSPLINE\nX10 Y10\nX20 Y0 F200", 4, 8, "F cannot change inside a B spline"),
    # LinuxCNC G5.2
    (F + "G5.2 X0 Y1 L3", 2, 6, "needs X, Y and a weight P"),
    (F + "G5.2 L2", 2, 6, "order L must be an integer >= 3"),
    (F + "G5.2 L14", 2, 6, "order L must be <= 13"),
    (F + "G18 G5.2 P1", 2, 5, "planar in XY"),
    (F + "G91 G5.2 P1", 2, 5, "absolute (G90)"),
    (F + "G5.2\nX1 Y1 P1\nX2 Y0 P1\nG1 X5", 5, 1, "closed with G5.3"),
    (F + "G5.2\nX1 Y1 P1", 2, 1, "program ends inside this G5.2"),
    (F + "G5.2 L4\nX1 Y1 P1\nG5.3", 4, 1, "needs at least 4 control points"),
    (F + "G5.2\nX1 Y1 Z1 P1", 3, 7, "planar in XY"),
    (F + "G5.2\nX1 Y1 P0", 3, 7, "weight P must be > 0"),
    ("G5.3", 1, 1, "without an open G5.2"),
]


@pytest.mark.parametrize(("text", "line", "col", "fragment"), MALFORMED, ids=[f"m{i}" for i in range(len(MALFORMED))])
def test_malformed_program_names_line_and_column(text: str, line: int, col: int, fragment: str) -> None:
    with pytest.raises(GcodeError) as info:
        parse(text)
    err = info.value
    assert isinstance(err, GeometryError)
    assert (err.line, err.col) == (line, col), err
    assert err.field == f"gcode:line {line}:col {col}"
    assert fragment in err.rule, err
    assert str(err).startswith(f"{err.field}: {err.rule}")


@pytest.mark.parametrize(("text", "line", "fragment"), [
    ("G1 X1" + "0" * 200 + " F100", 1, "coordinates must be within"),  # (was a 500: an infinite length)
    ("G1 X10 F600\nG91" + "\nX100000000" * 11, 12,
     "coordinates must be within"),  # (incremental steps past the bound: the line that crosses it)
])
def test_toolpath_errors_of_a_program_name_its_line(text: str, line: int, fragment: str) -> None:
    """What the toolpath refuses (not the parser) is named by the program's line, not by a ``segments[i]`` the
    upload does not have (session 58's probe)."""
    with pytest.raises(GcodeError) as info:
        parse(text).toolpath()
    assert info.value.field == f"gcode:line {line}:col 1" and fragment in info.value.rule


@pytest.mark.parametrize(("end", "full"), [("X10.000001 Y0", True), ("X9.999999 Y0", True), ("X10 Y0.000001", True),
                                           ("X10 Y-0.000001", False), ("X10 Y0", True)])
def test_an_arc_ending_within_its_radius_tolerance_of_its_start(end: str, full: bool) -> None:
    """G2 from (10, 0) around (0, 0) to an end 1 um off the start: along the radius the centre went to the chord's
    midpoint and the arc was a 1 um half circle (LinuxCNC, from equal angles, cuts a full circle; session 58's
    probe).  The angles from the given centre decide: a full circle where they are equal or the end is just past
    the start, a 1 um arc where it is just short of it (clockwise), ending on the programmed point."""
    tp = parse(f"G21 G90\nG1 X10 F600\nG2 {end} I-10\n").toolpath()
    want = 10.0 + (2 * math.pi * 10.0 if full else 1e-6)
    assert tp.length == pytest.approx(want, abs=2e-6)
    x, y = (float(w[1:]) for w in end.split())
    np.testing.assert_allclose(tp.positions(np.array([tp.length]))[0], [x, y, 0.0], rtol=0, atol=1e-12)


def test_a_leading_byte_order_mark_is_not_part_of_the_program() -> None:
    """Windows CAM files often start with a UTF-8 BOM: it was "unexpected character" at line 1 col 1."""
    plain, marked = parse("G21 G90\nG1 X10 F600\n"), parse("\ufeffG21 G90\nG1 X10 F600\n")
    assert len(marked.segments) == len(plain.segments) == 1
    np.testing.assert_array_equal(marked.segments[0].control_points, plain.segments[0].control_points)


def test_invalid_parse_arguments() -> None:
    with pytest.raises(GeometryError) as info:
        parse("G0 X1", units="furlong")
    assert info.value.field == "units"
    with pytest.raises(GeometryError) as info:
        parse("G0 X1", start=(0.0, math.nan, 0.0))
    assert info.value.field == "start"
