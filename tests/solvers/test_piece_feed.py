"""Knots from a piece's programmed feed (``Piece.feed``): a piece whose F words are all under the machine's top feed
gets the knots, windows and knot floor of the stopping distance at its own feed, as a machine feed cap
(``Machine.feed_max``) of that value gives them.

Truth: the feeds given to the toolpath (a piece's feed is the highest of its segments'); the same path under the
machine's feed cap; the straight legs' travel at the programmed feed (L / F); the samples by finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry import Toolpath
from geometry import examples as ex
from solvers import lp
from solvers import pipeline as P
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import fd_drive, utilisation

#: Sampled limits (issue 2's bound) and the drive's (lp+nlp).
LIMIT_FACTOR = 1.01
#: lp+nlp on the square of 20 mm legs at F600 (10 mm/s), its rest ends included, at most this far over L / F
#: (measured 1.0056; 1.0169 on the machine's knots, before the piece's feed set them).
SQUARE_OVER_TRAVEL = 0.01
#: The same square under a machine feed cap instead of F words: the same knots, the motion within this (relative).
SAME_AS_FEED_MAX = 1e-9
#: ``Machine.stopping_distance`` against ``lp.s_curve``'s ramp (relative).
S_CURVE_RTOL = 1e-12

SQUARE = [(0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (20.0, 20.0, 0.0), (0.0, 20.0, 0.0), (0.0, 0.0, 0.0)]


def _square(feeds: list[float | None] | None) -> Toolpath:
    return Toolpath([ex.line(SQUARE[i], SQUARE[i + 1]) for i in range(4)], feed_limits=feeds)


def test_a_pieces_feed_is_the_highest_of_its_segments() -> None:
    """Corners at each vertex of the square: one piece per leg, and a segment without an F word leaves its piece
    uncapped; a straight leg split in two segments (a tangent join, no corner) is one piece, with the higher feed."""
    assert [p.feed for p in _square([10.0, 20.0, 5.0, None]).pieces] == [10.0, 20.0, 5.0, math.inf]
    assert all(p.feed == math.inf for p in _square(None).pieces)
    split = Toolpath([ex.line((0.0, 0.0, 0.0), (5.0, 0.0, 0.0)), ex.line((5.0, 0.0, 0.0), (10.0, 0.0, 0.0)),
                      ex.line((10.0, 0.0, 0.0), (10.0, 10.0, 0.0))], feed_limits=[4.0, 7.0, 3.0])
    assert [p.feed for p in split.pieces] == [7.0, 3.0]


@pytest.mark.parametrize("feed", [1.0, 10.0, 100.0, 1e6])
def test_the_stopping_distance_at_a_feed_is_the_one_under_that_feed_cap(feed: float) -> None:
    """Against the machine under a feed cap of that value, and against the S-curve's ramp distance per axis
    (``lp.s_curve`` from rest to min(vmax, feed): the jerk-limited stop, read backwards)."""
    m = router()
    capped = m.with_feed_max(feed)
    assert m.stopping_distance(feed) == capped.stopping_distance()
    assert m.top_feed(feed) == capped.top_feed() == min(feed, max(a.limits.vmax for a in m.axes))
    vmax, amax, jmax = m.limit_arrays()
    _, ramp = lp.s_curve(np.minimum(vmax, feed), 0.0, jmax, amax)
    assert m.stopping_distance(feed) == pytest.approx(float(np.max(ramp)), rel=S_CURVE_RTOL)
    assert m.stopping_distance(feed) <= m.stopping_distance()


def test_f_words_plan_lp_nlps_knots_as_a_feed_cap_of_the_same_value_does() -> None:
    """The square at F600 (10 mm/s) on the router, lp+nlp: the knots are 0.1 x the stopping distance at 10 mm/s
    (~14 um, not the machine's 2.3 mm), as under a machine feed cap of 10 mm/s; its ramps at the four corners then
    cost under 1 % of L / F (on the machine's knots its NLP could not form them in the first knot interval:
    1.69 %)."""
    F = 10.0
    m = router()
    opt = Options(method="lp+nlp")
    tp = _square([F] * 4)
    capped = _square(None)
    for p, q in zip(tp.pieces, capped.pieces, strict=True):
        assert P.plan_piece(p, m, opt).n_int == P.plan_piece(q, m.with_feed_max(F), opt).n_int
        assert P.plan_piece(p, m, opt).n_int > 50 * P.plan_piece(q, m, opt).n_int
    got = schedule(tp, m, opt)
    ref = schedule(capped, m.with_feed_max(F), opt)
    assert got.summary["control_points"] == ref.summary["control_points"]
    assert got.summary["motion_time"] == pytest.approx(ref.summary["motion_time"], rel=SAME_AS_FEED_MAX)
    smp = got.samples
    assert np.max(smp.feed) <= LIMIT_FACTOR * F
    assert got.summary["motion_time"] <= (1.0 + SQUARE_OVER_TRAVEL) * tp.length / F
    dr = m.drive_arrays()
    u, e = fd_drive(smp.position, opt.sample_period, dr)
    assert max(np.max(np.abs(u) / dr["umax"]), np.max(np.abs(e) / dr["emax"])) <= LIMIT_FACTOR


def test_method_lp_keeps_the_machines_knots_under_f_words() -> None:
    """Method lp's steep rest shapes form the ramp inside one knot interval (``pipeline.PIECE_FEED_KNOTS``): the same
    square keeps the knots of the machine's stopping distance, and its samples hold v, a, j."""
    m = router()
    opt = Options(method="lp")
    tp = _square([10.0] * 4)
    for p, q in zip(tp.pieces, _square(None).pieces, strict=True):
        assert P.plan_piece(p, m, opt).n_int == P.plan_piece(q, m, opt).n_int
    got = schedule(tp, m, opt)
    vmax, amax, jmax = m.limit_arrays()
    u = utilisation(got.samples.position, opt.sample_period, vmax, amax, jmax)
    assert max(u.values()) <= LIMIT_FACTOR, u
    assert np.max(got.samples.feed) <= LIMIT_FACTOR * 10.0


def test_the_knot_floor_follows_a_pieces_f_words() -> None:
    """A 30 mm line at F60 (1 mm/s), lp+nlp: the floor's knots are the ones 1 mm/s covers in KNOT_FLOOR_SAMPLES
    sample periods (10 um), as under a machine feed cap of 1 mm/s, and the schedule keeps them.  Under method lp the
    plan's knots (the machine's) are already coarser, and the floor does not apply."""
    m = router()
    line = ex.line((0.0, 0.0, 0.0), (30.0, 0.0, 0.0))
    tp, capped = Toolpath([line], feed_limits=[1.0]), Toolpath([line])
    opt = Options(method="lp+nlp")
    n_f = P.floor_count(tp.pieces[0], m, opt)
    assert n_f is not None and n_f == P.floor_count(capped.pieces[0], m.with_feed_max(1.0), opt)
    assert n_f == pytest.approx(tp.length / (P.KNOT_FLOOR_SAMPLES * opt.sample_period * 1.0), abs=1)
    got = schedule(tp, m, opt)
    assert got.summary["knot_floor_pieces"] == 1
    assert got.summary["motion_time"] <= (1.0 + SQUARE_OVER_TRAVEL) * tp.length / 1.0
    lp_opt = Options(method="lp")
    assert P.floor_count(tp.pieces[0], m, lp_opt) is None
    assert P.plan_piece(tp.pieces[0], m, lp_opt).n_int < n_f
