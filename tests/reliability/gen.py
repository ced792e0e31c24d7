"""Seeded generator of random toolpaths and machines (issue 5, item 1).

``case(seed, profile)`` is a pure function of its arguments: the same seed
always gives the same path and machine.

Paths: chains of 1..MAX_SEGMENTS segments, 2-D (z = 0) or 3-D:

- random NURBS of degree 2-5 with 3..9 control points more than the degree
  requires, random interior knots (some repeated up to multiplicity p, where
  the curve is only C0), random weights (or all 1), on a random parameter
  interval; about one in seven is unclamped (the curve starts and ends away
  from its first and last control points);
- exact lines and planar arcs from ``geometry.primitives``; exact circles
  from ``geometry.examples``;
- junctions either tangent-continuous (G1 by construction) or corners of at
  least MIN_CORNER_DEG; some chains are closed loops (end = start);
- scaled so the path is LENGTHS[profile] long (1 mm .. 10 m), moved to a
  random offset.

Machines: the router's drive models (``solvers.machine.ROUTER_DRIVES``) with
each parameter jittered per axis, then scaled in length by lambda and in time
by tau (M tau^2 / lambda, b tau / lambda, Kv tau, Ka tau^2, Kj tau^3,
emax lambda), so v, a, j limits scale by lambda / tau^k and stay consistent
with the drive (``derive_limits``): lp+nlp can always fall back on the LP.
lambda is set from the path length so that the path is RATIOS[profile] times
the machine's stopping distance (bounding the knot count); tau spans TAUS.
The LP run may use a second machine without drives whose limits are jittered
independently per axis (so v, a and j are not tied to one drive).

Segments are kept as plain data (``checker.Nurbs``) for the independent
checker; ``Case.toolpath()`` builds the scheduler's ``Toolpath`` from the same
numbers.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from geometry import examples, gcode, primitives
from geometry.arcblend import MIN_BLEND_TOLERANCE_MM
from geometry.clothoid import ClothoidSegment
from geometry.nurbs import NurbsSegment
from geometry.toolpath import Toolpath
from solvers.machine import AXES, ROUTER_DRIVES, Axis, AxisLimits, DriveModel, Machine, derive_limits
from tests.reliability.checker import Arc, Limits, Line, Nurbs, Program, Segment, Spiral, corners

FloatArray = np.ndarray

#: Path length range (mm, log-uniform) per profile: "test" runs in ``make test``, "bench" in bench/.
LENGTHS = {"test": (1.0, 300.0), "bench": (1.0, 10_000.0)}
#: Path length / machine stopping distance range (log-uniform).
RATIOS = {"test": (0.1, 3.0), "bench": (0.1, 20.0)}
#: Time scale tau range (log-uniform): tau = 1 is the router.
TAUS = {"test": (0.1, 2.0), "bench": (0.05, 5.0)}
MAX_SEGMENTS = {"test": 3, "bench": 5}
#: Curvature-continuous geometry only (the class ``make test`` holds to): interior knot
#: multiplicity <= p - 2, degree 2 without interior knots, junctions are corners (rest).
#: The bench profile also draws C1 knots and G1 junctions, where the curvature jumps
#: (see tests/reliability/test_regressions.py for what that does to the jerk).
CURVATURE_CONTINUOUS = {"test": True, "bench": False}
#: Smallest angle of a generated corner (degrees); G1 junctions are exact.
MIN_CORNER_DEG = 5.0
#: Per-axis jitter (decades, +-) of the drive parameters and of the drive-less LP machine's limits.
DRIVE_JITTER_DEC = 0.5
LIMIT_JITTER_DEC = 0.7
#: Router's requested axis speed (mm/s) before jitter.
BASE_VMAX = 150.0

#: CAM profiles (``cam_case``): G-code programs of lines, XY arcs and rapids, corners blended or not.
CAM_PROFILES = ("cam", "cam-bench")
for _p, _q in zip(CAM_PROFILES, ("test", "bench"), strict=True):
    LENGTHS[_p], RATIOS[_p], TAUS[_p] = LENGTHS[_q], RATIOS[_q], TAUS[_q]
#: Moves per program (uniform).
CAM_MOVES = {"cam": (2, 30), "cam-bench": (2, 300)}
#: A vertex's turn (degrees) by class, with each class's probability: collinear, under the corner
#: tolerance (passed at speed), moderate, sharp.
CAM_TURNS = (((0.0, 0.0), 0.1), ((0.01, 0.45), 0.3), ((1.0, 90.0), 0.4), ((90.0, 175.0), 0.2))
#: Share of moves that are XY arcs (G02/G03) and rapids (G00).
CAM_ARC_SHARE = 0.15
CAM_RAPID_SHARE = 0.08
#: Share of programs with corner blends, and the blend tolerance's range as a share of the mean leg (at least
#: the product's ``arcblend.MIN_BLEND_TOLERANCE_MM``, 1 um, the path fidelity).
CAM_BLEND_SHARE = 0.5
CAM_BLEND_RANGE = (1e-4, 0.3)
#: Programmed feeds: a share of the machine's smallest axis vmax (log-uniform); each cutting move
#: changes F with this probability.
CAM_FEED_RANGE = (0.05, 1.5)
CAM_FEED_CHANGE = 0.3
#: Decimals of the program's coordinates (1e-9 mm).
CAM_DECIMALS = 9

#: Profiles with random scheduling options: "<profile>+opts" is "<profile>"'s case (the same path and machines)
#: scheduled with the options ``random_options`` draws from the seed (``Case.options``; ``harness.options_for``).
OPTS_SUFFIX = "+opts"
OPTS_PROFILES = tuple(p + OPTS_SUFFIX for p in ("test", "bench", *CAM_PROFILES))
for _p in OPTS_PROFILES:
    _q = _p.removesuffix(OPTS_SUFFIX)
    LENGTHS[_p], RATIOS[_p], TAUS[_p] = LENGTHS[_q], RATIOS[_q], TAUS[_q]
#: Chance that each option is given (else it keeps its default), by option.
OPTS_CHANCE = {
    "sample_period": 0.5, "jerk": 0.25, "knot_spacing": 0.3, "checkpoints_per_interval": 0.3, "lp_window": 0.3,
    "lp_overlap": 0.5, "solver": 0.1, "nlp_overlap": 0.3, "nlp_window": 0.5, "nlp_checkpoints_per_interval": 0.3,
    "nlp_axis_velocity": 0.2, "nlp_kinematic": 0.2,
}
#: Ranges of the drawn options: the sample period (s, log-uniform), the knot spacing as a factor of 0.1 x the
#: run's machine's stopping distance (log-uniform; ``harness.options_for`` turns it into mm), the checkpoints
#: per interval and the windows (knot intervals; integers, both ends included).  lp_overlap is drawn in [3,
#: lp_window / 2] and nlp_window in [max(4, 2 nlp_overlap), NLP_WINDOW_MAX] (``Options``' rules).
OPTS_SAMPLE_PERIOD = (2e-4, 5e-3)
OPTS_KNOT_FACTOR = (0.5, 3.0)
OPTS_CHECKPOINTS = (2, 10)
OPTS_LP_WINDOW = (8, 120)
OPTS_NLP_OVERLAP = (2, 8)
OPTS_NLP_WINDOW_MAX = 40
OPTS_NLP_CHECKPOINTS = (2, 8)


@dataclass
class Case:
    seed: int
    profile: str
    segments: Sequence[Segment]
    machine: Machine  # with drives (both methods)
    lp_machine: Machine  # the LP run's machine (the same, or drive-less with independent limits)
    length: float
    tags: dict[str, object] = field(default_factory=dict)

    #: scheduling options beyond the method (``random_options``: "+opts" profiles); "knot_spacing" is a factor
    #: of 0.1 x the run's machine's stopping distance (``harness.options_for``)
    options: dict[str, object] = field(default_factory=dict)
    gcode: str | None = None  # a CAM case's program (its toolpath: parsed and blended as the service does)
    program: Program | None = None  # ... and the programmed path and feeds for the checker
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the program's position before its first move

    def toolpath(self) -> Toolpath:
        if self.gcode is not None and self.program is not None:
            return gcode.parse(self.gcode, start=self.start).toolpath(blend_mm=self.program.tolerance_mm)
        segs = [NurbsSegment.create(s.degree, s.knots, s.ctrl, s.weights, name=f"segments[{i}]")
                for i, s in enumerate(self.segments) if isinstance(s, Nurbs)]
        return Toolpath(segs)


def limits_of(m: Machine) -> Limits:
    """Plain arrays of a machine's numbers for the checker."""
    vmax = np.array([a.limits.vmax for a in m.axes])
    amax = np.array([a.limits.amax for a in m.axes])
    jmax = np.array([a.limits.jmax for a in m.axes])
    drive = None
    if all(a.drive is not None for a in m.axes):
        keys = ("M", "b", "c", "d", "Kv", "Ka", "Kj", "umax", "emax")
        drive = {k: np.array([getattr(a.drive, k) for a in m.axes]) for k in keys}
    return Limits(vmax, amax, jmax, m.feed_max, drive)


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(10.0 ** rng.uniform(math.log10(lo), math.log10(hi)))


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v), dtype=np.float64)


def _data(seg: NurbsSegment) -> Nurbs:
    return Nurbs(seg.degree, np.array(seg.knots), np.array(seg.control_points), np.array(seg.weights))


def _direction(rng: np.random.Generator, dims: int) -> FloatArray:
    v = rng.normal(size=3)
    if dims == 2:
        v[2] = 0.0
    return _unit(v)


def _corner_direction(rng: np.random.Generator, dims: int, prev: FloatArray | None) -> FloatArray:
    while True:
        d = _direction(rng, dims)
        if prev is None or math.degrees(math.acos(float(np.clip(np.dot(d, prev), -1, 1)))) >= MIN_CORNER_DEG:
            return d


def _knots(rng: np.random.Generator, p: int, n: int, clamped: bool, max_mult: int) -> FloatArray:
    """Knot vector of n + p + 1 entries on a random interval, some interior knots repeated."""
    if clamped:
        m = n - p - 1  # interior knots
        vals: list[float] = []
        while len(vals) < m:
            v = float(rng.uniform(0.02, 0.98))
            mult = 1
            if rng.random() < 0.3 and max_mult >= 2:
                mult = int(rng.integers(2, max_mult + 1))  # up to p: C0 at p
            vals += [v] * min(mult, m - len(vals))
        U = np.concatenate([np.zeros(p + 1), np.sort(vals), np.ones(p + 1)])
    else:
        steps = rng.uniform(0.5, 1.5, size=n + p)
        U = np.concatenate([[0.0], np.cumsum(steps)])
        U /= U[-1]
    a = float(rng.uniform(-10.0, 10.0))
    b = _loguniform(rng, 1e-2, 1e2)
    return np.asarray(a + b * U, dtype=np.float64)


def _random_nurbs(
    rng: np.random.Generator, start: FloatArray, d0: FloatArray, dims: int, end: FloatArray | None,
    clamped: bool, c2: bool,
) -> Nurbs:
    """Random NURBS starting at ``start`` heading along ``d0`` (clamped), optionally ending at ``end``."""
    p = int(rng.integers(2, 6))
    n = p + 1 + int(rng.integers(0, 7))
    if end is not None:
        n = max(n, p + 2)
    if c2 and p == 2:  # every interior knot of a quadratic is only C1: one Bezier piece
        n, clamped = 3, True
        if end is not None:
            p, n = 3, 5
    wiggle = float(rng.uniform(0.2, 1.5))
    d = d0.copy()
    P = [start.copy()]
    for _ in range(n - 1):
        P.append(P[-1] + float(rng.uniform(0.3, 1.0)) * d)
        noise = rng.normal(size=3) * wiggle
        if dims == 2:
            noise[2] = 0.0
        d = _unit(d + noise)
    ctrl = np.array(P)
    if end is not None:
        ctrl[-1] = end
    w = np.ones(n) if rng.random() < 0.4 else 10.0 ** rng.uniform(-0.7, 0.7, size=n)
    seg = Nurbs(p, _knots(rng, p, n, clamped, p - 2 if c2 else p), ctrl, w)
    if not clamped:  # move it so the curve (not the control polygon) starts at ``start``
        shift = start - seg.points(np.array([seg.domain[0]]))[0]
        seg = replace(seg, ctrl=seg.ctrl + shift)
    return seg


def _arc(rng: np.random.Generator, start: FloatArray, tangent: FloatArray) -> Nurbs:
    """Planar (XY) arc from ``start`` leaving along ``tangent`` (which must lie in XY)."""
    t = _unit(np.array([tangent[0], tangent[1], 0.0]))
    normal = np.array([-t[1], t[0], 0.0])
    ccw = rng.random() < 0.5
    r = _loguniform(rng, 0.1, 2.0)
    centre = start + (normal if ccw else -normal) * r
    sweep = float(rng.uniform(0.2, 1.9 * math.pi)) * (1.0 if ccw else -1.0)
    rel = start - centre
    c, s = math.cos(sweep), math.sin(sweep)
    end = centre + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1], 0.0])
    seg = primitives.arc(start, end, centre=centre, plane="G17", direction="ccw" if ccw else "cw")
    return _data(seg)


def _path(rng: np.random.Generator, profile: str) -> tuple[list[Nurbs], dict[str, object]]:
    dims = int(rng.choice([2, 3]))
    closed = bool(rng.random() < 0.2)
    c2 = CURVATURE_CONTINUOUS[profile]
    smooth = bool(rng.random() < 0.5) and not c2
    n_seg = int(rng.integers(1, MAX_SEGMENTS[profile] + 1))
    tags: dict[str, object] = {"dims": dims, "closed": closed, "smooth": smooth, "segments": n_seg, "kinds": []}
    kinds: list[str] = []
    if closed and n_seg == 1 and rng.random() < 0.25:
        circ = examples.circle(1.0, (0.0, 0.0))
        kinds.append("circle")
        tags["kinds"] = kinds
        return [_data(circ)], tags
    segs: list[Nurbs] = []
    start = np.zeros(3)
    origin = start.copy()
    prev_t: FloatArray | None = None
    for i in range(n_seg):
        last = i == n_seg - 1
        end = origin if (closed and last) else None
        if smooth and prev_t is not None:
            d0 = prev_t
        else:
            d0 = _corner_direction(rng, dims, prev_t)
        r = rng.random()
        if end is None and r < 0.12 and abs(d0[2]) < 1e-12:
            seg = _arc(rng, start, d0)
            kinds.append("arc")
        elif r < 0.24 and (end is None or np.linalg.norm(end - start) > 0.1):
            target = end if end is not None else start + d0 * float(rng.uniform(0.3, 2.0))
            if end is not None and smooth:
                kinds.append("line-close")
            else:
                kinds.append("line")
            seg = _data(primitives.line(start, target))
        else:
            clamped = not (rng.random() < 0.15 and end is None and not (smooth and prev_t is not None))
            seg = _random_nurbs(rng, start, d0, dims, end, clamped, c2)
            kinds.append("nurbs" if clamped else "nurbs-unclamped")
        segs.append(seg)
        start = seg.points(np.array([seg.domain[1]]))[0]
        prev_t = seg.end_tangent(True)
    tags["kinds"] = kinds
    return segs, tags


def _length(segs: list[Nurbs]) -> float:
    total = 0.0
    for s in segs:
        u = np.linspace(*s.domain, 4001)
        total += float(np.sum(np.linalg.norm(np.diff(s.points(u), axis=0), axis=1)))
    return total


def _scaled_drive(dr: DriveModel, lam: float, tau: float) -> DriveModel:
    return DriveModel(M=dr.M * tau**2 / lam, b=dr.b * tau / lam, c=dr.c, d=dr.d, Kv=dr.Kv * tau,
                      Ka=dr.Ka * tau**2, Kj=dr.Kj * tau**3, umax=dr.umax, emax=dr.emax * lam)


def _jittered_drive(rng: np.random.Generator, base: DriveModel) -> DriveModel:
    def j(x: float) -> float:
        return x * float(10.0 ** rng.uniform(-DRIVE_JITTER_DEC, DRIVE_JITTER_DEC))

    return DriveModel(M=j(base.M), b=j(base.b), c=float(rng.uniform(-1.0, 1.0)), d=float(rng.uniform(0.0, 0.3)),
                      Kv=j(base.Kv), Ka=j(base.Ka), Kj=j(base.Kj), umax=base.umax,
                      emax=base.emax * float(10.0 ** rng.uniform(-0.3, 0.3)))


def _machine(rng: np.random.Generator, length: float, profile: str) -> tuple[Machine, Machine, dict[str, float]]:
    drives = {ax: _jittered_drive(rng, ROUTER_DRIVES[ax]) for ax in AXES}
    vreq = {ax: BASE_VMAX * float(10.0 ** rng.uniform(-0.5, 0.5)) for ax in AXES}
    unit = Machine("unit", tuple(Axis(ax, derive_limits(drives[ax], vreq[ax], ax), drives[ax])  # type: ignore[arg-type]
                                 for ax in AXES))
    ratio = _loguniform(rng, *RATIOS[profile])
    tau = _loguniform(rng, *TAUS[profile])
    lam = length / (ratio * unit.stopping_distance())
    axes = []
    for ax in AXES:
        dr = _scaled_drive(drives[ax], lam, tau)
        axes.append(Axis(ax, derive_limits(dr, vreq[ax] * lam / tau, ax), dr))
    feed_max = None
    if rng.random() < 0.25:
        feed_max = float(rng.uniform(0.2, 1.0)) * min(a.limits.vmax for a in axes)
    m = Machine("random", tuple(axes), feed_max)  # type: ignore[arg-type]
    lp_m = m
    if rng.random() < 0.5:
        def jit(x: float) -> float:
            return x * float(10.0 ** rng.uniform(-LIMIT_JITTER_DEC, LIMIT_JITTER_DEC))

        lp_axes = tuple(Axis(a.name, AxisLimits(jit(a.limits.vmax), jit(a.limits.amax), jit(a.limits.jmax)), None)
                        for a in axes)
        lp_m = Machine("random-limits", lp_axes, feed_max)  # type: ignore[arg-type]
    return m, lp_m, {"ratio": ratio, "tau": tau, "lambda": lam}


def random_options(seed: int) -> dict[str, object]:
    """Scheduling options drawn from ``seed`` (deterministic; a stream of its own, so the "+opts" profiles keep
    their base profile's paths and machines): each option of ``OPTS_CHANCE`` is given with its chance, from the
    ``OPTS_*`` ranges; every draw is made whether or not the option is kept."""
    rng = np.random.default_rng([seed, 11])
    keep = {k: bool(rng.random() < c) for k, c in OPTS_CHANCE.items()}
    lp_window = int(rng.integers(OPTS_LP_WINDOW[0], OPTS_LP_WINDOW[1] + 1))
    nlp_overlap = int(rng.integers(OPTS_NLP_OVERLAP[0], OPTS_NLP_OVERLAP[1] + 1))
    drawn: dict[str, object] = {
        "sample_period": _loguniform(rng, *OPTS_SAMPLE_PERIOD),
        "jerk": False,
        "knot_spacing": _loguniform(rng, *OPTS_KNOT_FACTOR),
        "checkpoints_per_interval": int(rng.integers(OPTS_CHECKPOINTS[0], OPTS_CHECKPOINTS[1] + 1)),
        "lp_window": lp_window,
        "lp_overlap": int(rng.integers(3, lp_window // 2 + 1)),
        "solver": "clarabel",
        "nlp_overlap": nlp_overlap,
        "nlp_window": int(rng.integers(max(4, 2 * nlp_overlap), OPTS_NLP_WINDOW_MAX + 1)),
        "nlp_checkpoints_per_interval": int(rng.integers(OPTS_NLP_CHECKPOINTS[0], OPTS_NLP_CHECKPOINTS[1] + 1)),
        "nlp_axis_velocity": True,
        "nlp_kinematic": True,
    }
    if not keep["lp_window"]:
        keep["lp_overlap"] = False  # (the overlap's range is the window's)
    return {k: v for k, v in drawn.items() if keep[k]}


def case(seed: int, profile: str = "test") -> Case:
    """The random case of ``seed`` (deterministic)."""
    if profile in OPTS_PROFILES:
        base = case(seed, profile.removesuffix(OPTS_SUFFIX))
        opts = random_options(seed)
        return replace(base, profile=profile, options=opts, tags={**base.tags, "options": opts})
    if profile in CAM_PROFILES:
        return cam_case(seed, profile)
    rng = np.random.default_rng([seed, 5])
    segs, tags = _path(rng, profile)
    length = _loguniform(rng, *LENGTHS[profile])
    scale = length / _length(segs)
    offset = rng.uniform(-500.0, 500.0, size=3)
    if tags["dims"] == 2:
        offset[2] = 0.0
    segs = [replace(s, ctrl=s.ctrl * scale + offset) for s in segs]
    m, lp_m, mt = _machine(rng, length, profile)
    tags.update(mt)
    tags["corners"] = len(corners(segs))
    return Case(seed, profile, segs, m, lp_m, length, tags)


# --------------------------------------------------------------------------- CAM programs


def _turned(rng: np.random.Generator, d: FloatArray, deg: float, planar: bool) -> FloatArray:
    """``d`` turned by ``deg`` degrees about a random axis normal to it (about z if ``planar``)."""
    if planar:
        axis = np.array([0.0, 0.0, 1.0 if rng.random() < 0.5 else -1.0])
    else:
        axis = _unit(np.cross(d, _direction(rng, 3)))
    n = np.cross(axis, d)
    a = math.radians(deg)
    return _unit(math.cos(a) * d + math.sin(a) * n)


def _turn_deg(rng: np.random.Generator) -> float:
    k = int(rng.choice(len(CAM_TURNS), p=[w for _, w in CAM_TURNS]))
    lo, hi = CAM_TURNS[k][0]
    return float(rng.uniform(lo, hi))


def _moves(rng: np.random.Generator, n: int, dims: int) -> tuple[list[dict[str, object]], dict[str, int]]:
    """``n`` moves of a unit-scale program from the origin: dicts of kind ("G00", "G01", "G02", "G03"), end,
    and for arcs the centre; each leaves the previous end along the previous direction turned by
    ``_turn_deg`` (a rapid's direction is free)."""
    pos = np.zeros(3)
    d = _direction(rng, dims)
    out: list[dict[str, object]] = []
    counts = {"G00": 0, "G01": 0, "G02": 0, "G03": 0}
    for i in range(n):
        r = rng.random()
        kind = "G00" if i and r < CAM_RAPID_SHARE else ("ARC" if r < CAM_RAPID_SHARE + CAM_ARC_SHARE else "G01")
        if kind == "G00":
            d = _direction(rng, dims)
        else:
            d = _turned(rng, d, _turn_deg(rng), dims == 2)
        leg = _loguniform(rng, 0.2, 5.0)
        if kind == "ARC":
            t = np.array([d[0], d[1], 0.0])
            if np.linalg.norm(t) < 0.1:  # leaving nearly along z: a line instead
                kind = "G01"
            else:
                t = _unit(t)
                ccw = rng.random() < 0.5
                normal = np.array([-t[1], t[0], 0.0]) * (1.0 if ccw else -1.0)
                radius = leg * _loguniform(rng, 0.2, 2.0)
                centre = pos + radius * normal
                sweep = math.radians(float(rng.uniform(10.0, 300.0))) * (1.0 if ccw else -1.0)
                rel = pos - centre
                c, s_ = math.cos(sweep), math.sin(sweep)
                end = centre + np.array([c * rel[0] - s_ * rel[1], s_ * rel[0] + c * rel[1], 0.0])
                kind = "G03" if ccw else "G02"
                out.append({"kind": kind, "end": end, "centre": centre})
                counts[kind] += 1
                e = end - centre
                d = _unit(np.array([-e[1], e[0], 0.0]) * (1.0 if ccw else -1.0))
                pos = end
                continue
        end = pos + leg * d
        out.append({"kind": kind, "end": end})
        counts[kind] += 1
        pos = end
    return out, counts


def _fmt(x: float) -> str:
    return f"{x:.{CAM_DECIMALS}f}"


def _program_text(moves: list[dict[str, object]], start: FloatArray, feeds: list[float | None],
                  ) -> tuple[str, list[Line | Arc]]:
    """The G-code (absolute mm, G17, arcs by I J) of ``moves`` already scaled and moved, and the programmed
    moves from the same rounded numbers (arcs: centre, start radius and sweep from the I J and end words)."""
    lines = ["G21 G90 G17"]
    segs: list[Line | Arc] = []
    pos = np.array([float(_fmt(v)) for v in start])
    last_f: float | None = None
    for m, f in zip(moves, feeds, strict=True):
        kind = str(m["kind"])
        end = np.array([float(_fmt(v)) for v in np.asarray(m["end"])])
        words = [kind, f"X{_fmt(end[0])}", f"Y{_fmt(end[1])}", f"Z{_fmt(end[2])}"]
        if kind in ("G02", "G03"):
            ij = np.asarray(m["centre"]) - pos
            ij = np.array([float(_fmt(ij[0])), float(_fmt(ij[1])), 0.0])
            words += [f"I{_fmt(ij[0])}", f"J{_fmt(ij[1])}"]
            centre = pos + ij
            r = float(np.linalg.norm(pos - centre))
            e1 = (pos - centre) / r
            e2 = np.cross([0.0, 0.0, 1.0 if kind == "G03" else -1.0], e1)
            rel = end - centre
            sweep = math.atan2(float(rel @ e2), float(rel @ e1)) % (2.0 * math.pi)
            segs.append(Arc(centre, e1, e2, r, sweep))
        else:
            segs.append(Line(pos, end))
        if f is not None and f != last_f:
            words.append(f"F{f * 60.0:.6f}")
            last_f = f
        lines.append(" ".join(words))
        pos = end
    return "\n".join(lines) + "\n", segs


def _checked_segments(tp: Toolpath) -> list[Segment]:
    """The toolpath's segments (its corner blends included) as the checker's plain data."""
    out: list[Segment] = []
    for seg in tp.segments:
        if isinstance(seg, ClothoidSegment):
            out.append(Spiral(np.array(seg.start), np.array(seg.e1), np.array(seg.e2), seg.phi0, seg.kappa0,
                              seg.sharpness, seg.length))
        elif isinstance(seg, NurbsSegment):
            out.append(_data(seg))
        else:
            raise TypeError(f"no checker data for {type(seg).__name__}")
    return out


def cam_case(seed: int, profile: str = "cam", min_blend_mm: float = MIN_BLEND_TOLERANCE_MM) -> Case:
    """A random G-code program (deterministic in ``seed``): 2-D or 3-D chains of lines, XY arcs (G02/G03
    by I J) and rapids (G00), each vertex turning by a random class of angle (``CAM_TURNS``: collinear,
    under the corner tolerance, moderate, sharp), F words changing along the way (a share of the
    machine's smallest vmax), corners blended at a random tolerance in half of them (``CAM_BLEND_SHARE``).
    The machine is drawn as in ``case``, sized to the mean leg (not the whole path), so the legs are
    RATIOS[profile] stopping distances long.

    The checker's path is the toolpath the product builds from the program (the blends' clothoids
    included); the programmed moves and feeds go in ``Case.program``, so the samples are also checked
    against the program itself (within the blend tolerance) and its F words.

    A drawn blend tolerance under ``min_blend_mm`` is raised to it (the product refuses blends under
    MIN_BLEND_TOLERANCE_MM); a test of the solver on narrower blends passes 0 and lifts the product's rule."""
    rng = np.random.default_rng([seed, 7])
    dims = int(rng.choice([2, 3]))
    n = int(rng.integers(CAM_MOVES[profile][0], CAM_MOVES[profile][1] + 1))
    moves, counts = _moves(rng, n, dims)
    ends = [np.zeros(3)] + [np.asarray(m["end"]) for m in moves]
    unit_len = float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(ends)))
    length = _loguniform(rng, *LENGTHS[profile])
    scale = length / unit_len
    offset = rng.uniform(-500.0, 500.0, size=3)
    if dims == 2:
        offset[2] = 0.0
    moves = [{k: (np.asarray(v) * scale + offset if k in ("end", "centre") else v) for k, v in m.items()}
             for m in moves]
    m, lp_m, mt = _machine(rng, length / n, profile)
    vref = min(a.limits.vmax for a in m.axes)
    feeds: list[float | None] = []
    f: float | None = None
    for mv in moves:
        if mv["kind"] == "G00":
            feeds.append(None)
            continue
        if f is None or rng.random() < CAM_FEED_CHANGE:
            f = vref * _loguniform(rng, *CAM_FEED_RANGE)
        feeds.append(f)
    blend = 0.0
    if rng.random() < CAM_BLEND_SHARE:
        blend = float(_fmt(max(min_blend_mm, length / n * _loguniform(rng, *CAM_BLEND_RANGE))))
    text, prog_segs = _program_text(moves, offset, feeds)
    start = (float(_fmt(offset[0])), float(_fmt(offset[1])), float(_fmt(offset[2])))
    # the rounded F words, as the program states them
    feeds_r = [None if x is None else float(f"{x * 60.0:.6f}") / 60.0 for x in feeds]
    prog = Program(prog_segs, blend, feeds_r)
    c = Case(seed, profile, [], m, lp_m, length, {"dims": dims, "moves": n, "blend_mm": blend, **counts, **mt},
             gcode=text, program=prog, start=start)
    tp = c.toolpath()
    c.segments = _checked_segments(tp)
    c.tags["corners"] = len(corners(c.segments))
    c.tags["unblended"] = len(tp.unblended)
    return c
