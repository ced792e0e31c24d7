"""Uniform quadratic B-spline feed profiles (spec §3).

A profile over a piece [0, L] with knot spacing d = L / n_int has n_int + 2
control points c_0 .. c_{n_int+1}; on knot interval k (s in [k d, (k+1) d],
tau = s/d - k in [0, 1]) only c_k, c_{k+1}, c_{k+2} act:

    q    = c_k (1-tau)^2/2  + c_{k+1} (-2 tau^2 + 2 tau + 1)/2 + c_{k+2} tau^2/2
    q'   = [-c_k (1-tau)    + c_{k+1} (1 - 2 tau)            + c_{k+2} tau] / d
    q''  = [ c_k            - 2 c_{k+1}                      + c_{k+2}    ] / d^2

So at knot k: q = (c_k + c_{k+1})/2 and q' = (c_{k+1} - c_k)/d; fixing two
consecutive control points fixes q and q' there.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from solvers import csr, native

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def basis(
    s: FloatArray, d: float, n_int: int, k_lo: int = 0, k_hi: int | None = None
) -> tuple[IntArray, FloatArray, FloatArray, FloatArray]:
    """Basis weights at piece-local arc lengths s (mm), knot intervals clamped to [k_lo, k_hi].

    Returns:
        k: (K,) index of the first active control point (= knot interval).
        W0, W1, W2: (K, 3) weights of c_k, c_{k+1}, c_{k+2} for q, q' (1/mm), q'' (1/mm^2).
    """
    hi = n_int - 1 if k_hi is None else k_hi
    lib = native.library()
    if lib is not None:  # the same numbers, compiled (``solvers.native``)
        return native.basis(lib, np.asarray(s, dtype=np.float64), d, k_lo, hi)
    x = np.asarray(s, dtype=np.float64) / d
    k = np.clip(np.floor(x), k_lo, hi).astype(np.int64)
    t = x - k
    W0 = np.column_stack([(1 - t) ** 2 / 2, (-2 * t * t + 2 * t + 1) / 2, t * t / 2])
    W1 = np.column_stack([-(1 - t), 1 - 2 * t, t]) / d
    W2 = np.broadcast_to(np.array([1.0, -2.0, 1.0]) / (d * d), W0.shape).copy()
    return k, W0, W1, W2


def design(k: IntArray, W: FloatArray, col0: int, ncols: int) -> sp.csr_matrix:
    """Sparse (K, ncols) matrix with W's rows at columns k - col0 .. k - col0 + 2."""
    K = k.size
    rows = np.repeat(np.arange(K), 3)
    return sp.csr_matrix((W.ravel(), (rows, design_columns(k, col0))), shape=(K, ncols))


def design_columns(k: IntArray, col0: int) -> IntArray:
    """The columns k - col0 .. k - col0 + 2 of each point's three basis functions, row by row (3 K,)."""
    return np.asarray((k[:, None] - col0 + np.arange(3)[None, :]).ravel(), dtype=np.int64)


def combination(k: IntArray, terms: list[tuple[FloatArray, FloatArray]], col0: int, ncols: int) -> sp.csr_matrix:
    """sum_i diag(a_i) design(k, W_i) for terms (a_i (K,), W_i (K, 3)) as one CSR matrix (K, ncols), built on
    the designs' common sparsity (3 non-zeros a row, explicit zeros kept): the same values, summed in the
    same order, as the sparse products and sums, at a fraction of their cost (the LP's rows)."""
    K = k.size
    # (32-bit indices, as scipy would make them: given 64-bit ones it scans them to see that they fit, twice the
    # constructor's ~30 us)
    return csr.make(combination_data(terms).ravel(), design_columns(k, col0).astype(np.int32),
                    np.arange(0, 3 * K + 1, 3, dtype=np.int32), (K, ncols))


def combination_data(terms: list[tuple[FloatArray, FloatArray]]) -> FloatArray:
    """The (K, 3) entries of ``combination``: sum_i a_i[:, None] W_i, summed in the terms' order."""
    a0, W0 = terms[0]
    data = a0[:, None] * W0
    for a, W in terms[1:]:
        data = data + a[:, None] * W
    return np.asarray(data, dtype=np.float64)


def evaluate(
    c: FloatArray, s: FloatArray, d: float, k_lo: int = 0, k_hi: int | None = None, col0: int = 0
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """q, q', q'' at piece-local s of the profile whose control points c start at
    global index ``col0``; knot intervals clamped to [k_lo, k_hi] (default: all of c)."""
    hi = col0 + c.size - 3 if k_hi is None else k_hi
    lib = native.library()
    if lib is not None:  # the same numbers, compiled (``solvers.native``)
        return native.evaluate(lib, c, np.asarray(s, dtype=np.float64), d, k_lo, hi, col0)
    x = np.asarray(s, dtype=np.float64) / d
    k = np.clip(np.floor(x), k_lo, hi).astype(np.int64)
    t = x - k
    i = k - col0
    c0, c1, c2 = c[i], c[i + 1], c[i + 2]
    a2 = c0 - 2.0 * c1 + c2
    a1 = c1 - c0
    # q in the basis form (non-negative weights on [0, 1]), not as (c0 + c1)/2 + a1 t + a2 t^2 / 2:
    # where q dips to ~1e-9 of its neighbours' control points the monomial form cancels to an
    # absolute error of ~1e-16 of them (a relative noise of ~1e-7 in q), and the time quadrature
    # (1 / sqrt(q) to 1e-13) bisected that noise into millions of intervals (bench seed 163: 1.85 M
    # nodes, 3.8 GB).  The basis form is accurate relative to q itself.
    q = value(c0, c1, c2, t)
    return q, (a1 + a2 * t) / d, a2 / (d * d)


def value(c0: FloatArray, c1: FloatArray, c2: FloatArray, t: FloatArray) -> FloatArray:
    """The uniform quadratic B-spline at t in [0, 1] of a knot interval with control points c0, c1, c2, in the
    basis form (non-negative weights: accurate relative to the value itself; see ``evaluate``)."""
    u = 1.0 - t
    return np.asarray(0.5 * (c0 * u * u + c1 * (1.0 + 2.0 * t * u) + c2 * t * t), dtype=np.float64)


def integral_weights(k0: int, k1: int, d: float, col0: int, ncols: int) -> FloatArray:
    """w with w . c = integral of q over knot intervals [k0, k1) (mm^3/s^2 per unit c)."""
    w = np.zeros(ncols)
    idx = np.arange(k0, k1) - col0
    np.add.at(w, idx, d / 6.0)
    np.add.at(w, idx + 1, 2.0 * d / 3.0)
    np.add.at(w, idx + 2, d / 6.0)
    return w


#: The power m of the rest interval's bump b = tau (1 - tau)^m (``rest_bump``).
REST_BUMP_POWER = 2
#: The powers k of the rest interval's rises e_k = tau^2 (1 - tau)^k (``rest_bump``; each k >= 2): one
#: amplitude each.  With the quadratic and the bump, (2,) spans the quartics that vanish at rest; each
#: further power adds a degree.  Flower lp+nlp with the rest points (``solvers.nlp.REST_SUBDIV`` 4):
#: (2,) 2.9945 s, (2, 3) 2.9908, (2, 3, 4) 2.9843, (2, 3, 4, 5) 2.9810, (2, ..., 6) 2.9815 s.
REST_RISE_POWERS: tuple[int, ...] = (2, 3, 4, 5)
#: The powers of the rises the LP of method lp (with jerk) adds to its rest intervals (``rest_shapes``): those of
#: REST_RISE_POWERS first (a rise amplitude list h of length R reads the first R of these: ``rest_bump``), then
#: steeper ones, the rise of power j peaking at r = 2 / (j + 2) from rest.  A jerk-limited start from rest has
#: q ~ s^(4/3) over a few micrometres (on the router's x, amax / jmax = 7.9 ms, 5 um) and q' ~ 2 amax after it;
#: with the quartic-to-septic shapes alone q' rose from 2 a_rest (``solvers.lp``) over much of the rest interval,
#: and each rest end cost 15 / 35 / 47 ms at 0.31 / 1.56 / 2.30 mm knots against Ruckig's jerk-limited optimum
#: on rest-to-rest lines (session 47).  Lines of 1-500 mm / the square corner / the flower, method lp, motion:
#: (2, 3, 4, 5) 0.1051 0.2194 0.4384 1.0519 3.7368 s / 1.1252 / 4.2304 s; + (8, 12, 16, 24) 0.1044 0.2156 0.4184
#: 1.0075 3.6830 / 1.0900 / 4.2217; + (8, 16, 32, 64) ... 0.9943 3.6670 / 1.0796 / 4.2202; + (8, 16, 32, 64, 128)
#: 0.1042 0.2149 0.4161 0.9863 3.6573 / 1.0768 / 4.2170 (short rest-to-rest pieces ~1.2-1.5x the CPU: a cut round
#: more, HiGHS on more columns, the time table over the steeper rest intervals); + (8, 16, 32, 64, 128, 256)
#: ... 0.9841 3.6504 / 1.0761 / 4.2178.  The NLP's rises stay REST_RISE_POWERS: with these its rest windows
#: were slower and no faster in motion (flower lp+nlp 2.9797 -> 3.0025 s with (.., 32, 48, 64)).  Session 48's
#: cap on q* next to rest (``lp.QSTAR_REST_REACH``) let the rows read the jerk leaving rest as it is, and 256
#: gained more than it had: lines of 1 / 5 / 20 / 100 / 500 mm 0.09959 0.21279 0.41565 0.98643 3.65685 s ->
#: 0.09889 0.21133 0.41410 0.98393 3.65003 / the corner 1.06210 -> 1.05980 / the flower 4.21011 -> 4.20499 s, at
#: 0.98-1.09x the CPU; + (256, 512): ... 0.09822 0.21028 0.41281 0.98295 3.65049 / 1.06203 / 4.20294 s at 1.05-1.75x
#: (the 1 mm line ran out of cut rounds: a row 49 nm from rest held in HiGHS's scaled form, not in a; see
#: docs/history.md, session 48).
LP_REST_RISE_POWERS: tuple[int, ...] = (*REST_RISE_POWERS, 8, 16, 32, 64, 128, 256)


def rest_bump(
    s: FloatArray, d: float, k: int, head: bool, g: float, h: Sequence[float] = ()
) -> tuple[FloatArray, FloatArray, FloatArray]:
    r"""What the rest interval's extra shapes add to its q (``solvers.nlp.REST_BUMP``, ``REST_RISE``),
    g b + sum_k h_k e_k, and their s-derivatives, at piece-local s on knot interval k (the piece's first,
    ``head``, or last), with m = REST_BUMP_POWER, the k of the first len(h) of LP_REST_RISE_POWERS (h: one
    amplitude each, or none; the NLP's rises are those of REST_RISE_POWERS) and r the unit distance from rest
    (tau = s / d - k at the head, 1 - tau at the tail), u = 1 - r:

        b = r u^m,      db/dr = u^(m-1) (1 - (m+1) r),     d2b/dr2 = -m u^(m-2) (2 - (m+1) r)
        e_k = r^2 u^k,  de_k/dr = r u^(k-1) (2 - (2+k) r),  d2e_k/dr2 = u^(k-2) (2 u^2 - 4 k r u + k (k-1) r^2)

    (d/ds = +-1/d d/dr).  All are 0 at both ends of the interval, and so are their slopes at the inner
    knot: q + g b + h e keeps q's value at rest and its value and slope at the inner knot.  g adds g / d
    to |q'| at rest (the acceleration step); e_k has slope 0 at rest too, so h shapes the acceleration
    after the step without moving it (the bump alone is spent on the step where the step is at its bound).
    g, h in mm^2/s^2; returns (K,) mm^2/s^2, mm/s^2, 1/s^2."""
    t = np.asarray(s, dtype=np.float64) / d - k
    r = t if head else 1.0 - t
    sign = 1.0 if head else -1.0
    powers = _rise_powers(len(h))
    up = _powers(1.0 - r, (REST_BUMP_POWER, *powers))
    bb = _bump_shape(r, up)
    b = (g * bb[0], g * bb[1], g * bb[2])
    used = [i for i, hk in enumerate(h) if hk]
    if used:
        e = _rise_block(r, tuple(powers[i] for i in used), up)
        hu = np.asarray([h[i] for i in used], dtype=np.float64).reshape(-1, 1)
        b = (_add_rows(b[0], hu * e[0].T), _add_rows(b[1], hu * e[1].T), _add_rows(b[2], hu * e[2].T))
    return b[0], sign * b[1] / d, b[2] / (d * d)


def _add_rows(x: FloatArray, rows: FloatArray) -> FloatArray:
    """x + rows[0] + rows[1] + ... (rows (J, K)), added left to right: ``rest_bump``'s sum of its shapes in the
    order they always were (numpy's reductions may pair them)."""
    out: FloatArray = x + rows[0]
    for row in rows[1:]:
        out += row
    return out


def add_rest_bump(
    q3: tuple[FloatArray, FloatArray, FloatArray], s: FloatArray, d: float, k: int, head: bool, g: float,
    h: Sequence[float] = (),
) -> None:
    """Add ``rest_bump`` in place to q, q', q'' (``q3``, each (K,)) at those of the piece-local points s that lie on
    the rest interval k (the piece's first, ``head``: s < (k + 1) d; or last: s > k d); nothing where g and h are
    all 0 (``timing.PieceProfile.feed``, ``solvers.lp.WindowLP._eval``)."""
    if not (g or any(h)):
        return
    at = on_rest_interval(s, d, k, head)
    if at.any():
        for x, bx in zip(q3, rest_bump(s[at], d, k, head, g, h), strict=True):
            x[at] += bx


def on_rest_interval(s: FloatArray, d: float, k: int, head: bool) -> NDArray[np.bool_]:
    """Which of the piece-local points s (K,) lie on the rest interval k, the piece's first (``head``) or last:
    where the rest shapes are added (``add_rest_bump``) and where the LP has their columns
    (``solvers.lp.WindowLP._basis``).  The interval of a point is ``evaluate``'s and ``basis``', floor(s / d)
    clamped: a point exactly on the last interval's inner knot is in it, and takes its shapes too (with
    s > k d it took the interval's spline without them, a q'' neither side's: bench seeds 1478 and 1617 lp
    read jerk 1.11 and 1.25 x there, exactly at the knot, 0.54 / 0.20 and 0.47 / 0.61 x either side)."""
    k_s = np.floor(np.asarray(s, dtype=np.float64) / d)
    return np.asarray(k_s <= k if head else k_s >= k)


def _rise_powers(n: int) -> tuple[int, ...]:
    """The powers of n rise amplitudes: the first n of LP_REST_RISE_POWERS (REST_RISE_POWERS for the NLP's)."""
    if n > len(LP_REST_RISE_POWERS):
        raise ValueError(f"{n} rise amplitudes, at most {len(LP_REST_RISE_POWERS)} (LP_REST_RISE_POWERS)")
    return LP_REST_RISE_POWERS[:n]


#: ``_powers`` builds u^k for k up to this by successive products (the NLP's rises, k <= 5, as they always were);
#: a higher k as u^(k // 2) u^(k - k // 2).
_PRODUCT_TOP = 8


def _powers(u: Any, exps: Sequence[int], below: int = 2) -> dict[int, Any]:
    """u^k for each k of ``exps`` and the ``below`` exponents under it (floats, arrays or CasADi expressions), as
    {k: u^k}, by products (``_power_plan``): numpy's float ``u ** j`` calls ``pow`` per element for j > 2 (the
    shapes' powers were ~5 % of a flower loop with jerk), and 127 successive products for u^128 took ~10 ms of the
    1-loop flower's LP with jerk (session 47)."""
    out: dict[int, Any] = {0: 1.0, 1: u}
    for k, a, b in _power_plan(tuple(exps), below):
        out[k] = out[a] * out[b]
    return out


@functools.lru_cache(maxsize=32)
def _power_plan(exps: tuple[int, ...], below: int) -> tuple[tuple[int, int, int], ...]:
    """The products (k, a, b), u^k = u^a u^b in this order, that ``_powers`` makes: up to _PRODUCT_TOP one after
    the other (u^k = u^(k-1) u: the NLP's rises, k <= 5, as they always were), above it by halves."""
    plan: list[tuple[int, int, int]] = []
    have = {0, 1}

    def make(k: int) -> None:
        if k in have:
            return
        if k <= _PRODUCT_TOP:
            make(k - 1)
            plan.append((k, k - 1, 1))
        else:
            make(k // 2)
            make(k - k // 2)
            plan.append((k, k // 2, k - k // 2))
        have.add(k)

    for k in sorted({k - i for k in exps for i in range(below + 1)}):
        make(k)
    return tuple(plan)


def _bump_shape(r: FloatArray, up: dict[int, Any]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The bump b = r (1 - r)^m (m = REST_BUMP_POWER) and its first two r-derivatives (``rest_bump``); ``up`` the
    powers of 1 - r (``_powers``)."""
    m = REST_BUMP_POWER
    return r * up[m], up[m - 1] * (1.0 - (m + 1) * r), -m * up[m - 2] * (2.0 - (m + 1) * r)


def _rise_block(r: FloatArray, powers: tuple[int, ...], up: dict[int, Any]) -> tuple[FloatArray, FloatArray,
                                                                                      FloatArray]:
    """The rises e_j = r^2 (1 - r)^j of ``powers`` (J,) and their first two r-derivatives at r (K,), as three
    (K, J) arrays, one column per power (``rest_bump``, ``rest_shapes``); ``up`` the powers of 1 - r (``_powers``).
    One numpy operation per term over all the powers (they were ~5 % of the flower's CPU with jerk, one power
    at a time), each element the same products in the same order as the scalar form

        e_j = r r u^j,   de_j/dr = r u^(j-1) (2 - (2 + j) r),   d2e_j/dr2 = u^(j-2) (2 u u - 4 j r u + j (j-1) r r)."""
    rr = np.asarray(r, dtype=np.float64).reshape(-1, 1)
    u = np.asarray(up[1], dtype=np.float64).reshape(-1, 1)
    jj = np.asarray(powers, dtype=np.float64)
    uj = np.empty((3, len(powers), rr.shape[0]))
    for c, j in enumerate(powers):
        uj[0, c], uj[1, c], uj[2, c] = up[j], up[j - 1], up[j - 2]
    u0, u1, u2 = uj[0].T, uj[1].T, uj[2].T
    return (rr * rr * u0, rr * u1 * (2.0 - (2.0 + jj) * rr),
            u2 * (2.0 * u * u - 4.0 * jj * rr * u + jj * (jj - 1.0) * rr * rr))


#: Amplitudes of a rest interval's shapes in ``rest_shapes``: the bump, then one rise per LP_REST_RISE_POWERS.
REST_SHAPES = 1 + len(LP_REST_RISE_POWERS)


def rest_shapes(s: FloatArray, d: float, k: int, head: bool) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The rest interval's shapes one by one (``rest_bump`` with a unit amplitude each: the bump, then the rises of
    LP_REST_RISE_POWERS) and their s-derivatives at piece-local s on knot interval k (the piece's first, ``head``,
    or last): three (K, REST_SHAPES) arrays, 1, 1/mm, 1/mm^2 per unit amplitude.  What the LP of method lp
    adds to q in its rest intervals (``solvers.lp.WindowSpec.rest_shapes``)."""
    t = np.asarray(s, dtype=np.float64) / d - k
    r = t if head else 1.0 - t
    sign = 1.0 if head else -1.0
    up = _powers(1.0 - r, (REST_BUMP_POWER, *LP_REST_RISE_POWERS))
    bump, rise = _bump_shape(r, up), _rise_block(r, LP_REST_RISE_POWERS, up)
    return (np.column_stack([bump[0], rise[0]]), sign * np.column_stack([bump[1], rise[1]]) / d,
            np.column_stack([bump[2], rise[2]]) / (d * d))


def rest_shape_integrals(d: float) -> FloatArray:
    """Integral over the rest interval of each ``rest_shapes`` shape (REST_SHAPES,), mm per unit amplitude:
    d B(2, m + 1) for the bump, d B(3, j + 1) for the rise of power j (B the beta function)."""
    m = REST_BUMP_POWER
    out = [1.0 / ((m + 1) * (m + 2))] + [2.0 / ((j + 1) * (j + 2) * (j + 3)) for j in LP_REST_RISE_POWERS]
    return np.asarray(out, dtype=np.float64) * d


def rest_shape_peaks() -> FloatArray:
    """The largest value on [0, 1] of each ``rest_shapes`` shape (REST_SHAPES,), per unit amplitude: the bump
    r (1 - r)^m at r = 1 / (m + 1), the rise r^2 (1 - r)^j at r = 2 / (j + 2) (1.3e-4 for j = 128; as 4 (j / (j + 2))^j
    / (j + 2)^2 in floats: j^j overflows a float from j = 144)."""
    m = REST_BUMP_POWER
    out = [m**m / (m + 1) ** (m + 1)] + [4.0 * (j / (j + 2)) ** j / (j + 2) ** 2 for j in LP_REST_RISE_POWERS]
    return np.asarray(out, dtype=np.float64)


def rest_bump_quotient(r: Any, g: Any, h: Sequence[Any] = ()) -> Any:
    """(g b + sum_k h_k e_k) / r = g (1 - r)^m + sum_k h_k r (1 - r)^k of ``rest_bump`` at the unit distance r
    from rest (floats, arrays or CasADi expressions): what the shapes add under the root of a rest interval's
    time integrand, where q / r is taken with r = w^2 (``timing.PieceProfile.h_local``,
    ``timing.rest_interval_times``, ``solvers.nlp._Shape._rest_rows``)."""
    powers = _rise_powers(len(h))
    up = _powers(1.0 - r, (REST_BUMP_POWER, *powers), below=0)
    out = g * up[REST_BUMP_POWER]
    for hk, j in zip(h, powers, strict=True):
        out = out + hk * (r * up[j])
    return out
