"""Gaps within the gap tolerance between consecutive segments are closed (``geometry.toolpath.close_gaps``).

A gap passed at speed is a position step between two samples (0.5 um made the sampled jerk 12 x jmax,
``tests/reliability/test_adversarial.py``).  The end control points meeting at the gap move to their
midpoint; the rational basis functions are in [0, 1], so no point of either curve moves by more than
half the gap.  Checked against geomdl evaluating the unmoved input.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import GeometryError, Toolpath, primitives
from geometry.nurbs import NurbsSegment
from geometry.toolpath import GAP_CLOSE_MIN_MM, GAP_TOL_MM
from tests.geometry.nurbs_factory import RawNurbs, random_nurbs
from tests.geometry.test_nurbs_oracle import geomdl_curve

#: Rounding allowed on top of the half-gap bound, mm.
ROUND_MM = 1e-12
N_U = 400


def _chain(rng: np.random.Generator, gap_mm: float) -> tuple[RawNurbs, RawNurbs]:
    """Two random rational cubics; the second starts gap_mm off the first one's end."""
    a = random_nurbs(rng, 3, 3)
    b = random_nurbs(rng, 3, 2)
    off = rng.normal(size=3)
    off *= gap_mm / np.linalg.norm(off)
    pts = b.control_points.copy()
    pts[0] = a.control_points[-1] + off
    return a, RawNurbs(b.degree, b.knots, pts, b.weights)


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("gap_mm", [2e-9, 5e-4, 0.999 * GAP_TOL_MM])
def test_gap_is_closed_within_half_of_it(seed: int, gap_mm: float) -> None:
    a, b = _chain(np.random.default_rng(seed), gap_mm)
    tp = Toolpath([a.segment("segments[0]"), b.segment("segments[1]")])
    assert len(tp.closed_gaps) == 1
    assert tp.closed_gaps[0][0] == 1
    assert tp.closed_gaps[0][1] == pytest.approx(gap_mm, rel=1e-6)
    # continuous at the junction: the path's two sides meet
    s_j = tp.offsets[1]
    left, right = tp.positions(np.array([s_j * (1 - 1e-15), s_j]))
    assert np.linalg.norm(right - left) <= ROUND_MM + 1e-13 * s_j
    # each curve within half the gap of the input, point for point (geomdl on the input as given)
    u = np.linspace(0.0, 1.0, N_U)
    for raw, seg in ((a, tp.segments[0]), (b, tp.segments[1])):
        ref = np.asarray(geomdl_curve(raw).evaluate_list(u.tolist()), dtype=np.float64)
        moved = np.max(np.linalg.norm(seg.points(u) - ref, axis=1))
        assert moved <= 0.5 * gap_mm + ROUND_MM


def test_rounding_gaps_and_exact_joins_are_left_alone() -> None:
    segs = [primitives.line([0, 0, 0], [10, 0, 0]), primitives.line([10, 0, 0.1 * GAP_CLOSE_MIN_MM], [20, 5, 0])]
    tp = Toolpath(segs)
    assert tp.closed_gaps == []
    assert tp.segments[0] is segs[0] and tp.segments[1] is segs[1]


def test_gap_over_the_tolerance_is_still_an_error() -> None:
    segs = [primitives.line([0, 0, 0], [10, 0, 0]), primitives.line([10, 0, 2 * GAP_TOL_MM], [20, 0, 0])]
    with pytest.raises(GeometryError) as info:
        Toolpath(segs)
    assert info.value.field == "segments[1].control_points[0]"


def test_unclamped_end_is_not_moved() -> None:
    """An unclamped knot vector does not start at its first control point: that side is left as it is
    (and the gap, measured on the curves, is what the tolerance judges)."""
    p = 2
    knots = np.array([0.0, 0.1, 0.2, 0.5, 0.8, 0.9, 1.0])  # not clamped at the start
    pts = np.array([[10.0, 0.0, 0.0], [12.0, 1.0, 0.0], [14.0, 0.0, 0.0], [16.0, 1.0, 0.0]])
    b = NurbsSegment.create(p, knots, pts)
    start = b.points(np.array([b.domain[0]]))[0]
    a = primitives.line([0, 0, 0], start + np.array([0.0, 0.0, 5e-4]))
    tp = Toolpath([a, b])
    assert tp.closed_gaps == []
    assert tp.segments[1] is b
