"""``solvers.ccompile``: the NLP's interval functions compiled to C give the virtual machine's values bit for
bit (random inputs, and whole schedules), are cached on disk, and fall back to the virtual machine without
a compiler or when disabled."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry import examples as ex
from solvers import ccompile, nlp
from solvers.machine import router
from solvers.pipeline import Options, schedule


def _outputs(fun: ca.Function, args: list[np.ndarray]) -> np.ndarray:
    return np.asarray(fun(*args), dtype=np.float64)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), na=st.integers(1, 3), with_aj=st.booleans(), values_only=st.booleans(),
       n=st.integers(1, 12))
def test_compiled_interval_function_equals_the_virtual_machine(
    seed: int, na: int, with_aj: bool, values_only: bool, n: int,
) -> None:
    """Mapped over n intervals, on random inputs spanning magnitudes (and signs, and f^ near 0)."""
    if ccompile._compiler() is None:
        pytest.skip("no C compiler: the virtual machine is used")
    N = 4
    fun = nlp._interval_function(na, with_aj, N, values_only)
    assert fun.is_a("External")
    ref = nlp.interval_sx(na, with_aj, N, values_only)  # (what the virtual machine evaluates)
    assert not ref.is_a("External")
    rng = np.random.default_rng(seed)
    args = []
    for i in range(ref.n_in()):
        shape = (int(ref.size1_in(i)), int(ref.size2_in(i)) * (1 if i == 2 else n))
        args.append(rng.normal(size=shape) * 10.0 ** rng.integers(-4, 4, size=shape))
    got, want = _outputs(fun.map(n), args), _outputs(ref.map(n), args)
    assert np.isfinite(want).any()
    np.testing.assert_array_equal(got, want)


def test_schedule_is_the_same_compiled_or_not(monkeypatch: pytest.MonkeyPatch) -> None:
    """flower x2, lp+nlp: the same samples with the compiled functions and with the virtual machine's."""
    tp, m = ex.flower(2), router()
    compiled = schedule(tp, m, Options(method="lp+nlp", lp_window=60))
    shapes = dict(nlp._SHAPE_CACHE.shapes)
    monkeypatch.setattr(ccompile, "_compiler", lambda: None)  # (not DISABLE_ENV: it turns the NURBS kernel off too)
    nlp._interval_functions.cache_clear()
    monkeypatch.setattr(nlp._SHAPE_CACHE, "shapes", type(nlp._SHAPE_CACHE.shapes)())
    try:
        plain = schedule(tp, m, Options(method="lp+nlp", lp_window=60))
        assert not nlp._interval_function(2, False, 4).is_a("External")
    finally:
        nlp._interval_functions.cache_clear()
    assert shapes and compiled.summary["nlp_windows"] > 0
    np.testing.assert_array_equal(compiled.samples.position, plain.samples.position)
    assert compiled.summary["nlp_iterations"] == plain.summary["nlp_iterations"]


def _small() -> ca.Function:
    x = ca.SX.sym("x", 3)
    return ca.Function("ccompile_probe", [x], [ca.vertcat(ca.sin(x[0]) * x[1], x[2] / (1 + x[0] ** 2))])


def test_compiled_is_cached_on_disk_and_reused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(ccompile.CACHE_ENV, str(tmp_path))
    monkeypatch.delenv(ccompile.DISABLE_ENV, raising=False)
    f = ccompile.compiled(_small())
    assert f.is_a("External")
    libs = sorted(tmp_path.glob("ccompile_probe-*.so"))
    assert len(libs) == 1 and not list(tmp_path.glob("*.part"))
    stamp = libs[0].stat().st_mtime_ns
    g = ccompile.compiled(_small())  # found, not compiled again
    assert libs[0].stat().st_mtime_ns == stamp and len(list(tmp_path.iterdir())) == 1
    x = np.array([0.3, -2.0, 5.0])
    np.testing.assert_array_equal(np.asarray(f(x)), np.asarray(_small()(x)))
    np.testing.assert_array_equal(np.asarray(g(x)), np.asarray(_small()(x)))


def test_without_a_compiler_or_when_disabled_the_function_is_used_as_given(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
) -> None:
    monkeypatch.setenv(ccompile.CACHE_ENV, str(tmp_path / "c"))
    fun = _small()
    monkeypatch.setenv(ccompile.DISABLE_ENV, "1")
    assert ccompile.compiled(fun) is fun
    monkeypatch.delenv(ccompile.DISABLE_ENV)
    monkeypatch.setattr(ccompile, "_compiler", lambda: None)
    assert ccompile.compiled(fun) is fun
    # a compiler that fails: no library left behind, the function as given
    bad = tmp_path / "badcc"
    bad.write_text("#!/bin/sh\necho broken >&2\nexit 1\n")
    bad.chmod(0o755)
    monkeypatch.setattr(ccompile, "_compiler", lambda: str(bad))
    assert ccompile.compiled(fun) is fun
    assert not [p for p in (tmp_path / "c").glob("*") if p.suffix in (".so", ".part")]


def test_the_service_worker_module_loads_the_default_interval_functions() -> None:
    """``service.worker`` (which the service's forkserver imports) builds the default options' interval
    functions and loads the per-point kernels at import, so a solver process forked from it does not build them
    again (a fresh process)."""
    import subprocess
    import sys

    code = (
        "import service.worker\n"
        "from solvers import nlp\n"
        "m = nlp._interval_functions.cache_info().misses\n"
        "assert m >= 6, m\n"
        "for na in (1, 2, 3):\n"
        "    nlp._interval_function(na, False, 4)\n"
        "    nlp._interval_function(na, False, 4, values_only=True)\n"
        "assert nlp._interval_functions.cache_info().misses == m\n"
        "from geometry import native\n"
        "assert native.disabled() or {'geometry_native', 'solvers_native'} <= set(native._LIBS), native._LIBS\n"
    )
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
