"""Independent checker of a sampled schedule (issue 5, item 1).

Shares no code with ``solvers/`` or with ``geometry/``'s evaluation: it reads
only plain data (NURBS degree, knots, control points, weights; the machine's
limit and drive numbers; the sampled t, feed and positions) and recomputes
everything itself:

- its own NURBS evaluator (de Boor's algorithm on homogeneous points [w P, w]);
- velocity, acceleration and jerk by finite differences of the sampled
  positions, the machine held at rest before the first and after the last
  sample (a k-th difference is a positive-kernel average of the k-th
  derivative, so it never over-reports a smooth motion; ``tests.fdcheck``,
  the tests' own differences);
- control signal u = M a + b v + c + d sign(v) and servo error
  e = Kv v + Ka a + Kj j from those differences (central v, j at each point);
- distance of every sample from the path: nearest point of a dense polyline of
  the curve (refined until its chords are short), then a golden-section search
  of |C(u) - x| over the two neighbouring parameter intervals;
- time strictly increasing at the fixed period from t = 0, no NaN, rest at both
  ends (on the path's end points) and at every corner it finds itself
  (tangent break between segments or at a C0 knot), feed continuous and
  consistent with the distance travelled.

Every limit is checked against ``LIMIT_FACTOR`` x the machine's value.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from tests.fdcheck import REST_PAD, fd_drive, fd_kinematics

FloatArray = NDArray[np.float64]

#: Allowed overshoot of every limit (issue 5: 1.01 x).
LIMIT_FACTOR = 1.01
#: Every sample lies within this distance of the path (mm; issue 5: 1 um).
PATH_TOL_MM = 1e-3
#: First and last sample sit on the path's end points within this (mm).
END_TOL_MM = 1e-6
#: Period jitter allowed in t, relative to Ts: t_k = k Ts to rounding.
PERIOD_TOL = 1e-9
#: Junction angle (degrees) above which the checker demands a stop; the scheduler stops
#: above 0.5 degrees, the margin keeps near-threshold junctions out of the test.
CORNER_CHECK_DEG = 1.0
#: Junctions below this angle (degrees) are smooth for the checker too.
SMOOTH_DEG = 0.25
#: At a stop the nearest sample moves at most this many (acceleration bound x Ts) per second
#: (the stop lies between two samples: speed there <= a Ts, distance <= a Ts^2 / 2).
CORNER_SLACK = 2.0
#: The feed changes between samples by at most this many (acceleration bound x Ts).
FEED_STEP_SLACK = 2.0
#: Feed vs travelled distance: |(f_k + f_k+1) / 2 - |dp| / Ts| within this share of the peak feed
#: plus (acceleration bound x Ts) (trapezoid error Ts^2 f'' / 12 and chord vs arc, at most about
#: 0.2 a Ts, are smaller).
FEED_CONSISTENCY = 1e-2
#: Golden-section iterations of the projection (bracket shrinks by 0.618 per step).
GOLDEN_ITERATIONS = 50
#: The fast first search of every point: golden-section steps (bracket down to ~0.3 %), then Newton
#: steps on the projection with central differences of step NEWTON_H x the bracket.  Its distances are
#: distances to curve points (upper bounds), so a point it finds close enough (SETTLED_MM) is settled
#: and only the others get the full search.
FAST_GOLDEN_ITERATIONS = 12
NEWTON_STEPS = 3
NEWTON_H = 1e-3
#: ... settled by the fast search only this close (a wrong bracket can hold a curve point within
#: PATH_TOL_MM of x that is not its foot, and the worst distance is reported): 1 nm.
SETTLED_MM = 1e-3 * PATH_TOL_MM
#: Curve points per bracket scanned before the last search of a point still off the path.
SCAN_POINTS = 257
#: Nearest dense points whose brackets the full search of a point the fast search left off covers.  Two
#: left 24,880 of bench seed 8542's 75,731 samples (a slow 210 mm path, weights up to ~5: its feet lay
#: in none of the two brackets, 40 um off) to the per-point search of every bracket in reach, 160 s of
#: CPU, over the bench's check budget; eight settle all of them (4.7 s).
NEAREST_BRACKETS = 8
#: Points per chunk of the distance search (bench seed 388: 5.5 M samples ran out of a 4 GB limit).
DISTANCE_CHUNK = 100_000
#: Dense polyline: initial points per knot span, and chord refinement target as a share of the path length.
DENSE_PER_SPAN = 32
DENSE_CHORD_SHARE = 1e-3
DENSE_MAX_ROUNDS = 8
DENSE_MAX_POINTS = 2_000_000
#: Dense chords per segment of the path's mean segment length, at least (``dense_polyline``).
DENSE_PER_SEGMENT = 16
#: Fewest dense chords of a spiral (``dense_polyline``).
SPIRAL_MIN_POINTS = 4


#: A derivative shorter than this share of the control points' size is a cusp: the tangent from points instead.
TANGENT_ZERO = 1e-12


@dataclass(frozen=True)
class Nurbs:
    """Plain NURBS data: degree p, knots (n + p + 1,), control points (n, 3), weights (n,)."""

    degree: int
    knots: FloatArray
    ctrl: FloatArray
    weights: FloatArray

    @property
    def domain(self) -> tuple[float, float]:
        n = self.ctrl.shape[0]
        return float(self.knots[self.degree]), float(self.knots[n])

    def spans(self) -> FloatArray:
        """Distinct knots inside the domain, both ends included."""
        lo, hi = self.domain
        u = np.unique(self.knots)
        return np.asarray(u[(u >= lo) & (u <= hi)], dtype=np.float64)

    def points(self, u: FloatArray) -> FloatArray:
        """C(u), (K, 3), by de Boor's algorithm on homogeneous control points."""
        d = _de_boor(self.degree, self.knots, self._homogeneous(), self.domain, np.asarray(u, dtype=np.float64))
        return np.asarray(d[:, :3] / d[:, 3:4], dtype=np.float64)

    def _homogeneous(self) -> FloatArray:
        return np.column_stack([self.ctrl * self.weights[:, None], self.weights])

    def tangent(self, u: float, left: bool) -> FloatArray:
        """Unit tangent at u from the derivative curve (the spans ending at u if ``left``), not differences of
        points: a segment of a few nm (the rest of a leg between two blends) far from the origin has its points
        at u and u + h equal to the last bits.  Rational: C' w = A' - w' C, A and w the homogeneous curve's
        parts; A' and w' from the hodograph, degree p - 1, control points p (Pw[i+1] - Pw[i]) /
        (U[i+p+1] - U[i+1]) on the knots without their first and last."""
        p, U, Pw = self.degree, self.knots, self._homogeneous()
        den = U[p + 1 : p + Pw.shape[0]] - U[1 : Pw.shape[0]]
        Q = p * np.diff(Pw, axis=0) / np.where(den > 0.0, den, np.inf)[:, None]
        uu = np.array([u], dtype=np.float64)
        A = _de_boor(p, U, Pw, self.domain, uu, left)[0]
        dA = _de_boor(p - 1, U[1:-1], Q, self.domain, uu, left)[0]
        t = dA[:3] - dA[3] * A[:3] / A[3]
        norm = float(np.linalg.norm(t))
        if not norm > TANGENT_ZERO * float(np.max(np.abs(self.ctrl))):  # a cusp or coincident control points
            return self._tangent_by_points(u, left)
        return np.asarray(t / norm, dtype=np.float64)

    def _tangent_by_points(self, u: float, left: bool) -> FloatArray:
        lo, hi = self.domain
        h = 1e-7 * (hi - lo)
        P = self.points(np.array([u - h, u] if left else [u, u + h]))
        t = P[1] - P[0]
        return np.asarray(t / np.linalg.norm(t), dtype=np.float64)

    def c0_knots(self) -> FloatArray:
        """Knots inside the domain where the curve is only C0 (multiplicity >= degree)."""
        lo, hi = self.domain
        vals, counts = np.unique(self.knots, return_counts=True)
        return np.asarray(vals[(vals > lo) & (vals < hi) & (counts >= self.degree)], dtype=np.float64)

    def end_tangent(self, at_end: bool, u_at: float | None = None, left: bool = True) -> FloatArray:
        """Unit tangent (direction of travel) at a domain end or, with ``u_at``, one side of a knot."""
        lo, hi = self.domain
        if u_at is None:
            return self.tangent(hi if at_end else lo, at_end)
        return self.tangent(u_at, left)


def _de_boor(p: int, U: FloatArray, Pw: FloatArray, domain: tuple[float, float], u: FloatArray,
             left: bool = False) -> FloatArray:
    """The B-spline of degree p, knots U, control points Pw (n, dim) at u (K,) clipped to ``domain``, (K, dim),
    by de Boor's algorithm; at a knot, on the span ending there if ``left`` (else the one starting there)."""
    lo, hi = domain
    u = np.clip(u, lo, hi)
    k = np.searchsorted(U, u, side="left" if left else "right") - 1
    first = int(np.searchsorted(U, lo, side="right")) - 1  # first non-empty span
    last = int(np.searchsorted(U, hi, side="left")) - 1  # last non-empty span
    k = np.clip(k, first, last)
    idx = k[:, None] - p + np.arange(p + 1)[None, :]
    d = Pw[idx]  # (K, p+1, dim)
    for r in range(1, p + 1):
        for j in range(p, r - 1, -1):
            i = k - p + j
            den = U[i + p + 1 - r] - U[i]
            alpha = ((u - U[i]) / den)[:, None]
            d[:, j] = (1.0 - alpha) * d[:, j - 1] + alpha * d[:, j]
    return np.asarray(d[:, p], dtype=np.float64)


#: Gauss-Legendre nodes and weights on [0, 1] of the spiral's position integral: the tangent angle is a
#: quadratic in s turning at most a few radians over a blend, where 24 nodes are exact to rounding.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)
_GL_X, _GL_W = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W


@dataclass(frozen=True)
class Spiral:
    """Plain Euler-spiral data (a corner blend's clothoid): start point, the plane's orthonormal e1, e2 (3,),
    tangent angle phi(s) = phi0 + kappa0 s + sharpness s^2 / 2 from e1 towards e2, s in [0, length] mm.

    Evaluated by quadrature of the unit tangent, C(s) = start + int_0^s (cos phi e1 + sin phi e2), not by
    the Fresnel integrals ``geometry.clothoid`` uses."""

    start: FloatArray
    e1: FloatArray
    e2: FloatArray
    phi0: float
    kappa0: float
    sharpness: float
    length: float

    @property
    def domain(self) -> tuple[float, float]:
        return 0.0, self.length

    def spans(self) -> FloatArray:
        return np.array([0.0, self.length])

    def c0_knots(self) -> FloatArray:
        return np.zeros(0)

    def _phi(self, s: FloatArray) -> FloatArray:
        return np.asarray(self.phi0 + s * (self.kappa0 + 0.5 * self.sharpness * s), dtype=np.float64)

    def points(self, u: FloatArray) -> FloatArray:
        s = np.clip(np.asarray(u, dtype=np.float64), 0.0, self.length)
        phi = self._phi(s[:, None] * _GL_X[None, :])  # (K, nodes)
        cx = s * (np.cos(phi) @ _GL_W)
        cy = s * (np.sin(phi) @ _GL_W)
        return np.asarray(self.start + cx[:, None] * self.e1 + cy[:, None] * self.e2, dtype=np.float64)

    def end_tangent(self, at_end: bool, u_at: float | None = None, left: bool = True) -> FloatArray:
        s = (self.length if at_end else 0.0) if u_at is None else u_at
        phi = float(self._phi(np.array([s]))[0])
        return np.asarray(math.cos(phi) * self.e1 + math.sin(phi) * self.e2, dtype=np.float64)


#: A segment of the checked path.
Segment = Nurbs | Spiral


def _angle_deg(a: FloatArray, b: FloatArray) -> float:
    return float(np.degrees(np.arccos(np.clip(float(np.dot(a, b)), -1.0, 1.0))))


def corners(path: Sequence[Segment]) -> list[tuple[FloatArray, float]]:
    """(position, angle in degrees) of every tangent break above SMOOTH_DEG: between segments and at C0 knots."""
    out: list[tuple[FloatArray, float]] = []
    for i, seg in enumerate(path):
        for v in seg.c0_knots():
            ang = _angle_deg(seg.end_tangent(True, float(v), left=True), seg.end_tangent(True, float(v), False))
            if ang > SMOOTH_DEG:
                out.append((seg.points(np.array([v]))[0], ang))
        if i + 1 < len(path):
            nxt = path[i + 1]
            ang = _angle_deg(seg.end_tangent(True), nxt.end_tangent(False))
            if ang > SMOOTH_DEG:
                out.append((nxt.points(np.array([nxt.domain[0]]))[0], ang))
    return out


@dataclass
class Dense:
    """A dense polyline of the path: points (M, 3), their segment index and parameter."""

    pts: FloatArray
    seg: NDArray[np.int64]
    u: FloatArray


def dense_polyline(path: Sequence[Segment]) -> Dense:
    """Sample every segment until no chord is longer than DENSE_CHORD_SHARE x the path length, nor than the mean
    segment length / DENSE_PER_SEGMENT."""
    per_seg: list[FloatArray] = []
    for seg in path:
        br = seg.spans()
        t = np.linspace(0.0, 1.0, DENSE_PER_SPAN + 1)[:-1]
        u = np.concatenate([a + (b - a) * t for a, b in itertools.pairwise(br)] + [br[-1:]])
        per_seg.append(u)
    total = sum(float(np.sum(np.linalg.norm(np.diff(s.points(u), axis=0), axis=1)))
                for s, u in zip(path, per_seg, strict=True))
    # ... and to a share of the mean segment: on a program of hundreds of moves a sample on a long line lay farther
    # from its own line's dense points than from NEAREST_BRACKETS points of a neighbouring move (bench cam seed 5,
    # 383 segments over ~5 m, 5 mm chords), and went to the per-point search
    h = min(DENSE_CHORD_SHARE, 1.0 / (DENSE_PER_SEGMENT * len(path))) * total
    # a spiral (a corner blend's) far shorter than the chords gets fewer points: a program's blends of a few um
    # held 33 points each within a few um, and those clusters took every nearest-point slot of the samples on the
    # long lines next to them, which then went to the per-point search (bench cam seed 5: 195 s of checking)
    for k, seg in enumerate(path):
        if isinstance(seg, Spiral):
            n = int(np.clip(math.ceil(DENSE_PER_SPAN * seg.length / h), SPIRAL_MIN_POINTS, DENSE_PER_SPAN))
            per_seg[k] = np.linspace(0.0, seg.length, n + 1)
    for k, seg in enumerate(path):
        u = per_seg[k]
        for _ in range(DENSE_MAX_ROUNDS):
            chord = np.linalg.norm(np.diff(seg.points(u), axis=0), axis=1)
            long = chord > h
            if not long.any() or u.size > DENSE_MAX_POINTS:
                break
            mids = 0.5 * (u[:-1] + u[1:])[long]
            u = np.sort(np.concatenate([u, mids]))
        per_seg[k] = u
    pts = np.concatenate([s.points(u) for s, u in zip(path, per_seg, strict=True)])
    segi = np.concatenate([np.full(u.size, i, dtype=np.int64) for i, u in enumerate(per_seg)])
    return Dense(pts, segi, np.concatenate(per_seg))


def path_distance(path: Sequence[Segment], x: FloatArray, dense: Dense | None = None,
                  tol_mm: float = PATH_TOL_MM) -> FloatArray:
    """Distance (mm) of each point x (K, 3) from the path (union of the segments).

    Every figure is the distance to a point of the curve, so an upper bound of the true distance: a
    cheap search that already finds a foot within SETTLED_MM settles the point; the others get the
    full search (and then, if still over ``tol_mm``, the search of every bracket in reach)."""
    dense = dense or dense_polyline(path)
    tree = cKDTree(dense.pts)
    d0, j0 = tree.query(x, k=NEAREST_BRACKETS)
    best = np.asarray(d0[:, 0], dtype=np.float64).copy()
    # fast: in the bracket of the nearest dense point, a short golden-section search, then Newton steps
    # on (C(u) - x) . C'(u) = 0; the points it leaves off get the full search in the brackets of the
    # NEAREST_BRACKETS nearest
    for lo in range(0, x.shape[0], DISTANCE_CHUNK):  # in chunks: de Boor holds (3 K, p + 1, 4) arrays
        hi = min(x.shape[0], lo + DISTANCE_CHUNK)
        part = best[lo:hi]  # (a view: updated in place)
        _nearest_brackets(path, dense, x[lo:hi], j0[lo:hi, :1], part, FAST_GOLDEN_ITERATIONS, NEWTON_STEPS)
        off = np.flatnonzero(part > SETTLED_MM)
        if off.size:
            sub = part[off].copy()
            _nearest_brackets(path, dense, x[lo:hi][off], j0[lo:hi][off], sub, GOLDEN_ITERATIONS, 0)
            part[off] = np.minimum(part[off], sub)
    # Points still off: the true foot lies within a chord of some dense point no farther than the
    # nearest dense distance plus the longest chord (near a sharp corner the two nearest dense points
    # can sit on the other branch); search the brackets of all of them.
    M = dense.pts.shape[0]
    chord = float(np.max(np.linalg.norm(np.diff(dense.pts, axis=0), axis=1))) if M > 1 else 0.0
    # A bracket need not be unimodal (bench seed 2527: a tight bend inside one holds two local minima of
    # the distance, and the golden search settled on the one 66 um off), so each is first scanned at
    # SCAN_POINTS and the search runs around the best of them.
    for i in np.flatnonzero(best > tol_mm):
        cand = np.asarray(tree.query_ball_point(x[i], float(d0[i, 0]) + chord), dtype=np.int64)
        for si in np.unique(dense.seg[cand]):
            seg = path[int(si)]
            jj = cand[dense.seg[cand] == si]
            a, b = _scan(seg, *_bracket(dense, si, jj), x[i])
            xm = np.repeat(x[i : i + 1], jj.size, axis=0)
            a, b = _golden(seg, a, b, xm, GOLDEN_ITERATIONS)
            best[i] = min(best[i], float(np.min(_dist(seg, 0.5 * (a + b), xm))))
    return best


def _scan(seg: Segment, a: FloatArray, b: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Brackets [a, b] (m,) narrowed to the two scan steps around the nearest of SCAN_POINTS curve points
    of each (to x (3,))."""
    t = np.linspace(0.0, 1.0, SCAN_POINTS)
    u = a[:, None] + (b - a)[:, None] * t[None, :]
    d = _dist(seg, u.ravel(), np.repeat(x[None, :], u.size, axis=0)).reshape(u.shape)
    k = np.argmin(d, axis=1)
    rows = np.arange(u.shape[0])
    return u[rows, np.maximum(k - 1, 0)], u[rows, np.minimum(k + 1, SCAN_POINTS - 1)]


def _bracket(dense: Dense, si: int, jj: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    """The parameter bracket of segment si around dense points jj: their neighbours on that segment."""
    M = dense.pts.shape[0]
    jl = np.maximum(jj - 1, 0)
    jr = np.minimum(jj + 1, M - 1)
    a = np.where(dense.seg[jl] == si, dense.u[jl], dense.u[jj])
    b = np.where(dense.seg[jr] == si, dense.u[jr], dense.u[jj])
    return a, b


def _golden(seg: Segment, a: FloatArray, b: FloatArray, x: FloatArray, iterations: int,
            ) -> tuple[FloatArray, FloatArray]:
    """Golden-section search of |C(u) - x| over [a, b] (the bracket shrinks by 0.618 per step)."""
    g = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(iterations):
        c = b - g * (b - a)
        e = a + g * (b - a)
        left = _dist(seg, c, x) < _dist(seg, e, x)
        b = np.where(left, e, b)
        a = np.where(left, a, c)
    return a, b


def _nearest_brackets(
    path: Sequence[Segment], dense: Dense, x: FloatArray, j0: NDArray[np.int64], best: FloatArray,
    iterations: int, newton: int,
) -> None:
    """Lower ``best`` (K,) to the distance found in the brackets of the dense points j0 (K, m): golden
    section, then ``newton`` steps u -= f / f' with f = (C - x) . C', f' = |C'|^2 + (C - x) . C''
    (central differences, step NEWTON_H of the bracket), kept inside the bracket."""
    for col in range(j0.shape[1]):
        j = j0[:, col]
        for si in np.unique(dense.seg[j]):
            seg = path[int(si)]
            m = dense.seg[j] == si
            a, b = _bracket(dense, int(si), j[m])
            xm = x[m]
            a, b = _golden(seg, a, b, xm, iterations)
            u = 0.5 * (a + b)
            d = _dist(seg, u, xm)
            hi = seg.domain[1]
            for _ in range(newton):
                h = np.maximum(NEWTON_H * (b - a), 1e-14 * max(1.0, abs(hi)))
                pts = seg.points(np.concatenate([u - h, u, u + h])).reshape(3, -1, 3)
                r = pts[1] - xm
                c1 = (pts[2] - pts[0]) / (2.0 * h[:, None])
                c2 = (pts[2] - 2.0 * pts[1] + pts[0]) / (h * h)[:, None]
                fp = np.sum(c1 * c1, axis=1) + np.sum(r * c2, axis=1)
                step = np.where(fp > 0.0, np.sum(r * c1, axis=1) / np.where(fp > 0.0, fp, 1.0), 0.0)
                u = np.clip(u - step, a, b)
                d = np.minimum(d, _dist(seg, u, xm))
            best[m] = np.minimum(best[m], d)


def _dist(seg: Segment, u: FloatArray, x: FloatArray) -> FloatArray:
    return np.asarray(np.linalg.norm(seg.points(u) - x, axis=1), dtype=np.float64)


@dataclass
class Limits:
    """Machine numbers as plain arrays (3,) per axis; ``drive`` keys M b c d Kv Ka Kj umax emax."""

    vmax: FloatArray
    amax: FloatArray
    jmax: FloatArray
    feed_max: float | None = None
    drive: dict[str, FloatArray] | None = None


@dataclass
class Report:
    utilisation: dict[str, float] = field(default_factory=dict)
    violations: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.violations


#: Points per programmed move whose nearest bounds each sample's distance from the program (``program_distances``).
PROGRAM_PROBES = 33


@dataclass(frozen=True)
class Line:
    """A programmed straight move from a to b (3,), mm."""

    a: FloatArray
    b: FloatArray

    def distance(self, x: FloatArray) -> FloatArray:
        """Exact distance (K,) of points x (K, 3) from the segment."""
        d = self.b - self.a
        t = np.clip((x - self.a) @ d / float(d @ d), 0.0, 1.0)
        return np.asarray(np.linalg.norm(x - self.a - t[:, None] * d, axis=1), dtype=np.float64)


@dataclass(frozen=True)
class Arc:
    """A programmed circular move: centre (3,), orthonormal e1 (towards the start) and e2 (the direction of travel
    at the start), radius, sweep >= 0 rad: C(t) = centre + radius (cos t e1 + sin t e2), t in [0, sweep]."""

    centre: FloatArray
    e1: FloatArray
    e2: FloatArray
    radius: float
    sweep: float

    def point(self, t: float) -> FloatArray:
        return np.asarray(self.centre + self.radius * (math.cos(t) * self.e1 + math.sin(t) * self.e2),
                          dtype=np.float64)

    def distance(self, x: FloatArray) -> FloatArray:
        """Exact distance (K,) of points x (K, 3) from the arc: to the circle where the point's angle in the arc's
        plane lies within the sweep, else to the nearer end."""
        p = x - self.centre
        u, v = p @ self.e1, p @ self.e2
        h2 = np.maximum(np.einsum("ij,ij->i", p, p) - u * u - v * v, 0.0)
        ang = np.mod(np.arctan2(v, u), 2.0 * math.pi)
        on = ang <= self.sweep
        d_circle = np.sqrt(h2 + (np.hypot(u, v) - self.radius) ** 2)
        d_ends = np.minimum(np.linalg.norm(x - self.point(0.0), axis=1),
                            np.linalg.norm(x - self.point(self.sweep), axis=1))
        return np.asarray(np.where(on, d_circle, d_ends), dtype=np.float64)


@dataclass(frozen=True)
class Program:
    """A programmed path of lines and arcs (``moves``) that the scheduled one may leave by up to ``tolerance_mm``
    (corner blends), with each move's programmed feed limit in mm/s (None: none, e.g. a rapid)."""

    moves: Sequence[Line | Arc]
    tolerance_mm: float
    feed: Sequence[float | None]


def program_distances(prog: Program, x: FloatArray) -> FloatArray:
    """Exact distance (K, moves) of each point from each move; inf where a move's bounding sphere is farther from the
    point than the largest distance that matters (an upper bound of the point's nearest distance, from
    PROGRAM_PROBES points on each move, + the tolerance + PATH_TOL_MM), so far moves cost nothing."""
    t = np.linspace(0.0, 1.0, PROGRAM_PROBES)
    probes = np.concatenate([m.a + t[:, None] * (m.b - m.a) if isinstance(m, Line)
                             else np.array([m.point(float(a)) for a in t * m.sweep]) for m in prog.moves])
    reach = float(np.max(cKDTree(probes).query(x)[0])) + prog.tolerance_mm + PATH_TOL_MM
    tree = cKDTree(x)
    out = np.full((x.shape[0], len(prog.moves)), np.inf)
    for i, m in enumerate(prog.moves):
        if isinstance(m, Line):
            c, r = 0.5 * (m.a + m.b), 0.5 * float(np.linalg.norm(m.b - m.a))
        else:
            c, r = m.centre, m.radius
        idx = np.asarray(tree.query_ball_point(c, r + reach), dtype=np.int64)
        if idx.size:
            out[idx, i] = m.distance(x[idx])
    return out


def _limit_checks(checks: list[tuple[str, FloatArray, FloatArray]], rep: Report, bad: list[str]) -> None:
    """Utilisation per axis of each (name, values (K, 3), limits (3,)) into ``rep``; over LIMIT_FACTOR into ``bad``."""
    for name, val, cap in checks:
        for i, ax in enumerate("xyz"):
            util = float(np.max(np.abs(val[:, i])) / cap[i])
            key = f"{name}_{ax}"
            rep.utilisation[key] = util
            if util > LIMIT_FACTOR:
                k = int(np.argmax(np.abs(val[:, i])))
                bad.append(f"{key} at {util:.4f} x limit (padded index {k} of {val.shape[0]})")


def check(
    path: Sequence[Segment], lim: Limits, Ts: float, t: FloatArray, feed: FloatArray, position: FloatArray,
    kinematic: bool, drive: bool, axis_velocity: bool = False, program: Program | None = None, jerk: bool = True,
) -> Report:
    """Check one sampled schedule; ``kinematic``: v, a, j limits (j only with ``jerk``: method lp without its
    jerk stage promises v and a); ``drive``: u, e (and v if ``axis_velocity``: lp+nlp holds the LP's vmax only
    with ``Options.nlp_axis_velocity``; by default speed is limited through u, e).

    With ``program`` (a G-code program whose corners ``path`` blends), also: every sample within the program's
    tolerance (+ PATH_TOL_MM) of the programmed path, and the speed between samples and the reported feed
    under each programmed feed (``_check_program``)."""
    rep = Report()
    bad = rep.violations
    arrays = {"t": t, "feed": feed, "position": position}
    for name, arr in arrays.items():
        if not np.all(np.isfinite(arr)):
            bad.append(f"non-finite values in {name}")
    if bad:
        return rep
    K = t.size
    if K < 2 or position.shape != (K, 3) or feed.shape != (K,):
        bad.append(f"shapes t {t.shape} feed {feed.shape} position {position.shape}")
        return rep
    # time: from 0 at the fixed period, strictly increasing
    if t[0] != 0.0:
        bad.append(f"t[0] = {t[0]}")
    dt = np.diff(t)
    if not np.all(dt > 0):
        bad.append("t not strictly increasing")
    if np.max(np.abs(t - Ts * np.arange(K))) > PERIOD_TOL * Ts:
        bad.append(f"t off the fixed period by {np.max(np.abs(t - Ts * np.arange(K))):.3g} s")
    # rest at the ends, on the path's end points
    start = path[0].points(np.array([path[0].domain[0]]))[0]
    end = path[-1].points(np.array([path[-1].domain[1]]))[0]
    d_start = float(np.linalg.norm(position[0] - start))
    d_end = float(np.linalg.norm(position[-1] - end))
    rep.utilisation["end_offset_mm"] = max(d_start, d_end)
    if d_start > END_TOL_MM or d_end > END_TOL_MM:
        bad.append(f"end points off the path ends by {d_start:.3g}, {d_end:.3g} mm")
    if feed[0] != 0.0 or feed[-1] != 0.0:
        bad.append(f"feed at the ends {feed[0]}, {feed[-1]} (rest expected)")
    if np.any(feed < 0):
        bad.append(f"negative feed {float(np.min(feed))}")
    # kinematics by finite differences
    v, a, j = fd_kinematics(position, Ts)
    checks: list[tuple[str, FloatArray, FloatArray]] = []
    if kinematic:
        checks += [("velocity", v, lim.vmax), ("acceleration", a, lim.amax)]
        if jerk:
            checks.append(("jerk", j, lim.jmax))
    elif drive and axis_velocity:
        checks.append(("velocity", v, lim.vmax))
    if drive:
        if lim.drive is None:
            bad.append("drive check asked for but the machine has no drive model")
            return rep
        checks += zip(("control_signal", "servo_error"), fd_drive(position, Ts, lim.drive, (v, a, j)),
                      (lim.drive["umax"], lim.drive["emax"]), strict=True)
    _limit_checks(checks, rep, bad)
    speed = np.linalg.norm(v, axis=1)
    # the differences are not read again: released before the distance search, the check's peak (cam-bench
    # seed 100, lp+nlp: 10.4 M samples under the bench's 8 GiB)
    del v, a, j, checks
    if lim.feed_max is not None:
        util = max(float(np.max(feed)), float(np.max(speed))) / lim.feed_max
        rep.utilisation["feed"] = util
        if util > LIMIT_FACTOR:
            bad.append(f"feed at {util:.4f} x feed_max")
    # feed: continuous (steps bounded by the machine's acceleration) and consistent with the travel;
    # the bound is the machine's, not the one observed (a corner passed at speed would inflate that):
    # |amax| for lp, and |a| <= (umax + |c| + d + b vmax) / M per axis from the drive model for lp+nlp
    if kinematic or lim.drive is None:
        a_bound = float(np.linalg.norm(lim.amax))
    else:
        dr = lim.drive
        a_bound = float(np.linalg.norm((dr["umax"] + np.abs(dr["c"]) + dr["d"] + dr["b"] * lim.vmax) / dr["M"]))
    f_peak = float(np.max(feed))
    step = float(np.max(np.abs(np.diff(feed))))
    rep.utilisation["feed_step"] = step / (LIMIT_FACTOR * a_bound * Ts) if a_bound > 0 else 0.0
    if step > FEED_STEP_SLACK * LIMIT_FACTOR * a_bound * Ts:
        bad.append(f"feed jumps by {step:.4g} mm/s between samples (acceleration bound {a_bound:.4g} mm/s^2)")
    chord = speed[REST_PAD : REST_PAD + K - 1]
    mean_feed = 0.5 * (feed[:-1] + feed[1:])
    tol = FEED_CONSISTENCY * f_peak + a_bound * Ts
    mismatch = float(np.max(np.abs(mean_feed - chord))) / tol if tol > 0 else math.inf
    rep.utilisation["feed_mismatch"] = mismatch
    if mismatch > 1.0:
        bad.append(f"feed disagrees with the travelled distance by {mismatch:.3g} of the peak feed")
    # every sample on the path
    dense = dense_polyline(path)
    dist = path_distance(path, position, dense)
    worst = float(np.max(dist))
    rep.utilisation["path_deviation"] = worst / PATH_TOL_MM
    if worst > PATH_TOL_MM:
        bad.append(f"sample {int(np.argmax(dist))} is {worst:.3g} mm off the path")
    # rest at every corner: some sample within a Ts^2 of it moving at most a Ts (a: the bound above)
    v_rest = CORNER_SLACK * a_bound * Ts
    r_rest = CORNER_SLACK * a_bound * Ts * Ts
    moving = np.minimum(speed[REST_PAD - 1 : REST_PAD - 1 + K], speed[REST_PAD : REST_PAD + K])
    worst_corner = 0.0
    for pos, ang in corners(path):
        if ang <= CORNER_CHECK_DEG:
            continue
        near = np.linalg.norm(position - pos, axis=1) <= max(r_rest, END_TOL_MM)
        slowest = float(np.min(moving[near])) if near.any() else math.inf
        worst_corner = max(worst_corner, slowest / v_rest if v_rest > 0 else math.inf)
        if not slowest <= v_rest:
            bad.append(f"no stop at the {ang:.2f} degree corner at {pos.tolist()} (slowest nearby {slowest:.3g})")
    rep.utilisation["corner_speed"] = worst_corner
    if program is not None:
        _check_program(rep, program, position, feed, speed[REST_PAD : REST_PAD + K - 1])
    return rep


def _check_program(rep: Report, prog: Program, position: FloatArray, feed: FloatArray, chord: FloatArray) -> None:
    """``check``'s program part (chord: |dp| / Ts (K - 1,)): the distance of every sample to the programmed path
    (exact, to its lines and arcs), and its feeds: each sample's limit is the highest F of the moves within its
    nearest move's distance + the tolerance + PATH_TOL_MM (a sample in a corner blend may take either move's F,
    the scheduler holds the lower; elsewhere its own move's), and the speed between two samples is held to the
    higher of theirs."""
    bad = rep.violations
    tol = prog.tolerance_mm + PATH_TOL_MM
    F_move = np.array([math.inf if f is None else float(f) for f in prog.feed])
    K = position.shape[0]
    dmin, F = np.empty(K), np.empty(K)
    # DISTANCE_CHUNK samples at a time: the distances are (samples, moves), 5 GB for 2 M samples of 300 moves at once
    for lo in range(0, K, DISTANCE_CHUNK):
        D = program_distances(prog, position[lo : lo + DISTANCE_CHUNK])
        dmin[lo : lo + D.shape[0]] = np.min(D, axis=1)
        near = D <= (dmin[lo : lo + D.shape[0]] + tol)[:, None]
        F[lo : lo + D.shape[0]] = np.max(np.where(near, F_move[None, :], -math.inf), axis=1)
    worst = float(np.max(dmin))
    rep.utilisation["program_deviation"] = worst / tol
    if worst > tol:
        bad.append(f"sample {int(np.argmax(dmin))} is {worst:.3g} mm off the programmed path (tolerance {tol:.3g})")
    if not np.isfinite(F_move).any():
        return
    pair = np.maximum(F[:-1], F[1:])
    util = max(float(np.max(chord / pair)), float(np.max(feed / F)))
    rep.utilisation["program_feed"] = util
    if util > LIMIT_FACTOR:
        bad.append(f"feed at {util:.4f} x the programmed feed")
