"""Euler spirals (clothoids), exactly arc-length parameterised, and G2 corner blends for line chains.

A clothoid in the plane spanned by the orthonormal e1, e2 through P0, with tangent
angle phi0, curvature kappa0 and sharpness c = d kappa / ds != 0 (1/mm^2) at s = 0:

    phi(s)   = phi0 + kappa0 s + c s^2 / 2                      (rad)
    kappa(s) = kappa0 + c s                                      (1/mm)
    T(s) = cos phi e1 + sin phi e2,   N(s) = -sin phi e1 + cos phi e2
    C'(s) = T,   C''(s) = kappa N,   C'''(s) = c N - kappa^2 T    (|C'| = 1: u is arc length)
    C(s) = P0 + Re(I) e1 + Im(I) e2,   I(s) = integral_0^s exp(i phi) ds

and with b = kappa0 / c, a = sqrt(pi / |c|), sigma = sign(c) (completing the square):

    I(s) = a exp(i (phi0 - kappa0^2 / (2 c))) [ (Cf(t1) - Cf(t0)) + i sigma (Sf(t1) - Sf(t0)) ],
    t0 = b / a,   t1 = (s + b) / a

where Sf, Cf are the Fresnel integrals integral_0^t sin(pi x^2 / 2) dx, cos(...) dx
(``scipy.special.fresnel``, absolute accuracy ~1e-15 for |t| <= a few).

Corner blend (``blend_corner``). Two lines meet at V with unit directions t_in, t_out
turning by theta in (0, pi). The corner is replaced by two mirror-image clothoids of
length L each: the first from curvature 0 to kappa_m = theta / L, turning theta / 2,
the second back to 0, turning theta / 2 (c = +-theta / L^2). Curvature is continuous
(0 at both lines, kappa_m at the junction M): G2. In the frame (t_in, n), n the in-plane
normal towards the turn, the unit spiral (L = 1) ends at

    fx(theta) = Cf(z) / z,   fy(theta) = Sf(z) / z,   z = sqrt(theta / pi)

so the blend starts at A = V - d t_in and ends at B = V + d t_out with the set-back

    d = L g(theta),   g = fx + fy tan(theta / 2)

and its junction M lies on the corner's bisector at the distance from V

    delta = |V - M| = L h(theta),   h = fy / cos(theta / 2)

delta is the largest deviation between the blend and the original corner in both
directions (two-sided Hausdorff distance): along the first spiral the distance to the
incoming line is its y-coordinate, which grows monotonically (phi <= theta/2 < pi/2)
to fy L <= delta at M, and the nearest blend point to V is M. Given a tolerance eps,

    L = min(eps / h(theta), d_max / g(theta))

where d_max keeps consecutive blends from overlapping (half of each leg; the whole leg
at the ends of the chain). delta = eps unless the legs are too short.

Corners where a line meets an arc, or two arcs meet, are blended by ``geometry.arcblend``
(a clothoid pair with non-zero end curvatures, fitted on the line and the circle).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy.special import fresnel

from geometry import primitives
from geometry.errors import GeometryError
from geometry.nurbs import FloatArray
from geometry.segment import Segment

IntArray = NDArray[np.int64]

#: Corners turning less than this (rad) are left as they are (no blend needed).
MIN_BLEND_ANGLE_RAD: Final = 1e-9
#: Corners turning more than pi minus this (rad) are reversals: no blend fits, the path stops.
MAX_BLEND_ANGLE_MARGIN_RAD: Final = 1e-6
#: Shortest clothoid (mm).
MIN_CLOTHOID_LENGTH_MM: Final = 1e-9
#: Shortest spiral a corner blend makes (mm); a corner whose blend would be shorter stays a corner (the path stops
#: there).  A blend that short turns at ~theta / L: a 1e-7 mm jog between two 90 degree corners, blended at
#: 0.05 mm, made spirals of ~1e-7 mm and a feed that stalls in them (a 422 under both methods; 1e-6 mm under
#: lp+nlp), where the same corners unblended schedule (session 58's API probe).  Jogs of 1e-5 mm and more blend
#: and schedule.  Far under any machine's resolution either way.
MIN_BLEND_SPIRAL_MM: Final = 1e-5
#: Frame vectors must be unit and orthogonal to this (dimensionless).
FRAME_TOL: Final = 1e-12


@dataclass(frozen=True, eq=False, slots=True)
class ClothoidSegment:
    """One Euler spiral, u = arc length s in [0, length] (see the module docstring).

    Attributes:
        start: (3,) start point, mm.
        e1, e2: (3,) orthonormal vectors spanning the spiral's plane.
        phi0: start tangent angle from e1 towards e2, rad.
        kappa0: start curvature, 1/mm (signed: > 0 turns towards e2).
        sharpness: c = d kappa / ds, 1/mm^2, non-zero.
        length: L, mm.
        name: field path used in error messages.
    """

    start: FloatArray
    e1: FloatArray
    e2: FloatArray
    phi0: float
    kappa0: float
    sharpness: float
    length: float
    name: str = "clothoid"

    @classmethod
    def create(
        cls,
        start: object,
        e1: object,
        e2: object,
        phi0: float,
        kappa0: float,
        sharpness: float,
        length: float,
        name: str = "clothoid",
    ) -> ClothoidSegment:
        """Validate and build; raises GeometryError naming the field."""
        P = _vec(start, f"{name}.start")
        a = _vec(e1, f"{name}.e1")
        b = _vec(e2, f"{name}.e2")
        if abs(np.linalg.norm(a) - 1.0) > FRAME_TOL or abs(np.linalg.norm(b) - 1.0) > FRAME_TOL:
            raise GeometryError(f"{name}.e1", [float(np.linalg.norm(a)), float(np.linalg.norm(b))],
                                "e1 and e2 must be unit vectors")
        if abs(float(np.dot(a, b))) > FRAME_TOL:
            raise GeometryError(f"{name}.e2", float(np.dot(a, b)), "e2 must be orthogonal to e1")
        for fld, v in (("phi0", phi0), ("kappa0", kappa0), ("sharpness", sharpness), ("length", length)):
            if not math.isfinite(v):
                raise GeometryError(f"{name}.{fld}", v, "must be finite (no NaN/Inf)")
        if sharpness == 0.0:
            raise GeometryError(f"{name}.sharpness", sharpness, "a clothoid needs a non-zero sharpness")
        if not length > MIN_CLOTHOID_LENGTH_MM:
            raise GeometryError(f"{name}.length", length, f"length must be > {MIN_CLOTHOID_LENGTH_MM} mm")
        return cls(P, a, b, float(phi0), float(kappa0), float(sharpness), float(length), name)

    @property
    def domain(self) -> tuple[float, float]:
        return 0.0, self.length

    @property
    def breakpoints(self) -> FloatArray:
        return np.array([0.0, self.length])

    def split_at_c0_knots(self) -> Sequence[Segment]:
        return [self]

    def angle(self, s: FloatArray) -> FloatArray:
        """Tangent angle phi(s), rad."""
        s = np.asarray(s, dtype=np.float64)
        return np.asarray(self.phi0 + self.kappa0 * s + 0.5 * self.sharpness * s * s, dtype=np.float64)

    def curvature(self, s: FloatArray) -> FloatArray:
        """Signed curvature kappa(s), 1/mm."""
        return np.asarray(self.kappa0 + self.sharpness * np.asarray(s, dtype=np.float64), dtype=np.float64)

    def points(self, u: FloatArray) -> FloatArray:
        """C(s), (K, 3) mm, by Fresnel integrals."""
        s = np.clip(np.asarray(u, dtype=np.float64), 0.0, self.length)
        c = self.sharpness
        a = math.sqrt(math.pi / abs(c))
        b = self.kappa0 / c
        sigma = 1.0 if c > 0 else -1.0
        S1, C1 = fresnel((s + b) / a)
        S0, C0 = fresnel(b / a)
        w = a * np.exp(1j * (self.phi0 - self.kappa0 * self.kappa0 / (2.0 * c))) * ((C1 - C0) + 1j * sigma * (S1 - S0))
        return np.asarray(self.start + np.real(w)[:, None] * self.e1 + np.imag(w)[:, None] * self.e2, dtype=np.float64)

    def derivatives(self, u: FloatArray) -> FloatArray:
        """(4, K, 3): C, C' = T, C'' = kappa N, C''' = c N - kappa^2 T (mm, 1, 1/mm, 1/mm^2)."""
        s = np.clip(np.asarray(u, dtype=np.float64), 0.0, self.length)
        phi = self.angle(s)
        k = self.curvature(s)[:, None]
        cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
        T = cos * self.e1 + sin * self.e2
        N = -sin * self.e1 + cos * self.e2
        return np.stack([self.points(s), T, k * N, self.sharpness * N - k * k * T])

    def speed(self, u: FloatArray) -> FloatArray:
        """|C'(s)| = 1."""
        return np.ones(np.asarray(u).shape[0])


@dataclass(frozen=True)
class CornerBlend:
    """The two spirals replacing one corner, and where they attach.

    Attributes:
        spirals: (in, out) clothoids, each of length ``length``.
        setback: d, distance from the corner to where the blend leaves each line, mm.
        deviation: delta = |V - M|, the blend's largest distance from the corner, mm.
        entry, exit: A = V - d t_in and B = V + d t_out, mm.
    """

    spirals: tuple[ClothoidSegment, ClothoidSegment]
    length: float
    setback: float
    deviation: float
    entry: FloatArray
    exit: FloatArray


def unit_spiral(theta: float) -> tuple[float, float]:
    """(fx, fy): end point of the unit-length spiral turning theta / 2 (curvature 0 -> theta)."""
    z = math.sqrt(theta / math.pi)
    S, C = fresnel(z)
    return float(C) / z, float(S) / z


def blend_factors(theta: float) -> tuple[float, float]:
    """(g, h): set-back d = g L and deviation delta = h L of a blend of spiral length L, turn theta."""
    fx, fy = unit_spiral(theta)
    half = 0.5 * theta
    return fx + fy * math.tan(half), fy / math.cos(half)


def blend_corner(
    vertex: FloatArray, t_in: FloatArray, t_out: FloatArray, tolerance_mm: float, max_setback_mm: float, name: str
) -> CornerBlend | None:
    """Two clothoids replacing the corner at ``vertex`` (unit directions t_in, t_out), or None
    if the corner turns less than MIN_BLEND_ANGLE_RAD or is a reversal."""
    cos_t = float(np.clip(np.dot(t_in, t_out), -1.0, 1.0))
    # the turn from atan2 (acos loses half the digits near 0: collinear legs came out as 1.5e-8 rad)
    theta = math.atan2(float(np.linalg.norm(np.cross(t_in, t_out))), cos_t)
    if theta < MIN_BLEND_ANGLE_RAD or theta > math.pi - MAX_BLEND_ANGLE_MARGIN_RAD:
        return None
    n = _normal(t_in[None, :], t_out[None, :], np.array([cos_t]))[0]
    g, h = blend_factors(theta)
    L = min(tolerance_mm / h, max_setback_mm / g)
    if not L > MIN_BLEND_SPIRAL_MM:
        return None
    d = g * L
    c = theta / (L * L)
    A = vertex - d * t_in
    first = ClothoidSegment.create(A, t_in, n, 0.0, 0.0, c, L, name=f"{name}.in")
    M = first.points(np.array([L]))[0]
    second = ClothoidSegment.create(M, t_in, n, 0.5 * theta, theta / L, -c, L, name=f"{name}.out")
    return CornerBlend((first, second), L, d, h * L, A, vertex + d * t_out)


def blend_polyline(points: object, tolerance_mm: float, name: str = "polyline") -> list[Segment]:
    """Lines through ``points`` with every corner replaced by a G2 clothoid pair within ``tolerance_mm``
    (``blend_polyline_legs`` without the legs)."""
    return blend_polyline_legs(points, tolerance_mm, name)[0]


def blend_polyline_legs(
    points: object, tolerance_mm: float, name: str = "polyline"
) -> tuple[list[Segment], IntArray, IntArray]:
    """Lines through ``points`` with every corner replaced by a G2 clothoid pair within ``tolerance_mm``.

    Each blend keeps its set-back within half of each adjacent leg (the whole leg at the
    chain's ends), so blends never overlap; on short legs the deviation is then below the
    tolerance. Reversals (theta > pi - MAX_BLEND_ANGLE_MARGIN_RAD) stay corners (rest
    points). ``tolerance_mm`` = 0 returns the plain lines (stop at every corner).

    All corners are computed at once (numpy over the corners; ``blend_corner`` is the same
    construction for one corner), so a chain of 10^5 legs costs about as much as building
    its segment objects.

    Returns:
        Segments in path order: lines (degree-1 NurbsSegment) and ClothoidSegments; and for each
        segment the legs it lies on (int arrays ``before``, ``after``; leg j runs from points[j] to
        points[j + 1]): a line is part of one leg (before = after = j), a corner's two spirals sit
        between legs j and j + 1 (before = j, after = j + 1).
    """
    if not (isinstance(tolerance_mm, (int, float)) and math.isfinite(tolerance_mm) and tolerance_mm >= 0.0):
        raise GeometryError("corner_tolerance_mm", tolerance_mm, "must be a finite number >= 0")
    P = primitives.polyline(points, name=name).control_points  # validates: finite, no repeated points
    legs = np.diff(P, axis=0)
    lengths = np.linalg.norm(legs, axis=1)
    units = legs / lengths[:, None]
    m = len(legs)  # corners j = 0 .. m - 2 at P[j + 1], between legs j and j + 1
    t_in, t_out, V = units[:-1], units[1:], P[1:-1]
    cos_t = np.clip(np.einsum("ij,ij->i", t_in, t_out), -1.0, 1.0)
    theta = np.arctan2(np.linalg.norm(np.cross(t_in, t_out), axis=1), cos_t)
    ok = (theta >= MIN_BLEND_ANGLE_RAD) & (theta <= math.pi - MAX_BLEND_ANGLE_MARGIN_RAD) & (tolerance_mm > 0.0)
    j = np.arange(m - 1)
    room = np.minimum(lengths[:-1] * np.where(j == 0, 1.0, 0.5), lengths[1:] * np.where(j + 1 == m - 1, 1.0, 0.5))
    th = np.where(ok, theta, 1.0)  # placeholder turn where no blend is made (keeps the arithmetic finite)
    g, h = _blend_factors(th)
    L = np.minimum(tolerance_mm / h, room / g)
    ok &= L > MIN_BLEND_SPIRAL_MM
    L = np.where(ok, L, 1.0)
    n = _normal(t_in, t_out, cos_t)
    d = g * L
    c = th / (L * L)
    A = V - d[:, None] * t_in
    B = V + d[:, None] * t_out
    # junction M = end of the first spiral (phi0 = kappa0 = 0, c > 0): ClothoidSegment.points at L
    a = np.sqrt(np.pi / c)
    S1, C1 = fresnel(L / a)
    M = A + (a * C1)[:, None] * t_in + (a * S1)[:, None] * n
    # the chain: a line up to each blend's entry A (or to an unblended corner), the two spirals
    prev = np.concatenate([P[:1], np.where(ok[:, None], B, V)])  # where the path stands after corner j - 1
    line_a: list[FloatArray] = []
    line_b: list[FloatArray] = []
    line_name: list[str] = []
    # placeholders: a line's index into line_a, or a corner's (j, first or second spiral)
    order: list[tuple[int, int]] = []
    leg_of: list[int] = []  # the leg before each entry of order (a corner's spirals: the incoming one)
    for jj in range(m - 1):
        i = jj + 1
        if ok[jj]:
            if np.linalg.norm(A[jj] - prev[jj]) > primitives.MIN_LENGTH_MM:
                order.append((0, len(line_a)))
                leg_of.append(jj)
                line_a.append(prev[jj])
                line_b.append(A[jj])
                line_name.append(f"{name}.line[{i - 1}]")
            order.extend(((1, jj), (2, jj)))
            leg_of.extend((jj, jj))
        else:
            order.append((0, len(line_a)))
            leg_of.append(jj)
            line_a.append(prev[jj])
            line_b.append(V[jj])
            line_name.append(f"{name}.line[{i - 1}]")
    if np.linalg.norm(P[-1] - prev[-1]) > primitives.MIN_LENGTH_MM:
        order.append((0, len(line_a)))
        leg_of.append(m - 1)
        line_a.append(prev[-1])
        line_b.append(P[-1])
        line_name.append(f"{name}.line[{m - 1}]")
    segs = primitives.lines(np.array(line_a).reshape(-1, 3), np.array(line_b).reshape(-1, 3), line_name)
    out: list[Segment] = []
    for kind, idx in order:
        if kind == 0:
            out.append(segs[idx])
        elif kind == 1:
            e1, e2 = t_in[idx], n[idx]  # one frame (two array views) for both spirals of the corner
            out.append(ClothoidSegment(A[idx], e1, e2, 0.0, 0.0, float(c[idx]), float(L[idx]),
                                       f"{name}.corner[{idx + 1}].in"))
        else:
            out.append(ClothoidSegment(M[idx], e1, e2, 0.5 * float(th[idx]), float(th[idx] / L[idx]),
                                       -float(c[idx]), float(L[idx]), f"{name}.corner[{idx + 1}].out"))
    before = np.array(leg_of, dtype=np.int64)
    after = before + np.array([kind != 0 for kind, _ in order], dtype=np.int64)
    return out, before, after


def _normal(t_in: FloatArray, t_out: FloatArray, cos_t: FloatArray) -> FloatArray:
    """Unit normals (K, 3) in the plane of t_in, t_out, towards the turn, orthogonal to t_in to rounding
    even for nearly straight joints (where t_out - cos t_in is mostly rounding noise)."""
    n = t_out - cos_t[:, None] * t_in
    n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    n = n - np.einsum("ij,ij->i", n, t_in)[:, None] * t_in
    return np.asarray(n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None], dtype=np.float64)


def _blend_factors(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``blend_factors`` for many turns at once."""
    z = np.sqrt(theta / np.pi)
    S, C = fresnel(z)
    fx, fy = C / z, S / z
    half = 0.5 * theta
    return fx + fy * np.tan(half), fy / np.cos(half)


def _vec(value: object, fld: str) -> FloatArray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(fld, value, "must be a 3-vector") from exc
    if v.shape != (3,):
        raise GeometryError(fld, v.shape, "must be a 3-vector")
    if not np.all(np.isfinite(v)):
        raise GeometryError(fld, v.tolist(), "must be finite (no NaN/Inf)")
    return v
