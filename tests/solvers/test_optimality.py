"""LP optimality against toppra (the velocity/acceleration time optimum), in one run, and against the
closed-form jerk-limited optimum of a straight line."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry import Toolpath
from geometry import examples as ex
from solvers.machine import router
from solvers.pipeline import Options, schedule

#: Issue 2: within 1 % of toppra at 4000 grid points.
TOPPRA_GAP = 0.01
TOPPRA_GRID = 4000
#: A rest-to-rest line under the pseudo-jerk LP: at most this much over the jerk-limited optimum
#: (measured 5.4-7.9 % on 1-100 mm with the LP's rest shapes, session 27; 25.8-28.5 % before them, and
#: 54 % at 5 mm and 33 % at 100 mm when a piece was solved on 16 knot intervals: the ramps from and to
#: rest sit in the first and last interval)
LINE_JERK_GAP = 0.10


def test_flower_lp_within_one_percent_of_toppra() -> None:
    ta = pytest.importorskip("toppra")
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    ta.setup_logging("WARNING")
    tp = ex.flower(1)
    m = router()
    ours = schedule(tp, m, Options(method="lp", jerk=False, knot_spacing=1.0)).summary["motion_time"]
    s = np.linspace(0.0, tp.length, 8001)
    path = ta.SplineInterpolator(s, tp.evaluate(s).position)
    vm = np.array([a.limits.vmax for a in m.axes])
    am = np.array([a.limits.amax for a in m.axes])
    cons = [
        constraint.JointVelocityConstraint(np.column_stack([-vm, vm])),
        constraint.JointAccelerationConstraint(np.column_stack([-am, am])),
    ]
    grid = np.linspace(0.0, tp.length, TOPPRA_GRID)
    inst = algo.TOPPRA(cons, path, gridpoints=grid, parametrizer="ParametrizeConstAccel")
    theirs = inst.compute_trajectory(0, 0).duration
    assert abs(ours - theirs) / theirs < TOPPRA_GAP, (ours, theirs)


def ramp_from_rest(peak: float, a: float, j: float) -> tuple[float, float]:
    """(time, distance) of the fastest ramp from rest to ``peak`` at zero acceleration under |a| <= a, |jerk| <= j
    (the S-curve's; its distance is the spec's stopping distance from ``peak``)."""
    t = peak / a + a / j if peak >= a * a / j else 2.0 * math.sqrt(peak / j)
    return t, 0.5 * peak * t


def s_curve_time(length: float, v: float, a: float, j: float) -> float:
    """Time-optimal rest-to-rest move of ``length`` mm in one axis under |v| <= v, |a| <= a, |jerk| <= j
    (the 7-phase S-curve, in closed form; the cruise-free case by bisection on the peak speed)."""

    def ramp(peak: float) -> tuple[float, float]:
        return ramp_from_rest(peak, a, j)

    t_v, d_v = ramp(v)
    if length >= 2.0 * d_v:
        return 2.0 * t_v + (length - 2.0 * d_v) / v
    lo, hi = 0.0, v
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if 2.0 * ramp(mid)[1] > length else (mid, hi)
    return 2.0 * ramp(lo)[0]


@pytest.mark.parametrize("length", [1.0, 5.0, 20.0, 100.0])
def test_line_within_the_pseudo_jerk_price_of_the_jerk_limited_optimum(length: float) -> None:
    """A straight x move of the router (method lp, jerk on): never faster than the closed-form S-curve
    optimum, and at most LINE_JERK_GAP slower (pipeline.REST_MIN_INTERVALS)."""
    m = router()
    ax = m.axes[0].limits
    t_opt = s_curve_time(length, ax.vmax, ax.amax, ax.jmax)
    sch = schedule(Toolpath([ex.line((0.0, 0.0, 0.0), (length, 0.0, 0.0))]), m, Options(method="lp"))
    motion = float(sch.summary["motion_time"])
    assert t_opt * (1.0 - 1e-9) <= motion <= (1.0 + LINE_JERK_GAP) * t_opt, (motion, t_opt)
