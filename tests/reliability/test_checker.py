"""The independent checker is not vacuous: its evaluator matches analytic curves, and it rejects
schedules spoiled in each way it is meant to catch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from geometry import examples as ex
from geometry import primitives
from geometry.toolpath import Toolpath
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.reliability import checker, gen

TS = 1e-3
RADIUS = 10.0
#: Offsets used to spoil a schedule (mm): twice the path tolerance.
OFF_PATH_MM = 2.0 * checker.PATH_TOL_MM


def _nurbs(seg: object) -> checker.Nurbs:
    return checker.Nurbs(seg.degree, seg.knots, seg.control_points, seg.weights)  # type: ignore[attr-defined]


def test_de_boor_matches_the_circle_and_distance_is_exact() -> None:
    n = _nurbs(ex.circle(RADIUS))
    u = np.linspace(*n.domain, 101)
    np.testing.assert_allclose(np.linalg.norm(n.points(u)[:, :2], axis=1), RADIUS, rtol=0, atol=1e-12)
    rng = np.random.default_rng(3)
    th = rng.uniform(0, 2 * np.pi, 400)
    r = RADIUS + rng.uniform(-1e-3, 1e-3, 400)
    x = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros_like(th)])
    np.testing.assert_allclose(checker.path_distance([n], x), np.abs(r - RADIUS), rtol=0, atol=1e-12)


def test_tangents_are_exact_on_a_circle_at_a_c0_knot_and_on_a_nanometre_line() -> None:
    """Tangents from the hodograph: the rational circle's at its ends and quarter points (analytic: the
    radius turned 90 degrees), both sides of a C0 knot (a polyline's legs), and a 35 nm line 500 mm from the
    origin (the rest of a leg between two 1 um blends, cam-bench seed 16), whose points differenced at
    1e-7 of its domain are equal to the last bits: that read as a 1.87 degree corner nobody stopped at."""
    n = _nurbs(ex.circle(RADIUS))
    lo, hi = n.domain
    for u in np.linspace(lo, hi, 5):
        p = n.points(np.array([u]))[0]
        want = np.array([-p[1], p[0], 0.0]) / RADIUS  # counter-clockwise
        for left in (True, False):
            np.testing.assert_allclose(n.tangent(float(u), left), want, rtol=0, atol=1e-12)
    poly = _nurbs(primitives.polyline([[0, 0, 0], [3, 0, 0], [3, 4, 0]]))
    (k,) = poly.c0_knots()
    np.testing.assert_allclose(poly.end_tangent(True, float(k), left=True), [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(poly.end_tangent(True, float(k), left=False), [0, 1, 0], atol=1e-15)
    a = np.array([300.3501896, 436.9865264, 0.0])
    d = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    tiny = _nurbs(primitives.line(a, a + 35e-6 * d))
    for at_end in (False, True):
        np.testing.assert_allclose(tiny.end_tangent(at_end), d, rtol=0, atol=1e-8)
    assert checker.corners([tiny, _nurbs(primitives.line(a + 35e-6 * d, a + 1.0 * d))]) == []


@pytest.fixture(scope="module")
def corner_run() -> tuple[list[checker.Nurbs], checker.Limits, object]:
    segs = [primitives.line([0, 0, 0], [20, 0, 0]), primitives.line([20, 0, 0], [20, 15, 5])]
    m = router()
    sch = schedule(Toolpath(segs), m, Options(method="lp", sample_period=TS))
    return [_nurbs(s) for s in segs], gen.limits_of(m), sch.samples


def _check(path: list[checker.Nurbs], lim: checker.Limits, t: np.ndarray, feed: np.ndarray,
           pos: np.ndarray) -> checker.Report:
    return checker.check(path, lim, TS, t, feed, pos, kinematic=True, drive=False)


def test_accepts_the_real_schedule(corner_run: tuple) -> None:  # type: ignore[type-arg]
    path, lim, smp = corner_run
    rep = _check(path, lim, smp.t, smp.feed, smp.position)
    assert rep.ok, rep.violations
    assert len(checker.corners(path)) == 1


def test_rejects_a_sample_off_the_path(corner_run: tuple) -> None:  # type: ignore[type-arg]
    path, lim, smp = corner_run
    pos = smp.position.copy()
    k = pos.shape[0] // 4
    pos[k, 2] += OFF_PATH_MM
    rep = _check(path, lim, smp.t, smp.feed, pos)
    assert any("off the path" in v for v in rep.violations)


def test_rejects_a_faster_replay(corner_run: tuple) -> None:  # type: ignore[type-arg]
    """The same positions replayed at 1.05 x speed (every 21st sample dropped) exceed some limit."""
    path, lim, smp = corner_run
    keep = np.ones(smp.t.size, dtype=bool)
    keep[1:-1:21] = False
    n = int(keep.sum())
    rep = _check(path, lim, TS * np.arange(n), smp.feed[keep] * 1.05, smp.position[keep])
    assert not rep.ok


def test_rejects_passing_a_corner_without_stopping() -> None:
    """A constant 10 mm/s walk along the polyline: at the corner it never slows down."""
    segs = [primitives.line([0, 0, 0], [2, 0, 0]), primitives.line([2, 0, 0], [2, 2, 0])]
    path = [_nurbs(s) for s in segs]
    lim = checker.Limits(np.full(3, 1e3), np.full(3, 1e2), np.full(3, 1e15))
    s = np.linspace(0.0, 4.0, 401)
    pos = np.where(s[:, None] <= 2.0, np.column_stack([s, 0 * s, 0 * s]),
                   np.column_stack([2.0 + 0 * s, s - 2.0, 0 * s]))
    feed = np.full(s.size, 4.0 / (400 * TS))
    feed[0] = feed[-1] = 0.0
    rep = checker.check(path, lim, TS, TS * np.arange(s.size), feed, pos, kinematic=True, drive=False)
    assert any("no stop" in v for v in rep.violations)


def test_rejects_nan_and_a_broken_period(corner_run: tuple) -> None:  # type: ignore[type-arg]
    path, lim, smp = corner_run
    pos = smp.position.copy()
    pos[3, 0] = np.nan
    assert not _check(path, lim, smp.t, smp.feed, pos).ok
    t = smp.t.copy()
    t[5] += 0.1 * TS
    assert any("period" in v for v in _check(path, lim, t, smp.feed, smp.position).violations)


#: Distance (mm) a point on the curve may read from it (the searches stop at ~1e-12 of a bracket).
ON_CURVE_MM = 1e-6


def test_points_on_the_curve_read_as_on_it_where_a_bracket_has_two_minima() -> None:
    """Bench seed 2527's last segment (degree 4, weights 0.34-2.2, 2,594 mm over two knot spans): its
    dense polyline has 5.9 mm chords, and around u = 7.30355 (a tight bend) one bracket holds two local
    minima of the distance; the golden search took the wrong one and read a point on the curve as
    66 um off (both methods failed the bench).  Points of the curve itself must read ~0: that one,
    and 2,000 random ones over the path."""
    path = gen.case(2527, "bench").segments
    rng = np.random.default_rng(0)
    pts = [path[4].points(np.array([7.3035553]))]
    for seg in path:
        lo, hi = seg.domain
        pts.append(seg.points(rng.uniform(lo, hi, 400)))
    d = checker.path_distance(path, np.concatenate(pts))
    assert float(np.max(d)) <= ON_CURVE_MM


#: Where bench seed 8542's lp schedule crawled before session 26 (mm of arc length), and points there.
CRAWL_8542_MM = (134.96, 135.01)
CRAWL_8542_POINTS = 40_000


def test_vectorised_search_settles_samples_whose_feet_lie_outside_the_two_nearest_brackets() -> None:
    """Bench seed 8542 (lp): the check of 75,731 samples took 160 s of CPU, over the bench's budget (a
    'CaseTimeout', the schedule itself 2.5 s and within every limit).  The brackets of the two nearest dense
    points held no foot for 24,880 samples (40 um off), which fell to the per-point search of every bracket
    in reach.  The chunked search now covers the NEAREST_BRACKETS nearest: it must settle every sample
    within PATH_TOL_MM by itself (the samples are C(s) to ~1e-12 mm).

    Those samples were a crawl over s = 134.96-135.01 mm (79.4 s of motion, 1.5 s since session 26's bounded
    break couplings, ``lp.WindowLP._step_jerk``), so the test now takes points of the path there itself,
    as densely as the crawl's samples."""
    case = gen.case(8542, "bench")
    x = case.toolpath().evaluate(np.linspace(*CRAWL_8542_MM, CRAWL_8542_POINTS)).position
    dense = checker.dense_polyline(case.segments)
    d0, j0 = cKDTree(dense.pts).query(x, k=checker.NEAREST_BRACKETS)
    best = np.asarray(d0[:, 0], dtype=np.float64).copy()
    checker._nearest_brackets(case.segments, dense, x, j0[:, :1], best, checker.FAST_GOLDEN_ITERATIONS,
                              checker.NEWTON_STEPS)
    off = best > checker.SETTLED_MM
    sub = best[off].copy()
    checker._nearest_brackets(case.segments, dense, x[off], j0[off], sub, checker.GOLDEN_ITERATIONS, 0)
    assert off.sum() > 1000  # (the case still exercises the full search)
    assert np.all(sub <= checker.PATH_TOL_MM), int(np.sum(sub > checker.PATH_TOL_MM))


# --------------------------------------------------------------------------- CAM programs: spirals, program checks


def test_spiral_quadrature_matches_a_circle_and_the_fresnel_form() -> None:
    """The checker's spiral (quadrature of its tangent) against two independent truths: zero sharpness is a
    circle of radius 1 / kappa0; non-zero, geometry.clothoid's Fresnel-integral evaluation."""
    from geometry.clothoid import ClothoidSegment

    e1, e2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.6, 0.8])
    arc = checker.Spiral(np.array([1.0, 2.0, 3.0]), e1, e2, 0.3, 0.5, 0.0, 5.0)
    s = np.linspace(0.0, 5.0, 201)
    centre = arc.start + 2.0 * (-np.sin(0.3) * e1 + np.cos(0.3) * e2)  # radius 1 / 0.5 to the left
    np.testing.assert_allclose(np.linalg.norm(arc.points(s) - centre, axis=1), 2.0, rtol=0, atol=1e-12)
    rng = np.random.default_rng(11)
    for _ in range(20):
        L = float(10.0 ** rng.uniform(-3, 1))
        k0 = float(rng.uniform(-1, 1)) / L
        c = float(rng.choice([-1, 1]) * rng.uniform(0.2, 3.0)) / L**2
        ref = ClothoidSegment.create(rng.normal(size=3), e1, e2, float(rng.uniform(-3, 3)), k0, c, L)
        sp = checker.Spiral(ref.start, e1, e2, ref.phi0, k0, c, L)
        u = np.linspace(0.0, L, 33)
        np.testing.assert_allclose(sp.points(u), ref.points(u), rtol=0, atol=1e-12 * max(1.0, L))
        np.testing.assert_allclose(sp.end_tangent(True), ref.derivatives(np.array([L]))[1, 0], atol=1e-12)


@pytest.fixture(scope="module")
def cam_run() -> tuple[gen.Case, checker.Limits, object]:
    """A blended random program (cam seed 3: 21 moves, 0.91 mm blends) scheduled under lp."""
    case = gen.cam_case(3, "cam")
    assert case.program is not None and case.program.tolerance_mm > 0
    assert any(isinstance(s, checker.Spiral) for s in case.segments)
    sch = schedule(case.toolpath(), case.lp_machine, Options(method="lp", sample_period=TS))
    return case, gen.limits_of(case.lp_machine), sch.samples


def test_accepts_a_blended_program_and_holds_it_to_its_tolerance_and_feeds(cam_run: tuple) -> None:  # type: ignore[type-arg]
    case, lim, smp = cam_run
    rep = checker.check(case.segments, lim, TS, smp.t, smp.feed, smp.position, kinematic=True, drive=False,
                        program=case.program)
    assert rep.ok, rep.violations
    # the blends leave the program (by up to their tolerance) and the F words bind somewhere
    assert 0.3 < rep.utilisation["program_deviation"] <= 1.0
    assert rep.utilisation["program_feed"] > 0.9
    # a tighter tolerance than the blends': samples off the programmed path
    tight = checker.Program(case.program.moves, 0.5 * case.program.tolerance_mm, case.program.feed)
    rep = checker.check(case.segments, lim, TS, smp.t, smp.feed, smp.position, kinematic=True, drive=False,
                        program=tight)
    assert any("off the programmed path" in v for v in rep.violations), rep.violations


def test_rejects_a_feed_over_a_programmed_f(cam_run: tuple) -> None:  # type: ignore[type-arg]
    case, lim, smp = cam_run
    F = [None if f is None else 0.95 * f for f in case.program.feed]
    lower = checker.Program(case.program.moves, case.program.tolerance_mm, F)
    rep = checker.check(case.segments, lim, TS, smp.t, smp.feed, smp.position, kinematic=True, drive=False,
                        program=lower)
    assert any("programmed feed" in v for v in rep.violations), rep.violations


def test_drive_check_reads_the_same_from_given_kinematics() -> None:
    """``fd_drive`` with the differences already at hand (``check`` passes its own) gives what it computes
    itself, and that is the drive model on the differences of a cubic: a and j exact, the central v off by
    Ts^2 x'''/6."""
    t = np.arange(200) * TS
    pos = np.stack([2.0 * t**3, -t**3 + t, 0.5 * t**2], axis=1)
    drive = {k: np.array(v, dtype=float) for k, v in
             {"M": [2.0, 3.0, 4.0], "b": [0.1, 0.2, 0.3], "c": [0.0, 0.5, 0.0], "d": [0.2, 0.0, 0.1],
              "Kv": [1e-3, 2e-3, 3e-3], "Ka": [1e-5, 0.0, 2e-5], "Kj": [0.0, 1e-7, 0.0]}.items()}
    u, e = checker.fd_drive(pos, TS, drive)
    u2, e2 = checker.fd_drive(pos, TS, drive, checker.fd_kinematics(pos, TS))
    np.testing.assert_array_equal(u, u2)
    np.testing.assert_array_equal(e, e2)
    # an interior sample k (index REST_PAD + k - 2 of u): v, a, j of the cubic at t_k
    k = 100
    tk = t[k]
    v = np.array([6.0 * tk**2, -3.0 * tk**2 + 1.0, tk])
    a = np.array([12.0 * tk, -6.0 * tk, 1.0])
    j = np.array([12.0, -6.0, 0.0])
    v = v + TS**2 * j / 6.0  # (the central difference's error on a cubic)
    want_u = drive["M"] * a + drive["b"] * v + drive["c"] + drive["d"] * np.sign(v)
    want_e = drive["Kv"] * v + drive["Ka"] * a + drive["Kj"] * j
    i = checker.REST_PAD + k - 2
    np.testing.assert_allclose(u[i], want_u, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(e[i], want_e, rtol=1e-6, atol=1e-12)
