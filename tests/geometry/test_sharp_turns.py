"""Sharp turns inside a segment (radius under a micrometre) are cut out and made corners.

Truth: a quadratic Bezier is the parabola y = (h / a^2) x^2 (control points (-a, h), (0, -h),
(a, h)), apex at the origin with radius a^2 / (2 h): every figure below is from that closed form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry import examples, nurbs
from geometry.nurbs import SHARP_TURN_CUT_MM, NurbsSegment
from geometry.toolpath import CORNER_TOL_DEG, Toolpath

#: Distance (mm) from the closed-form parabola that rounding allows (coordinates ~1 mm).
ROUND_MM = 1e-12
#: The apex is located to a chord of 1e-3 x the cut (``NurbsSegment.sharp_turns``), so the cut
#: points are the cut's chord from it to within this share.
APEX_SHARE = 1e-3
#: The corner's angle vs the parabola's turn between the cut points: closing the cut moves each end
#: control point by half the gap (here up to 1e-5 mm), which tilts the end tangent by that over the
#: last control polygon leg (~0.01 mm): up to ~0.06 degrees a side.
CORNER_TILT_DEG = 0.15


def _parabola(a: float, h: float) -> NurbsSegment:
    P = np.array([[-a, h, 0.0], [0.0, -h, 0.0], [a, h, 0.0]])
    return NurbsSegment.create(2, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], P, [1.0, 1.0, 1.0])


def _off_parabola(pts: np.ndarray, a: float, h: float) -> np.ndarray:
    """Distance (upper bound) from points to y = (h / a^2) x^2: the nearer of the vertical and the
    horizontal offsets to it."""
    x, y = pts[:, 0], pts[:, 1]
    dy = np.abs(y - h * x**2 / a**2)
    dx = np.where(y >= 0.0, np.abs(np.abs(x) - a * np.sqrt(np.maximum(y, 0.0) / h)), np.inf)
    return np.asarray(np.hypot(pts[:, 2], np.minimum(dx, dy)), dtype=np.float64)


@pytest.mark.parametrize(("a", "h"), [(1e-3, 1.0), (3e-4, 0.5), (1e-6, 1.0)])
def test_near_cusp_is_cut_into_a_corner_at_its_apex(a: float, h: float) -> None:
    """Apex radius a^2 / (2 h): 0.5 nm, 90 pm, 5e-13 mm.  One corner, within the cut of the apex;
    its angle is the parabola's turn between the cut points; the path stays on the parabola to
    within SHARP_TURN_CUT_MM and is shorter by the arc cut out."""
    seg = _parabola(a, h)
    tp = Toolpath([seg])
    assert len(tp.corners) == 1 and tp.sharp_turns == tp.corners
    c = tp.corners[0]
    cut = SHARP_TURN_CUT_MM * (1.0 + APEX_SHARE)
    assert np.linalg.norm(c.position) <= cut
    # the cut points are SHARP_TURN_CUT_MM (chord) from the apex (0, 0): x^2 = a^2 y / h and
    # x^2 + y^2 = cut^2, so y^2 + (a^2 / h) y - cut^2 = 0; the tangent's slope there is 2 h x / a^2
    y = float(np.max(np.roots([1.0, a**2 / h, -SHARP_TURN_CUT_MM**2]).real))
    x = a * math.sqrt(y / h)
    turn = 180.0 - 2.0 * math.degrees(math.atan(a**2 / (2.0 * h * x)))
    assert c.angle_deg == pytest.approx(turn, abs=CORNER_TILT_DEG)
    s = np.linspace(0.0, tp.length, 20001)
    pts = tp.evaluate(s).position
    assert float(np.max(_off_parabola(pts, a, h))) <= cut
    full = Toolpath([seg], corner_tol_deg=179.999).length  # (not cut: the turn is under the tolerance)
    # the arc cut out is at least its two chords and, this close to straight legs, under 1% more
    assert 2.0 * SHARP_TURN_CUT_MM * (1.0 - APEX_SHARE) <= full - tp.length <= 2.0 * cut * 1.01


def test_the_pieces_meet_at_the_cut_with_no_gap() -> None:
    seg = _parabola(1e-3, 1.0)
    parts, cuts = seg.cut_sharp_turns(math.radians(CORNER_TOL_DEG))
    assert cuts.shape == (1, 2) and len(parts) == 2
    end = parts[0].points(np.array([parts[0].domain[1]]))[0]
    start = parts[1].points(np.array([parts[1].domain[0]]))[0]
    assert np.linalg.norm(end - start) <= ROUND_MM
    # the removed apex lies between the cut parameters
    assert cuts[0, 0] < 0.5 < cuts[0, 1]


@pytest.mark.parametrize("radius", [2e-3, 1.0, 100.0])
def test_circles_of_a_micrometre_and_more_are_not_cut(radius: float) -> None:
    """An exact circle (rational quadratic) turns 360 degrees at radius >= 2 um: no sharp turn."""
    tp = Toolpath([examples.circle(radius)])
    assert tp.sharp_turns == [] and tp.corners == []


def test_flower_has_no_sharp_turn() -> None:
    tp = examples.flower()
    assert tp.sharp_turns == [] and tp.corners == []


def test_corner_tolerance_bounds_the_cut() -> None:
    """A near-cusp turning less than the corner tolerance is left alone (passed, not cut)."""
    seg = _parabola(1e-3, 1.0)
    assert seg.sharp_turns(math.radians(179.99)).shape == (0, 2)


def _hidden_apex(x1: float) -> tuple[NurbsSegment, float]:
    """A quadratic Bezier on the needle parabola y = (kappa0 / 2) x^2 (a = 1 mm, h = kappa0 / 2 mm, apex radius
    1 / kappa0 = 0.2 um) from x = -1 to x = c with c = 1 - 2 x1: x(t) = -1 + (1 + c) t is linear in t, so the
    sample t = 8 / 16 of ``sharp_turns`` lies x1 before the apex, on its flank (radius ~20 um for x1 = 0.9 um),
    and the next, t = 9 / 16, 0.12 mm after it, where the tangent is nearly vertical: ~167 degrees between two
    samples whose chord (~38 mm) times the flank's curvature explains any turn.  (P1 is where the end tangents
    meet.)  Returns the segment and kappa0."""
    kappa0 = 5000.0
    h = kappa0 / 2.0
    c = 1.0 - 2.0 * x1
    P = np.array([[-1.0, h, 0.0], [(c - 1.0) / 2.0, -h * c, 0.0], [c, h * c * c, 0.0]])
    return NurbsSegment.create(2, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0], P, [1.0, 1.0, 1.0]), kappa0


def test_an_apex_hidden_between_samples_is_found(monkeypatch: pytest.MonkeyPatch) -> None:
    """Bench seed 866's turn (176 degrees, 0.2 um radius) lay between two of the search's samples whose end
    curvature explained the turn, so it was not searched, and the schedule passed it at speed.  An interval
    turning by more than SHARP_TURN_SEARCH_RAD is searched anyway: the apex is found at the origin, to the
    search's accuracy, and the cut is SHARP_TURN_CUT_MM (chord) from it on each side."""
    x1 = 9e-4
    seg, kappa0 = _hidden_apex(x1)
    # the closed form: the two samples around the apex, their radii and the turn between them
    t = np.array([8.0, 9.0]) / 16.0
    x = -1.0 + (2.0 - 2.0 * x1) * t
    assert x[0] == pytest.approx(-x1) and x[1] > 0.1
    radius = (1.0 + (kappa0 * x) ** 2) ** 1.5 / kappa0
    assert min(radius) > 10.0 * nurbs.SHARP_TURN_RADIUS_MM  # (both over 10 um: neither end is sharp)
    turn = math.pi - math.atan(1.0 / (kappa0 * abs(x[0]))) - math.atan(1.0 / (kappa0 * x[1]))
    assert turn > nurbs.SHARP_TURN_SEARCH_RAD
    cuts = seg.sharp_turns(math.radians(CORNER_TOL_DEG))
    assert cuts.shape == (1, 2)
    ends = seg.points(cuts[0])
    # the cut's chord from the apex (the origin): SHARP_TURN_CUT_MM, doubled while the radius at the cut point
    # is under SHARP_TURN_RADIUS_MM (closed form: x^2 + (kappa0 x^2 / 2)^2 = chord^2 on the parabola)
    chord = SHARP_TURN_CUT_MM
    while chord < nurbs.SHARP_TURN_CUT_MAX_MM:
        xc = math.sqrt((math.sqrt(1.0 + (kappa0 * chord) ** 2) - 1.0) * 2.0 / kappa0**2)
        if (1.0 + (kappa0 * xc) ** 2) ** 1.5 / kappa0 >= nurbs.SHARP_TURN_RADIUS_MM:
            break
        chord *= 2.0
    dist = np.linalg.norm(ends, axis=1)
    assert np.all(np.abs(dist - chord) <= 2.0 * APEX_SHARE * chord), (dist, chord)
    assert ends[0, 0] < 0.0 < ends[1, 0]  # (one on each side of the apex)
    # without the search by angle the apex stays hidden (what the test guards)
    monkeypatch.setattr(nurbs, "SHARP_TURN_SEARCH_RAD", math.inf)
    assert seg.sharp_turns(math.radians(CORNER_TOL_DEG)).shape == (0, 2)
