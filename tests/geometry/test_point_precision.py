"""Emitted positions are smooth to a few units in the last place: their second differences, what a checker
reads as acceleration, against the analytic C_ss.

Bench seed 5029 (lp) was refused for its own samples: a segment 6 mm long over u in [0, 0.025] (|C'| up to
5.1e3 mm), on a machine whose amax_x Ts^2 is 9.7e-12 mm; the positions' noise, ~1e-13 mm, read as 1.2 % over
amax.  Two sources, both removed by ``Toolpath.evaluate(precise=True)``: u's own rounding and the
quintic guess's tolerance (an arc-length residual s - s(u), now followed along the tangent), and the compiled
kernel's Taylor form near a long span's ends (exact points now come from de Boor's algorithm).

The truth: for s_k = s_0 + k h, second differences of C(s_k) are h^2 C_ss(s_k) + O(h^4 C_ssss); at h = 1 um
the remainder is ~1e-24 mm, so what is left is rounding: of each point (POINT_ULPS units of the largest
control point coordinate) and of s_k itself (its ulp, times |C_s| = 1).  Without ``precise`` the same segments
read up to 154 units of the control points (the test's own check that it can fail)."""

from __future__ import annotations

import numpy as np
import pytest

from geometry.toolpath import Toolpath
from tests.geometry.nurbs_factory import random_nurbs

#: rounding of one emitted point, in units in the last place of the segment's largest control point
#: coordinate (seen after the change: second differences <= 17.5 such units over 8 segments, with s ~ 1.5e3 mm
#: contributing ~4 units a point)
POINT_ULPS = 4.0
#: the arc-length step of the differences (mm): 1 mm/s at 1 kHz
STEP_MM = 1e-6
#: differences per window
N_STEPS = 200_000
#: seeds whose window at the segment's end fails the bound without ``precise`` (2.8 and 3.2 x it; precise <= 0.6 x)
PLAIN_FAILS = (3, 6)


def _noise_bound(seg_scale: float, s_max: float) -> float:
    """Second differences' rounding bound: 4 points' worth (1, -2, 1) of point and arc-length rounding."""
    return 4.0 * (POINT_ULPS * float(np.spacing(seg_scale)) + float(np.spacing(s_max)))


@pytest.mark.parametrize("seed", range(8))
def test_second_differences_of_points_on_a_segment_long_in_mm_short_in_u(seed: int) -> None:
    """Cubic NURBS over u in [0, 0.025], control points up to 400 mm, weights 0.2-5 (|C'| ~ 1e4-1e5 mm): at the
    start, at 30 % and at the end of the segment."""
    rng = np.random.default_rng(seed)
    seg = random_nurbs(rng, 3, 1, 0.0, 0.025, (0.2, 5.0), extent_mm=400.0).segment()
    tp = Toolpath([seg])
    scale = float(np.max(np.abs(seg.control_points)))
    for s0 in (0.0, 0.3 * tp.length, tp.length - N_STEPS * STEP_MM):
        s = s0 + STEP_MM * np.arange(N_STEPS + 1)
        ev = tp.evaluate(s, precise=True)
        err = np.abs(np.diff(ev.position, 2, axis=0) - STEP_MM**2 * ev.d2[1:-1])
        assert err.max() <= _noise_bound(scale, float(s[-1])), (s0, err.max() / np.spacing(scale))
        if seed in PLAIN_FAILS and s0 > 0.3 * tp.length:  # the end: the test can fail
            plain = tp.evaluate(s).position
            plain_err = np.abs(np.diff(plain, 2, axis=0) - STEP_MM**2 * ev.d2[1:-1])
            assert plain_err.max() > _noise_bound(scale, float(s[-1]))


def test_coordinate_scale_is_the_largest_control_point_coordinate() -> None:
    """Far-out control points count, not only the curve's own extent."""
    seg = random_nurbs(np.random.default_rng(6), 3, 1, 0.0, 0.025, (0.2, 5.0), extent_mm=400.0).segment()
    tp = Toolpath([seg])
    assert tp.coordinate_scale == float(np.max(np.abs(seg.control_points)))
    assert tp.coordinate_scale >= float(np.max(np.abs(tp.evaluate(np.linspace(0.0, tp.length, 101)).position)))
