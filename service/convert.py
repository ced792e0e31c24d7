"""Conversion between API schemas and the pure solver/geometry types."""

from __future__ import annotations

from typing import Any

from geometry import NurbsSegment, Toolpath
from service.schemas import ScheduleRequest
from solvers.machine import AXES, Machine, preset
from solvers.pipeline import Options, Schedule


def to_problem(req: ScheduleRequest) -> tuple[Toolpath, Machine, Options]:
    segs = [
        NurbsSegment.create(s.degree, s.knots, s.control_points, s.weights, name=f"toolpath.segments[{i}]")
        for i, s in enumerate(req.toolpath.segments)
    ]
    tp = Toolpath(segs, corner_tol_deg=float(req.toolpath.corner_tolerance_deg))
    machine = preset(req.machine)
    o = req.options
    if o.feed_max is not None:
        machine = machine.with_feed_max(float(o.feed_max))
    opts = Options(
        method=o.method,
        sample_period=float(o.sample_period),
        knot_spacing=None if o.knot_spacing is None else float(o.knot_spacing),
        checkpoints_per_interval=o.checkpoints_per_interval,
        jerk=o.jerk,
        solver=o.solver,
    )
    return tp, machine, opts


def from_schedule(sch: Schedule) -> dict[str, Any]:
    smp = sch.samples
    cols: dict[str, list[float]] = {
        "t": smp.t.tolist(),
        "s": smp.s.tolist(),
        "feed": smp.feed.tolist(),
    }
    for i, ax in enumerate(AXES):
        cols[ax] = smp.position[:, i].tolist()
    for name, arr in (("v", smp.velocity), ("a", smp.acceleration), ("j", smp.jerk)):
        for i, ax in enumerate(AXES):
            cols[f"{name}_{ax}"] = arr[:, i].tolist()
    for name, arr in (("u", smp.control_signal), ("e", smp.servo_error)):
        if arr is not None:
            for i, ax in enumerate(AXES):
                cols[f"{name}_{ax}"] = arr[:, i].tolist()
    summary = {k: v for k, v in sch.summary.items() if k != "window_times"}
    return {"summary": summary, "diagnostics": sch.diagnostics, "samples": cols}
