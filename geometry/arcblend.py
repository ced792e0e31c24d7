"""G2 corner blends where a line meets an arc or two arcs meet: a clothoid pair fitted on the curves.

``geometry.clothoid.blend_polyline`` blends line-line corners in closed form. Where one side
(or both) of a tangent break is a circular arc, the corner is replaced here by two Euler
spirals (``ClothoidSegment``, kappa(s) = kappa0 + c s) that leave the incoming curve, join
each other, and land on the outgoing curve, matching position, unit tangent and signed
curvature at both ends; the arcs are trimmed where the blend meets them and stay exact
rational quadratic arcs (``arc_nurbs``).

Local frame of a corner at V (mm, complex numbers z = x + i y): e1 = the incoming unit
tangent at V, e2 = n x e1 with n the unit normal of the corner's plane oriented so that
the outgoing tangent is exp(i theta), theta in (0, pi) the tangent break (rad). Each side is a
line or a circle of signed curvature k (1/mm; k = +1/R turns towards e2, 0 for a line). The
point at arc length s from V (s < 0 on the incoming side, s > 0 on the outgoing side) is

    gamma1(s) = E(k1, s),   gamma2(s) = exp(i theta) E(k2, s),
    E(k, s) = (exp(i k s) - 1) / (i k) = s sinc(k s / pi) + i s sin(k s / 2) sinc(k s / (2 pi))

(E(0, s) = s; the sinc form has no cancellation as k -> 0). The blend starts at
A = gamma1(-sigma1) with tangent angle phiA = -k1 sigma1 and curvature k1, ends at
B = gamma2(sigma2) with angle phiB = theta + k2 sigma2 and curvature k2, sigma1, sigma2 > 0
(mm) the lengths of the curves it replaces. Both spirals have the length L (mm):

    spiral 1: kappa k1 -> km,  c1 = (km - k1) / L,   turns (k1 + km) L / 2
    spiral 2: kappa km -> k2,  c2 = (k2 - km) / L,   turns (km + k2) L / 2

The turns add up to phiB - phiA = theta + k1 sigma1 + k2 sigma2 =: Delta, so

    km = Delta / L - (k1 + k2) / 2                                       (1/mm)

and with D(kappa0, c, L) = integral_0^L exp(i (kappa0 t + c t^2 / 2)) dt (the Fresnel
integrals of ``geometry.clothoid``; here by 32-point Gauss-Legendre, exact to rounding for
turns below pi and well defined at c = 0) the closure equations in the two unknowns
(sigma1, sigma2) are

    F(sigma1, sigma2) = A + exp(i phiA) [D(k1, c1, L) + exp(i (k1 + km) L / 2) D(km, c2, L)] - B = 0

(two real equations). For k1 = k2 = 0 the solution is the symmetric line-line pair of
``blend_corner`` (sigma1 = sigma2 = g(theta) L); that is the starting guess, and
``scipy.optimize.root`` (MINPACK hybrid Powell) solves F / L = 0 to 1e-14.

Size. The two-sided Hausdorff distance ``deviation`` between the blend and the original
corner (the incoming curve from A to V and the outgoing one from V to B) is measured on the
solved blend: the distance of 257 points per spiral to the true line / circle pieces (the
largest refined twice on a 33-point grid between its neighbours, so a kink of the distance
function is not missed), and of 129 points per original piece (V included) to the blend
(nearest sample, then the two adjacent chords). L is chosen by a safeguarded secant on

    rho(L) = max(deviation / eps, sigma1 / room1, sigma2 / room2)

aiming at rho = 0.999 and accepting rho in [0.99, 1]: every quantity grows about linearly
with L. ``room`` keeps consecutive blends apart: half of a curve shared by two corners, the
whole of it at the end of a chain, and never more than a quarter turn of an arc.

When no blend passes every check (closure residual <= 1e-10 L, sigma1, sigma2 > 0, each
spiral turning less than pi with |c| L^2 >= 1e-12, deviation <= eps, rooms) the corner is
left as it is and reported (``Unblended``): e.g. an arc radius too small for the tolerance
leaves only L below MIN_BLEND_SPIRAL_MM. A wrong blend is never produced.

Limits: both curves must lie in one plane (lines in the arc's plane, arcs with parallel
normals, |cos| <= COPLANAR_TOL); others stay rest points ("not coplanar"). Junctions without
a tangent break (theta < MIN_BLEND_ANGLE_RAD, e.g. a line running tangentially into an arc)
are left as they are: the curvature still jumps there (the toolpath is G1, not G2).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
from scipy.optimize import root

from geometry import primitives
from geometry.clothoid import (
    MAX_BLEND_ANGLE_MARGIN_RAD,
    MIN_BLEND_ANGLE_RAD,
    MIN_BLEND_SPIRAL_MM,
    ClothoidSegment,
    blend_factors,
    blend_polyline_legs,
)
from geometry.errors import GeometryError
from geometry.nurbs import FloatArray, NurbsSegment
from geometry.segment import Segment

#: A line's direction may leave an arc's plane (or two arcs' normals may differ) by this much (|cos|, rad).
COPLANAR_TOL: Final = 1e-9
#: Relative tolerance of the exact-arc test on a NURBS (isosceles polygon, weight = cos(turn / 2), common circle).
ARC_FIT_TOL: Final = 1e-9
#: Two segments are blended only where they meet within this distance (mm).
JOINT_TOL_MM: Final = 1e-6
#: Smallest blend tolerance (mm) ``blend_path`` accepts other than 0: the path fidelity (every sample within
#: 1 um of the curve).  A narrower blend moves the path by less than the fidelity allows anyway and its
#: clothoids (a few nm to um long, curvature up to 10^6 /mm) only hold the feed down: random programs blended
#: at 4.5 nm and 34 nm stalled the LP ("feed stalls") and ran 129,079 s of lp+nlp motion where the LP alone
#: took 4,547 s (cam-bench seeds 20 and 14, session 38).
MIN_BLEND_TOLERANCE_MM: Final = 1e-3
#: The rule a blend tolerance under MIN_BLEND_TOLERANCE_MM breaks (``blend_path``, and the service's schema).
BLEND_TOLERANCE_RULE: Final = (f"must be 0 (stop at corners) or >= {MIN_BLEND_TOLERANCE_MM:g} mm: a narrower blend is "
                               "within the 1 um path fidelity and only holds the feed down")
#: Largest closure residual |F| accepted, relative to the spiral length L.
CLOSURE_TOL: Final = 1e-10
#: Aim of the secant on rho(L) and the band accepted below 1.
RHO_TARGET: Final = 0.999
RHO_ACCEPT: Final = 0.99
#: Smallest |c| L^2 (rad) of a spiral: below it the spiral is an arc and the Fresnel form loses digits.
MIN_SPIRAL_TURN_CHANGE: Final = 1e-12
#: Secant / bisection steps on L.
MAX_STEPS: Final = 40
#: Samples per spiral and per original piece for the deviation.
SPIRAL_SAMPLES: Final = 257
PIECE_SAMPLES: Final = 129
ZOOM_SAMPLES: Final = 33

_GL_X, _GL_W = np.polynomial.legendre.leggauss(32)


class Line(NamedTuple):
    """A straight line from ``start`` to ``end`` (mm). (Immutable like the dataclasses here, and cheaper
    to build: a dense program makes 10^5 of them.)"""

    start: FloatArray
    end: FloatArray

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    @property
    def direction(self) -> FloatArray:
        d = self.end - self.start
        return np.asarray(d / np.linalg.norm(d), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class Arc:
    """A circular arc C(t) = centre + radius (cos t e1 + sin t e2), t in [0, sweep] (rad).

    Attributes:
        centre: (3,) mm.  radius: R, mm.
        e1, e2: (3,) orthonormal; C(0) = centre + R e1 is the start; the arc runs counter-clockwise
            about normal = e1 x e2.
        sweep: total angle, rad, > 0 (more than 2 pi with full turns).
        start, end: (3,) the end points as the segment has them (exact control points), mm.
    """

    centre: FloatArray
    radius: float
    e1: FloatArray
    e2: FloatArray
    sweep: float
    start: FloatArray
    end: FloatArray

    @property
    def length(self) -> float:
        return self.radius * self.sweep

    @property
    def normal(self) -> FloatArray:
        return np.asarray(np.cross(self.e1, self.e2), dtype=np.float64)

    def point(self, t: float) -> FloatArray:
        return np.asarray(self.centre + self.radius * (math.cos(t) * self.e1 + math.sin(t) * self.e2),
                          dtype=np.float64)

    def tangent(self, t: float) -> FloatArray:
        return np.asarray(-math.sin(t) * self.e1 + math.cos(t) * self.e2, dtype=np.float64)


Primitive = Line | Arc


@dataclass(frozen=True)
class Unblended:
    """A corner ``blend_path`` left as it was (a rest point if it turns more than the corner tolerance).

    Attributes:
        segment: index of the input segment that starts at the corner.
        position: the corner, mm.
        angle_deg: its tangent break, degrees.
        reason: why no blend was made, in words.
    """

    segment: int
    position: tuple[float, float, float]
    angle_deg: float
    reason: str


@dataclass(frozen=True)
class ArcCornerBlend:
    """A solved corner (see the module docstring for the symbols).

    Attributes:
        sigma_in, sigma_out: sigma1, sigma2: length of the incoming / outgoing curve replaced, mm.
        length: L of each spiral, mm.  kappa_mid: km, 1/mm.
        sharpness: (c1, c2), 1/mm^2.  phi_in: phiA, rad (local frame).
        deviation: two-sided distance between the blend and the original corner, mm.
    """

    sigma_in: float
    sigma_out: float
    length: float
    kappa_mid: float
    sharpness: tuple[float, float]
    phi_in: float
    deviation: float


@dataclass(frozen=True)
class BlendedPath:
    """``blend_path``'s output: the segments, the input segments each came from, the corners left as they were.

    ``origin[k]`` is the input segment output segment k lies on; for a corner blend's spiral, the
    one before the corner, and ``after[k]`` the one after it (``after[k] == origin[k]`` elsewhere).
    A caller that gives the inputs different properties (e.g. feed limits) gives a blend both
    sides' (e.g. the lower feed).
    """

    segments: list[Segment]
    origin: list[int]
    unblended: list[Unblended]
    after: list[int]


# --------------------------------------------------------------------------- recognising lines and arcs


def primitives_of(seg: Segment) -> list[Primitive] | None:
    """The lines (a degree-1 NURBS: one per leg of non-zero length) or the exact circular arc that
    ``seg`` is, or None (any other curve; a NURBS arc that is not exactly circular)."""
    if not isinstance(seg, NurbsSegment):
        return None
    P = seg.control_points
    if seg.degree == 1:
        if P.shape[0] == 2:
            return [Line(P[0], P[1])]
        keep = np.concatenate([[True], np.linalg.norm(np.diff(P, axis=0), axis=1) > primitives.MIN_LENGTH_MM])
        Q = P[keep]
        return [Line(Q[i], Q[i + 1]) for i in range(Q.shape[0] - 1)] or None
    if seg.degree != 2:
        return None
    arc = _as_arc(seg)
    return None if arc is None else [arc]


def _as_arc(seg: NurbsSegment) -> Arc | None:
    """The circle of a rational quadratic NURBS made of Bezier pieces (double interior knots) each of
    which is an exact arc: isosceles control polygon Q0 Q1 Q2 turning by alpha in (0, pi) and
    w1 / sqrt(w0 w2) = cos(alpha / 2); all pieces on one circle, one normal (Piegl & Tiller 7.3)."""
    U, P, w = seg.knots, seg.control_points, seg.weights
    n = (P.shape[0] - 1) // 2
    if P.shape[0] != 2 * n + 1 or n < 1 or U.shape[0] != 2 * n + 4:
        return None
    if not (U[0] == U[1] == U[2] and U[-1] == U[-2] == U[-3]):
        return None
    inner = U[3:-3].reshape(-1, 2) if n > 1 else np.zeros((0, 2))
    if np.any(inner[:, 0] != inner[:, 1]):
        return None
    Q0, Q1, Q2 = P[0:-1:2], P[1::2], P[2::2]
    a, b = Q1 - Q0, Q2 - Q1
    la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    if not np.all((la > 0.0) & (lb > 0.0)):
        return None
    cr = np.cross(a, b)
    sin_n = np.linalg.norm(cr, axis=1)
    alpha = np.arctan2(sin_n, np.einsum("ij,ij->i", a, b))
    wn = w[1::2] / np.sqrt(w[0:-1:2] * w[2::2])
    if not (np.all(np.abs(la - lb) <= ARC_FIT_TOL * la) and np.all(sin_n > 0.0)
            and np.all(np.abs(wn - np.cos(0.5 * alpha)) <= ARC_FIT_TOL)):
        return None
    nrm = cr / sin_n[:, None]
    R = la / np.tan(0.5 * alpha)
    inward = np.cross(nrm, a / la[:, None])
    centres = Q0 + R[:, None] * inward
    r0, c0, n0 = float(R[0]), centres[0], nrm[0]
    if not (np.all(np.abs(R - r0) <= ARC_FIT_TOL * r0)
            and np.all(np.linalg.norm(centres - c0, axis=1) <= ARC_FIT_TOL * r0)
            and np.all(np.linalg.norm(nrm - n0, axis=1) <= ARC_FIT_TOL)):
        return None
    e1 = (P[0] - c0) / r0
    e1 = e1 - float(np.dot(e1, n0)) * n0
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n0, e1)
    return Arc(c0, r0, e1, e2, float(np.sum(alpha)), P[0].copy(), P[-1].copy())


def arc_nurbs(arc: Arc, t0: float, t1: float, start: FloatArray, end: FloatArray, name: str) -> NurbsSegment:
    """The part t in [t0, t1] of ``arc`` as an exact NURBS (``geometry.primitives.arc_frame_nurbs`` in
    the arc's own frame), first and last control points ``start`` and ``end`` exactly (the points
    where the neighbours attach)."""
    return primitives.arc_frame_nurbs(start, end, arc.centre, arc.e1, arc.e2, arc.radius, t0, t1 - t0, name)


# --------------------------------------------------------------------------- the corner in its plane


def _E(k: float, s: FloatArray) -> FloatArray:
    """E(k, s) = (exp(i k s) - 1) / (i k), complex, (K,): the point at arc length s from V of a
    curve of curvature k leaving V along +x."""
    s = np.asarray(s, dtype=np.float64)
    ks = k * s
    return np.asarray(s * np.sinc(ks / math.pi) + 1j * s * np.sin(0.5 * ks) * np.sinc(ks / (2.0 * math.pi)))


def _spiral_chord(kappa0: float, c: float, L: float) -> complex:
    """D(kappa0, c, L) = integral_0^L exp(i (kappa0 t + c t^2 / 2)) dt by Gauss-Legendre."""
    t = 0.5 * L * (_GL_X + 1.0)
    return complex(0.5 * L * np.sum(_GL_W * np.exp(1j * (kappa0 * t + 0.5 * c * t * t))))


@dataclass(frozen=True)
class _Pair:
    s1: float
    s2: float
    L: float
    km: float
    c1: float
    c2: float
    phiA: float


def _pair(theta: float, k1: float, k2: float, L: float, s1: float, s2: float) -> _Pair:
    delta = theta + k1 * s1 + k2 * s2
    km = delta / L - 0.5 * (k1 + k2)
    return _Pair(s1, s2, L, km, (km - k1) / L, (k2 - km) / L, -k1 * s1)


def _closure(theta: float, k1: float, k2: float, L: float, s1: float, s2: float) -> complex:
    """F(sigma1, sigma2) of the module docstring, mm."""
    p = _pair(theta, k1, k2, L, s1, s2)
    A = complex(_E(k1, np.array([-s1]))[0])
    B = complex(np.exp(1j * theta) * _E(k2, np.array([s2]))[0])
    turn1 = 0.5 * (k1 + p.km) * L
    D = _spiral_chord(k1, p.c1, L) + np.exp(1j * turn1) * _spiral_chord(p.km, p.c2, L)
    return complex(A + np.exp(1j * p.phiA) * D - B)


def _solve(theta: float, k1: float, k2: float, L: float, guess: tuple[float, float]) -> _Pair | None:
    def f(x: FloatArray) -> FloatArray:
        z = _closure(theta, k1, k2, L, float(x[0]), float(x[1])) / L
        return np.array([z.real, z.imag])

    sol = root(f, np.asarray(guess, dtype=np.float64), method="hybr", options={"xtol": 1e-14})
    s1, s2 = float(sol.x[0]), float(sol.x[1])
    if not (math.isfinite(s1) and math.isfinite(s2)):
        return None
    if abs(_closure(theta, k1, k2, L, s1, s2)) > CLOSURE_TOL * L:
        return None
    return _pair(theta, k1, k2, L, s1, s2)


def _local_spirals(p: _Pair, k1: float) -> tuple[ClothoidSegment, ClothoidSegment] | None:
    """The two spirals in the local frame (x, y, 0), or None if one is (nearly) an arc or turns >= pi."""
    L = p.L
    turn1 = 0.5 * (k1 + p.km) * L
    turn2 = 0.5 * (p.km + (p.km + p.c2 * L)) * L
    if min(abs(p.c1), abs(p.c2)) * L * L < MIN_SPIRAL_TURN_CHANGE or max(abs(turn1), abs(turn2)) >= math.pi:
        return None
    A = complex(_E(k1, np.array([-p.s1]))[0])
    ex, ey = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    first = ClothoidSegment(np.array([A.real, A.imag, 0.0]), ex, ey, p.phiA, k1, p.c1, L)
    M = first.points(np.array([L]))[0]
    second = ClothoidSegment(M, ex, ey, p.phiA + turn1, p.km, p.c2, L)
    return first, second


def _dist_piece(z: FloatArray, k: float, rot: complex, lo: float, hi: float) -> FloatArray:
    """Distance (K,) of points z (complex, local frame) to the curve rot E(k, s), s in [lo, hi]
    (|k| (hi - lo) <= pi / 2 + pi / 2: the nearest circle point is found by its angle)."""
    w = np.asarray(z) / rot
    if k == 0.0:
        x = np.clip(w.real, lo, hi)
        return np.asarray(np.abs(w - x), dtype=np.float64)
    c = 1j / k
    s_star = np.angle((w - c) / (-c)) / k
    inside = (s_star >= lo) & (s_star <= hi)
    d_circle = np.abs(np.abs(w - c) - 1.0 / abs(k))
    ends = _E(k, np.array([lo, hi]))
    d_ends = np.minimum(np.abs(w - ends[0]), np.abs(w - ends[1]))
    return np.asarray(np.where(inside, d_circle, d_ends), dtype=np.float64)


def _deviation(theta: float, k1: float, k2: float, p: _Pair, spirals: tuple[ClothoidSegment, ClothoidSegment]) -> float:
    """Two-sided distance between the blend and the original corner (module docstring), mm."""
    rot2 = complex(np.exp(1j * theta))

    def to_orig(sp: ClothoidSegment, s: FloatArray) -> FloatArray:
        q = sp.points(s)
        z = q[:, 0] + 1j * q[:, 1]
        return np.minimum(_dist_piece(z, k1, 1.0, -p.s1, 0.0), _dist_piece(z, k2, rot2, 0.0, p.s2))

    worst = 0.0
    chain: list[FloatArray] = []
    for sp in spirals:
        s = np.linspace(0.0, sp.length, SPIRAL_SAMPLES)
        d = to_orig(sp, s)
        for _ in range(2):  # zoom in between the neighbours of the largest
            j = int(np.argmax(d))
            s = np.linspace(s[max(j - 1, 0)], s[min(j + 1, s.size - 1)], ZOOM_SAMPLES)
            d = to_orig(sp, s)
        worst = max(worst, float(np.max(d)))
        q = sp.points(np.linspace(0.0, sp.length, SPIRAL_SAMPLES))
        chain.append(q[:, 0] + 1j * q[:, 1])
    blend = np.concatenate(chain)
    orig = np.concatenate([_E(k1, np.linspace(-p.s1, 0.0, PIECE_SAMPLES)),
                           rot2 * _E(k2, np.linspace(0.0, p.s2, PIECE_SAMPLES))])
    near = np.argmin(np.abs(orig[:, None] - blend[None, :]), axis=1)
    best = np.abs(orig - blend[near])
    for off in (-1, 0):  # the chords on either side of the nearest sample
        i0 = np.clip(near + off, 0, blend.size - 2)
        a, b = blend[i0], blend[i0 + 1]
        ab = b - a
        t = np.clip(np.real((orig - a) * np.conj(ab)) / np.maximum(np.abs(ab) ** 2, 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.abs(orig - (a + t * ab)))
    return max(worst, float(np.max(best)))


def solve_corner(
    theta: float, k1: float, k2: float, room1: float, room2: float, tolerance_mm: float
) -> tuple[ArcCornerBlend, tuple[ClothoidSegment, ClothoidSegment]] | str:
    """The clothoid pair for a corner in its local frame (module docstring), or the reason there is none.

    Args:
        theta: tangent break, rad, in [MIN_BLEND_ANGLE_RAD, pi - MAX_BLEND_ANGLE_MARGIN_RAD].
        k1, k2: signed curvature of the incoming / outgoing curve, 1/mm (0: line).
        room1, room2: longest part of each curve the blend may replace, mm.
        tolerance_mm: eps, the largest deviation allowed, mm.

    Returns:
        (the solution, the two spirals in the local frame: start at A = (x, y, 0), e1 = x, e2 = y).
    """
    g, h = blend_factors(theta)
    L = min(tolerance_mm / h, room1 / g, room2 / g)
    guess = (g * L, g * L)
    best: tuple[float, ArcCornerBlend, tuple[ClothoidSegment, ClothoidSegment]] | None = None
    hi = math.inf
    reason = "no clothoid pair closes the corner"
    for _ in range(MAX_STEPS):
        if not L > MIN_BLEND_SPIRAL_MM:
            reason = f"the spirals would be shorter than {MIN_BLEND_SPIRAL_MM} mm"
            break
        p = _solve(theta, k1, k2, L, guess)
        rho = math.inf
        if p is not None and p.s1 > 0.0 and p.s2 > 0.0:
            sp = _local_spirals(p, k1)
            if sp is not None:
                dev = _deviation(theta, k1, k2, p, sp)
                rho = max(dev / tolerance_mm, p.s1 / room1, p.s2 / room2)
                if rho <= 1.0 and (best is None or L > best[0]):
                    best = (L, ArcCornerBlend(p.s1, p.s2, L, p.km, (p.c1, p.c2), p.phiA, dev), sp)
                if rho <= 1.0 and rho >= RHO_ACCEPT:
                    break
                guess = (p.s1, p.s2)
        if rho > 1.0:
            hi = min(hi, L)
        lo = best[0] if best is not None else 0.0
        nxt = L * RHO_TARGET / rho if math.isfinite(rho) else 0.5 * (lo + L)
        if not lo < nxt < hi:
            nxt = 0.5 * (lo + hi)
        if best is not None and hi - lo <= 1e-9 * lo:
            break
        guess = (guess[0] * nxt / L, guess[1] * nxt / L)
        L = nxt
    if best is None:
        return reason
    return best[1], best[2]


# --------------------------------------------------------------------------- chains


@dataclass(frozen=True)
class _Corner:
    """A solved corner between pieces j and j + 1, in 3-D."""

    sigma_in: float
    sigma_out: float
    spirals: tuple[ClothoidSegment, ClothoidSegment]


def _tangent_in(pr: Primitive) -> FloatArray:
    return pr.direction if isinstance(pr, Line) else pr.tangent(pr.sweep)


def _tangent_out(pr: Primitive) -> FloatArray:
    return pr.direction if isinstance(pr, Line) else pr.tangent(0.0)


def _room(pr: Primitive, shared: bool) -> float:
    r = pr.length * (0.5 if shared else 1.0)
    return min(r, 0.5 * math.pi * pr.radius) if isinstance(pr, Arc) else r


def _arc_corner(
    a: Primitive, b: Primitive, room_a: float, room_b: float, tol: float, name: str
) -> _Corner | str | None:
    """The blend of the corner where ``a`` ends and ``b`` starts (at least one an arc), the reason
    there is none, or None where the tangent does not break (nothing to blend)."""
    t_in, t_out = _tangent_in(a), _tangent_out(b)
    arcs = [pr for pr in (a, b) if isinstance(pr, Arc)]
    nc = arcs[0].normal
    for pr in (a, b):
        if isinstance(pr, Arc):
            if float(np.linalg.norm(np.cross(pr.normal, nc))) > COPLANAR_TOL:
                return "not coplanar: the arcs lie in different planes"
        elif abs(float(np.dot(pr.direction, nc))) > COPLANAR_TOL:
            return "not coplanar: the line leaves the arc's plane"
    theta = math.atan2(float(np.dot(np.cross(t_in, t_out), nc)), float(np.dot(t_in, t_out)))
    if theta < 0.0:
        nc, theta = -nc, -theta
    if theta < MIN_BLEND_ANGLE_RAD:
        return None
    if theta > math.pi - MAX_BLEND_ANGLE_MARGIN_RAD:
        return "reversal: the path turns back on itself"
    e1 = t_in / np.linalg.norm(t_in)
    e2 = np.cross(nc, e1)
    e2 -= float(np.dot(e2, e1)) * e1
    e2 /= np.linalg.norm(e2)

    def curvature(pr: Primitive) -> float:
        return 0.0 if isinstance(pr, Line) else math.copysign(1.0 / pr.radius, float(np.dot(pr.normal, nc)))

    k1, k2 = curvature(a), curvature(b)
    out = solve_corner(theta, k1, k2, room_a, room_b, tol)
    if isinstance(out, str):
        return out
    sol, (l1, l2) = out
    A = a.end - sol.sigma_in * a.direction if isinstance(a, Line) else a.point(a.sweep - sol.sigma_in / a.radius)
    first = ClothoidSegment.create(A, e1, e2, l1.phi0, l1.kappa0, l1.sharpness, l1.length, name=f"{name}.in")
    M = first.points(np.array([sol.length]))[0]
    second = ClothoidSegment.create(M, e1, e2, l2.phi0, l2.kappa0, l2.sharpness, l2.length, name=f"{name}.out")
    return _Corner(sol.sigma_in, sol.sigma_out, (first, second))


def blend_path(
    segments: Sequence[Segment],
    tolerance_mm: float,
    keys: Sequence[Hashable] | None = None,
    names: Sequence[str] | None = None,
) -> BlendedPath:
    """``segments`` with the corners between lines and arcs replaced by G2 clothoid pairs within ``tolerance_mm``.

    Runs of consecutive segments that are lines, polylines or exact arcs (``primitives_of``), meet
    within JOINT_TOL_MM and have equal ``keys`` (e.g. the programmed feed) are blended: line-line
    corners by ``blend_polyline``, corners with an arc by ``solve_corner``; arcs are trimmed
    and stay exact (``arc_nurbs``). Other segments, and junctions between runs, are kept as they are.

    A run may join segments that differ in other ways (e.g. a G-code program passes the rapid flag
    as the key, so cutting moves at different F form one run): ``BlendedPath.origin`` and
    ``after`` tell which input segments each output segment lies between.

    ``tolerance_mm`` is 0 (no blends: the segments come back as they are) or at least
    MIN_BLEND_TOLERANCE_MM; anything else is a GeometryError.

    Returns:
        The segments, the index of the input segment each came from (a blend: the one before its
        corner; ``after``: the one after it) and the corners with an arc that could not be
        blended, with the reason.
    """
    if not (isinstance(tolerance_mm, (int, float)) and math.isfinite(tolerance_mm) and tolerance_mm >= 0.0):
        raise GeometryError("corner_tolerance_mm", tolerance_mm, "must be a finite number >= 0")
    if 0.0 < tolerance_mm < MIN_BLEND_TOLERANCE_MM:
        raise GeometryError("corner_tolerance_mm", tolerance_mm, BLEND_TOLERANCE_RULE)
    n = len(segments)
    nm = list(names) if names is not None else [seg.name for seg in segments]
    # plain lines (two control points) need no Line object unless their run has an arc: a dense program has 10^5
    plain = [isinstance(s, NurbsSegment) and s.degree == 1 and s.control_points.shape[0] == 2 for s in segments]
    prims = [None if plain[i] or tolerance_mm == 0.0 else primitives_of(s) for i, s in enumerate(segments)]
    # junction i joins segments i and i + 1 into one run (all at once)
    nan = np.full(3, np.nan)

    def end_point(i: int, last: bool) -> FloatArray:
        seg, pr = segments[i], prims[i]
        if plain[i] and isinstance(seg, NurbsSegment):
            return np.asarray(seg.control_points[-1 if last else 0], dtype=np.float64)
        if pr is None:
            return nan
        return pr[-1].end if last else pr[0].start

    ends = np.array([end_point(i, True) for i in range(n)]).reshape(-1, 3)
    starts = np.array([end_point(i, False) for i in range(n)]).reshape(-1, 3)
    joined = np.linalg.norm(starts[1:] - ends[:-1], axis=1) <= JOINT_TOL_MM  # False where NaN
    joined &= tolerance_mm > 0.0
    if keys is not None:
        joined &= np.array([keys[i + 1] == keys[i] for i in range(n - 1)], dtype=bool)
    out = BlendedPath([], [], [], [])
    i = 0
    breaks = [*np.flatnonzero(~joined).tolist(), n - 1]
    for j in breaks:  # a run is i .. j
        if j == i:
            out.segments.append(segments[i])
            out.origin.append(i)
            out.after.append(i)
        else:
            _blend_run(segments, plain, prims, i, j, tolerance_mm, nm, out)
        i = j + 1
    return out


def _blend_run(
    segments: Sequence[Segment], plain: list[bool], prims: list[list[Primitive] | None], i0: int, i1: int,
    tol: float, names: list[str], out: BlendedPath,
) -> None:
    """Blend segments i0 .. i1 (all lines / arcs, joined; ``plain``: a two-point line) into ``out``."""
    if all(plain[i0 : i1 + 1]):  # the closed-form, vectorised line chain
        cps = [s.control_points for s in segments[i0 : i1 + 1] if isinstance(s, NurbsSegment)]
        run, before, after = blend_polyline_legs(np.array([cps[0][0]] + [c[-1] for c in cps]), tol, name=names[i0])
        out.segments.extend(run)
        out.origin.extend((before + i0).tolist())  # leg q of the polyline is input segment i0 + q
        out.after.extend((after + i0).tolist())
        return
    pieces: list[Primitive] = []
    origin: list[int] = []
    for i in range(i0, i1 + 1):
        prs = prims[i] if not plain[i] else primitives_of(segments[i])
        assert prs is not None  # the run holds lines and arcs only (checked by blend_path)
        pieces.extend(prs)
        origin.extend([i] * len(prs))
    m = len(pieces)
    trim_start = np.zeros(m)
    trim_end = np.zeros(m)
    corners: dict[int, _Corner] = {}
    for j in range(m - 1):
        a, b = pieces[j], pieces[j + 1]
        if isinstance(a, Line) and isinstance(b, Line):
            continue
        room_a = _room(a, shared=j > 0)
        room_b = _room(b, shared=j + 1 < m - 1)
        res = _arc_corner(a, b, room_a, room_b, tol, f"{names[origin[j]]}.corner")
        if isinstance(res, _Corner):
            corners[j] = res
            trim_end[j] = res.sigma_in
            trim_start[j + 1] = res.sigma_out
        elif isinstance(res, str):
            t_in, t_out = _tangent_in(a), _tangent_out(b)
            ang = math.degrees(math.atan2(float(np.linalg.norm(np.cross(t_in, t_out))), float(np.dot(t_in, t_out))))
            V = a.end
            out.unblended.append(Unblended(origin[j + 1], (float(V[0]), float(V[1]), float(V[2])), ang, res))
    j = 0
    while j < m:
        pr = pieces[j]
        if isinstance(pr, Line):
            k = j
            while k + 1 < m and isinstance(pieces[k + 1], Line) and k not in corners:
                k += 1
            first, last = pieces[j], pieces[k]
            assert isinstance(first, Line) and isinstance(last, Line)
            pts: list[FloatArray] = [first.start + trim_start[j] * first.direction]
            pts += [pieces[q].end for q in range(j, k)]
            pts.append(last.end - trim_end[k] * last.direction)
            P = np.array(pts)
            segs: list[Segment]
            if k > j:
                segs, before, after = blend_polyline_legs(P, tol, name=names[origin[j]])
                out.origin.extend(origin[j + q] for q in before.tolist())  # leg q is piece j + q
                out.after.extend(origin[j + q] for q in after.tolist())
            elif float(np.linalg.norm(P[1] - P[0])) > primitives.MIN_LENGTH_MM:
                segs = [primitives.line(P[0], P[1], name=names[origin[j]])]
                out.origin.append(origin[j])
                out.after.append(origin[j])
            else:
                segs = []
            out.segments.extend(segs)
            j = k
        else:
            t0 = trim_start[j] / pr.radius
            t1 = pr.sweep - trim_end[j] / pr.radius
            if (t1 - t0) * pr.radius > primitives.MIN_LENGTH_MM:
                start = pr.start if trim_start[j] == 0.0 else pr.point(t0)
                end = pr.end if trim_end[j] == 0.0 else pr.point(t1)
                out.segments.append(arc_nurbs(pr, t0, t1, start, end, names[origin[j]]))
                out.origin.append(origin[j])
                out.after.append(origin[j])
        if j in corners:
            out.segments.extend(corners[j].spirals)
            out.origin.extend([origin[j]] * 2)
            out.after.extend([origin[j + 1]] * 2)
        j += 1
