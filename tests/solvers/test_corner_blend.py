"""Scheduling a zig-zag of lines: stop at every corner vs. G2 clothoid blends within a tolerance.

The blended path is one piece (no rest points) and its sampled output stays within the
machine's limits (independent finite-difference check); it is measurably faster.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import gcode, primitives
from geometry.clothoid import blend_polyline
from geometry.primitives import polyline
from geometry.toolpath import Toolpath
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.solvers.test_limits import _check
from tests.solvers.test_nlp import _check_drive

#: 8 legs of 11.2 mm turning 53 degrees alternately (a pocketing-style zig-zag).
ZIGZAG = np.array([[10.0 * i, 5.0 * (i % 2), 0.0] for i in range(9)])
#: Blend tolerance (mm) and the speed-up it must give over stopping at each corner
#: (measured 3.634 s / 2.252 s = 1.61 on the router preset at commit time; 3.129 s / 2.159 s = 1.45 before the
#: LP's rest shapes, which make a stop cheaper: 2.526 s / 1.998 s = 1.26, session 27).
BLEND_TOL_MM = 0.1
MIN_SPEEDUP = 1.2
#: Random program cam 20 blended at 0.46 um vs stopping at each corner: at most this many times as long (412 s /
#: 1.34 s = 308 before ``lp.curvature_jump``, 6.3 s / 1.34 s = 4.7 with it, 2.51 s / 1.34 s = 1.9 with the floor
#: refinements past the plan's doublings too, ``pipeline.FLOOR_REFINE_PAST_PLAN``).
CRAWL_FACTOR = 3.0


def test_blended_zigzag_is_faster_and_within_limits() -> None:
    m = router()
    stop = Toolpath([polyline(ZIGZAG)])
    blended = Toolpath(blend_polyline(ZIGZAG, BLEND_TOL_MM))
    assert len(stop.pieces) == 8 and len(blended.pieces) == 1
    t_stop = schedule(stop, m, Options(method="lp")).summary["motion_time"]
    sch = schedule(blended, m, Options(method="lp"))
    _check(blended, m, sch)
    t_blend = sch.summary["motion_time"]
    assert t_stop / t_blend >= MIN_SPEEDUP, (t_stop, t_blend)


def test_blended_zigzag_lp_nlp_within_drive_limits() -> None:
    m = router()
    blended = Toolpath(blend_polyline(ZIGZAG, BLEND_TOL_MM))
    lp = schedule(blended, m, Options(method="lp")).summary["motion_time"]
    sch = schedule(blended, m, Options(method="lp+nlp"))
    _check_drive(m, sch)
    assert sch.summary["motion_time"] < lp


def test_dense_g01_spiral_blended_within_limits_and_on_the_path() -> None:
    """Dense CAM output (issue 7 item 4), small: 1,500 G01 moves of 0.5 mm (0.75 m spiral) blended at
    0.02 mm run as one piece within every limit (sampled FD), each sample within the blend tolerance of
    the programmed polyline. ``bench/dense_gcode.py`` runs the same program at 150,000 moves."""
    from bench.dense_gcode import spiral_program
    from geometry import gcode

    prog = gcode.parse(spiral_program(1500))
    tp = prog.toolpath(0.5, blend_mm=0.02)
    assert len(tp.pieces) == 2  # the rapid to the start, then the whole G01 run without a stop
    assert {int(k) for k in tp.sub_kind} == {1, 2}  # lines and clothoids, all in closed form
    m = router()
    sch = schedule(tp, m, Options(method="lp"))
    _check(tp, m, sch)
    # distance of every sample of the G01 run to the programmed polyline (the blend tolerance)
    vertices = np.array([seg.control_points[-1] for seg in prog.segments])
    run = sch.samples.position[sch.samples.s > tp.pieces[1].s_start]
    a, b = vertices[:-1], vertices[1:]
    best = np.full(run.shape[0], np.inf)
    for i in range(0, a.shape[0], 200):  # legs in blocks (memory)
        aa, bb = a[i : i + 200], b[i : i + 200]
        d = bb - aa
        t = np.clip(np.einsum("kij,ij->ki", run[:, None, :] - aa[None], d) / np.einsum("ij,ij->i", d, d), 0, 1)
        near = aa[None] + t[..., None] * d[None]
        best = np.minimum(best, np.linalg.norm(run[:, None, :] - near, axis=2).min(axis=1))
    assert best.max() <= 0.02 * (1 + 1e-6)


def test_curvature_jump_reads_no_jump_inside_a_blend_and_one_over_r_at_an_arc() -> None:
    """``lp.curvature_jump`` at the junctions of a 0.2 um line-line blend (G2: no jump, though x_sss reaches
    1.4e6 /mm^2 there, so the plain difference of x_ss at +-1 nm reads 1.85 /mm; the residual, from x_ssss,
    3.2e-3), and where a line meets a tangent arc of radius R (a C1 junction: the jump is 1 / R, analytic)."""
    from solvers.lp import BREAK_EPS_MM, curvature_jump

    pts = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [15.0, 8.660254037844386, 0.0]])
    tp = Toolpath(blend_polyline(pts, 2e-4))
    br = tp.offsets[1:-1]
    assert br.size == 3  # line | spiral | spiral | line
    right, left = tp.evaluate(br + BREAK_EPS_MM), tp.evaluate(br - BREAK_EPS_MM)
    plain = np.max(np.abs(right.d2 - left.d2))
    assert plain > 1.0  # the smooth part of x_ss over 2 nm
    assert np.max(np.linalg.norm(curvature_jump(right, left, BREAK_EPS_MM), axis=1)) < 1e-2 * plain
    R = 4.0
    arc = Toolpath([primitives.line([-5.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
                    primitives.arc([0.0, 0.0, 0.0], [R, R, 0.0], centre=[0.0, R, 0.0], direction="ccw")])
    b = arc.offsets[1:2]
    jump = curvature_jump(arc.evaluate(b + BREAK_EPS_MM), arc.evaluate(b - BREAK_EPS_MM), BREAK_EPS_MM)
    np.testing.assert_allclose(np.linalg.norm(jump, axis=1), 1.0 / R, rtol=1e-6)


def test_tiny_blends_do_not_crawl(monkeypatch: pytest.MonkeyPatch) -> None:
    """Random program cam 20 (23 moves, corners blended at 0.46 um; its blends' clothoids are 0.6-2 um long):
    the curvature jumps read at their G2 junctions capped the LP's feed and held it at its floor across a
    0.14 mm knot interval, 412 s of motion for a 72 mm path that takes 1.34 s stopping at every corner.  Now
    2.5 s (its blends still cost: they are far narrower than the knots; see the README's limits).

    The product now refuses blend tolerances under 1 um (``arcblend.MIN_BLEND_TOLERANCE_MM``), but a NURBS
    path can still hold clothoid-sized features, so the solver is tested on the drawn 0.46 um with the rule
    lifted."""
    from geometry import arcblend
    from tests.reliability import gen, harness

    monkeypatch.setattr(arcblend, "MIN_BLEND_TOLERANCE_MM", 0.0)
    case = gen.cam_case(20, "cam", min_blend_mm=0.0)
    assert case.program is not None and case.program.tolerance_mm < 1e-3
    stops = gcode.parse(case.gcode or "", start=case.start).toolpath()
    t_stop = schedule(stops, case.lp_machine, Options(method="lp")).summary["motion_time"]
    out = harness.run(case, "lp")
    assert out.ok, out.describe()
    assert out.samples * 1e-3 < CRAWL_FACTOR * t_stop


#: A zig-zag of 10 mm legs at +-30 degrees (60 degree turns), F6000, router, lp+nlp, blended at 5 um vs stopping
#: at each corner: at most this many times as long (2.757 s / 1.770 s = 1.56 with the NLP's floor refinement
#: capped at 64 intervals; 1.793 s / 1.770 s = 1.01 at 512, ``pipeline.NLP_FLOOR_REFINE_MAX_INTERVALS``).
NARROW_BLEND_FACTOR = 1.1


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_lp_nlp_on_a_narrow_blend_is_not_much_slower_than_stopping() -> None:
    """A 5 um blend turns 60 degrees in clothoids of 25 um, far inside the plan's 1.25 mm knots: the LP holds
    control points at their floor there, and on the plan's knots the NLP ran 1.56 x as long as stopping at each
    corner.  Refined to 280 intervals (0.29 mm), within 1.1 x, and the samples stay within the drive's limits."""
    ang = np.radians(30.0)
    pts = [np.zeros(2)]
    for i in range(8):
        d = ang if i % 2 == 0 else -ang
        pts.append(pts[-1] + 10.0 * np.array([np.cos(d), np.sin(d)]))
    prog = "G21 G90 G01 F6000\n" + "\n".join(f"X{p[0]:.6f} Y{p[1]:.6f}" for p in pts[1:]) + "\n"
    m = router()
    opt = Options(method="lp+nlp")
    t_stop = schedule(gcode.parse(prog).toolpath(), m, opt).summary["motion_time"]
    blended = gcode.parse(prog).toolpath(blend_mm=0.005)
    sch = schedule(blended, m, opt)
    assert len(blended.pieces) == 1
    assert sch.summary["motion_time"] <= NARROW_BLEND_FACTOR * t_stop
    _check_drive(m, sch)
