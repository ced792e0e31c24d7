"""LP optimality against toppra (the velocity/acceleration time optimum), in one run."""

from __future__ import annotations

import numpy as np
import pytest

from geometry import examples as ex
from solvers.machine import router
from solvers.pipeline import Options, schedule

#: Issue 2: within 1 % of toppra at 4000 grid points.
TOPPRA_GAP = 0.01
TOPPRA_GRID = 4000


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
