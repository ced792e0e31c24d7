"""Closed-form evaluation of lines and clothoids (dense toolpaths) against the generic path.

``Toolpath`` measures and evaluates straight lines and clothoids in closed form, over
all of them at once; every other segment goes through its adaptive arc-length table.
Here each toolpath is built twice: as given (closed forms) and with every segment
wrapped in ``Opaque``, which hides its type so ``Toolpath`` takes the generic path.
Both must agree on arc length (1e-9 relative: they agree to rounding), positions and
arc-length derivatives at random s, u, corners, pieces and knots. The vectorised
``blend_polyline`` is compared with the corner-by-corner construction (``blend_corner``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pytest

from geometry import primitives
from geometry.arclength import ArcLengthTable
from geometry.clothoid import ClothoidSegment, blend_corner, blend_polyline
from geometry.errors import GeometryError
from geometry.nurbs import FloatArray, NurbsSegment
from geometry.segment import Segment
from geometry.toolpath import CLOTHOID, GENERIC, LINE, Toolpath

LENGTH_REL_TOL = 1e-9
POS_TOL_MM = 1e-9
UNIT_TOL = 1e-9
#: derivative tolerances relative to the largest |C_ss|, |C_sss| on the path
DERIV_REL_TOL = 1e-7


@dataclass(frozen=True, eq=False)
class Opaque:
    """A segment whose type Toolpath does not recognise: measured and evaluated generically."""

    inner: Segment

    @property
    def name(self) -> str:
        return self.inner.name

    @property
    def domain(self) -> tuple[float, float]:
        return self.inner.domain

    @property
    def breakpoints(self) -> FloatArray:
        return self.inner.breakpoints

    def derivatives(self, u: FloatArray) -> FloatArray:
        return self.inner.derivatives(u)

    def speed(self, u: FloatArray) -> FloatArray:
        return self.inner.speed(u)

    def points(self, u: FloatArray) -> FloatArray:
        return self.inner.points(u)

    def split_at_c0_knots(self) -> Sequence[Segment]:
        return [Opaque(p) for p in self.inner.split_at_c0_knots()]


def spiral(moves: int, step: float = 0.5, seed: int = 0) -> FloatArray:
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, moves + 1)
    theta = u * step * moves / 35.0
    r = 10.0 + 50.0 * u
    z = rng.uniform(-0.05, 0.05, moves + 1)
    return np.column_stack([r * np.cos(theta), r * np.sin(theta), z])


def compare(segs: list[Segment], n_points: int = 4000, seed: int = 1) -> tuple[Toolpath, Toolpath]:
    fast = Toolpath(segs)
    slow = Toolpath([Opaque(s) for s in segs])
    assert np.all(slow.sub_kind == GENERIC)
    assert len(fast.subs) == len(slow.subs)
    np.testing.assert_array_equal(fast.sub_origin, slow.sub_origin)
    np.testing.assert_allclose(np.diff(fast.offsets), np.diff(slow.offsets), rtol=LENGTH_REL_TOL, atol=0)
    assert fast.length == pytest.approx(slow.length, rel=LENGTH_REL_TOL)
    np.testing.assert_allclose(fast.knot_s, slow.knot_s, rtol=0, atol=POS_TOL_MM)
    assert [(c.segment, round(c.angle_deg, 6)) for c in fast.corners] == [
        (c.segment, round(c.angle_deg, 6)) for c in slow.corners
    ]
    assert [(p.first_sub, p.last_sub) for p in fast.pieces] == [(p.first_sub, p.last_sub) for p in slow.pieces]
    np.testing.assert_allclose(fast.junction_jumps, slow.junction_jumps, rtol=1e-6, atol=1e-6)
    rng = np.random.default_rng(seed)
    # random points, plus just inside both ends of every sub-segment (a point exactly on a junction
    # may fall on either side: the two toolpaths' offsets differ by rounding, and C_sss jumps there)
    s = np.concatenate([rng.uniform(0.0, fast.length, n_points), fast.offsets[1:-1] - 1e-7,
                        fast.offsets[1:-1] + 1e-7, [0.0, fast.length]])
    s = np.clip(s, 0.0, fast.length)
    # positions are continuous: exactly at the junctions too
    np.testing.assert_allclose(fast.positions(fast.offsets), slow.positions(fast.offsets), rtol=0, atol=POS_TOL_MM)
    for piece_f, piece_s in zip(fast.pieces, slow.pieces, strict=True):
        inside = s[(s >= piece_f.s_start) & (s <= piece_f.s_end)]
        a = fast.evaluate(inside, piece_f)
        b = slow.evaluate(inside, piece_s)
        np.testing.assert_allclose(a.position, b.position, rtol=0, atol=POS_TOL_MM)
        np.testing.assert_allclose(a.d1, b.d1, rtol=0, atol=UNIT_TOL)
        k2 = max(1.0, float(np.abs(b.d2).max()))
        k3 = max(1.0, float(np.abs(b.d3).max()))
        np.testing.assert_allclose(a.d2, b.d2, rtol=0, atol=DERIV_REL_TOL * k2)
        np.testing.assert_allclose(a.d3, b.d3, rtol=0, atol=DERIV_REL_TOL * k3)
        np.testing.assert_allclose(fast.positions(inside, piece_f), a.position, rtol=0, atol=1e-12)
        kf, uf = fast.locate(inside, piece_f)
        ks, us = slow.locate(inside, piece_s)
        np.testing.assert_array_equal(kf, ks)
        np.testing.assert_allclose(uf, us, rtol=0, atol=1e-9 * max(1.0, float(np.abs(us).max())))
    return fast, slow


@pytest.mark.parametrize("tol", [0.0, 0.02, 0.5])
def test_blended_spiral_closed_forms_match_the_tables(tol: float) -> None:
    segs = blend_polyline(spiral(300), tol)
    fast, _ = compare(segs)
    kinds = set(fast.sub_kind.tolist())
    assert kinds == ({LINE} if tol == 0.0 else {LINE, CLOTHOID})


def test_mixed_chain_with_nurbs_polyline_and_reparameterised_line() -> None:
    """Lines with u not equal to s (knots [2, 2, 7, 7]), a polyline split at its vertices, a
    rational NURBS (generic) and clothoids in one chain."""
    a = np.array([0.0, 0.0, 0.0])
    b = np.array([13.0, 0.0, 0.0])
    line_u = NurbsSegment.create(1, [2.0, 2.0, 7.0, 7.0], [a, b], name="line_u")
    arc = primitives.arc(b, [23.0, 10.0, 0.0], centre=[13.0, 10.0, 0.0], direction="ccw")
    poly = primitives.polyline([[23.0, 10.0, 0.0], [23.0, 20.0, 1.0], [30.0, 25.0, 1.0], [31.0, 35.0, 0.0]])
    blended = blend_polyline([[31.0, 35.0, 0.0], [31.5, 40.0, 0.0], [25.0, 44.0, 0.0], [20.0, 44.5, 0.0]], 0.3)
    segs: list[Segment] = [line_u, arc, poly, *blended]
    fast, _ = compare(segs)
    assert fast.sub_kind[0] == LINE and fast.sub_kind[1] == GENERIC
    _, u = fast.locate(np.array([0.0, 6.5, 13.0 - 1e-12]))
    np.testing.assert_allclose(u, [2.0, 4.5, 7.0], rtol=0, atol=1e-12)


def test_unequal_weights_line_is_generic() -> None:
    seg = NurbsSegment.create(1, [0, 0, 1, 1], [[0, 0, 0], [10, 0, 0]], [1.0, 3.0])
    tp = Toolpath([seg])
    assert tp.sub_kind.tolist() == [GENERIC]
    assert tp.length == pytest.approx(10.0, rel=1e-13)


def test_sub_tables_are_built_on_demand_and_match() -> None:
    segs = blend_polyline(spiral(20), 0.05)
    tp = Toolpath(segs)
    assert len(tp.subs) == len(segs)
    for k, tab in enumerate(tp.subs):
        ref = ArcLengthTable.build(segs[k])
        assert tab.segment is segs[k]
        assert tab.length == pytest.approx(ref.length, rel=1e-13)
        assert tab.length == pytest.approx(tp.offsets[k + 1] - tp.offsets[k], rel=1e-12)
    assert [t.segment for t in tp.subs[2:5]] == segs[2:5]
    assert tp.subs[-1].segment is segs[-1]


def reference_blend(points: FloatArray, tol: float, name: str = "polyline") -> list[Segment]:
    """The corner-by-corner construction (``blend_corner`` per corner, as before vectorising)."""
    P = primitives.polyline(points, name=name).control_points
    legs = np.diff(P, axis=0)
    lengths = np.linalg.norm(legs, axis=1)
    units = legs / lengths[:, None]
    out: list[Segment] = []
    current = P[0]
    last = len(legs) - 1
    for i in range(1, len(P) - 1):
        blend = None
        if tol > 0.0:
            room_in = lengths[i - 1] * (1.0 if i - 1 == 0 else 0.5)
            room_out = lengths[i] * (1.0 if i == last else 0.5)
            blend = blend_corner(P[i], units[i - 1], units[i], tol, min(room_in, room_out), f"{name}.corner[{i}]")
        if blend is None:
            out.append(primitives.line(current, P[i], name=f"{name}.line[{i - 1}]"))
            current = P[i]
            continue
        if np.linalg.norm(blend.entry - current) > primitives.MIN_LENGTH_MM:
            out.append(primitives.line(current, blend.entry, name=f"{name}.line[{i - 1}]"))
        out.extend(blend.spirals)
        current = blend.exit
    if np.linalg.norm(P[-1] - current) > primitives.MIN_LENGTH_MM:
        out.append(primitives.line(current, P[-1], name=f"{name}.line[{last}]"))
    return out


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("tol", [0.0, 0.01, 0.3, 5.0])
def test_vectorised_blend_equals_corner_by_corner(seed: int, tol: float) -> None:
    rng = np.random.default_rng(seed)
    pts = np.cumsum(rng.uniform(-3, 3, (40, 3)) * np.array([1.0, 1.0, 0.2]), axis=0)
    pts[7] = pts[6] + 2.0 * (pts[6] - pts[5])  # a straight joint (no blend)
    pts[12] = pts[11] - 0.5 * (pts[11] - pts[10])  # a reversal (stays a corner)
    got = blend_polyline(pts, tol, name="p")
    ref = reference_blend(pts, tol, name="p")
    assert [type(s) for s in got] == [type(s) for s in ref]
    for a, b in zip(got, ref, strict=True):
        assert a.name == b.name
        if isinstance(a, ClothoidSegment) and isinstance(b, ClothoidSegment):
            for f in ("start", "e1", "e2"):
                np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=0, atol=1e-12)
            for f in ("phi0", "kappa0", "sharpness", "length"):
                assert getattr(a, f) == pytest.approx(getattr(b, f), rel=1e-12, abs=1e-15)
        else:
            assert isinstance(a, NurbsSegment) and isinstance(b, NurbsSegment)
            np.testing.assert_allclose(a.control_points, b.control_points, rtol=0, atol=1e-12)
            np.testing.assert_allclose(a.knots, b.knots, rtol=1e-13, atol=1e-13)
            np.testing.assert_array_equal(a.weights, b.weights)
    tp_a, tp_b = Toolpath(got), Toolpath(ref)
    assert len(tp_a.corners) == len(tp_b.corners)
    assert tp_a.length == pytest.approx(tp_b.length, rel=1e-12)


def test_lines_batch_matches_line_and_names_the_bad_one() -> None:
    A = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    B = np.array([[3.0, 4.0, 0.0], [1.0, 2.0, 9.0]])
    got = primitives.lines(A, B, ["a", "b"])
    for seg, a, b, nm in zip(got, A, B, ["a", "b"], strict=True):
        ref = primitives.line(a, b, name=nm)
        np.testing.assert_array_equal(seg.knots, ref.knots)
        np.testing.assert_array_equal(seg.control_points, ref.control_points)
        np.testing.assert_array_equal(seg.weights, ref.weights)
        u = np.linspace(*seg.domain, 7)
        np.testing.assert_array_equal(seg.derivatives(u), ref.derivatives(u))
    with pytest.raises(GeometryError) as info:
        primitives.lines(A, np.array([[3.0, 4.0, 0.0], [1.0, 2.0, 3.0]]), ["a", "b"])
    assert info.value.field == "b.end"
    # longer than MIN_LENGTH_MM along a diagonal, but every coordinate within DEGENERATE_SPAN_MM
    with pytest.raises(GeometryError) as info:
        primitives.line([0, 0, 0], [9e-10, 9e-10, 9e-10], name="c")
    assert info.value.field == "c.control_points"
    with pytest.raises(GeometryError) as info2:
        NurbsSegment.create(1, [0, 0, 1, 1], [[0, 0, 0], [9e-10, 9e-10, 9e-10]], name="c")
    assert info2.value.field == "c.control_points"


def test_gap_error_is_unchanged() -> None:
    a = primitives.line([0, 0, 0], [10, 0, 0], name="segments[0]")
    b = primitives.line([10.01, 0, 0], [20, 0, 0], name="segments[1]")
    for segs in ([a, b], [Opaque(a), Opaque(b)]):
        with pytest.raises(GeometryError) as info:
            Toolpath(segs)
        assert info.value.field == "segments[1].control_points[0]"
        assert info.value.value == pytest.approx(0.01)


def test_collinear_points_are_not_blended() -> None:
    """A straight run tessellated into many moves (collinear up to rounding) has no blends there and no
    error (acos of a rounded cosine used to make such joints 1.5e-8 rad turns with a noise normal)."""
    x = np.linspace(0.0, 7.3, 50)
    pts = np.column_stack([x, 0.3 * x + 1.1, -0.7 * x])
    pts = np.concatenate([pts, pts[-1] + np.array([[0.0, 1.0, 0.0]])])
    segs = blend_polyline(pts, 0.05)
    assert sum(isinstance(s, ClothoidSegment) for s in segs) == 2
    tp = Toolpath(segs)
    assert tp.corners == []


def test_closed_forms_scale_linearly() -> None:
    """Building and evaluating 20,000 blended moves stays far below the per-segment-table cost."""
    pts = spiral(20_000)
    segs = blend_polyline(pts, 0.02)
    tp = Toolpath(segs)
    assert len(tp.subs) == len(segs) and len(tp.pieces) == 1
    s = np.linspace(0.0, tp.length, 200_001)
    ev = tp.evaluate(s)
    np.testing.assert_allclose(np.linalg.norm(ev.d1, axis=1), 1.0, atol=1e-12)
    assert math.isfinite(float(np.abs(ev.d3).max()))
