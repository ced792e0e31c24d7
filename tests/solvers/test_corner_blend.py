"""Scheduling a zig-zag of lines: stop at every corner vs. G2 clothoid blends within a tolerance.

The blended path is one piece (no rest points) and its sampled output stays within the
machine's limits (independent finite-difference check); it is measurably faster.
"""

from __future__ import annotations

import numpy as np

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
