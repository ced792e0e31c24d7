"""NURBS segments: validation and vectorised evaluation of C(u) and C', C'', C'''.

A NURBS curve of degree p with control points P_i (n x 3, mm), weights
w_i > 0 and non-decreasing knots U (length n + p + 1) is

    C(u) = A(u) / W(u),   A(u) = sum_i N_{i,p}(u) w_i P_i,   W(u) = sum_i N_{i,p}(u) w_i

for u in the domain [U_p, U_{n}].  A and W are one polynomial B-spline with
homogeneous control points [w P, w] (n x 4), evaluated with
``scipy.interpolate.BSpline`` for many u at once.  The u-derivatives of C
follow from the quotient rule (Piegl & Tiller eq. 4.8):

    C'   = (A'   - W' C) / W
    C''  = (A''  - 2 W' C'  - W'' C) / W
    C''' = (A''' - 3 W' C'' - 3 W'' C' - W''' C) / W
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from geometry import native
from geometry.errors import GeometryError

FloatArray = NDArray[np.float64]

#: Highest degree a segment may have (the API's schema says the same).  A G5.2 program's order L = 170 ran the
#: sync budget out in the geometry, and degrees of 80-150 read jerks 98-2 x 10^6 x the limit in the samples (session
#: 58's API probe): evaluation of such a basis is not what a CNC path needs.
MAX_DEGREE = 12
#: ``NurbsSegment.domain_scaled`` leaves a domain whose width is within 2^-20 .. 2^20 as it is.
DOMAIN_SCALE_POW2 = 20

#: A segment whose control points all lie within this distance (mm) of each
#: other is degenerate: it has no length to travel.
DEGENERATE_SPAN_MM = 1e-9
#: An interior knot where |C'| is at most this share of the control polygon's length per unit u
#: is a zero-speed point (repeated control points): the segment is split there.
ZERO_SPEED_SHARE = 1e-9
#: A turn inside a segment is *sharp* where its radius of curvature at the apex is under this (mm)
#: and the tangent turns by more than the corner tolerance between the points SHARP_TURN_CUT_MM
#: either side of the apex: a near-cusp (bench seeds 1731: 159 degrees within ~6 nm; 1951: 176
#: degrees within 2 nm).  Passed at speed it is a kink
#: the samples' differences see (6 x amax on 1731); passed at the feed its radius allows it is a
#: crawl (1,000 s for 4 um on 1951).  It is cut out and made a corner (``cut_sharp_turns``).
SHARP_TURN_RADIUS_MM = 1e-3
#: Chord (mm) cut off each side of a sharp turn's apex, doubled while the radius of curvature at the
#: cut is still under SHARP_TURN_RADIUS_MM, up to SHARP_TURN_CUT_MAX_MM: the path moves by at most that.
SHARP_TURN_CUT_MM = 1e-4
SHARP_TURN_CUT_MAX_MM = 4e-4
#: Samples per knot span in the search for sharp turns.
SHARP_TURN_SAMPLES = 16
#: An interval between those samples whose tangent turns by more than this (rad) is searched for an apex in
#: any case, even where the curvature at its ends could explain the turn.  Bench seed 866: a 176 degree turn
#: of 0.2 um radius inside a knot span of 0.29 mm, whose 16 samples put 166 degrees between two points of
#: radius 20 um: 2 chord x max kappa = 14.6 rad there, over the 2.9 rad turn, so it was not searched, and
#: the LP, verifying limits only at its points, passed the cusp at speed (sampled jerk 24.8 x, a 422).
SHARP_TURN_SEARCH_RAD = math.radians(30.0)
#: Knot spans searched for sharp turns at once (bounds the temporaries of a long segment).
SHARP_TURN_CHUNK = 4096


@dataclass(frozen=True, eq=False)
class NurbsSegment:
    """One validated NURBS segment.

    Attributes:
        degree: polynomial degree p >= 1.
        knots: (n + p + 1,) non-decreasing knot vector.
        control_points: (n, 3) control points in mm (2-D input is padded with z = 0).
        weights: (n,) positive weights.
        name: field path used in error messages, e.g. ``segments[3]``.
    """

    degree: int
    knots: FloatArray
    control_points: FloatArray
    weights: FloatArray
    name: str = "segment"

    @classmethod
    def create(
        cls,
        degree: object,
        knots: object,
        control_points: object,
        weights: object | None = None,
        name: str = "segment",
    ) -> NurbsSegment:
        """Validate raw input and build a segment; raise GeometryError naming the field."""
        p = _check_degree(degree, name)
        P = as_points(control_points, f"{name}.control_points")
        n = P.shape[0]
        if n < p + 1:
            raise GeometryError(
                f"{name}.control_points", n, f"degree {p} needs at least {p + 1} control points"
            )
        if weights is None:
            w = np.ones(n)
        else:
            w = _as_vector(weights, f"{name}.weights")
            if w.shape[0] != n:
                raise GeometryError(
                    f"{name}.weights", w.shape[0], f"need one weight per control point ({n})"
                )
            bad = np.flatnonzero(~(w > 0.0))
            if bad.size:
                raise GeometryError(f"{name}.weights[{bad[0]}]", float(w[bad[0]]), "weights must be > 0")
        U = _as_vector(knots, f"{name}.knots")
        if U.shape[0] != n + p + 1:
            raise GeometryError(
                f"{name}.knots",
                U.shape[0],
                f"need n + p + 1 = {n} + {p} + 1 = {n + p + 1} knots",
            )
        dec = np.flatnonzero(np.diff(U) < 0.0)
        if dec.size:
            i = int(dec[0]) + 1
            raise GeometryError(
                f"{name}.knots[{i}]", float(U[i]), f"knots must be non-decreasing (previous {U[i - 1]})"
            )
        lo, hi = U[p], U[n]
        if not hi > lo:
            raise GeometryError(f"{name}.knots", [float(lo), float(hi)], "parameter domain [U_p, U_n] is empty")
        # A knot repeated more than p + 1 times makes a basis function vanish identically: its
        # control point has no effect, and at the ends the curve no longer starts (ends) at the
        # first (last) control point, e.g. [0, 0, 0, 0, 1, 1, 1] for p = 2.  Rejected.
        vals, first, counts = np.unique(U, return_index=True, return_counts=True)
        over = np.flatnonzero(counts > p + 1)
        if over.size:
            i = int(first[over[0]]) + p + 1
            raise GeometryError(
                f"{name}.knots[{i}]",
                float(vals[over[0]]),
                f"knot {float(vals[over[0]])!r} repeated {int(counts[over[0]])} times; at most degree + 1 = {p + 1} "
                "(more makes a basis function vanish, so the curve would not start or end at its end control points)",
            )
        interior = U[(U > lo) & (U < hi)]
        if interior.size:
            vals, counts = np.unique(interior, return_counts=True)
            worst = int(np.argmax(counts))
            if counts[worst] > p:
                raise GeometryError(
                    f"{name}.knots",
                    float(vals[worst]),
                    f"interior knot multiplicity {int(counts[worst])} exceeds degree {p}",
                )
        span = float(np.max(np.ptp(P, axis=0)))
        if span <= DEGENERATE_SPAN_MM:
            raise GeometryError(
                f"{name}.control_points", span, "degenerate segment: all control points coincide"
            )
        return cls(degree=p, knots=U, control_points=P, weights=w, name=name)

    @cached_property
    def _spl(self) -> BSpline:
        """The homogeneous B-spline [wP, w], built on first evaluation (a dense G-code program holds
        hundreds of thousands of lines that ``Toolpath`` evaluates in closed form and never needs it)."""
        return BSpline(self.knots, self._hom_points, self.degree, extrapolate=False)

    @cached_property
    def _hom_points(self) -> FloatArray:
        """Homogeneous control points [w P, w] (n, 4), C-contiguous."""
        return np.ascontiguousarray(np.column_stack([self.control_points * self.weights[:, None], self.weights]))

    def _taylor(self, lib: ctypes.CDLL) -> native.Taylor:
        """The polynomial form of each knot span for the compiled kernel (``geometry.native``), built on first use."""
        form: native.Taylor | None = self.__dict__.get("_taylor_form")
        if form is None:
            form = native.taylor(lib, self.degree, self.knots, self._hom_points)
            self.__dict__["_taylor_form"] = form  # (a cache on a frozen dataclass, as cached_property keeps one)
        return form

    def _native(self, uu: FloatArray, order: int, exact_points: bool = False) -> FloatArray | None:
        """C and its u-derivatives up to ``order`` at uu (clipped to the domain) by the compiled kernel
        (``geometry.native``), (order + 1, K, 3); None without it."""
        lib = native.library()
        if lib is None:
            return None
        return native.nurbs_derivatives(lib, self._taylor(lib), uu, order, exact_points)

    @property
    def domain(self) -> tuple[float, float]:
        """Parameter domain [U_p, U_n]."""
        return float(self.knots[self.degree]), float(self.knots[-self.degree - 1])

    @property
    def breakpoints(self) -> FloatArray:
        """Distinct knots inside the domain, including both ends."""
        lo, hi = self.domain
        u = np.unique(self.knots)
        return u[(u >= lo) & (u <= hi)]

    def derivatives(self, u: FloatArray, exact_points: bool = False) -> FloatArray:
        """C and its first three u-derivatives.

        Args:
            u: (K,) parameters inside the domain.
            exact_points: C by de Boor's algorithm at u in the compiled kernel too (the numpy path always
                is): rounded to ~eps of the control points, not of the kernel's Taylor terms
                (``geometry.native.nurbs_derivatives``).  For emitted positions, whose differences are read.
        Returns:
            (4, K, 3) array: [C, C', C'', C'''] in mm, mm/u, mm/u^2, mm/u^3.
        """
        lo, hi = self.domain
        uu = np.clip(np.asarray(u, dtype=np.float64), lo, hi)
        fast = self._native(uu, 3, exact_points)
        if fast is not None:
            return fast
        H = [self._hom(uu, order) for order in range(4)]  # each (K, 4)
        A = [h[:, :3] for h in H]
        W = [h[:, 3:4] for h in H]
        C0 = A[0] / W[0]
        C1 = (A[1] - W[1] * C0) / W[0]
        C2 = (A[2] - 2.0 * W[1] * C1 - W[2] * C0) / W[0]
        C3 = (A[3] - 3.0 * W[1] * C2 - 3.0 * W[2] * C1 - W[3] * C0) / W[0]
        return np.stack([C0, C1, C2, C3])

    def speed(self, u: FloatArray) -> FloatArray:
        """|C'(u)| (mm per unit u), shape (K,)."""
        lo, hi = self.domain
        uu = np.clip(np.asarray(u, dtype=np.float64), lo, hi)
        fast = self._native(uu, 1)
        if fast is not None:
            c1 = fast[1]
        else:
            h0 = self._hom(uu, 0)
            h1 = self._hom(uu, 1)
            c0 = h0[:, :3] / h0[:, 3:4]
            c1 = (h1[:, :3] - h1[:, 3:4] * c0) / h0[:, 3:4]
        return np.asarray(np.sqrt(np.einsum("ij,ij->i", c1, c1)), dtype=np.float64)

    def _hom(self, u: FloatArray, order: int) -> FloatArray:
        """Homogeneous [wP, w] B-spline or its derivative at u, (K, 4)."""
        if order > self.degree:
            return np.zeros((u.shape[0], 4))
        return np.asarray(self._spl(u, nu=order), dtype=np.float64)

    def points(self, u: FloatArray) -> FloatArray:
        """C(u) only, (K, 3) mm."""
        lo, hi = self.domain
        uu = np.clip(np.asarray(u, dtype=np.float64), lo, hi)
        fast = self._native(uu, 0)
        if fast is not None:
            return np.asarray(fast[0], dtype=np.float64)
        h = self._hom(uu, 0)
        return np.asarray(h[:, :3] / h[:, 3:4], dtype=np.float64)

    def unit_tangents(self, u: FloatArray) -> FloatArray:
        """C'(u) / |C'(u)|, (K, 3) (NaN where |C'| = 0)."""
        lo, hi = self.domain
        uu = np.clip(np.asarray(u, dtype=np.float64), lo, hi)
        h0 = self._hom(uu, 0)
        h1 = self._hom(uu, 1)
        c1 = h1[:, :3] - h1[:, 3:4] * (h0[:, :3] / h0[:, 3:4])  # (times W > 0: the direction of C')
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(c1 / np.linalg.norm(c1, axis=1)[:, None], dtype=np.float64)

    def sharp_turns(self, tol_rad: float) -> FloatArray:
        """Sharp turns inside the segment (``SHARP_TURN_RADIUS_MM``), as (T, 2) parameter intervals
        [u_a, u_b] to cut out: C(u_a) and C(u_b) are SHARP_TURN_CUT_MM (chord) from the apex, and the
        tangent turns by more than ``tol_rad`` between them.

        Every knot span is sampled at SHARP_TURN_SAMPLES + 1 points.  An interval between samples
        whose tangent turns by more than ``tol_rad`` is searched for an apex if the turn is
        concentrated: more than twice what the curvature kappa at its ends explains (turn > 2 chord
        max kappa: the curvature peaks inside), or an end has a radius under SHARP_TURN_RADIUS_MM
        (the apex is on a sample), or it turns by more than SHARP_TURN_SEARCH_RAD (a peak the end
        curvature hides).  The search keeps the subinterval turning most, eight at a time, down to
        a chord of 1e-3 x SHARP_TURN_CUT_MM: its midpoint is the apex, and a radius
        there of SHARP_TURN_RADIUS_MM or more is not a sharp turn.  Turns whose cut would reach the
        segment's ends are left alone, and so is a turn whose tangents at the cut differ by no
        more than ``tol_rad``."""
        bp = self.breakpoints
        t = np.linspace(0.0, 1.0, SHARP_TURN_SAMPLES + 1)
        out: list[tuple[float, float]] = []
        for a in range(0, bp.size - 1, SHARP_TURN_CHUNK):
            b = min(bp.size - 1, a + SHARP_TURN_CHUNK)
            lo, hi = bp[a:b], bp[a + 1 : b + 1]
            uu = lo[:, None] + (hi - lo)[:, None] * t[None, :]
            D = self.derivatives(uu.ravel()).reshape(4, lo.size, t.size, 3)
            sp = np.linalg.norm(D[1], axis=2)
            with np.errstate(invalid="ignore", divide="ignore"):
                tan = D[1] / sp[..., None]
                kappa = curvature(D[1], D[2])
                turn = turn_angle(tan[:, :-1], tan[:, 1:])
                chord = np.linalg.norm(np.diff(D[0], axis=1), axis=2)
                k_end = np.fmax(kappa[:, :-1], kappa[:, 1:])
                flag = (turn > tol_rad) & ((turn > 2.0 * chord * k_end) | (k_end * SHARP_TURN_RADIUS_MM > 1.0)
                                           | ~np.isfinite(k_end) | (turn > SHARP_TURN_SEARCH_RAD))
            for i, j in zip(*np.nonzero(flag), strict=True):
                cut = self._cut_around(float(uu[i, j]), float(uu[i, j + 1]), tol_rad)
                if cut is not None and (not out or cut[0] > out[-1][1]):
                    out.append(cut)
        return np.asarray(out, dtype=np.float64).reshape(-1, 2)

    def _cut_around(self, ua: float, ub: float, tol_rad: float) -> tuple[float, float] | None:
        """[u_a, u_b] around the apex of the turn inside [ua, ub] (``sharp_turns``), or None."""
        lo, hi = self.domain
        for _ in range(200):
            uu = np.linspace(ua, ub, 9)
            tan = self.unit_tangents(uu)
            k = int(np.argmax(np.nan_to_num(turn_angle(tan[:-1], tan[1:]), nan=np.pi)))
            ua, ub = float(uu[k]), float(uu[k + 1])
            ends = self.points(np.array([ua, ub]))
            if np.linalg.norm(ends[1] - ends[0]) < 1e-3 * SHARP_TURN_CUT_MM or ub - ua <= 4.0 * np.spacing(ub):
                break
        uc = 0.5 * (ua + ub)
        if not self._radius_under(uc, SHARP_TURN_RADIUS_MM):
            return None  # (tight, but a radius the schedule passes: not a near-cusp)
        apex = self.points(np.array([uc]))[0]
        sides: list[float] = []
        for end in (lo, hi):
            # the point SHARP_TURN_CUT_MM (chord) from the apex; farther (doubling, up to SHARP_TURN_CUT_MAX_MM)
            # while the curvature there is still a radius under SHARP_TURN_RADIUS_MM (bench seed 3010: the
            # turn's tail at 0.1 um, a 0.5 um radius with |x_sss| ~ 1e8 /mm^2 at the new rest end, stalled it)
            h = SHARP_TURN_CUT_MM
            while True:
                u = self._chord_point(uc, end, apex, h)
                if u is None:
                    return None  # the cut would reach the segment's end
                if h >= SHARP_TURN_CUT_MAX_MM or not self._radius_under(u, SHARP_TURN_RADIUS_MM):
                    break
                h *= 2.0
            sides.append(u)
        u_a, u_b = sides
        if not (lo < u_a < uc < u_b < hi):
            return None
        tan = self.unit_tangents(np.array([u_a, u_b]))
        if not float(turn_angle(tan[:1], tan[1:])[0]) > tol_rad:
            return None
        return u_a, u_b

    def _chord_point(self, uc: float, end: float, apex: FloatArray, h: float) -> float | None:
        """The parameter between uc and ``end`` whose point is h (chord) from ``apex`` (bisection), or None if
        even ``end`` is within h."""
        if np.linalg.norm(self.points(np.array([end]))[0] - apex) <= h:
            return None
        near, far = uc, end
        for _ in range(200):
            mid = 0.5 * (near + far)
            if mid in (near, far):
                break
            if np.linalg.norm(self.points(np.array([mid]))[0] - apex) < h:
                near = mid
            else:
                far = mid
        return far

    def _radius_under(self, u: float, r: float) -> bool:
        """Whether the radius of curvature at u is under r (mm)."""
        D = self.derivatives(np.array([u]))
        return not float(curvature(D[1], D[2])[0]) * r <= 1.0

    def cut_sharp_turns(self, tol_rad: float) -> tuple[list[NurbsSegment], FloatArray]:
        """The segment with its sharp turns (``sharp_turns``) cut out: the parts between them, each
        cut [u_a, u_b] closed by moving the two end control points that meet there to their midpoint
        (as ``geometry.toolpath.close_gaps``; the rational basis is in [0, 1], so no point moves by
        more than half the gap, itself at most 2 SHARP_TURN_CUT_MM).  The Toolpath sees the tangent
        break left at each as a corner.  Returns (parts, (T, 2) the cuts)."""
        cuts = self.sharp_turns(tol_rad)
        if cuts.size == 0:
            return [self], cuts
        p = self.degree
        seg = self
        for v in np.unique(cuts):
            seg = seg.insert_knot(float(v), p - int(np.sum(seg.knots == v)))
        starts = set(cuts[:, 0].tolist())
        parts = [part for part in seg._split_c0(keep_degenerate=True) if part.domain[0] not in starts]
        for k in range(len(parts) - 1):
            parts[k], parts[k + 1] = meet_at_midpoint(parts[k], parts[k + 1])
        return parts, cuts

    def zero_speed_knots(self) -> FloatArray:
        """Interior knots (multiplicity < p) where |C'(u)| vanishes, (Z,).

        p equal consecutive control points P_i = ... = P_{i+p-1} make p - 1
        consecutive control points of C' zero, so C' = 0 at the knot between
        them: the curve stops there and its tangent may reverse (a cusp)."""
        lo, hi = self.domain
        vals, counts = np.unique(self.knots, return_counts=True)
        cand = vals[(vals > lo) & (vals < hi) & (counts < self.degree)]
        if cand.size == 0:
            return cand
        polygon = float(np.sum(np.linalg.norm(np.diff(self.control_points, axis=0), axis=1)))
        return np.asarray(cand[self.speed(cand) <= ZERO_SPEED_SHARE * polygon / (hi - lo)], dtype=np.float64)

    def insert_knot(self, u: float, times: int = 1) -> NurbsSegment:
        """The same curve with knot u inserted ``times`` times (Boehm; Piegl & Tiller A5.1).

        With U_k <= u < U_k+1, each insertion replaces the homogeneous control points
        Pw_i, k-p+1 <= i <= k, by alpha_i Pw_i + (1 - alpha_i) Pw_i-1 with
        alpha_i = (u - U_i) / (U_i+p - U_i) (alpha = 0 where U_i = u)."""
        p = self.degree
        U = self.knots
        Pw = np.column_stack([self.control_points * self.weights[:, None], self.weights])
        for _ in range(times):
            k = int(np.searchsorted(U, u, side="right")) - 1
            n = Pw.shape[0]
            Q = np.empty((n + 1, 4))
            Q[: k - p + 1] = Pw[: k - p + 1]
            Q[k + 1 :] = Pw[k:]
            i = np.arange(k - p + 1, k + 1)
            alpha = ((u - U[i]) / (U[i + p] - U[i]))[:, None]
            Q[i] = alpha * Pw[i] + (1.0 - alpha) * Pw[i - 1]
            U = np.insert(U, k + 1, u)
            Pw = Q
        return NurbsSegment(degree=p, knots=U, control_points=Pw[:, :3] / Pw[:, 3:4], weights=Pw[:, 3].copy(),
                            name=self.name)

    def domain_scaled(self) -> NurbsSegment:
        """The same curve with every knot times 2^m, its domain's width brought into [2^-DOMAIN_SCALE_POW2,
        2^DOMAIN_SCALE_POW2] where it is outside (else itself).  A B-spline is unchanged by scaling its knots, and
        a power of two scales them exactly; but its u-derivatives scale by 2^-m: on knots spanning 1e-120 the
        second derivatives overflowed, and the router's quarter arc came back with NaN accelerations (session 58's
        API probe); on 1e-154 or 1e200 its length was 0."""
        width = float(self.knots[-self.degree - 1] - self.knots[self.degree])
        m = -math.frexp(width)[1] if width > 0.0 and math.isfinite(width) else 0
        if abs(m) <= DOMAIN_SCALE_POW2:
            return self
        return replace(self, knots=np.ldexp(self.knots, m))

    def rebased(self) -> NurbsSegment:
        """The same curve on knots U - U_p, so its domain starts at u = 0.

        A point C(u(s)) is as fine as u is: u is rounded to ulp(u), which moves the point along the
        curve by up to ulp(u) |C'(u)|.  On a domain far from 0 against its width that is coarse:
        bench seed 5029's last segment runs over u in [-2.2745, -2.2493] (6.0 mm; |C'| = 5.1e3 mm at
        its end, ulp(u) = 4.4e-16), so its samples moved in steps of 1.85e-12 mm, and the third
        difference of x over 1 ms read 2.67 x a jmax of 2.1e-3 mm/s^3 (a machine 1e5 x slower than
        the router; samples 48 nm apart).  On [0, 0.0252] the steps are ~2e-14 mm (0.026 x).  B-splines are
        unchanged by shifting every knot by the same amount; the shift rounds each knot by at most
        half its ulp (exact where U_i and U_p are within a factor 2, Sterbenz)."""
        origin = self.knots[self.degree]
        if origin == 0.0:
            return self
        return replace(self, knots=self.knots - origin)

    def split_at_c0_knots(self) -> list[NurbsSegment]:
        """Split at interior knots of multiplicity p (where the curve is only C0), and at
        zero-speed knots (``zero_speed_knots``: first raised to multiplicity p), where the
        tangent may reverse: the Toolpath then sees the cusp as a corner.

        With multiplicity p at knot value k (first index j in U) the curve passes
        through P_{j-1}; the left piece keeps U[:j+p] + [k] and P[:j], the right
        piece [k] + U[j:] and P[j-1:].
        """
        seg = self
        for v in self.zero_speed_knots():
            seg = seg.insert_knot(float(v), self.degree - int(np.sum(seg.knots == v)))
        return seg._split_c0()

    def _split_c0(self, keep_degenerate: bool = False) -> list[NurbsSegment]:
        p = self.degree
        lo, hi = self.domain
        U = self.knots
        vals, first, counts = np.unique(U, return_index=True, return_counts=True)
        cuts = [int(j) for v, j, c in zip(vals, first, counts, strict=True) if lo < v < hi and c == p]
        if not cuts:
            return [self]
        pieces: list[NurbsSegment] = []
        seg = self
        offset = 0
        for j_abs in cuts:
            j = j_abs - offset
            k = seg.knots[j]
            left = NurbsSegment(
                degree=p,
                knots=np.concatenate([seg.knots[: j + p], [k]]),
                control_points=seg.control_points[:j],
                weights=seg.weights[:j],
                name=self.name,
            )
            right = NurbsSegment(
                degree=p,
                knots=np.concatenate([[k], seg.knots[j:]]),
                control_points=seg.control_points[j - 1 :],
                weights=seg.weights[j - 1 :],
                name=self.name,
            )
            pieces.append(left)
            offset += j - 1
            seg = right
        pieces.append(seg)
        if keep_degenerate:
            return pieces
        return [s for s in pieces if float(np.max(np.ptp(s.control_points, axis=0))) > DEGENERATE_SPAN_MM]


def meet_at_midpoint(a: NurbsSegment, b: NurbsSegment) -> tuple[NurbsSegment, NurbsSegment]:
    """``a`` and ``b`` with a's last and b's first control point moved to their midpoint (copies).

    For curves clamped there (their end points), the two then meet; a NURBS's rational basis
    functions are in [0, 1], so no point of either curve moves by more than half the gap."""
    mid = 0.5 * (a.control_points[-1] + b.control_points[0])
    Pa, Pb = a.control_points.copy(), b.control_points.copy()
    Pa[-1] = mid
    Pb[0] = mid
    return replace(a, control_points=Pa), replace(b, control_points=Pb)


def curvature(d1: FloatArray, d2: FloatArray) -> FloatArray:
    """|C' x C''| / |C'|^3 (1/mm) from u-derivatives along the last axis (inf or NaN where C' = 0)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.linalg.norm(np.cross(d1, d2), axis=-1) / np.linalg.norm(d1, axis=-1) ** 3
    return np.asarray(k, dtype=np.float64)


def turn_angle(a: FloatArray, b: FloatArray) -> FloatArray:
    """Angle (rad) between unit vectors along the last axis, 2 arcsin(|a - b| / 2) (accurate near 0
    and pi; NaN stays NaN)."""
    d = np.linalg.norm(a - b, axis=-1)
    return np.asarray(2.0 * np.arcsin(np.clip(0.5 * d, 0.0, 1.0)), dtype=np.float64)


def _check_degree(degree: object, name: str) -> int:
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)):
        if isinstance(degree, float) and degree.is_integer():
            degree = int(degree)
        else:
            raise GeometryError(f"{name}.degree", degree, "degree must be an integer")
    p = int(degree)
    if p < 1:
        raise GeometryError(f"{name}.degree", p, "degree must be >= 1")
    if p > MAX_DEGREE:
        raise GeometryError(f"{name}.degree", p, f"degree must be <= {MAX_DEGREE}")
    return p


def _as_vector(values: object, fld: str) -> FloatArray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(fld, values, "must be a list of numbers") from exc
    if a.ndim != 1:
        raise GeometryError(fld, a.shape, "must be a flat list of numbers")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise GeometryError(f"{fld}[{bad[0]}]", float(a[bad[0]]), "must be finite (no NaN/Inf)")
    return a


def as_points(values: object, fld: str) -> FloatArray:
    """(m, 3) float64 points (mm) from a list of [x, y] or [x, y, z]; GeometryError naming the bad entry."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryError(fld, values, "must be a list of [x, y, z] points") from exc
    if a.ndim != 2 or a.shape[1] not in (2, 3) or a.shape[0] == 0:
        raise GeometryError(fld, a.shape, "must be a non-empty list of [x, y] or [x, y, z] points")
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        i, k = (int(v) for v in bad[0])
        raise GeometryError(f"{fld}[{i}][{k}]", float(a[i, k]), "must be finite (no NaN/Inf)")
    if a.shape[1] == 2:
        a = np.column_stack([a, np.zeros(a.shape[0])])
    return np.ascontiguousarray(a)
