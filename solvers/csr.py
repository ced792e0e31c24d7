"""CSR matrices from arrays the caller has already made valid, without scipy's constructor checks.

    make(data, indices, indptr, shape) == scipy.sparse.csr_matrix((data, indices, indptr), shape=shape)

The LP builds each window's rows as CSR blocks (``bspline.combination``, ``lp.select_rows``,
``lp.stack_rows``, the jerk rows), ~26 a window.  scipy's constructor spends ~14 us on each checking
and choosing the index type (``get_index_dtype`` with ``check_contents``, ``check_format``) for arrays
these callers build with the right types and shapes: on cam-bench seed 71 (method lp, 6,677 windows)
the constructors took 9.8 s of its 120 s of CPU (under cProfile), ours 6.8 s of that.

``make`` takes the fast path only for arrays that scipy would keep as they are: float64 data, int32
indices and indptr (the type scipy picks for anything that fits), one entry per index, indptr of
shape[0] + 1 from 0 to nnz.  Anything else goes through scipy's constructor.  The fast path sets the
attributes scipy's constructor sets; ``_FAST`` is on only if, for a small matrix, those are exactly
the attributes a scipy-built one has (so a scipy version that sets more falls back, never half-built).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

_INDEX = np.dtype(np.int32)
_DATA = np.dtype(np.float64)


def _build(data: NDArray[Any], indices: NDArray[Any], indptr: NDArray[Any], shape: tuple[int, int],
           cls: type[Any] = sp.csr_matrix) -> Any:
    A = cast(Any, cls).__new__(cls)
    A._shape = (int(shape[0]), int(shape[1]))
    A.maxprint = _MAXPRINT
    A.data, A.indices, A.indptr = data, indices, indptr
    return A


def _reference(cls: type[Any] = sp.csr_matrix) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.int32],
                                                       tuple[int, int]]:
    indptr = [0, 2, 2, 3] if cls is sp.csr_matrix else [0, 2, 2, 3, 3]  # (3 rows or 4 columns)
    return (np.array([1.0, 2.0, 3.0]), np.array([0, 2, 1], dtype=np.int32), np.array(indptr, dtype=np.int32), (3, 4))


def _fast_agrees(cls: type[Any] = sp.csr_matrix) -> bool:
    """Whether the fast path builds, for a small matrix, the object scipy's constructor builds: the same
    attributes (names, values, types) and the same matrix."""
    try:
        data, indices, indptr, shape = _reference(cls)
        ref = cls((data, indices, indptr), shape=shape)
        got = _build(*_reference(cls), cls=cls)
        same = set(vars(ref)) == set(vars(got)) and ref.shape == got.shape and ref.maxprint == got.maxprint
        for name in ("data", "indices", "indptr"):
            a, b = getattr(ref, name), getattr(got, name)
            same = same and a.dtype == b.dtype and np.array_equal(a, b)
        return bool(same and np.array_equal(ref.toarray(), got.toarray()) and got.has_canonical_format)
    except Exception:  # any change in scipy's internals: scipy's constructor every time
        return False


#: what scipy's constructor sets ``maxprint`` to (its default)
_MAXPRINT = sp.csr_matrix((1, 1)).maxprint
_FAST = _fast_agrees()
#: the same for ``make_csc`` (column pointers)
_FAST_CSC = _fast_agrees(sp.csc_matrix)


def _kept(data: NDArray[Any], indices: NDArray[Any], indptr: NDArray[Any], major: int, shape: tuple[int, int]) -> bool:
    """Whether scipy's constructor would keep these arrays as they are (``major``: rows of a CSR, columns of a
    CSC)."""
    return (
        data.dtype == _DATA
        and indices.dtype == _INDEX
        and indptr.dtype == _INDEX
        and data.ndim == indices.ndim == indptr.ndim == 1
        and indptr.size == major + 1
        and data.size == indices.size == int(indptr[-1])
        and int(indptr[0]) == 0
        and max(shape) < 2**31
    )


def make(data: NDArray[Any], indices: NDArray[Any], indptr: NDArray[Any], shape: tuple[int, int]) -> sp.csr_matrix:
    """``scipy.sparse.csr_matrix((data, indices, indptr), shape=shape)``, sharing the arrays as scipy does
    (no copies), without its checks where the arrays are as scipy would keep them (module docstring)."""
    if _FAST and _kept(data, indices, indptr, shape[0], shape):
        return _build(data, indices, indptr, shape)
    return sp.csr_matrix((data, indices, indptr), shape=shape)


def make_csc(data: NDArray[Any], indices: NDArray[Any], indptr: NDArray[Any],
             shape: tuple[int, int]) -> sp.csc_matrix:
    """``scipy.sparse.csc_matrix((data, indices, indptr), shape=shape)`` as ``make`` builds a CSR (the dense
    interior point's J x: ``solvers.ipm.DenseIpm._jx``)."""
    if _FAST_CSC and _kept(data, indices, indptr, shape[1], shape):
        return _build(data, indices, indptr, shape, sp.csc_matrix)
    return sp.csc_matrix((data, indices, indptr), shape=shape)
