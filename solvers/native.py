"""The solvers package's compiled kernels (``native.c``), loaded by ``geometry.native.load``: compiled once per
machine into its cache, None without a C compiler or with FEEDSCHED_NO_COMPILE=1 (the callers' numpy path).

``basis``, ``evaluate`` (``solvers.bspline``) and ``axis_kinematics`` (``solvers.kinematics``): the B-spline's
basis weights, q, q', q'', and the axes' v, a, j, each point on its own: the LP's verification grid (~9,000
points), the samples and the checkpoints, ~15 numpy passes each.

``min_ratio``: the tightest axis's bound at each point (the LP's velocity bound vmax^2 / x_s^2, and its caps
amax / |x_ss|, jmax / |x_sss|) on the verification grid.

``h_local``: the time table's integrand dt/dx = d / sqrt(q) (``timing.PieceProfile.h_local``; its end intervals'
closed form too, where the NLP added no bumps or rises): the time table's build evaluates it at ~33,000 points in 12
calls and its Newton steps at ~25,000 more (flower loop, v + a).

Each does the same operations in the same order as its numpy code: the same numbers (tests/solvers/test_native.py).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from geometry import native as gnative
from geometry.native import f64, ptr

FloatArray = NDArray[np.float64]

SOURCE = Path(__file__).with_name("native.c")


def _declare(lib: ctypes.CDLL) -> None:
    i, d, P = ctypes.c_int, ctypes.c_double, gnative.P
    lib.fs_h_local.restype = None
    lib.fs_h_local.argtypes = [i, d, P, i, i, P, i, P, P]
    lib.fs_basis.restype = None
    lib.fs_basis.argtypes = [i, P, d, i, i, P, P]
    lib.fs_evaluate.restype = None
    lib.fs_evaluate.argtypes = [i, P, d, i, i, i, P, P]
    lib.fs_column_reach.restype = ctypes.c_int
    lib.fs_column_reach.argtypes = [i, P, P, P, i, d, P, P]
    lib.fs_min_ratio.restype = None
    lib.fs_min_ratio.argtypes = [i, P, P, d, i, P]
    lib.fs_axis_kinematics.restype = None
    lib.fs_axis_kinematics.argtypes = [i, P, P, P, P, P, P, P]


def library() -> ctypes.CDLL | None:
    """The kernels, compiled on first use; None when disabled or they cannot be built."""
    return gnative.load(SOURCE, "solvers_native", _declare)


def h_local(lib: ctypes.CDLL, n: int, d: float, c: FloatArray, x0: int, xl: FloatArray,
            ends: tuple[float, float, float, float] | None) -> FloatArray:
    """d / sqrt(max(q, 0)) at x = x0 + xl (K,) of the profile with n knot intervals, control points c (n + 2,); with
    ``ends`` (q1, q2 of the first and of the last interval), the end intervals' closed form without bumps or rises
    (``timing.PieceProfile.h_local``)."""
    xl_c, c_c = f64(xl), f64(c)
    q12 = np.asarray(ends if ends is not None else (0.0, 0.0, 0.0, 0.0), dtype=np.float64)
    out = np.empty(xl_c.size)
    if xl_c.size:
        lib.fs_h_local(n, d, ptr(c_c), x0, xl_c.size, ptr(xl_c), int(ends is not None), ptr(q12), ptr(out))
    return out


def basis(lib: ctypes.CDLL, s: FloatArray, d: float, k_lo: int, k_hi: int,
          ) -> tuple[NDArray[np.int64], FloatArray, FloatArray, FloatArray]:
    """``bspline.basis`` (the same numbers)."""
    s_c = f64(s)
    K = s_c.size
    k, W = np.empty(K, dtype=np.int64), np.empty((3, K, 3))
    if K:
        lib.fs_basis(K, ptr(s_c), d, k_lo, k_hi, ptr(k), ptr(W))
    return k, W[0], W[1], W[2]


def evaluate(lib: ctypes.CDLL, c: FloatArray, s: FloatArray, d: float, k_lo: int, hi: int, col0: int,
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``bspline.evaluate`` (the same numbers)."""
    s_c, c_c = f64(s), f64(c)
    K = s_c.size
    out = np.empty((3, K))
    if K:
        lib.fs_evaluate(K, ptr(s_c), d, k_lo, hi, col0, ptr(c_c), ptr(out))
    return out[0], out[1], out[2]


def axis_kinematics(lib: ctypes.CDLL, sdot: FloatArray, sddot: FloatArray, sdddot: FloatArray, d1: FloatArray,
                    d2: FloatArray, d3: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``kinematics.axis_kinematics`` (the same numbers)."""
    f, g, h, x1, x2, x3 = f64(sdot), f64(sddot), f64(sdddot), f64(d1), f64(d2), f64(d3)
    K = f.size
    out = np.empty((3, K, 3))
    if K:
        lib.fs_axis_kinematics(K, ptr(f), ptr(g), ptr(h), ptr(x1), ptr(x2), ptr(x3), ptr(out))
    return out[0], out[1], out[2]


def min_ratio(lib: ctypes.CDLL, X: FloatArray, num: FloatArray, eps: float, square: bool) -> FloatArray:
    """np.min(np.where(x > eps, num / x, np.inf), axis=1) with x = X**2 (``square``) or |X|, X (K, 3), num (3,)."""
    X_c, n_c = f64(X), f64(num)
    K = X_c.shape[0]
    out = np.empty(K)
    if K:
        lib.fs_min_ratio(K, ptr(X_c), ptr(n_c), eps, int(square), ptr(out))
    return out


def column_reach(lib: ctypes.CDLL, k: NDArray[np.int64], W0: FloatArray, cap: FloatArray, ncols: int,
                 min_basis: float, ok: NDArray[np.bool_] | None) -> FloatArray | None:
    """``lp.column_reach`` (the same minima); None if a point's column is outside [0, ncols)."""
    k_c = np.ascontiguousarray(k, dtype=np.int64)
    W_c, cap_c = f64(W0), f64(cap)
    ok_c = None if ok is None else np.ascontiguousarray(ok, dtype=np.uint8)
    out = np.full(ncols, np.inf)
    K = k_c.size
    if K and lib.fs_column_reach(K, ptr(k_c), ptr(W_c), ptr(cap_c), ncols, min_basis,
                                 None if ok_c is None else ptr(ok_c), ptr(out)) != 0:
        return None
    return out
