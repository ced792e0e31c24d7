"""Stage 2's q* next to rest ends capped at what a feed from rest can reach (``solvers.lp.QSTAR_REST_REACH``).

Independent truth: the fastest ramp from rest in the time domain (closed-form polynomials in t, against the
library's distance-domain Newton inversion), random jerk profiles integrated exactly piece by piece (none may beat
the reach), the closed-form jerk-limited optimum of a straight line (``tests.solvers.test_optimality.s_curve_time``)
and the random cases' independent checker (``tests.reliability.checker``) on the cases that found the traps.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry import Toolpath
from geometry import examples as ex
from solvers import lp
from solvers import pipeline as P
from solvers.lp import _reach_travel, reach_q
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.reliability import gen, harness
from tests.solvers.test_optimality import s_curve_time

#: The reach against its time-domain form (relative: the Newton steps reach the last places).
REACH_RTOL = 1e-11
#: A random profile's q against the reach (relative: both are sums of a few float products).
BOUND_RTOL = 1e-9
HYPOTHESIS_EXAMPLES = 200
#: Sampled limits (finite differences at 1 kHz), as everywhere (issue 2).
LIMIT_FACTOR = 1.01
#: A rest-to-rest x line on the router, method lp, within this share of the jerk-limited optimum (measured with the
#: cap: 1.9 / 1.9 / 1.2 %, and 1.2 / 1.5 / 0.96 % with the rise of power 256, ``bspline.LP_REST_RISE_POWERS``;
#: without the cap 6.6 / 2.0 / 1.2 %, session 47's rest shapes, ``test_lp_rest_shapes``) ...
CAPPED_LINE_GAP = {1.0: 0.025, 20.0: 0.025, 100.0: 0.015}
#: ... and at most this share of the time without the cap (1 mm: 0.955, 0.948 with the power 256)
CAPPED_GAIN_1MM = 0.97


def _ramp(t: np.ndarray, a0: float, J: float, A: float) -> tuple[np.ndarray, np.ndarray]:
    """sigma(t), v(t) of the step to a0, the ramp at J to A, then A (time domain, closed form)."""
    t1 = (A - a0) / J
    s1, v1 = a0 * t1**2 / 2 + J * t1**3 / 6, a0 * t1 + J * t1**2 / 2
    dt = np.maximum(t - t1, 0.0)
    on = t <= t1
    s = np.where(on, a0 * t**2 / 2 + J * t**3 / 6, s1 + v1 * dt + A * dt**2 / 2)
    v = np.where(on, a0 * t + J * t**2 / 2, v1 + A * dt)
    return s, v


@pytest.mark.parametrize(("a0", "J", "A"), [(33.0, 66075.0, 524.4), (0.0, 66075.0, 524.4), (524.4, 66075.0, 524.4),
                                            (5.6e4, 1.1e8, 3.4e5), (1e-3, 1.0, 2.0)])
def test_reach_is_the_fastest_ramp_in_the_time_domain(a0: float, J: float, A: float) -> None:
    t = np.concatenate([[0.0], np.geomspace(1e-6, 10.0, 400) * (A / J)])
    s, v = _ramp(t, a0, J, A)
    n = s.size
    q = reach_q(s, a0, np.full(n, J), np.full(n, A))
    np.testing.assert_allclose(q, v * v, rtol=REACH_RTOL, atol=0.0)
    # the travel in a given time (``_reach_travel``), and at most V t
    travel = np.array([_reach_travel(float(ti), a0, J, A, np.inf) for ti in t])
    np.testing.assert_allclose(travel, s, rtol=REACH_RTOL, atol=0.0)
    V = float(v[n // 2])
    assert _reach_travel(float(t[-1]), a0, J, A, V) == pytest.approx(V * float(t[-1]), rel=1e-15)


@settings(max_examples=HYPOTHESIS_EXAMPLES, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), pieces=st.integers(1, 8))
def test_no_feed_from_rest_under_the_bounds_beats_the_reach(seed: int, pieces: int) -> None:
    """Random piecewise-constant jerks in [-J, J] from a step in [0, a0], the acceleration held at A when it gets
    there, integrated exactly; stopped where the feed would turn back.  q = v^2 stays within the reach everywhere."""
    rng = np.random.default_rng(seed)
    a0, J, A = rng.uniform(0.0, 50.0), rng.uniform(1e3, 1e5), rng.uniform(100.0, 1000.0)
    a, v, s = rng.uniform(0.0, a0), 0.0, 0.0
    pts_s, pts_v = [0.0], [0.0]
    for _ in range(pieces):
        j, dur = rng.uniform(-J, J), rng.uniform(0.0, 3.0) * A / J
        for h in np.linspace(0.0, dur, 20)[1:] - np.linspace(0.0, dur, 20)[:-1]:
            if j > 0.0 and a + j * h > A:  # (up to A, then held there)
                h1 = (A - a) / j
                s, v, a = s + v * h1 + a * h1**2 / 2 + j * h1**3 / 6, v + a * h1 + j * h1**2 / 2, A
                s, v = s + v * (h - h1) + A * (h - h1) ** 2 / 2, v + A * (h - h1)
            else:
                s, v, a = s + v * h + a * h**2 / 2 + j * h**3 / 6, v + a * h + j * h**2 / 2, a + j * h
            if v < 0.0:
                break
            pts_s.append(s)
            pts_v.append(v)
        if v < 0.0:
            break
    ps, pv = np.array(pts_s), np.array(pts_v)
    reach = reach_q(ps, a0, np.full(ps.size, J), np.full(ps.size, A))
    assert np.all(pv * pv <= reach * (1.0 + BOUND_RTOL) + 1e-300), float(np.max(pv * pv / np.maximum(reach, 1e-300)))


@pytest.mark.parametrize("length", sorted(CAPPED_LINE_GAP))
def test_lines_leave_rest_at_the_jerk_bound(monkeypatch: pytest.MonkeyPatch, length: float) -> None:
    """With the cap the pseudo-jerk rows read the jerk leaving rest as it is: the line is within CAPPED_LINE_GAP of
    the jerk-limited optimum, and every sampled limit holds."""
    m = router()
    ax = m.axes[0].limits
    tp = Toolpath([ex.line((0.0, 0.0, 0.0), (length, 0.0, 0.0))])
    capped = schedule(tp, m, Options(method="lp"))
    t_opt = s_curve_time(length, ax.vmax, ax.amax, ax.jmax)
    t = float(capped.summary["motion_time"])
    assert t_opt * (1.0 - 1e-9) <= t <= (1.0 + CAPPED_LINE_GAP[length]) * t_opt, (t, t_opt)
    assert capped.summary["sample_repairs"] == 0
    vmax, amax, jmax = m.limit_arrays()
    u = utilisation(capped.samples.position, capped.summary["sample_period"], vmax, amax, jmax)
    assert max(u.values()) <= LIMIT_FACTOR, u
    if length == 1.0:
        monkeypatch.setattr(lp, "QSTAR_REST_REACH", 0.0)
        plain = float(schedule(tp, m, Options(method="lp")).summary["motion_time"])
        assert t <= CAPPED_GAIN_1MM * plain, (t, plain)


@pytest.mark.parametrize(("seed", "what"), [
    (125, "a path start: the samples read 1.025 x jmax at t = 0 with the cap, repaired without it"),
    (30, "corners on a fast machine (jmax ~1e8 mm/s^3): 1.14 x jmax next to a corner with the plain cap, 1.019 x "
         "after both repairs (which re-solve the piece after the corner only)"),
    (142, "a corner: 1.020 x jmax with the plain cap"),
])
def test_cases_that_found_the_reach_traps(seed: int, what: str) -> None:
    """Bench seeds that failed with the cap alone (``lp.WindowLP._step_reach_factor``, ``LimitSet.rest_reach``):
    ``what``.  Checked by the independent checker."""
    out = harness.run(gen.case(seed, "bench"), "lp")
    assert out.ok, f"{what}: {out.describe()}"


@pytest.mark.parametrize("seed", [125, 184])
def test_first_repair_keeps_the_cap(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """A piece repaired for its samples keeps the cap in its first round, with room for the acceleration step at
    its path ends (``pipeline._repair_limits``, ``LimitSet.rest_reach_ends``): bench seeds 125 and 184 (lp) need one
    repair round, pass the independent checker, and move faster than with the cap dropped in that round (session
    60: 0.35963 against 0.36081 s, 0.14250 against 0.14833 s).  Their samples before the repair read 1.041 x jy and
    1.037 x jx, far over the repair's 1.005.  Seed 51, this test's case until session 60 (0.61136 against 0.61926 s
    in session 50), needed its repair on the machines of sessions 50-59 and none on session 60's (an AMD EPYC
    without AVX-512, same pinned packages: 0.60565 s, another LP vertex); seed 55 before it needed none once the
    curvature jumps' reach was tightened (``lp.WindowLP._step_reach``)."""
    case = gen.case(seed, "bench")
    opt = Options(method="lp", sample_period=harness.TS)
    kept = schedule(case.toolpath(), case.lp_machine, opt)
    out = harness.run(case, "lp")
    assert out.ok, out.describe()
    monkeypatch.setattr(P, "REPAIR_REACH_ENDS", False)
    dropped = schedule(case.toolpath(), case.lp_machine, opt)
    assert kept.summary["sample_repairs"] == dropped.summary["sample_repairs"] == 1
    assert kept.summary["motion_time"] < dropped.summary["motion_time"]
