r"""Axis kinematics along the path from the feed and its time derivatives (spec §2).

With sdot = ds/dt, sddot, sdddot and the geometric derivatives x_s, x_ss,
x_sss of each axis (``PathSamples.d1, d2, d3``):

    v = x_s sdot
    a = x_ss sdot^2 + x_s sddot
    j = x_sss sdot^3 + 3 x_ss sdot sddot + x_s sdddot

The feed is either the LP's q = sdot^2 or the NLP's f = sdot, each a function
of s with derivatives ' = d/ds:

    from q:  sdot = sqrt(q),  sddot = q'/2,         sdddot = sqrt(q) q''/2
    from f:  sdot = f,        sddot = f f',         sdddot = f f'^2 + f^2 f''

Shapes: s-like arrays (K,), axis arrays (K, 3); units mm, s.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from geometry.toolpath import PathSamples
from solvers import native

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
FeedDerivs = tuple[FloatArray, FloatArray, FloatArray]


# Reductions over the axes of an axis array (K, n), n >= 1 small (the three axes): the columns combined one
# after the other, in place.  The same values as numpy's reductions along axis 1 (max and min propagate NaN as
# they do), which run an inner loop per row: on (7000, 3) np.max(X, axis=1) took ~480 us, this ~16 us.
def _by_columns(X: NDArray[Any], op: np.ufunc) -> NDArray[Any]:
    out = X[:, 0].copy()
    for i in range(1, X.shape[1]):
        op(out, X[:, i], out=out)
    return out


def row_max(X: FloatArray) -> FloatArray:
    """np.max(X, axis=1) of X (K, n)."""
    return _by_columns(X, np.maximum)


def row_min(X: FloatArray) -> FloatArray:
    """np.min(X, axis=1) of X (K, n)."""
    return _by_columns(X, np.minimum)


def row_any(B: BoolArray) -> BoolArray:
    """np.any(B, axis=1) of B (K, n)."""
    return _by_columns(B, np.logical_or)


def row_all(B: BoolArray) -> BoolArray:
    """np.all(B, axis=1) of B (K, n)."""
    return _by_columns(B, np.logical_and)


def from_q(q: FloatArray, q1: FloatArray, q2: FloatArray) -> FeedDerivs:
    """(sdot, sddot, sdddot) from q, q', q'' (q clipped at 0)."""
    f = np.sqrt(np.maximum(q, 0.0))
    return f, 0.5 * q1, 0.5 * f * q2


def from_f(f: FloatArray, f1: FloatArray, f2: FloatArray) -> FeedDerivs:
    """(sdot, sddot, sdddot) from f, f', f''."""
    return f, f * f1, f * f1 * f1 + f * f * f2


def axis_kinematics(g: PathSamples, sdot: FloatArray, sddot: FloatArray, sdddot: FloatArray) -> tuple[
    FloatArray, FloatArray, FloatArray
]:
    """Axis v, a, j, each (K, 3)."""
    lib = native.library()
    if lib is not None:  # the same numbers, compiled (``solvers.native``)
        return native.axis_kinematics(lib, sdot, sddot, sdddot, g.d1, g.d2, g.d3)
    f = sdot[:, None]
    f2 = f * f  # (the per-point factors on (K, 1) first, then one product per (K, 3) term; no float
    # powers: 1.5x faster than g.d2 * f * f and f**3 on 4e3-1.6e5 points)
    v = g.d1 * f
    a = g.d2 * f2 + g.d1 * sddot[:, None]
    j = g.d3 * (f2 * f) + g.d2 * (3.0 * f * sddot[:, None]) + g.d1 * sdddot[:, None]
    return v, a, j
