"""``solvers.native``: the time table's integrand compiled (``PieceProfile.h_local`` inside the piece) gives its numpy
code's values bit for bit, on random profiles (the end intervals' closed form, segment offsets x0, points outside
the piece clipped); profiles with the NLP's feed (f_mask) keep the numpy path."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry import native as gnative
from solvers import native
from solvers.timing import PieceProfile


def _numpy_h(prof: PieceProfile, x0: int, xl: np.ndarray, mp: pytest.MonkeyPatch) -> np.ndarray:
    with mp.context() as m:
        m.setenv(gnative.DISABLE_ENV, "1")
        assert native.library() is None
        return prof.h_local(x0, xl)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 40), bumps=st.booleans())
def test_h_local_compiled_is_the_numpy_code_bit_for_bit(seed: int, n: int, bumps: bool) -> None:
    if native.library() is None:
        pytest.skip("no C compiler (or FEEDSCHED_NO_COMPILE): the numpy path is used")
    mp = pytest.MonkeyPatch()
    try:
        rng = np.random.default_rng(seed)
        d = 10.0 ** rng.uniform(-2, 1)
        c = rng.uniform(0.0, 1e4, n + 2) * 10.0 ** rng.uniform(-3, 3)
        c[rng.random(n + 2) < 0.1] = 0.0  # (q touching 0 inside: h = inf, as in numpy)
        c[0], c[-1] = -c[1], -c[-2]  # rest at both ends
        g = (float(rng.uniform(-1, 1) * c[1]), 0.0) if bumps else (0.0, 0.0)
        h = ((float(rng.uniform(0, 1) * c[1]), 0.0, 0.0, 0.0), ()) if bumps else ((), ())
        prof = PieceProfile(0.0, n * d, d, c, rest_g=g, rest_h=h)
        for x0 in (0, int(rng.integers(0, n))):
            xl = np.concatenate([rng.uniform(-x0 - 0.5, n - x0 + 0.5, 400), np.arange(-x0, n - x0 + 1, 0.5)])
            with np.errstate(all="ignore"):
                got = prof.h_local(x0, xl)
            np.testing.assert_array_equal(got, _numpy_h(prof, x0, xl, mp))
    finally:
        mp.undo()


def test_profiles_with_the_nlps_feed_take_the_numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []
    real = native.h_local

    def counted(*a: object) -> np.ndarray:
        calls.append(1)
        return real(*a)  # type: ignore[arg-type]

    monkeypatch.setattr(native, "h_local", counted)
    n, d = 6, 1.0
    c = np.array([-1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 1.0, -1.0])
    x = np.linspace(1.0, n - 1.0, 50)
    plain = PieceProfile(0.0, n * d, d, c).h_local(0, x)
    assert calls or native.library() is None
    calls.clear()
    p = np.sqrt(np.abs(c))
    mask = np.array([False, False, True, True, False, False])
    mixed = PieceProfile(0.0, n * d, d, c, p=p, f_mask=mask).h_local(0, x)
    assert not calls
    k = np.clip(np.floor(x).astype(int), 0, n - 1)
    np.testing.assert_array_equal(mixed[~mask[k]], plain[~mask[k]])


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), K=st.integers(0, 300))
def test_grid_kernels_are_the_numpy_code_bit_for_bit(seed: int, K: int) -> None:
    """bspline.basis and evaluate, kinematics.axis_kinematics, lp._min_ratio and lp.column_reach compiled and in numpy,
    on random points (some outside the clamped intervals), control points, geometry (some axes flat) and caps."""
    from geometry.toolpath import PathSamples
    from solvers import bspline, kinematics, lp

    if native.library() is None:
        pytest.skip("no C compiler (or FEEDSCHED_NO_COMPILE): the numpy path is used")
    rng = np.random.default_rng(seed)
    n, d = int(rng.integers(3, 30)), float(10.0 ** rng.uniform(-2, 1))
    s = np.sort(rng.uniform(-0.2 * d, (n + 0.2) * d, K))
    c = rng.uniform(-1.0, 1e3, n + 2)
    k_lo, k_hi = int(rng.integers(0, 2)), n - 1 - int(rng.integers(0, 2))
    D = rng.normal(size=(3, K, 3)) * 10.0 ** rng.uniform(-3, 3, size=(3, 1, 1))
    D[:, rng.random(K) < 0.2, int(rng.integers(0, 3))] = 0.0
    g = PathSamples(s, np.zeros((K, 3)), D[0], D[1], D[2])
    num = rng.uniform(1.0, 1e4, 3)
    ok = rng.random(K) < 0.8
    k_basis, W0, *_ = bspline.basis(s, d, n, k_lo, k_hi)
    cap = rng.uniform(0.0, 1e4, K)

    def everything() -> list[np.ndarray]:
        kb, *W = bspline.basis(s, d, n, k_lo, k_hi)
        q3 = bspline.evaluate(c, s, d, k_lo, k_hi)
        vaj = kinematics.axis_kinematics(g, *kinematics.from_q(*q3))
        ratios = [lp._min_ratio(X, num, sq) for X in D for sq in (True, False)]
        reach = [lp.column_reach(k_basis - k_lo, W0, cap, n + 2 - k_lo, 0.25, o) for o in (None, ok)]
        return [kb.astype(np.float64), *W, *q3, *vaj, *ratios, *reach]

    got = everything()
    mp = pytest.MonkeyPatch()
    try:
        mp.setenv(gnative.DISABLE_ENV, "1")
        want = everything()
    finally:
        mp.undo()
    for x, y in zip(got, want, strict=True):
        np.testing.assert_array_equal(x, y)


#: the flower's motion with the NURBS kernel against scipy's evaluation (rounding moves degenerate LP vertices;
#: seen: equal to 12 digits)
NURBS_MOTION_REL = 1e-3


@pytest.mark.parametrize("jerk", [False, True])
def test_schedules_with_the_kernels_on_and_off(monkeypatch: pytest.MonkeyPatch, jerk: bool) -> None:
    """Lines (evaluated in closed form: no NURBS kernel) give the same samples bit for bit with every kernel on or
    off; the flower (NURBS) the same motion within NURBS_MOTION_REL."""
    from geometry import examples as ex
    from solvers.machine import router
    from solvers.pipeline import Options, schedule

    if native.library() is None or gnative.library() is None:
        pytest.skip("no C compiler (or FEEDSCHED_NO_COMPILE): the numpy path is used")
    m, o = router(), Options(method="lp", jerk=jerk)
    on = {name: schedule(tp(), m, o) for name, tp in (("corner", ex.square_corner), ("flower", lambda: ex.flower(1)))}
    monkeypatch.setenv(gnative.DISABLE_ENV, "1")
    off = {name: schedule(tp(), m, o) for name, tp in (("corner", ex.square_corner), ("flower", lambda: ex.flower(1)))}
    a, b = on["corner"].samples, off["corner"].samples
    for x, y in ((a.t, b.t), (a.s, b.s), (a.position, b.position), (a.velocity, b.velocity),
                 (a.acceleration, b.acceleration), (a.jerk, b.jerk)):
        np.testing.assert_array_equal(x, y)
    mt_on, mt_off = on["flower"].summary["motion_time"], off["flower"].summary["motion_time"]
    assert abs(mt_on - mt_off) <= NURBS_MOTION_REL * mt_off
