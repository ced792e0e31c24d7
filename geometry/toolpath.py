"""A toolpath: a chain of segments, its corners, and arc-length evaluation.

Arc-length (geometric) derivatives at arbitrary s, with g = C'.C':

    u_s   = g^(-1/2)
    u_ss  = -(C'.C'') u_s^4
    u_sss = 4 (C'.C'')^2 u_s^7 - (C''.C'' + C'.C''') u_s^5

    C_s   = C' u_s
    C_ss  = C'' u_s^2 + C' u_ss
    C_sss = C''' u_s^3 + 3 C'' u_s u_ss + C' u_sss

Checks: |C_s| = 1, C_s . C_ss = 0, |C_ss| = curvature (1/mm).

Corners: where the unit tangent turns by more than ``corner_tol_deg`` between
consecutive segments (or at a C0 knot inside one) the feed must come to rest.
The path is split there into *pieces*, each scheduled rest to rest.

Closed forms for dense paths. Straight lines (degree-1 NURBS with two control points
and equal weights, u linear in s) and clothoids (u = s) are measured and evaluated in
closed form for all of them at once, from columns of their parameters: a G-code
program of 150,000 short moves has about 450,000 such sub-segments after corner
blending, and a Python loop over them (one arc-length table each, one evaluation
call each) dominated both building the toolpath and scheduling it. Every other
segment keeps its adaptive arc-length table (``ArcLengthTable``); ``subs`` builds
the tables of closed-form sub-segments only when asked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Final, overload

import numpy as np
from numpy.typing import NDArray
from scipy.special import fresnel

from geometry import native
from geometry.arcblend import Unblended
from geometry.arclength import ArcLengthTable
from geometry.clothoid import ClothoidSegment
from geometry.errors import GeometryError
from geometry.nurbs import ZERO_SPEED_SHARE, NurbsSegment, meet_at_midpoint
from geometry.segment import Segment

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Largest gap (mm) allowed between the end of a segment and the start of the next.
GAP_TOL_MM = 1e-3
#: Default tangent break (degrees) above which a junction is a corner.
CORNER_TOL_DEG = 0.5
#: Shortest segment (mm) accepted; below it the segment has no length to travel.
MIN_SEGMENT_LENGTH_MM = 1e-9
#: Largest coordinate (mm) of a control point: a G-code X1e200 (or G91 steps summing past 1e307) reached the knot
#: plan as an infinite length, a 500 (session 58's probe).  The API's schema holds JSON points to 1e6 mm.
MAX_COORD_MM = 1e9
#: The lowest programmed feed limit (mm/s; an F word of 6e-11 mm/min): far under it the stopping distance that
#: sizes the knots underflows (session 59's probe: F0.000...1 with 310 zeros read a zero one, a 500).  As
#: ``solvers.machine.LIMIT_MIN``.
MIN_FEED_MM_S = 1e-12
#: Gaps between consecutive segments above this (and within the gap tolerance) are closed by moving
#: the NURBS end control points that meet there (``close_gaps``); smaller ones are rounding.
GAP_CLOSE_MIN_MM = 1e-9
#: Turns below the corner tolerance are reported (``Toolpath.passed_turns``) from this angle on.
PASSED_TURN_MIN_DEG = 1e-3
#: Where |C'| vanishes (repeated control points) derivatives are taken this far
#: inside (fraction of the parameter domain): the arc-length derivatives have a
#: limit there but the u-derivative formulas divide by |C'|.
ZERO_SPEED_NUDGE = 1e-7

#: Kinds of sub-segment: evaluated by the segment itself through its arc-length table, or in
#: closed form from the columns of ``_Closed`` (straight line, clothoid).
#: Junctions whose end derivatives are evaluated at once (bounds the temporaries of a dense path).
JUNCTION_CHUNK: Final = 65_536
GENERIC: Final = 0
LINE: Final = 1
CLOTHOID: Final = 2


@dataclass(frozen=True)
class PassedTurns:
    """Junctions turning by less than the corner tolerance (passed at speed), in order of s.

    Attributes:
        s: (n,) arc length of each, mm.
        angle_deg: (n,) the turn.
        jump: (n, 3) |jump of the unit tangent x_s| per axis (the velocity steps by feed x jump there).
    """

    s: FloatArray
    angle_deg: FloatArray
    jump: FloatArray


def _clamped(seg: NurbsSegment) -> tuple[bool, bool]:
    """Whether the curve starts / ends at its first / last control point (knot of multiplicity p + 1)."""
    U, p = seg.knots, seg.degree
    return bool(U[0] == U[p]), bool(U[-1] == U[-1 - p])


def close_gaps(segments: Sequence[Segment], gap_tol: float) -> tuple[list[Segment], list[tuple[int, float]]]:
    """``segments`` with the gaps of GAP_CLOSE_MIN_MM .. gap_tol mm between consecutive ones closed.

    A gap the schedule passed through would be a position step between two samples (a 0.5 um gap
    made the sampled jerk 12 x jmax).  Where segment i ends at a and segment i + 1 starts at b, the
    end control points meeting there move to their midpoint, each by |b - a| / 2.  A NURBS's rational
    basis functions are in [0, 1], so no point of either curve moves by more than that: the path
    stays within gap_tol / 2 of the input.  Gaps where a side is not a NURBS clamped at that end
    are left as they are.
    Returns (segments, [(i + 1, gap mm) for each gap closed])."""
    out = list(segments)
    starts = np.full((len(out), 3), np.nan)
    ends = np.full((len(out), 3), np.nan)
    for i, seg in enumerate(out):
        if isinstance(seg, NurbsSegment):
            cs, ce = _clamped(seg)
            if cs:
                starts[i] = seg.control_points[0]
            if ce:
                ends[i] = seg.control_points[-1]
    gap = np.linalg.norm(starts[1:] - ends[:-1], axis=1)  # NaN where a side is not a clamped NURBS
    closed: list[tuple[int, float]] = []
    for k in np.flatnonzero((gap > GAP_CLOSE_MIN_MM) & (gap <= gap_tol)).tolist():
        a, b = out[k], out[k + 1]
        if not (isinstance(a, NurbsSegment) and isinstance(b, NurbsSegment)):  # (a finite gap has both)
            continue
        a, b = meet_at_midpoint(a, b)
        out[k], out[k + 1] = a, b
        ends[k] = starts[k + 1] = a.control_points[-1]
        closed.append((k + 1, float(gap[k])))
    return out, closed


def segment_kind(seg: Segment) -> int:
    """LINE for a degree-1 NURBS with two control points and equal weights (u is then linear in
    arc length), CLOTHOID for a ``ClothoidSegment`` (u = arc length), GENERIC otherwise."""
    if isinstance(seg, ClothoidSegment):
        return CLOTHOID
    if (isinstance(seg, NurbsSegment) and seg.degree == 1 and seg.control_points.shape[0] == 2
            and seg.weights[0] == seg.weights[1]):
        return LINE
    return GENERIC


class _Closed:
    """Columns of the closed-form sub-segments (rows of other kinds hold zeros).

    Line k: C(s) = start_k + s e1_k (e1 the unit direction), u = u0_k + s du_k.
    Clothoid k (``geometry.clothoid``): start, e1, e2, phi0, kappa0, sharpness c; with
    a = sqrt(pi / |c|), b = kappa0 / c, sigma = sign(c), Fresnel S0, C0 at b / a and
    amp = a exp(i (phi0 - kappa0^2 / (2 c))):
        C(s) = start + Re(w) e1 + Im(w) e2,  w = amp ((Cf(t) - C0) + i sigma (Sf(t) - S0)),  t = (s + b) / a
    (the same operations as ``ClothoidSegment.points``).
    """

    def __init__(self, subs: Sequence[Segment], kind: IntArray) -> None:
        S = len(subs)
        self.kind = kind
        self.start = np.zeros((S, 3))
        self.e1 = np.zeros((S, 3))
        self.e2 = np.zeros((S, 3))
        self.end = np.zeros((S, 3))
        self.length = np.zeros(S)
        self.u0 = np.zeros(S)
        self.du = np.zeros(S)
        lines = np.flatnonzero(kind == LINE)
        if lines.size:
            segs = [subs[i] for i in lines.tolist()]
            P = np.array([s.control_points for s in segs if isinstance(s, NurbsSegment)])
            U = np.array([s.domain for s in segs])
            chord = P[:, 1] - P[:, 0]
            L = np.linalg.norm(chord, axis=1)
            self.start[lines] = P[:, 0]
            self.end[lines] = P[:, 1]
            self.e1[lines] = chord / np.where(L > 0.0, L, 1.0)[:, None]
            self.length[lines] = L
            self.u0[lines] = U[:, 0]
            self.du[lines] = (U[:, 1] - U[:, 0]) / np.where(L > 0.0, L, 1.0)
        self.phi0 = np.zeros(S)
        self.kappa0 = np.zeros(S)
        self.sharp = np.zeros(S)
        self.a = np.ones(S)
        self.b = np.zeros(S)
        self.sigma = np.ones(S)
        self.S0 = np.zeros(S)
        self.C0 = np.zeros(S)
        self.amp = np.zeros(S, dtype=np.complex128)
        cl = np.flatnonzero(kind == CLOTHOID)
        if cl.size:
            cs = [c for c in (subs[i] for i in cl.tolist()) if isinstance(c, ClothoidSegment)]
            self.start[cl] = np.array([c.start for c in cs])
            self.e1[cl] = np.array([c.e1 for c in cs])
            self.e2[cl] = np.array([c.e2 for c in cs])
            par = np.array([(c.phi0, c.kappa0, c.sharpness, c.length) for c in cs])
            phi0, k0, c, L = par.T
            self.phi0[cl], self.kappa0[cl], self.sharp[cl], self.length[cl] = phi0, k0, c, L
            self.du[cl] = 1.0
            a = np.sqrt(np.pi / np.abs(c))
            b = k0 / c
            self.a[cl], self.b[cl] = a, b
            self.sigma[cl] = np.where(c > 0, 1.0, -1.0)
            self.S0[cl], self.C0[cl] = fresnel(b / a)
            self.amp[cl] = a * np.exp(1j * (phi0 - k0 * k0 / (2.0 * c)))
            self.end[cl] = self._clothoid_points(cl, L)

    def _clothoid_points(self, k: IntArray, x: FloatArray) -> FloatArray:
        S1, C1 = fresnel((x + self.b[k]) / self.a[k])
        w = self.amp[k] * ((C1 - self.C0[k]) + 1j * self.sigma[k] * (S1 - self.S0[k]))
        return np.asarray(self.start[k] + np.real(w)[:, None] * self.e1[k] + np.imag(w)[:, None] * self.e2[k],
                          dtype=np.float64)

    def _clothoid_frame(self, k: IntArray, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Unit tangent T, normal N (K, 3) and curvature kappa (K,) of clothoids k at s = x."""
        phi = self.phi0[k] + self.kappa0[k] * x + 0.5 * self.sharp[k] * x * x
        cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
        T = cos * self.e1[k] + sin * self.e2[k]
        N = -sin * self.e1[k] + cos * self.e2[k]
        return T, N, self.kappa0[k] + self.sharp[k] * x

    def clip(self, k: IntArray, x: FloatArray) -> FloatArray:
        return np.asarray(np.minimum(np.maximum(x, 0.0), self.length[k]), dtype=np.float64)

    def points(self, k: IntArray, x: FloatArray) -> FloatArray:
        """C at local arc length x (clipped to the sub-segment) of closed-form sub-segments k, (K, 3)."""
        x = self.clip(k, x)
        out = self.start[k] + x[:, None] * self.e1[k]
        cl = self.kind[k] == CLOTHOID
        if cl.any():
            out[cl] = self._clothoid_points(k[cl], x[cl])
        return np.asarray(out, dtype=np.float64)

    def derivatives(self, k: IntArray, x: FloatArray) -> FloatArray:
        """(4, K, 3): C and its first three derivatives in u = s (lines: u - u0 = s / du, the same
        direction; ``arc_length_derivatives`` normalises either way)."""
        x = self.clip(k, x)
        D = np.zeros((4, x.size, 3))
        D[0] = self.start[k] + x[:, None] * self.e1[k]
        D[1] = self.e1[k]
        cl = np.flatnonzero(self.kind[k] == CLOTHOID)
        if cl.size:
            kc, xc = k[cl], x[cl]
            T, N, kap = self._clothoid_frame(kc, xc)
            D[0, cl] = self._clothoid_points(kc, xc)
            D[1, cl] = T
            D[2, cl] = kap[:, None] * N
            D[3, cl] = self.sharp[kc][:, None] * N - (kap * kap)[:, None] * T
        return D

    def end_tangents(self, k: IntArray) -> tuple[FloatArray, FloatArray]:
        """Unit tangents (K, 3) at the start and at the end of closed-form sub-segments k."""
        t0 = self.e1[k].copy()
        t1 = self.e1[k].copy()
        cl = np.flatnonzero(self.kind[k] == CLOTHOID)
        if cl.size:
            t0[cl] = self._clothoid_frame(k[cl], np.zeros(cl.size))[0]
            t1[cl] = self._clothoid_frame(k[cl], self.length[k[cl]])[0]
        return t0, t1


class SubTables(Sequence[ArcLengthTable]):
    """``Toolpath.subs``: the arc-length table of every sub-segment, built on first access for
    closed-form sub-segments (lines, clothoids), which ``Toolpath`` measures without one."""

    def __init__(self, segments: list[Segment], tables: dict[int, ArcLengthTable]) -> None:
        self._segments = segments
        self._tables = tables

    def __len__(self) -> int:
        return len(self._segments)

    @overload
    def __getitem__(self, i: int) -> ArcLengthTable: ...

    @overload
    def __getitem__(self, i: slice) -> list[ArcLengthTable]: ...

    def __getitem__(self, i: int | slice) -> ArcLengthTable | list[ArcLengthTable]:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        j = range(len(self))[i]
        t = self._tables.get(j)
        if t is None:
            t = self._tables[j] = ArcLengthTable.build(self._segments[j])
        return t

    def __iter__(self) -> Iterator[ArcLengthTable]:
        return (self[j] for j in range(len(self)))


@dataclass(frozen=True)
class PathSamples:
    """Geometry at arc lengths s.

    Attributes:
        s: (K,) arc length from the path start, mm.
        position: (K, 3) C(s), mm.
        d1: (K, 3) C_s, unit tangent (dimensionless).
        d2: (K, 3) C_ss, 1/mm.
        d3: (K, 3) C_sss, 1/mm^2.
        feed_limit: (K,) programmed feed limit of the segment at each point, mm/s
            (inf where the segment has none), or None when no segment has one.
    """

    s: FloatArray
    position: FloatArray
    d1: FloatArray
    d2: FloatArray
    d3: FloatArray
    feed_limit: FloatArray | None = None

    def subset(self, mask: NDArray[np.bool_] | NDArray[np.intp]) -> PathSamples:
        """The points selected by ``mask`` (a boolean mask or indices)."""
        fl = None if self.feed_limit is None else self.feed_limit[mask]
        return PathSamples(self.s[mask], self.position[mask], self.d1[mask], self.d2[mask], self.d3[mask], fl)

    def concat(self, other: PathSamples) -> PathSamples:
        """These points, then ``other``'s (feed limits only if both have them)."""
        fl = None
        if self.feed_limit is not None and other.feed_limit is not None:
            fl = np.concatenate([self.feed_limit, other.feed_limit])
        return PathSamples(
            np.concatenate([self.s, other.s]), np.concatenate([self.position, other.position]),
            np.concatenate([self.d1, other.d1]), np.concatenate([self.d2, other.d2]),
            np.concatenate([self.d3, other.d3]), fl,
        )


@dataclass(frozen=True)
class Corner:
    """A tangent break where the schedule comes to rest."""

    s: float
    angle_deg: float
    segment: int  # index (in the input chain) of the segment that starts here
    position: tuple[float, float, float]


@dataclass(frozen=True)
class Piece:
    """A stretch between two rest points: path start, corners, path end."""

    index: int
    s_start: float
    s_end: float
    first_sub: int
    last_sub: int  # inclusive
    #: the highest programmed feed limit (mm/s, an F word) on the piece; inf where one of its sub-segments has none
    feed: float = math.inf

    @property
    def length(self) -> float:
        return self.s_end - self.s_start


def arc_length_derivatives(D: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Map u-derivatives (4, K, 3) to arc-length derivatives C_s, C_ss, C_sss (K, 3 each)."""
    lib = native.library()
    if lib is not None:
        return native.arc_length_derivatives(lib, D)
    C1, C2, C3 = D[1], D[2], D[3]
    g = np.einsum("ij,ij->i", C1, C1)
    g12 = np.einsum("ij,ij->i", C1, C2)
    g22 = np.einsum("ij,ij->i", C2, C2)
    g13 = np.einsum("ij,ij->i", C1, C3)
    # u_s = g^-1/2, u_ss = -g12 u_s^4, u_sss = 4 g12^2 u_s^7 - (g22 + g13) u_s^5 (products, not powers:
    # numpy's float ** 4, ** 7 call pow: this function took 1.8x as long, 37 vs 20 ms on 1.6e5 points)
    us = 1.0 / np.sqrt(g)
    us2 = us * us
    us4 = us2 * us2
    uss = -g12 * us4
    usss = (4.0 * g12 * g12 * us2 - (g22 + g13)) * (us4 * us)
    d1 = C1 * us[:, None]
    d2 = C2 * us2[:, None] + C1 * uss[:, None]
    d3 = C3 * (us2 * us)[:, None] + C2 * (3.0 * us * uss)[:, None] + C1 * usss[:, None]
    return d1, d2, d3


class Toolpath:
    """Validated chain of segments with arc-length evaluation.

    Attributes:
        segments: the input segments in order, as given but for gaps within ``gap_tol`` closed (``close_gaps``).
        closed_gaps: (index of the segment after the gap, gap in mm) for every gap closed.
        subs: sub-segments after splitting at C0 knots, with their arc-length tables (``SubTables``); NURBS ones
            on knots rebased to start at u = 0 (``NurbsSegment.rebased``).
        sub_kind: (S,) GENERIC, LINE or CLOTHOID per sub-segment (how it is evaluated).
        sub_origin: (S,) index of the input segment each sub-segment came from.
        offsets: (S + 1,) cumulative arc length at each sub-segment start, mm.
        knot_s: arc lengths (sorted, unique) of the knots inside sub-segments and of the junctions between them.
        junction_jumps: (S - 1, 2) the jumps of C_ss and of C_sss (Euclidean norm, 1/mm and 1/mm^2)
            across each junction between sub-segments (corners included).
        corners: rest points inside the path, in order of s.
        sharp_turns: the corners made where a turn inside a segment was cut out
            (``NurbsSegment.cut_sharp_turns``: sharper than a micrometre radius).
        passed_turns: junctions turning by PASSED_TURN_MIN_DEG up to the corner tolerance (``PassedTurns``).
        unblended: corners that a corner blend left as they were, with the reason (``Unblended``).
        pieces: rest-to-rest stretches.
    """

    def __init__(
        self,
        segments: Sequence[Segment],
        corner_tol_deg: float = CORNER_TOL_DEG,
        gap_tol: float = GAP_TOL_MM,
        feed_limits: Sequence[float | None] | None = None,
        unblended: Sequence[Unblended] = (),
    ) -> None:
        """``feed_limits``: optional programmed feed limit (mm/s) per segment (None: no limit),
        e.g. a G-code block's F word; the schedule keeps the tangential feed under it.
        ``unblended``: corners a corner blend (``geometry.arcblend.blend_path``) left as they were,
        kept for the report."""
        if len(segments) == 0:
            raise GeometryError("segments", [], "a toolpath needs at least one segment")
        if not (np.isfinite(corner_tol_deg) and 0.0 <= corner_tol_deg < 180.0):
            raise GeometryError("corner_tolerance_deg", corner_tol_deg, "must be in [0, 180)")
        # (knot domains far from unit width scaled by a power of two: the same curves, finite derivatives)
        segments = [seg.domain_scaled() if isinstance(seg, NurbsSegment) else seg for seg in segments]
        for i, seg in enumerate(segments):
            if isinstance(seg, NurbsSegment):
                big = float(np.max(np.abs(seg.control_points)))
                if not big <= MAX_COORD_MM:
                    raise GeometryError(f"segments[{i}]", big, f"coordinates must be within +-{MAX_COORD_MM:g} mm", i)
        self.segments, self.closed_gaps = close_gaps(segments, gap_tol)
        self.unblended = list(unblended)
        self._feed = self._check_feed_limits(feed_limits, len(self.segments))
        parts: list[Segment] = []
        origin_l: list[int] = []
        kinds: list[int] = []
        tables: dict[int, ArcLengthTable] = {}
        lengths: list[float] = []
        cut_after: list[int] = []  # sub-segments that start where a sharp turn was cut out
        for i, seg in enumerate(self.segments):
            kind = segment_kind(seg)
            for part in [seg] if kind != GENERIC else self._cut_sharp_turns(seg, corner_tol_deg, cut_after, len(parts)):
                pk = kind if kind != GENERIC else segment_kind(part)
                if pk == GENERIC:
                    if isinstance(part, NurbsSegment):
                        part = part.rebased()  # u as fine as the curve needs (``NurbsSegment.rebased``)
                    table = ArcLengthTable.build(part)
                    tables[len(parts)] = table
                    lengths.append(table.length)
                else:
                    lengths.append(np.nan)  # measured below, all closed-form parts at once
                parts.append(part)
                origin_l.append(i)
                kinds.append(pk)
        kind_a = np.asarray(kinds, dtype=np.int64)
        closed = _Closed(parts, kind_a)
        length = np.asarray(lengths, dtype=np.float64)
        length[kind_a != GENERIC] = closed.length[kind_a != GENERIC]
        origin = np.asarray(origin_l, dtype=np.int64)
        keep = length > MIN_SEGMENT_LENGTH_MM
        covered = np.zeros(len(self.segments), dtype=bool)
        covered[origin[keep]] = True
        missing = np.flatnonzero(~covered)
        if missing.size:
            i = int(missing[0])
            raise GeometryError(f"segments[{i}]", 0.0, f"zero-length segment (< {MIN_SEGMENT_LENGTH_MM} mm)", i)
        if not keep.all():
            idx = np.flatnonzero(keep)
            new = {int(j): n for n, j in enumerate(idx)}
            parts = [parts[j] for j in idx]
            tables = {new[j]: t for j, t in tables.items() if j in new}
            kind_a, origin, length = kind_a[idx], origin[idx], length[idx]
            closed = _Closed(parts, kind_a)
        self._closed = closed
        self._generic = tables
        self._generic_idx = np.asarray(sorted(tables), dtype=np.int64)
        self.sub_kind = kind_a
        self.subs = SubTables(parts, dict(tables))
        self.sub_origin = origin
        self.offsets = np.concatenate([[0.0], np.cumsum(length)])
        # global arc length of every knot inside the sub-segments (where C''' may jump) and of the
        # junctions between sub-segments (where the curvature may jump too; those that are corners
        # are piece ends, outside every piece); closed-form parts have no inner knots
        inner = [self.offsets[k] + t.s_of_u(t.segment.breakpoints[1:-1]) for k, t in sorted(tables.items())]
        self.knot_s = np.union1d(np.concatenate([np.zeros(0), *inner]), self.offsets[1:-1])
        self._junctions(gap_tol, np.radians(corner_tol_deg))
        if not keep.all():
            cut_after = [new[j] for j in cut_after if j in new]
        self.sharp_turns = [c for c in self.corners if int(np.searchsorted(self.offsets, c.s)) in set(cut_after)]
        self.pieces = self._pieces()

    @staticmethod
    def _cut_sharp_turns(seg: Segment, corner_tol_deg: float, cut_after: list[int], n_before: int) -> list[Segment]:
        """``seg`` split at its C0 and zero-speed knots, and each part with its sharp turns cut out
        (``NurbsSegment.cut_sharp_turns``: the tangent break left there is a corner); the index each
        part after a cut will have among the sub-segments is appended to ``cut_after``."""
        out: list[Segment] = []
        for part in seg.split_at_c0_knots():
            if isinstance(part, NurbsSegment):
                cut_parts, _ = part.cut_sharp_turns(np.radians(corner_tol_deg))
                cut_after.extend(n_before + len(out) + k for k in range(1, len(cut_parts)))
                out.extend(cut_parts)
            else:
                out.append(part)
        return out

    @property
    def length(self) -> float:
        return float(self.offsets[-1])

    @staticmethod
    def _check_feed_limits(feed_limits: Sequence[float | None] | None, n: int) -> FloatArray | None:
        if feed_limits is None or all(f is None for f in feed_limits):
            return None
        if len(feed_limits) != n:
            raise GeometryError("feed_limits", len(feed_limits), f"needs one entry per segment ({n})")
        out = np.full(n, np.inf)
        # all at once when every limit is valid (a dense program has 10^5 segments) ...
        given = [i for i, f in enumerate(feed_limits) if f is not None]
        vals = [feed_limits[i] for i in given]
        if all(isinstance(f, (int, float)) and not isinstance(f, bool) for f in vals):
            arr = np.asarray(vals, dtype=np.float64)
            if np.all(np.isfinite(arr) & (arr >= MIN_FEED_MM_S)):
                out[given] = arr
                return out
        # ... else one by one, naming the first bad one
        for i, f in enumerate(feed_limits):
            if f is None:
                continue
            if isinstance(f, bool) or not isinstance(f, (int, float)) or not (np.isfinite(f) and f >= MIN_FEED_MM_S):
                raise GeometryError(f"segments[{i}].feed", f,
                                    f"a feed limit must be a finite number >= {MIN_FEED_MM_S:g} mm/s", i)
            out[i] = float(f)
        return out

    def feed_limit(self, s: FloatArray, piece: Piece | None = None) -> FloatArray | None:
        """Programmed feed limit (mm/s) at arc lengths s, (K,); inf where none; None if no segment has one."""
        if self._feed is None:
            return None
        k = self._sub_index(np.asarray(s, dtype=np.float64), piece)
        return np.asarray(self._feed[self.sub_origin[k]], dtype=np.float64)

    def _generic_end_derivs(self, k: int, at_end: bool) -> FloatArray:
        seg = self._generic[k].segment
        lo, hi = seg.domain
        u = np.array([hi if at_end else lo])
        D = seg.derivatives(u)[:, 0, :]
        if not np.linalg.norm(D[1]) > 0.0:
            # zero speed at the end (repeated control points): tangent from just inside
            u = u + (-1.0 if at_end else 1.0) * ZERO_SPEED_NUDGE * (hi - lo)
            D[1:] = seg.derivatives(u)[1:, 0, :]
        return D

    def _end_derivs(self, lo: int, hi: int, at_end: bool) -> FloatArray:
        """C and its first three u-derivatives (4, hi - lo, 3) at the start (or end) of sub-segments lo .. hi - 1."""
        cf = self._closed
        k = np.arange(lo, hi)
        D = cf.derivatives(k, cf.length[k] if at_end else np.zeros(k.size))
        if at_end:
            D[0] = cf.end[k]  # exact ends: a line's end point, a clothoid's by the same Fresnel form
        g = self._generic_idx
        for j in g[np.searchsorted(g, lo) : np.searchsorted(g, hi)].tolist():
            D[:, j - lo] = self._generic_end_derivs(j, at_end)
        return D

    def _junctions(self, gap_tol: float, tol_rad: float) -> None:
        """Gaps (error), jumps of C_ss and C_sss (``junction_jumps``) and corners at every junction,
        from the end derivatives of the sub-segments on either side, JUNCTION_CHUNK junctions at a time."""
        J = len(self.subs) - 1
        gaps = np.empty(J)
        cos = np.empty(J)
        p_in = np.empty((J, 3))
        dt = np.empty((J, 3))  # jump of the unit tangent
        self.junction_jumps = np.empty((J, 2))
        for a in range(0, J, JUNCTION_CHUNK):
            b = min(J, a + JUNCTION_CHUNK)  # junction k joins the end of sub k to the start of sub k + 1
            D_out = self._end_derivs(a, b, True)
            D_in = self._end_derivs(a + 1, b + 1, False)
            gaps[a:b] = np.linalg.norm(D_in[0] - D_out[0], axis=1)
            self.junction_jumps[a:b] = self._jumps(D_out, D_in)
            t_out, t_in = D_out[1], D_in[1]
            norms = np.linalg.norm(t_out, axis=1) * np.linalg.norm(t_in, axis=1)
            cos[a:b] = np.einsum("ij,ij->i", t_out, t_in) / norms
            p_in[a:b] = D_in[0]
            with np.errstate(invalid="ignore", divide="ignore"):
                dt[a:b] = (t_in / np.linalg.norm(t_in, axis=1)[:, None]
                           - t_out / np.linalg.norm(t_out, axis=1)[:, None])
        bad = np.flatnonzero(~(gaps <= gap_tol))
        if bad.size:
            k = int(bad[0])
            gap = float(gaps[k])
            i = int(self.sub_origin[k + 1])
            raise GeometryError(
                f"segments[{i}].control_points[0]",
                gap,
                f"gap of {gap:.6g} mm to the previous segment's end exceeds {gap_tol} mm",
                i,
            )
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        self.corners = [
            Corner(
                s=float(self.offsets[k + 1]),
                angle_deg=float(np.degrees(angle[k])),
                segment=int(self.sub_origin[k + 1]),
                position=(float(p_in[k, 0]), float(p_in[k, 1]), float(p_in[k, 2])),
            )
            for k in np.flatnonzero(angle > tol_rad).tolist()
        ]
        # turns below the corner tolerance, passed at speed (the feed is capped there: solvers.lp.v_step_limit)
        turn = 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(dt, axis=1), 0.0, 1.0))  # accurate near 0
        at = np.flatnonzero((angle <= tol_rad) & (turn > np.radians(PASSED_TURN_MIN_DEG)))
        self.passed_turns = PassedTurns(self.offsets[at + 1], np.degrees(turn[at]), np.abs(dt[at]))

    @staticmethod
    def _jumps(D_out: FloatArray, D_in: FloatArray) -> FloatArray:
        """Norms of the jumps of C_ss and C_sss at each junction, (J, 2)."""
        if D_out.shape[1] == 0:
            return np.zeros((0, 2))
        _, a2, a3 = arc_length_derivatives(D_out)
        _, b2, b3 = arc_length_derivatives(D_in)
        return np.column_stack([np.linalg.norm(b2 - a2, axis=1), np.linalg.norm(b3 - a3, axis=1)])

    def _pieces(self) -> list[Piece]:
        starts = [0] + [int(np.searchsorted(self.offsets, c.s)) for c in self.corners]
        ends = [*starts[1:], len(self.subs)]
        feed = (np.full(len(starts), math.inf) if self._feed is None
                else np.maximum.reduceat(self._feed[self.sub_origin], np.asarray(starts, dtype=np.int64)))
        return [
            Piece(
                index=i,
                s_start=float(self.offsets[a]),
                s_end=float(self.offsets[b]),
                first_sub=a,
                last_sub=b - 1,
                feed=float(feed[i]),
            )
            for i, (a, b) in enumerate(zip(starts, ends, strict=True))
        ]

    def _sub_index(self, s: FloatArray, piece: Piece | None) -> IntArray:
        lo_sub, hi_sub = (0, len(self.subs) - 1) if piece is None else (piece.first_sub, piece.last_sub)
        k = np.searchsorted(self.offsets, s, side="right") - 1
        return np.asarray(np.clip(k, lo_sub, hi_sub), dtype=np.int64)

    def _generic_runs(self, k: IntArray) -> Iterator[tuple[int, slice | IntArray]]:
        """(kk, at) for each NURBS sub-segment kk among the points' sub-segments k (K,): ``at`` selects
        its points, a slice where k is non-decreasing (s sorted: the solvers' grids, the samples), else
        indices in order.  One pass over k, where a mask per sub-segment would be K x S (the 18.35 m
        path's verification grids: 45 sub-segments, ~10^5 points)."""
        if k.size == 0:
            return
        order: IntArray | None = None
        ks = k
        if k.size > 1 and bool(np.any(k[1:] < k[:-1])):
            order = np.argsort(k, kind="stable")
            ks = k[order]
        cut = np.flatnonzero(ks[1:] != ks[:-1]) + 1
        for a, b in zip([0, *cut.tolist()], [*cut.tolist(), ks.size], strict=True):
            kk = int(ks[a])
            if self.sub_kind[kk] == GENERIC:
                yield kk, (slice(a, b) if order is None else order[a:b])

    def locate(self, s: FloatArray, piece: Piece | None = None) -> tuple[IntArray, FloatArray]:
        """Sub-segment index k and parameter u for each arc length s (mm): u is ``subs[k].segment``'s, whose
        NURBS domains start at u = 0 (``NurbsSegment.rebased``), not the input segment's."""
        s = np.asarray(s, dtype=np.float64)
        k = self._sub_index(s, piece)
        x = s - self.offsets[k]
        cf = self._closed
        u = np.asarray(cf.u0[k] + cf.clip(k, x) * cf.du[k], dtype=np.float64)
        for kk, m in self._generic_runs(k):
            u[m] = self._generic[kk].u_of_s(self._table_x(kk, s[m], x[m]))
        return k, u

    def _table_x(self, kk: int, s: FloatArray, x: FloatArray) -> FloatArray:
        """Sub-segment-local arc length for sub-segment kk's table: s at or past the sub-segment's end
        maps to the table's own length (offsets[kk + 1] - offsets[kk] differs from it by rounding,
        which would leave the end point 1e-15 mm short of the segment's end)."""
        return np.where(s >= self.offsets[kk + 1], self._generic[kk].length, x)

    def _derivatives(
        self, s: FloatArray, piece: Piece | None, exact: bool = True, precise: bool = False
    ) -> tuple[IntArray, FloatArray]:
        """Sub-segment index (K,) and C, C', C'', C''' (4, K, 3) at arc lengths s (``evaluate``)."""
        k = self._sub_index(s, piece)
        x = s - self.offsets[k]
        D = np.empty((4, s.size, 3))
        cl = np.flatnonzero(self.sub_kind[k] != GENERIC)  # lines, clothoids: closed form
        if cl.size:
            D[:, cl] = self._closed.derivatives(k[cl], x[cl])
        for kk, m in self._generic_runs(k):
            table = self._generic[kk]
            seg = table.segment
            xk = self._table_x(kk, s[m], x[m])
            um = table.u_of_s(xk, exact or precise)
            if precise and isinstance(seg, NurbsSegment):
                Dk = seg.derivatives(um, exact_points=True)
            else:
                Dk = seg.derivatives(um)
            lo, hi = seg.domain
            # zero speed, or a rounding residue of it (|C'| ~ 1e-16 at a cusp's knot): no tangent there
            tiny = ZERO_SPEED_SHARE * table.length / (hi - lo)
            stuck = ~(np.einsum("ij,ij->i", Dk[1], Dk[1]) > tiny * tiny)
            if stuck.any():
                us = um[stuck]
                nudge = np.where(us < 0.5 * (lo + hi), 1.0, -1.0) * ZERO_SPEED_NUDGE * (hi - lo)
                Dk[1:, stuck, :] = seg.derivatives(us + nudge)[1:]
            if precise:  # C(u) + (C' / |C'|) (s - s(u)): along the tangent by u's arc-length residual
                speed2 = np.einsum("ij,ij->i", Dk[1], Dk[1])
                ok = speed2 > 0.0
                r = np.where(ok, (xk - table.s_of_u(um)) / np.sqrt(np.where(ok, speed2, 1.0)), 0.0)
                Dk[0] += Dk[1] * r[:, None]
            D[:, m, :] = Dk
        return k, D

    def evaluate(
        self, s: FloatArray, piece: Piece | None = None, exact: bool = True, precise: bool = False
    ) -> PathSamples:
        """Position and arc-length derivatives at arc lengths s (mm), shape (K,).

        With ``piece`` given, points are evaluated on that piece's sub-segments
        only (so a corner's s is evaluated on the correct side).  ``exact=False`` maps s to u
        by the arc-length table's Hermite guess alone (within 1e-10 mm along the curve, see
        ``geometry.arclength``), for the solvers' checkpoint geometry; samples are exact.

        ``precise``: positions smooth to a few units in the last place of the coordinates (``coordinate_scale``),
        for samples whose differences resolve limits near that (about twice the cost of ``exact``).  Otherwise
        a point carries u's own rounding, ulp(u) |C'(u)|, and the quintic guess's QUINTIC_TOL (2e-13 mm), both
        uneven from point to point, and the compiled kernel's Taylor rounding, which near a long span's ends
        follows partial sums larger than the control points: bench seed 5029 lp (a segment 6 mm long over u in
        [0, 0.025], |C'| = 5.1e3 mm) had ~1e-13 mm of such noise, and its amax_x Ts^2 is 9.7e-12 mm: the
        second differences of its samples read 1.2 % over the limit.  With it, C(u) is moved along the
        tangent by the residual s - s(u), which the table gives to ~ulp(s), and C itself comes from de Boor's
        algorithm (``NurbsSegment.derivatives``' ``exact_points``): 0.2 % there
        (tests/geometry/test_point_precision.py).
        """
        s = np.asarray(s, dtype=np.float64)
        k, D = self._derivatives(s, piece, exact, precise)
        d1, d2, d3 = arc_length_derivatives(D)
        fl = None if self._feed is None else np.asarray(self._feed[self.sub_origin[k]], dtype=np.float64)
        return PathSamples(s=s, position=D[0], d1=d1, d2=d2, d3=d3, feed_limit=fl)

    @cached_property
    def coordinate_scale(self) -> float:
        """The largest coordinate (mm) a point is computed from: NURBS control points and the sub-segments'
        ends.  A point's rounding is a few units in its last place."""
        ends = float(np.max(np.abs(self.positions(self.offsets))))
        cps = [float(np.max(np.abs(t.segment.control_points))) for t in self._generic.values()
               if isinstance(t.segment, NurbsSegment)]
        return max([ends, *cps])

    @cached_property
    def axis_range(self) -> FloatArray:
        """(2, 3) mm: per axis the smallest and largest of the NURBS control points and of the points at the
        sub-segments' ends and quarters (a NURBS curve lies in its control points' hull; a line or arc that moves an
        axis moves it between its quarter points, an arc's extremes may lie a little outside them)."""
        o = self.offsets
        s = np.concatenate([o, *(o[:-1] + f * np.diff(o) for f in (0.25, 0.5, 0.75))])
        pts = [self.positions(s)]
        pts += [np.asarray(t.segment.control_points, dtype=np.float64) for t in self._generic.values()
                if isinstance(t.segment, NurbsSegment)]
        allp = np.concatenate(pts)
        return np.stack([allp.min(axis=0), allp.max(axis=0)])

    @property
    def axis_extent(self) -> FloatArray:
        """Per axis (3,), mm: the spread of ``axis_range``; 0 on an axis the path does not move."""
        lo, hi = self.axis_range
        return np.asarray(hi - lo, dtype=np.float64)

    def positions(self, s: FloatArray, piece: Piece | None = None) -> FloatArray:
        """C(s) only, (K, 3) mm."""
        s = np.asarray(s, dtype=np.float64)
        k = self._sub_index(s, piece)
        x = s - self.offsets[k]
        out = np.empty((s.size, 3))
        cl = np.flatnonzero(self.sub_kind[k] != GENERIC)
        if cl.size:
            out[cl] = self._closed.points(k[cl], x[cl])
        for kk, m in self._generic_runs(k):
            table = self._generic[kk]
            out[m] = table.segment.points(table.u_of_s(self._table_x(kk, s[m], x[m])))
        return out
