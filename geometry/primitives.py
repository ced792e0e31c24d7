"""Exact NURBS for the CAM primitives: straight lines, circular arcs, polylines.

Every constructor validates its input like ``NurbsSegment.create`` does (a
``GeometryError`` naming the field, the value and the rule) and returns one
``NurbsSegment`` that *is* the primitive, not an approximation of it.

Line from A to B (mm), degree 1, u = arc length:

    C(u) = A + u (B - A) / L,   u in [0, L],   L = |B - A| > 0

Polyline through P_0 .. P_{m-1}: degree 1, knots at the cumulative chord
lengths s_k, so C(s_k) = P_k and u is arc length; every interior knot has
multiplicity 1 = p, so ``Toolpath`` splits there and finds the corners.

Circular arc, centre c, radius r, in the plane spanned by the unit axes e1, e2
(plane normal e3 = e1 x e2), from angle t0 through the signed sweep D (rad,
D > 0 counter-clockwise seen from +e3):

    C(t) = c + r (cos t e1 + sin t e2),   t in [t0, t0 + D]

written as N = ceil(|D| / (pi/2)) rational quadratic pieces of sweep
phi = D / N (|phi| <= 90 degrees), each with control points and weights
(Piegl & Tiller, eq. 7.8)

    P0 = C(a),   P1 = c + r / cos(phi/2) (cos(a + phi/2) e1 + sin(a + phi/2) e2),   P2 = C(a + phi)
    w  = 1,      cos(phi/2),                                                          1

which lie exactly on the circle: |C(u) - c| = r for every u (to rounding).
Knots [0,0,0, 1,1, 2,2, ..., N,N,N] join the pieces with double knots (C0 in u,
but the tangent is continuous, so ``Toolpath`` finds no corner there).

Planes (G17/G18/G19) and directions follow RS274/NGC: the axis triples
(first, second, normal) are (X, Y, Z), (Z, X, Y) and (Y, Z, X), each right-handed,
and counter-clockwise (G03) is a positive rotation about the normal, seen from
its positive end.

Helical arcs (start and end differ along the plane normal) are *rejected*: a
helix is transcendental in its parameter and no NURBS reproduces it exactly; the
scheduler's exact arc length would be lost. They need a segment type of their
own, through the ``Segment`` protocol of ``geometry/segment.py`` (as ``ClothoidSegment`` does).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Final

import numpy as np

from geometry.errors import GeometryError
from geometry.nurbs import DEGENERATE_SPAN_MM, FloatArray, NurbsSegment, as_points

#: Shortest line or polyline leg (mm); shorter ones have no length to travel.
MIN_LENGTH_MM: Final = 1e-9
#: Arc radii |start - centre| and |end - centre| may differ by at most
#: max(ARC_RADIUS_ABS_TOL_MM, ARC_RADIUS_REL_TOL * radius): the absolute part is a
#: typical control's tolerance (LinuxCNC and Fanuc reject around 0.002-0.01 mm),
#: the relative part covers large radii written with few decimals.
ARC_RADIUS_ABS_TOL_MM: Final = 0.002
ARC_RADIUS_REL_TOL: Final = 1e-6
#: An arc whose start and end differ by more than this along the plane normal is helical.
HELIX_TOL_MM: Final = 1e-9
#: Start and end closer than this (mm, in the plane) make a centre-format arc a full circle.
FULL_CIRCLE_TOL_MM: Final = 1e-9
#: Smallest arc radius (mm).
MIN_RADIUS_MM: Final = 1e-9

#: (first, second, normal) axis indices of each plane; each triple is right-handed.
PLANES: Final[dict[str, tuple[int, int, int]]] = {"G17": (0, 1, 2), "G18": (2, 0, 1), "G19": (1, 2, 0)}
DIRECTIONS: Final[dict[str, int]] = {"ccw": 1, "cw": -1}
_QUARTER = 0.5 * math.pi
#: Most extra full turns of an arc (the API's schema says the same; a G-code P word is turns + 1): P1000000 took a
#: gigabyte in 15 s building its quarter arcs (session 58's API probe).
MAX_TURNS = 1000


def line(start: object, end: object, name: str = "line") -> NurbsSegment:
    """Straight line from ``start`` to ``end`` (mm, [x, y] or [x, y, z]), degree 1, u = arc length.

    Raises:
        GeometryError: non-finite coordinates, or a line shorter than MIN_LENGTH_MM.
    """
    A = _point(start, f"{name}.start")
    B = _point(end, f"{name}.end")
    chord = B - A
    length = float(np.linalg.norm(chord))
    if not length > MIN_LENGTH_MM:
        raise GeometryError(f"{name}.end", length, f"zero-length line: end is within {MIN_LENGTH_MM} mm of start")
    span = float(np.max(np.abs(chord)))
    if not span > DEGENERATE_SPAN_MM:  # as NurbsSegment.create says
        raise GeometryError(f"{name}.control_points", span, "degenerate segment: all control points coincide")
    # the segment NurbsSegment.create would build from these (already checked) inputs
    return NurbsSegment(1, np.array([0.0, 0.0, length, length]), np.array([A, B]), np.ones(2), name)


def lines(starts: FloatArray, ends: FloatArray, names: Sequence[str]) -> list[NurbsSegment]:
    """Many straight lines at once: ``line(starts[i], ends[i], names[i])`` for each i, from (n, 3)
    float arrays of finite points, checked together (a line program of 10^5 moves builds them in
    one pass instead of validating each through ``NurbsSegment.create``; the segments are the same).

    Raises:
        GeometryError: the first line shorter than MIN_LENGTH_MM (field ``<name>.end``) or whose
            points coincide within DEGENERATE_SPAN_MM in every coordinate (``<name>.control_points``,
            as ``NurbsSegment.create`` says).
    """
    A = np.asarray(starts, dtype=np.float64)
    B = np.asarray(ends, dtype=np.float64)
    chord = B - A
    length = np.linalg.norm(chord, axis=1)
    span = np.max(np.abs(chord), axis=1)
    bad = np.flatnonzero(~(length > MIN_LENGTH_MM) | ~(span > DEGENERATE_SPAN_MM))
    if bad.size:
        i = int(bad[0])
        if not length[i] > MIN_LENGTH_MM:
            raise GeometryError(f"{names[i]}.end", float(length[i]),
                                f"zero-length line: end is within {MIN_LENGTH_MM} mm of start")
        raise GeometryError(f"{names[i]}.control_points", float(span[i]),
                            "degenerate segment: all control points coincide")
    n = A.shape[0]
    cp = np.stack([A, B], axis=1)  # (n, 2, 3)
    knots = np.zeros((n, 4))
    knots[:, 2:] = length[:, None]
    weights = np.ones((n, 2))
    return [NurbsSegment(1, knots[i], cp[i], weights[i], names[i]) for i in range(n)]


def polyline(points: object, name: str = "polyline") -> NurbsSegment:
    """Polyline through ``points`` ((m, 2) or (m, 3) mm, m >= 2) as one degree-1 NURBS, u = arc length.

    Raises:
        GeometryError: fewer than 2 points, non-finite coordinates, or a point repeating
            its predecessor (leg shorter than MIN_LENGTH_MM), naming its index.
    """
    P = as_points(points, f"{name}.points")
    if P.shape[0] < 2:
        raise GeometryError(f"{name}.points", P.shape[0], "a polyline needs at least 2 points")
    legs = np.linalg.norm(np.diff(P, axis=0), axis=1)
    short = np.flatnonzero(~(legs > MIN_LENGTH_MM))
    if short.size:
        i = int(short[0]) + 1
        raise GeometryError(
            f"{name}.points[{i}]",
            float(legs[i - 1]),
            f"repeated point: within {MIN_LENGTH_MM} mm of points[{i - 1}] (zero-length leg)",
        )
    s = np.concatenate([[0.0], np.cumsum(legs)])
    knots = np.concatenate([[0.0], s, [s[-1]]])
    return NurbsSegment.create(1, knots, P, name=name)


def arc(
    start: object,
    end: object,
    *,
    centre: object | None = None,
    radius: object | None = None,
    plane: str = "G17",
    direction: str = "ccw",
    turns: object = 0,
    name: str = "arc",
) -> NurbsSegment:
    """Exact circular arc from ``start`` to ``end`` (mm) as rational quadratic pieces of <= 90 degrees.

    Args:
        start, end: [x, y] or [x, y, z] mm; they must agree along the plane normal (no helix).
        centre: circle centre (mm, [x, y] or [x, y, z]); its coordinate along the plane normal is
            not used (the arc lies in the plane through ``start``). Exclusive with ``radius``.
            With ``end`` == ``start`` (within FULL_CIRCLE_TOL_MM) the arc is a full circle.
        radius: R format (mm): R > 0 takes the arc of at most 180 degrees, R < 0 the one of at
            least 180 degrees (RS274/NGC, Fanuc). Cannot describe a full circle.
        plane: "G17" (XY), "G18" (ZX) or "G19" (YZ).
        direction: "ccw" (G03) or "cw" (G02), seen from the positive end of the plane normal.
        turns: extra full turns (integer >= 0) added to the sweep (LinuxCNC P word = turns + 1).

    Radius rule (centre format): with r0 = |start - centre| and r1 = |end - centre| measured in
    the plane, |r1 - r0| <= max(ARC_RADIUS_ABS_TOL_MM, ARC_RADIUS_REL_TOL * max(r0, r1)), else
    a GeometryError naming both radii and the tolerance. Within the tolerance the centre is
    moved to the nearest point of the chord's perpendicular bisector, so the circle passes
    exactly through both ``start`` and ``end`` (the move is at most about half the radius
    difference). R format: the chord must not exceed 2 |R| by more than the same tolerance.

    Returns:
        One degree-2 NurbsSegment, 2 N + 1 control points, N = ceil(|sweep| / 90 degrees).
    """
    S = _point(start, f"{name}.start")
    E = _point(end, f"{name}.end")
    if not isinstance(plane, str) or plane.upper() not in PLANES:
        raise GeometryError(f"{name}.plane", plane, "plane must be one of G17 (XY), G18 (ZX), G19 (YZ)")
    if not isinstance(direction, str) or direction.lower() not in DIRECTIONS:
        raise GeometryError(f"{name}.direction", direction, "direction must be 'cw' (G02) or 'ccw' (G03)")
    a, b, nrm = PLANES[plane.upper()]
    sense = DIRECTIONS[direction.lower()]
    n_turns = _turns(turns, f"{name}.turns")
    rise = float(E[nrm] - S[nrm])
    if abs(rise) > HELIX_TOL_MM:
        raise GeometryError(
            f"{name}.end[{nrm}]",
            rise,
            f"helical arc: end differs from start by {rise:.9g} mm along the plane normal; a helix has no "
            "exact NURBS form, so helical arcs are not supported (only planar arcs)",
        )
    s2 = S[[a, b]]
    e2 = E[[a, b]]
    chord_vec = e2 - s2
    chord = float(np.hypot(chord_vec[0], chord_vec[1]))
    if (centre is None) == (radius is None):  # (both: the radius is the one too many; neither: the centre missing)
        raise GeometryError(f"{name}.radius" if radius is not None else f"{name}.centre", radius,
                            "give exactly one of centre (I J K) or radius (R)")
    if centre is not None:
        C = _point(centre, f"{name}.centre")
        c2 = C[[a, b]]
        r0 = float(np.hypot(*(s2 - c2)))
        r1 = float(np.hypot(*(e2 - c2)))
        if not r0 > MIN_RADIUS_MM:
            raise GeometryError(f"{name}.centre", r0, f"zero radius: centre within {MIN_RADIUS_MM} mm of start")
        tol = radius_tolerance(max(r0, r1))
        if abs(r1 - r0) > tol:
            raise GeometryError(
                f"{name}.end",
                [r0, r1],
                f"inconsistent arc radii: |start - centre| = {r0:.9g} mm, |end - centre| = {r1:.9g} mm, "
                f"difference {abs(r1 - r0):.3g} mm exceeds the tolerance {tol:.3g} mm "
                f"(max({ARC_RADIUS_ABS_TOL_MM} mm, {ARC_RADIUS_REL_TOL:g} x radius))",
            )
        full = chord <= FULL_CIRCLE_TOL_MM
        if not full and chord > tol:
            # move the centre onto the perpendicular bisector of the chord: equal radii exactly.  Not on a chord
            # within the radius tolerance: the end is then as near the start as the radii may differ, and an end
            # 1 um off along the radius put the centre on the chord's midpoint, the arc a 1 um half circle where
            # LinuxCNC (equal angles) cuts a full one (session 58's probe); the angles from the given centre decide
            t = chord_vec / chord
            mid = 0.5 * (s2 + e2)
            off = c2 - mid
            c2 = mid + (off - float(np.dot(off, t)) * t)
    else:
        R = _finite(radius, f"{name}.radius")
        if not abs(R) > MIN_RADIUS_MM:
            raise GeometryError(f"{name}.radius", R, f"radius must be non-zero (|R| > {MIN_RADIUS_MM} mm)")
        if chord <= FULL_CIRCLE_TOL_MM:
            raise GeometryError(
                f"{name}.radius", R, "R format cannot describe a full circle (end = start): use a centre (I J K)"
            )
        half = 0.5 * chord
        rr = abs(R)
        if half > rr + radius_tolerance(rr):
            raise GeometryError(
                f"{name}.radius",
                R,
                f"radius {rr:.9g} mm cannot reach the end point: the chord is {chord:.9g} mm > 2 |R| = {2 * rr:.9g} mm "
                f"(tolerance {radius_tolerance(rr):.3g} mm)",
            )
        h = math.sqrt(max(rr * rr - half * half, 0.0))
        t = chord_vec / chord
        left = np.array([-t[1], t[0]])
        # short arc (R > 0) counter-clockwise has its centre left of the chord
        side = 1.0 if (sense > 0) == (R > 0) else -1.0
        c2 = 0.5 * (s2 + e2) + side * h * left
        full = False
    r = float(np.hypot(*(s2 - c2)))
    t0 = math.atan2(s2[1] - c2[1], s2[0] - c2[0])
    if full:
        sweep = 2.0 * math.pi
    else:
        t1 = math.atan2(e2[1] - c2[1], e2[0] - c2[0])
        sweep = (sense * (t1 - t0)) % (2.0 * math.pi)
        if sweep == 0.0:  # rounding put a (tiny) non-closed arc at zero sweep
            sweep = 2.0 * math.pi
    sweep = sense * (sweep + 2.0 * math.pi * n_turns)
    return _arc_nurbs(S, E if not full else S, c2, r, t0, sweep, (a, b, nrm), name)


def radius_tolerance(radius_mm: float) -> float:
    """Allowed difference (mm) between start and end radius of an arc of the given radius."""
    return max(ARC_RADIUS_ABS_TOL_MM, ARC_RADIUS_REL_TOL * radius_mm)


def arc_frame_nurbs(
    S: FloatArray,
    E: FloatArray,
    centre: FloatArray,
    e1: FloatArray,
    e2: FloatArray,
    r: float,
    t0: float,
    sweep: float,
    name: str,
) -> NurbsSegment:
    """The arc C(t) = centre + r (cos t e1 + sin t e2), t from t0 over ``sweep`` (rad, either sign), as
    N = ceil(|sweep| / (pi / 2)) rational quadratic pieces: control points at the ends and at the
    tangent intersections (radius r / cos(phi / 2), weight cos(phi / 2)); first and last control
    point are ``S`` and ``E`` exactly (the points where the neighbours attach).  ``e1``, ``e2``:
    orthonormal (3,) vectors spanning the arc's plane; ``centre`` (3,) mm."""
    n = max(1, math.ceil(abs(sweep) / _QUARTER - 1e-12))
    phi = sweep / n
    ends = t0 + phi * np.arange(n + 1)
    mids = t0 + phi * (np.arange(n) + 0.5)
    angles = np.empty(2 * n + 1)
    angles[0::2] = ends
    angles[1::2] = mids
    rad = np.full(2 * n + 1, r)
    rad[1::2] = r / math.cos(0.5 * phi)
    P = centre + rad[:, None] * (np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2)
    P[0] = S
    P[-1] = E
    w = np.ones(2 * n + 1)
    w[1::2] = math.cos(0.5 * phi)
    knots = np.concatenate([[0.0], np.repeat(np.arange(n + 1, dtype=np.float64), 2), [float(n)]])
    return NurbsSegment.create(2, knots, P, w, name=name)


def _arc_nurbs(
    S: FloatArray,
    E: FloatArray,
    c2: FloatArray,
    r: float,
    t0: float,
    sweep: float,
    axes: tuple[int, int, int],
    name: str,
) -> NurbsSegment:
    """The arc in the coordinate plane ``axes`` = (a, b, normal) around the in-plane centre c2, at
    the normal coordinate of S (``arc_frame_nurbs`` with e1, e2 the unit vectors of a and b)."""
    a, b, nrm = axes
    eye = np.eye(3)
    centre = np.zeros(3)
    centre[a], centre[b], centre[nrm] = c2[0], c2[1], S[nrm]
    return arc_frame_nurbs(S, E, centre, eye[a], eye[b], r, t0, sweep, name)


def _finite(value: object, fld: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GeometryError(fld, value, "must be a number")
    v = float(value)
    if not math.isfinite(v):
        raise GeometryError(fld, v, "must be finite (no NaN/Inf)")
    return v


def _turns(value: object, fld: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GeometryError(fld, value, "turns must be an integer >= 0")
    v = float(value)
    if not (math.isfinite(v) and v.is_integer() and v >= 0):
        raise GeometryError(fld, value, "turns must be an integer >= 0")
    if v > MAX_TURNS:
        raise GeometryError(fld, value, f"turns must be <= {MAX_TURNS}")
    return int(v)


def _point(value: object, fld: str) -> FloatArray:
    try:
        p = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(fld, value, "must be an [x, y] or [x, y, z] point in mm") from exc
    if p.shape not in ((2,), (3,)):
        raise GeometryError(fld, p.shape, "must be an [x, y] or [x, y, z] point in mm")
    if not np.isfinite(p).all():
        bad = np.flatnonzero(~np.isfinite(p))
        raise GeometryError(f"{fld}[{bad[0]}]", float(p[bad[0]]), "must be finite (no NaN/Inf)")
    return p if p.shape == (3,) else np.append(p, 0.0)
