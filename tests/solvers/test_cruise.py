"""LP windows not solved along a straight cruise (``pipeline._WindowWalk.cruise``, CRUISE_TOL): where the walk enters
a straight stretch at its constant velocity bound, the control points there are set to the bound and the next window
starts an overlap before the stretch ends.

Truth: the same schedule with every window solved (the jump switched off), which must be as fast to 1e-6; the
programmed feed (the cruise is at F exactly); the samples by finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from geometry import Toolpath
from geometry import examples as ex
from solvers import pipeline as P
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import fd_drive, utilisation

#: Sampled limits (issue 2's bound).
LIMIT_FACTOR = 1.01
#: Motion time with the jumps against every window solved (relative).
SAME_MOTION = 1e-6
#: An L of two 300 mm legs at 30 mm/s (F1800): 0.1 mm knots under lp+nlp (the stopping distance at 30 mm/s is
#: 1.02 mm), 2,941 a leg, windows of 368.
FEED = 30.0
LEGS = [(0.0, 0.0, 0.0), (300.0, 0.0, 0.0), (300.0, 300.0, 0.0)]


def _l_path() -> Toolpath:
    return Toolpath([ex.line(LEGS[0], LEGS[1]), ex.line(LEGS[1], LEGS[2])], feed_limits=[FEED, FEED])


@pytest.mark.parametrize("method", ["lp+nlp", "lp"])
def test_a_straight_cruise_skips_windows_and_keeps_the_motion(method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    tp, m = _l_path(), router()
    opt = Options(method=method, nlp_workers=1, **({} if method == "lp+nlp" else {"knot_spacing": 0.1}))
    got = schedule(tp, m, opt)
    monkeypatch.setattr(P, "CRUISE_TOL", -1.0)  # (no state is within a negative tolerance: every window solved)
    ref = schedule(tp, m, opt)
    assert got.summary["lp_cruise_jumps"] >= 2 and ref.summary["lp_cruise_jumps"] == 0
    assert got.summary["windows"] < ref.summary["windows"]
    assert got.summary["motion_time"] == pytest.approx(ref.summary["motion_time"], rel=SAME_MOTION)
    # the cruise holds the F word, and the jumped stretches are at it exactly
    smp = got.samples
    assert np.max(smp.feed) <= LIMIT_FACTOR * FEED
    mid = (smp.s > 50.0) & (smp.s < 250.0)
    assert np.all(np.abs(smp.feed[mid] - FEED) <= 1e-9 * FEED)
    if method == "lp":
        vmax, amax, jmax = m.limit_arrays()
        u = utilisation(smp.position, opt.sample_period, vmax, amax, jmax)
        assert max(u.values()) <= LIMIT_FACTOR, u
    else:
        dr = m.drive_arrays()
        uu, ee = fd_drive(smp.position, opt.sample_period, dr)
        assert max(np.max(np.abs(uu) / dr["umax"]), np.max(np.abs(ee) / dr["emax"])) <= LIMIT_FACTOR


def test_a_curve_is_no_cruise() -> None:
    """The flower (curved everywhere) solves every window: the same windows as with the jumps off."""
    tp, m = ex.flower(), router()
    got = schedule(tp, m, Options(method="lp", nlp_workers=1, knot_spacing=0.1))
    assert got.summary["lp_cruise_jumps"] == 0
