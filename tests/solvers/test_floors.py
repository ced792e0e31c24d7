"""The LP's floors next to rest ends (``solvers.lp.WindowLP.solve``, ``_ramp_reach``, ``RAMP_FLOOR_SHARE``).

Away from rest ends q is kept above a small floor (no stall at a knot).  On a short piece the ramp from rest
spans many knot intervals, and a floor there cannot be reached: both floored models were infeasible, each proved
twice by HiGHS, before the model without a floor (a 2.8 mm leg: 5 solves instead of 1).  The floors are now capped
at RAMP_FLOOR_SHARE of what the ramp from rest reaches.

Independent truth: the same schedule with every floor off (the floors do not bind on a straight leg, so the
motion is the same) and the finite differences of the sampled positions (``tests.fdcheck``).
"""

from __future__ import annotations

import collections
from dataclasses import replace
from typing import Any

import highspy
import numpy as np
import pytest

from geometry import Toolpath, primitives
from solvers import lp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.solvers.highs_runs import watch_highs_runs

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
#: Motion time with the floors against without them, relative (measured ~1e-13 on these legs).
MOTION_REL_TOL = 1e-9
LEGS = 6
LEG_XY = 2.0  # mm: legs of 2.83 mm turning by 90 degrees, each a rest-to-rest piece


def _zigzag() -> Toolpath:
    pts = np.array([[LEG_XY * i, LEG_XY * (i % 2), 0.0] for i in range(LEGS + 1)])
    return Toolpath([primitives.polyline(pts)])


def _statuses(monkeypatch: pytest.MonkeyPatch) -> collections.Counter[str]:
    seen: collections.Counter[str] = collections.Counter()

    def counted(h: Any) -> None:
        seen[str(h.getModelStatus())] += 1

    watch_highs_runs(monkeypatch, after=counted)
    return seen


@pytest.mark.parametrize("jerk", [False, True])
def test_short_pieces_are_solved_with_their_floors_at_the_first_try(monkeypatch: pytest.MonkeyPatch,
                                                                   jerk: bool) -> None:
    tp = _zigzag()
    assert len(tp.pieces) == LEGS
    seen = _statuses(monkeypatch)
    sch = schedule(tp, router(), Options(method="lp", jerk=jerk))
    assert seen[str(highspy.HighsModelStatus.kInfeasible)] == 0, seen
    assert seen[str(highspy.HighsModelStatus.kOptimal)] == sum(seen.values())
    # the floors bind nowhere on a straight leg: the same motion as without any floor
    monkeypatch.setattr(lp, "FLOOR_SHARE", 0.0)
    monkeypatch.setattr(lp, "LOCAL_FLOOR_SHARE", 0.0)
    free = schedule(tp, router(), Options(method="lp", jerk=jerk))
    t, t_free = float(sch.summary["motion_time"]), float(free.summary["motion_time"])
    assert t == pytest.approx(t_free, rel=MOTION_REL_TOL)
    vmax, amax, jmax = router().limit_arrays()
    u = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(v for k, v in u.items() if jerk or k[0] in "va") <= LIMIT_FACTOR, u


@pytest.mark.parametrize("jerk", [False, True])
def test_ramp_reach_from_rest_under_the_tangential_limits(jerk: bool) -> None:
    """``_ramp_reach`` on a straight x move, at distance r = (j - 1/2) d of column j from the nearer end:
    2 amax_x r, and with jerk rows 0.25 jmax_x^(2/3) (6 r)^(4/3) where less (the feed of a jerk-limited start from
    rest, v = j t^2 / 2 at s = j t^3 / 6)."""
    m = router()
    tp = Toolpath([primitives.polyline(np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]]))])
    piece = tp.pieces[0]
    n_int, d = 64, tp.length / 64
    lim = lp.LimitSet.from_machine(m, TS, jerk)
    if jerk:  # (the router's jerk binds only within ~0.01 mm of rest: 1 % of it binds at every column here)
        lim = replace(lim, jmax=lim.jmax / 100.0)

    def geometry(s: np.ndarray) -> Any:
        return tp.evaluate(np.asarray(s, dtype=np.float64) + piece.s_start, piece)

    spec = lp.WindowSpec(0, 0, n_int, d, n_int, None, True)
    w = lp.WindowLP(spec, lim, geometry, "highs")
    n = n_int + 2
    g = geometry(np.linspace(0.0, tp.length, 50))
    reach = w._ramp_reach(g, n)
    peak = (np.arange(n) - 0.5) * d
    r = np.minimum(np.maximum(peak, 0.0), np.maximum(tp.length - peak, 0.0))
    expect = 2.0 * float(lim.amax[0]) * r
    if jerk:
        v = np.cbrt(6.0 * r / float(lim.jmax[0])) ** 2 * float(lim.jmax[0]) / 2.0  # v(t) at s(t) = r
        assert np.any(v * v < expect)  # (the jerk binds near the ends)
        expect = np.minimum(expect, v * v)
    np.testing.assert_allclose(reach, expect, rtol=1e-12, atol=0.0)
    # a window between two others (no rest end) reaches anywhere
    mid = lp.WindowLP(lp.WindowSpec(1, 8, 40, d, n_int, (1.0, 1.0), False), lim, geometry, "highs")
    assert np.all(np.isinf(mid._ramp_reach(g, 34)))
