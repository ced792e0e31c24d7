"""Junctions that turn by less than the corner tolerance are passed at speed, within every limit.

Passing a tangent break of angle theta at feed f steps each axis velocity by f |jump of x_s|
(|jump| = 2 sin(theta / 2) in all).  Sampled at Ts that step is an impulse in the differences of the
positions: up to |step| / Ts in the acceleration and |step| / Ts^2 in the jerk.  Before the
velocity-step rows (``solvers.lp.v_step_limit``) such a polyline got a typed 422 ("sampled jerk
2.9 x its limit" at 0.2 degrees).  Checked here independently: finite differences of the returned
1 kHz positions (``tests/fdcheck.py``), v/a/j for method lp and u/e for lp+nlp.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import Toolpath, primitives
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import fd_drive, utilisation

TS = 1e-3
#: Allowed overshoot of any limit in the sampled output (issue: 1.01 x).
LIMIT_FACTOR = 1.01
LEG_MM = 10.0
#: The feed at a vertex (interpolated from the samples) within this factor of the reported cap.
FEED_CAP_TOL = 1.001
LEGS = 12


def _zigzag(turn_deg: float, lift: bool) -> Toolpath:
    """LEGS legs of LEG_MM, each turning by turn_deg (alternating sides; with ``lift`` the turns
    alternate between the XY and the XZ plane, so every axis sees velocity steps)."""
    d = np.array([1.0, 0.0, 0.0])
    pts = [np.zeros(3)]
    for i in range(LEGS):
        th = np.radians(turn_deg) * (1 if i % 4 < 2 else -1)
        c, s = np.cos(th), np.sin(th)
        if lift and i % 2:
            d = np.array([c * d[0] - s * d[2], d[1], s * d[0] + c * d[2]])
        else:
            d = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])
        pts.append(pts[-1] + LEG_MM * d)
    return Toolpath([primitives.polyline(np.array(pts))])


@pytest.mark.parametrize("method", ["lp", "lp+nlp"])
@pytest.mark.parametrize("turn_deg,lift", [(0.05, False), (0.2, True), (0.45, False), (0.45, True)])
def test_sub_tolerance_turns_pass_at_speed_within_limits(turn_deg: float, lift: bool, method: str) -> None:
    tp = _zigzag(turn_deg, lift)
    assert tp.corners == []  # below the 0.5 degree tolerance: no rest points
    m = router()
    sch = schedule(tp, m, Options(method=method))
    pos = sch.samples.position
    assert np.all(np.isfinite(pos))
    if method == "lp":
        vmax, amax, jmax = m.limit_arrays()
        util = utilisation(pos, TS, vmax, amax, jmax)
        assert max(util.values()) <= LIMIT_FACTOR, util
    else:
        dr = m.drive_arrays()
        u, e = fd_drive(pos, TS, dr)
        assert float(np.max(np.abs(u) / dr["umax"])) <= LIMIT_FACTOR
        assert float(np.max(np.abs(e) / dr["emax"])) <= LIMIT_FACTOR
    # passed at speed: the feed at every vertex is well above rest
    vertex_s = LEG_MM * np.arange(1, LEGS)
    feed_at = np.interp(vertex_s, sch.samples.s, sch.samples.feed)
    assert np.all(feed_at > 1.0), feed_at
    # and reported, with the feed cap the schedule kept there
    rep = sch.diagnostics["passed_turns"]
    assert rep["count"] == LEGS - 1
    assert rep["largest_angle_deg"] == pytest.approx(turn_deg, rel=1e-9)
    for t in rep["lowest_feed_cap"]:
        k = round(t["s"] / LEG_MM) - 1
        assert t["s"] == pytest.approx(vertex_s[k], abs=1e-9)
        assert feed_at[k] <= t["feed_cap"] * FEED_CAP_TOL
    # and faster than stopping at every vertex (the same path with every junction a corner)
    stop = schedule(Toolpath(tp.segments, corner_tol_deg=0.0), m, Options(method=method))
    assert sch.summary["motion_time"] < stop.summary["motion_time"]


def test_dense_polyline_of_small_turns_schedules_within_limits() -> None:
    """0.3 degrees every 0.5 mm (a tessellated arc of R 95 mm), method lp: several breaks lie within
    the samples' reach of one point, and their coupled rows once added up to an infeasible LP."""
    n = 80
    th = np.radians(40.0 + 0.3 * np.arange(n))  # at 45 degrees both axes run at vmax: Q = 2 vmax^2
    pts = np.zeros((n + 1, 3))
    pts[1:, 0] = np.cumsum(0.5 * np.cos(th))
    pts[1:, 1] = np.cumsum(0.5 * np.sin(th))
    m = router()
    sch = schedule(Toolpath([primitives.polyline(pts)]), m, Options(method="lp"))
    vmax, amax, jmax = m.limit_arrays()
    util = utilisation(sch.samples.position, TS, vmax, amax, jmax)
    assert max(util.values()) <= LIMIT_FACTOR, util


def test_smooth_path_and_corners_report_no_passed_turns() -> None:
    from geometry import examples as ex

    for tp in (ex.flower(1), ex.square_corner(50.0)):
        sch = schedule(tp, router(), Options(method="lp"))
        assert sch.diagnostics["passed_turns"] == {"count": 0}
