"""A budget of knot intervals against lp+nlp's F-word knots (``pipeline.fit_intervals``): where the knots at the
pieces' F words are too many, the lowest feed that sizes them (``Options.knot_feed_floor``) is raised until they fit,
never past the machine's own knots.

Truth: the stopping distance at a feed from the S-curve ramp of each axis (``test_optimality.ramp_from_rest``, not
``Machine.stopping_distance``); a square of straight 2 mm legs, one piece each (no curvature peak to phase, no knot
floor: the legs are under 500 stopping distances), so a leg at feed F has ceil(L / (0.1 D(F))) intervals; the
schedule's samples by finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry import Toolpath
from geometry import examples as ex
from solvers import pipeline as P
from solvers.machine import router
from solvers.pipeline import Options, fit_intervals, schedule, total_intervals
from tests.fdcheck import fd_drive
from tests.solvers.test_optimality import ramp_from_rest

#: Sampled drive limits and programmed feed of the fitted schedule (issue 2's bound).
LIMIT_FACTOR = 1.01
LEG = 2.0
SQUARE = [(0.0, 0.0, 0.0), (LEG, 0.0, 0.0), (LEG, LEG, 0.0), (0.0, LEG, 0.0), (0.0, 0.0, 0.0)]
#: The square's F word: 10 mm/s (F600), the router's stopping distance there 0.14 mm, 144 intervals a leg.
FEED = 10.0


def _square(feed: float | None = FEED) -> Toolpath:
    return Toolpath([ex.line(SQUARE[i], SQUARE[i + 1]) for i in range(4)], feed_limits=[feed] * 4)


def _ramp_distance(feed: float) -> float:
    """The router's stopping distance at ``feed``: the longest S-curve ramp of an axis from rest to min(vmax, feed)."""
    return max(ramp_from_rest(min(ax.limits.vmax, feed), ax.limits.amax, ax.limits.jmax)[1] for ax in router().axes)


def _leg_intervals(feed: float) -> int:
    return max(P.MIN_INTERVALS, math.ceil(LEG / (P.KNOT_SPACING_PER_STOP * _ramp_distance(feed)) - 1e-9))


def test_the_square_counts_its_legs_at_their_f_word() -> None:
    """The premise of the tests below: four legs of ceil(L / (0.1 D(F))) intervals each, none on the knot floor."""
    tp, m = _square(), router()
    assert [P.floor_count(p, m, Options()) for p in tp.pieces] == [None] * 4
    assert total_intervals(tp, m, Options()) == 4 * _leg_intervals(FEED) == 576
    assert total_intervals(tp, m, Options(knot_feed_floor=m.top_feed())) == 4 * P.MIN_INTERVALS


@settings(max_examples=25, deadline=None)
@given(budget=st.integers(min_value=4 * P.MIN_INTERVALS, max_value=4 * _leg_intervals(FEED) - 1))
def test_the_floor_is_the_lowest_feed_whose_knots_fit(budget: int) -> None:
    """Fitted, the legs' knots are those of the floor's stopping distance and their count is within the budget;
    just under the floor (KNOT_FEED_FLOOR_REL, the bisection's bracket) they would not be."""
    tp, m = _square(), router()
    got = fit_intervals(tp, m, Options(), budget)
    floor = got.knot_feed_floor
    assert floor is not None and FEED < floor <= m.top_feed()
    assert total_intervals(tp, m, got) == 4 * _leg_intervals(floor) <= budget
    assert 4 * _leg_intervals(floor / (1.0 + P.KNOT_FEED_FLOOR_REL)) > budget


def test_options_are_kept_where_they_fit_or_where_coarsening_cannot_help() -> None:
    tp, m = _square(), router()
    opt = Options()
    assert fit_intervals(tp, m, opt, 576) is opt  # fits already
    assert fit_intervals(tp, m, opt, 4 * P.MIN_INTERVALS - 1) is opt  # over even on the machine's knots
    lp_opt = Options(method="lp")
    assert total_intervals(tp, m, lp_opt) == 4 * P.MIN_INTERVALS  # lp plans on the machine's knots
    assert fit_intervals(tp, m, lp_opt, 40) is lp_opt
    explicit = Options(knot_spacing=0.001)
    assert fit_intervals(tp, m, explicit, 576) is explicit  # an explicit spacing is the caller's
    no_f = Options()
    assert fit_intervals(_square(None), m, no_f, 40) is no_f  # no F words: the machine's knots already


def test_a_fitted_schedule_plans_on_the_floors_knots_and_holds_the_drive() -> None:
    """A budget of 400 intervals: 100 a leg (0.02 mm knots, against 14 um at F600 and 0.125 mm on the machine's:
    16, MIN_INTERVALS; a piece is solved on at least REST_MIN_INTERVALS = 64 first anyway), the floor in the
    summary, the programmed feed kept and the drive's u, e within the limits."""
    tp, m = _square(), router()
    opt = fit_intervals(tp, m, Options(method="lp+nlp", nlp_workers=1), 400)
    assert _leg_intervals(opt.knot_feed_floor or math.inf) == 100
    sch = schedule(tp, m, opt)
    assert sch.summary["knot_feed_floor"] == opt.knot_feed_floor
    assert sch.summary["knot_spacing"] == pytest.approx(LEG / 100, rel=1e-12)
    assert float(sch.samples.feed.max()) <= LIMIT_FACTOR * FEED
    dr = m.drive_arrays()
    u, e = fd_drive(sch.samples.position, opt.sample_period, dr)
    assert max(np.max(np.abs(u) / dr["umax"]), np.max(np.abs(e) / dr["emax"])) <= LIMIT_FACTOR


def test_the_floor_must_be_a_positive_feed() -> None:
    with pytest.raises(P.InvalidOptionsError) as err:
        Options(knot_feed_floor=0.0)
    assert err.value.field == "options.knot_feed_floor"
