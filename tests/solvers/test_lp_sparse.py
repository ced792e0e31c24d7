"""``lp.select_rows`` and ``lp.stack_rows`` (the LP's row blocks without scipy's indexing and vstack overhead) give
scipy's matrices entry for entry, explicit zeros and row order kept."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from solvers import lp


def _random_csr(rng: np.random.Generator, rows: int, cols: int) -> sp.csr_matrix:
    A = sp.random(rows, cols, density=float(rng.uniform(0.0, 0.5)), format="csr", random_state=rng)
    if A.nnz:
        A.data[rng.random(A.nnz) < 0.1] = 0.0  # explicit zeros stay
    if rng.random() < 0.5:
        A.indices = A.indices.astype(np.int64)
        A.indptr = A.indptr.astype(np.int64)
    return A


def _same(got: sp.csr_matrix, want: sp.csr_matrix) -> None:
    assert got.shape == want.shape
    np.testing.assert_array_equal(got.indptr, want.indptr)
    np.testing.assert_array_equal(got.indices, want.indices)
    np.testing.assert_array_equal(got.data, want.data)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(0, 40), cols=st.integers(1, 12))
def test_select_rows_is_scipys_row_indexing(seed: int, rows: int, cols: int) -> None:
    rng = np.random.default_rng(seed)
    A = _random_csr(rng, rows, cols)
    which = rng.random(rows) < rng.uniform(0.0, 1.0)
    _same(lp.select_rows(A, which), A[which])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_blocks=st.integers(1, 6), cols=st.integers(1, 12))
def test_stack_rows_is_scipys_vstack(seed: int, n_blocks: int, cols: int) -> None:
    rng = np.random.default_rng(seed)
    blocks = [_random_csr(rng, int(rng.integers(0, 15)), cols) for _ in range(n_blocks)]
    _same(lp.stack_rows(blocks), sp.vstack(blocks, format="csr"))
