"""``bspline.combination`` (the LP's rows built on the designs' common sparsity) against the sparse products
it replaces: sum_i diag(a_i) @ design(k, W_i), bit for bit, on random knots, points and coefficients."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from solvers import bspline


def _reference(k: np.ndarray, terms: list[tuple[np.ndarray, np.ndarray]], col0: int, ncols: int) -> np.ndarray:
    out = None
    for a, W in terms:
        part = sp.diags(a) @ bspline.design(k, W, col0, ncols)
        out = part if out is None else out + part
    assert out is not None
    return np.asarray(sp.csr_matrix(out).toarray())


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_terms=st.integers(1, 3), points=st.integers(1, 60))
def test_combination_equals_the_sparse_products(seed: int, n_terms: int, points: int) -> None:
    rng = np.random.default_rng(seed)
    d, n_int, k0 = 0.7, 40, 5
    k1 = k0 + 20
    s = rng.uniform(k0 * d, k1 * d, points)
    s[: points // 4] = np.floor(s[: points // 4] / d) * d  # on knots: zero weights in the designs
    k, W0, W1, W2 = bspline.basis(s, d, n_int, k0, k1 - 1)
    ncols = k1 - k0 + 2
    coef = [rng.normal(size=points) * 10.0 ** rng.integers(-6, 6) for _ in range(n_terms)]
    coef[0][: points // 5] = 0.0  # rows of zeros too
    terms = list(zip(coef, (W0, W1, W2)[:n_terms], strict=False))
    got = bspline.combination(k, terms, k0, ncols)
    assert got.shape == (points, ncols)
    np.testing.assert_array_equal(got.toarray(), _reference(k, terms, k0, ncols))
