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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from geometry.arclength import ArcLengthTable
from geometry.errors import GeometryError
from geometry.nurbs import ZERO_SPEED_SHARE
from geometry.segment import Segment

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Largest gap (mm) allowed between the end of a segment and the start of the next.
GAP_TOL_MM = 1e-3
#: Default tangent break (degrees) above which a junction is a corner.
CORNER_TOL_DEG = 0.5
#: Shortest segment (mm) accepted; below it the segment has no length to travel.
MIN_SEGMENT_LENGTH_MM = 1e-9
#: Where |C'| vanishes (repeated control points) derivatives are taken this far
#: inside (fraction of the parameter domain): the arc-length derivatives have a
#: limit there but the u-derivative formulas divide by |C'|.
ZERO_SPEED_NUDGE = 1e-7


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

    def subset(self, mask: NDArray[np.bool_]) -> PathSamples:
        """The points selected by ``mask``."""
        fl = None if self.feed_limit is None else self.feed_limit[mask]
        return PathSamples(self.s[mask], self.position[mask], self.d1[mask], self.d2[mask], self.d3[mask], fl)


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

    @property
    def length(self) -> float:
        return self.s_end - self.s_start


def arc_length_derivatives(D: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Map u-derivatives (4, K, 3) to arc-length derivatives C_s, C_ss, C_sss (K, 3 each)."""
    C1, C2, C3 = D[1], D[2], D[3]
    g = np.einsum("ij,ij->i", C1, C1)
    g12 = np.einsum("ij,ij->i", C1, C2)
    g22 = np.einsum("ij,ij->i", C2, C2)
    g13 = np.einsum("ij,ij->i", C1, C3)
    us = 1.0 / np.sqrt(g)
    uss = -g12 * us**4
    usss = 4.0 * g12**2 * us**7 - (g22 + g13) * us**5
    d1 = C1 * us[:, None]
    d2 = C2 * (us**2)[:, None] + C1 * uss[:, None]
    d3 = C3 * (us**3)[:, None] + 3.0 * C2 * (us * uss)[:, None] + C1 * usss[:, None]
    return d1, d2, d3


class Toolpath:
    """Validated chain of segments with arc-length evaluation.

    Attributes:
        segments: the input segments (as given, in order).
        subs: sub-segments after splitting at C0 knots, with their arc-length tables.
        sub_origin: (S,) index of the input segment each sub-segment came from.
        offsets: (S + 1,) cumulative arc length at each sub-segment start, mm.
        corners: rest points inside the path, in order of s.
        pieces: rest-to-rest stretches.
    """

    def __init__(
        self,
        segments: Sequence[Segment],
        corner_tol_deg: float = CORNER_TOL_DEG,
        gap_tol: float = GAP_TOL_MM,
        feed_limits: Sequence[float | None] | None = None,
    ) -> None:
        """``feed_limits``: optional programmed feed limit (mm/s) per segment (None: no limit),
        e.g. a G-code block's F word; the schedule keeps the tangential feed under it."""
        if len(segments) == 0:
            raise GeometryError("segments", [], "a toolpath needs at least one segment")
        if not (np.isfinite(corner_tol_deg) and 0.0 <= corner_tol_deg < 180.0):
            raise GeometryError("corner_tolerance_deg", corner_tol_deg, "must be in [0, 180)")
        self.segments = list(segments)
        self._feed = self._check_feed_limits(feed_limits, len(self.segments))
        subs: list[ArcLengthTable] = []
        origin: list[int] = []
        for i, seg in enumerate(self.segments):
            for part in seg.split_at_c0_knots():
                table = ArcLengthTable.build(part)
                if table.length > MIN_SEGMENT_LENGTH_MM:
                    subs.append(table)
                    origin.append(i)
            if not origin or origin[-1] != i:
                raise GeometryError(
                    f"segments[{i}]", 0.0, f"zero-length segment (< {MIN_SEGMENT_LENGTH_MM} mm)", i
                )
        self.subs = subs
        self.sub_origin = np.asarray(origin, dtype=np.int64)
        self.offsets = np.concatenate([[0.0], np.cumsum([t.length for t in subs])])
        #: global arc length of every knot inside the sub-segments (where C''' may jump)
        # ... and the junctions between sub-segments (where the curvature may jump too; those that
        # are corners are piece ends, outside every piece)
        self.knot_s = np.union1d(
            np.concatenate(
                [off + t.s_of_u(t.segment.breakpoints[1:-1]) for off, t in zip(self.offsets[:-1], subs, strict=True)]
            ),
            self.offsets[1:-1],
        )
        # end derivatives at every junction, computed once: (out of sub k, into sub k+1)
        junctions = [(self._end_derivs(k, True), self._end_derivs(k + 1, False)) for k in range(len(subs) - 1)]
        self._check_gaps(junctions, gap_tol)
        self.corners = self._find_corners(junctions, np.radians(corner_tol_deg))
        self.pieces = self._pieces()

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
        for i, f in enumerate(feed_limits):
            if f is None:
                continue
            if isinstance(f, bool) or not isinstance(f, (int, float)) or not (np.isfinite(f) and f > 0):
                raise GeometryError(f"segments[{i}].feed", f, "a feed limit must be a finite number > 0 mm/s", i)
            out[i] = float(f)
        return out

    def feed_limit(self, s: FloatArray, piece: Piece | None = None) -> FloatArray | None:
        """Programmed feed limit (mm/s) at arc lengths s, (K,); inf where none; None if no segment has one."""
        if self._feed is None:
            return None
        k, _ = self.locate(s, piece)
        return np.asarray(self._feed[self.sub_origin[k]], dtype=np.float64)

    def _end_derivs(self, k: int, at_end: bool) -> FloatArray:
        seg = self.subs[k].segment
        lo, hi = seg.domain
        u = np.array([hi if at_end else lo])
        D = seg.derivatives(u)[:, 0, :]
        if not np.linalg.norm(D[1]) > 0.0:
            # zero speed at the end (repeated control points): tangent from just inside
            u = u + (-1.0 if at_end else 1.0) * ZERO_SPEED_NUDGE * (hi - lo)
            D[1:] = seg.derivatives(u)[1:, 0, :]
        return D

    def _check_gaps(self, junctions: list[tuple[FloatArray, FloatArray]], gap_tol: float) -> None:
        for k, (D_out, D_in) in enumerate(junctions):
            gap = float(np.linalg.norm(D_in[0] - D_out[0]))
            if gap > gap_tol:
                i = int(self.sub_origin[k + 1])
                raise GeometryError(
                    f"segments[{i}].control_points[0]",
                    gap,
                    f"gap of {gap:.6g} mm to the previous segment's end exceeds {gap_tol} mm",
                    i,
                )

    def _find_corners(self, junctions: list[tuple[FloatArray, FloatArray]], tol_rad: float) -> list[Corner]:
        corners: list[Corner] = []
        for k, (D_out, D_in) in enumerate(junctions):
            t_out, t_in = D_out[1], D_in[1]
            c = float(np.dot(t_out, t_in) / (np.linalg.norm(t_out) * np.linalg.norm(t_in)))
            angle = float(np.arccos(np.clip(c, -1.0, 1.0)))
            if angle > tol_rad:
                p = D_in[0]
                corners.append(
                    Corner(
                        s=float(self.offsets[k + 1]),
                        angle_deg=float(np.degrees(angle)),
                        segment=int(self.sub_origin[k + 1]),
                        position=(float(p[0]), float(p[1]), float(p[2])),
                    )
                )
        return corners

    def _pieces(self) -> list[Piece]:
        starts = [0] + [int(np.searchsorted(self.offsets, c.s)) for c in self.corners]
        ends = [*starts[1:], len(self.subs)]
        return [
            Piece(
                index=i,
                s_start=float(self.offsets[a]),
                s_end=float(self.offsets[b]),
                first_sub=a,
                last_sub=b - 1,
            )
            for i, (a, b) in enumerate(zip(starts, ends, strict=True))
        ]

    def locate(self, s: FloatArray, piece: Piece | None = None) -> tuple[IntArray, FloatArray]:
        """Sub-segment index and parameter u for each arc length s (mm)."""
        s = np.asarray(s, dtype=np.float64)
        lo_sub, hi_sub = (0, len(self.subs) - 1) if piece is None else (piece.first_sub, piece.last_sub)
        k = np.searchsorted(self.offsets, s, side="right") - 1
        k = np.clip(k, lo_sub, hi_sub).astype(np.int64)
        u = np.empty_like(s)
        for kk in np.unique(k):
            m = k == kk
            u[m] = self.subs[kk].u_of_s(s[m] - self.offsets[kk])
        return k, u

    def evaluate(self, s: FloatArray, piece: Piece | None = None) -> PathSamples:
        """Position and arc-length derivatives at arc lengths s (mm), shape (K,).

        With ``piece`` given, points are evaluated on that piece's sub-segments
        only (so a corner's s is evaluated on the correct side).
        """
        s = np.asarray(s, dtype=np.float64)
        k, u = self.locate(s, piece)
        D = np.empty((4, s.size, 3))
        for kk in np.unique(k):
            m = k == kk
            seg = self.subs[kk].segment
            Dk = seg.derivatives(u[m])
            lo, hi = seg.domain
            # zero speed, or a rounding residue of it (|C'| ~ 1e-16 at a cusp's knot): no tangent there
            tiny = ZERO_SPEED_SHARE * self.subs[kk].length / (hi - lo)
            stuck = ~(np.einsum("ij,ij->i", Dk[1], Dk[1]) > tiny * tiny)
            if stuck.any():
                um = u[m][stuck]
                nudge = np.where(um < 0.5 * (lo + hi), 1.0, -1.0) * ZERO_SPEED_NUDGE * (hi - lo)
                Dk[1:, stuck, :] = seg.derivatives(um + nudge)[1:]
            D[:, m, :] = Dk
        d1, d2, d3 = arc_length_derivatives(D)
        fl = None if self._feed is None else np.asarray(self._feed[self.sub_origin[k]], dtype=np.float64)
        return PathSamples(s=s, position=D[0], d1=d1, d2=d2, d3=d3, feed_limit=fl)

    def positions(self, s: FloatArray, piece: Piece | None = None) -> FloatArray:
        """C(s) only, (K, 3) mm."""
        s = np.asarray(s, dtype=np.float64)
        k, u = self.locate(s, piece)
        out = np.empty((s.size, 3))
        for kk in np.unique(k):
            m = k == kk
            out[m] = self.subs[kk].segment.points(u[m])
        return out
