"""Arc length s(u) and its inverse u(s) for one NURBS segment.

    s(u) = integral_{U_p}^{u} |C'(v)| dv

The domain is split at the distinct knots (where |C'| may lose smoothness),
then each interval is bisected until a 16-point Gauss-Legendre rule on the
interval and on its two halves agree to ``REL_TOL`` relative (plus an absolute
floor of ``ABS_TOL_MM``), which makes the total length converge to better than
1e-9 relative.  The result is a table of breakpoints u_b with cumulative
lengths s_b.

u(s) is the inverse: a cubic Hermite guess from the table (slopes
du/ds = 1/|C'|), then Newton steps u <- u - (s(u) - s)/|C'(u)| safeguarded by
the table interval, where s(u) = s_b[j] + Gauss-Legendre over [u_b[j], u].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from geometry.nurbs import NurbsSegment

FloatArray = NDArray[np.float64]

GL_ORDER = 16
#: Gauss-Legendre order for partial integrals inside one (converged) table interval.
GL_ORDER_PARTIAL = 6
REL_TOL = 1e-13
ABS_TOL_MM = 1e-15
MAX_BISECTIONS = 48
#: Every knot span starts as this many intervals, so the Hermite guess of u(s) is close.
MIN_INTERVALS_PER_SPAN = 4
NEWTON_STEPS = 1
#: Table intervals are bisected until the Hermite guess of u(s) is within this (mm).
GUESS_TOL_MM = 1e-7

_GL = {n: np.polynomial.legendre.leggauss(n) for n in (GL_ORDER, GL_ORDER_PARTIAL)}


def _gl(seg: NurbsSegment, a: FloatArray, b: FloatArray, order: int = GL_ORDER) -> FloatArray:
    """Gauss-Legendre integral of |C'| over each [a_i, b_i] (vectorised)."""
    x, w = _GL[order]
    half = 0.5 * (b - a)
    mid = 0.5 * (b + a)
    u = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    sp = seg.speed(u).reshape(a.shape[0], order)
    return np.asarray(half * (sp @ w), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class ArcLengthTable:
    """Breakpoints u_b (M+1,) and cumulative arc length s_b (M+1,) in mm."""

    segment: NurbsSegment
    u_b: FloatArray
    s_b: FloatArray
    speed_b: FloatArray

    @property
    def length(self) -> float:
        return float(self.s_b[-1])

    @classmethod
    def build(cls, seg: NurbsSegment) -> ArcLengthTable:
        knots = seg.breakpoints
        frac = np.linspace(0.0, 1.0, MIN_INTERVALS_PER_SPAN + 1)[:-1]
        a = (knots[:-1, None] + np.diff(knots)[:, None] * frac[None, :]).ravel()
        b = np.concatenate([a[1:], knots[-1:]])
        done_a: list[FloatArray] = []
        done_b: list[FloatArray] = []
        done_i: list[FloatArray] = []
        whole = _gl(seg, a, b)
        for _ in range(MAX_BISECTIONS):
            m = 0.5 * (a + b)
            left = _gl(seg, a, m)
            right = _gl(seg, m, b)
            halves = left + right
            ok = np.abs(halves - whole) <= REL_TOL * np.abs(halves) + ABS_TOL_MM
            # accept converged intervals as their two halves (the finer estimate)
            done_a.extend([a[ok], m[ok]])
            done_b.extend([m[ok], b[ok]])
            done_i.extend([left[ok], right[ok]])
            if ok.all():
                break
            nk = ~ok
            a = np.concatenate([a[nk], m[nk]])
            b = np.concatenate([m[nk], b[nk]])
            whole = np.concatenate([left[nk], right[nk]])
        else:  # pragma: no cover - only for pathological parameterisations
            done_a.append(a)
            done_b.append(b)
            done_i.append(whole)
        A = np.concatenate(done_a)
        order = np.argsort(A, kind="stable")
        A = A[order]
        Bv = np.concatenate(done_b)[order]
        I = np.concatenate(done_i)[order]
        u_b = np.concatenate([A, Bv[-1:]])
        s_b = np.concatenate([[0.0], np.cumsum(I)])
        table = cls(segment=seg, u_b=u_b, s_b=s_b, speed_b=seg.speed(u_b))
        for _ in range(MAX_BISECTIONS):
            table, refined = table._refine_for_inverse()
            if not refined:
                break
        return table

    def _refine_for_inverse(self) -> tuple[ArcLengthTable, bool]:
        """Bisect intervals where the Hermite guess of u(s) is off by more than
        ``GUESS_TOL_MM`` (measured as |du| |C'|), so one Newton step converges."""
        ua, ub = self.u_b[:-1], self.u_b[1:]
        um = 0.5 * (ua + ub)
        half = _gl(self.segment, ua, um)
        sm = self.s_b[:-1] + half
        guess = self._hermite(sm, np.arange(ua.size))
        bad = np.abs(guess - um) * self.segment.speed(um) > GUESS_TOL_MM
        if not bad.any():
            return self, False
        u_b = np.insert(self.u_b, np.flatnonzero(bad) + 1, um[bad])
        s_b = np.insert(self.s_b, np.flatnonzero(bad) + 1, sm[bad])
        return ArcLengthTable(self.segment, u_b, s_b, self.segment.speed(u_b)), True

    def _hermite(self, s: FloatArray, j: NDArray[np.intp]) -> FloatArray:
        """Cubic Hermite guess of u(s) inside table interval j (slopes du/ds = 1/|C'|)."""
        u0, u1 = self.u_b[j], self.u_b[j + 1]
        s0, s1 = self.s_b[j], self.s_b[j + 1]
        h = s1 - s0
        safe_h = np.where(h > 0.0, h, 1.0)
        t = np.where(h > 0.0, (s - s0) / safe_h, 0.0)
        sp0 = np.maximum(self.speed_b[j], 1e-300)
        sp1 = np.maximum(self.speed_b[j + 1], 1e-300)
        m0 = np.minimum(h / sp0, 3.0 * (u1 - u0))
        m1 = np.minimum(h / sp1, 3.0 * (u1 - u0))
        t2, t3 = t * t, t * t * t
        u = (
            (2 * t3 - 3 * t2 + 1) * u0
            + (t3 - 2 * t2 + t) * m0
            + (-2 * t3 + 3 * t2) * u1
            + (t3 - t2) * m1
        )
        return np.asarray(np.clip(u, u0, u1), dtype=np.float64)

    def s_of_u(self, u: FloatArray) -> FloatArray:
        """Arc length from the domain start to each u, shape (K,)."""
        u = np.clip(np.asarray(u, dtype=np.float64), self.u_b[0], self.u_b[-1])
        j = np.clip(np.searchsorted(self.u_b, u, side="right") - 1, 0, self.u_b.size - 2)
        return self.s_b[j] + _gl(self.segment, self.u_b[j], u, GL_ORDER_PARTIAL)

    def u_of_s(self, s: FloatArray) -> FloatArray:
        """Parameter u at each arc length s in [0, length], shape (K,)."""
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, self.length)
        j = np.clip(np.searchsorted(self.s_b, s, side="right") - 1, 0, self.s_b.size - 2)
        u0, u1, s0 = self.u_b[j], self.u_b[j + 1], self.s_b[j]
        u = self._hermite(s, j)
        for _ in range(NEWTON_STEPS):
            err = s0 + _gl(self.segment, u0, u, GL_ORDER_PARTIAL) - s
            sp = self.segment.speed(u)
            step = np.where(sp > 0.0, err / np.maximum(sp, 1e-300), 0.0)
            u = np.clip(u - step, u0, u1)
        return u
