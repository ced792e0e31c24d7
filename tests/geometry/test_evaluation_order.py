"""Toolpath evaluation does not depend on the order or grouping of the arc lengths asked for.

``Toolpath.evaluate`` / ``positions`` / ``locate`` group the points by sub-segment in one pass
(``Toolpath._generic_runs``: slices where s is sorted, an argsort otherwise) and evaluate closed-form
sub-segments (lines) apart from NURBS ones.  Truth here: the same points evaluated one at a time (no
grouping at all), and the analytic line and circle.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry.primitives import arc, line
from geometry.toolpath import Toolpath

#: Points asked for (spread over every sub-segment, plus the junctions and the ends).
N_POINTS = 400
#: Batched vs one-at-a-time evaluation: the same arithmetic on each point, so equal to rounding.
SAME_TOL = 1e-12
#: Distance of arc points from the analytic circle (mm), and of line points from the analytic line.
ANALYTIC_TOL_MM = 1e-9
RADIUS = 10.0


def _mixed_path() -> Toolpath:
    """Line (closed form), quarter arc (rational NURBS), line, half arc, line: tangent joins, no corners."""
    r = RADIUS
    return Toolpath([
        line([0.0, 0.0, 0.0], [20.0, 0.0, 0.0]),
        arc([20.0, 0.0, 0.0], [20.0 + r, r, 0.0], centre=[20.0, r]),
        line([20.0 + r, r, 0.0], [20.0 + r, r + 15.0, 0.0]),
        arc([20.0 + r, r + 15.0, 0.0], [20.0 - r, r + 15.0, 0.0], centre=[20.0, r + 15.0]),
        line([20.0 - r, r + 15.0, 0.0], [20.0 - r, 5.0, 0.0]),
    ])


def _grid(tp: Toolpath) -> np.ndarray:
    rng = np.random.default_rng(7)
    s = np.concatenate([rng.uniform(0.0, tp.length, N_POINTS), tp.offsets, [0.0, tp.length]])
    return np.sort(s)


def test_the_mixed_path_has_closed_form_and_nurbs_sub_segments() -> None:
    tp = _mixed_path()
    assert len(tp.subs) >= 5  # (arcs over 90 degrees are split into quarter arcs)
    assert len(tp.corners) == 0
    kinds = set(tp.sub_kind.tolist())
    assert len(kinds) == 2  # lines in closed form, arcs as NURBS


@pytest.mark.parametrize("order", ["sorted", "reversed", "shuffled"])
def test_evaluate_matches_one_point_at_a_time(order: str) -> None:
    tp = _mixed_path()
    s = _grid(tp)
    if order == "reversed":
        s = s[::-1].copy()
    elif order == "shuffled":
        s = np.random.default_rng(3).permutation(s)
    g = tp.evaluate(s)
    one = [tp.evaluate(s[i:i + 1]) for i in range(s.size)]
    for name in ("position", "d1", "d2", "d3"):
        got = getattr(g, name)
        ref = np.concatenate([getattr(o, name) for o in one])
        scale = max(1.0, float(np.max(np.abs(ref))))
        np.testing.assert_allclose(got, ref, rtol=0, atol=SAME_TOL * scale, err_msg=f"{order} {name}")
    np.testing.assert_allclose(tp.positions(s), g.position, rtol=0, atol=SAME_TOL * 100)
    k, u = tp.locate(s)
    k1 = np.concatenate([tp.locate(s[i:i + 1])[0] for i in range(s.size)])
    u1 = np.concatenate([tp.locate(s[i:i + 1])[1] for i in range(s.size)])
    np.testing.assert_array_equal(k, k1)
    np.testing.assert_allclose(u, u1, rtol=0, atol=SAME_TOL * 100)


def test_evaluate_is_the_analytic_path_in_any_order() -> None:
    tp = _mixed_path()
    s = np.random.default_rng(11).permutation(_grid(tp))
    g = tp.evaluate(s)
    # arc length at each input segment's start, and the end
    off = np.append(tp.offsets[np.searchsorted(tp.sub_origin, np.arange(5))], tp.length)
    r = RADIUS
    first = s <= off[1]
    np.testing.assert_allclose(g.position[first], np.column_stack([s[first], 0 * s[first], 0 * s[first]]),
                               rtol=0, atol=ANALYTIC_TOL_MM)
    np.testing.assert_allclose(g.d1[first], np.tile([1.0, 0.0, 0.0], (int(first.sum()), 1)), rtol=0,
                               atol=ANALYTIC_TOL_MM)
    quarter = (s > off[1]) & (s < off[2])
    d = np.linalg.norm(g.position[quarter] - [20.0, r, 0.0], axis=1)
    np.testing.assert_allclose(d, r, rtol=0, atol=ANALYTIC_TOL_MM)
    # curvature 1/R on the arcs: |x_ss| = 1 / R
    np.testing.assert_allclose(np.linalg.norm(g.d2[quarter], axis=1), 1.0 / r, rtol=1e-9)
    half = (s > off[3]) & (s < off[4])
    d = np.linalg.norm(g.position[half] - [20.0, r + 15.0, 0.0], axis=1)
    np.testing.assert_allclose(d, r, rtol=0, atol=ANALYTIC_TOL_MM)
    last = s > off[4]
    np.testing.assert_allclose(g.position[last, 1], r + 15.0 - (s[last] - off[4]), rtol=0, atol=ANALYTIC_TOL_MM)
    np.testing.assert_allclose(g.position[last, 0], 20.0 - r, rtol=0, atol=ANALYTIC_TOL_MM)


def test_empty_grid() -> None:
    tp = _mixed_path()
    g = tp.evaluate(np.zeros(0))
    assert g.position.shape == (0, 3) and g.d3.shape == (0, 3)
    assert tp.positions(np.zeros(0)).shape == (0, 3)
