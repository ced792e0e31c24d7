r"""Time-domain reconstruction (spec §7): t(s) = integral ds / sqrt(q(s)), inverted at t_k = k Ts.

Near a rest point q(s) ~ q'(0) s, so 1/sqrt(q) is singular but integrable.
The piece [0, L] (n_int knot intervals of length d) is mapped to a coordinate
x in [0, n_int] that removes the singularity:

    x in [0, 1]:            s = d x^2                 (rest at s = 0)
    x in [1, n_int - 1]:    s = d x
    x in [n_int - 1, n_int]: s = L - d (n_int - x)^2  (rest at s = L)

and h(x) = s'(x) / sqrt(q(s(x))) is smooth and finite on every interval
(h(0) = 2 sqrt(d / q'(0))); it jumps at x = 1 and n_int - 1, where s'(x) does
(2 d on the rest side, d on the other), and the table takes each side's value
there.  t(x) = integral h dx is tabulated to 1e-13 by adaptive Gauss-Legendre
(``geometry.quadrature``) and inverted at the sample times by a Hermite guess
(within TIME_GUESS_TOL_S) plus a Newton step, so s(t_k) is accurate to ~1e-12
relative and the sampled feed does not fluctuate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from geometry.quadrature import MonotoneTable, TableTooLarge
from solvers import bspline, kinematics, native
from solvers.errors import ScheduleError

FloatArray = NDArray[np.float64]

#: A feed with q below this share of its peak q inside a piece (feed under 1e-6 of its peak)
#: counts as stalled.
STALL_Q_SHARE = 1e-12
#: ... but the time table (``PieceTiming.build``) takes a profile whose only such dips are well
#: conditioned where they are (each interval's lowest q over STALL_Q_SHARE of its own control points:
#: no near-singularity for the quadrature) and over this share of the peak (bench seed 2966: 330 m/s
#: down to 0.15 mm/s at a 0.1 mm radius curvature jump, q 2e-13 of its peak, 1024 intervals).
STALL_Q_SHARE_CONDITIONED = 1e-18
#: Hermite guess tolerance for the time table, seconds.  One Newton step then leaves an error of order this
#: squared times |h'/h^2|, which is not small where h is small and steep: in the rest intervals 1e-6 s left
#: s(t) 1.2e-11 mm (flower v+a) and 8.8e-11 mm (with jerk) from quadrature, and the 18.35 m path's samples
#: moved by 7.7e-10 mm from 1e-6 to 1e-8; at 1e-8 they are within ~1e-15 mm there (``tests/solvers/test_timing``),
#: for ~15 % more time-table work than 1e-6 (a second Newton step cost ~45 % on the 18.35 m path).
TIME_GUESS_TOL_S = 1e-8


@dataclass(frozen=True, eq=False)
class PieceProfile:
    """Feed profile over one rest-to-rest piece: the LP's q, optionally refined by the NLP's f.

    Knot interval k is [k d, (k+1) d].  Where ``f_mask[k]`` the feed is
    sdot = f(s) (control points ``p``), elsewhere sdot = sqrt(q(s)) (control
    points ``c``).  The two agree in value and slope at every knot where they
    meet (the NLP fixes p there from q), so feed and tangential acceleration
    are continuous.  The first and last intervals (rest) are always q, plus
    ``rest_g`` times the rest interval's bump and ``rest_h`` times its rise (``bspline.rest_bump``: the
    NLP's extra shapes there, ``solvers.nlp.REST_BUMP`` and ``REST_RISE``; 0 for the LP's).

    Attributes:
        s_start: global arc length of the piece start, mm.
        length: piece length L, mm.
        d: knot spacing, mm.
        c: (n_int + 2,) control points of q, mm^2/s^2.
        p: (n_int + 2,) control points of f, mm/s, or None (LP only).
        f_mask: (n_int,) bool, intervals that use f, or None.
        rest_g: the bumps' amplitudes (first, last rest interval), mm^2/s^2.
        rest_h: the rises' amplitudes (first, last rest interval), one per power of the first ones of
            ``bspline.LP_REST_RISE_POWERS`` (``bspline.rest_bump``; or none), mm^2/s^2.
    """

    s_start: float
    length: float
    d: float
    c: FloatArray
    p: FloatArray | None = None
    f_mask: NDArray[np.bool_] | None = None
    rest_g: tuple[float, float] = (0.0, 0.0)
    rest_h: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())

    def rest_slopes(self) -> tuple[float, float]:
        """q' at the start (> 0 if the feed leaves rest) and at the end (< 0 if it reaches rest), mm/s^2."""
        c, d = self.c, self.d
        return (float(c[1] - c[0] + self.rest_g[0]) / d, float(c[-1] - c[-2] - self.rest_g[1]) / d)

    @property
    def n_int(self) -> int:
        return int(self.c.size - 2)

    def feed(self, s: FloatArray) -> kinematics.FeedDerivs:
        """(sdot, sddot, sdddot) at piece-local s, each (K,)."""
        s = np.asarray(s, dtype=np.float64)
        q3 = bspline.evaluate(self.c, s, self.d)
        if any(self.rest_g) or any(any(h) for h in self.rest_h):
            q3 = self._bumped(s, q3)
        out = kinematics.from_q(*q3)
        if self.p is None or self.f_mask is None:
            return out
        k = np.clip(np.floor(s / self.d), 0, self.n_int - 1).astype(np.int64)
        use = self.f_mask[k]
        if not use.any():
            return out
        fd = kinematics.from_f(*bspline.evaluate(self.p, s[use], self.d))
        for o, v in zip(out, fd, strict=True):
            o[use] = v
        return out

    def _bumped(
        self, s: FloatArray, q3: tuple[FloatArray, FloatArray, FloatArray]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """q, q', q'' with the rest intervals' bumps and rises (``rest_g``, ``rest_h``) added (copies)."""
        out = (q3[0].copy(), q3[1].copy(), q3[2].copy())
        bspline.add_rest_bump(out, s, self.d, 0, True, self.rest_g[0], self.rest_h[0])
        bspline.add_rest_bump(out, s, self.d, self.n_int - 1, False, self.rest_g[1], self.rest_h[1])
        return out

    def s_of_x(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Piece-local s(x) and ds/dx."""
        n, d = self.n_int, self.d
        x = np.clip(x, 0.0, float(n))
        s = np.where(x < 1.0, d * x * x, np.where(x > n - 1.0, self.length - d * (n - x) ** 2, d * x))
        ds = np.where(x < 1.0, 2 * d * x, np.where(x > n - 1.0, 2 * d * (n - x), d))
        return s, ds

    def h(self, x: FloatArray) -> FloatArray:
        """dt/dx, seconds per unit x (``h_local`` with x0 = 0)."""
        return self.h_local(0, x)

    def _end_slopes(self) -> tuple[float, float, float, float]:
        """|q'| at the rest end and q'' of the first knot interval, then of the last (``h_local``'s closed form)."""
        c, d = self.c, self.d
        return ((c[1] - c[0]) / d, (c[0] - 2 * c[1] + c[2]) / d**2, -(c[-1] - c[-2]) / d,
                (c[-3] - 2 * c[-2] + c[-1]) / d**2)

    def h_local(self, x0: int, xl: FloatArray) -> FloatArray:
        """dt/dx at x = x0 + xl, seconds per unit x; x0 a whole number of knot intervals.

        Inside the piece (1 <= x <= n_int - 1) h = d / sdot, with sdot evaluated on knot interval
        k = x0 + floor(xl) at t = xl - floor(xl): from the segment-local xl, not from s = d x.  At a global
        x of ~59,000 (a 273 m piece at 4.63 mm knots) the round trip s = d x, s / d moved t by ~1e-11, a
        relative noise of ~1e-10 in h on steep intervals, which the time quadrature (1e-13) bisected into
        2,000 nodes per knot interval (a segment of 8192 intervals: 0.88 M nodes, +100 MB).

        In the end intervals q = sigma (|q'_rest| + q''_end sigma / 2) with sigma
        the distance from the rest point = d w^2, so h = 2 sqrt(d) /
        sqrt(|q'_rest| + q''_end d w^2 / 2): no cancellation, no singularity (the bump and rises
        g b + sum_k h_k e_k add (g (1 - w^2)^2 + sum_k h_k w^2 (1 - w^2)^k) / d under the root:
        ``bspline.rest_bump`` with tau = w^2).
        """
        c, d, n = self.c, self.d, self.n_int
        xl = np.clip(np.asarray(xl, dtype=np.float64), -float(x0), float(n - x0))
        lib = native.library() if self.p is None or self.f_mask is None else None
        (g0, gL), (h0, hL) = self.rest_g, self.rest_h
        if lib is not None:  # the same numbers, compiled (``solvers.native``)
            if g0 or gL or any(h0) or any(hL):  # (bumps or rises: their closed form below)
                out = native.h_local(lib, n, d, c, x0, xl, None)
            else:
                return native.h_local(lib, n, d, c, x0, xl, self._end_slopes())
        else:
            k = np.clip(np.floor(xl).astype(np.int64) + x0, 0, n - 1)
            t = xl - (k - x0)  # (exact: small whole numbers)
            sdot = np.sqrt(np.maximum(bspline.value(c[k], c[k + 1], c[k + 2], t), 0.0))
            if self.p is not None and self.f_mask is not None:
                use = self.f_mask[k]
                if use.any():
                    p, ku = self.p, k[use]
                    sdot[use] = bspline.value(p[ku], p[ku + 1], p[ku + 2], t[use])
            with np.errstate(divide="ignore", invalid="ignore"):
                out = np.array(d / sdot, dtype=np.float64)
        x = xl + x0
        # the end intervals' closed form on their own points only (a long piece's table asks for ~10^5 points
        # a call, of which a handful are in the end intervals: 1.5 s of the 18.35 m path's sampling stage
        # went to the rises' powers over every point); most calls have none (two reductions, not two masks)
        if not x.size or (float(np.min(x)) >= 1.0 and float(np.max(x)) <= n - 1.0):
            return np.asarray(out, dtype=np.float64)
        q1_0, q2_0, q1_L, q2_L = self._end_slopes()
        for on, w, q1, q2, g, h in (
            (x < 1.0, x, q1_0, q2_0, g0, h0),
            ((x > n - 1.0) & (x >= 1.0), (n - x0) - xl, q1_L, q2_L, gL, hL),
        ):
            if not on.any():
                continue
            w_on = w[on]
            r = q1 + 0.5 * q2 * d * w_on * w_on
            if g or any(h):
                r = r + bspline.rest_bump_quotient(w_on * w_on, g, h) / d
            with np.errstate(divide="ignore", invalid="ignore"):
                out[on] = 2.0 * np.sqrt(d) / np.sqrt(r)
        return np.asarray(out, dtype=np.float64)


#: Where h jumps (``_segment_table``), h is read this share of the piece's knot intervals (at least 1) inside each
#: side: 2^-40 n stays ~2^12 units in the last place of x clear of the jump, and moves the guess's slope there
#: by ~1e-12 relative.
JUMP_EPS_SHARE = 2.0**-40


#: Knot intervals per time-table segment.  A piece with more intervals has its table built segment by
#: segment: the build keeps each segment's duration only, and ``s_at`` builds the table of a segment when its
#: times are asked for, holding one segment's table at a time.  So a corner-free piece of any length holds
#: a bounded table (~4 nodes, ~100 B, per knot interval: ~0.8 MB per segment) and bounded transients while
#: one is built, at the price of building the segments again to sample them.  A piece of at most this many
#: intervals keeps its one table (no second build).
TABLE_SEGMENT_INTERVALS = 8192


@dataclass(frozen=True, eq=False)
class PieceTiming:
    r"""t(x) over a piece, tabulated by segments of whole knot intervals.

    Segment j covers x in [edges[j], edges[j+1]] (TABLE_SEGMENT_INTERVALS knot intervals, the last one
    shorter) and starts at time t_edges[j] = sum of the durations before it: t(x) = t_edges[j] + its
    table's F(x - edges[j]) (tables in segment-local x: ``PieceProfile.h_local``).  One segment: one
    table, built once and kept.  More: ``held`` keeps the table last used (integral-only tables from the
    build are not kept), the others are rebuilt on demand.

    Attributes:
        profile: the feed profile.
        edges: (n_seg + 1,) segment edges in x (knot intervals), floats.
        t_edges: (n_seg + 1,) piece-local time at the edges, s; t_edges[-1] is the duration.
        invertible: whether ``s_at`` may be called (``build(inverse=True)``).
        held: segment index -> its table refined for the inverse (at most one entry with several
            segments).
    """

    profile: PieceProfile
    edges: FloatArray
    t_edges: FloatArray
    invertible: bool
    held: dict[int, MonotoneTable]

    @property
    def duration(self) -> float:
        return float(self.t_edges[-1])

    @classmethod
    def build(cls, profile: PieceProfile, inverse: bool = True) -> PieceTiming:
        """The time table of ``profile``; without ``inverse`` it holds the integral only (``duration``: the
        same value), not refined for ``s_at`` (which then raises)."""
        n = profile.n_int
        q1_0, q1_L = profile.rest_slopes()
        if not (q1_0 > 0 and q1_L < 0):
            raise ScheduleError(
                "feed profile cannot leave or reach a rest point (zero acceleration at rest): the path turns "
                "too sharply next to it for the knots, even after refining them",
                field="toolpath",
                value={"s_start": profile.s_start, "dq_start": q1_0, "dq_end": q1_L},
            )
        stalls = stalled_intervals(profile, conditioned=True)
        if stalls.size:
            raise ScheduleError(
                "feed stalls inside the path (q reaches 0, or under 1e-12 of its peak): the path turns too "
                "sharply for the knot spacing (a cusp, or a knot span far shorter than the knot spacing)",
                field="toolpath",
                value={"s_start": profile.s_start, "s": float(profile.s_start + (stalls[0] + 0.5) * profile.d)},
            )
        seg = TABLE_SEGMENT_INTERVALS
        edges = np.append(np.arange(0, n, seg, dtype=np.float64), float(n))
        one = edges.size == 2
        totals = np.empty(edges.size - 1)
        held: dict[int, MonotoneTable] = {}
        for j in range(edges.size - 1):
            # several segments: integral only now (each is built again, for the inverse, when sampled)
            table = _segment_table(profile, edges[j], edges[j + 1], inverse and one)
            if not np.all(np.isfinite(table.F_b)):
                raise ScheduleError("feed stalls inside the path (q reaches 0)", value=profile.s_start)
            totals[j] = table.total
            if one and inverse:
                held[0] = table
        return cls(profile, edges, np.concatenate([[0.0], np.cumsum(totals)]), inverse, held)

    def _segment(self, j: int) -> MonotoneTable:
        """Segment j's table refined for the inverse: the one held, or built (replacing it)."""
        table = self.held.get(j)
        if table is None:
            table = _segment_table(self.profile, self.edges[j], self.edges[j + 1], True)
            self.held.clear()
            self.held[j] = table
        return table

    def s_at(self, t_local: FloatArray) -> FloatArray:
        """Piece-local s at piece-local times (clamped to [0, duration]), each (K,).  Sorted times visit each
        segment once (the samples' order); unsorted ones may rebuild a segment's table more than once."""
        if not self.invertible:
            raise ValueError("this time table was built for its duration only (PieceTiming.build(inverse=False))")
        t_local = np.asarray(t_local, dtype=np.float64)
        n_seg = self.edges.size - 1
        j = np.clip(np.searchsorted(self.t_edges, t_local, side="right") - 1, 0, n_seg - 1)
        x = np.empty(t_local.shape)
        # (consecutive runs of one segment: sorted times build each table once)
        cuts = np.flatnonzero(np.diff(j)) + 1
        for lo, hi in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [j.size]]), strict=True):
            if lo == hi:
                continue
            k = int(j[lo])
            x[lo:hi] = self.edges[k] + self._segment(k).inverse(t_local[lo:hi] - self.t_edges[k])
        return self.profile.s_of_x(x)[0]


def _segment_table(profile: PieceProfile, x0: float, x1: float, inverse: bool) -> MonotoneTable:
    """t(x) - t(x0) over knot intervals x0 .. x1 of ``profile`` (each split in two, then bisected to 1e-13), in
    the segment-local x - x0 (``PieceProfile.h_local``)."""
    k0 = int(x0)
    edges = np.arange(0.0, x1 - x0 + 0.5, dtype=np.float64)
    # h jumps where the x map changes scale, at the rest intervals' inner knots (ds/dx = 2 d on the rest side,
    # d on the other): the table's guesses take h from each interval's own side there (``MonotoneTable``)
    n = profile.n_int
    jumps = np.array([1.0, n - 1.0]) - k0
    try:
        return MonotoneTable.build(partial(profile.h_local, k0), edges, min_intervals=2, abs_tol=1e-16,
                                   guess_tol=TIME_GUESS_TOL_S if inverse else np.inf, jumps=jumps,
                                   jump_eps=JUMP_EPS_SHARE * max(1.0, float(n)))
    except TableTooLarge as exc:  # (round-off: a motion so long that TIME_GUESS_TOL_S is under its time's ulp)
        raise ScheduleError(
            f"the time table of the piece does not converge within {exc.budget} intervals (a motion too long, or a "
            "feed too uneven, for float64 time to resolve)", field="toolpath",
            value={"s_start": profile.s_start, "knot_intervals": [x0, x1]}) from exc


def stuck(profile: PieceProfile) -> bool:
    """True if the feed cannot leave or reach a rest end (q' = 0 there) or stalls inside the piece."""
    q1_0, q1_L = profile.rest_slopes()
    return not (q1_0 > 0 and q1_L < 0) or stalled_intervals(profile).size > 0


def stalled_intervals(profile: PieceProfile, conditioned: bool = False) -> NDArray[np.int64]:
    """Knot intervals (not the two rest intervals) where the feed reaches 0, or drops below
    sqrt(STALL_Q_SHARE) of its peak: there the time integral of 1 / sdot diverges, or the
    quadrature bisects for minutes towards the near-singularity.  Each interval's quadratic
    (of q, or of f where ``f_mask``) is minimised exactly over [0, 1]."""
    n = profile.n_int
    if n < 3:
        return np.zeros(0, dtype=np.int64)
    k = np.arange(1, n - 1)
    lo = _interval_min(profile.c, k)
    peak = float(np.max(profile.c))
    if profile.p is not None and profile.f_mask is not None:
        use_f = profile.f_mask[k]
        f_lo = _interval_min(profile.p, k)
        lo = np.where(use_f, f_lo * np.abs(f_lo), lo)  # compare f^2 with q
        # the peak of the feed in use: f's control points of intervals that use f (the NLP's p elsewhere is
        # not the feed; counting it flagged an LP interval at 2.9e-11 of a smaller q peak: bench seed 1951)
        used = np.flatnonzero(profile.f_mask)
        if used.size:
            peak = max(peak, float(np.max(profile.p[np.concatenate([used, used + 1, used + 2])])) ** 2)
    if conditioned:  # the time table's test: dips well conditioned locally, and over a far smaller share
        c = profile.c
        local = np.maximum(np.maximum(c[k], c[k + 1]), c[k + 2])
        if profile.p is not None and profile.f_mask is not None:
            pk = np.maximum(np.maximum(profile.p[k], profile.p[k + 1]), profile.p[k + 2])
            local = np.where(profile.f_mask[k], pk * np.abs(pk), local)
        ok = (lo > STALL_Q_SHARE * local) & (lo > STALL_Q_SHARE_CONDITIONED * peak)
        return np.asarray(k[~ok], dtype=np.int64)
    return np.asarray(k[~(lo > STALL_Q_SHARE * peak)], dtype=np.int64)


def _interval_min(c: FloatArray, k: NDArray[np.int64]) -> FloatArray:
    """Minimum over t in [0, 1] of the uniform quadratic B-spline on interval k (control points c_k..c_k+2)."""
    c0, c1, c2 = c[k], c[k + 1], c[k + 2]
    a2 = c0 - 2.0 * c1 + c2
    a1 = c1 - c0
    q0 = 0.5 * (c0 + c1)
    q1 = q0 + a1 + 0.5 * a2
    with np.errstate(divide="ignore", invalid="ignore"):
        tv = np.where(a2 > 0, -a1 / np.where(a2 > 0, a2, 1.0), 0.0)
    tv = np.clip(tv, 0.0, 1.0)
    qv = q0 + tv * (a1 + 0.5 * a2 * tv)
    return np.asarray(np.minimum(np.minimum(q0, q1), qv), dtype=np.float64)



def interval_times(profile: PieceProfile, k: NDArray[np.int64]) -> FloatArray:
    """Time to cross each of the knot intervals k (inside the piece: 1 <= k <= n_int - 2), s, with the feed
    in use there (f where ``f_mask``, else q); inf where the feed reaches 0.

    On f's intervals the integral of d / f is exact (``_inverse_quadratic_integral``): a dip between the
    NLP's checkpoints is a peak of 1 / f far narrower than any fixed quadrature's node spacing.  On q's, the
    integral of d / sqrt(q) is exact too (``_inverse_sqrt_quadratic_integral``)."""
    k = np.asarray(k, dtype=np.int64)
    d, c, p = profile.d, profile.c, profile.p
    out = np.empty(k.size)
    use_f = np.zeros(k.size, dtype=bool) if p is None or profile.f_mask is None else profile.f_mask[k]
    if p is not None and use_f.any():
        kf = k[use_f]
        out[use_f] = d * _inverse_quadratic_integral(p[kf], p[kf + 1], p[kf + 2])
    kq = k[~use_f]
    if kq.size:
        out[~use_f] = d * _inverse_sqrt_quadratic_integral(c[kq], c[kq + 1], c[kq + 2])
    return out


def rest_interval_times(profile: PieceProfile) -> tuple[float, float]:
    r"""Time to cross the first and the last knot interval (from and to rest), s.

    On the first, c_0 = -c_1 and q(t) = 2 c_1 t + (c_2 - 3 c_1) t^2 / 2 (t in [0, 1]); with t = w^2 the
    time d * integral dt / sqrt(q) is 2 d * integral_0^1 dw / sqrt(A + B w^2), A = 2 c_1, B = (c_2 - 3 c_1) / 2:
    2 d asinh(sqrt(B / A)) / sqrt(B) if B > 0, 2 d asin(sqrt(-B / A)) / sqrt(-B) if B < 0 (A + B = q(1) > 0),
    2 d / sqrt(A) if B = 0; the last interval mirrored.  With a bump or rise (``PieceProfile.rest_g``,
    ``rest_h``: g b + sum_k h_k e_k added to q) the root is of A + B w^2 + g (1 - w^2)^2
    + sum_k h_k w^2 (1 - w^2)^k, smooth in w: REST_TIME_NODES-point Gauss-Legendre.
    inf if the feed does not leave (reach) rest."""
    d = profile.d
    out = []
    for A, B, g, h in _rest_ends(profile):
        if g or any(h):
            w, x = _REST_TIME_GL
            r = A + B * x * x + bspline.rest_bump_quotient(x * x, g, h)
            ok = A + g > 0.0 and A + B > 0.0 and bool(np.all(r > 0.0))
            out.append(2.0 * d * float(np.sum(w / np.sqrt(r))) if ok else math.inf)
            continue
        if not (A > 0.0 and A + B > 0.0):
            out.append(math.inf)
            continue
        z = B / A
        if abs(z) < 1e-8:
            val = 1.0 - z / 6.0
        elif z > 0.0:
            val = math.asinh(math.sqrt(z)) / math.sqrt(z)
        else:
            val = math.asin(math.sqrt(-z)) / math.sqrt(-z)
        out.append(2.0 * d * val / math.sqrt(A))
    return out[0], out[1]


def _rest_ends(profile: PieceProfile) -> list[tuple[float, float, float, tuple[float, ...]]]:
    """(A, B, g, h) of the first and the last knot interval: q = r (A + B r + ``bspline.rest_bump_quotient``(r, g, h))
    at the unit distance r from rest, A = 2 c_1 and B = (c_2 - 3 c_1) / 2 (c_1 next to rest; the last interval
    mirrored), g and h its bump's and rises' amplitudes (``rest_interval_times``, ``rest_dips``)."""
    c = profile.c
    return [(2.0 * float(c1), 0.5 * (float(c2) - 3.0 * float(c1)), g, h)
            for c1, c2, g, h in ((c[1], c[2], profile.rest_g[0], profile.rest_h[0]),
                                 (c[-2], c[-3], profile.rest_g[1], profile.rest_h[1]))]


def rest_dips(profile: PieceProfile) -> bool:
    """Whether q dips to (nearly) 0 inside, or at the rest end of, one of the two rest intervals that have a bump
    or rises.  There q = r (A + B r + ``bspline.rest_bump_quotient``(r)) at the unit distance r from rest (A, B as
    in ``rest_interval_times``), and the factor after r is checked at REST_DIP_POINTS points of r in [0, 1]:
    a dip is a value at most REST_DIP_SHARE of its largest.  At r = 0 the factor is d q'(rest): an LP whose
    row q' >= 0 at rest binds leaves it at a rounding residue (bench seed 894, 1.7e-15 against 31 at r = 1),
    which passes ``stuck`` but leaves the time table bisecting towards the near-singularity for minutes."""
    r = np.linspace(0.0, 1.0, REST_DIP_POINTS)
    for A, B, g, h in _rest_ends(profile):
        if not (g or any(h)):
            continue
        f = A + B * r + bspline.rest_bump_quotient(r, g, h)
        if not float(np.min(f)) > REST_DIP_SHARE * float(np.max(f)):
            return True
    return False


#: Points of ``rest_dips``, and the share of its largest value at which the factor counts as a dip.
REST_DIP_POINTS = 4097
REST_DIP_SHARE = 1e-6


#: Gauss-Legendre nodes for a rest interval's time with a bump (``rest_interval_times``).
REST_TIME_NODES = 48
_GL_X, _GL_W = np.polynomial.legendre.leggauss(REST_TIME_NODES)
#: (weights, nodes) on [0, 1]
_REST_TIME_GL = (0.5 * _GL_W, 0.5 * (_GL_X + 1.0))


def _inverse_quadratic_integral(p0: FloatArray, p1: FloatArray, p2: FloatArray) -> FloatArray:
    """Integral over t in [0, 1] of 1 / f(t), f = A t^2 + B t + C the quadratic B-spline with control points
    p0, p1, p2 (elementwise); inf where f reaches 0 on [0, 1].

    With X = 2 C + B and D = 4 A C - B^2:  (2 / sqrt(D)) atan2(sqrt(D), X) if D > 0 (no real root), and
    (2 / R) atanh(R / X), R = sqrt(-D), if D < 0 (real roots, both off [0, 1] iff X > R: X^2 + D =
    4 f(0) f(1)); both tend to 2 / X as D -> 0.  Where f has its minimum inside (A > 0, vertex t_v in
    (0, 1)) D is taken as 4 A f(t_v), accurate however deep the dip (4 A C - B^2 cancels there)."""
    C = 0.5 * (p0 + p1)
    B = p1 - p0
    A = 0.5 * (p0 - 2.0 * p1 + p2)
    X = 2.0 * C + B
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        tv = np.where(A > 0.0, -B / np.where(A > 0.0, 2.0 * A, 1.0), -1.0)
        inside = (tv > 0.0) & (tv < 1.0)
        D = np.where(inside, 4.0 * A * (C + tv * (B + A * tv)), 4.0 * A * C - B * B)
        root = np.sqrt(np.abs(D))
        z = np.where(root > 0.0, root / np.where(X != 0.0, np.abs(X), 1.0), 0.0)
        pos = 2.0 * np.arctan2(root, X) / np.where(root > 0.0, root, 1.0)
        # atanh(z) / z -> 1 as z -> 0 (z small: 1 + z^2 / 3 to double precision)
        ratio = np.where(z > 1e-4, np.arctanh(np.minimum(z, 1.0)) / np.where(z > 0.0, z, 1.0), 1.0 + z * z / 3.0)
        neg = 2.0 * ratio / X
        out = np.where(D > 0.0, pos, np.where(root > 0.0, neg, 2.0 / X))
        ok = (C > 0.0) & (A + B + C > 0.0) & ((D > 0.0) | (X > root))
    return np.asarray(np.where(ok, out, np.inf), dtype=np.float64)


def _inverse_sqrt_quadratic_integral(c0: FloatArray, c1: FloatArray, c2: FloatArray) -> FloatArray:
    """Integral over t in [0, 1] of 1 / sqrt(q(t)), q = A t^2 + B t + C the quadratic B-spline with control
    points c0, c1, c2 (elementwise); inf where q reaches 0 on [0, 1].  With q0 = q(0), q1 = q(1) and the
    vertex t_v = -B / (2 A):

    - A > 0, t_v in (0, 1), m = q(t_v) > 0: (asinh(w (1 - t_v)) + asinh(w t_v)) / sqrt(A), w = sqrt(A / m);
    - A > 0, t_v <= 0 (B >= 0): log1p((S1 - S0) / S0) / sqrt(A), S = 2 sqrt(A q) + 2 A t + B, with
      S1 - S0 = 2 sqrt(A) (A + B) / (sqrt(q0) + sqrt(q1)) + 2 A; t_v >= 1: the same on q(1 - t);
    - A < 0: atan2(sqrt(-A) ((1 - t_v) sqrt(q0) + t_v sqrt(q1)), sqrt(q0 q1) + A t_v (1 - t_v)) / sqrt(-A)
      (t = t_v + r sin(theta)), with t_v (A + B) for t_v (q1 - q0);
    - A = 0: 2 / (sqrt(q0) + sqrt(q1)).

    Each form is free of cancellation in its range and they meet as A -> 0."""
    C = 0.5 * (c0 + c1)
    B = c1 - c0
    A = 0.5 * (c0 - 2.0 * c1 + c2)
    q0 = C
    q1 = A + B + C
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r0 = np.sqrt(np.maximum(q0, 0.0))
        r1 = np.sqrt(np.maximum(q1, 0.0))
        nz = np.where(A != 0.0, A, 1.0)
        tv = -B / (2.0 * nz)
        ra = np.sqrt(np.abs(A))
        ra_nz = np.where(ra > 0.0, ra, 1.0)
        # A > 0, vertex inside
        inside = (A > 0.0) & (tv > 0.0) & (tv < 1.0)
        m = C + tv * (B + A * tv)
        w = np.sqrt(np.where(inside & (m > 0.0), A / np.where(m > 0.0, m, 1.0), 0.0))
        t_in = np.where(m > 0.0, (np.arcsinh(w * (1.0 - tv)) + np.arcsinh(w * tv)) / ra_nz, np.inf)
        # A > 0, monotone: from the low end (t_v <= 0), or mirrored (t_v >= 1: q(1 - t) has B' = -(2 A + B))
        left = B >= 0.0
        Bm = np.where(left, B, -(2.0 * A + B))
        s_lo = np.where(left, r0, r1)  # sqrt(q) at the low end
        s0 = 2.0 * ra * s_lo + Bm
        dS = 2.0 * ra * (A + Bm) / (r0 + r1) + 2.0 * A
        t_mono = np.log1p(dS / s0) / ra_nz
        # A < 0
        num = ra * (r0 + tv * (A + B) / (r0 + r1))
        den = r0 * r1 + A * tv * (1.0 - tv)
        t_cc = np.arctan2(num, den) / ra_nz
        t_lin = 2.0 / (r0 + r1)
        out = np.where(A > 0.0, np.where(inside, t_in, t_mono), np.where(A < 0.0, t_cc, t_lin))
        ok = (q0 > 0.0) & (q1 > 0.0) & np.isfinite(out)
    return np.asarray(np.where(ok, out, np.inf), dtype=np.float64)
