"""solvers.kinematics: the per-row reductions over the axes give numpy's reductions along axis 1."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from solvers import kinematics

FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.sampled_from([0.0, -0.0, 1.0]))


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=9), elements=FLOATS))
def test_row_max_and_min_are_numpys(X: np.ndarray) -> None:
    """The same values as np.max / np.min along axis 1, NaN propagated (compared bit for bit but the sign of
    zero, which numpy's reduction does not fix either)."""
    np.testing.assert_array_equal(kinematics.row_max(X), np.max(X, axis=1))
    np.testing.assert_array_equal(kinematics.row_min(X), np.min(X, axis=1))


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(np.bool_, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=9)))
def test_row_any_and_all_are_numpys(B: np.ndarray) -> None:
    np.testing.assert_array_equal(kinematics.row_any(B), np.any(B, axis=1))
    np.testing.assert_array_equal(kinematics.row_all(B), np.all(B, axis=1))


@pytest.mark.parametrize("shape", [(0, 3), (5, 1)])
def test_row_reductions_at_the_edges(shape: tuple[int, int]) -> None:
    """No rows, and one column (a copy: the result is not a view of X)."""
    X = np.arange(float(np.prod(shape))).reshape(shape)
    out = kinematics.row_max(X)
    np.testing.assert_array_equal(out, np.max(X, axis=1))
    out[...] = -1.0
    assert np.all(X >= 0.0)


def test_row_max_does_not_write_its_input() -> None:
    X = np.array([[1.0, 5.0, 2.0], [7.0, 0.0, np.nan]])
    before = X.copy()
    kinematics.row_max(X)
    kinematics.row_min(X)
    np.testing.assert_array_equal(X, before)
