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

import math
from dataclasses import dataclass, field, replace

import numpy as np

from geometry import examples, primitives
from geometry.nurbs import NurbsSegment
from geometry.toolpath import Toolpath
from solvers.machine import AXES, ROUTER_DRIVES, Axis, AxisLimits, DriveModel, Machine, derive_limits
from tests.reliability.checker import Limits, Nurbs, corners

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


@dataclass
class Case:
    seed: int
    profile: str
    segments: list[Nurbs]
    machine: Machine  # with drives (both methods)
    lp_machine: Machine  # the LP run's machine (the same, or drive-less with independent limits)
    length: float
    tags: dict[str, object] = field(default_factory=dict)

    def toolpath(self) -> Toolpath:
        segs = [NurbsSegment.create(s.degree, s.knots, s.ctrl, s.weights, name=f"segments[{i}]")
                for i, s in enumerate(self.segments)]
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


def case(seed: int, profile: str = "test") -> Case:
    """The random case of ``seed`` (deterministic)."""
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
