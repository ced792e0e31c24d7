"""``geometry.native``: the compiled NURBS kernel against scipy's de Boor evaluation (the numpy path it replaces),
the clamped ends exact, the arc-length map against its numpy formulas, the monotone table's inverse guesses bit
for bit against their numpy code, and the fallbacks (disabled, no compiler, a compiler that fails).  The oracle
tests against geomdl (test_nurbs_oracle.py) run on the kernel where it builds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry import native
from geometry import toolpath as tpm
from geometry.nurbs import NurbsSegment
from geometry.quadrature import MonotoneTable
from tests.geometry.nurbs_factory import random_nurbs

#: kernel against scipy, per derivative order k: |difference| <= this x the largest |C^(k)| over the points (the
#: Taylor form about each span's midpoint and de Boor's recursion round differently; seen: <= 4e-12 on the
#: flower's C''', ~1e-13 on C)
KERNEL_REL_TOL = 1e-9
#: exact points (``exact_points``: de Boor in C) against scipy's de Boor, in units in the last place of the largest
#: control point coordinate (seen: at most 2 over 300 random NURBS, 295 of them bit for bit)
EXACT_POINT_ULPS = 8
#: the arc-length map, the same formulas in C and numpy (sums and products in another order)
ARC_REL_TOL = 1e-13


def _lib() -> object:
    lib = native.library()
    if lib is None:
        pytest.skip("no C compiler (or FEEDSCHED_NO_COMPILE): the numpy path is used")
    return lib


def _numpy_derivatives(seg: NurbsSegment, u: np.ndarray, monkeypatch: pytest.MonkeyPatch) -> np.ndarray:
    with monkeypatch.context() as m:
        m.setenv(native.DISABLE_ENV, "1")
        assert native.library() is None
        return seg.derivatives(u)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), degree=st.integers(1, 7), n_interior=st.integers(0, 12),
       lo=st.floats(-1e3, 1e3), log_width=st.floats(-3.0, 3.0))
def test_kernel_matches_scipy_de_boor(seed: int, degree: int, n_interior: int, lo: float, log_width: float) -> None:
    """Random NURBS (weights 0.3-3, interior knots of multiplicity up to degree - 1, any domain): C, C', C'', C'''
    at random parameters, at every knot and at both ends."""
    _lib()
    mp = pytest.MonkeyPatch()
    try:
        rng = np.random.default_rng(seed)
        hi = lo + 10.0**log_width
        seg = random_nurbs(rng, degree, n_interior, lo, hi).segment()
        a, b = seg.domain
        u = np.concatenate([np.sort(rng.uniform(a, b, 200)), rng.uniform(a, b, 50), seg.breakpoints,
                            np.nextafter(seg.breakpoints, -np.inf), [a, b]])
        got = seg.derivatives(u)
        want = _numpy_derivatives(seg, u, mp)
        for k in range(4):
            scale = float(np.max(np.abs(want[k]))) + 1e-300
            assert np.max(np.abs(got[k] - want[k])) <= KERNEL_REL_TOL * scale, k
        # exact points (emitted positions): de Boor's at u, as scipy's to a few ulps of the control points (the
        # basis functions' sums in another order); the derivatives as before
        exact = seg.derivatives(u, exact_points=True)
        ulp = float(np.spacing(np.max(np.abs(seg.control_points))))
        assert np.max(np.abs(exact[0] - want[0])) <= EXACT_POINT_ULPS * ulp
        for k in range(1, 4):
            scale = float(np.max(np.abs(want[k]))) + 1e-300
            assert np.max(np.abs(exact[k] - want[k])) <= KERNEL_REL_TOL * scale, k
        # the lower orders as asked for alone: the same numbers as in the full evaluation
        np.testing.assert_array_equal(seg.points(u), got[0])
        np.testing.assert_array_equal(seg.speed(u), np.sqrt(np.einsum("ij,ij->i", got[1], got[1])))
    finally:
        mp.undo()


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_clamped_ends_are_the_end_control_points_exactly(degree: int) -> None:
    """Unit end weights: C at the domain's ends is the first and last control point bit for bit (the samples start
    and end on the path's end points), as scipy's evaluation gave them."""
    _lib()
    rng = np.random.default_rng(degree)
    raw = random_nurbs(rng, degree, 6, 0.25, 7.5)
    w = raw.weights.copy()
    w[0] = w[-1] = 1.0
    seg = NurbsSegment.create(degree, raw.knots, raw.control_points, w)
    a, b = seg.domain
    ends = seg.points(np.array([a, b, b + 1.0, a - 1.0]))  # (outside the domain: clipped to it)
    np.testing.assert_array_equal(ends[[0, 3]], raw.control_points[[0, 0]])
    np.testing.assert_array_equal(ends[[1, 2]], raw.control_points[[-1, -1]])


def test_arc_length_map_matches_its_numpy_formulas(monkeypatch: pytest.MonkeyPatch) -> None:
    """C_s, C_ss, C_sss of random NURBS's derivatives, each point's vectors within ARC_REL_TOL of their largest
    component."""
    lib = _lib()
    rng = np.random.default_rng(7)
    D = np.concatenate([(seg := random_nurbs(rng, 3, 8, 0.0, 10.0**e).segment()).derivatives(
        rng.uniform(*seg.domain, 200)) for e in (-2, 0, 2)], axis=1)
    got = native.arc_length_derivatives(lib, D)  # type: ignore[arg-type]
    monkeypatch.setenv(native.DISABLE_ENV, "1")
    want = tpm.arc_length_derivatives(D)
    for g, w in zip(got, want, strict=True):
        scale = np.max(np.abs(w), axis=1, keepdims=True)
        assert np.all(np.abs(g - w) <= ARC_REL_TOL * scale)


def _inverse_numpy(table: MonotoneTable, y: np.ndarray, newton: bool, monkeypatch: pytest.MonkeyPatch) -> np.ndarray:
    with monkeypatch.context() as m:
        m.setenv(native.DISABLE_ENV, "1")
        return table.inverse(y, newton)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), with_df=st.booleans(), with_jump=st.booleans(), newton=st.booleans())
def test_table_inverse_guesses_are_the_numpy_code_bit_for_bit(
    seed: int, with_df: bool, with_jump: bool, newton: bool,
) -> None:
    """F(x) = integral of f = 1 + a sin(b x) (+ a step at a jump) over random edges: ``MonotoneTable.inverse`` compiled
    and in numpy give the same x for y across [0, total], at every breakpoint's F, and outside it (clipped); the
    quintic guess where flagged (with f' given), the cubic guess and its Newton step elsewhere."""
    _lib()
    mp = pytest.MonkeyPatch()
    try:
        rng = np.random.default_rng(seed)
        a, b = rng.uniform(0.0, 0.9), rng.uniform(0.1, 20.0)
        jump = 0.37 if with_jump else np.inf

        def f(x: np.ndarray) -> np.ndarray:
            return np.asarray(1.0 + a * np.sin(b * x) + np.where(x >= jump, 0.5, 0.0), dtype=np.float64)

        def df(x: np.ndarray) -> np.ndarray:
            return np.asarray(a * b * np.cos(b * x), dtype=np.float64)

        edges = np.unique(np.concatenate([[0.0, 1.0], rng.uniform(0.0, 1.0, rng.integers(0, 6)),
                                          [0.37] if with_jump else []]))
        table = MonotoneTable.build(f, edges, guess_tol=10.0 ** rng.uniform(-9, -5),
                                    df=df if with_df and not with_jump else None,
                                    jumps=np.array([0.37]) if with_jump else None, jump_eps=1e-12)
        assert (table.quintic is not None) == (with_df and not with_jump)
        y = np.concatenate([rng.uniform(-0.1, table.total + 0.1, 300), table.F_b, [0.0, table.total]])
        np.testing.assert_array_equal(table.inverse(y, newton), _inverse_numpy(table, y, newton, mp))
    finally:
        mp.undo()


def test_disabled_or_without_a_compiler_the_numpy_path_is_used(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
) -> None:
    monkeypatch.setenv(native.CACHE_ENV, str(tmp_path / "c"))
    monkeypatch.setenv(native.DISABLE_ENV, "1")
    assert native.library() is None
    monkeypatch.delenv(native.DISABLE_ENV)
    native.reset()
    try:
        monkeypatch.setattr(native, "compiler", lambda: None)
        assert native.library() is None
        native.reset()
        # a compiler that fails: no library left behind, the numpy path
        bad = tmp_path / "badcc"
        bad.write_text("#!/bin/sh\necho broken >&2\nexit 1\n")
        bad.chmod(0o755)
        monkeypatch.setattr(native, "compiler", lambda: str(bad))
        assert native.library() is None
        assert not [p for p in (tmp_path / "c").glob("*") if p.suffix in (".so", ".part")]
        seg = random_nurbs(np.random.default_rng(3), 3, 4).segment()
        u = np.linspace(*seg.domain, 50)
        assert seg._native(u, 3) is None
        assert np.isfinite(seg.derivatives(u)).all()
    finally:
        native.reset()


def test_kernel_is_compiled_once_into_the_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    if native.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv(native.CACHE_ENV, str(tmp_path))
    monkeypatch.delenv(native.DISABLE_ENV, raising=False)
    native.reset()
    try:
        assert native.library() is not None
        libs = sorted(tmp_path.glob("geometry_native-*.so"))
        assert len(libs) == 1 and not list(tmp_path.glob("*.part"))
        stamp = libs[0].stat().st_mtime_ns
        native.reset()
        assert native.library() is not None  # found, not compiled again
        assert libs[0].stat().st_mtime_ns == stamp and len(list(tmp_path.iterdir())) == 1
    finally:
        native.reset()


def test_every_kernel_library_builds_where_there_is_a_compiler(monkeypatch: pytest.MonkeyPatch) -> None:
    """A source that does not compile falls back to numpy silently at run time (the same values, slower): here it
    fails (a missing header once left solvers/native.c on the numpy path with every other test green)."""
    from solvers import native as snative

    if native.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.delenv(native.DISABLE_ENV, raising=False)
    assert native.library() is not None
    assert snative.library() is not None
