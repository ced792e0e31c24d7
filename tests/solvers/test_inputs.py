"""Bad machine and option input raises typed errors naming the field."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from solvers.errors import InvalidMachineError, InvalidOptionsError, ScheduleError
from solvers.machine import Axis, AxisLimits, DriveModel, Machine, derive_limits, preset, router
from solvers.pipeline import Options
from solvers.timing import PieceProfile, PieceTiming, stalled_intervals


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"method": "magic"}, "options.method"),
        ({"solver": "gurobi"}, "options.solver"),
        ({"sample_period": 0.0}, "options.sample_period"),
        ({"sample_period": math.nan}, "options.sample_period"),
        ({"sample_period": True}, "options.sample_period"),
        ({"knot_spacing": -1.0}, "options.knot_spacing"),
        ({"knot_spacing": math.inf}, "options.knot_spacing"),
        ({"checkpoints_per_interval": 0}, "options.checkpoints_per_interval"),
        ({"lp_window": 4}, "options.lp_window"),
        ({"lp_window": 40, "lp_overlap": 30}, "options.lp_overlap"),
    ],
)
def test_bad_options(kwargs: dict[str, object], field: str) -> None:
    with pytest.raises(InvalidOptionsError) as err:
        Options(**kwargs)  # type: ignore[arg-type]
    assert err.value.field == field
    assert isinstance(err.value, ScheduleError)


@pytest.mark.parametrize("bad", [0.0, -5.0, math.nan, math.inf])
def test_bad_axis_limit(bad: float) -> None:
    axes = list(router().axes)
    axes[1] = Axis("y", AxisLimits(vmax=100.0, amax=bad, jmax=1e4))
    with pytest.raises(InvalidMachineError) as err:
        Machine("custom", tuple(axes))  # type: ignore[arg-type]
    assert err.value.field == "machine.axes.y.amax"


def test_unknown_preset() -> None:
    with pytest.raises(InvalidMachineError) as err:
        preset("mill9000")
    assert err.value.field == "machine"


def test_router_derived_limits_match_thesis_table() -> None:
    """Spec §4: derived from the drive model, X: amax ~ 500, jmax ~ 6.4e4; Y: ~3.3e3, ~1.56e5."""
    m = router()
    x = derive_limits(m.axes[0].drive, 150.0)  # type: ignore[arg-type]
    y = derive_limits(m.axes[1].drive, 150.0)  # type: ignore[arg-type]
    assert x.amax == pytest.approx(500.0, rel=0.01)
    assert x.jmax == pytest.approx(6.4e4, rel=0.02)
    assert y.amax == pytest.approx(3.34e3, rel=0.01)
    assert y.jmax == pytest.approx(1.56e5, rel=0.02)
    # the derived limits keep |u| <= umax and |e| <= emax at the corner of the box
    for axis, lim in (("x", x), ("y", y), ("z", m.axes[2].limits)):
        drv = m.axes["xyz".index(axis)].drive
        assert drv is not None
        u = drv.M * lim.amax + drv.b * lim.vmax + abs(drv.c) + drv.d
        e = drv.Kv * lim.vmax + drv.Ka * lim.amax + drv.Kj * lim.jmax
        assert u <= drv.umax * (1 + 1e-12)
        assert e <= drv.emax * (1 + 1e-12)


def test_drive_without_headroom_rejected() -> None:
    drv = DriveModel(M=1e-3, b=0.05, c=9.0, d=1.5, Kv=1e-5, Ka=1e-5, Kj=1e-8, umax=10.0, emax=0.02)
    with pytest.raises(InvalidMachineError) as err:
        derive_limits(drv, 100.0, "x")
    assert err.value.field == "machine.axes.x.drive.umax"


def test_feed_reaching_zero_inside_a_piece_is_a_clear_error_not_a_runaway() -> None:
    """A profile whose q dips to zero mid-piece: ScheduleError, quickly (was an unbounded bisection)."""
    n = 20
    c = np.full(n + 2, 100.0)
    c[0], c[-1] = -c[1], -c[-2]
    c[10] = c[11] = -5.0  # q < 0 around the middle
    with pytest.raises(ScheduleError):
        PieceTiming.build(PieceProfile(s_start=0.0, length=20.0, d=1.0, c=c))


def test_stall_is_judged_against_the_peak_of_the_feed_in_use() -> None:
    """``stalled_intervals`` compares each interval's lowest q (or f^2) with the peak of the feed the
    profile uses.  Bench seed 1951: a piece keeping the LP's q everywhere (f_mask all False) was
    judged against the NLP's unused f (p), whose square was over 1e12 x q's dip, and read as stalled."""
    n = 20
    c = np.full(n + 2, 100.0)
    c[0], c[-1] = -c[1], -c[-2]
    c[10] = c[11] = 1e-9  # q's dip: 1e-11 of its peak, above STALL_Q_SHARE
    p = np.full(n + 2, 1e4)  # f^2 = 1e8: the dip is 1e-17 of that
    idle = PieceProfile(s_start=0.0, length=20.0, d=1.0, c=c, p=p, f_mask=np.zeros(n, dtype=bool))
    assert stalled_intervals(idle).size == 0
    PieceTiming.build(idle)  # (integrates: no stall)
    used = np.zeros(n, dtype=bool)
    used[2:6] = True  # now f = 1e4 mm/s is the feed on intervals 2-5, and q's dip is a stall beside it
    assert stalled_intervals(replace(idle, f_mask=used)).tolist() == [9, 10]


def test_output_cap_counts_the_samples_exactly() -> None:
    """``Options.max_samples``: a schedule of exactly that many samples is returned; one more than the cap
    is an ``OutputTooLargeError`` naming the option, raised before the samples are built."""
    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.errors import OutputTooLargeError
    from solvers.pipeline import schedule

    tp = Toolpath([primitives.line([0, 0, 0], [30, 10, 0])])
    n = schedule(tp, router(), Options(method="lp")).samples.t.size
    assert schedule(tp, router(), Options(method="lp", max_samples=n)).samples.t.size == n
    with pytest.raises(OutputTooLargeError) as err:
        schedule(tp, router(), Options(method="lp", max_samples=n - 1))
    assert err.value.field == "options.max_samples" and err.value.value == n - 1
    for bad in (0, -5, 2.5, True):
        with pytest.raises(InvalidOptionsError) as e2:
            Options(max_samples=bad)  # type: ignore[arg-type]
        assert e2.value.field == "options.max_samples"


def test_a_deep_but_well_conditioned_dip_is_timed_not_refused() -> None:
    """Bench seed 2966: q falls from ~1e11 (330 m/s) to 0.0217 (a curvature-jump cap, 0.15 mm/s) over a
    few knots (1.3e8 -> 0.0217 over the last one): 2e-13 of its peak, under STALL_Q_SHARE, so the time
    table refused it as a stall.  Each interval's quadratic is well conditioned there (its lowest q is a
    large share of its own control points), so the table now times it: the flat stretch alone takes its
    length / sqrt(q)."""
    n = 40
    c = np.full(n + 2, 1e11)
    c[0], c[-1] = -c[1], -c[-2]
    c[10:15] = [1e9, 1e7, 1e5, 1e3, 10.0]  # down by 1e2 a knot, as the LP's decelerations into the cap
    c[15:25] = 0.0217  # q = 0.0217 on intervals 15..22 (each interval reads c_k .. c_k+2)
    c[25:30] = [10.0, 1e3, 1e5, 1e7, 1e9]
    prof = PieceProfile(s_start=0.0, length=float(n), d=1.0, c=c)
    assert stalled_intervals(prof).size > 0  # (what the knot refinement still treats as stuck)
    flat = 8.0 / math.sqrt(0.0217)
    assert flat < PieceTiming.build(prof).duration < 1.5 * flat
    c[19] = c[20] = 0.0217 * 1e-13  # a dip within the stretch, ill conditioned: still refused
    with pytest.raises(ScheduleError):
        PieceTiming.build(PieceProfile(s_start=0.0, length=float(n), d=1.0, c=c))


def test_a_schedule_over_the_output_cap_at_its_feed_caps_is_refused_before_any_solve() -> None:
    """cam-bench seed 35: F words of 0.02-0.4 mm/s over a 2,718 mm program take at least 22,164 s, over
    the cap, and lp+nlp spent minutes on the pieces before the refusal came.  ``motion_time_floor`` (the
    path at its feed caps: F, Fmax and the axes' speeds) now refuses it before the first LP window (no
    progress reported); a cap just over the floor's samples still schedules, and the motion is not under
    the floor."""
    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.errors import OutputTooLargeError
    from solvers.pipeline import MOTION_FLOOR_SHARE, motion_time_floor, schedule

    f = 2.0  # mm/s on a 30 mm line and a 40 mm one: 35 s at the F words alone
    tp = Toolpath([primitives.line([0, 0, 0], [30, 0, 0]), primitives.line([30, 0, 0], [30, 40, 0])],
                  feed_limits=[f, f])
    for method in ("lp", "lp+nlp"):
        opt = Options(method=method)
        floor = motion_time_floor(tp, router(), opt)
        assert floor == pytest.approx(MOTION_FLOOR_SHARE * 70.0 / f, rel=1e-12)
        seen: list[float] = []
        with pytest.raises(OutputTooLargeError) as err:
            schedule(tp, router(), replace(opt, max_samples=30_000), progress=seen.append)
        assert err.value.field == "options.max_samples" and "at its feed and acceleration limits" in str(err.value)
        assert seen == []  # refused before the first window
        sch = schedule(tp, router(), replace(opt, max_samples=40_000))
        assert floor <= sch.summary["motion_time"] <= 70.0 / f + 1.0


def test_motion_time_floor_bounds_the_axes_speeds() -> None:
    """Without F words the feed is bounded by the axes' speeds (f^2 = sum v_i^2): lp's vmax; lp+nlp's peak
    speed under the control signal, (umax + |c| - d) / b per axis, which the router's 200 mm diagonal line at
    lp+nlp must not pass (a peak of |v| has a = 0, so u = b v + c + d there)."""
    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.machine import drive_speed_bound
    from solvers.pipeline import MOTION_FLOOR_SHARE, motion_time_floor, schedule

    m = router()
    dx = np.array([200.0, 200.0, 100.0])
    tp = Toolpath([primitives.line([0, 0, 0], dx)])
    vmax = np.array([a.limits.vmax for a in m.axes])
    # (the slowest axis over its travel, if that takes longer than the feed at ||vmax||: z here, session 58)
    assert motion_time_floor(tp, m, Options(method="lp")) == pytest.approx(
        MOTION_FLOOR_SHARE * max(300.0 / float(np.linalg.norm(vmax)), float(np.max(dx / vmax))), rel=1e-12)
    assert np.max(dx / vmax) > 300.0 / float(np.linalg.norm(vmax))
    dr = m.drive_arrays()
    v_u = drive_speed_bound(dr)
    assert v_u == pytest.approx((dr["umax"] + np.abs(dr["c"]) - dr["d"]) / dr["b"], rel=1e-15)
    assert np.all(v_u > vmax)  # the NLP may pass the LP's vmax
    # a drive with no voltage left for speed (or no viscous term) bounds nothing: inf, never 0 or negative
    stuck = {**dr, "d": dr["umax"] + np.abs(dr["c"]) + 1.0, "b": np.array([0.0, 1.0, 1.0])}
    assert np.all(drive_speed_bound(stuck) == np.inf)
    assert motion_time_floor(tp, m, Options(method="lp+nlp")) == pytest.approx(
        MOTION_FLOOR_SHARE * max(300.0 / float(np.linalg.norm(v_u)), float(np.max(dx / v_u))), rel=1e-12)
    sch = schedule(tp, m, Options(method="lp+nlp"))
    assert np.all(np.abs(sch.samples.velocity).max(axis=0) <= v_u)
    assert sch.summary["motion_time"] >= motion_time_floor(tp, m, Options(method="lp+nlp"))
    sch = schedule(tp, m, Options(method="lp"))
    assert sch.summary["motion_time"] >= motion_time_floor(tp, m, Options(method="lp"))


def test_motion_time_floor_refuses_a_slow_axis_up_front() -> None:
    """One axis at 1e-8 mm/s on a 10 mm x travel: 1e9 s of
    motion.  The floor read the feed at ||vmax|| alone (0.08 s), the LP ran, and the time table of 1e9 s never
    finished (session 58's API probe: a sync request hung to its 30 s budget, a job ran on).  The slowest axis
    over its travel bounds the time too: refused at once.  On a curve the bound is the axes' end-to-end travel
    (a lower bound of what they travel): a semicircle in x, y with y at 1 mm/s takes at least its 2 R of y
    travel (4 s at R = 2 mm), and its schedule is not under it."""
    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.errors import OutputTooLargeError
    from solvers.machine import Axis, AxisLimits, Machine
    from solvers.pipeline import MOTION_FLOOR_SHARE, motion_time_floor, schedule

    def machine(vx: float, vy: float) -> Machine:
        ax = (("x", vx), ("y", vy), ("z", 100.0))
        return Machine("slow", tuple(Axis(n, AxisLimits(v, 400.0, 50_000.0)) for n, v in ax))  # type: ignore[arg-type]

    tp = Toolpath([primitives.line([0, 0, 0], [10, 5, 1])])
    slow = machine(1e-8, 100.0)
    assert motion_time_floor(tp, slow, Options(method="lp")) == pytest.approx(MOTION_FLOOR_SHARE * 1e9, rel=1e-12)
    with pytest.raises(OutputTooLargeError):
        schedule(tp, slow, Options(method="lp", max_samples=10**7))
    arc = Toolpath([primitives.arc([0, 0, 0], [4, 0, 0], centre=[2, 0, 0], direction="ccw")])
    m = machine(100.0, 1.0)
    floor = motion_time_floor(arc, m, Options(method="lp"))
    assert floor == pytest.approx(MOTION_FLOOR_SHARE * 4.0, rel=1e-9)
    assert schedule(arc, m, Options(method="lp")).summary["motion_time"] >= floor


def test_motion_time_floor_reads_the_promised_accelerations() -> None:
    """Where the schedule promises axis accelerations (method lp), a rest-to-rest path takes at least
    2 sqrt(L / ||A||) and each axis 2 sqrt(|D_i| / A_i), A = ACCEL_FLOOR_SLACK x amax.  Session 59's probe: amax
    1e-12 on a 5 mm line (3.4e6 s of motion) read "cannot leave rest" after a solve; now refused up front as over
    the output cap, before any window.  On the router a short line's schedule (its jerk limits too) is not under
    the floor; lp+nlp promises no accelerations (the NLP may pass the LP's amax): its floor is the feed's."""
    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.errors import OutputTooLargeError
    from solvers.machine import Axis, AxisLimits, Machine
    from solvers.pipeline import ACCEL_FLOOR_SLACK, MOTION_FLOOR_SHARE, motion_time_floor, schedule

    crawl = Machine("crawl", tuple(Axis(n, AxisLimits(100.0, 1e-12, 1e3)) for n in "xyz"))  # type: ignore[arg-type]
    tp = Toolpath([primitives.line([0, 0, 0], [5, 0, 0])])
    floor = motion_time_floor(tp, crawl, Options(method="lp"))
    assert floor == pytest.approx(MOTION_FLOOR_SHARE * 2.0 * math.sqrt(5.0 / (ACCEL_FLOOR_SLACK * 1e-12)), rel=1e-12)
    seen: list[float] = []
    with pytest.raises(OutputTooLargeError, match="acceleration limits"):
        schedule(tp, crawl, Options(method="lp", max_samples=10**7), progress=seen.append)
    assert seen == []
    m = router()
    amax = np.array([a.limits.amax for a in m.axes])
    d = np.array([3.0, -2.0, 0.5])
    line = Toolpath([primitives.line([0, 0, 0], d)])
    bound = max(2.0 * math.sqrt(float(np.linalg.norm(d)) / float(np.linalg.norm(ACCEL_FLOOR_SLACK * amax))),
                float(np.max(2.0 * np.sqrt(np.abs(d) / (ACCEL_FLOOR_SLACK * amax)))))
    floor = motion_time_floor(line, m, Options(method="lp"))
    assert floor == pytest.approx(MOTION_FLOOR_SHARE * bound, rel=1e-12)
    assert floor > motion_time_floor(line, m, Options(method="lp+nlp"))  # (the feed's floor alone there)
    assert schedule(line, m, Options(method="lp")).summary["motion_time"] >= floor


@pytest.mark.parametrize("scale", [1e-120, 1e100])
def test_a_quarter_arc_on_extreme_knots_schedules_as_on_unit_knots(scale: float) -> None:
    """Session 58's probe: knots spanning 1e-120 gave a 200 with NaN accelerations and samples 189 x over amax
    (1e100: a HiGHS failure).  Now the same schedule as on [0, 1] knots, every column finite, within the limits by
    finite differences."""
    from geometry.nurbs import NurbsSegment
    from geometry.toolpath import Toolpath
    from solvers.pipeline import schedule
    from tests.fdcheck import utilisation

    pts, w = [[10.0, 0.0, 0.0], [10.0, 10.0, 0.0], [0.0, 10.0, 0.0]], [1.0, 0.7071067811865476, 1.0]
    m = router()
    times = []
    for k in (1.0, scale):
        seg = NurbsSegment.create(2, [0, 0, 0, k, k, k], pts, w, name="segments[0]")
        sch = schedule(Toolpath([seg]), m, Options(method="lp"))
        smp = sch.samples
        assert all(np.all(np.isfinite(x)) for x in (smp.position, smp.velocity, smp.acceleration, smp.jerk))
        assert max(utilisation(smp.position, 1e-3, *m.limit_arrays()).values()) <= 1.01
        times.append(sch.summary["motion_time"])
    assert times[1] == pytest.approx(times[0], rel=1e-3)


def test_a_window_highs_cannot_solve_names_the_machine_and_the_window(monkeypatch: pytest.MonkeyPatch) -> None:
    """A HiGHS run that ends short of optimality (here its time limit set to nothing, as an ill-conditioned
    LP's iteration stalls end) raises SolverFailure naming the machine, the window and HiGHS's status."""
    import highspy

    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.errors import SolverFailure
    from solvers.lp import WindowLP
    from solvers.pipeline import schedule

    def no_time(h: highspy.Highs) -> None:
        h.setOptionValue("time_limit", 0.0)
        h.run()

    monkeypatch.setattr(WindowLP, "_timed_run", staticmethod(no_time))
    tp = Toolpath([primitives.line(np.zeros(3), np.array([50.0, 20.0, 0.0]))])
    with pytest.raises(SolverFailure) as err:
        schedule(tp, router(), Options(method="lp"))
    assert err.value.field == "machine"
    assert err.value.window == 0
    assert err.value.status is not None and "TimeLimit" in err.value.status
    assert "LP window 0" in err.value.rule


@pytest.mark.parametrize(("key", "bad"), [("amax", 5e-324), ("jmax", 1e-310), ("vmax", 1e-13), ("amax", 1e16)])
def test_a_limit_out_of_float64_s_scale_is_refused(key: str, bad: float) -> None:
    """Limits within [LIMIT_MIN, LIMIT_MAX]: amax 5e-324 made the stopping distance inf and the knot plan raise
    OverflowError (a 500 in the service, session 59's probe)."""
    from solvers.machine import LIMIT_MAX, LIMIT_MIN

    m = router()
    lim = replace(m.axes[0].limits, **{key: bad})
    with pytest.raises(InvalidMachineError) as err:
        Machine(m.name, (replace(m.axes[0], limits=lim), m.axes[1], m.axes[2]))
    assert err.value.field == f"machine.axes.x.{key}" and f"{LIMIT_MIN:g}" in err.value.rule
    assert f"{LIMIT_MAX:g}" in err.value.rule
    with pytest.raises(InvalidMachineError) as err:
        m.with_feed_max(1e-310)
    assert err.value.field == "machine.feed_max"


def test_derived_limits_out_of_scale_name_the_drive_and_drive_vmax_caps_them() -> None:
    """A drive whose Kj is 5e-324 derives jmax = inf: refused naming the drive (it named ``machine.axes.x.jmax``,
    which no request has); a drive's own vmax caps the derived vmax (lp held 51.5 mm/s past vmax 5)."""
    d = router().axes[0].drive
    assert d is not None
    with pytest.raises(InvalidMachineError) as err:
        derive_limits(replace(d, Kj=5e-324), math.inf, "x")
    assert err.value.field == "machine.axes.x.drive" and err.value.value["jmax"] == math.inf
    assert derive_limits(replace(d, vmax=5.0), math.inf, "x").vmax == 5.0
    assert derive_limits(d, math.inf, "x").vmax > 5.0


def test_a_sample_period_under_a_microsecond_is_refused() -> None:
    with pytest.raises(InvalidOptionsError) as err:
        Options(sample_period=1e-300)
    assert err.value.field == "options.sample_period"


@pytest.mark.parametrize("jmax", [1e-3, 1e3])
def test_an_axis_far_slower_than_the_others_schedules_its_own_line(jmax: float) -> None:
    """x amax 1e-3 mm/s^2 (y, z 1000) on a 5 mm x line: the window's q scale read the norm of all three amax
    (2 ||amax|| L = 14,142 against a reachable 0.01), its q sat ~5e-7 of the scale, under HiGHS's tolerances,
    and the acceleration rows gave way through every cut round: a 422 after 15-47 s (sampled a 2.11 x, j 532 x;
    session 59's probe).  The scale reads the moving axes only (``lp.Q_REACH_MOVING_AXES``): it schedules, the
    motion at least the bang-bang optimum 2 sqrt(L / a), the finite differences within the limits."""
    from geometry import primitives
    from geometry.toolpath import Toolpath
    from solvers.machine import Axis, AxisLimits, Machine
    from solvers.pipeline import schedule

    other = AxisLimits(100.0, 1000.0, 1e5)
    m = Machine("slow-x", (Axis("x", AxisLimits(100.0, 1e-3, jmax)), Axis("y", other), Axis("z", other)))
    sch = schedule(Toolpath([primitives.line(np.zeros(3), np.array([5.0, 0.0, 0.0]))]), m, Options(method="lp"))
    assert sch.summary["motion_time"] >= 2.0 * math.sqrt(5.0 / 1e-3)
    x = np.asarray(sch.samples.position)[:, 0]
    ts = sch.summary["sample_period"]
    v, a, j = np.diff(x) / ts, np.diff(x, 2) / ts**2, np.diff(x, 3) / ts**3
    assert np.max(np.abs(v)) <= 100.0 * 1.01 and np.max(np.abs(a)) <= 1e-3 * 1.01
    assert np.max(np.abs(j)) <= jmax * 1.01
