"""Small C kernels compiled once per machine and loaded with ctypes, with numpy as the fallback.

Evaluating a NURBS segment with ``scipy.interpolate.BSpline`` takes one call per derivative order, and
the quotient rule and the map to arc-length derivatives take ~30 numpy passes over (K, 3) arrays: on
the flower's 9,000-point verification grid, 3.5 ms and 0.7 ms (the v + a schedule's largest share
after HiGHS).  ``native.c`` does the same per point in one pass (de Boor's basis function
derivatives, Piegl & Tiller A2.3, then the same quotient rule and arc-length formulas, in the same
order of operations).

The source is compiled with ``cc`` into the cache directory (CACHE_ENV, else ``$XDG_CACHE_HOME/feedsched``
or ``~/.cache/feedsched``) under a name hashed from the source, the flags and the compiler, once per
machine (~0.2 s; written under a temporary name and renamed, so processes compiling at once do not read
a partial file).  Without a C compiler, with an unwritable cache directory or with DISABLE_ENV set to
"1", ``library`` returns None and the callers evaluate with numpy and scipy: the same values to
rounding (tests/geometry/test_native.py).  ``solvers.ccompile`` compiles CasADi's generated C the same
way (``build``).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: environment variables: the cache directory, and "1" to use numpy (and CasADi's virtual machine) only
CACHE_ENV = "FEEDSCHED_CACHE_DIR"
DISABLE_ENV = "FEEDSCHED_NO_COMPILE"
#: compile flags (after the compiler): optimised, position-independent, exact IEEE arithmetic (no fused
#: multiply-adds, no fast-math: the same operations, rounded the same way, as written)
CFLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math")
#: longest a compile may take (s) before the fallback is used
COMPILE_TIMEOUT_S = 120.0
#: the geometry package's kernels, next to this module
SOURCE = Path(__file__).with_name("native.c")


def cache_dir() -> Path:
    """Where compiled libraries are kept."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "feedsched"


def disabled() -> bool:
    """DISABLE_ENV is set (to anything but "" or "0")."""
    return os.environ.get(DISABLE_ENV, "") not in ("", "0")


def compiler() -> str | None:
    """The C compiler: $CC, else cc, else gcc; None without one."""
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


def build(cc: str, name: str, source: bytes, flags: tuple[str, ...], extra: bytes = b"") -> Path:
    """The shared library of C ``source`` in the cache directory, compiled with ``cc`` and ``flags`` unless it is
    there already (its name hashes the source, the flags, ``extra`` and the compiler).  Raises OSError or
    subprocess.SubprocessError if it cannot be compiled or written."""
    key = hashlib.sha256(b"\0".join([source, " ".join(flags).encode(), extra, cc.encode()])).hexdigest()[:20]
    out = cache_dir() / f"{name}-{key}.so"
    if out.exists():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    part = out.with_name(f"{out.name}.{os.getpid()}.part")
    try:
        with tempfile.TemporaryDirectory(prefix="feedsched-cc-") as tmp:
            src = Path(tmp) / f"{name}.c"
            src.write_bytes(source)
            subprocess.run([cc, *flags, str(src), "-o", str(part), "-lm"],
                           check=True, capture_output=True, timeout=COMPILE_TIMEOUT_S)
        os.replace(part, out)
    finally:
        part.unlink(missing_ok=True)
    return out


_F64 = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
_I32 = np.ctypeslib.ndpointer(dtype=np.int32, flags="C_CONTIGUOUS")
_I64 = np.ctypeslib.ndpointer(dtype=np.int64, flags="C_CONTIGUOUS")
_U8 = np.ctypeslib.ndpointer(dtype=np.uint8, flags="C_CONTIGUOUS")
#: ctypes argument types of array parameters, for the packages' ``declare`` functions
F64, I32, I64, U8 = _F64, _I32, _I64, _U8


@cache
def _load(source: Path, name: str, declare: Callable[[ctypes.CDLL], None], cache_env: str | None,
          xdg: str | None, cc_env: str | None) -> ctypes.CDLL | None:
    """The library of ``source`` for these values of CACHE_ENV, XDG_CACHE_HOME and CC (``load``)."""
    cc = compiler()
    if cc is None:
        return None
    try:
        lib = ctypes.CDLL(str(build(cc, name, source.read_bytes(), CFLAGS)))
    except (OSError, subprocess.SubprocessError):
        return None
    declare(lib)
    return lib


def load(source: Path, name: str, declare: Callable[[ctypes.CDLL], None]) -> ctypes.CDLL | None:
    """The shared library of C ``source`` (compiled into the cache on first use, ``build``) with its functions'
    types set by ``declare``; None when disabled or it cannot be built (the callers' numpy path then).  (Called
    for every evaluation: it reads the environment only, ~1 us.)"""
    env = os.environ
    if env.get(DISABLE_ENV, "") not in ("", "0"):
        return None
    return _load(source, name, declare, env.get(CACHE_ENV), env.get("XDG_CACHE_HOME"), env.get("CC"))


def _declare(lib: ctypes.CDLL) -> None:
    lib.fs_nurbs_taylor.restype = ctypes.c_int
    lib.fs_nurbs_taylor.argtypes = [ctypes.c_int, ctypes.c_int, _F64, _F64, ctypes.c_int, _I32, _F64, _F64]
    lib.fs_nurbs_eval.restype = ctypes.c_int
    lib.fs_nurbs_eval.argtypes = [ctypes.c_int, ctypes.c_int, _F64, _F64, ctypes.c_int, _I32, _F64, _F64, _F64,
                                  ctypes.c_int, _F64, ctypes.c_int, _F64]
    lib.fs_arc_ders.restype = None
    lib.fs_arc_ders.argtypes = [ctypes.c_int, _F64, _F64, _F64, _F64]
    lib.fs_table_guess.restype = None
    lib.fs_table_guess.argtypes = [ctypes.c_int, _F64, _F64, _F64, _F64, ctypes.c_void_p, ctypes.c_void_p,
                                   ctypes.c_int, ctypes.c_int, _F64, _F64, _I64, _U8]


def library() -> ctypes.CDLL | None:
    """The geometry package's kernels (``native.c``), compiled on first use; None when disabled or it cannot be
    built."""
    return load(SOURCE, "geometry_native", _declare)


@dataclass(frozen=True)
class Taylor:
    """A NURBS's homogeneous B-spline [w P, w] as a polynomial on each non-empty knot span j: span starts ``lo``
    (m,), the midpoints ``mid`` (m,) the Taylor expansions are about, and the coefficients ``coef`` (m, p + 1, 4),
    coef[j, k] = A^(k)(mid[j]) / k! (de Boor's basis function derivatives at the midpoint)."""

    degree: int
    knots: FloatArray
    hom: FloatArray
    span: NDArray[np.int32]
    lo: FloatArray
    mid: FloatArray
    coef: FloatArray


def taylor(lib: ctypes.CDLL, degree: int, knots: FloatArray, hom: FloatArray) -> Taylor:
    """The ``Taylor`` form of the NURBS of ``degree``, ``knots`` (n + p + 1,) and homogeneous control points ``hom``
    [w P, w] (n, 4).

    About the midpoint, |t| <= h / 2 on a span of length h: each term c_k t^k is at most ~2^-k of its size at
    the span's start, and the values agree with de Boor's evaluation to ~1e-15 of the control points' size
    (tests/geometry/test_native.py)."""
    n = hom.shape[0]
    U = np.ascontiguousarray(knots, dtype=np.float64)
    H = np.ascontiguousarray(hom, dtype=np.float64)
    i = np.arange(degree, n)
    span = np.ascontiguousarray(i[U[i] < U[i + 1]], dtype=np.int32)
    lo = np.ascontiguousarray(U[span])
    mid = np.ascontiguousarray(0.5 * (U[span] + U[span + 1]))
    coef = np.empty((span.size, degree + 1, 4))
    if lib.fs_nurbs_taylor(degree, n, U, H, span.size, span, mid, coef) != 0:
        raise MemoryError("geometry native kernel: no memory for the basis functions")
    return Taylor(degree, U, H, span, lo, mid, coef)


def nurbs_derivatives(lib: ctypes.CDLL, form: Taylor, u: FloatArray, order: int) -> FloatArray:
    """C and its u-derivatives up to ``order`` (<= 3) at u (K,) inside the domain, (order + 1, K, 3), from the
    NURBS's ``Taylor`` form."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    out = np.empty((order + 1, u.size, 3))
    if u.size and lib.fs_nurbs_eval(form.degree, form.hom.shape[0], form.knots, form.hom, form.lo.size, form.span,
                                    form.lo, form.mid, form.coef, u.size, u, order, out) != 0:
        raise MemoryError("geometry native kernel: no memory for the basis functions")
    return out


def arc_length_derivatives(lib: ctypes.CDLL, D: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``geometry.toolpath.arc_length_derivatives`` of D (4, K, 3), by the kernel."""
    D = np.ascontiguousarray(D, dtype=np.float64)
    K = D.shape[1]
    d1, d2, d3 = np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3))
    if K:
        lib.fs_arc_ders(K, D, d1, d2, d3)
    return d1, d2, d3


def table_guess(lib: ctypes.CDLL, x_b: FloatArray, F_b: FloatArray, fa: FloatArray, fz: FloatArray,
                fp: FloatArray | None, quintic: NDArray[np.bool_] | None, step: bool, y: FloatArray,
                ) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.bool_]]:
    """``geometry.quadrature.MonotoneTable.inverse``'s guesses at y (K,): x, each point's interval j, and where a
    Newton step is to follow (``step``: the cubic guess was taken).  The same operations in the same order as
    ``MonotoneTable._hermite`` and ``_quintic``: the same numbers."""
    y = np.ascontiguousarray(y, dtype=np.float64)
    K = y.size
    x, j, newton = np.empty(K), np.empty(K, dtype=np.int64), np.empty(K, dtype=np.uint8)
    use_q = step and quintic is not None and fp is not None
    fp_c = np.ascontiguousarray(fp, dtype=np.float64) if use_q and fp is not None else None
    q_c = np.ascontiguousarray(quintic, dtype=np.uint8) if use_q and quintic is not None else None
    if K:
        lib.fs_table_guess(x_b.size, np.ascontiguousarray(x_b), np.ascontiguousarray(F_b),
                           np.ascontiguousarray(fa), np.ascontiguousarray(fz),
                           None if fp_c is None else fp_c.ctypes.data, None if q_c is None else q_c.ctypes.data,
                           int(step), K, y, x, j, newton)
    return x, j, newton.view(np.bool_)
