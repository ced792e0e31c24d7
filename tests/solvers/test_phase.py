"""Default knots phased to the curvature peaks (``solvers.pipeline.phase_intervals``).

Truth: the flower r = 40 + 15 cos(5 theta) has 5 equal petal valleys (radius of curvature 1.77 mm) at
theta = (2k + 1) pi / 5, one fifth of the loop apart in arc length by symmetry; their positions are
found here from the analytic polar curve (independent of the NURBS fit the toolpath holds), and the
motion time of method lp is compared on the knot counts the heuristic weighs (the effect it relies
on: a valley on a knot costs more time than one mid-interval).
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import examples as ex
from geometry.toolpath import Toolpath
from solvers import pipeline as P
from solvers.machine import router
from solvers.pipeline import Options, schedule

#: A valley counts as mid-interval within this phase distance of 0.5.
MID_PHASE_TOL = 0.1
#: Arc length of a valley from the analytic curve vs the NURBS fit's, mm (the fit is within ~1 um).
VALLEY_S_TOL = 0.05


def _valleys_analytic() -> np.ndarray:
    """Arc lengths of the flower's 5 valleys on the analytic curve (trapezoid on 2e5 steps), (5,)."""
    th = np.linspace(0.0, 2.0 * np.pi, 200_001)
    r = 40.0 + 15.0 * np.cos(5.0 * th)
    dr = -75.0 * np.sin(5.0 * th)
    speed = np.hypot(r, dr)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(th))])
    return np.interp((2 * np.arange(5) + 1) * np.pi / 5.0, th, s)


def _phases(s: np.ndarray, L: float, n: int) -> np.ndarray:
    return np.mod(s * n / L, 1.0)


def test_flower_valleys_go_mid_interval() -> None:
    tp, m = ex.flower(1), router()
    piece = tp.pieces[0]
    n0 = P.plan_piece(piece, m, Options()).n_int
    n = P.plan_piece(piece, m, Options(), toolpath=tp).n_int
    # method lp keeps the plain count (its knot refinements undo the phase: pipeline.PHASE_SEARCH)
    assert P.plan_piece(piece, m, Options(method="lp"), toolpath=tp).n_int == n0
    valleys = _valleys_analytic()
    # the fit's curvature peaks are where the analytic valleys are
    s = np.linspace(0.0, tp.length, 400_001)
    kap = np.linalg.norm(tp.evaluate(s).d2, axis=1)
    for v in valleys:
        near = np.abs(s - v) < 5.0
        assert abs(s[near][np.argmax(kap[near])] - v) < VALLEY_S_TOL
    assert abs(n - n0) <= np.ceil(P.PHASE_SEARCH * n0)
    assert np.all(np.abs(_phases(valleys, tp.length, n) - 0.5) <= MID_PHASE_TOL), _phases(valleys, tp.length, n)
    # the plain count leaves some valley near a knot (else this test would not test the search)
    assert np.any(np.abs(_phases(valleys, tp.length, n0) - 0.5) > 2 * MID_PHASE_TOL)


def test_phased_knots_are_faster_than_valleys_on_knots() -> None:
    """The effect the heuristic relies on, measured: method lp on the phased knot count vs the plain
    count and vs the count in the search range that puts every valley nearest a knot."""
    tp, m = ex.flower(1), router()
    piece = tp.pieces[0]
    L = tp.length
    n0 = P.plan_piece(piece, m, Options()).n_int
    n = P.plan_piece(piece, m, Options(), toolpath=tp).n_int
    valleys = _valleys_analytic()
    cands = np.arange(int(n0 * (1 - P.PHASE_SEARCH)), int(n0 * (1 + P.PHASE_SEARCH)) + 1)
    worst = int(cands[np.argmin([np.sum(np.sin(np.pi * _phases(valleys, L, c)) ** 2) for c in cands])])
    t = {k: schedule(tp, m, Options(method="lp", knot_spacing=L / k)).summary["motion_time"] for k in (n, n0, worst)}
    assert t[n] < t[n0] < t[worst]
    # the default (lp+nlp) schedule is the phased one
    assert schedule(tp, m, Options()).summary["motion_time"] == pytest.approx(
        schedule(tp, m, Options(knot_spacing=L / n)).summary["motion_time"], rel=1e-9)


def test_no_sharp_peaks_keep_the_plain_count() -> None:
    m = router()
    for tp in (Toolpath([ex.line((0.0, 0.0, 0.0), (300.0, 0.0, 0.0))]), Toolpath([ex.circle(30.0)])):
        piece = tp.pieces[0]
        assert P.plan_piece(piece, m, Options(), toolpath=tp).n_int == P.plan_piece(piece, m, Options()).n_int


def test_long_pieces_and_explicit_spacing_keep_the_plain_count(monkeypatch: pytest.MonkeyPatch) -> None:
    tp, m = ex.flower(1), router()
    piece = tp.pieces[0]
    assert P.plan_piece(piece, m, Options(knot_spacing=2.3), toolpath=tp).n_int == P.plan_piece(
        piece, m, Options(knot_spacing=2.3)).n_int
    n0 = P.plan_piece(piece, m, Options()).n_int
    monkeypatch.setattr(P, "PHASE_MAX_INTERVALS", n0 - 1)
    assert P.plan_piece(piece, m, Options(), toolpath=tp).n_int == n0
