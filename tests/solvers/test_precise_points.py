"""When the samples take ``Toolpath.evaluate``'s precise points (``pipeline.precise_points``): only where the
plain points' rounding could reach a share of a promised limit in the sampled differences
(``verify.noise_share``).  The precision itself is tests/geometry/test_point_precision.py's."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from geometry import examples
from geometry.toolpath import Toolpath
from solvers import pipeline, verify
from solvers.lp import LimitSet
from solvers.machine import Machine, router
from solvers.pipeline import Options, schedule

TS = 1e-3


def _limits(v: float, a: float, j: float, drive: dict[str, np.ndarray] | None = None) -> verify.Limits:
    return verify.Limits(np.full(3, v), np.full(3, a), np.full(3, j), drive, None)


def test_noise_share_is_the_differences_of_the_noise_over_each_limit() -> None:
    """v 2n / Ts, a 4n / Ts^2, j 8n / Ts^3 over their limits, whichever is largest; u and e from the drive terms."""
    n = 1e-12
    assert verify.noise_share(_limits(1e3, 1e3, 1e6), TS, n) == pytest.approx(8 * n / TS**3 / 1e6)
    assert verify.noise_share(_limits(1e3, 1e-5, 1e6), TS, n) == pytest.approx(4 * n / TS**2 / 1e-5)
    assert verify.noise_share(_limits(1e-9, 1e3, 1e6), TS, n) == pytest.approx(2 * n / TS / 1e-9)
    drive = {k: np.full(3, x) for k, x in
             {"M": -2.0, "b": 3.0, "c": 100.0, "d": 100.0, "Kv": 0.0, "Ka": 0.0, "Kj": -5.0, "umax": 1e-3,
              "emax": 1e9}.items()}
    lim = verify.Limits(None, None, None, drive, None)
    want = (2.0 * 4 * n / TS**2 + 3.0 * 2 * n / TS) / 1e-3  # c and d are no difference
    assert verify.noise_share(lim, TS, n) == pytest.approx(want)
    assert verify.noise_share(verify.Limits(None, None, None, None, None), TS, n) == 0.0


def _scaled(m: Machine, factor: float) -> Machine:
    """The machine with every v, a, j limit times factor."""
    axes = [replace(a, limits=replace(a.limits, vmax=a.limits.vmax * factor, amax=a.limits.amax * factor,
                                      jmax=a.limits.jmax * factor)) for a in m.axes]
    return replace(m, axes=(axes[0], axes[1], axes[2]))


def _decides(tp: Toolpath, m: Machine) -> bool:
    opt = Options(method="lp")
    lim = LimitSet.from_machine(m, opt.sample_period, opt.jerk)
    return pipeline.precise_points(tp, pipeline._promised(lim, opt, m), opt.sample_period)


def test_router_samples_are_plain_and_a_machine_near_float_resolution_takes_precise_points() -> None:
    """The flower on the router: plain (its limits ~1e8 x above the noise).  The same limits 1e-9 x (amax ~1e-5
    mm/s^2, as bench seed 5029's x axis): precise."""
    tp = examples.flower(1)
    assert not _decides(tp, router())
    assert _decides(tp, _scaled(router(), 1e-9))


def test_samples_are_evaluated_with_the_decided_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    """The schedule's samples ask ``Toolpath.evaluate`` for precise points exactly when ``precise_points`` says so
    (the solvers' own geometry never does)."""
    tp = examples.flower(1)
    seen: list[bool] = []
    real = Toolpath.evaluate

    def spy(self: Toolpath, s: np.ndarray, piece: object = None, exact: bool = True, precise: bool = False) -> object:
        seen.append(precise)
        return real(self, s, piece, exact, precise)  # type: ignore[arg-type]

    monkeypatch.setattr(Toolpath, "evaluate", spy)
    schedule(tp, router(), Options(method="lp"))
    assert seen and not any(seen)
    seen.clear()
    monkeypatch.setattr(pipeline, "PRECISE_POINTS_SHARE", 0.0)
    sch = schedule(tp, router(), Options(method="lp"))
    assert any(seen)
    # the samples' positions are the precise points at their s
    s = np.asarray(sch.samples.s)
    np.testing.assert_array_equal(np.asarray(sch.samples.position)[1:-1],
                                  real(tp, s[1:-1], None, True, True).position)
