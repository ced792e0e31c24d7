"""``solvers.csr.make`` (and ``make_csc``) against scipy's own constructor: the same object (attributes, types,
values) and the same matrix, for random CSR (CSC) arrays on the fast path and off it (the types scipy would
change), and scipy's constructor whenever the module found its fast path disagreeing with scipy's (``_FAST``,
``_FAST_CSC`` off)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from solvers import csr


def _random_csr(seed: int, rows: int, cols: int, itype: type) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, min(cols, 4) + 1, size=rows)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(itype)
    indices = np.concatenate([np.sort(rng.choice(cols, size=c, replace=False)) for c in counts] or [np.zeros(0)])
    data = rng.normal(size=int(indptr[-1]))
    return data, indices.astype(itype), indptr


def _same(got: sp.spmatrix, ref: sp.spmatrix) -> None:
    assert type(got) is type(ref)
    assert set(vars(got)) == set(vars(ref))
    assert got.shape == ref.shape and got.maxprint == ref.maxprint
    for name in ("data", "indices", "indptr"):
        a, b = getattr(got, name), getattr(ref, name)
        assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(got.toarray(), ref.toarray())
    x = np.arange(1.0, ref.shape[1] + 1.0)
    np.testing.assert_array_equal(got @ x, ref @ x)
    np.testing.assert_array_equal(sp.vstack([got, got]).toarray(), sp.vstack([ref, ref]).toarray())
    assert got.has_sorted_indices == ref.has_sorted_indices


def test_the_fast_path_is_taken_on_this_scipy() -> None:
    """(Otherwise the LP runs at scipy's constructor cost and this module is dead weight.)"""
    assert csr._FAST
    data, indices, indptr = _random_csr(0, 5, 7, np.int32)
    A = csr.make(data, indices, indptr, (5, 7))
    assert A.data is data and A.indices is indices and A.indptr is indptr  # (shared, as scipy shares them)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(0, 30), cols=st.integers(1, 30),
       itype=st.sampled_from([np.int32, np.int64]))
def test_make_builds_what_scipy_builds(seed: int, rows: int, cols: int, itype: type) -> None:
    data, indices, indptr = _random_csr(seed, rows, cols, itype)
    ref = sp.csr_matrix((data.copy(), indices.copy(), indptr.copy()), shape=(rows, cols))
    _same(csr.make(data, indices, indptr, (rows, cols)), ref)


def test_arrays_scipy_would_change_go_through_its_constructor() -> None:
    data, indices, indptr = _random_csr(3, 6, 9, np.int32)
    for args in ((data.astype(np.float32), indices, indptr), (data, indices.astype(np.int64), indptr),
                 (np.concatenate([data, [5.0]]), np.concatenate([indices, [0]]).astype(np.int32), indptr)):
        _same(csr.make(*args, (6, 9)), sp.csr_matrix(args, shape=(6, 9)))
    with pytest.raises(ValueError):  # indptr of the wrong length: scipy's own error
        csr.make(data, indices, indptr[:-1], (6, 9))


def test_without_the_fast_path_it_is_scipys_constructor(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(csr, "_FAST", False)
    monkeypatch.setattr(csr, "_build", lambda *a: pytest.fail("fast path taken with _FAST off"))
    data, indices, indptr = _random_csr(4, 6, 9, np.int32)
    _same(csr.make(data, indices, indptr, (6, 9)), sp.csr_matrix((data, indices, indptr), shape=(6, 9)))


def test_a_scipy_setting_other_attributes_turns_the_fast_path_off(monkeypatch: pytest.MonkeyPatch) -> None:
    """The self-check at import compares attribute sets: one scipy sets and the fast path does not -> off."""
    real = sp.csr_matrix.__init__

    def init(self: sp.csr_matrix, *a: object, **k: object) -> None:
        real(self, *a, **k)
        self._new_in_some_scipy = 1

    monkeypatch.setattr(sp.csr_matrix, "__init__", init)
    assert not csr._fast_agrees()


def test_the_csc_fast_path_is_taken_on_this_scipy() -> None:
    """(Otherwise the dense interior point's J x builds through scipy's constructor.)"""
    assert csr._FAST_CSC
    data, indices, indptr = _random_csr(0, 7, 5, np.int32)  # (7 columns of 5 rows)
    A = csr.make_csc(data, indices, indptr, (5, 7))
    assert isinstance(A, sp.csc_matrix)
    assert A.data is data and A.indices is indices and A.indptr is indptr


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 30), cols=st.integers(0, 30),
       itype=st.sampled_from([np.int32, np.int64]))
def test_make_csc_builds_what_scipy_builds(seed: int, rows: int, cols: int, itype: type) -> None:
    data, indices, indptr = _random_csr(seed, cols, rows, itype)  # (column pointers, row indices)
    ref = sp.csc_matrix((data.copy(), indices.copy(), indptr.copy()), shape=(rows, cols))
    _same(csr.make_csc(data, indices, indptr, (rows, cols)), ref)


def test_without_the_csc_fast_path_it_is_scipys_constructor(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(csr, "_FAST_CSC", False)
    monkeypatch.setattr(csr, "_build", lambda *a: pytest.fail("fast path taken with _FAST_CSC off"))
    data, indices, indptr = _random_csr(4, 9, 6, np.int32)
    _same(csr.make_csc(data, indices, indptr, (6, 9)), sp.csc_matrix((data, indices, indptr), shape=(6, 9)))
    with pytest.raises(ValueError):  # indptr of the wrong length: scipy's own error
        monkeypatch.undo()
        csr.make_csc(data, indices, indptr[:-1], (6, 9))
