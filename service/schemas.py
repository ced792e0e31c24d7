"""Request/response schemas of the HTTP API (pydantic).  No solver imports here.

Numbers and booleans are strict (booleans and strings are not numbers; "false"
and 0 are not booleans) and numbers finite (JSON has no NaN/Inf;
``allow_inf_nan=False`` also rejects the ``NaN`` token Python's JSON parser
would accept).  Bounds keep every accepted request physically
meaningful and numerically safe for the solver.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Strict,
    StrictBool,
    StrictInt,
    Tag,
    field_validator,
    model_validator,
)

from geometry.arcblend import BLEND_TOLERANCE_RULE, MIN_BLEND_TOLERANCE_MM
from geometry.nurbs import MAX_DEGREE
from geometry.primitives import MAX_TURNS
from geometry.toolpath import MIN_FEED_MM_S

#: A finite JSON number (integers accepted, booleans and strings not).
Number = Annotated[float, Strict(), AllowInfNan(False)]
Coord = Annotated[Number, Field(ge=-1e6, le=1e6)]


#: The smallest limit or feed cap (``solvers.machine.LIMIT_MIN``, 1e-12 in each unit): far under it the stopping
#: distance that sizes the knots overflowed or underflowed (amax 5e-324, feed_max 1e-310: 500s, session 59's probe).
LIMIT_MIN = MIN_FEED_MM_S
Speed = Annotated[Number, Field(ge=LIMIT_MIN, le=1e5)]  # mm/s
Accel = Annotated[Number, Field(ge=LIMIT_MIN, le=1e8)]  # mm/s^2
Jerk = Annotated[Number, Field(ge=LIMIT_MIN, le=1e12)]  # mm/s^3

MEDIA_JSON = "application/json"
MEDIA_CSV = "text/csv"
MEDIA_NDJSON = "application/x-ndjson"
MEDIA_PROBLEM = "application/problem+json"


class NurbsIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    type: Literal["nurbs"] = "nurbs"
    degree: StrictInt = Field(ge=1, le=MAX_DEGREE)
    knots: list[Annotated[Number, Field(ge=-1e9, le=1e9)]] = Field(min_length=2, max_length=200_000)
    control_points: list[Annotated[list[Coord], Field(min_length=2, max_length=3)]] = Field(
        min_length=2, max_length=200_000
    )
    weights: list[Annotated[Number, Field(gt=0, le=1e6)]] | None = Field(default=None, max_length=200_000)


#: A point in mm: [x, y] (z = 0) or [x, y, z].
PointIn = Annotated[list[Coord], Field(min_length=2, max_length=3)]
START_DOC = "mm; default: where the previous segment ends (required on the first segment)"


class LineIn(BaseModel):
    """A straight line (exact: a degree-1 NURBS)."""

    model_config = ConfigDict(extra="forbid")
    type: Literal["line"]
    start: PointIn | None = Field(default=None, description=START_DOC)
    end: PointIn


class ArcIn(BaseModel):
    """A circular arc in the G17 (XY), G18 (ZX) or G19 (YZ) plane (exact rational quadratic pieces).

    Exactly one of ``centre`` (absolute, mm) and ``radius`` (R format: > 0 the arc of at most 180
    degrees, < 0 the one of at least 180) is given; with ``centre`` and ``end`` = ``start`` the arc
    is a full circle. Start and end radii must agree within max(0.002 mm, 1e-6 R); helical arcs are
    rejected."""

    model_config = ConfigDict(extra="forbid")
    type: Literal["arc"]
    start: PointIn | None = Field(default=None, description=START_DOC)
    end: PointIn
    centre: PointIn | None = None
    radius: Annotated[Number, Field(ge=-1e6, le=1e6)] | None = None
    plane: Literal["G17", "G18", "G19"] = "G17"
    direction: Literal["cw", "ccw"] = Field(default="ccw", description="cw = G02, ccw = G03, seen from the "
                                            "positive end of the plane normal")
    turns: StrictInt = Field(default=0, ge=0, le=MAX_TURNS, description="extra full turns")


class PolylineIn(BaseModel):
    """Straight lines through ``points`` (the first is the start; a degree-1 NURBS, u = arc length)."""

    model_config = ConfigDict(extra="forbid")
    type: Literal["polyline"]
    points: list[PointIn] = Field(min_length=2, max_length=200_000)


def _segment_kind(v: Any) -> str:
    kind = v.get("type", "nurbs") if isinstance(v, dict) else getattr(v, "type", "nurbs")
    return kind if kind in ("nurbs", "line", "arc", "polyline") else "nurbs"


SegmentIn = Annotated[
    Annotated[NurbsIn, Tag("nurbs")] | Annotated[LineIn, Tag("line")] | Annotated[ArcIn, Tag("arc")]
    | Annotated[PolylineIn, Tag("polyline")],
    Discriminator(_segment_kind),
]


#: Longest G-code program accepted in a request (characters).
GCODE_MAX_CHARS = 20_000_000


class ToolpathIn(BaseModel):
    """Either ``segments`` (NURBS, lines, arcs, polylines, joined end to end) or a G-code program
    (``gcode``), not both."""

    model_config = ConfigDict(extra="forbid")
    segments: list[SegmentIn] | None = Field(default=None, min_length=1, max_length=10_000)
    gcode: str | None = Field(
        default=None, min_length=1, max_length=GCODE_MAX_CHARS,
        description="G-code text (G00-G03, G17-G19, G20/G21, G90/G91, Fanuc G06.2, Siemens BSPLINE, LinuxCNC "
        "G5.2); F words become the feed limit of their blocks, G00 moves run at the machine's own limits",
    )
    corner_tolerance_deg: Annotated[Number, Field(ge=0, lt=180)] = 0.5
    corner_blend_mm: Annotated[Number, Field(ge=0, le=100)] = Field(
        default=0.0, description="blend the tangent breaks of chains of lines and arcs (G-code runs at one F, "
        "or consecutive JSON line / arc / polyline segments and NURBS that are exact lines or arcs) with G2 "
        "clothoid pairs within this distance (mm) of the original corner, so the schedule runs through them; "
        "corners that cannot be blended (not coplanar, no fit) stay rest points and are listed in "
        "diagnostics.unblended_corners; 0 stops at each corner; other than 0 at least 0.001 (the path "
        "fidelity: a narrower blend only holds the feed down)",
    )

    @field_validator("corner_blend_mm")
    @classmethod
    def _blend_within_fidelity(cls, v: float) -> float:
        if 0.0 < v < MIN_BLEND_TOLERANCE_MM:
            raise ValueError(BLEND_TOLERANCE_RULE)
        return v

    @model_validator(mode="after")
    def _one_source(self) -> ToolpathIn:
        if (self.segments is None) == (self.gcode is None):
            raise ValueError("give exactly one of toolpath.segments and toolpath.gcode")
        return self


class LimitsIn(BaseModel):
    """Kinematic limits of one axis."""

    model_config = ConfigDict(extra="forbid")
    vmax: Speed = Field(description="mm/s")
    amax: Accel = Field(description="mm/s^2")
    jmax: Jerk = Field(description="mm/s^3")


class DriveIn(BaseModel):
    """Feed-drive model of one axis: u = M a + b v + c + d sign(v) [V], e = Kv v + Ka a + Kj j [mm]."""

    model_config = ConfigDict(extra="forbid")
    M: Annotated[Number, Field(gt=0, le=1e3)] = Field(description="V s^2/mm")
    b: Annotated[Number, Field(ge=0, le=1e3)] = Field(description="V s/mm")
    c: Annotated[Number, Field(ge=-1e3, le=1e3)] = Field(description="V (bias, e.g. gravity)")
    d: Annotated[Number, Field(ge=0, le=1e3)] = Field(description="V (Coulomb friction)")
    Kv: Annotated[Number, Field(gt=0, le=1e3)] = Field(description="s")
    Ka: Annotated[Number, Field(ge=0, le=1e3)] = Field(description="s^2")
    Kj: Annotated[Number, Field(gt=0, le=1e3)] = Field(description="s^3")
    umax: Annotated[Number, Field(gt=0, le=1e4)] = Field(description="V")
    emax: Annotated[Number, Field(gt=0, le=1e3)] = Field(description="mm")
    vmax: Speed | None = Field(
        default=None, description="mm/s, the drive's own speed limit (held by lp+nlp, and by lp where the axis "
        "limits are derived from the drive); none: speed is limited through u and e only (the axis limits' vmax is "
        "the LP's limit)",
    )


class AxisIn(BaseModel):
    """One axis: limits, a drive model, or both.  Without limits they are derived from the drive model."""

    model_config = ConfigDict(extra="forbid")
    limits: LimitsIn | None = None
    drive: DriveIn | None = None
    vmax_request: Speed | None = Field(
        default=None, description="mm/s; the speed asked of the drive when limits are derived (default: what the "
        "drive can hold)",
    )

    @model_validator(mode="after")
    def _limits_or_drive(self) -> AxisIn:
        if self.limits is None and self.drive is None:
            raise ValueError("give limits, a drive model, or both")
        return self


class AxesIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    x: AxisIn
    y: AxisIn
    z: AxisIn


class MachineIn(BaseModel):
    """A custom 3-axis machine."""

    model_config = ConfigDict(extra="forbid")
    name: str = Field(default="custom", max_length=64)
    axes: AxesIn
    feed_max: Speed | None = Field(default=None, description="tangential feed limit, mm/s")


PLOT_NAMES = ("toolpath", "feed", "axes", "comparison")
PlotName = Literal["toolpath", "feed", "axes", "comparison"]
PlotFormat = Literal["svg", "png"]


class OptionsIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    method: Literal["lp", "lp+nlp"] = Field(
        default="lp+nlp",
        description='"lp+nlp" (default: LP, then the NLP refinement under the drive\'s control-signal and servo-error '
        'limits) or "lp" (velocity/acceleration/jerk limits only)'
    )
    sample_period: Annotated[Number, Field(ge=1e-5, le=0.1)] = Field(default=0.001, description="s")
    knot_spacing: Annotated[Number, Field(ge=1e-3, le=1e4)] | None = Field(
        default=None, description="mm; default 0.1 x the machine's stopping distance (under method lp+nlp, at each "
        "piece's programmed feed, coarsened to fit the request's budget of knot intervals: summary.knot_feed_floor; "
        "under a low feed cap or F word a piece is first solved on knots the top feed covers in 10 sample periods, "
        "kept if within 0.2 % of its motion's lower bound)"
    )
    checkpoints_per_interval: StrictInt = Field(default=5, ge=1, le=64)
    jerk: StrictBool = Field(
        default=True, description="the LP's pseudo-jerk stage; false (velocity and acceleration limits only) needs "
        'method "lp"'
    )
    solver: Literal["highs", "clarabel"] = Field(
        default="highs", description='the LP solver; under "clarabel" an LP window it fails on, or whose feed comes to '
        "rest inside it, is solved again with HiGHS (summary.solver_fallbacks)"
    )
    feed_max: Speed | None = Field(default=None, description="mm/s (overrides the machine's)")
    plots: list[PlotName] | None = Field(
        default=None, max_length=len(PLOT_NAMES),
        description="POST /v1/schedule only: plots to return in the JSON body's `plots` as data: URIs "
        '("comparison" needs method lp+nlp); jobs serve theirs at /v1/jobs/{id}/plots/{name}.{svg|png}',
    )
    plot_format: PlotFormat = Field(default="svg", description="format of the plots asked for in `plots`")


EXAMPLE: dict[str, Any] = {
    "toolpath": {
        "segments": [
            {
                "type": "nurbs",
                "degree": 2,
                "knots": [0, 0, 0, 1, 1, 1],
                "control_points": [[0, 0, 0], [40, 0, 0], [40, 40, 0]],
                "weights": [1, 0.7071067811865476, 1],
            }
        ]
    },
    "machine": "router",
    "options": {"method": "lp+nlp", "sample_period": 0.001},
}


#: Union-branch tags pydantic puts into error locations (service.errors drops them from field paths).
UNION_TAGS = ("preset", "custom", "nurbs", "line", "arc", "polyline")


def _machine_kind(v: Any) -> str:
    return "custom" if isinstance(v, (dict, MachineIn)) else "preset"


MachineField = Annotated[
    Annotated[Literal["router"], Tag("preset")] | Annotated[MachineIn, Tag("custom")], Discriminator(_machine_kind)
]


class ScheduleRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [EXAMPLE]})
    toolpath: ToolpathIn
    machine: MachineField = Field(
        default="router", description='a preset name ("router") or a custom per-axis machine'
    )
    options: OptionsIn = OptionsIn()


class ScheduleResponse(BaseModel):
    summary: dict[str, Any]
    diagnostics: dict[str, Any]
    samples: dict[str, list[float]] = Field(
        description="columns t, s, feed, x, y, z, v_x.., a_x.., j_x.. and, with a drive model, u_x.. (V), e_x.. (mm)"
    )
    plots: dict[str, str] | None = Field(
        default=None, description="the plots asked for in options.plots, name -> data: URI (image/svg+xml or "
        "image/png, base64)",
    )


JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]


class ProblemDetail(BaseModel):
    """One offending input: where, what and which rule."""

    field: str | None = None
    pointer: str | None = None
    value: Any = None
    rule: str


class Problem(BaseModel):
    """RFC 9457 problem details."""

    type: str
    title: str
    status: int
    detail: str
    instance: str | None = None
    errors: list[ProblemDetail] = []


class JobTimings(BaseModel):
    created: float = Field(description="Unix time, s")
    started: float | None = None
    finished: float | None = None
    queued_s: float | None = None
    run_s: float | None = None


class JobOut(BaseModel):
    id: str
    status: JobStatus
    progress: float = Field(ge=0, le=1, description="fraction of the path length scheduled")
    attempts: int
    worker_pid: int | None = Field(default=None, description="pid of the solver process while running (local "
                                   "executor) or last reported by the Dask worker")
    timings: JobTimings
    error: Problem | None = None
    summary: dict[str, Any] | None = None
    links: dict[str, str]


class ExampleOut(BaseModel):
    name: str
    description: str
    href: str


class ExampleList(BaseModel):
    examples: list[ExampleOut]


class MachineList(BaseModel):
    machines: list[str]


class MachineOut(BaseModel):
    name: str
    feed_max: float | None
    stopping_distance_mm: float
    axes: list[dict[str, Any]]
    units: dict[str, str]


class Health(BaseModel):
    status: Literal["ok"]
    schedules_in_flight: int = Field(description="synchronous schedules being solved or waiting for a solver")
    schedules_limit: int = Field(description="FEEDSCHED_MAX_INFLIGHT: one more is answered 503")
    schedules_refused: int = Field(description="503 answers to POST /v1/schedule since the start")
    jobs_active: int = Field(description="jobs queued or running")
    jobs_limit: int = Field(description="FEEDSCHED_JOB_QUEUE_DEPTH: one more POST /v1/jobs is answered 503")
    jobs_refused: int = Field(description="503 answers to POST /v1/jobs since the start")
