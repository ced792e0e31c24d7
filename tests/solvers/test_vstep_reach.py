"""How far a tangent break's velocity step reaches: the travel over 3 Ts either side of it.

A tangent break passed at speed (a vertex turning by less than the corner tolerance) steps the axis velocity by
f |jump of x_s|; the sampled differences whose span holds the break see it, and the rows of the points within
3 Ts of travel carry its impulse (``lp.WindowLP._vstep_coupling``).  That travel is bounded by
min(3 Ts sqrt(Q), 3 Ts sqrt(qmax_b) + |amax| (3 Ts)^2 / 2), qmax_b the break's largest q (its caps) and
sqrt(Q) the window's largest feed, the same bound as a curvature jump's (``_step_reach``).  Until session 51
the tangent breaks took 3 Ts (sqrt(qmax_b) + 3 Ts |amax|), twice the acceleration's share and not bounded by
sqrt(Q): more breaks counted as crowding one another, and their linearisation points were lowered more than
they need.
"""

from __future__ import annotations

import numpy as np

from geometry import Toolpath, primitives
from solvers import lp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.solvers.one_window import whole_piece_window

TS = 1e-3
#: Relative slack of the reach against its formula (float rounding).
REACH_RTOL = 1e-12
#: Relative slack of the sampled travel against the bound (s(t) between samples is interpolated linearly).
TRAVEL_RTOL = 1e-3
#: The polyline's turn at each vertex (degrees; under the default corner tolerance of 0.5) and its leg (mm).
TURN_DEG = 0.3
LEG_MM = 3.0


def _zigzag(n: int) -> Toolpath:
    """A planar polyline of n legs of LEG_MM, turning by +-TURN_DEG at every vertex: no corners, n - 1 tangent
    breaks passed at speed."""
    heading = np.radians(TURN_DEG) * (np.arange(n) % 2)
    legs = LEG_MM * np.column_stack([np.cos(heading), np.sin(heading), np.zeros(n)])
    pts = np.vstack([np.zeros((1, 3)), np.cumsum(legs, axis=0)])
    return Toolpath([primitives.polyline(pts)])


def _bound(lim: lp.LimitSet, Q: float, qmax: np.ndarray) -> np.ndarray:
    span = 3.0 * TS
    return np.asarray(np.minimum(span * np.sqrt(Q), span * np.sqrt(qmax) + 0.5 * float(np.linalg.norm(lim.amax))
                                 * span**2))


def test_tangent_break_reach_is_the_travel_over_3_ts() -> None:
    """The reach of every live tangent break, for the acceleration and the jerk rows of each axis, against the
    bound computed here from its caps; under a Q small enough that sqrt(Q) decides too."""
    lim = lp.LimitSet.from_machine(router(), TS, True)
    assert lim.v_step_period == TS
    tp = _zigzag(40)
    for Q in (float(np.max(lim.vmax)) ** 2, 50.0**2):
        w = whole_piece_window(tp, lim, Q)
        qmax_all = w._break_qmax()
        br_all = w._steps()[0]
        assert br_all.size == 39
        seen = 0
        for ax in range(2):
            for limit, kernel, power in ((lim.amax[ax], lp.V_KERNEL_A, 1), (lim.jmax[ax], lp.V_KERNEL_J, 2)):
                live = w._vstep_live(ax, float(limit), kernel, power)
                if live is None:
                    continue
                br, _, reach, _ = live
                qmax = qmax_all[np.searchsorted(br_all, br)]
                np.testing.assert_allclose(reach, _bound(lim, Q, qmax) + lp.BREAK_EPS_MM, rtol=REACH_RTOL, atol=0.0)
                seen += br.size
        assert seen > 0


def test_sampled_travel_around_a_tangent_break_stays_within_its_reach() -> None:
    """The bound is one on the motion: in the 1 kHz samples of the zigzag (method lp), the arc length covered
    over 3 Ts either side of the time each break is passed is within 3 Ts sqrt(qmax_b) + |amax| (3 Ts)^2 / 2
    (the Q term is the window's own; its largest feed bounds it anyway)."""
    m = router()
    lim = lp.LimitSet.from_machine(m, TS, True)
    tp = _zigzag(40)
    sch = schedule(tp, m, Options(method="lp", sample_period=TS))
    smp = sch.samples
    w = whole_piece_window(tp, lim, float(np.max(lim.vmax)) ** 2)
    br, qmax = w._steps()[0], w._break_qmax()
    t_b = np.interp(br, smp.s, smp.t)
    s_lo = np.interp(t_b - 3.0 * TS, smp.t, smp.s)
    s_hi = np.interp(t_b + 3.0 * TS, smp.t, smp.s)
    travel = np.maximum(br - s_lo, s_hi - br)
    bound = _bound(lim, np.inf, qmax)
    assert np.all(travel <= bound * (1.0 + TRAVEL_RTOL)), float(np.max(travel / bound))
    # the breaks are passed at speed, near their caps: the bound is not loose by orders of magnitude
    assert float(np.max(travel / bound)) > 0.5
