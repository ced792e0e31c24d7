"""Conversion between API schemas and the pure solver/geometry types, and the output encodings.

Every float leaves in full float64 precision: JSON and NDJSON through orjson
(shortest representation that parses back to the same double), CSV through
``repr`` (the same guarantee), stored results as ``.npz`` of raw float64.
"""

from __future__ import annotations

import io
import json
import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import orjson
from numpy.typing import NDArray

from geometry import GeometryError, NurbsSegment, Toolpath, arcblend, gcode, primitives
from geometry.segment import Segment
from service import resultfile
from service.errors import too_large
from service.schemas import ArcIn, LineIn, MachineIn, NurbsIn, PolylineIn, ScheduleRequest
from solvers.machine import AXES, Axis, AxisLimits, DriveModel, Machine, derive_limits, preset
from solvers.pipeline import Options, Schedule, TimeSamples, fit_intervals, motion_time_floor, total_intervals
from solvers.timing import PieceProfile

FloatArray = NDArray[np.float64]
#: Rows per chunk when streaming CSV/NDJSON.
CHUNK_ROWS = 2000
#: Numbers per piece of a JSON body sent in pieces (``iter_json``): ~1.2 MB.
JSON_CHUNK_VALUES = 65_536
#: Samples above which a JSON result is sent in pieces (``iter_json``) rather than encoded whole: ~30 MB of
#: body, about the synchronous API's budget of 300,000 samples.
JSON_STREAM_ROWS = 300_000
#: Samples of the LP feed kept for the LP vs LP+NLP comparison (diagnostics.lp_feed).
LP_FEED_POINTS = 1200


@dataclass(frozen=True)
class Budget:
    """Work allowed for one request: output samples and LP knot intervals (lower-bound estimates)."""

    max_samples: int
    max_intervals: int
    where: str = "the synchronous API"


@dataclass(frozen=True)
class Result:
    """A schedule as the service keeps it: summary, diagnostics and named float64 columns of equal length."""

    summary: dict[str, Any]
    diagnostics: dict[str, Any]
    columns: dict[str, FloatArray]


def to_machine(m: str | MachineIn) -> Machine:
    if isinstance(m, str):
        return preset(m)
    axes = []
    for name in AXES:
        a = getattr(m.axes, name)
        drive = DriveModel(**a.drive.model_dump()) if a.drive is not None else None
        if a.limits is not None:
            limits = AxisLimits(**a.limits.model_dump())
        else:
            assert drive is not None  # schema: limits or drive
            vmax = math.inf if a.vmax_request is None else float(a.vmax_request)
            limits = derive_limits(drive, vmax, name)
        axes.append(Axis(name, limits, drive))
    return Machine(name=m.name, axes=(axes[0], axes[1], axes[2]), feed_max=m.feed_max)


def machine_fields(m: str | MachineIn) -> dict[str, str]:
    """The request's field of each machine limit the solvers name by their own (``machine.axes.x.jmax``, the
    drive's ``machine.axes.x.drive.emax``): a preset's are all ``machine``; an axis's given limits
    ``machine.axes.x.limits.jmax``; limits derived from the axis's drive model ``machine.axes.x.drive``."""
    out: dict[str, str] = {}
    for name in AXES:
        a = None if isinstance(m, str) else getattr(m.axes, name)
        for key in ("vmax", "amax", "jmax"):
            out[f"machine.axes.{name}.{key}"] = ("machine" if a is None else f"machine.axes.{name}.drive"
                                                 if a.limits is None else f"machine.axes.{name}.limits.{key}")
        if a is None:
            out.update({f"machine.axes.{name}.drive.{key}": "machine" for key in ("umax", "emax")})
    return out


def to_problem(req: ScheduleRequest) -> tuple[Toolpath, Machine, Options]:
    corner_tol = float(req.toolpath.corner_tolerance_deg)
    if req.toolpath.gcode is not None:
        prog = gcode.parse(req.toolpath.gcode)
        if not prog.segments:
            raise GeometryError("toolpath.gcode", None, "the program has no motion")
        tp = prog.toolpath(corner_tol, blend_mm=float(req.toolpath.corner_blend_mm))
    else:
        items = req.toolpath.segments or []
        segs = to_segments(items)
        blend = float(req.toolpath.corner_blend_mm)
        passed: Sequence[Segment] = segs
        try:
            if blend > 0.0:
                bp = arcblend.blend_path(segs, blend)
                passed = bp.segments
                tp = Toolpath(bp.segments, corner_tol_deg=corner_tol, unblended=bp.unblended)
            else:
                tp = Toolpath(segs, corner_tol_deg=corner_tol)
        except GeometryError as exc:
            fld = _request_field(exc.field, items, [seg.name for seg in passed], blend > 0.0)
            if fld == exc.field:
                raise
            raise GeometryError(fld, exc.value, exc.rule, exc.segment) from exc
    machine = to_machine(req.machine)
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
        # one job per core already (``service.executor``: FEEDSCHED_WORKERS solver processes, daemonic)
        nlp_workers=1,
    )
    return tp, machine, opts


def _request_field(field: str, items: Sequence[NurbsIn | LineIn | ArcIn | PolylineIn], names: Sequence[str],
                   blended: bool) -> str:
    """A ``Toolpath`` error's field (``segments[i]...`` of the segments it was given, ``corner_tolerance_deg``: the
    geometry's own names) as the request's path: the segment's name (``toolpath.segments[k]``, or a blend's part
    of it), and unblended, a segment's start as its own kind names it (a NURBS's ``control_points[0]``, a
    polyline's ``points[0]``, a line's or arc's ``start``)."""
    m = re.match(r"segments\[(\d+)\](\.control_points\[0\])?(.*)$", field)
    if m is None:
        return f"toolpath.{field}" if field == "corner_tolerance_deg" else field
    i = int(m.group(1))
    if i >= len(names):
        return f"toolpath.{field}"
    start = m.group(2) or ""
    if blended:  # (the input segment a blend's part came from: its spirals are named after it, ``.corner.in``;
        # a trimmed segment starts where the blend left it)
        base = re.match(r"toolpath\.segments\[\d+\]", names[i])
        return base.group(0) if base else f"toolpath.{field}"
    if start and not isinstance(items[i], NurbsIn):
        start = ".points[0]" if isinstance(items[i], PolylineIn) else ".start"
    return f"{names[i]}{start}{m.group(3)}"


def to_segments(items: Sequence[NurbsIn | LineIn | ArcIn | PolylineIn]) -> list[NurbsSegment]:
    """Exact segments of a JSON chain; a line's or arc's missing start is the previous segment's end."""
    out: list[NurbsSegment] = []
    for i, s in enumerate(items):
        name = f"toolpath.segments[{i}]"
        if isinstance(s, NurbsIn):
            out.append(NurbsSegment.create(s.degree, s.knots, s.control_points, s.weights, name=name))
            continue
        if isinstance(s, PolylineIn):
            out.append(primitives.polyline(s.points, name=name))
            continue
        start: object = s.start if s.start is not None else (out[-1].control_points[-1] if out else None)
        if start is None:
            raise GeometryError(f"{name}.start", None, "the first segment needs a start point", i)
        if isinstance(s, LineIn):
            out.append(primitives.line(start, s.end, name=name))
        else:
            out.append(primitives.arc(start, s.end, centre=s.centre, radius=s.radius, plane=s.plane,
                                      direction=s.direction, turns=s.turns, name=name))
    return out


def control_point_count(req: ScheduleRequest) -> int:
    """Control points of a segment request (a line 2, an arc 9 per turn, a polyline its points);
    for G-code, its line count (an upper bound on its motions)."""
    if req.toolpath.gcode is not None:  # (its lines as the parser splits them: CR-only endings are lines too)
        return len(gcode.lines(req.toolpath.gcode)) + 1
    n = 0
    for s in req.toolpath.segments or []:
        if isinstance(s, NurbsIn):
            n += len(s.control_points)
        elif isinstance(s, PolylineIn):
            n += len(s.points)
        elif isinstance(s, ArcIn):
            n += 9 * (s.turns + 1)
        else:
            n += 2
    return n


def check_budget(tp: Toolpath, machine: Machine, opts: Options, budget: Budget) -> Options:
    """The options to solve with: ``opts``, with lp+nlp's F-word knots coarsened where their count is over
    ``budget`` and the machine's knots are not (``solvers.pipeline.fit_intervals``; the summary's
    ``knot_feed_floor``), and the budget's sample count as ``Options.max_samples`` (checked exactly once the motion
    time is known).  Raise a 413 ServiceError when the work certainly exceeds ``budget`` (estimates are lower
    bounds)."""
    intervals = total_intervals(tp, machine, opts)
    if intervals > budget.max_intervals:
        opts = fit_intervals(tp, machine, opts, budget.max_intervals)
        intervals = total_intervals(tp, machine, opts)
    if intervals > budget.max_intervals:
        raise too_large(
            f"{intervals} knot intervals exceed the {budget.max_intervals} allowed in {budget.where}",
            field="options.knot_spacing", value=opts.knot_spacing,
            rule=f"path length / knot spacing must be <= {budget.max_intervals}",
        )
    floor = motion_time_floor(tp, machine, opts)
    samples = floor / opts.sample_period
    if samples > budget.max_samples:
        raise too_large(
            f"at least {samples:.0f} samples (path {tp.length:.6g} mm in at least {floor:.6g} s at its feed and "
            f"acceleration limits, every {opts.sample_period} s) exceed the {budget.max_samples} allowed in "
            f"{budget.where}",
            field="options.sample_period", value=opts.sample_period,
            rule=f"motion time / sample period must be <= {budget.max_samples}",
        )
    return replace(opts, max_samples=budget.max_samples)


def columns_of(smp: TimeSamples) -> dict[str, FloatArray]:
    """The sample columns in API order: t, s, feed, x, y, z, then v_*, a_*, j_* and (with a drive model) u_*, e_*."""
    cols: dict[str, FloatArray] = {"t": smp.t, "s": smp.s, "feed": smp.feed}
    for i, ax in enumerate(AXES):
        cols[ax] = smp.position[:, i]
    for name, arr in (("v", smp.velocity), ("a", smp.acceleration), ("j", smp.jerk),
                      ("u", smp.control_signal), ("e", smp.servo_error)):
        if arr is not None:
            for i, ax in enumerate(AXES):
                cols[f"{name}_{ax}"] = arr[:, i]
    return {k: np.ascontiguousarray(v, dtype=np.float64) for k, v in cols.items()}


def meta_of(summary: dict[str, Any], diagnostics: dict[str, Any],
            profiles: tuple[PieceProfile, ...]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Summary and diagnostics as the API serves them (plain JSON values; the LP feed of an lp+nlp schedule
    in ``diagnostics.lp_feed``; no per-window timings)."""
    summ = {k: v for k, v in summary.items() if k != "window_times"}
    diag = dict(diagnostics)
    if summary.get("method") == "lp+nlp" and profiles:
        diag["lp_feed"] = lp_feed(profiles)
    return _plain(summ), _plain(diag)


def from_schedule(sch: Schedule) -> Result:
    summary, diagnostics = meta_of(sch.summary, sch.diagnostics, sch.profiles)
    return Result(summary=summary, diagnostics=diagnostics, columns=columns_of(sch.samples))


def lp_feed(profiles: tuple[PieceProfile, ...], points: int = LP_FEED_POINTS) -> dict[str, list[float]]:
    """The LP stage's feed (before the NLP refined it) along the path: ``{"s": [...], "feed": [...]}``, mm and mm/s,
    about ``points`` samples (at least 16 per rest-to-rest piece, both ends included)."""
    total = sum(p.length for p in profiles) or 1.0
    s_out: list[FloatArray] = []
    f_out: list[FloatArray] = []
    for prof in profiles:
        s_loc = np.linspace(0.0, prof.length, max(16, round(points * prof.length / total)))
        lp_only = replace(prof, p=None, f_mask=None)
        s_out.append(s_loc + prof.s_start)
        f_out.append(lp_only.feed(s_loc)[0])
    return {"s": np.concatenate(s_out).tolist(), "feed": np.concatenate(f_out).tolist()}


def _plain(v: Any) -> Any:
    """JSON-compatible copy (numpy scalars to Python numbers)."""
    return json.loads(orjson.dumps(v, option=orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS))


# --- encodings ----------------------------------------------------------------
def encode_json(res: Result, plots: dict[str, str] | None = None) -> bytes:
    body: dict[str, Any] = {"summary": res.summary, "diagnostics": res.diagnostics, "samples": res.columns}
    if plots is not None:
        body["plots"] = plots
    return orjson.dumps(body, option=orjson.OPT_SERIALIZE_NUMPY)


def iter_json(res: Result, plots: dict[str, str] | None = None) -> Iterator[bytes]:
    """``encode_json``'s bytes in pieces, never the whole body at once: the samples column by column,
    JSON_CHUNK_VALUES numbers at a time (a stored result is read from its memory map as it goes)."""
    opt = orjson.OPT_SERIALIZE_NUMPY
    yield b'{"summary":' + orjson.dumps(res.summary, option=opt) + b',"diagnostics":' \
        + orjson.dumps(res.diagnostics, option=opt) + b',"samples":{'
    for i, (name, col) in enumerate(res.columns.items()):
        yield (b"," if i else b"") + orjson.dumps(name) + b":["
        for a in range(0, len(col), JSON_CHUNK_VALUES):
            yield (b"," if a else b"") + orjson.dumps(col[a : a + JSON_CHUNK_VALUES], option=opt)[1:-1]
        yield b"]"
    yield b"}" + (b',"plots":' + orjson.dumps(plots) if plots is not None else b"") + b"}"


def _rows(res: Result, a: int, b: int) -> tuple[list[str], Iterator[tuple[float, ...]]]:
    names = list(res.columns)
    return names, zip(*(res.columns[n][a:b].tolist() for n in names), strict=True)


def _n(res: Result) -> int:
    return len(next(iter(res.columns.values()))) if res.columns else 0


def iter_csv(res: Result) -> Iterator[bytes]:
    """Header line, then one line per sample; repr() keeps every float64 bit."""
    yield (",".join(res.columns) + "\n").encode()
    n = _n(res)
    for a in range(0, n, CHUNK_ROWS):
        _, rows = _rows(res, a, a + CHUNK_ROWS)
        yield "".join(",".join(map(repr, row)) + "\n" for row in rows).encode()


def ndjson_rows(columns: dict[str, FloatArray]) -> Iterator[bytes]:
    """One JSON object per sample and line (``{"t": ..., "s": ..., ...}``), CHUNK_ROWS lines per chunk."""
    names = list(columns)
    n = len(columns[names[0]]) if names else 0
    for a in range(0, n, CHUNK_ROWS):
        rows = zip(*(columns[k][a : a + CHUNK_ROWS].tolist() for k in names), strict=True)
        yield b"".join(orjson.dumps(dict(zip(names, row, strict=True))) + b"\n" for row in rows)


def ndjson_summary(summary: dict[str, Any], diagnostics: dict[str, Any]) -> bytes:
    """The last line of a complete NDJSON result: ``{"event": "summary", "summary": ..., "diagnostics": ...}``."""
    return orjson.dumps({"event": "summary", "summary": summary, "diagnostics": diagnostics},
                        option=orjson.OPT_SERIALIZE_NUMPY) + b"\n"


def ndjson_error(problem: dict[str, Any]) -> bytes:
    """The last line of a failed NDJSON stream: ``{"event": "error", <problem+json fields>}``."""
    return orjson.dumps({"event": "error", **problem}) + b"\n"


def iter_ndjson(res: Result) -> Iterator[bytes]:
    """One JSON object per sample and line, then the summary line (NDJSON_PROTOCOL)."""
    yield from ndjson_rows(res.columns)
    yield ndjson_summary(res.summary, res.diagnostics)


# --- storage (never pickle: float64 arrays in .npz, metadata as JSON) ----------------
def result_bytes(res: Result) -> bytes:
    """A result as .npz bytes: raw float64 columns plus JSON metadata."""
    buf = io.BytesIO()
    meta = json.dumps({"summary": res.summary, "diagnostics": res.diagnostics, "columns": list(res.columns)})
    arrays: dict[str, Any] = {f"c{i}": v for i, v in enumerate(res.columns.values())}
    arrays["__meta__"] = np.frombuffer(meta.encode(), dtype=np.uint8)
    np.savez(buf, **arrays)
    return buf.getvalue()


def save_result(res: Result, path: Path) -> None:
    """A result held in memory (a Dask task's) as the file a solver process streams (``service.resultfile``)."""
    writer = resultfile.ResultWriter(path)
    try:
        writer.append(res.columns)
        writer.finish(res.summary, res.diagnostics)
    except BaseException:
        writer.abort()
        raise


def load_result(path: Path) -> Result:
    """A stored result; its columns are read-only views of a memory map of the file (``resultfile.load``)."""
    summary, diagnostics, columns = resultfile.load(path)
    return Result(summary=summary, diagnostics=diagnostics, columns=columns)


def result_from_bytes(data: bytes) -> Result:
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        meta = json.loads(bytes(z["__meta__"]).decode())
        cols = {name: np.asarray(z[f"c{i}"], dtype=np.float64) for i, name in enumerate(meta["columns"])}
    return Result(summary=meta["summary"], diagnostics=meta["diagnostics"], columns=cols)
