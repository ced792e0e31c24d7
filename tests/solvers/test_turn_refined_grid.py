"""The LP's cut rounds check points added where the path turns sharply between the verification grid's points
(``solvers.lp.WindowLP._check_geometry``, ``VERIFY_TURN_RAD``; method lp only, ``LimitSet.check_turns``).

Truth: a quadratic Bezier on the parabola y = (kappa0 / 2) x^2, apex radius 1 / kappa0, whose arc length from
x = -a to the apex x = 0 is closed form; and the unit tangents of the grid's own points (the turn between
neighbours).  A flower loop, smooth at its grid's scale, gets no point added.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geometry import Toolpath
from geometry import examples as ex
from geometry.nurbs import NurbsSegment
from solvers import lp
from solvers.machine import router

TS = 1e-3
#: Knot intervals of the window (the default plan's minimum is 64).
N_INT = 64


def _needle(radius: float, a: float) -> Toolpath:
    """x from -a to a on y = x^2 / (2 radius): apex radius ``radius`` (mm), arms a (mm) wide."""
    kappa0 = 1.0 / radius
    h = kappa0 * a * a / 2.0
    P = np.array([[-a, h, 0.0], [0.0, -h, 0.0], [a, h, 0.0]])
    return Toolpath([NurbsSegment.create(2, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], P, [1.0, 1.0, 1.0])])


def _window(tp: Toolpath, rest_from_drive: bool = False) -> tuple[lp.WindowLP, np.ndarray]:
    piece = tp.pieces[0]
    d = piece.length / N_INT

    def geometry(s: np.ndarray) -> Any:
        return tp.evaluate(np.asarray(s, dtype=np.float64) + piece.s_start, piece)

    lim = lp.LimitSet.from_machine(router(), TS, True, rest_from_drive=rest_from_drive)
    w = lp.WindowLP(lp.WindowSpec(0, 0, N_INT, d, N_INT, None, True), lim, geometry, "highs")
    return w, np.linspace(0.0, piece.length, N_INT * 5 + 1)


def _turns(g: Any) -> np.ndarray:
    return np.asarray(2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(np.diff(g.d1, axis=0), axis=1), 0.0, 1.0)))


def test_a_turn_narrower_than_the_grid_gets_points_at_its_apex() -> None:
    radius, a = 0.02, 10.0  # (20 um: not a sharp turn; the path is ~5 m, its grid points ~2 mm apart)
    tp = _needle(radius, a)
    assert tp.sharp_turns == []
    w, s_check = _window(tp)
    plain = w.geometry(w._fine(s_check))
    assert float(np.max(_turns(plain))) > math.radians(60.0)  # (the plain grid jumps across the apex)
    g = w._check_geometry(s_check)
    k = 1.0 / radius
    s_apex = a / 2.0 * math.sqrt(1.0 + (k * a) ** 2) + math.asinh(k * a) / (2.0 * k)  # arc length -a .. 0
    assert float(np.min(np.abs(g.s - s_apex))) <= radius  # a point within one radius of the apex
    assert float(np.max(_turns(g))) <= lp.VERIFY_TURN_RAD  # every gap now turns by no more than that
    assert np.all(np.diff(g.s) > 0.0)
    # the floors and column scales read the plain grid
    np.testing.assert_array_equal(w._fine_geometry(s_check).s, plain.s)
    # the grid's old points are all still there, with the same geometry
    i = np.searchsorted(g.s, plain.s)
    np.testing.assert_array_equal(g.s[i], plain.s)
    np.testing.assert_array_equal(g.d2[i], plain.d2)


def test_lp_nlp_checks_the_plain_grid() -> None:
    """Under lp+nlp the NLP windows refine their own grid at turns; the LP keeps its grid."""
    w, s_check = _window(_needle(0.02, 10.0), rest_from_drive=True)
    assert not w.lim.check_turns
    np.testing.assert_array_equal(w._check_geometry(s_check).s, w.geometry(w._fine(s_check)).s)


def test_a_smooth_path_keeps_its_grid() -> None:
    w, s_check = _window(ex.flower(1))
    plain = w.geometry(w._fine(s_check))
    g = w._check_geometry(s_check)
    assert float(np.max(_turns(plain))) < lp.VERIFY_TURN_RAD
    np.testing.assert_array_equal(g.s, plain.s)
