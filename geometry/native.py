"""Small C kernels compiled once per machine and loaded with ctypes, with numpy as the fallback.

A grid of 900-9,000 points went through ~15-30 numpy passes a stage, each a few microseconds of overhead plus
its arithmetic: on the flower's v + a schedule ~25 ms of ~35 besides HiGHS.  ``native.c`` (this package's) and
``solvers/native.c`` do such stages point by point in one pass:

- NURBS C and three u-derivatives (``Taylor``, ``nurbs_derivatives``): each knot span's homogeneous spline as a
  Taylor polynomial about the span's midpoint (coefficients from de Boor's basis function derivatives, Piegl &
  Tiller A2.3), Horner per point, the quotient rule; de Boor's basis functions at the point itself on a span's
  start and at the domain's end.  Against scipy's ``BSpline``: ~1e-15 of the coordinates' size (the one kernel
  whose numbers differ from its numpy path's); 8,945 points 4.1 -> 0.5 ms.
- the arc-length map (``arc_length_derivatives``) and the monotone tables' inverse guesses (``table_guess``): the
  same operations in the same order as their numpy code, the same numbers.

The sources are compiled with ``cc`` into the cache directory (CACHE_ENV, else ``$XDG_CACHE_HOME/feedsched`` or
``~/.cache/feedsched``) under names hashed from the source, the flags and the compiler, once per machine (~0.2 s;
written under a temporary name and renamed, so processes compiling at once do not read a partial file).  Without
a C compiler, with an unwritable cache directory or with DISABLE_ENV set to "1", ``load`` returns None and the
callers take their numpy path (tests/geometry/test_native.py, tests/solvers/test_native.py compare the two).
``solvers.ccompile`` compiles CasADi's generated C the same way (``build``).
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
from pathlib import Path
from typing import Any

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


#: ctypes type of array parameters: a pointer, passed as ``ptr(a)`` of a C-contiguous array of the C type that the
#: caller keeps referenced until the call returns (numpy's ``ndpointer`` checks took ~2 us an argument, and the
#: checks are the wrappers' own: each makes its arrays contiguous of the right type first)
P = ctypes.c_void_p


def ptr(a: NDArray[Any]) -> int:
    """The address of ``a``'s data."""
    return int(a.ctypes.data)


def f64(a: object) -> FloatArray:
    """``a`` as a C-contiguous float64 array (itself if it is one)."""
    return np.ascontiguousarray(a, dtype=np.float64)


#: loaded libraries by name (None: could not be built), for the environment at their first use (``reset``)
_LIBS: dict[str, ctypes.CDLL | None] = {}


def _load(source: Path, name: str, declare: Callable[[ctypes.CDLL], None]) -> ctypes.CDLL | None:
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
    types set by ``declare``; None when DISABLE_ENV is set or it cannot be built (the callers' numpy path then).
    Called for every evaluation: it reads DISABLE_ENV and looks the library up (~1.5 us); the cache directory and
    the compiler are read at the first use (``reset`` forgets the libraries, for another environment)."""
    if disabled():
        return None
    try:
        return _LIBS[name]
    except KeyError:
        lib = _LIBS[name] = _load(source, name, declare)
        return lib


def reset() -> None:
    """Forget the loaded libraries: the next use looks for them (and builds them) with the environment then."""
    _LIBS.clear()


def _declare(lib: ctypes.CDLL) -> None:
    i = ctypes.c_int
    lib.fs_nurbs_taylor.restype = ctypes.c_int
    lib.fs_nurbs_taylor.argtypes = [i, i, P, P, i, P, P, P]
    lib.fs_nurbs_eval.restype = ctypes.c_int
    lib.fs_nurbs_eval.argtypes = [i, i, P, P, i, P, P, P, P, i, P, i, i, P]
    lib.fs_arc_ders.restype = None
    lib.fs_arc_ders.argtypes = [i, P, P]
    lib.fs_table_guess.restype = None
    lib.fs_table_guess.argtypes = [i, P, P, P, P, P, P, i, i, P, P, P, P]


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
    U, H = f64(knots), f64(hom)
    i = np.arange(degree, n)
    span = np.ascontiguousarray(i[U[i] < U[i + 1]], dtype=np.int32)
    lo = f64(U[span])
    mid = f64(0.5 * (U[span] + U[span + 1]))
    coef = np.empty((span.size, degree + 1, 4))
    if lib.fs_nurbs_taylor(degree, n, ptr(U), ptr(H), span.size, ptr(span), ptr(mid), ptr(coef)) != 0:
        raise MemoryError("geometry native kernel: no memory for the basis functions")
    return Taylor(degree, U, H, span, lo, mid, coef)


def nurbs_derivatives(lib: ctypes.CDLL, form: Taylor, u: FloatArray, order: int, exact_points: bool = False
                      ) -> FloatArray:
    """C and its u-derivatives up to ``order`` (<= 3) at u (K,) inside the domain, (order + 1, K, 3), from the
    NURBS's ``Taylor`` form; with ``exact_points``, C itself from de Boor's algorithm at u, as on the numpy path."""
    u = f64(u)
    out = np.empty((order + 1, u.size, 3))
    if u.size and lib.fs_nurbs_eval(form.degree, form.hom.shape[0], ptr(form.knots), ptr(form.hom), form.lo.size,
                                    ptr(form.span), ptr(form.lo), ptr(form.mid), ptr(form.coef), u.size, ptr(u),
                                    order, int(exact_points), ptr(out)) != 0:
        raise MemoryError("geometry native kernel: no memory for the basis functions")
    return out


def arc_length_derivatives(lib: ctypes.CDLL, D: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``geometry.toolpath.arc_length_derivatives`` of D (4, K, 3), by the kernel."""
    D = f64(D)
    K = D.shape[1]
    out = np.empty((3, K, 3))
    if K:
        lib.fs_arc_ders(K, ptr(D), ptr(out))
    return out[0], out[1], out[2]


def table_guess(lib: ctypes.CDLL, x_b: FloatArray, F_b: FloatArray, fa: FloatArray, fz: FloatArray,
                fp: FloatArray | None, quintic: NDArray[np.bool_] | None, step: bool, y: FloatArray,
                ) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.bool_]]:
    """``geometry.quadrature.MonotoneTable.inverse``'s guesses at y (K,): x, each point's interval j, and where a
    Newton step is to follow (``step``: the cubic guess was taken).  The same operations in the same order as
    ``MonotoneTable._hermite`` and ``_quintic``: the same numbers."""
    y = f64(y)
    K = y.size
    x, j, newton = np.empty(K), np.empty(K, dtype=np.int64), np.empty(K, dtype=np.uint8)
    use_q = step and quintic is not None and fp is not None
    fp_c = f64(fp) if use_q and fp is not None else None
    q_c = np.ascontiguousarray(quintic, dtype=np.uint8) if use_q and quintic is not None else None
    xb, Fb, fa_c, fz_c = f64(x_b), f64(F_b), f64(fa), f64(fz)
    if K:
        lib.fs_table_guess(xb.size, ptr(xb), ptr(Fb), ptr(fa_c), ptr(fz_c), None if fp_c is None else ptr(fp_c),
                           None if q_c is None else ptr(q_c), int(step), K, ptr(y), ptr(x), ptr(j), ptr(newton))
    return x, j, newton.view(np.bool_)
