"""Cumulative integrals of positive functions, and their inverses, to ~1e-13.

    F(x) = integral_{x_0}^{x} f(v) dv,   f > 0 (almost everywhere)

used for arc length s(u) (f = |C'(u)|) and for time t(x) along a feed
profile (f = ds/dx / sqrt(q)).  The domain is split at given edges, each edge
interval into ``min_intervals`` pieces, and intervals are bisected until a
16-point Gauss-Legendre rule on the interval and on its halves agree to
``REL_TOL`` relative.  Intervals are then bisected further until a cubic
Hermite interpolant of the inverse x(F) (slopes 1/f) is within
``guess_tol`` (in F's units) at interval midpoints, so a single Newton step

    x <- x - (F(x) - y) / f(x),   F(x) = F_b[j] + GL_6 over [x_b[j], x]

converges to machine precision.  Callers that need no more than the guess
tolerance pass ``newton=False`` to ``inverse`` and skip the 6-point partial
integral and the extra f evaluation (the solvers' own geometry does: about
60 % of evaluating the geometry).

f may jump at given breakpoints (``jumps``): there the table keeps both one-sided values of f, each a
hair's breadth (``jump_eps``) inside its interval, and the Hermite guesses take the slope from the interval's
own side (a time table's x map changes its scale at the rest intervals' inner knots, where dt/dx halves:
the guess took the other side's slope there, and the intervals next to the knot were bisected 11 rounds
deep, to 1/8192 of a knot interval, before it met the tolerance).

Given f' (``df``), the table also holds a quintic Hermite guess of x(F) (slopes
1/f, curvatures -f'/f^3): checked at the same midpoints, in the round where an
interval is final, and flagged per interval where it is within ``QUINTIC_TOL``
(in F's units).  There ``inverse`` takes it instead of the Newton step: the same
point to a few units in the last place of F (the step's own F(x) is a sum
rounded to F's last place), for none of its 7 evaluations of f per point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from geometry import native

FloatArray = NDArray[np.float64]
Integrand = Callable[[FloatArray], FloatArray]

GL_ORDER = 16
GL_ORDER_PARTIAL = 6
REL_TOL = 1e-13
MAX_BISECTIONS = 48
NEWTON_STEPS = 1
#: The quintic guess stands for the Newton step where it is within this (in F's units: 2e-13 mm of arc
#: length, ~4 units in the last place of F at 400 mm; the 18.35 m flower's tables: at most 1.4e-13 mm).
QUINTIC_TOL = 2e-13

_GL = {n: np.polynomial.legendre.leggauss(n) for n in (GL_ORDER, GL_ORDER_PARTIAL)}

#: A table may have at most this many intervals, or TABLE_GROWTH times those it starts from if more.  Where
#: round-off keeps an interval from converging it is split at every level, and the intervals double up to
#: MAX_BISECTIONS times: weights of 1e-16 : 1 : 1e-16 built 27 M breakpoints in a minute, a time table over 1e9 s
#: of motion (an axis at 1e-8 mm/s) never finished (session 58's API probe).  Past it ``TableTooLarge``.
MAX_TABLE_INTERVALS = 1 << 20
TABLE_GROWTH = 64


class TableTooLarge(ValueError):
    """The table did not converge within its interval budget (``MAX_TABLE_INTERVALS``)."""

    def __init__(self, intervals: int, budget: int) -> None:
        self.intervals, self.budget = intervals, budget
        super().__init__(f"the table needs more than {budget} intervals ({intervals} so far) to converge")


#: Intervals per evaluation of the integrand (GL_ORDER points each): a time table over a 183.5 m piece
#: evaluated 1.3 M points at once, ~0.5 GB of transients in the feed's evaluation.
GL_CHUNK = 16_384


def gauss_legendre(f: Integrand, a: FloatArray, b: FloatArray, order: int = GL_ORDER) -> FloatArray:
    """Integral of f over each [a_i, b_i] (vectorised over i, GL_CHUNK intervals at a time)."""
    if a.shape[0] > GL_CHUNK:
        return np.concatenate([
            gauss_legendre(f, a[i : i + GL_CHUNK], b[i : i + GL_CHUNK], order) for i in range(0, a.shape[0], GL_CHUNK)
        ])
    x, w = _GL[order]
    half = 0.5 * (b - a)
    mid = 0.5 * (b + a)
    pts = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    vals = f(pts).reshape(a.shape[0], order)
    return np.asarray(half * (vals @ w), dtype=np.float64)


#: Points per evaluation of the integrand at breakpoints and midpoints (``_at``): as many as one
#: ``gauss_legendre`` chunk.  A 183.5 m piece's time table has ~0.4 M breakpoints.
EVAL_CHUNK = GL_CHUNK * GL_ORDER


def _at(f: Integrand, x: FloatArray) -> FloatArray:
    """f(x), EVAL_CHUNK points at a time (f is elementwise: the same values as at once)."""
    n = EVAL_CHUNK
    if x.size <= n:
        return f(x)
    return np.concatenate([f(x[i : i + n]) for i in range(0, x.size, n)])


@dataclass(frozen=True, eq=False)
class MonotoneTable:
    """Breakpoints x_b (M+1,), cumulative integral F_b (M+1,) and f(x_b); with f' given, f'(x_b) (M+1,)
    and the intervals (M,) where the quintic guess stands for the Newton step; with jumps of f, its limits
    from the left and from the right at each breakpoint (M+1,) (None: f_b on both sides)."""

    f: Integrand
    x_b: FloatArray
    F_b: FloatArray
    f_b: FloatArray
    df: Integrand | None = None
    fp_b: FloatArray | None = None
    quintic: NDArray[np.bool_] | None = None
    f_left: FloatArray | None = None
    f_right: FloatArray | None = None

    @property
    def total(self) -> float:
        return float(self.F_b[-1])

    @classmethod
    def build(
        cls,
        f: Integrand,
        edges: FloatArray,
        min_intervals: int = 4,
        abs_tol: float = 1e-15,
        guess_tol: float = 1e-7,
        df: Integrand | None = None,
        jumps: FloatArray | None = None,
        jump_eps: float = 0.0,
    ) -> MonotoneTable:
        """The table of f over ``edges`` (each split in ``min_intervals``), bisected until GL_ORDER agrees
        with its halves to REL_TOL (or ``abs_tol``), then until the cubic guess of the inverse is within
        ``guess_tol`` (np.inf: no inverse); with ``df`` = f', the quintic guess's flags too.  ``jumps``: edges
        where f may jump (without ``df``); f is taken ``jump_eps`` to either side of them for the guesses
        (an eps that x +- eps tells apart from x in f's own arithmetic)."""
        frac = np.linspace(0.0, 1.0, min_intervals + 1)[:-1]
        a = (edges[:-1, None] + np.diff(edges)[:, None] * frac[None, :]).ravel()
        b = np.concatenate([a[1:], edges[-1:]])
        out_a: list[FloatArray] = []
        out_i: list[FloatArray] = []
        whole = gauss_legendre(f, a, b)
        budget = max(MAX_TABLE_INTERVALS, TABLE_GROWTH * a.size)
        done = 0
        for _ in range(MAX_BISECTIONS):
            if done + 2 * a.size > budget:
                raise TableTooLarge(done + 2 * a.size, budget)
            m = 0.5 * (a + b)
            left = gauss_legendre(f, a, m)
            right = gauss_legendre(f, m, b)
            halves = left + right
            ok = np.abs(halves - whole) <= REL_TOL * np.abs(halves) + abs_tol
            # a non-finite integral stops refining (it stays in the table for the caller to reject);
            # splitting it further only doubles the work at every level
            ok |= ~np.isfinite(halves)
            out_a.extend([a[ok], m[ok]])
            out_i.extend([left[ok], right[ok]])
            done += 2 * int(ok.sum())
            if ok.all():
                break
            nk = ~ok
            a = np.concatenate([a[nk], m[nk]])
            b = np.concatenate([m[nk], b[nk]])
            whole = np.concatenate([left[nk], right[nk]])
        else:  # pragma: no cover - pathological integrands only
            out_a.append(a)
            out_i.append(whole)
        A = np.concatenate(out_a)
        order = np.argsort(A, kind="stable")
        x_b = np.concatenate([A[order], edges[-1:]])
        F_b = np.concatenate([[0.0], np.cumsum(np.concatenate(out_i)[order])])
        table = cls(f=f, x_b=x_b, F_b=F_b, f_b=_at(f, x_b))
        if guess_tol == np.inf:  # (the integral only: ``total`` and ``value``, no inverse)
            return table
        if df is not None:
            table = cls(f, x_b, F_b, table.f_b, df, _at(df, x_b), np.zeros(x_b.size - 1, dtype=bool))
        elif jumps is not None and jumps.size:
            table = table._one_sided(jumps, jump_eps)
        todo = np.ones(x_b.size - 1, dtype=bool)
        for _ in range(MAX_BISECTIONS):
            table, todo = table._refine_for_inverse(guess_tol, todo)
            if not todo.any():
                break
            if table.x_b.size - 1 + int(todo.sum()) > budget:
                raise TableTooLarge(table.x_b.size - 1 + int(todo.sum()), budget)
        return table

    def _one_sided(self, jumps: FloatArray, eps: float) -> MonotoneTable:
        """This table with f's limits from either side at those breakpoints that are in ``jumps``."""
        at = np.searchsorted(self.x_b, jumps)
        inside = at < self.x_b.size
        at = at[inside][self.x_b[at[inside]] == jumps[inside]]
        if not at.size:
            return self
        f_left, f_right = self.f_b.copy(), self.f_b.copy()
        f_left[at] = self.f(self.x_b[at] - eps)
        f_right[at] = self.f(self.x_b[at] + eps)
        return replace(self, f_left=f_left, f_right=f_right)

    def _refine_for_inverse(
        self, guess_tol: float, todo: NDArray[np.bool_]
    ) -> tuple[MonotoneTable, NDArray[np.bool_]]:
        """Split the intervals flagged in ``todo`` whose Hermite guess at the midpoint misses by more than
        ``guess_tol``; returns the new table and the flags of its intervals to check next (the halves
        just made: an interval that passed, or was not flagged, is unchanged and stays as it is).  An
        interval that passes gets its quintic flag from the same midpoint."""
        j = np.flatnonzero(todo)
        xa, xb = self.x_b[j], self.x_b[j + 1]
        xm = 0.5 * (xa + xb)
        Fm = self.F_b[j] + gauss_legendre(self.f, xa, xm)
        guess = self._hermite(Fm, j)
        fm = _at(self.f, xm)
        bad = np.abs(guess - xm) * fm > guess_tol
        quintic = self.quintic
        if quintic is not None:
            quintic = quintic.copy()
            with np.errstate(all="ignore"):  # (f = 0 at a cusp: NaN, not within the tolerance)
                miss = np.abs(self._quintic(Fm, j) - xm) * fm
            quintic[j] = ~bad & (miss <= QUINTIC_TOL)
        if not bad.any():
            return replace(self, quintic=quintic), np.zeros(todo.size, dtype=bool)
        at = j[bad] + 1
        x_b = np.insert(self.x_b, at, xm[bad])
        F_b = np.insert(self.F_b, at, Fm[bad])
        split = np.zeros(todo.size, dtype=bool)
        split[j[bad]] = True
        # interval i of the old table becomes one interval, or two if split: both halves are checked next
        nxt = np.repeat(split, np.where(split, 2, 1))
        f_b = np.insert(self.f_b, at, fm[bad])
        # (a midpoint is never a jump: both one-sided values are f there)
        f_left = None if self.f_left is None else np.insert(self.f_left, at, fm[bad])
        f_right = None if self.f_right is None else np.insert(self.f_right, at, fm[bad])
        if quintic is None or self.df is None or self.fp_b is None:
            return MonotoneTable(self.f, x_b, F_b, f_b, f_left=f_left, f_right=f_right), nxt
        fp_b = np.insert(self.fp_b, at, _at(self.df, xm[bad]))
        return MonotoneTable(self.f, x_b, F_b, f_b, self.df, fp_b, np.repeat(quintic, np.where(split, 2, 1)),
                             f_left, f_right), nxt

    def _hermite(self, y: FloatArray, j: NDArray[np.intp]) -> FloatArray:
        """Cubic Hermite guess of x(F = y) inside interval j (slopes dx/dF = 1/f)."""
        x0, x1 = self.x_b[j], self.x_b[j + 1]
        h = self.F_b[j + 1] - self.F_b[j]
        t = np.where(h > 0.0, (y - self.F_b[j]) / np.where(h > 0.0, h, 1.0), 0.0)
        fa = self.f_b if self.f_right is None else self.f_right  # (f at the interval's ends, from inside it)
        fz = self.f_b if self.f_left is None else self.f_left
        m0 = np.minimum(h / np.maximum(fa[j], 1e-300), 3.0 * (x1 - x0))
        m1 = np.minimum(h / np.maximum(fz[j + 1], 1e-300), 3.0 * (x1 - x0))
        t2, t3 = t * t, t * t * t
        x = (2 * t3 - 3 * t2 + 1) * x0 + (t3 - 2 * t2 + t) * m0 + (-2 * t3 + 3 * t2) * x1 + (t3 - t2) * m1
        return np.asarray(np.clip(x, x0, x1), dtype=np.float64)

    def _quintic(self, y: FloatArray, j: NDArray[np.intp]) -> FloatArray:
        """Quintic Hermite guess of x(F = y) inside interval j: slopes dx/dF = 1/f and curvatures
        d2x/dF2 = -f'/f^3 at both ends (needs ``fp_b``)."""
        assert self.fp_b is not None  # (only called on a table built with df)
        x0, x1 = self.x_b[j], self.x_b[j + 1]
        h = self.F_b[j + 1] - self.F_b[j]
        f0, f1 = self.f_b[j], self.f_b[j + 1]
        t = (y - self.F_b[j]) / h
        m0, m1 = h / f0, h / f1
        c0, c1 = -h * h * self.fp_b[j] / f0**3, -h * h * self.fp_b[j + 1] / f1**3
        t2 = t * t
        t3 = t2 * t
        # the six quintic Hermite basis functions, grouped (1 - t)^3 and t^3 (Horner in t)
        b0 = 1.0 - t3 * (10.0 - t * (15.0 - 6.0 * t))
        b5 = 1.0 - b0
        b1 = t * (1.0 - t2 * (6.0 - t * (8.0 - 3.0 * t)))
        b2 = 0.5 * t2 * (1.0 - t) ** 3
        b3 = 0.5 * t3 * (1.0 - t) ** 2
        b4 = -t3 * (4.0 - t * (7.0 - 3.0 * t))
        x = b0 * x0 + b1 * m0 + b2 * c0 + b3 * c1 + b4 * m1 + b5 * x1
        return np.asarray(np.clip(x, x0, x1), dtype=np.float64)

    def value(self, x: FloatArray) -> FloatArray:
        """F(x), shape (K,)."""
        x = np.clip(np.asarray(x, dtype=np.float64), self.x_b[0], self.x_b[-1])
        j = np.clip(np.searchsorted(self.x_b, x, side="right") - 1, 0, self.x_b.size - 2)
        return self.F_b[j] + gauss_legendre(self.f, self.x_b[j], x, GL_ORDER_PARTIAL)

    def inverse(self, y: FloatArray, newton: bool = True) -> FloatArray:
        """x with F(x) = y for y in [0, total], shape (K,); without ``newton``, the cubic Hermite guess
        (within the table's guess tolerance, in F's units).  With it: the quintic guess in the intervals
        flagged for it, one Newton step from the cubic guess elsewhere."""
        y = np.clip(np.asarray(y, dtype=np.float64), 0.0, self.total)
        lib = native.library()
        if lib is not None:  # the same guesses, compiled (``geometry.native.table_guess``)
            x, j, step = native.table_guess(
                lib, self.x_b, self.F_b, self.f_b if self.f_right is None else self.f_right,
                self.f_b if self.f_left is None else self.f_left, self.fp_b, self.quintic, newton, y)
            if newton and step.any():
                x[step] = self._newton(y[step], j[step], x[step])
            return np.where(y >= self.total, self.x_b[-1], np.where(y <= 0.0, self.x_b[0], x))
        j = np.clip(np.searchsorted(self.F_b, y, side="right") - 1, 0, self.F_b.size - 2)
        x = self._hermite(y, j)
        if newton:
            step = np.ones(y.size, dtype=bool) if self.quintic is None else ~self.quintic[j]
            if not step.all():
                q = ~step
                x[q] = self._quintic(y[q], j[q])
            if step.any():
                x[step] = self._newton(y[step], j[step], x[step])
        # the domain's ends exactly (a Newton step's rounding residue would move an end point)
        return np.where(y >= self.total, self.x_b[-1], np.where(y <= 0.0, self.x_b[0], x))

    def _newton(self, y: FloatArray, j: NDArray[np.intp], x: FloatArray) -> FloatArray:
        """NEWTON_STEPS steps x <- x - (F(x) - y) / f(x) inside interval j."""
        x0, x1 = self.x_b[j], self.x_b[j + 1]
        for _ in range(NEWTON_STEPS):
            err = self.F_b[j] + gauss_legendre(self.f, x0, x, GL_ORDER_PARTIAL) - y
            fx = self.f(x)
            step = np.where(fx > 0.0, err / np.maximum(fx, 1e-300), 0.0)
            x = np.clip(x - step, x0, x1)
        return x
