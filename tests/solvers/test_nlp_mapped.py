"""An NLP window's derivatives from the mapped checkpoint function (``nlp._Shape._mapped_problem``, what the
dense interior point evaluates) against CasADi's automatic differentiation of the same window written as one
SX problem (``_Shape._lifted``, the independent oracle: ``DenseIpm`` differentiates it itself), at random
points, for every kind of shape: plain, with cut slots, from and to rest, with the a / j rows, 1-3 axes."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from solvers import nlp
from solvers.ipm import DenseIpm

#: Agreement of values and derivatives, relative to max(1, |oracle|) (both are float64 evaluations of the
#: same expressions in a different order: ~1e-15 relative read on 78-interval windows).
REL_TOL = 1e-11
HYPOTHESIS_EXAMPLES = 25


def _evaluated(d: DenseIpm, x: np.ndarray, p: np.ndarray, lam: np.ndarray) -> list[np.ndarray]:
    """f, grad f, g (extended), J and H (lower) at x in x's coordinates, from one evaluation of each
    of d's functions; g and f also from its value-only function."""
    d._v[:] = d._lx(x)
    d._p[:] = p
    d._lam[:] = lam
    d._eval_full()
    d._eval_fg()
    n, nv, m = d.n, d._v.size, d.m
    o = d._out
    k = 1 + nv + m
    J = np.zeros((m, n))
    J[d._jr, d._jc] = o[k : k + d._nj]
    H = np.zeros(n * n)
    H[d._h_at] = o[k + d._nj :]
    return [o[:1], d._LT @ o[1 : 1 + nv], o[1 + nv : k], J, H.reshape(n, n), d._out_fg.copy()]


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(4, 24), N=st.integers(2, 5),
       axes=st.sampled_from([(0,), (2,), (0, 1), (0, 1, 2)]), with_aj=st.booleans(), slotted=st.booleans(),
       head=st.booleans(), tail=st.booleans())
def test_mapped_derivatives_equal_the_whole_windows_automatic_ones(
    seed: int, n: int, N: int, axes: tuple[int, ...], with_aj: bool, slotted: bool, head: bool, tail: bool,
) -> None:
    shape = nlp._Shape(n, N, axes, with_aj, slotted, head, tail)
    mapped = shape.ipm
    assert mapped is not None
    oracle = DenseIpm(shape._lifted)
    rng = np.random.default_rng(seed)
    assert (mapped.n, mapped.m) == (oracle.n, oracle.m)
    np.testing.assert_array_equal(mapped.linear, oracle.linear)
    for _ in range(3):
        x = rng.uniform(0.2, 1.5, mapped.n)
        p = rng.uniform(0.2, 1.5, mapped._p.size)
        lam = rng.uniform(-1.0, 1.0, mapped.m)
        for name, got, want in zip(("f", "grad", "g", "J", "H", "fg"), _evaluated(mapped, x, p, lam),
                                   _evaluated(oracle, x, p, lam), strict=True):
            assert np.all(np.isfinite(got)), name
            err = np.max(np.abs(got - want) / np.maximum(1.0, np.abs(want)))
            assert err <= REL_TOL, (name, err)


@pytest.mark.parametrize("with_aj", [False, True])
@pytest.mark.parametrize("head", [False, True])
@pytest.mark.parametrize("tail", [False, True])
def test_mapped_cut_slots_equal_the_automatic_ones(with_aj: bool, head: bool, tail: bool) -> None:
    """The cut slots' rows by the mapped slot function (``nlp.slot_sx``: neighbouring slots share two control
    points, so their Hessian blocks overlap) against the whole window's automatic derivatives, every kind of
    slotted window with three axes."""
    inner = test_mapped_derivatives_equal_the_whole_windows_automatic_ones.hypothesis.inner_test  # type: ignore[attr-defined]
    inner(seed=7, n=9, N=3, axes=(0, 1, 2), with_aj=with_aj, slotted=True, head=head, tail=tail)


@pytest.mark.parametrize(("bump", "rise"), [(True, True), (True, False), (False, False)])
@pytest.mark.parametrize("n", [3, 8])
def test_mapped_rest_ends_equal_the_automatic_ones(monkeypatch: pytest.MonkeyPatch, bump: bool, rise: bool,
                                                   n: int) -> None:
    """The rest ends' rows by their own functions (``nlp.RestEnd``: derivatives in the end's z, gathered into
    the window's) against the whole window's automatic derivatives, with and without the bump and the rises
    (the functions are cached by these settings too), on a window whose two ends share a control point (n = 3:
    the head reads p_0 .. p_2, the tail p_2 .. p_4) and on a longer one."""
    monkeypatch.setattr(nlp, "REST_BUMP", bump)
    monkeypatch.setattr(nlp, "REST_RISE", rise)
    inner = test_mapped_derivatives_equal_the_whole_windows_automatic_ones.hypothesis.inner_test  # type: ignore[attr-defined]
    inner(seed=n, n=n, N=3, axes=(0, 1), with_aj=False, slotted=False, head=True, tail=True)
    inner(seed=n + 1, n=n, N=2, axes=(0, 1, 2), with_aj=True, slotted=True, head=True, tail=True)


def test_a_shape_builds_its_whole_window_problem_only_when_asked() -> None:
    """The dense method's problem comes from the functions built once per kind of window; the whole window's
    SX problem (Ipopt's, ``_Shape._lifted``) is built on first use, with the rows the shape was laid out with."""
    shape = nlp._Shape(6, 3, (0, 1), False, True, True, True)
    assert shape.ipm is not None and shape._lifted_sx is None
    assert int(shape._problem["g"].size1()) == shape.rows
    assert shape._lifted_sx is not None


@pytest.mark.parametrize(("na", "with_aj", "N", "head"), [(1, False, 4, True), (2, False, 3, False),
                                                          (3, True, 2, True), (2, True, 5, False)])
@pytest.mark.parametrize(("bump", "rise", "points"), [(True, True, True), (True, False, True), (False, False, False)])
def test_rest_end_chain_rule_equals_the_automatic_derivatives(
    monkeypatch: pytest.MonkeyPatch, na: int, with_aj: bool, N: int, head: bool, bump: bool, rise: bool,
    points: bool,
) -> None:
    """A rest end's values and derivatives by the chain rule through w and the points' (q, q', q'')
    (``nlp._rest_end_mx``, what the dense method evaluates) against CasADi's automatic derivatives of the same
    rows in z (``nlp.rest_end_sx``), at random inputs, with the bump and the rises on and off and with and
    without rest points."""
    monkeypatch.setattr(nlp, "REST_BUMP", bump)
    nr = len(nlp.bspline.REST_RISE_POWERS) if bump and rise else 0
    M = nlp.rest_point_taus(N).size if points else 0
    end = nlp._rest_end_function(na, with_aj, N, head, nr, M)
    rng = np.random.default_rng(na * 1000 + N)
    for values_only, got_fn in ((False, end.derivatives), (True, end.values)):
        ref = nlp.rest_end_sx(na, with_aj, N, head, nr, M, values_only)
        assert got_fn.n_out() == ref.n_out()
        for _ in range(3):
            args = [rng.uniform(0.2, 1.5, ref.sparsity_in(i).shape) for i in range(ref.n_in())]
            if not values_only:
                args[-1] = rng.uniform(-1.0, 1.0, args[-1].shape)
            got, want = got_fn.call(args), ref.call(args)
            for k, (g, w) in enumerate(zip(got, want, strict=True)):
                g, w = np.asarray(ca.DM(g).full()), np.asarray(ca.DM(w).full())
                err = np.max(np.abs(g - w) / np.maximum(1.0, np.abs(w)))
                assert err <= REL_TOL, (values_only, k, err)
