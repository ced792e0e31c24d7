"""Stretches of a chain whose LP feed is kept unsolved (``solvers.nlp.kept_parts``, ``NlpRefiner._chain_parts``).

Where the LP's feed sits at the feed bound, well inside every other NLP limit, the NLP cannot go faster: a
chain is solved as the parts either side of such a stretch.  The parts' layout is checked against cases
worked by hand and, for random flags, against the rules it must keep; a schedule with kept stretches
against the same schedule with every stretch solved, its limits re-computed from the 1 kHz samples.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry import NurbsSegment, Toolpath
from geometry import examples as ex
from solvers import nlp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.solvers.test_nlp import _assert_seams_continuous, _check_drive

#: The kept stretches may not lengthen the motion against solving them (relative).  Measured: 0.9999991 x.
KEPT_MOTION_REL = 1e-5
#: Sampled feed over the machine's feed limit allowed (relative; the NLP's VERIFY_TOL is 2e-3).
FEED_OVER = 2e-3


def _parts(flags: str, A: int, n_int: int, margin: int, min_run: int, window: int) -> list[tuple[int, int, bool]]:
    return nlp.kept_parts(np.array([ch == "T" for ch in flags]), A, n_int, margin, min_run, window)


def test_solved_stretches_take_their_margin_and_grow_to_a_window() -> None:
    # solved [0, 5), [60, 62), [65, 100); margin 4: [0, 9), [56, 66), [61, 100); the first grows to 12 intervals
    # (the chain's start stops it on the left), the second to [55, 67) and merges with the third
    flags = "F" * 5 + "T" * 55 + "F" * 2 + "T" * 3 + "F" * 35
    assert _parts(flags, 10, 1000, 4, 8, 12) == [(10, 22, False), (22, 65, True), (65, 110, False)]


def test_a_stretch_at_the_chains_end_keeps_it_without_a_margin() -> None:
    # the chain's end is an LP join: the LP's state there is the next chain's start anyway
    flags = "F" * 40 + "T" * 60
    assert _parts(flags, 10, 1000, 4, 8, 12) == [(10, 54, False), (54, 110, True)]


def test_a_short_stretch_is_solved() -> None:
    # solved [0, 22) and [28, 50) with margin 2: the 6 intervals left between them are under min_run
    flags = "F" * 20 + "T" * 10 + "F" * 20
    assert _parts(flags, 10, 1000, 2, 8, 12) == [(10, 60, False)]
    assert _parts(flags, 10, 1000, 2, 6, 12) == [(10, 32, False), (32, 38, True), (38, 60, False)]


def test_rest_intervals_do_not_count_in_a_solved_window() -> None:
    # chain [0, 50) of a 50-interval piece: its rest intervals 0 and 49 are solved; each solved part grows
    # until its grid between them (knots 1 .. 49) holds the 12-interval window
    flags = "F" + "T" * 48 + "F"
    assert _parts(flags, 0, 50, 3, 8, 12) == [(0, 13, False), (13, 37, True), (37, 50, False)]


@settings(max_examples=300, deadline=None)
@given(flags=st.lists(st.booleans(), min_size=1, max_size=120), A=st.integers(0, 30),
       margin=st.integers(1, 6), min_run=st.integers(1, 20), window=st.integers(2, 30))
def test_parts_cover_the_chain_and_keep_only_kept_intervals(flags: list[bool], A: int, margin: int, min_run: int,
                                                            window: int) -> None:
    n = len(flags)
    n_int = A + n + 5
    parts = nlp.kept_parts(np.array(flags, dtype=bool), A, n_int, margin, min_run, window)
    assert parts[0][0] == A and parts[-1][1] == A + n
    for (_, b, k), (a2, _, k2) in itertools.pairwise(parts):
        assert b == a2 and k != k2  # consecutive, alternating
    for a, b, k in parts:
        assert b > a
        if k:
            assert all(flags[a - A : b - A]) and b - a >= min_run
        elif len(parts) > 1:
            # a solved part holds the usual window between the rest intervals (unless it is the whole chain)
            assert nlp._grid_span(a, b, n_int) >= window
            assert b - a >= 2
    for i, f in enumerate(flags):
        if not f:  # every interval that may not keep the LP's feed is solved, with its margin
            around = range(max(0, i - margin), min(n, i + margin + 1))
            assert not any(k for a, b, k in parts for j in around if a <= A + j < b)


def _straight_turn_straight(L: float) -> Toolpath:
    """Two straight stretches of L mm and a tight turn between them, as one cubic NURBS (four collinear control
    points in a row make a straight span)."""
    P = [(0, 0, 0), (L / 3, 0, 0), (2 * L / 3, 0, 0), (L, 0, 0), (L + 4, 0, 0), (L + 6, 2, 0), (L + 6, 6, 0),
         (L + 6, L / 3, 0), (L + 6, 2 * L / 3, 0), (L + 6, L, 0)]
    n = len(P)
    U = [0] * 4 + list(range(1, n - 3)) + [n - 3] * 4
    return Toolpath([NurbsSegment.create(3, U, P, [1.0] * n)])


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_kept_stretch_at_the_feed_limit_holds_the_limits_and_loses_no_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """At a 100 mm/s feed limit the LP's feed sits at it on the straights: a stretch of the second chain
    keeps it unsolved.  Against every stretch solved: fewer NLP windows, no longer motion, and the samples
    hold u, e and the feed limit; the feed and its slope join continuously at the stretch's ends."""
    F = 100.0
    tp = _straight_turn_straight(150.0)
    m = router().with_feed_max(F)
    kept = schedule(tp, m, Options(method="lp+nlp", nlp_workers=1))
    assert kept.summary["nlp_lp_kept_spans"] >= 1 and kept.summary["nlp_lp_kept_chains"] == 0
    prof = kept.profiles[0]
    assert prof.f_mask is not None and not prof.f_mask[1:-1].all()
    _check_drive(m, kept)
    assert float(np.max(kept.samples.feed)) <= F * (1 + FEED_OVER)
    _assert_seams_continuous(kept)
    # the same in forked workers while the LP runs (``ChainPipeline``)
    par = schedule(tp, m, Options(method="lp+nlp", nlp_workers=2))
    assert par.summary["motion_time"] == kept.summary["motion_time"]
    assert par.summary["nlp_lp_kept_intervals"] == kept.summary["nlp_lp_kept_intervals"]

    monkeypatch.setattr(nlp, "LP_KEPT_MIN_RUN_PER_OVERLAP", 1e6)
    solved = schedule(tp, m, Options(method="lp+nlp", nlp_workers=1))
    assert solved.summary["nlp_lp_kept_spans"] == 0
    assert kept.summary["nlp_windows"] < solved.summary["nlp_windows"]
    assert kept.summary["motion_time"] <= (1 + KEPT_MOTION_REL) * solved.summary["motion_time"]


def test_a_break_whose_step_cap_the_feed_is_far_under_does_not_stop_a_stretch(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 3-D wave at a 10 mm/s cap: C1 knots (a step cap on the feed at each) every ~12 knot intervals, the
    LP's feed at the cap between them and a few % of each step's cap.  Kept against every break stopping a
    stretch (LP_KEPT_STEP_CAP_SHARE 0, as until session 53): whole chains kept, far fewer NLP windows,
    the motion longer by at most the kept feed's gap to its bound, the samples within u, e and the cap."""
    F = 10.0
    tp = Toolpath([ex.wave3d()])
    m = router().with_feed_max(F)
    kept = schedule(tp, m, Options(method="lp+nlp", nlp_workers=1))
    assert kept.summary["nlp_lp_kept_chains"] >= 1 and kept.summary["nlp_lp_kept_spans"] >= 1
    _check_drive(m, kept)
    assert float(np.max(kept.samples.feed)) <= F * (1 + FEED_OVER)
    _assert_seams_continuous(kept)
    monkeypatch.setattr(nlp, "LP_KEPT_STEP_CAP_SHARE", 0.0)
    solved = schedule(tp, m, Options(method="lp+nlp", nlp_workers=1))
    assert solved.summary["nlp_lp_kept_chains"] == 0
    assert solved.summary["nlp_lp_kept_intervals"] < 0.1 * solved.profiles[0].n_int
    assert 4 * kept.summary["nlp_windows"] < solved.summary["nlp_windows"]
    assert kept.summary["motion_time"] <= (1 + nlp.LP_KEPT_FEED_GAP) * solved.summary["motion_time"]
