"""The solvers package's compiled kernels (``native.c``), loaded by ``geometry.native.load``: compiled once per
machine into its cache, None without a C compiler or with FEEDSCHED_NO_COMPILE=1 (the callers' numpy path).

``h_local``: the time table's integrand dt/dx = d / sqrt(q) inside a piece (``timing.PieceProfile.h_local``), the
same operations in the same order as its numpy code, point by point: the time table's build evaluates it at
~33,000 points in 12 calls and its Newton steps at ~25,000 more (flower loop, v + a), where each numpy pass was a
few microseconds of overhead.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from geometry import native as gnative

FloatArray = NDArray[np.float64]

SOURCE = Path(__file__).with_name("native.c")


def _declare(lib: ctypes.CDLL) -> None:
    lib.fs_h_local.restype = None
    lib.fs_h_local.argtypes = [ctypes.c_int, ctypes.c_double, gnative.F64, ctypes.c_int, ctypes.c_int, gnative.F64,
                               gnative.F64]


def library() -> ctypes.CDLL | None:
    """The kernels, compiled on first use; None when disabled or they cannot be built."""
    return gnative.load(SOURCE, "solvers_native", _declare)


def h_local(lib: ctypes.CDLL, n: int, d: float, c: FloatArray, x0: int, xl: FloatArray) -> FloatArray:
    """d / sqrt(max(q, 0)) at x = x0 + xl (K,) of the profile with n knot intervals, control points c (n + 2,)."""
    xl = np.ascontiguousarray(xl, dtype=np.float64)
    out = np.empty(xl.size)
    if xl.size:
        lib.fs_h_local(n, d, np.ascontiguousarray(c, dtype=np.float64), x0, xl.size, xl, out)
    return out
