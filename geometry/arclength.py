"""Arc length s(u) and its inverse u(s) for one segment (NURBS, clothoid: any ``Segment``).

    s(u) = integral_{U_p}^{u} |C'(v)| dv

computed per knot span by adaptive Gauss-Legendre quadrature to 1e-13
relative (see ``geometry.quadrature``), inverted by a quintic Hermite guess
(slopes 1/|C'|, curvatures from d|C'|/du) where the table's midpoint check holds
it within QUINTIC_TOL = 2e-13 mm, else by the cubic guess and one Newton step;
s(u(s)) = s to ~1e-13 mm.  The guess alone is within
GUESS_TOL_MM = 1e-10 mm (checked at every interval midpoint, where the Hermite
error t^2 (1-t)^2 peaks): ``u_of_s(s, exact=False)`` returns it, for the
solvers' checkpoint geometry.  (The 18.35 m flower chain's tables grow from
259k to 357k breakpoints for it.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from geometry.errors import GeometryError
from geometry.nurbs import FloatArray
from geometry.quadrature import MonotoneTable, TableTooLarge
from geometry.segment import Segment

#: The Hermite guess of u(s) is refined until it is within this distance (mm).
GUESS_TOL_MM = 1e-10


def speed_slope(seg: Segment, u: FloatArray) -> FloatArray:
    """d|C'|/du = C' . C'' / |C'| (K,); NaN where C' = 0 (a cusp: no quintic guess there)."""
    D = seg.derivatives(u)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.einsum("ij,ij->i", D[1], D[2]) / np.sqrt(np.einsum("ij,ij->i", D[1], D[1])),
                          dtype=np.float64)


@dataclass(frozen=True, eq=False)
class ArcLengthTable:
    """Arc-length table of one segment: u_b (M+1,), s_b (M+1,) in mm."""

    segment: Segment
    table: MonotoneTable

    @classmethod
    def build(cls, seg: Segment) -> ArcLengthTable:
        """Raises GeometryError naming the segment where the table does not converge (``TableTooLarge``: a
        parameterisation so uneven that round-off holds the quadrature off, e.g. weights 1e-16 : 1 : 1e-16)."""
        try:
            return cls(seg, MonotoneTable.build(seg.speed, seg.breakpoints, guess_tol=GUESS_TOL_MM,
                                                df=partial(speed_slope, seg)))
        except TableTooLarge as exc:
            w = getattr(seg, "weights", None)
            value: dict[str, float] = {"quadrature_intervals": exc.intervals}
            if w is not None:  # (the spread as max and min where their ratio overflows: 1e300 : 1e-300)
                wmax, wmin = float(np.max(w)), float(np.min(w))
                value = ({"weights_max_over_min": wmax / wmin} if math.isfinite(wmax / wmin)
                         else {"weights_max": wmax, "weights_min": wmin})
            raise GeometryError(
                seg.name,
                value,
                f"its arc length does not converge to 1e-13 within {exc.budget} quadrature intervals: the speed "
                "|C'(u)| varies too unevenly along u for float64 (weights spanning more than ~1e15, or knot spans "
                "far apart in size)") from exc

    @property
    def length(self) -> float:
        return self.table.total

    @property
    def u_b(self) -> FloatArray:
        return self.table.x_b

    @property
    def s_b(self) -> FloatArray:
        return self.table.F_b

    def s_of_u(self, u: FloatArray) -> FloatArray:
        """Arc length from the domain start to each u, shape (K,)."""
        return self.table.value(np.asarray(u, dtype=np.float64))

    def u_of_s(self, s: FloatArray, exact: bool = True) -> FloatArray:
        """Parameter u at each arc length s in [0, length], shape (K,); ``exact=False``: within
        GUESS_TOL_MM of it along the curve, at 40 % of the cost (exact: the quintic guess where the
        table's check holds it within QUINTIC_TOL mm, else one Newton step)."""
        return self.table.inverse(np.asarray(s, dtype=np.float64), newton=exact)
